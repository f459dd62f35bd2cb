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
    initial_positions,
    weak_geometry,
)

__all__ = ["StandaloneSolution", "pdop", "solve_standalone"]

#: A normal matrix whose diagonally scaled condition number exceeds this is reported singular
#: (the numpy solves of this package and the compiled kernels share the value).
COND_LIMIT = _kernels.COND_LIMIT


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
    pos = initial_positions(x0_ecef_m, n_rx)
    pos, cov, clock, status, n_used, n_iter = _standalone_solve(
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


def _standalone_solve(
    obs: GnssObservations,
    pos: np.ndarray,
    max_iter: int,
    tol_m: float,
    plausible_radius_m: tuple[float, float] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Every receiver's Gauss-Newton fix from the starting positions ``pos`` (n_rx, 3), by
    the compiled :func:`coopnav_env.nav._kernels.standalone_solve`.

    Returns ``pos (n_rx, 3), cov (n_rx, 3, 3), clock (n_rx, n_sys), status (n_rx,),
    n_used (n_rx,), n_iter`` as :class:`StandaloneSolution` holds them.
    """
    # the kernel's records (_kernels.Measured, SolverLimits) as plain tuples, which numba
    # types faster
    return _kernels.standalone_solve(
        (
            np.ascontiguousarray(obs.pr_m, dtype=float),
            np.ascontiguousarray(obs.visible, dtype=bool),
            np.ascontiguousarray(obs.sv_ecef_m, dtype=float),
            np.ascontiguousarray(obs.system, dtype=np.int64),
            np.ascontiguousarray(obs.sigma_user_m, dtype=float),
            np.ascontiguousarray(obs.sigma_common_m, dtype=float),
            np.ascontiguousarray(obs.el_deg, dtype=float),
            int(obs.n_systems),
        ),
        np.ascontiguousarray(pos),
        (int(max_iter), float(tol_m), *_radius_args(plausible_radius_m)),
    )


def _radius_args(plausible_radius_m: tuple[float, float] | None) -> tuple[bool, float, float]:
    """``plausible_radius_m`` as the kernels take it: ``(check, min, max)``."""
    if plausible_radius_m is None:
        return False, 0.0, 0.0
    lo, hi = plausible_radius_m
    return True, float(lo), float(hi)
