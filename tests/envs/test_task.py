"""The task module (:mod:`coopnav_env.envs.task`) apart from the world and the adapter."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0, urban_canyon_v1
from coopnav_env.agents import make_policy
from coopnav_env.envs import _fused, _kernels, autopilot, task, urban_canyon
from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.envs.task import (
    REWARD_TERMS,
    UrbanCanyonTask,
    episode_end,
    navigated_distance,
    reward_params,
)
from tests.test_layout import private_imports

NLOS = {"nlos_probability": 0.3}  # settings the fused step does not take: the env's own step


def _fly_and_recompute(env, policy_name: str, seed: int) -> int:
    """Fly an episode and, at every step, recompute the step's reward, end, observations and
    state with a task of its own from the epochs the environment went through; assert they
    equal what the environment returned, bit for bit. Returns the number of steps."""
    own = UrbanCanyonTask(env.config)
    policy = make_policy(policy_name, env)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    steps = 0
    while env.agents:
        prev, unpaid, route_m = env._epoch, env._unpaid_m.copy(), env._route_m
        obs, rewards, term, trunc, infos = env.step(policy.act(obs))
        steps += 1
        ep = env._epoch
        out = own.reward(env.world, prev, ep, unpaid, route_m)
        for i, a in enumerate(env.possible_agents):
            assert rewards[a] == out.reward[i]
            for t, v in out.terms.items():
                assert infos[a][f"reward_{t}"] == v[i], t
            assert infos[a]["in_goal"] == bool(out.in_goal[i])
        np.testing.assert_array_equal(out.unpaid_m, env._unpaid_m)
        end = episode_end(steps, env.config.max_steps, out.crashed, out.reached)
        assert end == (term["uav_0"], trunc["uav_0"])
        got = own.observations(env.world, ep, steps, own.observation_params(env._city_scale_m))
        assert got.tobytes() == np.stack([obs[a] for a in env.possible_agents]).tobytes()
        low, high = env.state_space.low, env.state_space.high
        scale = env._city_scale_m
        assert own.state(env.world, ep, steps, scale, low, high).tobytes() == env.state().tobytes()
    return steps


@pytest.mark.parametrize(
    ("make", "kwargs", "policy", "seed"),
    [
        (urban_canyon_v1.parallel_env, {"n_uavs": 4}, "waypoint", 3),  # the fused step
        (urban_canyon_v1.parallel_env, {"n_uavs": 4, **NLOS}, "waypoint", 5),
        (
            urban_canyon_v0.parallel_env,
            {"n_uavs": 3, "nav_team_weight": 0.5, "nav_reward": "sigma", **NLOS},
            "waypoint",
            2,
        ),
        (
            urban_canyon_v0.parallel_env,
            {"n_uavs": 3, "integrity": "fde", "integrity_penalty": 0.5, "max_steps": 60, **NLOS},
            "waypoint",
            6,
        ),
    ],
)
@pytest.mark.filterwarnings("ignore:urban_canyon_v0 is a legacy version")
def test_task_terms_equal_the_environments_on_a_flown_episode(make, kwargs, policy, seed) -> None:
    """A task of its own, given the epochs an environment went through, returns the rewards,
    terms, ends, observations and state the environment returned (the fused step included)."""
    env = make(**kwargs)
    assert _fly_and_recompute(env, policy, seed) > 10


def test_v1_step_computes_each_term_once(monkeypatch) -> None:
    """With ``reward_scheme="navigated_distance"`` the step never computes the per-step
    ``nav`` and ``progress`` terms, and its reward is the navigated-distance terms plus the
    event terms, computed directly here."""
    monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
    per_step_calls = []

    def refuse(*args):
        per_step_calls.append(args)
        raise AssertionError("the per-step reward terms were computed under navigated_distance")

    monkeypatch.setattr(task._kernels, "reward_terms", refuse)
    env = urban_canyon_v1.parallel_env(n_uavs=3)
    cfg = env.config
    policy = make_policy("waypoint", env)
    obs, _ = env.reset(seed=4)
    policy.reset(seed=4)
    total = 0.0
    while env.agents:
        unpaid = env._unpaid_m.copy()
        obs, rewards, term, _, _ = env.step(policy.act(obs))
        ep = env._epoch
        reached = bool(term["uav_0"]) and not ep.collided.any()
        nav, progress, _ = navigated_distance(
            env.world.route_xy_m,
            env.world.route_tail_m,
            ep,
            unpaid,
            env._route_m,
            reached,
            cfg.nav_reward_cap_m,
        )
        events = [
            -cfg.collision_penalty * ep.collided,
            -cfg.separation_penalty * ep.separation_violation,
            -cfg.contact_penalty * ep.out_of_contact,
            np.full(cfg.n_uavs, cfg.goal_bonus if reached else 0.0),
        ]
        want = np.stack([nav, progress, *events]).sum(axis=0)
        np.testing.assert_array_equal([rewards[a] for a in env.possible_agents], want)
        total += float(np.sum(want))
    assert not per_step_calls
    assert reached and total > 0.0  # the episode arrived: every term was exercised


def test_event_terms_are_the_per_step_kernels_rows() -> None:
    """:func:`_kernels.event_reward_terms` returns rows 2..5, flags, crash and arrival of
    :func:`_kernels.reward_terms` bit for bit, with rows 0 and 1 zero."""
    rng = np.random.default_rng(0)
    cfg = UrbanCanyonConfig(collision_penalty=2.5, separation_penalty=0.25)
    params = reward_params(cfg)
    route = rng.uniform(-50, 50, (4, 2))
    tail = np.array([30.0, 20.0, 10.0, 0.0])
    for trial in range(30):
        n = 5
        goal = np.array([0.0, 0.0, 10.0])
        pos = rng.normal(0.0, 20.0 if trial % 2 else 2.0, (n, 3))
        flags = [rng.random(n) < p for p in (0.1 * (trial % 3), 0.3, 0.3)]
        if trial % 3 == 0:
            flags[0][:] = False  # no collision: the swarm may arrive
        full = _kernels.reward_terms(
            _kernels.RouteAhead(route, tail, rng.integers(0, 4, n)),
            _kernels.StepPositions(
                rng.normal(0.0, 20.0, (n, 2)),
                pos,
                goal,
                pos + rng.normal(0.0, 3.0, (n, 3)),
                np.broadcast_to(np.eye(3), (n, 3, 3)).copy(),
            ),
            _kernels.StepEvents(*flags),
            False,
            params,
        )
        events = _kernels.event_reward_terms(pos, goal, _kernels.StepEvents(*flags), params)
        assert events[0][2:].tobytes() == full[0][2:].tobytes()
        assert not events[0][:2].any()
        assert events[1].tobytes() == full[1].tobytes()
        assert events[2:] == full[2:]


@pytest.mark.parametrize(
    ("steps", "crashed", "reached", "want"),
    [
        (5, False, False, (False, False)),
        (5, True, False, (True, False)),
        (5, False, True, (True, False)),
        (10, False, False, (False, True)),
        (10, True, False, (True, False)),  # a crash at the last step terminates
        (12, False, True, (True, False)),
    ],
)
def test_episode_end(steps, crashed, reached, want) -> None:
    assert episode_end(steps, 10, crashed, reached) == want


def test_old_import_places_still_work() -> None:
    """What moved to the task and the autopilot is importable from the adapter as before."""
    assert urban_canyon.REWARD_TERMS is REWARD_TERMS
    assert urban_canyon.route_frame_command is autopilot.route_frame_command
    assert urban_canyon.route_offset_room_m is autopilot.route_offset_room_m
    assert urban_canyon.ROUTE_FRAME_GAIN_PER_S == autopilot.ROUTE_FRAME_GAIN_PER_S == 0.6


@pytest.mark.parametrize("module", [urban_canyon, task, autopilot])
def test_the_env_imports_no_private_names_of_the_world(module) -> None:
    """The adapter, the task and the autopilot use only public names of ``coopnav_env.sim``."""
    found = private_imports(inspect.getsource(module))
    assert [name for _, name in found if name.startswith("coopnav_env.sim")] == []


@pytest.mark.parametrize("kwargs", [{"n_uavs": 4}, {"n_uavs": 3, "city": "geojson:sample"}])
def test_world_sensors_equal_the_citys(kwargs) -> None:
    """``UrbanWorld.sky_and_walls`` (what the task's observations read) returns the numbers
    of the checked ``City.sky_and_walls``, bit for bit, on box and polygon cities."""
    env = urban_canyon_v1.parallel_env(**kwargs)
    env.reset(seed=2)
    az = env.task.az_deg
    for _ in range(5):
        env.step({a: np.array([0.0, 0.0, 0.2]) for a in env.agents})  # climb in place
        pos = env._epoch.pos_enu_m
        got = env.world.sky_and_walls(pos, az)
        want = env.world.city.sky_and_walls(pos, az)
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()
        assert np.isfinite(got[0]).all() and got[0].shape == (env.config.n_uavs, az.shape[0])
