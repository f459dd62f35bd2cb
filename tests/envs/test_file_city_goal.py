"""A file city's goal is never silently where the settings did not ask (issue 45, finding 8)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import make_config
from coopnav_env.sim.file_city import load_file_city, sample_city_path

CITY = {"city": "geojson:sample"}
pytestmark = pytest.mark.filterwarnings("ignore:city file")


def _sample_city():
    return load_file_city(sample_city_path(), alt_m=make_config(**CITY).alt_m, warn=False)


def test_a_goal_at_the_start_is_refused() -> None:
    city = _sample_city()
    start = city.xy_to_lat_lon(city.random_street_points(np.random.default_rng(0), 1)[0, :2])
    with pytest.raises(ValueError, match=r"city_goal_lat_lon=.* is 0\.0 m from city_start_lat_lon"):
        make_config(**CITY, city_start_lat_lon=start, city_goal_lat_lon=start)


def test_a_goal_distance_larger_than_the_city_is_refused() -> None:
    x0, x1, y0, y1 = _sample_city().extent_m
    across = float(np.hypot(x1 - x0, y1 - y0))
    with pytest.raises(ValueError, match=r"goal_distance_min_m=.* is more than the .* m across"):
        make_config(**CITY, goal_distance_min_m=across + 1.0)


def test_a_nearer_goal_than_goal_distance_min_m_is_said() -> None:
    x0, x1, y0, y1 = _sample_city().extent_m
    far = 0.99 * float(np.hypot(x1 - x0, y1 - y0))  # allowed, but no drawn point is that far
    env = urban_canyon_v0.parallel_env(**CITY, goal_distance_min_m=far)
    with pytest.warns(UserWarning, match="no free point is goal_distance_min_m from this start"):
        env.reset(seed=0)
