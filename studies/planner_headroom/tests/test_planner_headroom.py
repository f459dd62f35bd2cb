"""planner_headroom.py: the planner's episodes kept step by step, the analysis."""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.planner_headroom import planner_headroom


def _module():
    return planner_headroom


def test_ridge_r2_finds_a_linear_rule_and_not_noise() -> None:
    mod = _module()
    rng = np.random.default_rng(0)
    x = rng.standard_normal((2000, 6))
    groups = np.repeat(np.arange(40), 50)
    y_rule = np.c_[x[:, 0] - 0.5 * x[:, 3], 0.2 * x[:, 1]] + 0.01 * rng.standard_normal((2000, 2))
    assert np.all(mod.ridge_r2(x, y_rule, groups) > 0.99)
    y_noise = rng.standard_normal((2000, 2))
    # out of sample, noise cannot be explained: R^2 near 0 (slightly below, by overfitting);
    # 2000 samples, 7 coefficients: |R^2| well under 0.02
    r2 = mod.ridge_r2(x, y_noise, groups)
    assert np.all(np.abs(r2) < 0.02)
    # weights select the samples the fit must explain: a rule that holds only where the
    # weight is non-zero is found with the weights, not without them
    w = (np.arange(2000) % 2 == 0).astype(float)
    y_half = np.where(w[:, None] > 0, y_rule, y_noise)
    assert np.all(mod.ridge_r2(x, y_half, groups, w) > 0.99)
    assert np.all(mod.ridge_r2(x, y_half, groups) < 0.9)


def test_the_lookahead_model_learns_a_rule_of_the_candidates_and_not_noise() -> None:
    mod = _module()
    rng = np.random.default_rng(1)

    def episodes(rule: bool, count: int = 20) -> list:
        out = []
        for _ in range(count):
            steps, n_c, n = 30, 4, 3
            obs = rng.standard_normal((steps, n, 5))
            base = rng.standard_normal((steps, n, 3))
            cands = 0.3 * rng.standard_normal((steps, n_c, n, 3))
            cands[:, 0] = 0.0
            if rule:  # a look-ahead that pays 5 m per unit of East offset of UAV 0
                costs = 5.0 * cands[:, :, 0, 0] + 0.01 * rng.standard_normal((steps, n_c))
            else:  # costs that no input predicts
                costs = rng.standard_normal((steps, n_c))
            costs[:, 0] = 0.0 if rule else costs[:, 0]
            out.append((obs, base, cands, costs))
        return out

    r = mod.lookahead_model(episodes(True))
    assert r["lookahead_model_samples"] == 20 * 30 * 3
    assert r["lookahead_model_r2"] > 0.99
    # choosing by the model is (nearly) the look-ahead's own choice, well below a random one
    assert r["lookahead_model_choice_cost_m"] == pytest.approx(
        r["lookahead_own_choice_cost_m"], abs=0.05
    )
    assert r["lookahead_model_choice_cost_m"] < r["lookahead_random_choice_cost_m"] - 0.5
    noise = mod.lookahead_model(episodes(False, 60))
    # out of sample, noise is not explained: R^2 near 0, below it by overfitting, which for
    # p = 34 coefficients and n = 5400 samples is of the order of 2 p / n (0.013); allow 4 p / n
    n_s, p_c = noise["lookahead_model_samples"], 5 * 3 + 3 * 3 + 3 * 3 + 1
    assert n_s == 60 * 30 * 3 and abs(noise["lookahead_model_r2"]) < 4 * p_c / n_s
    assert mod.lookahead_model(episodes(True)[:1]) == {}  # one episode: nothing to hold out


def test_outage_edges_counts_outages_and_the_errors_around_them() -> None:
    mod = _module()
    nan = np.nan
    # UAV 0: fix, fix, [out, out], fix, [out] (still flying at the end: no fix after it);
    # UAV 1: no fix at the start (not an outage), then fixes; stops flying after step 4.
    nav = np.array([[1.0, 9.0], [2.0, 3.0], [5.0, 3.0], [7.0, 4.0], [4.0, nan], [8.0, nan]])
    fix = np.array([[1, 0], [1, 1], [0, 1], [0, 1], [1, 0], [0, 0]], dtype=bool)
    alive = np.array([[1, 1], [1, 1], [1, 1], [1, 1], [1, 0], [1, 0]], dtype=bool)
    r = mod.outage_edges([(nav, fix, alive)])
    assert r["outages_per_episode"] == 2.0
    assert r["mean_length_steps"] == 1.5  # 2 steps and 1 step
    assert r["last_fix_before_m"] == pytest.approx((2.0 + 4.0) / 2)
    assert r["first_outage_step_m"] == pytest.approx((5.0 + 8.0) / 2)
    assert r["last_outage_step_m"] == pytest.approx((7.0 + 8.0) / 2)
    assert r["first_fix_after_m"] == pytest.approx(4.0)  # only the first outage ends
    assert r["all_fix_steps_m"] == pytest.approx(np.mean([1.0, 2.0, 4.0, 3.0, 3.0, 4.0]))
    # two episodes: outages are counted per episode
    assert mod.outage_edges([(nav, fix, alive)] * 2)["outages_per_episode"] == 2.0
    # no outage at all: NaN figures, not an error
    r0 = mod.outage_edges([(nav[:2, :1], np.ones((2, 1), bool), np.ones((2, 1), bool))])
    assert r0["outages_per_episode"] == 0.0 and np.isnan(r0["last_fix_before_m"])


def test_planner_headroom_script_runs_resumes_and_refuses_other_settings(tmp_path, capsys) -> None:
    mod = _module()
    out = tmp_path / "h"
    env = ["--env-set", "n_uavs=3", "max_steps=4"]
    args = ["--episodes", "2", "--first-seed", "1000000", "--jobs", "1", "--base", "wide_column"]
    assert mod.main([*args, *env, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "nav error planner" in text and "R^2" in text and "goal rate: planner" in text
    r = json.loads((out / "report.json").read_text())
    assert r["episodes"] == 2
    pm, lo, hi = r["paired_m"]
    assert lo <= pm <= hi
    assert pm == pytest.approx(r["planner_nav_m"] - r["base_nav_m"], abs=1e-9)
    assert 0.0 <= r["planner_goal_rate"] <= 1.0 and 0.0 <= r["base_goal_rate"] <= 1.0
    ep = np.load(out / "1000000.npz")
    steps, n = ep["alive"].shape
    assert 1 <= steps <= 4 and n == 3
    assert ep["obs"].shape[:2] == (steps, 3) and ep["offset"].shape == (steps, 3, 3)
    assert np.all(ep["cost_best"] <= ep["cost_base"])
    # every candidate scored, with its cost: the default planner scores 8 x 2 per step, the
    # first the base alone (offset zero, cost_base), the cheapest the plan applied
    cands, costs = ep["candidates"], ep["candidate_costs"]
    assert cands.shape == (steps, 16, 3, 3) and costs.shape == (steps, 16)
    assert not cands[:, 0].any()
    np.testing.assert_array_equal(costs[:, 0], ep["cost_base"])
    np.testing.assert_array_equal(costs.min(axis=1), ep["cost_best"])
    assert r["lookahead_model_samples"] == 15 * sum(
        np.load(out / f"{s}.npz")["candidate_costs"].shape[0] for s in (1000000, 1000001)
    )
    assert "a model of the look-ahead" in text
    base = np.load(out / "1000000_base.npz")
    assert base["fix"].shape == base["alive"].shape == base["nav"].shape
    assert base["alive"].shape[1] == 3
    for who in ("planner", "base"):
        share = r[who]["no_fix_swarm_wide_share"]
        assert np.isnan(share) or 0.0 <= share <= 1.0
    # a second run flies nothing again: the episode files are kept as they are
    before = {p.name: p.stat().st_mtime_ns for p in out.glob("*.npz")}
    assert mod.main([*args, *env, "--out", str(out)]) == 0
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.npz")} == before
    with pytest.raises(SystemExit, match="other settings"):
        mod.main([*args, "--env-set", "n_uavs=4", "max_steps=4", "--out", str(out)])
    with pytest.raises(SystemExit, match="--planner-set takes KEY=VALUE"):
        mod.main([*args, *env, "--planner-set", "from_estimate", "--out", str(tmp_path / "x")])
    with pytest.raises(SystemExit, match="--episodes must be >= 2"):
        mod.main(["--episodes", "1", "--out", str(out)])


def test_a_planner_that_only_has_its_base_is_recorded_as_its_base(tmp_path) -> None:
    # with the base as its only candidate the planner flies the base, so the two recordings
    # (the planner's from its infos, the base's from run_episode) must agree step by step
    mod = _module()
    out = tmp_path / "same"
    args = ["--episodes", "2", "--first-seed", "1000010", "--jobs", "1", "--base", "wide_column"]
    env = ["--env-set", "n_uavs=3"]  # whole episodes: both reach the goal
    one = ["--planner-set", "n_samples=1", "n_elite=1", "iterations=1", "horizon=1"]
    assert mod.main([*args, *env, *one, "--out", str(out)]) == 0
    for seed in (1000010, 1000011):
        p, b = np.load(out / f"{seed}.npz"), np.load(out / f"{seed}_base.npz")
        np.testing.assert_array_equal(p["alive"], b["alive"])
        np.testing.assert_array_equal(p["fix"][p["alive"]], b["fix"][b["alive"]])
        np.testing.assert_array_equal(p["nav"][p["alive"]], b["nav"][b["alive"]])
        assert not p["offset"].any()
        assert p["success"].shape == b["success"].shape == ()
        assert bool(p["success"]) == bool(b["success"])  # the same goal, the same way
    r = json.loads((out / "report.json").read_text())
    assert r["paired_m"] == [0.0, 0.0, 0.0]
    assert r["planner_goal_rate"] == r["base_goal_rate"] == 1.0
    assert r["both_finished_episodes"] == 2 and r["paired_both_finished_m"] == [0.0, 0.0, 0.0]
    # no offsets, so nothing to explain: R^2 is undefined (NaN), not a number made up
    assert np.all(np.isnan(r["r2_unweighted"])) and np.all(np.isnan(r["r2_gain_weighted"]))


def test_goal_rates_and_the_comparison_on_the_episodes_both_finish(tmp_path) -> None:
    mod = _module()
    rng = np.random.default_rng(0)
    steps, n = 6, 2
    # planner error 1 m lower everywhere, but it fails episode 2; the base fails episode 3
    outcomes = {10: (True, True), 11: (True, True), 12: (False, True), 13: (True, False)}
    for seed, (p_ok, b_ok) in outcomes.items():
        nav_b = np.full((steps, n), 3.0 + seed % 10)
        alive = np.ones((steps, n), dtype=bool)
        fix = np.ones((steps, n), dtype=bool)
        np.savez(
            tmp_path / f"{seed}.npz",
            obs=rng.standard_normal((steps, n, 4)),
            base=rng.standard_normal((steps, n, 3)),
            offset=rng.standard_normal((steps, n, 3)),
            fix=fix,
            nav=nav_b - 1.0,
            alive=alive,
            cost_base=np.ones(steps),
            cost_best=np.zeros(steps),
            success=np.asarray(p_ok),
        )
        np.savez(
            tmp_path / f"{seed}_base.npz", nav=nav_b, fix=fix, alive=alive, success=np.asarray(b_ok)
        )
    r = mod.analyse(tmp_path, list(outcomes))
    assert r["planner_goal_rate"] == 0.75 and r["base_goal_rate"] == 0.75
    assert r["both_finished_episodes"] == 2
    assert r["paired_both_finished_m"] == pytest.approx([-1.0, -1.0, -1.0])
    assert "goal rate: planner 0.750" in "\n".join(mod.report_lines(r, "wide_column"))
    # episode files without the flag (older runs): no goal rates, rather than made-up ones
    np.savez(
        tmp_path / "14.npz",
        **{k: v for k, v in np.load(tmp_path / "10.npz").items() if k != "success"},
    )
    np.savez(tmp_path / "14_base.npz", **dict(np.load(tmp_path / "10_base.npz")))
    r_old = mod.analyse(tmp_path, [*outcomes, 14])
    assert "planner_goal_rate" not in r_old and "paired_both_finished_m" not in r_old
