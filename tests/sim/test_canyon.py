"""The paper's analytic canyon mask (Eq. 25) and its 3-D counterpart, canyon_city."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.sim import DEFAULT_CANYON_GAPS_DEG, CanyonMask, canyon_city, line_of_sight


def _dirs(az_deg: np.ndarray, el_deg: np.ndarray) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)


def test_eq25_values() -> None:
    m = CanyonMask(gaps_deg=())
    np.testing.assert_allclose(m.mask_elevation_deg([0.0, 180.0, 360.0]), 0.0, atol=1e-12)
    np.testing.assert_allclose(m.mask_elevation_deg([90.0, 270.0]), 60.0)  # atan(sqrt(3))
    phi = np.linspace(0, 360, 73)
    expected = np.degrees(np.abs(np.arctan(math.sqrt(3) * np.sin(np.radians(phi)))))
    np.testing.assert_allclose(m.mask_elevation_deg(phi), expected)
    # phi is measured from the street axis: rotating the street rotates the mask
    rot = CanyonMask(street_azimuth_deg=30.0, gaps_deg=())
    np.testing.assert_allclose(rot.mask_elevation_deg(phi + 30.0), expected, atol=1e-12)
    assert m.mask_elevation_deg(np.zeros((2, 3))).shape == (2, 3)


def test_gaps_and_visibility() -> None:
    m = CanyonMask()  # default gaps
    assert m.gaps_deg == DEFAULT_CANYON_GAPS_DEG
    a0, a1 = DEFAULT_CANYON_GAPS_DEG[0]
    mid = (a0 + a1) / 2
    assert m.mask_elevation_deg(mid) == 0.0
    assert m.in_gap(mid) and not m.in_gap(90.0)
    assert m.visible(mid, 1.0) and not m.visible(90.0, 59.0) and m.visible(90.0, 61.0)
    assert not m.visible(0.0, 0.0)  # the horizon is never visible (el > mask >= 0)
    vis = m.visible(np.array([[mid], [90.0]]), np.array([10.0, 70.0]))
    np.testing.assert_array_equal(vis, [[True, True], [False, True]])
    # a gap through North wraps around
    wrap = CanyonMask(street_azimuth_deg=90.0, gaps_deg=((350.0, 10.0),))
    np.testing.assert_array_equal(wrap.in_gap([355.0, 5.0, 0.0, 20.0, 340.0]), [1, 1, 1, 0, 0])
    assert wrap.mask_elevation_deg(5.0) == 0.0 and wrap.mask_elevation_deg(20.0) > 50.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"h_over_d": -1.0}, r"CanyonMask\.h_over_d must be in \[0\.0, inf\], got -1\.0"),
        ({"h_over_d": float("nan")}, r"CanyonMask\.h_over_d"),
        ({"street_azimuth_deg": 360.0}, r"CanyonMask\.street_azimuth_deg .*\[0\.0, 360\.0\)"),
        ({"gaps_deg": ((10.0, 400.0),)}, r"CanyonMask\.gaps_deg must be in \[0\.0, 360\.0\]"),
        ({"gaps_deg": ((10.0, 10.0),)}, r"CanyonMask\.gaps_deg interval .* is empty"),
        ({"gaps_deg": ((1.0, 2.0, 3.0),)}, r"CanyonMask\.gaps_deg entries must be"),
        ({"gaps_deg": 5}, r"CanyonMask\.gaps_deg must be a tuple"),
    ],
)
def test_canyon_mask_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CanyonMask(**kwargs)


def test_canyon_city_geometry() -> None:
    city = canyon_city()
    b = city.buildings
    roof = 15.0 + math.sqrt(3) * 10.0
    np.testing.assert_allclose(b.heights_m, roof)
    assert b.n == 4  # each row cut once by its gap
    np.testing.assert_allclose(
        np.sort(np.abs(np.r_[b.min_m[:, 0], b.max_m[:, 0]])), [10] * 4 + [30] * 4
    )
    assert city.canyon_mask == CanyonMask(math.sqrt(3), 0.0, DEFAULT_CANYON_GAPS_DEG)
    np.testing.assert_array_equal(city.street_centres_x_m, [0.0])
    assert city.street_centres_y_m.size == 0 and city.open_squares.shape == (0, 2)
    assert city.config is None and city.street_width_m == 20.0
    # the east gap is where the wall is seen under azimuths 50-70 deg from the origin
    east = b.min_m[:, 0] > 0
    ys = np.sort(np.r_[b.min_m[east, 1], b.max_m[east, 1]])
    np.testing.assert_allclose(
        ys[1:3], [10 / math.tan(math.radians(70)), 10 / math.tan(math.radians(50))]
    )
    pts = city.random_street_points(np.random.default_rng(0), 200)
    assert np.all(np.abs(pts[:, 0]) <= 8.0) and not city.is_inside_building(pts).any()
    assert canyon_city(gaps_deg=()).buildings.n == 2


@pytest.mark.parametrize("z_m", [15.0, 5.0, 25.0])
@pytest.mark.parametrize("y_m", [0.0, 60.0])
def test_canyon_city_los_matches_eq25_on_the_centre_line(z_m: float, y_m: float) -> None:
    city = canyon_city(gaps_deg=())  # no gaps: the analytic mask without gaps
    d = city.street_width_m / 2
    h_over_d = (city.buildings.heights_m[0] - z_m) / d
    analytic = CanyonMask(h_over_d=h_over_d, street_azimuth_deg=0.0, gaps_deg=())
    rng = np.random.default_rng(int(z_m + y_m))
    az = rng.uniform(0, 360, 3000)
    el = rng.uniform(0.5, 89.5, 3000)
    mask = analytic.mask_elevation_deg(az)
    # away from the mask boundary, and where the ray meets the walls before the canyon ends
    keep = (np.abs(el - mask) > 0.5) & (np.abs(np.sin(np.radians(az))) > 0.1)
    az, el = az[keep], el[keep]
    los = line_of_sight(city.buildings, np.array([[0.0, y_m, z_m]]), _dirs(az, el))[0]
    np.testing.assert_array_equal(los, analytic.visible(az, el))
    assert 0.2 < los.mean() < 0.8
    # the skyline of the boxes is Eq. 25 itself
    sky = city.mask_elevation_deg(np.array([[0.0, y_m, z_m]]), az)[0]
    np.testing.assert_allclose(sky, analytic.mask_elevation_deg(az), atol=1e-9)


def test_canyon_city_gap_lets_satellites_through() -> None:
    city = canyon_city()
    pos = np.array([[0.0, 0.0, 15.0]])
    no_gap = CanyonMask(gaps_deg=())
    # azimuth 60 (middle of the east gap), elevation 52: the wall of Eq. 25 (56.3 deg) would
    # block it, the gap lets it through (its side walls only block below ~46 deg)
    assert not no_gap.visible(60.0, 52.0)
    assert city.line_of_sight(pos, _dirs(np.array([60.0]), np.array([52.0])))[0, 0]
    assert city.canyon_mask is not None and city.canyon_mask.visible(60.0, 52.0)
    # away from the gaps, 3-D and analytic agree
    assert not city.line_of_sight(pos, _dirs(np.array([120.0]), np.array([50.0])))[0, 0]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"h_over_d": 0.0}, r"canyon_city\.h_over_d must be in \(0\.0, 100\.0\]"),
        ({"street_width_m": -2.0}, r"canyon_city\.street_width_m"),
        ({"length_m": 0.0}, r"canyon_city\.length_m"),
        ({"building_depth_m": 0.0}, r"canyon_city\.building_depth_m"),
        ({"reference_altitude_m": -1.0}, r"canyon_city\.reference_altitude_m"),
        ({"gaps_deg": ((170.0, 190.0),)}, r"canyon_city\.gaps_deg interval .* one side"),
        ({"gaps_deg": ((350.0, 10.0),)}, r"canyon_city\.gaps_deg interval .* one side"),
    ],
)
def test_canyon_city_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        canyon_city(**kwargs)
