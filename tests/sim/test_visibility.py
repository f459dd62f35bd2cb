"""3-D line of sight, skyline mask and wall distances, against brute force and hand-made
geometry; NLOS."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.sim import (
    Buildings,
    CityConfig,
    draw_nlos,
    generate_city,
    line_of_sight,
    mask_elevation_deg,
    swept_collisions,
    wall_distance_m,
)


def _dirs(az_deg: np.ndarray, el_deg: np.ndarray) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)


def _hemisphere(n: int) -> np.ndarray:
    """Fibonacci directions evenly covering the upper hemisphere, shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = k / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _brute_force_los(b: Buildings, pos: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Reference: one ray at a time, one box at a time, ray against each of the 6 faces."""
    out = np.ones((len(pos), len(d)), dtype=bool)
    for i, p in enumerate(pos):
        for j, v in enumerate(d):
            v = v / np.linalg.norm(v)
            if v[2] <= 0.0:
                out[i, j] = False
                continue
            for lo, hi in zip(b.min_m, b.max_m):
                if np.all(p > lo) and np.all(p < hi):
                    out[i, j] = False
                    break
                hit = False
                for a in range(3):
                    if v[a] == 0.0:
                        continue
                    for plane in (lo[a], hi[a]):
                        t = (plane - p[a]) / v[a]
                        if t <= 0.0:
                            continue
                        q = p + t * v
                        others = [k for k in range(3) if k != a]
                        if all(lo[k] <= q[k] <= hi[k] for k in others):
                            hit = True
                if hit:
                    out[i, j] = False
                    break
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_line_of_sight_matches_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_b = 25
    xy0 = rng.uniform(-100, 100, size=(n_b, 2))
    size = rng.uniform(2, 30, size=(n_b, 2))
    b = Buildings.from_footprints(np.c_[xy0, xy0 + size], rng.uniform(5, 60, n_b))
    pos = np.c_[rng.uniform(-110, 110, size=(30, 2)), rng.uniform(0, 50, 30)]
    pos[:3] = (b.min_m[:3] + b.max_m[:3]) / 2  # three receivers inside buildings
    az = np.r_[rng.uniform(0, 360, 40), 0.0, 90.0, 180.0, 270.0, 0.0]
    el = np.r_[rng.uniform(-10, 90, 40), 10.0, 20.0, 30.0, 5.0, 90.0]
    d = _dirs(az, el)
    d[-5:] = np.where(np.abs(d[-5:]) < 1e-12, 0.0, d[-5:])  # exact axis-aligned and zenith
    d[:10] *= rng.uniform(0.1, 10, size=(10, 1))  # not unit vectors
    los = line_of_sight(b, pos, d)
    assert los.shape == (30, 45) and los.dtype == bool
    np.testing.assert_array_equal(los, _brute_force_los(b, pos, d))
    assert not los[:3].any()
    assert not los[:, el <= 0].any()
    assert 0.1 < los.mean() < 0.9  # the cases are not trivial


def test_line_of_sight_inputs_not_modified_and_empty_cases() -> None:
    b = Buildings.from_boxes([(10, -5, 20, 5, 30)])
    pos = np.array([[0.0, 0.0, 10.0]])
    d = _dirs(np.array([90.0, 270.0]), np.array([30.0, 30.0]))
    pos.setflags(write=False)
    d.setflags(write=False)
    np.testing.assert_array_equal(line_of_sight(b, pos, d), [[False, True]])
    np.testing.assert_array_equal(line_of_sight(Buildings.empty(), pos, d), [[True, True]])
    assert line_of_sight(b, np.zeros((0, 3)), d).shape == (0, 2)
    with pytest.raises(ValueError, match="dir_enu must not contain zero vectors"):
        line_of_sight(b, pos, np.zeros((1, 3)))
    with pytest.raises(ValueError, match=r"dir_enu must have shape \(n, 3\)"):
        line_of_sight(b, pos, np.ones(3))


def test_line_of_sight_large_case_is_bounded_and_consistent() -> None:
    """100 receivers x 40 satellites x ~500 buildings runs, and agrees with the skyline."""
    rng = np.random.default_rng(11)
    city = generate_city(CityConfig(n_blocks_x=16, n_blocks_y=16, buildings_per_block=2), rng)
    assert city.buildings.n >= 450
    pos = city.random_street_points(rng, 100, altitude_m=15.0)
    az, el = rng.uniform(0, 360, 40), rng.uniform(1, 89, 40)
    los = city.line_of_sight(pos, _dirs(az, el))
    mask = city.mask_elevation_deg(pos, az)
    # rays exactly on the skyline are measure-zero; the two models agree elsewhere
    np.testing.assert_array_equal(los, el[None, :] > mask)


def test_open_square_sees_more_sky_than_a_narrow_street() -> None:
    city = generate_city(
        CityConfig(n_blocks_x=3, n_blocks_y=3, open_square_fraction=1 / 9, height_std_m=0.0),
        np.random.default_rng(0),
    )
    d = _hemisphere(600)
    sq = city.open_squares[0]
    in_square = np.array([[sq[0], sq[1], 10.0]])
    # midpoints of the north-south street segments between two built blocks
    block_y = (city.street_centres_y_m[:-1] + city.street_centres_y_m[1:]) / 2
    cx = city.street_centres_x_m[1:-1]
    streets = np.array([[x, y, 10.0] for x in cx for y in block_y])
    far = np.max(np.abs(streets[:, :2] - sq) - 40.0, axis=1) > 0  # not next to the square
    streets = streets[far]
    assert len(streets) > 0
    sky_square = city.line_of_sight(in_square, d).mean()
    sky_street = city.line_of_sight(streets, d).mean(axis=1)
    assert sky_square > 0.5
    assert np.all(sky_square > sky_street + 0.2)


def test_mask_elevation_single_building_by_hand() -> None:
    # one box east of the origin: x in [10, 20], y in [-5, 5], roof 30 m
    b = Buildings.from_boxes([(10.0, -5.0, 20.0, 5.0, 30.0)])
    pos = np.array(
        [
            [0.0, 0.0, 10.0],  # west of the box, 20 m below the roof
            [15.0, -20.0, 10.0],  # south of the box
            [0.0, 0.0, 40.0],  # above the roof
            [15.0, 0.0, 10.0],  # inside
        ]
    )
    az = np.array([0.0, 45.0, 80.0, 90.0, 180.0, 270.0])
    m = mask_elevation_deg(b, pos, az)
    assert m.shape == (4, 6)
    t80 = 10.0 / math.sin(math.radians(80.0))  # y at the wall = 1.76 m, inside [-5, 5]
    expected0 = [0.0, 0.0, math.degrees(math.atan(20 / t80)), math.degrees(math.atan(2.0)), 0, 0]
    np.testing.assert_allclose(m[0], expected0, atol=1e-9)
    np.testing.assert_allclose(m[1], [math.degrees(math.atan(20 / 15)), 0, 0, 0, 0, 0], atol=1e-9)
    np.testing.assert_array_equal(m[2], 0.0)
    np.testing.assert_allclose(m[3], 90.0)
    # line of sight agrees with the skyline just above / below it
    d_above = _dirs(az[[2, 3]], m[0, [2, 3]] + 0.1)
    d_below = _dirs(az[[2, 3]], m[0, [2, 3]] - 0.1)
    assert line_of_sight(b, pos[:1], d_above).all()
    assert not line_of_sight(b, pos[:1], d_below).any()


def test_mask_elevation_skyline_is_the_highest_roof() -> None:
    # a low building in front of a taller one along azimuth 90
    b = Buildings.from_boxes([(10, -5, 12, 5, 20.0), (30, -5, 40, 5, 60.0)])
    m = mask_elevation_deg(b, np.array([[0.0, 0.0, 0.0]]), np.array([90.0]))
    np.testing.assert_allclose(m, [[math.degrees(math.atan(2.0))]])  # 60/30 beats 20/10


def test_mask_elevation_errors() -> None:
    b = Buildings.empty()
    with pytest.raises(ValueError, match=r"az_deg must have shape \(n_az,\)"):
        mask_elevation_deg(b, np.zeros((1, 3)), np.zeros((2, 2)))
    np.testing.assert_array_equal(mask_elevation_deg(b, np.zeros((2, 3)), [0.0, 1.0]), 0.0)


def test_wall_distance_single_building_by_hand() -> None:
    # the same box: x in [10, 20], y in [-5, 5], roof 30 m
    b = Buildings.from_boxes([(10.0, -5.0, 20.0, 5.0, 30.0)])
    pos = np.array(
        [
            [0.0, 0.0, 10.0],  # west of the box, below the roof
            [15.0, -20.0, 10.0],  # south of the box
            [0.0, 0.0, 40.0],  # above the roof: overflies it
            [15.0, 0.0, 10.0],  # inside
            [0.0, 4.0, 29.9],  # just below the roof, 4 m north of the box axis
        ]
    )
    az = np.array([0.0, 45.0, 80.0, 90.0, 180.0, 270.0])
    d = wall_distance_m(b, pos, az)
    assert d.shape == (5, 6)
    inf = np.inf
    t80 = 10.0 / math.sin(math.radians(80.0))  # the wall at x = 10 seen under azimuth 80
    # azimuth 45 from the origin: the ray meets x = 10 at y = 10, north of the box
    np.testing.assert_allclose(d[0], [inf, inf, t80, 10.0, inf, inf])
    np.testing.assert_allclose(d[1], [15.0, inf, inf, inf, inf, inf])
    assert np.all(np.isinf(d[2]))
    np.testing.assert_array_equal(d[3], 0.0)
    # from y = 4 the azimuth-80 ray reaches x = 10 at y = 5.76, north of the box: a miss
    np.testing.assert_allclose(d[4], [inf, inf, inf, 10.0, inf, inf])
    # a UAV flying the measured distance (minus its radius) straight at the wall just misses it
    r, start, u = 1.0, pos[:1], np.array([1.0, 0.0, 0.0])
    assert not swept_collisions(b, start, start + u * (d[0, 3] - r - 0.01), r)[0]
    assert swept_collisions(b, start, start + u * (d[0, 3] - r + 0.01), r)[0]


def test_wall_distance_matches_the_city_and_brute_force() -> None:
    city = generate_city(CityConfig(), np.random.default_rng(5))
    pos = city.random_street_points(np.random.default_rng(6), 30, altitude_m=15.0)
    az = np.arange(8) * 45.0
    d = city.wall_distance_m(pos, az)
    np.testing.assert_array_equal(d, wall_distance_m(city.buildings, pos, az))
    assert np.all(d > 0.0)
    # brute force: march along each ray in 5 cm steps until a point is inside a building
    step = 0.05
    for i in range(0, 30, 7):
        for k, a in enumerate(az):
            u = np.array([math.sin(math.radians(a)), math.cos(math.radians(a)), 0.0])
            s = np.arange(0.0, 120.0, step)
            inside = city.is_inside_building(pos[i] + s[:, None] * u)
            first = s[np.argmax(inside)] if inside.any() else np.inf
            if np.isfinite(first) or d[i, k] < 120.0:
                assert abs(first - d[i, k]) <= step + 1e-9, (i, a, first, d[i, k])
    with pytest.raises(ValueError, match=r"az_deg must have shape \(n_az,\)"):
        wall_distance_m(city.buildings, pos, np.zeros((2, 2)))
    assert np.all(np.isinf(wall_distance_m(Buildings.empty(), pos[:2], az)))


def test_draw_nlos_statistics_and_determinism() -> None:
    rng = np.random.default_rng(3)
    blocked = rng.random((200, 50)) < 0.5
    p, mean, floor = 0.3, 8.0, 1.0
    received, bias = draw_nlos(np.random.default_rng(4), blocked, p, mean, floor)
    assert received.shape == bias.shape == blocked.shape
    assert received[~blocked].all() and np.all(bias[~blocked] == 0.0)
    nlos = blocked & received
    assert np.all(bias[blocked & ~received] == 0.0)
    assert np.all(bias[nlos] >= floor)
    n_blk = blocked.sum()
    frac = nlos.sum() / n_blk
    assert abs(frac - p) < 5 * math.sqrt(p * (1 - p) / n_blk)
    n_nlos = nlos.sum()
    assert abs(bias[nlos].mean() - (floor + mean)) < 5 * mean / math.sqrt(n_nlos)
    # the random stream does not depend on the mask
    g1, g2 = np.random.default_rng(9), np.random.default_rng(9)
    draw_nlos(g1, np.zeros((4, 5), bool), 0.5, 3.0)
    draw_nlos(g2, np.ones((4, 5), bool), 0.5, 3.0)
    assert g1.random() == g2.random()
    r1, b1 = draw_nlos(np.random.default_rng(1), blocked, p, mean)
    r2, b2 = draw_nlos(np.random.default_rng(1), blocked, p, mean)
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(b1, b2)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"probability": 1.5}, r"draw_nlos\.probability must be in \[0\.0, 1\.0\], got 1\.5"),
        ({"bias_mean_m": -1.0}, r"draw_nlos\.bias_mean_m"),
        ({"bias_floor_m": -0.1}, r"draw_nlos\.bias_floor_m"),
    ],
)
def test_draw_nlos_errors(kwargs: dict[str, float], match: str) -> None:
    args = {"probability": 0.5, "bias_mean_m": 5.0} | kwargs
    with pytest.raises(ValueError, match=match):
        draw_nlos(np.random.default_rng(0), np.zeros((2, 2), bool), **args)
