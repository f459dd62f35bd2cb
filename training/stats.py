"""Statistics for comparing RL policies: interquartile mean and stratified bootstrap CIs.

The definitions follow Agarwal et al., *Deep Reinforcement Learning at the Edge of the
Statistical Precipice* (NeurIPS 2021) and its library ``rliable``: scores form a
``(runs, tasks)`` matrix (here: training seeds x held-out episodes; a deterministic heuristic
is one run); the interquartile mean (IQM) is the mean of the middle 50 % of all scores
(``scipy.stats.trim_mean(x, 0.25)``: ``int(0.25 n)`` scores cut from each end); a stratified
bootstrap resamples runs with replacement *within* each task and, with
``task_bootstrap=True``, the tasks too; the CI is the percentile interval. ``rliable`` 1.2.0
itself does not import beside the ``arch`` and ``pandas`` releases that pip resolves today
(``TypeError: deprecate_kwarg()``), so the few lines it needs are here, tested against a
direct formulation (``tests/training/test_stats.py``).

Paired comparisons (:func:`paired_difference`, :func:`gap_closed`) resample the same
episodes for every policy compared, so that the episode-to-episode variation (city, route,
satellites) cancels. :func:`suite_paired_difference` puts per-city paired differences
together into one suite-level figure, every city weighted equally, with a bootstrap stratified
by city.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Interval",
    "bootstrap_mean_interval",
    "gap_closed",
    "interquartile_mean",
    "paired_difference",
    "stratified_bootstrap_ci",
    "suite_paired_difference",
]


@dataclass(frozen=True)
class Interval:
    """A point estimate with its confidence interval."""

    value: float
    low: float
    high: float

    def excludes_zero(self) -> bool:
        """Whether the interval lies entirely above or below zero."""
        return self.low > 0.0 or self.high < 0.0

    def as_dict(self) -> dict[str, float]:
        """``{"value", "low", "high"}``."""
        return {"value": self.value, "low": self.low, "high": self.high}


def interquartile_mean(x: np.ndarray) -> float:
    """Mean of the middle 50 % of all entries of ``x`` (``scipy.stats.trim_mean(x, 0.25)``)."""
    v = np.sort(np.asarray(x, dtype=float).ravel())
    if v.size == 0:
        raise ValueError("interquartile_mean of an empty array")
    cut = int(0.25 * v.size)
    return float(v[cut : v.size - cut].mean())


def _check_scores(scores: np.ndarray) -> np.ndarray:
    s = np.asarray(scores, dtype=float)
    if s.ndim != 2 or s.shape[0] < 1 or s.shape[1] < 1:
        raise ValueError(f"scores must be a (runs, tasks) matrix, got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError("scores must be finite")
    return s


def stratified_bootstrap_ci(
    scores: np.ndarray,
    statistic: Callable[[np.ndarray], float],
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
    task_bootstrap: bool = True,
) -> Interval:
    """``statistic(scores)`` with its stratified-bootstrap percentile interval.

    Parameters
    ----------
    scores : ndarray, shape (runs, tasks)
    statistic : callable
        Of a ``(runs, tasks)`` matrix, e.g. ``np.mean`` or :func:`interquartile_mean`.
    reps : int
        Bootstrap replicates.
    confidence : float
        Coverage of the interval, in (0, 1).
    seed : int
        Seed of the resampling generator (results are deterministic).
    task_bootstrap : bool
        Also resample the tasks (episodes); needed when there is a single run.
    """
    s = _check_scores(scores)
    if not (0.0 < confidence < 1.0):
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    rng = np.random.default_rng(seed)
    n_runs, n_tasks = s.shape
    stats = np.empty(reps)
    cols = np.arange(n_tasks)
    for r in range(reps):
        tasks = rng.integers(0, n_tasks, n_tasks) if task_bootstrap else cols
        runs = rng.integers(0, n_runs, (n_runs, n_tasks))  # within each task
        stats[r] = statistic(s[runs, tasks[None, :]])
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(stats, [alpha, 1.0 - alpha])
    return Interval(float(statistic(s)), float(lo), float(hi))


def paired_difference(
    a: np.ndarray,
    b: np.ndarray,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[Interval, float]:
    """Mean of ``a - b`` over paired episodes, with a bootstrap CI; and P(a < b) by episode.

    ``a`` and ``b`` are ``(runs, episodes)`` matrices over the same episodes (columns in the
    same order); each method's runs are averaged per episode in every replicate after
    resampling its runs, and the episodes are resampled once for both (pairing).

    Returns
    -------
    interval : Interval
        The mean difference and its percentile interval.
    share_lower : float
        Share of episodes where ``a``'s run-mean is below ``b``'s.
    """
    a, b = _check_scores(a), _check_scores(b)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"a and b must cover the same episodes, got {a.shape} and {b.shape}")
    rng = np.random.default_rng(seed)
    n = a.shape[1]
    diffs = np.empty(reps)
    for r in range(reps):
        ep = rng.integers(0, n, n)
        ra = rng.integers(0, a.shape[0], a.shape[0])
        rb = rng.integers(0, b.shape[0], b.shape[0])
        diffs[r] = float(a[ra][:, ep].mean() - b[rb][:, ep].mean())
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(diffs, [alpha, 1.0 - alpha])
    per_ep = a.mean(axis=0) - b.mean(axis=0)
    return Interval(float(per_ep.mean()), float(lo), float(hi)), float(np.mean(per_ep < 0.0))


def suite_paired_difference(
    a: Sequence[np.ndarray],
    b: Sequence[np.ndarray],
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """Mean over cities of each city's mean paired difference ``a - b``, with a bootstrap CI.

    The suite-level figure of a generalisation benchmark: every city counts once, whatever
    its number of episodes, so the estimate is ``mean_c mean_e (a_c - b_c)[e]`` (the runs of
    each method averaged per episode first, as in :func:`paired_difference`). Each replicate
    resamples the episodes of every city with replacement *within* that city (stratified
    bootstrap; the same episodes for both methods), then the runs of each method, and takes
    the same mean over cities; the interval is the percentile interval of the replicates. A
    method's runs (training seeds) are the same policies in every city, so a replicate draws
    one set of runs per method for all cities, applied in each city as
    :func:`paired_difference` applies them. With a single city the result is
    :func:`paired_difference`'s interval for the same ``seed``, bit for bit.

    Parameters
    ----------
    a, b : sequence of ndarray, each of shape (runs, episodes)
        Per-city score matrices of the two methods, one entry per city, in the same city
        order; ``a[c]`` and ``b[c]`` cover the same episodes of city ``c`` (columns in the
        same order). The number of runs of a method must be the same in every city (row ``i``
        is the same training run everywhere); the episode counts may differ between cities.
    reps : int
        Bootstrap replicates (at least 1).
    confidence : float
        Coverage of the interval, in (0, 1).
    seed : int
        Seed of the resampling generator (results are deterministic).

    Returns
    -------
    Interval
        The equal-weight mean of the per-city mean differences and its percentile interval.

    Raises
    ------
    ValueError
        No city, ``a`` and ``b`` of different city counts, a city's matrix that is not
        ``(runs, episodes)`` or not finite, a city where ``a`` and ``b`` cover different
        episode counts, a method whose run count differs between cities, fewer than 1
        replicate, or a ``confidence`` outside (0, 1).
    """
    a_cities, b_cities = list(a), list(b)
    if not a_cities:
        raise ValueError("give at least one city: a and b are empty")
    if len(a_cities) != len(b_cities):
        raise ValueError(
            f"a and b must hold one matrix per city each, got {len(a_cities)} and "
            f"{len(b_cities)} cities"
        )
    a_cities = [_check_city(x, "a", c) for c, x in enumerate(a_cities)]
    b_cities = [_check_city(x, "b", c) for c, x in enumerate(b_cities)]
    for c, (x, y) in enumerate(zip(a_cities, b_cities)):
        if x.shape[1] != y.shape[1]:
            raise ValueError(
                f"city {c}: a and b must cover the same episodes, got {x.shape[1]} and "
                f"{y.shape[1]} episodes"
            )
    for name, cities in (("a", a_cities), ("b", b_cities)):
        runs = [x.shape[0] for x in cities]
        if len(set(runs)) != 1:
            raise ValueError(
                f"{name} must have the same runs (training seeds) in every city, got run "
                f"counts {runs}; drop the runs missing from some city"
            )
    if int(reps) < 1:
        raise ValueError(f"reps must be at least 1, got {reps}")
    if not (0.0 < confidence < 1.0):
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    rng = np.random.default_rng(seed)
    n_cities = len(a_cities)
    n_a, n_b = a_cities[0].shape[0], b_cities[0].shape[0]
    diffs = np.empty(int(reps))
    for r in range(int(reps)):
        # the draw order of paired_difference (episodes, then runs of a, then of b), with
        # every city's episodes drawn first
        eps = [rng.integers(0, x.shape[1], x.shape[1]) for x in a_cities]
        ra = rng.integers(0, n_a, n_a)
        rb = rng.integers(0, n_b, n_b)
        total = 0.0
        for x, y, ep in zip(a_cities, b_cities, eps):
            total += float(x[ra][:, ep].mean() - y[rb][:, ep].mean())
        diffs[r] = total / n_cities
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(diffs, [alpha, 1.0 - alpha])
    per_city = [float((x.mean(axis=0) - y.mean(axis=0)).mean()) for x, y in zip(a_cities, b_cities)]
    return Interval(sum(per_city) / n_cities, float(lo), float(hi))


def _check_city(x: np.ndarray, name: str, city: int) -> np.ndarray:
    s = np.asarray(x, dtype=float)
    if s.ndim != 2 or s.shape[0] < 1 or s.shape[1] < 1:
        raise ValueError(
            f"{name}[{city}] must be a (runs, episodes) matrix with at least one of each, got "
            f"shape {s.shape}"
        )
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{name}[{city}] scores must be finite")
    return s


def bootstrap_mean_interval(
    d: np.ndarray, reps: int, rng: np.random.Generator
) -> tuple[float, float, float]:
    """Mean of the 1-D sample ``d`` and the 95 % percentile interval of its bootstrap means.

    The one-level bootstrap of the benchmark scripts' paired screening: ``d`` is already one
    difference per episode (a method's runs averaged), and each of the ``reps`` replicates is
    ``rng.choice(d, d.size).mean()``. ``rng`` is passed in so that a script drawing several
    intervals from one generator keeps its sequence. Unlike :func:`paired_difference` it does
    not resample training runs; ``d`` must be what the caller wants averaged (filter
    non-finite entries first).
    """
    boot = [rng.choice(d, d.size).mean() for _ in range(reps)]
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return float(np.mean(d)), float(lo), float(hi)


def gap_closed(
    method: np.ndarray,
    baseline: np.ndarray,
    reference: np.ndarray,
    reps: int = 2000,
    seed: int = 0,
) -> Interval:
    """Share of the gap from ``baseline`` to ``reference`` that ``method`` closes, with a paired
    bootstrap interval.

    The estimate is ``(mean(method) - mean(baseline)) / (mean(reference) - mean(baseline))``
    over the episodes: 0 scores as the baseline, 1 as the reference, above 1 beyond it. Each
    of the ``reps`` replicates resamples the episodes with replacement, the same episodes for
    all three (pairing), and the interval is the 2.5 and 97.5 percentiles of the replicates.

    Parameters
    ----------
    method, baseline, reference : ndarray, shape (episodes,) or (runs, episodes)
        Per-episode scores on the same episodes, in the same order; a matrix holds one row per
        training run, averaged per episode first (the runs are not resampled, as in the
        comparison of methods that pools training seeds per episode).
    reps : int
        Bootstrap replicates (at least 1).
    seed : int
        Seed of the resampling generator (results are deterministic).

    Raises
    ------
    ValueError
        Arrays of other shapes or episode counts, non-finite scores, fewer than 1 replicate,
        or a baseline and reference with the same mean score (no gap to close).
    """

    def episodes(x: np.ndarray, name: str) -> np.ndarray:
        a = np.asarray(x, dtype=float)
        if a.ndim == 1:
            a = a[None, :]
        if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
            raise ValueError(
                f"{name} must be per-episode scores, shape (episodes,) or (runs, episodes), "
                f"got shape {np.shape(x)}"
            )
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} scores must be finite")
        return a.mean(axis=0)

    m = episodes(method, "method")
    b = episodes(baseline, "baseline")
    r = episodes(reference, "reference")
    if not (m.size == b.size == r.size):
        raise ValueError(
            f"method, baseline and reference must cover the same episodes, got {m.size}, "
            f"{b.size} and {r.size}"
        )
    if int(reps) < 1:
        raise ValueError(f"reps must be at least 1, got {reps}")
    gap = r.mean() - b.mean()
    if gap == 0.0:
        raise ValueError(
            "the baseline and the reference have the same mean score on these episodes: there "
            "is no gap to close; choose a reference that scores differently"
        )
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, m.size, size=(int(reps), m.size))
    mb, bb, rb = m[idx].mean(axis=1), b[idx].mean(axis=1), r[idx].mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        boots = (mb - bb) / (rb - bb)
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return Interval(float((m.mean() - b.mean()) / gap), float(lo), float(hi))
