"""The compiled receiver-satellite geometry and error model agree with their numpy oracles
(``tests/gnss/oracles.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.gnss import default_constellation, errors
from coopnav_env.gnss.frames import geodetic_to_ecef
from tests.gnss import oracles


def test_kernel_matches_numpy_everywhere_on_earth() -> None:
    sv = default_constellation(("GPS", "BDS")).positions_ecef(1234.0)
    rng = np.random.default_rng(0)
    for _ in range(40):
        lat, lon = rng.uniform(-90.0, 90.0), rng.uniform(-180.0, 180.0)
        rx = geodetic_to_ecef(
            np.clip(lat + rng.normal(0.0, 0.01, 25), -90.0, 90.0),
            lon + rng.normal(0.0, 0.01, 25),
            rng.uniform(-100.0, 2000.0, 25),
        )
        rng_k, az_k, el_k = errors._range_azimuth_elevation(rx, sv)
        rng_n, az_n, el_n = oracles.range_azimuth_elevation(rx, sv)
        np.testing.assert_array_equal(rng_k, rng_n)  # same operations, same order
        assert np.all((az_k >= 0.0) & (az_k < 360.0))
        d_az = np.abs(az_k - az_n)
        # libm vs numpy transcendental functions: a few ulps of 360 deg, amplified by at most
        # 1/cos(el) for azimuth; elevation near +-90 deg through arcsin's steep end
        assert np.minimum(d_az, 360.0 - d_az).max() < 1e-9
        assert np.abs(el_k - el_n).max() < 1e-9


def test_kernel_without_azimuths_keeps_ranges_and_elevations() -> None:
    """``azimuth=False`` (the batched step's call) leaves the ranges, elevations and flags of
    the full call bit for bit, and NaN azimuths."""
    from coopnav_env.constants import WGS84_A_M, WGS84_B_M, WGS84_E2, WGS84_F
    from coopnav_env.gnss import _kernels
    from coopnav_env.gnss.frames import _EP2, _N_BOWRING_ITER

    sv = default_constellation(("GPS", "BDS")).positions_ecef(1234.0)
    rng = np.random.default_rng(1)
    rx = geodetic_to_ecef(
        rng.uniform(-90.0, 90.0, 30), rng.uniform(-180.0, 180.0, 30), rng.uniform(0, 500, 30)
    )
    wgs = (WGS84_A_M, WGS84_B_M, WGS84_F, WGS84_E2, _EP2, _N_BOWRING_ITER)
    full = _kernels.range_azimuth_elevation(rx, sv, *wgs)
    bare = _kernels.range_azimuth_elevation(rx, sv, *wgs, False)
    for i in (0, 2, 3, 4):
        np.testing.assert_array_equal(bare[i], full[i])
    assert np.isnan(bare[1]).all()


def test_zero_range_is_still_an_error() -> None:
    sv = np.array([[7e6, 0.0, 0.0], [0.0, 2.6e7, 0.0]])
    with pytest.raises(ValueError, match="zero range"):
        errors._range_azimuth_elevation(np.array([[7e6, 0.0, 0.0]]), sv)


def test_earth_centre_is_still_an_error() -> None:
    sv = np.array([[2.6e7, 0.0, 0.0]])
    with pytest.raises(ValueError, match="Earth's centre"):
        errors._range_azimuth_elevation(np.zeros((1, 3)), sv)


@pytest.mark.parametrize("differential", [False, True])
@pytest.mark.parametrize("tropo", [True, False])
@pytest.mark.parametrize("with_extra", [False, True])
def test_pseudorange_model_kernel_matches_numpy(monkeypatch, differential, tropo, with_extra):
    """Same draws, same sigmas and pseudoranges to a few ulps (libm exp/sin vs numpy's)."""
    from coopnav_env.gnss import ErrorModel

    model = ErrorModel(differential=differential, tropo=tropo)
    sv = default_constellation(("GPS", "BDS")).positions_ecef(500.0)
    rng = np.random.default_rng(3)
    rx = geodetic_to_ecef(31.2 + rng.normal(0, 0.001, 7), 121.5 + rng.normal(0, 0.001, 7), 20.0)
    _, _, el = errors._range_azimuth_elevation(rx, sv)
    keep = el.min(axis=0) > -5.0
    sv = sv[keep]
    system = default_constellation(("GPS", "BDS")).system[keep].astype(np.intp)
    vis = rng.random((7, sv.shape[0])) > 0.3
    clock = rng.normal(0.0, 3e4, (7, 2))
    extra = rng.uniform(0.0, 20.0, vis.shape) if with_extra else None
    for el_ref in (None, np.full(sv.shape[0], 35.0)):
        fast = errors._simulate_pseudoranges(
            np.random.default_rng(9), rx, sv, system, vis, model, clock, extra, el_ref
        )
        with monkeypatch.context() as m:
            calls = oracles.use_gnss_oracles(m)
            ref = errors._simulate_pseudoranges(
                np.random.default_rng(9), rx, sv, system, vis, model, clock, extra, el_ref
            )
        assert calls == {"range_azimuth_elevation": 1, "pseudorange_model": 1}
        np.testing.assert_array_equal(np.isnan(fast.pr_m), ~vis)
        for name in ("sigma_common_m", "sigma_user_m", "common_error_m", "user_error_m"):
            np.testing.assert_allclose(
                getattr(fast, name), getattr(ref, name), rtol=1e-13, atol=0.0, err_msg=name
            )
        np.testing.assert_allclose(fast.pr_m[vis], ref.pr_m[vis], rtol=1e-15, atol=1e-8)
