"""The cooperative kernel's common-error block runs over the satellites some UAV uses.

A satellite that no UAV receives adds an identity row to ``I + E^T P E`` and exact zeros
everywhere else, so :func:`coopnav_env.nav._kernels.cooperative_isotropic` must give the same
results bit for bit with or without it in the sky; a non-finite common sigma of such a
satellite keeps it in the block (its NaN terms make the problem singular, as they always did).
"""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.nav import _kernels, cooperative
from tests.nav.scenario import make_scenario


def _isotropic_arguments(seed: int, n_uav: int, transfer: str) -> list:
    """The arguments of ``cooperative_isotropic`` for a scenario with every UAV a centroid:
    its records ``Measured``, ``CentroidProblems``, ``SolverLimits`` and ``with_uavs``."""
    sc = make_scenario(seed=seed, n_uav=n_uav)
    rng = np.random.default_rng(100 + seed)
    obs, _ = cooperative._sort_by_system(sc.observations(rng))
    n = sc.pos_ecef.shape[0]
    var = rng.uniform(0.05, 2.0, (n, n))
    var = (var + var.T) / 2
    np.fill_diagonal(var, 0.0)
    avail = np.ones((n, n), dtype=bool)
    np.fill_diagonal(avail, False)
    return [
        _kernels.Measured(
            obs.pr_m,
            obs.visible,
            obs.sv_ecef_m,
            obs.system,
            obs.sigma_user_m,
            obs.sigma_common_m,
            obs.el_deg,
            int(obs.n_systems),
        ),
        _kernels.CentroidProblems(
            np.ascontiguousarray(sc.relative(rng).rel_ecef_m, dtype=np.float64),
            var,
            avail,
            np.arange(n, dtype=np.int64),
            sc.pos_ecef + 25.0,
            transfer == "ddt",
            -1,
        ),
        _kernels.SolverLimits(8, 1e-4, False, 0.0, np.inf),
        False,
    ]


def _with_unseen_satellite(args: list, sigma_common_m: float) -> list:
    """``args`` with one more satellite, of the last constellation, that no UAV receives."""
    pr, vis, sv, system, su, sc, el, n_sys = args[0]
    n = pr.shape[0]
    measured = _kernels.Measured(
        np.hstack([pr, np.full((n, 1), np.nan)]),
        np.hstack([vis, np.zeros((n, 1), dtype=bool)]),
        np.vstack([sv, sv[-1:] * 1.01]),
        np.append(system, system[-1]),
        np.hstack([su, np.full((n, 1), 1.5)]),
        np.append(sc, sigma_common_m),
        np.hstack([el, np.full((n, 1), np.nan)]),
        n_sys,
    )
    return [measured, *args[1:]]


@pytest.mark.parametrize("seed, n_uav", [(1, 5), (2, 4), (6, 9)])
@pytest.mark.parametrize("transfer", ["sdt", "ddt"])
def test_an_unseen_satellite_changes_no_bit(seed, n_uav, transfer) -> None:
    args = _isotropic_arguments(seed, n_uav, transfer)
    ref = _kernels.cooperative_isotropic(*args)
    assert (ref[3] == 0).any()  # some centroid solved
    out = _kernels.cooperative_isotropic(*_with_unseen_satellite(args, 2.0))
    assert len(out) == len(ref)
    for a, b in zip(out, ref):
        if isinstance(a, np.ndarray):
            assert a.shape == b.shape and a.tobytes() == b.tobytes()
        else:
            assert a == b


def test_an_unseen_satellite_with_infinite_common_sigma_stays_in_the_block() -> None:
    args = _isotropic_arguments(1, 5, "ddt")
    ref = _kernels.cooperative_isotropic(*args)
    out = _kernels.cooperative_isotropic(*_with_unseen_satellite(args, np.inf))
    solved = ref[3] == 0
    assert solved.any()
    assert (out[3][solved] == 2).all()  # SINGULAR_GEOMETRY: the NaN block fails Cholesky
