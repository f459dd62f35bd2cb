"""The environment on generated cities (``city="family:NAME"``)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v1
from coopnav_env.agents import make_policy
from coopnav_env.envs import make_config
from coopnav_env.sim.city import is_inside_building
from coopnav_env.sim.city_families import FAMILIES
from coopnav_env.sim.file_city import FileCity


def _edges(env) -> np.ndarray:
    return np.asarray(env.world.city.buildings.edges_m)


@pytest.mark.parametrize("name", FAMILIES)
def test_the_env_resets_and_steps_in_every_family(name: str) -> None:
    env = urban_canyon_v1.parallel_env(city=f"family:{name}")
    obs, _ = env.reset(seed=4)
    city = env.world.city
    assert isinstance(city, FileCity) and city.source == f"family:{name}"
    assert city.is_free_xy(env.world.start_enu_m[:, :2]).all()
    assert not is_inside_building(city.buildings, env.world.start_enu_m).any()
    rng = np.random.default_rng(0)
    for _ in range(3):
        obs, *_ = env.step({a: rng.uniform(-0.3, 0.3, 3) for a in env.agents})
    for agent, o in obs.items():
        assert np.all(np.isfinite(o)) and env.observation_space(agent).contains(o)


def test_each_episode_flies_a_new_city_and_a_city_seed_keeps_one() -> None:
    env = urban_canyon_v1.parallel_env(city="family:irregular")
    env.reset(seed=1)
    first = _edges(env)
    env.reset(seed=2)
    assert not np.array_equal(_edges(env), first)
    env.reset(seed=1)  # the episode's seed gives its city again
    np.testing.assert_array_equal(_edges(env), first)
    fixed = urban_canyon_v1.parallel_env(city="family:irregular", city_seed=7)
    fixed.reset(seed=1)
    one = _edges(fixed)
    fixed.reset(seed=2)
    np.testing.assert_array_equal(_edges(fixed), one)
    assert fixed.world.start_enu_m.shape == (fixed.config.n_uavs, 3)


def test_an_unknown_family_is_refused_listing_the_families() -> None:
    with pytest.raises(ValueError, match=r"city='family:suburb'.*'family:irregular'.*courtyards"):
        make_config(city="family:suburb")
    with pytest.raises(ValueError, match=r"'family:NAME'"):
        make_config(city="families")


@pytest.mark.parametrize("name", FAMILIES)
def test_the_column_heuristic_flies_towards_the_goal_in_every_family(name: str) -> None:
    env = urban_canyon_v1.parallel_env(city=f"family:{name}", max_steps=60)
    policy = make_policy("column", env)
    obs, _ = env.reset(seed=5)
    policy.reset(seed=5)
    start = env.world.start_enu_m[:, :2].mean(0)
    goal = env.world.goal_enu_m[:2]
    crashed = False
    while env.agents:
        obs, _, _, _, infos = env.step(policy.act(obs))
        crashed |= any(infos[a].get("collided", 0.0) for a in infos)
    assert not crashed
    moved = np.linalg.norm(goal - start) - np.linalg.norm(goal - env.world.pos_enu_m[:, :2].mean(0))
    assert moved > 60.0
