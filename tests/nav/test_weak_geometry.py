"""A converged fix on ill-conditioned geometry is flagged (issue 45, finding 11)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.nav import (
    WEAK_GEOMETRY_SIGMA_M,
    GnssObservations,
    NavStatus,
    solve_cooperative,
    solve_master_slave,
    solve_standalone,
    weak_geometry,
)
from tests.nav import oracles
from tests.nav.scenario import make_scenario

TRUTH = np.array([6378137.0, 0.0, 0.0])


@pytest.fixture(params=["kernels", "numpy"])
def formulation(request, monkeypatch):
    """The solvers with their compiled kernels, or with the numpy oracles in their place."""
    if request.param == "numpy":
        oracles.use_nav_oracles(monkeypatch)
    return request.param


def _narrow_cone(spread_rad: float) -> GnssObservations:
    """Six satellites 20,000 km out within ``spread_rad`` of one direction (1 m noise)."""
    d = np.array([[1, 0, 0], [1, 1, 0], [1, 0, 1], [1, -1, 0], [1, 0, -1], [1, 1, 1]], float)
    d[:, 1:] *= spread_rad
    d /= np.linalg.norm(d, axis=1)[:, None]
    sv = TRUTH + 2.0e7 * d
    pr = np.linalg.norm(sv - TRUTH, axis=1) + np.random.default_rng(0).normal(0.0, 1.0, 6)
    return GnssObservations(
        pr_m=pr[None],
        sv_ecef_m=sv,
        system=np.zeros(6, dtype=int),
        sigma_user_m=np.ones((1, 6)),
        sigma_common_m=np.zeros(6),
        el_deg=np.full((1, 6), 80.0),
        n_systems=1,
    )


def test_an_ok_fix_far_from_the_truth_is_flagged(formulation):
    sol = solve_standalone(_narrow_cone(0.01), TRUTH + 50.0)
    assert sol.status[0] == NavStatus.OK  # converged ...
    assert np.linalg.norm(sol.pos_ecef_m[0] - TRUTH) > 1000.0  # ... kilometres off
    assert sol.weak_geometry.tolist() == [True]
    wide = solve_standalone(_narrow_cone(0.3), TRUTH + 50.0)
    assert wide.status[0] == NavStatus.OK and wide.weak_geometry.tolist() == [False]


def test_normal_geometry_is_not_flagged_and_failed_fixes_are_not_weak(formulation):
    sc = make_scenario(n_uav=3, seed=2)
    obs, rel = sc.observations(np.random.default_rng(0)), sc.relative(np.random.default_rng(1))
    for sol in (
        solve_standalone(obs),
        solve_cooperative(obs, rel),
        solve_master_slave(obs, rel, master=0),
    ):
        assert sol.ok.all() and not sol.weak_geometry.any()
    failed = solve_standalone(obs, np.tile(obs.sv_ecef_m[0], (3, 1)))  # singular: no fix
    assert not failed.ok.any() and not failed.weak_geometry.any()


def test_the_limit_is_the_users_to_choose():
    status = np.array([NavStatus.OK, NavStatus.OK, NavStatus.NOT_CONVERGED])
    cov = np.stack([np.eye(3) * 30.0**2, np.eye(3) * 80.0**2, np.eye(3) * 1e8])
    assert weak_geometry(status, cov).tolist() == [False, True, False]  # 52 m, 139 m
    assert weak_geometry(status, cov, limit_m=200.0).tolist() == [False, False, False]
    assert WEAK_GEOMETRY_SIGMA_M == 100.0
    with pytest.raises(ValueError, match="limit_m must be a finite number > 0, got 0"):
        weak_geometry(status, cov, limit_m=0)
