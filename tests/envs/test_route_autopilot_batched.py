"""The route autopilot of K swarms at once equals the one-swarm autopilot, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.envs import BatchedUrbanCanyonEnv
from coopnav_env.envs.autopilot import route_frame_velocity
from coopnav_env.envs.urban_canyon import ROUTE_FRAME_GAIN_PER_S, route_frame_command


def _batched(action, est, wp, routes, cfg, offset_max_m=None):
    kin = cfg.kinematics
    return route_frame_velocity(
        action,
        est,
        wp,
        routes,
        kin.max_speed_mps,
        (kin.altitude_min_m, kin.altitude_max_m),
        cfg.route_offset_max_m if offset_max_m is None else offset_max_m,
        cfg.route_turn_brake_mps2,
        ROUTE_FRAME_GAIN_PER_S,
    )


@pytest.mark.parametrize("brake", [0.0, 2.0])
def test_k_swarms_fly_the_one_swarm_commands_on_recorded_episodes(brake) -> None:
    k_ = 6
    venv = BatchedUrbanCanyonEnv(
        k_, n_uavs=4, max_steps=40, action_frame="route", route_turn_brake_mps2=brake
    )
    venv.reset(seed=11)
    cfg = venv.config
    rng = np.random.default_rng(3)
    checked = 0
    lengths, waypoints = set(), set()
    for _ in range(60):  # episodes end and restart at different steps
        action = rng.uniform(-1.3, 1.3, (k_, 4, 3))  # beyond [-1, 1]: the clipping too
        est = np.stack([e._epoch.nav_pos_enu_m for e in venv.envs]).copy()
        est[rng.random((k_, 4)) < 0.05] = np.nan  # UAVs without a fix hold still
        wp = np.stack([e._epoch.next_waypoint for e in venv.envs]).copy()
        wp[rng.random((k_, 4)) < 0.1] = 0  # before the first waypoint: the way to it
        routes = [e.world.route_xy_m for e in venv.envs]
        lengths |= {len(r) for r in routes}
        waypoints |= set(wp.ravel().tolist())
        cap = rng.uniform(1.0, cfg.route_offset_max_m, (k_, 4))
        for offset in (None, cap):
            got = _batched(action, est, wp, routes, cfg, offset)
            want = np.stack(
                [
                    route_frame_command(
                        action[k],
                        est[k],
                        wp[k],
                        routes[k],
                        cfg,
                        offset_max_m=None if offset is None else offset[k],
                    )
                    for k in range(k_)
                ]
            )
            assert got.shape == (k_, 4, 3)
            assert got.tobytes() == want.tobytes()
            # the routes padded into one (K, R, 2) array (the fused step's form)
            padded = np.full((k_, max(len(r) for r in routes), 2), np.nan)
            for k, r in enumerate(routes):
                padded[k, : len(r)] = r
            n_points = np.array([len(r) for r in routes])
            kin = cfg.kinematics
            got_padded = route_frame_velocity(
                action,
                est,
                wp,
                padded,
                kin.max_speed_mps,
                (kin.altitude_min_m, kin.altitude_max_m),
                cfg.route_offset_max_m if offset is None else offset,
                cfg.route_turn_brake_mps2,
                ROUTE_FRAME_GAIN_PER_S,
                route_lengths=n_points,
            )
            assert got_padded.tobytes() == want.tobytes()
            checked += 1
        venv.step(action)
    assert checked == 120
    assert len(lengths) > 1  # swarms with routes of different lengths
    assert {0, 1, 2} <= waypoints  # before the first waypoint, and on legs


def test_one_route_per_swarm_is_required() -> None:
    venv = BatchedUrbanCanyonEnv(2, n_uavs=3, action_frame="route")
    venv.reset(seed=0)
    routes = [venv.envs[0].world.route_xy_m]
    with pytest.raises(ValueError, match=r"routes_xy_m must hold 2 routes .* got 1"):
        _batched(
            np.zeros((2, 3, 3)), np.zeros((2, 3, 3)), np.zeros((2, 3), int), routes, venv.config
        )


def test_padded_routes_need_one_length_per_swarm() -> None:
    with pytest.raises(ValueError, match=r"padded routes_xy_m must have shape \(2, R, 2\)"):
        route_frame_velocity(
            np.zeros((2, 3, 3)),
            np.zeros((2, 3, 3)),
            np.zeros((2, 3), int),
            np.zeros((2, 4, 2)),
            10.0,
            (10.0, 60.0),
            4.0,
            0.0,
            ROUTE_FRAME_GAIN_PER_S,
            route_lengths=np.array([4]),
        )
