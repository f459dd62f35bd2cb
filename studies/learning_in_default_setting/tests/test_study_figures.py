"""The learning study's figures: file cities draw their footprints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from studies.learning_in_default_setting.learning_study import plot_trajectories


@pytest.mark.filterwarnings("ignore:city file")
def test_trajectories_of_a_file_city_draw_its_footprints(tmp_path: Path) -> None:
    env_kwargs = {"city": "geojson:sample"}
    env = urban_canyon_v0.parallel_env(**env_kwargs)
    env.reset(seed=1_000_000)
    x, y = np.asarray(env.unwrapped.world.route_xy_m)[0]
    start = np.array([[x, y, 20.0], [x + 5.0, y, 20.0], [x, y + 5.0, 20.0]])
    flights = {"column": np.stack([start, start + np.array([5.0, 5.0, 0.0])])}
    path = plot_trajectories(env_kwargs, 1_000_000, flights, tmp_path / "trajectories.png")
    assert path.is_file() and path.stat().st_size > 0
