"""The column slows at a bend of a file city's route by the bend's angle
(``ColumnPolicy(full_turn_deg=...)``, :func:`coopnav_env.agents.heuristics.v_corner_at`);
a grid's routes keep every vertex a full corner (their golden episodes are pinned in
``test_heuristic_golden.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env import urban_canyon_v1
from coopnav_env.agents import make_policy
from coopnav_env.agents.heuristics import FILE_CITY_FULL_TURN_DEG, v_corner_at
from coopnav_env.sim.route import Polyline

V_TURN, BRAKE, VMAX = 2.0, 1.0, 7.0


def _bend(turn_deg: float, leg_m: float = 100.0) -> Polyline:
    """East for ``leg_m``, then ``leg_m`` turned left by ``turn_deg``."""
    a = math.radians(turn_deg)
    return Polyline([[0.0, 0.0], [leg_m, 0.0], [leg_m + leg_m * math.cos(a), leg_m * math.sin(a)]])


@pytest.mark.parametrize(
    ("turn_deg", "expected"),
    [(90.0, V_TURN), (60.0, V_TURN), (30.0, V_TURN + 0.5 * (VMAX - V_TURN)), (0.0, VMAX)],
)
def test_speed_at_a_bend_grows_as_its_angle_shrinks(turn_deg: float, expected: float) -> None:
    at_vertex = np.array([100.0])
    v = v_corner_at(_bend(turn_deg), at_vertex, V_TURN, BRAKE, VMAX, full_turn_deg=60.0)
    assert v[0] == pytest.approx(expected)


def test_without_a_full_turn_every_vertex_is_a_corner() -> None:
    s = np.array([0.0, 50.0, 97.0, 100.0, 150.0])
    for turn_deg in (5.0, 90.0):
        v = v_corner_at(_bend(turn_deg), s, V_TURN, BRAKE, VMAX)
        d = np.where(s <= 100.0, np.maximum(100.0 - s - 3.0, 0.0), 1e9)
        np.testing.assert_array_equal(v, np.minimum(VMAX, V_TURN + np.sqrt(2.0 * BRAKE * d)))


def test_a_sharp_corner_ahead_binds_over_a_gentle_bend_before_it() -> None:
    """A 10 deg bend at 20 m, a right angle 5 m after it: at 15 m the corner binds."""
    a = math.radians(10.0)
    bend_end = [20.0 + 5.0 * math.cos(a), 5.0 * math.sin(a)]
    path = Polyline([[0.0, 0.0], [20.0, 0.0], bend_end, [bend_end[0], 40.0]])
    v = v_corner_at(path, np.array([15.0]), V_TURN, BRAKE, VMAX, full_turn_deg=60.0)
    corner = V_TURN + math.sqrt(2.0 * BRAKE * (path.s[2] - 15.0 - 3.0))
    bend = V_TURN + (VMAX - V_TURN) * (1.0 - 10.0 / 60.0) + math.sqrt(2.0 * BRAKE * 2.0)
    assert corner < bend
    assert v[0] == pytest.approx(corner)


def test_auto_is_a_full_turn_in_a_file_city_and_none_on_a_grid() -> None:
    for city, expected in (("grid", None), ("geojson:sample", FILE_CITY_FULL_TURN_DEG)):
        env = urban_canyon_v1.parallel_env(city=city)
        policy = make_policy("column", env)
        obs, _ = env.reset(seed=3)
        policy.reset(3)
        policy.act(obs)
        assert policy._full_turn_now == expected, city
        env.close()


@pytest.mark.parametrize("bad", [0.0, -5.0, 200.0, "sharp"])
def test_a_bad_full_turn_is_refused_naming_it(bad) -> None:
    env = urban_canyon_v1.parallel_env()
    with pytest.raises(ValueError, match="full_turn_deg"):
        make_policy(f"column@full_turn_deg={bad}", env)
