"""City generation: determinism, layout invariants, helpers and configuration errors."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.sim import Buildings, City, CityConfig, generate_city, is_inside_building


def _city(seed: int = 0, **kw: object) -> City:
    return generate_city(CityConfig(**kw), np.random.default_rng(seed))


def test_generation_is_deterministic_for_a_seed() -> None:
    a, b, c = _city(7), _city(7), _city(8)
    np.testing.assert_array_equal(a.buildings.min_m, b.buildings.min_m)
    np.testing.assert_array_equal(a.buildings.max_m, b.buildings.max_m)
    np.testing.assert_array_equal(a.open_squares, b.open_squares)
    assert not np.array_equal(a.buildings.max_m, c.buildings.max_m)


def test_default_city_layout() -> None:
    cfg = CityConfig()
    city = _city(1)
    n_open = round(cfg.open_square_fraction * cfg.n_blocks_x * cfg.n_blocks_y)
    assert city.open_squares.shape == (n_open, 2)
    assert city.buildings.n == (cfg.n_blocks_x * cfg.n_blocks_y - n_open) * 2
    assert city.street_centres_x_m.shape == (cfg.n_blocks_x + 1,)
    assert city.street_centres_y_m.shape == (cfg.n_blocks_y + 1,)
    size = cfg.n_blocks_x * cfg.block_size_m + (cfg.n_blocks_x + 1) * cfg.street_width_m
    np.testing.assert_allclose(city.extent_m, (-size / 2, size / 2, -size / 2, size / 2))
    assert city.street_width_m == cfg.street_width_m
    assert city.config is cfg or city.config == cfg
    h = city.buildings.heights_m
    assert np.all((h >= cfg.height_min_m) & (h <= cfg.height_max_m))
    assert np.all(city.buildings.min_m[:, 2] == 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("per_block", [1, 2, 3])
def test_buildings_inside_extent_off_streets_and_disjoint(seed: int, per_block: int) -> None:
    city = _city(seed, buildings_per_block=per_block, open_square_fraction=0.2)
    b = city.buildings
    x0, x1, y0, y1 = city.extent_m
    tol = 1e-9
    assert np.all(b.min_m[:, 0] >= x0 - tol) and np.all(b.max_m[:, 0] <= x1 + tol)
    assert np.all(b.min_m[:, 1] >= y0 - tol) and np.all(b.max_m[:, 1] <= y1 + tol)
    half = city.street_width_m / 2
    # no footprint overlaps the open interior of a street strip
    for cx in city.street_centres_x_m:
        assert np.all((b.max_m[:, 0] <= cx - half + tol) | (b.min_m[:, 0] >= cx + half - tol))
    for cy in city.street_centres_y_m:
        assert np.all((b.max_m[:, 1] <= cy - half + tol) | (b.min_m[:, 1] >= cy + half - tol))
    # buildings do not overlap each other
    lo, hi = b.min_m[:, None, :2], b.max_m[:, None, :2]
    overlap = np.all((lo < b.max_m[None, :, :2] - tol) & (b.min_m[None, :, :2] < hi - tol), axis=2)
    np.fill_diagonal(overlap, False)
    assert not overlap.any()
    # open squares hold no building
    sq = np.c_[city.open_squares, np.full(len(city.open_squares), 1.0)]
    assert not is_inside_building(b, sq).any()


def test_all_blocks_open_gives_no_buildings() -> None:
    city = _city(0, open_square_fraction=1.0)
    assert city.buildings.n == 0
    assert city.open_squares.shape == (36, 2)


def test_equal_heights_when_std_is_zero() -> None:
    city = _city(3, height_std_m=0.0, height_mean_m=30.0)
    np.testing.assert_array_equal(city.buildings.heights_m, 30.0)


def test_random_street_points_are_free_and_on_streets() -> None:
    city = _city(4)
    rng = np.random.default_rng(5)
    pts = city.random_street_points(rng, 500, altitude_m=12.0, margin_m=2.0)
    assert pts.shape == (500, 3)
    np.testing.assert_array_equal(pts[:, 2], 12.0)
    assert not city.is_inside_building(pts).any()
    half = city.street_width_m / 2 - 2.0 + 1e-9
    on_x = np.min(np.abs(pts[:, :1] - city.street_centres_x_m[None, :]), axis=1) <= half
    on_y = np.min(np.abs(pts[:, 1:2] - city.street_centres_y_m[None, :]), axis=1) <= half
    assert np.all(on_x | on_y)
    x0, x1, y0, y1 = city.extent_m
    assert np.all((pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1))
    one = city.random_street_point(np.random.default_rng(5), altitude_m=12.0)
    np.testing.assert_array_equal(
        one, city.random_street_points(np.random.default_rng(5), 1, 12.0)[0]
    )


def test_is_inside_building_strict_interior() -> None:
    b = Buildings.from_boxes([(0.0, 0.0, 10.0, 10.0, 20.0)])
    pts = np.array([[5, 5, 5], [5, 5, 25], [10, 5, 5], [-1, 5, 5], [5, 5, 20]], dtype=float)
    np.testing.assert_array_equal(is_inside_building(b, pts), [True, False, False, False, False])


def test_buildings_constructors_and_read_only() -> None:
    b = Buildings.from_boxes([(0, 0, 1, 2, 3), (5, 5, 6, 7, 8)])
    assert b.n == 2
    np.testing.assert_array_equal(b.heights_m, [3, 8])
    np.testing.assert_array_equal(b.footprints_m, [[0, 0, 1, 2], [5, 5, 6, 7]])
    with pytest.raises(ValueError):
        b.min_m[0, 0] = 1.0
    assert Buildings.empty().n == 0
    assert b.concatenate(Buildings.empty()).n == 2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_blocks_x": 0}, r"CityConfig\.n_blocks_x .*\[1, 200\].*0"),
        ({"n_blocks_y": 2.5}, r"CityConfig\.n_blocks_y must be an integer"),
        ({"n_blocks_x": True}, r"CityConfig\.n_blocks_x"),
        ({"block_size_m": -1.0}, r"CityConfig\.block_size_m .*\(0\.0, 10000\.0\]"),
        ({"street_width_m": float("nan")}, r"CityConfig\.street_width_m"),
        ({"buildings_per_block": 0}, r"CityConfig\.buildings_per_block"),
        ({"building_gap_m": 59.0}, r"CityConfig\.building_gap_m .*\[0\.0, 58\.0\]"),
        ({"height_min_m": 0.0}, r"CityConfig\.height_min_m"),
        ({"height_max_m": 5.0}, r"CityConfig\.height_max_m"),
        ({"height_mean_m": 200.0}, r"CityConfig\.height_mean_m .*\[10\.0, 150\.0\].*200"),
        ({"height_std_m": -1.0}, r"CityConfig\.height_std_m"),
        ({"open_square_fraction": 1.5}, r"CityConfig\.open_square_fraction .*\[0\.0, 1\.0\]"),
    ],
)
def test_city_config_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CityConfig(**kwargs)


def test_city_config_rejects_unknown_keys() -> None:
    with pytest.raises(TypeError):
        CityConfig(n_blocks=3)  # type: ignore[call-arg]


def test_buildings_errors() -> None:
    with pytest.raises(ValueError, match=r"min_m must have shape \(n_b, 3\)"):
        Buildings(np.zeros((2, 2)), np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"max_m must be > min_m"):
        Buildings.from_boxes([(0, 0, 0, 1, 5)])
    with pytest.raises(ValueError, match=r"min_m\[:, 2\] must be 0"):
        Buildings(np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 1.0, 5.0]]))
    with pytest.raises(ValueError, match="heights_m must have one value per footprint"):
        Buildings.from_footprints([[0, 0, 1, 1]], [1.0, 2.0])
    with pytest.raises(ValueError, match=r"pos_enu_m must have shape \(n, 3\)"):
        is_inside_building(Buildings.empty(), np.zeros(3))


def test_street_point_errors() -> None:
    city = _city(0)
    with pytest.raises(ValueError, match=r"margin_m must be in \[0\.0, 10\.0\)"):
        city.random_street_points(np.random.default_rng(0), 3, margin_m=10.0)
    with pytest.raises(ValueError, match=r"City\.street_width_m is required"):
        City(Buildings.empty(), (0, 1, 0, 1), [0.5], [], np.zeros((0, 2)))
    with pytest.raises(ValueError, match=r"City\.extent_m"):
        City(Buildings.empty(), (1, 0, 0, 1), [0.5], [], np.zeros((0, 2)), street_width_m=1.0)
