"""The ``action_frame`` option: velocity commands, or set-points along the street route."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from coopnav_env import urban_canyon_v1
from coopnav_env.agents.heuristics import waypoint_policy
from coopnav_env.envs import make_config
from coopnav_env.envs.urban_canyon import route_frame_command
from tests.batched_alike import assert_batched_obs_equal_separate

ROUTE = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])


def test_options_are_validated_and_velocity_is_the_default() -> None:
    cfg = make_config()
    assert cfg.action_frame == "velocity"
    assert cfg.route_offset_max_m == 4.0
    with pytest.raises(ValueError, match=r"action_frame must be one of .* got 'polar'"):
        make_config(action_frame="polar")
    with pytest.raises(ValueError, match=r"route_offset_max_m must be in .* got -1"):
        make_config(route_offset_max_m=-1.0)
    # 20 m streets, 1 m UAV radius: the offset must stay below 9 m
    env = urban_canyon_v1.parallel_env(action_frame="route", route_offset_max_m=9.0)
    with pytest.raises(ValueError, match=r"route_offset_max_m must be less than .* got 9.0"):
        env.reset(seed=0)
    urban_canyon_v1.parallel_env(action_frame="route", route_offset_max_m=8.5).reset(seed=0)


def _command(action, est, wp, **kw):
    cfg = make_config(action_frame="route", **kw)
    return route_frame_command(
        np.asarray(action, dtype=float), np.asarray(est, dtype=float), np.asarray(wp), ROUTE, cfg
    )


def test_set_points_give_the_speed_offset_and_altitude_asked() -> None:
    kin = make_config().kinematics
    est = [[20.0, 0.0, 17.5], [20.0, 0.0, 17.5], [20.0, 0.0, 17.5], [20.0, 0.0, 5.0]]
    act = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    cmd = _command(act, est, [1, 1, 1, 1]) * kin.max_speed_mps
    # full speed along the leg toward waypoint 1, at the middle of the band: no climb
    np.testing.assert_allclose(cmd[0], [10.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(cmd[1], 0.0, atol=1e-12)  # -1 holds its place
    # half speed, aimed 4 m to the left of travel (North) at the waypoint 80 m ahead
    np.testing.assert_allclose(cmd[2][:2], 5.0 * np.array([80.0, 4.0]) / np.hypot(80.0, 4.0))
    # the top of the band (30 m) from 5 m: 0.6 * 25 m/s, clipped to the maximum speed
    np.testing.assert_allclose(cmd[3], [5.0, 0.0, 10.0], atol=1e-12)


def test_speed_falls_before_a_waypoint_and_a_lost_estimate_holds_still() -> None:
    kin = make_config().kinematics
    est = [[95.0, 0.0, 17.5], [np.nan, 0.0, 17.5], [100.0, 50.0, 40.0]]
    cmd = _command([[1.0, 0.0, 0.0]] * 3, est, [1, 1, 2]) * kin.max_speed_mps
    np.testing.assert_allclose(cmd[0], [1.0 + 0.6 * 5.0, 0.0, 0.0])
    np.testing.assert_array_equal(cmd[1], 0.0)
    # an estimate above the band counts as at its top: 0.6 * (17.5 - 30) down
    np.testing.assert_allclose(cmd[2], [0.0, 10.0, -7.5], atol=1e-12)


def test_route_frame_steps_as_its_velocity_command() -> None:
    kw = {"n_uavs": 3, "max_steps": 60}
    route = urban_canyon_v1.parallel_env(action_frame="route", **kw)
    plain = urban_canyon_v1.parallel_env(**kw)
    rng = np.random.default_rng(4)
    for seed in (2, 9):
        o_r, _ = route.reset(seed=seed)
        o_p, _ = plain.reset(seed=seed)
        score_r = score_p = 0.0
        while route.agents:
            act = rng.uniform(-0.2, 1.0, (3, 3))
            ep = plain.unwrapped._epoch
            cmd = route_frame_command(
                act,
                ep.nav_pos_enu_m,
                ep.next_waypoint,
                plain.unwrapped.world.route_xy_m,
                route.unwrapped.config,
            )
            o_r, r_r, *_ = route.step(dict(zip(route.agents, act)))
            o_p, r_p, *_ = plain.step(dict(zip(plain.agents, cmd)))
            for a in o_r:
                assert o_r[a].tobytes() == o_p[a].tobytes()
            score_r += sum(r_r.values())
            score_p += sum(r_p.values())
        assert not plain.agents
        assert score_r == score_p


def test_a_constant_action_crosses_the_city_together() -> None:
    env = urban_canyon_v1.parallel_env(action_frame="route")
    arrived = 0
    for seed in range(4):
        env.reset(seed=seed)
        infos = {}
        while env.agents:
            _, _, _, _, infos = env.step({a: np.array([0.4, 0.0, 0.84]) for a in env.agents})
        arrived += all(i["in_goal"] for i in infos.values())
    assert arrived >= 3


def test_batched_equals_separate_environments_and_the_api_holds() -> None:
    assert_batched_obs_equal_separate({"n_uavs": 3, "max_steps": 12, "action_frame": "route"}, 5)
    parallel_api_test(urban_canyon_v1.parallel_env(n_uavs=3, action_frame="route"), num_cycles=50)


def test_velocity_heuristics_refuse_the_route_frame() -> None:
    env = urban_canyon_v1.parallel_env(action_frame="route")
    with pytest.raises(ValueError, match="need action_frame='velocity', got action_frame='route'"):
        waypoint_policy(env)


def test_setpoints_policy_gives_each_uav_its_set_points() -> None:
    from coopnav_env.agents import make_policy

    env = urban_canyon_v1.parallel_env(action_frame="route", n_uavs=3)
    obs, _ = env.reset(seed=1)
    pol = make_policy("setpoints@speed_mps=9,altitude_m=30,offset_m=-2,speed_step_mps=3", env)
    act = pol.act(obs)
    np.testing.assert_allclose(act["uav_0"], [0.8, -0.5, 1.0], atol=1e-6)
    np.testing.assert_allclose(act["uav_2"], [2.0 * 3.0 / 10.0 - 1.0, -0.5, 1.0], atol=1e-6)
    with pytest.raises(ValueError, match=r"speed_step_mps must leave the last of 3 UAVs"):
        make_policy("setpoints@speed_mps=5,speed_step_mps=3", env)
    with pytest.raises(ValueError, match=r"offset_m must be in \[-4, 4\]"):
        make_policy("setpoints@offset_m=5", env)
    with pytest.raises(ValueError, match="needs action_frame='route', got action_frame='velocity'"):
        make_policy("setpoints", urban_canyon_v1.parallel_env())


def test_setpoints_that_step_the_speed_string_the_swarm_out() -> None:
    from coopnav_env.agents import make_policy

    gaps = {}
    for step in (0.0, 1.5):
        env = urban_canyon_v1.parallel_env(action_frame="route", n_uavs=3)
        pol = make_policy(f"setpoints@speed_mps=8,altitude_m=28,speed_step_mps={step}", env)
        obs, _ = env.reset(seed=6)
        for _ in range(30):
            obs, *_ = env.step(pol.act(obs))
        pos = env.unwrapped._epoch.pos_enu_m
        gaps[step] = np.linalg.norm(pos[0] - pos[2])
    assert gaps[0.0] < 8.0 < 30.0 < gaps[1.5]


def test_turn_braking_limits_the_speed_before_a_turn_only() -> None:
    kin = make_config().kinematics
    est = [[80.0, 0.0, 17.5], [95.0, 0.0, 17.5], [100.0, 50.0, 17.5]]
    act = [[1.0, 0.0, 0.0]] * 3
    plain = _command(act, est, [1, 1, 2]) * kin.max_speed_mps
    braked = _command(act, est, [1, 1, 2], route_turn_brake_mps2=2.0) * kin.max_speed_mps
    np.testing.assert_allclose(plain[:, :2], [[10.0, 0.0], [4.0, 0.0], [0.0, 10.0]])
    # 1 + sqrt(2 * 2 * (d - 3)) at d = 20 and 5 m before the turn; the goal leg unchanged
    np.testing.assert_allclose(braked[0, 0], 1.0 + np.sqrt(68.0))
    np.testing.assert_allclose(braked[1, 0], 1.0 + np.sqrt(8.0))
    np.testing.assert_allclose(braked[2], plain[2])
    with pytest.raises(ValueError, match=r"route_turn_brake_mps2 must be in .* got -1"):
        make_config(route_turn_brake_mps2=-1.0)


def test_action_frame_of_names_the_frame_each_policy_flies_in() -> None:
    from coopnav_env.agents import action_frame_of

    assert action_frame_of("setpoints") == "route"
    assert action_frame_of("setpoints@speed_mps=10,altitude_m=30") == "route"
    assert action_frame_of("waypoint@altitude_m=28") == "velocity"
    assert action_frame_of("wide") == "velocity"
    assert action_frame_of("mappo:runs/v1/any") is None  # its run's frame


def test_evaluate_flies_route_frame_heuristics_in_their_frame(tmp_path) -> None:
    """``coopnav evaluate --policies setpoints`` needs no ``--env-set action_frame=route``;
    a velocity heuristic beside it flies the environment's default frame, the report says
    which policy flew in a frame of its own."""
    import argparse
    import json

    from coopnav_env.training import evaluate_cli as ev

    parser = argparse.ArgumentParser()
    ev.add_arguments(parser)
    common = ["--env-id", "urban_canyon_v1", "--episodes", "1", "--no-plots"]
    common += ["--env-set", "max_steps=4"]
    out = tmp_path / "ev"
    args = parser.parse_args(["--policies", "setpoints", "--out", str(out), *common])
    assert ev.run(args) == 0
    data = json.loads((out / "report.json").read_text())
    assert data["env_kwargs"] == {"max_steps": 4, "action_frame": "route"}
    both = tmp_path / "both"
    mixed = parser.parse_args(["--policies", "setpoints", "waypoint", "--out", str(both), *common])
    assert ev.run(mixed) == 0
    data = json.loads((both / "report.json").read_text())
    assert data["env_kwargs"] == {"max_steps": 4}
    assert data["own_frame"] == {"setpoints": "route"}
