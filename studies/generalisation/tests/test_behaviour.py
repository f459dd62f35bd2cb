"""Behaviour descriptors of a swarm's cruise (studies.generalisation.behaviour)."""

from __future__ import annotations

import numpy as np
import pytest

from studies.generalisation.behaviour import cross_track_m, cruise_behaviour

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


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="dt_s"):
        cruise_behaviour(np.zeros((3, 2, 3)), ROUTE, 0.0)
    with pytest.raises(ValueError, match="route_xy_m"):
        cross_track_m(np.zeros((2, 2)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="pos_enu_m"):
        cruise_behaviour(np.zeros((3, 2)), ROUTE, 1.0)
