"""Inputs and outputs of the navigation solvers.

The solvers consume one epoch of the whole swarm: every UAV's pseudoranges (paper Eq. 1, after
the ionosphere-free combination), the satellite positions, the error model's standard deviations
(Eq. 3-8) and the relative position measurements between UAVs (Eq. 9). Everything is in ECEF
metres; :meth:`RelativePositions.from_enu` converts sensor outputs given in a local ENU frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from coopnav_env.constants import SYSTEMS

__all__ = [
    "PLAUSIBLE_RADIUS_M",
    "WEAK_GEOMETRY_SIGMA_M",
    "GnssObservations",
    "NavStatus",
    "RelativePositions",
    "VirtualPoint",
    "check_iteration",
    "initial_positions",
    "weak_geometry",
]


class NavStatus(IntEnum):
    """Outcome of one position fix. Degenerate cases are reported here, never raised.

    Attributes
    ----------
    OK
        A valid fix with its covariance: the solver converged on enough measurements. On
        ill-conditioned geometry (a near-singular normal matrix) it can be far from the truth,
        its covariance as large: test :func:`weak_geometry` (the solutions' ``weak_geometry``
        property). It says nothing of the measurements' consistency unless an integrity
        monitor tested the residuals (:mod:`coopnav_env.nav.integrity`; the environment's
        ``integrity`` setting): without one, a fix that uses a faulty pseudorange (a 1 km
        outlier) is OK too, its error far beyond its covariance.
    TOO_FEW_SATELLITES
        Fewer usable measurements than unknowns (standalone needs ``3 + N_const``; the
        cooperative DDT needs one satellite at the centroid UAV, SDT ``3 + N_const`` there).
    SINGULAR_GEOMETRY
        Enough measurements, but the normal matrix is numerically singular, or the
        linearisation is undefined: a satellite at the current iterate (its line of sight,
        the derivative of the range, has no direction).
    NOT_CONVERGED
        The Gauss-Newton iteration did not converge within ``max_iter``; the last iterate is
        returned.
    NO_RELATIVE_POSITION
        The UAV has no relative position measurement to a shared centroid (or master), so it
        cannot be located from it.
    IMPLAUSIBLE_POSITION
        The iteration converged, but to a point whose distance from the Earth's centre lies
        outside ``plausible_radius_m`` (default :data:`PLAUSIBLE_RADIUS_M`). The pseudorange
        equations have a second, spurious root; with no redundancy (as many measurements as
        unknowns) Gauss-Newton started at the Earth's centre, the paper's start, can converge
        to it, tens of thousands of km away, with a consistent (zero) residual. The last
        iterate and its covariance are returned for diagnosis, but the fix is not valid.
    FAULT_DETECTED
        Set only by the integrity monitor (:mod:`coopnav_env.nav.integrity`): its residual
        test found a fault that exclusion could not clear (no redundancy left to identify it,
        or the exclusion budget spent). The solver's fix with all measurements is returned
        for diagnosis, but it is not valid.
    """

    OK = 0
    TOO_FEW_SATELLITES = 1
    SINGULAR_GEOMETRY = 2
    NOT_CONVERGED = 3
    NO_RELATIVE_POSITION = 4
    IMPLAUSIBLE_POSITION = 5
    FAULT_DETECTED = 6


#: Default range of geocentric distance [m] of a plausible fix of a UAV: from 6,300 km (below
#: the polar radius 6,356.8 km by a margin) to 6,500 km (about 120 km above the equator).
PLAUSIBLE_RADIUS_M: tuple[float, float] = (6.3e6, 6.5e6)


#: Default limit [m] of :func:`weak_geometry`: an OK fix whose predicted 3-D standard deviation
#: ``sqrt(trace(cov))`` is larger has converged on ill-conditioned geometry (satellites in a
#: narrow cone, a near-singular normal matrix) and may lie far from the truth.
WEAK_GEOMETRY_SIGMA_M: float = 100.0


def weak_geometry(
    status: Any, cov_ecef_m2: Any, limit_m: float = WEAK_GEOMETRY_SIGMA_M
) -> np.ndarray:
    """Which OK fixes converged on ill-conditioned geometry: their predicted 3-D standard
    deviation ``sqrt(trace(cov_ecef_m2))`` exceeds ``limit_m``.

    ``NavStatus.OK`` says that the solver converged; when the satellites lie in a narrow cone
    the normal matrix is near-singular (still below the solvers' singular limit), the fix
    can be hundreds of metres to kilometres from the truth, and its covariance says so. The
    solvers' results expose this test as their ``weak_geometry`` property.

    Parameters
    ----------
    status : array_like of int, shape (n,)
        :class:`NavStatus` of each fix.
    cov_ecef_m2 : array_like, shape (n, 3, 3)
        Position covariance of each fix [m^2] (NaN where there is none).
    limit_m : float, default :data:`WEAK_GEOMETRY_SIGMA_M`
        Largest predicted 3-D standard deviation [m] of a fix of usable geometry, > 0.

    Returns
    -------
    ndarray of bool, shape (n,)
        True for OK fixes above the limit; False for the others (not OK fixes included).

    Raises
    ------
    ValueError
        ``limit_m`` is not a finite number > 0.
    """
    if isinstance(limit_m, bool) or not (isinstance(limit_m, (int, float, np.number))):
        raise ValueError(f"limit_m must be a finite number > 0, got {limit_m!r}")
    if not 0.0 < float(limit_m) < np.inf:
        raise ValueError(f"limit_m must be a finite number > 0, got {limit_m!r}")
    status = np.asarray(status)
    cov = np.asarray(cov_ecef_m2, dtype=float)
    trace = np.trace(cov, axis1=-2, axis2=-1)
    with np.errstate(invalid="ignore"):
        large = ~(trace <= float(limit_m) ** 2)  # NaN or inf covariance of an OK fix: weak
    return (status == NavStatus.OK) & large


def check_iteration(max_iter: Any, tol_m: Any) -> int:
    """Validate the Gauss-Newton limits of a solver; returns ``max_iter`` as an int.

    Raises
    ------
    ValueError
        ``max_iter`` is not an integer >= 1 (a bool, a float such as 2.5 or a string is
        refused), or ``tol_m`` is not a finite number > 0.
    """
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)):
        raise ValueError(f"max_iter must be an integer, got {max_iter!r}")
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter}")
    real = isinstance(tol_m, (int, float, np.integer, np.floating)) and not isinstance(tol_m, bool)
    if not real or not 0 < tol_m < np.inf:
        raise ValueError(f"tol_m must be a finite number > 0, got {tol_m!r}")
    return int(max_iter)


def initial_positions(x0_ecef_m: Any, n: int) -> np.ndarray:
    """The ``(n, 3)`` start of ``n`` Gauss-Newton problems from an ``x0_ecef_m`` argument.

    None gives zeros (the Earth's centre, Eq. 15's start); a ``(3,)`` point is shared by all.

    Raises
    ------
    ValueError
        Not numeric, another shape (checked before any arithmetic, so the message is ours
        and not numpy's broadcasting error), or NaN/inf.
    """
    x0 = np.zeros((n, 3))
    if x0_ecef_m is None:
        return x0
    try:
        given = np.asarray(x0_ecef_m, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"x0_ecef_m must be a numeric array, got {x0_ecef_m!r}") from None
    if given.shape not in ((3,), (n, 3)):
        raise ValueError(f"x0_ecef_m must have shape ({n}, 3) or (3,), got {given.shape}")
    if not np.all(np.isfinite(given)):
        raise ValueError("x0_ecef_m contains NaN or inf")
    return x0 + given


def check_plausible_radius(plausible_radius_m: tuple[float, float] | None) -> None:
    """Validate a ``plausible_radius_m`` argument (``None`` disables the check)."""
    if plausible_radius_m is None:
        return
    try:
        lo, hi = (float(v) for v in plausible_radius_m)
    except (TypeError, ValueError):
        raise ValueError(
            f"plausible_radius_m must be None or a pair (min, max) in m, got {plausible_radius_m!r}"
        ) from None
    if not (0.0 <= lo < hi and np.isfinite(hi)):
        raise ValueError(
            f"plausible_radius_m must satisfy 0 <= min < max < inf, got {plausible_radius_m!r}"
        )


def implausible_radius(
    pos_ecef_m: np.ndarray, plausible_radius_m: tuple[float, float] | None
) -> np.ndarray:
    """Boolean mask of finite positions outside the plausible geocentric shell."""
    if plausible_radius_m is None:
        return np.zeros(pos_ecef_m.shape[:-1], dtype=bool)
    r = np.linalg.norm(pos_ecef_m, axis=-1)
    lo, hi = plausible_radius_m
    return np.isfinite(r) & ((r < lo) | (r > hi))


def _as_float_array(name: str, value, shape: tuple[int | None, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


@dataclass(frozen=True)
class GnssObservations:
    """One epoch of pseudoranges for a swarm of ``n_rx`` receivers and ``n_sv`` satellites.

    Parameters
    ----------
    pr_m : ndarray, shape (n_rx, n_sv)
        Ionosphere-free pseudoranges [m] (paper Eq. 1); NaN where a satellite is not received.
    sv_ecef_m : ndarray, shape (n_sv, 3)
        Satellite positions in ECEF [m].
    system : ndarray of int, shape (n_sv,)
        Constellation index of each satellite into :data:`coopnav_env.constants.SYSTEMS`.
    sigma_user_m : ndarray, shape (n_rx, n_sv)
        Receiver-specific (multipath + noise, Eq. 6-8) standard deviation [m].
    sigma_common_m : ndarray, shape (n_sv,)
        Standard deviation [m] of the errors common to all receivers for one satellite
        (clock/ephemeris and troposphere, Eq. 4-5); 0 with differential correction.
    el_deg : ndarray, shape (n_rx, n_sv)
        Elevation [deg] of each satellite at each receiver (pivot selection for DDT).
    n_systems : int
        Number of constellations in the clock state (``N_const``); default ``len(SYSTEMS)``.
    """

    pr_m: np.ndarray
    sv_ecef_m: np.ndarray
    system: np.ndarray
    sigma_user_m: np.ndarray
    sigma_common_m: np.ndarray
    el_deg: np.ndarray
    n_systems: int = len(SYSTEMS)
    visible: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pr = np.asarray(self.pr_m, dtype=float)
        if pr.ndim != 2:
            raise ValueError(f"pr_m must have shape (n_rx, n_sv), got {pr.shape}")
        n_rx, n_sv = pr.shape
        sv = _as_float_array("sv_ecef_m", self.sv_ecef_m, (n_sv, 3))
        system = np.asarray(self.system)
        if system.shape != (n_sv,) or not np.issubdtype(system.dtype, np.integer):
            raise ValueError(f"system must be an integer array of shape ({n_sv},), got {system!r}")
        if not isinstance(self.n_systems, int | np.integer) or self.n_systems < 1:
            raise ValueError(f"n_systems must be a positive integer, got {self.n_systems!r}")
        if n_sv and (system.min() < 0 or system.max() >= self.n_systems):
            raise ValueError(
                f"system indices must lie in [0, {self.n_systems - 1}], got {np.unique(system)}"
            )
        su = _as_float_array("sigma_user_m", self.sigma_user_m, (n_rx, n_sv))
        sc = _as_float_array("sigma_common_m", self.sigma_common_m, (n_sv,))
        el = _as_float_array("el_deg", self.el_deg, (n_rx, n_sv))
        if not np.all(np.isfinite(sv)):
            raise ValueError("sv_ecef_m contains NaN or inf")
        visible = np.isfinite(pr)
        if np.any(np.isinf(pr)):
            raise ValueError("pr_m contains inf; use NaN for a satellite that is not received")
        if np.any(~np.isfinite(su[visible])) or np.any(su[visible] <= 0):
            bad = su[visible][~(np.isfinite(su[visible]) & (su[visible] > 0))][:3]
            raise ValueError(
                f"sigma_user_m must be finite and > 0 for every received satellite, got {bad}"
            )
        if np.any(~np.isfinite(sc)) or np.any(sc < 0):
            raise ValueError(f"sigma_common_m must be finite and >= 0, got {sc[~(sc >= 0)][:3]}")
        if np.any(~np.isfinite(el[visible])):
            raise ValueError("el_deg must be finite for every received satellite")
        self._store(pr, sv, system, su, sc, el, visible)

    def _store(self, pr, sv, system, su, sc, el, visible) -> None:
        """Set the fields from valid arrays (the one place that decides what is stored)."""
        # Values at satellites that are not received are irrelevant: store NaN there so that
        # nothing downstream can use them by accident.
        su = np.where(visible, su, np.nan)
        el = np.where(visible, el, np.nan)
        for name, arr in (
            ("pr_m", pr),
            ("sv_ecef_m", sv),
            ("system", system.astype(np.int64)),
            ("sigma_user_m", su),
            ("sigma_common_m", sc),
            ("el_deg", el),
        ):
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "visible", visible)

    @classmethod
    def _trusted_from_epoch(cls, epoch, n_systems: int = len(SYSTEMS)) -> GnssObservations:
        """:meth:`from_epoch` without the validation, for the simulator's own output.

        The simulator's arrays are valid by construction (shapes, finite where received, NaN
        elsewhere); the hot path of :class:`coopnav_env.sim.UrbanWorld` skips the checks. The
        stored fields are exactly those of :meth:`from_epoch` (same ``_store``).
        """
        out = object.__new__(cls)
        object.__setattr__(out, "n_systems", n_systems)
        out._store(
            epoch.pr_m,
            epoch.sv_ecef_m,
            epoch.system,
            epoch.sigma_user_m,
            epoch.sigma_common_m,
            epoch.el_deg,
            np.isfinite(epoch.pr_m),
        )
        return out

    @property
    def n_rx(self) -> int:
        """Number of receivers (UAVs)."""
        return self.pr_m.shape[0]

    @property
    def n_sv(self) -> int:
        """Number of satellites (visible or not) in the arrays."""
        return self.pr_m.shape[1]

    @classmethod
    def from_epoch(cls, epoch, n_systems: int = len(SYSTEMS)) -> GnssObservations:
        """Build from a :class:`coopnav_env.gnss.PseudorangeEpoch` (the simulator's output)."""
        return cls(
            pr_m=epoch.pr_m,
            sv_ecef_m=epoch.sv_ecef_m,
            system=epoch.system,
            sigma_user_m=epoch.sigma_user_m,
            sigma_common_m=epoch.sigma_common_m,
            el_deg=epoch.el_deg,
            n_systems=n_systems,
        )

    def subset_receivers(self, idx) -> GnssObservations:
        """The observations of the receivers ``idx`` only."""
        idx = np.atleast_1d(idx)
        return GnssObservations(
            pr_m=self.pr_m[idx],
            sv_ecef_m=self.sv_ecef_m,
            system=self.system,
            sigma_user_m=self.sigma_user_m[idx],
            sigma_common_m=self.sigma_common_m,
            el_deg=self.el_deg[idx],
            n_systems=self.n_systems,
        )


def _check_cov(name: str, cov: np.ndarray) -> None:
    if not np.all(np.isfinite(cov)):
        raise ValueError(f"{name} contains NaN or inf")
    if not np.allclose(cov, np.swapaxes(cov, -1, -2), rtol=1e-9, atol=1e-12):
        raise ValueError(f"{name} must be symmetric")
    if cov.size:
        eig_min = np.linalg.eigvalsh(cov).min()
        scale = max(float(np.abs(cov).max()), 1e-300)
        if eig_min < -1e-9 * scale:
            raise ValueError(f"{name} must be positive semi-definite (min eigenvalue {eig_min:g})")


@dataclass(frozen=True)
class RelativePositions:
    """Pairwise relative position measurements between the UAVs (paper Eq. 9), in ECEF.

    Parameters
    ----------
    rel_ecef_m : ndarray, shape (n_rx, n_rx, 3)
        ``rel_ecef_m[b, q]`` is the measured position of UAV ``q`` relative to UAV ``b``
        (``p_q - p_b + eps_bq``) [m]. The diagonal is zero.
    cov_ecef_m2 : ndarray, shape (n_rx, n_rx, 3, 3)
        Covariance ``C_d`` of each measurement [m^2]; the diagonal blocks are zero. Different
        pairs have independent errors (the paper's assumption, Appendix A case 2).
    available : ndarray of bool, shape (n_rx, n_rx)
        Whether the pair is within sensing range. The diagonal is ignored (a UAV always knows
        its own offset, zero).
    """

    rel_ecef_m: np.ndarray
    cov_ecef_m2: np.ndarray
    available: np.ndarray

    def __post_init__(self) -> None:
        rel = np.asarray(self.rel_ecef_m, dtype=float)
        if rel.ndim != 3 or rel.shape[0] != rel.shape[1] or rel.shape[2] != 3:
            raise ValueError(f"rel_ecef_m must have shape (n, n, 3), got {rel.shape}")
        n = rel.shape[0]
        cov = _as_float_array("cov_ecef_m2", self.cov_ecef_m2, (n, n, 3, 3))
        avail = np.asarray(self.available)
        if avail.shape != (n, n) or avail.dtype != bool:
            raise ValueError(f"available must be a bool array of shape ({n}, {n})")
        avail = avail.copy()
        np.fill_diagonal(avail, True)
        if not np.all(np.isfinite(rel[avail])):
            raise ValueError("rel_ecef_m contains NaN or inf for an available pair")
        _check_cov("cov_ecef_m2", cov[avail])
        self._store(rel, cov, avail)

    def _store(self, rel: np.ndarray, cov: np.ndarray, avail: np.ndarray) -> None:
        object.__setattr__(self, "rel_ecef_m", rel)
        object.__setattr__(self, "cov_ecef_m2", cov)
        object.__setattr__(self, "available", avail)

    @classmethod
    def _trusted(cls, rel: np.ndarray, cov: np.ndarray, available: np.ndarray) -> RelativePositions:
        """The constructor without its checks, for measurements valid by construction.

        :func:`coopnav_env.sim.swarm.measure_relative_positions` gives finite values and
        symmetric PSD covariances; skipping ``__post_init__``'s checks (an eigenvalue
        decomposition per pair, a millisecond for 50 UAVs) stores exactly the same arrays.
        """
        out = object.__new__(cls)
        avail = np.array(available, dtype=bool)  # a copy: the caller's array is not modified
        np.fill_diagonal(avail, True)
        out._store(rel, cov, avail)
        return out

    @property
    def n_rx(self) -> int:
        """Number of UAVs."""
        return self.rel_ecef_m.shape[0]

    @classmethod
    def from_enu(
        cls,
        rel_enu_m: np.ndarray,
        cov_enu_m2: np.ndarray,
        available: np.ndarray,
        lat_deg: float,
        lon_deg: float,
    ) -> RelativePositions:
        """Rotate ENU measurements into ECEF using the local frame at ``(lat_deg, lon_deg)``.

        The ENU inputs are what :func:`coopnav_env.sim.swarm.measure_relative_positions`
        returns: ``rel_enu_m`` (n, n, 3), ``cov_enu_m2`` (n, n, 3, 3), ``available`` (n, n).
        """
        from coopnav_env.gnss.frames import enu_rotation

        r = enu_rotation(lat_deg, lon_deg)  # d_enu = R d_ecef, so d_ecef = R^T d_enu
        rel = np.asarray(rel_enu_m, dtype=float) @ r
        cov = r.T @ np.asarray(cov_enu_m2, dtype=float) @ r
        return cls(rel_ecef_m=rel, cov_ecef_m2=cov, available=np.asarray(available, dtype=bool))

    @classmethod
    def exact(cls, pos_ecef_m: np.ndarray) -> RelativePositions:
        """Error-free, all-available relative positions of the given true positions (tests)."""
        pos = np.asarray(pos_ecef_m, dtype=float)
        n = pos.shape[0]
        return cls(
            rel_ecef_m=pos[None, :, :] - pos[:, None, :],
            cov_ecef_m2=np.zeros((n, n, 3, 3)),
            available=np.ones((n, n), dtype=bool),
        )


@dataclass(frozen=True)
class VirtualPoint:
    """A fixed virtual centroid that is not a UAV (paper Section 3.1, "a fixed point").

    Parameters
    ----------
    rel_ecef_m : ndarray, shape (n_rx, 3)
        Measured position of each UAV relative to the virtual point (``p_q - p_v + eps_q``) [m].
    cov_ecef_m2 : ndarray, shape (n_rx, 3, 3)
        Covariance of each of those measurements [m^2]; errors independent across UAVs.
    available : ndarray of bool, shape (n_rx,)
        Which UAVs have the measurement.
    """

    rel_ecef_m: np.ndarray
    cov_ecef_m2: np.ndarray
    available: np.ndarray

    def __post_init__(self) -> None:
        rel = np.asarray(self.rel_ecef_m, dtype=float)
        if rel.ndim != 2 or rel.shape[1] != 3:
            raise ValueError(f"VirtualPoint.rel_ecef_m must have shape (n, 3), got {rel.shape}")
        n = rel.shape[0]
        cov = _as_float_array("VirtualPoint.cov_ecef_m2", self.cov_ecef_m2, (n, 3, 3))
        avail = np.asarray(self.available)
        if avail.shape != (n,) or avail.dtype != bool:
            raise ValueError(f"VirtualPoint.available must be a bool array of shape ({n},)")
        if not np.all(np.isfinite(rel[avail])):
            raise ValueError("VirtualPoint.rel_ecef_m contains NaN or inf for an available UAV")
        _check_cov("VirtualPoint.cov_ecef_m2", cov[avail])
        object.__setattr__(self, "rel_ecef_m", rel)
        object.__setattr__(self, "cov_ecef_m2", cov)
        object.__setattr__(self, "available", avail)
