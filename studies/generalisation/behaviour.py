"""Behaviour descriptors: what a swarm does during the cruise of one episode.

:func:`cruise_behaviour` describes one episode's true positions by four numbers over its
cruise (the middle of the episode, :data:`coopnav_env.training.evaluate.CRUISE`): how far
apart the UAVs fly (distance to the nearest UAV, as ``coopnav evaluate``'s cruise spacing),
how high, how far they spread across their street route, and how fast they fly.
:func:`cross_track_m` gives the signed distance of points from a route polyline that the
spread is measured with. Nothing here flies episodes yet: the descriptors take the
positions of ``coopnav_env.training.evaluate.run_episode``'s record and the environment's
route of that episode.
"""

from __future__ import annotations

import math

import numpy as np

from coopnav_env.training.evaluate import CRUISE, cruise_spacing_m

__all__ = ["cross_track_m", "cruise_behaviour"]


def cross_track_m(xy_m: np.ndarray, route_xy_m: np.ndarray) -> np.ndarray:
    """Signed horizontal distance of points from a route polyline [m].

    Parameters
    ----------
    xy_m : ndarray, shape (..., 2)
        Points (East, North).
    route_xy_m : ndarray, shape (K, 2)
        The route's points in order, ``K >= 2``.

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
    pos_enu_m: np.ndarray,
    route_xy_m: np.ndarray,
    dt_s: float,
    cruise: tuple[float, float] = CRUISE,
) -> dict[str, float]:
    """Spacing, altitude, spread across the route and speed of a swarm in its cruise.

    Parameters
    ----------
    pos_enu_m : ndarray, shape (T + 1, N, 3)
        True positions from the reset on (``EpisodeRecord.pos_enu_m``).
    route_xy_m : ndarray, shape (K, 2)
        The episode's street route (the environment's ``world.route_xy_m``).
    dt_s : float
        Step length [s], > 0.
    cruise : (float, float)
        The share of the steps that counts, as :func:`cruise_spacing_m` takes it.

    Returns
    -------
    dict
        ``spacing_m``: mean distance of a UAV to its nearest neighbour
        (:func:`~coopnav_env.training.evaluate.cruise_spacing_m`); ``altitude_m``: mean
        altitude; ``lateral_spread_m``: mean over steps of the swarm's extent across the
        route (largest minus smallest :func:`cross_track_m`): 0 for a column in line on the
        route, the street's width for a swarm spread across it; ``speed_mps``: mean
        horizontal speed of a UAV between steps. NaN where there are fewer than two steps
        (and spacing and spread with one UAV).
    """
    pos = np.asarray(pos_enu_m, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise ValueError(f"pos_enu_m must have shape (T + 1, N, 3), got {pos.shape}")
    if not dt_s > 0.0:
        raise ValueError(f"dt_s must be > 0 seconds, got {dt_s}")
    nan = {"spacing_m": math.nan, "altitude_m": math.nan}
    nan.update(lateral_spread_m=math.nan, speed_mps=math.nan)
    if pos.shape[0] < 2:
        return nan
    t0, t1 = (round(f * (len(pos) - 1)) for f in cruise)
    lo, hi = max(t0, 1), max(t1, t0 + 1)
    part = pos[lo : hi + 1]
    out = dict(nan)
    out["spacing_m"] = cruise_spacing_m(pos, cruise)
    out["altitude_m"] = float(part[:, :, 2].mean())
    if pos.shape[1] > 1:
        off = cross_track_m(part[:, :, :2], route_xy_m)
        out["lateral_spread_m"] = float((off.max(axis=1) - off.min(axis=1)).mean())
    steps = pos[lo - 1 : hi + 1, :, :2]
    out["speed_mps"] = float(np.linalg.norm(np.diff(steps, axis=0), axis=-1).mean() / dt_s)
    return out
