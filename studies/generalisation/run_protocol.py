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

A policy ``masac:FOLDER`` is a MASAC actor saved by ``studies/off_policy/train_masac.py``
(``FOLDER`` holds ``actor.pt`` and ``actor.json``; it needs BenchMARL's venv, the
``benchmarl`` extra). Its row is named after the folder (``masac_`` added unless the name
starts with it). The actor is flown, with torch on one thread, in the environment settings
of its run except the city and the reward-only team credit (``nav_team_weight``: it moves
reward between UAVs, not what they see or do, and every row is scored without it). A policy
given by name carries no run of its own, so every row of that protocol is flown with those
settings (the suite's overrides): the rules fly as without them (the index only adds
observation entries, the rules command velocities). The MASAC actors of one protocol must
share their settings, and no other trained policy may be flown beside them.

Usage::

    python studies/generalisation/run_protocol.py --episodes 50 --tune 20
"""

from __future__ import annotations

import argparse
import contextlib
import math
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

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


MASAC_PREFIX = "masac:"
NOT_FLOWN_WITH = ("city", "constellation", "systems", "nav_team_weight")
"""Settings of a MASAC run that its actor is not flown with: the suite's city and sky replace
these and every ``city_*`` key; team credit changes only how reward is shared."""


def masac_row_name(spec: str) -> str:
    """The row name of ``masac:FOLDER``: the folder's name as an identifier, ``masac_`` added
    unless it starts with it."""
    folder = Path(spec[len(MASAC_PREFIX) :])
    name = "".join(c if c.isalnum() else "_" for c in folder.name)
    return name if name.startswith("masac") else f"masac_{name}"


@contextlib.contextmanager
def masac_policies(specs: Sequence[str]) -> Iterator[tuple[list[str], dict[str, Any]]]:
    """Register every ``masac:FOLDER`` of ``specs`` as a policy; yields the policy names in
    order (others unchanged) and the environment settings the actors share (their runs'
    settings without the city keys; empty without MASAC), with torch on one thread.

    ``ValueError`` for a folder that is not a saved actor, actors of different settings, two
    folders of one name, or a MASAC actor beside another trained policy (``kind:PATH``).
    """
    from coopnav_env.agents import register_policy

    masac = [p for p in specs if p.startswith(MASAC_PREFIX)]
    if not masac:
        yield list(specs), {}
        return
    others = [p for p in specs if ":" in p and not p.startswith(MASAC_PREFIX)]
    if others:
        raise ValueError(
            f"MASAC actors are flown with their own settings for every row; fly {others} "
            "in a protocol of their own"
        )
    names = [masac_row_name(p) if p in masac else p for p in specs]
    if len(set(names)) != len(names):
        raise ValueError(f"two policies would share a row name: {names}")
    from studies.off_policy.masac import MasacPolicy, load_actor
    from studies.task_objective.compare_learned import one_torch_thread

    shared: dict[str, Any] | None = None
    with tempfile.TemporaryDirectory() as scratch, one_torch_thread():
        for spec, name in zip(specs, names):
            if spec not in masac:
                continue
            module, settings = load_actor(Path(spec[len(MASAC_PREFIX) :]), Path(scratch) / name)
            env = {
                k: v
                for k, v in settings.env.items()
                if k not in NOT_FLOWN_WITH and not k.startswith("city_")
            }
            if shared is not None and env != shared:
                raise ValueError(f"{spec} was trained with {env}, the other actors with {shared}")
            shared = env

            def factory(env_: Any, _m=module, _h=settings.hold, _n=name) -> MasacPolicy:
                return MasacPolicy(_m, env_.possible_agents, _h, _n)

            register_policy(name, factory, overwrite=True)
        yield names, dict(shared or {})


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    if (out / "report.md").exists() and not args.overwrite:
        print(f"{out / 'report.md'} exists: pass --overwrite to replace it", file=sys.stderr)
        return 2
    with contextlib.ExitStack() as stack:
        try:
            policies, overrides = stack.enter_context(masac_policies(args.policies))
        except ValueError as exc:  # refused before any episode is flown
            print(f"run_protocol: {exc}", file=sys.stderr)
            return 2
        return run(args, out, policies, overrides, argv)


def run(
    args: argparse.Namespace,
    out: Path,
    policies: list[str],
    overrides: dict[str, Any],
    argv: list[str] | None,
) -> int:
    """Fly the protocol of ``args`` (policies by their row names, every row with the
    environment settings ``overrides``) and write ``out/report.md``."""
    seeds = heldout_seeds(args.episodes, args.seed_start)
    parts, timing = [], []
    for suite in args.parts:
        t0 = time.perf_counter()
        if (out / suite).exists():
            shutil.rmtree(out / suite)
        result = evaluate_suite(
            policies,
            seeds,
            suite,
            out / suite,
            overrides=overrides,
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
    flown_with = (
        f" Every row flown with the MASAC actors' settings {overrides}." if overrides else ""
    )
    text = (
        "# Generalisation protocol\n\n"
        f"Regenerate: `{command}`. Held-out reset seeds {seeds[0]}..{seeds[-1]}; "
        f"wall time: {walls}.{flown_with}\n\n" + "\n\n".join(parts) + "\n"
    )
    atomic_write_text(out / "report.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
