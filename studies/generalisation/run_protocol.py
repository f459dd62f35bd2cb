"""The generalisation protocol: policies flown on held-out grids, generated families and real
cities, beside the rules tuned on grids and a rule re-tuned per city.

Three test sets, never trained on (reset seeds from ``--seed-start``, at least
``coopnav_env.training.envs.EVAL_SEED_START``; training and tuning use the seeds below), each a
suite of ``coopnav evaluate --suite`` (:mod:`coopnav_env.training.suite`):

1. ``grid``: the environment's own random street grids under the nominal GPS + BeiDou sky;
2. ``families``: a new generated city of each family every episode
   (:mod:`coopnav_env.sim.city_families`);
3. ``real``: three real OpenStreetMap places under a real GPS sky
   (:mod:`coopnav_env.sim.real_suite`).

Every city also gets ``per_city_column`` (the column preset with the best mean score on
``--tune`` tuning episodes of that city) and every row its paired score difference from
``--compare`` (the best rule as tuned on grids) with a 95 % bootstrap interval, and its share
of the gap from ``--baseline`` (the plain column) to ``per_city_column`` in that city.
Writes ``report.md`` and each suite's reports into ``--out``; refuses a folder that holds a
finished protocol unless ``--overwrite``.

Usage::

    python studies/generalisation/run_protocol.py --episodes 50 --tune 20
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from coopnav_env.training.envs import EVAL_SEED_START, heldout_seeds
from coopnav_env.training.files import atomic_write_text
from coopnav_env.training.stats import gap_closed
from coopnav_env.training.suite import PER_CITY_RULE, SuiteReport, evaluate_suite

MIN_GAP = 0.01
"""A city's gap from the baseline to its re-tuned rule below this (score units) is too small
for a share of it to mean anything: reported as n/a with its size."""

SUITE_TITLES = {
    "grid": "Held-out street grids",
    "families": "Generated families, held-out cities",
    "real": "Real cities, real sky",
}

HERE = Path(__file__).resolve().parent

POLICIES = (
    "column",
    "high_wide_column",
    "mappo:pretrained/v1_s0",
    "mappo:pretrained/route_s0",
)
"""Flown by default: the plain and the grid-re-tuned column, and the shipped learned policies
of the velocity frame and of the route frame."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description="Fly policies on held-out grids, generated families and real cities "
        "beside grid-tuned and per-city re-tuned rules; write report.md.",
    )
    ap.add_argument(
        "--policies",
        nargs="+",
        default=list(POLICIES),
        help=f"policies to fly (default: {' '.join(POLICIES)})",
    )
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes per city (50)")
    ap.add_argument(
        "--seed-start",
        type=int,
        default=EVAL_SEED_START + 200,
        help=f"first held-out reset seed, >= {EVAL_SEED_START} ({EVAL_SEED_START + 200})",
    )
    ap.add_argument(
        "--tune", type=int, default=20, help="tuning episodes of the per-city rule (20)"
    )
    ap.add_argument(
        "--compare",
        default="high_wide_column",
        help="the reference of the paired differences: the best rule as tuned on grids "
        "(high_wide_column)",
    )
    ap.add_argument(
        "--baseline",
        default="column",
        help="the gap's 0 in every city (column); its 1 is the city's per_city_column",
    )
    ap.add_argument(
        "--parts",
        nargs="+",
        choices=tuple(SUITE_TITLES),
        default=list(SUITE_TITLES),
        help="which suites to fly (all three: grid families real)",
    )
    ap.add_argument("--out", default=str(HERE / "protocol"), help="output folder")
    ap.add_argument("--overwrite", action="store_true", help="replace a finished protocol in --out")
    args = ap.parse_args(argv)
    for flag, name in (("--compare", args.compare), ("--baseline", args.baseline)):
        if name not in args.policies:
            ap.error(f"{flag} {name!r} must be one of --policies")
    if args.episodes < 1 or args.tune < 1:
        ap.error("--episodes and --tune must be >= 1")
    return args


def gap_markdown(result: SuiteReport, baseline: str) -> str:
    """Every row's share of the gap from ``baseline`` to ``per_city_column`` per city, with a
    paired 95 % bootstrap interval (n/a where the gap is below :data:`MIN_GAP`)."""
    lines = [
        f"| city | policy | gap closed ({baseline} = 0, {PER_CITY_RULE} = 1) [95 % CI] |",
        "|---|---|---|",
    ]
    for name, report in result.reports.items():
        scores = {
            p: np.array([e.episode_return for e in eps]) for p, eps in report.episodes.items()
        }
        for p in scores:
            if p in (baseline, PER_CITY_RULE):
                continue
            gap = float(scores[PER_CITY_RULE].mean() - scores[baseline].mean())
            if abs(gap) < MIN_GAP or math.isnan(float(scores[p].mean())):
                cell = f"n/a (gap {gap:+.3f})"
            else:
                g = gap_closed(scores[p], scores[baseline], scores[PER_CITY_RULE])
                cell = f"{g.value:.2f} [{g.low:.2f}, {g.high:.2f}]"
            lines.append(f"| {name} | {p} | {cell} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    if (out / "report.md").exists() and not args.overwrite:
        print(f"{out / 'report.md'} exists: pass --overwrite to replace it", file=sys.stderr)
        return 2
    seeds = heldout_seeds(args.episodes, args.seed_start)
    parts, timing = [], []
    for suite in args.parts:
        t0 = time.perf_counter()
        if (out / suite).exists():
            shutil.rmtree(out / suite)
        result = evaluate_suite(
            args.policies,
            seeds,
            suite,
            out / suite,
            verbose=True,
            per_city_rule=args.tune,
            compare=args.compare,
        )
        timing.append((suite, time.perf_counter() - t0))
        parts.append(
            f"## {SUITE_TITLES[suite]} (`--suite {suite}`)\n\n{result.header()}\n\n"
            f"{result.to_markdown()}\n\nPaired differences from `{args.compare}`:\n\n"
            f"{result.comparison_markdown()}\n\n{gap_markdown(result, args.baseline)}"
        )
    given = argv if argv is not None else sys.argv[1:]
    command = " ".join(["python studies/generalisation/run_protocol.py", *given])
    walls = ", ".join(f"{name} {s / 60:.1f} min" for name, s in timing)
    text = (
        "# Generalisation protocol\n\n"
        f"Regenerate: `{command}`. Held-out reset seeds {seeds[0]}..{seeds[-1]}; "
        f"wall time: {walls}.\n\n" + "\n\n".join(parts) + "\n"
    )
    atomic_write_text(out / "report.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
