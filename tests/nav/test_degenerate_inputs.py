"""The navigation library keeps its promise (issue 15): degenerate cases are statuses, bad
arguments a clear ``ValueError`` raised before any arithmetic; with the compiled kernels and
with their numpy oracles alike."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.nav import (
    NavStatus,
    solve_cooperative,
    solve_cooperative_samples,
    solve_master_slave,
    solve_standalone,
)
from tests.nav import oracles
from tests.nav.scenario import make_scenario


@pytest.fixture(params=["kernels", "numpy"])
def formulation(request, monkeypatch):
    """The solvers with their compiled kernels, or with the numpy oracles in their place."""
    if request.param == "numpy":
        oracles.use_nav_oracles(monkeypatch)
    return request.param


def _epoch():
    sc = make_scenario(n_uav=3, seed=2)
    return sc, sc.observations(np.random.default_rng(0)), sc.relative(np.random.default_rng(1))


def test_a_satellite_at_the_start_point_is_a_status(formulation):
    """Start the iteration on a satellite: today the kernels raised ZeroDivisionError."""
    _, obs, rel = _epoch()
    on_sat = np.tile(obs.sv_ecef_m[0], (3, 1))  # satellite 0 is received by every UAV
    assert obs.visible[:, 0].all()
    sa = solve_standalone(obs, on_sat)
    assert np.all(sa.status == NavStatus.SINGULAR_GEOMETRY)
    assert np.all(np.isnan(sa.pos_ecef_m))
    co = solve_cooperative(obs, rel, x0_ecef_m=on_sat)  # each UAV its own centroid
    assert np.all(co.status == NavStatus.SINGULAR_GEOMETRY)
    shared = solve_cooperative(obs, rel, centroid=0, x0_ecef_m=on_sat[0])
    assert np.all(shared.status == NavStatus.SINGULAR_GEOMETRY)
    # only the receiver that starts on the satellite is affected
    start = np.zeros((3, 3))
    start[1] = obs.sv_ecef_m[0]
    mixed = solve_standalone(obs, start)
    assert list(mixed.status) == [NavStatus.OK, NavStatus.SINGULAR_GEOMETRY, NavStatus.OK]
    np.testing.assert_allclose(mixed.pos_ecef_m[[0, 2]], solve_standalone(obs).pos_ecef_m[[0, 2]])
    ms = solve_master_slave(obs, rel, master=0, x0_ecef_m=on_sat)
    assert ms.status[0] == NavStatus.SINGULAR_GEOMETRY


def test_the_kernels_and_numpy_agree_on_the_status(monkeypatch):
    _, obs, rel = _epoch()
    on_sat = np.tile(obs.sv_ecef_m[3], (3, 1))
    a = solve_cooperative(obs, rel, x0_ecef_m=on_sat).status
    calls = oracles.use_nav_oracles(monkeypatch)
    assert np.array_equal(a, solve_cooperative(obs, rel, x0_ecef_m=on_sat).status)
    assert calls["gauss_newton"] == 1


@pytest.mark.parametrize(
    ("x0", "match"),
    [
        (np.zeros((5, 3)), r"x0_ecef_m must have shape \(3, 3\) or \(3,\), got \(5, 3\)"),
        (np.zeros(2), r"x0_ecef_m must have shape \(3, 3\) or \(3,\), got \(2,\)"),
        (np.full(3, np.nan), "x0_ecef_m contains NaN or inf"),
        ("abc", "x0_ecef_m must be a numeric array"),
    ],
)
def test_x0_is_checked_before_any_arithmetic(formulation, x0, match):
    _, obs, rel = _epoch()
    with pytest.raises(ValueError, match=match):
        solve_standalone(obs, x0)
    with pytest.raises(ValueError, match=match):
        solve_cooperative(obs, rel, x0_ecef_m=x0)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"max_iter": "5"}, "max_iter must be an integer, got '5'"),
        ({"max_iter": 2.5}, "max_iter must be an integer, got 2.5"),
        ({"max_iter": True}, "max_iter must be an integer, got True"),
        ({"max_iter": 0}, "max_iter must be >= 1, got 0"),
        ({"tol_m": 0.0}, "tol_m must be a finite number > 0"),
        ({"tol_m": "1e-4"}, "tol_m must be a finite number > 0"),
        ({"tol_m": float("inf")}, "tol_m must be a finite number > 0"),
    ],
)
def test_iteration_limits_are_checked(kw, match):
    sc, obs, rel = _epoch()
    with pytest.raises(ValueError, match=match):
        solve_standalone(obs, **kw)
    with pytest.raises(ValueError, match=match):
        solve_cooperative(obs, rel, **kw)
    pr = obs.pr_m[None]
    base = sc.pos_ecef[None] - sc.pos_ecef[0]
    with pytest.raises(ValueError, match=match):
        solve_cooperative_samples(obs, pr, rel, base, centroid=0, **kw)


def test_integer_types_of_numpy_are_accepted():
    obs = _epoch()[1]
    a = solve_standalone(obs, max_iter=np.int64(10))
    b = solve_standalone(obs, max_iter=10)
    np.testing.assert_array_equal(a.pos_ecef_m, b.pos_ecef_m)
