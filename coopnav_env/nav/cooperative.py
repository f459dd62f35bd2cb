r"""Cooperative navigation by measurement transfer to a virtual centroid (paper Sections 2.3-3.3).

Every UAV's pseudoranges are transferred to a virtual centroid with the measured relative
positions, by single (SDT, Eq. 10-11) or double (DDT, Eq. 12-13) differenced transfer; one WLS
(Eq. 14-16) over all transferred measurements gives the centroid's position and its covariance
``H*`` (Eq. 17-18); each UAV's position is the centroid's plus its relative position, with the
covariance ``H_p`` of Eq. 19-23.

What this module does exactly, and where it departs from the paper
-------------------------------------------------------------------
Signs and frames.  ``1^k`` points from the receiver to satellite ``k``. The baseline of UAV ``q``
is its measured position relative to the centroid, ``x_q = p_q - p_c + eps_q``. Transfer moves a
pseudorange from ``p_q`` to ``p_c``: ``rho_c = rho_q - (|s - (p_c + x_q)| - |s - p_c|)``, which to
first order is the paper's Eq. 11 (``1 . x``). We evaluate the range difference exactly at the
current iterate instead of with a shared LOS vector, so transfer adds no linearisation error even
for baselines of hundreds of metres (the paper's approximation errs by ``|x|^2 / 2d``, about
0.25 mm per 100 m). The error of a transferred measurement then contains ``+1^k . eps_q`` and the
UAV's position error ``p_c~ + eps_q``, which is the sign convention of the paper's Appendix B.

Clocks.  Each receiver has one clock state per constellation (state length ``3 + N_const``).
The centroid's clocks are those of the *clock reference* UAV: the centroid UAV itself, or for a
:class:`VirtualPoint` the UAV that sees the most satellites.

SDT.  Eq. 10 needs the relative clock bias between each UAV and the centroid. We estimate those
``N_const`` relative clocks per UAV jointly with the centroid (as nuisance parameters eliminated
block by block), which is the between-receiver DGNSS estimate of the paper done inside the same
WLS, with its error propagated exactly instead of ignored. The paper's availability rule is kept:
a UAV that is its own centroid needs ``3 + N_const`` satellites of its own for SDT (configurable).

DDT.  Eq. 12 with a pivot per constellation: the highest-elevation satellite of that constellation
at the clock reference UAV that the transferring UAV also sees. A single pivot across
constellations would leave the difference of two receivers' inter-system biases in every
transferred measurement, so a UAV's measurements of a constellation are transferred only when it
shares a satellite of that constellation with the reference. The transferred pivot row itself is
an exact copy of the reference's own measurement and is not used twice. DDT needs one satellite
at the centroid UAV (paper Section 2.3).

Exact covariance (default, ``covariance="exact"``).  The paper's Eq. 18 is exact only for SDT
with an isotropic ``C_d`` and a centroid that is not a UAV. In general the error of the
transferred measurement ``(q, k)`` is, from the independent sources (common error ``e_c^k`` per
satellite, user error ``e_u`` per receiver and satellite, relative error ``eps_q``):

* SDT: ``e_c^k + e_u,q^k + 1_q^k . eps_q`` (and ``-dt_q``, estimated);
* DDT, ``q`` not the reference ``r``:
  ``e_c^k + e_u,q^k - e_u,q^j + e_u,r^j + (1_q^k - 1_q^j) . eps_q`` -- the relative error
  projects on a *difference* of LOS vectors and the pivot errors ``e_u,q^j`` (within a UAV)
  and ``e_u,r^j`` (across all UAVs) correlate rows;
* rows of a UAV that is its own centroid carry no relative error at all.

``C* = B Sigma B^T`` over those sources. The DDT estimate with this exact ``C*`` is identical to
the estimate from the undifferenced measurements with one nuisance clock per UAV and
constellation, because double differencing is a full-row-rank map whose null space is exactly
those clock columns (the classic equivalence of differenced and undifferenced least squares).
The structured solver uses that form; ``method="dense"`` builds the literal transferred
measurements and the dense ``C*`` and inverts it, and the tests show both agree to 1e-9.

Paper covariance (``covariance="paper"``).  Eq. 18 literally, for reproduction: ``sigma_d^2``
from ``1^j C_d 1^k`` including the centroid UAV's own rows, no pivot correlations, and Eq. 19-22
for ``H_p``. Eq. 19 writes ``(1 + 2 S E_p) C_d``, which is not symmetric; we use its symmetric
form ``H* + C_d + S E_p C_d + (S E_p C_d)^T``, which is what Appendix B's ``2 cov(.,.)`` means.

Ideal case (Eq. 24).  With co-located UAVs in open sky, differential correction and error-free
relative positions, ``H* = H / N_v`` holds exactly for SDT and DDT (see the tests).

Structure and speed.  ``C*`` is never formed or inverted densely. It is a block-diagonal part
per UAV (diagonal user errors plus a rank-3 relative-error term) plus a rank-``n_sv`` term of
errors common to all UAVs. We write each low-rank term as a latent variable with a unit prior
and eliminate, in order: the per-UAV latent (Woodbury with a 3x3 solve per UAV), the per-UAV
nuisance clocks (an ``N_const x N_const`` solve per UAV), and the common errors (one
``n_sv x n_sv`` Cholesky). For the exact model the Gauss-Newton loop runs in a compiled kernel
(:mod:`coopnav_env.nav._kernels`, numba), one loop per centroid problem; the numpy formulation
here (batched over UAVs and centroids) serves the paper's covariance and the literal DDT (the
tests also run it on the exact model, as the second implementation of the kernel).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from coopnav_env.nav import _kernels
from coopnav_env.nav.types import (
    PLAUSIBLE_RADIUS_M,
    GnssObservations,
    NavStatus,
    RelativePositions,
    VirtualPoint,
    check_iteration,
    check_plausible_radius,
    initial_positions,
    weak_geometry,
)
from coopnav_env.nav.wls import (
    StandaloneSolution,
    _radius_args,
    _safe_inverse,
    solve_standalone,
)

__all__ = [
    "CooperativeSolution",
    "MasterSlaveSolution",
    "solve_cooperative",
    "solve_cooperative_samples",
    "solve_master_slave",
]

Transfer = Literal["sdt", "ddt"]
CovarianceModel = Literal["exact", "paper"]


@dataclass(frozen=True)
class CooperativeSolution:
    """Cooperative fixes of every UAV of the swarm.

    Attributes
    ----------
    pos_ecef_m : ndarray, shape (n_rx, 3)
        Each UAV's position [m] (centroid position plus its relative position, Section 3.2);
        NaN where there is no fix.
    cov_ecef_m2 : ndarray, shape (n_rx, 3, 3)
        Each UAV's position covariance ``H_p`` [m^2] (Eq. 19); NaN where there is no fix.
    status : ndarray of int, shape (n_rx,)
        :class:`NavStatus` per UAV.
    centroid_pos_ecef_m : ndarray, shape (n_centroids, 3)
        Position of each virtual centroid solved for [m].
    centroid_cov_ecef_m2 : ndarray, shape (n_centroids, 3, 3)
        ``H*`` of each centroid [m^2].
    centroid_clock_m : ndarray, shape (n_centroids, n_systems)
        Clock bias of each centroid's clock reference per constellation [m] (NaN if unseen).
    centroid_status : ndarray of int, shape (n_centroids,)
    n_uavs_used : ndarray of int, shape (n_centroids,)
        UAVs contributing at least one measurement to each centroid solution.
    n_meas_used : ndarray of int, shape (n_centroids,)
        Measurements used by each centroid solution.
    n_iter : int
        Gauss-Newton iterations run.
    """

    pos_ecef_m: np.ndarray
    cov_ecef_m2: np.ndarray
    status: np.ndarray
    centroid_pos_ecef_m: np.ndarray
    centroid_cov_ecef_m2: np.ndarray
    centroid_clock_m: np.ndarray
    centroid_status: np.ndarray
    n_uavs_used: np.ndarray
    n_meas_used: np.ndarray
    n_iter: int

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of UAVs with a valid cooperative fix."""
        return self.status == NavStatus.OK

    @property
    def weak_geometry(self) -> np.ndarray:
        """Boolean mask of OK fixes on ill-conditioned geometry: predicted 3-D standard
        deviation above :data:`~coopnav_env.nav.types.WEAK_GEOMETRY_SIGMA_M`
        (:func:`~coopnav_env.nav.types.weak_geometry`; call it for another limit)."""
        return weak_geometry(self.status, self.cov_ecef_m2)


@dataclass(frozen=True)
class MasterSlaveSolution:
    """The "traditional" master-slave scheme of Section 4.2.

    Attributes
    ----------
    pos_ecef_m : ndarray, shape (n_rx, 3)
        Master: its standalone fix; slaves: master fix plus measured relative position [m].
    cov_ecef_m2 : ndarray, shape (n_rx, 3, 3)
        ``H_master + C_d`` for slaves (independent errors), ``H_master`` for the master [m^2].
    status : ndarray of int, shape (n_rx,)
    master : int
        Index of the master UAV.
    """

    pos_ecef_m: np.ndarray
    cov_ecef_m2: np.ndarray
    status: np.ndarray
    master: int

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of UAVs with a valid fix."""
        return self.status == NavStatus.OK

    @property
    def weak_geometry(self) -> np.ndarray:
        """Boolean mask of OK fixes on ill-conditioned geometry: predicted 3-D standard
        deviation above :data:`~coopnav_env.nav.types.WEAK_GEOMETRY_SIGMA_M`
        (:func:`~coopnav_env.nav.types.weak_geometry`; call it for another limit)."""
        return weak_geometry(self.status, self.cov_ecef_m2)


# --------------------------------------------------------------------------------------------
# Problem set-up shared by the structured and the dense solvers
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Setup:
    """Batched description of ``B`` centroid problems over ``N`` UAVs and ``S`` satellites."""

    centroid_uav: np.ndarray  # (B,) int, -1 for a virtual point
    ref: np.ndarray  # (B,) int clock reference UAV (-1: none available)
    base: np.ndarray  # (B, N, 3) measured baseline of q from the centroid
    bcov: np.ndarray  # (B, N, 3, 3) its covariance
    froot: np.ndarray  # (B, N, 3, 3) symmetric square root of bcov
    froot_paper: np.ndarray | None  # (B, N, 3, 3) root used by Eq. 18 (covariance="paper")
    used: np.ndarray  # (B, N, S) measurement used (before the DDT pivot exclusion)
    has_clock: np.ndarray  # (B, n_sys) centroid clock column estimable
    pivot: np.ndarray  # (B, N, n_sys) DDT pivot satellite index (-1: none)
    too_few: np.ndarray  # (B,) availability rule violated
    pr: np.ndarray  # (B or 1, N, S) pseudoranges, 0 where not received
    avail: np.ndarray  # (B, N) UAV has a relative measurement to the centroid
    sys_slices: tuple[slice, ...]  # contiguous satellite range of each constellation


def _system_slices(system: np.ndarray, n_sys: int) -> tuple[slice, ...]:
    """Contiguous satellite range of each constellation (``system`` must be sorted).

    Cached by value: an environment asks for the same few satellite sets every step.
    """
    key = (np.asarray(system).tobytes(), np.asarray(system).dtype.str, int(n_sys))
    hit = _SLICES.get(key)
    if hit is None:
        edges = np.searchsorted(system, np.arange(n_sys + 1))
        hit = tuple(slice(int(edges[i]), int(edges[i + 1])) for i in range(n_sys))
        if len(_SLICES) >= 4096:
            _SLICES.clear()
        _SLICES[key] = hit
    return hit


_SLICES: dict[tuple, tuple[slice, ...]] = {}


def _sort_by_system(obs: GnssObservations) -> tuple[GnssObservations, np.ndarray | None]:
    """The observations with satellites ordered by constellation (stable), and the order used.

    The solver works on contiguous constellation groups; the result does not depend on the
    order of the satellites, so callers never see the permutation.
    """
    system = obs.system
    if system.size < 2 or bool((system[1:] >= system[:-1]).all()):
        return obs, None
    order = np.argsort(obs.system, kind="stable")
    return (
        GnssObservations(
            pr_m=obs.pr_m[:, order],
            sv_ecef_m=obs.sv_ecef_m[order],
            system=obs.system[order],
            sigma_user_m=obs.sigma_user_m[:, order],
            sigma_common_m=obs.sigma_common_m[order],
            el_deg=obs.el_deg[:, order],
            n_systems=obs.n_systems,
        ),
        order,
    )


def _sqrtm_psd(cov: np.ndarray) -> np.ndarray:
    """Symmetric square roots of positive semi-definite ``(..., 3, 3)`` matrices.

    When every matrix is diagonal (the simulator's relative sensing: ``sigma_d^2 I``) the
    root is the square root of the diagonal (:func:`coopnav_env.nav._kernels.sqrtm_diagonal`),
    which is what the eigendecomposition returns for a diagonal matrix too (to the last bit for
    ordinary values; the tests check it), without its cost.
    """
    flat3 = np.ascontiguousarray(cov, dtype=np.float64).reshape(-1, 3, 3)
    root, diagonal = _kernels.sqrtm_diagonal(flat3)
    if diagonal:
        return root.reshape(cov.shape)
    lam, vec = np.linalg.eigh(cov)
    return np.einsum("...ij,...j,...kj->...ik", vec, np.sqrt(np.clip(lam, 0.0, None)), vec)


def _setup(
    obs: GnssObservations,
    rel: RelativePositions | None,
    centroid: str | int | VirtualPoint,
    transfer: Transfer,
    sdt_min_centroid_sats: int | None,
    covariance: CovarianceModel = "exact",
) -> _Setup:
    n = obs.n_rx
    if isinstance(centroid, VirtualPoint):
        if centroid.rel_ecef_m.shape[0] != n:
            raise ValueError(
                f"VirtualPoint has {centroid.rel_ecef_m.shape[0]} UAVs, observations have {n}"
            )
        cen = np.array([-1])
        base = centroid.rel_ecef_m[None]
        bcov = centroid.cov_ecef_m2[None]
        bavail = centroid.available[None]
    else:
        if rel is None:
            raise ValueError("relative positions are required unless centroid is a VirtualPoint")
        if rel.n_rx != n:
            raise ValueError(f"relative positions are for {rel.n_rx} UAVs, observations for {n}")
        if isinstance(centroid, str):
            if centroid != "self":
                raise ValueError(
                    f"centroid must be 'self', a UAV index or a VirtualPoint, got {centroid!r}"
                )
            cen = np.arange(n)
        elif isinstance(centroid, int | np.integer) and not isinstance(centroid, bool):
            if not 0 <= centroid < n:
                raise ValueError(f"centroid UAV index must be in [0, {n - 1}], got {centroid}")
            cen = np.array([int(centroid)])
        else:
            raise ValueError(
                f"centroid must be 'self', a UAV index or a VirtualPoint, got {centroid!r}"
            )
        base = rel.rel_ecef_m[cen]
        bcov = rel.cov_ecef_m2[cen]
        bavail = rel.available[cen]
        base = np.where(bavail[..., None], base, 0.0)
        bcov = np.where(bavail[..., None, None], bcov, 0.0)
    n_b = cen.shape[0]
    ref, used, has_clock, pivot, too_few = _setup_masks(
        obs, bavail, cen, transfer, sdt_min_centroid_sats
    )
    bidx = np.arange(n_b)
    froot = _sqrtm_psd(bcov)

    froot_paper = None
    if covariance == "paper":
        # Eq. 18 adds sigma_d^2 to every row, the centroid UAV's own rows included: give those
        # rows the mean relative covariance of the other available UAVs.
        own = np.zeros((n_b, n), dtype=bool)
        own[bidx[cen >= 0], cen[cen >= 0]] = True
        others = bavail & ~own
        cnt = np.maximum(others.sum(axis=1), 1)
        mean_cov = np.einsum("bn,bnij->bij", others.astype(float), bcov) / cnt[:, None, None]
        bcov_paper = np.where(own[..., None, None], mean_cov[:, None], bcov)
        froot_paper = _sqrtm_psd(bcov_paper)
    return _Setup(
        centroid_uav=cen,
        ref=ref,
        base=base,
        bcov=bcov,
        froot=froot,
        froot_paper=froot_paper,
        used=used,
        has_clock=has_clock,
        pivot=pivot,
        too_few=too_few,
        pr=np.where(obs.visible, obs.pr_m, 0.0)[None],
        avail=bavail,
        sys_slices=_system_slices(obs.system, obs.n_systems),
    )


def _setup_masks(
    obs: GnssObservations,
    bavail: np.ndarray,
    cen: np.ndarray,
    transfer: Transfer,
    sdt_min_centroid_sats: int | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``ref, used, has_clock, pivot, too_few`` of the centroid problems ``cen`` (B,): clock
    reference UAV (B,), rows used (B, N, S), constellations with a clock (B, n_sys), DDT pivot
    per UAV and constellation (B, N, n_sys; -1: none) and the problems without enough
    satellites (B,), by the compiled :func:`coopnav_env.nav._kernels.setup_masks`."""
    return _kernels.setup_masks(
        np.ascontiguousarray(obs.visible, dtype=bool),
        np.ascontiguousarray(bavail, dtype=bool),
        np.ascontiguousarray(cen, dtype=np.int64),
        np.ascontiguousarray(obs.system, dtype=np.int64),
        np.ascontiguousarray(obs.el_deg, dtype=np.float64),
        int(obs.n_systems),
        transfer == "ddt",
        -1 if sdt_min_centroid_sats is None else int(sdt_min_centroid_sats),
    )


@dataclass
class _Linear:
    """Linearised batched model: padded rows (B, N, S)."""

    rows: np.ndarray  # (B, N, S) bool rows present
    A: np.ndarray  # (B, N, S, P) design of the global parameters
    a: np.ndarray  # (B, N, S) residual (measurement - model)
    nuis: np.ndarray  # (B, N, S, Q) design of per-UAV nuisance clocks
    u: np.ndarray  # (B, N, S, 3) LOS of the row's own satellite at the row's UAV
    u_piv: np.ndarray | None  # (B, N, S, 3) LOS of the row's pivot at the row's UAV (DDT)
    u_piv_ref: np.ndarray | None  # (B, N, S, 3) LOS of the row's pivot at the reference
    piv_idx: np.ndarray | None  # (B, N, S) pivot satellite of each row (DDT literal)
    is_ref: np.ndarray  # (B, N) row block belongs to the clock reference


def _linearize(
    obs: GnssObservations, st: _Setup, pos: np.ndarray, clk: np.ndarray, literal_ddt: bool
) -> _Linear:
    """Residuals and Jacobians at the centroid iterate ``pos`` (B, 3), ``clk`` (B, n_sys)."""
    n_b = pos.shape[0]
    n, s = obs.pr_m.shape
    n_sys = obs.n_systems
    onehot = np.eye(n_sys)[obs.system]  # (S, n_sys)
    pos_q = pos[:, None, :] + st.base  # (B, N, 3)
    diff = obs.sv_ecef_m[None, None, :, :] - pos_q[:, :, None, :]
    rng = np.linalg.norm(diff, axis=-1)  # (B, N, S)
    # (a satellite at a UAV's iterate has no line of sight: :func:`_at_satellite` reports it)
    u = diff / np.where(rng == 0.0, 1.0, rng)[..., None]
    pr = st.pr  # (B or 1, N, S)
    clock_cols = onehot[None, None] * st.has_clock[:, None, None, :]  # (B, 1, S, n_sys)
    clk_term = np.einsum("bs,ks->bk", clk * st.has_clock, onehot)[:, None, :]  # (B, 1, S)
    is_ref = np.arange(n)[None, :] == st.ref[:, None]  # (B, N)
    if not literal_ddt:
        A = np.concatenate([-u, np.broadcast_to(clock_cols, (n_b, n, s, n_sys))], axis=-1)
        a = pr - rng - clk_term
        nuis = onehot[None, None] * (~is_ref)[:, :, None, None]
        nuis = np.broadcast_to(nuis, (n_b, n, s, n_sys))
        return _Linear(st.used, A, a, nuis, u, None, None, None, is_ref)
    # Literal double-differenced transfer (Eq. 12-13) at the current iterate.
    piv = st.pivot[:, :, obs.system]  # (B, N, S) pivot of the row's constellation
    pj = np.maximum(piv, 0)
    bidx = np.arange(n_b)[:, None, None]
    qidx = np.arange(n)[None, :, None]
    refi = np.maximum(st.ref, 0)[:, None, None]
    rows = st.used & (is_ref[:, :, None] | (np.arange(s)[None, None, :] != piv))
    pb = np.broadcast_to(pr, (n_b, n, s))
    pr_qj = pb[bidx, qidx, pj]  # (B, N, S)
    pr_rj = pb[bidx, refi, pj]
    rng_qj = rng[bidx, qidx, pj]
    rng_rj = rng[bidx, refi, pj]
    u_qj = u[bidx, qidx, pj]
    u_rj = u[bidx, refi, pj]
    isr = is_ref[:, :, None]
    meas = np.where(isr, pr, pr - pr_qj + pr_rj)
    model = np.where(isr, rng, rng - rng_qj + rng_rj) + clk_term
    jac = np.where(isr[..., None], -u, -u + u_qj - u_rj)
    A = np.concatenate([jac, np.broadcast_to(clock_cols, (n_b, n, s, n_sys))], axis=-1)
    nuis = np.zeros((n_b, n, s, 0))
    return _Linear(rows, A, meas - model, nuis, u, u_qj, u_rj, piv, is_ref)


# --------------------------------------------------------------------------------------------
# Structured generalised least squares
# --------------------------------------------------------------------------------------------


def _inv_sym3(m: np.ndarray) -> np.ndarray:
    """Closed-form inverse of a batch of symmetric positive definite 3x3 matrices."""
    a, b, c = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    d, e, f = m[..., 1, 1], m[..., 1, 2], m[..., 2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    out = np.stack([c00, c01, c02, c01, c11, c12, c02, c12, c22], axis=-1)
    return out.reshape(m.shape) / det[..., None, None]


def _structured_normal(
    w: np.ndarray,
    A: np.ndarray,
    a: np.ndarray,
    nuis_slices: tuple[slice, ...],
    nuis_active: np.ndarray | None,
    lam: np.ndarray,
    sig_c: np.ndarray,
    eps_load: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Reduced normal equations of a GLS with structured covariance.

    The row covariance is ``C = blockdiag_n(diag(1/w_n) + lam_n lam_n^T) + E E^T`` where
    ``E[(n, k), k'] = sig_c[k] delta_kk'`` (errors common to all blocks for one satellite), and
    each active block ``n`` has one flat-prior nuisance parameter per satellite group (its clock
    for that constellation): the satellites are sorted by constellation and ``nuis_slices``
    gives each group's contiguous range.

    Each low-rank term is a latent variable with a unit prior; nuisances and latents are
    eliminated in closed form, never by forming ``C``:

    1. per block, the nuisance clocks: ``N^T W N`` is diagonal (one clock per group), so
       ``P0 = W - W N (N^T W N)^-1 N^T W`` is a weighted mean removal per group;
    2. per block, the rank-3 relative-error latent (Woodbury with a closed-form 3x3 inverse):
       ``P = P0 - P0 lam (I + lam^T P0 lam)^-1 lam^T P0``;
    3. the common errors, with one ``S x S`` solve per batch element:
       ``A^T C~^-1 A = A^T P A - (A^T P E)(I + E^T P E)^-1 (E^T P A)``.

    Parameters
    ----------
    w : (B, N, S) inverse variances of the diagonal part; 0 marks an absent row.
    A : (B, N, S, P) design of the global parameters.
    a : (B, N, S) residuals.
    nuis_slices : satellite ranges of the nuisance groups (empty: no nuisances).
    nuis_active : (B, N) blocks that carry the nuisances (None: none).
    lam : (B, N, S, 3) per-block low-rank loadings.
    sig_c : (B, S) or (1, S) common-error standard deviations.
    eps_load : (B, N, S, 3) or None
        Loadings of the per-block relative error for the cross-covariance; ``None`` means
        ``lam`` (the exact model), for which ``P lam = P0 lam M^-1`` needs no extra columns.

    Returns
    -------
    info : (B, P, P) ``A^T C~^-1 A`` with nuisances eliminated.
    rhs : (B, P) ``A^T C~^-1 a``.
    cross : (B, N, P, 3) ``A^T C~^-1 eps_load_n`` per block.
    """
    b, n, s = w.shape
    p_dim = A.shape[-1]
    parts = [lam, A, a[..., None]] + ([] if eps_load is None else [eps_load])
    x = np.concatenate(parts, axis=-1)  # (B, N, S, 3 + P + 1 [+ 3])
    p0x = w[..., None] * x
    groups = []  # (slice, w of the group, coefficient active / sum w) per nuisance group
    if nuis_active is not None:
        for sl in nuis_slices:
            wq = w[:, :, sl]
            d = wq.sum(axis=2)  # N^T W N for this clock; 0 for a constellation the UAV lacks
            coef = np.divide(nuis_active, d, out=np.zeros_like(d), where=d > 0)
            p0x[:, :, sl] -= (
                wq[..., None] * (coef[..., None] * p0x[:, :, sl].sum(axis=2))[:, :, None, :]
            )
            groups.append((sl, wq, coef))
    p0lam, x_rest, p0_rest = p0x[..., :3], x[..., 3:], p0x[..., 3:]
    m3inv = _inv_sym3(np.eye(3) + np.swapaxes(lam, -1, -2) @ p0lam)  # (B, N, 3, 3)
    g3 = p0lam @ m3inv  # (B, N, S, 3)
    px = p0_rest - g3 @ (np.swapaxes(p0lam, -1, -2) @ x_rest)
    pa, pr = px[..., :p_dim], px[..., p_dim]
    pe = g3 if eps_load is None else px[..., p_dim + 1 :]
    # A^T P [A, a] summed over blocks
    a_flat = A.reshape(b, n * s, p_dim)
    atpx = np.swapaxes(a_flat, 1, 2) @ px[..., : p_dim + 1].reshape(b, n * s, p_dim + 1)
    # sum_n P_n = diag(sum_n w_n) - sum_n [W N D^-1 N^T W]_n - sum_n [P0 lam M^-1 lam^T P0]_n
    left = g3.swapaxes(1, 2).reshape(b, s, n * 3)
    right = p0lam.swapaxes(1, 2).reshape(b, s, n * 3)
    sum_p = -(left @ right.swapaxes(1, 2))
    for sl, wq, coef in groups:  # - sum_n w_s w_t / d over pairs in the same group
        sum_p[:, sl, sl] -= (wq * coef[..., None]).swapaxes(1, 2) @ wq
    diag = np.arange(s)
    sum_p[:, diag, diag] += w.sum(axis=1)
    mg = sig_c[:, :, None] * sum_p * sig_c[:, None, :]
    mg[:, diag, diag] += 1.0  # I + E^T P E: SPD
    ape = pa.sum(axis=1).swapaxes(1, 2) * sig_c[:, None, :]  # (B, P, S)
    epr = sig_c * pr.sum(axis=1)  # (B, S)
    mg_inv = np.linalg.inv(mg)
    g = ape @ mg_inv  # (B, P, S)
    info = atpx[..., :p_dim] - g @ np.swapaxes(ape, 1, 2)
    rhs = atpx[..., p_dim] - (g @ epr[..., None])[..., 0]
    # cross-covariance terms A^T P~ eps_n = A^T P_n eps_n - (A^T P E) Mg^-1 (E^T P_n eps_n)
    cross = np.swapaxes(A, -1, -2) @ pe - g[:, None] @ (sig_c[:, None, :, None] * pe)
    return info, rhs, cross


def _weights(
    obs: GnssObservations, st: _Setup, lin: _Linear, covariance: CovarianceModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``w, lam, sig_c, eps_load`` of the structured covariance for the rows of ``lin``.

    ``eps_load`` is None when it equals ``lam`` (the exact covariance model).
    """
    # rows that are absent get zero weight; nothing else needs masking (see _structured_normal)
    w = np.where(lin.rows, 1.0 / obs.sigma_user_m[None] ** 2, 0.0)
    sig_c = obs.sigma_common_m[None, :]  # (1, S): broadcasts over the batch
    # Eq. 21-22: the relative error of UAV q loads its own rows with 1^k (paper and exact SDT)
    eps_load = lin.u @ st.froot
    if covariance != "paper":
        return w, eps_load, sig_c, None
    return w, lin.u @ st.froot_paper, sig_c, eps_load


def _wls_step(
    obs: GnssObservations,
    st: _Setup,
    lin: _Linear,
    transfer: Transfer,
    covariance: CovarianceModel,
    method: str,
    usable: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One WLS solve (Eq. 15-17) with the full covariance C* at the linearisation ``lin``.

    Returns the inverse normal matrix ``(G^T C*^-1 G)^-1`` (B, P, P), the update (B, P), the
    cross-covariance terms (B, N, P, 3) and the singular flags (B,).
    """
    if method == "dense":
        info, rhs, cross = _dense_normal(obs, st, lin, transfer, covariance)
    else:
        w, lam, sig_c, eps_load = _weights(obs, st, lin, covariance)
        active = ~lin.is_ref if lin.nuis.shape[-1] else None
        info, rhs, cross = _structured_normal(
            w, lin.A, lin.a, st.sys_slices, active, lam, sig_c, eps_load
        )
    if not st.has_clock.all():  # unit diagonal for the clocks of constellations not seen
        idx = np.arange(3, info.shape[-1])
        info[:, idx, idx] += ~st.has_clock
    inv, singular = _safe_inverse(info, usable)
    return inv, np.einsum("bpq,bq->bp", inv, rhs), cross, singular


def _gauss_newton(
    obs: GnssObservations,
    st: _Setup,
    x0: np.ndarray,
    transfer: Transfer,
    covariance: CovarianceModel,
    method: str,
    max_iter: int,
    tol_m: float,
):
    """Gauss-Newton iterations of the centroid WLS of every problem of ``st``.

    Returns ``pos, clk, inv, cross, converged, singular, rows, n_nuis, n_iter``: the rows used
    (B, N, S) and the number of nuisance clocks they carry (B,) are what :func:`_finish` needs.
    The exact structured model runs in the compiled kernel
    (:func:`coopnav_env.nav._kernels.cooperative_gauss_newton`); the paper's covariance, the
    literal DDT and the dense reference run :func:`_gauss_newton_numpy`.
    """
    usable = ~st.too_few
    if method == "structured" and covariance == "exact":
        # the records _kernels.Transferred and Problems, as plain tuples
        pos, clk, inv, cross, converged, singular, iters = _kernels.cooperative_gauss_newton(
            (
                np.ascontiguousarray(st.pr, dtype=float),
                np.ascontiguousarray(obs.sv_ecef_m, dtype=float),
                np.ascontiguousarray(obs.visible, dtype=bool),
                np.ascontiguousarray(obs.sigma_user_m, dtype=float),
                np.ascontiguousarray(obs.sigma_common_m, dtype=float),
                np.ascontiguousarray(obs.system, dtype=np.int64),
            ),
            (
                np.ascontiguousarray(st.used),
                np.ascontiguousarray(st.base, dtype=float),
                np.ascontiguousarray(st.froot, dtype=float),
                np.ascontiguousarray(st.ref, dtype=np.int64),
                np.ascontiguousarray(st.has_clock),
                np.ascontiguousarray(usable),
                np.ascontiguousarray(x0, dtype=float),
            ),
            int(max_iter),
            float(tol_m),
        )
        n_iter = int(iters.max()) if iters.size else 0
        return pos, clk, inv, cross, converged, singular, st.used, _n_nuisance(obs, st), n_iter
    return _gauss_newton_numpy(obs, st, x0, transfer, covariance, method, max_iter, tol_m)


def _gauss_newton_numpy(
    obs: GnssObservations,
    st: _Setup,
    x0: np.ndarray,
    transfer: Transfer,
    covariance: CovarianceModel,
    method: str,
    max_iter: int,
    tol_m: float,
):
    """:func:`_gauss_newton` of every problem at once with numpy (what the paper's
    covariance, the literal DDT and the dense reference run; on the exact structured model it
    computes what the compiled kernel computes, and the tests compare the two)."""
    n_b = st.ref.shape[0]
    n_sys = obs.n_systems
    p_dim = 3 + n_sys
    literal = transfer == "ddt" and (covariance == "paper" or method == "dense")
    usable = ~st.too_few
    pos = x0.copy()
    clk = np.zeros((n_b, n_sys))
    converged = np.zeros(n_b, dtype=bool)
    singular = np.zeros(n_b, dtype=bool)
    inv = np.zeros((n_b, p_dim, p_dim))
    cross = np.zeros((n_b, obs.n_rx, p_dim, 3))
    lin = None
    n_iter = 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007 - reported
        lin = _linearize(obs, st, pos, clk, literal)
        at_sat = _at_satellite(obs, st, pos)
        inv, dx, cross, singular = _wls_step(
            obs, st, lin, transfer, covariance, method, usable & ~at_sat
        )
        singular |= usable & at_sat
        dx[~usable | singular] = 0.0
        pos = pos + dx[:, :3]
        clk = clk + dx[:, 3:]
        converged = np.linalg.norm(dx[:, :3], axis=1) < tol_m
        if np.all(converged | ~usable | singular):
            break
    n_nuis = _n_nuisance(obs, st) if lin.nuis.shape[-1] else np.zeros(n_b, dtype=int)
    return pos, clk, inv, cross, converged, singular, lin.rows, n_nuis, n_iter


def _at_satellite(obs: GnssObservations, st: _Setup, pos: np.ndarray) -> np.ndarray:
    """(B,) problems in which a satellite of a used row sits exactly at its UAV's iterate:
    the range has no derivative there, so the geometry is reported singular (the compiled
    kernel does the same)."""
    pos_q = pos[:, None, :] + st.base  # (B, N, 3)
    rng = np.linalg.norm(obs.sv_ecef_m[None, None, :, :] - pos_q[:, :, None, :], axis=-1)
    return np.any((rng == 0.0) & st.used, axis=(1, 2))


def _n_nuisance(obs: GnssObservations, st: _Setup) -> np.ndarray:
    """Nuisance clocks (UAV other than the reference, constellation with a row) per problem
    (B,), by the compiled :func:`coopnav_env.nav._kernels.n_nuisance`."""
    return _kernels.n_nuisance(
        np.ascontiguousarray(st.used, dtype=bool),
        np.ascontiguousarray(obs.system, dtype=np.int64),
        np.ascontiguousarray(st.ref, dtype=np.int64),
        int(obs.n_systems),
    )


# --------------------------------------------------------------------------------------------
# Dense reference (tests and benchmarks only)
# --------------------------------------------------------------------------------------------


def _dense_normal(
    obs: GnssObservations,
    st: _Setup,
    lin: _Linear,
    transfer: Transfer,
    covariance: CovarianceModel,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normal equations by forming ``C*`` densely and inverting it with ``numpy.linalg.inv``.

    Builds the literal transferred measurements (DDT: Eq. 12) and the covariance from the
    independent error sources (exact) or from Eq. 18 (paper), :func:`_dense_system`. Slow; the
    reference for tests.
    """
    n_b, n = lin.rows.shape[:2]
    n_sys = obs.n_systems
    p_dim = 3 + n_sys
    info = np.zeros((n_b, p_dim, p_dim))
    rhs = np.zeros((n_b, p_dim))
    cross = np.zeros((n_b, n, p_dim, 3))
    for bi in range(n_b):
        system = _dense_system(obs, st, lin, transfer, covariance, bi)
        if system is None:
            continue
        g, a_vec, cov, eps_cols = system
        cinv = np.linalg.inv(cov)
        full_info = g.T @ cinv @ g
        full_rhs = g.T @ cinv @ a_vec
        # eliminate the nuisance columns (Schur complement)
        gp, gn = slice(0, p_dim), slice(p_dim, g.shape[1])
        if g.shape[1] > p_dim:
            nn = np.linalg.inv(full_info[gn, gn])
            info[bi] = full_info[gp, gp] - full_info[gp, gn] @ nn @ full_info[gn, gp]
            rhs[bi] = full_rhs[gp] - full_info[gp, gn] @ nn @ full_rhs[gn]
            proj = cinv @ g[:, gp] - cinv @ g[:, gn] @ nn @ full_info[gn, gp]
        else:
            info[bi] = full_info
            rhs[bi] = full_rhs
            proj = cinv @ g
        cross[bi] = np.einsum("mp,mnl->npl", proj, eps_cols)
    return info, rhs, cross


def _dense_system(
    obs: GnssObservations,
    st: _Setup,
    lin: _Linear,
    transfer: Transfer,
    covariance: CovarianceModel,
    bi: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The dense linear system of centroid problem ``bi`` at the linearisation ``lin``.

    Returns ``g`` (m, P [+ nuisance columns]), the residuals ``a`` (m,), the dense covariance
    ``C*`` (m, m) of the rows (literal DDT rows when ``lin`` is the literal linearisation)
    and the loadings of every UAV's relative error on the rows (m, N, 3); ``None`` without
    rows. Also the reference of the integrity tests (the residual statistic with this ``C*``).
    """
    n = lin.rows.shape[1]
    s = lin.rows.shape[2]
    n_sys = obs.n_systems
    qq, kk = np.nonzero(lin.rows[bi])
    m = qq.size
    if m == 0:
        return None
    a_vec = lin.a[bi, qq, kk]
    g = lin.A[bi, qq, kk]
    if lin.nuis.shape[-1]:
        nz = lin.nuis[bi, qq, kk]  # (m, Q)
        cols = [np.where(qq == q, nz[:, c], 0.0) for q in range(n) for c in range(n_sys)]
        cols = [c for c in cols if np.any(c)]
        if cols:
            g = np.concatenate([g, np.stack(cols, axis=1)], axis=1)
    su = np.nan_to_num(obs.sigma_user_m)
    u_row = lin.u[bi, qq, kk]
    f = st.froot[bi]
    if covariance == "paper":
        fp = st.froot_paper[bi]
        lv = np.einsum("mi,mij->mj", u_row, fp[qq])
        cov = np.diag(su[qq, kk] ** 2)
        cov += (qq[:, None] == qq[None, :]) * (lv @ lv.T)
        sc = obs.sigma_common_m[kk]
        cov += (kk[:, None] == kk[None, :]) * np.outer(sc, sc)
        eps_cols = np.zeros((m, n, 3))
        eps_cols[np.arange(m), qq] = np.einsum("mi,mij->mj", u_row, f[qq])
        return g, a_vec, cov, eps_cols
    # Loadings of the independent sources: common (S), user (N*S), relative (N*3)
    n_src = s + n * s + 3 * n
    bm = np.zeros((m, n_src))
    sig = np.zeros(n_src)
    sig[:s] = obs.sigma_common_m
    sig[s : s + n * s] = su.ravel()
    sig[s + n * s :] = 1.0  # relative errors enter through F z with z ~ N(0, I)
    rows = np.arange(m)
    bm[rows, kk] = 1.0
    bm[rows, s + qq * s + kk] += 1.0
    eps_cols = np.zeros((m, n, 3))
    eps_cols[rows, qq] = np.einsum("mi,mij->mj", u_row, f[qq])
    if transfer == "ddt":
        ref = st.ref[bi]
        jj = lin.piv_idx[bi, qq, kk]
        notref = qq != ref
        r_ = rows[notref]
        bm[r_, s + qq[notref] * s + jj[notref]] -= 1.0
        bm[r_, s + ref * s + jj[notref]] += 1.0
        u_qj = lin.u_piv[bi, qq[notref], kk[notref]]
        u_rj = lin.u_piv_ref[bi, qq[notref], kk[notref]]
        eps_cols[r_, qq[notref]] -= np.einsum("mi,mij->mj", u_qj, f[qq[notref]])
        eps_cols[r_, ref] += np.einsum("mi,ij->mj", u_rj, f[ref])
    bm[:, s + n * s :] = eps_cols.reshape(m, 3 * n)
    cov = (bm * sig**2) @ bm.T
    return g, a_vec, cov, eps_cols


# --------------------------------------------------------------------------------------------
# Public solvers
# --------------------------------------------------------------------------------------------


def solve_cooperative(
    obs: GnssObservations,
    rel: RelativePositions | None,
    *,
    transfer: Transfer = "ddt",
    centroid: str | int | VirtualPoint = "self",
    covariance: CovarianceModel = "exact",
    x0_ecef_m: np.ndarray | None = None,
    sdt_min_centroid_sats: int | None = None,
    method: Literal["structured", "dense"] = "structured",
    max_iter: int = 10,
    tol_m: float = 1e-4,
    plausible_radius_m: tuple[float, float] | None = PLAUSIBLE_RADIUS_M,
) -> CooperativeSolution:
    """Cooperative position fix of every UAV through a virtual centroid (Eq. 10-23).

    Parameters
    ----------
    obs : GnssObservations
        Pseudoranges of all ``n_rx`` UAVs at one epoch.
    rel : RelativePositions or None
        Pairwise relative positions (Eq. 9). Not needed when ``centroid`` is a VirtualPoint.
    transfer : {"ddt", "sdt"}
        Double (Eq. 12-13, default, the paper's choice in Section 4) or single (Eq. 10-11)
        differenced transfer.
    centroid : "self", int or VirtualPoint
        ``"self"`` (default, the paper's choice in Section 3.1): each UAV is its own centroid and
        gets its own solution from all UAVs in relative-sensing range of it. An ``int`` ``a``:
        one shared centroid at UAV ``a``; every UAV in range of ``a`` is located from it.
        A :class:`VirtualPoint`: one fixed point that is not a UAV.
    covariance : {"exact", "paper"}
        ``"exact"`` (default): the covariance of the transferred measurements derived from the
        independent error sources (module docstring). ``"paper"``: Eq. 18 and Eq. 19 as printed.
    x0_ecef_m : ndarray, shape (n_centroids, 3) or (3,), optional
        Initial centroid position(s) [m]; default zero (Eq. 15's start).
    sdt_min_centroid_sats : int, optional
        SDT availability rule at a UAV centroid; default ``3 + N_const`` (paper Section 2.3).
    method : {"structured", "dense"}
        ``"structured"`` (default) exploits the structure of ``C*``; ``"dense"`` forms and
        inverts ``C*`` (reference for tests and benchmarks).
    max_iter, tol_m
        Gauss-Newton iteration limit and position-update threshold [m].
    plausible_radius_m : (float, float) or None
        Geocentric distance range [m] of a valid centroid fix (default
        :data:`~coopnav_env.nav.types.PLAUSIBLE_RADIUS_M`); outside it the status is
        ``IMPLAUSIBLE_POSITION`` (see :class:`NavStatus`). ``None`` disables the check.

    Returns
    -------
    CooperativeSolution
        Degenerate cases (too few satellites, singular geometry, no relative link to the
        centroid, non-convergence, a spurious far root) are reported in ``status``; nothing is
        raised for them.
    """
    if transfer not in ("sdt", "ddt"):
        raise ValueError(f"transfer must be 'sdt' or 'ddt', got {transfer!r}")
    if covariance not in ("exact", "paper"):
        raise ValueError(f"covariance must be 'exact' or 'paper', got {covariance!r}")
    if method not in ("structured", "dense"):
        raise ValueError(f"method must be 'structured' or 'dense', got {method!r}")
    max_iter = check_iteration(max_iter, tol_m)
    check_plausible_radius(plausible_radius_m)
    obs, _ = _sort_by_system(obs)
    st = _setup(obs, rel, centroid, transfer, sdt_min_centroid_sats, covariance)
    x0 = initial_positions(x0_ecef_m, st.ref.shape[0])
    pos, clk, inv, cross, converged, singular, rows, n_nuis, n_iter = _gauss_newton(
        obs, st, x0, transfer, covariance, method, max_iter, tol_m
    )
    self_centroids = isinstance(centroid, str)
    finished = _finish(
        obs,
        st,
        pos,
        clk,
        inv,
        cross,
        converged,
        singular,
        rows,
        n_nuis,
        plausible_radius_m,
        with_uavs=not self_centroids,
    )
    return _solution(finished, self_centroids, n_iter)


def _solution(finished: tuple, self_centroids: bool, n_iter: int) -> CooperativeSolution:
    """The :class:`CooperativeSolution` of :func:`_finish`'s outputs (``"self"`` centroids:
    UAV q's solution is centroid q's; otherwise the one centroid's UAV outputs)."""
    c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status = finished
    if self_centroids:
        uav_pos, uav_cov, uav_status = c_pos, h_star, c_status.copy()
    else:
        uav_pos, uav_cov, uav_status = uav_pos[0], uav_cov[0], uav_status[0]
    return CooperativeSolution(
        pos_ecef_m=uav_pos,
        cov_ecef_m2=uav_cov,
        status=uav_status,
        centroid_pos_ecef_m=c_pos,
        centroid_cov_ecef_m2=h_star,
        centroid_clock_m=c_clk,
        centroid_status=c_status,
        n_uavs_used=n_uavs,
        n_meas_used=n_meas,
        n_iter=int(n_iter),
    )


def _solve_isotropic(
    obs: GnssObservations,
    rel_ecef_m: np.ndarray,
    var_m2: np.ndarray,
    available: np.ndarray,
    centroid: str | int,
    transfer: Transfer,
    x0_ecef_m: np.ndarray,
    max_iter: int,
    tol_m: float = 1e-4,
    plausible_radius_m: tuple[float, float] | None = PLAUSIBLE_RADIUS_M,
) -> CooperativeSolution | None:
    """:func:`solve_cooperative` (exact covariance, structured) in one compiled call.

    For the simulator's hot path: trusted arrays, relative positions with isotropic
    covariances ``var_m2 * I``. ``centroid="self"``: ``rel_ecef_m`` (N, N, 3), ``var_m2`` and
    ``available`` (N, N), ``x0_ecef_m`` (N, 3), as :class:`RelativePositions` holds them. An
    ``int`` ``a``: only UAV ``a``'s row, ``rel_ecef_m`` (N, 3), ``var_m2`` and ``available``
    (N,), ``x0_ecef_m`` (3,). Returns exactly what ``solve_cooperative`` returns for
    ``RelativePositions(rel_ecef_m, var_m2[..., None, None] * I, available)`` (the same kernels
    on the same arguments: :func:`coopnav_env.nav._kernels.cooperative_isotropic`), or None
    when this path does not apply (satellites not grouped by constellation): the caller then
    runs ``solve_cooperative``.
    """
    system = obs.system
    if system.size > 1 and not bool((system[1:] >= system[:-1]).all()):
        return None
    n = obs.n_rx
    self_centroids = isinstance(centroid, str)
    if self_centroids:
        cen = np.arange(n, dtype=np.int64)
        rel_b, var_b, avail_b, x0 = rel_ecef_m, var_m2, available, x0_ecef_m
    else:
        cen = np.array([int(centroid)], dtype=np.int64)
        rel_b, var_b, avail_b, x0 = rel_ecef_m[None], var_m2[None], available[None], x0_ecef_m[None]
    # the kernel's records (_kernels.Measured, CentroidProblems, SolverLimits) as plain
    # tuples, which numba types faster
    out = _kernels.cooperative_isotropic(
        (
            obs.pr_m,
            obs.visible,
            obs.sv_ecef_m,
            system,
            obs.sigma_user_m,
            obs.sigma_common_m,
            obs.el_deg,
            int(obs.n_systems),
        ),
        (
            np.ascontiguousarray(rel_b, dtype=np.float64),
            np.ascontiguousarray(var_b, dtype=np.float64),
            np.ascontiguousarray(avail_b, dtype=bool),
            cen,
            np.ascontiguousarray(x0, dtype=np.float64),
            transfer == "ddt",
            -1,
        ),
        (int(max_iter), float(tol_m), *_radius_args(plausible_radius_m)),
        not self_centroids,
    )
    return _solution(out[:9], self_centroids, out[9])


def _finish(
    obs,
    st,
    pos,
    clk,
    inv,
    cross,
    converged,
    singular,
    rows,
    n_nuis,
    plausible_radius_m,
    with_uavs=True,
):
    """Statuses, centroid outputs and every UAV's position/covariance from each centroid.

    ``with_uavs=False`` (centroid ``"self"``, where UAV q's solution is centroid q's) skips
    the UAV outputs and returns ``None`` for them. Computed by the compiled
    :func:`coopnav_env.nav._kernels.cooperative_finish`.
    """
    out = _kernels.cooperative_finish(  # the records Solved and ProblemSetup, as plain tuples
        (
            np.ascontiguousarray(pos, dtype=float),
            np.ascontiguousarray(clk, dtype=float),
            np.ascontiguousarray(inv, dtype=float),
            np.ascontiguousarray(cross, dtype=float),
            np.ascontiguousarray(converged, dtype=bool),
            np.ascontiguousarray(singular, dtype=bool),
        ),
        (
            np.ascontiguousarray(rows, dtype=bool),
            np.ascontiguousarray(n_nuis, dtype=np.int64),
            np.ascontiguousarray(st.too_few, dtype=bool),
            np.ascontiguousarray(st.has_clock, dtype=bool),
            np.ascontiguousarray(st.base, dtype=float),
            np.ascontiguousarray(st.bcov, dtype=float),
            np.ascontiguousarray(st.froot, dtype=float),
            np.ascontiguousarray(st.avail, dtype=bool),
        ),
        *_radius_args(plausible_radius_m),
        bool(with_uavs),
    )
    if not with_uavs:
        return (*out[:6], None, None, None)
    return out


def solve_cooperative_samples(
    obs: GnssObservations,
    pr_samples_m: np.ndarray,
    rel: RelativePositions | VirtualPoint,
    rel_samples_m: np.ndarray,
    *,
    centroid: int | VirtualPoint,
    transfer: Transfer = "ddt",
    covariance: CovarianceModel = "exact",
    x0_ecef_m: np.ndarray | None = None,
    sdt_min_centroid_sats: int | None = None,
    max_iter: int = 10,
    tol_m: float = 1e-4,
    plausible_radius_m: tuple[float, float] | None = PLAUSIBLE_RADIUS_M,
) -> CooperativeSolution:
    """Solve many noise realisations of one geometry at once (Monte Carlo), one shared centroid.

    The satellites, visibility and error model come from ``obs``; ``pr_samples_m`` replaces
    its pseudoranges and ``rel_samples_m`` the measured baselines of every UAV relative to the
    centroid. Equivalent to calling :func:`solve_cooperative` once per sample (the tests check
    this), but batched, so that Monte Carlo studies are fast.

    Parameters
    ----------
    obs : GnssObservations
        Template epoch (its ``pr_m`` is only used for the visibility mask).
    pr_samples_m : ndarray, shape (K, n_rx, n_sv)
    rel : RelativePositions or VirtualPoint
        Template for covariances and availability of the relative measurements.
    rel_samples_m : ndarray, shape (K, n_rx, 3)
        Measured position of each UAV relative to the centroid in each sample [m].
    centroid : int or VirtualPoint
        The shared centroid (a UAV index, or the virtual point described by ``rel``).

    Returns
    -------
    CooperativeSolution
        With a leading sample axis: ``pos_ecef_m`` (K, n_rx, 3), ``cov_ecef_m2``
        (K, n_rx, 3, 3), ``status`` (K, n_rx) and centroid fields (K, ...).
    """
    pr_samples_m = np.asarray(pr_samples_m, dtype=float)
    k = pr_samples_m.shape[0]
    if pr_samples_m.shape[1:] != obs.pr_m.shape:
        raise ValueError(f"pr_samples_m must have shape (K, {obs.n_rx}, {obs.n_sv})")
    rel_samples_m = np.asarray(rel_samples_m, dtype=float)
    if rel_samples_m.shape != (k, obs.n_rx, 3):
        raise ValueError(f"rel_samples_m must have shape ({k}, {obs.n_rx}, 3)")
    if isinstance(centroid, str):
        raise ValueError("solve_cooperative_samples needs one shared centroid (int/VirtualPoint)")
    max_iter = check_iteration(max_iter, tol_m)
    check_plausible_radius(plausible_radius_m)
    x0 = initial_positions(x0_ecef_m, k)
    obs, order = _sort_by_system(obs)
    if order is not None:
        pr_samples_m = pr_samples_m[:, :, order]
    st = _setup(
        obs,
        rel if isinstance(rel, RelativePositions) else None,
        centroid,
        transfer,
        sdt_min_centroid_sats,
        covariance,
    )
    if np.any(np.isfinite(pr_samples_m) != obs.visible[None]):
        raise ValueError("pr_samples_m must be finite exactly where obs.pr_m is")
    rep = {
        f: np.repeat(getattr(st, f), k, axis=0)
        for f in st.__dataclass_fields__
        if isinstance(getattr(st, f), np.ndarray)
    }
    rep["base"] = np.where(st.avail[0][None, :, None], rel_samples_m, 0.0)
    rep["pr"] = np.where(obs.visible[None], pr_samples_m, 0.0)
    st = replace(st, **rep)
    pos, clk, inv, cross, converged, singular, rows, n_nuis, n_iter = _gauss_newton(
        obs, st, x0, transfer, covariance, "structured", max_iter, tol_m
    )
    c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status = _finish(
        obs, st, pos, clk, inv, cross, converged, singular, rows, n_nuis, plausible_radius_m
    )
    return CooperativeSolution(
        pos_ecef_m=uav_pos,
        cov_ecef_m2=uav_cov,
        status=uav_status,
        centroid_pos_ecef_m=c_pos,
        centroid_cov_ecef_m2=h_star,
        centroid_clock_m=c_clk,
        centroid_status=c_status,
        n_uavs_used=n_uavs,
        n_meas_used=n_meas,
        n_iter=n_iter,
    )


def solve_master_slave(
    obs: GnssObservations,
    rel: RelativePositions,
    *,
    master: int | Literal["best"] = "best",
    standalone: StandaloneSolution | None = None,
    x0_ecef_m: np.ndarray | None = None,
) -> MasterSlaveSolution:
    """The "traditional" cooperative scheme of Section 4.2: slaves use the master's fix.

    The master solves standalone (Eq. 14-17); each slave in relative-sensing range of it takes
    ``p_master + x_(master, slave)`` and discards its own GNSS observations. Errors of the master
    fix and of the relative measurement are independent, so ``H_slave = H_master + C_d``.

    Parameters
    ----------
    obs : GnssObservations
    rel : RelativePositions
    master : int or "best"
        The master UAV; ``"best"`` picks the UAV with the smallest standalone position variance
        (trace of ``H``) among those with a fix.
    standalone : StandaloneSolution, optional
        Reuse an already computed standalone solution of the same epoch.
    x0_ecef_m : ndarray, optional
        Initial positions for the standalone solve.
    """
    n = obs.n_rx
    if rel.n_rx != n:
        raise ValueError(f"relative positions are for {rel.n_rx} UAVs, observations for {n}")
    sa = standalone if standalone is not None else solve_standalone(obs, x0_ecef_m)
    if isinstance(master, str):
        if master != "best":
            raise ValueError(f"master must be a UAV index or 'best', got {master!r}")
        tr = np.where(
            sa.ok, np.trace(np.nan_to_num(sa.cov_ecef_m2, nan=np.inf), axis1=1, axis2=2), np.inf
        )
        m = int(np.argmin(tr))
    else:
        if not 0 <= int(master) < n:
            raise ValueError(f"master must be in [0, {n - 1}], got {master}")
        m = int(master)
    pos = sa.pos_ecef_m[m][None, :] + rel.rel_ecef_m[m]
    cov = sa.cov_ecef_m2[m][None] + rel.cov_ecef_m2[m]
    status = np.full(n, sa.status[m], dtype=np.int64)
    link = rel.available[m]
    status[~link & (status == NavStatus.OK)] = NavStatus.NO_RELATIVE_POSITION
    pos[~link] = np.nan
    cov[~link] = np.nan
    return MasterSlaveSolution(pos_ecef_m=pos, cov_ecef_m2=cov, status=status, master=m)
