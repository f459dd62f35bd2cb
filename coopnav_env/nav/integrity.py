r"""Integrity monitoring: residual RAIM with fault detection and exclusion (FDE), protection levels.

A least-squares fix certifies itself through its covariance only while every measurement
follows the error model. A street canyon breaks that: a blocked satellite received by
reflection (NLOS) arrives with a positive bias of metres to hundreds of metres, and the
solvers of :mod:`coopnav_env.nav` report such a fix OK with a covariance of a few metres.
This module tests every fix against its own residuals, excludes what the test identifies, and
bounds the position error that a fault the test could miss can cause.

What is computed, per fix
-------------------------
*Model.* The linearised GLS of the solver at its fix: ``a = A x + N c + e`` with ``x`` the
position, ``N c`` the receivers' clocks and ``e ~ N(0, C)``. For
:func:`~coopnav_env.nav.solve_standalone`, ``C`` is diagonal (Eq. 3). For
:func:`~coopnav_env.nav.solve_cooperative` (SDT or DDT, any centroid) it is the exact
covariance ``C*`` of the transferred measurements (module docstring of
:mod:`coopnav_env.nav.cooperative`): errors common to all UAVs per satellite, per-receiver
errors, and each UAV's relative-position error projected on its lines of sight, so the rows
are correlated across UAVs (common errors) and within a UAV (its relative error); for DDT the
pivot errors correlate them further. We work in the undifferenced form (one clock per UAV and
constellation, all eliminated as nuisance parameters: the same column space as the solvers'
clock reference plus relative clocks, so the same residuals and position gains, without a
clock estimate), which gives DDT's estimate and residual statistic with the exact ``C*``
exactly (double differencing is a full-row-rank map whose null space is the clock columns;
``tests/nav/test_integrity.py`` checks the statistic against the literal double differences
with the dense ``C*`` of the solver's reference, ``cooperative._dense_system``), and whose
rows are the receivers' own pseudoranges, which is what a fault hits and what exclusion
removes. Nothing is formed densely: the elimination is the solver's (clocks and the rank-3
relative errors per UAV, then one solve for the common errors of the satellites in use), see
:mod:`coopnav_env.nav._integrity_kernels`.

*Test.* ``T = a^T R a`` with ``R = P - P A (A^T P A)^-1 A^T P``, ``A`` the position columns
and ``P`` the precision with the clocks eliminated: the minimum weighted sum of squared
residuals. Without a fault ``T ~ chi2(dof)`` with ``dof = measurements - clocks - 3``; a fault is
declared when ``T`` exceeds the ``1 - p_fa`` quantile (``p_fa`` default 1e-3 per test, as
RTKLIB). A bias ``b`` on row ``i`` makes ``T`` non-central with ``lambda = b^2 R_ii``.

*Identification: the largest normalised residual* (Baarda's w-test) with the residual
covariance: ``w_i = (R a)_i / sqrt(R_ii)``. We chose it over solution separation because (i)
with correlated rows each ``w_i`` is the uniformly most powerful invariant test of a bias on
row ``i``, and the largest one is the generalised likelihood-ratio choice among the
single-fault hypotheses; it uses the residual covariance ``R`` itself (the raw residual over
its own sigma would not: ``C`` is not diagonal); (ii) ``w_i^2`` is exactly the drop of ``T``
when row ``i`` is excluded, so the largest ``|w_i|`` names the exclusion that leaves the
smallest statistic -- what RTKLIB finds by re-solving once per satellite and what solution
separation approximates -- in one pass, without ``n`` re-solves; (iii) it needs nothing beyond
what the test computes. Rows that no residual can tell apart (``|w_i|`` equal, e.g. the only
two satellites of a constellation at the clock reference, where a bias on one and the opposite
bias on the other leave the same residuals) are a tie, broken toward the positive residual, the
sign of an NLOS bias (either exclusion leaves a set the test accepts). The identified row is
excluded, the fix re-solved by the solver's own kernels from the current fix (for the
cooperative solution with the solver's set-up, so DDT's pivot rule and SDT's availability rule
hold after the exclusion), and the test repeated until it passes, or identification is
impossible (fewer than 2 degrees of freedom: with 1, every ``|w_i|`` is equal), or
``max_exclusions`` is spent. A fault that cannot be cleared leaves the solver's original fix
with :attr:`NavStatus.FAULT_DETECTED` (not valid), never an exception.

*Protection levels.* Slope-based RAIM bound plus a fault-free term:
``HPL = max_i(|K_H,i| / sqrt(R_ii)) sqrt(lambda_md) + k_H sigma_major`` and
``VPL = max_i(|K_U,i| / sqrt(R_ii)) sqrt(lambda_md) + k_V sigma_U``, where ``K_i`` is the
shift of the fix per metre of bias on row ``i``, ``lambda_md`` the non-centrality the test
detects with probability ``1 - P_md`` (``P_md = integrity_risk``), ``sigma_major`` the
semi-major axis of the horizontal error ellipse, ``k_H = sqrt(-2 ln integrity_risk)`` (the
exact tail of ``chi2(2)``, which bounds any 2-D Gaussian through its major axis) and
``k_V = Phi^-1(1 - integrity_risk / 2)``. Why this bounds the misleading-information
probability by ``integrity_risk`` for a single fault of *any* size on any row (and for none):
if its ``lambda >= lambda_md`` the fault is missed with probability at most ``P_md``; if
``lambda < lambda_md`` its own shift is at most the slope term, so the error exceeds the PL
only when the noise exceeds the fault-free term, probability at most ``integrity_risk``. (The
classic slope-only bound, ``Slope_max sqrt(lambda)`` with no noise term, does not have this
property for faults just below the detectable size; the tests measure it.) A row whose fault
the residuals cannot see (``R_ii = 0``) but which moves the fix makes the PL infinite. After an
exclusion the PLs are those of the remaining set under the same single-fault assumption
(the risk of a wrong exclusion is not added; multiple simultaneous faults are outside the
bound, as in the classic RAIM it follows). For a UAV located from a shared centroid,
``sigma`` comes from its own covariance ``H_p`` (Eq. 19) and the slopes from the centroid's
rows (a GNSS fault moves the centroid; the UAV's offset is a relative measurement).

*Many simultaneous faults.* The identification assumes that the faults are few: with many
biased rows at once (street-canyon NLOS, about 40 % of the rows in the ``urban_nlos``
preset) the fix is pulled toward them and one-at-a-time exclusion can stop at a wrong fix
that passes (masking); ``fault_sign="positive"`` helps but does not cure it, and NLOS
delays of similar size on one UAV's satellites are absorbed by its clocks, invisible to any
residual test. The navigation core has no map; the environment's answer is to remove the
rows a 3-D city model predicts reflected before the test (3D-mapping-aided NLOS exclusion,
:mod:`coopnav_env.sim.map_aided`, ``nlos_exclusion="map"``), which leaves this FDE few
faults to deal with.

Compared with the public designs
--------------------------------
* RTKLIB (``pntpos.c``, ``valsol`` / ``raim_fde``): a chi-square test at 0.001 on the
  residuals normalised by their (diagonal) variances, a GDOP check; on failure, with at
  least 6 satellites, every single-satellite exclusion is re-solved and the one with the
  smallest residual RMS that passes is kept; one exclusion at most, no protection levels.
  Ours: the same test, but with the full covariance (for the cooperative fix ``C*``, which
  RTKLIB's diagonal weighting cannot express), one-pass identification, repeated exclusion,
  and protection levels.
* gnss_lib_py (``algorithms/fde.py``): a residual method with a fixed threshold on the
  unweighted RMS, and the greedy Euclidean-distance-matrix FDE (Knowles and Gao 2021), which
  needs one receiver's clock-corrected ranges to the satellites to build the EDM. Neither
  applies to transferred measurements at a virtual centroid with correlated rows and several
  receivers' clocks; the EDM test also has no false-alarm probability to configure.

Public entry points: :func:`fde_standalone`, :func:`fde_cooperative` (each returns the
solution after FDE and an :class:`IntegrityResult`), :func:`protection_factors`,
:func:`threshold_tables`, :func:`integrity_rates` (availability and misleading-information
rate from arrays of errors and protection levels, for evaluations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Literal

import numpy as np

from coopnav_env.nav import _integrity_kernels as _ik
from coopnav_env.nav.cooperative import (
    CooperativeSolution,
    _setup,
    _sort_by_system,
    solve_cooperative,
)
from coopnav_env.nav.types import (
    PLAUSIBLE_RADIUS_M,
    GnssObservations,
    RelativePositions,
    VirtualPoint,
    check_plausible_radius,
)
from coopnav_env.nav.wls import StandaloneSolution, _radius_args, solve_standalone

__all__ = [
    "DEFAULT_INTEGRITY_RISK",
    "DEFAULT_P_FA",
    "IntegrityRates",
    "IntegrityResult",
    "IntegrityStatus",
    "fde_cooperative",
    "fde_standalone",
    "integrity_rates",
    "protection_factors",
    "threshold_tables",
]

#: Default false-alarm probability of one residual test.
DEFAULT_P_FA: float = 1e-3
#: Default integrity risk of one fix (missed-detection allocation and fault-free tail).
DEFAULT_INTEGRITY_RISK: float = 1e-7


class IntegrityStatus(IntEnum):
    """Outcome of the integrity monitor for one fix (degenerate cases are statuses).

    Attributes
    ----------
    OK
        The test passed with every measurement; the protection levels hold.
    EXCLUDED
        The test failed, measurement(s) were excluded and the re-solved fix passes; the
        protection levels are those of the remaining measurements.
    FAULT_DETECTED
        The test failed and exclusion could not clear it; the fix carries
        :attr:`NavStatus.FAULT_DETECTED` and must not be used (protection levels infinite).
    NO_REDUNDANCY
        A valid fix without a degree of freedom to test (as many measurements as unknowns):
        nothing can be detected, the protection levels are infinite.
    NO_FIX
        The solver gave no valid fix (its :class:`NavStatus` says why).
    """

    OK = _ik.INT_OK
    EXCLUDED = _ik.INT_EXCLUDED
    FAULT_DETECTED = _ik.INT_FAULT_DETECTED
    NO_REDUNDANCY = _ik.INT_NO_REDUNDANCY
    NO_FIX = _ik.INT_NO_FIX


@dataclass(frozen=True)
class IntegrityResult:
    """The integrity monitor's figures for ``n`` fixes (one per UAV).

    Attributes
    ----------
    status : ndarray of int, shape (n,)
        :class:`IntegrityStatus` of each fix.
    fault_detected : ndarray of bool, shape (n,)
        The first test of the solver's fix failed (whether or not exclusion cleared it).
    n_excluded : ndarray of int, shape (n,)
        Pseudoranges excluded from the returned fix.
    excluded : ndarray of bool, shape (n, n_rx, n_sv)
        ``excluded[f, q, k]``: UAV ``q``'s pseudorange to satellite ``k`` (the observations'
        satellite order) was excluded from fix ``f``.
    test_statistic : ndarray, shape (n,)
        ``T`` of the returned fix's measurements (for FAULT_DETECTED: of the solver's fix);
        NaN where no test ran.
    threshold : ndarray, shape (n,)
        The chi-square threshold ``T`` was compared with; NaN where no test ran.
    dof : ndarray of int, shape (n,)
        Degrees of freedom of the test.
    hpl_m, vpl_m : ndarray, shape (n,)
        Horizontal and vertical protection levels [m]; inf unless status is OK or EXCLUDED.
    p_fa, integrity_risk : float
        The false-alarm probability per test and the integrity risk used.
    """

    status: np.ndarray
    fault_detected: np.ndarray
    n_excluded: np.ndarray
    excluded: np.ndarray
    test_statistic: np.ndarray
    threshold: np.ndarray
    dof: np.ndarray
    hpl_m: np.ndarray
    vpl_m: np.ndarray
    p_fa: float
    integrity_risk: float

    @property
    def usable(self) -> np.ndarray:
        """Fixes whose test passed (status OK or EXCLUDED), shape (n,)."""
        return (self.status == IntegrityStatus.OK) | (self.status == IntegrityStatus.EXCLUDED)

    def available(self, alert_limit_m: float, vertical_alert_limit_m: float | None = None):
        """Fixes whose HPL (and VPL, if a vertical limit is given) is within the limit."""
        ok = self.hpl_m <= alert_limit_m
        if vertical_alert_limit_m is not None:
            ok &= self.vpl_m <= vertical_alert_limit_m
        return ok


# --------------------------------------------------------------------------------------------
# parameters
# --------------------------------------------------------------------------------------------


def _check_probability(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in (0, 0.5], got {value!r}") from None
    if not (0.0 < v <= 0.5):
        raise ValueError(f"{name} must be in (0, 0.5], got {value!r}")
    return v


def protection_factors(integrity_risk: float = DEFAULT_INTEGRITY_RISK) -> tuple[float, float]:
    """The fault-free multipliers ``(k_H, k_V)`` of the protection levels for a risk.

    ``k_H = sqrt(-2 ln risk)``: ``P(|e_H| > k sigma_major) <= P(chi2(2) > k^2) = exp(-k^2/2)``
    for any 2-D Gaussian error. ``k_V = Phi^-1(1 - risk / 2)`` (two-sided normal tail).
    """
    ir = _check_probability("integrity_risk", integrity_risk)
    return math.sqrt(-2.0 * math.log(ir)), -float(_ik.norm_ppf(0.5 * ir))


_TABLES: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}


def threshold_tables(
    p_fa: float = DEFAULT_P_FA,
    integrity_risk: float = DEFAULT_INTEGRITY_RISK,
    dof_max: int = 64,
) -> tuple[np.ndarray, np.ndarray]:
    """Chi-square thresholds and detectable non-centralities per degree of freedom.

    Returns ``thr, lam`` of length at least ``dof_max + 1``: ``thr[d]`` is the ``1 - p_fa``
    quantile of ``chi2(d)`` and ``lam[d]`` the non-centrality with
    ``P(chi2(d, lam) < thr[d]) = integrity_risk`` (entry 0: NaN). Computed by the compiled
    distribution functions, cached per ``(p_fa, integrity_risk)`` and grown on demand; the
    arrays are read-only.
    """
    p_fa = _check_probability("p_fa", p_fa)
    ir = _check_probability("integrity_risk", integrity_risk)
    if not isinstance(dof_max, int | np.integer) or dof_max < 1:
        raise ValueError(f"dof_max must be a positive integer, got {dof_max!r}")
    key = (p_fa, ir)
    hit = _TABLES.get(key)
    if hit is None or hit[0].shape[0] <= dof_max:
        size = max(int(dof_max), 64 if hit is None else 2 * (hit[0].shape[0] - 1))
        thr, lam = _ik.threshold_tables(p_fa, ir, size)
        thr.flags.writeable = False
        lam.flags.writeable = False
        hit = (thr, lam)
        _TABLES[key] = hit
    return hit


def _positive_only(fault_sign: str) -> bool:
    if fault_sign not in ("any", "positive"):
        raise ValueError(f"fault_sign must be 'any' or 'positive', got {fault_sign!r}")
    return fault_sign == "positive"


def _max_exclusions(max_exclusions: int | None) -> int:
    if max_exclusions is None:
        return 1 << 30
    if (
        not isinstance(max_exclusions, int | np.integer)
        or isinstance(max_exclusions, bool)
        or max_exclusions < 0
    ):
        raise ValueError(f"max_exclusions must be None or an integer >= 0, got {max_exclusions!r}")
    return int(max_exclusions)


def _enu_rotations(pos_ecef_m: np.ndarray) -> np.ndarray:
    """ECEF -> ENU rotations at each position (n, 3) (identity where not finite)."""
    from coopnav_env.gnss.frames import ecef_to_geodetic, enu_rotation

    pos = np.asarray(pos_ecef_m, dtype=float)
    out = np.broadcast_to(np.eye(3), (pos.shape[0], 3, 3)).copy()
    good = np.all(np.isfinite(pos), axis=1) & (np.linalg.norm(pos, axis=1) > 1.0)
    if good.any():
        lat, lon, _h = ecef_to_geodetic(pos[good])
        out[good] = enu_rotation(lat, lon)
    return out


def _observation_arrays(obs: GnssObservations) -> tuple:
    """The kernels' ``obs`` tuple: ``(vis, pr, sigma_user, sigma_common, sv, system, n_sys,
    el)``, writable copies where an exclusion edits copies of them."""
    return (
        np.array(obs.visible, dtype=bool),
        np.array(obs.pr_m, dtype=float),
        np.ascontiguousarray(obs.sigma_user_m, dtype=float),
        np.ascontiguousarray(obs.sigma_common_m, dtype=float),
        np.ascontiguousarray(obs.sv_ecef_m, dtype=float),
        np.ascontiguousarray(obs.system, dtype=np.int64),
        int(obs.n_systems),
        np.array(obs.el_deg, dtype=float),
    )


def _solver_settings(max_iter: int, tol_m: float, plausible_radius_m) -> tuple:
    """The kernels' ``solver`` tuple: ``(max_iter, tol_m, check, r_lo, r_hi)``."""
    return (int(max_iter), float(tol_m), *_radius_args(plausible_radius_m))


def _rotations(enu_rotation: np.ndarray | None, pos_ecef_m: np.ndarray) -> np.ndarray:
    """One rotation per position: ``enu_rotation`` for all, or the local frame at each."""
    if enu_rotation is None:
        return _enu_rotations(pos_ecef_m)
    r = np.asarray(enu_rotation, dtype=float)
    if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9):
        raise ValueError(f"enu_rotation must be a (3, 3) rotation matrix, got {enu_rotation!r}")
    return np.ascontiguousarray(np.broadcast_to(r, (pos_ecef_m.shape[0], 3, 3)))


def _protection_levels(istat, dof, h_slope, v_slope, cov, rot, lam, k_h, k_v):
    """HPL and VPL per fix (inf unless the test passed)."""
    n = istat.shape[0]
    hpl = np.full(n, np.inf)
    vpl = np.full(n, np.inf)
    for f in range(n):
        if istat[f] in (_ik.INT_OK, _ik.INT_EXCLUDED):
            hpl[f], vpl[f] = _ik.protection_level(
                h_slope[f], v_slope[f], math.sqrt(lam[dof[f]]), cov[f], rot[f], k_h, k_v
            )
    return hpl, vpl


def _result(istat, detected, n_excl, excluded, t_stat, dof, hpl, vpl, thr, p_fa, ir):
    tested = np.isfinite(t_stat) & (dof >= 1)
    threshold = np.where(tested, thr[np.maximum(dof, 0)], np.nan)
    return IntegrityResult(
        status=np.asarray(istat, dtype=np.int64),
        fault_detected=np.asarray(detected, dtype=bool),
        n_excluded=np.asarray(n_excl, dtype=np.int64),
        excluded=excluded,
        test_statistic=np.where(tested, t_stat, np.nan),
        threshold=threshold,
        dof=np.asarray(dof, dtype=np.int64),
        hpl_m=hpl,
        vpl_m=vpl,
        p_fa=p_fa,
        integrity_risk=ir,
    )


# --------------------------------------------------------------------------------------------
# standalone
# --------------------------------------------------------------------------------------------


def fde_standalone(
    obs: GnssObservations,
    solution: StandaloneSolution | None = None,
    *,
    x0_ecef_m: np.ndarray | None = None,
    p_fa: float = DEFAULT_P_FA,
    integrity_risk: float = DEFAULT_INTEGRITY_RISK,
    max_exclusions: int | None = None,
    max_iter: int = 10,
    tol_m: float = 1e-4,
    plausible_radius_m: tuple[float, float] | None = PLAUSIBLE_RADIUS_M,
    enu_rotation: np.ndarray | None = None,
    fault_sign: Literal["any", "positive"] = "any",
) -> tuple[StandaloneSolution, IntegrityResult]:
    """RAIM FDE and protection levels of every receiver's standalone WLS fix.

    Parameters
    ----------
    obs : GnssObservations
    solution : StandaloneSolution, optional
        The fixes of ``obs`` by :func:`~coopnav_env.nav.solve_standalone` (solved here with
        ``x0_ecef_m``, ``max_iter``, ``tol_m``, ``plausible_radius_m`` when omitted).
    p_fa : float
        False-alarm probability of each chi-square test, in (0, 0.5]; default 1e-3.
    integrity_risk : float
        Integrity risk of a fix (missed-detection allocation and fault-free tail of the
        protection levels), in (0, 0.5]; default 1e-7.
    max_exclusions : int or None
        Exclusions allowed per fix; ``None`` (default): until the test passes or redundancy
        runs out; 0: detection only (a failing fix becomes ``FAULT_DETECTED``).
    max_iter, tol_m, plausible_radius_m
        Solver settings of the re-solves (those of :func:`solve_standalone`).
    enu_rotation : ndarray, shape (3, 3), optional
        The ECEF -> ENU rotation that splits horizontal and vertical for every fix (e.g. a
        city's local frame); default: the local frame at each fix.
    fault_sign : {"any", "positive"}
        ``"positive"``: identify (and exclude) only among measurements with a positive
        normalised residual, for faults known to be positive range biases (NLOS reception:
        a reflected signal arrives late). Under many simultaneous NLOS faults the fix is
        pulled toward them and good measurements can show the largest residuals, of the
        opposite sign; the one-sided choice never excludes those. Detection stays two-sided.

    Returns
    -------
    solution : StandaloneSolution
        The fixes after exclusion; a fault that could not be cleared leaves the solver's fix
        with status ``FAULT_DETECTED``.
    result : IntegrityResult
        Per receiver.
    """
    p_fa = _check_probability("p_fa", p_fa)
    ir = _check_probability("integrity_risk", integrity_risk)
    max_excl = _max_exclusions(max_exclusions)
    _positive_only(fault_sign)
    check_plausible_radius(plausible_radius_m)
    if solution is None:
        solution = solve_standalone(
            obs, x0_ecef_m, max_iter=max_iter, tol_m=tol_m, plausible_radius_m=plausible_radius_m
        )
    elif solution.pos_ecef_m.shape != (obs.n_rx, 3):
        raise ValueError(
            f"solution is for {solution.pos_ecef_m.shape[0]} receivers, observations for {obs.n_rx}"
        )
    thr, lam = threshold_tables(p_fa, ir, max(obs.n_sv, 1))
    k_h, k_v = protection_factors(ir)
    pos = np.array(solution.pos_ecef_m, dtype=float)
    cov = np.array(solution.cov_ecef_m2, dtype=float)
    clock = np.array(solution.clock_m, dtype=float)
    status = np.array(solution.status, dtype=np.int64)
    n_used = np.array(solution.n_used, dtype=np.int64)
    rot = _rotations(enu_rotation, pos)
    istat, detected, n_excl, excl, t_stat, dof, h_sl, v_sl = _ik.standalone_fde(
        _observation_arrays(obs),
        _solver_settings(max_iter, tol_m, plausible_radius_m),
        (pos, cov, clock, status, n_used),
        rot,
        (thr, max_excl, _positive_only(fault_sign)),
    )
    hpl, vpl = _protection_levels(istat, dof, h_sl, v_sl, cov, rot, lam, k_h, k_v)
    n = obs.n_rx
    excluded = np.zeros((n, n, obs.n_sv), dtype=bool)
    excluded[np.arange(n), np.arange(n)] = excl
    out = replace(
        solution, pos_ecef_m=pos, cov_ecef_m2=cov, clock_m=clock, status=status, n_used=n_used
    )
    return out, _result(istat, detected, n_excl, excluded, t_stat, dof, hpl, vpl, thr, p_fa, ir)


# --------------------------------------------------------------------------------------------
# cooperative
# --------------------------------------------------------------------------------------------


def fde_cooperative(
    obs: GnssObservations,
    rel: RelativePositions | None,
    solution: CooperativeSolution | None = None,
    *,
    transfer: Literal["sdt", "ddt"] = "ddt",
    centroid: str | int | VirtualPoint = "self",
    x0_ecef_m: np.ndarray | None = None,
    sdt_min_centroid_sats: int | None = None,
    p_fa: float = DEFAULT_P_FA,
    integrity_risk: float = DEFAULT_INTEGRITY_RISK,
    max_exclusions: int | None = None,
    max_iter: int = 10,
    tol_m: float = 1e-4,
    plausible_radius_m: tuple[float, float] | None = PLAUSIBLE_RADIUS_M,
    enu_rotation: np.ndarray | None = None,
    fault_sign: Literal["any", "positive"] = "any",
) -> tuple[CooperativeSolution, IntegrityResult]:
    """RAIM FDE and protection levels of the virtual-centroid cooperative fixes.

    One test per centroid problem (``centroid="self"``: one per UAV, each over the
    measurements of every UAV linked to it), on all transferred measurements with their exact
    covariance ``C*``; exclusion removes one UAV's pseudorange to one satellite from that
    problem and re-solves it.

    Parameters
    ----------
    obs, rel, transfer, centroid, x0_ecef_m, sdt_min_centroid_sats, max_iter, tol_m,
    plausible_radius_m
        As :func:`~coopnav_env.nav.solve_cooperative` (the covariance is always
        ``"exact"``: the test's distribution is known only with the true covariance).
    solution : CooperativeSolution, optional
        The solution of exactly this problem by ``solve_cooperative(...,
        covariance="exact")``; solved here when omitted.
    p_fa, integrity_risk, max_exclusions, enu_rotation, fault_sign
        As :func:`fde_standalone` (the rotation default: the frame at each centroid).

    Returns
    -------
    solution : CooperativeSolution
        After exclusion (a fault that could not be cleared: the solver's fix with status
        ``FAULT_DETECTED``).
    result : IntegrityResult
        Per UAV (its fix: its own centroid's, or the shared centroid's plus its offset).
    """
    p_fa = _check_probability("p_fa", p_fa)
    ir = _check_probability("integrity_risk", integrity_risk)
    max_excl = _max_exclusions(max_exclusions)
    _positive_only(fault_sign)
    check_plausible_radius(plausible_radius_m)
    if transfer not in ("sdt", "ddt"):
        raise ValueError(f"transfer must be 'sdt' or 'ddt', got {transfer!r}")
    if solution is None:
        solution = solve_cooperative(
            obs,
            rel,
            transfer=transfer,
            centroid=centroid,
            covariance="exact",
            x0_ecef_m=x0_ecef_m,
            sdt_min_centroid_sats=sdt_min_centroid_sats,
            max_iter=max_iter,
            tol_m=tol_m,
            plausible_radius_m=plausible_radius_m,
        )
    obs_s, order = _sort_by_system(obs)
    st = _setup(obs_s, rel, centroid, transfer, sdt_min_centroid_sats, "exact")
    n_b = st.ref.shape[0]
    n, s = obs.n_rx, obs.n_sv
    self_c = isinstance(centroid, str)
    if solution.centroid_pos_ecef_m.shape != (n_b, 3) or solution.pos_ecef_m.shape != (n, 3):
        raise ValueError("solution does not belong to these observations and centroid choice")
    thr, lam = threshold_tables(p_fa, ir, max(n * s, 1))
    k_h, k_v = protection_factors(ir)
    c_pos = np.array(solution.centroid_pos_ecef_m, dtype=float)
    c_clk = np.array(solution.centroid_clock_m, dtype=float)
    c_status = np.array(solution.centroid_status, dtype=np.int64)
    h_star = np.array(solution.centroid_cov_ecef_m2, dtype=float)
    n_uavs = np.array(solution.n_uavs_used, dtype=np.int64)
    n_meas = np.array(solution.n_meas_used, dtype=np.int64)
    if self_c:
        uav_pos, uav_cov = np.zeros((n_b, 0, 3)), np.zeros((n_b, 0, 3, 3))
        uav_status = np.zeros((n_b, 0), dtype=np.int64)
    else:
        uav_pos = np.array(solution.pos_ecef_m, dtype=float)[None]
        uav_cov = np.array(solution.cov_ecef_m2, dtype=float)[None]
        uav_status = np.array(solution.status, dtype=np.int64)[None]
    rot = _rotations(enu_rotation, c_pos)
    need = -1 if sdt_min_centroid_sats is None else int(sdt_min_centroid_sats)
    setup = (st.base, st.bcov, st.froot, st.avail, st.centroid_uav, transfer == "ddt", need)
    sol = (c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status)
    istat, detected, n_excl, excl, t_stat, dof, h_sl, v_sl = _ik.cooperative_fde(
        _observation_arrays(obs_s),
        (*(np.ascontiguousarray(a) for a in setup[:4]), *setup[4:], not self_c),
        _solver_settings(max_iter, tol_m, plausible_radius_m),
        sol,
        rot,
        (thr, max_excl, _positive_only(fault_sign)),
    )
    if order is not None:  # back to the caller's satellite order
        inv_order = np.empty_like(order)
        inv_order[order] = np.arange(order.size)
        excl = excl[:, :, inv_order]
    if self_c:
        prob = np.arange(n)
        pos, cov, status = c_pos, h_star, c_status.copy()
        f_istat = istat
    else:
        prob = np.zeros(n, dtype=np.int64)
        pos, cov, status = uav_pos[0], uav_cov[0], uav_status[0]
        linked = st.avail[0]
        f_istat = np.where(linked, istat[0], _ik.INT_NO_FIX)
    hpl, vpl = _protection_levels(
        f_istat, dof[prob], h_sl[prob], v_sl[prob], cov, rot[prob], lam, k_h, k_v
    )
    out = replace(
        solution,
        pos_ecef_m=pos,
        cov_ecef_m2=cov,
        status=status,
        centroid_pos_ecef_m=c_pos,
        centroid_cov_ecef_m2=h_star,
        centroid_clock_m=c_clk,
        centroid_status=c_status,
        n_uavs_used=n_uavs,
        n_meas_used=n_meas,
    )
    result = _result(
        f_istat,
        detected[prob],
        n_excl[prob],
        excl[prob],
        t_stat[prob],
        dof[prob],
        hpl,
        vpl,
        thr,
        p_fa,
        ir,
    )
    return out, result


# --------------------------------------------------------------------------------------------
# evaluation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class IntegrityRates:
    """Availability and misleading-information figures over a set of fixes.

    Attributes
    ----------
    n : int
        Fixes counted.
    availability : float
        Share with a protection level at or below the alert limit.
    misleading_rate : float
        Share whose true error exceeds its (finite) protection level (misleading
        information, MI).
    hazardous_rate : float
        Share declared available (PL <= alert limit) whose true error exceeds the alert
        limit (hazardously misleading information, HMI).
    """

    n: int
    availability: float
    misleading_rate: float
    hazardous_rate: float


def integrity_rates(
    error_m: np.ndarray, protection_level_m: np.ndarray, alert_limit_m: float
) -> IntegrityRates:
    """Availability, MI and HMI rates from arrays of true errors and protection levels.

    Parameters
    ----------
    error_m : array_like
        True position errors [m] of the same kind as the protection levels (e.g. horizontal
        errors with HPLs). NaN (no fix) counts as neither available nor misleading.
    protection_level_m : array_like, same shape
        Protection levels [m]; inf, NaN or negative (the environment's infos report -1):
        not available.
    alert_limit_m : float
        Alert limit [m], > 0.

    Returns
    -------
    IntegrityRates
        Each rate over all ``n`` entries (an unavailable fix counts in the denominator);
        NaN rates for ``n = 0``.
    """
    err = np.asarray(error_m, dtype=float).ravel()
    pl = np.asarray(protection_level_m, dtype=float).ravel()
    if err.shape != pl.shape:
        raise ValueError(
            f"error_m and protection_level_m must have the same size, got {err.size} and {pl.size}"
        )
    with np.errstate(invalid="ignore"):
        pl = np.where(pl >= 0.0, pl, np.inf)  # -1 (the infos) or NaN: no protection level
    try:
        al = float(alert_limit_m)
    except (TypeError, ValueError):
        raise ValueError(f"alert_limit_m must be a number > 0, got {alert_limit_m!r}") from None
    if not (al > 0.0 and math.isfinite(al)):
        raise ValueError(f"alert_limit_m must be finite and > 0, got {alert_limit_m!r}")
    n = err.size
    if n == 0:
        return IntegrityRates(0, math.nan, math.nan, math.nan)
    with np.errstate(invalid="ignore"):
        available = pl <= al
        misleading = np.isfinite(pl) & (err > pl)
        hazardous = available & (err > al)
    return IntegrityRates(
        n=int(n),
        availability=float(available.mean()),
        misleading_rate=float(misleading.mean()),
        hazardous_rate=float(hazardous.mean()),
    )
