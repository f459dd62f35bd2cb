"""retune_heuristics.py: scores, the re-tuning grid and the confirmation on fresh episodes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env.training.alignment import fly
from studies.task_objective import retune_heuristics as rt


def test_retune_writes_both_tables_and_scores_are_the_mean_return(tmp_path, capsys):
    out = tmp_path / "report"
    args = ["--episodes", "2", "--seed-start", "1000000", "--out", str(out), "--no-progress"]
    grid = ["--spacings", "45", "--speeds", "7", "--ceiling-margins", "0.5", "-10"]
    assert rt.main([*args, "--policies", "column", "wide_column", "waypoint", *grid]) == 0
    report = json.loads((out / "report.json").read_text())
    assert (out / "report.md").read_text().startswith("# Heuristics on urban_canyon_v1")
    assert "Best heuristic re-tuned on v1" in capsys.readouterr().out

    assert report["tuning_seeds"] == [1_000_000, 1_000_001]
    assert report["confirmation_seeds"] == [1_000_002, 1_000_003]
    # the grid: two settings over the best named column; the one equal to its preset reuses it
    assert report["best_named_column"] in ("column", "wide_column")
    settings = report["grid"]["settings"]
    assert len(settings) == 2
    if report["best_named_column"] == "wide_column":
        assert sorted(str(s["same_as"]) for s in settings) == ["None", "wide_column"]
    tuning = {r["policy"]: r for r in report["tuning"]}
    assert {"column", "wide_column", "waypoint"} <= set(tuning)
    assert len(tuning) == 3 + sum(s["same_as"] is None for s in settings)
    scores = [r["score"] for r in report["tuning"]]
    assert scores == sorted(scores, reverse=True)
    assert report["best_on_tuning"] == report["tuning"][0]["policy"]
    assert report["best_retuned"] in tuning
    assert max(s["score"] for s in settings) == pytest.approx(
        tuning[report["best_retuned"]]["score"]
    )
    for row in report["tuning"]:
        lo, hi = row["score_ci95"]
        assert lo <= row["score"] <= hi
        assert 0.0 <= row["goal_rate"] <= 1.0 and 0.0 <= row["collision_rate"] <= 1.0
        assert row["steps"] > 0 and row["nav_error_m"] > 0
    assert tuning[report["best_on_tuning"]]["vs_reference"] == {
        "value": 0.0,
        "low": 0.0,
        "high": 0.0,
    }
    # the confirmation flies the chosen setting, wide and formation on the next seeds
    confirm = {r["policy"]: r for r in report["confirmation"]}
    assert {report["best_retuned"], "wide_column", "column"} == set(confirm)

    # the score is the mean undiscounted return of alignment.fly on the same seeds
    expected = np.mean(
        [e.episode_return for e in fly("waypoint", "urban_canyon_v1", [1_000_000, 1_000_001])]
    )
    assert tuning["waypoint"]["score"] == pytest.approx(expected, rel=1e-12)
    expected = [
        e.episode_return for e in fly("wide_column", "urban_canyon_v1", [1_000_002, 1_000_003])
    ]
    assert report["per_episode"]["confirmation"]["wide_column"]["score"] == pytest.approx(expected)
    assert confirm["wide_column"]["score"] == pytest.approx(np.mean(expected))

    # an existing report is not overwritten without --overwrite
    with pytest.raises(SystemExit):
        rt.main([*args, "--policies", "wide_column", *grid])
    assert "overwrite" in capsys.readouterr().err


def test_retune_refuses_bad_input():
    with pytest.raises(ValueError, match="episodes must be >= 2, got 1"):
        rt.retune(1, 1_000_000, progress=False)
    with pytest.raises(ValueError, match="no column heuristic"):
        rt.retune(2, 1_000_000, policies=["waypoint"], progress=False)
    with pytest.raises(ValueError, match="at least one spacing"):
        rt.grid_names("wide_column", [], [7.0], [0.5])


def test_effective_setting_matches_a_preset_and_its_explicit_options():
    assert rt.effective_setting("wide_column") == ("wide_column", 45.0, 7.0, 0.5)
    assert rt.effective_setting(
        "wide_column@spacing_m=45,cruise_speed_mps=7,ceiling_margin_m=0.5"
    ) == rt.effective_setting("wide_column")
    assert rt.effective_setting("ceiling_column")[3] == -10.0
    assert rt.effective_setting("waypoint@altitude_m=28") is None
    assert rt.effective_setting("wide_column@route_index=1") is None
