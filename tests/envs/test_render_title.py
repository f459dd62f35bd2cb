"""The title of a rendered frame: the environment's own id and the GNSS time (UTC time of day
for a sky from a navigation file)."""

from __future__ import annotations

import datetime as dt
import re
import types
import warnings

import pytest

from coopnav_env import urban_canyon_v0, urban_canyon_v1
from coopnav_env.envs.render import gnss_time_text

pytest.importorskip("matplotlib")


def _title(env) -> str:
    """The first line of the frame's title, as ``render()`` draws it (Figure.text recorded)."""
    from matplotlib.figure import Figure

    texts: list[str] = []
    draw = Figure.text

    def record(self, x, y, s, *args, **kwargs):
        texts.append(str(s))
        return draw(self, x, y, s, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Figure, "text", record)
        frame = env.render()
    assert frame.ndim == 3 and frame.dtype.name == "uint8"
    return texts[0]


def test_title_names_the_environment_it_renders() -> None:
    env = urban_canyon_v1.parallel_env(n_uavs=2, render_mode="rgb_array")
    env.reset(seed=0)
    title = _title(env)
    assert title.startswith("urban_canyon_v1  ·  grid city  ·  2 UAVs  ·  step 0 / 200")
    assert re.search(r"GNSS t = \d+ s$", title), title  # the nominal sky: its clock's seconds
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        legacy = urban_canyon_v0.parallel_env(n_uavs=2, render_mode="rgb_array")
    legacy.reset(seed=0)
    assert _title(legacy).startswith("urban_canyon_v0  ·  ")


def test_title_of_a_file_sky_shows_the_utc_time_of_day() -> None:
    """The sample file's sky at 2026-12-03 06:00:00 UTC (GPS - UTC = 18 s then) and two steps
    of 1 s later: the title shows 06:00:02 UTC."""
    env = urban_canyon_v1.parallel_env(
        n_uavs=2,
        render_mode="rgb_array",
        constellation="rinex:sample",
        constellation_start="2026-12-03T06:00:00Z",
    )
    env.reset(seed=0)
    for _ in range(2):
        env.step({a: env.action_space(a).sample() * 0 for a in env.agents})
    title = _title(env)
    assert title.startswith("urban_canyon_v1  ·  ")
    assert title.endswith("GNSS 06:00:02 UTC"), title


def test_gnss_time_text_counts_leap_seconds_and_days() -> None:
    """GPS time less the leap seconds of its date: 18 s in 2026, 17 s in 2016 (before the
    leap second of 2017-01-01), the time of day only."""
    gps_epoch = dt.datetime(1980, 1, 6)

    def sky_at(utc: dt.datetime, leap_s: int) -> types.SimpleNamespace:
        return types.SimpleNamespace(reference_gps_s=(utc - gps_epoch).total_seconds() + leap_s)

    assert gnss_time_text(sky_at(dt.datetime(2026, 12, 3, 8, 0, 0), 18), 47.0) == (
        "GNSS 08:00:47 UTC"
    )
    assert gnss_time_text(sky_at(dt.datetime(2016, 6, 1, 23, 59, 50), 17), 15.0) == (
        "GNSS 00:00:05 UTC"
    )
    assert gnss_time_text(object(), 115247.4) == "GNSS t = 115247 s"
