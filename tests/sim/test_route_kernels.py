"""The compiled kernels of a file city's routes (``coopnav_env.sim._route_kernels``) against
their Python oracle: the same grid traversal and the same kept waypoints, bit for bit."""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np

from coopnav_env.sim._route_kernels import pull_string, segment_free
from coopnav_env.sim.file_city import PREFERRED_CLEARANCE_M, load_file_city, sample_city_path


def segment_free_oracle(city, a, b, min_clear_m, grid) -> bool:
    """Whether the leg ``a -> b`` crosses reachable cells of clearance >= ``min_clear_m`` only
    (a grid traversal; a leg through a cell corner checks both cells beside it)."""
    res = city.resolution_m
    u0 = (a[0] - city.grid_x_m[0]) / res + 0.5
    v0 = (a[1] - city.grid_y_m[0]) / res + 0.5
    u1 = (b[0] - city.grid_x_m[0]) / res + 0.5
    v1 = (b[1] - city.grid_y_m[0]) / res + 0.5
    ny, nx = city.reachable.shape
    i, j = math.floor(u0), math.floor(v0)
    i_end, j_end = math.floor(u1), math.floor(v1)
    du, dv = u1 - u0, v1 - v0
    si, sj = (1 if du > 0 else -1), (1 if dv > 0 else -1)
    tx = ((i + (si > 0)) - u0) / du if du != 0 else math.inf
    ty = ((j + (sj > 0)) - v0) / dv if dv != 0 else math.inf
    dtx = abs(1.0 / du) if du != 0 else math.inf
    dty = abs(1.0 / dv) if dv != 0 else math.inf

    def ok(ci: int, cj: int) -> bool:
        inside = 0 <= ci < nx and 0 <= cj < ny
        return inside and bool(city.reachable[cj, ci]) and grid[cj, ci] >= min_clear_m

    for _ in range(abs(i_end - i) + abs(j_end - j) + 2):
        if not ok(i, j):
            return False
        if i == i_end and j == j_end:
            return True
        if tx == ty:
            if not (ok(i + si, j) and ok(i, j + sj)):
                return False
            i, j, tx, ty = i + si, j + sj, tx + dtx, ty + dty
        elif tx < ty:
            i, tx = i + si, tx + dtx
        else:
            j, ty = j + sj, ty + dty
    return ok(i, j)


def pull_string_oracle(city, pts, clear, grid) -> list[int]:
    kept, i = [0], 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1 and not segment_free_oracle(
            city, pts[i], pts[j], min(float(clear[i : j + 1].min()), PREFERRED_CLEARANCE_M), grid
        ):
            j -= 1
        kept.append(j)
        i = j
    return kept


def _city():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_file_city(sample_city_path())


def _grid(city, clear):
    """The kernels' record (``_route_kernels.FreeGrid``) as a plain tuple."""
    return (
        city.reachable,
        clear,
        float(city.grid_x_m[0]),
        float(city.grid_y_m[0]),
        float(city.resolution_m),
    )


def test_segment_free_is_the_oracle_on_random_legs() -> None:
    city = _city()
    grid = np.ascontiguousarray(city.clearance_grid_m, dtype=float)
    rng = np.random.default_rng(0)
    x0, x1, y0, y1 = city.extent_m
    found = set()
    for _ in range(400):
        a = rng.uniform([x0 - 20, y0 - 20], [x1 + 20, y1 + 20])
        b = a + rng.normal(0.0, 60.0, 2)
        if rng.random() < 0.2:  # axis-aligned and diagonal legs: cell edges and corners
            b = a + rng.choice([-1.0, 0.0, 1.0], 2) * 25.0
        need = float(rng.choice([0.0, 3.0, 6.0]))
        want = segment_free_oracle(city, a, b, need, grid)
        got = segment_free(_grid(city, grid), (a[0], a[1]), (b[0], b[1]), need)
        assert got == want, (a, b, need)
        found.add(want)
    assert found == {True, False}


def test_pull_string_keeps_the_oracles_waypoints_on_a_routes_cells() -> None:
    city = _city()
    grid = np.ascontiguousarray(city.clearance_grid_m, dtype=float)
    rng = np.random.default_rng(1)
    pts_all = city.random_street_points(rng, 12, margin_m=0.0)[:, :2]
    for k in range(6):
        route = city.free_space_route(pts_all[2 * k], pts_all[2 * k + 1])
        legs = [np.linspace(p, q, 8, endpoint=False) for p, q in itertools.pairwise(route)]
        pts = np.vstack([*legs, route[-1:]])  # a dense path along the route
        cells = [city._cell(p) for p in pts]
        clear = np.array([grid[r, c] for r, c in cells], dtype=float)
        got = pull_string(pts, clear, _grid(city, grid), PREFERRED_CLEARANCE_M)
        assert list(got) == pull_string_oracle(city, pts, clear, grid)
        assert len(got) < len(pts)
