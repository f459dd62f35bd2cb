"""The autopilots: pursuit of a point, and the route action frame built on it.

:func:`pursuit_velocity` turns a point to fly to and an altitude error into a velocity: the
`waypoint` follower (:class:`coopnav_env.agents.heuristics.WaypointPolicy`) flies it toward its
next waypoint, and ``action_frame="route"`` (:func:`route_frame_command`) toward set-points
along the street route; :func:`route_frame_velocity` is that route autopilot for ``K`` swarms
at once. :func:`route_offset_room_m` and :func:`check_route_offset` bound the set-points'
offset across the street to the room the city leaves.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from coopnav_env.envs.config import UrbanCanyonConfig

if TYPE_CHECKING:
    from coopnav_env.sim.file_city import FileCity

__all__ = [
    "ROUTE_FRAME_GAIN_PER_S",
    "check_route_offset",
    "pursuit_velocity",
    "route_frame_command",
    "route_frame_velocity",
    "route_offset_room_m",
]


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


ROUTE_FRAME_GAIN_PER_S = 0.6
"""Gain of the ``action_frame="route"`` autopilot on the altitude and on the speed before
a waypoint [1/s] (the `waypoint` follower's)."""


def check_route_offset(cfg: UrbanCanyonConfig, street_width_m: float) -> None:
    """Refuse (``ValueError``) a ``route_offset_max_m`` that reaches the walls of a street
    ``street_width_m`` wide: it must be less than half the width less the UAV radius."""
    room_m = street_width_m / 2.0 - cfg.kinematics.uav_radius_m
    if not cfg.route_offset_max_m < room_m:
        raise ValueError(
            f"route_offset_max_m must be less than half the street width minus the UAV radius "
            f"({street_width_m:g} / 2 - {cfg.kinematics.uav_radius_m:g} = {room_m:g} m), got "
            f"{cfg.route_offset_max_m!r}"
        )


def route_offset_room_m(
    city: FileCity, route_xy_m: np.ndarray, cfg: UrbanCanyonConfig
) -> np.ndarray:
    """Largest route-frame offset [m] on each leg of a file city's route, ``(k,)``: leg ``i``
    ends at waypoint ``i`` (leg 0: the way to the first waypoint, its clearance there). It is
    ``route_offset_max_m``, or less where the free space is narrower: the smallest distance to
    a wall of the free-space cells along the leg
    (:attr:`~coopnav_env.sim.file_city.FileCity.clearance_grid_m`, sampled every metre) less
    the UAV radius and 1 m, at least 0."""
    route = np.asarray(route_xy_m, dtype=np.float64).reshape(-1, 2)
    res = city.resolution_m
    ny, nx = city.clearance_grid_m.shape
    room = np.empty(route.shape[0])
    for i in range(route.shape[0]):
        a = route[max(i - 1, 0)]
        b = route[i]
        n = max(int(np.ceil(np.linalg.norm(b - a))), 1) + 1
        pts = np.linspace(a, b, n)
        col = np.clip(np.floor((pts[:, 0] - city.grid_x_m[0]) / res + 0.5), 0, nx - 1)
        row = np.clip(np.floor((pts[:, 1] - city.grid_y_m[0]) / res + 0.5), 0, ny - 1)
        room[i] = city.clearance_grid_m[row.astype(np.int64), col.astype(np.int64)].min()
    room -= cfg.kinematics.uav_radius_m + 1.0
    return np.clip(room, 0.0, cfg.route_offset_max_m)


def route_frame_command(
    action: np.ndarray,
    est_enu_m: np.ndarray,
    next_waypoint: np.ndarray,
    route_xy_m: np.ndarray,
    cfg: UrbanCanyonConfig,
    offset_max_m: np.ndarray | None = None,
) -> np.ndarray:
    """The velocity command of route-frame set-points (``action_frame="route"``).

    Parameters
    ----------
    action : ndarray, shape (N, 3)
        Set-points in ``[-1, 1]``: speed along the route, offset across the street, altitude
        (:class:`~coopnav_env.envs.config.UrbanCanyonConfig`, ``action_frame``).
    est_enu_m : ndarray, shape (N, 3)
        Each UAV's estimated position [m] (the autopilot flies on what the UAV knows).
    next_waypoint : ndarray of int, shape (N,)
        Each UAV's next waypoint on ``route_xy_m``.
    route_xy_m : ndarray, shape (k, 2)
        The street route's waypoints [m].
    cfg : UrbanCanyonConfig
    offset_max_m : ndarray, shape (N,), optional
        Each UAV's largest offset [m] in place of ``route_offset_max_m`` (a file city: the
        room on the UAV's leg, :func:`route_offset_room_m`).

    Returns
    -------
    ndarray, shape (N, 3)
        The velocity command, fractions of ``max_speed_mps`` in ``[-1, 1]``: the `waypoint`
        follower's autopilot with set-points. Horizontally, from the estimated position
        toward the next waypoint moved ``o = a1 * route_offset_max_m`` (or ``offset_max_m``)
        to the left of the leg that ends there (before the first waypoint: of the way to it),
        at the speed
        ``(a0 + 1) / 2 * max_speed_mps``, at most ``1 + 0.6 d`` m/s at ``d`` m from that
        point (with ``route_turn_brake_mps2 = b > 0``, also at most ``1 + sqrt(2 b (d - 3))``
        m/s before a turn). Vertically ``0.6 (h - h_est)`` toward ``h`` from ``altitude_min_m``
        (``a2 = -1``) to ``altitude_max_m`` (``+1``), with the estimated altitude ``h_est``
        clamped to the band. A UAV with no finite estimate holds still (zero command).
    """
    kin = cfg.kinematics
    gain = ROUTE_FRAME_GAIN_PER_S
    act = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    route = np.asarray(route_xy_m, dtype=np.float64).reshape(-1, 2)
    wp = np.asarray(next_waypoint, dtype=np.int64)
    est = np.asarray(est_enu_m, dtype=np.float64)
    ok = np.all(np.isfinite(est), axis=1)
    est = np.where(ok[:, None], est, 0.0)
    target = route[wp]
    # the leg that ends at the next waypoint; before the first one, the way to it
    leg = np.where((wp > 0)[:, None], target - route[np.maximum(wp - 1, 0)], target - est[:, :2])
    norm = np.linalg.norm(leg, axis=1)
    tangent = np.where((norm > 1e-9)[:, None], leg / np.maximum(norm, 1e-9)[:, None], 0.0)
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    o_max = cfg.route_offset_max_m if offset_max_m is None else np.asarray(offset_max_m)
    aim = target + left * (act[:, 1] * o_max)[:, None] - est[:, :2]
    speed = (act[:, 0] + 1.0) / 2.0 * kin.max_speed_mps
    # braking for the route's turns: before every waypoint but the last
    brake = np.where(wp < route.shape[0] - 1, cfg.route_turn_brake_mps2, 0.0)
    band_m = kin.altitude_max_m - kin.altitude_min_m
    height = kin.altitude_min_m + (act[:, 2] + 1.0) / 2.0 * band_m
    # the UAV flies inside the altitude band: an estimate outside it is clamped to it
    climb = height - np.clip(est[:, 2], kin.altitude_min_m, kin.altitude_max_m)
    v = pursuit_velocity(aim, speed, climb, gain, brake)
    v[~ok] = 0.0
    return np.clip(v / kin.max_speed_mps, -1.0, 1.0)


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
    :func:`route_frame_command` (one swarm), so swarm ``k``'s
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
