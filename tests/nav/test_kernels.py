"""The compiled Gauss-Newton kernels against the numpy oracles of the same solvers.

The solvers run their iterations in ``coopnav_env.nav._kernels`` (numba); the numpy oracles
(``tests/nav/oracles.py``) are a second, independent implementation of the same algebra.
Both must give the same statuses, positions to 1e-6 m and covariances to 1e-9 relative, in
every mode the kernels serve, with noise, masked UAVs, UAVs out of range, degenerate problems
and warm starts.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from coopnav_env.nav import (
    NavStatus,
    VirtualPoint,
    cooperative,
    solve_cooperative,
    solve_cooperative_samples,
    solve_standalone,
    wls,
)
from tests.nav import oracles
from tests.nav.scenario import make_scenario


def _both(monkeypatch, fn):
    """``fn()`` with the kernels and with the numpy oracles (each oracle that ``fn`` needs
    must have run)."""
    fast = fn()
    with monkeypatch.context() as m:
        calls = oracles.use_nav_oracles(m)
        ref = fn()
    assert calls["standalone_solve"] + calls["gauss_newton"] > 0
    return fast, ref


def _assert_same(fast, ref, pos_tol=1e-6, cov_rel=1e-9):
    assert np.array_equal(fast.status, ref.status)
    assert np.array_equal(np.isnan(fast.pos_ecef_m), np.isnan(ref.pos_ecef_m))
    ok = np.isfinite(ref.pos_ecef_m)
    assert np.abs(fast.pos_ecef_m[ok] - ref.pos_ecef_m[ok]).max(initial=0.0) < pos_tol
    cok = np.isfinite(ref.cov_ecef_m2)
    scale = np.abs(ref.cov_ecef_m2[cok]).max(initial=1.0)
    assert np.abs(fast.cov_ecef_m2[cok] - ref.cov_ecef_m2[cok]).max(initial=0.0) <= cov_rel * scale
    assert np.array_equal(np.isnan(fast.cov_ecef_m2), np.isnan(ref.cov_ecef_m2))


CASES = [
    dict(seed=1),
    dict(seed=2, canyon_uav=0),
    dict(seed=3, canyon_uav=1, canyon_hd=3.0, spread_m=300.0),
    dict(seed=4, differential=True, canyon_uav=2),
    dict(seed=5, n_uav=1),
    dict(seed=6, n_uav=9, n_sv=22, canyon_uav=4),
    dict(seed=7, max_open=6, canyon_uav=0, canyon_hd=4.0),
]


@pytest.mark.parametrize("case", CASES)
def test_standalone_kernel_equals_numpy(monkeypatch, case):
    sc = make_scenario(**case)
    obs = sc.observations(np.random.default_rng(case["seed"]))
    for x0 in (None, sc.pos_ecef + 30.0):
        fast, ref = _both(monkeypatch, lambda x0=x0: solve_standalone(obs, x0))
        _assert_same(fast, ref)
        ok = ref.status == NavStatus.OK
        assert np.abs(fast.clock_m[ok] - ref.clock_m[ok]).max(initial=0.0) < 1e-6


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("transfer", ["sdt", "ddt"])
@pytest.mark.parametrize("centroid", ["self", 0, "virtual"])
def test_cooperative_kernel_equals_numpy(monkeypatch, case, transfer, centroid):
    sc = make_scenario(**case)
    rng = np.random.default_rng(100 + case["seed"])
    obs = sc.observations(rng)
    n = sc.pos_ecef.shape[0]
    cov_enu = np.broadcast_to(np.diag([0.3, 0.8, 0.5]) ** 2, (n, n, 3, 3)).copy()
    rel = sc.relative(rng, cov_enu=cov_enu)
    if n > 2:  # one UAV out of range of every other one
        avail = rel.available.copy()
        avail[n - 1, :] = False
        avail[:, n - 1] = False
        rel = type(rel)(rel.rel_ecef_m, rel.cov_ecef_m2, avail)
    if centroid == "virtual":
        p_v = sc.pos_ecef.mean(axis=0) + 3.0
        cov = np.broadcast_to(0.16 * np.eye(3), (n, 3, 3)).copy()
        cen = VirtualPoint(sc.pos_ecef - p_v, cov, np.ones(n, dtype=bool))
    else:
        cen = centroid
    x0 = None if centroid == "virtual" else sc.pos_ecef[0] + 20.0
    fast, ref = _both(
        monkeypatch,
        lambda: solve_cooperative(obs, rel, transfer=transfer, centroid=cen, x0_ecef_m=x0),
    )
    _assert_same(fast, ref)
    assert np.array_equal(fast.centroid_status, ref.centroid_status)
    assert np.array_equal(fast.n_meas_used, ref.n_meas_used)
    assert np.array_equal(fast.n_uavs_used, ref.n_uavs_used)


def test_cooperative_kernel_degenerate_problems(monkeypatch):
    """Too few satellites, a UAV blind to everything, and a singular geometry."""
    sc = make_scenario(seed=8, n_sv=8)
    obs = sc.observations(np.random.default_rng(8))
    rel = sc.relative(np.random.default_rng(9))
    vis = np.ones_like(obs.visible)
    vis[0] = False  # UAV 0 sees nothing
    vis[1, 2:] = False  # UAV 1 sees two satellites
    blind = replace(
        obs,
        pr_m=np.where(vis, obs.pr_m, np.nan),
        sigma_user_m=np.where(vis, obs.sigma_user_m, np.nan),
    )
    for transfer in ("sdt", "ddt"):
        fast, ref = _both(monkeypatch, lambda t=transfer: solve_cooperative(blind, rel, transfer=t))
        _assert_same(fast, ref)
        assert fast.status[0] != NavStatus.OK or transfer == "ddt"
    fast, ref = _both(monkeypatch, lambda: solve_standalone(blind))
    _assert_same(fast, ref)
    assert fast.status[0] == NavStatus.TOO_FEW_SATELLITES
    # every satellite in one direction: singular
    sv = obs.sv_ecef_m.copy()
    sv[:] = sv[0] + np.arange(sv.shape[0])[:, None] * 1e-3
    flat = replace(obs, sv_ecef_m=sv)
    fast, ref = _both(monkeypatch, lambda: solve_standalone(flat))
    assert np.array_equal(fast.status, ref.status)
    assert np.all(fast.status == NavStatus.SINGULAR_GEOMETRY)


def test_samples_kernel_equals_numpy(monkeypatch):
    sc = make_scenario(seed=10, canyon_uav=0)
    obs = sc.observations(np.random.default_rng(1))
    rel = sc.relative(np.random.default_rng(2))
    rng = np.random.default_rng(3)
    k = 7
    pr_s = obs.pr_m[None] + rng.normal(0.0, 2.0, (k, *obs.pr_m.shape))
    rel_s = rel.rel_ecef_m[2][None] + rng.normal(0.0, 0.3, (k, sc.pos_ecef.shape[0], 3))
    fast, ref = _both(
        monkeypatch, lambda: solve_cooperative_samples(obs, pr_s, rel, rel_s, centroid=2)
    )
    _assert_same(fast, ref)


@pytest.mark.parametrize("seed", range(12))
def test_setup_masks_kernel_equals_numpy(seed):
    """References, used rows, clocks, DDT pivots and availability of every problem type,
    with randomly masked satellites and unlinked UAVs: identical arrays (dtype included)."""
    rng = np.random.default_rng(seed)
    sc = make_scenario(
        seed=seed, n_uav=int(rng.integers(1, 8)), n_sv=int(rng.integers(4, 20)), canyon_uav=0
    )
    obs = sc.observations(rng)
    vis = obs.visible & (rng.random(obs.visible.shape) > 0.35)
    obs = replace(
        obs,
        pr_m=np.where(vis, obs.pr_m, np.nan),
        sigma_user_m=np.where(vis, obs.sigma_user_m, np.nan),
    )
    rel = sc.relative(rng)
    n = obs.n_rx
    avail = rel.available & (rng.random((n, n)) > 0.2)
    avail = avail & avail.T
    np.fill_diagonal(avail, True)
    rel = type(rel)(rel.rel_ecef_m, rel.cov_ecef_m2, avail)
    sobs, _ = cooperative._sort_by_system(obs)
    virtual = VirtualPoint(rel.rel_ecef_m[0], rel.cov_ecef_m2[0], rng.random(n) > 0.3)
    for centroid in ("self", n - 1, virtual):
        for transfer in ("ddt", "sdt"):
            for need in (None, 2, 7):
                bavail = (
                    virtual.available[None]
                    if centroid is virtual
                    else rel.available[np.arange(n) if centroid == "self" else [centroid]]
                )
                cen = (
                    np.array([-1])
                    if centroid is virtual
                    else (np.arange(n) if centroid == "self" else np.array([centroid]))
                )
                fast = cooperative._kernels.setup_masks(
                    sobs.visible,
                    bavail,
                    cen,
                    sobs.system.astype(np.int64),
                    sobs.el_deg,
                    sobs.n_systems,
                    transfer == "ddt",
                    -1 if need is None else need,
                )
                ref = oracles.setup_masks(sobs, bavail, cen, transfer, need)
                for name, a, b in zip(
                    ("ref", "used", "has_clock", "pivot", "too_few"), fast, ref, strict=True
                ):
                    assert a.shape == b.shape and np.array_equal(a, b), name


@pytest.mark.parametrize("cond", [1.0, 1e3, 1e8, 3e9, 3e10, 1e12, 1e17])
def test_safe_inverse_condition_test(cond):
    """The Cholesky-first shortcut decides singularity as the eigenvalue test does."""
    from coopnav_env.nav import _kernels

    rng = np.random.default_rng(int(np.log10(cond)) + 1)
    for _ in range(20):
        q, _ = np.linalg.qr(rng.normal(size=(5, 5)))
        lam = np.geomspace(1.0, 1.0 / cond, 5) * rng.uniform(0.5, 2.0)
        a = (q * lam) @ q.T
        a = (a + a.T) / 2.0
        d = np.sqrt(np.diag(a))
        scaled = a / np.outer(d, d)
        ev = np.linalg.eigvalsh(scaled)
        expect = bool(ev[0] <= 0.0 or ev[-1] > wls.COND_LIMIT * ev[0])
        out = np.empty((5, 5))
        singular = _kernels._safe_inverse_one(a, True, out)
        assert singular == expect
        if not singular:
            np.testing.assert_allclose(out @ a, np.eye(5), atol=1e-9 * cond)
        else:
            np.testing.assert_allclose(out * np.outer(d, d), np.eye(5), rtol=1e-14, atol=1e-14)


def test_square_root_of_diagonal_covariances():
    """The diagonal shortcut (compiled and its numpy oracle) equals the eigendecomposition's
    root."""
    rng = np.random.default_rng(0)
    var = rng.uniform(0.0, 4.0, (3, 17, 3)) ** 2
    var[0, 0] = [0.0, -0.0, 1e-300]  # zero, negative zero, tiny
    cov = var[..., None] * np.eye(3)
    lam, vec = np.linalg.eigh(cov)
    eig_root = np.einsum("...ij,...j,...kj->...ik", vec, np.sqrt(np.clip(lam, 0.0, None)), vec)
    fast = cooperative._sqrtm_psd(cov)
    ref = oracles.sqrtm_psd(cov)
    assert fast.shape == ref.shape == cov.shape
    assert fast.tobytes() == ref.tobytes()
    np.testing.assert_allclose(fast, eig_root, rtol=1e-15, atol=0.0)
    np.testing.assert_array_equal(fast[1:], eig_root[1:])  # ordinary values: bit for bit
    # a full matrix takes the eigendecomposition in both
    a = rng.normal(size=(4, 3, 3))
    full = a @ np.swapaxes(a, 1, 2)
    root = cooperative._sqrtm_psd(full)
    np.testing.assert_allclose(root @ root, full, atol=1e-12)
    assert root.tobytes() == oracles.sqrtm_psd(full).tobytes()


def _fields_equal(a, b) -> None:
    """Two CooperativeSolutions equal bit for bit (NaN where NaN)."""
    for name in (
        "pos_ecef_m",
        "cov_ecef_m2",
        "status",
        "centroid_pos_ecef_m",
        "centroid_cov_ecef_m2",
        "centroid_clock_m",
        "centroid_status",
        "n_uavs_used",
        "n_meas_used",
    ):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        assert np.array_equal(x, y, equal_nan=True), name
    assert a.n_iter == b.n_iter


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("transfer", ["sdt", "ddt"])
@pytest.mark.parametrize("which", ["self", "first", "last"])
def test_one_call_isotropic_solve_equals_solve_cooperative(case, transfer, which):
    """The simulator's one-call path (`_solve_isotropic`) is `solve_cooperative`, bit for bit
    (centroid "self", or one shared centroid at the first or the last UAV)."""
    sc = make_scenario(**case)
    rng = np.random.default_rng(200 + case["seed"])
    obs, _ = cooperative._sort_by_system(sc.observations(rng))
    n = sc.pos_ecef.shape[0]
    centroid = {"self": "self", "first": 0, "last": n - 1}[which]
    rel_ecef = sc.relative(rng).rel_ecef_m
    var = rng.uniform(0.05, 2.0, (n, n))
    var = (var + var.T) / 2
    np.fill_diagonal(var, 0.0)
    avail = np.ones((n, n), dtype=bool)
    np.fill_diagonal(avail, False)
    if n > 2:  # one UAV out of range of every other one, one broken link
        avail[n - 1, :] = avail[:, n - 1] = False
        avail[0, 1] = avail[1, 0] = False
    x0 = sc.pos_ecef + 25.0
    rel_cov = var[:, :, None, None] * np.eye(3)
    ref = solve_cooperative(
        obs,
        cooperative.RelativePositions._trusted(rel_ecef, rel_cov, avail),
        transfer=transfer,
        centroid=centroid,
        x0_ecef_m=x0 if centroid == "self" else x0[centroid],
        max_iter=8,
    )
    if centroid == "self":
        fast = cooperative._solve_isotropic(obs, rel_ecef, var, avail, "self", transfer, x0, 8)
    else:
        a = centroid
        fast = cooperative._solve_isotropic(
            obs, rel_ecef[a], var[a], avail[a], a, transfer, x0[a], 8
        )
    _fields_equal(fast, ref)


def test_one_call_isotropic_solve_declines_unsorted_satellites():
    """The one-call path declines (the caller then runs solve_cooperative) for satellites
    not grouped by constellation."""
    sc = make_scenario(seed=3)
    obs = sc.observations(np.random.default_rng(3))
    assert np.any(np.diff(obs.system) < 0)
    n = sc.pos_ecef.shape[0]
    out = cooperative._solve_isotropic(
        obs,
        sc.relative(np.random.default_rng(4)).rel_ecef_m,
        np.full((n, n), 0.25),
        np.ones((n, n), dtype=bool),
        "self",
        "ddt",
        sc.pos_ecef,
        8,
    )
    assert out is None


@pytest.mark.parametrize("radius", [None, (6.0e6, 7.0e6)])
def test_fix_status_kernel_equals_numpy(radius):
    """Statuses and failed flags of every combination of the inputs, identical."""
    from coopnav_env.nav import _kernels

    rng = np.random.default_rng(11)
    n = 400
    pos = rng.normal(0.0, 1.0, (n, 3)) * rng.choice([5.0e6, 6.4e6, 9.0e6], n)[:, None]
    flags = [rng.random(n) < 0.3 for _ in range(3)]
    check, lo, hi = wls._radius_args(radius)
    fast = _kernels.fix_status(pos, *flags, check, lo, hi)
    ref = oracles.fix_status(pos, *flags, radius)
    assert fast[0].dtype == ref[0].dtype and np.array_equal(fast[0], ref[0])
    assert np.array_equal(fast[1], ref[1])
    assert len(set(ref[0].tolist())) >= 4  # most statuses occur


def _relabelled(transferred, problems, n_sys):
    """The centroid problems ``transferred, problems`` with the satellites split into
    ``n_sys`` constellations (contiguous, sorted, as the kernel expects) and one clock column
    per constellation."""
    pr, sv, vis, sigma_user, sig_c, _system = transferred
    rows, base, froot, ref, _has_clock, usable, x0 = problems
    n_sv = sv.shape[0]
    system = np.minimum(np.arange(n_sv) * n_sys // n_sv, n_sys - 1).astype(np.int64)
    has_clock = np.ones((rows.shape[0], n_sys), dtype=bool)
    return (pr, sv, vis, sigma_user, sig_c, system), (
        rows,
        base,
        froot,
        ref,
        has_clock,
        usable,
        x0,
    )


def test_cooperative_kernel_compiled_per_constellation_count_is_the_same(monkeypatch):
    """The Gauss-Newton kernel compiled for one or two constellations (a compile-time
    constant) gives the bits of the one that reads the count from its arguments."""
    from coopnav_env.nav import _kernels

    calls = []
    kernel = _kernels.cooperative_gauss_newton

    def recording(*args):
        calls.append(args)
        return kernel(*args)

    monkeypatch.setattr(cooperative._kernels, "cooperative_gauss_newton", recording)
    for seed, transfer in ((1, "ddt"), (3, "sdt"), (6, "ddt")):
        sc = make_scenario(seed=seed)
        rng = np.random.default_rng(seed)
        obs = sc.observations(rng)
        solve_cooperative(obs, sc.relative(rng), transfer=transfer, x0_ecef_m=sc.pos_ecef[0])
    assert len(calls) == 3
    for transferred, problems, max_iter, tol_m in calls:
        for n_sys in (1, 2, 3):  # (three: the general build on both sides)
            t, p = _relabelled(transferred, problems, n_sys)
            fast = kernel(t, p, max_iter, tol_m)
            ref = _kernels._gauss_newton_any(t, p, max_iter, tol_m)
            for a, b in zip(fast, ref, strict=True):
                assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
            assert fast[1].shape[1] == n_sys
            assert fast[6].min() >= 1 and fast[6].max() >= 2  # iterated, past a first update
