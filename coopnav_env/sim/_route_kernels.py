"""Compiled kernels of a file city's routes
(:meth:`coopnav_env.sim.file_city.FileCity.free_space_route`).

:func:`segment_free` walks the cells a straight leg crosses on the free-space grid;
:func:`pull_string` keeps, from each waypoint of an A* cell path, the farthest later one a
straight leg reaches. Both take the grid as the record :class:`FreeGrid`. Their Python
oracle is in ``tests/sim/test_route_kernels.py``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = ["FreeGrid", "pull_string", "segment_free"]


class FreeGrid(NamedTuple):
    """A file city's free-space grid (:func:`segment_free`, :func:`pull_string`)."""

    reachable: np.ndarray  # (ny, nx) bool cells a UAV can reach
    clear: np.ndarray  # (ny, nx) clearance of each cell [m]
    x0_m: float  # centre of cell (0, 0), east [m]
    y0_m: float  # north [m]
    res_m: float  # cell size [m]


@njit(cache=True, inline="always")
def _cell_ok(reachable, clear, ci, cj, min_clear_m):
    ny, nx = reachable.shape
    return 0 <= ci < nx and 0 <= cj < ny and reachable[cj, ci] and clear[cj, ci] >= min_clear_m


@njit(cache=True)
def segment_free(grid, a, b, min_clear_m):
    """Whether the straight leg ``a -> b`` (each ``(x, y)`` [m]) crosses reachable cells of
    clearance at least ``min_clear_m`` only (a grid traversal; a leg through a cell corner
    checks both cells beside it). ``grid``: the record :class:`FreeGrid` (or a plain tuple
    of its fields)."""
    reachable, clear, x0_m, y0_m, res_m = grid
    ax, ay = a
    bx, by = b
    u0 = (ax - x0_m) / res_m + 0.5
    v0 = (ay - y0_m) / res_m + 0.5
    u1 = (bx - x0_m) / res_m + 0.5
    v1 = (by - y0_m) / res_m + 0.5
    i, j = math.floor(u0), math.floor(v0)
    i_end, j_end = math.floor(u1), math.floor(v1)
    du, dv = u1 - u0, v1 - v0
    si = 1 if du > 0 else -1
    sj = 1 if dv > 0 else -1
    tx = ((i + (1 if si > 0 else 0)) - u0) / du if du != 0 else math.inf
    ty = ((j + (1 if sj > 0 else 0)) - v0) / dv if dv != 0 else math.inf
    dtx = abs(1.0 / du) if du != 0 else math.inf
    dty = abs(1.0 / dv) if dv != 0 else math.inf
    for _ in range(abs(i_end - i) + abs(j_end - j) + 2):
        if not _cell_ok(reachable, clear, i, j, min_clear_m):
            return False
        if i == i_end and j == j_end:
            return True
        if tx == ty:  # through a corner: both side cells must be free too
            if not (
                _cell_ok(reachable, clear, i + si, j, min_clear_m)
                and _cell_ok(reachable, clear, i, j + sj, min_clear_m)
            ):
                return False
            i, j, tx, ty = i + si, j + sj, tx + dtx, ty + dty
        elif tx < ty:
            i, tx = i + si, tx + dtx
        else:
            j, ty = j + sj, ty + dty
    return _cell_ok(reachable, clear, i, j, min_clear_m)


@njit(cache=True)
def pull_string(pts, clear_along, grid, cap_m):
    """Indices into ``pts`` (k, 2) [m] of the waypoints kept: from each kept one, the farthest
    later waypoint that a straight leg reaches on ``grid`` (the record :class:`FreeGrid`, or
    a plain tuple of its fields) keeping the least clearance of the path between them
    (``clear_along``, per waypoint), at most ``cap_m``."""
    n = pts.shape[0]
    out = np.empty(n, dtype=np.int64)
    out[0] = 0
    k = 1
    i = 0
    while i < n - 1:
        j = n - 1
        while j > i + 1:
            least = clear_along[i]
            for m in range(i + 1, j + 1):
                if clear_along[m] < least:
                    least = clear_along[m]
            need = least if least < cap_m else cap_m
            if segment_free(grid, (pts[i, 0], pts[i, 1]), (pts[j, 0], pts[j, 1]), need):
                break
            j -= 1
        out[k] = j
        k += 1
        i = j
    return out[:k]
