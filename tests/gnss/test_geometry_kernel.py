"""The compiled receiver-satellite geometry agrees with the numpy formulation."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.gnss import default_constellation, errors
from coopnav_env.gnss.frames import geodetic_to_ecef


@pytest.fixture
def numpy_geometry(monkeypatch):
    def run(rx, sv):
        monkeypatch.setattr(errors, "_USE_KERNEL", False)
        try:
            return errors._range_azimuth_elevation(rx, sv)
        finally:
            monkeypatch.setattr(errors, "_USE_KERNEL", True)

    return run


def test_kernel_matches_numpy_everywhere_on_earth(numpy_geometry) -> None:
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
        rng_n, az_n, el_n = numpy_geometry(rx, sv)
        np.testing.assert_array_equal(rng_k, rng_n)  # same operations, same order
        assert np.all((az_k >= 0.0) & (az_k < 360.0))
        d_az = np.abs(az_k - az_n)
        # libm vs numpy transcendental functions: a few ulps of 360 deg, amplified by at most
        # 1/cos(el) for azimuth; elevation near +-90 deg through arcsin's steep end
        assert np.minimum(d_az, 360.0 - d_az).max() < 1e-9
        assert np.abs(el_k - el_n).max() < 1e-9


def test_zero_range_is_still_an_error() -> None:
    sv = np.array([[7e6, 0.0, 0.0], [0.0, 2.6e7, 0.0]])
    with pytest.raises(ValueError, match="zero range"):
        errors._range_azimuth_elevation(np.array([[7e6, 0.0, 0.0]]), sv)


def test_earth_centre_is_still_an_error() -> None:
    sv = np.array([[2.6e7, 0.0, 0.0]])
    with pytest.raises(ValueError, match="Earth's centre"):
        errors._range_azimuth_elevation(np.zeros((1, 3)), sv)
