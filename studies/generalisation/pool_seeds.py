"""Pool a method's training seeds in protocol reports and compare it with a rule, per city.

Reads the per-episode records (``report.json``) of one or more folders written by
``run_protocol.py`` (each holding ``grid/``, ``families/`` and ``real/`` suites of city
folders), takes every policy whose name starts with ``--method-prefix`` as one training seed of
the method, and writes, per city, the method's mean score, goal rate and cruise spacing, its
paired score difference from ``--reference`` (a rule, or with a trailing ``*`` another
method's seeds, pooled the same way) with a 95 % bootstrap interval over episodes and
seeds (:func:`coopnav_env.training.stats.paired_difference`: runs averaged per episode), and
its share of the gap from ``--baseline`` to ``--reference``. After the cities of a suite with
at least two cities, one row ``SUITE: all cities (equal weight)`` gives the same over the whole
suite, every city weighted equally: the mean of the cities' mean scores, goal rates and
spacings, and the mean of their paired differences with an interval that resamples episodes
within each city and the seeds once for all cities
(:func:`coopnav_env.training.stats.suite_paired_difference`; no gap share). The reference's
episodes must be the same in every folder (the same seeds, bit-identical returns), else it
stops.

Usage::

    python studies/generalisation/pool_seeds.py \\
        studies/generalisation/trained_on_families/protocol \\
        studies/generalisation/trained_on_families/protocol_s2 \\
        --out studies/generalisation/trained_on_families/pooled.md
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from coopnav_env.training.files import atomic_write_text
from coopnav_env.training.stats import gap_closed, paired_difference, suite_paired_difference
from coopnav_env.training.suite import ALL_CITIES

SUITES = ("grid", "families", "real")


def _episodes(folders: list[Path]) -> dict[str, dict[str, dict[str, list[dict]]]]:
    """``suite -> city -> policy -> episodes`` over every folder (a policy met twice must
    agree in every field both records have), suites in :data:`SUITES` order."""
    out: dict[str, dict[str, dict[str, list[dict]]]] = {}
    for folder in folders:
        for suite in SUITES:
            for report in sorted((folder / suite).glob("*/report.json")):
                city = report.parent.name
                data = json.loads(report.read_text())
                per_city = out.setdefault(suite, {}).setdefault(city, {})
                for policy, eps in data["episodes"].items():
                    if policy in per_city and not _same_episodes(per_city[policy], eps):
                        raise ValueError(
                            f"{report}: the episodes of {policy!r} differ from those of "
                            "another folder: the reports are not of the same protocol"
                        )
                    per_city[policy] = eps
    if not out:
        raise ValueError(f"no report.json under {', '.join(map(str, folders))}")
    return {suite: out[suite] for suite in SUITES if suite in out}


def _same_episodes(a: list[dict], b: list[dict]) -> bool:
    """Whether two reports' records of one policy are the same episodes: equal in every field
    both have (a report written before a field was added lacks it)."""
    return len(a) == len(b) and all(
        all(x[k] == y[k] for k in x.keys() & y.keys()) for x, y in zip(a, b, strict=True)
    )


def _scores(eps: list[dict], key: str = "return") -> np.ndarray:
    return np.array([float(e[key]) for e in eps])


def pooled_table(
    folders: list[Path], prefix: str, reference: str, baseline: str
) -> tuple[str, int]:
    """The markdown table of the pooled method per city (and over every suite of two or more
    cities, each weighted equally), and the number of seeds pooled."""
    rows = [
        f"| city | seeds | score | score - {reference} [95 % CI] | excludes 0 | goal rate | "
        f"{reference} goal rate | cruise spacing [m] | gap closed ({baseline} = 0, "
        f"{reference} = 1) |",
        "|---|---:|---:|---|---|---:|---:|---:|---|",
    ]
    n_seeds = 0
    for suite, cities in _episodes(folders).items():
        pooled = []
        for city, policies in cities.items():
            row = _city_row(city, policies, prefix, reference, baseline)
            if row is not None:
                rows.append(row[0])
                pooled.append(row[1])
        n_seeds = max([n_seeds, *(len(p.runs) for p in pooled)])
        if len(pooled) >= 2:
            rows.append(_suite_row(suite, pooled))
    return "\n".join(rows), n_seeds


@dataclass(frozen=True)
class _Pooled:
    """One city's pooled figures: the method's seeds, score matrices and means."""

    city: str
    runs: tuple[str, ...]
    method: np.ndarray  # (runs, episodes)
    reference: np.ndarray  # (reference runs, episodes)
    goal: float
    reference_goal: float
    spacing: float


def _suite_row(suite: str, pooled: list[_Pooled]) -> str:
    """The row over every city of ``suite``, each weighted equally."""
    runs = pooled[0].runs
    for p in pooled:
        if p.runs != runs:
            raise ValueError(
                f"{suite}: {p.city} pools the seeds {list(p.runs)} and {pooled[0].city} "
                f"{list(runs)}: a suite row needs the same seeds in every city"
            )
    diff = suite_paired_difference([p.method for p in pooled], [p.reference for p in pooled])
    sign = "above" if diff.low > 0 else "below" if diff.high < 0 else "no"
    score = np.mean([p.method.mean() for p in pooled])
    goal = np.mean([p.goal for p in pooled])
    ref_goal = np.mean([p.reference_goal for p in pooled])
    spacing = np.mean([p.spacing for p in pooled])
    return (
        f"| {suite}: {ALL_CITIES} | {len(runs)} | {score:.3f} | {diff.value:+.3f} "
        f"[{diff.low:+.3f}, {diff.high:+.3f}] | {sign} | {goal:.2f} | {ref_goal:.2f} | "
        f"{spacing:.1f} | n/a |"
    )


def _reference_runs(policies: dict[str, list[dict]], reference: str) -> list[str]:
    """The reference's policies: ``reference`` itself, or with a trailing ``*`` every policy
    whose name starts with the text before it (another method's training seeds)."""
    if reference.endswith("*"):
        return sorted(p for p in policies if p.startswith(reference[:-1]))
    return [reference] if reference in policies else []


def _city_row(
    city: str, policies: dict[str, list[dict]], prefix: str, reference: str, baseline: str
) -> tuple[str, _Pooled] | None:
    """The table row of one city and its pooled figures (None without the method or the
    reference)."""
    runs = sorted(p for p in policies if p.startswith(prefix))
    refs = _reference_runs(policies, reference)
    if not runs or not refs:
        return None
    seeds = [e["seed"] for e in policies[refs[0]]]
    for p in (*runs, *refs):
        if [e["seed"] for e in policies[p]] != seeds:
            raise ValueError(f"{city}: {p!r} flew other episodes than {refs[0]!r}")
    method = np.stack([_scores(policies[p]) for p in runs])
    ref = np.stack([_scores(policies[p]) for p in refs])
    diff, _ = paired_difference(method, ref)
    goal = np.mean([[e["success"] for e in policies[p]] for p in runs])
    ref_goal = np.mean([[e["success"] for e in policies[p]] for p in refs])
    spacing = np.nanmean([[e["cruise_spacing_m"] for e in policies[p]] for p in runs])
    gap = "n/a"
    if baseline in policies:
        base = _scores(policies[baseline])
        size = float(ref.mean() - base.mean())
        if abs(size) >= 0.01:
            g = gap_closed(method, base, ref.mean(axis=0))
            gap = f"{g.value:.2f} [{g.low:.2f}, {g.high:.2f}]"
        else:
            gap = f"n/a (gap {size:+.3f})"
    sign = "above" if diff.low > 0 else "below" if diff.high < 0 else "no"
    row = (
        f"| {city} | {len(runs)} | {method.mean():.3f} | {diff.value:+.3f} "
        f"[{diff.low:+.3f}, {diff.high:+.3f}] | {sign} | {goal:.2f} | {ref_goal:.2f} | "
        f"{spacing:.1f} | {gap} |"
    )
    pooled = _Pooled(city, tuple(runs), method, ref, float(goal), float(ref_goal), float(spacing))
    return row, pooled


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description="Pool a method's training seeds in generalisation protocol reports and "
        "compare it with a rule per city (paired 95 %% bootstrap intervals); write markdown."
    )
    ap.add_argument("folders", nargs="+", help="protocol output folders (run_protocol.py --out)")
    ap.add_argument(
        "--method-prefix",
        default="mappo:pretrained/families_scratch_s",
        help="policies whose names start with this are the method's seeds "
        "(mappo:pretrained/families_scratch_s)",
    )
    ap.add_argument(
        "--reference",
        default="high_wide_column",
        help="the policy compared against (high_wide_column); with a trailing '*', every "
        "policy whose name starts with the text before it, pooled as one method's seeds",
    )
    ap.add_argument("--baseline", default="column", help="the gap's 0 (column)")
    ap.add_argument("--out", help="markdown file to write (default: print only)")
    args = ap.parse_args(argv)
    table, n = pooled_table(
        [Path(f) for f in args.folders], args.method_prefix, args.reference, args.baseline
    )
    if n == 0:
        ap.error(f"no policy named {args.method_prefix}* beside {args.reference} in the reports")
    given = argv if argv is not None else sys.argv[1:]
    text = (
        f"# `{args.method_prefix}*` pooled over {n} training seeds\n\n"
        f"Regenerate: `python studies/generalisation/pool_seeds.py {' '.join(given)}`\n\n"
        f"{table}\n"
    )
    if args.out:
        atomic_write_text(Path(args.out), text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
