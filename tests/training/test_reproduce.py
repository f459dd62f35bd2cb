"""Tests of ``coopnav reproduce``: the paper's qualitative claims on a quick run, determinism,
outputs, configuration validation and the scenario builder."""

from __future__ import annotations

import copy
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.nav import (
    NavStatus,
    RelativePositions,
    solve_cooperative,
    solve_master_slave,
    solve_standalone,
)
from reproduction import ReproduceConfig, reproduce, simulate_epoch
from reproduction.scenario import (
    PaperScenario,
    canyon_mask_elevation_deg,
    formation_enu,
    in_azimuth_intervals,
)
from training.cli import main as cli_main

FIGURES = (
    "fig6_skyplot.png",
    "fig7_error_time.png",
    "fig8_cdf.png",
    "fig9_sig_std.png",
    "fig10_improvement_vs_los.png",
    "fig11_error_vs_los.png",
    "fig12_improvement_vs_relerr.png",
    "table2_swarm_size.png",
)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> tuple[Path, dict]:
    """One ``coopnav reproduce --quick`` run through the command line."""
    out = tmp_path_factory.mktemp("repro")
    assert cli_main(["reproduce", "--out", str(out), "--quick", "--no-progress"]) == 0
    return out, json.loads((out / "results.json").read_text())


def _numbers(results: dict) -> dict:
    return {k: v for k, v in results.items() if k != "timing"}


# --------------------------------------------------------------------------------------------
# The paper's qualitative claims
# --------------------------------------------------------------------------------------------


def test_cooperative_beats_standalone(quick_run):
    _, r = quick_run
    for tr in ("ddt", "sdt"):
        imp = r["main"]["improvement"][tr]
        assert imp["sig"] > 0 and imp["rms"] > 0
        p3 = r["main"]["p3m"][tr]
        assert p3["cooperative"] > p3["standalone"]
    t1 = r["main"]["table1"]
    for ax in ("E", "N", "U"):
        assert t1["cooperative"][ax]["std"] < t1["standalone"][ax]["std"]


def test_gain_shrinks_as_canyon_uav_sees_more_satellites(quick_run):
    _, r = quick_run
    for key in ("without", "with"):
        pts = [
            (b["n_los"], b[key]["improvement_ddt"]["sig"])
            for b in r["los"]["bins"]
            if b[key]["improvement_ddt"]["sig"] is not None
        ]
        assert len(pts) >= 3
        x, y = np.array(pts).T
        assert np.polyfit(x, y, 1)[0] < 0
        assert y[0] > y[-1]


def test_gain_grows_with_swarm_size_with_differential_correction(quick_run):
    _, r = quick_run
    with_ = [r["swarm"]["with"][n]["sig"] for n in ("2", "5", "10", "20", "50")]
    assert all(b > a for a, b in itertools.pairwise(with_))
    without = [r["swarm"]["without"][n]["sig"] for n in ("2", "5", "10", "20", "50")]
    assert max(without) - min(without) < max(with_) - min(with_)


def test_proposed_beats_master_slave_at_every_relative_error(quick_run):
    _, r = quick_run
    for key in ("without", "with"):
        assert len(r["rel_error"][key]) >= 3
        for sd, v in r["rel_error"][key].items():
            assert v["proposed"]["sig"] > v["master_slave"]["sig"], (key, sd)
            assert v["proposed"]["rms"] > v["master_slave"]["rms"], (key, sd)


def test_only_ddt_works_with_one_to_three_satellites(quick_run):
    _, r = quick_run
    few = [b for b in r["los"]["bins"] if 1 <= b["n_los"] <= 3 and b["without"]["epochs"]]
    assert few
    for b in few:
        assert b["without"]["fix_rate_standalone"] == 0
        assert b["without"]["fix_rate_sdt"] == 0
        assert b["without"]["fix_rate_ddt"] > 0


# --------------------------------------------------------------------------------------------
# Outputs and determinism
# --------------------------------------------------------------------------------------------


def test_outputs_exist_and_are_consistent(quick_run):
    out, r = quick_run
    report = (out / "report.md").read_text()
    for name in FIGURES:
        assert (out / name).stat().st_size > 1000, name
        assert f"]({name})" in report
    assert "| Table 1" in report or "## Table 1" in report
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["seed"] == 0 and cfg == r["config"]
    assert ReproduceConfig.from_dict(cfg) == ReproduceConfig.quick(progress=False)
    published = {row["quantity"]: row for row in r["comparison"]}
    row = published["Table 2 improvement N = 5, without differential correction"]
    assert row["published"] == 57.53
    assert math.isclose(row["difference"], row["reproduced"] - 57.53)
    assert len(r["comparison"]) == 18 + 2 + 10
    assert r["main"]["exclusions"]["standalone"]["epochs"] == 12


def test_same_seed_gives_identical_results(tmp_path):
    cfg = ReproduceConfig.quick(sensitivity=False, figures=False, progress=False)
    a = json.loads((reproduce(cfg, tmp_path / "a") / "results.json").read_text())
    b = json.loads((reproduce(cfg, tmp_path / "b") / "results.json").read_text())
    assert _numbers(a) == _numbers(b)
    c = json.loads(
        (
            reproduce(
                ReproduceConfig.quick(seed=1, sensitivity=False, figures=False, progress=False),
                tmp_path / "c",
            )
            / "results.json"
        ).read_text()
    )
    assert _numbers(c)["main"] != _numbers(a)["main"]


# --------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_epochs": 1}, r"ReproduceConfig.n_epochs must be an integer in \[2, 10000\]"),
        ({"n_samples": 2.5}, r"ReproduceConfig.n_samples must be an integer"),
        ({"epoch_spacing_s": 0.0}, r"ReproduceConfig.epoch_spacing_s must be in \(0.0"),
        ({"covariance": "approx"}, r"ReproduceConfig.covariance must be one of"),
        ({"transfer": "tdt"}, r"ReproduceConfig.transfer must be one of"),
        ({"swarm_sizes": (5, 2)}, r"ReproduceConfig.swarm_sizes must be strictly increasing"),
        ({"swarm_sizes": (1, 5)}, r"ReproduceConfig.swarm_sizes must be an integer in \[2, 200"),
        ({"rel_errors_m": (-0.5,)}, r"ReproduceConfig.rel_errors_m must be in \[0.0, 100.0\]"),
        ({"los_method": "bins"}, r"ReproduceConfig.los_method must be one of"),
        ({"max_pdop": 0.5}, r"ReproduceConfig.max_pdop must be in \[1.0, 1000.0\]"),
        ({"figures": 1}, r"ReproduceConfig.figures must be one of"),
        ({"scenario": {"h_over_d": 2}}, r"ReproduceConfig.scenario must be a PaperScenario"),
    ],
)
def test_bad_config_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ReproduceConfig(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_uavs": 1}, r"PaperScenario.n_uavs must be an integer in \[2, 200\]"),
        ({"canyon_uav": 5}, r"PaperScenario.canyon_uav must be an integer in \[0, 4\]"),
        ({"h_over_d": -1.0}, r"PaperScenario.h_over_d must be in \[0.0, 1000.0\]"),
        ({"elevation_cutoff_deg": 60.0}, r"PaperScenario.elevation_cutoff_deg must be in"),
        ({"gaps_deg": ((10.0, 400.0),)}, r"PaperScenario.gaps_deg end must be in \[0.0, 360"),
        ({"gaps_deg": (5.0,)}, r"PaperScenario.gaps_deg must be a sequence of \(start, end\)"),
        ({"frequencies": "L5"}, r"PaperScenario.frequencies must be one of"),
        ({"open_sky_selection": "best"}, r"PaperScenario.open_sky_selection must be one of"),
        ({"differential": "yes"}, r"PaperScenario.differential must be one of"),
        ({"sigma_rel_m": math.nan}, r"PaperScenario.sigma_rel_m must be in"),
    ],
)
def test_bad_scenario_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PaperScenario(**kwargs)


def test_unknown_keys_are_rejected(tmp_path, capsys):
    with pytest.raises(ValueError, match="unknown ReproduceConfig keys"):
        ReproduceConfig.from_dict({"n_epoch": 3})
    with pytest.raises(ValueError, match="unknown PaperScenario keys"):
        ReproduceConfig.from_dict({"scenario": {"hd": 3}})
    assert cli_main(["reproduce", "--out", str(tmp_path), "--set", "hd=3"]) == 2
    assert "unknown --set key 'hd'" in capsys.readouterr().err
    assert cli_main(["reproduce", "--out", str(tmp_path), "--set", "n_epochs=1"]) == 2
    assert "ReproduceConfig.n_epochs" in capsys.readouterr().err


def test_config_round_trip():
    cfg = ReproduceConfig(
        scenario=PaperScenario(gaps_deg=(), h_over_d=2.0), max_pdop=10.0, covariance="paper"
    )
    again = ReproduceConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg


# --------------------------------------------------------------------------------------------
# Scenario builder
# --------------------------------------------------------------------------------------------


def test_canyon_mask_eq25_with_gaps():
    hd = math.sqrt(3.0)
    az = np.array([0.0, 90.0, 180.0, 270.0, 60.0, 30.0])
    mask = canyon_mask_elevation_deg(az, hd, 0.0, ((50.0, 70.0),))
    assert np.allclose(mask[:4], [0.0, 60.0, 0.0, 60.0], atol=1e-9)
    assert mask[4] == 0.0  # in the gap
    assert math.isclose(mask[5], math.degrees(math.atan(hd * 0.5)))
    turned = canyon_mask_elevation_deg(np.array([90.0, 0.0]), hd, 90.0, ())
    assert np.allclose(turned, [0.0, 60.0], atol=1e-9)
    assert in_azimuth_intervals(np.array([355.0, 5.0, 20.0]), ((350.0, 10.0),)).tolist() == [
        True,
        True,
        False,
    ]


def test_formation_is_a_cross_and_grows_compactly():
    f5 = formation_enu(5, 20.0)
    assert np.array_equal(f5[0], [0.0, 0.0, 0.0])
    assert np.allclose(np.sort(np.linalg.norm(f5[1:], axis=1)), 20.0)
    f50 = formation_enu(50, 10.0)
    assert len({tuple(p) for p in f50}) == 50
    assert np.abs(f50).max() <= 40.0


def test_epoch_visibility_and_draws():
    scen = PaperScenario()
    rng = np.random.default_rng(0)
    ep = scen.epoch(3600.0, rng)
    assert np.all(ep.visible.sum(axis=1) <= scen.max_sats)
    assert np.all(ep.visible[1:].sum(axis=1) == scen.max_sats)
    c = ep.canyon_uav
    above = ep.el_deg[c][ep.visible[c]]
    assert np.all(above > scen.canyon_mask_deg(ep.az_deg[c][ep.visible[c]]))
    smp = ep.draw(rng, 4)
    assert smp.pr_m.shape == (4, ep.n_uavs, ep.n_sv)
    assert np.array_equal(np.isfinite(smp.pr_m[0]), ep.visible)
    assert np.all(smp.eps_enu_m[:, c] == 0.0)
    thin = scen.epoch(3600.0, np.random.default_rng(1), n_los=2)
    assert thin.n_los == 2


def test_bulk_methods_equal_the_library_solvers():
    """simulate_epoch's batched fixes equal solve_standalone, solve_cooperative(centroid='self')
    and solve_master_slave on the same realisation."""
    scen = PaperScenario(h_over_d=1.0)
    rng = np.random.default_rng(3)
    ep = scen.epoch(7200.0, rng)
    c = ep.canyon_uav
    smp = ep.draw(copy.deepcopy(rng), 3)
    res = simulate_epoch(ep, rng, 3, methods=("standalone", "ddt", "sdt", "master_slave"))
    obs = ep.observations(smp.pr_m[0])
    rel_exact = ep.relative_positions()
    rel = rel_exact.rel_ecef_m.copy()
    rel[c] = smp.rel_from_canyon_ecef_m[0]
    rel[:, c] = -rel[c]
    rel = RelativePositions(rel, rel_exact.cov_ecef_m2, rel_exact.available)
    truth = ep.pos_ecef_m[c]
    sa = solve_standalone(obs, ep.origin_ecef_m)
    assert sa.status[c] == NavStatus.OK
    assert np.allclose(
        (sa.pos_ecef_m[c] - truth) @ ep.rot_enu.T, res.err_enu_m["standalone"][0], atol=1e-6
    )
    for tr in ("ddt", "sdt"):
        co = solve_cooperative(obs, rel, transfer=tr, centroid="self", x0_ecef_m=ep.origin_ecef_m)
        err = (co.pos_ecef_m[c] - truth) @ ep.rot_enu.T
        assert np.allclose(err, res.err_enu_m[tr][0], atol=1e-6)
        var = np.diag(ep.rot_enu @ co.cov_ecef_m2[c] @ ep.rot_enu.T)
        assert np.allclose(var, res.var_enu_m2[tr][0], rtol=1e-9)
    master = solve_master_slave(ep.observations(), rel_exact).master
    ms = solve_master_slave(obs, rel, master=master, x0_ecef_m=ep.origin_ecef_m)
    err = (ms.pos_ecef_m[c] - truth) @ ep.rot_enu.T
    assert np.allclose(err, res.err_enu_m["master_slave"][0], atol=1e-6)
    var = np.diag(ep.rot_enu @ ms.cov_ecef_m2[c] @ ep.rot_enu.T)
    assert np.allclose(var, res.var_enu_m2["master_slave"][0], rtol=1e-6)
