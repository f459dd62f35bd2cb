"""Street routes: shortest route on the grid, arc-length polylines, waypoint tracking."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from coopnav_env.sim import CityConfig, generate_city
from coopnav_env.sim.route import (
    Polyline,
    advance_waypoints,
    extend_route,
    remaining_route_m,
    route_tail_lengths_m,
    street_route,
)


class _Grid:
    street_centres_x_m = np.array([-100.0, 0.0, 100.0])
    street_centres_y_m = np.array([-100.0, 0.0, 100.0])


def _on_streets(route: np.ndarray, grid=_Grid) -> bool:
    xs, ys = grid.street_centres_x_m, grid.street_centres_y_m
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


def test_street_route_edge_cases():
    same = street_route(_Grid, (0.0, 10.0), (0.0, 10.0))
    assert same.shape == (1, 2)

    class Canyon:  # one north-south street, no cross street
        street_centres_x_m = np.array([0.0])
        street_centres_y_m = np.zeros(0)

    route = street_route(Canyon, (3.0, -100.0), (-2.0, 150.0))
    np.testing.assert_allclose(route, [[0, -100], [0, 150]])

    class Empty:
        street_centres_x_m = np.zeros(0)
        street_centres_y_m = np.zeros(0)

    with pytest.raises(ValueError, match="at least one street"):
        street_route(Empty, (0.0, 0.0), (1.0, 1.0))


def test_street_routes_of_a_generated_city_stay_on_its_streets():
    city = generate_city(CityConfig(), np.random.default_rng(3))
    pts = city.random_street_points(np.random.default_rng(4), 40, margin_m=9.0)[:, :2]
    for a, b in itertools.pairwise(pts):
        route = street_route(city, a, b)
        assert _on_streets(route, city)
        # the straight legs between waypoints never cross a building at any UAV altitude
        for p, q in itertools.pairwise(route):
            s = np.linspace(0.0, 1.0, 50)[:, None]
            xyz = np.column_stack([p + s * (q - p), np.full(50, 15.0)])
            assert not city.is_inside_building(xyz).any()


def test_polyline_projection_respects_window():
    line = Polyline(np.array([[0.0, 0.0], [0.0, 100.0], [100.0, 100.0]]))
    p = np.array([[5.0, 95.0]])  # near both legs around the corner
    assert line.project(p, np.array([0.0]), np.array([90.0]))[0] == pytest.approx(90.0)
    assert line.project(p, np.array([100.0]), np.array([200.0]))[0] == pytest.approx(105.0)
    np.testing.assert_allclose(line.point(np.array([150.0])), [[50.0, 100.0]])
    assert line.distance_to_corner(np.array([30.0]))[0] == pytest.approx(70.0)
    assert np.isinf(line.distance_to_corner(np.array([130.0]))[0])


def test_extend_route_stays_inside_the_city():
    out = extend_route(np.array([[0.0, -90.0], [0.0, 0.0]]), 50.0, 500.0, (-100, 100, -100, 100))
    np.testing.assert_allclose(out, [[0, -98], [0, -90], [0, 0], [0, 98]])


ROUTE = np.array([[0.0, 0.0], [0.0, 100.0], [100.0, 100.0], [100.0, 250.0]])


def test_route_lengths():
    np.testing.assert_allclose(route_tail_lengths_m(ROUTE), [350.0, 250.0, 150.0, 0.0])
    xy = np.array([[3.0, 50.0], [50.0, 104.0]])
    np.testing.assert_allclose(
        remaining_route_m(ROUTE, xy, [1, 2]), [np.hypot(3, 50) + 250.0, np.hypot(50, 4) + 150.0]
    )


def test_waypoints_advance_when_reached_or_passed():
    xy = np.array(
        [
            [0.0, 50.0],  # on the first leg, far from the corner: stays
            [6.0, 94.0],  # inside the 8 m reach square of the corner
            [-9.0, 101.0],  # past the corner along the arriving leg (north of it)
            [8.0, 91.0],  # inside-corner turn, 9 m before the corner: not yet
        ]
    )
    idx = advance_waypoints(ROUTE, xy, np.ones(4, dtype=int), reach_m=8.0)
    np.testing.assert_array_equal(idx, [1, 2, 2, 1])
    # a point may skip several waypoints; the last one (the goal) is never passed
    far = advance_waypoints(ROUTE, np.array([[100.0, 400.0]]), [1], reach_m=8.0)
    assert far[0] == 3
    # indices never decrease and the input is not modified
    start = np.array([2])
    assert advance_waypoints(ROUTE, np.array([[0.0, 0.0]]), start, 8.0)[0] == 2
    assert start[0] == 2
    # a route of one point: index 0 stays
    assert advance_waypoints(ROUTE[:1], np.array([[5.0, 5.0]]), [0], 8.0)[0] == 0
