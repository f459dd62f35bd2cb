"""Behaviour descriptors: what a swarm does during the cruise of one episode.

``coopnav evaluate`` reports them beside the score (:mod:`coopnav_env.training.evaluate`), so
that a reader sees *what* a policy learned, not only how well it scores:

* :func:`cruise_spacing_m`: how far apart the UAVs fly (the distance of a UAV to its nearest
  neighbour);
* :func:`cruise_behaviour`: that spacing with the altitude, the swarm's extent across its
  street route and the horizontal speed;
* :func:`cross_track_m`: the signed distance of points from a route polyline, which the
  extent across the route is measured with.

All of them take the true positions of one episode (``EpisodeRecord.pos_enu_m``) over its
cruise, the middle of the episode (:data:`CRUISE`), which leaves out the start lattice and
the closing at the goal.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["BEHAVIOUR_KEYS", "CRUISE", "cross_track_m", "cruise_behaviour", "cruise_spacing_m"]

CRUISE: tuple[float, float] = (0.2, 0.8)
"""The share of an episode's steps that counts as the cruise (start and end left out)."""

BEHAVIOUR_KEYS: tuple[str, ...] = ("spacing_m", "altitude_m", "lateral_spread_m", "speed_mps")
"""The keys of :func:`cruise_behaviour`'s result, in the order reports show them."""


def _cruise_steps(n_positions: int, cruise: tuple[float, float]) -> tuple[int, int]:
    """First and last position index (both included) of the cruise of ``n_positions``
    positions (the reset and ``n_positions - 1`` steps)."""
    lo_share, hi_share = cruise
    if not 0.0 <= lo_share <= hi_share <= 1.0:
        raise ValueError(f"cruise must be two shares 0 <= first <= last <= 1, got {cruise}")
    t0, t1 = (round(f * (n_positions - 1)) for f in cruise)
    return max(t0, 1), max(t1, t0 + 1)


def cruise_spacing_m(pos_enu_m: np.ndarray | None, cruise: tuple[float, float] = CRUISE) -> float:
    """Mean distance of a UAV to its nearest neighbour during the cruise of one episode [m].

    Parameters
    ----------
    pos_enu_m : ndarray, shape (T + 1, N, 3), or None
        True positions from the reset on (``EpisodeRecord.pos_enu_m``).
    cruise : (float, float)
        The first and last share of the steps that count (:data:`CRUISE`): the positions
        from step ``round(cruise[0] T)`` (at least 1) to step ``round(cruise[1] T)`` (at least
        the one after the first), both included.

    Returns
    -------
    float
        The mean over those steps and over UAVs of the distance to the nearest other UAV
        (crashed UAVs keep their last position); NaN without positions or with one UAV.
    """
    if pos_enu_m is None:
        return math.nan
    pos = np.asarray(pos_enu_m, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise ValueError(f"pos_enu_m must have shape (T + 1, N, 3), got {pos.shape}")
    if pos.shape[1] < 2 or pos.shape[0] < 2:
        return math.nan
    lo, hi = _cruise_steps(len(pos), cruise)
    part = pos[lo : hi + 1]
    d = np.linalg.norm(part[:, :, None, :] - part[:, None, :, :], axis=-1)
    n = d.shape[1]
    d[:, np.arange(n), np.arange(n)] = np.inf
    return float(d.min(axis=2).mean())


def cross_track_m(xy_m: np.ndarray, route_xy_m: np.ndarray) -> np.ndarray:
    """Signed horizontal distance of points from a route polyline [m].

    Parameters
    ----------
    xy_m : ndarray, shape (..., 2)
        Points (East, North) [m].
    route_xy_m : ndarray, shape (K, 2)
        The route's points in order, ``K >= 2`` [m].

    Returns
    -------
    ndarray, shape (...)
        The distance to the nearest point of the route, positive left of the route's
        direction of travel at that point, negative right of it.
    """
    pts = np.asarray(xy_m, dtype=float)
    route = np.asarray(route_xy_m, dtype=float)
    if route.ndim != 2 or route.shape[1] != 2 or route.shape[0] < 2:
        raise ValueError(f"route_xy_m must have shape (K >= 2, 2), got {route.shape}")
    if pts.shape[-1] != 2:
        raise ValueError(f"xy_m must have shape (..., 2), got {pts.shape}")
    a, seg = route[:-1], np.diff(route, axis=0)  # (S, 2)
    length2 = np.maximum((seg**2).sum(axis=1), 1e-12)
    rel = pts[..., None, :] - a  # (..., S, 2)
    t = np.clip((rel * seg).sum(axis=-1) / length2, 0.0, 1.0)
    foot = a + t[..., None] * seg
    d = np.linalg.norm(pts[..., None, :] - foot, axis=-1)  # (..., S)
    k = np.argmin(d, axis=-1)
    nearest = np.take_along_axis(d, k[..., None], axis=-1)[..., 0]
    s = seg[k]
    r = np.take_along_axis(rel, k[..., None, None], axis=-2)[..., 0, :]
    side = np.sign(s[..., 0] * r[..., 1] - s[..., 1] * r[..., 0])
    return np.where(side < 0, -nearest, nearest)


def cruise_behaviour(
    pos_enu_m: np.ndarray | None,
    route_xy_m: np.ndarray | None,
    dt_s: float,
    cruise: tuple[float, float] = CRUISE,
) -> dict[str, float]:
    """Spacing, altitude, spread across the route and speed of a swarm in its cruise.

    Parameters
    ----------
    pos_enu_m : ndarray, shape (T + 1, N, 3), or None
        True positions from the reset on (``EpisodeRecord.pos_enu_m``).
    route_xy_m : ndarray, shape (K, 2), or None
        The episode's street route (the environment's ``world.route_xy_m``); None where the
        environment has none (the spread is then NaN).
    dt_s : float
        Step length [s], > 0; NaN where unknown (the speed is then NaN).
    cruise : (float, float)
        The share of the steps that counts, as :func:`cruise_spacing_m` takes it.

    Returns
    -------
    dict
        ``spacing_m``: mean distance of a UAV to its nearest neighbour
        (:func:`cruise_spacing_m`); ``altitude_m``: mean altitude (Up); ``lateral_spread_m``:
        mean over steps of the swarm's extent across the route (largest minus smallest
        :func:`cross_track_m`): 0 for a column in line on the route, the street's width for a
        swarm spread across it; ``speed_mps``: mean horizontal speed of a UAV between steps
        (a crashed UAV, standing still, counts at 0). NaN without positions or with fewer
        than two of them (and spacing and spread with one UAV).
    """
    out = dict.fromkeys(BEHAVIOUR_KEYS, math.nan)
    if not (dt_s > 0.0 or math.isnan(dt_s)):
        raise ValueError(f"dt_s must be > 0 seconds (or NaN: unknown), got {dt_s}")
    if pos_enu_m is None:
        return out
    pos = np.asarray(pos_enu_m, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise ValueError(f"pos_enu_m must have shape (T + 1, N, 3), got {pos.shape}")
    if pos.shape[0] < 2:
        return out
    lo, hi = _cruise_steps(len(pos), cruise)
    part = pos[lo : hi + 1]
    out["spacing_m"] = cruise_spacing_m(pos, cruise)
    out["altitude_m"] = float(part[:, :, 2].mean())
    if pos.shape[1] > 1 and route_xy_m is not None:
        off = cross_track_m(part[:, :, :2], route_xy_m)
        out["lateral_spread_m"] = float((off.max(axis=1) - off.min(axis=1)).mean())
    steps = pos[lo - 1 : hi + 1, :, :2]
    out["speed_mps"] = float(np.linalg.norm(np.diff(steps, axis=0), axis=-1).mean() / dt_s)
    return out
