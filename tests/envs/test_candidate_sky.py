"""The ``obs_candidate_sky`` observation option: satellites the receiver would use at candidate
positions (its 3D-mapping-aided exclusion rule), for the UAV and for the swarm."""

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
    assert make_config().obs_candidate_sky is False
    assert make_config().obs_dim == 52  # the default observation is unchanged
    with pytest.raises(ValueError, match="obs_candidate_sky must be True or False, got 'yes'"):
        make_config(obs_candidate_sky="yes")
    cfg = preset_config("urban_nlos_3dma", obs_lookahead=True, obs_candidate_sky=True)
    assert cfg.obs_dim == 52 + 4 + 10
    layout = obs_layout(cfg)
    assert list(layout)[-3:] == [
        "swarm_satellites_ahead",
        "candidate_satellites",
        "candidate_swarm_satellites",
    ]
    assert layout["candidate_satellites"].stop == cfg.obs_dim - 5
    assert_layout_bounds_are_the_space(cfg)


def test_candidates_are_here_ahead_left_right_and_far() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=4, obs_candidate_sky=True)
    kin = env.config.kinematics
    for seed, steps in ((3, 0), (3, 25), (8, 40)):
        fly_random(env, seed, steps)
        if not env.agents:
            continue
        est = env._epoch.nav_pos_enu_m
        pts = env._candidate_points()
        assert pts.shape == (5, 4, 3)
        z = np.clip(est[:, 2], kin.altitude_min_m, kin.altitude_max_m)
        assert np.all(pts[:, :, 2] == z)  # every candidate at the estimated altitude, in the band
        np.testing.assert_array_equal(pts[0, :, :2], est[:, :2])
        route = env._route_points((env.CANDIDATE_AHEAD_M, env.CANDIDATE_FAR_M))
        np.testing.assert_array_equal(pts[1], route[0])
        np.testing.assert_array_equal(pts[4], route[1])
        for i in range(4):
            fwd = pts[1, i, :2] - est[i, :2]
            side_l = pts[2, i, :2] - pts[1, i, :2]
            side_r = pts[3, i, :2] - pts[1, i, :2]
            np.testing.assert_allclose(np.hypot(*side_l), env.CANDIDATE_SIDE_M)
            np.testing.assert_allclose(side_l, -side_r)
            if np.hypot(*fwd) > 1e-6:  # left of the way ahead: a positive cross product
                assert abs(np.dot(fwd, side_l)) < 1e-6 * np.hypot(*fwd)
                assert fwd[0] * side_l[1] - fwd[1] * side_l[0] > 0.0


def _usable(env, pts, cov):
    world, cfg, kin = env.world, env.config, env.config.kinematics
    use = predicted_line_of_sight(
        world.city.buildings,
        world._sky(world.t_s).directions,
        pts,
        cov,
        margin_sigma=cfg.nlos_exclusion_margin_sigma,
        max_margin_m=cfg.nlos_exclusion_max_margin_m,
        altitude_band_m=(kin.altitude_min_m, kin.altitude_max_m),
    )
    return use & ~is_inside_building(world.city.buildings, pts)[:, None]


def test_entries_count_what_the_receiver_would_use_there() -> None:
    env = urban_canyon_v0.parallel_env(
        config=preset_config(
            "urban_nlos_3dma", n_uavs=4, dead_reckoning_noise=True, obs_candidate_sky=True
        )
    )
    cfg = env.config
    checked = 0
    for steps in (0, 10, 30, 60):
        obs = fly_random(env, 11, steps)
        if not env.agents:
            break
        pts = env._candidate_points()
        dr_var = (cfg.dead_reckoning_sigma_mps * cfg.dt_s) ** 2
        cov = env.world.nav_cov_enu_m2 + np.eye(3) * dr_var
        cols = env._candidate_sky()
        assert cols.shape == (4, 10) and cols.dtype == np.float32
        ahead = _usable(env, pts[1], cov)
        for i in range(4):
            for c in range(5):
                use = _usable(env, pts[c, i][None], cov[i][None])[0]
                assert cols[i, c] == pytest.approx(min(use.sum() / 20.0, 1.0))
                pooled = use | np.delete(ahead, i, axis=0).any(axis=0)
                assert cols[i, 5 + c] == pytest.approx(min(pooled.sum() / 20.0, 1.0))
                # the swarm keeps at least what the UAV keeps
                assert cols[i, 5 + c] >= cols[i, c]
            checked += 1
        for a in env.agents:
            np.testing.assert_array_equal(obs[a][-10:], cols[env.possible_agents.index(a)])
    assert checked >= 8


def test_more_uncertainty_leaves_fewer_usable_satellites() -> None:
    # the exclusion margin grows with the covariance (up to its cap), so a UAV whose estimate
    # is uncertain is predicted to keep at most the satellites a certain one keeps
    env = urban_canyon_v0.parallel_env(
        config=preset_config("urban_nlos_3dma", n_uavs=3, obs_candidate_sky=True)
    )
    fly_random(env, 5, 20)
    sure = env._candidate_sky()
    env.world.nav_cov_enu_m2 = env.world.nav_cov_enu_m2 + np.eye(3) * 25.0  # +5 m sigma
    unsure = env._candidate_sky()
    assert np.all(unsure[:, :5] <= sure[:, :5])
    assert np.any(unsure[:, :5] < sure[:, :5])


def test_without_map_exclusion_it_is_plain_line_of_sight() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=3, obs_candidate_sky=True)
    assert env.config.nlos_exclusion == "off"
    fly_random(env, 4, 15)
    world, kin = env.world, env.config.kinematics
    pts = env._candidate_points().reshape(-1, 3)
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
    own = los.reshape(5, 3, -1).sum(axis=2).T
    np.testing.assert_allclose(env._candidate_sky()[:, :5], np.minimum(own / 20.0, 1.0))


def test_a_candidate_inside_a_building_counts_none(monkeypatch) -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=3, obs_candidate_sky=True)
    env.reset(seed=2)
    inside = point_inside_tallest_building(env)
    pts = env._candidate_points()
    pts[2, 0] = inside  # UAV 0's left candidate
    monkeypatch.setattr(env, "_candidate_points", lambda: pts)
    cols = env._candidate_sky()
    assert cols[0, 2] == 0.0 and cols[0, 1] > 0.0


def test_batched_equals_separate_environments() -> None:
    kwargs = {"n_uavs": 3, "max_steps": 12, "obs_candidate_sky": True}
    batch = assert_batched_obs_equal_separate(kwargs, seed=21)
    assert batch.obs_dim == 62


def test_parallel_api_with_the_option() -> None:
    parallel_api_test(
        urban_canyon_v0.parallel_env(n_uavs=3, obs_candidate_sky=True), num_cycles=100
    )
