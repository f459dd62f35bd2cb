"""The swarm: UAV kinematics, collisions and relative (UWB-like) sensing.

All positions and velocities are in the local ENU frame of :mod:`coopnav_env.sim.city`
(metres, metres per second; ``z`` up, ground at 0). Every function is pure (inputs are never
modified) and vectorised over UAVs and buildings; randomness only through an explicit
:class:`numpy.random.Generator`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from coopnav_env.sim import _kernels
from coopnav_env.sim.city import (
    BoolArray,
    Buildings,
    FloatArray,
    _as_points,
    _check_real,
    _chunk_slices,
)

__all__ = [
    "KinematicsConfig",
    "RelativeSensingConfig",
    "building_collisions",
    "measure_relative_positions",
    "pairwise_ranges_m",
    "separation_violations",
    "step_kinematics",
    "swept_collisions",
]


# --------------------------------------------------------------------------------------------
# kinematics
# --------------------------------------------------------------------------------------------


MIN_STEP_M: float = 1e-6
"""Smallest allowed ``max_speed_mps * dt_s`` [m] (observations and rewards divide by it)."""


@dataclass(frozen=True)
class KinematicsConfig:
    """Point-mass kinematics of a multirotor UAV.

    Parameters
    ----------
    dt_s : float, default 1.0
        Time step, in (0, 60] [s] (the GNSS epoch interval).
    max_speed_mps : float, default 10.0
        Largest commanded speed, horizontally (norm) and vertically, in (0, 100] [m/s].
    max_accel_mps2 : float, default 4.0
        Largest change of velocity per second (3-D norm), in (0, 100] [m/s^2].
    altitude_min_m, altitude_max_m : float, default 5.0, 30.0
        Altitude band, ``0 <= altitude_min_m < altitude_max_m <= 10000`` [m]. The default
        ceiling is below typical roofs (generated cities draw heights around 45 m; the default
        :func:`~coopnav_env.sim.city.canyon_city` roofs are 32.3 m) so that UAVs must fly
        through the streets instead of over the roofs.
    uav_radius_m : float, default 1.0
        Radius of the sphere that stands for a UAV in building collisions, in [0, 100] [m].
    min_separation_m : float, default 3.0
        Smallest allowed distance between two UAV centres, in [0, 1000] [m].
    """

    dt_s: float = 1.0
    max_speed_mps: float = 10.0
    max_accel_mps2: float = 4.0
    altitude_min_m: float = 5.0
    altitude_max_m: float = 30.0
    uav_radius_m: float = 1.0
    min_separation_m: float = 3.0

    def __post_init__(self) -> None:
        o = "KinematicsConfig"
        _check_real(o, "dt_s", self.dt_s, 0.0, 60.0, lo_open=True)
        _check_real(o, "max_speed_mps", self.max_speed_mps, 0.0, 100.0, lo_open=True)
        _check_real(o, "max_accel_mps2", self.max_accel_mps2, 0.0, 100.0, lo_open=True)
        _check_real(o, "altitude_min_m", self.altitude_min_m, 0.0, 10_000.0)
        _check_real(
            o, "altitude_max_m", self.altitude_max_m, self.altitude_min_m, 10_000.0, lo_open=True
        )
        _check_real(o, "uav_radius_m", self.uav_radius_m, 0.0, 100.0)
        _check_real(o, "min_separation_m", self.min_separation_m, 0.0, 1000.0)
        # the environment divides by the largest step; a product that underflows is refused
        if not self.max_speed_mps * self.dt_s >= MIN_STEP_M:
            raise ValueError(
                f"{o}: max_speed_mps * dt_s (the largest step, {self.max_speed_mps!r} m/s x "
                f"{self.dt_s!r} s) must be >= {MIN_STEP_M} m"
            )


def step_kinematics(
    pos_enu_m: ArrayLike, vel_enu_mps: ArrayLike, cmd: ArrayLike, cfg: KinematicsConfig
) -> tuple[FloatArray, FloatArray]:
    """Advance the UAVs by one time step.

    The command is a desired velocity as a fraction of ``cfg.max_speed_mps`` on each ENU axis
    (clipped to [-1, 1]); its horizontal norm is then clipped to ``max_speed_mps`` (a diagonal
    command would otherwise be sqrt(2) times faster). The velocity moves toward the desired
    one by at most ``max_accel_mps2 * dt_s`` (3-D norm), then the position is integrated with
    the new velocity (semi-implicit Euler). Finally the altitude is clamped to
    ``[altitude_min_m, altitude_max_m]``; at a limit the vertical velocity component that
    points out of the band is zeroed.

    Parameters
    ----------
    pos_enu_m : array_like, shape (n, 3)
        Positions in ENU [m].
    vel_enu_mps : array_like, shape (n, 3)
        Velocities in ENU [m/s].
    cmd : array_like, shape (n, 3)
        Velocity commands, fractions of ``max_speed_mps`` in [-1, 1] (clipped).
    cfg : KinematicsConfig

    Returns
    -------
    pos_enu_m : ndarray, shape (n, 3)
        New positions [m].
    vel_enu_mps : ndarray, shape (n, 3)
        New velocities [m/s].

    Notes
    -----
    Collisions are not resolved here: check :func:`swept_collisions` between the old and new
    positions.
    """
    pos = _as_points(pos_enu_m, "pos_enu_m")
    vel = _as_points(vel_enu_mps, "vel_enu_mps")
    c = _as_points(cmd, "cmd")
    if vel.shape != pos.shape or c.shape != pos.shape:
        raise ValueError(
            f"pos_enu_m, vel_enu_mps and cmd must share one shape (n, 3), got {pos.shape}, "
            f"{vel.shape} and {c.shape}"
        )
    v_max = cfg.max_speed_mps
    v_des = np.clip(c, -1.0, 1.0) * v_max
    h_speed = np.hypot(v_des[:, 0], v_des[:, 1])
    h_scale = np.minimum(1.0, v_max / np.maximum(h_speed, 1e-300))
    v_des[:, :2] *= h_scale[:, None]

    dv = v_des - vel
    dv_norm = np.linalg.norm(dv, axis=1)
    dv_max = cfg.max_accel_mps2 * cfg.dt_s
    dv = dv * np.minimum(1.0, dv_max / np.maximum(dv_norm, 1e-300))[:, None]
    vel_new = vel + dv
    pos_new = pos + vel_new * cfg.dt_s

    z = pos_new[:, 2]
    below = z < cfg.altitude_min_m
    above = z > cfg.altitude_max_m
    pos_new[:, 2] = np.clip(z, cfg.altitude_min_m, cfg.altitude_max_m)
    vz = vel_new[:, 2]
    vel_new[:, 2] = np.where(below, np.maximum(vz, 0.0), np.where(above, np.minimum(vz, 0.0), vz))
    return pos_new, vel_new


# --------------------------------------------------------------------------------------------
# collisions
# --------------------------------------------------------------------------------------------


def _check_radius(radius_m: float) -> float:
    return _check_real("collisions", "radius_m", radius_m, 0.0)


def building_collisions(buildings: Buildings, pos_enu_m: ArrayLike, radius_m: float) -> BoolArray:
    """Sphere-versus-box collisions of UAVs with buildings.

    Parameters
    ----------
    buildings : Buildings
    pos_enu_m : array_like, shape (n, 3)
        Sphere centres in ENU [m].
    radius_m : float
        Sphere radius, >= 0 [m].

    Returns
    -------
    ndarray of bool, shape (n,)
        True when the distance from the centre to some box is <= ``radius_m`` (touching counts
        as a collision; with radius 0, a point on a wall collides).
    """
    pos = _as_points(pos_enu_m, "pos_enu_m")
    r = _check_radius(radius_m)
    hit = np.zeros(pos.shape[0], dtype=bool)
    for cb in _chunk_slices(buildings.n, 3 * max(pos.shape[0], 1)):
        p = pos[:, None, :]
        excess = np.maximum(
            np.maximum(buildings.min_m[None, cb] - p, 0.0), p - buildings.max_m[None, cb]
        )
        hit |= np.any(np.einsum("nbk,nbk->nb", excess, excess) <= r * r, axis=1)
    return hit


def _segment_box_min_dist2(
    p0: FloatArray, d: FloatArray, lo: FloatArray, hi: FloatArray
) -> FloatArray:
    """Exact smallest squared distance between segments ``p0 + t d`` (t in [0, 1]) and boxes.

    ``p0`` and ``d`` have shape (n, 1, 3); ``lo`` and ``hi`` (1, m, 3). Returns (n, m).

    The squared distance to a box along the segment is a convex piecewise quadratic in ``t``
    whose pieces change where a coordinate crosses a slab bound; its minimum is at an end, at a
    crossing, or at the stationary point of one piece. All these candidates are evaluated.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        t_lo = (lo - p0) / d
        t_hi = (hi - p0) / d
    cross = np.concatenate([t_lo, t_hi], axis=2)  # (n, m, 6)
    cross = np.where(np.isfinite(cross), np.clip(cross, 0.0, 1.0), 0.0)
    shape = cross.shape[:2]
    tb = np.sort(
        np.concatenate([np.zeros((*shape, 1)), np.ones((*shape, 1)), cross], axis=2), axis=2
    )  # (n, m, 8)
    a, b = tb[..., :-1], tb[..., 1:]  # the 7 pieces
    tm = 0.5 * (a + b)
    p0e, de = p0[:, :, None, :], d[:, :, None, :]  # (n, 1, 1, 3)
    loe, hie = lo[:, :, None, :], hi[:, :, None, :]  # (1, m, 1, 3)
    pm = p0e + tm[..., None] * de
    bound = np.where(pm < loe, loe, np.where(pm > hie, hie, np.nan))
    active = ~np.isnan(bound)
    off = np.where(active, p0e - bound, 0.0)
    dd = np.where(active, de, 0.0)
    num = -np.sum(dd * off, axis=3)
    den = np.sum(dd * dd, axis=3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_star = np.where(den > 0.0, num / den, tm)
    t_star = np.clip(t_star, a, b)
    cand = np.concatenate([tb, t_star], axis=2)  # (n, m, 15)
    pc = p0e + cand[..., None] * de
    excess = np.maximum(np.maximum(loe - pc, 0.0), pc - hie)
    return np.min(np.sum(excess * excess, axis=3), axis=2)


def swept_collisions(
    buildings: Buildings, start_enu_m: ArrayLike, end_enu_m: ArrayLike, radius_m: float
) -> BoolArray:
    """Collisions of spheres moving along straight segments with buildings (no tunnelling).

    The exact smallest distance between each segment and each box is computed, so a UAV that
    would cross a thin building within one step is caught.

    Parameters
    ----------
    buildings : Buildings
    start_enu_m, end_enu_m : array_like, shape (n, 3)
        Sphere centres at the start and end of the step, ENU [m].
    radius_m : float
        Sphere radius, >= 0 [m].

    Returns
    -------
    ndarray of bool, shape (n,)
        True when the swept sphere touches or penetrates some box.
    """
    p0 = _as_points(start_enu_m, "start_enu_m")
    p1 = _as_points(end_enu_m, "end_enu_m")
    if p1.shape != p0.shape:
        raise ValueError(
            f"start_enu_m and end_enu_m must share one shape (n, 3), got {p0.shape}, {p1.shape}"
        )
    r = _check_radius(radius_m)
    d = p1 - p0
    hit = np.zeros(p0.shape[0], dtype=bool)
    for cb in _chunk_slices(buildings.n, 48 * max(p0.shape[0], 1)):
        d2 = _segment_box_min_dist2(
            p0[:, None, :], d[:, None, :], buildings.min_m[None, cb], buildings.max_m[None, cb]
        )
        hit |= np.any(d2 <= r * r, axis=1)
    return hit


def pairwise_ranges_m(pos_enu_m: ArrayLike) -> FloatArray:
    """Distances between all UAV pairs.

    Parameters
    ----------
    pos_enu_m : array_like, shape (n, 3)
        Positions in ENU [m].

    Returns
    -------
    ndarray, shape (n, n)
        ``range[b, q] = |pos[q] - pos[b]|`` [m]; 0 on the diagonal.
    """
    pos = _as_points(pos_enu_m, "pos_enu_m")
    return np.linalg.norm(pos[None, :, :] - pos[:, None, :], axis=2)


def separation_violations(pos_enu_m: ArrayLike, min_separation_m: float) -> BoolArray:
    """UAVs closer than the minimum separation to any other UAV.

    Parameters
    ----------
    pos_enu_m : array_like, shape (n, 3)
        Positions in ENU [m].
    min_separation_m : float
        Minimum allowed distance between centres, >= 0 [m].

    Returns
    -------
    ndarray of bool, shape (n,)
        True for each UAV with another UAV strictly closer than ``min_separation_m``.
        Computed in one compiled call (:func:`coopnav_env.sim._kernels.separation_violations`).
    """
    sep = _check_real("separation_violations", "min_separation_m", min_separation_m, 0.0)
    pos = _as_points(pos_enu_m, "pos_enu_m")
    return _kernels.separation_violations(np.ascontiguousarray(pos), float(sep))


# --------------------------------------------------------------------------------------------
# relative sensing
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RelativeSensingConfig:
    """UWB-like relative positioning between UAVs (the paper's Eq. 9 input).

    Each pair measures the ENU vector between the two UAVs with an isotropic Gaussian error of
    standard deviation ``sigma_d = sigma0_m + sigma_per_m * range`` per ENU axis.

    Parameters
    ----------
    max_range_m : float, default 200.0
        Largest range at which a pair can measure, in (0, 100000] [m]. UWB links reach a
        few hundred metres in line of sight; 200 m is a conservative urban figure.
    sigma0_m : float, default 0.1
        Range-independent part of the per-axis standard deviation, in [0, 100] [m]: UWB
        ranging is accurate to about 10 cm.
    sigma_per_m : float, default 0.002
        Growth of the per-axis standard deviation with range, in [0, 1] [m/m]: the direction
        (from antenna arrays or the swarm's geometry) is known to a few milliradians, so the
        cross-range error grows linearly. With the defaults ``sigma_d`` reaches 0.5 m at
        200 m, the paper's relative-position error ([0.5, 0.5, 0.5] m ENU, Section 4.1).
    """

    max_range_m: float = 200.0
    sigma0_m: float = 0.1
    sigma_per_m: float = 0.002

    def __post_init__(self) -> None:
        o = "RelativeSensingConfig"
        _check_real(o, "max_range_m", self.max_range_m, 0.0, 100_000.0, lo_open=True)
        _check_real(o, "sigma0_m", self.sigma0_m, 0.0, 100.0)
        _check_real(o, "sigma_per_m", self.sigma_per_m, 0.0, 1.0)

    def sigma_m(self, range_m: ArrayLike) -> FloatArray:
        """Per-axis standard deviation [m] at the given ranges [m]; same shape as the input."""
        return self.sigma0_m + self.sigma_per_m * np.asarray(range_m, dtype=np.float64)


def measure_relative_positions(
    rng: np.random.Generator, pos_enu_m: ArrayLike, cfg: RelativeSensingConfig
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Noisy relative positions between all UAV pairs.

    ``rel[b, q] = pos[q] - pos[b] + eps[b, q]`` is the measured position of UAV ``q`` relative
    to UAV ``b``. One physical measurement is made per pair, so the errors are antisymmetric:
    ``eps[q, b] = -eps[b, q]`` and ``rel[q, b] = -rel[b, q]``.

    Parameters
    ----------
    rng : numpy.random.Generator
    pos_enu_m : array_like, shape (n, 3)
        True positions in ENU [m].
    cfg : RelativeSensingConfig

    Returns
    -------
    rel_enu_m : ndarray, shape (n, n, 3)
        Measured relative positions [m]; 0 on the diagonal and for unavailable pairs.
    cov_enu_m2 : ndarray, shape (n, n, 3, 3)
        Error covariance ``sigma_d(range)^2 * I`` [m^2]; 0 on the diagonal and for unavailable
        pairs.
    available : ndarray of bool, shape (n, n)
        True when ``0 < range <= cfg.max_range_m``; False on the diagonal.

    Notes
    -----
    The ``n (n - 1) / 2 x 3`` standard normal draws of the upper triangle (``b < q``, in
    row-major order) are made whatever the availability, so the random stream does not depend
    on the geometry.
    """
    pos = _as_points(pos_enu_m, "pos_enu_m")
    rel, var, available = _measure_relative(rng, pos, cfg)
    cov = var[:, :, None, None] * np.eye(3)
    return rel, cov, available


def _measure_relative(
    rng: np.random.Generator, pos: FloatArray, cfg: RelativeSensingConfig
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """:func:`measure_relative_positions` of validated positions, with the per-axis variance
    ``(n, n)`` instead of the covariance matrices (``cov = var * I``).

    The draws are made here; the arithmetic is one compiled call
    (:func:`coopnav_env.sim._kernels.relative_measurements`), which the tests compare bit for
    bit with a numpy formulation of the same operations (``tests/sim/oracles.py``).
    """
    n = pos.shape[0]
    z = rng.standard_normal((n * (n - 1) // 2, 3))
    return _kernels.relative_measurements(
        pos, z, float(cfg.sigma0_m), float(cfg.sigma_per_m), float(cfg.max_range_m)
    )
