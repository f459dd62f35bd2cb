"""Coordinate frames: WGS 84 geodetic, ECEF and local East-North-Up (ENU).

Conventions
-----------
* Angles in degrees, distances in metres; the unit is part of every name.
* Geodetic coordinates are on the WGS 84 ellipsoid (``coopnav_env.constants``).
* The ENU frame at a point has E along increasing longitude, N along increasing
  latitude and U along the ellipsoid normal. ``enu_rotation`` returns the matrix
  ``R`` whose rows are the E, N, U unit vectors in ECEF, so ``d_enu = R @ d_ecef``
  and ``d_ecef = R.T @ d_enu``.
* Azimuth is clockwise from north in ``[0, 360)`` deg, elevation in ``[-90, 90]``
  deg above the local (ellipsoidal) horizon, as in ``pymap3d.ecef2aer``.

All functions broadcast over leading dimensions, never modify their inputs and
raise ``ValueError`` on wrong shapes, non-finite values or latitudes outside
``[-90, 90]`` deg.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.constants import WGS84_A_M, WGS84_B_M, WGS84_E2, WGS84_F
from coopnav_env.gnss._validate import (
    as_elevation_deg,
    as_float_array,
    as_latitude_deg,
    as_point_list,
    as_points,
)

__all__ = [
    "azimuth_elevation",
    "cov_ecef_to_enu",
    "cov_enu_to_ecef",
    "direction_enu",
    "ecef_to_enu",
    "ecef_to_geodetic",
    "enu_rotation",
    "enu_to_ecef",
    "geodetic_to_ecef",
    "line_of_sight",
]

_EP2: float = WGS84_E2 / (1.0 - WGS84_E2)
"""WGS 84 second eccentricity squared [-]."""

_N_BOWRING_ITER: int = 4
"""Bowring iterations in ``ecef_to_geodetic`` (converges to < 1e-12 rad from LEO to GEO)."""


def geodetic_to_ecef(
    lat_deg: ArrayLike, lon_deg: ArrayLike, alt_m: ArrayLike
) -> NDArray[np.float64]:
    """Convert WGS 84 geodetic coordinates to ECEF.

    Parameters
    ----------
    lat_deg : array_like, shape (...)
        Geodetic latitude [deg], in ``[-90, 90]``.
    lon_deg : array_like, shape (...)
        Longitude [deg].
    alt_m : array_like, shape (...)
        Height above the ellipsoid [m].

    Returns
    -------
    ndarray, shape (..., 3)
        ECEF position [m]; the leading shape is the broadcast of the three inputs.
    """
    lat = np.radians(as_latitude_deg(lat_deg, "lat_deg"))
    lon = np.radians(as_float_array(lon_deg, "lon_deg"))
    alt = as_float_array(alt_m, "alt_m")
    sin_lat = np.sin(lat)
    cos_lat = np.cos(lat)
    n_m = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat**2)  # prime-vertical radius
    x = (n_m + alt) * cos_lat * np.cos(lon)
    y = (n_m + alt) * cos_lat * np.sin(lon)
    z = (n_m * (1.0 - WGS84_E2) + alt) * sin_lat
    x, y, z = np.broadcast_arrays(x, y, z)
    return np.stack([x, y, z], axis=-1)


def ecef_to_geodetic(
    pos_ecef_m: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Convert ECEF positions to WGS 84 geodetic coordinates.

    Uses Bowring's (1976) parametric-latitude iteration with a fixed number of
    steps (vectorised, no data-dependent loop); the error is below 1e-9 m in
    height and 1e-12 deg in latitude for heights from -10 km to beyond GEO.

    Parameters
    ----------
    pos_ecef_m : array_like, shape (..., 3)
        ECEF position [m]. Must not be the Earth's centre.

    Returns
    -------
    lat_deg : ndarray, shape (...)
        Geodetic latitude [deg], in ``[-90, 90]``.
    lon_deg : ndarray, shape (...)
        Longitude [deg], in ``(-180, 180]``.
    alt_m : ndarray, shape (...)
        Height above the ellipsoid [m].
    """
    return _ecef_to_geodetic(as_points(pos_ecef_m, "pos_ecef_m"))


def _ecef_to_geodetic(pos: NDArray[np.float64]):
    """:func:`ecef_to_geodetic` of a validated float array of shape (..., 3)."""
    x, y, z = pos[..., 0], pos[..., 1], pos[..., 2]
    p_m = np.hypot(x, y)
    if np.any((p_m == 0.0) & (z == 0.0)):
        raise ValueError("pos_ecef_m contains the Earth's centre [0, 0, 0], which has no latitude")
    lon = np.arctan2(y, x)
    # Parametric (reduced) latitude, initial guess from a sphere scaled by (1 - f).
    beta = np.arctan2(z, (1.0 - WGS84_F) * p_m)
    lat = beta
    for _ in range(_N_BOWRING_ITER):  # fixed count, vectorised over all points
        lat = np.arctan2(
            z + _EP2 * WGS84_B_M * np.sin(beta) ** 3,
            p_m - WGS84_E2 * WGS84_A_M * np.cos(beta) ** 3,
        )
        beta = np.arctan2((1.0 - WGS84_F) * np.sin(lat), np.cos(lat))
    sin_lat = np.sin(lat)
    # Height formula valid at all latitudes, poles included.
    alt = p_m * np.cos(lat) + z * sin_lat - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    return np.degrees(lat), np.degrees(lon), alt


def enu_rotation(lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrix from ECEF to local ENU.

    Parameters
    ----------
    lat_deg : array_like, shape (...)
        Geodetic latitude of the ENU origin [deg].
    lon_deg : array_like, shape (...)
        Longitude of the ENU origin [deg].

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R`` with rows the E, N, U unit vectors expressed in ECEF, so that
        ``d_enu = R @ d_ecef``. Leading shape is the broadcast of the inputs.
    """
    return _enu_rotation(as_latitude_deg(lat_deg, "lat_deg"), as_float_array(lon_deg, "lon_deg"))


def _enu_rotation(lat_deg: NDArray[np.float64], lon_deg: NDArray[np.float64]):
    """:func:`enu_rotation` of validated float arrays."""
    lat = np.radians(lat_deg)
    lon = np.radians(lon_deg)
    lat, lon = np.broadcast_arrays(lat, lon)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    zero = np.zeros_like(lat)
    east = np.stack([-so, co, zero], axis=-1)
    north = np.stack([-sl * co, -sl * so, cl], axis=-1)
    up = np.stack([cl * co, cl * so, sl], axis=-1)
    return np.stack([east, north, up], axis=-2)


def ecef_to_enu(
    pos_ecef_m: ArrayLike, lat0_deg: ArrayLike, lon0_deg: ArrayLike, alt0_m: ArrayLike
) -> NDArray[np.float64]:
    """Express ECEF positions in the ENU frame of a geodetic origin.

    Parameters
    ----------
    pos_ecef_m : array_like, shape (..., 3)
        ECEF position [m].
    lat0_deg, lon0_deg, alt0_m : array_like, shape broadcastable to (...)
        Geodetic origin of the ENU frame [deg, deg, m].

    Returns
    -------
    ndarray, shape (..., 3)
        Position relative to the origin in ENU [m].
    """
    pos = as_points(pos_ecef_m, "pos_ecef_m")
    origin = geodetic_to_ecef(lat0_deg, lon0_deg, alt0_m)
    rot = enu_rotation(lat0_deg, lon0_deg)
    return (rot @ (pos - origin)[..., None])[..., 0]


def enu_to_ecef(
    pos_enu_m: ArrayLike, lat0_deg: ArrayLike, lon0_deg: ArrayLike, alt0_m: ArrayLike
) -> NDArray[np.float64]:
    """Convert ENU positions relative to a geodetic origin back to ECEF.

    Parameters
    ----------
    pos_enu_m : array_like, shape (..., 3)
        Position in the ENU frame of the origin [m].
    lat0_deg, lon0_deg, alt0_m : array_like, shape broadcastable to (...)
        Geodetic origin of the ENU frame [deg, deg, m].

    Returns
    -------
    ndarray, shape (..., 3)
        ECEF position [m].
    """
    pos = as_points(pos_enu_m, "pos_enu_m")
    origin = geodetic_to_ecef(lat0_deg, lon0_deg, alt0_m)
    rot_t = np.swapaxes(enu_rotation(lat0_deg, lon0_deg), -1, -2)
    return (rot_t @ pos[..., None])[..., 0] + origin


def _as_cov(cov: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = as_float_array(cov, name)
    if arr.ndim < 2 or arr.shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (..., 3, 3), got shape {arr.shape}")
    return arr


def cov_ecef_to_enu(
    cov_ecef: ArrayLike, lat0_deg: ArrayLike, lon0_deg: ArrayLike
) -> NDArray[np.float64]:
    """Rotate a position covariance from ECEF to the local ENU frame.

    Parameters
    ----------
    cov_ecef : array_like, shape (..., 3, 3)
        Covariance in ECEF [m^2].
    lat0_deg, lon0_deg : array_like, shape broadcastable to (...)
        Geodetic latitude and longitude of the ENU frame [deg].

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R @ cov_ecef @ R.T`` [m^2].
    """
    cov = _as_cov(cov_ecef, "cov_ecef")
    rot = enu_rotation(lat0_deg, lon0_deg)
    return rot @ cov @ np.swapaxes(rot, -1, -2)


def cov_enu_to_ecef(
    cov_enu: ArrayLike, lat0_deg: ArrayLike, lon0_deg: ArrayLike
) -> NDArray[np.float64]:
    """Rotate a position covariance from the local ENU frame to ECEF.

    Parameters
    ----------
    cov_enu : array_like, shape (..., 3, 3)
        Covariance in ENU [m^2].
    lat0_deg, lon0_deg : array_like, shape broadcastable to (...)
        Geodetic latitude and longitude of the ENU frame [deg].

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R.T @ cov_enu @ R`` [m^2].
    """
    cov = _as_cov(cov_enu, "cov_enu")
    rot = enu_rotation(lat0_deg, lon0_deg)
    return np.swapaxes(rot, -1, -2) @ cov @ rot


def line_of_sight(
    rx_ecef_m: ArrayLike, sv_ecef_m: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Line-of-sight unit vectors and geometric ranges (paper Eq. 2).

    Parameters
    ----------
    rx_ecef_m : array_like, shape (n_rx, 3)
        Receiver ECEF positions [m].
    sv_ecef_m : array_like, shape (n_sv, 3)
        Satellite ECEF positions [m].

    Returns
    -------
    unit_ecef : ndarray, shape (n_rx, n_sv, 3)
        Unit vectors in ECEF pointing from each receiver TOWARD each satellite [-].
    range_m : ndarray, shape (n_rx, n_sv)
        Euclidean distance ``d_r^k`` [m] (paper Eq. 2).
    """
    rx = as_point_list(rx_ecef_m, "rx_ecef_m")
    sv = as_point_list(sv_ecef_m, "sv_ecef_m")
    return _line_of_sight(rx, sv)


def _line_of_sight(rx: NDArray[np.float64], sv: NDArray[np.float64]):
    """:func:`line_of_sight` of validated ``(n_rx, 3)`` and ``(n_sv, 3)`` float arrays."""
    diff = sv[None, :, :] - rx[:, None, :]
    range_m = np.linalg.norm(diff, axis=-1)
    if np.any(range_m == 0.0):
        raise ValueError("line_of_sight: a receiver coincides with a satellite (zero range)")
    return diff / range_m[..., None], range_m


def azimuth_elevation(
    rx_ecef_m: ArrayLike, sv_ecef_m: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Azimuth and elevation of each satellite seen from each receiver.

    Parameters
    ----------
    rx_ecef_m : array_like, shape (n_rx, 3)
        Receiver ECEF positions [m].
    sv_ecef_m : array_like, shape (n_sv, 3)
        Satellite ECEF positions [m].

    Returns
    -------
    az_deg : ndarray, shape (n_rx, n_sv)
        Azimuth clockwise from geodetic north, in ``[0, 360)`` [deg].
    el_deg : ndarray, shape (n_rx, n_sv)
        Elevation above the receiver's ellipsoidal horizon, in ``[-90, 90]`` [deg].
    """
    unit, _ = line_of_sight(rx_ecef_m, sv_ecef_m)
    return _azimuth_elevation(np.asarray(rx_ecef_m, dtype=np.float64), unit)


def _azimuth_elevation(rx: NDArray[np.float64], unit: NDArray[np.float64]):
    """:func:`azimuth_elevation` from validated receivers and their line-of-sight unit vectors
    (the first output of :func:`line_of_sight`, which the caller may already have)."""
    lat, lon, _ = _ecef_to_geodetic(rx)
    rot = _enu_rotation(lat, lon)  # (n_rx, 3, 3)
    enu = np.einsum("rij,rsj->rsi", rot, unit)
    az = np.degrees(np.arctan2(enu[..., 0], enu[..., 1])) % 360.0
    az = np.where(az >= 360.0, az - 360.0, az)  # -tiny % 360 rounds to 360.0
    el = np.degrees(np.arcsin(np.clip(enu[..., 2], -1.0, 1.0)))
    return az, el


def direction_enu(az_deg: ArrayLike, el_deg: ArrayLike) -> NDArray[np.float64]:
    """Unit vector in ENU for an azimuth/elevation direction.

    Parameters
    ----------
    az_deg : array_like, shape (...)
        Azimuth clockwise from north [deg].
    el_deg : array_like, shape (...)
        Elevation above the horizon [deg], in ``[-90, 90]``.

    Returns
    -------
    ndarray, shape (..., 3)
        ``[cos(el) sin(az), cos(el) cos(az), sin(el)]`` [-].
    """
    az = np.radians(as_float_array(az_deg, "az_deg"))
    el = np.radians(as_elevation_deg(el_deg, "el_deg"))
    az, el = np.broadcast_arrays(az, el)
    cos_el = np.cos(el)
    return np.stack([cos_el * np.sin(az), cos_el * np.cos(az), np.sin(el)], axis=-1)
