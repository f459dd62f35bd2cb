"""``coopnav evaluate --suite real`` (``coopnav_env.training.suite``): one command flies a
policy family on every real city of the suite with the real sky, one report per city and a
summary table.

The cities are OpenStreetMap extracts: these tests need pyosmium (the ``osm`` extra).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from coopnav_env.sim.real_suite import REAL_SUITE
from coopnav_env.training.cli import main
from coopnav_env.training.envs import EVAL_SEED_START

pytest.importorskip("osmium")

SEED = EVAL_SEED_START


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code)


def test_the_suite_command_writes_a_report_per_city_and_a_summary(tmp_path: Path, capsys):
    out = tmp_path / "suite"
    rc = _run(
        [
            *("evaluate", "--suite", "real", "--policies", "column", "sky_column"),
            *("--seeds", str(SEED), "--out", str(out)),
        ]
    )
    printed = capsys.readouterr().out
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [c["name"] for c in summary["cities"]] == [c.name for c in REAL_SUITE]
    assert len(summary["rows"]) == 2 * len(REAL_SUITE)
    for row in summary["rows"]:
        assert 0.0 <= row["goal_rate"] <= 1.0
        assert row["n_sats_mean"] >= 4.0  # a real GPS sky over every city
        assert row["episodes"] == 1
        # what the swarm did, beside how well: the behaviour descriptors of the cruise
        assert 0.0 < row["cruise_spacing_m"] < 500.0
        assert 0.0 < row["cruise_altitude_m"] < 200.0
        assert row["cruise_spread_m"] >= 0.0 and row["cruise_speed_mps"] >= 0.0
    for city in REAL_SUITE:
        report = json.loads((out / city.name / "report.json").read_text())
        assert report["env_kwargs"]["city"] == f"osm:{city.osm}"
        assert report["env_kwargs"]["constellation"] == "rinex:igs_brdc"
        assert report["env_kwargs"]["city_bbox"] == list(city.bbox)
        assert f"| {city.name} | column |" in printed
    table = (out / "summary.md").read_text()
    assert "| city | policy | score | nav error mean [m] |" in table and "sats/UAV" in table
    assert "| cruise spacing [m] | altitude [m] | spread across route [m] | speed [m/s] |" in table


def test_a_trained_policy_flies_its_runs_settings_in_the_suite_city():
    pytest.importorskip("torchrl")
    from coopnav_env.training.suite import evaluate_suite

    result = evaluate_suite(["column", "mappo:pretrained/route_s0"], [SEED])
    for city in REAL_SUITE:
        report = result.reports[city.name]
        assert [s.policy for s in report.stats] == ["column", "mappo:pretrained/route_s0"]
        assert "mappo:pretrained/route_s0 with the settings of its run" in report.env_source
        assert '"action_frame": "route"' in report.env_source
        assert "column with" not in report.env_source
        assert report.env_kwargs == city.env_settings()  # the heuristic's: the suite's alone


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--city", "grid"], "leave out --city"),
        (["--methods", "m=column"], "leave out --methods"),
        (["--seeds", "3"], "--seeds must be >= "),
    ],
)
def test_suite_refusals_name_the_flag(extra, message, capsys):
    rc = _run(["evaluate", "--suite", "real", "--policies", "column", *extra])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and "Traceback" not in err


def test_an_unknown_suite_is_refused_before_any_work(tmp_path: Path, capsys):
    out = tmp_path / "nothing"
    rc = _run(["evaluate", "--suite", "unreal", "--policies", "column", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "unknown suite 'unreal'; suites: ['families', 'grid', 'real']" in err
    assert not out.exists()
