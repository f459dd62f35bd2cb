"""Relative (UWB-like) position sensing: structure, antisymmetry and Monte Carlo statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.sim import RelativeSensingConfig, measure_relative_positions, pairwise_ranges_m

# four UAVs: ranges from UAV 0 are 50, 150 and 250 m (the last beyond the default 200 m)
POS = np.array([[0.0, 0.0, 10.0], [30.0, 40.0, 10.0], [0.0, 150.0, 10.0], [0.0, -250.0, 10.0]])


def test_structure_and_antisymmetry() -> None:
    cfg = RelativeSensingConfig()
    rel, cov, avail = measure_relative_positions(np.random.default_rng(0), POS, cfg)
    n = len(POS)
    assert rel.shape == (n, n, 3) and cov.shape == (n, n, 3, 3) and avail.shape == (n, n)
    rng_m = pairwise_ranges_m(POS)
    np.testing.assert_array_equal(avail, (rng_m > 0) & (rng_m <= 200.0))
    assert not np.diag(avail).any()
    np.testing.assert_array_equal(avail, avail.T)
    np.testing.assert_array_equal(rel, -rel.transpose(1, 0, 2))  # one measurement per pair
    np.testing.assert_array_equal(rel[~avail], 0.0)
    np.testing.assert_array_equal(cov[~avail], 0.0)
    sigma = cfg.sigma0_m + cfg.sigma_per_m * rng_m
    expected_cov = (np.where(avail, sigma**2, 0.0))[:, :, None, None] * np.eye(3)
    np.testing.assert_allclose(cov, expected_cov)
    # measured vectors are close to the truth
    diff = POS[None, :, :] - POS[:, None, :]
    err = np.linalg.norm(rel - diff, axis=2)[avail]
    assert np.all(err < 6 * sigma[avail] * math.sqrt(3))


def test_coincident_uavs_are_unavailable() -> None:
    pos = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 10.0]])
    _, _, avail = measure_relative_positions(np.random.default_rng(0), pos, RelativeSensingConfig())
    assert not avail.any()


def test_determinism_and_stream_independent_of_availability() -> None:
    cfg = RelativeSensingConfig()
    a = measure_relative_positions(np.random.default_rng(5), POS, cfg)
    b = measure_relative_positions(np.random.default_rng(5), POS, cfg)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    g1, g2 = np.random.default_rng(6), np.random.default_rng(6)
    measure_relative_positions(g1, POS, RelativeSensingConfig(max_range_m=1.0))
    measure_relative_positions(g2, POS, RelativeSensingConfig(max_range_m=1e4))
    assert g1.random() == g2.random()
    pos = POS.copy()
    pos.setflags(write=False)  # inputs are never modified
    measure_relative_positions(np.random.default_rng(0), pos, cfg)


def test_monte_carlo_error_statistics() -> None:
    cfg = RelativeSensingConfig()
    rng = np.random.default_rng(12345)
    n_mc = 4000
    diff = POS[None, :, :] - POS[:, None, :]
    errs = np.empty((n_mc, 4, 4, 3))
    for k in range(n_mc):
        rel, cov, avail = measure_relative_positions(rng, POS, cfg)
        errs[k] = rel - diff
    pairs = [(0, 1), (0, 2), (1, 2)]  # available pairs, ranges 50, 150 and 111.8 m
    for b, q in pairs:
        assert avail[b, q]
        e = errs[:, b, q, :]  # (n_mc, 3)
        sigma = cfg.sigma0_m + cfg.sigma_per_m * np.linalg.norm(diff[b, q])
        # mean: standard error sigma / sqrt(n); 4.5 sigma tolerance
        np.testing.assert_array_less(np.abs(e.mean(axis=0)), 4.5 * sigma / math.sqrt(n_mc))
        # per-axis variance: relative standard error sqrt(2 / (n - 1))
        var = e.var(axis=0, ddof=1)
        np.testing.assert_array_less(np.abs(var / sigma**2 - 1), 4.5 * math.sqrt(2 / (n_mc - 1)))
        # sampled covariance matches the predicted one (off-diagonal ~ 0)
        c = np.cov(e.T) / sigma**2
        off = c[~np.eye(3, dtype=bool)]
        np.testing.assert_array_less(np.abs(off), 4.5 / math.sqrt(n_mc))
        np.testing.assert_allclose(cov[b, q], sigma**2 * np.eye(3))
    # errors of different pairs are independent
    r = np.corrcoef(errs[:, 0, 1, 0], errs[:, 0, 2, 0])[0, 1]
    assert abs(r) < 4.5 / math.sqrt(n_mc)


def test_sigma_model() -> None:
    cfg = RelativeSensingConfig()
    np.testing.assert_allclose(cfg.sigma_m([0.0, 200.0]), [0.1, 0.5])  # paper: 0.5 m per axis


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"max_range_m": 0.0},
            r"RelativeSensingConfig\.max_range_m must be in \(0\.0, 100000\.0\]",
        ),
        ({"sigma0_m": -0.1}, r"RelativeSensingConfig\.sigma0_m"),
        ({"sigma_per_m": 2.0}, r"RelativeSensingConfig\.sigma_per_m must be in \[0\.0, 1\.0\]"),
    ],
)
def test_config_errors(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        RelativeSensingConfig(**kwargs)
