"""Deterministic tests of the standalone and cooperative solvers (noise-free, identities, API)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.nav import (
    GnssObservations,
    NavStatus,
    RelativePositions,
    VirtualPoint,
    solve_cooperative,
    solve_cooperative_samples,
    solve_master_slave,
    solve_standalone,
)
from tests.nav.scenario import make_scenario

MODES = [
    (tr, cen, cov)
    for tr in ("sdt", "ddt")
    for cen in ("self", 2, "virtual")
    for cov in ("exact", "paper")
]


def _virtual(sc, offset_enu=(5.0, -3.0, 2.0), sigma=0.0):
    """A virtual point near the swarm and error-free baselines to it."""
    p_v = sc.pos_ecef.mean(axis=0) + np.asarray(offset_enu) @ sc.rot
    n = sc.pos_ecef.shape[0]
    cov = np.broadcast_to(sigma**2 * np.eye(3), (n, 3, 3)).copy()
    return VirtualPoint(sc.pos_ecef - p_v, cov, np.ones(n, dtype=bool))


@pytest.mark.parametrize("canyon", [None, 0])
def test_standalone_noise_free_recovers_truth(canyon):
    sc = make_scenario(canyon_uav=canyon)
    sol = solve_standalone(sc.observations(noise=False))
    assert np.all(sol.status == NavStatus.OK)
    assert np.abs(sol.pos_ecef_m - sc.pos_ecef).max() < 1e-3
    assert np.allclose(sol.clock_m, sc.clock, atol=1e-3)


@pytest.mark.parametrize(("transfer", "centroid", "covariance"), MODES)
@pytest.mark.parametrize("spread", [40.0, 400.0])
def test_cooperative_noise_free_recovers_truth(transfer, centroid, covariance, spread):
    sc = make_scenario(canyon_uav=0, spread_m=spread)
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    cen = _virtual(sc) if centroid == "virtual" else centroid
    sol = solve_cooperative(obs, rel, transfer=transfer, centroid=cen, covariance=covariance)
    assert np.all(sol.status == NavStatus.OK)
    assert np.abs(sol.pos_ecef_m - sc.pos_ecef).max() < 1e-3


@pytest.mark.parametrize(("transfer", "centroid", "covariance"), MODES)
def test_structured_solver_equals_dense_reference(transfer, centroid, covariance):
    """The structured solve equals the literal transfer with a dense C* inverted by numpy.

    For exact DDT this also shows that the undifferenced form with per-UAV nuisance clocks
    gives the same estimate and covariance as the double-differenced measurements with their
    exact (pivot-correlated) covariance.
    """
    sc = make_scenario(canyon_uav=0, seed=4)
    rng = np.random.default_rng(11)
    obs = sc.observations(rng)
    cov_enu = np.broadcast_to(np.diag([0.3, 0.8, 0.5]) ** 2, (5, 5, 3, 3)).copy()
    rel = sc.relative(rng, cov_enu=cov_enu)
    cen = _virtual(sc, sigma=0.4) if centroid == "virtual" else centroid
    kw = dict(transfer=transfer, centroid=cen, covariance=covariance)
    s = solve_cooperative(obs, rel, method="structured", **kw)
    d = solve_cooperative(obs, rel, method="dense", **kw)
    assert np.array_equal(s.status, d.status)
    assert np.abs(s.pos_ecef_m - d.pos_ecef_m).max() < 1e-6
    scale = np.abs(d.cov_ecef_m2).max()
    assert np.abs(s.cov_ecef_m2 - d.cov_ecef_m2).max() < 1e-9 * scale


@pytest.mark.parametrize(
    ("transfer", "covariance"), [("sdt", "exact"), ("ddt", "exact"), ("sdt", "paper")]
)
def test_ideal_case_identity_eq24(transfer, covariance):
    """Eq. 24: open sky, differential correction, error-free relative positions: H* = H / N_v.

    The identity needs every UAV to see the same satellites along the same lines of sight with
    the same error model, which the paper assumes (shared LOS); we realise it exactly with
    co-located UAVs.
    """
    n_uav = 6
    sc = make_scenario(n_uav=n_uav, differential=True, sigma_d=0.0, colocated=True)
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    h = solve_standalone(obs).cov_ecef_m2[0]
    sol = solve_cooperative(obs, rel, transfer=transfer, covariance=covariance)
    for h_star in sol.centroid_cov_ecef_m2:
        assert np.abs(h_star - h / n_uav).max() < 1e-9 * np.abs(h).max()


def test_eq24_fails_for_ddt_with_the_papers_eq18():
    """With Eq. 18 the DDT rows are treated as independent although their pivot errors
    correlate them, so the paper's own covariance misses Eq. 24 for DDT (a finding we report)."""
    n_uav = 6
    sc = make_scenario(n_uav=n_uav, differential=True, sigma_d=0.0, colocated=True)
    obs = sc.observations(noise=False)
    h = solve_standalone(obs).cov_ecef_m2[0]
    sol = solve_cooperative(obs, sc.relative(noise=False), transfer="ddt", covariance="paper")
    assert np.abs(sol.centroid_cov_ecef_m2[0] - h / n_uav).max() > 0.05 * np.abs(h).max()


def _single_sat_scenario():
    sc = make_scenario(n_uav=5, n_sv=16, seed=2)
    keep = int(np.argmax(np.where(sc.system == 0, sc.el_deg[0], -1)))  # highest GPS satellite
    sc.visible[0] = False
    sc.visible[0, keep] = True
    return sc


def test_ddt_locates_uav_that_sees_one_satellite():
    sc = _single_sat_scenario()
    rng = np.random.default_rng(3)
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    assert solve_standalone(obs).status[0] == NavStatus.TOO_FEW_SATELLITES
    ddt = solve_cooperative(obs, rel, transfer="ddt")
    assert ddt.status[0] == NavStatus.OK
    assert np.abs(ddt.pos_ecef_m[0] - sc.pos_ecef[0]).max() < 1e-3
    sdt = solve_cooperative(obs, rel, transfer="sdt")
    assert sdt.status[0] == NavStatus.TOO_FEW_SATELLITES
    assert np.all(np.isnan(sdt.pos_ecef_m[0]))
    # and with noise the fix is close to truth within its predicted uncertainty
    noisy = solve_cooperative(sc.observations(rng), sc.relative(rng), transfer="ddt")
    err = noisy.pos_ecef_m[0] - sc.pos_ecef[0]
    assert err @ np.linalg.solve(noisy.cov_ecef_m2[0], err) < 16.3  # chi2(3) 99.9 %


def test_no_satellites_is_a_reported_state():
    sc = make_scenario()
    sc.visible[:] = False
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    assert np.all(solve_standalone(obs).status == NavStatus.TOO_FEW_SATELLITES)
    for transfer in ("sdt", "ddt"):
        sol = solve_cooperative(obs, rel, transfer=transfer)
        assert np.all(sol.status == NavStatus.TOO_FEW_SATELLITES)
        assert np.all(np.isnan(sol.pos_ecef_m))


def test_uav_out_of_relative_range_navigates_standalone():
    sc = make_scenario(seed=5)
    rng = np.random.default_rng(5)
    obs = sc.observations(rng)
    r = sc.relative(rng)
    avail = r.available.copy()
    avail[1, :] = avail[:, 1] = False
    rel = RelativePositions(r.rel_ecef_m, r.cov_ecef_m2, avail)
    coop = solve_cooperative(obs, rel)
    sa = solve_standalone(obs)
    assert coop.n_uavs_used[1] == 1
    assert np.abs(coop.pos_ecef_m[1] - sa.pos_ecef_m[1]).max() < 1e-6
    assert np.allclose(coop.cov_ecef_m2[1], sa.cov_ecef_m2[1], rtol=1e-9)
    shared = solve_cooperative(obs, rel, centroid=0)
    assert shared.status[1] == NavStatus.NO_RELATIVE_POSITION
    ms = solve_master_slave(obs, rel, master=0)
    assert ms.status[1] == NavStatus.NO_RELATIVE_POSITION


def test_master_slave_noise_free_and_covariance():
    sc = make_scenario(canyon_uav=0)
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    ms = solve_master_slave(obs, rel)
    assert ms.master != 0  # the canyon UAV is never the best master
    assert np.abs(ms.pos_ecef_m - sc.pos_ecef).max() < 1e-3
    sa = solve_standalone(obs)
    assert np.allclose(ms.cov_ecef_m2[0], sa.cov_ecef_m2[ms.master] + rel.cov_ecef_m2[ms.master, 0])


def test_samples_match_one_by_one():
    sc = make_scenario(canyon_uav=0, seed=8)
    rng = np.random.default_rng(8)
    obs = sc.observations(rng)
    rel = sc.relative(rng)
    prs, bases, singles = [], [], []
    for _ in range(3):
        o = sc.observations(rng)
        r = sc.relative(rng)
        prs.append(o.pr_m)
        bases.append(r.rel_ecef_m[1])
        singles.append(solve_cooperative(o, r, centroid=1))
    many = solve_cooperative_samples(obs, np.stack(prs), rel, np.stack(bases), centroid=1)
    for k, one in enumerate(singles):
        assert np.abs(one.pos_ecef_m - many.pos_ecef_m[k]).max() < 1e-9
        assert np.allclose(one.cov_ecef_m2, many.cov_ecef_m2[k], rtol=1e-12, atol=1e-15)


def test_deterministic():
    sc = make_scenario(canyon_uav=0)
    obs = sc.observations(np.random.default_rng(1))
    rel = sc.relative(np.random.default_rng(2))
    a = solve_cooperative(obs, rel)
    b = solve_cooperative(obs, rel)
    assert np.array_equal(a.pos_ecef_m, b.pos_ecef_m)
    assert np.array_equal(a.cov_ecef_m2, b.cov_ecef_m2)


def test_inputs_are_not_modified():
    sc = make_scenario(canyon_uav=0)
    obs = sc.observations(np.random.default_rng(1))
    rel = sc.relative(np.random.default_rng(2))
    before = (obs.pr_m.copy(), rel.rel_ecef_m.copy(), rel.cov_ecef_m2.copy())
    solve_cooperative(obs, rel, centroid=1)
    solve_master_slave(obs, rel)
    assert np.array_equal(obs.pr_m, before[0], equal_nan=True)
    assert np.array_equal(rel.rel_ecef_m, before[1])
    assert np.array_equal(rel.cov_ecef_m2, before[2])


def _obs_kwargs(sc):
    o = sc.observations(noise=False)
    return dict(
        pr_m=o.pr_m,
        sv_ecef_m=o.sv_ecef_m,
        system=o.system,
        sigma_user_m=sc.sigma_user,
        sigma_common_m=o.sigma_common_m,
        el_deg=sc.el_deg,
    )


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("pr_m", np.zeros(5), "pr_m must have shape"),
        ("sv_ecef_m", np.zeros((3, 3)), "sv_ecef_m must have shape"),
        ("system", np.full(16, 7), "system indices must lie in"),
        ("system", np.zeros(16), "integer array"),
        ("sigma_common_m", -np.ones(16), "sigma_common_m must be finite and >= 0"),
    ],
)
def test_bad_observations_raise(field, value, match):
    sc = make_scenario()
    kw = _obs_kwargs(sc)
    kw[field] = value
    with pytest.raises(ValueError, match=match):
        GnssObservations(**kw)


def test_bad_sigma_user_and_nan_satellite_raise():
    sc = make_scenario()
    kw = _obs_kwargs(sc)
    kw["sigma_user_m"] = -sc.sigma_user
    with pytest.raises(ValueError, match="sigma_user_m must be finite and > 0"):
        GnssObservations(**kw)
    kw = _obs_kwargs(sc)
    kw["sv_ecef_m"] = kw["sv_ecef_m"].copy()
    kw["sv_ecef_m"][0, 0] = np.nan
    with pytest.raises(ValueError, match="sv_ecef_m contains NaN"):
        GnssObservations(**kw)


def test_bad_solver_arguments_raise():
    sc = make_scenario()
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    with pytest.raises(ValueError, match="transfer must be 'sdt' or 'ddt'"):
        solve_cooperative(obs, rel, transfer="tdt")
    with pytest.raises(ValueError, match="covariance must be 'exact' or 'paper'"):
        solve_cooperative(obs, rel, covariance="approx")
    with pytest.raises(ValueError, match="centroid UAV index must be in"):
        solve_cooperative(obs, rel, centroid=9)
    with pytest.raises(ValueError, match="centroid must be 'self'"):
        solve_cooperative(obs, rel, centroid="middle")
    with pytest.raises(ValueError, match="relative positions are required"):
        solve_cooperative(obs, None)
    with pytest.raises(ValueError, match="master must be in"):
        solve_master_slave(obs, rel, master=-1)
    bad = rel.cov_ecef_m2.copy()
    bad[0, 1] = -np.eye(3)
    with pytest.raises(ValueError, match="positive semi-definite"):
        RelativePositions(rel.rel_ecef_m, bad, rel.available)
    with pytest.raises(ValueError, match="max_iter must be >= 1"):
        solve_standalone(obs, max_iter=0)
    for bad_radius in [(6.5e6, 6.3e6), (-1.0, 6.5e6), (6.3e6, np.inf), "far", (1.0,)]:
        with pytest.raises(ValueError, match="plausible_radius_m must"):
            solve_standalone(obs, plausible_radius_m=bad_radius)
        with pytest.raises(ValueError, match="plausible_radius_m must"):
            solve_cooperative(obs, rel, plausible_radius_m=bad_radius)


def test_plausibility_shell_flags_fixes_outside_it_and_keeps_them_for_diagnosis():
    """Real fixes lie in the default shell; a shell that excludes them reports every fix."""
    sc = make_scenario()
    obs = sc.observations(noise=False)
    rel = sc.relative(noise=False)
    assert np.all(solve_standalone(obs).status == NavStatus.OK)
    assert np.all(solve_cooperative(obs, rel).status == NavStatus.OK)
    shell = (7.0e6, 8.0e6)  # everything on the ground is "implausible" here
    sa = solve_standalone(obs, plausible_radius_m=shell)
    assert np.all(sa.status == NavStatus.IMPLAUSIBLE_POSITION) and not sa.ok.any()
    np.testing.assert_allclose(sa.pos_ecef_m, sc.pos_ecef, atol=1e-6)
    co = solve_cooperative(obs, rel, plausible_radius_m=shell)
    assert np.all(co.status == NavStatus.IMPLAUSIBLE_POSITION)
    assert np.all(co.centroid_status == NavStatus.IMPLAUSIBLE_POSITION)


def test_singular_geometry_is_reported():
    """Satellites all along nearly one line of sight: enough of them, but no geometry."""
    sc = make_scenario(n_sv=8, seed=6)
    base_dir = sc.sv_ecef[0] - sc.pos_ecef.mean(axis=0)
    base_dir /= np.linalg.norm(base_dir)
    sc.sv_ecef = sc.pos_ecef.mean(axis=0) + base_dir * 2.2e7 + np.arange(8)[:, None] * 1e-3
    obs = sc.observations(noise=False)
    sa = solve_standalone(obs, sc.pos_ecef)
    assert np.all(sa.status == NavStatus.SINGULAR_GEOMETRY)
    assert np.all(np.isnan(sa.pos_ecef_m))
    coop = solve_cooperative(obs, sc.relative(noise=False), x0_ecef_m=sc.pos_ecef)
    assert np.all(coop.status == NavStatus.SINGULAR_GEOMETRY)


def test_non_convergence_is_reported():
    sc = make_scenario()
    obs = sc.observations(noise=False)
    assert np.all(solve_standalone(obs, max_iter=1).status == NavStatus.NOT_CONVERGED)
    coop = solve_cooperative(obs, sc.relative(noise=False), max_iter=1)
    assert np.all(coop.status == NavStatus.NOT_CONVERGED)
    assert np.all(np.isfinite(coop.pos_ecef_m))  # the last iterate is returned


@pytest.mark.parametrize("transfer", ["sdt", "ddt"])
def test_result_does_not_depend_on_satellite_order(transfer):
    sc = make_scenario(canyon_uav=0, seed=12)
    rng = np.random.default_rng(12)
    obs = sc.observations(rng)
    rel = sc.relative(rng)
    order = np.random.default_rng(0).permutation(obs.n_sv)
    shuffled = GnssObservations(
        pr_m=obs.pr_m[:, order],
        sv_ecef_m=obs.sv_ecef_m[order],
        system=obs.system[order],
        sigma_user_m=sc.sigma_user[:, order],
        sigma_common_m=obs.sigma_common_m[order],
        el_deg=sc.el_deg[:, order],
    )
    a = solve_cooperative(obs, rel, transfer=transfer)
    b = solve_cooperative(shuffled, rel, transfer=transfer)
    assert np.abs(a.pos_ecef_m - b.pos_ecef_m).max() < 1e-6
    assert np.allclose(a.cov_ecef_m2, b.cov_ecef_m2, rtol=1e-9, atol=1e-12)
