"""Numpy oracles of the navigation kernels (:mod:`coopnav_env.nav._kernels`,
:mod:`coopnav_env.nav._integrity_kernels`).

The library runs the standalone Gauss-Newton loop, the exact structured cooperative loop and
their helpers (statuses, set-up masks, nuisance count, the outputs of every UAV, the square
root of diagonal covariances) in compiled kernels only. The functions here are their numpy
definitions, written batched over receivers and centroid problems: a second, independent
implementation of the same algebra that the tests compare the kernels with (statuses,
masks and counts identical; positions to 1e-6 m and covariances to 1e-9 relative, the
summation orders differing). The exact structured cooperative loop is the library's own numpy
loop (``cooperative._gauss_newton_numpy``, which the paper's covariance runs), given the exact
covariance. :func:`problem_statistics` is the dense definition of the integrity monitor's
residual statistic. :func:`use_nav_oracles` puts the solvers' oracles in place of the kernels.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.nav import _integrity_kernels as _ik
from coopnav_env.nav import cooperative as _cooperative
from coopnav_env.nav import wls as _wls
from coopnav_env.nav.types import NavStatus, implausible_radius
from coopnav_env.nav.wls import _safe_inverse

__all__ = [
    "cooperative_gauss_newton",
    "finish",
    "fix_status",
    "n_nuisance",
    "problem_statistics",
    "setup_masks",
    "sqrtm_psd",
    "standalone_gauss_newton",
    "standalone_solve",
    "use_nav_oracles",
]

_DIAGONAL = np.array([0, 4, 8])
_OFF_DIAGONAL = np.array([1, 2, 3, 5, 6, 7])


# --------------------------------------------------------------------------------------------
# standalone WLS (wls._standalone_solve, _kernels.standalone_solve)
# --------------------------------------------------------------------------------------------


def standalone_solve(obs, pos, max_iter, tol_m, plausible_radius_m):
    """``pos, cov, clock, status, n_used, n_iter`` of every receiver: the definition of
    ``wls._standalone_solve`` (same arguments, same results)."""
    vis = obs.visible
    n_sys = obs.n_systems
    w = np.where(vis, 1.0 / (obs.sigma_user_m**2 + obs.sigma_common_m[None, :] ** 2), 0.0)
    pr = np.where(vis, obs.pr_m, 0.0)
    onehot = np.eye(n_sys)[obs.system]  # (n_sv, n_sys)
    seen = np.einsum("rs,sk->rk", vis.astype(float), onehot) > 0  # (n_rx, n_sys)
    n_used = vis.sum(axis=1)
    too_few = n_used < 3 + seen.sum(axis=1)
    pos, clock, inv, converged, singular, n_iter = standalone_gauss_newton(
        obs, pr, w, onehot, seen, ~too_few, pos, max_iter, tol_m
    )
    status, failed = fix_status(pos, converged, singular, too_few, plausible_radius_m)
    pos[failed] = np.nan
    cov = inv[:, :3, :3].copy()
    cov[failed] = np.nan
    clock = np.where(seen & ~failed[:, None], clock, np.nan)
    return pos, cov, clock, status, n_used, n_iter


def fix_status(pos, converged, singular, too_few, plausible_radius_m):
    """:class:`NavStatus` of each fix (n,) and whether it failed (no position): the definition
    of ``_kernels.fix_status``. In increasing precedence: ``OK``, ``NOT_CONVERGED``,
    ``IMPLAUSIBLE_POSITION``, ``SINGULAR_GEOMETRY``, ``TOO_FEW_SATELLITES``."""
    status = np.full(pos.shape[0], NavStatus.OK, dtype=np.int64)
    status[~converged] = NavStatus.NOT_CONVERGED
    status[converged & implausible_radius(pos, plausible_radius_m)] = NavStatus.IMPLAUSIBLE_POSITION
    status[singular] = NavStatus.SINGULAR_GEOMETRY
    status[too_few] = NavStatus.TOO_FEW_SATELLITES
    failed = (status == NavStatus.TOO_FEW_SATELLITES) | (status == NavStatus.SINGULAR_GEOMETRY)
    return status, failed


def standalone_gauss_newton(obs, pr, w, onehot, seen, usable, pos, max_iter, tol_m):
    """The standalone Gauss-Newton loop of every receiver at once (the definition of
    ``_kernels.standalone_gauss_newton``): ``pos, clock, inv, converged, singular, n_iter``."""
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


# --------------------------------------------------------------------------------------------
# cooperative solve (cooperative._setup_masks, _n_nuisance, _finish, _sqrtm_psd, _gauss_newton)
# --------------------------------------------------------------------------------------------


def sqrtm_psd(cov: np.ndarray) -> np.ndarray:
    """Symmetric square roots of positive semi-definite ``(..., 3, 3)`` matrices: the square
    root of the diagonal when every matrix is diagonal, else the eigendecomposition's (the
    definition of ``cooperative._sqrtm_psd``)."""
    flat = cov.reshape((*cov.shape[:-2], 9))
    if not flat[..., _OFF_DIAGONAL].any():
        return np.sqrt(np.clip(flat[..., _DIAGONAL], 0.0, None))[..., None] * np.eye(3)
    lam, vec = np.linalg.eigh(cov)
    return np.einsum("...ij,...j,...kj->...ik", vec, np.sqrt(np.clip(lam, 0.0, None)), vec)


def setup_masks(obs, bavail, cen, transfer, sdt_min_centroid_sats):
    """``ref, used, has_clock, pivot, too_few`` of the centroid problems ``cen``: the
    definition of ``cooperative._setup_masks`` (same arguments, same results)."""
    n_b = cen.shape[0]
    vis = obs.visible
    n_sys = obs.n_systems
    onehot = np.eye(n_sys, dtype=bool)[obs.system]  # (S, n_sys)
    used0 = vis[None, :, :] & bavail[:, :, None]  # (B, N, S)
    n_vis = (used0).sum(axis=2)  # (B, N)
    ref = cen.copy()
    virt = cen < 0
    if np.any(virt):
        # clock reference of a virtual point: the available UAV seeing most satellites
        best = np.argmax(n_vis[virt], axis=1)
        ref[virt] = np.where(n_vis[virt][np.arange(best.size), best] > 0, best, -1)
    bidx = np.arange(n_b)
    ref_vis = np.where((ref >= 0)[:, None], used0[bidx, np.maximum(ref, 0)], False)  # (B, S)
    has_clock = (ref_vis[:, :, None] & onehot[None]).any(axis=1)  # (B, n_sys)

    # DDT pivots: highest elevation (at the reference) among satellites of the constellation
    # seen by both the reference and UAV q.
    el_ref = np.where(ref_vis, obs.el_deg[np.maximum(ref, 0)], -np.inf)  # (B, S)
    common = used0 & ref_vis[:, None, :]  # (B, N, S)
    score = np.where(
        common[..., None] & onehot[None, None], el_ref[:, None, :, None], -np.inf
    )  # (B, N, S, n_sys)
    pivot = np.argmax(score, axis=2)  # (B, N, n_sys)
    pivot = np.where(np.isfinite(np.max(score, axis=2)), pivot, -1)

    if transfer == "ddt":
        # measurements of constellation s are transferred only with a common pivot
        used = used0 & (pivot >= 0)[:, :, obs.system]
        n_ref = ref_vis.sum(axis=1)
        too_few = n_ref < 1
    else:
        used = used0
        if sdt_min_centroid_sats is None:
            need = 3 + has_clock.sum(axis=1)
        else:
            need = np.full(n_b, int(sdt_min_centroid_sats))
        n_ref = ref_vis.sum(axis=1)
        too_few = np.where(cen >= 0, n_ref < need, ref < 0)

    return ref, used, has_clock, pivot, too_few


def n_nuisance(obs, st) -> np.ndarray:
    """Nuisance clocks (UAV other than the reference, constellation with a row) per problem:
    the definition of ``cooperative._n_nuisance``."""
    onehot = np.eye(obs.n_systems)[obs.system]  # (S, n_sys)
    per = np.einsum("bns,sq->bnq", st.used.astype(float), onehot) > 0
    not_ref = np.arange(obs.n_rx)[None, :] != st.ref[:, None]
    return (per & not_ref[:, :, None]).sum(axis=(1, 2))


def finish(
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
    """Statuses, centroid outputs and every UAV's position/covariance from each centroid:
    the definition of ``cooperative._finish`` (same arguments, same results)."""
    n_meas = rows.sum(axis=(1, 2))
    n_uavs = rows.any(axis=2).sum(axis=1)
    # counting rule: measurements minus per-UAV nuisance clocks must cover the unknowns
    too_few = st.too_few | (n_meas - n_nuis < 3 + st.has_clock.sum(axis=1))
    c_status, failed = fix_status(pos, converged, singular, too_few, plausible_radius_m)
    h_star = inv[:, :3, :3].copy()
    c_pos = pos.copy()
    c_pos[failed] = np.nan
    h_star[failed] = np.nan
    c_clk = np.where(st.has_clock & ~failed[:, None], clk, np.nan)
    if not with_uavs:
        return c_pos, h_star, c_clk, c_status, n_uavs, n_meas, None, None, None
    # Every UAV from each centroid: p_q = p* + x_q, H_q = H* + C_d,q + Y + Y^T, where
    # Y = cov(p*~, eps_q) = [H A^T C~^-1 (1 F_q)]_pos F_q^T (Eq. 19-22, Appendix B)
    y = np.matmul(inv[:, None, :3], cross) @ np.swapaxes(st.froot, -1, -2)
    uav_pos = c_pos[:, None, :] + st.base
    uav_cov = h_star[:, None] + st.bcov + y + np.swapaxes(y, -1, -2)
    uav_status = np.repeat(c_status[:, None], obs.n_rx, axis=1)
    no_link = ~st.avail
    uav_status[no_link & (uav_status == NavStatus.OK)] = NavStatus.NO_RELATIVE_POSITION
    uav_pos[no_link] = np.nan
    uav_cov[no_link] = np.nan
    return c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status


def cooperative_gauss_newton(obs, st, x0, transfer, covariance, method, max_iter, tol_m):
    """``cooperative._gauss_newton`` with numpy in every mode: the exact structured model
    (which the library runs in ``_kernels.cooperative_gauss_newton``) by the library's numpy
    loop (:func:`coopnav_env.nav.cooperative._gauss_newton_numpy`)."""
    return _cooperative._gauss_newton_numpy(
        obs, st, x0, transfer, covariance, method, max_iter, tol_m
    )


# --------------------------------------------------------------------------------------------
# integrity monitoring (_integrity_kernels.problem_statistics)
# --------------------------------------------------------------------------------------------


def problem_statistics(
    pr, sv, system, rows, w, sig_c, pos, clk, base, bcov, ref, has_clock, rot, positive_only=False
):
    """The numpy definition of :func:`coopnav_env.nav._integrity_kernels.problem_statistics`:
    the covariance formed densely (``diag(1/w) + sig_c sig_c^T [same satellite] +
    u^T C_d u [same UAV]``), the clocks as the solvers parametrise them (the clock reference's
    clocks ``has_clock`` and one nuisance clock per other UAV and constellation) as explicit
    columns, ``numpy.linalg`` for every inverse (the kernel eliminates every UAV's own clocks
    instead: the same column space). Returns the same tuple (``ok`` always True) plus
    ``R a``, ``diag R`` and the ECEF position gains ``K`` (3, m) of the rows
    (``numpy.nonzero(rows)`` order)."""
    qq, kk = np.nonzero(rows)
    m = qq.size
    n_sys = has_clock.shape[0]
    pq = pos[None] + base[qq]
    d = sv[kk] - pq
    rng = np.linalg.norm(d, axis=1)
    u = d / rng[:, None]
    cols = [-u]
    onehot = np.eye(n_sys)[system[kk]]
    cols.append(onehot * has_clock[None])
    nuis = []
    for q in np.unique(qq):
        if q == ref:
            continue
        for j in range(n_sys):
            c = ((qq == q) & (system[kk] == j)).astype(float)
            if c.any():
                nuis.append(c)
    g = np.concatenate(cols + ([np.stack(nuis, axis=1)] if nuis else []), axis=1)
    keep = np.ones(g.shape[1], dtype=bool)
    keep[3 : 3 + n_sys] = has_clock
    g = g[:, keep]
    a = pr[qq, kk] - rng - np.where(has_clock[system[kk]], clk[system[kk]], 0.0)
    cov = np.diag(1.0 / w[qq, kk])
    cov += (kk[:, None] == kk[None, :]) * np.outer(sig_c[kk], sig_c[kk])
    cov += (qq[:, None] == qq[None, :]) * np.einsum("mi,mij,nj->mn", u, bcov[qq], u)
    cinv = np.linalg.inv(cov)
    info = g.T @ cinv @ g
    info_inv = np.linalg.inv(info)
    r_mat = cinv - cinv @ g @ info_inv @ g.T @ cinv
    resid = a - g @ (info_inv @ (g.T @ (cinv @ a)))  # the GLS residuals
    ra = cinv @ resid  # = R a
    t_stat = float(resid @ ra)
    dof = m - g.shape[1]
    gain = (info_inv @ g.T @ cinv)[:3]  # (3, m) position shift per unit bias
    k_enu = rot @ gain
    kh = np.hypot(k_enu[0], k_enu[1])
    ku = np.abs(k_enu[2])
    r_ii = np.diag(r_mat)
    obs_ok = r_ii > _ik.UNOBSERVABLE_RII * w[qq, kk]
    sr = np.sqrt(np.where(obs_ok, r_ii, 1.0))
    h_slope = float(np.max(np.where(obs_ok, kh / sr, 0.0)))
    v_slope = float(np.max(np.where(obs_ok, ku / sr, 0.0)))
    if np.any(~obs_ok & (kh > _ik.HARMLESS_GAIN)):
        h_slope = math.inf
    if np.any(~obs_ok & (ku > _ik.HARMLESS_GAIN)):
        v_slope = math.inf
    wstat = np.where(obs_ok & ((ra > 0.0) | (not positive_only)), np.abs(ra) / sr, -1.0)
    # the largest; an exact tie (within TIE_RTOL) goes to the first positive residual
    tie = (wstat >= 0.0) & (wstat >= wstat.max() * (1.0 - _ik.TIE_RTOL))
    positive_tie = tie & (ra > 0.0)
    i = int(np.flatnonzero(positive_tie if positive_tie.any() else tie)[0])
    return (
        True,
        t_stat,
        dof,
        int(qq[i]),
        int(kk[i]),
        float(wstat[i]),
        h_slope,
        v_slope,
        ra,
        r_ii,
        gain,
    )


# --------------------------------------------------------------------------------------------
# all of them in place of the kernels
# --------------------------------------------------------------------------------------------


def use_nav_oracles(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Make :func:`~coopnav_env.nav.solve_standalone`, :func:`~coopnav_env.nav.solve_cooperative`
    and :func:`~coopnav_env.nav.solve_cooperative_samples` run the oracles above instead of
    the compiled kernels, and ``cooperative._solve_isotropic`` (the simulator's one-call
    cooperative solve) decline, so that its callers run ``solve_cooperative`` (a module that
    imported it by name keeps its own: ``tests/envs/oracles.use_all_oracles`` rebinds the
    world's).

    Returns a dict counting the calls of each oracle, so that a test can check they ran.
    """
    calls = dict.fromkeys(
        ("standalone_solve", "setup_masks", "n_nuisance", "finish", "sqrtm_psd", "gauss_newton"),
        0,
    )

    def counted(name, fn):
        def run(*args, **kwargs):
            calls[name] += 1
            return fn(*args, **kwargs)

        return run

    monkeypatch.setattr(_wls, "_standalone_solve", counted("standalone_solve", standalone_solve))
    monkeypatch.setattr(_cooperative, "_setup_masks", counted("setup_masks", setup_masks))
    monkeypatch.setattr(_cooperative, "_n_nuisance", counted("n_nuisance", n_nuisance))
    monkeypatch.setattr(_cooperative, "_finish", counted("finish", finish))
    monkeypatch.setattr(_cooperative, "_sqrtm_psd", counted("sqrtm_psd", sqrtm_psd))
    monkeypatch.setattr(
        _cooperative, "_gauss_newton", counted("gauss_newton", cooperative_gauss_newton)
    )
    monkeypatch.setattr(_cooperative, "_solve_isotropic", lambda *args, **kwargs: None)
    return calls
