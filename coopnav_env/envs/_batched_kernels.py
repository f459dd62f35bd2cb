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
its own random draws, in a loop over the copies that the call claims: its arithmetic does
not depend on ``K``, on the other swarms or on the thread that runs it, so copy ``k`` of a
batch is bit for bit a separate environment (the tests of ``tests/envs/test_batched.py`` and
``tests/envs/test_batched_polygons.py`` compare them).

The copies are shared between threads without locks (``_fused._run_parallel``): they come
in segments (:func:`copy_segments`), one per thread of the pool, which takes its segment's
copies from the front; the calling thread, once it has done its own work, takes copies from
the back of the segments, the last first, until it meets each segment's thread. A copy
claimed by both threads at their meeting is computed twice, identically, into the same rows
(every kernel writes only its copies' rows of its outputs and reads none of them back from
another copy), so no copy is missed and the split never changes a result.

The kernels take a few typed records (named tuples of arrays and numbers, built where their
arrays are allocated): each kernel's settings (:class:`MotionSettings`,
:class:`NavigationSettings`, :class:`ObservationSettings`), the copies' :class:`Cities` and
:class:`Routes`, the epoch's :class:`SkyRows`, the arrays of the step that a kernel reads
(:class:`MotionInputs`, :class:`Moved`, :class:`NavigationInputs`, :class:`ObservationInputs`,
:class:`DistanceInputs`) and those it writes (:class:`Moved`, :class:`Navigated`,
:class:`Observed`, :class:`Paid`).

Arrays whose size depends on the swarm are padded: box buildings ``(K, B_max, 3)`` with
counts ``n_b``; a swarm whose city is extruded polygons (a file or family city) has none, and
its polygons come in :class:`Cities` too (edges ``(K, E_max, 4)``, ring offsets, roofs and
bounding boxes with per-swarm counts, :func:`_polygons_of`), traced by the kernels of
:mod:`coopnav_env.sim._polygon_kernels` in the order of ``UrbanWorld.step`` (swept collisions
after the motion, then the separation test again; line of sight; the skyline and walls).
Routes are ``(K, R_max, 2)`` with counts ``n_route``; the satellites come from a table of
skies ``(T, S_max, ...)`` with the row of each swarm's epoch ``row`` and its count
``n_sv``; the line-of-sight matrices go into one flat buffer at offsets ``los_off`` (each
copy's ``(N, S)`` block contiguous).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from coopnav_env.envs import _kernels as _env_kernels
from coopnav_env.gnss import _kernels as _gnss_kernels
from coopnav_env.sim import _kernels as _sim_kernels
from coopnav_env.sim import _polygon_kernels as _poly_kernels


def copy_segments(n_copies: int, n_segments: int) -> np.ndarray:
    """The copies ``0 <= k < n_copies`` in ``n_segments`` contiguous segments of about equal
    size, as the kernels' ``claims`` take them: ``(n_segments, 2)`` int64, each row
    ``[first, end)``."""
    if n_segments == 1:  # (every step of a parallel environment: the short way)
        return np.array([[0, n_copies]], dtype=np.int64)
    bounds = [n_copies * s // n_segments for s in range(n_segments + 1)]
    return np.array([bounds[:-1], bounds[1:]], dtype=np.int64).T.copy()


class Cities(NamedTuple):
    """Each copy's fence and buildings, padded to the largest copy (reloaded at its resets).

    A copy of box buildings has ``n_b`` boxes and ``is_poly`` False; a copy of extruded
    polygons has no boxes, and its polygons are ``edges (n_edge, 4)``, ring offsets
    ``edge_start (n_poly + 1,)``, roofs ``heights (n_poly,)`` and bounding boxes ``bbox
    (n_poly, 4)`` (:func:`_polygons_of`).
    """

    fence_lo: np.ndarray  # (K, 2) the fence's low corner, less the UAV radius
    fence_hi: np.ndarray  # (K, 2)
    b_lo: np.ndarray  # (K, B_max, 3) box buildings' low corners
    b_hi: np.ndarray  # (K, B_max, 3)
    n_b: np.ndarray  # (K,) int64 boxes of each copy
    is_poly: np.ndarray  # (K,) bool: the copy's buildings are extruded polygons
    edges: np.ndarray  # (K, E_max, 4) polygon edges (x0, y0, x1, y1)
    edge_start: np.ndarray  # (K, P_max + 1) int64 first edge of each polygon
    heights: np.ndarray  # (K, P_max) roof heights
    bbox: np.ndarray  # (K, P_max, 4) polygon bounding boxes
    n_poly: np.ndarray  # (K,) int64 polygons of each copy
    n_edge: np.ndarray  # (K,) int64 edges of each copy


class Routes(NamedTuple):
    """Each copy's route and goal, padded to the longest route (reloaded at its resets)."""

    route: np.ndarray  # (K, R_max, 2) waypoints
    tail: np.ndarray  # (K, R_max) route length after each waypoint
    n_route: np.ndarray  # (K,) int64 waypoints of each copy
    goal: np.ndarray  # (K, 3)


class SkyRows(NamedTuple):
    """The satellites of each copy's epoch: its row of a table of skies ``(T, S_max, ...)``,
    and where its line-of-sight block ``(N, n_sv)`` lies in the flat buffer."""

    row: np.ndarray  # (K,) int64 row of each copy's sky in the table
    n_sv: np.ndarray  # (K,) int64 satellites above the mask
    n_up: np.ndarray  # (K,) int64 rising satellites (line-of-sight order)
    los_off: np.ndarray  # (K + 1,) int64 offsets of the line-of-sight blocks
    sv: np.ndarray  # (T, S_max, 3) satellite positions in ECEF
    system: np.ndarray  # (T, S_max) int64 constellation index (sorted)
    up: np.ndarray  # (T, S_max) bool
    order: np.ndarray  # (T, S_max) int64
    cot: np.ndarray  # (T, S_max)
    hdir: np.ndarray  # (T, S_max, 2)


class MotionSettings(NamedTuple):
    """The configuration of :func:`motion_sight_relative`."""

    motion: np.ndarray  # (7,) max speed, max dv, dt, altitude min, max, radius, min separation
    sensing: np.ndarray  # (3,) relative sensing sigma0, sigma per metre, max range
    moving: bool  # False at an episode's first epoch (the swarm stays where it starts)


class MotionInputs(NamedTuple):
    """The arrays of a step that :func:`motion_sight_relative` reads."""

    pos0: np.ndarray  # (K, N, 3) true positions before the step [m]
    vel0: np.ndarray  # (K, N, 3) true velocities before the step [m/s]
    cmd: np.ndarray  # (K, N, 3) clipped commands
    z: np.ndarray  # (K, L_max) the epoch's standard normal draws


class Moved(NamedTuple):
    """What :func:`motion_sight_relative` writes (the swarms after their motion)."""

    pos: np.ndarray  # (K, N, 3) true positions after the step
    vel: np.ndarray  # (K, N, 3)
    hit: np.ndarray  # (K, N) bool collided
    sep: np.ndarray  # (K, N) bool separation violated
    los_flat: np.ndarray  # (los_off[K],) bool line of sight (= the received satellites)
    rel: np.ndarray  # (K, N, N, 3) measured relative positions (ENU)
    var: np.ndarray  # (K, N, N)
    avail: np.ndarray  # (K, N, N) bool
    n_rx: np.ndarray  # (K, N) int64 satellites in line of sight of each UAV


class NavigationSettings(NamedTuple):
    """The configuration of :func:`navigation_reward_sensors`."""

    shared: bool  # one shared centroid per swarm (else one per UAV)
    model: np.ndarray  # (3,) sigma URE, troposphere (1/0), differential (1/0)
    iono: np.ndarray  # (n_sys_all,)
    n_sys: int  # clock states: the systems flown
    ddt: bool  # double-difference transfer (else single)
    max_iter: int
    radius: np.ndarray  # (3,) check (1/0), min, max plausible radius
    gate: np.ndarray  # (2,) on (1/0), max sigma^2
    origin: np.ndarray  # (3,) ECEF origin of the ENU frame
    rot: np.ndarray  # (3, 3) ENU rotation
    dr_var: float  # dead-reckoning variance of a step (0 at an episode's first epoch)
    reach_m: float  # waypoint reach
    reward_mode: int  # 0: distance nav term, 1: sigma nav term, 2: events only
    reward_params: np.ndarray
    rays: np.ndarray  # (A, 2) sensor ray directions
    wgs: np.ndarray  # (5,) WGS84 a, b, f, e2, e'2
    n_bowring: int


class NavigationInputs(NamedTuple):
    """The arrays of a step that :func:`navigation_reward_sensors` reads besides the motion."""

    pos0: np.ndarray  # (K, N, 3) true positions before the step
    rx_ecef: np.ndarray  # (K, N, 3) true positions after it, ECEF
    pred: np.ndarray  # (K, N, 3) ENU predicted positions
    x0: np.ndarray  # (K, N, 3) the same in ECEF
    prev_cov: np.ndarray  # (K, N, 3, 3) covariances of the previous estimates
    rel_ecef: np.ndarray  # (K, N, N, 3) relative positions in ECEF ((K, 1, N, 3): shared)
    next_wp: np.ndarray  # (K, N) int64 next waypoints before the step
    clock: np.ndarray  # (K, N, n_sys_all) receiver clock biases [m]
    z: np.ndarray  # (K, L_max) the epoch's standard normal draws (MotionInputs.z)


class Navigated(NamedTuple):
    """What :func:`navigation_reward_sensors` writes (:func:`navigation_outputs` allocates it)."""

    sa_status: np.ndarray  # (K, N) int64
    n_iter: np.ndarray  # (K, 2) int64 standalone, cooperative iterations
    sa_pos: np.ndarray  # (K, N, 3)
    sa_cov: np.ndarray  # (K, N, 3, 3)
    co_pos: np.ndarray  # (K, N, 3)
    co_cov: np.ndarray  # (K, N, 3, 3)
    co_status: np.ndarray  # (K, N) int64
    source: np.ndarray  # (K, N) int64
    nav_pos: np.ndarray  # (K, N, 3)
    nav_cov: np.ndarray  # (K, N, 3, 3)
    sa_rej: np.ndarray  # (K, N) bool
    co_rej: np.ndarray  # (K, N) bool
    next_wp: np.ndarray  # (K, N) int64
    n_swarm: np.ndarray  # (K, N) int64
    n_sats: np.ndarray  # (K, N) int64
    centroid_uav: np.ndarray  # (K,) int64 (-1: one centroid per UAV)
    out_of_contact: np.ndarray  # (K, N) bool
    terms: np.ndarray  # (K, 6, N) reward terms
    in_goal: np.ndarray  # (K, N) bool
    ends: np.ndarray  # (K, 2) bool crash, reached
    tan_max: np.ndarray  # (K, N, A) skyline tangents
    walls: np.ndarray  # (K, N, A)
    bad_geometry: np.ndarray  # (K,) bool a receiver at the Earth's centre or on a satellite


def navigation_outputs(n_copies: int, n: int, n_az: int) -> Navigated:
    """The arrays :func:`navigation_reward_sensors` fills, for ``n_copies`` swarms of ``n``
    UAVs with ``n_az`` sensor rays."""
    k, i64 = n_copies, np.int64
    return Navigated(
        sa_status=np.empty((k, n), dtype=i64),
        n_iter=np.empty((k, 2), dtype=i64),
        sa_pos=np.empty((k, n, 3)),
        sa_cov=np.empty((k, n, 3, 3)),
        co_pos=np.empty((k, n, 3)),
        co_cov=np.empty((k, n, 3, 3)),
        co_status=np.empty((k, n), dtype=i64),
        source=np.empty((k, n), dtype=i64),
        nav_pos=np.empty((k, n, 3)),
        nav_cov=np.empty((k, n, 3, 3)),
        sa_rej=np.empty((k, n), dtype=bool),
        co_rej=np.empty((k, n), dtype=bool),
        next_wp=np.empty((k, n), dtype=i64),
        n_swarm=np.empty((k, n), dtype=i64),
        n_sats=np.empty((k, n), dtype=i64),
        centroid_uav=np.empty(k, dtype=i64),
        out_of_contact=np.empty((k, n), dtype=bool),
        terms=np.empty((k, 6, n)),
        in_goal=np.empty((k, n), dtype=bool),
        ends=np.empty((k, 2), dtype=bool),
        tan_max=np.empty((k, n, n_az)),
        walls=np.empty((k, n, n_az)),
        bad_geometry=np.zeros(k, dtype=bool),
    )


class ObservationSettings(NamedTuple):
    """The configuration of :func:`observations_infos`."""

    k_neigh: int  # neighbours observed
    low: np.ndarray  # (obs_dim,) the observation space's bounds
    high: np.ndarray  # (obs_dim,)


class ObservationInputs(NamedTuple):
    """The arrays of a step that :func:`observations_infos` reads (of :class:`Moved` and
    :class:`Navigated`, and the skyline)."""

    pos: np.ndarray  # (K, N, 3) true positions after the step
    vel: np.ndarray  # (K, N, 3)
    rel: np.ndarray  # (K, N, N, 3) measured relative positions (ENU)
    avail: np.ndarray  # (K, N, N) bool
    nav_pos: np.ndarray  # (K, N, 3) estimates
    nav_cov: np.ndarray  # (K, N, 3, 3)
    co_pos: np.ndarray  # (K, N, 3) cooperative estimates
    sa_pos: np.ndarray  # (K, N, 3) standalone estimates
    n_sats: np.ndarray  # (K, N) int64 satellites received
    n_swarm: np.ndarray  # (K, N) int64 satellites received by the swarm
    n_sv: np.ndarray  # (K,) int64 satellites above the mask
    next_wp: np.ndarray  # (K, N) int64 next waypoints after the step
    source: np.ndarray  # (K, N) int64 estimate sources
    walls: np.ndarray  # (K, N, A) wall distances
    sky_deg: np.ndarray  # (K, N, A) skyline elevations
    steps: np.ndarray  # (K,) steps of each episode so far
    obs_params: np.ndarray  # (K, 9) each copy's observation scales


class Observed(NamedTuple):
    """What :func:`observations_infos` writes."""

    obs: np.ndarray  # (K, N, obs_dim) float32
    floats: np.ndarray  # (K, 8, N) the infos' real numbers


@njit(cache=True, inline="always")
def _polygons_of(k, cities):
    """Copy ``k``'s extruded polygon buildings from ``cities``: whether it has them (else
    boxes), and its ``edges (n_e, 4), edge_start (n_p + 1,), heights (n_p,), bbox (n_p, 4)``
    as :mod:`coopnav_env.sim._polygon_kernels` takes them."""
    npb = cities.n_poly[k]
    return (
        cities.is_poly[k],
        np.ascontiguousarray(cities.edges[k, : cities.n_edge[k]]),
        np.ascontiguousarray(cities.edge_start[k, : npb + 1]),
        np.ascontiguousarray(cities.heights[k, :npb]),
        np.ascontiguousarray(cities.bbox[k, :npb]),
    )


@njit(cache=True, inline="always")
def _boxes_of(k, cities):
    """Copy ``k``'s box buildings ``lo, hi (n_b, 3)`` from ``cities``."""
    nb = cities.n_b[k]
    return (
        np.ascontiguousarray(cities.b_lo[k, :nb]),
        np.ascontiguousarray(cities.b_hi[k, :nb]),
    )


@njit(cache=True, inline="always")
def _next_copy(claims, s, front):
    """Claim the next copy of segment ``s`` of ``claims`` (:func:`copy_segments`): from its front
    (``front``) or its back; -1 when the segment has none left."""
    if front:
        k = claims[s, 0]
        if k >= claims[s, 1]:
            return -1
        claims[s, 0] = k + 1
        return k
    k = claims[s, 1] - 1
    if k < claims[s, 0]:
        return -1
    claims[s, 1] = k
    return k


@njit(cache=True, inline="always")
def _claim(claims, seg, cursor):
    """The next copy a kernel's call takes, or -1 when none is left.

    ``claims`` (int64, ``(S, 2)``) holds the segments of the copies still to do, each
    ``[next, end)`` (:func:`copy_segments`), shared with the threads that run the kernel
    beside this call and updated as copies are taken. ``seg >= 0``: the copies of segment
    ``seg``, from its front, in increasing order; ``seg = -1``: the copies left in every
    segment, from its back, the last segment first (``cursor[0]`` is the segment this call
    takes from: start it at the last).
    """
    if seg >= 0:
        return _next_copy(claims, seg, True)
    while cursor[0] >= 0:
        k = _next_copy(claims, cursor[0], False)
        if k >= 0:
            return k
        cursor[0] -= 1
    return -1


@njit(cache=True, inline="always")
def _motion_one(k, settings, cities, sky, inputs, out):
    pos0, vel0, cmd, z = inputs.pos0, inputs.vel0, inputs.cmd, inputs.z
    n = pos0.shape[1]
    motion = settings.motion
    lo, hi = _boxes_of(k, cities)
    is_poly, edges, edge_start, heights, bbox = _polygons_of(k, cities)
    if settings.moving:
        limits = (motion[0], motion[1], motion[2], motion[3], motion[4], motion[5], motion[6])
        p1, v1, h, s = _sim_kernels.world_motion(
            pos0[k], vel0[k], cmd[k], limits, (cities.fence_lo[k], cities.fence_hi[k]), (lo, hi)
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
    out.pos[k] = p1
    out.vel[k] = v1
    out.hit[k] = h
    out.sep[k] = s
    row = sky.row[k]
    ns = sky.n_sv[k]
    nu = sky.n_up[k]
    up = np.ascontiguousarray(sky.up[row, :ns])
    order = np.ascontiguousarray(sky.order[row, :nu])
    cot = np.ascontiguousarray(sky.cot[row, :nu])
    hdir = np.ascontiguousarray(sky.hdir[row, :nu])
    if is_poly:
        vis = _poly_kernels.line_of_sight(
            p1, edges, edge_start, heights, bbox, up, order, cot, hdir
        )
    else:
        vis = _sim_kernels.line_of_sight(p1, lo, hi, up, order, cot, hdir)
    off = sky.los_off[k]
    for i in range(n):
        c = 0
        for j in range(ns):
            out.los_flat[off + i * ns + j] = vis[i, j]
            if vis[i, j]:
                c += 1
        out.n_rx[k, i] = c
    # the draws of the epoch: pseudoranges (S + N S), then relative sensing (N (N - 1) / 2, 3)
    m = n * (n - 1) // 2
    start = ns + n * ns
    zr = np.empty((m, 3))
    for p in range(m):
        for c in range(3):
            zr[p, c] = z[k, start + 3 * p + c]
    sensing = settings.sensing
    r, v, a = _sim_kernels.relative_measurements(p1, zr, sensing[0], sensing[1], sensing[2])
    out.rel[k] = r
    out.var[k] = v
    out.avail[k] = a


@njit(cache=True, nogil=True)
def motion_sight_relative(claims, seg, settings, cities, sky, inputs, out):
    """Motion, line of sight and relative sensing of the copies that
    ``claims`` gives this call (see the module docstring), written into ``out``.

    Each record may come as a plain tuple of its fields (as ``_fused.FusedStep`` passes it).

    Parameters
    ----------
    claims : ndarray of int64, shape (S, 2)
    seg : int
        The copies this call takes, shared with the threads that run it beside this call
        (:func:`_claim`).
    settings : MotionSettings
    cities : Cities
    sky : SkyRows
    inputs : MotionInputs
        The swarms before the step, their commands and the epoch's draws.
    out : Moved
        The arrays written.
    """
    settings, cities, sky = MotionSettings(*settings), Cities(*cities), SkyRows(*sky)
    inputs, out = MotionInputs(*inputs), Moved(*out)
    cursor = np.full(1, claims.shape[0] - 1)
    k = _claim(claims, seg, cursor)
    while k >= 0:
        _motion_one(k, settings, cities, sky, inputs, out)
        k = _claim(claims, seg, cursor)


@njit(cache=True, inline="always")
def _navigate_one(k, settings, cities, routes, sky, moved, inputs, out):
    n = inputs.rx_ecef.shape[1]
    z = inputs.z
    row = sky.row[k]
    ns = sky.n_sv[k]
    sv = np.ascontiguousarray(sky.sv[row, :ns])
    system = np.ascontiguousarray(sky.system[row, :ns])
    off = sky.los_off[k]
    n_sats = out.n_sats
    received = np.empty((n, ns), dtype=np.bool_)
    for i in range(n):
        c = 0
        for j in range(ns):
            received[i, j] = moved.los_flat[off + i * ns + j]
            if received[i, j]:
                c += 1
        n_sats[k, i] = c
    wgs = settings.wgs
    range_m, _az, el_deg, at_centre, zero_range = _gnss_kernels.range_azimuth_elevation(
        inputs.rx_ecef[k], sv, wgs[0], wgs[1], wgs[2], wgs[3], wgs[4], settings.n_bowring, False
    )
    if at_centre or zero_range:
        out.bad_geometry[k] = True
        return
    z_common = np.empty(ns)
    z_user = np.empty((n, ns))
    for j in range(ns):
        z_common[j] = z[k, j]
    for i in range(n):
        for j in range(ns):
            z_user[i, j] = z[k, ns + i * ns + j]
    av = moved.avail[k]
    x0 = inputs.x0
    if settings.shared:  # one centroid: the UAV receiving the most satellites (the first of equals)
        a = 0
        for i in range(1, n):
            if n_sats[k, i] > n_sats[k, a]:
                a = i
        linked = av[a].copy()
        linked[a] = True
        rel_b = np.empty((1, n, 3))
        var_b = np.empty((1, n))
        avail_b = np.empty((1, n), dtype=np.bool_)
        rel_b[0] = inputs.rel_ecef[k, 0]  # the centroid row only
        var_b[0] = moved.var[k, a]
        avail_b[0] = av[a]
        cen = np.array([a], dtype=np.int64)
        x0_co = np.empty((1, 3))
        x0_co[0] = x0[k, a]
        out.centroid_uav[k] = a
    else:  # every UAV its own centroid; one out of range of every other navigates standalone
        linked = np.empty(n, dtype=np.bool_)
        for i in range(n):
            any_link = False
            for p in range(n):
                any_link = any_link or av[i, p]
            linked[i] = any_link or n == 1
        rel_b = inputs.rel_ecef[k]
        var_b = moved.var[k]
        avail_b = av
        cen = np.arange(n).astype(np.int64)
        x0_co = x0[k]
        out.centroid_uav[k] = -1
    nr = routes.n_route[k]
    r_k = np.ascontiguousarray(routes.route[k, :nr])
    t_k = np.ascontiguousarray(routes.tail[k, :nr])
    model, radius, gate = settings.model, settings.radius, settings.gate
    s_status, s_iter, c_iter, sel, wp, nsw, _used = _sim_kernels.epoch_navigation(
        _sim_kernels.Geometry(range_m, el_deg, sv, system, received),
        _sim_kernels.Pseudoranges(
            inputs.clock[k],
            settings.iono,
            z_common,
            z_user,
            np.zeros((n, ns)),
            np.full(ns, np.nan),
            model[0],
            model[1] != 0.0,
            model[2] != 0.0,
            settings.n_sys,
        ),
        _sim_kernels.Centroids(rel_b, var_b, avail_b, cen, x0_co, settings.ddt, linked, av),
        _sim_kernels.Solving(
            settings.max_iter,
            1e-4,
            radius[0] != 0.0,
            radius[1],
            radius[2],
            gate[0] != 0.0,
            gate[1],
        ),
        _sim_kernels.Prior(
            x0[k],
            settings.origin,
            settings.rot,
            inputs.pred[k],
            inputs.prev_cov[k],
            settings.dr_var,
        ),
        _sim_kernels.Waypoints(r_k, inputs.next_wp[k], settings.reach_m),
    )
    out.sa_status[k] = s_status
    out.n_iter[k, 0] = s_iter
    out.n_iter[k, 1] = c_iter
    out.sa_pos[k] = sel[0]
    out.sa_cov[k] = sel[1]
    out.co_pos[k] = sel[2]
    out.co_cov[k] = sel[3]
    out.co_status[k] = sel[4]
    out.source[k] = sel[5]
    out.nav_pos[k] = sel[6]
    out.nav_cov[k] = sel[7]
    out.sa_rej[k] = sel[8]
    out.co_rej[k] = sel[9]
    out.next_wp[k] = wp
    out.n_swarm[k] = nsw
    for i in range(n):
        lonely = True
        for p in range(n):
            lonely = lonely and not av[i, p]
        out.out_of_contact[k, i] = lonely and n > 1
    pos1 = moved.pos
    events = _env_kernels.StepEvents(moved.hit[k], moved.sep[k], out.out_of_contact[k])
    if settings.reward_mode == 2:  # navigated distance: nav and progress come from the route after
        t, g, crash, reached = _env_kernels.event_reward_terms(
            pos1[k], routes.goal[k], events, settings.reward_params
        )
    else:
        xy_prev = np.empty((n, 2))
        for i in range(n):
            xy_prev[i, 0] = inputs.pos0[k, i, 0]
            xy_prev[i, 1] = inputs.pos0[k, i, 1]
        t, g, crash, reached = _env_kernels.reward_terms(
            _env_kernels.RouteAhead(r_k, t_k, inputs.next_wp[k]),
            _env_kernels.StepPositions(xy_prev, pos1[k], routes.goal[k], sel[6], sel[7]),
            events,
            settings.reward_mode == 1,
            settings.reward_params,
        )
    out.terms[k] = t
    out.in_goal[k] = g
    out.ends[k, 0] = crash
    out.ends[k, 1] = reached
    if cities.is_poly[k]:  # (a box city's copy makes no polygon arrays)
        _p, edges, edge_start, heights, bbox = _polygons_of(k, cities)
        tm, w = _poly_kernels.sky_and_walls(
            pos1[k], settings.rays, edges, edge_start, heights, bbox
        )
    else:
        lo, hi = _boxes_of(k, cities)
        tm, w = _sim_kernels.sky_and_walls(pos1[k], settings.rays, lo, hi)
    out.tan_max[k] = tm
    out.walls[k] = w


@njit(cache=True, nogil=True)
def navigation_reward_sensors(claims, seg, settings, cities, routes, sky, moved, inputs, out):
    """Navigation, reward terms and skyline / wall sensors of the copies that
    ``claims`` gives this call (module docstring), written into ``out``.

    Each record may come as a plain tuple of its fields (as ``_fused.FusedStep`` passes it).

    Parameters
    ----------
    claims : ndarray of int64, shape (S, 2)
    seg : int
        The copies this call takes, shared with the threads that run it beside this call
        (:func:`_claim`).
    settings : NavigationSettings
    cities : Cities
    routes : Routes
    sky : SkyRows
    moved : Moved
        The swarms after :func:`motion_sight_relative`.
    inputs : NavigationInputs
        The arrays of the step besides the motion, the epoch's draws among them.
    out : Navigated
        The arrays written.
    """
    settings, cities, routes = NavigationSettings(*settings), Cities(*cities), Routes(*routes)
    sky, moved, inputs = SkyRows(*sky), Moved(*moved), NavigationInputs(*inputs)
    out = Navigated(*out)
    cursor = np.full(1, claims.shape[0] - 1)
    k = _claim(claims, seg, cursor)
    while k >= 0:
        _navigate_one(k, settings, cities, routes, sky, moved, inputs, out)
        k = _claim(claims, seg, cursor)


@njit(cache=True, inline="always")
def _observe_one(k, settings, routes, inputs, out):
    nr = routes.n_route[k]
    out.obs[k] = _env_kernels.observation_rows(
        _env_kernels.EpochFigures(
            inputs.nav_pos[k],
            routes.goal[k],
            inputs.vel[k],
            inputs.nav_cov[k],
            inputs.n_sats[k],
            inputs.n_swarm[k],
            max(inputs.n_sv[k], 1),
            inputs.rel[k],
            inputs.avail[k],
            inputs.source[k],
            inputs.steps[k],
        ),
        _env_kernels.Sensors(inputs.sky_deg[k], inputs.walls[k]),
        _env_kernels.RouteAhead(
            np.ascontiguousarray(routes.route[k, :nr]),
            np.ascontiguousarray(routes.tail[k, :nr]),
            inputs.next_wp[k],
        ),
        _env_kernels.ObservationScales(
            inputs.obs_params[k], settings.k_neigh, settings.low, settings.high
        ),
    )
    out.floats[k] = _env_kernels.info_floats(
        inputs.pos[k],
        inputs.nav_pos[k],
        inputs.co_pos[k],
        inputs.sa_pos[k],
        inputs.nav_cov[k],
        routes.goal[k],
    )


@njit(cache=True, nogil=True)
def observations_infos(claims, seg, settings, routes, inputs, out):
    """Observations and the infos' real numbers of the copies that ``claims``
    gives this call, written into ``out``.

    Each record may come as a plain tuple of its fields (as ``_fused.FusedStep`` passes it).

    Parameters
    ----------
    claims : ndarray of int64, shape (S, 2)
    seg : int
        The copies this call takes, shared with the threads that run it beside this call
        (:func:`_claim`).
    settings : ObservationSettings
    routes : Routes
    inputs : ObservationInputs
    out : Observed
        The arrays written.
    """
    settings, routes = ObservationSettings(*settings), Routes(*routes)
    inputs, out = ObservationInputs(*inputs), Observed(*out)
    cursor = np.full(1, claims.shape[0] - 1)
    k = _claim(claims, seg, cursor)
    while k >= 0:
        _observe_one(k, settings, routes, inputs, out)
        k = _claim(claims, seg, cursor)


class DistanceInputs(NamedTuple):
    """The arrays of a step that :func:`navigated_distance_terms` reads besides the routes."""

    pos: np.ndarray  # (K, N, 3) true positions after the step [m]
    nav_pos: np.ndarray  # (K, N, 3) estimates after the step [m] (NaN: none)
    next_wp: np.ndarray  # (K, N) int64 next waypoints after the step
    reached: np.ndarray  # (K,) bool the swarm arrived this step
    unpaid: np.ndarray  # (K, N) route not yet paid before the step [m]
    route_len: np.ndarray  # (K, N) route length at reset [m] (> 0)


class Paid(NamedTuple):
    """What :func:`navigated_distance_terms` writes."""

    terms: np.ndarray  # (K, 6, N) reward terms: rows 0 (nav) and 1 (progress) written
    unpaid_after: np.ndarray  # (K, N) route not yet paid after the step [m]


@njit(cache=True, nogil=True)
def navigated_distance_terms(routes, inputs, cap_m, out):
    """The terms ``nav`` and ``progress`` of ``reward_scheme="navigated_distance"`` of every
    copy (:func:`coopnav_env.envs.task.navigated_distance`), with the float64 operations of
    its numpy formulation in the same order (the oracle ``navigated_distance_rows`` of
    ``tests/envs/oracles.py``, equal bit for bit): the remaining route is the distance to the
    next waypoint plus the route after it; ``np.clip(x, 0, None)`` is ``np.maximum(x, 0)``;
    ``np.fmin`` takes the cap where the error is not a number.

    Takes the records :class:`Routes` (its ``route`` and ``tail``), :class:`DistanceInputs`
    and :class:`Paid` (written; each may come as a plain tuple of its fields) and ``cap_m``
    (``nav_reward_cap_m``)."""
    route, tail, _n_route, _goal = routes
    pos, nav_pos, wp, reached, unpaid, route_len = inputs
    terms, unpaid_after = out
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


@njit(cache=True, nogil=True)
def episode_ends(pos, goal, hit, goal_r):
    """Whether each copy's episode ends by its events after a motion step, ``(K, 2)`` bool:
    a UAV collided (column 0) or the swarm reached the goal (column 1), from the true
    positions ``pos (K, N, 3)``, goals ``(K, 3)``, collisions ``hit (K, N)`` and the goal
    radius ``goal_r``: the ``ends`` that :func:`navigation_reward_sensors` computes for
    them (the same function on the same arrays), known before it runs."""
    ends = np.zeros((pos.shape[0], 2), dtype=np.bool_)
    for k in range(pos.shape[0]):
        _in_goal, crash, reached = _env_kernels._goal_events(pos[k], goal[k], hit[k], goal_r)
        ends[k, 0] = crash
        ends[k, 1] = reached
    return ends
