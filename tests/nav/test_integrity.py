"""Integrity monitoring (coopnav_env.nav.integrity): RAIM, FDE and protection levels.

Geometry: the nominal GPS + BeiDou-3 constellation over the paper's Shanghai site, a swarm of
five UAVs 30 m apart (as ``coopnav demo``); UAV 0 flies in the paper's street canyon (Eq. 25,
``h/d = sqrt(3)``, the default gaps), the others in open sky above a 10 deg mask. The error
model is the paper's (``tests/nav/scenario.py``). At ``t = 7200 s`` the canyon UAV receives 5
satellites (3 GPS + 2 BDS): as many as its 5 unknowns, so its own residual test has no degree
of freedom; at ``t = 0`` it receives 6 (one degree of freedom: a fault can be detected but not
identified). The open-sky UAVs receive 15 satellites.

Monte Carlo tolerances: a rate estimated from ``K`` independent trials has the binomial
standard error ``sqrt(p (1 - p) / K)``; each check allows 4 standard errors of the predicted
rate (two-sided p = 6e-5 per check), stated next to each sample size. Fixed seeds make every
run identical.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from coopnav_env.constants import SHANGHAI_ALT_M, SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG
from coopnav_env.gnss import azimuth_elevation, default_constellation, enu_rotation, enu_to_ecef
from coopnav_env.nav import (
    GnssObservations,
    IntegrityStatus,
    NavStatus,
    RelativePositions,
    VirtualPoint,
    fde_cooperative,
    fde_standalone,
    integrity_rates,
    solve_cooperative,
    solve_standalone,
)
from coopnav_env.nav import _integrity_kernels as ik
from coopnav_env.nav import _kernels as nav_kernels
from coopnav_env.nav import integrity as integ
from coopnav_env.nav.cooperative import _dense_system, _linearize, _setup, _sort_by_system
from coopnav_env.sim import CanyonMask
from tests.nav import oracles
from tests.nav.scenario import Scenario, sig_tropo, sig_user

LAT, LON, ALT = SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M + 30.0
ROT = enu_rotation(LAT, LON)
FORMATION = np.array([[0, 0, 0], [30, 0, 0], [-30, 0, 0], [0, 30, 0], [0, -30, 0]], float)


def paper_swarm(t_s: float, n: int = 5, canyon: bool = True, seed: int = 0) -> Scenario:
    """The swarm at GNSS time ``t_s``; UAV 0 behind the Eq. 25 canyon mask if ``canyon``."""
    const = default_constellation()
    pos = enu_to_ecef(FORMATION[:n], LAT, LON, ALT)
    sv_all = const.positions_ecef(float(t_s))
    az, el = azimuth_elevation(pos, sv_all)
    keep = (el > 10.0).any(axis=0)
    az, el = az[:, keep], el[:, keep]
    vis = el > 10.0
    if canyon:
        vis[0] &= CanyonMask().visible(az[0], el[0])
    system = np.asarray(const.system)[keep]
    assert np.all(np.diff(system) >= 0)  # grouped by constellation, as the solvers order them
    rng = np.random.default_rng(seed)
    return Scenario(
        pos_ecef=pos,
        sv_ecef=sv_all[keep],
        system=system,
        visible=vis,
        el_deg=el,
        az_deg=az,
        sigma_user=sig_user(np.maximum(el, 1.0)),
        sigma_common=np.sqrt(1.0 + sig_tropo(el.mean(axis=0)) ** 2),
        clock=rng.uniform(-3e4, 3e4, (n, 2)),
        sigma_d=np.full((n, n), 0.5),
        rot=ROT,
    )


def with_bias(obs: GnssObservations, q: int, k: int, bias_m: float) -> GnssObservations:
    pr = obs.pr_m.copy()
    pr[q, k] += bias_m
    return GnssObservations(
        pr, obs.sv_ecef_m, obs.system, obs.sigma_user_m, obs.sigma_common_m, obs.el_deg
    )


def sigma_total(sc: Scenario, q: int, k: int) -> float:
    """Standard deviation of one pseudorange (receiver plus common errors)."""
    return float(np.hypot(sc.sigma_user[q, k], sc.sigma_common[k]))


def h_error(sc: Scenario, pos_ecef: np.ndarray) -> np.ndarray:
    d = (pos_ecef - sc.pos_ecef) @ ROT.T
    return np.hypot(d[..., 0], d[..., 1])


def standalone_reference(sc: Scenario, q: int):
    """Receiver ``q``'s noiseless observations and the dense reference statistics of its
    standalone fix at the truth (``tests/nav/oracles.problem_statistics``' outputs)."""
    sub = sc.observations(noise=False).subset_receivers([q])
    w = np.where(sub.visible, 1.0 / (sub.sigma_user_m**2 + sub.sigma_common_m**2), 0.0)
    hc = np.zeros(2, bool)
    hc[np.unique(sub.system[sub.visible[0]])] = True
    out = oracles.problem_statistics(
        np.nan_to_num(sub.pr_m),
        sub.sv_ecef_m,
        sub.system,
        sub.visible,
        np.nan_to_num(w),
        np.zeros(sub.n_sv),
        sc.pos_ecef[q],
        sc.clock[q],
        np.zeros((1, 3)),
        np.zeros((1, 3, 3)),
        0,
        hc,
        ROT,
    )
    return sub, out


def gls_statistic(g: np.ndarray, a: np.ndarray, cov: np.ndarray) -> float:
    """Minimum weighted sum of squared residuals of ``a ~ g x`` with covariance ``cov``."""
    ci = np.linalg.inv(cov)
    r = a - g @ np.linalg.solve(g.T @ ci @ g, g.T @ ci @ a)
    return float(r @ ci @ r)


def binomial_tol(p: float, k: int) -> float:
    """Four binomial standard errors of a rate ``p`` estimated from ``k`` trials."""
    return 4.0 * math.sqrt(p * (1.0 - p) / k)


# --------------------------------------------------------------------------------------------
# distributions (scipy is a test dependency only)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [1, 2, 3, 5, 10, 37, 120, 400])
def test_chi2_quantile_and_noncentral_cdf_match_scipy(k) -> None:
    for p in (0.5, 0.05, 1e-3, 1e-7):
        x = ik.chi2_isf(p, float(k))
        assert x == pytest.approx(stats.chi2.isf(p, k), rel=1e-10)
        assert ik.chi2_sf(x, float(k)) == pytest.approx(p, rel=1e-10)
    for lam in (0.3, 4.0, 40.0, 300.0):
        for x in (0.2, 0.5 * k, k + lam, k + lam + 6 * math.sqrt(2 * (k + 2 * lam))):
            want = stats.ncx2.cdf(x, k, lam)
            assert ik.ncx2_cdf(x, float(k), lam) == pytest.approx(want, rel=1e-9, abs=1e-13)
    thr = ik.chi2_isf(1e-3, float(k))
    for p_md in (0.5, 1e-3, 1e-7):
        lam = ik.ncx2_lambda(thr, float(k), p_md)
        assert stats.ncx2.cdf(thr, k, lam) == pytest.approx(p_md, rel=1e-8)


def test_normal_quantile_and_gamma_match_scipy() -> None:
    for p in (1e-12, 1e-7, 0.01, 0.02425, 0.3, 0.5, 0.9, 0.99):
        assert ik.norm_ppf(p) == pytest.approx(stats.norm.ppf(p), rel=1e-12, abs=1e-12)
    # near 1 the double p itself carries the error (1 - p has lost 7 digits)
    assert ik.norm_ppf(1 - 1e-9) == pytest.approx(stats.norm.ppf(1 - 1e-9), rel=1e-9)
    for a in (0.5, 1.0, 7.5, 60.0):
        for x in (0.01, a, 3.0 * a + 5.0):
            assert ik.gamma_p(a, x) == pytest.approx(stats.gamma.cdf(x, a), rel=1e-12)
            assert ik.gamma_q(a, x) == pytest.approx(stats.gamma.sf(x, a), rel=1e-11)


def test_threshold_tables_and_protection_factors() -> None:
    thr, lam = integ.threshold_tables(1e-3, 1e-7, 30)
    assert np.isnan(thr[0]) and np.isnan(lam[0]) and thr.shape[0] >= 31
    for d in (1, 4, 30):
        assert thr[d] == pytest.approx(stats.chi2.isf(1e-3, d), rel=1e-10)
        assert stats.ncx2.cdf(thr[d], d, lam[d]) == pytest.approx(1e-7, rel=1e-7)
    assert not thr.flags.writeable
    k_h, k_v = integ.protection_factors(1e-7)
    assert stats.chi2.sf(k_h**2, 2) == pytest.approx(1e-7, rel=1e-12)
    assert 2 * stats.norm.sf(k_v) == pytest.approx(1e-7, rel=1e-10)


# --------------------------------------------------------------------------------------------
# the statistic uses the exact covariance
# --------------------------------------------------------------------------------------------


def _problem_args(obs, rel, centroid, transfer, sol, b):
    obs_s, _ = _sort_by_system(obs)
    st = _setup(obs_s, rel, centroid, transfer, None, "exact")
    w = np.where(obs_s.visible, 1.0 / np.nan_to_num(obs_s.sigma_user_m, nan=1.0) ** 2, 0.0)
    common = (
        np.nan_to_num(obs_s.pr_m),
        obs_s.sv_ecef_m,
        obs_s.system,
        st.used[b],
        w,
        obs_s.sigma_common_m,
        sol.centroid_pos_ecef_m[b],
        np.nan_to_num(sol.centroid_clock_m[b]),
        st.base[b],
    )
    return common, st


def kernel_statistics(args, froot):
    """The compiled statistics on :func:`_problem_args`'s arguments (it eliminates every
    UAV's clocks itself: no clock estimate, reference or clock columns)."""
    pr, sv, system, rows, w, sig_c, pos, _clk, base = args
    # the kernel's records (ik.FixRows, ik.FixPoint) as plain tuples
    return ik.problem_statistics(
        (pr, sv, system, 2, rows, w, sig_c), (pos, base, froot), ROT, False
    )


@pytest.mark.parametrize("transfer", ["ddt", "sdt"])
@pytest.mark.parametrize("centroid", ["self", 2, "virtual"])
def test_compiled_statistics_equal_the_dense_reference(transfer, centroid) -> None:
    """The structured kernel (C* never formed, every UAV's clocks eliminated) against numpy with
    C* formed densely and the solver's clock parametrisation (the reference's clocks plus
    nuisance clocks) as columns: statistic, degrees of freedom, identified row, slopes. An
    anisotropic relative covariance exercises the full rank-3 relative-error terms."""
    sc = paper_swarm(0.0, n=4)
    rng = np.random.default_rng(3)
    obs = with_bias(sc.observations(rng), 2, int(np.flatnonzero(sc.visible[2])[4]), 25.0)
    cov_enu = np.diag([0.3, 0.8, 0.5]) ** 2 + 0.02
    rel = sc.relative(rng, cov_enu=np.broadcast_to(cov_enu, (4, 4, 3, 3)).copy())
    if centroid == "virtual":
        base = sc.pos_ecef - sc.pos_ecef.mean(axis=0)
        cen = VirtualPoint(
            base, np.broadcast_to(ROT.T @ cov_enu @ ROT, (4, 3, 3)), np.ones(4, bool)
        )
    else:
        cen = centroid
    sol = solve_cooperative(obs, rel, transfer=transfer, centroid=cen)
    for b in range(sol.centroid_pos_ecef_m.shape[0]):
        if sol.centroid_status[b] != NavStatus.OK:
            continue
        args, st = _problem_args(obs, rel, cen, transfer, sol, b)
        ref, hc = int(st.ref[b]), st.has_clock[b]
        got = kernel_statistics(args, st.froot[b])
        want = oracles.problem_statistics(*args, st.bcov[b], ref, hc, ROT)
        assert got[0]
        assert got[1] == pytest.approx(want[1], rel=1e-9)
        assert got[2] == want[2] > 10
        assert got[3:5] == want[3:5] == (2, int(np.flatnonzero(sc.visible[2])[4]))
        assert got[5] == pytest.approx(want[5], rel=1e-8)
        assert got[6] == pytest.approx(want[6], rel=1e-8)
        assert got[7] == pytest.approx(want[7], rel=1e-8)


def _bits(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float64).view(np.int64)


def test_scalar_3x3_inverses_equal_the_solvers_bit_for_bit() -> None:
    """The statistics kernels invert their 3x3 matrices in scalars (no arrays: no allocation
    or reference counting); they must give what the solvers' array versions
    (``nav._kernels._cholesky_inverse_into``, ``_inv3``) give, bit for bit: 3000 random
    symmetric positive definite matrices with scales over 12 orders of magnitude, and
    matrices that are not positive definite (reported by both)."""
    rng = np.random.default_rng(11)
    low, linv, out = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    upper = np.triu_indices(3)  # (0,0) (0,1) (0,2) (1,1) (1,2) (2,2): the scalars' order
    n_failed = 0
    for t in range(3000):
        g = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-6.0, 6.0, size=3)[:, None]
        a = g @ g.T
        if t % 10 == 0:  # indefinite or singular
            a[2, 2] = -abs(a[2, 2]) if t % 20 == 0 else a[2, 0] ** 2 / a[0, 0]
        ok = nav_kernels._cholesky_inverse_into(a, out, low, linv)
        got = ik.cholesky_inverse3(a[0, 0], a[1, 0], a[1, 1], a[2, 0], a[2, 1], a[2, 2])
        assert got[0] == ok
        n_failed += not ok
        if ok:
            assert (_bits(got[1:]) == _bits(out[upper])).all()
        a_sym = np.triu(a) + np.triu(a, 1).T  # _inv3 reads the upper triangle
        nav_kernels._inv3(a_sym, out)
        got3 = ik.inverse3_sym(a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2])
        assert (_bits(got3) == _bits(out[upper])).all()
    assert n_failed >= 150  # every 20th matrix is indefinite


@pytest.mark.parametrize("q", [0, 1])
def test_standalone_statistics_equal_the_dense_reference(q) -> None:
    """The O(m) standalone path (clocks by weighted mean removal) against the general
    compiled path and the dense reference, on a receiver with a 25 m fault (the canyon UAV,
    one degree of freedom at t = 0, and an open-sky one)."""
    sc = paper_swarm(0.0)
    rng = np.random.default_rng(6)
    k = int(np.flatnonzero(sc.visible[q])[2])
    sub = with_bias(sc.observations(rng), q, k, 25.0).subset_receivers([q])
    sol = solve_standalone(sub, sc.pos_ecef[q])
    w = np.nan_to_num(1.0 / (sub.sigma_user_m**2 + sub.sigma_common_m**2))
    pr, zs = np.nan_to_num(sub.pr_m), np.zeros(sub.n_sv)
    # the kernels' records (ik.ReceiverRows; ik.FixRows, ik.FixPoint) as plain tuples
    fast = ik.standalone_statistics(
        (pr[0], sub.sv_ecef_m, sub.system, 2, sub.visible[0], w[0]),
        sol.pos_ecef_m[0],
        ROT,
        False,
        np.empty((sub.n_sv, 4)),
    )
    pos, base, root = sol.pos_ecef_m[0], np.zeros((1, 3)), np.zeros((1, 3, 3))
    general = ik.problem_statistics(
        (pr, sub.sv_ecef_m, sub.system, 2, sub.visible, w, zs), (pos, base, root), ROT, False
    )
    hc = np.ones(2, bool)
    dense = oracles.problem_statistics(
        pr,
        sub.sv_ecef_m,
        sub.system,
        sub.visible,
        w,
        zs,
        pos,
        sol.clock_m[0],
        base,
        root,
        0,
        hc,
        ROT,
    )
    assert fast[2] == general[2] == dense[2] == (1 if q == 0 else 8)
    assert fast[3:5] == general[3:5] == dense[3:5]
    for i in (1, 5, 6, 7):
        assert fast[i] == pytest.approx(dense[i], rel=1e-9)
        assert general[i] == pytest.approx(dense[i], rel=1e-9)


@pytest.mark.parametrize("centroid", ["self", 1])
def test_ddt_statistic_equals_the_literal_double_differences_with_dense_c_star(centroid) -> None:
    """The undifferenced form with nuisance clocks gives exactly the residual statistic of the
    literal double differences (Eq. 12) weighted by the inverse of their dense, correlated
    covariance C* (the solver's dense reference, ``cooperative._dense_system``); with the
    diagonal of C* instead (correlations ignored) the statistic is different."""
    sc = paper_swarm(7200.0, n=4)
    rng = np.random.default_rng(5)
    obs, rel = sc.observations(rng), sc.relative(rng)
    sol = solve_cooperative(obs, rel, transfer="ddt", centroid=centroid)
    obs_s, _ = _sort_by_system(obs)
    for b in range(sol.centroid_pos_ecef_m.shape[0]):
        args, st = _problem_args(obs, rel, centroid, "ddt", sol, b)
        got = kernel_statistics(args, st.froot[b])
        clk = np.nan_to_num(sol.centroid_clock_m)
        lin = _linearize(obs_s, st, sol.centroid_pos_ecef_m, clk, True)
        g, a, cov, _eps = _dense_system(obs_s, st, lin, "ddt", "exact", b)
        g = g[:, np.abs(g).sum(axis=0) > 0]
        assert a.size - g.shape[1] == got[2]  # the same degrees of freedom
        assert gls_statistic(g, a, cov) == pytest.approx(got[1], rel=1e-9)
        assert abs(gls_statistic(g, a, np.diag(np.diag(cov))) - got[1]) > 1e-3 * got[1]


@pytest.mark.slow
def test_statistic_is_chi_square_only_with_the_correlated_covariance() -> None:
    """K = 1500 noise draws of the literal DDT problem at the canyon UAV (dof 39): the
    statistic with the dense C* has mean dof and variance 2 dof (SE of the mean
    sqrt(2 dof / K) = 0.23; of the sample variance, from the chi-square's kurtosis,
    sqrt(8 dof (dof + 6) / K) = 3.4; both checked at 4 SE; measured 38.9 and 78.4). The same
    residuals weighted with the diagonal of C* only (correlations ignored, as a per-row
    weighting like RTKLIB's does) are not chi-square: mean 27.8, off by more than 8 SE."""
    k_samples = 1500
    sc = paper_swarm(7200.0, n=4)
    rng = np.random.default_rng(11)
    t_full, t_diag = [], []
    obs_s = None
    for _ in range(k_samples):
        obs, rel = sc.observations(rng), sc.relative(rng)
        sol = solve_cooperative(obs, rel, transfer="ddt", centroid=0, x0_ecef_m=sc.pos_ecef[0])
        obs_s, _ = _sort_by_system(obs)
        st = _setup(obs_s, rel, 0, "ddt", None, "exact")
        clk = np.nan_to_num(sol.centroid_clock_m)
        lin = _linearize(obs_s, st, sol.centroid_pos_ecef_m, clk, True)
        g, a, cov, _eps = _dense_system(obs_s, st, lin, "ddt", "exact", 0)
        g = g[:, np.abs(g).sum(axis=0) > 0]
        t_full.append(gls_statistic(g, a, cov))
        t_diag.append(gls_statistic(g, a, np.diag(np.diag(cov))))
    dof = a.size - g.shape[1]
    se = math.sqrt(2 * dof / k_samples)
    t_full, t_diag = np.array(t_full), np.array(t_diag)
    assert abs(t_full.mean() - dof) < 4 * se, (t_full.mean(), dof)
    var_se = 2 * dof * math.sqrt(2 * (dof + 6) / (dof * k_samples))
    assert abs(t_full.var() - 2 * dof) < 4 * var_se
    assert abs(t_diag.mean() - dof) > 8 * se, (t_diag.mean(), dof)


# --------------------------------------------------------------------------------------------
# Monte Carlo: false alarms, detection, protection levels
# --------------------------------------------------------------------------------------------


def _open_sky_swarm(seed=0):
    return paper_swarm(7200.0, n=5, canyon=False, seed=seed)


@pytest.mark.slow
@pytest.mark.parametrize("p_fa", [0.05, 1e-3])
def test_false_alarm_rate_of_the_standalone_test(p_fa) -> None:
    """No fault: the share of failed tests matches ``p_fa``. K = 2000 epochs x 5 receivers
    (the receivers' tests are nearly independent: they share only the common errors).
    p_fa = 0.05: 10000 tests, 4 SE = 0.0087; p_fa = 1e-3: 4 SE = 0.0013 (the rate must also
    be above 0, i.e. the test is not trivially conservative)."""
    k_samples = 2000
    sc = _open_sky_swarm()
    rng = np.random.default_rng(21)
    alarms = 0
    for _ in range(k_samples):
        _sa, res = fde_standalone(
            sc.observations(rng),
            p_fa=p_fa,
            max_exclusions=0,
            enu_rotation=ROT,
            x0_ecef_m=sc.pos_ecef,
        )
        assert np.all(res.dof == 10)
        alarms += int(res.fault_detected.sum())
    rate = alarms / (5 * k_samples)
    assert abs(rate - p_fa) < binomial_tol(p_fa, 5 * k_samples), rate
    assert alarms > 0


@pytest.mark.slow
@pytest.mark.parametrize("p_fa", [0.05, 1e-3])
def test_false_alarm_rate_of_the_cooperative_test(p_fa) -> None:
    """No fault, cooperative DDT with one shared centroid at the canyon UAV (its 5
    satellites plus the 4 open-sky UAVs' 15 each, less 8 nuisance clocks and 5 unknowns:
    dof 52). K = 2000 epochs;
    p_fa = 0.05: 4 SE = 0.0195; p_fa = 1e-3: 4 SE = 0.0028."""
    k_samples = 2000
    sc = paper_swarm(7200.0)
    rng = np.random.default_rng(22)
    alarms = 0
    for _ in range(k_samples):
        obs, rel = sc.observations(rng), sc.relative(rng)
        _co, res = fde_cooperative(
            obs,
            rel,
            centroid=0,
            p_fa=p_fa,
            max_exclusions=0,
            enu_rotation=ROT,
            x0_ecef_m=sc.pos_ecef[0],
        )
        assert res.dof[0] == 52
        alarms += int(res.fault_detected[0])
    rate = alarms / k_samples
    assert abs(rate - p_fa) < binomial_tol(p_fa, k_samples), rate


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["standalone", "cooperative"])
def test_detection_rate_follows_the_noncentral_chi_square(solver) -> None:
    """A bias ``b`` on one pseudorange makes the statistic chi2(dof, b^2 R_ii): the detection
    rate at p_fa = 0.05 for b = 1.5, 3 and 4.5 sigma matches ``1 - F_ncx2(thr; dof, lambda)``
    with ``R_ii`` from the dense reference at the truth. K = 1000 per bias, 4 SE <= 0.063.
    Standalone: an open-sky receiver; cooperative: a satellite of the canyon UAV (whose own
    test has no degree of freedom), shared centroid at UAV 1."""
    k_samples = 1000
    sc = paper_swarm(7200.0)
    q = 1 if solver == "standalone" else 0
    k = int(np.flatnonzero(sc.visible[q])[2])
    rng = np.random.default_rng(23)
    obs0, rel0 = sc.observations(noise=False), sc.relative(noise=False)
    if solver == "standalone":
        sub, ref_stats = standalone_reference(sc, q)
        row = int(np.searchsorted(np.flatnonzero(sub.visible[0]), k))
    else:
        sol = solve_cooperative(obs0, rel0, centroid=1)
        args, st = _problem_args(obs0, rel0, 1, "ddt", sol, 0)
        ref_stats = oracles.problem_statistics(*args, st.bcov[0], 1, st.has_clock[0], ROT)
        qq, kk = np.nonzero(st.used[0])
        row = int(np.flatnonzero((qq == q) & (kk == k))[0])
    dof, r_ii = ref_stats[2], ref_stats[9][row]
    thr = ik.chi2_isf(0.05, float(dof))
    sig = sigma_total(sc, q, k)
    for c in (1.5, 3.0, 4.5):
        bias = c * sig
        predicted = 1.0 - ik.ncx2_cdf(thr, float(dof), bias**2 * r_ii)
        hits = 0
        for _ in range(k_samples):
            obs = with_bias(sc.observations(rng), q, k, bias)
            if solver == "standalone":
                _s, res = fde_standalone(
                    obs.subset_receivers([q]), p_fa=0.05, max_exclusions=0, enu_rotation=ROT
                )
            else:
                _s, res = fde_cooperative(
                    obs,
                    sc.relative(rng),
                    centroid=1,
                    p_fa=0.05,
                    max_exclusions=0,
                    enu_rotation=ROT,
                )
            hits += int(res.fault_detected[0])
        rate = hits / k_samples
        assert abs(rate - predicted) < binomial_tol(predicted, k_samples), (c, rate, predicted)


@pytest.mark.slow
def test_ten_sigma_faults_are_detected_in_open_sky() -> None:
    """A bias of 10 sigma of the faulty pseudorange, on a random satellite of a random
    open-sky receiver, default p_fa = 1e-3: at least 99 % detected by the receiver's own
    test and by the cooperative test (self centroids). K = 1000 faults each; the predicted
    rate is >= 0.995 for every row (dense reference), so 99 % is 2.8 SE below the worst
    row's prediction and further below the average."""
    k_samples = 1000
    sc = _open_sky_swarm()
    rng = np.random.default_rng(24)
    hits_sa = hits_co = 0
    for _ in range(k_samples):
        q = int(rng.integers(5))
        k = int(rng.choice(np.flatnonzero(sc.visible[q])))
        obs = with_bias(sc.observations(rng), q, k, 10.0 * sigma_total(sc, q, k))
        _s, r_sa = fde_standalone(obs, max_exclusions=0, enu_rotation=ROT)
        _c, r_co = fde_cooperative(obs, sc.relative(rng), max_exclusions=0, enu_rotation=ROT)
        hits_sa += int(r_sa.fault_detected[q])
        hits_co += int(r_co.fault_detected[q])
    assert hits_sa / k_samples >= 0.99, hits_sa
    assert hits_co / k_samples >= 0.99, hits_co


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["standalone", "cooperative"])
def test_misleading_information_rate_is_within_the_integrity_risk(solver) -> None:
    """integrity_risk = 0.01, p_fa = 1e-3, FDE on. A bias on the row with the largest
    horizontal slope (the worst case of the bound) of 0, 0.5, 0.8, 1, 1.5 and 3 times the
    smallest bias the test detects with probability 1 - 0.01, and a fault-free case: the share
    of fixes that pass the monitor (OK or EXCLUDED) with a horizontal or vertical error above
    their protection level stays at or below 0.01 at each bias. K = 600 per bias: a true rate
    of 0.01 would be seen above 0.01 + 4 SE = 0.026 with probability 3e-5; the rate measured
    at the worst bias is reported in the assertion message."""
    k_samples = 600
    ir = 0.01
    sc = _open_sky_swarm()
    q = 1
    rng = np.random.default_rng(25)
    obs0 = sc.observations(noise=False)
    rel0 = sc.relative(noise=False)
    # the worst row and its minimal detectable bias, from the noiseless geometry
    if solver == "standalone":
        sub, out = standalone_reference(sc, q)
        rows_k = np.flatnonzero(sub.visible[0])
        rows_q = np.full(rows_k.size, q)
    else:
        sol = solve_cooperative(obs0, rel0, centroid=q)
        args, st = _problem_args(obs0, rel0, q, "ddt", sol, 0)
        out = oracles.problem_statistics(*args, st.bcov[0], q, st.has_clock[0], ROT)
        rows_q, rows_k = np.nonzero(st.used[0])
    dof, r_ii, gain = out[2], out[9], out[10]
    _thr, lam = integ.threshold_tables(1e-3, ir, dof)
    slope = np.hypot(*(ROT @ gain)[:2]) / np.sqrt(r_ii)
    worst = int(np.argmax(slope))
    qw, kw = int(rows_q[worst]), int(rows_k[worst])
    mdb = math.sqrt(lam[dof] / r_ii[worst])
    worst_rate = 0.0
    for f in (0.0, 0.5, 0.8, 1.0, 1.5, 3.0):
        mi = 0
        for _ in range(k_samples):
            obs = with_bias(sc.observations(rng), qw, kw, f * mdb)
            if solver == "standalone":
                sol_f, res = fde_standalone(obs, integrity_risk=ir, enu_rotation=ROT)
            else:
                sol_f, res = fde_cooperative(
                    obs, sc.relative(rng), centroid=q, integrity_risk=ir, enu_rotation=ROT
                )
            if not res.usable[q]:
                continue
            d = ROT @ (sol_f.pos_ecef_m[q] - sc.pos_ecef[q])
            mi += int(np.hypot(d[0], d[1]) > res.hpl_m[q] or abs(d[2]) > res.vpl_m[q])
        rate = mi / k_samples
        worst_rate = max(worst_rate, rate)
        assert rate <= ir + binomial_tol(ir, k_samples), (f, rate)
    assert worst_rate <= ir + binomial_tol(ir, k_samples), worst_rate


@pytest.mark.slow
def test_the_slope_only_bound_would_mislead_below_the_detectable_bias() -> None:
    """Why the protection level carries a fault-free term: an open-sky receiver, detection
    only, integrity_risk = 0.01, a bias of 0.75 times the detectable bias on its worst-slope
    row. The classic slope-only HPL (``Slope_max sqrt(lambda)``, our HPL less its fault-free
    term) is exceeded by undetected errors far more often than 0.01 (measured 0.029); ours is
    not. K = 2000: 0.01 + 4 SE = 0.019."""
    k_samples = 2000
    ir = 0.01
    sc = _open_sky_swarm()
    q = 1
    sub, out = standalone_reference(sc, q)
    dof, r_ii, gain = out[2], out[9], out[10]
    _thr, lam = integ.threshold_tables(1e-3, ir, dof)
    k_h, _k_v = integ.protection_factors(ir)
    worst = int(np.argmax(np.hypot(*(ROT @ gain)[:2]) / np.sqrt(r_ii)))
    k = int(np.flatnonzero(sub.visible[0])[worst])
    bias = 0.75 * math.sqrt(lam[dof] / r_ii[worst])
    rng = np.random.default_rng(26)
    mi_ours = mi_slope_only = 0
    for _ in range(k_samples):
        obs = with_bias(sc.observations(rng), q, k, bias).subset_receivers([q])
        sol, res = fde_standalone(obs, integrity_risk=ir, max_exclusions=0, enu_rotation=ROT)
        if not res.usable[0]:
            continue
        d = ROT @ (sol.pos_ecef_m[0] - sc.pos_ecef[q])
        c = ROT @ sol.cov_ecef_m2[0] @ ROT.T
        fault_free = k_h * math.sqrt(np.linalg.eigvalsh(c[:2, :2])[-1])
        mi_ours += int(np.hypot(d[0], d[1]) > res.hpl_m[0])
        mi_slope_only += int(np.hypot(d[0], d[1]) > res.hpl_m[0] - fault_free)
    assert mi_ours / k_samples <= ir
    assert mi_slope_only / k_samples > ir + binomial_tol(ir, k_samples), mi_slope_only


# --------------------------------------------------------------------------------------------
# the swarm's redundancy: a fault the canyon UAV alone cannot see
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("centroid", ["self", 0, 3])
def test_cooperative_fde_excludes_a_canyon_fault_the_standalone_test_cannot_see(
    centroid,
) -> None:
    """t = 7200 s: the canyon UAV receives 5 satellites for its 5 unknowns. A 60 m bias on
    any one of them: its standalone fix has no degree of freedom (NO_REDUNDANCY: the fault
    goes unseen and the fix, 100-150 m off, reports OK); the cooperative DDT solution
    (each centroid choice) detects it, excludes exactly that pseudorange and returns a fix
    within a few metres, under its protection level."""
    sc = paper_swarm(7200.0)
    assert sc.visible[0].sum() == 5 and set(sc.system[sc.visible[0]]) == {0, 1}
    rng = np.random.default_rng(31)
    for k in np.flatnonzero(sc.visible[0]):
        obs = with_bias(sc.observations(rng), 0, int(k), 60.0)
        rel = sc.relative(rng)
        sa, r_sa = fde_standalone(obs, x0_ecef_m=sc.pos_ecef)
        assert r_sa.status[0] == IntegrityStatus.NO_REDUNDANCY and r_sa.dof[0] == 0
        assert sa.status[0] == NavStatus.OK and not r_sa.fault_detected[0]
        assert np.isinf(r_sa.hpl_m[0])
        # ... while the unseen fault puts it 100-150 m off with a predicted sigma of 5.6 m
        err_sa = np.linalg.norm(sa.pos_ecef_m[0] - sc.pos_ecef[0])
        assert err_sa > 60.0 and err_sa > 10.0 * np.sqrt(np.trace(sa.cov_ecef_m2[0]))
        co, r_co = fde_cooperative(obs, rel, centroid=centroid, x0_ecef_m=sc.pos_ecef[0])
        assert r_co.fault_detected[0] and r_co.status[0] == IntegrityStatus.EXCLUDED
        assert r_co.n_excluded[0] == 1 and r_co.excluded[0, 0, k]
        assert co.status[0] == NavStatus.OK
        err_co = h_error(sc, co.pos_ecef_m)[0]
        assert err_co < 5.0 and err_co < r_co.hpl_m[0] < 50.0, (k, err_co, r_co.hpl_m[0])


def test_one_degree_of_freedom_detects_but_cannot_identify() -> None:
    """t = 0: the canyon UAV receives 6 satellites (1 degree of freedom). Its own test detects
    a 60 m fault but every normalised residual is equal, so nothing can be excluded: the fix
    is FAULT_DETECTED (not valid, the solver's fix kept for diagnosis). The swarm's test
    excludes it."""
    sc = paper_swarm(0.0)
    assert sc.visible[0].sum() == 6
    rng = np.random.default_rng(32)
    k = int(np.flatnonzero(sc.visible[0])[1])
    obs = with_bias(sc.observations(rng), 0, k, 60.0)
    plain = solve_standalone(obs, sc.pos_ecef)
    sa, r_sa = fde_standalone(obs, plain)
    assert r_sa.status[0] == IntegrityStatus.FAULT_DETECTED and r_sa.dof[0] == 1
    assert sa.status[0] == NavStatus.FAULT_DETECTED and r_sa.n_excluded[0] == 0
    assert np.array_equal(sa.pos_ecef_m[0], plain.pos_ecef_m[0]) and np.isinf(r_sa.hpl_m[0])
    assert r_sa.test_statistic[0] > r_sa.threshold[0]
    co, r_co = fde_cooperative(obs, sc.relative(rng))
    assert r_co.status[0] == IntegrityStatus.EXCLUDED and r_co.excluded[0, 0, k]
    assert h_error(sc, co.pos_ecef_m)[0] < 5.0


# --------------------------------------------------------------------------------------------
# statuses, exclusions, arguments
# --------------------------------------------------------------------------------------------


def test_statuses_of_degenerate_fixes_and_detection_only() -> None:
    sc = paper_swarm(7200.0)
    rng = np.random.default_rng(41)
    obs = sc.observations(rng)
    # the canyon UAV with one satellite less: too few for a standalone fix
    pr = obs.pr_m.copy()
    pr[0, np.flatnonzero(sc.visible[0])[0]] = np.nan
    few = GnssObservations(
        pr, obs.sv_ecef_m, obs.system, obs.sigma_user_m, obs.sigma_common_m, obs.el_deg
    )
    sa, res = fde_standalone(few, x0_ecef_m=sc.pos_ecef)
    assert sa.status[0] == NavStatus.TOO_FEW_SATELLITES
    assert res.status[0] == IntegrityStatus.NO_FIX and np.isinf(res.hpl_m[0])
    assert np.isnan(res.test_statistic[0]) and np.isnan(res.threshold[0])
    assert np.all(res.status[1:] == IntegrityStatus.OK)
    assert np.all(np.isfinite(res.hpl_m[1:])) and np.all(res.hpl_m[1:] > 0)
    # detection only: a 200 m fault on an open-sky receiver is flagged, nothing excluded
    k = int(np.flatnonzero(sc.visible[2])[0])
    bad = with_bias(obs, 2, k, 200.0)
    plain = solve_standalone(bad, sc.pos_ecef)
    sa, res = fde_standalone(bad, plain, max_exclusions=0)
    assert sa.status[2] == NavStatus.FAULT_DETECTED
    assert res.status[2] == IntegrityStatus.FAULT_DETECTED and res.n_excluded[2] == 0
    assert np.array_equal(sa.pos_ecef_m[2], plain.pos_ecef_m[2])
    assert not res.usable[2] and res.usable[1]
    # with exclusion: the same fault is removed and the fix is good again
    sa, res = fde_standalone(bad, plain)
    assert res.status[2] == IntegrityStatus.EXCLUDED and res.excluded[2, 2, k]
    assert res.excluded.sum() == 1 and h_error(sc, sa.pos_ecef_m)[2] < 10.0
    assert res.test_statistic[2] <= res.threshold[2]


def test_several_faults_are_excluded_one_by_one() -> None:
    """Two 80 m faults on two UAVs and a 150 m one on a third: the cooperative FDE (shared
    centroid) excludes the three, one per round, and nothing else."""
    sc = paper_swarm(7200.0)
    rng = np.random.default_rng(42)
    obs = sc.observations(rng)
    faults = [(1, 80.0), (2, 80.0), (3, 150.0)]
    picks = []
    for q, b in faults:
        k = int(np.flatnonzero(sc.visible[q])[q + 2])
        obs = with_bias(obs, q, k, b)
        picks.append((q, k))
    co, res = fde_cooperative(obs, sc.relative(rng), centroid=1)
    assert np.all(res.status == IntegrityStatus.EXCLUDED)
    assert np.all(res.n_excluded == 3)
    assert sorted(map(tuple, np.argwhere(res.excluded[0]).tolist())) == sorted(picks)
    assert np.all(h_error(sc, co.pos_ecef_m) < 5.0)


def test_one_sided_identification_under_many_nlos_faults() -> None:
    """35 % of the swarm's pseudoranges carry an NLOS-like delay (3 m + Exp(30 m)); six draws.
    With ``fault_sign="positive"`` FDE excludes only delayed measurements, in every draw; the
    two-sided choice also excludes good ones (the fix is pulled toward the many delayed
    measurements, and good ones show large negative residuals), here in four of the six."""
    sc = paper_swarm(7200.0)
    wrong_two_sided = 0
    for seed in range(6):
        rng = np.random.default_rng(seed)
        obs, rel = sc.observations(rng), sc.relative(rng)
        faulty = sc.visible & (rng.random(sc.visible.shape) < 0.35)
        pr = obs.pr_m.copy()
        pr[faulty] += 3.0 + rng.exponential(30.0, faulty.sum())
        obs = GnssObservations(
            pr, obs.sv_ecef_m, obs.system, obs.sigma_user_m, obs.sigma_common_m, obs.el_deg
        )
        co, res = fde_cooperative(obs, rel, centroid=1, fault_sign="positive")
        assert res.status[1] == IntegrityStatus.EXCLUDED
        assert not np.any(res.excluded[1] & ~faulty) and res.n_excluded[1] >= 0.6 * faulty.sum()
        assert h_error(sc, co.pos_ecef_m)[1] < 3.0
        _co, res2 = fde_cooperative(obs, rel, centroid=1)
        wrong_two_sided += int(np.any(res2.excluded[1] & ~faulty))
    assert wrong_two_sided == 4


def test_satellite_order_does_not_matter() -> None:
    """Satellites not grouped by constellation (the solver sorts them): the result is the
    same, and ``excluded`` is reported in the caller's satellite order."""
    sc = paper_swarm(7200.0)
    rng = np.random.default_rng(43)
    k = int(np.flatnonzero(sc.visible[0])[3])
    obs = with_bias(sc.observations(rng), 0, k, 60.0)
    rel = sc.relative(rng)
    perm = rng.permutation(obs.n_sv)
    shuffled = GnssObservations(
        obs.pr_m[:, perm],
        obs.sv_ecef_m[perm],
        obs.system[perm],
        obs.sigma_user_m[:, perm],
        obs.sigma_common_m[perm],
        obs.el_deg[:, perm],
    )
    co_a, r_a = fde_cooperative(obs, rel)
    co_b, r_b = fde_cooperative(shuffled, rel)
    assert np.allclose(co_a.pos_ecef_m, co_b.pos_ecef_m, atol=1e-6)
    assert np.array_equal(r_a.excluded[:, :, perm], r_b.excluded)
    assert np.allclose(r_a.hpl_m, r_b.hpl_m, rtol=1e-8)


def test_bad_arguments_raise_value_errors_naming_them() -> None:
    sc = paper_swarm(7200.0)
    obs, rel = sc.observations(noise=False), sc.relative(noise=False)
    for kw, name in (
        ({"p_fa": 0.0}, "p_fa"),
        ({"p_fa": 0.7}, "p_fa"),
        ({"integrity_risk": -1.0}, "integrity_risk"),
        ({"max_exclusions": -1}, "max_exclusions"),
        ({"max_exclusions": 1.5}, "max_exclusions"),
        ({"enu_rotation": np.ones((3, 3))}, "enu_rotation"),
        ({"fault_sign": "negative"}, "fault_sign"),
    ):
        with pytest.raises(ValueError, match=name):
            fde_standalone(obs, **kw)
        with pytest.raises(ValueError, match=name):
            fde_cooperative(obs, rel, **kw)
    with pytest.raises(ValueError, match="transfer"):
        fde_cooperative(obs, rel, transfer="tdt")
    with pytest.raises(ValueError, match="solution"):
        fde_standalone(obs, solve_standalone(obs.subset_receivers([0, 1])))
    with pytest.raises(ValueError, match="solution"):
        fde_cooperative(obs, rel, solve_cooperative(obs, rel, centroid=1))


# --------------------------------------------------------------------------------------------
# evaluation helper
# --------------------------------------------------------------------------------------------


def test_integrity_rates() -> None:
    err = np.array([1.0, 5.0, 50.0, 8.0, np.nan, 3.0])
    pl = np.array([4.0, 4.0, 20.0, 40.0, np.inf, np.nan])
    r = integrity_rates(err, pl, alert_limit_m=30.0)
    assert r.n == 6
    assert r.availability == pytest.approx(3 / 6)  # PL 4, 4, 20 are within 30 m
    assert r.misleading_rate == pytest.approx(2 / 6)  # 5 > 4 and 50 > 20
    assert r.hazardous_rate == pytest.approx(1 / 6)  # 50 > 30 while declared available
    empty = integrity_rates(np.array([]), np.array([]), 10.0)
    assert empty.n == 0 and math.isnan(empty.availability)
    with pytest.raises(ValueError, match="alert_limit_m"):
        integrity_rates(err, pl, 0.0)
    with pytest.raises(ValueError, match="same size"):
        integrity_rates(err, pl[:3], 10.0)


def test_relative_positions_helper_is_consistent() -> None:
    """The test geometry itself: true relative positions reproduce the formation."""
    sc = paper_swarm(0.0)
    rel = sc.relative(noise=False)
    assert isinstance(rel, RelativePositions)
    enu = rel.rel_ecef_m[0] @ ROT.T
    assert np.allclose(enu, FORMATION - FORMATION[0], atol=1e-6)
