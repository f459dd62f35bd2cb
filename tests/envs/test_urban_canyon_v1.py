"""``urban_canyon_v1``: the undiscounted return of an episode is its score."""

from __future__ import annotations

from types import SimpleNamespace

import gymnasium
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

from coopnav_env import GYM_ENV_ID_V1, urban_canyon_v0, urban_canyon_v1
from coopnav_env.agents import make_policy
from coopnav_env.envs.config import PER_STEP_REWARD_FIELDS, V1_DEFAULTS, UrbanCanyonConfig
from coopnav_env.envs.task import navigated_distance
from coopnav_env.envs.urban_canyon import REWARD_TERMS
from coopnav_env.sim.route import route_tail_lengths_m

HELDOUT = 1_000_000


def _fly(env, policy_name: str, seed: int) -> tuple[dict[str, float], list[dict]]:
    """Returns per UAV and the infos of every step."""
    policy = make_policy(policy_name, env)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    returns = dict.fromkeys(env.possible_agents, 0.0)
    steps = []
    while env.agents:
        obs, rewards, _, _, infos = env.step(policy.act(obs))
        for a, r in rewards.items():
            returns[a] += r
        steps.append(infos)
    return returns, steps


def test_v1_metadata_and_defaults() -> None:
    env = urban_canyon_v1.parallel_env()
    assert env.metadata["name"] == "urban_canyon_v1"
    assert urban_canyon_v0.parallel_env().metadata["name"] == "urban_canyon_v0"
    for key, value in V1_DEFAULTS.items():
        assert getattr(env.config, key) == value
    # fields and presets go on top of the v1 defaults
    env = urban_canyon_v1.parallel_env(preset="urban_nlos", goal_bonus=2.0, n_uavs=3)
    assert env.config.reward_scheme == "navigated_distance"
    assert env.config.integrity == "fde" and env.config.goal_bonus == 2.0


@pytest.mark.parametrize("name", PER_STEP_REWARD_FIELDS)
def test_per_step_weights_are_refused_with_navigated_distance(name: str) -> None:
    with pytest.raises(ValueError, match=f"{name} is a per-step reward weight"):
        urban_canyon_v1.parallel_env(**{name: 0.1})
    with pytest.raises(ValueError, match="nav_reward_weight is a per-step"):
        UrbanCanyonConfig(reward_scheme="navigated_distance")


def test_navigated_distance_needs_the_true_error() -> None:
    with pytest.raises(ValueError, match="nav_reward must be 'error'"):
        urban_canyon_v1.parallel_env(nav_reward="sigma")
    with pytest.raises(ValueError, match="reward_scheme"):
        urban_canyon_v1.parallel_env(reward_scheme="per_metre")


@pytest.mark.parametrize("policy_name", ["wide", "formation", "random"])
def test_return_equals_the_score_from_the_infos(policy_name: str) -> None:
    """Every UAV's return is its score, recomputed from the infos: each share of the route
    weighted by the quality of navigation there, plus goal and collision."""
    env = urban_canyon_v1.parallel_env()
    cap = env.config.nav_reward_cap_m
    for seed in (HELDOUT, HELDOUT + 1):
        returns, steps = _fly(env, policy_name, seed)
        for a, ret in returns.items():
            share = np.array([s[a]["reward_progress"] for s in steps])
            err = np.array([s[a]["nav_error_m"] for s in steps])
            quality = 1.0 - np.minimum(err, cap) / cap
            score = (share * quality).sum()
            score += sum(s[a]["reward_goal"] + s[a]["reward_collision"] for s in steps)
            assert ret == pytest.approx(score, abs=1e-12)
            assert np.all(share >= 0.0) and share.sum() <= 1.0 + 1e-12
            terms = sum(s[a][f"reward_{t}"] for s in steps for t in REWARD_TERMS)
            assert ret == pytest.approx(terms, abs=1e-12)
        if steps[-1]["uav_0"]["in_goal"] and not any(s["uav_0"]["collided"] for s in steps):
            # an arriving swarm is paid its whole route once, and the bonus
            for a in returns:
                assert sum(s[a]["reward_progress"] for s in steps) == pytest.approx(1.0, abs=1e-12)
                assert steps[-1][a]["reward_goal"] == env.config.goal_bonus


def _route_walk(env, step_m: float, error_m: float, back_and_forth: bool = False):
    """Fake epochs of UAVs that walk along the episode's route in steps of ``step_m``."""
    route = np.asarray(env.world.route_xy_m, dtype=float)
    tail = route_tail_lengths_m(route)
    seg = np.linalg.norm(np.diff(route, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    total = cum[-1]
    n = env.config.n_uavs

    def epoch(s: float) -> SimpleNamespace:
        k = int(np.clip(np.searchsorted(cum, s, side="right"), 1, len(route) - 1))
        xy = route[k - 1] + (route[k] - route[k - 1]) * (s - cum[k - 1]) / seg[k - 1]
        pos = np.zeros((n, 3))
        pos[:, :2] = xy
        return SimpleNamespace(
            pos_enu_m=pos,
            next_waypoint=np.full(n, k),
            nav_error_m=np.full(n, error_m),
        )

    route_m = np.full(n, total)
    unpaid_m = np.full(n, total)
    assert tail[0] == pytest.approx(total)
    cap = env.config.nav_reward_cap_m
    s_values = list(np.arange(step_m, total - 1.0, step_m))
    if back_and_forth:  # forward 2 steps, back 1, ...
        walk = []
        for i, s in enumerate(s_values):
            walk.append(s)
            if i % 2:
                walk.append(max(s - 1.5 * step_m, 0.0))
        s_values = walk
    paid = np.zeros(n)
    for s in s_values:
        nav, progress, unpaid_m = navigated_distance(
            route, tail, epoch(s), unpaid_m, route_m, False, cap
        )
        paid += nav + progress
    nav, progress, _ = navigated_distance(
        route, tail, epoch(total - 1.0), unpaid_m, route_m, True, cap
    )
    return paid + nav + progress


@pytest.mark.parametrize("step_m", [0.7, 3.0, 9.5])
def test_the_score_does_not_pay_for_speed(step_m: float) -> None:
    """The same route at any speed (step length), at a constant error, scores ``q(e)``."""
    env = urban_canyon_v1.parallel_env()
    env.reset(seed=HELDOUT)
    for error_m in (0.0, 2.5, 40.0):
        q = 1.0 - min(error_m, 10.0) / 10.0
        np.testing.assert_allclose(_route_walk(env, step_m, error_m), q, atol=1e-12)
        # flying back and forth earns nothing more
        np.testing.assert_allclose(_route_walk(env, step_m, error_m, True), q, atol=1e-12)


def test_v1_flies_as_v0() -> None:
    """The reward does not change the flight: the same seed, the same observations."""
    e0, e1 = urban_canyon_v0.parallel_env(), urban_canyon_v1.parallel_env()
    p0, p1 = make_policy("sky", e0), make_policy("sky", e1)
    o0, _ = e0.reset(seed=7)
    o1, _ = e1.reset(seed=7)
    p0.reset(seed=7)
    p1.reset(seed=7)
    while e0.agents:
        for a in o0:
            np.testing.assert_array_equal(o0[a], o1[a])
        o0, *_ = e0.step(p0.act(o0))
        o1, *_ = e1.step(p1.act(o1))
    assert not e1.agents


def test_v1_passes_pettingzoo_and_gymnasium_checks() -> None:
    parallel_api_test(urban_canyon_v1.parallel_env(n_uavs=3, max_steps=30), num_cycles=40)
    parallel_seed_test(lambda: urban_canyon_v1.parallel_env(n_uavs=3, max_steps=20))
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(GYM_ENV_ID_V1, n_uavs=3, max_steps=20)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.unwrapped.par_env.metadata["name"] == "urban_canyon_v1"


def test_v1_same_seed_same_episode() -> None:
    a, b = urban_canyon_v1.parallel_env(), urban_canyon_v1.parallel_env()
    ra, sa = _fly(a, "wide", 11)
    rb, sb = _fly(b, "wide", 11)
    assert ra == rb and sa == sb


def test_compiled_and_numpy_rewards_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.envs import oracles

    ra, sa = _fly(urban_canyon_v1.parallel_env(), "sky", 5)
    calls = oracles.use_oracles_in_env(monkeypatch)
    rb, sb = _fly(urban_canyon_v1.parallel_env(), "sky", 5)
    assert calls["reward_terms"] > 0
    assert ra == pytest.approx(rb, abs=1e-12)
    for x, y in zip(sa, sb):
        for a in x:
            for t in REWARD_TERMS:
                assert x[a][f"reward_{t}"] == pytest.approx(y[a][f"reward_{t}"], abs=1e-12)
