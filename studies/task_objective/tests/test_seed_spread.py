"""seed_spread.py: a policy's open gap splits into failed and completed episodes exactly."""

from __future__ import annotations

import json

import pytest

from studies.task_objective import seed_spread as ss


def _episode(score: float, goal: float, nav: float = 2.0, alt: float = 30.0) -> dict[str, float]:
    return {
        "score": score,
        "goal": goal,
        "nav_error_m": nav,
        "steps": 90.0,
        "cruise_spacing_m": 20.0,
        "cruise_altitude_m": alt,
    }


def _report() -> dict:
    """Four episodes: the baseline scores 1, the reference 2; a learned policy fails the
    first episode (0.5) and completes the others at 1.5 / 2.0 / 2.0."""
    return {
        "baseline": "column",
        "reference": "wide",
        "episodes_per_policy": {
            "column": [_episode(1.0, 1.0) for _ in range(4)],
            "wide": [_episode(2.0, 1.0, nav=1.5) for _ in range(4)],
            "mappo:p/a": [
                _episode(0.5, 0.0, nav=9.0),
                _episode(1.5, 1.0, nav=3.0, alt=20.0),
                _episode(2.0, 1.0, nav=2.0, alt=20.0),
                _episode(2.0, 1.0, nav=1.0, alt=20.0),
            ],
        },
    }


def test_the_open_gap_is_what_failed_and_completed_episodes_lose():
    (row,) = ss.split_gap(_report())  # the heuristics get no row
    assert row["policy"] == "mappo:p/a" and row["failed"] == 1
    assert row["closed"] == pytest.approx((6.0 / 4 - 1.0) / 1.0)
    assert row["lost_on_failed"] == pytest.approx(1.5 / 4)
    assert row["lost_on_completed"] == pytest.approx(0.5 / 4)
    assert row["closed"] + row["lost_on_failed"] + row["lost_on_completed"] == pytest.approx(1.0)
    # figures over the completed episodes only, the reference's on the same ones
    assert row["nav_error_m"] == pytest.approx(2.0) and row["reference_nav_error_m"] == 1.5
    assert row["cruise_altitude_m"] == pytest.approx(20.0)


def test_a_report_without_episodes_or_gap_is_refused():
    bare = {k: v for k, v in _report().items() if k != "episodes_per_policy"}
    with pytest.raises(ValueError, match="per-episode"):
        ss.split_gap(bare)
    flat = _report()
    flat["reference"] = "column"
    with pytest.raises(ValueError, match="gap must be positive"):
        ss.split_gap(flat)


def test_main_writes_one_table_per_report(tmp_path):
    paths = []
    for name in ("one", "two"):
        p = tmp_path / f"{name}.json"
        p.write_text(json.dumps(_report()))
        paths.append(str(p))
    assert ss.main(["--report", *paths, "--out", str(tmp_path / "out")]) == 0
    text = (tmp_path / "out" / "report.md").read_text()
    assert text.count("| a | 0.500 | 1 | 0.375 | 0.125 |") == 2
    saved = json.loads((tmp_path / "out" / "report.json").read_text())
    assert [s["source"] for s in saved["reports"]] == paths
    with pytest.raises(SystemExit):
        ss.main(["--report", str(tmp_path / "missing.json"), "--out", str(tmp_path / "x")])
