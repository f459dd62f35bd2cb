"""The skies of many epochs at once (``_sky_epochs``, the look-ahead of file skies) are the
skies of each epoch alone, bit for bit."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.gnss.frames import geodetic_to_ecef
from coopnav_env.gnss.rinex import load_broadcast_constellation
from coopnav_env.sim import scenario as _scenario
from coopnav_env.sim.scenario import _sky_epoch, _sky_epochs

_FIELDS = ("sv_index", "sv_ecef", "system", "system_idx", "az", "el")
_DIRECTION_FIELDS = ("up", "order", "cot_s", "h_dir")


def _assert_same_sky(a, b, where: str) -> None:
    for name in _FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, (where, name)
        assert x.tobytes() == y.tobytes(), (where, name)
    for name in _DIRECTION_FIELDS:
        x, y = getattr(a.directions, name), getattr(b.directions, name)
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), (where, name)
    assert a.directions.n_sv == b.directions.n_sv and a.grouped == b.grouped, where


_STATION_NAV = str(
    Path(__file__).resolve().parents[1] / "gnss" / "data" / "ELKO00USA_R_20182100000_01D_MN.rnx.gz"
)


@pytest.mark.parametrize(
    ("spec", "systems", "lat", "lon"),
    [
        ("igs_brdc", ("GPS",), 31.2304, 121.4737),
        ("igs_brdc", ("GPS",), 43.7311, 7.4197),
        ("sample", ("GPS", "BDS"), 31.2304, 121.4737),
        (_STATION_NAV, ("GPS", "BDS"), 40.84, -115.79),  # a station's file: BeiDou GEO, gaps
    ],
)
def test_sky_epochs_equal_single_epochs_bit_for_bit(spec, systems, lat, lon):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sky = load_broadcast_constellation(spec, systems)
    origin = geodetic_to_ecef(lat, lon, 0.0)
    lo, hi = sky.coverage_s
    rng = np.random.default_rng(7)
    # blocks of 1 s steps from random starts (as an episode meets them), and the coverage's ends
    starts = [lo, hi - 5.0, *rng.uniform(lo, hi - 40.0, 12).tolist()]
    n_checked = 0
    for t0 in starts:
        times = [t0]
        while len(times) < 32 and times[-1] + 1.0 <= hi:
            times.append(times[-1] + 1.0)
        batch = _sky_epochs(sky, origin, 10.0, times)
        assert len(batch) == len(times)
        for t, got in zip(times, batch, strict=True):
            _assert_same_sky(got, _sky_epoch(sky, origin, 10.0, t), f"{spec} t={t}")
            n_checked += 1
    assert n_checked > 300


def test_sky_epochs_drop_satellites_without_a_valid_ephemeris():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sky = load_broadcast_constellation("igs_brdc", ("GPS",))
    origin = geodetic_to_ecef(31.2304, 121.4737, 0.0)
    lo, hi = sky.coverage_s
    times = np.linspace(lo, hi, 40).tolist()
    known = np.isfinite(sky.positions_ecef(np.asarray(times))).all(axis=2)
    assert not known.all()  # the file has satellites that are not broadcasting at some times
    for t, k, got in zip(times, known, _sky_epochs(sky, origin, 10.0, times), strict=True):
        assert set(got.sv_index.tolist()) <= set(np.flatnonzero(k).tolist()), t
        _assert_same_sky(got, _sky_epoch(sky, origin, 10.0, t), f"t={t}")


def test_sky_cache_computes_the_epochs_ahead_once_and_hands_them_over():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sky = load_broadcast_constellation("igs_brdc", ("GPS",))
    origin = geodetic_to_ecef(31.2304, 121.4737, 0.0)
    cache = _scenario._SkyCache(max_size=8, max_ahead=5)
    head = ("test", 10.0)
    first = cache.get((*head, 100.0), sky, origin, [101.0, 102.0, 103.0])
    assert len(cache._ahead) == 3 and len(cache._data) == 1
    second = cache.get((*head, 101.0), sky, origin, [102.0, 103.0, 104.0])
    assert len(cache._ahead) == 2  # taken from the epochs ahead, nothing computed
    _assert_same_sky(first, _sky_epoch(sky, origin, 10.0, 100.0), "t=100")
    _assert_same_sky(second, _sky_epoch(sky, origin, 10.0, 101.0), "t=101")
    # a new episode's epochs push out the oldest waiting ones beyond max_ahead
    cache.get((*head, 5000.0), sky, origin, [5001.0, 5002.0, 5003.0, 5004.0])
    assert len(cache._ahead) == 5
    assert (*head, 5004.0) in cache._ahead and (*head, 102.0) not in cache._ahead
    cache.clear()
    assert not cache._ahead and not cache._data
