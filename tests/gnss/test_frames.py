"""Tests for coopnav_env.gnss.frames, checked against pymap3d (WGS 84)."""

from __future__ import annotations

import numpy as np
import pymap3d
import pytest

from coopnav_env.constants import SHANGHAI_ALT_M, SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG
from coopnav_env.gnss.frames import (
    azimuth_elevation,
    cov_ecef_to_enu,
    cov_enu_to_ecef,
    direction_enu,
    ecef_to_enu,
    ecef_to_geodetic,
    enu_rotation,
    enu_to_ecef,
    geodetic_to_ecef,
    line_of_sight,
)

N_POINTS = 2000


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240601)


def _random_geodetic(rng: np.random.Generator, n: int, alt_lo: float, alt_hi: float):
    lat = rng.uniform(-90.0, 90.0, n)
    lon = rng.uniform(-180.0, 180.0, n)
    alt = rng.uniform(alt_lo, alt_hi, n)
    return lat, lon, alt


def _wrap180(angle_deg: np.ndarray) -> np.ndarray:
    return (angle_deg + 180.0) % 360.0 - 180.0


@pytest.mark.parametrize(("alt_lo", "alt_hi"), [(-1e4, 1e4), (1e4, 2e6), (2e6, 4.5e7)])
def test_geodetic_to_ecef_matches_pymap3d(rng, alt_lo, alt_hi):
    lat, lon, alt = _random_geodetic(rng, N_POINTS, alt_lo, alt_hi)
    got = geodetic_to_ecef(lat, lon, alt)
    x, y, z = pymap3d.geodetic2ecef(lat, lon, alt)
    assert got.shape == (N_POINTS, 3)
    np.testing.assert_allclose(got, np.stack([x, y, z], axis=-1), rtol=0, atol=1e-6)


@pytest.mark.parametrize(("alt_lo", "alt_hi"), [(-1e4, 1e4), (1e4, 2e6), (2e6, 4.5e7)])
def test_ecef_to_geodetic_round_trip(rng, alt_lo, alt_hi):
    lat, lon, alt = _random_geodetic(rng, N_POINTS, alt_lo, alt_hi)
    lat2, lon2, alt2 = ecef_to_geodetic(geodetic_to_ecef(lat, lon, alt))
    np.testing.assert_allclose(lat2, lat, rtol=0, atol=1e-9)
    np.testing.assert_allclose(_wrap180(lon2 - lon), 0.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(alt2, alt, rtol=0, atol=1e-6)


def test_ecef_to_geodetic_matches_pymap3d(rng):
    # pymap3d's closed form loses latitude accuracy far above the surface (about 2e-7 deg
    # at 1000 km), so it is used as a reference only up to 100 km; the round trip above
    # covers MEO/GEO heights.
    pos = geodetic_to_ecef(*_random_geodetic(rng, N_POINTS, -1e4, 1e5))
    lat, lon, alt = ecef_to_geodetic(pos)
    lat_ref, lon_ref, alt_ref = pymap3d.ecef2geodetic(pos[:, 0], pos[:, 1], pos[:, 2])
    np.testing.assert_allclose(lat, lat_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(_wrap180(lon - lon_ref), 0.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(alt, alt_ref, rtol=0, atol=1e-6)


def test_ecef_to_geodetic_poles_and_equator():
    lat, _, alt = ecef_to_geodetic(geodetic_to_ecef([90.0, -90.0, 0.0], [0.0, 0.0, 0.0], 100.0))
    np.testing.assert_allclose(lat, [90.0, -90.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(alt, 100.0, atol=1e-6)


def test_ecef_to_geodetic_shapes():
    lat, lon, alt = ecef_to_geodetic(np.full((2, 4, 3), 7e6))
    assert lat.shape == lon.shape == alt.shape == (2, 4)
    lat0, _, _ = ecef_to_geodetic([7e6, 0.0, 0.0])
    assert np.ndim(lat0) == 0


def test_geodetic_to_ecef_broadcasts():
    out = geodetic_to_ecef(np.zeros((4, 1)), np.zeros((1, 5)), 0.0)
    assert out.shape == (4, 5, 3)


def test_enu_rotation_is_orthonormal_with_expected_rows():
    rot = enu_rotation(np.linspace(-90, 90, 7)[:, None], np.linspace(-180, 180, 5)[None, :])
    assert rot.shape == (7, 5, 3, 3)
    eye = np.broadcast_to(np.eye(3), rot.shape)
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), eye, atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-14)
    r0 = enu_rotation(0.0, 0.0)  # at (0, 0): E = +y, N = +z, U = +x
    np.testing.assert_allclose(r0, [[0, 1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-15)


def test_ecef_enu_match_pymap3d_and_round_trip(rng):
    lat0, lon0, alt0 = SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M
    lat, lon, alt = _random_geodetic(rng, N_POINTS, -1e3, 3e7)
    pos = geodetic_to_ecef(lat, lon, alt)
    enu = ecef_to_enu(pos, lat0, lon0, alt0)
    e, n, u = pymap3d.ecef2enu(pos[:, 0], pos[:, 1], pos[:, 2], lat0, lon0, alt0)
    np.testing.assert_allclose(enu, np.stack([e, n, u], axis=-1), rtol=0, atol=1e-6)
    back = enu_to_ecef(enu, lat0, lon0, alt0)
    np.testing.assert_allclose(back, pos, rtol=0, atol=1e-6)
    x, y, z = pymap3d.enu2ecef(enu[:, 0], enu[:, 1], enu[:, 2], lat0, lon0, alt0)
    np.testing.assert_allclose(back, np.stack([x, y, z], axis=-1), rtol=0, atol=1e-6)


def test_ecef_to_enu_with_per_point_origins(rng):
    lat0, lon0, alt0 = _random_geodetic(rng, 50, 0.0, 1e3)
    pos = geodetic_to_ecef(*_random_geodetic(rng, 50, 0.0, 1e5))
    enu = ecef_to_enu(pos, lat0, lon0, alt0)
    e, n, u = pymap3d.ecef2enu(pos[:, 0], pos[:, 1], pos[:, 2], lat0, lon0, alt0)
    np.testing.assert_allclose(enu, np.stack([e, n, u], axis=-1), rtol=0, atol=1e-6)
    np.testing.assert_allclose(enu_to_ecef(enu, lat0, lon0, alt0), pos, rtol=0, atol=1e-6)


def test_origin_maps_to_zero_enu():
    origin = geodetic_to_ecef(SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M)
    enu = ecef_to_enu(origin, SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M)
    np.testing.assert_allclose(enu, 0.0, atol=1e-8)
    up = enu_to_ecef([0.0, 0.0, 100.0], SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M)
    lat, lon, alt = ecef_to_geodetic(up)
    np.testing.assert_allclose([lat, lon, alt], [SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, 110.0])


def test_covariance_rotation(rng):
    a = rng.standard_normal((10, 3, 3))
    cov_ecef = a @ np.swapaxes(a, -1, -2)
    lat0 = rng.uniform(-90, 90, 10)
    lon0 = rng.uniform(-180, 180, 10)
    cov_enu = cov_ecef_to_enu(cov_ecef, lat0, lon0)
    rot = enu_rotation(lat0, lon0)
    np.testing.assert_allclose(cov_enu, rot @ cov_ecef @ np.swapaxes(rot, -1, -2), atol=1e-12)
    np.testing.assert_allclose(
        np.trace(cov_enu, axis1=-2, axis2=-1), np.trace(cov_ecef, axis1=-2, axis2=-1)
    )
    np.testing.assert_allclose(cov_enu_to_ecef(cov_enu, lat0, lon0), cov_ecef, atol=1e-12)
    # Outer product of a displacement transforms like the displacement itself.
    d_ecef = rng.standard_normal(3)
    d_enu = rot[0] @ d_ecef
    got = cov_ecef_to_enu(np.outer(d_ecef, d_ecef), lat0[0], lon0[0])
    np.testing.assert_allclose(got, np.outer(d_enu, d_enu), atol=1e-12)


def test_line_of_sight_shapes_and_values():
    rx = np.array([[6.4e6, 0.0, 0.0], [0.0, 6.4e6, 0.0]])
    sv = np.array([[2.64e7, 0.0, 0.0], [0.0, 0.0, 2.0e7], [1e7, 1e7, 1e7]])
    unit, rng_m = line_of_sight(rx, sv)
    assert unit.shape == (2, 3, 3)
    assert rng_m.shape == (2, 3)
    np.testing.assert_allclose(np.linalg.norm(unit, axis=-1), 1.0)
    np.testing.assert_allclose(rng_m[0, 0], 2.0e7)
    np.testing.assert_allclose(unit[0, 0], [1.0, 0.0, 0.0])  # toward the satellite
    np.testing.assert_allclose(
        rx[:, None, :] + unit * rng_m[..., None], np.broadcast_to(sv, unit.shape)
    )


def test_azimuth_elevation_matches_pymap3d(rng):
    lat, lon, alt = _random_geodetic(rng, 20, -100.0, 1e4)
    rx = geodetic_to_ecef(lat, lon, alt)
    sv = geodetic_to_ecef(*_random_geodetic(rng, 40, 1.9e7, 3.6e7))
    az, el = azimuth_elevation(rx, sv)
    assert az.shape == el.shape == (20, 40)
    az_ref, el_ref, srange = pymap3d.ecef2aer(
        sv[None, :, 0], sv[None, :, 1], sv[None, :, 2], lat[:, None], lon[:, None], alt[:, None]
    )
    np.testing.assert_allclose(el, el_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(_wrap180(az - az_ref), 0.0, rtol=0, atol=1e-9)
    assert np.all((az >= 0.0) & (az < 360.0))
    np.testing.assert_allclose(line_of_sight(rx, sv)[1], srange, rtol=0, atol=1e-6)


def test_direction_enu_consistent_with_azimuth_elevation(rng):
    lat0, lon0, alt0 = SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M
    rx = geodetic_to_ecef(lat0, lon0, alt0)[None, :]
    sv = geodetic_to_ecef(*_random_geodetic(rng, 30, 2e7, 2.1e7))
    az, el = azimuth_elevation(rx, sv)
    enu = ecef_to_enu(sv, lat0, lon0, alt0)
    np.testing.assert_allclose(
        direction_enu(az[0], el[0]), enu / np.linalg.norm(enu, axis=-1, keepdims=True), atol=1e-12
    )
    np.testing.assert_allclose(direction_enu(0.0, 90.0), [0.0, 0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(direction_enu(90.0, 0.0), [1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(
        direction_enu([0.0, 180.0], 0.0), [[0, 1, 0], [0, -1, 0]], atol=1e-15
    )


def test_inputs_are_not_modified(rng):
    rx = geodetic_to_ecef(*_random_geodetic(rng, 3, 0.0, 10.0))
    sv = geodetic_to_ecef(*_random_geodetic(rng, 5, 2e7, 2.1e7))
    rx0, sv0 = rx.copy(), sv.copy()
    azimuth_elevation(rx, sv)
    line_of_sight(rx, sv)
    ecef_to_geodetic(rx)
    ecef_to_enu(sv, 10.0, 20.0, 0.0)
    enu_to_ecef(sv, 10.0, 20.0, 0.0)
    np.testing.assert_array_equal(rx, rx0)
    np.testing.assert_array_equal(sv, sv0)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: geodetic_to_ecef(91.0, 0.0, 0.0), "lat_deg"),
        (lambda: geodetic_to_ecef(np.nan, 0.0, 0.0), "lat_deg"),
        (lambda: geodetic_to_ecef(0.0, np.inf, 0.0), "lon_deg"),
        (lambda: ecef_to_geodetic(np.zeros((4, 2))), r"pos_ecef_m.*\(\.\.\., 3\)"),
        (lambda: ecef_to_geodetic([0.0, 0.0, 0.0]), "centre"),
        (lambda: ecef_to_geodetic([np.nan, 1.0, 2.0]), "pos_ecef_m"),
        (lambda: ecef_to_enu(np.zeros(2), 0.0, 0.0, 0.0), "pos_ecef_m"),
        (lambda: enu_to_ecef(np.zeros(3), -95.0, 0.0, 0.0), "lat_deg"),
        (lambda: cov_ecef_to_enu(np.eye(2), 0.0, 0.0), "cov_ecef"),
        (lambda: cov_enu_to_ecef(np.full((3, 3), np.nan), 0.0, 0.0), "cov_enu"),
        (lambda: line_of_sight(np.zeros(3), np.ones((2, 3))), r"rx_ecef_m.*\(n, 3\)"),
        (lambda: line_of_sight(np.ones((1, 3)), np.ones((2, 3))), "zero range"),
        (lambda: azimuth_elevation(np.ones((1, 3)), np.ones((2, 4))), "sv_ecef_m"),
        (lambda: direction_enu(0.0, 100.0), "el_deg"),
    ],
)
def test_bad_inputs_raise(call, match):
    with pytest.raises(ValueError, match=match):
        call()
