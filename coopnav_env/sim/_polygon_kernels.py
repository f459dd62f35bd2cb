"""Compiled (numba) loops of :mod:`coopnav_env.sim.file_city`: rays, inside tests, swept
collisions and the wall-clearance grid against buildings that are extruded polygons.

The buildings are given as flat arrays (see :class:`~coopnav_env.sim.file_city.ExtrudedBuildings`):
``edges`` ``(n_e, 4)`` rows ``(ax, ay, bx, by)`` of every ring edge (exterior and holes, ENU [m]),
``edge_start`` ``(n_b + 1,)`` the first edge of each building (building ``b`` owns edges
``edge_start[b]:edge_start[b + 1]``), ``heights`` ``(n_b,)`` roofs [m] and ``bbox`` ``(n_b, 4)``
``(x_min, y_min, x_max, y_max)`` footprints' bounding boxes (the cull of every loop).

Geometry conventions (shared by every kernel, so that line of sight, the skyline and the wall
distances agree with each other):

* inside a footprint: the even-odd rule over all of a building's rings (holes are courtyards),
  with the half-open rule on ``y`` (a point exactly on an edge may fall either way);
* the *entry distance* of a horizontal ray ``p + t d`` (``t >= 0``, ``|d| = 1``) into a
  footprint is 0 when ``p`` is inside it, else the smallest ``t >= 0`` at which the ray meets
  an edge (touching a vertex counts; an edge collinear with the ray is met at its nearest
  point), ``inf`` when it meets none. Because every building stands on the ground and a ray
  toward a satellite only rises, the lowest point of the ray above a footprint is at this entry:
  the ray is blocked exactly when it is at most roof-high there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


@njit(cache=True)
def inside_footprint(px, py, edges, e0, e1):
    """Whether ``(px, py)`` is inside the footprint owning edges ``e0:e1`` (even-odd rule)."""
    inside = False
    for e in range(e0, e1):
        ay, by = edges[e, 1], edges[e, 3]
        if (ay > py) != (by > py):
            ax, bx = edges[e, 0], edges[e, 2]
            x_cross = ax + (py - ay) * (bx - ax) / (by - ay)
            if px < x_cross:
                inside = not inside
    return inside


@njit(cache=True)
def _ray_bbox(px, py, dx, dy, x0, y0, x1, y1):
    """Whether the ray ``p + t d`` (t >= 0) meets the closed box (slab test)."""
    t_lo, t_hi = 0.0, np.inf
    for k in range(2):
        p = px if k == 0 else py
        d = dx if k == 0 else dy
        lo = x0 if k == 0 else y0
        hi = x1 if k == 0 else y1
        if d == 0.0:
            if p < lo or p > hi:
                return False
        else:
            t1 = (lo - p) / d
            t2 = (hi - p) / d
            if t1 > t2:
                t1, t2 = t2, t1
            t_lo = max(t_lo, t1)
            t_hi = min(t_hi, t2)
            if t_lo > t_hi:
                return False
    return True


@njit(cache=True)
def entry_distance(px, py, dx, dy, edges, e0, e1):
    """Entry distance of the ray ``p + t d`` into the footprint of edges ``e0:e1`` (module
    docstring): 0 inside, else the nearest edge met at ``t >= 0``, ``inf`` for none."""
    if inside_footprint(px, py, edges, e0, e1):
        return 0.0
    best = np.inf
    for e in range(e0, e1):
        ax, ay, bx, by = edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3]
        ex, ey = bx - ax, by - ay
        wx, wy = ax - px, ay - py
        den = _cross(dx, dy, ex, ey)
        if den == 0.0:
            if _cross(wx, wy, dx, dy) == 0.0:  # collinear: nearest point of the edge ahead
                ta = wx * dx + wy * dy
                tb = (bx - px) * dx + (by - py) * dy
                lo, hi = min(ta, tb), max(ta, tb)
                if hi >= 0.0:
                    t = max(lo, 0.0)
                    if t < best:
                        best = t
            continue
        t = _cross(wx, wy, ex, ey) / den
        s = _cross(wx, wy, dx, dy) / den
        if t >= 0.0 and s >= 0.0 and s <= 1.0 and t < best:
            best = t
    return best


@njit(cache=True)
def _bbox_dist(px, py, bbox, b):
    ddx = max(max(bbox[b, 0] - px, 0.0), px - bbox[b, 2])
    ddy = max(max(bbox[b, 1] - py, 0.0), py - bbox[b, 3])
    return math.hypot(ddx, ddy)


@njit(cache=True)
def blocked_sorted(pos, edges, edge_start, heights, bbox, cot_s, h_dir):
    """Blocked (receiver, rising satellite) pairs, satellites in the sorted order of
    :class:`~coopnav_env.sim.city.SkyDirections` (``cot_s`` increasing, ``h_dir`` (n_up, 2)).

    A building is tested only when its roof is above the receiver and its bounding box within
    reach of the lowest ray, and then only against the satellites low enough to pass under the
    roof at the box's nearest point; a satellite is blocked when the ray's entry distance into
    the footprint is at most ``(roof - z) cot(el)`` (the ray is at most roof-high there).
    """
    n_rx = pos.shape[0]
    m = heights.shape[0]
    n_up = cot_s.shape[0]
    blocked = np.zeros((n_rx, n_up), dtype=np.bool_)
    if n_up == 0:
        return blocked
    cot_max = cot_s[n_up - 1]
    for i in range(n_rx):
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        for b in range(m):
            climb = heights[b] - pz
            if not climb > 0.0:
                continue
            dist_xy = _bbox_dist(px, py, bbox, b)
            if not dist_xy <= climb * cot_max:
                continue
            first = np.searchsorted(cot_s, dist_xy / climb)
            e0, e1 = edge_start[b], edge_start[b + 1]
            for s in range(first, n_up):
                if blocked[i, s]:
                    continue
                dx, dy = h_dir[s, 0], h_dir[s, 1]
                if not _ray_bbox(px, py, dx, dy, bbox[b, 0], bbox[b, 1], bbox[b, 2], bbox[b, 3]):
                    continue
                t = entry_distance(px, py, dx, dy, edges, e0, e1)
                if t <= climb * cot_s[s]:
                    blocked[i, s] = True
    return blocked


@njit(cache=True)
def line_of_sight(pos, edges, edge_start, heights, bbox, up, order, cot_s, h_dir):
    """Visible (receiver, satellite) pairs ``(n_rx, n_sv)``: ``up`` satellites not blocked
    (:func:`blocked_sorted`; columns as :class:`~coopnav_env.sim.city.SkyDirections` sorts)."""
    n_rx = pos.shape[0]
    n_sv = up.shape[0]
    visible = np.empty((n_rx, n_sv), dtype=np.bool_)
    for i in range(n_rx):
        for k in range(n_sv):
            visible[i, k] = up[k]
    n_up = cot_s.shape[0]
    if heights.shape[0] == 0 or n_rx == 0 or n_up == 0:
        return visible
    blocked = blocked_sorted(pos, edges, edge_start, heights, bbox, cot_s, h_dir)
    up_idx = np.nonzero(up)[0]
    for j in range(n_up):
        col = up_idx[order[j]]
        for i in range(n_rx):
            visible[i, col] = not blocked[i, j]
    return visible


@njit(cache=True)
def sky_and_walls(pos, dirs, edges, edge_start, heights, bbox):
    """Skyline ``tan(elevation)`` and nearest wall per (receiver, azimuth), ``(n, n_az)`` each.

    Skyline: the largest ``(roof - z) / t`` over buildings with a roof above the receiver,
    ``t`` the entry distance (``inf`` inside a footprint, 0 when no such building lies along
    the ray). Wall: the smallest entry distance over buildings whose roof is above the
    receiver and whose base is not (``0 <= z < roof``), ``inf`` for none.
    """
    n = pos.shape[0]
    n_az = dirs.shape[0]
    m = heights.shape[0]
    tan_max = np.zeros((n, n_az))
    dist = np.full((n, n_az), np.inf)
    for i in range(n):
        px, py, z = pos[i, 0], pos[i, 1], pos[i, 2]
        for b in range(m):
            rel_h = heights[b] - z
            if not rel_h > 0.0:
                continue
            e0, e1 = edge_start[b], edge_start[b + 1]
            for a in range(n_az):
                dx, dy = dirs[a, 0], dirs[a, 1]
                if not _ray_bbox(px, py, dx, dy, bbox[b, 0], bbox[b, 1], bbox[b, 2], bbox[b, 3]):
                    continue
                t = entry_distance(px, py, dx, dy, edges, e0, e1)
                if t == np.inf:
                    continue
                tan_el = rel_h / t if t > 0.0 else np.inf
                if tan_el > tan_max[i, a]:
                    tan_max[i, a] = tan_el
                if z >= 0.0 and t < dist[i, a]:
                    dist[i, a] = t
    return tan_max, dist


@njit(cache=True)
def inside_buildings(pos, edges, edge_start, heights, bbox):
    """Whether each point ``(n, 3)`` is inside a building: inside a footprint (even-odd) with
    ``0 < z < roof``."""
    n = pos.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        px, py, z = pos[i, 0], pos[i, 1], pos[i, 2]
        for b in range(heights.shape[0]):
            if not (z > 0.0 and z < heights[b]):
                continue
            if px < bbox[b, 0] or px > bbox[b, 2] or py < bbox[b, 1] or py > bbox[b, 3]:
                continue
            if inside_footprint(px, py, edges, edge_start[b], edge_start[b + 1]):
                out[i] = True
                break
    return out


@njit(cache=True)
def _edge_dist2(qx, qy, ax, ay, bx, by):
    """Squared distance from ``q`` to the segment ``a b``."""
    ex, ey = bx - ax, by - ay
    l2 = ex * ex + ey * ey
    u = 0.0
    if l2 > 0.0:
        u = min(max(((qx - ax) * ex + (qy - ay) * ey) / l2, 0.0), 1.0)
    rx, ry = qx - (ax + u * ex), qy - (ay + u * ey)
    return rx * rx + ry * ry


@njit(cache=True)
def _wall_g(t, p0, d, ax, ay, bx, by, h):
    """Squared distance at ``p0 + t d`` to the vertical wall ``edge x [0, h]``."""
    qx, qy, qz = p0[0] + t * d[0], p0[1] + t * d[1], p0[2] + t * d[2]
    dz = max(qz - h, 0.0) + max(-qz, 0.0)
    return _edge_dist2(qx, qy, ax, ay, bx, by) + dz * dz


@njit(cache=True)
def segment_wall_dist2(p0, d, ax, ay, bx, by, h):
    """Smallest squared distance between the segment ``p0 + t d`` (t in [0, 1]) and the wall
    ``edge a b x [0, h]``.

    The squared distance to a convex set along a segment is a convex piecewise quadratic in
    ``t``; its pieces change where the projection onto the edge leaves ``[0, 1]`` or the height
    crosses 0 or ``h``. The minimum is at an end, at a piece boundary or at the stationary point
    of a piece (found exactly from three samples of the quadratic); all are evaluated.
    """
    ex, ey = bx - ax, by - ay
    l2 = ex * ex + ey * ey
    ts = np.empty(8)
    k = 0
    ts[k] = 0.0
    k += 1
    ts[k] = 1.0
    k += 1
    du = d[0] * ex + d[1] * ey
    if l2 > 0.0 and du != 0.0:
        u0 = (p0[0] - ax) * ex + (p0[1] - ay) * ey
        for target in (0.0, l2):
            t = (target - u0) / du
            if t > 0.0 and t < 1.0:
                ts[k] = t
                k += 1
    if d[2] != 0.0:
        for zt in (0.0, h):
            t = (zt - p0[2]) / d[2]
            if t > 0.0 and t < 1.0:
                ts[k] = t
                k += 1
    tb = np.sort(ts[:k])
    best = np.inf
    for j in range(k):
        g = _wall_g(tb[j], p0, d, ax, ay, bx, by, h)
        if g < best:
            best = g
    for j in range(k - 1):
        a, b = tb[j], tb[j + 1]
        if b - a <= 0.0:
            continue
        m = 0.5 * (a + b)
        ga = _wall_g(a, p0, d, ax, ay, bx, by, h)
        gm = _wall_g(m, p0, d, ax, ay, bx, by, h)
        gb = _wall_g(b, p0, d, ax, ay, bx, by, h)
        # quadratic through (a, ga), (m, gm), (b, gb): curvature c2 and slope at m
        half = 0.5 * (b - a)
        c2 = (ga - 2.0 * gm + gb) / (2.0 * half * half)
        slope = (gb - ga) / (2.0 * half)
        if c2 > 0.0:
            t = min(max(m - slope / (2.0 * c2), a), b)
            g = _wall_g(t, p0, d, ax, ay, bx, by, h)
            if g < best:
                best = g
    return best


@njit(cache=True)
def swept_collisions(edges, edge_start, heights, bbox, start, end, radius):
    """Whether each sphere of ``radius`` moving from ``start`` to ``end`` ``(n, 3)`` touches a
    building (distance <= radius).

    The distance to an extruded polygon is the smaller of the distances to its walls (each
    edge times ``[0, roof]``) and, where an end of the segment is above the footprint, its
    height above the roof (inside the footprint below the roof: 0). Buildings whose bounding
    box, grown by ``radius``, misses the segment's are skipped.
    """
    n = start.shape[0]
    hit = np.zeros(n, dtype=np.bool_)
    r2 = radius * radius
    p0 = np.empty(3)
    d = np.empty(3)
    for i in range(n):
        for k in range(3):
            p0[k] = start[i, k]
            d[k] = end[i, k] - start[i, k]
        sx0, sx1 = min(start[i, 0], end[i, 0]), max(start[i, 0], end[i, 0])
        sy0, sy1 = min(start[i, 1], end[i, 1]), max(start[i, 1], end[i, 1])
        sz0 = min(start[i, 2], end[i, 2])
        for b in range(heights.shape[0]):
            if sx1 < bbox[b, 0] - radius or sx0 > bbox[b, 2] + radius:
                continue
            if sy1 < bbox[b, 1] - radius or sy0 > bbox[b, 3] + radius:
                continue
            h = heights[b]
            if sz0 > h + radius:
                continue
            e0, e1 = edge_start[b], edge_start[b + 1]
            touched = False
            for q in (start, end):  # an end above (or inside) the footprint
                if inside_footprint(q[i, 0], q[i, 1], edges, e0, e1):
                    dz = max(q[i, 2] - h, 0.0) + max(-q[i, 2], 0.0)
                    if dz * dz <= r2:
                        touched = True
            if not touched:
                for e in range(e0, e1):
                    g = segment_wall_dist2(
                        p0, d, edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3], h
                    )
                    if g <= r2:
                        touched = True
                        break
            if touched:
                hit[i] = True
                break
    return hit


@njit(cache=True)
def wall_clearance(xs, ys, reach, edges, edge_start, bbox):
    """Clearance grid: ``out[j, i]`` is the distance from the cell centre ``(xs[i], ys[j])`` to
    the nearest wall, 0 inside a footprint, capped at ``reach`` (buildings whose box lies
    farther are skipped)."""
    ny, nx = ys.shape[0], xs.shape[0]
    out = np.full((ny, nx), reach)
    for j in range(ny):
        qy = ys[j]
        for i in range(nx):
            qx = xs[i]
            best2 = reach * reach
            for b in range(edge_start.shape[0] - 1):
                if qx < bbox[b, 0] - reach or qx > bbox[b, 2] + reach:
                    continue
                if qy < bbox[b, 1] - reach or qy > bbox[b, 3] + reach:
                    continue
                e0, e1 = edge_start[b], edge_start[b + 1]
                if inside_footprint(qx, qy, edges, e0, e1):
                    best2 = 0.0
                    break
                for e in range(e0, e1):
                    d2 = _edge_dist2(qx, qy, edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3])
                    if d2 < best2:
                        best2 = d2
            out[j, i] = math.sqrt(best2)
    return out


@njit(cache=True)
def largest_component(free):
    """The largest 8-connected piece of ``free`` (n_y, n_x) bool, with the moves of
    :func:`astar` (no corner cutting): pieces are numbered in row-major order of their first
    cell, and of equally large pieces the first counts. Returns a bool array like ``free``."""
    ny, nx = free.shape
    label = np.full((ny, nx), -1, dtype=np.int64)
    stack = np.empty(ny * nx, dtype=np.int64)
    steps_r = (1, -1, 0, 0, 1, 1, -1, -1)
    steps_c = (0, 0, 1, -1, 1, -1, 1, -1)
    best, best_size, n_pieces = -1, 0, 0
    for r0 in range(ny):
        for c0 in range(nx):
            if not free[r0, c0] or label[r0, c0] >= 0:
                continue
            k = n_pieces
            n_pieces += 1
            label[r0, c0] = k
            stack[0] = r0 * nx + c0
            top, size = 1, 0
            while top > 0:
                top -= 1
                cur = stack[top]
                r, c = cur // nx, cur % nx
                size += 1
                for s in range(8):
                    dr, dc = steps_r[s], steps_c[s]
                    rr, cc = r + dr, c + dc
                    if rr < 0 or rr >= ny or cc < 0 or cc >= nx:
                        continue
                    if not free[rr, cc] or label[rr, cc] >= 0:
                        continue
                    if dr != 0 and dc != 0 and not (free[r + dr, c] and free[r, c + dc]):
                        continue
                    label[rr, cc] = k
                    stack[top] = rr * nx + cc
                    top += 1
            if size > best_size:
                best, best_size = k, size
    out = np.zeros((ny, nx), dtype=np.bool_)
    if best < 0:
        return out
    for r in range(ny):
        for c in range(nx):
            out[r, c] = label[r, c] == best
    return out


@njit(cache=True, inline="always")
def _heap_less(hf, hc, i, j):
    return hf[i] < hf[j] or (hf[i] == hf[j] and hc[i] < hc[j])


@njit(cache=True)
def astar(free, clear, preferred, start, goal):
    """Cheapest 8-connected path of cells on ``free`` (n_y, n_x) from ``start`` to ``goal``
    (flat indices ``row * n_x + col``), no corner cutting: a step costs its length (1 or
    sqrt 2) times ``1 + 4 (1 - min(clear, preferred) / preferred)`` of the cell entered; the
    octile distance is the heuristic; ties go to the earlier pushed node. Returns the flat
    indices of the path, start first (empty when the goal cannot be reached)."""
    ny, nx = free.shape
    n = ny * nx
    sq2 = math.sqrt(2.0)
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    done = np.zeros(n, dtype=np.bool_)
    cap = 8 * n + 1
    hf = np.empty(cap)
    hc = np.empty(cap, dtype=np.int64)
    hn = np.empty(cap, dtype=np.int64)
    size = 0
    counter = 0
    gr, gc = goal // nx, goal % nx
    g[start] = 0.0
    dr0, dc0 = abs(start // nx - gr), abs(start % nx - gc)
    hf[0] = max(dr0, dc0) + (sq2 - 1.0) * min(dr0, dc0)
    hc[0] = 0
    hn[0] = start
    size = 1
    steps_r = (1, -1, 0, 0, 1, 1, -1, -1)
    steps_c = (0, 0, 1, -1, 1, -1, 1, -1)
    while size > 0:
        cur = hn[0]
        # pop: move the last to the root and sift down
        size -= 1
        hf[0], hc[0], hn[0] = hf[size], hc[size], hn[size]
        i = 0
        while True:
            a, b = 2 * i + 1, 2 * i + 2
            m = i
            if a < size and _heap_less(hf, hc, a, m):
                m = a
            if b < size and _heap_less(hf, hc, b, m):
                m = b
            if m == i:
                break
            hf[i], hf[m] = hf[m], hf[i]
            hc[i], hc[m] = hc[m], hc[i]
            hn[i], hn[m] = hn[m], hn[i]
            i = m
        if cur == goal:
            length = 1
            k = cur
            while parent[k] >= 0:
                k = parent[k]
                length += 1
            path = np.empty(length, dtype=np.int64)
            k = cur
            for j in range(length - 1, -1, -1):
                path[j] = k
                k = parent[k]
            return path
        if done[cur]:
            continue
        done[cur] = True
        r, c = cur // nx, cur % nx
        for s in range(8):
            dr, dc = steps_r[s], steps_c[s]
            rr, cc = r + dr, c + dc
            if rr < 0 or rr >= ny or cc < 0 or cc >= nx or not free[rr, cc]:
                continue
            if dr != 0 and dc != 0 and not (free[r + dr, c] and free[r, c + dc]):
                continue
            near = 1.0 - min(clear[rr, cc], preferred) / preferred
            cost = g[cur] + (sq2 if dr != 0 and dc != 0 else 1.0) * (1.0 + 4.0 * near)
            nxt = rr * nx + cc
            if cost < g[nxt]:
                g[nxt] = cost
                parent[nxt] = cur
                counter += 1
                ddr, ddc = abs(rr - gr), abs(cc - gc)
                # push and sift up
                i = size
                size += 1
                hf[i] = cost + max(ddr, ddc) + (sq2 - 1.0) * min(ddr, ddc)
                hc[i] = counter
                hn[i] = nxt
                while i > 0:
                    p = (i - 1) // 2
                    if not _heap_less(hf, hc, i, p):
                        break
                    hf[i], hf[p] = hf[p], hf[i]
                    hc[i], hc[p] = hc[p], hc[i]
                    hn[i], hn[p] = hn[p], hn[i]
                    i = p
    return np.empty(0, dtype=np.int64)
