"""Tests for coopnav_env.gnss.constellation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from coopnav_env.constants import (
    GM_EARTH_M3PS2,
    OMEGA_EARTH_RADPS,
    SHANGHAI_ALT_M,
    SHANGHAI_LAT_DEG,
    SHANGHAI_LON_DEG,
)
from coopnav_env.gnss.constellation import (
    BDS_MEO_A_M,
    GEOSYNC_A_M,
    GPS_A_M,
    Constellation,
    beidou3_constellation,
    default_constellation,
    gps_nominal_constellation,
    select_highest,
)
from coopnav_env.gnss.frames import azimuth_elevation, ecef_to_geodetic, geodetic_to_ecef

DAY_S = 86_400.0
GEO_IDX = np.arange(24, 27)
IGSO_IDX = np.arange(27, 30)


def _rot_z(angle_rad: float) -> np.ndarray:
    """Frame rotation about z: coordinates in a frame turned by +angle."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def test_gps_nominal_layout():
    gps = gps_nominal_constellation()
    assert gps.n_sv == 24
    assert gps.prn[0] == "G01"
    assert gps.prn[-1] == "G24"
    np.testing.assert_array_equal(gps.system, 0)
    np.testing.assert_allclose(gps.semi_major_axis_m, 26_559_700.0)
    np.testing.assert_allclose(np.degrees(gps.inclination_rad), 55.0)
    np.testing.assert_allclose(np.degrees(gps.raan_rad[:4]), 272.847)  # plane A
    np.testing.assert_allclose(np.degrees(gps.arg_lat_rad[0]), 268.126)  # A1
    np.testing.assert_allclose(np.degrees(gps.gha0_rad), 279.06)  # 18h 36m 14.4s


def test_beidou_layout():
    meo = beidou3_constellation()
    assert meo.n_sv == 24
    np.testing.assert_array_equal(meo.system, 1)
    raan_deg = np.degrees(meo.raan_rad).reshape(3, 8)
    np.testing.assert_allclose(raan_deg, np.array([[0.0], [120.0], [240.0]]) + np.zeros(8))
    u_deg = np.degrees(meo.arg_lat_rad).reshape(3, 8)
    np.testing.assert_allclose(np.diff(u_deg, axis=1) % 360.0, 45.0)  # 8 per plane
    np.testing.assert_allclose((u_deg[1:, 0] - u_deg[:-1, 0]) % 360.0, 15.0)  # Walker F = 1
    full = beidou3_constellation(include_geo_igso=True)
    assert full.n_sv == 30
    assert full.prn[-1] == "C30"
    np.testing.assert_allclose(full.semi_major_axis_m[24:], GEOSYNC_A_M)
    np.testing.assert_allclose(np.degrees(full.inclination_rad[GEO_IDX]), 0.0)
    np.testing.assert_allclose(np.degrees(full.inclination_rad[IGSO_IDX]), 55.0)


@pytest.mark.parametrize("build", [gps_nominal_constellation, lambda: beidou3_constellation(True)])
def test_orbit_radius_equals_semi_major_axis(build):
    const = build()
    pos = const.positions_ecef(np.linspace(0.0, DAY_S, 50))
    radius_m = np.linalg.norm(pos, axis=-1)
    assert radius_m.shape == (50, const.n_sv)
    np.testing.assert_allclose(
        radius_m, np.broadcast_to(const.semi_major_axis_m, radius_m.shape), rtol=1e-13
    )


@pytest.mark.parametrize(
    ("build", "a_m"), [(gps_nominal_constellation, GPS_A_M), (beidou3_constellation, BDS_MEO_A_M)]
)
def test_period_is_keplerian(build, a_m):
    const = build()
    period_s = 2.0 * np.pi * np.sqrt(a_m**3 / GM_EARTH_M3PS2)
    assert 11.9 * 3600 < period_s < 14.2 * 3600
    t0 = 1234.5
    pos0, pos1 = const.positions_ecef(np.array([t0, t0 + period_s]))
    # After one period the satellite is back at the same inertial point; in ECEF the
    # Earth has turned by OMEGA_EARTH * period.
    np.testing.assert_allclose(pos1, pos0 @ _rot_z(OMEGA_EARTH_RADPS * period_s).T, atol=1e-5)
    half = const.positions_ecef(t0 + 0.5 * period_s)
    assert np.all(np.linalg.norm(half - pos0, axis=-1) > 1.9 * a_m * 0.5)


def test_gps_speed():
    gps = gps_nominal_constellation()
    t = 5000.0
    pos0, pos1 = gps.positions_ecef(np.array([t, t + 1.0]))
    v_ecef = pos1 - pos0  # m over 1 s
    mid = 0.5 * (pos0 + pos1)
    v_inertial = v_ecef + np.cross([0.0, 0.0, OMEGA_EARTH_RADPS], mid)  # add back Earth rotation
    # Inertial circular speed sqrt(GM / a) = 3.874 km/s ("about 3.9 km/s").
    np.testing.assert_allclose(np.linalg.norm(v_inertial, axis=-1), 3874.0, atol=1.0)
    np.testing.assert_allclose(
        np.linalg.norm(v_inertial, axis=-1), np.sqrt(GM_EARTH_M3PS2 / GPS_A_M), atol=1e-3
    )
    # Earth-fixed speed is lower: between about 2.76 and 3.19 km/s depending on latitude.
    speed_ecef = np.linalg.norm(v_ecef, axis=-1)
    assert np.all((speed_ecef > 2.7e3) & (speed_ecef < 3.3e3))


def test_geo_is_fixed_in_ecef():
    geo = beidou3_constellation(include_geo_igso=True).subset(GEO_IDX)
    pos = geo.positions_ecef(np.linspace(0.0, 3600.0, 13))
    assert np.max(np.linalg.norm(pos - pos[0], axis=-1)) < 1.0
    lat, lon, alt = ecef_to_geodetic(pos[0])
    np.testing.assert_allclose(lat, 0.0, atol=1e-9)
    np.testing.assert_allclose(lon, [80.0, 110.5, 140.0], atol=1e-9)
    np.testing.assert_allclose(alt, 35_786e3, atol=1e3)


def test_igso_ascending_nodes_at_118e():
    igso = beidou3_constellation(include_geo_igso=True).subset(IGSO_IDX)
    n_radps = np.sqrt(GM_EARTH_M3PS2 / igso.semi_major_axis_m**3)
    t_node = ((-igso.arg_lat_rad) % (2 * np.pi)) / n_radps  # u(t_node) = 0
    pos = igso.positions_ecef(t_node)[np.arange(3), np.arange(3)]
    lat, lon, _ = ecef_to_geodetic(pos)
    np.testing.assert_allclose(lat, 0.0, atol=1e-9)
    np.testing.assert_allclose(lon, 118.0, atol=1e-9)
    np.testing.assert_allclose(np.sort(t_node) / 3600.0, [0.0, 7.98, 15.96], atol=0.01)


def _counts_above(const: Constellation, mask_deg: float = 10.0) -> np.ndarray:
    rx = geodetic_to_ecef(SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M)[None, :]
    pos = const.positions_ecef(np.arange(0.0, DAY_S, 300.0))  # (n_t, n_sv, 3)
    _, el = azimuth_elevation(rx, pos.reshape(-1, 3))
    return (el.reshape(pos.shape[:2]) > mask_deg).sum(axis=1)


@pytest.mark.parametrize("build", [gps_nominal_constellation, beidou3_constellation])
def test_visible_count_at_shanghai(build):
    counts = _counts_above(build())
    assert counts.min() >= 4
    assert counts.max() <= 12
    assert np.mean((counts >= 6) & (counts <= 12)) > 0.9


def test_geo_igso_visible_from_shanghai():
    full = beidou3_constellation(include_geo_igso=True)
    assert np.all(_counts_above(full.subset(GEO_IDX)) == 3)
    assert np.all(_counts_above(full.subset(IGSO_IDX)) >= 2)


def test_vectorised_time_matches_scalar_calls():
    const = default_constellation(bds_geo_igso=True)
    t = np.array([0.0, 17.0, 3600.0, 1e6])
    pos = const.positions_ecef(t)
    assert pos.shape == (4, const.n_sv, 3)
    assert const.positions_ecef(17.0).shape == (const.n_sv, 3)
    assert const.positions_ecef(np.float64(17.0)).shape == (const.n_sv, 3)
    np.testing.assert_allclose(
        pos, np.stack([const.positions_ecef(tk) for tk in t]), rtol=0, atol=1e-9
    )
    assert const.positions_ecef(np.array([])).shape == (0, const.n_sv, 3)


def test_default_constellation_systems():
    both = default_constellation()
    assert both.n_sv == 48
    np.testing.assert_array_equal(both.system, np.repeat([0, 1], 24))
    assert default_constellation(("BDS",)).prn[0] == "C01"
    assert default_constellation(("BDS", "GPS")).system[0] == 1
    assert default_constellation(bds_geo_igso=True).n_sv == 54
    with pytest.raises(ValueError, match="unknown system 'GLONASS'"):
        default_constellation(("GPS", "GLONASS"))
    with pytest.raises(ValueError, match="at least one"):
        default_constellation(())
    with pytest.raises(ValueError, match="repeat"):
        default_constellation(("GPS", "GPS"))


def test_subset_and_concatenate():
    gps = gps_nominal_constellation()
    bds = beidou3_constellation()
    both = gps + bds
    assert both.n_sv == 48
    assert both.prn[24] == "C01"
    np.testing.assert_array_equal(Constellation.concatenate(gps, bds).system, both.system)
    mask = np.zeros(48, dtype=bool)
    mask[[3, 30]] = True
    sub = both.subset(mask)
    assert sub.prn == ("G04", "C07")
    np.testing.assert_allclose(sub.positions_ecef(100.0), both.positions_ecef(100.0)[[3, 30]])
    assert both.subset([30, 3]).prn == ("C07", "G04")
    assert both.subset(np.array([], dtype=int)).n_sv == 0
    with pytest.raises(ValueError, match="prn labels must be unique"):
        gps + gps
    with pytest.raises(ValueError, match="mask_or_indices"):
        both.subset([48])
    with pytest.raises(ValueError, match="mask_or_indices"):
        both.subset(np.ones(3, dtype=bool))


def test_constellation_is_immutable():
    gps = gps_nominal_constellation()
    with pytest.raises(dataclasses.FrozenInstanceError):
        gps.semi_major_axis_m = np.zeros(24)  # type: ignore[misc]
    with pytest.raises(ValueError):
        gps.raan_rad[0] = 1.0


def _fields(n: int = 2, **override):
    fields = dict(
        system=np.zeros(n, dtype=int),
        prn=tuple(f"G{k + 1:02d}" for k in range(n)),
        semi_major_axis_m=np.full(n, GPS_A_M),
        inclination_rad=np.full(n, 0.9),
        raan_rad=np.zeros(n),
        arg_lat_rad=np.zeros(n),
        gha0_rad=np.zeros(n),
    )
    fields.update(override)
    return fields


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"system": np.array([0, 2])}, "system"),
        ({"semi_major_axis_m": np.array([GPS_A_M, 6.0e6])}, "semi_major_axis_m"),
        ({"inclination_rad": np.array([0.1, 4.0])}, "inclination_rad"),
        ({"raan_rad": np.zeros(3)}, "raan_rad"),
        ({"arg_lat_rad": np.array([0.0, np.nan])}, "arg_lat_rad"),
        ({"prn": ("G01", "G01")}, "unique"),
    ],
)
def test_constellation_validation(override, match):
    Constellation(**_fields())  # baseline is valid
    with pytest.raises(ValueError, match=match):
        Constellation(**_fields(**override))


def test_positions_bad_time():
    gps = gps_nominal_constellation()
    with pytest.raises(ValueError, match="t_s"):
        gps.positions_ecef(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="t_s"):
        gps.positions_ecef(np.nan)


def test_select_highest():
    el = np.array([[10.0, 50.0, 30.0, 50.0, 80.0], [5.0, np.nan, 20.0, 20.0, 20.0]])
    vis = np.array([[True, True, True, True, False], [True, False, True, True, True]])
    el0, vis0 = el.copy(), vis.copy()
    keep = select_highest(el, vis, 2)
    np.testing.assert_array_equal(
        keep, [[False, True, False, True, False], [False, False, True, True, False]]
    )  # invisible 80 deg ignored; ties to the lower index
    np.testing.assert_array_equal(el, el0)
    np.testing.assert_array_equal(vis, vis0)
    np.testing.assert_array_equal(select_highest(el, vis, 10), vis)
    assert not select_highest(el, vis, 0).any()
    assert select_highest(el, vis, 3).sum(axis=1).tolist() == [3, 3]


def test_select_highest_random_is_subset_with_highest():
    rng = np.random.default_rng(5)
    el = rng.uniform(-10, 90, (50, 40))
    vis = el > 10.0
    keep = select_highest(el, vis, 10)
    assert np.all(keep <= vis)
    np.testing.assert_array_equal(keep.sum(axis=1), np.minimum(vis.sum(axis=1), 10))
    lowest_kept = np.where(keep, el, np.inf).min(axis=1)
    highest_dropped = np.where(vis & ~keep, el, -np.inf).max(axis=1)
    assert np.all(lowest_kept > highest_dropped)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.zeros(3), np.ones(3, dtype=bool), 2), "el_deg"),
        ((np.zeros((2, 3)), np.ones((2, 2), dtype=bool), 2), "visible"),
        ((np.zeros((2, 3)), np.ones((2, 3), dtype=bool), -1), "max_sats"),
        ((np.zeros((2, 3)), np.ones((2, 3), dtype=bool), 2.5), "max_sats"),
        ((np.full((2, 3), np.nan), np.ones((2, 3), dtype=bool), 2), "NaN"),
        ((np.full((2, 3), 95.0), np.ones((2, 3), dtype=bool), 2), "el_deg"),
    ],
)
def test_select_highest_bad_inputs(args, match):
    with pytest.raises(ValueError, match=match):
        select_highest(*args)


def test_default_constellation_is_built_once_per_arguments():
    """Every world of a configuration shares one constellation: it is immutable."""
    first = default_constellation(("GPS", "BDS"))
    assert default_constellation(["GPS", "BDS"]) is first
    assert default_constellation(("BDS", "GPS")) is not first
    assert default_constellation(("GPS", "BDS"), bds_geo_igso=True) is not first
    assert default_constellation("GPS") is default_constellation(("GPS",))
    for name in ("system", "semi_major_axis_m", "raan_rad", "arg_lat_rad", "gha0_rad"):
        assert not getattr(first, name).flags.writeable, name
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.prn = ()  # type: ignore[misc]
    with pytest.raises(ValueError, match="must not repeat"):
        default_constellation(("GPS", "GPS"))
