"""Policies: the registry, valid actions, seeding, route planning, and reaching the goal."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from coopnav_env.agents import POLICY_NAMES, Policy, make_policy
from coopnav_env.agents.heuristics import Polyline, street_route
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


def test_policy_options_after_at_sign():
    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env()
    pol = make_policy("waypoint@altitude_m=28,cruise_speed_mps=5.5", env)
    assert pol.name == "waypoint"
    assert pol.altitude_m == 28.0 and pol.cruise_speed_mps == 5.5
    with pytest.raises(ValueError, match=r"bad option for policy 'waypoint'.*altitude"):
        make_policy("waypoint@altitude=28", env)
    with pytest.raises(ValueError, match=r"bad option for policy 'waypoint'.*abc"):
        make_policy("waypoint@altitude_m=abc", env)
    with pytest.raises(ValueError, match="expected key=value pairs"):
        make_policy("waypoint@28", env)
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        make_policy("nope@a=1", env)


def test_missing_checkpoint_names_the_path(tmp_path):
    missing = tmp_path / "nowhere" / "final_model.zip"
    with pytest.raises(FileNotFoundError, match="nowhere"):
        make_policy(f"ppo:{missing}", ToyParallelEnv())


def test_heuristics_need_the_urban_env():
    for name in ("column", "sky_column", "waypoint"):
        with pytest.raises(ValueError, match="urban_canyon_v0"):
            make_policy(name, ToyParallelEnv())


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
# route planning (tested in tests/sim/test_route.py)
# --------------------------------------------------------------------------------------------


def test_heuristics_use_the_route_module():
    from coopnav_env.sim import route

    assert street_route is route.street_route
    assert Polyline is route.Polyline


# --------------------------------------------------------------------------------------------
# on urban_canyon_v0
# --------------------------------------------------------------------------------------------


@needs_env
@pytest.mark.parametrize(
    "name",
    [
        "random",
        "column",
        "sky_column",
        "stretched_column",
        "wide_column",
        "guarded_column",
        "ceiling_column",
        "waypoint",
    ],
)
def test_policies_give_valid_actions_on_the_env(name):
    env = urban(max_steps=25)
    pol = make_policy(name, env)
    assert isinstance(pol, Policy)
    _, actions = fly(env, pol, seed=1_000_003)
    assert actions and len(actions) <= 25
    assert_valid(env, actions)


@needs_env
@pytest.mark.parametrize(
    "name",
    [
        "column",
        "sky_column",
        "stretched_column",
        "wide_column",
        "guarded_column",
        "ceiling_column",
        "waypoint",
    ],
)
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
    pol = make_policy("column", env)
    for seed in (1_000_002, 1_000_003):
        infos, _ = fly(env, pol, seed=seed)
        assert len(pol._path.points) >= 4  # at least one turn between the extensions
        assert all(infos[a]["in_goal"] for a in env.possible_agents), seed
        assert not any(infos[a]["collided"] for a in env.possible_agents), seed


@needs_env
def test_heuristics_are_deterministic():
    env = urban(max_steps=30)
    for name in ("column", "sky_column"):
        pol = make_policy(name, env)
        _, a1 = fly(env, pol, seed=1_000_002)
        _, a2 = fly(env, pol, seed=1_000_002)
        assert all(np.array_equal(x[k], y[k]) for x, y in zip(a1, a2) for k in x)


@needs_env
def test_waypoint_follower_turns_corners_of_the_grid():
    """Obs-only route following: toward the next waypoint, which advances at each corner."""
    env = urban(max_steps=200)
    pol = make_policy("waypoint", env)
    assert pol.name == "waypoint"
    reached = 0
    for seed in range(1_000_000, 1_000_004):
        infos, _ = fly(env, pol, seed=seed)
        reached += all(infos[a]["in_goal"] for a in env.possible_agents)
    assert reached >= 3


@needs_env
def test_opening_column_starts_tight_and_opens_ahead():
    """``open_distance_m``: the column starts at ``goal_spacing_m`` and opens to ``spacing_m``
    as the head advances, its tail held (the rear UAV is not sent back along the route)."""
    env = urban()
    pol = make_policy("stretched_column@spacing_m=30,close_distance_m=120,open_distance_m=96", env)
    obs, _ = env.reset(seed=1_000_000)
    pol.reset(1_000_000)
    pol.act(obs)
    head0 = pol._head0
    assert pol._spacing_now() == pytest.approx(6.0 + 24.0 * (pol._head - head0) / 96.0)
    assert pol._spacing_now() < 10.0
    tail = pol._head - 4 * pol._spacing_now()
    for _ in range(40):
        obs, *_ = env.step(pol.act(obs))
        # with open_distance = (N - 1)(spacing - goal_spacing) the tail's slot never goes back
        new_tail = pol._head - 4 * pol._spacing_now()
        assert new_tail >= tail - 1e-9
        tail = new_tail
    assert pol._head - head0 > 96.0
    assert pol._spacing_now() == pytest.approx(30.0)
    with pytest.raises(ValueError, match="open_distance_m"):
        make_policy("stretched_column@open_distance_m=0", env)


@needs_env
def test_wide_column_defaults_follow_its_spacing():
    """``wide_column``: close over 4 x spacing, open over (N - 1)(spacing - goal spacing); options
    after ``@`` still override them."""
    env = urban(n_uavs=4)
    pol = make_policy("wide_column", env)
    assert (pol.spacing_m, pol.goal_spacing_m) == (45.0, 6.0)
    assert pol.close_distance_m == 180.0 and pol.open_distance_m == 3 * 39.0
    pol = make_policy("wide_column@spacing_m=30,open_distance_m=50", env)
    assert pol.close_distance_m == 120.0 and pol.open_distance_m == 50.0


@needs_env
def test_wall_guard_pushes_away_from_a_near_wall():
    """With ``wall_margin_m``, a wall the range sensor puts inside the margin pushes the UAV
    away by ``wall_gain_per_s`` times the intrusion; walls outside it change nothing."""
    from coopnav_env.envs import obs_layout

    env = urban(n_uavs=3)
    obs, _ = env.reset(seed=1_000_002)
    walls = obs_layout(env.unwrapped.config)["wall_distance"]
    n_az = walls.size
    east = n_az // 4  # azimuth 90 deg: East
    far = {a: o.copy() for a, o in obs.items()}
    for o in far.values():
        o[walls.slice] = 1.0  # every wall at the sensor's range (50 m)
    near = {a: o.copy() for a, o in far.items()}
    a0 = env.possible_agents[0]
    near[a0][walls.start + east] = 2.0 / walls.scale  # a wall 2 m to the East of UAV 0
    vmax = env.unwrapped.config.kinematics.max_speed_mps

    def cmd(name, o):
        pol = make_policy(name, env)
        pol.reset(seed=1_000_002)
        return pol.act(o)

    g = "wide_column@wall_margin_m=8,wall_gain_per_s=0.5"
    c_far, c_near = cmd(g, far), cmd(g, near)
    assert c_far[a0][0] - c_near[a0][0] == pytest.approx(0.5 * (8.0 - 2.0) / vmax, abs=1e-6)
    assert c_far[a0][1] == pytest.approx(c_near[a0][1], abs=1e-6)  # nothing to the North
    for a in env.possible_agents[1:]:
        assert np.array_equal(c_far[a], c_near[a])
    # no guard: the wall is ignored
    assert np.array_equal(cmd("wide_column", far)[a0], cmd("wide_column", near)[a0])
    with pytest.raises(ValueError, match="wall_margin_m must be in"):
        make_policy("wide_column@wall_margin_m=0", env)
    with pytest.raises(ValueError, match="wall_gain_per_s must be in"):
        make_policy("wide_column@wall_margin_m=5,wall_gain_per_s=-1", env)


def test_guard_delta_removes_only_the_part_toward_a_near_wall():
    """``guard_delta`` drops the horizontal part of a change that points at a wall inside the
    margin (two near walls at a corner: both), cuts it toward a wall beyond the margin to the
    speed that reaches the margin in ``time_s``, keeps every other part, and is the identity
    without a wall margin or a wall in the sensor's range."""
    from coopnav_env.envs import obs_layout

    env = urban(n_uavs=3)
    obs, _ = env.reset(seed=1_000_002)
    walls = obs_layout(env.unwrapped.config)["wall_distance"]
    n_az = walls.size
    east, north = n_az // 4, 0  # sector azimuths 90 and 0 deg
    o = np.stack([obs[a] for a in env.possible_agents]).astype(np.float64)
    o[:, walls.slice] = 1.0  # every wall at the sensor's range
    o[0, walls.start + east] = 2.0 / walls.scale  # UAV 0: a wall 2 m to the East
    o[1, walls.start + east] = 2.0 / walls.scale  # UAV 1: walls East and North (a corner)
    o[1, walls.start + north] = 3.0 / walls.scale
    o[2, walls.start + east] = 12.0 / walls.scale  # UAV 2: a wall 12 m East, 4 m beyond
    delta = np.array([[0.4, 0.3, 0.2], [0.4, 0.3, -0.1], [0.4, 0.3, 0.2]])
    pol = make_policy("ceiling_column", env)  # wall margin 8 m
    vmax = env.unwrapped.config.kinematics.max_speed_mps
    out = pol.guard_delta(o, delta)
    np.testing.assert_allclose(out[0], [0.0, 0.3, 0.2], atol=1e-12)  # East part gone
    np.testing.assert_allclose(out[1], [0.0, 0.0, -0.1], atol=1e-12)  # both parts gone
    # toward the wall 4 m beyond the margin: at most the speed that reaches it in 2 s
    np.testing.assert_allclose(out[2], [(12.0 - 8.0) / 2.0 / vmax, 0.3, 0.2], atol=1e-12)
    slow = pol.guard_delta(o, delta, time_s=40.0)
    np.testing.assert_allclose(slow[2], [(12.0 - 8.0) / 40.0 / vmax, 0.3, 0.2], atol=1e-12)
    o[2, walls.start + east] = 1.0
    np.testing.assert_array_equal(pol.guard_delta(o, delta)[2], delta[2])  # no near wall
    away = pol.guard_delta(o, -delta)  # pointing away from the walls: unchanged
    np.testing.assert_array_equal(away, -delta)
    # without a wall margin the change is returned as it is
    np.testing.assert_array_equal(make_policy("wide_column", env).guard_delta(o, delta), delta)
    with pytest.raises(ValueError, match="guard_delta needs delta"):
        pol.guard_delta(o, delta[:2])
    with pytest.raises(ValueError, match="time_s must be > 0"):
        pol.guard_delta(o, delta, time_s=0.0)


@needs_env
def test_ceiling_climbs_to_and_holds_the_top_of_the_band():
    """``ceiling_column`` = ``guarded_column`` with its altitude target 10 m above the band: it
    climbs faster and then sits at the band's top, where ``guarded_column`` hovers below it."""
    env = urban(preset="urban_nlos_3dma", dead_reckoning_noise=True, max_steps=60)
    pol = make_policy("ceiling_column", env)
    assert pol.ceiling_margin_m == -10.0
    assert (pol.wall_margin_m, pol.gain_per_s, pol.spacing_m) == (8.0, 0.2, 45.0)
    top = env.unwrapped.config.kinematics.altitude_max_m
    alt = {}
    for name in ("guarded_column", "ceiling_column"):
        p = make_policy(name, env)
        obs, _ = env.reset(seed=1_000_000)
        p.reset(seed=1_000_000)
        zs = []
        for _ in range(60):
            obs, *_ = env.step(p.act(obs))
            zs.append(env.unwrapped.world.pos_enu_m[:, 2].copy())
            if not env.agents:
                break
        alt[name] = np.array(zs)
    # after 30 s every UAV of ``ceiling_column`` is within 0.5 m of the top; ``guarded_column``
    # is not
    assert np.all(alt["ceiling_column"][30:] >= top - 0.5), alt["ceiling_column"][30:].min()
    assert alt["ceiling_column"][30:].mean() > alt["guarded_column"][30:].mean()
    assert alt["ceiling_column"][:10].mean() > alt["guarded_column"][:10].mean()  # climbs faster
    with pytest.raises(ValueError, match="ceiling_margin_m must be in"):
        make_policy("ceiling_column@ceiling_margin_m=-60", env)


@needs_env
@pytest.mark.slow
def test_guarded_defaults_and_fewer_crashes_under_degraded_navigation():
    """``guarded_column`` = ``wide_column`` + wall guard + soft tracking; under NLOS reception
    with a drifting dead reckoning it crashes far less than ``wide_column`` on the same
    episodes."""
    env = urban(preset="urban_nlos_3dma", dead_reckoning_noise=True)
    pol = make_policy("guarded_column", env)
    assert (pol.wall_margin_m, pol.wall_gain_per_s, pol.gain_per_s) == (8.0, 4.0, 0.2)
    assert pol.spacing_m == 45.0  # wide's column
    crashes = {}
    for name in ("wide_column", "guarded_column"):
        p = make_policy(name, env)
        crashes[name] = sum(
            any(fly(env, p, seed=s)[0][a]["collided"] for a in env.possible_agents)
            for s in range(1_000_000, 1_000_100)
        )
    # measured on these 100 episodes: wide 16, guarded 2 (300 episodes: 15 % against 2 %)
    assert crashes["guarded_column"] <= crashes["wide_column"] - 8, crashes
