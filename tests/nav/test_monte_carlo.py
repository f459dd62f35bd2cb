"""Monte Carlo: the predicted standard deviation (SIG, Eq. 23) matches the sampled STD.

Tolerance: with K independent samples of a Gaussian error the relative standard error of the
sample standard deviation is 1 / sqrt(2 K). With K = 6000 that is 0.91 %, so the 3 % band the
issue asks for is 3.3 standard errors wide (two-sided p = 0.001 per axis). Fixed seeds make every
run identical.
"""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.nav import (
    GnssObservations,
    RelativePositions,
    VirtualPoint,
    solve_cooperative_samples,
    solve_standalone,
)
from tests.nav.scenario import make_scenario

K = 6000
TOL = 0.03
assert TOL > 3.0 / np.sqrt(2 * K)


def _draw(sc, rng):
    n, s = sc.visible.shape
    common = rng.standard_normal((K, s)) * sc.sigma_common
    user = rng.standard_normal((K, n, s)) * sc.sigma_user
    pr = sc.range + sc.clock[:, sc.system] + common[:, None] + user
    return np.where(sc.visible, pr, np.nan)


def _enu_ratio(sc, err_ecef, cov_ecef):
    r = sc.rot
    err = err_ecef @ r.T
    sig = np.sqrt(np.einsum("ij,kjl,il->ki", r, cov_ecef, r))
    assert np.all(np.isfinite(sig))
    # mean error must be zero within 4 standard errors (unbiased estimator)
    assert np.all(np.abs(err.mean(axis=0)) < 4 * sig.mean(axis=0) / np.sqrt(K))
    return err.std(axis=0) / np.sqrt((sig**2).mean(axis=0))


def _baselines(rel_cov, true_base, rng, zero_row=None):
    root = np.linalg.cholesky(rel_cov + 1e-18 * np.eye(3))
    z = rng.standard_normal((K, true_base.shape[0], 3))
    base = true_base[None] + np.einsum("nij,knj->kni", root, z)
    if zero_row is not None:
        base[:, zero_row] = 0.0
    return base


SCENARIOS = [
    pytest.param(dict(differential=d, canyon_uav=c), id=f"diff={d}-canyon={c is not None}")
    for d in (False, True)
    for c in (None, 0)
]


@pytest.mark.parametrize("kw", SCENARIOS)
def test_standalone_sig_matches_std(kw):
    sc = make_scenario(max_open=10, seed=3, **kw)
    prs = _draw(sc, np.random.default_rng(7))
    obs = GnssObservations(
        pr_m=prs[:, 0],
        sv_ecef_m=sc.sv_ecef,
        system=sc.system,
        sigma_user_m=np.repeat(sc.sigma_user[:1], K, axis=0),
        sigma_common_m=sc.sigma_common,
        el_deg=np.repeat(sc.el_deg[:1], K, axis=0),
    )
    sol = solve_standalone(obs, sc.pos_ecef[0])
    assert np.all(sol.ok)
    ratio = _enu_ratio(sc, sol.pos_ecef_m - sc.pos_ecef[0], sol.cov_ecef_m2)
    assert np.all(np.abs(ratio - 1) < TOL), ratio


@pytest.mark.parametrize("transfer", ["sdt", "ddt"])
@pytest.mark.parametrize("kw", SCENARIOS)
def test_cooperative_sig_matches_std_own_centroid(kw, transfer):
    """UAV 0 as its own centroid (the paper's choice); UAV 0 is the canyon UAV if any."""
    sc = make_scenario(max_open=10, seed=3, **kw)
    rng = np.random.default_rng(7)
    prs = _draw(sc, rng)
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    base = _baselines(rel.cov_ecef_m2[0], rel.rel_ecef_m[0], rng, zero_row=0)
    sol = solve_cooperative_samples(
        obs, prs, rel, base, centroid=0, transfer=transfer, x0_ecef_m=sc.pos_ecef[0]
    )
    assert np.all(sol.centroid_status == 0)
    ratio = _enu_ratio(sc, sol.pos_ecef_m[:, 0] - sc.pos_ecef[0], sol.cov_ecef_m2[:, 0])
    assert np.all(np.abs(ratio - 1) < TOL), ratio


@pytest.mark.parametrize("transfer", ["sdt", "ddt"])
@pytest.mark.parametrize("differential", [False, True])
def test_cooperative_sig_matches_std_shared_centroid_anisotropic(transfer, differential):
    """UAV 0 located from a centroid at UAV 2 with a non-isotropic C_d: H_p of Eq. 19 with the
    cross-covariance between the centroid estimate and UAV 0's relative error."""
    sc = make_scenario(max_open=10, seed=3, canyon_uav=0, differential=differential)
    rng = np.random.default_rng(9)
    prs = _draw(sc, rng)
    obs = sc.observations(noise=False)
    cov_enu = np.broadcast_to(np.diag([0.3, 0.9, 0.5]) ** 2, (5, 5, 3, 3)).copy()
    rel = sc.relative(noise=False, cov_enu=cov_enu)
    base = _baselines(rel.cov_ecef_m2[2], rel.rel_ecef_m[2], rng, zero_row=2)
    sol = solve_cooperative_samples(
        obs, prs, rel, base, centroid=2, transfer=transfer, x0_ecef_m=sc.pos_ecef[2]
    )
    ratio = _enu_ratio(sc, sol.pos_ecef_m[:, 0] - sc.pos_ecef[0], sol.cov_ecef_m2[:, 0])
    assert np.all(np.abs(ratio - 1) < TOL), ratio


def test_cooperative_sig_matches_std_virtual_point():
    sc = make_scenario(max_open=10, seed=3, canyon_uav=0)
    rng = np.random.default_rng(13)
    prs = _draw(sc, rng)
    obs = sc.observations(noise=False)
    p_v = sc.pos_ecef.mean(axis=0)
    n = sc.pos_ecef.shape[0]
    cov = np.broadcast_to(0.5**2 * np.eye(3), (n, 3, 3)).copy()
    vp = VirtualPoint(sc.pos_ecef - p_v, cov, np.ones(n, dtype=bool))
    base = _baselines(cov, vp.rel_ecef_m, rng)
    sol = solve_cooperative_samples(obs, prs, vp, base, centroid=vp, x0_ecef_m=p_v)
    ratio = _enu_ratio(sc, sol.pos_ecef_m[:, 0] - sc.pos_ecef[0], sol.cov_ecef_m2[:, 0])
    assert np.all(np.abs(ratio - 1) < TOL), ratio


@pytest.mark.parametrize("kw", SCENARIOS)
def test_master_slave_sig_matches_std(kw):
    """Slave 0 (the canyon UAV if any) located from master 2's standalone fix (Section 4.2)."""
    sc = make_scenario(max_open=10, seed=3, **kw)
    rng = np.random.default_rng(17)
    prs = _draw(sc, rng)
    m = 2
    obs = GnssObservations(
        pr_m=prs[:, m],
        sv_ecef_m=sc.sv_ecef,
        system=sc.system,
        sigma_user_m=np.repeat(sc.sigma_user[m : m + 1], K, axis=0),
        sigma_common_m=sc.sigma_common,
        el_deg=np.repeat(sc.el_deg[m : m + 1], K, axis=0),
    )
    master = solve_standalone(obs, sc.pos_ecef[m])
    rel: RelativePositions = sc.relative(noise=False)
    eps = _baselines(rel.cov_ecef_m2[m, 0][None], np.zeros((1, 3)), rng)[:, 0]
    # the scheme itself: slave = master fix + measured relative position, H = H_m + C_d
    from coopnav_env.nav import solve_master_slave

    one = solve_master_slave(sc.observations(noise=False), rel, master=m)
    assert np.allclose(one.pos_ecef_m[0], sc.pos_ecef[0], atol=1e-3)
    slave = master.pos_ecef_m + rel.rel_ecef_m[m, 0] + eps
    cov = master.cov_ecef_m2 + rel.cov_ecef_m2[m, 0]
    ratio = _enu_ratio(sc, slave - sc.pos_ecef[0], cov)
    assert np.all(np.abs(ratio - 1) < TOL), ratio
