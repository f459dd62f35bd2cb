"""One epoch's navigation with integrity monitoring in one compiled call.

:func:`epoch_navigation_fde` is :func:`coopnav_env.sim._kernels.epoch_navigation` with the
RAIM FDE of :mod:`coopnav_env.nav.integrity` between the solvers and the estimate selection:
the same stages (``epoch_observations``, ``epoch_solutions``, ``epoch_selection``) and the
integrity kernels the public functions :func:`~coopnav_env.nav.fde_standalone` and
:func:`~coopnav_env.nav.fde_cooperative` call, on the same arguments, so that the modular
path of :class:`~coopnav_env.sim.scenario.UrbanWorld` (those public functions) gives the same
epochs bit for bit (``tests/envs/test_integrity_env.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from coopnav_env.nav import _integrity_kernels as _ik
from coopnav_env.nav import _kernels as _nav_kernels
from coopnav_env.sim._kernels import (
    cooperative_fixes,
    epoch_observations,
    epoch_selection,
    epoch_solutions,
)


@njit(cache=True)
def used_integrity(
    source, co_istat, co_det, co_excl, co_hpl, co_vpl, sa_istat, sa_det, sa_excl, sa_hpl, sa_vpl
):
    """The integrity figures of the estimate each UAV uses (``NavSource``: 0 cooperative,
    1 standalone, 2 dead reckoning: no protection, ``NO_FIX``). ``fault_detected`` is
    whether either of the UAV's fixes detected a fault. Returns ``hpl, vpl, istat,
    fault_detected, n_excluded``."""
    n = source.shape[0]
    hpl = np.full(n, np.inf)
    vpl = np.full(n, np.inf)
    istat = np.full(n, _ik.INT_NO_FIX, dtype=np.int64)
    n_excl = np.zeros(n, dtype=np.int64)
    det = np.zeros(n, dtype=np.bool_)
    for q in range(n):
        det[q] = co_det[q] or sa_det[q]
        if source[q] == 0:
            hpl[q], vpl[q], istat[q], n_excl[q] = co_hpl[q], co_vpl[q], co_istat[q], co_excl[q]
        elif source[q] == 1:
            hpl[q], vpl[q], istat[q], n_excl[q] = sa_hpl[q], sa_vpl[q], sa_istat[q], sa_excl[q]
    return hpl, vpl, istat, det, n_excl


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
def epoch_navigation_fde(
    range_m,
    el_deg,
    sv,
    system,
    received,
    clock,
    iono,
    z_common,
    z_user,
    extra,
    el_ref,
    sigma_ure,
    tropo,
    differential,
    n_sys,
    x0,
    rel_b,
    var_b,
    avail_b,
    cen,
    x0_co,
    ddt,
    max_iter,
    tol_m,
    check,
    r_lo,
    r_hi,
    linked,
    gate_on,
    gate2,
    origin,
    rot,
    pred_enu,
    prev_cov,
    dr_var,
    route,
    next_wp,
    reach_m,
    avail,
    thr,  # (D + 1,) chi-square thresholds per degree of freedom
    lam,  # (D + 1,) detectable non-centralities
    k_h,
    k_v,
    max_excl,
    positive_only,
):
    """:func:`~coopnav_env.sim._kernels.epoch_navigation` with RAIM FDE of both solutions.

    Arguments: those of ``epoch_navigation``, then the threshold tables, the fault-free
    factors, the exclusions allowed per fix and whether only positive residuals are
    identified. A fix whose fault could not be cleared has
    ``NavStatus.FAULT_DETECTED`` and is not used (the selection takes the next source).
    Returns ``epoch_navigation``'s outputs and the integrity figures of the estimate each UAV
    uses: ``hpl, vpl, istat, fault_detected, n_excluded`` (:func:`used_integrity`).
    """
    n = received.shape[0]
    pr, vis, su, sc, el = epoch_observations(
        range_m,
        el_deg,
        system,
        received,
        clock,
        iono,
        z_common,
        z_user,
        extra,
        el_ref,
        sigma_ure,
        tropo,
        differential,
    )
    sa, out = epoch_solutions(
        pr,
        vis,
        sv,
        system,
        su,
        sc,
        el,
        n_sys,
        x0,
        rel_b,
        var_b,
        avail_b,
        cen,
        x0_co,
        ddt,
        max_iter,
        tol_m,
        check,
        r_lo,
        r_hi,
    )
    sa_pos, sa_cov, sa_clk, sa_status, sa_n_used, sa_n_iter = sa
    rot_n = np.empty((n, 3, 3))
    for q in range(n):
        rot_n[q] = rot
    sa_istat, sa_det, sa_excl, _ex, _t, sa_dof, sa_h, sa_v = _ik.standalone_fde(
        vis,
        pr,
        sv,
        su,
        sc,
        system,
        n_sys,
        max_iter,
        tol_m,
        check,
        r_lo,
        r_hi,
        sa_pos,
        sa_cov,
        sa_clk,
        sa_status,
        sa_n_used,
        rot_n,
        thr,
        max_excl,
        positive_only,
    )
    n_b = cen.shape[0]
    bavail, base, bcov, froot = _nav_kernels.isotropic_setup(rel_b, var_b, avail_b, cen)
    c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status, co_n_iter = out
    rot_b = rot_n[:n_b]
    co_istat_b, co_det_b, co_excl_b, _ex, _t, co_dof_b, co_h_b, co_v_b = _ik.cooperative_fde(
        pr,
        vis,
        sv,
        system,
        su,
        sc,
        el,
        n_sys,
        base,
        bcov,
        froot,
        bavail,
        cen,
        ddt,
        -1,
        max_iter,
        tol_m,
        check,
        r_lo,
        r_hi,
        n_b == 1,
        c_pos,
        c_clk,
        c_status,
        h_star,
        n_uavs,
        n_meas,
        uav_pos,
        uav_cov,
        uav_status,
        rot_b,
        thr,
        max_excl,
        positive_only,
    )
    co_pos, co_cov, co_status = cooperative_fixes(
        (c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status, co_n_iter),
        n_b,
    )
    # per UAV: its own centroid's figures, or the shared centroid's (NO_FIX without a link)
    co_istat = np.empty(n, dtype=np.int64)
    co_det = np.empty(n, dtype=np.bool_)
    co_excl = np.empty(n, dtype=np.int64)
    co_dof = np.empty(n, dtype=np.int64)
    co_h = np.empty(n)
    co_v = np.empty(n)
    for q in range(n):
        b = q if n_b > 1 else 0
        co_istat[q] = co_istat_b[b] if (n_b > 1 or bavail[0, q]) else _ik.INT_NO_FIX
        co_det[q] = co_det_b[b]
        co_excl[q] = co_excl_b[b]
        co_dof[q] = co_dof_b[b]
        co_h[q] = co_h_b[b]
        co_v[q] = co_v_b[b]
    sa_hpl, sa_vpl = fix_protection_levels(sa_istat, sa_dof, sa_h, sa_v, sa_cov, rot, lam, k_h, k_v)
    co_hpl, co_vpl = fix_protection_levels(co_istat, co_dof, co_h, co_v, co_cov, rot, lam, k_h, k_v)
    sel, wp, n_swarm = epoch_selection(
        sa_status,
        sa_pos,
        sa_cov,
        co_status,
        co_pos,
        co_cov,
        linked,
        gate_on,
        gate2,
        origin,
        rot,
        pred_enu,
        prev_cov,
        dr_var,
        route,
        next_wp,
        reach_m,
        avail,
        received,
    )
    integrity = used_integrity(
        sel[5],
        co_istat,
        co_det,
        co_excl,
        co_hpl,
        co_vpl,
        sa_istat,
        sa_det,
        sa_excl,
        sa_hpl,
        sa_vpl,
    )
    return sa_status, sa_n_iter, co_n_iter, sel, wp, n_swarm, integrity
