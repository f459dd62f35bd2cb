"""``benchmarks/bench_nav.py`` times what ``epoch_navigation`` computes.

Its stage split must rebuild each stage's inputs from a recorded call (the stages, run one
after another, give the kernel's own selection bit for bit), and ``positional`` must give an
older revision's kernel the 39 arguments in the order it took them (``--compare``).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.benchmark_scripts import load_benchmark

bench_nav = load_benchmark("bench_nav")

# epoch_navigation's arguments before it took records, in their order: (record, field)
OLD_ORDER = [
    *(("geometry", f) for f in ("range_m", "el_deg", "sv", "system", "received")),
    *(
        ("pseudoranges", f)
        for f in (
            "clock",
            "iono",
            "z_common",
            "z_user",
            "extra",
            "el_ref",
            "sigma_ure",
            "tropo",
            "differential",
            "n_sys",
        )
    ),
    ("prior", "x0"),
    *(("centroids", f) for f in ("rel", "var", "avail", "cen", "x0", "ddt")),
    *(("solving", f) for f in ("max_iter", "tol_m", "check", "r_lo", "r_hi")),
    ("centroids", "linked"),
    ("solving", "gate_on"),
    ("solving", "gate2"),
    *(("prior", f) for f in ("origin", "rot", "pred_enu", "prev_cov", "dr_var")),
    *(("waypoints", f) for f in ("route", "next_wp", "reach_m")),
    ("centroids", "links"),
]


@pytest.fixture(scope="module")
def epochs():
    return bench_nav.record_epochs(1, 6, 0)


def test_the_recording_holds_the_kernels_records(epochs):
    assert len(epochs) == 7  # the reset's first epoch and 6 steps
    records = dict(zip(("geometry", "pseudoranges", "centroids", "solving", "prior"), epochs[0]))
    assert records["geometry"][0].shape == records["pseudoranges"][3].shape  # (N, S)


def test_positional_is_the_order_of_the_arguments_before_the_records(epochs):
    names = ("geometry", "pseudoranges", "centroids", "solving", "prior", "waypoints")
    kinds = (
        bench_nav.sim_k.Geometry,
        bench_nav.sim_k.Pseudoranges,
        bench_nav.sim_k.Centroids,
        bench_nav.sim_k.Solving,
        bench_nav.sim_k.Prior,
        bench_nav.sim_k.Waypoints,
    )
    args = epochs[1]
    records = {name: kind(*a) for name, kind, a in zip(names, kinds, args, strict=True)}
    flat = bench_nav.positional(args)
    assert len(flat) == len(OLD_ORDER) == 39
    for value, (record, field) in zip(flat, OLD_ORDER, strict=True):
        expected = getattr(records[record], field)
        if isinstance(expected, np.ndarray):
            assert value is expected, (record, field)
        else:
            assert value == expected and type(value) is type(expected), (record, field)


def test_the_stages_run_one_after_another_give_the_kernels_selection(epochs):
    for args in epochs[::2]:
        stages, sizes = bench_nav.stage_inputs(args)
        assert set(stages) >= {"pseudoranges", "standalone", "co_gauss_newton", "selection"}
        whole = bench_nav.sim_k.epoch_navigation(*args)
        by_stage = bench_nav.sim_k.select_navigation(*stages["selection"])
        for a, b in zip(whole[3], by_stage, strict=True):  # the ten arrays of the selection
            assert a.tobytes() == b.tobytes()
        assert sizes["flops"]["cooperative"] > 0 and sizes["flops"]["standalone"] > 0


def test_random_commands_record_the_same_epochs_for_a_seed_and_refuse_other_policies():
    first = bench_nav.record_epochs(2, 6, 3, "random")
    again = bench_nav.record_epochs(2, 6, 3, "random")
    assert len(first) == len(again) >= 4  # two resets' first epochs and some steps
    for a, b in zip(first, again, strict=True):  # the same commands, hence the same epochs
        assert a[0][0].tobytes() == b[0][0].tobytes()  # the receivers' ranges
    with pytest.raises(ValueError, match="'hover'"):
        bench_nav.record_epochs(1, 6, 0, "hover")
