"""3D-mapping-aided NLOS exclusion: the candidate positions and the line-of-sight prediction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.sim import Buildings, CityConfig, generate_city, line_of_sight
from coopnav_env.sim import map_aided as ma
from coopnav_env.sim.city import is_inside_building, sky_directions

BAND = (5.0, 30.0)
# one block east of the UAV: x in [10, 30], roof at 20 m
WALL = Buildings.from_boxes([[10.0, -50.0, 30.0, 50.0, 20.0]])


def _direction(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = math.radians(az_deg), math.radians(el_deg)
    return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


def _cov(sig_e: float, sig_n: float, sig_u: float, rot_deg: float = 0.0) -> np.ndarray:
    c, s = math.cos(math.radians(rot_deg)), math.sin(math.radians(rot_deg))
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return r @ np.diag([sig_e**2, sig_n**2, sig_u**2]) @ r.T


def _predict_from_candidates(buildings, sky, pos, cov, **kw):
    """``predicted_line_of_sight`` through the candidates, the inside test and the line of
    sight (the path of a file city's polygons), for box buildings too."""
    lo, hi = kw["altitude_band_m"]
    return ma._predict_from_candidates(
        buildings, sky, pos, cov, kw["margin_sigma"], kw["max_margin_m"], lo, hi
    )


@pytest.fixture(params=["compiled", "candidates"])
def predict(request):
    """The prediction of box buildings: the compiled call, or through the candidates."""
    if request.param == "compiled":
        return ma.predicted_line_of_sight
    return _predict_from_candidates


def test_candidates_follow_the_covariance() -> None:
    """+-2 sigma along the horizontal principal axes (a 3 x 1 m ellipse turned 30 degrees)
    and the vertical (2 m), each capped at ``max_margin_m``, altitudes clamped to the band;
    a covariance that is not finite gives the cap along North, East and Up."""
    pos = np.array([[0.0, 0.0, 15.0], [1.0, 2.0, 6.0], [0.0, 0.0, 15.0]])
    cov = np.stack([_cov(3.0, 1.0, 2.0, 30.0), _cov(3.0, 1.0, 2.0, 30.0), np.full((3, 3), np.nan)])
    cand = ma.candidate_positions(pos, cov, 2.0, 10.0, BAND)
    assert cand.shape == (3, ma.N_CANDIDATES, 3)
    d = cand[0] - pos[0]
    major = np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0))])
    assert np.allclose(d[0], 0.0)
    assert np.allclose(abs(d[1, :2] @ major), 6.0) and np.allclose(d[1, :2], -d[2, :2])
    assert np.allclose(np.linalg.norm(d[3, :2]), 2.0) and np.allclose(d[3, :2] @ major, 0.0)
    assert np.allclose(d[5], [0.0, 0.0, 4.0]) and np.allclose(d[6], [0.0, 0.0, -4.0])
    # the altitude band: 6 - 4 m is clamped to 5 m
    assert cand[1, 6, 2] == 5.0 and cand[1, 5, 2] == 10.0
    # the cap: 2.5 sigma of 3 m is 7.5 m, capped at 5 m
    capped = ma.candidate_positions(pos[:1], cov[:1], 2.5, 5.0, BAND)[0] - pos[0]
    assert np.allclose(np.linalg.norm(capped[1:5, :2], axis=1), [5.0, 5.0, 2.5, 2.5])
    # not finite: the cap along North, East and Up
    d = cand[2] - pos[2]
    assert np.allclose(np.abs(d[1:5, :2]), [[0, 10], [0, 10], [10, 0], [10, 0]])
    assert np.allclose(d[5:, 2], [10.0, -10.0])


def test_compiled_prediction_equals_the_numpy_formulation() -> None:
    """500 random swarms in a grid city (positions inside buildings, degenerate and
    non-finite covariances, margins 0-3 sigma, caps 0-100 m): the compiled call and the
    numpy formulation through the candidates (the path of a file city's polygons) give the
    same prediction."""
    city = generate_city(CityConfig(), np.random.default_rng(1))
    rng = np.random.default_rng(2)
    dirs = np.array([_direction(az, el) for az, el in rng.uniform([0, 5], [360, 89], (24, 2))])
    sky = sky_directions(dirs)
    x0, x1, y0, y1 = city.extent_m
    for trial in range(500):
        n = int(rng.integers(1, 7))
        pos = np.c_[rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(0, 40, n)]
        a = rng.normal(size=(n, 3, 3)) * rng.uniform(0.1, 8.0, (n, 1, 1))
        cov = a @ np.swapaxes(a, 1, 2)
        if trial % 7 == 0:
            cov[0] = np.nan
        if trial % 5 == 0:
            cov[-1] = np.diag([4.0, 4.0, 9.0])  # a circle: no preferred axis
        kw = dict(
            margin_sigma=float(rng.choice([0.0, 1.0, 2.0, 3.0])),
            max_margin_m=float(rng.choice([0.0, 5.0, 10.0, 100.0])),
            altitude_band_m=BAND,
        )
        fast = ma.predicted_line_of_sight(city.buildings, sky, pos, cov, **kw)
        ref = _predict_from_candidates(city.buildings, sky, pos, cov, **kw)
        assert fast.shape == (n, 24) and fast.dtype == bool
        assert np.array_equal(fast, ref), trial


def test_the_buildings_culled_per_uav_change_nothing() -> None:
    """The compiled prediction traces each UAV's candidates against the buildings that may
    matter to them only (``_near_buildings``): 400 groups of seven candidates within a few
    metres of each other in a grid city (some inside buildings, satellites down to 5 degrees):
    the line of sight and the inside test on the subset equal those on every building. With
    the satellites above the default 10 degree mask the subset is about half the city (0.51
    measured on these draws)."""
    city = generate_city(CityConfig(), np.random.default_rng(4))
    rng = np.random.default_rng(5)
    dirs = np.array([_direction(az, el) for az, el in rng.uniform([0, 5], [360, 89], (24, 2))])
    sky = sky_directions(dirs)
    sky10 = sky_directions(dirs[np.degrees(np.arcsin(dirs[:, 2])) >= 10.0])
    b = city.buildings
    x0, x1, y0, y1 = city.extent_m
    sub_lo, sub_hi = np.empty_like(b.min_m), np.empty_like(b.max_m)
    kept = []
    for _ in range(400):
        centre = [rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(0.0, 40.0)]
        cand = centre + rng.normal(size=(ma.N_CANDIDATES, 3)) * rng.uniform(0.1, 8.0)
        m = ma._near_buildings(cand, b.min_m, b.max_m, sky.cot_s, sub_lo, sub_hi)
        sub = Buildings(sub_lo[:m], sub_hi[:m])
        assert np.array_equal(line_of_sight(sub, cand, dirs), line_of_sight(b, cand, dirs))
        assert np.array_equal(is_inside_building(sub, cand), is_inside_building(b, cand))
        m10 = ma._near_buildings(cand, b.min_m, b.max_m, sky10.cot_s, sub_lo, sub_hi)
        kept.append(m10 / b.min_m.shape[0])
    assert np.mean(kept) < 0.65


def test_a_satellite_blocked_from_one_candidate_is_not_used(predict) -> None:
    """A UAV 10 m west of a 20 m high wall, at 10 m: a satellite to the east at 50 degrees
    clears the roof from the predicted position (LOS) but not from 4 m further east (2 sigma
    along East); the same satellite to the west and one due south are clear from everywhere."""
    sky = sky_directions([_direction(90.0, 50.0), _direction(270.0, 50.0), _direction(180, 30)])
    pos = np.array([[0.0, 0.0, 10.0]])
    east = [_direction(90.0, 50.0)]
    two = [[0.0, 0.0, 10.0], [4.0, 0.0, 10.0]]
    assert np.array_equal(line_of_sight(WALL, two, east), [[True], [False]])
    cov = _cov(2.0, 0.5, 0.01)[None]
    kw = dict(max_margin_m=10.0, altitude_band_m=BAND)
    at_centre = predict(WALL, sky, pos, cov, margin_sigma=0.0, **kw)
    assert np.array_equal(at_centre, [[True, True, True]])
    with_margin = predict(WALL, sky, pos, cov, margin_sigma=2.0, **kw)
    assert np.array_equal(with_margin, [[False, True, True]])
    # the same 4 m of margin from the cap, whatever the covariance says
    wide = _cov(50.0, 50.0, 0.01)[None]
    capped = predict(WALL, sky, pos, wide, margin_sigma=2.0, max_margin_m=4.0, altitude_band_m=BAND)
    assert np.array_equal(capped, [[False, True, True]])


def test_candidates_inside_a_building_are_ignored(predict) -> None:
    """A UAV 2 m from the wall with 4 m of margin east: that candidate is inside the
    building (the UAV cannot be there) and blocks nothing; the others see the steep eastern
    satellite. A UAV whose every candidate is inside a building: the map says nothing."""
    sky = sky_directions([_direction(90.0, 80.0), _direction(270.0, 30.0)])
    cov = _cov(2.0, 0.5, 0.01)[None]
    kw = dict(margin_sigma=2.0, max_margin_m=10.0, altitude_band_m=BAND)
    near = np.array([[8.0, 0.0, 10.0]])
    assert np.array_equal(predict(WALL, sky, near, cov, **kw), [[True, True]])
    inside = np.array([[20.0, 0.0, 10.0]])
    assert np.array_equal(predict(WALL, sky, inside, cov, **kw), [[True, True]])
    # ... and from inside with no margin: the centre is inside as well
    kw0 = {**kw, "margin_sigma": 0.0}
    assert np.array_equal(predict(WALL, sky, inside, cov, **kw0), [[True, True]])


def test_bad_arguments_raise_value_errors_naming_them() -> None:
    sky = sky_directions([_direction(90.0, 50.0)])
    pos, cov = np.zeros((1, 3)), np.eye(3)[None]
    good = dict(margin_sigma=1.0, max_margin_m=10.0, altitude_band_m=BAND)
    with pytest.raises(ValueError, match="margin_sigma"):
        ma.predicted_line_of_sight(WALL, sky, pos, cov, **{**good, "margin_sigma": -1.0})
    with pytest.raises(ValueError, match="max_margin_m"):
        ma.predicted_line_of_sight(WALL, sky, pos, cov, **{**good, "max_margin_m": math.inf})
    with pytest.raises(ValueError, match="altitude_band_m"):
        ma.predicted_line_of_sight(WALL, sky, pos, cov, **{**good, "altitude_band_m": (30, 5)})
    with pytest.raises(ValueError, match=r"pos_enu_m must be \(N, 3\)"):
        ma.predicted_line_of_sight(WALL, sky, pos, np.eye(3), **good)
