"""Routes along the street network: shortest street route, arc-length polylines, waypoints.

Pure numpy, no randomness. Every street of a :class:`~coopnav_env.sim.city.City` spans the
whole city (a Manhattan grid: north-south centre lines ``street_centres_x_m``, east-west ones
``street_centres_y_m``), so the shortest route along street centre lines from one street point
to another has at most two turns (:func:`street_route`). The environment plans this route at
reset and tracks each UAV's next waypoint on it (:func:`advance_waypoints`,
:func:`remaining_route_m`); the column heuristics of :mod:`coopnav_env.agents.heuristics`
fly along it with :class:`Polyline`.

Frames and units: the city's local East-North-Up frame, metres; routes are horizontal
``(k, 2)`` arrays of East/North waypoints.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from coopnav_env.sim import _kernels
from coopnav_env.sim.file_city import FileCity

__all__ = [
    "Polyline",
    "advance_waypoints",
    "extend_route",
    "remaining_route_m",
    "route_tail_lengths_m",
    "street_route",
    "street_routes",
]


# --------------------------------------------------------------------------------------------
# route planning on the street grid
# --------------------------------------------------------------------------------------------


def _first_min(distances: list[float]) -> tuple[float, int]:
    """The smallest distance and its first index (``inf, -1`` when empty; as numpy's ``min``
    and ``argmin``, the first NaN where there is one)."""
    best, arg = math.inf, -1
    for i, d in enumerate(distances):
        if d != d:
            return d, i
        if d < best or arg < 0:
            best, arg = d, i
    return best, arg


def _street_of(x: float, y: float, cx: list[float], cy: list[float]) -> tuple[str, float]:
    """The street a point is on: ``("ns", x_centre)`` or ``("ew", y_centre)``, the nearest
    (a north-south one where both are as near)."""
    dx, ix = _first_min([abs(c - x) for c in cx])
    dy, iy = _first_min([abs(c - y) for c in cy])
    if dx <= dy:
        return "ns", cx[ix]
    return "ew", cy[iy]


def _snapped_ends(
    city: Any, start_xy: ArrayLike, goal_xy: ArrayLike
) -> tuple[list[float], list[float], tuple[str, float, float], tuple[str, float, float]]:
    """The street centre lines (x of the north-south ones, y of the east-west ones, as
    Python floats: a grid has a few, and scalar arithmetic on them is numpy's, bit for bit)
    and both ends snapped to their nearest street: ``(kind, East, North)`` each."""
    cx = np.asarray(city.street_centres_x_m, dtype=float).reshape(-1).tolist()
    cy = np.asarray(city.street_centres_y_m, dtype=float).reshape(-1).tolist()
    if not cx and not cy:
        raise ValueError("street_route needs a city with at least one street")
    ends = []
    for xy in (start_xy, goal_xy):
        x, y = np.asarray(xy, dtype=float).reshape(2).tolist()
        kind, c = _street_of(x, y, cx, cy)
        ends.append((kind, c, y) if kind == "ns" else (kind, x, c))
    return cx, cy, ends[0], ends[1]


def _nearest_pair(values: list[float], a: float, b: float) -> float:
    """The value with the smallest ``|v - a| + |v - b|`` (:func:`_first_min`'s choice)."""
    return values[_first_min([abs(v - a) + abs(v - b) for v in values])[1]]


def street_route(city: Any, start_xy: ArrayLike, goal_xy: ArrayLike) -> np.ndarray:
    """Shortest route along street centre lines from ``start_xy`` to ``goal_xy``.

    Each end is snapped to its nearest street centre line (north-south or east-west). On the
    same street the route is straight; on crossing streets it turns once at their
    intersection; on two parallel streets it turns twice, through the cross street that
    minimises the length (ties: the first in the city's order).

    A :class:`~coopnav_env.sim.file_city.FileCity` has no street grid: its route is
    :meth:`~coopnav_env.sim.file_city.FileCity.free_space_route` (ends off the free space are
    snapped to it).

    Parameters
    ----------
    city : coopnav_env.sim.city.City
        Anything with ``street_centres_x_m`` (north-south centre lines, East [m]) and
        ``street_centres_y_m`` (east-west centre lines, North [m]), each street spanning the
        whole city; at least one street.
    start_xy, goal_xy : array_like, shape (2,)
        East/North of the start and the goal [m].

    Returns
    -------
    ndarray, shape (k, 2)
        Waypoints [m], ``1 <= k <= 4``: the snapped start, the corners, the snapped goal,
        without repeated points (``k = 1`` when both ends snap to the same point).
    """
    if isinstance(city, FileCity):
        return city.free_space_route(start_xy, goal_xy, snap=True)
    cx, cy, (s_kind, sx, sy), (g_kind, gx, gy) = _snapped_ends(city, start_xy, goal_xy)
    pts: list[tuple[float, float]] = [(sx, sy)]
    if s_kind == g_kind == "ns":
        if not math.isclose(sx, gx) and cy:
            b = _nearest_pair(cy, sy, gy)
            pts += [(sx, b), (gx, b)]
    elif s_kind == g_kind == "ew":
        if not math.isclose(sy, gy) and cx:
            b = _nearest_pair(cx, sx, gx)
            pts += [(b, sy), (b, gy)]
    elif s_kind == "ns":
        pts.append((sx, gy))
    else:
        pts.append((gx, sy))
    pts.append((gx, gy))
    return np.array(_without_repeats(pts), dtype=float).reshape(-1, 2)


def _without_repeats(pts: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """``pts`` without points within 1 um of the one kept before them."""
    out = [pts[0]]
    for p in pts[1:]:
        if math.hypot(p[0] - out[-1][0], p[1] - out[-1][1]) > 1e-6:
            out.append(p)
    return out


def _clean_route(pts: list[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
    """Drop repeated points and straight-through (collinear) corners of a waypoint list."""
    out = _without_repeats(pts)
    k = 1
    while k < len(out) - 1:
        a, b, c = out[k - 1], out[k], out[k + 1]
        cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
        if abs(cross) < 1e-6:
            del out[k]
        else:
            k += 1
    return tuple(out)


def street_routes(
    city: Any, start_xy: ArrayLike, goal_xy: ArrayLike, max_turns: int = 3
) -> list[np.ndarray]:
    """Every shortest route along street centre lines with at most ``max_turns`` turns.

    On a Manhattan grid many routes share the shortest length: any staircase that never
    moves away from the goal. They differ in the streets they fly through, and so in the
    buildings that shade the sky along them (the ``route_choice`` option of
    :class:`coopnav_env.agents.heuristics.ColumnPolicy`). Each end is snapped to its nearest
    street centre line as in :func:`street_route`; the routes alternate between north-south and
    east-west legs, starting on the start's street and ending on the goal's, and turn only at
    street intersections.

    Parameters
    ----------
    city : coopnav_env.sim.city.City
        As for :func:`street_route`.
    start_xy, goal_xy : array_like, shape (2,)
        East/North of the start and the goal [m].
    max_turns : int, default 3
        Most turns of a route, in [0, 8]. Each turn makes a column brake to its turn speed,
        so routes with more turns take longer although they are as long.

    Returns
    -------
    list of ndarray, each shape (k, 2)
        The routes [m], first the one :func:`street_route` returns (always included, even
        when it has more turns than ``max_turns`` or the grid leaves no route of its length
        with fewer turns), then the others of the same length (within 1 mm) by number of
        turns and then waypoints, without duplicates.
    """
    if isinstance(max_turns, bool) or not isinstance(max_turns, (int, np.integer)):
        raise ValueError(f"max_turns must be an int in [0, 8], got {max_turns!r}")
    if not 0 <= int(max_turns) <= 8:
        raise ValueError(f"max_turns must be in [0, 8], got {max_turns}")
    first = street_route(city, start_xy, goal_xy)
    if isinstance(city, FileCity):  # one route through the free space
        return [first]
    cx, cy, (s_kind, sx, sy), (g_kind, gx, gy) = _snapped_ends(city, start_xy, goal_xy)
    s_c = sx if s_kind == "ns" else sy
    g_c = gx if g_kind == "ns" else gy

    def between(vals: list[float], a: float, b: float) -> list[float]:
        lo, hi = min(a, b) - 1e-6, max(a, b) + 1e-6
        return [float(v) for v in vals if lo <= v <= hi]

    # only streets between the ends can lie on a shortest (monotone) route
    xs, ys = between(cx, sx, gx), between(cy, sy, gy)
    found: dict[tuple[tuple[float, float], ...], None] = {}
    for legs in range(1, int(max_turns) + 2):
        kinds = [("ns", "ew")[(k + (s_kind == "ew")) % 2] for k in range(legs)]
        if kinds[-1] != g_kind:
            continue
        inner = [xs if k == "ns" else ys for k in kinds[1:-1]]
        for choice in itertools.product(*inner):
            coords = [s_c, *choice, g_c] if legs > 1 else [s_c]
            if legs == 1 and not math.isclose(s_c, g_c):
                continue
            pts = [(sx, sy)]
            for k in range(legs - 1):
                a, b = coords[k], coords[k + 1]
                pts.append((a, b) if kinds[k] == "ns" else (b, a))
            pts.append((gx, gy))
            found.setdefault(_clean_route(pts), None)
    first_key = _clean_route([tuple(p) for p in first])
    shortest = _route_length(first)
    others = [r for r in found if r != first_key and _route_length(np.array(r)) <= shortest + 1e-3]
    others.sort(key=lambda r: (len(r), r))
    return [first] + [np.array(r, dtype=float).reshape(-1, 2) for r in others]


def _route_length(route: np.ndarray) -> float:
    seg = np.diff(np.asarray(route, dtype=float).reshape(-1, 2), axis=0)
    return float(np.hypot(seg[:, 0], seg[:, 1]).sum())


def extend_route(points: ArrayLike, back_m: float, fwd_m: float, extent: tuple) -> np.ndarray:
    """Prepend/append straight extensions along the first/last leg, kept inside ``extent``.

    Parameters
    ----------
    points : array_like, shape (k, 2)
        A route [m].
    back_m, fwd_m : float
        Length of the extension before the first and after the last waypoint [m].
    extent : tuple of 4 float
        ``(x_min, x_max, y_min, y_max)`` of the city [m]; the extensions stop 2 m inside it.

    Returns
    -------
    ndarray, shape (k', 2)
        The route with up to two extra end points (a single point extends northward).
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if pts.shape[0] < 2:
        d0 = d1 = np.array([0.0, 1.0])
    else:
        d0 = pts[1] - pts[0]
        d0 /= np.linalg.norm(d0)
        d1 = pts[-1] - pts[-2]
        d1 /= np.linalg.norm(d1)
    x0, x1, y0, y1 = extent
    lo, hi = np.array([x0 + 2.0, y0 + 2.0]), np.array([x1 - 2.0, y1 - 2.0])
    first = np.clip(pts[0] - d0 * back_m, lo, hi)
    last = np.clip(pts[-1] + d1 * fwd_m, lo, hi)
    out = [first] if np.linalg.norm(first - pts[0]) > 1e-6 else []
    out += list(pts)
    if np.linalg.norm(last - pts[-1]) > 1e-6:
        out.append(last)
    return np.array(out)


# --------------------------------------------------------------------------------------------
# waypoint tracking
# --------------------------------------------------------------------------------------------


def route_tail_lengths_m(route: ArrayLike) -> np.ndarray:
    """Length of the route after each waypoint [m], shape ``(k,)`` (0 at the last one)."""
    pts = np.asarray(route, dtype=float).reshape(-1, 2).tolist()
    # the legs' lengths as numpy's norm of each difference (sqrt of dx^2 + dy^2) and their
    # sums from the end, in Python floats (a route has a few points)
    tail = [0.0] * max(len(pts), 1)
    acc = 0.0
    for i in range(len(pts) - 2, -1, -1):
        dx = pts[i + 1][0] - pts[i][0]
        dy = pts[i + 1][1] - pts[i][1]
        acc += math.sqrt(dx * dx + dy * dy)
        tail[i] = acc
    return np.array(tail)


def remaining_route_m(
    route: ArrayLike, xy: ArrayLike, next_wp: ArrayLike, tail_m: np.ndarray | None = None
) -> np.ndarray:
    """Remaining route length of each point: straight to its next waypoint, then along the route.

    ``|xy - route[next_wp]| + (length of the route after route[next_wp])``.

    Parameters
    ----------
    route : array_like, shape (k, 2)
        Waypoints [m].
    xy : array_like, shape (n, 2)
        Horizontal positions [m].
    next_wp : array_like of int, shape (n,)
        Index of each point's next waypoint, in ``[0, k - 1]``.
    tail_m : ndarray, shape (k,), optional
        :func:`route_tail_lengths_m` of ``route``, when the caller already has it.

    Returns
    -------
    ndarray, shape (n,)
        [m].
    """
    pts = np.asarray(route, dtype=float).reshape(-1, 2)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    idx = np.asarray(next_wp, dtype=np.int64)
    d = np.linalg.norm(xy - pts[idx], axis=1)
    return d + (route_tail_lengths_m(pts) if tail_m is None else tail_m)[idx]


def advance_waypoints(
    route: ArrayLike, xy: ArrayLike, next_wp: ArrayLike, reach_m: float
) -> np.ndarray:
    """Advance each point's next waypoint once it is reached or passed.

    Waypoint ``i`` (not the last) counts as reached by a point that is within ``reach_m`` of it
    along both East and North (inside the square of side ``2 reach_m`` centred on it: with
    ``reach_m`` half the street width, the intersection of a corner), or that is past it along
    the leg that arrives at it (``(xy - w_i) . (w_i - w_{i-1}) >= 0``). The test repeats, so
    a point may skip several waypoints in one call. The last waypoint (the goal) is never
    passed.

    Parameters
    ----------
    route : array_like, shape (k, 2)
        Waypoints [m].
    xy : array_like, shape (n, 2)
        Horizontal positions [m] (the environment passes the *estimated* positions).
    next_wp : array_like of int, shape (n,)
        Current next waypoint of each point, in ``[0, k - 1]``.
    reach_m : float
        Half side of the reach square [m], >= 0.

    Returns
    -------
    ndarray of int, shape (n,)
        The updated indices (a new array), never smaller than ``next_wp``. Computed in one
        compiled call (:func:`coopnav_env.sim._kernels.advance_waypoints`).
    """
    pts = np.asarray(route, dtype=float).reshape(-1, 2)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    idx = np.array(next_wp, dtype=np.int64, copy=True).reshape(-1)
    return _kernels.advance_waypoints(
        np.ascontiguousarray(pts), np.ascontiguousarray(xy), idx, float(reach_m)
    )


# --------------------------------------------------------------------------------------------
# arc-length polyline
# --------------------------------------------------------------------------------------------


class Polyline:
    """A 2-D polyline parametrised by arc length.

    Parameters
    ----------
    points : array_like, shape (k, 2)
        Vertices [m]; consecutive duplicates are not allowed (k >= 1; a single point becomes
        a 1 mm segment).
    """

    def __init__(self, points: ArrayLike):
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if pts.shape[0] == 1:
            pts = np.vstack([pts, pts + np.array([1e-3, 0.0])])
        self.points = pts
        seg = np.diff(pts, axis=0)
        self.seg_len = np.linalg.norm(seg, axis=1)
        self.seg_dir = seg / self.seg_len[:, None]
        self.s = np.r_[0.0, np.cumsum(self.seg_len)]  # arc length at each vertex
        self.length = float(self.s[-1])

    def _seg(self, s: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, self.seg_len.size - 1)

    def point(self, s: ArrayLike) -> np.ndarray:
        """Points at arc lengths ``s`` (clamped to the ends), shape ``s.shape + (2,)``."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        k = self._seg(s)
        return self.points[k] + self.seg_dir[k] * (s - self.s[k])[..., None]

    def tangent(self, s: ArrayLike) -> np.ndarray:
        """Unit tangents at arc lengths ``s``, shape ``s.shape + (2,)``."""
        return self.seg_dir[self._seg(np.clip(np.asarray(s, dtype=float), 0.0, self.length))]

    def distance_to_corner(self, s: ArrayLike) -> np.ndarray:
        """Arc length from ``s`` to the next interior vertex (inf after the last one)."""
        s = np.asarray(s, dtype=float)
        corners = self.s[1:-1]
        if corners.size == 0:
            return np.full(s.shape, np.inf)
        ahead = corners[None, :] - s.reshape(-1, 1)
        ahead = np.where(ahead >= -1e-9, ahead, np.inf)
        return ahead.min(axis=1).reshape(s.shape)

    def project(self, xy: ArrayLike, lo: ArrayLike, hi: ArrayLike) -> np.ndarray:
        """Arc length of the nearest point of the polyline within ``[lo, hi]``, per point.

        Parameters
        ----------
        xy : array_like, shape (n, 2)
        lo, hi : array_like, shape (n,)
            Window of admissible arc lengths (keeps the projection from jumping to another
            leg of the route).
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        lo = np.asarray(lo, dtype=float)
        hi = np.asarray(hi, dtype=float)
        rel = xy[:, None, :] - self.points[None, :-1, :]  # (n, m, 2)
        t = np.clip(np.einsum("nmk,mk->nm", rel, self.seg_dir), 0.0, self.seg_len[None, :])
        s = self.s[None, :-1] + t
        s = np.clip(s, lo[:, None], hi[:, None])
        k = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, self.seg_len.size - 1)
        pts = self.points[k] + self.seg_dir[k] * (s - self.s[k])[..., None]
        d = np.linalg.norm(pts - xy[:, None, :], axis=2)
        best = np.argmin(d, axis=1)
        return s[np.arange(xy.shape[0]), best]
