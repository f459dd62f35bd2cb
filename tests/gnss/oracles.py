"""Numpy oracles of the GNSS measurement kernels (:mod:`coopnav_env.gnss._kernels`).

The library computes the receiver-satellite geometry and the pseudorange error model in
compiled loops only; the functions here are their readable numpy definitions, which the
tests compare with them. The geometry agrees to a few units in the last place (numpy's
transcendental functions here, libm's in the kernel); the ranges agree bit for bit.
:func:`use_gnss_oracles` puts them in place of the kernels for end-to-end comparisons.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from coopnav_env.gnss import errors as _errors
from coopnav_env.gnss.errors import ErrorModel, _iono_factors, _sigma_user
from coopnav_env.gnss.frames import _azimuth_elevation, _line_of_sight

__all__ = ["pseudorange_model", "range_azimuth_elevation", "use_gnss_oracles"]


def range_azimuth_elevation(
    rx: NDArray[np.float64], sv: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Range [m], azimuth [deg] and elevation [deg] of every (receiver, satellite) pair,
    ``(n_rx, n_sv)`` each: ``frames.line_of_sight`` then ``frames.azimuth_elevation``
    (the definition of ``errors._range_azimuth_elevation``)."""
    unit, range_m = _line_of_sight(rx, sv)
    az_deg, el_deg = _azimuth_elevation(rx, unit)
    return range_m, az_deg, el_deg


def pseudorange_model(
    z_common: NDArray[np.float64],
    z_user: NDArray[np.float64],
    range_m: NDArray[np.float64],
    el_deg: NDArray[np.float64],
    sys_idx: NDArray[np.intp],
    vis: NDArray[np.bool_],
    model: ErrorModel,
    clock: NDArray[np.float64],
    extra: NDArray[np.float64],
    el_ref: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], ...]:
    """``sigma_common, sigma_user, common_error, user_error, pr`` of one epoch (Eq. 1-8): the
    numpy definition of ``errors._pseudorange_model`` (same arguments, same results)."""
    if el_ref is None:
        el_ref = el_deg.mean(axis=0)
    # model.sigma_common_m(el_ref) and model.sigma_user_m(el_deg, sys_idx), unchecked
    sigma_common = model._sigma_common(el_ref)
    sigma_user = _sigma_user(el_deg, _iono_factors(model)[sys_idx])
    common_error = sigma_common * z_common
    user_error = sigma_user * z_user
    pr = range_m + clock[:, sys_idx] + common_error[None, :] + user_error + extra
    pr = np.where(vis, pr, np.nan)
    return sigma_common, sigma_user, common_error, user_error, pr


def use_gnss_oracles(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Make :func:`coopnav_env.gnss.errors._simulate_pseudoranges` (and every caller of the
    two functions it calls) run the oracles above instead of the compiled kernels.

    Returns a dict counting the calls of each oracle, so that a test can check they ran.
    """
    calls = {"range_azimuth_elevation": 0, "pseudorange_model": 0}

    def geometry(rx, sv):
        calls["range_azimuth_elevation"] += 1
        return range_azimuth_elevation(rx, sv)

    def errors_model(*args):
        calls["pseudorange_model"] += 1
        return pseudorange_model(*args)

    monkeypatch.setattr(_errors, "_range_azimuth_elevation", geometry)
    monkeypatch.setattr(_errors, "_pseudorange_model", errors_model)
    return calls
