"""compare_learned.py: per-policy and per-method scores, spacing and the gap closed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env.training.alignment import fly as fly_scores
from studies.task_objective import compare_learned as cl


def test_compare_writes_the_report_and_its_figures_are_consistent(tmp_path) -> None:
    out = tmp_path / "cmp"
    args = [
        "--methods",
        "m=sky_column,wide_column@spacing_m=30",
        "--heuristics",
        "column",
        "wide_column",
    ]
    args += ["--episodes", "2", "--reps", "50", "--out", str(out)]
    assert cl.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    rows = {r["name"]: r for r in report["rows"]}
    assert set(rows) == {"column", "wide_column", "m", "sky_column", "wide_column@spacing_m=30"}
    # a policy's score is its mean v1 return; a method's is the mean of its seeds'
    ref = [
        e.episode_return
        for e in fly_scores("sky_column", "urban_canyon_v1", [1_000_100, 1_000_101])
    ]
    assert rows["sky_column"]["score"][0] == pytest.approx(np.mean(ref), abs=1e-12)
    method = np.mean([rows["sky_column"]["score"][0], rows["wide_column@spacing_m=30"]["score"][0]])
    assert rows["m"]["score"][0] == pytest.approx(method, abs=1e-12)
    # the reference closes the whole gap, the baseline none of it
    assert rows["wide_column"]["gap_closed"][0] == pytest.approx(1.0)
    assert rows["column"]["gap_closed"][0] == pytest.approx(0.0)
    # the wide column flies farther apart during the cruise than the formation
    assert rows["wide_column"]["cruise_spacing_m"] > 2 * rows["column"]["cruise_spacing_m"]
    assert "gap closed" in (out / "report.md").read_text()
    # one method: no difference between methods to report
    assert report["between_methods"] == []
    with pytest.raises(SystemExit):  # an existing report needs --overwrite
        cl.main(args)


def test_bad_methods_are_refused(tmp_path) -> None:
    with pytest.raises(SystemExit):
        cl.main(["--methods", "m=", "--out", str(tmp_path / "x")])


def test_a_trained_policy_is_flown_in_its_runs_settings_and_others_are_refused(tmp_path) -> None:
    def run(env_id: str, env: str) -> str:
        folder = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
        folder.mkdir()
        (folder / "config.yaml").write_text(f"env_id: {env_id}\nenv: {env}\n")
        return f"mappo:{folder}"

    neutral = "{reward_scheme: navigated_distance, nav_team_weight: 1.0, obs_agent_index: true}"
    assert cl.env_settings_of(run("urban_canyon_v1", neutral)) == {
        "reward_scheme": "navigated_distance",
        "nav_team_weight": 1.0,
        "obs_agent_index": True,
    }
    assert cl.env_settings_of("wide_column") == {}
    with pytest.raises(ValueError, match=r"\['collision_penalty'\]"):
        cl.env_settings_of(run("urban_canyon_v1", "{collision_penalty: 5.0}"))
    with pytest.raises(ValueError, match="urban_canyon_v0"):
        cl.env_settings_of(run("urban_canyon_v0", "{}"))


def test_methods_are_compared_pairwise_on_the_same_episodes(tmp_path) -> None:
    out = tmp_path / "pairs"
    args = ["--methods", "a=sky_column", "b=wide_column", "--heuristics", "column", "wide_column"]
    args += ["--episodes", "2", "--reps", "50", "--out", str(out)]
    assert cl.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    (d,) = report["between_methods"]
    assert (d["a"], d["b"]) == ("a", "b")
    eps = report["episodes_per_policy"]
    want = np.mean([x["score"] - y["score"] for x, y in zip(eps["sky_column"], eps["wide_column"])])
    assert d["score_a_minus_b"][0] == pytest.approx(want, abs=1e-12)
    assert "`a` - `b`" in (out / "report.md").read_text()


@pytest.mark.parametrize("policy", ["formation", "mappo:pretrained/route_s0"])
def test_coopnav_evaluate_gives_this_scripts_spacing_and_score(policy) -> None:
    """The cruise spacing and score of ``coopnav evaluate``
    (:mod:`coopnav_env.training.evaluate`) are this script's, episode by episode, to the bit
    (torch on one thread in both)."""
    pytest.importorskip("torch")
    from coopnav_env.training.evaluate import cruise_spacing_m, evaluate

    seeds = [1_000_100, 1_000_101]
    want = cl.fly(policy, seeds)
    with cl.one_torch_thread():
        report = evaluate(
            [policy], seeds, cl.env_settings_of(policy), env_id="urban_canyon_v1", plots=False
        )
    for got, w in zip(report.episodes[policy], want):
        assert cruise_spacing_m(got.pos_enu_m) == w["cruise_spacing_m"]
        assert got.episode_return == w["score"] and float(got.length) == w["steps"]
    assert report[policy].cruise_spacing_m == pytest.approx(
        np.mean([w["cruise_spacing_m"] for w in want]), rel=1e-12
    )


def test_coopnav_evaluates_intervals_are_this_scripts() -> None:
    """The gap closed and the score interval of ``coopnav evaluate``'s gap table
    (:func:`coopnav_env.training.stats.gap_closed`,
    :func:`~coopnav_env.training.stats.bootstrap_mean_interval`) are this script's."""
    from coopnav_env.training.stats import bootstrap_mean_interval, gap_closed

    rng = np.random.default_rng(5)
    base, ref = rng.normal(1.45, 0.2, 60), rng.normal(1.8, 0.02, 60)
    runs = rng.normal(1.75, 0.05, (3, 60))
    got = gap_closed(runs, base, ref, reps=400)
    assert [got.value, got.low, got.high] == cl._gap_closed(runs.mean(axis=0), base, ref, 400)
    mean = bootstrap_mean_interval(runs.mean(axis=0), 400, np.random.default_rng(0))
    assert list(mean) == cl._mean_ci(runs.mean(axis=0), 400)
