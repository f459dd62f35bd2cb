"""The ``obs_lookahead`` observation option: satellites the map predicts along the route ahead."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import make_config, obs_layout, preset_config
from coopnav_env.sim.city import is_inside_building
from coopnav_env.sim.map_aided import predicted_line_of_sight
from tests.batched_alike import assert_batched_obs_equal_separate
from tests.env_flight import (
    assert_layout_bounds_are_the_space,
    fly_random,
    point_inside_tallest_building,
)


def test_option_is_validated_off_by_default_and_named_in_the_layout() -> None:
    assert make_config().obs_lookahead is False
    assert make_config().obs_dim == 52  # the default observation is unchanged
    with pytest.raises(ValueError, match="obs_lookahead must be True or False, got 1"):
        make_config(obs_lookahead=1)
    cfg = preset_config("urban_nlos", obs_satellite_sectors=True, obs_lookahead=True)
    assert cfg.obs_dim == 52 + 16 + 4
    layout = obs_layout(cfg)
    assert list(layout)[-2:] == ["satellites_ahead", "swarm_satellites_ahead"]
    assert layout["satellites_ahead"].stop == cfg.obs_dim - 2
    assert_layout_bounds_are_the_space(cfg)


def test_points_lie_along_the_route_from_the_estimate() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=4, obs_lookahead=True)
    for seed, steps in ((3, 0), (3, 25), (8, 40)):
        fly_random(env, seed, steps)
        if not env.agents:
            continue
        ep, world = env._epoch, env.world
        pts = env._lookahead_points()
        assert pts.shape == (2, 4, 3)
        est = ep.nav_pos_enu_m
        for i in range(4):
            # the path: the estimate, then the route from the next waypoint on
            path = np.vstack([est[i, :2], world.route_xy_m[int(ep.next_waypoint[i]) :]])
            first_leg = np.hypot(*(path[1] - path[0])) if len(path) > 1 else 0.0
            for d, dist in enumerate(env.LOOKAHEAD_M):
                # never farther than the distance walked, in a straight line
                assert np.hypot(*(pts[d, i, :2] - est[i, :2])) <= dist + 1e-9
                if first_leg >= dist:  # still on the first leg: exactly dist towards it
                    u = (path[1] - path[0]) / first_leg
                    np.testing.assert_allclose(pts[d, i, :2], est[i, :2] + dist * u, atol=1e-9)
            kin = env.config.kinematics
            z = np.clip(est[i, 2], kin.altitude_min_m, kin.altitude_max_m)
            assert np.all(pts[:, i, 2] == z)  # at the estimated altitude, in the band


def test_entries_count_the_predicted_satellites_at_the_points() -> None:
    env = urban_canyon_v0.parallel_env(
        config=preset_config("urban_nlos_3dma", n_uavs=4, obs_lookahead=True)
    )
    for steps in (0, 10, 30):
        obs = fly_random(env, 11, steps)
        if not env.agents:
            break
        world, kin = env.world, env.config.kinematics
        pts = env._lookahead_points().reshape(-1, 3)
        los = predicted_line_of_sight(
            world.city.buildings,
            world._sky(world.t_s).directions,
            pts,
            np.zeros((len(pts), 3, 3)),
            margin_sigma=0.0,
            max_margin_m=0.0,
            altitude_band_m=(kin.altitude_min_m, kin.altitude_max_m),
        )
        los &= ~is_inside_building(world.city.buildings, pts)[:, None]
        los = los.reshape(2, 4, -1)
        cols = env._lookahead()
        np.testing.assert_allclose(cols[:, :2], np.minimum(los.sum(axis=2).T / 20.0, 1.0))
        swarm = np.minimum(los.any(axis=1).sum(axis=1) / 20.0, 1.0)
        np.testing.assert_allclose(cols[:, 2:], np.broadcast_to(swarm, (4, 2)))
        # the swarm sees at least what any one UAV sees
        assert np.all(cols[:, 2:] >= cols[:, :2].max(axis=0) - 1e-7)
        for a in env.agents:
            np.testing.assert_array_equal(obs[a][-4:], cols[env.possible_agents.index(a)])


def test_a_point_inside_a_building_counts_none(monkeypatch) -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=3, obs_lookahead=True)
    env.reset(seed=2)
    inside = point_inside_tallest_building(env)
    pts = env._lookahead_points()
    pts[:, 0] = inside
    monkeypatch.setattr(env, "_lookahead_points", lambda: pts)
    cols = env._lookahead()
    assert np.all(cols[0, :2] == 0.0) and np.all(cols[1:, :2] > 0.0)


def test_batched_equals_separate_environments() -> None:
    kwargs = {"n_uavs": 3, "max_steps": 12, "obs_lookahead": True}
    batch = assert_batched_obs_equal_separate(kwargs, seed=20)
    assert batch.obs_dim == 56


def test_parallel_api_with_the_option() -> None:
    parallel_api_test(urban_canyon_v0.parallel_env(n_uavs=3, obs_lookahead=True), num_cycles=100)
