"""Swarm kinematics, building collisions (static and swept) and separation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.sim import (
    Buildings,
    KinematicsConfig,
    building_collisions,
    separation_violations,
    step_kinematics,
    swept_collisions,
)


def test_kinematics_respects_limits() -> None:
    cfg = KinematicsConfig()
    rng = np.random.default_rng(0)
    n = 50
    pos = np.c_[rng.uniform(-50, 50, (n, 2)), rng.uniform(5, 30, n)]
    vel = np.zeros((n, 3))
    for _ in range(60):
        cmd = rng.uniform(-1.5, 1.5, (n, 3))
        new_pos, new_vel = step_kinematics(pos, vel, cmd, cfg)
        assert np.all(np.hypot(new_vel[:, 0], new_vel[:, 1]) <= cfg.max_speed_mps + 1e-9)
        assert np.all(np.abs(new_vel[:, 2]) <= cfg.max_speed_mps + 1e-9)
        # the acceleration limit holds except for the vertical velocity zeroed at a band limit
        at_limit = np.isin(new_pos[:, 2], [cfg.altitude_min_m, cfg.altitude_max_m])
        dv = np.linalg.norm(new_vel - vel, axis=1)
        assert np.all(dv[~at_limit] <= cfg.max_accel_mps2 * cfg.dt_s + 1e-9)
        dv_h = np.linalg.norm(new_vel[:, :2] - vel[:, :2], axis=1)
        assert np.all(dv_h <= cfg.max_accel_mps2 * cfg.dt_s + 1e-9)
        assert np.all((new_pos[:, 2] >= cfg.altitude_min_m) & (new_pos[:, 2] <= cfg.altitude_max_m))
        # semi-implicit Euler horizontally
        np.testing.assert_allclose(new_pos[:, :2], pos[:, :2] + new_vel[:, :2] * cfg.dt_s)
        pos, vel = new_pos, new_vel


def test_kinematics_reaches_commanded_speed_and_clips() -> None:
    cfg = KinematicsConfig(dt_s=0.5, max_speed_mps=8.0, max_accel_mps2=2.0)
    pos, vel = np.array([[0.0, 0.0, 10.0]]), np.zeros((1, 3))
    cmd = np.array([[1.0, 1.0, 0.0]])  # diagonal: horizontal norm clipped to max speed
    for _ in range(20):
        pos, vel = step_kinematics(pos, vel, cmd, cfg)
    np.testing.assert_allclose(vel[0], [8 / math.sqrt(2), 8 / math.sqrt(2), 0.0], atol=1e-12)
    # an over-range command is clipped to [-1, 1]
    a = step_kinematics(pos, vel, np.array([[5.0, -5.0, 0.0]]), cfg)
    b = step_kinematics(pos, vel, np.array([[1.0, -1.0, 0.0]]), cfg)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_altitude_clamp_zeroes_outward_vertical_velocity() -> None:
    cfg = KinematicsConfig()
    pos = np.array([[0.0, 0.0, 29.0], [0.0, 0.0, 6.0], [0.0, 0.0, 20.0]])
    vel = np.array([[0.0, 0.0, 8.0], [0.0, 0.0, -8.0], [0.0, 0.0, 3.0]])
    cmd = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.3]])
    new_pos, new_vel = step_kinematics(pos, vel, cmd, cfg)
    np.testing.assert_allclose(new_pos[:, 2], [30.0, 5.0, 23.0])
    np.testing.assert_allclose(new_vel[:, 2], [0.0, 0.0, 3.0])


def test_kinematics_does_not_modify_inputs() -> None:
    cfg = KinematicsConfig()
    pos, vel, cmd = np.array([[0.0, 0.0, 40.0]]), np.array([[1.0, 2, 3]]), np.array([[1.0, 0, 1]])
    for a in (pos, vel, cmd):
        a.setflags(write=False)
    step_kinematics(pos, vel, cmd, cfg)


def test_kinematics_shape_errors() -> None:
    cfg = KinematicsConfig()
    with pytest.raises(ValueError, match="must share one shape"):
        step_kinematics(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((3, 3)), cfg)
    with pytest.raises(ValueError, match="cmd must be finite"):
        step_kinematics(np.zeros((1, 3)), np.zeros((1, 3)), np.full((1, 3), np.nan), cfg)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"dt_s": 0.0}, r"KinematicsConfig\.dt_s must be in \(0\.0, 60\.0\], got 0\.0"),
        ({"max_speed_mps": -1.0}, r"KinematicsConfig\.max_speed_mps"),
        ({"max_accel_mps2": 0.0}, r"KinematicsConfig\.max_accel_mps2"),
        ({"altitude_min_m": -1.0}, r"KinematicsConfig\.altitude_min_m"),
        ({"altitude_max_m": 5.0}, r"KinematicsConfig\.altitude_max_m must be in \(5\.0, "),
        ({"uav_radius_m": -0.5}, r"KinematicsConfig\.uav_radius_m"),
        ({"min_separation_m": "3"}, r"KinematicsConfig\.min_separation_m must be a real"),
    ],
)
def test_kinematics_config_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        KinematicsConfig(**kwargs)


BOX = Buildings.from_boxes([(0.0, 0.0, 10.0, 10.0, 20.0)])


def test_sphere_box_collisions() -> None:
    pos = np.array(
        [
            [-0.9, 5.0, 5.0],  # 0.9 m from the west wall
            [-1.1, 5.0, 5.0],  # 1.1 m
            [5.0, 5.0, 20.9],  # above the roof by 0.9 m
            [5.0, 5.0, 5.0],  # inside
            [-0.7, -0.7, 20.7],  # near the roof corner: distance 0.7 * sqrt(3) = 1.21 m
            [-0.5, -0.5, 20.5],  # 0.87 m from the corner
        ]
    )
    np.testing.assert_array_equal(
        building_collisions(BOX, pos, 1.0), [True, False, True, True, False, True]
    )
    np.testing.assert_array_equal(building_collisions(Buildings.empty(), pos, 1.0), False)
    with pytest.raises(ValueError, match=r"collisions\.radius_m must be in \[0\.0, inf\]"):
        building_collisions(BOX, pos, -1.0)


def test_swept_collision_catches_tunnelling() -> None:
    wall = Buildings.from_boxes([(0.0, -50.0, 0.3, 50.0, 40.0)])  # 30 cm thick, ends at y = 50
    start = np.array([[-4.0, 0.0, 10.0], [-4.0, 0.0, 10.0], [-4.0, 52.0, 10.0]])
    end = np.array([[4.0, 0.0, 10.0], [-3.0, 0.0, 10.0], [4.0, 52.0, 10.0]])
    assert not building_collisions(wall, start, 1.0).any()
    assert not building_collisions(wall, end, 1.0).any()
    # through the wall / stops short / passes 2 m beyond its northern end
    np.testing.assert_array_equal(swept_collisions(wall, start, end, 1.0), [True, False, False])
    np.testing.assert_array_equal(swept_collisions(wall, start, end, 2.5), [True, False, True])
    # over the roof (z = 40) at 42 m: clear with r = 1, touching with r = 2
    over = np.array([[-4.0, 0.0, 42.0]]), np.array([[4.0, 0.0, 42.0]])
    assert not swept_collisions(wall, *over, 1.0)[0]
    assert swept_collisions(wall, *over, 2.0)[0]
    with pytest.raises(ValueError, match="must share one shape"):
        swept_collisions(wall, start, end[:2], 1.0)


def test_swept_min_distance_matches_dense_sampling() -> None:
    rng = np.random.default_rng(2)
    n_b = 6
    xy0 = rng.uniform(-30, 30, (n_b, 2))
    b = Buildings.from_footprints(
        np.c_[xy0, xy0 + rng.uniform(1, 10, (n_b, 2))], rng.uniform(3, 20, n_b)
    )
    start = np.c_[rng.uniform(-40, 40, (300, 2)), rng.uniform(0, 25, 300)]
    end = start + rng.normal(0, 15, (300, 3))
    t = np.linspace(0, 1, 4001)
    pts = start[:, None, :] + t[None, :, None] * (end - start)[:, None, :]
    excess = np.maximum(
        np.maximum(b.min_m[None, None] - pts[:, :, None], 0), pts[:, :, None] - b.max_m[None, None]
    )
    d_min = np.sqrt(np.min(np.sum(excess**2, axis=3), axis=(1, 2)))
    step = np.linalg.norm(end - start, axis=1) / 4000
    for r in (0.5, 2.0, 5.0):
        got = swept_collisions(b, start, end, r)
        clear = np.abs(d_min - r) > step  # sampling resolves the answer
        np.testing.assert_array_equal(got[clear], d_min[clear] <= r)
        assert 0 < got.sum() < len(got)
    # a zero-length segment is a static sphere
    np.testing.assert_array_equal(
        swept_collisions(b, start, start, 2.0), building_collisions(b, start, 2.0)
    )


def test_separation_violations() -> None:
    pos = np.array([[0.0, 0.0, 10.0], [2.0, 0.0, 10.0], [10.0, 0.0, 10.0], [10.0, 0.0, 13.5]])
    np.testing.assert_array_equal(separation_violations(pos, 3.0), [True, True, False, False])
    np.testing.assert_array_equal(separation_violations(pos, 4.0), [True, True, True, True])
    assert not separation_violations(pos[:1], 3.0).any()
    with pytest.raises(ValueError, match=r"separation_violations\.min_separation_m"):
        separation_violations(pos, -1.0)
