"""The environment under a sky from a RINEX navigation file (``constellation="rinex:..."``)."""

from __future__ import annotations

import datetime as dt
import pickle
import shutil
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

from coopnav_env import GYM_ENV_ID, urban_canyon_v0
from coopnav_env.envs import make_config
from coopnav_env.gnss.rinex import (
    SAMPLE_NAV_PATH,
    BroadcastConstellation,
    RinexWarning,
    clear_caches,
)
from coopnav_env.sim.scenario import ScenarioConfig, UrbanWorld

SKY = {"constellation": "rinex:sample"}
# 2026-12-03 06:00:00 UTC = 06:00:18 GPST, inside the sample's coverage
START_UTC = "2026-12-03T06:00:00Z"
START_GPS_S = (dt.date(2026, 12, 3) - dt.date(1980, 1, 6)).days * 86400 + 6 * 3600 + 18


def _episode(env, seed: int, steps: int) -> list:
    out = [env.reset(seed=seed)]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        if not env.agents:
            break
        out.append(env.step({a: rng.uniform(-0.5, 0.5, 3) for a in env.agents}))
    return out


def test_parallel_api_and_seed_tests_pass() -> None:
    parallel_api_test(urban_canyon_v0.parallel_env(**SKY), num_cycles=100)
    parallel_seed_test(lambda: urban_canyon_v0.parallel_env(city="canyon", **SKY), num_cycles=30)


@pytest.mark.slow
def test_pettingzoo_render_test_passes(monkeypatch) -> None:
    pytest.importorskip("matplotlib")
    from pettingzoo.test import render_test

    monkeypatch.setenv("MPLBACKEND", "Agg")  # "human" frames go to a window-less backend
    render_test(lambda render_mode=None: urban_canyon_v0.env(render_mode=render_mode, **SKY))


def test_gymnasium_checker_passes() -> None:
    env = gymnasium.make(GYM_ENV_ID, **SKY)
    assert isinstance(env.unwrapped.par_env.world.constellation, BroadcastConstellation)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(env.unwrapped)
    assert not caught, [str(w.message) for w in caught]


def test_same_seed_same_episode_bit_for_bit_and_starts_drawn_in_the_coverage() -> None:
    env1 = urban_canyon_v0.parallel_env(**SKY)
    env2 = urban_canyon_v0.parallel_env(**SKY)
    a, b = _episode(env1, 11, 15), _episode(env2, 11, 15)
    assert pickle.dumps(a) == pickle.dumps(b)  # bit for bit, infos included
    sky = env1.world.constellation
    lo, hi = sky.coverage_s
    starts = []
    for seed in range(6):
        env1.reset(seed=seed)
        starts.append(env1.world.t_s)
    horizon = env1.config.max_steps * env1.config.dt_s
    assert all(lo <= t <= hi - horizon for t in starts)
    assert len(set(starts)) == len(starts)  # drawn per episode
    # the satellites in view are the file's, and change with the start time
    env1.reset(seed=0)
    seen0 = {sky.prn[j] for j in env1.world.last.sv_index}
    env1.reset(seed=1)
    seen1 = {sky.prn[j] for j in env1.world.last.sv_index}
    assert seen0 != seen1 and len(seen0) >= 8
    assert seen0 <= set(sky.prn)


def test_a_given_start_is_used_in_utc_or_gps_seconds() -> None:
    sky = urban_canyon_v0.parallel_env(**SKY).world.constellation
    want = START_GPS_S - sky.reference_gps_s
    for start in (START_UTC, START_GPS_S, float(START_GPS_S), dt.datetime(2026, 12, 3, 6)):
        env = urban_canyon_v0.parallel_env(constellation_start=start, **SKY)
        env.reset(seed=5)
        assert env.world.t_s == want, start
        env.step({a: np.zeros(3) for a in env.agents})
        assert env.world.t_s == want + env.config.dt_s
    cfg = make_config(constellation_start=dt.datetime(2026, 12, 3, 6), **SKY)
    assert cfg.constellation_start == "2026-12-03T06:00:00"  # a datetime is kept as ISO text
    spread = urban_canyon_v0.parallel_env(constellation_start=START_UTC, t0_random_s=600.0, **SKY)
    t = []
    for seed in (1, 2):
        spread.reset(seed=seed)
        t.append(spread.world.t_s)
    assert all(want <= x <= want + 600.0 for x in t) and t[0] != t[1]


def test_the_world_flies_the_files_satellites_at_the_epoch_time() -> None:
    cfg = ScenarioConfig(constellation="rinex:sample", constellation_start=START_UTC, n_uavs=2)
    world = UrbanWorld(cfg)
    epoch = world.reset(np.random.default_rng(0))
    sky = world.constellation
    pos = sky.positions_ecef(epoch.t_s)
    np.testing.assert_array_equal(world._sky(epoch.t_s).sv_ecef, pos[epoch.sv_index])
    # nominal skies are unchanged: the default world still flies the nominal constellations
    assert type(UrbanWorld(ScenarioConfig()).constellation).__name__ == "Constellation"


def test_systems_select_the_files_satellites() -> None:
    env = urban_canyon_v0.parallel_env(systems=("BDS",), **SKY)
    sky = env.world.constellation
    assert sky.n_sv == 30 and all(p.startswith("C") for p in sky.prn)


def test_satellites_without_an_ephemeris_are_not_in_view(tmp_path) -> None:
    """A satellite whose ephemerides stop is not broadcasting: the world leaves it out."""
    lines = SAMPLE_NAV_PATH.read_text().splitlines(keepends=True)
    end = next(k for k, line in enumerate(lines) if "END OF HEADER" in line) + 1
    body = [lines[k : k + 8] for k in range(end, len(lines), 8)]
    # drop every ephemeris of G01 after 02:00 GPST
    kept = [r for r in body if not (r[0].startswith("G01") and r[0][15:17] not in ("00", "02"))]
    path = tmp_path / "gap.rnx"
    path.write_text("".join(lines[:end] + [x for r in kept for x in r]))
    start = START_UTC  # 06:00 UTC: G01's last ephemeris (02:00) ended at 04:00
    cfg = ScenarioConfig(constellation=f"rinex:{path}", constellation_start=start, n_uavs=2)
    world = UrbanWorld(cfg)
    g01 = world.constellation.prn.index("G01")
    epoch = world.reset(np.random.default_rng(0))
    assert np.all(np.isnan(world.constellation.positions_ecef(epoch.t_s)[g01]))
    assert g01 not in epoch.sv_index.tolist()
    assert len(epoch.sv_index) >= 8


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"constellation": "rinex:/nowhere/nav.rnx"}, r"constellation='rinex:/nowhere/nav.rnx'.*"),
        ({"constellation": "rinex:"}, r"constellation must be 'nominal' or 'rinex:PATH'"),
        ({"constellation": "yuma:x.alm"}, r"constellation must be 'nominal' or 'rinex:PATH'"),
        ({"constellation_start": START_UTC}, r"constellation_start needs constellation='rinex"),
        ({**SKY, "t0_s": 10.0}, r"t0_s must be 0 with constellation='rinex:sample'"),
        ({**SKY, "t0_random_s": 10.0}, r"t0_random_s must be 0 with constellation="),
        (
            {**SKY, "constellation_start": "2026-12-05T00:00:00Z"},
            r"constellation_start='2026-12-05T00:00:00Z' .* outside the validity of the "
            r"ephemerides in .*sample_nav.rnx: its coverage is 2026-12-02T23:00:14 GPST to "
            r"2026-12-04T00:00:00 GPST",
        ),
        (
            {**SKY, "constellation_start": "2026-12-03T23:58:00Z", "max_steps": 200},
            r"the episode \(200 s\) reach",
        ),
        ({**SKY, "constellation_start": "tomorrow"}, r"constellation_start: a time must be"),
        ({**SKY, "max_steps": 100_000}, r"an episode spans 100000 s but the file covers only"),
    ],
)
def test_bad_sky_settings_raise_at_construction(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        urban_canyon_v0.parallel_env(**kwargs)


def test_a_bad_file_is_reported_with_its_line(tmp_path) -> None:
    bad = tmp_path / "bad.rnx"
    text = SAMPLE_NAV_PATH.read_text().splitlines(keepends=True)
    assert text[13].startswith("G02 ")  # line 14: the second record's epoch line
    text[13] = "Z" + text[13][1:]
    bad.write_text("".join(text))
    with pytest.raises(ValueError, match=r"bad.rnx, line 14: unknown satellite system 'Z'"):
        urban_canyon_v0.parallel_env(constellation=f"rinex:{bad}")


def test_evaluate_command_line_flies_a_rinex_sky(tmp_path) -> None:
    from coopnav_env.training.cli import main

    nav = tmp_path / "my nav.rnx"
    shutil.copyfile(SAMPLE_NAV_PATH, nav)
    out = tmp_path / "eval"
    args = ["evaluate", "--policies", "formation", "--episodes", "1", "--no-plots"]
    args += ["--env-set", "n_uavs=2", "--env-set", "max_steps=20"]
    args += ["--env-set", f"constellation=rinex:{nav}"]
    args += ["--env-set", f"constellation_start={START_UTC}"]
    args += ["--out", str(out)]
    assert main(args) == 0
    assert (out / "report.json").is_file()
    assert "rinex:" in (out / "report.json").read_text()


# --------------------------------------------------------------------------------------------
# a real station's file
# --------------------------------------------------------------------------------------------

ELKO = (
    Path(__file__).resolve().parents[1] / "gnss" / "data" / "ELKO00USA_R_20182100000_01D_MN.rnx.gz"
)
AT_ELKO = {"lat_deg": 40.91, "lon_deg": -115.74, "alt_m": 1600.0}  # the station


def _rinex_warnings(call):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = call()
    return out, [str(w.message) for w in caught if issubclass(w.category, RinexWarning)]


def test_a_station_file_flies_where_it_is_valid() -> None:
    """Bad records left out with one warning; 20 episodes without a start time all start in
    the file's usable spans, with 4 or more satellites per UAV in the open and a cooperative
    fix on most steps."""
    clear_caches()
    make = lambda: urban_canyon_v0.parallel_env(  # noqa: E731
        constellation=f"rinex:{ELKO}", max_steps=20, **AT_ELKO
    )
    env, messages = _rinex_warnings(make)
    assert len(messages) == 1 and "left out 63 of 331 GPS and BeiDou records" in messages[0]
    sky = env.world.constellation
    spans = sky.visibility(40.91, -115.74, 1600.0, 10.0).spans_s
    horizon = env.config.max_steps * env.config.dt_s
    starts, fixes, steps = [], 0, 0
    for seed in range(20):
        _, infos = env.reset(seed=seed)
        t0 = env.world.t_s
        starts.append(t0)
        assert any(a <= t0 and t0 + horizon <= b for a, b in spans), t0
        assert len(env.world.last.sv_index) >= 4  # above the cut-off at the origin
        assert all(infos[a]["n_sats_open_sky"] >= 4 for a in env.agents)
        while env.agents:
            _, _, _, _, infos = env.step({a: np.zeros(3) for a in env.agents})
            for a in infos:
                fixes += bool(infos[a]["coop_fix"])
                steps += 1
    # a station's sky is thinner than the nominal one (about 10 satellites in the open)
    assert len(set(starts)) == 20 and fixes >= 0.6 * steps, (fixes, steps)
    # the day of the file: 2018-07-29 (GPST), and the evening before
    days = {
        str(dt.datetime(1980, 1, 6) + dt.timedelta(seconds=t + sky.reference_gps_s))[:10]
        for t in starts
    }
    assert days <= {"2018-07-28", "2018-07-29"}


def test_a_station_file_far_from_the_origin_warns() -> None:
    env, messages = _rinex_warnings(
        lambda: urban_canyon_v0.parallel_env(constellation=f"rinex:{ELKO}", max_steps=20)
    )
    far = [m for m in messages if "Fly near the station" in m]
    assert (
        far
        and "at the origin (31.0252, 121.434)" in far[0]
        and "the file holds what its station" in far[0]
    )
    # every episode still starts where 4 satellites are above the cut-off
    for seed in range(5):
        env.reset(seed=seed)
        assert len(env.world.last.sv_index) >= 4
    _, messages = _rinex_warnings(
        lambda: urban_canyon_v0.parallel_env(constellation=f"rinex:{ELKO}", max_steps=20, **AT_ELKO)
    )
    assert not [m for m in messages if "Fly near the station" in m]


def test_gps_only_on_a_mixed_station_file_with_bad_beidou_records() -> None:
    clear_caches()
    env, messages = _rinex_warnings(
        lambda: urban_canyon_v0.parallel_env(
            constellation=f"rinex:{ELKO}", systems=("GPS",), max_steps=20, **AT_ELKO
        )
    )
    assert len(messages) == 1  # the file's BeiDou records are checked too
    _, messages = _rinex_warnings(  # the file is read once for every choice of systems
        lambda: urban_canyon_v0.parallel_env(constellation=f"rinex:{ELKO}", **AT_ELKO)
    )
    assert not messages
    sky = env.world.constellation
    assert sky.n_sv == 31 and all(p.startswith("G") for p in sky.prn)
    env.reset(seed=3)
    assert len(env.world.last.sv_index) >= 4


def test_a_given_start_outside_the_usable_spans_warns() -> None:
    make = lambda start: urban_canyon_v0.parallel_env(  # noqa: E731
        constellation=f"rinex:{ELKO}", constellation_start=start, **AT_ELKO
    )
    # 20:00:14 to 21:00:14 GPST no BeiDou ephemeris is valid
    env, messages = _rinex_warnings(lambda: make("2018-07-29T20:20:00Z"))
    gap = [m for m in messages if "leave the file's usable spans" in m]
    assert len(gap) == 1 and "2018-07-29T20:00:14 GPST, 2018-07-29T21:00:14 GPST" in gap[0]
    env.reset(seed=0)  # flown as asked
    assert not np.any(env.world.constellation.system[env.world.last.sv_index] == 1)
    _, messages = _rinex_warnings(lambda: make("2018-07-29T12:00:00Z"))
    assert not [m for m in messages if "usable spans" in m]


def test_a_file_with_no_usable_stretch_is_refused(tmp_path) -> None:
    lines = SAMPLE_NAV_PATH.read_text().splitlines(keepends=True)
    end = next(k for k, line in enumerate(lines) if "END OF HEADER" in line) + 1
    body = [lines[k : k + 8] for k in range(end, len(lines), 8)]
    kept = [r for r in body if r[0][:3] in ("G01", "G02", "G03")]  # 3 satellites
    path = tmp_path / "three.rnx"
    path.write_text("".join(lines[:end] + [x for r in kept for x in r]))
    with pytest.raises(ValueError, match=r"no 200 s of the file \(an episode\) in which every"):
        urban_canyon_v0.parallel_env(constellation=f"rinex:{path}", systems=("GPS",))
