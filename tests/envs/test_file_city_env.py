"""The environment on a city read from a file (``city="geojson:..."``, ``city="osm:..."``)."""

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
    with pytest.raises(
        ValueError, match=r"(?s)bad\.geojson: 1 feature problem.*feature 0 \(id 'w7'\).*'high'"
    ):
        urban_canyon_v0.parallel_env(city=f"geojson:{bad}", city_repair=False)
    with pytest.raises(ValueError, match=r"\('grid', 'canyon'\), 'geojson:PATH' .* or 'osm:PATH'"):
        make_config(city="osmx:x")


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
    """The motion oracle (tests/sim/oracles.py) on a file city's polygons: the same episode."""
    from coopnav_env.envs import _fused
    from coopnav_env.sim import scenario
    from tests.sim import oracles

    fast = _episode(urban_canyon_v0.parallel_env(**CITY), 4, 30)
    calls = {"motion": 0}

    def motion(*args):
        calls["motion"] += 1
        return oracles.world_motion(*args)

    monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
    monkeypatch.setattr(scenario, "_world_motion", motion)
    slow = _episode(urban_canyon_v0.parallel_env(**CITY), 4, 30)
    assert len(fast) == len(slow) and calls["motion"] == len(slow) - 1  # every step
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


# ---- real cities: OpenStreetMap input, reading settings, tuples as users write them -------


def test_an_osm_extract_flies_directly() -> None:
    pytest.importorskip("osmium")
    box = (60.166, 24.938, 60.174, 24.950)
    env = urban_canyon_v0.parallel_env(
        city="osm:helsinki", city_bbox=box, city_default_height_m=20.0, n_uavs=3
    )
    _, infos = env.reset(seed=1)
    city = env.world.city
    assert isinstance(city, FileCity) and city.buildings.n == 183
    assert city.report.n_default_height == 122
    assert np.all(city.buildings.heights_m[city.buildings.heights_m != 20.0] > 0)
    assert abs(env.config.lat_deg - 60.170) < 0.005 and abs(env.config.lon_deg - 24.944) < 0.005
    rng = np.random.default_rng(1)
    for _ in range(5):
        obs, rewards, _, _, infos = env.step({a: rng.uniform(-0.5, 0.5, 3) for a in env.agents})
    assert len(obs) == 3
    assert all(np.all(np.isfinite(o)) for o in obs.values())
    assert all(np.isfinite(r) for r in rewards.values())
    assert all(infos[a]["n_sats"] >= 4 for a in infos)


def test_reading_settings_change_the_city_and_are_checked() -> None:
    from coopnav_env.sim.osm_city import helsinki_geojson_path

    city = f"geojson:{helsinki_geojson_path()}"
    tall = make_config(city=city, city_default_height_m=40.0, city_storey_height_m=4.0)
    low = make_config(city=city)
    from coopnav_env.sim.scenario import make_city

    rng = np.random.default_rng(0)
    h_tall = make_city(tall, rng).buildings.heights_m
    h_low = make_city(low, rng).buildings.heights_m
    defaulted = h_low == 10.0
    assert np.all(h_tall[defaulted] == 40.0) and np.all(h_tall[~defaulted] >= h_low[~defaulted])
    with pytest.raises(ValueError, match=r"city_storey_height_m must be in \[2, 10\] m"):
        make_config(city=city, city_storey_height_m=0.5)
    with pytest.raises(ValueError, match=r"city_default_height_m must be None or in \[1, 500\]"):
        make_config(city=city, city_default_height_m=-1.0)
    with pytest.raises(ValueError, match=r"city_bbox must be \(south_deg, west_deg"):
        make_config(city=city, city_bbox=(60.2, 24.9, 60.1))
    with pytest.raises(ValueError, match="city_default_height_m needs city='geojson:PATH'"):
        make_config(city="grid", city_default_height_m=20.0)
    with pytest.raises(ValueError, match="city_repair must be True or False"):
        make_config(city=city, city_repair="yes")


@pytest.mark.parametrize("brackets", ["()", "[]"])
def test_env_set_takes_lat_lon_tuples_as_users_write_them(brackets: str) -> None:
    from coopnav_env.training.config import apply_overrides

    city = load_file_city(sample_city_path(), alt_m=make_config(**CITY).alt_m, warn=False)
    lat, lon = (round(v, 6) for v in city.xy_to_lat_lon(city.nearest_free_xy([0.0, 0.0])))
    written = f"{brackets[0]}{lat}, {lon}{brackets[1]}"
    kwargs = apply_overrides({}, ["city=geojson:sample", f"city_goal_lat_lon={written}"])
    assert make_config(**kwargs).city_goal_lat_lon == (lat, lon)


def test_the_route_frame_flies_a_file_city_with_the_room_of_each_leg() -> None:
    from coopnav_env import urban_canyon_v1
    from coopnav_env.envs.urban_canyon import route_frame_command, route_offset_room_m
    from coopnav_env.sim.osm_city import helsinki_geojson_path

    env = urban_canyon_v1.parallel_env(
        city=f"geojson:{helsinki_geojson_path()}", action_frame="route", n_uavs=3
    )
    env.reset(seed=2)  # a file city has no single street width: no refusal
    city, route, cfg = env.world.city, env.world.route_xy_m, env.config
    cap = env._route_offset_cap_m
    assert cap.shape == (route.shape[0],)
    assert np.all((cap >= 0.0) & (cap <= cfg.route_offset_max_m))
    for i in range(1, route.shape[0]):  # the offset keeps the UAV's radius + 1 m off the walls
        pts = np.linspace(route[i - 1], route[i], 50)
        _, wall_m = city.buildings.sky_and_walls(
            np.column_stack([pts, np.full(50, 1.0)]), np.arange(0.0, 360.0, 15.0)
        )
        assert cap[i] + cfg.kinematics.uav_radius_m + 1.0 <= wall_m.min() + city.resolution_m
    assert np.all(route_offset_room_m(city, route, cfg) == cap)
    # the command aims at most cap[wp] to the side of the leg
    est = np.column_stack([route[[1, 1, 1]], np.full(3, 15.0)])
    wp = np.array([1, 1, 1])
    act = np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    free = route_frame_command(act, est, wp, route, cfg)
    capped = route_frame_command(act, est, wp, route, cfg, offset_max_m=cap[wp])
    assert np.allclose(capped[2], free[2])  # no offset asked: the same command
    if cap[1] < cfg.route_offset_max_m:
        assert not np.allclose(capped[0], free[0])
    rng = np.random.default_rng(2)
    for _ in range(20):
        obs, *_ = env.step({a: rng.uniform(-1.0, 1.0, 3) for a in env.agents})
        if not env.agents:
            break
    assert all(np.all(np.isfinite(o)) for o in obs.values())
