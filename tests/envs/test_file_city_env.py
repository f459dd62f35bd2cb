"""The environment on a city read from a GeoJSON file (``city="geojson:..."``)."""

from __future__ import annotations

import json
import pickle
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

from coopnav_env import GYM_ENV_ID, urban_canyon_v0
from coopnav_env.agents import make_policy
from coopnav_env.envs import make_config
from coopnav_env.sim.city import is_inside_building
from coopnav_env.sim.file_city import FileCity, load_file_city, sample_city_path

CITY = {"city": "geojson:sample"}


@pytest.fixture(autouse=True)
def _quiet_default_heights():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*get the default height.*")
        yield


def _episode(env, seed: int, steps: int) -> list:
    out = [env.reset(seed=seed)]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        if not env.agents:
            break
        out.append(env.step({a: rng.uniform(-0.5, 0.5, 3) for a in env.agents}))
    return out


def test_parallel_api_and_seed_tests_pass() -> None:
    parallel_api_test(urban_canyon_v0.parallel_env(**CITY), num_cycles=100)
    parallel_seed_test(lambda: urban_canyon_v0.parallel_env(**CITY), num_cycles=30)


def test_gymnasium_checker_passes() -> None:
    env = gymnasium.make(GYM_ENV_ID, **CITY)
    env.reset(seed=0)
    assert isinstance(env.unwrapped.par_env.world.city, FileCity)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.filterwarnings("ignore", message=".*get the default height.*")
        gym_check_env(env.unwrapped)
    assert not caught, [str(w.message) for w in caught]


def test_same_seed_same_episode_bit_for_bit_and_the_city_is_the_files() -> None:
    env1 = urban_canyon_v0.parallel_env(**CITY)
    env2 = urban_canyon_v0.parallel_env(**CITY)
    a, b = _episode(env1, 5, 25), _episode(env2, 5, 25)
    assert pickle.dumps(a) == pickle.dumps(b)  # bit for bit, infos included
    c = _episode(env1, 6, 3)
    assert not np.array_equal(a[0][0]["uav_0"], c[0][0]["uav_0"])
    world = env1.world
    assert isinstance(world.city, FileCity) and world.city.buildings.n > 200
    # the world's geodetic origin is the file's centroid
    assert (env1.config.lat_deg, env1.config.lon_deg) == world.city.origin[:2]
    # starts, goal and route lie in the free space
    assert world.city.is_free_xy(world.start_enu_m[:, :2]).all()
    assert world.city.is_free_xy(world.goal_enu_m[:2]).all()
    assert not is_inside_building(world.city.buildings, world.start_enu_m).any()
    assert np.linalg.norm(world.goal_enu_m[:2] - world.start_enu_m[:, :2].mean(0)) >= 200.0
    np.testing.assert_array_equal(world.route_xy_m[-1], world.goal_enu_m[:2])


def test_pickled_env_continues_identically() -> None:
    env = urban_canyon_v0.parallel_env(**CITY)
    env.reset(seed=2)
    clone = pickle.loads(pickle.dumps(env))
    act = {a: np.array([0.2, 0.1, 0.0]) for a in env.agents}
    assert pickle.dumps(env.step(act)) == pickle.dumps(clone.step(act))


def test_start_and_goal_from_lat_lon_and_refused_inside_a_building() -> None:
    city = load_file_city(sample_city_path(), alt_m=make_config(**CITY).alt_m, warn=False)
    rng = np.random.default_rng(0)
    s, g = city.random_street_points(rng, 2)[:, :2]
    s_ll, g_ll = city.xy_to_lat_lon(s), city.xy_to_lat_lon(g)
    env = urban_canyon_v0.parallel_env(
        **CITY, city_start_lat_lon=s_ll, city_goal_lat_lon=list(g_ll)
    )
    env.reset(seed=0)
    w = env.world
    assert np.linalg.norm(w.start_enu_m[:, :2].mean(0) - s) < 6.0
    np.testing.assert_allclose(w.goal_enu_m[:2], g, atol=1e-6)
    b = city.buildings
    k = int(np.argmax(b.heights_m))
    x0, y0, x1, y1 = b.bbox_m[k]
    cand = np.column_stack([rng.uniform(x0, x1, 100), rng.uniform(y0, y1, 100), np.ones(100)])
    inside = cand[is_inside_building(b, cand)][0, :2]
    with pytest.raises(ValueError, match=r"city_goal_lat_lon=.* lies inside a building of .*"):
        make_config(**CITY, city_goal_lat_lon=city.xy_to_lat_lon(inside))
    with pytest.raises(ValueError, match=r"city_start_lat_lon must be \(lat_deg, lon_deg\)"):
        make_config(**CITY, city_start_lat_lon=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="city_start_lat_lon needs city='geojson:PATH'"):
        make_config(city_start_lat_lon=s_ll)


def test_origin_from_the_config_and_bad_files(tmp_path: Path) -> None:
    cfg = make_config(**CITY, city_origin="config", lat_deg=31.2331, lon_deg=121.4951)
    assert (cfg.lat_deg, cfg.lon_deg) == (31.2331, 121.4951)
    with pytest.raises(ValueError, match=r"city='geojson:.*nowhere\.geojson'.*no such file"):
        make_config(city=f"geojson:{tmp_path / 'nowhere.geojson'}")
    bad = tmp_path / "bad.geojson"
    feat = {
        "type": "Feature",
        "id": "w7",
        "properties": {"height": "high"},
        "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [0, 1e-4], [1e-4, 0], [0, 0]]]},
    }
    bad.write_text(json.dumps({"type": "FeatureCollection", "features": [feat]}))
    with pytest.raises(ValueError, match=r"bad\.geojson, feature 0 \(id 'w7'\).*'high'"):
        urban_canyon_v0.parallel_env(city=f"geojson:{bad}")
    with pytest.raises(ValueError, match=r"\('grid', 'canyon'\) or 'geojson:PATH'"):
        make_config(city="osm:x")


@pytest.mark.parametrize("name", ["formation", "wide"])
def test_heuristics_fly_the_free_space_route_without_crashing(name: str) -> None:
    env = urban_canyon_v0.parallel_env(**CITY, max_steps=120)
    policy = make_policy(name, env)
    obs, _ = env.reset(seed=3)
    policy.reset(seed=3)
    start = env.world.start_enu_m[:, :2].mean(0)
    goal = env.world.goal_enu_m[:2]
    crashed = False
    for _ in range(120):
        obs, _, _, _, infos = env.step(policy.act(obs))
        crashed |= any(infos[a].get("collided", 0.0) for a in infos)
        if not env.agents:
            break
    assert not crashed
    moved = np.linalg.norm(goal - start) - np.linalg.norm(goal - env.world.pos_enu_m[:, :2].mean(0))
    assert moved > 100.0


def test_rgb_frame_draws_the_polygons() -> None:
    pytest.importorskip("matplotlib")
    env = urban_canyon_v0.parallel_env(**CITY, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 10


def test_coopnav_evaluate_runs_on_the_sample_city(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    from coopnav_env.training.cli import main

    city = f"city=geojson:{sample_city_path()}"
    argv = ["evaluate", "--policies", "formation", "wide", "--episodes", "2"]
    assert main([*argv, "--env-set", city, "--out", str(tmp_path / "ev")]) == 0
    report = json.loads((tmp_path / "ev" / "report.json").read_text())
    assert "geojson:" in json.dumps(report)
    assert (tmp_path / "ev" / "trajectories_wide.png").stat().st_size > 10_000


@pytest.mark.slow
def test_pettingzoo_render_test_passes(monkeypatch) -> None:
    pytest.importorskip("matplotlib")
    from pettingzoo.test import render_test

    monkeypatch.setenv("MPLBACKEND", "Agg")  # "human" frames go to a window-less backend
    render_test(lambda render_mode=None: urban_canyon_v0.env(render_mode=render_mode, **CITY))


def test_coopnav_train_runs_on_the_sample_city(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from coopnav_env.training.cli import main

    tiny = ["--timesteps", "128", "--n-envs", "1", "--no-progress"]
    sets = ["--set", "ppo.n_steps=64", "--set", "ppo.batch_size=64", "--set", "pretrain=null"]
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), "--city", "geojson:sample", *tiny, *sets]) == 0
    assert (out / "final_model.zip").is_file()
    assert "geojson:sample" in (out / "config.yaml").read_text()


def test_numpy_motion_path_equals_the_compiled_one(monkeypatch) -> None:
    from coopnav_env.sim import scenario

    fast = _episode(urban_canyon_v0.parallel_env(**CITY), 4, 30)
    monkeypatch.setattr(scenario, "_USE_KERNEL", False)
    slow = _episode(urban_canyon_v0.parallel_env(**CITY), 4, 30)
    assert len(fast) == len(slow)
    for a, b in zip(fast, slow):
        for x, y in zip(a[0].values(), b[0].values()):  # observations
            np.testing.assert_array_equal(x, y)


def test_map_aided_exclusion_and_map_line_of_sight_run_on_polygons() -> None:
    env = urban_canyon_v0.parallel_env(**CITY, nlos_exclusion="map")
    obs, _ = env.reset(seed=1)
    space = env.observation_space("uav_0")
    for _ in range(10):
        obs, _, _, _, _ = env.step({a: np.array([0.1, 0.1, 0.0]) for a in env.agents})
        assert all(space.contains(o) for o in obs.values())
    ep = env.world.last
    assert ep.received.sum() > 0 and (ep.map_excluded is not None)
    los = env.world.map_line_of_sight(env.world.pos_enu_m)  # the route choice's prediction
    assert los.shape == ep.received.shape and los.any()
