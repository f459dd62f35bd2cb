"""Standalone weighted least squares (paper Eq. 14-17), vectorised over receivers.

Each receiver solves for its ECEF position and one clock bias per constellation it sees
(state length ``3 + N_const``) from its own pseudoranges, weighted by ``W = C^-1`` with the
diagonal covariance of Eq. 3 (``sigma_URE^2 + sigma_tropo^2 + sigma_user^2``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coopnav_env.nav import _kernels
from coopnav_env.nav.types import (
    PLAUSIBLE_RADIUS_M,
    GnssObservations,
    NavStatus,
    check_iteration,
    check_plausible_radius,
    implausible_radius,
    initial_positions,
    weak_geometry,
)

__all__ = ["StandaloneSolution", "pdop", "solve_standalone"]

#: A normal matrix whose diagonally scaled condition number exceeds this is reported singular
#: (the numpy formulation and the compiled kernels share the value).
COND_LIMIT = _kernels.COND_LIMIT

_USE_KERNEL = True
"""Run the Gauss-Newton loop in the compiled kernel (False: the numpy formulation)."""


def pdop(los_unit: np.ndarray, system: np.ndarray) -> float:
    """Position dilution of precision of a standalone fix with unit weights.

    State: the position and one receiver clock per constellation among ``system`` (Eq. 14).

    Parameters
    ----------
    los_unit : ndarray, shape (S, 3)
        Unit vectors from the receiver to the satellites, in any Cartesian frame (PDOP does
        not depend on its orientation).
    system : ndarray, shape (S,)
        Constellation of each satellite.

    Returns
    -------
    float
        ``sqrt(trace((G^T G)^-1)[:3, :3])``; ``inf`` when there are fewer satellites than
        unknowns or the normal matrix is singular (condition number above 1e12).
    """
    los = np.asarray(los_unit, dtype=float).reshape(-1, 3)
    sys_ = np.asarray(system).reshape(-1)
    systems = np.unique(sys_)
    g = np.concatenate([-los, (sys_[:, None] == systems[None]).astype(float)], axis=1)
    if g.shape[0] < g.shape[1]:
        return math.inf
    info = g.T @ g
    if np.linalg.cond(info) > 1e12:
        return math.inf
    return float(np.sqrt(np.trace(np.linalg.inv(info)[:3, :3])))


@dataclass(frozen=True)
class StandaloneSolution:
    """Standalone fixes of ``n_rx`` receivers.

    Attributes
    ----------
    pos_ecef_m : ndarray, shape (n_rx, 3)
        Estimated positions [m]; NaN where ``status`` is TOO_FEW_SATELLITES or SINGULAR_GEOMETRY.
    cov_ecef_m2 : ndarray, shape (n_rx, 3, 3)
        Position block of ``H = (G^T C^-1 G)^-1`` (Eq. 17) [m^2]; NaN where no fix.
    clock_m : ndarray, shape (n_rx, n_systems)
        Receiver clock bias per constellation [m]; NaN for a constellation not seen.
    status : ndarray of int, shape (n_rx,)
        :class:`NavStatus` values.
    n_used : ndarray of int, shape (n_rx,)
        Number of pseudoranges used.
    n_iter : int
        Gauss-Newton iterations run.
    """

    pos_ecef_m: np.ndarray
    cov_ecef_m2: np.ndarray
    clock_m: np.ndarray
    status: np.ndarray
    n_used: np.ndarray
    n_iter: int

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of receivers with a valid fix (status OK, no other status)."""
        return self.status == NavStatus.OK

    @property
    def weak_geometry(self) -> np.ndarray:
        """Boolean mask of OK fixes on ill-conditioned geometry: predicted 3-D standard
        deviation above :data:`~coopnav_env.nav.types.WEAK_GEOMETRY_SIGMA_M`
        (:func:`~coopnav_env.nav.types.weak_geometry`; call it for another limit)."""
        return weak_geometry(self.status, self.cov_ecef_m2)


def _safe_inverse(info: np.ndarray, usable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert a batch of symmetric normal matrices, reporting singular ones.

    Parameters
    ----------
    info : ndarray, shape (B, P, P)
        Normal matrices; rows/columns of parameters without data must already carry a unit
        diagonal so that they do not make the matrix singular.
    usable : ndarray of bool, shape (B,)
        Batch elements worth inverting.

    Returns
    -------
    inv : ndarray, shape (B, P, P)
        Inverses (identity where singular or not usable).
    singular : ndarray of bool, shape (B,)
    """
    d = np.sqrt(np.clip(np.diagonal(info, axis1=1, axis2=2), 1e-300, None))
    scaled = info / d[:, :, None] / d[:, None, :]
    # (the np.where calls are skipped when they would select everything: the hot path)
    if usable.all():
        eig = np.linalg.eigvalsh(scaled)
    else:
        eig = np.linalg.eigvalsh(np.where(usable[:, None, None], scaled, np.eye(info.shape[-1])))
    singular = usable & ((eig[:, 0] <= 0) | (eig[:, -1] > COND_LIMIT * eig[:, 0]))
    good = usable & ~singular
    safe = scaled if good.all() else np.where(good[:, None, None], scaled, np.eye(info.shape[-1]))
    inv = np.linalg.inv(safe) / d[:, :, None] / d[:, None, :]
    return inv, singular


def solve_standalone(
    obs: GnssObservations,
    x0_ecef_m: np.ndarray | None = None,
    *,
    max_iter: int = 10,
    tol_m: float = 1e-4,
    plausible_radius_m: tuple[float, float] | None = PLAUSIBLE_RADIUS_M,
) -> StandaloneSolution:
    """Standalone WLS position fix of every receiver (paper Eq. 14-17).

    Gauss-Newton iterations of ``dp = (G^T W G)^-1 G^T W a`` (Eq. 15) with
    ``W = C^-1`` (Eq. 16), ``C = diag(sigma_common^2 + sigma_user^2)`` (Eq. 3) and the
    geometry matrix ``G = [-1^T, e_sys]`` (Eq. 14). The iteration starts from zero (the
    paper's choice, the Earth's centre) unless ``x0_ecef_m`` is given. The returned
    covariance is ``H = (G^T C^-1 G)^-1`` (Eq. 17) at the solution.

    Parameters
    ----------
    obs : GnssObservations
        Pseudoranges of ``n_rx`` receivers.
    x0_ecef_m : ndarray, shape (n_rx, 3) or (3,), optional
        Initial positions [m]. Default: zeros.
    max_iter : int
        Maximum Gauss-Newton iterations (default 10; from zero about 6 are needed).
    tol_m : float
        Convergence threshold on the position update norm [m].
    plausible_radius_m : (float, float) or None
        Geocentric distance range [m] of a valid fix (default :data:`PLAUSIBLE_RADIUS_M`);
        a converged fix outside it gets ``IMPLAUSIBLE_POSITION`` (the spurious root of the
        pseudorange equations, see :class:`NavStatus`). ``None`` disables the check.

    Returns
    -------
    StandaloneSolution
        Receivers that see fewer than ``3 + (number of constellations seen)`` satellites get
        ``TOO_FEW_SATELLITES``; a numerically singular normal matrix gives
        ``SINGULAR_GEOMETRY``; both have NaN positions. Nothing is raised for such cases.
    """
    check_plausible_radius(plausible_radius_m)
    max_iter = check_iteration(max_iter, tol_m)
    n_rx = obs.pr_m.shape[0]
    n_sys = obs.n_systems
    vis = obs.visible
    pos = initial_positions(x0_ecef_m, n_rx)
    if _USE_KERNEL:
        pos, cov, clock, status, n_used, n_iter = _kernels.standalone_solve(
            np.ascontiguousarray(vis, dtype=bool),
            np.ascontiguousarray(obs.pr_m, dtype=float),
            np.ascontiguousarray(obs.sv_ecef_m, dtype=float),
            np.ascontiguousarray(obs.sigma_user_m, dtype=float),
            np.ascontiguousarray(obs.sigma_common_m, dtype=float),
            np.ascontiguousarray(obs.system, dtype=np.int64),
            int(n_sys),
            np.ascontiguousarray(pos),
            int(max_iter),
            float(tol_m),
            *_radius_args(plausible_radius_m),
        )
    else:
        pos, cov, clock, status, n_used, n_iter = _standalone_numpy(
            obs, pos, max_iter, tol_m, plausible_radius_m
        )
    return StandaloneSolution(
        pos_ecef_m=pos,
        cov_ecef_m2=cov,
        clock_m=clock,
        status=status,
        n_used=n_used,
        n_iter=int(n_iter),
    )


def _standalone_numpy(obs, pos, max_iter, tol_m, plausible_radius_m):
    """The numpy formulation of :func:`coopnav_env.nav._kernels.standalone_solve`."""
    vis = obs.visible
    n_sys = obs.n_systems
    w = np.where(vis, 1.0 / (obs.sigma_user_m**2 + obs.sigma_common_m[None, :] ** 2), 0.0)
    pr = np.where(vis, obs.pr_m, 0.0)
    onehot = np.eye(n_sys)[obs.system]  # (n_sv, n_sys)
    seen = np.einsum("rs,sk->rk", vis.astype(float), onehot) > 0  # (n_rx, n_sys)
    n_used = vis.sum(axis=1)
    too_few = n_used < 3 + seen.sum(axis=1)
    pos, clock, inv, converged, singular, n_iter = _gauss_newton_numpy(
        obs, pr, w, onehot, seen, ~too_few, pos, max_iter, tol_m
    )
    status, failed = fix_status(pos, converged, singular, too_few, plausible_radius_m)
    pos[failed] = np.nan
    cov = inv[:, :3, :3].copy()
    cov[failed] = np.nan
    clock = np.where(seen & ~failed[:, None], clock, np.nan)
    return pos, cov, clock, status, n_used, n_iter


def fix_status(
    pos: np.ndarray,
    converged: np.ndarray,
    singular: np.ndarray,
    too_few: np.ndarray,
    plausible_radius_m: tuple[float, float] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """:class:`NavStatus` of each fix (n,) and whether it failed (no position).

    In increasing precedence: ``OK``, ``NOT_CONVERGED``, ``IMPLAUSIBLE_POSITION`` (a
    converged fix outside ``plausible_radius_m``), ``SINGULAR_GEOMETRY``,
    ``TOO_FEW_SATELLITES``; the last two have failed. Shared by both solvers (a compiled
    helper; the numpy formulation is :func:`_fix_status_numpy`).
    """
    if not _USE_KERNEL:
        return _fix_status_numpy(pos, converged, singular, too_few, plausible_radius_m)
    return _kernels.fix_status(
        np.ascontiguousarray(pos, dtype=float),
        np.ascontiguousarray(converged, dtype=bool),
        np.ascontiguousarray(singular, dtype=bool),
        np.ascontiguousarray(too_few, dtype=bool),
        *_radius_args(plausible_radius_m),
    )


def _radius_args(plausible_radius_m: tuple[float, float] | None) -> tuple[bool, float, float]:
    """``plausible_radius_m`` as the kernels take it: ``(check, min, max)``."""
    if plausible_radius_m is None:
        return False, 0.0, 0.0
    lo, hi = plausible_radius_m
    return True, float(lo), float(hi)


def _fix_status_numpy(pos, converged, singular, too_few, plausible_radius_m):
    """The numpy formulation of :func:`fix_status`."""
    status = np.full(pos.shape[0], NavStatus.OK, dtype=np.int64)
    status[~converged] = NavStatus.NOT_CONVERGED
    status[converged & implausible_radius(pos, plausible_radius_m)] = NavStatus.IMPLAUSIBLE_POSITION
    status[singular] = NavStatus.SINGULAR_GEOMETRY
    status[too_few] = NavStatus.TOO_FEW_SATELLITES
    failed = (status == NavStatus.TOO_FEW_SATELLITES) | (status == NavStatus.SINGULAR_GEOMETRY)
    return status, failed


def _gauss_newton_numpy(obs, pr, w, onehot, seen, usable, pos, max_iter, tol_m):
    """The numpy formulation of the standalone Gauss-Newton loop (second implementation of
    :func:`coopnav_env.nav._kernels.standalone_gauss_newton`, used by the tests)."""
    n_rx, n_sv = pr.shape
    n_sys = seen.shape[1]
    clock = np.zeros((n_rx, n_sys))
    converged = np.zeros(n_rx, dtype=bool)
    n_iter = 0
    singular = np.zeros(n_rx, dtype=bool)
    inv = np.zeros((n_rx, 3 + n_sys, 3 + n_sys))
    for n_iter in range(1, max_iter + 1):  # noqa: B007 - n_iter is reported
        diff = obs.sv_ecef_m[None, :, :] - pos[:, None, :]
        rng_m = np.linalg.norm(diff, axis=-1)
        # a satellite at the iterate: no line of sight, the receiver's geometry is singular
        at_sat = np.any((rng_m == 0.0) & (w > 0.0), axis=1)
        los = diff / np.where(rng_m == 0.0, 1.0, rng_m)[..., None]
        # Rows of satellites not received carry zero weight (w = 0), so they drop out.
        g = np.concatenate([-los, np.broadcast_to(onehot, (n_rx, n_sv, n_sys))], axis=-1)
        resid = pr - rng_m - clock @ onehot.T
        info = np.einsum("rsp,rs,rsq->rpq", g, w, g)
        # Clock columns of constellations a receiver does not see carry no data.
        idx = np.arange(3, 3 + n_sys)
        info[:, idx, idx] += ~seen
        rhs = np.einsum("rsp,rs,rs->rp", g, w, resid)
        inv, singular = _safe_inverse(info, usable & ~at_sat)
        singular |= usable & at_sat
        dx = np.einsum("rpq,rq->rp", inv, rhs)
        dx[~usable | singular] = 0.0
        pos = pos + dx[:, :3]
        clock = clock + dx[:, 3:]
        step = np.linalg.norm(dx[:, :3], axis=1)
        converged = step < tol_m
        if np.all(converged | ~usable | singular):
            break
    return pos, clock, inv, converged, singular, n_iter
