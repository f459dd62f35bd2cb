"""Behaviour descriptors of a swarm's cruise (``coopnav_env.training.behaviour``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.training.behaviour import cross_track_m, cruise_behaviour

ROUTE = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])


def test_cross_track_is_signed_left_of_travel() -> None:
    pts = np.array([[50.0, 3.0], [50.0, -4.0], [103.0, 50.0], [96.0, 50.0]])
    # on the first leg (East) left is North; on the second (North) left is West
    assert cross_track_m(pts, ROUTE) == pytest.approx([3.0, -4.0, -3.0, 4.0])


def test_a_swarm_spread_across_its_route_at_known_speed_and_height() -> None:
    steps, dt = 11, 0.5
    x = 4.0 * np.arange(steps)  # 4 m per 0.5 s: 8 m/s along the East leg
    lateral = np.array([-6.0, 0.0, 6.0])  # three UAVs abreast, 6 m apart
    pos = np.zeros((steps, 3, 3))
    pos[:, :, 0] = x[:, None]
    pos[:, :, 1] = lateral[None, :]
    pos[:, :, 2] = [20.0, 30.0, 40.0]
    b = cruise_behaviour(pos, ROUTE, dt)
    assert b["lateral_spread_m"] == pytest.approx(12.0)
    assert b["speed_mps"] == pytest.approx(8.0)
    assert b["altitude_m"] == pytest.approx(30.0)
    assert b["spacing_m"] == pytest.approx(
        np.mean([np.hypot(6, 10), np.hypot(6, 10), np.hypot(6, 10)])
    )
    # the same swarm in line on the route has no spread
    pos[:, :, 1] = 0.0
    assert cruise_behaviour(pos, ROUTE, dt)["lateral_spread_m"] == pytest.approx(0.0)


def test_the_cruise_leaves_out_the_start_and_the_end() -> None:
    # 11 positions: the cruise is positions 2..8; two UAVs climbing from 10 m to 110 m
    pos = np.zeros((11, 2, 3))
    pos[:, 1, 1] = 5.0
    pos[:, :, 2] = 10.0 * np.arange(11)[:, None] + 10.0
    b = cruise_behaviour(pos, ROUTE, 1.0)
    assert b["altitude_m"] == pytest.approx(np.mean(10.0 * np.arange(2, 9) + 10.0))
    assert b["speed_mps"] == 0.0  # climbing only: no horizontal speed
    assert b["lateral_spread_m"] == pytest.approx(5.0)


def test_what_is_unknown_is_nan() -> None:
    pos = np.zeros((5, 2, 3))
    pos[:, 1, 0] = 3.0
    b = cruise_behaviour(pos, None, math.nan)  # no route, no step length
    assert b["spacing_m"] == pytest.approx(3.0) and b["altitude_m"] == 0.0
    assert math.isnan(b["lateral_spread_m"]) and math.isnan(b["speed_mps"])
    assert all(math.isnan(v) for v in cruise_behaviour(None, ROUTE, 1.0).values())
    one = cruise_behaviour(pos[:, :1], ROUTE, 1.0)  # one UAV: no neighbour, no extent
    assert math.isnan(one["spacing_m"]) and math.isnan(one["lateral_spread_m"])
    assert one["speed_mps"] == 0.0


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="dt_s"):
        cruise_behaviour(np.zeros((3, 2, 3)), ROUTE, 0.0)
    with pytest.raises(ValueError, match="route_xy_m"):
        cross_track_m(np.zeros((2, 2)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="pos_enu_m"):
        cruise_behaviour(np.zeros((3, 2)), ROUTE, 1.0)
    with pytest.raises(ValueError, match="cruise"):
        cruise_behaviour(np.zeros((3, 2, 3)), ROUTE, 1.0, cruise=(0.8, 0.2))
