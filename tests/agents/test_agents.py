"""Policies: the registry, valid actions, seeding, route planning, and reaching the goal."""

from __future__ import annotations

import importlib.util
import itertools

import numpy as np
import pytest

from agents import POLICY_NAMES, Policy, make_policy
from agents.heuristics import Polyline, street_route
from tests.training.toy_env import ToyParallelEnv

HAS_ENV = importlib.util.find_spec("coopnav_env.urban_canyon_v0") is not None
needs_env = pytest.mark.skipif(not HAS_ENV, reason="coopnav_env.urban_canyon_v0 not available")


def urban(**kw):
    from coopnav_env import urban_canyon_v0

    return urban_canyon_v0.parallel_env(**kw)


def fly(env, policy, seed: int, max_steps: int = 10_000):
    """Run one episode; return (final infos, every action taken)."""
    obs, infos = env.reset(seed=seed)
    policy.reset(seed=seed)
    actions = []
    steps = 0
    while env.agents and steps < max_steps:
        act = policy.act(obs)
        actions.append(act)
        obs, _r, _te, _tr, infos = env.step(act)
        steps += 1
    return infos, actions


def assert_valid(env, actions):
    for act in actions:
        assert set(act) <= set(env.possible_agents)
        for agent, a in act.items():
            assert isinstance(a, np.ndarray) and a.dtype == np.float32 and a.shape == (3,)
            assert env.action_space(agent).contains(a), a


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------


def test_unknown_name_lists_valid_ones():
    env = ToyParallelEnv()
    with pytest.raises(ValueError, match="unknown policy 'greedy'") as exc:
        make_policy("greedy", env)
    for name in POLICY_NAMES:
        assert name in str(exc.value)
    with pytest.raises(ValueError, match="needs the path"):
        make_policy("ppo:", env)


def test_missing_checkpoint_names_the_path(tmp_path):
    missing = tmp_path / "nowhere" / "final_model.zip"
    with pytest.raises(FileNotFoundError, match="nowhere"):
        make_policy(f"ppo:{missing}", ToyParallelEnv())


def test_heuristics_need_the_urban_env():
    with pytest.raises(ValueError, match="urban_canyon_v0"):
        make_policy("formation", ToyParallelEnv())


def test_random_policy_is_seeded_and_valid():
    env = ToyParallelEnv(n_uavs=3, max_steps=15)
    pol = make_policy("random", env)
    assert isinstance(pol, Policy) and pol.name == "random"
    _, a1 = fly(env, pol, seed=4)
    _, a2 = fly(env, pol, seed=4)
    _, a3 = fly(env, pol, seed=5)
    assert_valid(env, a1)
    assert all(np.array_equal(x[k], y[k]) for x, y in zip(a1, a2) for k in x)
    assert not all(np.array_equal(x[k], y[k]) for x, y in zip(a1, a3) for k in x)


# --------------------------------------------------------------------------------------------
# route planning
# --------------------------------------------------------------------------------------------


class _Grid:
    street_centres_x_m = np.array([-100.0, 0.0, 100.0])
    street_centres_y_m = np.array([-100.0, 0.0, 100.0])


def _on_streets(route: np.ndarray) -> bool:
    xs, ys = _Grid.street_centres_x_m, _Grid.street_centres_y_m
    for p, q in itertools.pairwise(route):
        if np.isclose(p[0], q[0]):  # north-south leg
            if not np.isclose(np.abs(xs - p[0]).min(), 0.0):
                return False
        elif np.isclose(p[1], q[1]):  # east-west leg
            if not np.isclose(np.abs(ys - p[1]).min(), 0.0):
                return False
        else:
            return False
    return True


@pytest.mark.parametrize(
    ("start", "goal", "length"),
    [
        ((0.0, -80.0), (0.0, 60.0), 140.0),  # same street
        ((1.0, -80.0), (60.0, 100.0), 180.0 + 60.0),  # NS then EW
        ((-100.0, -70.0), (100.0, -40.0), 30.0 + 200.0 + 60.0),  # NS - EW - NS, best cross st.
        ((-70.0, 99.0), (30.0, -100.0), 70.0 + 200.0 + 30.0),  # EW - NS - EW
        ((50.0, 0.0), (-100.0, 50.0), 150.0 + 50.0),  # EW then NS
    ],
)
def test_street_route_is_on_streets_and_shortest(start, goal, length):
    route = street_route(_Grid, np.array(start), np.array(goal))
    assert _on_streets(route)
    assert route.shape[0] <= 4
    line = Polyline(route)
    assert line.length == pytest.approx(length)


def test_polyline_projection_respects_window():
    line = Polyline(np.array([[0.0, 0.0], [0.0, 100.0], [100.0, 100.0]]))
    p = np.array([[5.0, 95.0]])  # near both legs around the corner
    assert line.project(p, np.array([0.0]), np.array([90.0]))[0] == pytest.approx(90.0)
    assert line.project(p, np.array([100.0]), np.array([200.0]))[0] == pytest.approx(105.0)
    np.testing.assert_allclose(line.point(np.array([150.0])), [[50.0, 100.0]])
    assert line.distance_to_corner(np.array([30.0]))[0] == pytest.approx(70.0)
    assert np.isinf(line.distance_to_corner(np.array([130.0]))[0])


# --------------------------------------------------------------------------------------------
# on urban_canyon_v0
# --------------------------------------------------------------------------------------------


@needs_env
@pytest.mark.parametrize("name", ["random", "formation", "sky"])
def test_policies_give_valid_actions_on_the_env(name):
    env = urban(max_steps=25)
    pol = make_policy(name, env)
    assert isinstance(pol, Policy)
    _, actions = fly(env, pol, seed=1_000_003)
    assert actions and len(actions) <= 25
    assert_valid(env, actions)


@needs_env
@pytest.mark.parametrize("name", ["formation", "sky"])
def test_heuristics_reach_the_goal_along_the_canyon(name):
    """The paper's straight canyon: flying the street is enough to get there."""
    env = urban(city="canyon", n_uavs=4, max_steps=120)
    pol = make_policy(name, env)
    for seed in (1_000_000, 1_000_001):
        infos, _ = fly(env, pol, seed=seed)
        assert all(infos[a]["in_goal"] for a in env.possible_agents), seed
        assert not any(infos[a]["collided"] for a in env.possible_agents)


@needs_env
def test_formation_follower_reaches_the_goal_in_an_easy_grid():
    """Wide streets and low buildings (good satellite visibility, small navigation errors):
    the column follows routes with turns to the goal."""
    easy = {
        "street_width_m": 30.0,
        "height_mean_m": 25.0,
        "height_std_m": 5.0,
        "height_min_m": 10.0,
        "height_max_m": 40.0,
    }
    env = urban(n_uavs=3, max_steps=200, city_config=easy)
    pol = make_policy("formation", env)
    for seed in (1_000_002, 1_000_003):
        infos, _ = fly(env, pol, seed=seed)
        assert len(pol._path.points) >= 4  # at least one turn between the extensions
        assert all(infos[a]["in_goal"] for a in env.possible_agents), seed
        assert not any(infos[a]["collided"] for a in env.possible_agents), seed


@needs_env
def test_heuristics_are_deterministic():
    env = urban(max_steps=30)
    for name in ("formation", "sky"):
        pol = make_policy(name, env)
        _, a1 = fly(env, pol, seed=1_000_002)
        _, a2 = fly(env, pol, seed=1_000_002)
        assert all(np.array_equal(x[k], y[k]) for x, y in zip(a1, a2) for k in x)
