"""coopnav study: descriptors, statistics and the written report."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from studies.learning_in_default_setting.learning_study import (
    EpisodeResult,
    behaviour_descriptors,
    summarise,
)


def test_descriptors_of_a_known_formation() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=3)
    env.reset(seed=0)
    city = env.unwrapped.world.city
    x = float(city.street_centres_x_m[1])
    y = float(city.street_centres_y_m[1])
    # three UAVs in a north-south column on a street, 10 m apart, the middle one on an
    # intersection centre, at 20 m; two steps
    col = np.array([[x, y - 10.0, 20.0], [x, y, 20.0], [x, y + 10.0, 20.0]])
    pos = np.stack([col, col])
    d = behaviour_descriptors(env, pos, np.array([7, 9]))
    assert d["spacing_m"] == pytest.approx(10.0)
    assert d["altitude_m"] == pytest.approx(20.0)
    assert d["cross_extent_m"] == pytest.approx(0.0)  # a column in one street
    assert d["near_open_share"] == pytest.approx(1.0)  # all within 10 m of the crossing
    assert d["swarm_sats"] == pytest.approx(8.0)
    far = pos.copy()
    far[:, :, 1] += 0.5 * (float(city.street_centres_y_m[2]) - y)  # mid-block
    assert behaviour_descriptors(env, far, np.array([7, 9]))["near_open_share"] < 1.0


def _episodes(errors, success) -> list[EpisodeResult]:
    return [
        EpisodeResult(
            seed=i,
            coop_error_mean_m=e,
            p_fix=1.0,
            success=s,
            collided=not s,
            length=10,
            descriptors={"altitude_m": 20.0},
        )
        for i, (e, s) in enumerate(zip(errors, success))
    ]


def test_summary_pairs_by_episode_and_flags_a_real_difference() -> None:
    rng = np.random.default_rng(0)
    base = rng.uniform(1.5, 4.0, 60)
    results = {
        "formation": [_episodes(base, [True] * 60)],
        "learned": [_episodes(base - 0.2 + rng.normal(0, 0.02, 60), [True] * 60) for _ in range(3)],
    }
    s = summarise(results, ["formation"], reps=400)
    p = s["paired"]["learned"]["formation"]
    assert p["excludes_zero"] and p["error_diff_m"]["high"] < 0
    assert p["error_diff_m"]["value"] == pytest.approx(-0.2, abs=0.02)
    m = s["methods"]["learned"]
    assert m["runs"] == 3 and len(m["per_run_error_mean"]) == 3
    assert m["goal_rate"]["value"] == 1.0
    assert math.isclose(m["descriptors"]["altitude_m"], 20.0)


def test_summary_ranks_by_the_chosen_score() -> None:
    rng = np.random.default_rng(1)
    base = rng.uniform(1.5, 4.0, 40)

    def eps(coop, nav):
        out = _episodes(coop, [True] * len(coop))
        for r, v in zip(out, nav):
            r.nav_error_mean_m = float(v)
        return out

    # "learned" is better in the nav score and worse in the coop score
    results = {
        "wide": [eps(base, base)],
        "learned": [eps(base + 0.3, base - 0.5)],
    }
    coop = summarise(results, ["wide"], reps=300)
    nav = summarise(results, ["wide"], reps=300, score="nav")
    assert coop["score"] == "coop" and nav["score"] == "nav" and nav["other_score"] == "coop"
    assert coop["paired"]["learned"]["wide"]["error_diff_m"]["value"] == pytest.approx(0.3)
    assert nav["paired"]["learned"]["wide"]["error_diff_m"]["value"] == pytest.approx(-0.5)
    assert nav["paired"]["learned"]["wide"]["other_error_diff_m"]["value"] == pytest.approx(0.3)
    assert nav["methods"]["learned"]["other_error_mean"]["value"] == pytest.approx(
        float(np.mean(base + 0.3))
    )
    with pytest.raises(ValueError, match="score must be one of"):
        summarise(results, ["wide"], reps=10, score="sigma")


def test_study_command_writes_its_report(tmp_path) -> None:
    from studies.learning_in_default_setting.learning_study import main

    out = tmp_path / "study"
    rc = main(
        [
            "--heuristics",
            "formation",
            "spread",
            "--episodes",
            "2",
            "--planner-episodes",
            "0",
            "--reps",
            "100",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    data = json.loads((out / "report.json").read_text())
    assert set(data["summary"]["methods"]) == {"formation", "spread"}
    assert "spread" in data["summary"]["paired"]["formation"] or data["summary"]["paired"]
    text = (out / "report.md").read_text()
    assert "| formation |" in text and "| spread |" in text
    assert (out / "errors.png").is_file() and (out / "trajectories.png").is_file()
    assert data["seeds"] == [1_000_000, 1_000_001]
    # a fresh set of episodes, ranked by the nav score
    out2 = tmp_path / "later"
    args = ["--heuristics", "formation", "--episodes", "2", "--planner-episodes", "0"]
    env_set = ["--env-set", "integrity_p_fa=1e-3"]  # YAML reads 1e-3 as a string
    assert (
        main([*args, *env_set, "--first-seed", "1000500", "--score", "nav", "--out", str(out2)])
        == 0
    )
    later = json.loads((out2 / "report.json").read_text())
    assert later["env"] == {"integrity_p_fa": 1e-3}
    assert later["seeds"] == [1_000_500, 1_000_501]
    assert later["summary"]["score"] == "nav"
    assert "(`--score nav`)" in (out2 / "report.md").read_text()


def test_runs_entries_are_checked(tmp_path) -> None:
    """``coopnav study --runs``: malformed entries, a name given twice and a folder without a
    model are errors that name the problem, raised before anything is flown."""
    import argparse

    from studies.learning_in_default_setting import learning_study as ls
    from studies.learning_in_default_setting.learning_study import parse_named_lists

    def study_main(argv):  # the script without its one-line error messages: the exceptions
        parser = argparse.ArgumentParser()
        ls.add_arguments(parser)
        return ls.run(parser.parse_args(argv))

    assert parse_named_lists(["m=a,b", "n=c"], "--x", "F") == {"m": ["a", "b"], "n": ["c"]}
    # a policy's own options stay with it; a bare name after them is the next entry
    assert parse_named_lists(
        ["g=ceiling@gain_per_s=0.3,cruise_speed_mps=10,wide", "h=torchrl:a,torchrl:b"], "--x", "F"
    ) == {
        "g": ["ceiling@gain_per_s=0.3,cruise_speed_mps=10", "wide"],
        "h": ["torchrl:a", "torchrl:b"],
    }
    run = tmp_path / "r0"
    run.mkdir()
    (run / "final_model.pt").write_bytes(b"")
    out = ["--out", str(tmp_path / "out")]
    with pytest.raises(ValueError, match=r"--runs entries are NAME=DIR\[,DIR\.\.\.\]"):
        study_main(["--runs", "m", *out])
    with pytest.raises(ValueError, match="--runs: the name 'm' is given twice"):
        study_main(["--runs", f"m={run}", f"m={run}", *out])
    with pytest.raises(ValueError, match=r"has none of final_model\.pt, final_model\.zip, route"):
        study_main(["--runs", f"m={tmp_path / 'missing'}", *out])
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--planner", "spread"], "--planner must"),
        (["--planner-episodes", "0", "--runs", "a=,"], "--runs a=, names nothing after"),
        (["--planner-episodes", "0", "--reps", "0"], "--reps must be >= 1, got 0"),
        (["--planner-episodes", "5"], "--planner-episodes 5 must be <= --episodes 1"),
        (
            ["--planner-episodes", "0", "--runs", "a={tmp}/listrun"],
            "listrun/run.json must hold a JSON object, got a list",
        ),
    ],
)
def test_bad_options_are_one_line_errors_before_flying(tmp_path, capsys, extra, message) -> None:
    """(Formerly ``coopnav study`` refusals; the last two once ended in an internal error
    after flying every episode.) Should one pass validation after all, the study flies one
    episode of one heuristic."""
    from studies.learning_in_default_setting.learning_study import main as study_main

    (tmp_path / "listrun").mkdir()
    (tmp_path / "listrun" / "final_model.zip").write_bytes(b"PK")
    (tmp_path / "listrun" / "run.json").write_text("[1, 2]\n")
    argv = ["--out", str(tmp_path / "study"), "--heuristics", "column", "--episodes", "1"]
    argv += [e.replace("{tmp}", str(tmp_path)) for e in extra]
    assert study_main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("learning_study.py: error: ") and message in err, err
    assert err.count("\n") == 1
