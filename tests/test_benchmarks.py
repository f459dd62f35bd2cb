"""The helpers of ``benchmarks/bench_env.py`` count what they say they count."""

from __future__ import annotations

import sys
import warnings

import numpy as np

from tests.benchmark_scripts import load_benchmark

bench_env = load_benchmark("bench_env")


def test_the_benchmark_measures_urban_canyon_v1_without_the_legacy_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error", FutureWarning)
        env = bench_env.make_urban(3)
    assert env.metadata["name"] == "urban_canyon_v1"
    assert len(env.possible_agents) == 3


def test_reachable_bytes_counts_a_shared_array_once():
    data = np.zeros(1000)  # 8,000 bytes of data
    first, second = [data], [data]
    seen: set[int] = set()
    b1, a1 = bench_env.reachable_bytes(first, seen)
    b2, a2 = bench_env.reachable_bytes(second, seen)
    assert a1 == 8000 and b1 >= 8000 + sys.getsizeof(first)
    assert a2 == 0 and b2 == sys.getsizeof(second)


def test_reachable_bytes_hands_back_the_array_a_view_looks_into():
    base = np.zeros((64, 5, 3))
    view = base[3]
    bases: list[np.ndarray] = []
    b, a = bench_env.reachable_bytes({"pos": view}, set(), bases)
    assert a == 0 and b < base.nbytes  # the view's header, not the batch's buffer
    assert len(bases) == 1 and bases[0] is base
    b_all, a_all = bench_env.reachable_bytes({"pos": view}, set())
    assert a_all == base.nbytes and b_all > base.nbytes


def test_reachable_bytes_counts_the_buffer_of_an_array_a_kernel_made():
    from numba import njit

    @njit
    def make(n):
        return np.zeros(n)

    made = make(1000)  # its base is numba's memory info, not an array
    assert not isinstance(made.base, np.ndarray)
    _b, a = bench_env.reachable_bytes([made, made[10:]], set())
    assert a == 8000  # once, the view's header not counted again
    bases: list[np.ndarray] = []
    bench_env.reachable_bytes({"view": made[3:]}, set(), bases)
    assert len(bases) == 1 and bases[0] is made


def test_memory_options_default_to_the_issue_sizes():
    args = bench_env.parse_args([])
    assert args.memory_copies == [64, 256, 1024, 4096]
    assert (args.copies, args.scale_copies) == (64, 256)  # K = 256 beside K = 64
    assert bench_env.parse_args(["--quick"]).scale_copies == 0
    assert "batch_memory" in bench_env.SECTIONS
    quick = bench_env.parse_args(["--quick"])
    assert max(quick.memory_copies) < 4096


def test_city_options_fly_the_copies_on_a_built_family_pool():
    from coopnav_env.sim.city_families import seeded_family_city

    args = bench_env.parse_args(["--city", "family:mixed", "--city-pool", "3"])
    assert (args.city, args.city_pool) == ("family:mixed", 3)
    assert bench_env.city_settings(None, None) == {}
    kw = bench_env.city_settings(args.city, args.city_pool)
    assert kw == {"city": "family:mixed", "city_pool": 3}
    bench_env.build_city_pool(2, args.city, args.city_pool)
    misses = seeded_family_city.cache_info().misses
    env = bench_env.make_urban(2, **kw)
    for seed in range(4):  # every episode flies one of the pool's cities, built already
        env.reset(seed=seed)
    assert seeded_family_city.cache_info().misses == misses


def test_the_arrays_stepper_steps_every_copy_through_step_arrays(monkeypatch):
    from coopnav_env.envs import BatchedUrbanCanyonEnv

    calls = []
    step_arrays = BatchedUrbanCanyonEnv.step_arrays

    def counted(self, actions):
        calls.append(np.asarray(actions).shape)
        return step_arrays(self, actions)

    monkeypatch.setattr(BatchedUrbanCanyonEnv, "step_arrays", counted)
    step, batch = bench_env.batch_stepper(2, 3)
    steps0 = [e._steps for e in batch.envs]
    step(2)
    assert calls == [(3, 2, 3), (3, 2, 3)]  # K copies of N UAVs, one call per batched step
    # every copy advanced twice, or began a new episode on the way
    assert all(e._steps in (s + 2, 0, 1) for e, s in zip(batch.envs, steps0))
    batch.close()


def test_scale_copies_steps_the_larger_batch_in_the_same_rounds(monkeypatch, capsys):
    import pytest

    if not (bench_env.have("stable_baselines3") and bench_env.have("supersuit")):
        pytest.skip("section 5 needs the train extra")
    called = []

    def one_step_each(fns, seconds, rounds):  # every stepper once, at 1 step/s
        for name, fn in fns.items():
            fn(1)
            called.append(name)
        return dict.fromkeys(fns, 1.0)

    monkeypatch.setattr(bench_env, "side_by_side", one_step_each)
    args = bench_env.parse_args(
        ["--sections", "batched", "--copies", "4", "--scale-copies", "8", "--seconds", "0.1"]
    )
    out: dict = {}
    bench_env.section_batched(args, out)
    rates = out["batched"]["env_steps_per_s"]
    assert {"arrays", "arrays@8"} <= set(called)
    # env-steps/s are the batch's steps/s times its copies
    assert rates["arrays"] == 4.0 and rates["arrays@8"] == 8.0
    assert out["batched"]["scale_copies"] == 8
    assert "K = 8 against K = 4: arrays 0.50x" in capsys.readouterr().out


def test_copy_breakdown_counts_the_step_arrays_the_copies_share_once():
    from coopnav_env.envs import BatchedUrbanCanyonEnv

    batch = BatchedUrbanCanyonEnv.from_envs([bench_env.make_urban(2) for _ in range(3)])
    batch.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(2):
        batch.step(rng.uniform(-1.0, 1.0, (3, 2, 3)))
    parts, (shared_b, shared_a) = bench_env.copy_breakdown(batch.envs, set())
    # every copy's last epoch views the step's (K, ...) arrays: those are the batch's,
    # counted once, not in the first copy that reaches them
    assert parts["world.last"][1] == 0
    epochs, _k = batch.envs[0].world.last.__dict__["_pending"]  # (not read: no views yet)
    rows = [a for a in epochs.rows if isinstance(a, np.ndarray)]
    assert rows and shared_a >= sum(a.nbytes for a in rows)
    assert shared_b >= shared_a > 0
    batch.close()


def test_array_step_timeline_splits_the_step_and_counts_the_resets():
    import importlib

    _fused = importlib.import_module("coopnav_env.envs._fused")
    step, batch = bench_env.batch_stepper(3, 8)
    run_parallel = _fused._run_parallel
    ms = bench_env.array_step_timeline(step, 0.0, min_steps=12)
    assert _fused._run_parallel is run_parallel  # the timer is taken off again
    windows = ("motion_sight_relative", "navigation_reward_sensors", "observations_infos")
    assert set(windows) <= set(ms)
    # the windows and the Python outside them make up the step; the resets run inside the
    # navigation window (random commands crash copies within a few steps: there are some)
    assert abs(sum(ms[w] for w in windows) + ms["python"] - ms["step"]) < 1e-9
    assert ms["python"] > 0.0 and all(ms[w] > 0.0 for w in windows)
    assert 0.0 < ms["resets"] < ms["navigation_reward_sensors"]
    batch.close()
