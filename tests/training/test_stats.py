"""coopnav_env.training.stats: IQM and bootstrap intervals against direct formulations."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.training.stats import (
    bootstrap_mean_interval,
    interquartile_mean,
    paired_difference,
    stratified_bootstrap_ci,
    suite_paired_difference,
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


def test_suite_difference_is_the_equal_weight_mean_of_the_city_means() -> None:
    # by hand: city 0 differences 1, 2, 3 (mean 2); city 1 a single episode of 5 - 1 = 4;
    # suite: (2 + 4) / 2 = 3, not the episode-weighted (1 + 2 + 3 + 4) / 4 = 2.5
    a = [np.array([[1.0, 2.0, 3.0]]), np.array([[5.0]])]
    b = [np.zeros((1, 3)), np.ones((1, 1))]
    iv = suite_paired_difference(a, b, reps=500)
    assert iv.value == pytest.approx(3.0, abs=1e-12)
    # city 1 has no spread; city 0's bootstrap means lie in [1, 3]: the suite's in [2.5, 3.5]
    assert 2.5 <= iv.low < iv.value < iv.high <= 3.5
    # runs are averaged per episode: two runs 0 and 2 score as one run of 1
    two_runs = [np.array([[0.0, 1.0, 2.0], [2.0, 3.0, 4.0]]), np.array([[4.0], [6.0]])]
    assert suite_paired_difference(two_runs, b, reps=50).value == pytest.approx(3.0, abs=1e-12)


def test_a_city_with_more_episodes_does_not_weigh_more() -> None:
    # a constant difference per city: 1 on 200 episodes, 0 on 5; the suite's figure is their
    # plain mean, and no replicate can move it
    a = [np.ones((1, 200)), np.zeros((1, 5))]
    b = [np.zeros((1, 200)), np.zeros((1, 5))]
    iv = suite_paired_difference(a, b, reps=200)
    assert iv.value == iv.low == iv.high == pytest.approx(0.5, abs=1e-12)
    # the same two cities with their episode counts swapped: the same figure
    swapped = suite_paired_difference(
        [np.ones((1, 5)), np.zeros((1, 200))], [np.zeros((1, 5)), np.zeros((1, 200))], reps=200
    )
    assert swapped.value == pytest.approx(0.5, abs=1e-12)


def test_a_suite_of_one_city_is_the_paired_difference_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    a, b = rng.normal(1.0, 1.0, (3, 25)), rng.normal(0.8, 1.0, (1, 25))
    iv = suite_paired_difference([a], [b], reps=300, seed=4)
    direct, _ = paired_difference(a, b, reps=300, seed=4)
    assert iv == direct


def test_a_training_run_is_resampled_once_for_every_city() -> None:
    # run 0 scores 1 everywhere, run 1 scores 0 everywhere, no episode spread: a replicate
    # drawing run 1 twice scores 0 in every city at once (probability 1/4), so the 2.5 %
    # quantile is 0. Runs drawn per city independently would need it in all three cities
    # (1/64 < 2.5 %) and the low end would lie above 0.
    a = [np.array([[1.0] * n, [0.0] * n]) for n in (4, 6, 8)]
    b = [np.zeros((1, n)) for n in (4, 6, 8)]
    iv = suite_paired_difference(a, b, reps=400)
    assert (iv.value, iv.low, iv.high) == (0.5, 0.0, 1.0)


def test_the_suite_interval_covers_the_true_difference_at_its_nominal_rate() -> None:
    # 150 simulated suites of three cities with 12, 20 and 40 episodes and true mean
    # differences 0.5, -0.2 and 0.3 (suite: 0.2). Binomial SE at p = 0.95, n = 150: 1.8 %;
    # the percentile bootstrap under-covers slightly at 12 episodes, so accept 0.88-0.99
    # (about -4 / +2.5 SE).
    rng = np.random.default_rng(11)
    sizes, shifts = (12, 20, 40), (0.5, -0.2, 0.3)
    hits, trials = 0, 150
    for t in range(trials):
        base = [rng.normal(2.0, 1.0, (1, n)) for n in sizes]  # shared episode variation
        a = [x + d + rng.normal(0.0, 0.5, x.shape) for x, d in zip(base, shifts)]
        b = [x + rng.normal(0.0, 0.5, x.shape) for x in base]
        iv = suite_paired_difference(a, b, reps=200, seed=t)
        hits += iv.low <= 0.2 <= iv.high
    assert 0.88 <= hits / trials <= 0.99


@pytest.mark.parametrize(
    ("a", "b", "kwargs", "message"),
    [
        ([], [], {}, "at least one city"),
        ([np.zeros((1, 3))], [np.zeros((1, 3))] * 2, {}, "one matrix per city"),
        ([np.zeros(3)], [np.zeros((1, 3))], {}, r"a\[0\] must be a \(runs, episodes\)"),
        ([np.zeros((1, 3))], [np.array([[0.0, np.nan, 0.0]])], {}, r"b\[0\] scores must be"),
        ([np.zeros((1, 3))], [np.zeros((1, 4))], {}, "city 0: a and b must cover the same"),
        (
            [np.zeros((2, 3)), np.zeros((3, 3))],
            [np.zeros((1, 3))] * 2,
            {},
            r"same runs .* in every city, got run counts \[2, 3\]",
        ),
        ([np.zeros((1, 3))], [np.zeros((1, 3))], {"reps": 0}, "reps must be at least 1"),
        ([np.zeros((1, 3))], [np.zeros((1, 3))], {"confidence": 1.0}, "confidence must be"),
    ],
)
def test_suite_difference_refuses_bad_input_by_name(a, b, kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        suite_paired_difference(a, b, **kwargs)
