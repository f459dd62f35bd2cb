"""The privileged planner (studies.planner_headroom.planner): copies, not the real episode; the
base alone is a candidate."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import studies.planner_headroom.planner  # noqa: F401  (registers 'planner')
from coopnav_env import urban_canyon_v0
from coopnav_env.agents import make_policy
from tests.fly_alike import assert_fly_alike


def test_with_only_the_zero_candidate_the_planner_flies_its_base() -> None:
    # one candidate, one round: the offset is zero, so the command is the base's, and the
    # look-ahead in copies must not disturb the real episode (its generator included)
    assert_fly_alike(
        "planner@n_samples=1,n_elite=1,iterations=1,horizon=2",
        "wide_column",
        seed=1_000_001,
        steps=15,
    )
    assert_fly_alike(
        "planner@n_samples=1,n_elite=1,iterations=1,horizon=1,base='stretched_column'",
        "stretched_column",
        seed=1_000_001,
        steps=10,
    )


def test_the_planner_chooses_the_cheapest_candidate() -> None:
    env = urban_canyon_v0.parallel_env()
    obs, _ = env.reset(seed=1_000_002)
    planner = make_policy("planner@n_samples=6,n_elite=2,iterations=1,horizon=3", env)
    planner.reset(1_000_002)
    costs = []
    rng = np.random.default_rng(0)
    cands = [np.zeros((5, 3)), *(0.3 * rng.standard_normal((5, 5, 3)))]
    for c in cands:
        costs.append(planner._rollout(c, obs, 123))
    # the same candidate and noise seed give the same cost (common random numbers)
    assert planner._rollout(cands[1], obs, 123) == costs[1]
    assert len(set(costs)) > 1  # the candidates differ, so choosing can matter


@pytest.mark.parametrize("bad", ["horizon=0", "n_samples=2,n_elite=3", "offset_std=-1"])
def test_bad_planner_settings(bad) -> None:
    env = urban_canyon_v0.parallel_env()
    with pytest.raises(ValueError, match="planner"):
        make_policy(f"planner@{bad}", env)


def test_last_plan_describes_the_command_applied() -> None:
    env = urban_canyon_v0.parallel_env()
    obs, _ = env.reset(seed=1_000_003)
    planner = make_policy("planner@n_samples=4,n_elite=2,iterations=2,horizon=2", env)
    planner.reset(1_000_003)
    assert planner.last_plan == {}
    cmd = planner.act(obs)
    plan = planner.last_plan
    # the base alone is a candidate, so the plan applied is never dearer than it
    assert plan["best_cost"] <= plan["base_cost"] < np.inf
    assert plan["offsets"].shape == (len(env.possible_agents), 3)
    assert set(plan["base_command"]) == set(cmd)
    for i, a in enumerate(env.possible_agents):
        expect = np.clip(plan["base_command"][a] + plan["offsets"][i], -1.0, 1.0)
        np.testing.assert_allclose(cmd[a], expect, rtol=0, atol=1e-6)
    # every candidate scored, the base alone first, the plan applied the cheapest of them
    assert plan["candidates"].shape == (4 * 2, len(env.possible_agents), 3)
    assert plan["costs"].shape == (8,)
    assert np.all(plan["candidates"][0] == 0.0) and plan["costs"][0] == plan["base_cost"]
    best = int(np.argmin(plan["costs"]))
    assert plan["costs"][best] == plan["best_cost"]
    np.testing.assert_array_equal(plan["candidates"][best], plan["offsets"])


def _flown_off_the_truth() -> tuple[Any, dict[str, np.ndarray]]:
    """A default environment flown 5 steps (from reset seed 1,000,004): the estimates are off
    the truth; the environment and its last observations."""
    env = urban_canyon_v0.parallel_env()
    obs, _ = env.reset(seed=1_000_004)
    for _ in range(5):
        obs, *_ = env.step({a: np.zeros(3, dtype=np.float32) for a in env.agents})
    return env, obs


def test_the_on_board_planner_looks_ahead_from_the_estimate() -> None:
    # with the base as its only candidate it flies the base, like the privileged one
    assert_fly_alike(
        "planner@n_samples=1,n_elite=1,iterations=1,horizon=2,from_estimate=True",
        "wide_column",
        seed=1_000_001,
        steps=10,
    )
    env, obs = _flown_off_the_truth()
    world = env.unwrapped.world
    truth = world.pos_enu_m.copy()
    assert np.abs(world.nav_pos_enu_m - truth).max() > 0.0
    onboard = make_policy("planner@from_estimate=True,horizon=2", env)
    privileged = make_policy("planner@horizon=2", env)
    zero = np.zeros((len(env.possible_agents), 3))
    # the same noise and candidate, a different start (the belief): a different cost
    assert onboard._rollout(zero, obs, 7) != privileged._rollout(zero, obs, 7)
    np.testing.assert_array_equal(world.pos_enu_m, truth)  # the real world is untouched
    with pytest.raises(ValueError, match="from_estimate must be True or False"):
        make_policy("planner@from_estimate=1", env)


def test_the_belief_sampling_planner_starts_from_draws_of_the_receivers_belief() -> None:
    env, obs = _flown_off_the_truth()
    world = env.unwrapped.world
    truth = world.pos_enu_m.copy()
    belief = make_policy("planner@from_estimate=True,sample_belief=True,horizon=2", env)
    onboard = make_policy("planner@from_estimate=True,horizon=2", env)
    zero = np.zeros((len(env.possible_agents), 3))
    # reproducible for a noise seed, and not the look-ahead from the estimate itself
    assert belief._rollout(zero, obs, 7) == belief._rollout(zero, obs, 7)
    assert belief._rollout(zero, obs, 7) != onboard._rollout(zero, obs, 7)
    np.testing.assert_array_equal(world.pos_enu_m, truth)  # the real world is untouched
    # the draws follow N(estimate, P): mean and per-axis variance within 5 standard errors
    est = np.asarray(world.nav_pos_enu_m, dtype=float)
    rng = np.random.default_rng(3)
    n = 4000
    draws = np.stack([belief._belief_draw(est, world, rng) for _ in range(n)])
    var = np.einsum("nii->ni", np.asarray(world.nav_cov_enu_m2))
    inside = np.all(draws == est, axis=2).mean()
    assert inside < 0.01  # few draws fall back to the estimate (inside a building)
    dev = draws - est
    assert np.all(np.abs(dev.mean(axis=0)) <= 5.0 * np.sqrt(var / n))
    # the variance of n normal draws has a standard error of var * sqrt(2 / n)
    np.testing.assert_allclose(dev.var(axis=0), var, rtol=5.0 * np.sqrt(2.0 / n) + inside)
    with pytest.raises(ValueError, match="sample_belief=True needs from_estimate=True"):
        make_policy("planner@sample_belief=True", env)
    with pytest.raises(ValueError, match="sample_belief must be True or False"):
        make_policy("planner@from_estimate=True,sample_belief=1", env)


def test_guarded_offsets_never_point_at_a_near_wall() -> None:
    env, obs = _flown_off_the_truth()
    from coopnav_env.envs import obs_layout

    walls = obs_layout(env.unwrapped.config)["wall_distance"]
    guarded = make_policy(
        "planner@from_estimate=True,guard_offsets=True,base='ceiling_column',n_samples=3,iterations=1,"
        "horizon=2",
        env,
    )
    base = guarded.base
    n = len(env.possible_agents)
    live = list(obs)
    o = np.stack([obs[a] for a in live]).astype(np.float64)
    o[:, walls.slice] = 1.0
    o[0, walls.start + walls.size // 4] = 2.0 / walls.scale  # a wall 2 m East of UAV 0
    fake = {a: o[i].astype(np.float32) for i, a in enumerate(live)}
    offsets = np.tile([0.5, 0.0, 0.0], (n, 1))  # everyone pushed East
    applied = guarded._applied(base, offsets, fake, live)
    assert applied[0, 0] == pytest.approx(0.0, abs=1e-12)  # not toward the near wall
    np.testing.assert_array_equal(applied[1:], offsets[1:])  # the others keep theirs
    # the guarded look-ahead is a different plan from the unguarded one only where it acts
    plain = make_policy(
        "planner@from_estimate=True,base='ceiling_column',n_samples=3,horizon=2", env
    )
    np.testing.assert_array_equal(plain._applied(base, offsets, fake, live), offsets)
    cmd = guarded.act(obs)
    assert set(cmd) == set(obs)
    with pytest.raises(ValueError, match="guard_offsets must be True or False"):
        make_policy("planner@guard_offsets=1", env)
    with pytest.raises(ValueError, match="needs a base with a wall guard"):
        make_policy("planner@guard_offsets=True,base='wide_column'", env)


def test_the_return_objective_is_minus_the_swarms_mean_reward_over_the_horizon() -> None:
    import copy

    from coopnav_env import urban_canyon_v1

    env = urban_canyon_v1.parallel_env()
    obs, _ = env.reset(seed=1_000_004)
    planner = make_policy("planner@objective='return',horizon=3", env)
    planner.reset(1_000_004)
    offsets = np.zeros((len(env.possible_agents), 3))
    cost = planner._rollout(offsets, obs, 77)
    # the same look-ahead by hand: a copy with the noise seed, the base alone, rewards summed
    twin, base = copy.deepcopy((env, planner.base))
    twin._rng = np.random.default_rng(77)
    o, total = dict(obs), 0.0
    for _ in range(3):
        o, rewards, *_ = twin.step(base.act(o))
        total += float(np.mean(list(rewards.values())))
    assert total > 0.0  # the swarm covered route: v1 paid it
    assert cost == pytest.approx(-total, abs=1e-12)
    with pytest.raises(ValueError, match="objective"):
        make_policy("planner@objective='score'", env)
