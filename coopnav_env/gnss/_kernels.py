"""Compiled (numba) receiver-satellite geometry of :mod:`coopnav_env.gnss.frames`.

:func:`range_azimuth_elevation` computes, per (receiver, satellite) pair, what
``frames._line_of_sight`` followed by ``frames._azimuth_elevation`` compute for a whole array:
the range, and the azimuth and elevation in the receiver's ENU frame (whose latitude and
longitude it also computes, as ``frames._ecef_to_geodetic`` does). The numpy formulation is
the reference (``tests/gnss/oracles.py``); the two agree to a few units in the last place
(the transcendental functions are libm's here and numpy's there), which the tests bound.

:func:`pseudorange_model` computes the error model and pseudoranges of
``errors._simulate_pseudoranges`` (Eq. 1-8) from an epoch's geometry, its random draws
(:class:`ErrorDraws`) and the error budget (:class:`ErrorBudget`); its numpy formulation is
the oracle ``pseudorange_model`` of ``tests/gnss/oracles.py``, to the same few ulps.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def range_azimuth_elevation(rx, sv, a_m, b_m, f, e2, ep2, n_bowring, azimuth=True):
    """Range [m], azimuth [deg, 0..360) and elevation [deg] of every (receiver, satellite).

    ``rx`` (n, 3) and ``sv`` (s, 3) ECEF [m]. The ENU frame of each receiver comes from its
    geodetic latitude and longitude (Bowring's iteration with ``n_bowring`` steps on the
    ellipsoid ``a_m, b_m, f, e2, ep2``, as ``frames._ecef_to_geodetic``). Returns
    ``range_m, az_deg, el_deg`` (n, s) and two flags: a receiver at the Earth's centre (no
    latitude) and a zero range (receiver on a satellite); the caller raises for them. With
    ``azimuth`` False the azimuths are not computed (``az_deg`` is NaN; the ranges and
    elevations are the same): a caller that reads none saves an ``arctan2`` per pair.
    """
    n = rx.shape[0]
    s = sv.shape[0]
    range_m = np.empty((n, s))
    az = np.empty((n, s))
    el = np.empty((n, s))
    to_deg = 180.0 / np.pi
    at_centre = False
    zero_range = False
    for i in range(n):
        x, y, z = rx[i, 0], rx[i, 1], rx[i, 2]
        p = np.hypot(x, y)
        if p == 0.0 and z == 0.0:
            at_centre = True
        lon = np.arctan2(y, x)
        beta = np.arctan2(z, (1.0 - f) * p)
        lat = beta
        for _ in range(n_bowring):
            lat = np.arctan2(z + ep2 * b_m * np.sin(beta) ** 3, p - e2 * a_m * np.cos(beta) ** 3)
            beta = np.arctan2((1.0 - f) * np.sin(lat), np.cos(lat))
        sl, cl = np.sin(lat), np.cos(lat)
        so, co = np.sin(lon), np.cos(lon)
        for k in range(s):
            d0 = sv[k, 0] - x
            d1 = sv[k, 1] - y
            d2 = sv[k, 2] - z
            r = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            range_m[i, k] = r
            if r == 0.0:
                zero_range = True
            u0 = d0 / r
            u1 = d1 / r
            u2 = d2 / r
            # rows of the ECEF-to-ENU rotation (frames.enu_rotation)
            e = -so * u0 + co * u1 + 0.0 * u2
            nn = -sl * co * u0 + -sl * so * u1 + cl * u2
            up = cl * co * u0 + cl * so * u1 + sl * u2
            if azimuth:
                a = np.arctan2(e, nn) * to_deg
                a = a % 360.0
                if a >= 360.0:
                    a -= 360.0
                az[i, k] = a
            else:
                az[i, k] = np.nan
            el[i, k] = np.arcsin(min(max(up, -1.0), 1.0)) * to_deg
    return range_m, az, el, at_centre, zero_range


class ErrorDraws(NamedTuple):
    """The random draws and biases of an epoch's pseudoranges (:func:`pseudorange_model`)."""

    clock: np.ndarray  # (N, n_sys) receiver clock bias per constellation [m]
    z_common: np.ndarray  # (S,) standard normal draws of the errors common to all receivers
    z_user: np.ndarray  # (N, S) those of each receiver's own errors
    extra: np.ndarray  # (N, S) extra (unmodelled, e.g. NLOS) bias [m]


class ErrorBudget(NamedTuple):
    """The error budget the sigmas are computed from (:func:`pseudorange_model`; the
    kernel's form of ``errors.ErrorModel``)."""

    factors: np.ndarray  # (n_sys,) iono-free noise amplification per constellation (Eq. 8)
    el_ref: np.ndarray  # (S,) elevation of the common error [deg], NaN: mean over receivers
    sigma_ure: float  # clock/ephemeris sigma [m] (Eq. 4)
    tropo: bool  # include the residual troposphere (Eq. 5) in the common error
    differential: bool  # differential corrections: no common error (sigma 0)


@njit(cache=True, error_model="numpy")
def pseudorange_model(range_m, el, sys_idx, vis, draws, budget):
    """The error model and pseudoranges of ``errors._simulate_pseudoranges`` (Eq. 1-8).

    Takes the geometry ``range_m`` [m] and ``el`` [deg] (N, S), the constellation index
    ``sys_idx`` (S,) int64 and the received flags ``vis`` (N, S) bool, and the records
    :class:`ErrorDraws` and :class:`ErrorBudget` (each may come as a plain tuple of its
    fields).

    ``el_ref`` NaN entries: the common error's elevation is the mean over the receivers (the
    numpy formulation's default). Sigmas: common ``hypot(sigma_URE, sigma_tropo(el_ref))``
    (0 with differential correction), receiver ``factor_sys * hypot(sigma_MP(el),
    sigma_noise(el))``; ``pr = range + clock + sigma_common z_common + sigma_user z_user +
    extra`` where received, NaN elsewhere. Returns ``sigma_common, sigma_user, common_error,
    user_error, pr``.
    """
    clock, z_common, z_user, extra = draws
    factors, el_ref, ure, tropo, differential = budget
    n, s = el.shape
    sigma_common = np.empty(s)
    common_error = np.empty(s)
    for k in range(s):
        e = el_ref[k]
        if e != e:
            acc = el[0, k]
            for i in range(1, n):
                acc += el[i, k]
            e = acc / n
        if differential:
            sc = 0.0
        else:
            t = 0.0
            if tropo:
                sn = np.sin(np.pi * e / 180.0)
                t = 0.12 * 1.001 / np.sqrt(0.002001 + sn * sn)
            sc = np.hypot(ure, t)
        sigma_common[k] = sc
        common_error[k] = sc * z_common[k]
    sigma_user = np.empty((n, s))
    user_error = np.empty((n, s))
    pr = np.empty((n, s))
    for i in range(n):
        for k in range(s):
            x = el[i, k]
            mp = 0.13 + 0.53 * np.exp(-x / 10.0)
            noise = 0.15 + 0.43 * np.exp(-x / 6.9)
            su = factors[sys_idx[k]] * np.hypot(mp, noise)
            sigma_user[i, k] = su
            ue = su * z_user[i, k]
            user_error[i, k] = ue
            if vis[i, k]:
                pr[i, k] = range_m[i, k] + clock[i, sys_idx[k]] + common_error[k] + ue + extra[i, k]
            else:
                pr[i, k] = np.nan
    return sigma_common, sigma_user, common_error, user_error, pr
