"""Fly a family of policies on every city of a suite (``coopnav evaluate --suite real``).

:func:`evaluate_suite` evaluates the given policies on the same held-out reset seeds in each
city of a suite (:mod:`coopnav_env.sim.real_suite`), with the suite city's settings
(:meth:`~coopnav_env.sim.real_suite.SuiteCity.env_settings`) over the rest:

* a heuristic flies the environment's defaults, in the action frame it commands;
* a trained policy flies the settings of the run it came from (its ``config.yaml``: action
  frame, observation and reward settings), the city and sky of the suite replacing the run's.

``overrides`` (``--env-set``) change every city's settings last. Each city gets the report
of :func:`coopnav_env.training.evaluate.evaluate` (``report.md``, ``report.json``, ...) in a
folder of its name; :class:`SuiteReport` puts them together in one table (score, navigation
error, goal rate, satellites per UAV, per city and policy), written as ``summary.md`` and
``summary.json``.

Two references can be added per city:

* ``per_city_rule=N``: the column preset (:data:`coopnav_env.agents.heuristics.
  COLUMN_PRESETS`) with the best mean score on ``N`` tuning episodes of that city (reset
  seeds from :data:`TUNING_SEED_START`, below the held-out seeds, as training episodes are),
  flown on the held-out seeds as the row :data:`PER_CITY_RULE`: a rule re-tuned for each
  city, which a policy tuned on other cities does not get;
* ``compare=NAME``: every other policy's paired difference of episode scores from policy
  ``NAME`` in each city, with a paired 95 % bootstrap interval (``comparison.md``), and over
  the whole suite (the row :data:`ALL_CITIES`): the mean of the per-city differences, every
  city weighted equally, with an interval that resamples episodes within each city
  (:func:`coopnav_env.training.stats.suite_paired_difference`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.sim.real_suite import GeneratedSuiteCity, SuiteCity, suite_cities
from coopnav_env.training.envs import DEFAULT_ENV_ID, EVAL_SEED_START
from coopnav_env.training.evaluate import PolicyStats, Report, evaluate, write_report
from coopnav_env.training.files import atomic_write_text, jsonable, write_json
from coopnav_env.training.run_configs import train_config_of_policies
from coopnav_env.training.stats import Interval, paired_difference, suite_paired_difference

__all__ = [
    "ALL_CITIES",
    "PER_CITY_RULE",
    "SUITE_COLUMNS",
    "TUNING_SEED_START",
    "Comparison",
    "SuiteReport",
    "evaluate_suite",
    "suite_outputs",
]

ALL_CITIES: str = "all cities (equal weight)"
"""City name of the suite-level comparison rows (``compare``): every city weighted equally."""

PER_CITY_RULE: str = "per_city_column"
"""Row name of the column preset re-tuned for each city (``per_city_rule``)."""

TUNING_SEED_START: int = 900_000
"""First reset seed of the tuning episodes of ``per_city_rule`` (below
:data:`~coopnav_env.training.envs.EVAL_SEED_START`, so never a held-out episode)."""

SuiteEntry = SuiteCity | GeneratedSuiteCity

SUITE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("score", "return_mean", "{:.3f}"),
    ("nav error mean [m]", "nav_error_mean_m", "{:.2f}"),
    ("coop mean [m]", "coop_error_mean_m", "{:.2f}"),
    ("goal rate", "goal_rate", "{:.3f}"),
    ("collisions", "collisions", "{:d}"),
    ("sats/UAV", "n_sats_mean", "{:.1f}"),
    ("steps", "length_mean", "{:.1f}"),
    ("cruise spacing [m]", "cruise_spacing_m", "{:.1f}"),
    ("altitude [m]", "cruise_altitude_m", "{:.1f}"),
    ("spread across route [m]", "cruise_spread_m", "{:.1f}"),
    ("speed [m/s]", "cruise_speed_mps", "{:.1f}"),
)
"""Columns of the summary table: (title, :class:`PolicyStats` field, format); the last four
are the behaviour descriptors of :mod:`coopnav_env.training.behaviour`."""


def suite_outputs(suite: str, compare: bool = False) -> tuple[str, ...]:
    """The entries ``coopnav evaluate --suite NAME --out DIR`` writes into ``DIR`` (with
    ``compare``, ``comparison.md`` too)."""
    extra = ("comparison.md",) if compare else ()
    return ("summary.md", "summary.json", *extra, *(c.name for c in suite_cities(suite)))


@dataclass(frozen=True)
class Comparison:
    """One policy against the suite's reference policy in one city, or over the suite.

    Attributes
    ----------
    city, policy, reference : str
        ``city`` is :data:`ALL_CITIES` for the suite-level row.
    score_difference : Interval
        Mean over the city's episodes of the policy's score minus the reference's on the same
        episode, with its paired 95 % bootstrap interval; for the suite-level row, the mean of
        the cities' mean differences (every city weighted equally), with a 95 % bootstrap
        interval stratified by city.
    goal_rate, reference_goal_rate : float
        Share of episodes with the whole swarm at the goal; for the suite-level row, the mean
        of the cities' goal rates.
    """

    city: str
    policy: str
    reference: str
    score_difference: Interval
    goal_rate: float
    reference_goal_rate: float


@dataclass
class SuiteReport:
    """Policies flown on every city of a suite.

    Attributes
    ----------
    suite : str
        The suite's name.
    cities : list of SuiteCity
    reports : dict of str to Report
        The evaluation of each city, by city name.
    n_buildings : dict of str to float
        Buildings flown in each city, by city name (for a generated family, the mean over
        the episodes' cities).
    picks : dict of str to tuple of (str, float)
        With ``per_city_rule``: per city, the preset flown as :data:`PER_CITY_RULE` and its
        mean score on the tuning episodes.
    comparisons : list of Comparison
        With ``compare``: every other policy against the reference, per city.
    suite_comparisons : list of Comparison
        With ``compare``: every other policy against the reference over the whole suite (city
        :data:`ALL_CITIES`, every city weighted equally), one per policy.
    files : list of Path
        What was written (empty when nothing was).
    """

    suite: str
    cities: list[SuiteEntry]
    reports: dict[str, Report]
    n_buildings: dict[str, float]
    picks: dict[str, tuple[str, float]] = field(default_factory=dict)
    comparisons: list[Comparison] = field(default_factory=list)
    suite_comparisons: list[Comparison] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)

    def rows(self) -> list[tuple[SuiteEntry, PolicyStats]]:
        """(city, policy stats) for every city, then every policy, in the order flown."""
        return [(c, s) for c in self.cities for s in self.reports[c.name].stats]

    def to_markdown(self) -> str:
        """The summary table in GitHub Markdown, a row per city and policy."""
        head = ["city", "policy", *(t for t, _, _ in SUITE_COLUMNS)]
        lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
        for city, s in self.rows():
            cells = [_fmt(getattr(s, f), fmt) for _, f, fmt in SUITE_COLUMNS]
            lines.append(f"| {city.name} | {s.policy} | " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def header(self) -> str:
        """The suite, its cities and the episodes flown (printed above the table)."""
        first = next(iter(self.reports.values()))
        seeds = first.seeds
        span = f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
        places = "; ".join(
            f"`{c.name}`: {c.place}, {c.character} ({_buildings(self.n_buildings[c.name])})"
            for c in self.cities
        )
        text = (
            f"Suite `{self.suite}`, environment `{first.env_id}`: {places}. "
            f"{len(seeds)} held-out episodes per city and policy (reset seeds {span}). "
            "Score: the task's score (mean episode return); nav error: 3-D error of the estimate "
            "each UAV used; goal rate: episodes in which the whole swarm reached the goal area."
        )
        if self.picks:
            chosen = "; ".join(
                f"{city}: `{preset}` ({score:.3f})" for city, (preset, score) in self.picks.items()
            )
            text += (
                f" `{PER_CITY_RULE}`: the column preset with the best mean score on tuning "
                f"episodes of the city (reset seeds from {TUNING_SEED_START}), per city: "
                f"{chosen}."
            )
        return text

    def comparison_markdown(self) -> str:
        """The paired score differences from the reference (``compare``), a row per city and
        policy, then a row per policy over all cities (:data:`ALL_CITIES`), in GitHub
        Markdown."""
        if not self.comparisons:
            return ""
        ref = self.comparisons[0].reference
        head = [
            "city",
            "policy",
            f"score - {ref} [95 % CI]",
            "interval excludes 0",
            "goal rate",
            f"{ref} goal rate",
        ]
        lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
        for c in (*self.comparisons, *self.suite_comparisons):
            d = c.score_difference
            side = "above" if d.low > 0.0 else "below" if d.high < 0.0 else "no"
            lines.append(
                f"| {c.city} | {c.policy} | {d.value:+.3f} [{d.low:+.3f}, {d.high:+.3f}] "
                f"| {side} | {c.goal_rate:.3f} | {c.reference_goal_rate:.3f} |"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (NaN written as null)."""
        return {
            "suite": self.suite,
            "cities": [asdict(c) | {"buildings": self.n_buildings[c.name]} for c in self.cities],
            "env_settings": {
                c.name: jsonable(self.reports[c.name].env_kwargs) for c in self.cities
            },
            "seeds": list(next(iter(self.reports.values())).seeds),
            "per_city_rule": {
                city: {"preset": preset, "tuning_score": score}
                for city, (preset, score) in self.picks.items()
            },
            "comparisons": [_comparison_dict(c) for c in self.comparisons],
            "suite_comparisons": [_comparison_dict(c) for c in self.suite_comparisons],
            "rows": [
                {"city": c.name, **jsonable({f: getattr(s, f) for _, f, _ in SUITE_COLUMNS})}
                | {"policy": s.policy, "episodes": s.episodes}
                for c, s in self.rows()
            ],
        }


def _comparison_dict(c: Comparison) -> dict[str, Any]:
    """One comparison row of ``summary.json``."""
    return {
        "city": c.city,
        "policy": c.policy,
        "reference": c.reference,
        "score_difference": jsonable(c.score_difference.as_dict()),
        "goal_rate": c.goal_rate,
        "reference_goal_rate": c.reference_goal_rate,
    }


def _fmt(value: Any, fmt: str) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return "n/a"
    return fmt.format(value)


def _buildings(n: float) -> str:
    return f"{n:.0f} buildings" if float(n).is_integer() else f"{n:.0f} buildings on average"


def _run_settings(policy: str) -> tuple[str, dict[str, Any]]:
    """(env id, env settings) of the training run a trained policy came from ({} for others)."""
    found = train_config_of_policies([policy])
    return str(found.get("env_id") or DEFAULT_ENV_ID), dict(found.get("env") or {})


def _per_city_rule(
    city: SuiteEntry, base: Mapping[str, Any], n_tune: int, verbose: bool
) -> tuple[str, float]:
    """The column preset with the best mean score on ``n_tune`` tuning episodes of ``city``
    (the first of equals in :data:`~coopnav_env.agents.heuristics.COLUMN_PRESETS` order), and
    that score."""
    from coopnav_env.agents.heuristics import COLUMN_PRESETS

    presets = list(COLUMN_PRESETS)
    seeds = list(range(TUNING_SEED_START, TUNING_SEED_START + n_tune))
    if verbose:
        print(f"  {city.name}: tuning {len(presets)} column presets", file=sys.stderr)
    report = evaluate(presets, seeds, dict(base), env_id=DEFAULT_ENV_ID, verbose=verbose)
    scores = [s.return_mean for s in report.stats]
    best = int(np.argmax(scores))
    return presets[best], float(scores[best])


def _city_report(
    city: SuiteEntry,
    groups: Mapping[str, tuple[dict[str, Any], list[str]]],
    policies: Sequence[str],
    seeds: Sequence[int],
    overrides: Mapping[str, Any],
    verbose: bool,
    per_city_rule: int,
) -> tuple[Report, float, tuple[str, float] | None]:
    """Evaluate every group of policies (same run settings) in ``city``: one report, the
    number of buildings flown, and the per-city rule's pick (None without one)."""
    base = {**city.env_settings(), **overrides}
    pick = _per_city_rule(city, base, per_city_rule, verbose) if per_city_rule else None
    reports = []
    for run_env, members in groups.values():
        kwargs = {**run_env, **base}
        if verbose:
            print(f"  {city.name}: {', '.join(members)}", file=sys.stderr)
        reports.append(evaluate(members, seeds, kwargs, env_id=DEFAULT_ENV_ID, verbose=verbose))
    stats = {s.policy: s for r in reports for s in r.stats}
    episodes = {k: v for r in reports for k, v in r.episodes.items()}
    own = {k: v for r in reports for k, v in r.own_frame.items()}
    names = list(policies)
    if pick is not None:
        preset = pick[0]
        if preset in stats:  # flown already, on the same episodes and settings
            rule_stats, rule_eps = stats[preset], episodes[preset]
        else:
            r = evaluate([preset], seeds, base, env_id=DEFAULT_ENV_ID, verbose=verbose)
            rule_stats, rule_eps = r.stats[0], r.episodes[preset]
        stats[PER_CITY_RULE] = dataclasses.replace(rule_stats, policy=PER_CITY_RULE)
        episodes[PER_CITY_RULE] = rule_eps
        names.append(PER_CITY_RULE)
    n = city.buildings_flown(base, seeds)
    trained = [
        f"{', '.join(m)} with the settings of its run ({json.dumps(jsonable(e))})"
        for e, m in groups.values()
        if e
    ]
    source = f"suite city {city.name}, {city.place}; {_buildings(n)}"
    if pick is not None:
        source += f"; {PER_CITY_RULE}: {pick[0]} (tuned on {per_city_rule} episodes)"
    if trained:
        source += "; " + "; ".join(trained)
    report = Report(
        [stats[p] for p in names],
        list(seeds),
        base,
        DEFAULT_ENV_ID,
        {p: episodes[p] for p in names},
        env_source=source,
        own_frame=own,
    )
    return report, n, pick


def _comparisons(city: str, report: Report, reference: str) -> list[Comparison]:
    """Every policy of ``report`` but ``reference`` against it, on the same episodes."""
    scores = {p: np.array([[e.episode_return for e in eps]]) for p, eps in report.episodes.items()}
    goal = {s.policy: s.goal_rate for s in report.stats}
    out = []
    for p in (s.policy for s in report.stats):
        if p == reference:
            continue
        diff, _ = paired_difference(scores[p], scores[reference])
        out.append(Comparison(city, p, reference, diff, goal[p], goal[reference]))
    return out


def _suite_comparisons(reports: Mapping[str, Report], reference: str) -> list[Comparison]:
    """Every policy but ``reference`` against it over all cities of ``reports``: the mean of
    the cities' mean paired differences, every city weighted equally."""
    scores = {
        city: {p: np.array([[e.episode_return for e in eps]]) for p, eps in r.episodes.items()}
        for city, r in reports.items()
    }
    goal = {city: {s.policy: s.goal_rate for s in r.stats} for city, r in reports.items()}
    first = next(iter(reports.values()))
    out = []
    for p in (s.policy for s in first.stats):
        if p == reference:
            continue
        diff = suite_paired_difference(
            [scores[c][p] for c in reports], [scores[c][reference] for c in reports]
        )
        out.append(
            Comparison(
                ALL_CITIES,
                p,
                reference,
                diff,
                float(np.mean([goal[c][p] for c in reports])),
                float(np.mean([goal[c][reference] for c in reports])),
            )
        )
    return out


def evaluate_suite(
    policies: Sequence[str],
    seeds: Sequence[int],
    suite: str = "real",
    out: str | Path | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    verbose: bool = False,
    per_city_rule: int = 0,
    compare: str | None = None,
) -> SuiteReport:
    """Fly ``policies`` on every city of ``suite``, the same reset seeds in each.

    Parameters
    ----------
    policies : sequence of str
        Policy names as for :func:`coopnav_env.training.evaluate.evaluate` (heuristics,
        ``mappo:pretrained/route_s0``, ...), unique.
    seeds : sequence of int
        Reset seeds, one episode per city and policy, each ``>= EVAL_SEED_START``.
    suite : str, default "real"
        A key of :data:`coopnav_env.sim.real_suite.SUITES` (``"real"``, ``"families"``).
    out : path or None
        Folder for ``summary.md``, ``summary.json`` (and ``comparison.md`` with ``compare``)
        and one report folder per city (no plots); None writes nothing.
    overrides : mapping, optional
        Environment settings applied last in every city (``--env-set``).
    verbose : bool, default False
        Print progress per city and policy on stderr.
    per_city_rule : int, default 0
        With ``N > 0``, add the row :data:`PER_CITY_RULE`: per city, the column preset with
        the best mean score on ``N`` tuning episodes of that city (see the module docstring).
    compare : str or None
        A policy of ``policies`` (or :data:`PER_CITY_RULE`) to compare every other row with:
        paired score differences with 95 % bootstrap intervals, per city and over all cities
        (every city weighted equally).

    Returns
    -------
    SuiteReport

    Raises
    ------
    ValueError
        An unknown suite, no policy or seed, a seed below ``EVAL_SEED_START``, a duplicated
        policy, a ``compare`` that is not flown, a negative ``per_city_rule``, a trained
        policy whose run is of another environment than ``urban_canyon_v1``, or bad settings.
    """
    cities = list(suite_cities(suite))
    policies = list(policies)
    if not policies:
        raise ValueError("give at least one policy to fly on the suite")
    if len(set(policies)) != len(policies):
        raise ValueError(f"policy names must be unique, got {policies}")
    if PER_CITY_RULE in policies:
        raise ValueError(f"{PER_CITY_RULE!r} is the per-city rule's row, not a policy name")
    if not seeds:
        raise ValueError("give at least one evaluation seed")
    if min(seeds) < EVAL_SEED_START:
        raise ValueError(
            f"suite seeds must be >= {EVAL_SEED_START} (seeds below may have been seen in "
            f"training or tuning), got {min(seeds)}"
        )
    if int(per_city_rule) < 0:
        raise ValueError(f"per_city_rule must be >= 0 tuning episodes, got {per_city_rule}")
    rows = policies + ([PER_CITY_RULE] if per_city_rule else [])
    if compare is not None and compare not in rows:
        raise ValueError(f"compare must name a flown row ({', '.join(rows)}), got {compare!r}")
    groups: dict[str, tuple[dict[str, Any], list[str]]] = {}
    for name in policies:
        env_id, run_env = _run_settings(name)
        if env_id != DEFAULT_ENV_ID:
            raise ValueError(
                f"policy {name!r} was trained in {env_id}; the suite flies {DEFAULT_ENV_ID}"
            )
        replaced = [k for k in run_env if k.startswith("city_")]
        for key in ("city", "constellation", "systems", *replaced):
            run_env.pop(key, None)  # the suite's city and sky replace the run's
        key = json.dumps(jsonable(run_env), sort_keys=True)
        groups.setdefault(key, (run_env, []))[1].append(name)
    reports, n_buildings, picks, comparisons = {}, {}, {}, []
    for city in cities:
        report, n, pick = _city_report(
            city, groups, policies, seeds, dict(overrides or {}), verbose, int(per_city_rule)
        )
        reports[city.name], n_buildings[city.name] = report, n
        if pick is not None:
            picks[city.name] = pick
        if compare is not None:
            comparisons += _comparisons(city.name, report, compare)
    suite_rows = _suite_comparisons(reports, compare) if compare is not None else []
    result = SuiteReport(suite, cities, reports, n_buildings, picks, comparisons, suite_rows)
    if out is not None:
        out = Path(out)
        for city in cities:
            folder = out / city.name
            write_report(reports[city.name], folder)
            result.files.append(folder)
        write_json(out / "summary.json", result.to_dict())
        text = f"# Suite `{suite}`\n\n{result.header()}\n\n{result.to_markdown()}\n"
        atomic_write_text(out / "summary.md", text)
        result.files += [out / "summary.json", out / "summary.md"]
        if compare is not None:
            text = (
                f"# Suite `{suite}`: paired differences from `{compare}`\n\n"
                f"{result.comparison_markdown()}\n"
            )
            atomic_write_text(out / "comparison.md", text)
            result.files.append(out / "comparison.md")
    return result
