"""Generated city families (``coopnav_env.sim.city_families``): valid, deterministic cities."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.sim.city import CityConfig, generate_city
from coopnav_env.sim.city_families import (
    BORDER_STREET_M,
    FAMILIES,
    FAMILY_SIZE_M,
    city_statistics,
    family_city,
    family_footprints,
    family_name,
    seeded_family_city,
    statistics_table,
)
from coopnav_env.sim.file_city import FileCity

HEIGHTS_M = {
    "irregular": (6.0, 80.0),
    "old_town": (9.6, 20.7),
    "high_rise": (20.0, 300.0),
    "avenues": (12.0, 45.0),
    "courtyards": (15.0, 27.0),
}


@pytest.mark.parametrize("name", FAMILIES)
def test_footprints_are_valid_apart_and_inside_the_square(name: str) -> None:
    shapely = pytest.importorskip("shapely")
    from shapely.geometry import Polygon

    fp = family_footprints(name, np.random.default_rng(3))
    polys = [Polygon(r[0], r[1:]) for r in fp.rings_m]
    assert len(polys) >= 20 and fp.heights_m.shape == (len(polys),)
    assert all(p.is_valid and p.area > 0.0 for p in polys)
    tree = shapely.STRtree(polys)
    overlaps = [
        (i, int(j))
        for i, p in enumerate(polys)
        for j in tree.query(p)
        if j > i and p.intersection(polys[j]).area > 1e-6
    ]
    assert overlaps == []
    half = FAMILY_SIZE_M / 2.0 - BORDER_STREET_M
    allv = np.concatenate([r for rings in fp.rings_m for r in rings])
    assert np.all(np.abs(allv) <= half + 1e-9)
    lo, hi = HEIGHTS_M[name]
    assert np.all((fp.heights_m >= lo) & (fp.heights_m <= hi))
    if name == "courtyards":  # perimeter blocks: most have a yard
        assert sum(len(r) == 2 for r in fp.rings_m) >= len(fp.rings_m) // 2


@pytest.mark.parametrize("name", FAMILIES)
def test_a_seed_gives_one_city_and_another_seed_another(name: str) -> None:
    a = family_footprints(name, np.random.default_rng(11))
    b = family_footprints(name, np.random.default_rng(11))
    c = family_footprints(name, np.random.default_rng(12))
    assert len(a.rings_m) == len(b.rings_m)
    assert all(np.array_equal(x, y) for ra, rb in zip(a.rings_m, b.rings_m) for x, y in zip(ra, rb))
    np.testing.assert_array_equal(a.heights_m, b.heights_m)
    assert len(a.rings_m) != len(c.rings_m) or not np.array_equal(a.heights_m, c.heights_m)


def test_a_family_city_has_the_free_space_of_a_file_city() -> None:
    city = family_city("avenues", np.random.default_rng(0), origin=(48.85, 2.35, 35.0))
    assert isinstance(city, FileCity)
    h = FAMILY_SIZE_M / 2.0
    assert city.extent_m == (-h, h, -h, h) and city.origin == (48.85, 2.35, 35.0)
    assert city.source == "family:avenues"
    assert city.built_up.sum() > 1000 and np.all(city.reachable[city.built_up])
    start = city.random_street_points(np.random.default_rng(1), 1)[0, :2]
    goal = city.random_street_points(np.random.default_rng(2), 1)[0, :2]
    route = city.free_space_route(start, goal)
    assert np.array_equal(route[0], start) and np.array_equal(route[-1], goal)
    assert city.is_free_xy(route).all()
    # the cached city of a seed is the city drawn from that seed's generator
    cached = seeded_family_city("avenues", 0, (48.85, 2.35, 35.0))
    assert seeded_family_city("avenues", 0, (48.85, 2.35, 35.0)) is cached
    np.testing.assert_array_equal(cached.buildings.edges_m, city.buildings.edges_m)


def test_an_unknown_family_is_refused_naming_the_families() -> None:
    assert family_name("family:old_town") == "old_town"
    with pytest.raises(ValueError, match=r"unknown city family 'medieval'.*'family:old_town'"):
        family_footprints("medieval", np.random.default_rng(0))


def test_statistics_measure_the_grid_city_streets() -> None:
    grid = city_statistics(generate_city(CityConfig(), np.random.default_rng(0)), "grid")
    assert 19.0 <= grid.street_width_m <= 22.0  # the grid's streets are 20 m wide
    assert grid.n_buildings == generate_city(CityConfig(), np.random.default_rng(0)).buildings.n
    low = city_statistics(family_city("old_town", np.random.default_rng(0)), "old")
    tall = city_statistics(family_city("high_rise", np.random.default_rng(0)), "tall")
    assert low.height_median_m < tall.height_median_m
    assert low.open_sky_share > tall.open_sky_share
    assert 0.0 < low.built_share < 1.0 and low.street_width_m < tall.street_width_m
    table = statistics_table([grid, low]).splitlines()
    assert len(table) == 4 and table[2].startswith("| grid | ")


def test_the_tiled_built_up_count_equals_asking_every_building() -> None:
    from coopnav_env.sim.file_city import BUILT_UP_RADIUS_M, _walls_within, load_file_city
    from coopnav_env.sim.osm_city import helsinki_geojson_path

    for city in (
        load_file_city(helsinki_geojson_path(), warn=False),
        family_city("old_town", np.random.default_rng(5)),
    ):
        rows, cols = np.nonzero(city.reachable)
        cells = np.column_stack([city.grid_x_m[cols], city.grid_y_m[rows], np.full(rows.size, 0.5)])
        _, wall_m = city.buildings.sky_and_walls(cells, np.arange(0.0, 360.0, 45.0))
        every = np.sum(wall_m <= BUILT_UP_RADIUS_M, axis=1)
        tiled = _walls_within(city.buildings, cells, BUILT_UP_RADIUS_M)
        np.testing.assert_array_equal(tiled, every)
        assert 0 < np.count_nonzero(every >= 4) < every.size
