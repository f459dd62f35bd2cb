"""The pursuit autopilot shared by the `waypoint` follower and the route action frame.

:func:`pursuit_velocity` turns a point to fly to and an altitude error into a velocity: the
`waypoint` follower (:class:`coopnav_env.agents.heuristics.WaypointPolicy`) flies it toward its
next waypoint, and ``action_frame="route"``
(:func:`coopnav_env.envs.urban_canyon.route_frame_command`) toward set-points along the street
route; :func:`route_frame_velocity` is that route autopilot for ``K`` swarms at once.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pursuit_velocity", "route_frame_velocity"]


def pursuit_velocity(
    to_point_xy_m: np.ndarray,
    speed_limit_mps: np.ndarray | float,
    altitude_error_m: np.ndarray,
    gain_per_s: float,
    brake_mps2: np.ndarray | float = 0.0,
) -> np.ndarray:
    """The velocity [m/s] that pursues a point horizontally and an altitude vertically.

    Parameters
    ----------
    to_point_xy_m : ndarray, shape (N, 2)
        From each UAV to the point it flies to [m].
    speed_limit_mps : float or ndarray, shape (N,)
        The horizontal speed it flies at far from the point [m/s].
    altitude_error_m : ndarray, shape (N,)
        Altitude to reach minus the altitude now [m].
    gain_per_s : float
        Proportional gain [1/s]: near the point the speed is at most ``1 + gain_per_s * d``
        m/s at ``d`` m from it; the climb rate is ``gain_per_s * altitude_error_m``.
    brake_mps2 : float or ndarray, shape (N,), default 0
        Where ``b > 0``, the speed is also at most ``1 + sqrt(2 b max(d - 3, 0))`` m/s, so
        that the UAV can brake at ``b`` m/s² before the point (the 3 m allow for one step of
        travel); 0: no such limit.

    Returns
    -------
    ndarray, shape (N, 3)
        East, North, Up velocity [m/s], horizontally toward the point at
        ``min(speed_limit_mps, 1 + gain_per_s * d)`` and the braking limit (zero at the point
        itself).
    """
    to_point = np.asarray(to_point_xy_m, dtype=np.float64)
    dist = np.linalg.norm(to_point, axis=1)
    speed = np.minimum(speed_limit_mps, gain_per_s * dist + 1.0)
    brake = np.broadcast_to(np.asarray(brake_mps2, dtype=np.float64), dist.shape)
    if np.any(brake > 0.0):
        room = np.sqrt(2.0 * brake * np.maximum(dist - 3.0, 0.0))
        speed = np.where(brake > 0.0, np.minimum(speed, 1.0 + room), speed)
    v = np.zeros((to_point.shape[0], 3))
    v[:, :2] = to_point / np.maximum(dist, 1e-6)[:, None] * speed[:, None]
    v[:, 2] = gain_per_s * np.asarray(altitude_error_m, dtype=np.float64)
    return v


def route_frame_velocity(
    action: np.ndarray,
    est_enu_m: np.ndarray,
    next_waypoint: np.ndarray,
    routes_xy_m: list[np.ndarray],
    max_speed_mps: float,
    altitude_band_m: tuple[float, float],
    offset_max_m: np.ndarray | float,
    turn_brake_mps2: float,
    gain_per_s: float,
    route_lengths: np.ndarray | None = None,
) -> np.ndarray:
    """The route autopilot of ``K`` swarms at once: route-frame set-points to velocity commands.

    Every entry is computed from its own UAV's numbers with the operations of
    :func:`coopnav_env.envs.urban_canyon.route_frame_command` (one swarm), so swarm ``k``'s
    commands equal that function's on swarm ``k`` alone, bit for bit.

    Parameters
    ----------
    action : ndarray, shape (K, N, 3)
        Set-points (clipped to ``[-1, 1]``): speed along the route, offset across the street,
        altitude.
    est_enu_m : ndarray, shape (K, N, 3)
        Each UAV's estimated position [m]; a UAV with a non-finite estimate holds still.
    next_waypoint : ndarray of int, shape (K, N)
        Each UAV's next waypoint on its swarm's route.
    routes_xy_m : list of K ndarrays, shape (k_i, 2), or ndarray, shape (K, R, 2)
        Each swarm's street route [m]; an array (with ``route_lengths``) holds swarm ``k``'s
        route in its first ``route_lengths[k]`` rows (the rest is padding, never read).
    max_speed_mps : float
        The speed of a command of 1 [m/s].
    altitude_band_m : (float, float)
        The altitudes of the set-points -1 and +1 [m]; estimates are clamped to the band.
    offset_max_m : float or ndarray, shape (K, N)
        The offset of the set-point 1 to the left of the leg [m].
    turn_brake_mps2 : float
        The braking the speed allows before every waypoint but a route's last [m/s²].
    gain_per_s : float
        The pursuit gain [1/s] (:func:`pursuit_velocity`).
    route_lengths : ndarray of int, shape (K,), optional
        The waypoints of each swarm's route when ``routes_xy_m`` is a padded ``(K, R, 2)``
        array; None when it is a list of routes.

    Returns
    -------
    ndarray, shape (K, N, 3)
        Velocity commands, fractions of ``max_speed_mps`` in ``[-1, 1]``.
    """
    act = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    k_, n_ = act.shape[:2]
    if len(routes_xy_m) != k_:
        raise ValueError(
            f"routes_xy_m must hold {k_} routes (one per swarm), got {len(routes_xy_m)}"
        )
    if route_lengths is None:
        routes = [np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in routes_xy_m]
        lengths = np.array([r.shape[0] for r in routes], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])[:, None]  # (K, 1)
        flat = np.concatenate(routes)
    else:
        padded = np.asarray(routes_xy_m, dtype=np.float64)
        lengths = np.asarray(route_lengths, dtype=np.int64)
        if padded.ndim != 3 or padded.shape[2] != 2 or lengths.shape != (k_,):
            raise ValueError(
                f"padded routes_xy_m must have shape ({k_}, R, 2) with route_lengths of shape "
                f"({k_},), got {padded.shape} and {lengths.shape}"
            )
        starts = (np.arange(k_, dtype=np.int64) * padded.shape[1])[:, None]
        flat = padded.reshape(-1, 2)
    wp = np.asarray(next_waypoint, dtype=np.int64)
    est = np.asarray(est_enu_m, dtype=np.float64).reshape(k_ * n_, 3)
    ok = np.all(np.isfinite(est), axis=1)
    est = np.where(ok[:, None], est, 0.0)
    target = flat[(starts + wp).ravel()]
    before = flat[(starts + np.maximum(wp - 1, 0)).ravel()]
    first = (wp > 0).ravel()
    # the leg that ends at the next waypoint; before the first one, the way to it
    leg = np.where(first[:, None], target - before, target - est[:, :2])
    norm = np.linalg.norm(leg, axis=1)
    tangent = np.where((norm > 1e-9)[:, None], leg / np.maximum(norm, 1e-9)[:, None], 0.0)
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    flat_act = act.reshape(k_ * n_, 3)
    o_max = np.asarray(offset_max_m, dtype=np.float64)
    o_max = o_max.ravel() if o_max.ndim else o_max
    aim = target + left * (flat_act[:, 1] * o_max)[:, None] - est[:, :2]
    speed = (flat_act[:, 0] + 1.0) / 2.0 * max_speed_mps
    # braking for the route's turns: before every waypoint but the last
    brake = np.where((wp < (lengths - 1)[:, None]).ravel(), turn_brake_mps2, 0.0)
    low, high = altitude_band_m
    height = low + (flat_act[:, 2] + 1.0) / 2.0 * (high - low)
    climb = height - np.clip(est[:, 2], low, high)
    v = pursuit_velocity(aim, speed, climb, gain_per_s, brake)
    v[~ok] = 0.0
    return np.clip(v / max_speed_mps, -1.0, 1.0).reshape(k_, n_, 3)
