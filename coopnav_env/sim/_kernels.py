"""Compiled (numba) loops of the world: line of sight, the horizontal-ray sensors of
:mod:`.city`, relative sensing, motion (kinematics, collisions, separation), waypoint advance
and the estimate selection of :class:`~coopnav_env.sim.scenario.UrbanWorld`; and
:func:`epoch_navigation`, which composes these with the measurement and solver kernels of
:mod:`coopnav_env.gnss` and :mod:`coopnav_env.nav` into one call per epoch (the same kernels
on the same arguments as the function-by-function path, so the same results bit for bit).

Each has a numpy formulation that stays the readable definition, as a test oracle
(``tests/sim/oracles.py``), and a test that compares the two. Most compute the same floating-point
operations in the same order (including numpy's handling of signed zeros in ``maximum`` and
``clip``), so the results are identical bit for bit; the estimate selection rotates to ENU in
loops instead of matmuls (1e-13 apart). They exist because the numpy versions spend most of
their time in the overhead of many small array operations.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from coopnav_env.gnss import _kernels as _gnss_kernels
from coopnav_env.nav import _kernels as _nav_kernels
from coopnav_env.sim import _integrity_kernels


@njit(cache=True)
def grid_boxes(bx0, by0, split_along_x, weights, weight_sums, heights, block_m, span_m, gap_m):
    """The boxes of a grid city's built blocks: ``lo, hi (m k, 3)`` [m], building ``j`` of
    block ``b`` in row ``b k + j``.

    Block ``b`` (west and south edges ``bx0[b], by0[b]``, side ``block_m``) is cut into
    ``k`` strips stacked along East where ``split_along_x[b]`` (else along North), of lengths
    ``weights[b, j] / weight_sums[b] * span_m`` (``span_m``: the side less the gaps) with
    ``gap_m`` between them; each box stands from the ground to ``heights[b k + j]``. The
    arithmetic of the numpy definition (``tests/sim/oracles.py``, ``generate_city``), in its
    order: the strips' starts are their cumulative sums less their lengths plus ``j gap``.
    """
    m, k = weights.shape
    lo = np.zeros((m * k, 3))
    hi = np.empty((m * k, 3))
    for b in range(m):
        cum = 0.0
        for j in range(k):
            length = weights[b, j] / weight_sums[b] * span_m
            cum += length
            start = cum - length + gap_m * j
            end = start + length
            r = b * k + j
            if split_along_x[b]:
                lo[r, 0] = bx0[b] + start
                hi[r, 0] = bx0[b] + end
                lo[r, 1] = by0[b] + 0.0
                hi[r, 1] = by0[b] + block_m
            else:
                lo[r, 0] = bx0[b] + 0.0
                hi[r, 0] = bx0[b] + block_m
                lo[r, 1] = by0[b] + start
                hi[r, 1] = by0[b] + end
            hi[r, 2] = heights[r]
    return lo, hi


@njit(cache=True)
def street_frames(cdf, u_street, u_along, centres, n_x, extent, margin_m):
    """Street points ``xy (n, 2)`` [m] and whether each lies on a north-south street
    ``(n,)``, from the streets' cumulative length distribution ``cdf (S,)`` (the ``n_x``
    north-south streets first, then the east-west ones), their centre lines ``centres (S,)``
    [m], the city's ``extent (x0, x1, y0, y1)`` [m] and ``n`` uniform draws each: the street
    ``u_street`` picks (``np.searchsorted(cdf, u, side="right")``) and the fraction
    ``u_along`` of the street's length less ``margin_m`` at either end. The arithmetic of the
    numpy definition (``tests/sim/oracles.py``, ``street_frames``), in its order."""
    x0, x1, y0, y1 = extent
    street = np.searchsorted(cdf, u_street, side="right")
    n = street.shape[0]
    xy = np.empty((n, 2))
    ns = np.empty(n, dtype=np.bool_)
    y_start, y_span = y0 + margin_m, y1 - y0 - 2.0 * margin_m
    x_start, x_span = x0 + margin_m, x1 - x0 - 2.0 * margin_m
    for i in range(n):
        s = street[i]
        ns[i] = s < n_x
        if ns[i]:
            xy[i, 0] = centres[s]
            xy[i, 1] = y_start + u_along[i] * y_span
        else:
            xy[i, 0] = x_start + u_along[i] * x_span
            xy[i, 1] = centres[s]
    return xy, ns


@njit(cache=True)
def far_candidate(cand, centre, min_m):
    """The index of the first candidate point ``cand (n, 2)`` at least ``min_m`` [m] from
    ``centre (2,)``, or where none is, of the farthest (the first of equals): ``(d >=
    min_m).argmax()`` and ``d.argmax()`` of the distances ``d = np.hypot(...)``."""
    far, far_d = 0, -np.inf
    for j in range(cand.shape[0]):
        d = np.hypot(cand[j, 0] - centre[0], cand[j, 1] - centre[1])
        if d >= min_m:
            return j
        if d > far_d or (d != d and far_d == far_d):  # numpy's argmax: the first NaN
            far, far_d = j, d
    return far


@njit(cache=True, inline="always")
def _fmax(a, b):
    """``numpy.maximum`` of two floats (``max`` differs for signed zeros: max(-0., 0.) = -0.)."""
    if a > b or a != a:
        return a
    return b


@njit(cache=True, inline="always")
def _fmin(a, b):
    """``numpy.minimum`` of two floats."""
    if a < b or a != a:
        return a
    return b


@njit(cache=True, inline="always", error_model="numpy")
def _slab_1d(p, d, lo, hi):
    """Parameter interval of ``p + t d`` inside ``[lo, hi]`` along one axis (exact for d = 0)."""
    if d == 0.0:
        if p >= lo and p <= hi:
            return -np.inf, np.inf
        return np.inf, -np.inf
    inv = 1.0 / d
    t1 = (lo - p) * inv
    t2 = (hi - p) * inv
    return _fmin(t1, t2), _fmax(t1, t2)


@njit(cache=True, error_model="numpy")
def _slab_2d(px, py, dx, dy, lox, loy, hix, hiy):
    """``t_near, t_far`` of the horizontal line ``p + t d`` in a footprint (as ``_sweep_slab``)."""
    lo_x, hi_x = _slab_1d(px, dx, lox, hix)
    lo_y, hi_y = _slab_1d(py, dy, loy, hiy)
    return _fmax(lo_x, lo_y), _fmin(hi_x, hi_y)


@njit(cache=True, inline="always")
def _slab_offsets(o_lo, o_hi, d, inv, inside):
    """:func:`_slab_1d` from the offsets ``o_lo = lo - p``, ``o_hi = hi - p``, the direction
    ``d``, its reciprocal ``inv = 1 / d`` and whether ``lo <= p <= hi`` (the same results)."""
    if d == 0.0:
        if inside:
            return -np.inf, np.inf
        return np.inf, -np.inf
    t1 = o_lo * inv
    t2 = o_hi * inv
    return _fmin(t1, t2), _fmax(t1, t2)


@njit(cache=True, error_model="numpy")
def sky_and_walls(pos, dirs, lo, hi):
    """Skyline ``tan(elevation)`` and nearest wall per (receiver, azimuth).

    ``pos`` (n, 3), ``dirs`` (n_az, 2) horizontal unit directions with exact zeros on the
    cardinal axes, ``lo``/``hi`` (m, 3) corners of the buildings taller than the lowest
    receiver. Returns ``tan_max`` (n, n_az) (0: no roof above the receiver along the ray,
    inf: inside a footprint) and ``dist`` (n, n_az) (inf: no wall).

    Each ray's footprint interval is :func:`_slab_2d`'s, with the same operations: the
    reciprocals of the directions are taken once per ray and the offsets ``lo - p``,
    ``hi - p`` once per (receiver, building), and every ray takes the buildings in their
    order, so each ray's largest tangent and smallest distance are those of one ray at a
    time.

    A ray is not traced through a footprint that lies wholly on one side of the receiver
    along an axis (``lo > p`` or ``hi < p``) when the ray does not head that way: both of
    that axis's slab parameters are then negative (or its interval is empty, for a ray
    along the other axis), so the ray's interval ends behind the receiver and would change
    neither result. Skipping it leaves every ray's results the same, bit for bit.
    """
    n = pos.shape[0]
    n_az = dirs.shape[0]
    m = lo.shape[0]
    tan_max = np.zeros((n, n_az))
    dist = np.full((n, n_az), np.inf)
    inv = np.empty((n_az, 2))  # _slab_1d's 1 / d (unused where d == 0)
    heads = np.empty((n_az, 4), dtype=np.bool_)  # the ray heads to +x, -x, +y, -y
    for a in range(n_az):
        for c in range(2):
            d = dirs[a, c]
            inv[a, c] = 1.0 / d if d != 0.0 else 0.0
            heads[a, 2 * c] = d > 0.0
            heads[a, 2 * c + 1] = d < 0.0
    for i in range(n):
        px, py, z = pos[i, 0], pos[i, 1], pos[i, 2]
        for b in range(m):
            top = hi[b, 2]
            # Both updates need the roof above the receiver: the skyline ``top - z > 0``,
            # the wall ``z < top``; the two agree for every pair of floats (a difference of
            # finite floats is 0 only when they are equal and keeps the sign of the exact
            # one; an infinite or NaN operand fails both or passes both), so a building
            # with ``not z < top`` changes no ray's result.
            if not z < top:
                continue
            rel_h = top - z
            is_wall = z >= lo[b, 2]
            x0, x1 = lo[b, 0], hi[b, 0]
            y0, y1 = lo[b, 1], hi[b, 1]
            in_x = px >= x0 and px <= x1
            in_y = py >= y0 and py <= y1
            ox0, ox1 = x0 - px, x1 - px
            oy0, oy1 = y0 - py, y1 - py
            # the sides of the receiver the footprint lies wholly on (all False for NaN)
            east, west = x0 > px, x1 < px
            north, south = y0 > py, y1 < py
            for a in range(n_az):
                if (
                    (east and not heads[a, 0])
                    or (west and not heads[a, 1])
                    or (north and not heads[a, 2])
                    or (south and not heads[a, 3])
                ):
                    continue  # the ray's interval in the footprint ends behind the receiver
                lo_x, hi_x = _slab_offsets(ox0, ox1, dirs[a, 0], inv[a, 0], in_x)
                lo_y, hi_y = _slab_offsets(oy0, oy1, dirs[a, 1], inv[a, 1], in_y)
                t_near = _fmax(lo_x, lo_y)
                t_far = _fmin(hi_x, hi_y)
                if not t_near <= t_far:
                    continue
                t_in = _fmax(t_near, 0.0)
                if t_far > 0.0:
                    tan_el = rel_h / t_in
                    if tan_el > tan_max[i, a]:
                        tan_max[i, a] = tan_el
                if t_far >= 0.0 and is_wall and t_in < dist[i, a]:
                    dist[i, a] = t_in
    return tan_max, dist


@njit(cache=True, error_model="numpy")
def blocked_sorted(pos, lo, hi, cot_s, h_dir):
    """Blocked (receiver, rising satellite) pairs, satellites in the sorted order of
    :class:`~coopnav_env.sim.city.SkyDirections` (``cot_s`` increasing, ``h_dir`` (n_up, 2)).

    The culling of ``city._trace_line_of_sight``: a building is tested only when its roof is
    above the receiver and its footprint within reach of the lowest ray, and then only against
    the satellites low enough to pass under the roof at the footprint's nearest point.
    """
    n_rx = pos.shape[0]
    m = lo.shape[0]
    n_up = cot_s.shape[0]
    blocked = np.zeros((n_rx, n_up), dtype=np.bool_)
    if n_up == 0:
        return blocked
    cot_max = cot_s[n_up - 1]
    for i in range(n_rx):
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        for b in range(m):
            climb = hi[b, 2] - pz
            if not climb > 0.0:
                continue
            ddx = _fmax(_fmax(lo[b, 0] - px, 0.0), px - hi[b, 0])
            ddy = _fmax(_fmax(lo[b, 1] - py, 0.0), py - hi[b, 1])
            dist_xy = np.hypot(ddx, ddy)
            if not dist_xy <= climb * cot_max:
                continue
            first = np.searchsorted(cot_s, dist_xy / climb)
            for s in range(first, n_up):
                if blocked[i, s]:
                    continue
                t_near, t_far = _slab_2d(
                    px, py, h_dir[s, 0], h_dir[s, 1], lo[b, 0], lo[b, 1], hi[b, 0], hi[b, 1]
                )
                if t_far > 0.0 and t_near <= t_far and _fmax(t_near, 0.0) <= climb * cot_s[s]:
                    blocked[i, s] = True
    return blocked


@njit(cache=True, error_model="numpy")
def relative_measurements(pos, z, sigma0, sigma_per, max_range):
    """Pairwise relative measurements of :func:`~coopnav_env.sim.swarm.measure_relative_positions`.

    ``pos`` (n, 3) true ENU positions, ``z`` (n (n - 1) / 2, 3) the standard normal draws of the
    upper triangle in row-major order. Returns ``rel`` (n, n, 3), the per-axis variance ``var``
    (n, n) and ``available`` (n, n), with the numpy formulation's arithmetic in its order.
    """
    n = pos.shape[0]
    rel = np.zeros((n, n, 3))
    var = np.zeros((n, n))
    available = np.zeros((n, n), dtype=np.bool_)
    k = 0
    for b in range(n):
        for q in range(b + 1, n):
            d0 = pos[q, 0] - pos[b, 0]
            d1 = pos[q, 1] - pos[b, 1]
            d2 = pos[q, 2] - pos[b, 2]
            r = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            s = sigma0 + sigma_per * r
            e0 = z[k, 0] * s
            e1 = z[k, 1] * s
            e2 = z[k, 2] * s
            k += 1
            if r > 0.0 and r <= max_range:
                available[b, q] = True
                available[q, b] = True
                v = s * s
                var[b, q] = v
                var[q, b] = v
                rel[b, q, 0] = d0 + e0
                rel[b, q, 1] = d1 + e1
                rel[b, q, 2] = d2 + e2
                rel[q, b, 0] = -d0 + -e0
                rel[q, b, 1] = -d1 + -e1
                rel[q, b, 2] = -d2 + -e2
    return rel, var, available


@njit(cache=True)
def advance_waypoints(pts, xy, next_wp, reach_m):
    """:func:`coopnav_env.sim.route.advance_waypoints` of validated arrays, one point at a time.

    ``pts`` (k, 2) waypoints, ``xy`` (n, 2), ``next_wp`` (n,) int64. A point advances while its
    next waypoint is not the last and is reached (inside the reach square) or passed (at or
    beyond it along the arriving leg, when that leg has a length).
    """
    k = pts.shape[0]
    idx = next_wp.copy()
    for i in range(xy.shape[0]):
        while idx[i] < k - 1:
            j = idx[i]
            dx = xy[i, 0] - pts[j, 0]
            dy = xy[i, 1] - pts[j, 1]
            near = abs(dx) <= reach_m and abs(dy) <= reach_m
            ax = 0.0
            ay = 0.0
            if j > 0:
                ax = pts[j, 0] - pts[j - 1, 0]
                ay = pts[j, 1] - pts[j - 1, 1]
            past = dx * ax + dy * ay >= 0.0 and (ax != 0.0 or ay != 0.0)
            if not (near or past):
                break
            idx[i] = j + 1
    return idx


@njit(cache=True, inline="always")
def _to_enu(p, origin, rot, out):
    """``(p - origin) @ rot.T`` of one ECEF point into ``out`` (3,)."""
    d0 = p[0] - origin[0]
    d1 = p[1] - origin[1]
    d2 = p[2] - origin[2]
    for i in range(3):
        out[i] = d0 * rot[i, 0] + d1 * rot[i, 1] + d2 * rot[i, 2]


@njit(cache=True, inline="always")
def _cov_to_enu(c, rot, tmp, out):
    """``rot @ c @ rot.T`` of one 3x3 covariance into ``out``."""
    for i in range(3):
        for k in range(3):
            tmp[i, k] = rot[i, 0] * c[0, k] + rot[i, 1] * c[1, k] + rot[i, 2] * c[2, k]
    for i in range(3):
        for j in range(3):
            out[i, j] = tmp[i, 0] * rot[j, 0] + tmp[i, 1] * rot[j, 1] + tmp[i, 2] * rot[j, 2]


@njit(cache=True, inline="always")
def _take_fix(pos, cov, i, add, add_var, nav_pos, nav_cov):
    """Row ``i`` of ``pos``/``cov`` into the estimate; with ``add``, ``cov + add_var I`` (as
    the numpy formulation's dead-reckoning covariance, zeros added off the diagonal too).

    Element loops, not array assignments: those compile numba's slow shape-error path.
    """
    for a in range(3):
        nav_pos[i, a] = pos[i, a]
        for b in range(3):
            v = cov[i, a, b]
            if add:
                v = v + (add_var if a == b else 0.0)
            nav_cov[i, a, b] = v


class Fixes(NamedTuple):
    """Each UAV's standalone and cooperative fix of an epoch (:func:`select_navigation`)."""

    sa_status: np.ndarray  # (N,) int64 standalone statuses
    sa_pos: np.ndarray  # (N, 3) ECEF [m]
    sa_cov: np.ndarray  # (N, 3, 3) ECEF [m^2]
    co_status: np.ndarray  # (N,) int64 cooperative statuses
    co_pos: np.ndarray  # (N, 3) ECEF [m]
    co_cov: np.ndarray  # (N, 3, 3) ECEF [m^2]


class Gate(NamedTuple):
    """The integrity gate of the estimate selection (:func:`select_navigation`)."""

    on: bool  # a fix whose trace(cov) exceeds max_sigma2 is not used
    max_sigma2: float  # [m^2]


class Frame(NamedTuple):
    """The local ENU frame (:func:`select_navigation`)."""

    origin: np.ndarray  # (3,) ECEF of the ENU origin [m]
    rot: np.ndarray  # (3, 3) ECEF-to-ENU rotation


class DeadReckoning(NamedTuple):
    """The estimate of a UAV without a fix (:func:`select_navigation`)."""

    pred_enu: np.ndarray  # (N, 3) predicted positions [m]
    prev_cov: np.ndarray  # (N, 3, 3) covariances of the previous estimates (ENU) [m^2]
    dr_var: float  # per-axis variance dead reckoning adds over the step [m^2]


@njit(cache=True)
def select_navigation(fixes, linked, gate, frame, dead_reckoning):
    """The estimate each UAV uses: cooperative, else standalone, else dead reckoning.

    ``UrbanWorld._epoch``'s selection (its numpy formulation is ``select_navigation`` of
    ``tests/sim/oracles.py``) from the records :class:`Fixes`, :class:`Gate`, :class:`Frame`
    and :class:`DeadReckoning` (each may come as a plain tuple of its fields) and ``linked``
    ``(N,)`` bool (the UAV has a relative link for the cooperative fix): fixes with status OK
    whose ``trace(cov)`` passes the gate, expressed in ENU (NaN where not used). Status 4
    (NO_RELATIVE_POSITION) replaces the cooperative status of an unlinked UAV. Returns
    ``sa_pos, sa_cov, co_pos, co_cov`` (ENU), ``co_status, source, nav_pos, nav_cov,
    sa_rejected, co_rejected``.
    """
    sa_status, sa_pos, sa_cov, co_status_raw, co_pos, co_cov = fixes
    check_sigma, max_sigma2 = gate
    origin, rot = frame
    pred_enu, prev_cov, dr_var = dead_reckoning
    n = sa_status.shape[0]
    sa_pos_e = np.full((n, 3), np.nan)
    sa_cov_e = np.full((n, 3, 3), np.nan)
    co_pos_e = np.full((n, 3), np.nan)
    co_cov_e = np.full((n, 3, 3), np.nan)
    co_status = np.empty(n, dtype=np.int64)
    source = np.empty(n, dtype=np.int64)
    nav_pos = np.empty((n, 3))
    nav_cov = np.empty((n, 3, 3))
    sa_rej = np.zeros(n, dtype=np.bool_)
    co_rej = np.zeros(n, dtype=np.bool_)
    tmp = np.empty((3, 3))
    for i in range(n):
        co_status[i] = co_status_raw[i] if linked[i] else 4
        sa_ok = sa_status[i] == 0
        co_ok = co_status[i] == 0
        if check_sigma:
            if sa_ok and not (sa_cov[i, 0, 0] + sa_cov[i, 1, 1] + sa_cov[i, 2, 2] <= max_sigma2):
                sa_rej[i] = True
                sa_ok = False
            if co_ok and not (co_cov[i, 0, 0] + co_cov[i, 1, 1] + co_cov[i, 2, 2] <= max_sigma2):
                co_rej[i] = True
                co_ok = False
        if sa_ok:
            _to_enu(sa_pos[i], origin, rot, sa_pos_e[i])
            _cov_to_enu(sa_cov[i], rot, tmp, sa_cov_e[i])
        if co_ok:
            _to_enu(co_pos[i], origin, rot, co_pos_e[i])
            _cov_to_enu(co_cov[i], rot, tmp, co_cov_e[i])
        if co_ok:
            source[i] = 0
            _take_fix(co_pos_e, co_cov_e, i, False, 0.0, nav_pos, nav_cov)
        elif sa_ok:
            source[i] = 1
            _take_fix(sa_pos_e, sa_cov_e, i, False, 0.0, nav_pos, nav_cov)
        else:
            source[i] = 2
            _take_fix(pred_enu, prev_cov, i, True, dr_var, nav_pos, nav_cov)
    return (
        sa_pos_e,
        sa_cov_e,
        co_pos_e,
        co_cov_e,
        co_status,
        source,
        nav_pos,
        nav_cov,
        sa_rej,
        co_rej,
    )


@njit(cache=True, inline="always")
def _clip01(x):
    """``numpy.clip(x, 0, 1)`` of a finite float (a signed zero becomes +0)."""
    x = x if x > 0.0 else 0.0
    return x if x < 1.0 else 1.0


@njit(cache=True, error_model="numpy")
def _segment_box_dist2(p0, d, lo, hi):
    """``swarm._segment_box_min_dist2`` of one segment and one box, same operations."""
    tb = np.empty(8)
    tb[0] = 0.0
    tb[1] = 1.0
    for k in range(3):
        t_lo = (lo[k] - p0[k]) / d[k]
        t_hi = (hi[k] - p0[k]) / d[k]
        tb[2 + k] = _clip01(t_lo) if np.isfinite(t_lo) else 0.0
        tb[5 + k] = _clip01(t_hi) if np.isfinite(t_hi) else 0.0
    # insertion sort (8 finite values; equal values are equal, so the order of ties is moot)
    for i in range(1, 8):
        v = tb[i]
        j = i - 1
        while j >= 0 and tb[j] > v:
            tb[j + 1] = tb[j]
            j -= 1
        tb[j + 1] = v
    best = np.inf
    for c in range(15):
        if c < 8:
            t = tb[c]
        else:
            a = tb[c - 8]
            b = tb[c - 7]
            tm = 0.5 * (a + b)
            num = 0.0
            den = 0.0
            for k in range(3):
                pm = p0[k] + tm * d[k]
                if pm < lo[k]:
                    off = p0[k] - lo[k]
                    dd = d[k]
                elif pm > hi[k]:
                    off = p0[k] - hi[k]
                    dd = d[k]
                else:
                    off = 0.0
                    dd = 0.0
                num += dd * off
                den += dd * dd
            num = -num
            t = num / den if den > 0.0 else tm
            t = t if t > a else a  # numpy.clip(t, a, b)
            t = t if t < b else b
        e2 = 0.0
        for k in range(3):
            pc = p0[k] + t * d[k]
            ex = _fmax(_fmax(lo[k] - pc, 0.0), pc - hi[k])
            e2 += ex * ex
        if e2 < best:
            best = e2
    return best


@njit(cache=True, error_model="numpy")
def swept_collisions_culled(lo, hi, start, end, radius):
    """:func:`~coopnav_env.sim.swarm.swept_collisions` restricted to the (UAV, building) pairs
    whose bounding boxes overlap (touching counts): the exact segment-box test on those pairs
    only, any hit per UAV (its numpy formulation is ``swept_collisions_culled`` of
    ``tests/sim/oracles.py``)."""
    n = start.shape[0]
    m = lo.shape[0]
    hit = np.zeros(n, dtype=np.bool_)
    r2 = radius * radius
    d = np.empty(3)
    for i in range(n):
        for k in range(3):
            d[k] = end[i, k] - start[i, k]
        for b in range(m):
            overlap = True
            for k in range(3):
                s_lo = _fmin(start[i, k], end[i, k]) - radius
                s_hi = _fmax(start[i, k], end[i, k]) + radius
                if not (s_lo <= hi[b, k] and s_hi >= lo[b, k]):
                    overlap = False
                    break
            if overlap and _segment_box_dist2(start[i], d, lo[b], hi[b]) <= r2:
                hit[i] = True
                break
    return hit


@njit(cache=True)
def separation_violations(pos, sep):
    """``swarm.separation_violations``: UAVs with another UAV strictly closer than ``sep``
    (pairwise ``sqrt(dx*dx + dy*dy + dz*dz)``, as ``numpy.linalg.norm`` sums three terms)."""
    n = pos.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        for j in range(i + 1, n):
            d0 = pos[j, 0] - pos[i, 0]
            d1 = pos[j, 1] - pos[i, 1]
            d2 = pos[j, 2] - pos[i, 2]
            if np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < sep:
                out[i] = True
                out[j] = True
    return out


@njit(cache=True, inline="always")
def _clip(x, lo, hi):
    """``numpy.clip`` of a finite float to finite bounds."""
    x = x if x > lo else lo
    return x if x < hi else hi


class MotionLimits(NamedTuple):
    """The kinematics of a motion step (:func:`world_motion`)."""

    v_max: float  # speed limit [m/s]
    dv_max: float  # largest change of velocity in a step [m/s]
    dt: float  # step [s]
    alt_min: float  # altitude band [m]
    alt_max: float
    radius: float  # UAV radius [m]
    min_sep: float  # separation below which two UAVs violate it [m]


@njit(cache=True, error_model="numpy")
def world_motion(pos0, vel0, cmd, limits, fence, boxes):
    """One motion step of ``UrbanWorld.step``: ``swarm.step_kinematics``, the virtual fence
    at the city extent, swept collisions (a colliding UAV stays where it was, at rest) and
    the separation test, with the numpy formulation's operations in its order.

    Takes the positions and velocities ``(N, 3)`` before the step, the commands ``cmd (N,
    3)``, the record :class:`MotionLimits` (or a plain tuple of its fields), the fence
    ``(lo, hi)`` (each ``(2,)`` east-north [m]) and the box buildings ``(b_lo, b_hi)``
    (each ``(B, 3)``). Returns ``pos1, vel1, hit, sep``.
    """
    v_max, dv_max, dt, alt_min, alt_max, radius, min_sep = limits
    fence_lo, fence_hi = fence
    b_lo, b_hi = boxes
    n = pos0.shape[0]
    pos1 = np.empty((n, 3))
    vel1 = np.empty((n, 3))
    for i in range(n):
        vx = _clip(cmd[i, 0], -1.0, 1.0) * v_max
        vy = _clip(cmd[i, 1], -1.0, 1.0) * v_max
        vz = _clip(cmd[i, 2], -1.0, 1.0) * v_max
        h_scale = _fmin(1.0, v_max / _fmax(np.hypot(vx, vy), 1e-300))
        vx *= h_scale
        vy *= h_scale
        d0 = vx - vel0[i, 0]
        d1 = vy - vel0[i, 1]
        d2 = vz - vel0[i, 2]
        f = _fmin(1.0, dv_max / _fmax(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2), 1e-300))
        vel1[i, 0] = vel0[i, 0] + d0 * f
        vel1[i, 1] = vel0[i, 1] + d1 * f
        vel1[i, 2] = vel0[i, 2] + d2 * f
        for k in range(3):
            pos1[i, k] = pos0[i, k] + vel1[i, k] * dt
        z = pos1[i, 2]
        if z < alt_min:
            vel1[i, 2] = _fmax(vel1[i, 2], 0.0)
        elif z > alt_max:
            vel1[i, 2] = _fmin(vel1[i, 2], 0.0)
        pos1[i, 2] = _clip(z, alt_min, alt_max)
        for k in range(2):  # virtual fence
            p = pos1[i, k]
            if p < fence_lo[k] or p > fence_hi[k]:
                vel1[i, k] = 0.0
            pos1[i, k] = _clip(p, fence_lo[k], fence_hi[k])
    hit = swept_collisions_culled(b_lo, b_hi, pos0, pos1, radius)
    for i in range(n):
        if hit[i]:
            for k in range(3):
                pos1[i, k] = pos0[i, k]
                vel1[i, k] = 0.0
    sep = separation_violations(pos1, min_sep)
    return pos1, vel1, hit, sep


@njit(cache=True, error_model="numpy")
def line_of_sight(pos, lo, hi, up, order, cot_s, h_dir):
    """``city._trace_line_of_sight``: visible (receiver, satellite) pairs ``(n_rx, n_sv)``.

    A satellite below the horizon (``up`` False) is never visible; a rising one is unless
    :func:`blocked_sorted` finds a building in the way (its columns are those of ``up``'s
    True entries permuted by ``order``, as :class:`~coopnav_env.sim.city.SkyDirections`
    sorts them).
    """
    n_rx = pos.shape[0]
    n_sv = up.shape[0]
    visible = np.empty((n_rx, n_sv), dtype=np.bool_)
    for i in range(n_rx):
        for k in range(n_sv):
            visible[i, k] = up[k]
    n_up = cot_s.shape[0]
    if lo.shape[0] == 0 or n_rx == 0 or n_up == 0:
        return visible
    blocked = blocked_sorted(pos, lo, hi, cot_s, h_dir)
    up_idx = np.nonzero(up)[0]
    for j in range(n_up):
        col = up_idx[order[j]]
        for i in range(n_rx):
            visible[i, col] = not blocked[i, j]
    return visible


# --------------------------------------------------------------------------------------------
# one epoch's measurements and navigation in one call
# --------------------------------------------------------------------------------------------


class Geometry(NamedTuple):
    """The receivers and satellites of an epoch (:func:`epoch_navigation`)."""

    range_m: np.ndarray  # (N, S) receiver-satellite ranges [m]
    el_deg: np.ndarray  # (N, S) elevations [deg]
    sv: np.ndarray  # (S, 3) satellite positions, ECEF [m]
    system: np.ndarray  # (S,) int64 constellation index, sorted
    received: np.ndarray  # (N, S) bool


class Pseudoranges(NamedTuple):
    """The measurement model of an epoch and its random draws (:func:`epoch_navigation`)."""

    clock: np.ndarray  # (N, n_sys_all) receiver clock biases [m]
    iono: np.ndarray  # (n_sys_all,) ionospheric factor per constellation
    z_common: np.ndarray  # (S,) standard normal draws of the errors common to all receivers
    z_user: np.ndarray  # (N, S) those of each receiver's own errors
    extra: np.ndarray  # (N, S) extra (NLOS) bias [m]
    el_ref: np.ndarray  # (S,) NaN: the mean elevation over the receivers
    sigma_ure: float
    tropo: bool
    differential: bool
    n_sys: int  # clock states: the constellations flown


class Centroids(NamedTuple):
    """The cooperative problems of an epoch, one per centroid UAV (:func:`epoch_navigation`)."""

    rel: np.ndarray  # (B, N, 3) ECEF relative positions from each centroid UAV [m]
    var: np.ndarray  # (B, N) their per-axis variances [m^2]
    avail: np.ndarray  # (B, N) bool
    cen: np.ndarray  # (B,) int64 centroid UAVs
    x0: np.ndarray  # (B, 3) ECEF starts of the centroid solves
    ddt: bool  # the transfer: DDT (else SDT)
    linked: np.ndarray  # (N,) bool: a UAV with a cooperative solution
    links: np.ndarray  # (N, N) bool relative links


class Solving(NamedTuple):
    """The solvers' settings and the integrity gate (:func:`epoch_navigation`)."""

    max_iter: int
    tol_m: float
    check: bool  # check the fixes' geocentric distance against [r_lo, r_hi]
    r_lo: float
    r_hi: float
    gate_on: bool  # a fix whose 3-D sigma^2 exceeds gate2 is not used
    gate2: float


class Prior(NamedTuple):
    """The local frame and what is known before the epoch's measurements
    (:func:`epoch_navigation`)."""

    x0: np.ndarray  # (N, 3) ECEF starts of the standalone solves (the predicted positions)
    origin: np.ndarray  # (3,) ECEF origin of the ENU frame
    rot: np.ndarray  # (3, 3) ECEF-to-ENU rotation
    pred_enu: np.ndarray  # (N, 3) predicted positions (dead reckoning)
    prev_cov: np.ndarray  # (N, 3, 3) covariances of the previous estimates
    dr_var: float  # per-axis variance dead reckoning adds over the step


class Waypoints(NamedTuple):
    """The swarm's route and where each UAV is on it (:func:`epoch_navigation`)."""

    route: np.ndarray  # (R, 2) waypoints [m]
    next_wp: np.ndarray  # (N,) int64
    reach_m: float


@njit(cache=True)
def epoch_navigation(geometry, pseudoranges, centroids, solving, prior, waypoints, fde=None):
    """``UrbanWorld._epoch`` from the receiver geometry and the random draws to the estimates.

    Takes the records :class:`Geometry`, :class:`Pseudoranges`, :class:`Centroids`,
    :class:`Solving`, :class:`Prior` and :class:`Waypoints` (each may come as a plain tuple
    of its fields) and ``fde``: integrity monitoring, None (off) or the settings tuple of
    :mod:`coopnav_env.sim._integrity_kernels`.

    The kernels of the modular path on the same arguments, in its order:
    :func:`coopnav_env.gnss._kernels.pseudorange_model`, the stored observation fields of
    ``GnssObservations._trusted_from_epoch`` (received = finite pseudorange, NaN sigmas and
    elevations elsewhere), :func:`coopnav_env.nav._kernels.standalone_solve`,
    :func:`coopnav_env.nav._kernels.cooperative_isotropic`, :func:`select_navigation`,
    :func:`advance_waypoints`, and the swarm's satellite count; so the results are the
    modular path's bit for bit (the golden episodes of ``tests/envs/test_golden.py`` run
    through both). Returns ``sa_status, sa_n_iter, co_n_iter, select_navigation's ten
    arrays, next_wp, n_swarm`` and the integrity figures of the estimates used: with ``fde``
    (:mod:`coopnav_env.sim._integrity_kernels`) the RAIM / FDE of both solutions runs
    between the solvers and the selection (:func:`~coopnav_env.sim._integrity_kernels.
    epoch_fde`, the kernels of ``fde_standalone`` / ``fde_cooperative``); without it (the
    default) that stage is compiled out and the figures are those of no monitoring.
    """
    range_m, el_deg, sv, system, received = geometry
    clock, iono, z_common, z_user, extra, el_ref, sigma_ure, tropo, differential, n_sys = (
        pseudoranges
    )
    rel_b, var_b, avail_b, cen, x0_co, ddt, linked, avail = centroids
    max_iter, tol_m, check, r_lo, r_hi, gate_on, gate2 = solving
    x0, origin, rot, pred_enu, prev_cov, dr_var = prior
    route, next_wp, reach_m = waypoints
    n, s = received.shape
    _sc, _su, _ce, _ue, pr = _gnss_kernels.pseudorange_model(
        range_m,
        el_deg,
        system,
        received,
        _gnss_kernels.ErrorDraws(clock, z_common, z_user, extra),
        _gnss_kernels.ErrorBudget(iono, el_ref, sigma_ure, tropo, differential),
    )
    vis = np.empty((n, s), dtype=np.bool_)
    su = np.empty((n, s))
    el = np.empty((n, s))
    for q in range(n):
        for k in range(s):
            v = np.isfinite(pr[q, k])
            vis[q, k] = v
            su[q, k] = _su[q, k] if v else np.nan
            el[q, k] = el_deg[q, k] if v else np.nan
    measured = _nav_kernels.Measured(pr, vis, sv, system, su, _sc, el, n_sys)
    limits = _nav_kernels.SolverLimits(max_iter, tol_m, check, r_lo, r_hi)
    sa_pos, sa_cov, _clk, sa_status, _n_used, sa_n_iter = _nav_kernels.standalone_solve(
        measured, x0.copy(), limits
    )
    out = _nav_kernels.cooperative_isotropic(
        measured,
        _nav_kernels.CentroidProblems(rel_b, var_b, avail_b, cen, x0_co, ddt, -1),
        limits,
        cen.shape[0] == 1,
    )
    if fde is not None:  # updates the solutions in place
        fixes = _integrity_kernels.epoch_fde(
            fde,
            (vis, pr, su, _sc, sv, system, n_sys, el),
            (rel_b, var_b, avail_b, cen, ddt),
            limits,
            rot,
            (sa_pos, sa_cov, _clk, sa_status, _n_used),
            out,
        )
    c_pos, h_star, c_status, uav_pos, uav_cov, uav_status, co_n_iter = (
        out[0],
        out[1],
        out[3],
        out[6],
        out[7],
        out[8],
        out[9],
    )
    if cen.shape[0] == 1:  # one shared centroid: its UAV outputs
        co_pos, co_cov, co_status = uav_pos[0], uav_cov[0], uav_status[0]
    else:  # "self": UAV q's solution is centroid q's
        co_pos, co_cov, co_status = c_pos, h_star, c_status.copy()
    sel = select_navigation(
        (sa_status, sa_pos, sa_cov, co_status, co_pos, co_cov),
        linked,
        (gate_on, gate2),
        (origin, rot),
        (pred_enu, prev_cov, dr_var),
    )
    nav_pos = sel[6]
    xy = np.empty((n, 2))
    for q in range(n):
        xy[q, 0] = nav_pos[q, 0]
        xy[q, 1] = nav_pos[q, 1]
    wp = advance_waypoints(route, xy, next_wp.copy(), reach_m)
    n_swarm = np.zeros(n, dtype=np.int64)
    for q in range(n):
        for k in range(s):
            for p in range(n):
                if (p == q or avail[q, p]) and received[p, k]:
                    n_swarm[q] += 1
                    break
    if fde is None:
        used = _integrity_kernels.no_integrity()
    else:
        used = _integrity_kernels.used_integrity(sel[5], *fixes)
    return sa_status, sa_n_iter, co_n_iter, sel, wp, n_swarm, used
