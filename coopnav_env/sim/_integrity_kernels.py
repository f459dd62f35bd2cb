"""Integrity monitoring inside the one-call epoch navigation (``ScenarioConfig.integrity``).

:func:`coopnav_env.sim._kernels.epoch_navigation` takes an optional ``fde`` settings tuple
(:func:`coopnav_env.sim._integrity.fused_arguments`: thresholds, non-centralities, fault-free
factors, exclusions allowed, one-sided identification). With it, :func:`epoch_fde` runs the
RAIM FDE of both solutions between the solvers and the estimate selection, with the kernels
the public :func:`~coopnav_env.nav.fde_standalone` and :func:`~coopnav_env.nav.fde_cooperative`
call on the same arguments, so that the modular path of
:class:`~coopnav_env.sim.scenario.UrbanWorld` (those public functions) gives the same epochs
bit for bit (``tests/envs/test_integrity_env.py``); :func:`used_integrity` then picks the
figures of the estimate each UAV uses from the two solutions' :class:`FixIntegrity`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from coopnav_env.nav import _integrity_kernels as _ik
from coopnav_env.nav import _kernels as _nav_kernels


class FixIntegrity(NamedTuple):
    """The integrity figures of each UAV's fix of one solution (standalone or cooperative)
    after FDE (:func:`used_integrity`)."""

    istat: np.ndarray  # (N,) int64 IntegrityStatus
    detected: np.ndarray  # (N,) bool a fault was detected
    n_excluded: np.ndarray  # (N,) int64 measurements excluded
    hpl: np.ndarray  # (N,) horizontal protection level [m] (inf: none)
    vpl: np.ndarray  # (N,) vertical protection level [m] (inf: none)


@njit(cache=True)
def used_integrity(source, cooperative, standalone):
    """The integrity figures of the estimate each UAV uses (``NavSource``: 0 cooperative,
    1 standalone, 2 dead reckoning: no protection, ``NO_FIX``), packed in one ``(5, N)``
    array (one array to return to Python; :func:`coopnav_env.sim._integrity.unpack`): the
    rows ``hpl, vpl, istat, fault_detected`` (either of the UAV's fixes detected a fault)
    and ``n_excluded``.

    Takes the selection's ``source`` (N,) int64 and the :class:`FixIntegrity` of the
    cooperative and of the standalone fixes (each may come as a plain tuple of its
    fields)."""
    co_istat, co_det, co_excl, co_hpl, co_vpl = cooperative
    sa_istat, sa_det, sa_excl, sa_hpl, sa_vpl = standalone
    n = source.shape[0]
    out = np.empty((5, n))
    for q in range(n):
        out[0, q] = np.inf
        out[1, q] = np.inf
        out[2, q] = _ik.INT_NO_FIX
        out[3, q] = 1.0 if (co_det[q] or sa_det[q]) else 0.0
        out[4, q] = 0.0
        if source[q] <= 1:  # a fix: the cooperative (0) or the standalone (1) one's figures
            co = source[q] == 0
            out[0, q] = co_hpl[q] if co else sa_hpl[q]
            out[1, q] = co_vpl[q] if co else sa_vpl[q]
            out[2, q] = co_istat[q] if co else sa_istat[q]
            out[4, q] = co_excl[q] if co else sa_excl[q]
    return out


@njit(cache=True)
def no_integrity():
    """:func:`used_integrity`'s output type without monitoring (empty)."""
    return np.empty((0, 0))


@njit(cache=True)
def fix_protection_levels(istat, dof, h_slope, v_slope, cov, rot, lam, k_h, k_v):
    """HPL and VPL of each fix (inf unless its test passed), one rotation for all."""
    n = istat.shape[0]
    hpl = np.full(n, np.inf)
    vpl = np.full(n, np.inf)
    for f in range(n):
        if istat[f] == _ik.INT_OK or istat[f] == _ik.INT_EXCLUDED:
            hpl[f], vpl[f] = _ik.protection_level(
                h_slope[f], v_slope[f], np.sqrt(lam[dof[f]]), cov[f], rot, k_h, k_v
            )
    return hpl, vpl


@njit(cache=True)
def epoch_fde(fde, obs, rel, solver, rot, sa, out):
    """RAIM FDE of an epoch's standalone and cooperative solutions (in place).

    ``fde``: ``(thr, lam, k_h, k_v, max_excl, positive_only)``; ``obs``: ``(vis, pr,
    sigma_user, sigma_common, sv, system, n_sys, el)``; ``rel``: the cooperative solve's
    relative rows ``(rel_b, var_b, avail_b, cen, ddt)``; ``solver``: ``(max_iter, tol_m,
    check, r_lo, r_hi)``; ``rot``: the city's ECEF -> ENU rotation; ``sa``: the first five
    outputs of ``standalone_solve``, ``out``: those of ``cooperative_isotropic`` (both updated
    in place). Returns the figures of each UAV's cooperative and standalone fix, the
    arguments of :func:`used_integrity` after the source: two :class:`FixIntegrity`.
    """
    thr, lam, k_h, k_v, max_excl, positive_only = fde
    rel_b, var_b, avail_b, cen, ddt = rel
    test = (thr, max_excl, positive_only)
    n = obs[0].shape[0]
    rot_n = np.empty((n, 3, 3))
    for q in range(n):
        rot_n[q] = rot
    sa_istat, sa_det, sa_excl, _ex, _t, sa_dof, sa_h, sa_v = _ik.standalone_fde(
        obs, solver, sa, rot_n, test
    )
    n_b = cen.shape[0]
    bavail, base, bcov, froot = _nav_kernels.isotropic_setup(rel_b, var_b, avail_b, cen)
    setup = (base, bcov, froot, bavail, cen, ddt, -1, n_b == 1)
    co_istat_b, co_det_b, co_excl_b, _ex, _t, co_dof_b, co_h_b, co_v_b = _ik.cooperative_fde(
        obs, setup, solver, out[:9], rot_n[:n_b], test
    )
    h_star, uav_cov = out[1], out[7]
    # per UAV: its own centroid's figures, or the shared centroid's (NO_FIX without a link)
    co_istat = np.empty(n, dtype=np.int64)
    co_det = np.empty(n, dtype=np.bool_)
    co_excl = np.empty(n, dtype=np.int64)
    co_dof = np.empty(n, dtype=np.int64)
    co_h = np.empty(n)
    co_v = np.empty(n)
    co_cov = np.empty((n, 3, 3))
    for q in range(n):
        b = q if n_b > 1 else 0
        co_istat[q] = co_istat_b[b] if (n_b > 1 or bavail[0, q]) else _ik.INT_NO_FIX
        co_det[q] = co_det_b[b]
        co_excl[q] = co_excl_b[b]
        co_dof[q] = co_dof_b[b]
        co_h[q] = co_h_b[b]
        co_v[q] = co_v_b[b]
        co_cov[q] = h_star[q] if n_b > 1 else uav_cov[0, q]
    sa_cov = sa[1]
    sa_hpl, sa_vpl = fix_protection_levels(sa_istat, sa_dof, sa_h, sa_v, sa_cov, rot, lam, k_h, k_v)
    co_hpl, co_vpl = fix_protection_levels(co_istat, co_dof, co_h, co_v, co_cov, rot, lam, k_h, k_v)
    return (
        FixIntegrity(co_istat, co_det, co_excl, co_hpl, co_vpl),
        FixIntegrity(sa_istat, sa_det, sa_excl, sa_hpl, sa_vpl),
    )
