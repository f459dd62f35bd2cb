"""The pursuit autopilot shared by the `waypoint` follower and the route action frame.

:func:`pursuit_velocity` turns a point to fly to and an altitude error into a velocity: the
`waypoint` follower (:class:`coopnav_env.agents.heuristics.WaypointPolicy`) flies it toward its
next waypoint, and ``action_frame="route"``
(:func:`coopnav_env.envs.urban_canyon.route_frame_command`) toward set-points along the street
route.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pursuit_velocity"]


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
