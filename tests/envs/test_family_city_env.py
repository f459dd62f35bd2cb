"""The environment on generated cities (``city="family:NAME"``)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v1
from coopnav_env.agents import make_policy
from coopnav_env.envs import make_config
from coopnav_env.sim.city import is_inside_building
from coopnav_env.sim.city_families import (
    FAMILIES,
    family_footprints,
    family_of_seed,
    seeded_family_city,
)
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


def test_the_mixed_family_draws_each_family_from_the_city_seed() -> None:
    assert [family_of_seed("family:mixed", s) for s in range(len(FAMILIES))] == list(FAMILIES)
    assert family_of_seed("family:old_town", 3) == "old_town"
    env = urban_canyon_v1.parallel_env(city="family:mixed", city_pool=len(FAMILIES))
    seen = set()
    for seed in range(30):
        env.reset(seed=seed)
        seen.add(env.world.city.source)
    # five cities in the pool, one of each family: thirty episodes meet all of them
    assert seen == {f"family:{f}" for f in FAMILIES}
    with pytest.raises(ValueError, match="family:mixed names every family"):
        family_footprints("mixed", np.random.default_rng(0))


def test_a_city_pool_draws_the_city_seeds_below_it() -> None:
    env = urban_canyon_v1.parallel_env(city="family:irregular", city_pool=2)
    cfg = env.config
    origin = (cfg.lat_deg, cfg.lon_deg, cfg.alt_m)
    pool = [seeded_family_city("irregular", s, origin) for s in (0, 1)]
    for seed in range(6):
        env.reset(seed=seed)
        assert any(env.world.city is c for c in pool)


def test_a_city_pool_outside_family_cities_or_with_a_city_seed_is_refused() -> None:
    with pytest.raises(ValueError, match=r"city_pool=3 applies to generated family cities.*'grid'"):
        make_config(city="grid", city_pool=3)
    with pytest.raises(ValueError, match=r"city_pool=3 and city_seed=1 exclude each other"):
        make_config(city="family:mixed", city_pool=3, city_seed=1)
    with pytest.raises(ValueError, match=r"city_pool must be an integer in \[1, "):
        make_config(city="family:mixed", city_pool=0)
