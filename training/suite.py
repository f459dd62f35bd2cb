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
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from coopnav_env.sim.real_suite import SuiteCity, suite_cities
from coopnav_env.training.envs import DEFAULT_ENV_ID
from coopnav_env.training.evaluate import PolicyStats, Report, evaluate, write_report
from coopnav_env.training.files import atomic_write_text, jsonable, write_json
from coopnav_env.training.run_configs import train_config_of_policies

__all__ = ["SUITE_COLUMNS", "SuiteReport", "evaluate_suite", "suite_outputs"]

SUITE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("score", "return_mean", "{:.3f}"),
    ("nav error mean [m]", "nav_error_mean_m", "{:.2f}"),
    ("coop mean [m]", "coop_error_mean_m", "{:.2f}"),
    ("goal rate", "goal_rate", "{:.3f}"),
    ("collisions", "collisions", "{:d}"),
    ("sats/UAV", "n_sats_mean", "{:.1f}"),
    ("steps", "length_mean", "{:.1f}"),
)
"""Columns of the summary table: (title, :class:`PolicyStats` field, format)."""


def suite_outputs(suite: str) -> tuple[str, ...]:
    """The entries ``coopnav evaluate --suite NAME --out DIR`` writes into ``DIR``."""
    return ("summary.md", "summary.json", *(c.name for c in suite_cities(suite)))


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
    n_buildings : dict of str to int
        Buildings flown in each city, by city name.
    files : list of Path
        What was written (empty when nothing was).
    """

    suite: str
    cities: list[SuiteCity]
    reports: dict[str, Report]
    n_buildings: dict[str, int]
    files: list[Path] = field(default_factory=list)

    def rows(self) -> list[tuple[SuiteCity, PolicyStats]]:
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
            f"`{c.name}`: {c.place}, {c.character} ({self.n_buildings[c.name]} buildings)"
            for c in self.cities
        )
        return (
            f"Suite `{self.suite}`, environment `{first.env_id}`: {places}. "
            f"{len(seeds)} held-out episodes per city and policy (reset seeds {span}). "
            "Score: the task's score (mean episode return); nav error: 3-D error of the estimate "
            "each UAV used; goal rate: episodes in which the whole swarm reached the goal area."
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (NaN written as null)."""
        return {
            "suite": self.suite,
            "cities": [asdict(c) | {"buildings": self.n_buildings[c.name]} for c in self.cities],
            "env_settings": {
                c.name: jsonable(self.reports[c.name].env_kwargs) for c in self.cities
            },
            "seeds": list(next(iter(self.reports.values())).seeds),
            "rows": [
                {"city": c.name, **jsonable({f: getattr(s, f) for _, f, _ in SUITE_COLUMNS})}
                | {"policy": s.policy, "episodes": s.episodes}
                for c, s in self.rows()
            ],
        }


def _fmt(value: Any, fmt: str) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return "n/a"
    return fmt.format(value)


def _run_settings(policy: str) -> tuple[str, dict[str, Any]]:
    """(env id, env settings) of the training run a trained policy came from ({} for others)."""
    found = train_config_of_policies([policy])
    return str(found.get("env_id") or DEFAULT_ENV_ID), dict(found.get("env") or {})


def _city_report(
    city: SuiteCity,
    groups: Mapping[str, tuple[dict[str, Any], list[str]]],
    policies: Sequence[str],
    seeds: Sequence[int],
    overrides: Mapping[str, Any],
    verbose: bool,
) -> tuple[Report, int]:
    """Evaluate every group of policies (same run settings) in ``city``: one report, and the
    number of buildings flown."""
    from coopnav_env.sim.file_city import load_file_city
    from coopnav_env.sim.osm_city import resolve_osm_path

    base = {**city.env_settings(), **overrides}
    reports = []
    for run_env, members in groups.values():
        kwargs = {**run_env, **base}
        if verbose:
            print(f"  {city.name}: {', '.join(members)}", file=sys.stderr)
        reports.append(evaluate(members, seeds, kwargs, env_id=DEFAULT_ENV_ID, verbose=verbose))
    stats = {s.policy: s for r in reports for s in r.stats}
    episodes = {k: v for r in reports for k, v in r.episodes.items()}
    own = {k: v for r in reports for k, v in r.own_frame.items()}
    n = load_file_city(  # as flown: --env-set may change the box or the default height
        f"osm:{resolve_osm_path(city.osm)}",
        bbox=base.get("city_bbox", city.bbox),
        default_height_m=base.get("city_default_height_m", city.default_height_m),
        warn=False,
    ).buildings.n
    trained = [
        f"{', '.join(m)} with the settings of its run ({json.dumps(jsonable(e))})"
        for e, m in groups.values()
        if e
    ]
    source = f"suite city {city.name}, {city.place}; {n} buildings"
    if trained:
        source += "; " + "; ".join(trained)
    report = Report(
        [stats[p] for p in policies],
        list(seeds),
        base,
        DEFAULT_ENV_ID,
        {p: episodes[p] for p in policies},
        env_source=source,
        own_frame=own,
    )
    return report, n


def evaluate_suite(
    policies: Sequence[str],
    seeds: Sequence[int],
    suite: str = "real",
    out: str | Path | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    verbose: bool = False,
) -> SuiteReport:
    """Fly ``policies`` on every city of ``suite``, the same reset seeds in each.

    Parameters
    ----------
    policies : sequence of str
        Policy names as for :func:`coopnav_env.training.evaluate.evaluate` (heuristics,
        ``mappo:pretrained/route_s0``, ...), unique.
    seeds : sequence of int
        Reset seeds, one episode per city and policy.
    suite : str, default "real"
        A key of :data:`coopnav_env.sim.real_suite.SUITES`.
    out : path or None
        Folder for ``summary.md``, ``summary.json`` and one report folder per city (no plots);
        None writes nothing.
    overrides : mapping, optional
        Environment settings applied last in every city (``--env-set``).
    verbose : bool, default False
        Print progress per city and policy on stderr.

    Returns
    -------
    SuiteReport

    Raises
    ------
    ValueError
        An unknown suite, no policy or seed, a duplicated policy, a trained policy whose run
        is of another environment than ``urban_canyon_v1``, or bad settings.
    """
    cities = list(suite_cities(suite))
    policies = list(policies)
    if not policies:
        raise ValueError("give at least one policy to fly on the suite")
    if len(set(policies)) != len(policies):
        raise ValueError(f"policy names must be unique, got {policies}")
    if not seeds:
        raise ValueError("give at least one evaluation seed")
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
    reports, n_buildings = {}, {}
    for city in cities:
        reports[city.name], n_buildings[city.name] = _city_report(
            city, groups, policies, seeds, dict(overrides or {}), verbose
        )
    result = SuiteReport(suite, cities, reports, n_buildings)
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
    return result
