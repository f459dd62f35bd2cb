"""Numpy oracles of the world's compiled kernels (:mod:`coopnav_env.sim._kernels`).

Each function here computes what one compiled path of :mod:`coopnav_env.sim` computes, written
with numpy array operations: the readable definition of the kernel, which the library no longer
runs. Most perform the same floating-point operations in the same order as their kernel
(numpy's ``maximum`` and ``clip`` with their signed zeros included), so the tests compare the
two bit for bit. :func:`use_oracles_in_world` puts them in place of the kernels in
:class:`~coopnav_env.sim.scenario.UrbanWorld`'s function-by-function path, for end-to-end
comparisons of whole episodes.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.nav import NavStatus
from coopnav_env.sim import city as _city
from coopnav_env.sim import map_aided as _map_aided
from coopnav_env.sim import scenario as _scenario
from coopnav_env.sim.city import (
    CHUNK_ELEMENTS,
    BoolArray,
    Buildings,
    FloatArray,
    SkyDirections,
    _as_points,
    _check_real,
    _chunk_slices,
    ray_directions,
)
from coopnav_env.sim.scenario import NavSource
from coopnav_env.sim.swarm import (
    KinematicsConfig,
    RelativeSensingConfig,
    pairwise_ranges_m,
    step_kinematics,
    swept_collisions,
)

__all__ = [
    "advance_waypoints",
    "blocked_sorted",
    "largest_component",
    "mask_elevation_deg",
    "navigate_function_by_function",
    "relative_measurements",
    "select_navigation",
    "separation_violations",
    "sky_and_walls",
    "slab_interval",
    "swept_collisions_culled",
    "trace_line_of_sight",
    "use_oracles_in_world",
    "wall_distance_m",
    "world_motion",
]


# --------------------------------------------------------------------------------------------
# line of sight (city._trace_line_of_sight, _kernels.line_of_sight / blocked_sorted)
# --------------------------------------------------------------------------------------------


def slab_interval(
    p: Sequence[FloatArray],
    d: Sequence[FloatArray],
    lo: Sequence[FloatArray],
    hi: Sequence[FloatArray],
) -> tuple[FloatArray, FloatArray]:
    """Parameter interval ``[t_near, t_far]`` of the line ``p + t d`` inside a box.

    Each argument is a sequence with one array per coordinate axis (2 or 3 axes); the arrays
    broadcast against each other. Axes along which ``d`` is zero are handled exactly (the line
    is inside that slab for all ``t`` or for none). The box is missed when ``t_near > t_far``.
    """
    t_near: FloatArray | None = None
    t_far: FloatArray | None = None
    for p_k, d_k, lo_k, hi_k in zip(p, d, lo, hi, strict=True):
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d_k
            t1 = (lo_k - p_k) * inv
            t2 = (hi_k - p_k) * inv
        t_lo = np.minimum(t1, t2)
        t_hi = np.maximum(t1, t2)
        zero = d_k == 0.0
        if np.any(zero):
            in_slab = (p_k >= lo_k) & (p_k <= hi_k)
            t_lo = np.where(zero, np.where(in_slab, -np.inf, np.inf), t_lo)
            t_hi = np.where(zero, np.where(in_slab, np.inf, -np.inf), t_hi)
        t_near = t_lo if t_near is None else np.maximum(t_near, t_lo)
        t_far = t_hi if t_far is None else np.minimum(t_far, t_hi)
    assert t_near is not None and t_far is not None
    return t_near, t_far


def _ragged_chunks(counts: NDArray[np.intp], max_total: int) -> Iterator[tuple[int, int]]:
    """Ranges ``[p0, p1)`` of items whose ``counts`` sum to at most ``max_total`` (or 1 item)."""
    cum = np.cumsum(counts)
    start, n = 0, counts.size
    while start < n:
        base = int(cum[start - 1]) if start else 0
        stop = max(int(np.searchsorted(cum, base + max_total, side="right")), start + 1)
        yield start, stop
        start = stop


def blocked_sorted(
    pos: FloatArray, lo: FloatArray, hi: FloatArray, cot_s: FloatArray, h_dir: FloatArray
) -> BoolArray:
    """:func:`coopnav_env.sim._kernels.blocked_sorted`: blocked (receiver, rising satellite)
    pairs ``(n_rx, n_up)``, satellites in the sorted order of
    :class:`~coopnav_env.sim.city.SkyDirections` (``cot_s`` increasing, ``h_dir`` (n_up, 2)).

    (Receiver, building) pairs are culled first (no roof above the receiver, or the footprint
    beyond the reach of the lowest ray); per remaining pair only the satellites low enough to
    pass under the roof at the footprint's nearest point are tested, with the slab test of
    the horizontal ray and the height test, in bounded chunks of triples.
    """
    n_rx, n_up = pos.shape[0], cot_s.size
    blocked_s = np.zeros((n_rx, n_up), dtype=bool)  # columns in sorted order
    if n_up == 0:
        return blocked_s
    for cb in _chunk_slices(lo.shape[0], 4 * n_rx):
        # 1. cull (receiver, building) pairs, arrays of shape (n_rx, n_b_chunk)
        climb_m = hi[None, cb, 2] - pos[:, None, 2]
        dx = np.maximum(
            np.maximum(lo[None, cb, 0] - pos[:, None, 0], 0.0), pos[:, None, 0] - hi[None, cb, 0]
        )
        dy = np.maximum(
            np.maximum(lo[None, cb, 1] - pos[:, None, 1], 0.0), pos[:, None, 1] - hi[None, cb, 1]
        )
        dist_xy = np.hypot(dx, dy)
        rx_idx, b_loc = np.nonzero((climb_m > 0.0) & (dist_xy <= climb_m * cot_s[-1]))
        # 2. per pair, only satellites low enough to pass under the roof at the footprint's
        #    nearest point can be blocked: those with cot(el) >= dist_xy / climb
        first = np.searchsorted(cot_s, dist_xy[rx_idx, b_loc] / climb_m[rx_idx, b_loc])
        some = first < n_up
        rx_idx, b_idx, first = rx_idx[some], b_loc[some] + cb.start, first[some]
        n_cand = n_up - first
        # 3. exact test on the (receiver, building, satellite) triples, in bounded chunks
        for p0, p1 in _ragged_chunks(n_cand, CHUNK_ELEMENTS // 16):
            k = n_cand[p0:p1]
            pair = np.repeat(np.arange(p0, p1), k)
            sat = first[pair] + np.arange(pair.size) - np.repeat(np.cumsum(k) - k, k)
            rx, b = rx_idx[pair], b_idx[pair]
            t_near, t_far = slab_interval(
                [pos[rx, 0], pos[rx, 1]],
                [h_dir[sat, 0], h_dir[sat, 1]],
                [lo[b, 0], lo[b, 1]],
                [hi[b, 0], hi[b, 1]],
            )  # horizontal distances along the ray's azimuth
            climb_t = hi[b, 2] - pos[rx, 2]
            hit = (
                (t_far > 0.0)
                & (t_near <= t_far)
                & (np.maximum(t_near, 0.0) <= climb_t * cot_s[sat])
            )
            blocked_s[rx[hit], sat[hit]] = True
    return blocked_s


def trace_line_of_sight(buildings: Buildings, pos: FloatArray, sky: SkyDirections) -> BoolArray:
    """``city._trace_line_of_sight`` for box buildings: visible (receiver, satellite) pairs
    ``(n_rx, n_sv)`` of validated receivers ``pos`` (n_rx, 3) and prepared directions ``sky``
    (:func:`~coopnav_env.sim.city.sky_directions`). A satellite below the horizon is never
    visible; a rising one is unless :func:`blocked_sorted` finds a building in the way (a
    receiver inside a building needs no special case: its footprint distance is 0, so every
    satellite is tested, and the ray starts inside the footprint below the roof)."""
    n_rx, n_sv = pos.shape[0], sky.n_sv
    up = sky.up
    visible = np.broadcast_to(up, (n_rx, n_sv)).copy()
    if buildings.n == 0 or n_rx == 0 or not np.any(up):
        return visible
    blocked_s = blocked_sorted(pos, buildings.min_m, buildings.max_m, sky.cot_s, sky.h_dir)
    blocked_up = np.empty_like(blocked_s)
    blocked_up[:, sky.order] = blocked_s
    visible[:, up] = ~blocked_up
    return visible


# --------------------------------------------------------------------------------------------
# horizontal sensors (city.sky_and_walls, _kernels.sky_and_walls)
# --------------------------------------------------------------------------------------------


class _HorizontalSweep:
    """Slab intervals of horizontal rays (receivers x azimuths) against the building footprints.

    Iterating yields ``(t_near, t_far, lo, hi)`` per chunk of buildings taller than the lowest
    receiver: the footprint entry/exit distances, shape ``(n, n_az, n_chunk)``, and the chunk's
    box corners broadcastable as ``(1, 1, n_chunk, 3)``. Chunking bounds the memory.
    """

    def __init__(self, buildings: Buildings, pos: FloatArray, az_deg: ArrayLike) -> None:
        self._dir = ray_directions(az_deg)
        self._pos = pos
        self.shape = (pos.shape[0], self._dir.shape[0])
        if buildings.n == 0 or pos.shape[0] == 0 or self._dir.shape[0] == 0:
            self._tall = np.zeros(0, dtype=np.intp)
        else:
            self._tall = np.flatnonzero(buildings.max_m[:, 2] > pos[:, 2].min())
        self._lo = buildings.min_m[self._tall]
        self._hi = buildings.max_m[self._tall]

    def __iter__(self):
        pos, d, lo, hi = self._pos, self._dir, self._lo, self._hi
        for cb in _chunk_slices(self._tall.size, 2 * self.shape[0] * self.shape[1]):
            t_near, t_far = _sweep_slab(pos, d, lo[cb], hi[cb])
            yield t_near, t_far, lo[None, None, cb], hi[None, None, cb]


def _sweep_slab(
    pos: FloatArray, d: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`slab_interval` of receivers (n, 3) x directions (n_az, 2) x boxes (m, 3).

    The same values, computed the same way, except that the directions with a zero component
    along an axis (the cardinal azimuths) get their infinite slab bounds written into their
    columns only, instead of by full-size ``where`` passes over every azimuth.
    """
    t_near: FloatArray | None = None
    t_far: FloatArray | None = None
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(2):
            p_k, lo_k, hi_k = pos[:, None, None, k], lo[None, None, :, k], hi[None, None, :, k]
            inv = 1.0 / d[None, :, None, k]
            t1 = (lo_k - p_k) * inv
            t2 = (hi_k - p_k) * inv
            t_lo = np.minimum(t1, t2)
            t_hi = np.maximum(t1, t2, out=t1)  # (in place: fewer large temporaries)
            zero = np.flatnonzero(d[:, k] == 0.0)
            if zero.size:
                in_slab = (p_k >= lo_k) & (p_k <= hi_k)  # (n, 1, m)
                t_lo[:, zero, :] = np.where(in_slab, -np.inf, np.inf)
                t_hi[:, zero, :] = np.where(in_slab, np.inf, -np.inf)
            if t_near is None or t_far is None:
                t_near, t_far = t_lo, t_hi
            else:
                np.maximum(t_near, t_lo, out=t_near)
                np.minimum(t_far, t_hi, out=t_far)
    assert t_near is not None and t_far is not None
    return t_near, t_far


def _skyline_tan(pos: FloatArray, entered, t_in, t_far, hi) -> FloatArray:
    """Largest ``tan(elevation)`` of a roof edge per (receiver, azimuth) over a building chunk.

    ``entered = t_near <= t_far`` and ``t_in = max(t_near, 0)`` of the sweep, ``(n, n_az, m)``.
    """
    rel_h = hi[..., 2] - pos[:, None, None, 2]
    hit = (t_far > 0.0) & entered & (rel_h > 0.0)
    tan_el = np.zeros(hit.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(rel_h, t_in, out=tan_el, where=hit)  # +inf inside a footprint
    return tan_el.max(axis=2)


def _wall_min(pos: FloatArray, entered, t_in, t_far, lo, hi) -> FloatArray:
    """Nearest footprint entry per (receiver, azimuth) over a building chunk (inf: none)."""
    z = pos[:, None, None, 2]
    below_roof = (z < hi[..., 2]) & (z >= lo[..., 2])
    hit = (t_far >= 0.0) & entered & below_roof
    return np.where(hit, t_in, np.inf).min(axis=2)


def sky_and_walls(
    buildings: Buildings, pos_enu_m: ArrayLike, az_deg: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """:func:`coopnav_env.sim.city.sky_and_walls` for box buildings: the skyline elevation
    [deg] and the distance to the nearest wall [m] along each azimuth, each ``(n, n_az)``,
    from one chunked sweep of the horizontal rays through the footprints."""
    pos = _as_points(pos_enu_m, "pos_enu_m")
    sweep = _HorizontalSweep(buildings, pos, az_deg)
    tan_max = np.zeros(sweep.shape)
    dist = np.full(sweep.shape, np.inf)
    for t_near, t_far, lo, hi in sweep:
        entered = t_near <= t_far
        t_in = np.maximum(t_near, 0.0)
        tan_max = np.maximum(tan_max, _skyline_tan(pos, entered, t_in, t_far, hi))
        dist = np.minimum(dist, _wall_min(pos, entered, t_in, t_far, lo, hi))
    return np.degrees(np.arctan(tan_max)), dist


def mask_elevation_deg(buildings: Buildings, pos_enu_m: ArrayLike, az_deg: ArrayLike) -> FloatArray:
    """:func:`coopnav_env.sim.city.mask_elevation_deg` for box buildings, ``(n, n_az)`` [deg]:
    the skyline part of :func:`sky_and_walls` from a sweep of its own."""
    pos = _as_points(pos_enu_m, "pos_enu_m")
    tan_max = np.zeros((pos.shape[0], np.asarray(az_deg).shape[0]))
    for t_near, t_far, _lo, hi in _HorizontalSweep(buildings, pos, az_deg):
        entered = t_near <= t_far
        tan_max = np.maximum(
            tan_max, _skyline_tan(pos, entered, np.maximum(t_near, 0.0), t_far, hi)
        )
    return np.degrees(np.arctan(tan_max))


def wall_distance_m(buildings: Buildings, pos_enu_m: ArrayLike, az_deg: ArrayLike) -> FloatArray:
    """:func:`coopnav_env.sim.city.wall_distance_m` for box buildings, ``(n, n_az)`` [m]: the
    wall part of :func:`sky_and_walls` from a sweep of its own."""
    pos = _as_points(pos_enu_m, "pos_enu_m")
    dist = np.full((pos.shape[0], np.asarray(az_deg).shape[0]), np.inf)
    for t_near, t_far, lo, hi in _HorizontalSweep(buildings, pos, az_deg):
        t_in = np.maximum(t_near, 0.0)
        dist = np.minimum(dist, _wall_min(pos, t_near <= t_far, t_in, t_far, lo, hi))
    return dist


# --------------------------------------------------------------------------------------------
# the swarm (swarm.separation_violations, swarm._measure_relative) and the route
# --------------------------------------------------------------------------------------------


def separation_violations(pos_enu_m: ArrayLike, min_separation_m: float) -> BoolArray:
    """:func:`coopnav_env.sim.swarm.separation_violations`: UAVs ``(n,)`` with another UAV
    strictly closer than ``min_separation_m``, from the matrix of pairwise ranges."""
    sep = _check_real("separation_violations", "min_separation_m", min_separation_m, 0.0)
    rng_m = pairwise_ranges_m(pos_enu_m)
    np.fill_diagonal(rng_m, np.inf)
    return np.any(rng_m < sep, axis=1)


def relative_measurements(
    pos: FloatArray, z: FloatArray, cfg: RelativeSensingConfig
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """:func:`coopnav_env.sim._kernels.relative_measurements` with the sensing settings
    ``cfg``: measured relative positions ``rel`` (n, n, 3), per-axis variances ``var`` (n, n)
    and availability (n, n) of UAVs at ``pos`` (n, 3), from the standard normal draws ``z``
    (n (n - 1) / 2, 3) of the upper triangle in row-major order (antisymmetric errors)."""
    n = pos.shape[0]
    diff = pos[None, :, :] - pos[:, None, :]  # diff[b, q] = pos[q] - pos[b]
    range_m = np.linalg.norm(diff, axis=2)
    sigma = cfg.sigma_m(range_m)
    iu, ju = np.triu_indices(n, 1)
    eps = np.zeros((n, n, 3))
    eps[iu, ju] = z * sigma[iu, ju, None]
    eps[ju, iu] = -eps[iu, ju]
    available = (range_m > 0.0) & (range_m <= cfg.max_range_m)
    np.fill_diagonal(available, False)
    rel = np.where(available[:, :, None], diff + eps, 0.0)
    var = np.where(available, sigma**2, 0.0)
    return rel, var, available


def advance_waypoints(
    route: ArrayLike, xy: ArrayLike, next_wp: ArrayLike, reach_m: float
) -> np.ndarray:
    """:func:`coopnav_env.sim.route.advance_waypoints`: each point's next waypoint index
    ``(n,)`` (int64, a new array), advanced while the point is within ``reach_m`` of it along
    East and North or past it along the leg arriving at it, never beyond the last waypoint;
    all points at once, one round per possible skip."""
    pts = np.asarray(route, dtype=float).reshape(-1, 2)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    idx = np.array(next_wp, dtype=np.int64, copy=True).reshape(-1)
    k = pts.shape[0]
    arrive = np.zeros_like(pts)  # direction of the leg arriving at each waypoint
    if k > 1:
        arrive[1:] = np.diff(pts, axis=0)
    for _ in range(k):
        not_last = idx < k - 1
        w = pts[idx]
        near = np.all(np.abs(xy - w) <= reach_m, axis=1)
        past = np.einsum("ij,ij->i", xy - w, arrive[idx]) >= 0.0
        past &= np.any(arrive[idx] != 0.0, axis=1)
        step = not_last & (near | past)
        if not step.any():
            break
        idx[step] += 1
    return idx


# --------------------------------------------------------------------------------------------
# motion (scenario._world_motion, _kernels.world_motion / swept_collisions_culled)
# --------------------------------------------------------------------------------------------


def swept_collisions_culled(
    buildings: Buildings, start_enu_m: FloatArray, end_enu_m: FloatArray, radius_m: float
) -> BoolArray:
    """:func:`~coopnav_env.sim.swarm.swept_collisions` restricted to the (UAV, building) pairs
    whose boxes overlap (the definition of ``_kernels.swept_collisions_culled``).

    The bounding box of each swept sphere is tested against every building box first; the
    exact segment-box distance then runs on the UAVs and buildings of overlapping pairs. The
    result equals :func:`~coopnav_env.sim.swarm.swept_collisions` (the exact test runs on a
    superset of the pairs that can collide).
    """
    n = start_enu_m.shape[0]
    lo = np.minimum(start_enu_m, end_enu_m) - radius_m
    hi = np.maximum(start_enu_m, end_enu_m) + radius_m
    overlap = np.all(
        (lo[:, None, :] <= buildings.max_m[None]) & (hi[:, None, :] >= buildings.min_m[None]),
        axis=2,
    )  # (N, n_b)
    hit = np.zeros(n, dtype=bool)
    uav = np.flatnonzero(overlap.any(axis=1))
    if uav.size == 0:
        return hit
    bld = np.flatnonzero(overlap.any(axis=0))
    sub = Buildings(buildings.min_m[bld], buildings.max_m[bld])
    hit[uav] = swept_collisions(sub, start_enu_m[uav], end_enu_m[uav], radius_m)
    return hit


def world_motion(
    pos0: FloatArray,
    vel0: FloatArray,
    cmd: FloatArray,
    kin: KinematicsConfig,
    lo: FloatArray,
    hi: FloatArray,
    buildings,
) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """``pos1, vel1, hit, sep`` of one motion step: the definition of
    ``scenario._world_motion`` (same arguments, same results). Kinematics, the fence at
    ``[lo, hi]``, swept collisions (a UAV that hits stays where it was, at rest) and the
    separation violations of the new positions."""
    pos1, vel1 = step_kinematics(pos0, vel0, cmd, kin)
    out = (pos1[:, :2] < lo) | (pos1[:, :2] > hi)
    pos1[:, :2] = np.clip(pos1[:, :2], lo, hi)
    vel1[:, :2] = np.where(out, 0.0, vel1[:, :2])
    if isinstance(buildings, Buildings):
        hit = swept_collisions_culled(buildings, pos0, pos1, kin.uav_radius_m)
    else:  # a file city's extruded polygons
        hit = buildings.swept_collisions(pos0, pos1, kin.uav_radius_m)
    pos1[hit] = pos0[hit]
    vel1[hit] = 0.0
    sep = separation_violations(pos1, kin.min_separation_m)
    return pos1, vel1, hit, sep


# --------------------------------------------------------------------------------------------
# the estimate selection (scenario._select_navigation, _kernels.select_navigation)
# --------------------------------------------------------------------------------------------


def _sigma_within(cov_ecef_m2: FloatArray, max_sigma_m: float | None) -> BoolArray:
    """``sqrt(trace(cov)) <= max_sigma_m`` per fix (True everywhere when the gate is off); the
    trace is invariant under the ECEF-ENU rotation, NaN covariances give False."""
    if max_sigma_m is None:
        return np.ones(cov_ecef_m2.shape[0], dtype=bool)
    tr = np.einsum("nii->n", cov_ecef_m2)
    with np.errstate(invalid="ignore"):
        return tr <= max_sigma_m**2


def select_navigation(world, sa, co, linked, pred_enu, dr_var):
    """The estimate each UAV uses, cooperative, else standalone, else dead reckoning: the
    definition of ``scenario._select_navigation`` (same arguments and results; the kernel
    rotates to ENU in loops instead of matmuls, 1e-13 apart)."""
    cfg = world.config
    sa_ok = sa.status == NavStatus.OK
    co_status = np.where(linked, co.status, NavStatus.NO_RELATIVE_POSITION).astype(np.int64)
    co_ok = co_status == NavStatus.OK
    # integrity gate: a fix whose predicted 3-D sigma is too large is not used
    sa_rej = sa_ok & ~_sigma_within(sa.cov_ecef_m2, cfg.max_fix_sigma_m)
    co_rej = co_ok & ~_sigma_within(co.cov_ecef_m2, cfg.max_fix_sigma_m)
    sa_ok &= ~sa_rej
    co_ok &= ~co_rej
    sa_pos = np.where(sa_ok[:, None], world.ecef_to_enu(sa.pos_ecef_m), np.nan)
    sa_cov = np.where(sa_ok[:, None, None], world.cov_ecef_to_enu(sa.cov_ecef_m2), np.nan)
    co_pos = np.where(co_ok[:, None], world.ecef_to_enu(co.pos_ecef_m), np.nan)
    co_cov = np.where(co_ok[:, None, None], world.cov_ecef_to_enu(co.cov_ecef_m2), np.nan)
    source = np.where(
        co_ok,
        NavSource.COOPERATIVE,
        np.where(sa_ok, NavSource.STANDALONE, NavSource.DEAD_RECKONING),
    ).astype(np.int64)
    dr_cov = world.nav_cov_enu_m2 + np.eye(3) * dr_var
    nav_pos = np.where(co_ok[:, None], co_pos, np.where(sa_ok[:, None], sa_pos, pred_enu))
    nav_cov = np.where(co_ok[:, None, None], co_cov, np.where(sa_ok[:, None, None], sa_cov, dr_cov))
    return sa_pos, sa_cov, co_pos, co_cov, co_status, source, nav_pos, nav_cov, sa_rej, co_rej


# --------------------------------------------------------------------------------------------
# the oracles in the world
# --------------------------------------------------------------------------------------------


def navigate_function_by_function(monkeypatch) -> None:
    """Make ``UrbanWorld`` run every epoch's navigation function by function
    (``UrbanWorld._navigate``, the definition of the one-call ``_navigate_fused``), until
    ``monkeypatch`` undoes it."""
    monkeypatch.setattr(_scenario.UrbanWorld, "_navigate_fused", _scenario.UrbanWorld._navigate)


def use_oracles_in_world(monkeypatch) -> dict[str, int]:
    """Make ``UrbanWorld`` navigate function by function (:func:`navigate_function_by_function`)
    and run the oracles above instead of the compiled kernels there and in the city's
    horizontal sensors, for box buildings (a file city's polygons keep their own kernels),
    until ``monkeypatch`` undoes it: line of sight (map-aided prediction included), relative
    sensing, motion (kinematics, fence, collisions, separation), the estimate selection,
    waypoint advance and the skyline and wall sensors.

    Returns
    -------
    dict
        How many times each oracle ran, by name (``trace_line_of_sight``, ``predicted``,
        ``relative_measurements``, ``world_motion``, ``select_navigation``,
        ``advance_waypoints``, ``sky_and_walls``), updated as the world steps.
    """
    navigate_function_by_function(monkeypatch)
    calls = dict.fromkeys(
        (
            "trace_line_of_sight",
            "predicted",
            "relative_measurements",
            "world_motion",
            "select_navigation",
            "advance_waypoints",
            "sky_and_walls",
        ),
        0,
    )
    trace_kernel = _city._trace_line_of_sight
    sky_kernel = _city.sky_and_walls

    def trace(buildings, pos, sky):
        if isinstance(buildings, Buildings):
            calls["trace_line_of_sight"] += 1
            return trace_line_of_sight(buildings, pos, sky)
        return trace_kernel(buildings, pos, sky)

    def sensors(buildings, pos_enu_m, az_deg):
        if isinstance(buildings, Buildings):
            calls["sky_and_walls"] += 1
            return sky_and_walls(buildings, pos_enu_m, az_deg)
        return sky_kernel(buildings, pos_enu_m, az_deg)

    def motion(*args):
        calls["world_motion"] += 1
        return world_motion(*args)

    def select(*args):
        calls["select_navigation"] += 1
        return select_navigation(*args)

    def waypoints(route, xy, next_wp, reach_m):
        calls["advance_waypoints"] += 1
        return advance_waypoints(route, xy, next_wp, reach_m)

    def predicted(buildings, sky, pos_enu_m, cov_enu_m2, **kw):
        calls["predicted"] += 1
        lo, hi = (float(v) for v in kw["altitude_band_m"])
        return _map_aided._predict_from_candidates(
            buildings,
            sky,
            np.ascontiguousarray(pos_enu_m, dtype=float),
            np.ascontiguousarray(cov_enu_m2, dtype=float),
            kw["margin_sigma"],
            kw["max_margin_m"],
            lo,
            hi,
        )

    def measure(rng, pos, cfg):
        calls["relative_measurements"] += 1
        n = pos.shape[0]
        return relative_measurements(pos, rng.standard_normal((n * (n - 1) // 2, 3)), cfg)

    monkeypatch.setattr(_scenario, "_trace_line_of_sight", trace)
    monkeypatch.setattr(_map_aided, "_trace_line_of_sight", trace)
    monkeypatch.setattr(_scenario, "predicted_line_of_sight", predicted)
    monkeypatch.setattr(_scenario, "_measure_relative", measure)
    monkeypatch.setattr(_scenario, "_world_motion", motion)
    monkeypatch.setattr(_scenario, "_select_navigation", select)
    monkeypatch.setattr(_scenario, "advance_waypoints", waypoints)
    monkeypatch.setattr(_city, "sky_and_walls", sensors)
    return calls


_GRID_STEPS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
"""The 8 moves of a free-space grid (rows, columns)."""


def largest_component(free: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """:func:`coopnav_env.sim._polygon_kernels.largest_component`: the largest 8-connected
    piece of ``free`` (a diagonal move needs both cells beside it free), pieces numbered in
    row-major order of their first cell, the first of equally large pieces kept."""
    ny, nx = free.shape
    label = np.full(free.shape, -1, dtype=np.int64)
    sizes = []
    for r0, c0 in zip(*np.nonzero(free)):
        if label[r0, c0] >= 0:
            continue
        k = len(sizes)
        label[r0, c0] = k
        stack, size = [(int(r0), int(c0))], 0
        while stack:
            r, c = stack.pop()
            size += 1
            for dr, dc in _GRID_STEPS:
                rr, cc = r + dr, c + dc
                if 0 <= rr < ny and 0 <= cc < nx and free[rr, cc] and label[rr, cc] < 0:
                    if dr and dc and not (free[r + dr, c] and free[r, c + dc]):
                        continue
                    label[rr, cc] = k
                    stack.append((rr, cc))
        sizes.append(size)
    if not sizes:
        return np.zeros_like(free)
    return label == int(np.argmax(sizes))


def generate_city(config: _city.CityConfig, rng: np.random.Generator) -> _city.City:
    """A grid city by the constructors' checked path: the definition of
    :func:`coopnav_env.sim.city.generate_city` (which caches the layout a configuration fixes
    and builds its boxes without the constructors' checks), the same draws in the same order
    and the same arithmetic."""
    c = config
    block, street, k = c.block_size_m, c.street_width_m, c.buildings_per_block
    pitch = block + street
    size_x = c.n_blocks_x * block + (c.n_blocks_x + 1) * street
    size_y = c.n_blocks_y * block + (c.n_blocks_y + 1) * street
    x0, y0 = -size_x / 2.0, -size_y / 2.0
    street_x = x0 + street / 2.0 + pitch * np.arange(c.n_blocks_x + 1)
    street_y = y0 + street / 2.0 + pitch * np.arange(c.n_blocks_y + 1)
    n_blocks = c.n_blocks_x * c.n_blocks_y
    n_open = round(c.open_square_fraction * n_blocks)
    open_idx = rng.choice(n_blocks, size=n_open, replace=False)
    built = np.ones(n_blocks, dtype=bool)
    built[open_idx] = False
    ix, iy = np.unravel_index(np.arange(n_blocks), (c.n_blocks_x, c.n_blocks_y))
    blk_x0 = x0 + street + pitch * ix
    blk_y0 = y0 + street + pitch * iy
    open_squares = np.stack([blk_x0, blk_y0], axis=1)[np.sort(open_idx)] + block / 2.0
    m = int(built.sum())
    bx0, by0 = blk_x0[built], blk_y0[built]
    split_along_x = rng.integers(0, 2, size=m).astype(bool)
    weights = rng.uniform(0.6, 1.4, size=(m, k))
    heights = _city._truncated_normal(
        rng, m * k, c.height_mean_m, c.height_std_m, c.height_min_m, c.height_max_m
    )
    lengths = weights / weights.sum(axis=1, keepdims=True) * (block - (k - 1) * c.building_gap_m)
    starts = np.cumsum(lengths, axis=1) - lengths + c.building_gap_m * np.arange(k)
    lo_along, hi_along = starts, starts + lengths
    full_lo, full_hi = np.zeros((m, k)), np.full((m, k), block)
    sx = split_along_x[:, None]
    fx0 = bx0[:, None] + np.where(sx, lo_along, full_lo)
    fx1 = bx0[:, None] + np.where(sx, hi_along, full_hi)
    fy0 = by0[:, None] + np.where(sx, full_lo, lo_along)
    fy1 = by0[:, None] + np.where(sx, full_hi, hi_along)
    footprints = np.stack([fx0, fy0, fx1, fy1], axis=2).reshape(-1, 4)
    return _city.City(
        buildings=Buildings.from_footprints(footprints, heights),
        extent_m=(x0, -x0, y0, -y0),
        street_centres_x_m=street_x,
        street_centres_y_m=street_y,
        open_squares=open_squares,
        config=config,
    )


def street_frames(
    city: _city.City, rng: np.random.Generator, n: int, margin_m: float
) -> tuple[FloatArray, BoolArray]:
    """The definition of ``coopnav_env.sim.scenario._street_frames`` (which draws the
    streets from their cumulative distribution itself): ``rng.choice`` with the streets'
    lengths as weights."""
    x0, x1, y0, y1 = city.extent_m
    cx, cy = city.street_centres_x_m, city.street_centres_y_m
    lengths = np.r_[np.full(cx.size, y1 - y0), np.full(cy.size, x1 - x0)]
    street = rng.choice(lengths.size, size=n, p=lengths / lengths.sum())
    along01 = rng.random(n)
    ns = street < cx.size
    centre = np.r_[cx, cy][street]
    y_along = y0 + margin_m + along01 * (y1 - y0 - 2.0 * margin_m)
    x_along = x0 + margin_m + along01 * (x1 - x0 - 2.0 * margin_m)
    xy = np.stack([np.where(ns, centre, x_along), np.where(ns, y_along, centre)], axis=1)
    return xy, ns


def street_route(city: _city.City, start_xy: ArrayLike, goal_xy: ArrayLike) -> FloatArray:
    """The definition of ``coopnav_env.sim.route.street_route`` on a grid city in numpy (which
    the library computes on Python floats): ends snapped to the nearest street centre line
    (``min``/``argmin``, NaN first), one turn between crossing streets, two through the cross
    street nearest both ends between parallel ones."""
    import math

    cx = np.asarray(city.street_centres_x_m, dtype=float).reshape(-1)
    cy = np.asarray(city.street_centres_y_m, dtype=float).reshape(-1)
    ends = []
    for xy in (start_xy, goal_xy):
        p = np.asarray(xy, dtype=float).reshape(2)
        dx = np.abs(cx - p[0]) if cx.size else np.array([np.inf])
        dy = np.abs(cy - p[1]) if cy.size else np.array([np.inf])
        if dx.min() <= dy.min():
            ends.append(("ns", float(cx[int(np.argmin(dx))]), float(p[1])))
        else:
            ends.append(("ew", float(p[0]), float(cy[int(np.argmin(dy))])))
    (s_kind, sx, sy), (g_kind, gx, gy) = ends
    pts = [(sx, sy)]
    if s_kind == g_kind == "ns":
        if not math.isclose(sx, gx) and cy.size:
            b = cy[int(np.argmin(np.abs(cy - sy) + np.abs(cy - gy)))]
            pts += [(sx, b), (gx, b)]
    elif s_kind == g_kind == "ew":
        if not math.isclose(sy, gy) and cx.size:
            b = cx[int(np.argmin(np.abs(cx - sx) + np.abs(cx - gx)))]
            pts += [(b, sy), (b, gy)]
    elif s_kind == "ns":
        pts.append((sx, gy))
    else:
        pts.append((gx, sy))
    pts.append((gx, gy))
    out = [pts[0]]
    for p in pts[1:]:
        if math.hypot(p[0] - out[-1][0], p[1] - out[-1][1]) > 1e-6:
            out.append(p)
    return np.array(out, dtype=float).reshape(-1, 2)


def route_tail_lengths_m(route: ArrayLike) -> FloatArray:
    """The definition of ``coopnav_env.sim.route.route_tail_lengths_m`` in numpy: the norms
    of the legs summed from the end."""
    pts = np.asarray(route, dtype=float).reshape(-1, 2)
    legs = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    tail = np.zeros(legs.size + 1)
    tail[:-1] = np.cumsum(legs[::-1])[::-1]
    return tail
