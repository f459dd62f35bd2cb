"""Compiled (numba) receiver-satellite geometry of :mod:`coopnav_env.gnss.frames`.

:func:`range_azimuth_elevation` computes, per (receiver, satellite) pair, what
``frames._line_of_sight`` followed by ``frames._azimuth_elevation`` compute for a whole array:
the range, and the azimuth and elevation in the receiver's ENU frame. The numpy formulation is
the reference (``errors._USE_KERNEL = False``); the two agree to a few units in the last place
(the transcendental functions are libm's here and numpy's there), which the tests bound.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def range_azimuth_elevation(rx, sv, rot):
    """Range [m], azimuth [deg, 0..360) and elevation [deg] of every (receiver, satellite).

    ``rx`` (n, 3) and ``sv`` (s, 3) ECEF [m]; ``rot`` (n, 3, 3) the ECEF-to-ENU rotation at
    each receiver (rows E, N, U). A zero range gives NaN angles (the caller reports it).
    """
    n = rx.shape[0]
    s = sv.shape[0]
    range_m = np.empty((n, s))
    az = np.empty((n, s))
    el = np.empty((n, s))
    to_deg = 180.0 / np.pi
    for i in range(n):
        for k in range(s):
            d0 = sv[k, 0] - rx[i, 0]
            d1 = sv[k, 1] - rx[i, 1]
            d2 = sv[k, 2] - rx[i, 2]
            r = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            range_m[i, k] = r
            u0 = d0 / r
            u1 = d1 / r
            u2 = d2 / r
            e = rot[i, 0, 0] * u0 + rot[i, 0, 1] * u1 + rot[i, 0, 2] * u2
            nn = rot[i, 1, 0] * u0 + rot[i, 1, 1] * u1 + rot[i, 1, 2] * u2
            up = rot[i, 2, 0] * u0 + rot[i, 2, 1] * u1 + rot[i, 2, 2] * u2
            a = np.arctan2(e, nn) * to_deg
            a = a % 360.0
            if a >= 360.0:
                a -= 360.0
            az[i, k] = a
            el[i, k] = np.arcsin(min(max(up, -1.0), 1.0)) * to_deg
    return range_m, az, el
