"""Compiled (numba) observation builder and reward terms of the task (:mod:`coopnav_env.envs.task`).

:func:`observation_rows` writes every agent's observation vector in one pass, with the same
float64 operations in the same order as the numpy formulation (the test oracle
``observation_rows`` of ``tests/envs/oracles.py``), then clips and rounds to float32 as it
does, so the two agree bit for bit (the tests compare them). The numpy version spends its time
in the overhead of some thirty small array operations per step. The reward terms, info figures
and satellite sectors below have their oracles there too.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _clip32(x, lo, hi):
    """``numpy.clip`` (NaN propagates) to float64 bounds, then the float32 rounding."""
    if x != x:
        return np.float32(x)
    x = x if x > lo else lo  # numpy's clip: max then min, a signed zero at a bound -> bound
    x = x if x < hi else hi
    return np.float32(x)


class EpochFigures(NamedTuple):
    """What the observation reads of a swarm's epoch (:func:`observation_rows`)."""

    nav_pos: np.ndarray  # (n, 3) estimated ENU position
    goal: np.ndarray  # (3,)
    vel: np.ndarray  # (n, 3)
    nav_cov: np.ndarray  # (n, 3, 3) covariance of the estimate (sigma: sqrt of the diagonal)
    n_sats: np.ndarray  # (n,) int
    n_swarm: np.ndarray  # (n,) int
    n_open: int  # satellites above the cut-off (>= 1)
    rel: np.ndarray  # (n, n, 3) measured relative positions
    avail: np.ndarray  # (n, n) bool
    nav_source: np.ndarray  # (n,) int
    steps: int  # steps of the episode so far


class Sensors(NamedTuple):
    """The horizontal-ray sensors at the true positions (:func:`observation_rows`)."""

    sky_deg: np.ndarray  # (n, A) skyline elevation [deg]
    walls: np.ndarray  # (n, A) wall distances [m]


class RouteAhead(NamedTuple):
    """The route and each UAV's next waypoint (:func:`observation_rows`; for
    :func:`reward_terms` the waypoint that was next at the previous step)."""

    route: np.ndarray  # (k, 2) waypoints
    tail: np.ndarray  # (k,) route length after each waypoint
    wp: np.ndarray  # (n,) next waypoint


class ObservationScales(NamedTuple):
    """The observation's scales and bounds (:func:`observation_rows`)."""

    params: np.ndarray  # (9,) city scale, max speed, sigma max, sensing range, max steps,
    #                     route scale, altitude min, altitude max, wall scale
    k_neigh: int  # neighbour slots
    low: np.ndarray  # (obs_dim,) float64 bounds
    high: np.ndarray


@njit(cache=True)
def observation_rows(epoch, sensors, route_ahead, scales):
    """Every agent's observation vector, ``(n, obs_dim)`` float32, from the records
    :class:`EpochFigures`, :class:`Sensors`, :class:`RouteAhead` and
    :class:`ObservationScales` (each may come as a plain tuple of its fields)."""
    nav_pos, goal, vel, nav_cov, n_sats, n_swarm, n_open, rel, avail, nav_source, steps = epoch
    sky_deg, walls = sensors
    route, tail, wp = route_ahead
    params, k_neigh, low, high = scales
    n = nav_pos.shape[0]
    n_az = sky_deg.shape[1]
    big, max_speed, sigma_max, max_range = params[0], params[1], params[2], params[3]
    max_steps, route_scale, alt_min, alt_max = params[4], params[5], params[6], params[7]
    wall_scale = params[8]
    dim = low.shape[0]
    out = np.empty((n, dim), dtype=np.float32)
    row = np.empty(dim)
    m = min(k_neigh, n)
    last = route.shape[0] - 1
    taken = np.zeros(n, dtype=np.bool_)
    dist = np.empty(n)
    for i in range(n):
        c = 0
        for j in range(3):
            row[c] = (nav_pos[i, j] - goal[j]) / big
            c += 1
        for j in range(3):
            row[c] = vel[i, j] / max_speed
            c += 1
        for j in range(3):  # Epoch.nav_sigma_enu_m: sqrt(clip(diagonal, 0, None))
            v = nav_cov[i, j, j]
            v = v if (v > 0.0 or v != v) else 0.0
            row[c] = np.sqrt(v) / sigma_max
            c += 1
        row[c] = n_sats[i] / n_open
        row[c + 1] = n_swarm[i] / n_open
        c += 2
        for a in range(n_az):
            row[c] = sky_deg[i, a] / 90.0
            c += 1
        # neighbour slots: the m nearest measured neighbours (stable order), zeros after
        for q in range(n):
            taken[q] = False
            if avail[i, q]:
                dist[q] = np.sqrt(
                    rel[i, q, 0] * rel[i, q, 0]
                    + rel[i, q, 1] * rel[i, q, 1]
                    + rel[i, q, 2] * rel[i, q, 2]
                )
            else:
                dist[q] = np.inf
        for s in range(k_neigh):
            if s < m:
                best = -1
                for q in range(n):
                    if taken[q]:
                        continue
                    if best < 0 or dist[q] < dist[best]:
                        best = q
                taken[best] = True
                if avail[i, best]:
                    for j in range(3):
                        row[c + j] = rel[i, best, j] / max_range
                    row[c + 3] = 1.0
                else:
                    for j in range(4):
                        row[c + j] = 0.0
            else:
                for j in range(4):
                    row[c + j] = 0.0
            c += 4
        row[c] = 1.0 if nav_source[i] == 0 else 0.0
        row[c + 1] = 1.0 if nav_source[i] != 2 else 0.0
        row[c + 2] = 1.0 - steps / max_steps
        c += 3
        w = wp[i]
        w1 = min(w + 1, last)
        dx = route[w, 0] - nav_pos[i, 0]
        dy = route[w, 1] - nav_pos[i, 1]
        row[c] = dx / route_scale
        row[c + 1] = dy / route_scale
        row[c + 2] = (route[w1, 0] - route[w, 0]) / route_scale
        row[c + 3] = (route[w1, 1] - route[w, 1]) / route_scale
        c += 4
        ex = nav_pos[i, 0] - route[w, 0]
        ey = nav_pos[i, 1] - route[w, 1]
        remaining = np.sqrt(ex * ex + ey * ey) + tail[w]
        row[c] = remaining / (2.0 * big)
        row[c + 1] = (nav_pos[i, 2] - alt_min) / (alt_max - alt_min)
        c += 2
        for a in range(n_az):
            v = walls[i, a] / wall_scale
            row[c] = v if v < 1.0 or v != v else 1.0
            c += 1
        for j in range(dim):
            out[i, j] = _clip32(row[j], low[j], high[j])
    return out


@njit(cache=True, inline="always")
def _goal_events(pos, goal, collided, goal_r):
    """The in-goal flags (n,) (horizontal distance to the goal <= ``goal_r``), whether a UAV
    collided, and whether the swarm reached the goal (every UAV in it, none collided)."""
    n = pos.shape[0]
    in_goal = np.empty(n, dtype=np.bool_)
    crash = False
    all_in = True
    for i in range(n):
        dx = pos[i, 0] - goal[0]
        dy = pos[i, 1] - goal[1]
        in_goal[i] = np.hypot(dx, dy) <= goal_r
        all_in = all_in and in_goal[i]
        crash = crash or collided[i]
    return in_goal, crash, all_in and not crash


@njit(cache=True, inline="always")
def _event_terms(terms, collided, separation, out_of_contact, reached, params):
    """Rows 2..5 of ``terms`` (collision, separation, contact, goal) for each UAV."""
    pen_col, pen_sep, pen_con, goal_bonus = params[5], params[6], params[7], params[9]
    for i in range(terms.shape[1]):
        terms[2, i] = -pen_col * (1.0 if collided[i] else 0.0)
        terms[3, i] = -pen_sep * (1.0 if separation[i] else 0.0)
        terms[4, i] = -pen_con * (1.0 if out_of_contact[i] else 0.0)
        terms[5, i] = goal_bonus if reached else 0.0


class StepPositions(NamedTuple):
    """Where the swarm was, is and estimates it is, over a step (:func:`reward_terms`)."""

    xy_prev: np.ndarray  # (n, 2) true positions before the step
    pos: np.ndarray  # (n, 3) true positions after it
    goal: np.ndarray  # (3,)
    nav_pos: np.ndarray  # (n, 3) estimate used
    nav_cov: np.ndarray  # (n, 3, 3) its covariance


class StepEvents(NamedTuple):
    """The step's events of each UAV (:func:`reward_terms`, :func:`event_reward_terms`)."""

    collided: np.ndarray  # (n,) bool
    separation: np.ndarray  # (n,) bool closer than the minimum separation to another UAV
    out_of_contact: np.ndarray  # (n,) bool no relative link


@njit(cache=True)
def reward_terms(route_ahead, positions, events, sigma_reward, params):
    """The per-step reward terms (``reward_scheme="per_step"``; its numpy formulation is
    ``reward_terms`` of ``tests/envs/oracles.py``), in the order of ``REWARD_TERMS``, shape
    (6, n); the in-goal flags (n,); whether a UAV collided; whether the swarm reached the
    goal.

    Takes the records :class:`RouteAhead` (with the waypoints that were next at the previous
    step), :class:`StepPositions` and :class:`StepEvents` (each may come as a plain tuple of
    its fields), ``sigma_reward`` (bool: the nav term from the predicted sigma, else from the
    true error) and ``params`` (10,) float (see ``coopnav_env.envs.task.reward_params``)."""
    route, tail, wp_prev = route_ahead
    xy_prev, pos, goal, nav_pos, nav_cov = positions
    collided, separation, out_of_contact = events
    n = pos.shape[0]
    w_nav, cap, scale, w_prog, step_len = params[0], params[1], params[2], params[3], params[4]
    terms = np.empty((6, n))
    in_goal, crash, reached = _goal_events(pos, goal, collided, params[8])
    for i in range(n):
        w = wp_prev[i]
        ax = xy_prev[i, 0] - route[w, 0]
        ay = xy_prev[i, 1] - route[w, 1]
        d_prev = np.sqrt(ax * ax + ay * ay) + tail[w]
        bx = pos[i, 0] - route[w, 0]
        by = pos[i, 1] - route[w, 1]
        d_now = np.sqrt(bx * bx + by * by) + tail[w]
        if sigma_reward:
            tr = nav_cov[i, 0, 0] + nav_cov[i, 1, 1] + nav_cov[i, 2, 2]
            if not (tr > 0.0 or tr != tr):
                tr = 0.0
            nav_m = np.sqrt(tr)
        else:
            e0 = nav_pos[i, 0] - pos[i, 0]
            e1 = nav_pos[i, 1] - pos[i, 1]
            e2 = nav_pos[i, 2] - pos[i, 2]
            nav_m = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        capped = nav_m if (nav_m < cap or nav_m != nav_m) else cap  # numpy.minimum
        terms[0, i] = -w_nav * capped / scale
        terms[1, i] = w_prog * (d_prev - d_now) / step_len
    _event_terms(terms, collided, separation, out_of_contact, reached, params)
    return terms, in_goal, crash, reached


@njit(cache=True)
def event_reward_terms(pos, goal, events, params):
    """The reward terms of the step's events (collision, separation, contact, goal) alone, in
    the order of ``REWARD_TERMS``, shape (6, n), with the rows ``nav`` and ``progress`` zero
    (``reward_scheme="navigated_distance"`` computes those from the route); the in-goal flags
    (n,); whether a UAV collided; whether the swarm reached the goal. Rows 2..5 and the flags
    are those of :func:`reward_terms`, bit for bit.

    Takes the true positions after the step ``pos`` (n, 3), the ``goal`` (3,), the record
    :class:`StepEvents` (or a plain tuple of its fields) and ``params`` (10,) float (see
    ``coopnav_env.envs.task.reward_params``)."""
    collided, separation, out_of_contact = events
    terms = np.zeros((6, pos.shape[0]))
    in_goal, crash, reached = _goal_events(pos, goal, collided, params[8])
    _event_terms(terms, collided, separation, out_of_contact, reached, params)
    return terms, in_goal, crash, reached


@njit(cache=True)
def info_floats(
    pos,  # (n, 3) true positions
    nav_pos,  # (n, 3) estimate used
    coop_pos,  # (n, 3) cooperative fix (NaN: none)
    sa_pos,  # (n, 3) standalone fix (NaN: none)
    nav_cov,  # (n, 3, 3) covariance of the estimate used
    goal,  # (3,)
):
    """The per-agent real numbers of ``UrbanCanyonEnv._infos`` (its numpy formulation is
    ``info_floats`` of ``tests/envs/oracles.py``), with the same float64 operations,
    ``(8, n)``: errors of the estimate used, the cooperative and the standalone fix (inf: no
    fix), sigma E/N/U and 3-D, goal distance."""
    n = pos.shape[0]
    floats = np.empty((8, n))
    for i in range(n):
        for r in range(3):
            src = nav_pos if r == 0 else (coop_pos if r == 1 else sa_pos)
            d0 = src[i, 0] - pos[i, 0]
            d1 = src[i, 1] - pos[i, 1]
            d2 = src[i, 2] - pos[i, 2]
            e = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)  # numpy.linalg.norm of three terms
            floats[r, i] = e if (r == 0 or np.isfinite(e)) else np.inf
        acc = 0.0
        for a in range(3):
            v = nav_cov[i, a, a]
            v = v if (v > 0.0 or v != v) else 0.0  # numpy.maximum(v, 0.0)
            s = np.sqrt(v)
            floats[3 + a, i] = s
            acc = acc + s * s if a else s * s
        floats[6, i] = np.sqrt(acc)
        floats[7, i] = np.hypot(pos[i, 0] - goal[0], pos[i, 1] - goal[1])
    return floats


@njit(cache=True)
def satellite_sectors(tracked, az_deg, n_az):
    """The ``obs_satellite_sectors`` columns (the numpy formulation is ``satellite_sectors``
    of ``tests/envs/oracles.py``), ``(n, 2 n_az)`` float32: per sector of the
    skyline azimuths ``360 a / n_az`` (the sector centred on each, ``floor(az n_az / 360 +
    0.5) mod n_az``), the satellites tracked, then those above the cut-off not tracked, each
    count / 4 clipped to [0, 1]. ``tracked`` is ``(n, S)`` bool, ``az_deg`` ``(S,)``."""
    n, n_sv = tracked.shape
    sector = np.empty(n_sv, dtype=np.int64)
    for j in range(n_sv):
        sector[j] = np.int64(np.floor(az_deg[j] * (n_az / 360.0) + 0.5)) % n_az
    counts = np.zeros((n, 2 * n_az))
    for i in range(n):
        for j in range(n_sv):
            col = sector[j] if tracked[i, j] else n_az + sector[j]
            counts[i, col] += 1.0
    out = np.empty((n, 2 * n_az), dtype=np.float32)
    for i in range(n):
        for c in range(2 * n_az):
            v = counts[i, c] / 4.0
            out[i, c] = np.float32(v if v < 1.0 else 1.0)
    return out
