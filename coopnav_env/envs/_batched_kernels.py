"""Compiled (numba) steps of ``K`` swarms at once, parallel over the swarms.

The three kernels below advance every copy of :class:`coopnav_env.envs.BatchedUrbanCanyonEnv`
by one epoch between the numpy operations whose rounding they must keep (the ENU-to-ECEF
rotations and the skyline's ``arctan``, which stay numpy calls on ``(K, ...)`` arrays):

1. :func:`motion_sight_relative`: motion (kinematics, fence, collisions, separation), line of
   sight and relative sensing;
2. :func:`navigation_reward_sensors`: receiver-satellite geometry, pseudoranges, standalone
   and cooperative navigation, the estimate selection and waypoints
   (:func:`coopnav_env.sim._kernels.epoch_navigation`), the reward terms and the skyline and
   wall sensors;
3. :func:`observations_infos`: observations and the real numbers of the infos.

Each swarm ``k`` runs the kernels of the one-swarm step (:mod:`coopnav_env.sim._kernels`,
:mod:`coopnav_env.gnss._kernels`, :mod:`coopnav_env.envs._kernels`) on its own slices, with
its own random draws, in a ``prange`` loop: its arithmetic does not depend on ``K`` or on the
other swarms, so copy ``k`` of a batch is bit for bit a separate environment (the tests of
``tests/envs/test_batched.py`` and ``tests/envs/test_batched_polygons.py`` compare them).

Arrays whose size depends on the swarm are padded: box buildings ``(K, B_max, 3)`` with
counts ``n_b``; a swarm whose city is extruded polygons (a file or family city) has none, and
its polygons come in ``polygons`` (edges ``(K, E_max, 4)``, ring offsets, roofs and bounding
boxes with per-swarm counts, :func:`_polygons_of`), traced by the kernels of
:mod:`coopnav_env.sim._polygon_kernels` in the order of ``UrbanWorld.step`` (swept collisions
after the motion, then the separation test again; line of sight; the skyline and walls).
Routes are ``(K, R_max, 2)`` with counts ``n_route``; the satellites come from a table of
skies ``(T, S_max, ...)`` with the row of each swarm's epoch ``sky_row`` and its count
``n_sv``; the line-of-sight matrices go into one flat buffer at offsets ``los_off`` (each
copy's ``(N, S)`` block contiguous).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from coopnav_env.envs import _kernels as _env_kernels
from coopnav_env.gnss import _kernels as _gnss_kernels
from coopnav_env.sim import _kernels as _sim_kernels
from coopnav_env.sim import _polygon_kernels as _poly_kernels


@njit(cache=True)
def _polygons_of(k, polygons):
    """Copy ``k``'s extruded polygon buildings from the padded ``polygons``: whether it has
    them (else boxes), and its ``edges (n_e, 4), edge_start (n_p + 1,), heights (n_p,),
    bbox (n_p, 4)`` as :mod:`coopnav_env.sim._polygon_kernels` takes them."""
    is_poly, edges, edge_start, heights, bbox, n_poly, n_edge = polygons
    npb = n_poly[k]
    return (
        is_poly[k],
        np.ascontiguousarray(edges[k, : n_edge[k]]),
        np.ascontiguousarray(edge_start[k, : npb + 1]),
        np.ascontiguousarray(heights[k, :npb]),
        np.ascontiguousarray(bbox[k, :npb]),
    )


@njit(cache=True)
def _motion_one(
    k,
    pos0,
    vel0,
    cmd,
    motion,
    moving,
    fence_lo,
    fence_hi,
    b_lo,
    b_hi,
    n_b,
    polygons,
    sky_row,
    n_sv,
    sky_up,
    sky_order,
    sky_cot,
    sky_hdir,
    n_up,
    z,
    sensing,
    pos1,
    vel1,
    hit,
    sep,
    los_flat,
    los_off,
    rel,
    var,
    avail,
    n_rx,
):
    n = pos0.shape[1]
    nb = n_b[k]
    lo = np.ascontiguousarray(b_lo[k, :nb])
    hi = np.ascontiguousarray(b_hi[k, :nb])
    is_poly, edges, edge_start, heights, bbox = _polygons_of(k, polygons)
    if moving:
        p1, v1, h, s = _sim_kernels.world_motion(
            pos0[k],
            vel0[k],
            cmd[k],
            motion[0],
            motion[1],
            motion[2],
            motion[3],
            motion[4],
            fence_lo[k],
            fence_hi[k],
            lo,
            hi,
            motion[5],
            motion[6],
        )
        if is_poly:  # the motion above met no building: collide with the polygons
            h = _poly_kernels.swept_collisions(
                edges, edge_start, heights, bbox, pos0[k], p1, motion[5]
            )
            for i in range(n):
                if h[i]:
                    for c in range(3):
                        p1[i, c] = pos0[k, i, c]
                        v1[i, c] = 0.0
            s = _sim_kernels.separation_violations(p1, motion[6])
    else:  # the first epoch of an episode: where the swarm starts, no collision test
        p1 = pos0[k].copy()
        v1 = vel0[k].copy()
        h = np.zeros(n, dtype=np.bool_)
        s = np.zeros(n, dtype=np.bool_)
    pos1[k] = p1
    vel1[k] = v1
    hit[k] = h
    sep[k] = s
    row = sky_row[k]
    ns = n_sv[k]
    nu = n_up[k]
    up = np.ascontiguousarray(sky_up[row, :ns])
    order = np.ascontiguousarray(sky_order[row, :nu])
    cot = np.ascontiguousarray(sky_cot[row, :nu])
    hdir = np.ascontiguousarray(sky_hdir[row, :nu])
    if is_poly:
        vis = _poly_kernels.line_of_sight(
            p1, edges, edge_start, heights, bbox, up, order, cot, hdir
        )
    else:
        vis = _sim_kernels.line_of_sight(p1, lo, hi, up, order, cot, hdir)
    off = los_off[k]
    for i in range(n):
        c = 0
        for j in range(ns):
            los_flat[off + i * ns + j] = vis[i, j]
            if vis[i, j]:
                c += 1
        n_rx[k, i] = c
    # the draws of the epoch: pseudoranges (S + N S), then relative sensing (N (N - 1) / 2, 3)
    m = n * (n - 1) // 2
    start = ns + n * ns
    zr = np.empty((m, 3))
    for p in range(m):
        for c in range(3):
            zr[p, c] = z[k, start + 3 * p + c]
    r, v, a = _sim_kernels.relative_measurements(p1, zr, sensing[0], sensing[1], sensing[2])
    rel[k] = r
    var[k] = v
    avail[k] = a


@njit(cache=True, nogil=True)
def motion_sight_relative(
    k0,  # the copies k0 <= k < k1 of the batch
    k1,
    pos0,  # (K, N, 3) true positions before the step
    vel0,  # (K, N, 3)
    cmd,  # (K, N, 3) clipped commands
    motion,  # (7,) max speed, max dv, dt, altitude min, altitude max, radius, min separation
    moving,  # bool: False at an episode's first epoch (the swarm stays where it starts)
    fence_lo,  # (K, 2)
    fence_hi,  # (K, 2)
    b_lo,  # (K, B_max, 3) building boxes
    b_hi,
    n_b,  # (K,)
    polygons,  # extruded polygon buildings (see _polygons_of)
    sky_row,  # (K,) row of each swarm's sky in the table
    n_sv,  # (K,)
    sky_up,  # (T, S_max) bool
    sky_order,  # (T, S_max) int
    sky_cot,  # (T, S_max)
    sky_hdir,  # (T, S_max, 2)
    n_up,  # (K,) rising satellites of each swarm's sky
    z,  # (K, L_max) standard normal draws of the epoch
    sensing,  # (3,) relative sensing sigma0, sigma per metre, max range
    los_off,  # (K + 1,) offsets of the line-of-sight blocks in the flat buffer
    pos1,  # outputs: (K, N, 3)
    vel1,  # (K, N, 3)
    hit,  # (K, N) bool
    sep,  # (K, N) bool
    los_flat,  # (los_off[K],) bool
    rel,  # (K, N, N, 3)
    var,  # (K, N, N)
    avail,  # (K, N, N) bool
    n_rx,  # (K, N) int64 satellites in line of sight of each UAV
):
    """Motion, line of sight and relative sensing of the copies ``k0 <= k < k1`` (see the
    module docstring), written into the output arrays."""
    for k in range(k0, k1):
        _motion_one(
            k,
            pos0,
            vel0,
            cmd,
            motion,
            moving,
            fence_lo,
            fence_hi,
            b_lo,
            b_hi,
            n_b,
            polygons,
            sky_row,
            n_sv,
            sky_up,
            sky_order,
            sky_cot,
            sky_hdir,
            n_up,
            z,
            sensing,
            pos1,
            vel1,
            hit,
            sep,
            los_flat,
            los_off,
            rel,
            var,
            avail,
            n_rx,
        )


@njit(cache=True)
def _navigate_one(
    k,
    shared,
    rx_ecef,
    sky_row,
    n_sv,
    sky_sv,
    sky_sys,
    los_flat,
    los_off,
    clock,
    iono,
    z,
    model,
    n_sys,
    x0,
    rel_ecef,
    var,
    avail,
    ddt,
    max_iter,
    radius,
    gate,
    origin,
    rot,
    pred,
    prev_cov,
    dr_var,
    route,
    tail,
    n_route,
    next_wp,
    reach_m,
    pos0,
    pos1,
    goal,
    hit,
    sep,
    reward_mode,
    reward_params,
    rays,
    b_lo,
    b_hi,
    n_b,
    polygons,
    wgs,
    n_bowring,
    sa_status,
    n_iter,
    sa_pos,
    sa_cov,
    co_pos,
    co_cov,
    co_status,
    source,
    nav_pos,
    nav_cov,
    sa_rej,
    co_rej,
    wp_out,
    n_swarm,
    n_sats,
    centroid_uav,
    out_of_contact,
    terms,
    in_goal,
    ends,
    tan_max,
    walls,
    bad_geometry,
):
    n = rx_ecef.shape[1]
    row = sky_row[k]
    ns = n_sv[k]
    sv = np.ascontiguousarray(sky_sv[row, :ns])
    system = np.ascontiguousarray(sky_sys[row, :ns])
    off = los_off[k]
    received = np.empty((n, ns), dtype=np.bool_)
    for i in range(n):
        c = 0
        for j in range(ns):
            received[i, j] = los_flat[off + i * ns + j]
            if received[i, j]:
                c += 1
        n_sats[k, i] = c
    range_m, _az, el_deg, at_centre, zero_range = _gnss_kernels.range_azimuth_elevation(
        rx_ecef[k], sv, wgs[0], wgs[1], wgs[2], wgs[3], wgs[4], n_bowring
    )
    if at_centre or zero_range:
        bad_geometry[k] = True
        return
    z_common = np.empty(ns)
    z_user = np.empty((n, ns))
    for j in range(ns):
        z_common[j] = z[k, j]
    for i in range(n):
        for j in range(ns):
            z_user[i, j] = z[k, ns + i * ns + j]
    av = avail[k]
    if shared:  # one centroid: the UAV receiving the most satellites (the first of equals)
        a = 0
        for i in range(1, n):
            if n_sats[k, i] > n_sats[k, a]:
                a = i
        linked = av[a].copy()
        linked[a] = True
        rel_b = np.empty((1, n, 3))
        var_b = np.empty((1, n))
        avail_b = np.empty((1, n), dtype=np.bool_)
        rel_b[0] = rel_ecef[k, 0]  # the centroid row only
        var_b[0] = var[k, a]
        avail_b[0] = av[a]
        cen = np.array([a], dtype=np.int64)
        x0_co = np.empty((1, 3))
        x0_co[0] = x0[k, a]
        centroid_uav[k] = a
    else:  # every UAV its own centroid; one out of range of every other navigates standalone
        linked = np.empty(n, dtype=np.bool_)
        for i in range(n):
            any_link = False
            for p in range(n):
                any_link = any_link or av[i, p]
            linked[i] = any_link or n == 1
        rel_b = rel_ecef[k]
        var_b = var[k]
        avail_b = av
        cen = np.arange(n).astype(np.int64)
        x0_co = x0[k]
        centroid_uav[k] = -1
    nr = n_route[k]
    r_k = np.ascontiguousarray(route[k, :nr])
    t_k = np.ascontiguousarray(tail[k, :nr])
    s_status, s_iter, c_iter, sel, wp, nsw, _used = _sim_kernels.epoch_navigation(
        range_m,
        el_deg,
        sv,
        system,
        received,
        clock[k],
        iono,
        z_common,
        z_user,
        np.zeros((n, ns)),
        np.full(ns, np.nan),
        model[0],
        model[1] != 0.0,
        model[2] != 0.0,
        n_sys,
        x0[k],
        rel_b,
        var_b,
        avail_b,
        cen,
        x0_co,
        ddt,
        max_iter,
        1e-4,
        radius[0] != 0.0,
        radius[1],
        radius[2],
        linked,
        gate[0] != 0.0,
        gate[1],
        origin,
        rot,
        pred[k],
        prev_cov[k],
        dr_var,
        r_k,
        next_wp[k],
        reach_m,
        av,
    )
    sa_status[k] = s_status
    n_iter[k, 0] = s_iter
    n_iter[k, 1] = c_iter
    sa_pos[k] = sel[0]
    sa_cov[k] = sel[1]
    co_pos[k] = sel[2]
    co_cov[k] = sel[3]
    co_status[k] = sel[4]
    source[k] = sel[5]
    nav_pos[k] = sel[6]
    nav_cov[k] = sel[7]
    sa_rej[k] = sel[8]
    co_rej[k] = sel[9]
    wp_out[k] = wp
    n_swarm[k] = nsw
    for i in range(n):
        lonely = True
        for p in range(n):
            lonely = lonely and not av[i, p]
        out_of_contact[k, i] = lonely and n > 1
    if reward_mode == 2:  # navigated distance: nav and progress come from the route after
        t, g, crash, reached = _env_kernels.event_reward_terms(
            pos1[k], goal[k], hit[k], sep[k], out_of_contact[k], reward_params
        )
    else:
        xy_prev = np.empty((n, 2))
        for i in range(n):
            xy_prev[i, 0] = pos0[k, i, 0]
            xy_prev[i, 1] = pos0[k, i, 1]
        t, g, crash, reached = _env_kernels.reward_terms(
            r_k,
            t_k,
            next_wp[k],
            xy_prev,
            pos1[k],
            goal[k],
            sel[6],
            sel[7],
            hit[k],
            sep[k],
            out_of_contact[k],
            reward_mode == 1,
            reward_params,
        )
    terms[k] = t
    in_goal[k] = g
    ends[k, 0] = crash
    ends[k, 1] = reached
    nb = n_b[k]
    is_poly, edges, edge_start, heights, bbox = _polygons_of(k, polygons)
    if is_poly:
        tm, w = _poly_kernels.sky_and_walls(pos1[k], rays, edges, edge_start, heights, bbox)
    else:
        tm, w = _sim_kernels.sky_and_walls(
            pos1[k], rays, np.ascontiguousarray(b_lo[k, :nb]), np.ascontiguousarray(b_hi[k, :nb])
        )
    tan_max[k] = tm
    walls[k] = w


@njit(cache=True, nogil=True)
def navigation_reward_sensors(
    k0,  # the copies k0 <= k < k1 of the batch
    k1,
    shared,  # bool: one shared centroid per swarm (else one per UAV)
    rx_ecef,  # (K, N, 3) true positions in ECEF
    sky_row,  # (K,)
    n_sv,  # (K,)
    sky_sv,  # (T, S_max, 3) satellite positions
    sky_sys,  # (T, S_max) int64 constellation index (sorted)
    los_flat,  # line of sight (= the received satellites), flat
    los_off,  # (K + 1,)
    clock,  # (K, N, n_sys_all) receiver clock biases [m]
    iono,  # (n_sys_all,)
    z,  # (K, L_max) the epoch's standard normal draws
    model,  # (3,) sigma URE, troposphere (1/0), differential (1/0)
    n_sys,
    x0,  # (K, N, 3) ECEF predicted positions
    rel_ecef,  # (K, N, N, 3) measured relative positions in ECEF ((K, 1, N, 3): shared)
    var,  # (K, N, N)
    avail,  # (K, N, N) bool
    ddt,
    max_iter,
    radius,  # (3,) check (1/0), min, max plausible radius
    gate,  # (2,) on (1/0), max sigma^2
    origin,
    rot,
    pred,  # (K, N, 3) ENU predicted positions
    prev_cov,  # (K, N, 3, 3) covariances of the previous estimates
    dr_var,
    route,  # (K, R_max, 2)
    tail,  # (K, R_max)
    n_route,  # (K,)
    next_wp,  # (K, N) next waypoints before the step
    reach_m,
    pos0,  # (K, N, 3) true positions before the step
    pos1,  # (K, N, 3) after it
    goal,  # (K, 3)
    hit,  # (K, N) collided
    sep,  # (K, N) separation violated
    reward_mode,  # 0: distance nav term, 1: sigma nav term, 2: events only (navigated distance)
    reward_params,
    rays,  # (A, 2) sensor ray directions
    b_lo,
    b_hi,
    n_b,
    polygons,  # extruded polygon buildings (see _polygons_of)
    wgs,  # (5,) WGS84 a, b, f, e2, e'2
    n_bowring,
    outputs,  # the arrays written (NAVIGATION_OUTPUTS, in order)
):
    """Navigation, reward terms and skyline / wall sensors of the copies ``k0 <= k < k1``
    (module docstring), written into ``outputs``: ``sa_status, n_iter (K, 2), sa_pos, sa_cov,
    co_pos, co_cov, co_status, source, nav_pos, nav_cov, sa_rej, co_rej, next_wp, n_swarm,
    n_sats, centroid_uav, out_of_contact, terms (K, 6, N), in_goal, ends (K, 2: crash,
    reached), tan_max, walls, bad_geometry (K,)``."""
    (
        sa_status,
        n_iter,
        sa_pos,
        sa_cov,
        co_pos,
        co_cov,
        co_status,
        source,
        nav_pos,
        nav_cov,
        sa_rej,
        co_rej,
        wp_out,
        n_swarm,
        n_sats,
        centroid_uav,
        out_of_contact,
        terms,
        in_goal,
        ends,
        tan_max,
        walls,
        bad_geometry,
    ) = outputs
    for k in range(k0, k1):
        _navigate_one(
            k,
            shared,
            rx_ecef,
            sky_row,
            n_sv,
            sky_sv,
            sky_sys,
            los_flat,
            los_off,
            clock,
            iono,
            z,
            model,
            n_sys,
            x0,
            rel_ecef,
            var,
            avail,
            ddt,
            max_iter,
            radius,
            gate,
            origin,
            rot,
            pred,
            prev_cov,
            dr_var,
            route,
            tail,
            n_route,
            next_wp,
            reach_m,
            pos0,
            pos1,
            goal,
            hit,
            sep,
            reward_mode,
            reward_params,
            rays,
            b_lo,
            b_hi,
            n_b,
            polygons,
            wgs,
            n_bowring,
            sa_status,
            n_iter,
            sa_pos,
            sa_cov,
            co_pos,
            co_cov,
            co_status,
            source,
            nav_pos,
            nav_cov,
            sa_rej,
            co_rej,
            wp_out,
            n_swarm,
            n_sats,
            centroid_uav,
            out_of_contact,
            terms,
            in_goal,
            ends,
            tan_max,
            walls,
            bad_geometry,
        )


@njit(cache=True)
def _observe_one(
    k,
    nav_pos,
    goal,
    vel,
    nav_cov,
    n_sats,
    n_swarm,
    n_sv,
    sky_deg,
    rel,
    avail,
    route,
    tail,
    n_route,
    wp,
    source,
    walls,
    steps,
    obs_params,
    k_neigh,
    low,
    high,
    pos,
    co_pos,
    sa_pos,
    obs,
    floats,
):
    nr = n_route[k]
    obs[k] = _env_kernels.observation_rows(
        nav_pos[k],
        goal[k],
        vel[k],
        nav_cov[k],
        n_sats[k],
        n_swarm[k],
        max(n_sv[k], 1),
        sky_deg[k],
        rel[k],
        avail[k],
        np.ascontiguousarray(route[k, :nr]),
        np.ascontiguousarray(tail[k, :nr]),
        wp[k],
        source[k],
        walls[k],
        steps[k],
        obs_params[k],
        k_neigh,
        low,
        high,
    )
    floats[k] = _env_kernels.info_floats(
        pos[k], nav_pos[k], co_pos[k], sa_pos[k], nav_cov[k], goal[k]
    )


@njit(cache=True, nogil=True)
def observations_infos(
    k0,  # the copies k0 <= k < k1 of the batch
    k1,
    nav_pos,  # (K, N, 3)
    goal,  # (K, 3)
    vel,  # (K, N, 3)
    nav_cov,  # (K, N, 3, 3)
    n_sats,  # (K, N)
    n_swarm,  # (K, N)
    n_sv,  # (K,)
    sky_deg,  # (K, N, A)
    rel,  # (K, N, N, 3)
    avail,  # (K, N, N)
    route,  # (K, R_max, 2)
    tail,  # (K, R_max)
    n_route,  # (K,)
    wp,  # (K, N)
    source,  # (K, N)
    walls,  # (K, N, A)
    steps,  # (K,) steps of each episode so far
    obs_params,  # (K, 9)
    k_neigh,
    low,  # (obs_dim,)
    high,
    pos,  # (K, N, 3) true positions
    co_pos,
    sa_pos,
    obs,  # outputs: (K, N, obs_dim) float32
    floats,  # (K, 8, N)
):
    """Observations and the infos' real numbers of the copies ``k0 <= k < k1``."""
    for k in range(k0, k1):
        _observe_one(
            k,
            nav_pos,
            goal,
            vel,
            nav_cov,
            n_sats,
            n_swarm,
            n_sv,
            sky_deg,
            rel,
            avail,
            route,
            tail,
            n_route,
            wp,
            source,
            walls,
            steps,
            obs_params,
            k_neigh,
            low,
            high,
            pos,
            co_pos,
            sa_pos,
            obs,
            floats,
        )


@njit(cache=True, nogil=True)
def navigated_distance_terms(
    pos,  # (K, N, 3) true positions after the step
    nav_pos,  # (K, N, 3) estimates after the step (NaN: none)
    route,  # (K, R_max, 2)
    tail,  # (K, R_max) route length after each waypoint
    wp,  # (K, N) next waypoints
    reached,  # (K,) bool: the swarm arrived this step
    unpaid,  # (K, N) route not yet paid before the step
    route_len,  # (K, N) route length at reset (> 0)
    cap_m,  # nav_reward_cap_m
    terms,  # output: (K, 6, N); rows 0 (nav) and 1 (progress) written
    unpaid_after,  # output: (K, N) route not yet paid after the step
):
    """The terms ``nav`` and ``progress`` of ``reward_scheme="navigated_distance"`` of every
    copy (:func:`coopnav_env.envs.task.navigated_distance`), with the float64 operations of
    its numpy formulation in the same order (the oracle ``navigated_distance_rows`` of
    ``tests/envs/oracles.py``, equal bit for bit): the remaining route is the distance to the
    next waypoint plus the route after it; ``np.clip(x, 0, None)`` is ``np.maximum(x, 0)``;
    ``np.fmin`` takes the cap where the error is not a number."""
    for k in range(pos.shape[0]):
        for i in range(pos.shape[1]):
            j = wp[k, i]
            dx = pos[k, i, 0] - route[k, j, 0]
            dy = pos[k, i, 1] - route[k, j, 1]
            now_m = np.sqrt(dx * dx + dy * dy) + tail[k, j]
            u = unpaid[k, i]
            if reached[k]:
                covered = u
            else:
                x = u - now_m
                covered = x if (x >= 0.0 or x != x) else 0.0  # numpy's maximum(x, 0)
            share = covered / route_len[k, i]
            ex = nav_pos[k, i, 0] - pos[k, i, 0]
            ey = nav_pos[k, i, 1] - pos[k, i, 1]
            ez = nav_pos[k, i, 2] - pos[k, i, 2]
            err = np.sqrt(ex * ex + ey * ey + ez * ez)
            short = (err if (err <= cap_m or cap_m != cap_m) else cap_m) / cap_m  # numpy's fmin
            terms[k, 0, i] = -share * short
            terms[k, 1, i] = share
            unpaid_after[k, i] = u - covered
