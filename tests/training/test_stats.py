"""coopnav_env.training.stats: IQM and bootstrap intervals against direct formulations."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.training.stats import (
    bootstrap_mean_interval,
    interquartile_mean,
    paired_difference,
    stratified_bootstrap_ci,
)


def test_iqm_matches_scipy_trim_mean() -> None:
    scipy_stats = pytest.importorskip("scipy.stats")
    rng = np.random.default_rng(0)
    for n in (4, 5, 7, 100, 301):
        x = rng.standard_normal(n) ** 3
        assert interquartile_mean(x) == pytest.approx(scipy_stats.trim_mean(x, 0.25))
    with pytest.raises(ValueError, match="empty"):
        interquartile_mean(np.array([]))


def test_bootstrap_interval_covers_the_true_mean_at_its_nominal_rate() -> None:
    # 200 experiments of 3 runs x 40 tasks; the 95 % interval of the mean should cover the
    # true mean in about 95 % of them. Binomial SE at p = 0.95, n = 200: 1.5 %; the
    # percentile bootstrap under-covers slightly at n = 120 samples, so accept 0.88-0.99
    # (about -4.5 / +2.5 SE).
    rng = np.random.default_rng(1)
    hits = 0
    trials = 200
    for t in range(trials):
        s = rng.normal(2.0, 1.0, (3, 40))
        iv = stratified_bootstrap_ci(s, np.mean, reps=300, seed=t)
        hits += iv.low <= 2.0 <= iv.high
    assert 0.88 <= hits / trials <= 0.99


def test_bootstrap_is_deterministic_and_single_runs_need_task_resampling() -> None:
    s = np.random.default_rng(2).normal(size=(1, 30))
    a = stratified_bootstrap_ci(s, np.mean, reps=200, seed=5)
    b = stratified_bootstrap_ci(s, np.mean, reps=200, seed=5)
    assert a == b
    assert a.low < a.value < a.high
    flat = stratified_bootstrap_ci(s, np.mean, reps=200, seed=5, task_bootstrap=False)
    assert flat.low == flat.high == pytest.approx(float(s.mean()))  # one run: no spread
    with pytest.raises(ValueError, match="runs, tasks"):
        stratified_bootstrap_ci(np.zeros(5), np.mean)
    with pytest.raises(ValueError, match="finite"):
        stratified_bootstrap_ci(np.array([[1.0, np.nan]]), np.mean)


def test_paired_difference_detects_a_small_shift_that_unpaired_noise_hides() -> None:
    rng = np.random.default_rng(3)
    episode = rng.normal(3.0, 1.0, 100)  # large episode-to-episode variation
    b = episode[None, :] + rng.normal(0, 0.05, (1, 100))
    a = episode[None, :] - 0.1 + rng.normal(0, 0.05, (3, 100))
    iv, share = paired_difference(a, b, reps=500)
    assert iv.excludes_zero() and iv.high < 0.0
    assert iv.value == pytest.approx(-0.1, abs=0.03)
    assert share > 0.8
    unpaired = stratified_bootstrap_ci(a, np.mean, reps=500).as_dict()
    other = stratified_bootstrap_ci(b, np.mean, reps=500).as_dict()
    assert unpaired["low"] < other["high"]  # the unpaired intervals overlap
    with pytest.raises(ValueError, match="same episodes"):
        paired_difference(a, b[:, :50])


def test_bootstrap_mean_interval_is_the_percentile_bootstrap_of_the_mean() -> None:
    d = np.random.default_rng(5).normal(0.3, 1.0, 400)
    mean, lo, hi = bootstrap_mean_interval(d, 1000, np.random.default_rng(0))
    rng = np.random.default_rng(0)  # the direct formulation, the same generator sequence
    direct = np.percentile(
        [d[rng.integers(0, d.size, d.size)].mean() for _ in range(1000)], [2.5, 97.5]
    )
    assert (lo, hi) == pytest.approx(tuple(direct), abs=1e-12)
    assert mean == pytest.approx(d.mean())
    # 400 draws of sd 1: the interval is about +/-1.96/20 = +/-0.098 wide around the mean
    assert lo < mean < hi and (hi - lo) == pytest.approx(2 * 1.96 / 20, rel=0.15)
    # a generator passed on keeps its sequence: two draws differ, a fresh seed repeats
    g = np.random.default_rng(1)
    first, second = bootstrap_mean_interval(d, 200, g), bootstrap_mean_interval(d, 200, g)
    assert first != second
    assert bootstrap_mean_interval(d, 200, np.random.default_rng(1)) == first
    assert bootstrap_mean_interval(np.full(50, 2.0), 100, np.random.default_rng(0)) == (
        2.0,
        2.0,
        2.0,
    )
