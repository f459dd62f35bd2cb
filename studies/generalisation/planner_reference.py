"""The privileged planner as a reference of the generalisation protocol, on a suite's cities.

Flies the base rule (``--base``, the protocol's grid-tuned rule ``high_wide_column``) and the
privileged planner over it (``planner@base=BASE``, :mod:`studies.planner_headroom.planner`,
with ``--planner-set`` options) through the first ``--episodes`` held-out episodes of the
protocol (reset seeds from ``--seed-start``) on every city of ``--suite``, with
:func:`coopnav_env.training.suite.evaluate_suite`. The planner is slow (tenths of a second per
step), so it flies fewer episodes than the protocol's other rows; to put it beside them on the
same episodes, every row of the protocol's report of that city (``--protocol``, written by
``run_protocol.py``) is paired with the base on the episodes both flew: score minus the base's
with a paired 95 % bootstrap interval (:func:`coopnav_env.training.stats.paired_difference`)
and the goal rate. The base's scores here must equal the protocol's on the same seeds (the
same episodes); a mismatch is an error.

Writes the suite's reports (one folder per city, ``summary.md``, ``comparison.md``) and
``report.md`` into ``--out``.

Usage::

    python studies/generalisation/planner_reference.py --episodes 20 \\
        --planner-set objective='return'
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

HERE = Path(__file__).resolve().parent


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    from coopnav_env.training.envs import EVAL_SEED_START

    ap = argparse.ArgumentParser(
        description="Fly the privileged planner over the grid-tuned rule on a suite's cities, "
        "paired with the generalisation protocol's rows on the same episodes.",
    )
    ap.add_argument("--suite", default="real", help="suite of cities (real)")
    ap.add_argument("--episodes", type=int, default=20, help="held-out episodes per city (20)")
    ap.add_argument(
        "--seed-start",
        type=int,
        default=EVAL_SEED_START + 200,
        help=f"first held-out reset seed, the protocol's ({EVAL_SEED_START + 200})",
    )
    ap.add_argument(
        "--base", default="high_wide_column", help="the planner's base rule (high_wide_column)"
    )
    ap.add_argument(
        "--planner-set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="planner options (studies.planner_headroom.planner.PrivilegedPlanner), "
        "e.g. objective='return'",
    )
    ap.add_argument(
        "--protocol",
        default=str(HERE / "protocol"),
        help="the protocol's output folder, whose rows are paired with the base (protocol/)",
    )
    ap.add_argument("--out", default=str(HERE / "planner_real"), help="output folder")
    args = ap.parse_args(argv)
    if args.episodes < 2:
        ap.error(f"--episodes must be >= 2 for a paired interval, got {args.episodes}")
    for item in args.planner_set:
        if "=" not in item:
            ap.error(f"--planner-set takes KEY=VALUE, got {item!r}")
    return args


def planner_name(base: str, planner_set: list[str]) -> str:
    """The policy name of the planner over ``base`` with the options ``planner_set``."""
    return ",".join([f"planner@base={base!r}", *planner_set])


def episode_scores(report: dict, policy: str) -> dict[int, tuple[float, bool]]:
    """``{seed: (score, reached the goal)}`` of ``policy`` in a ``report.json`` dict."""
    return {
        int(e["seed"]): (float(e["return"]), bool(e["success"])) for e in report["episodes"][policy]
    }


def paired_rows(
    ours: dict, protocol: dict | None, base: str, seeds: list[int]
) -> list[tuple[str, float, float, float, float, float]]:
    """Every row of ``ours`` and ``protocol`` (two ``report.json`` dicts of one city) but the
    base, against the base's scores on ``seeds``: ``(policy, mean difference, low, high, goal
    rate, base goal rate)``.

    Raises
    ------
    ValueError
        The protocol lacks one of ``seeds``, or its base scored otherwise on one (then the two
        did not fly the same episodes).
    """
    from coopnav_env.training.stats import paired_difference

    ref = episode_scores(ours, base)
    rows: dict[str, dict[int, tuple[float, bool]]] = {
        p: episode_scores(ours, p) for p in ours["episodes"] if p != base
    }
    if protocol is not None:
        theirs = episode_scores(protocol, base)
        missing = [s for s in seeds if s not in theirs]
        if missing:
            raise ValueError(
                f"the protocol's report lacks seeds {missing[:5]}: fly at most as many "
                "episodes as the protocol did, from its --seed-start"
            )
        off = [s for s in seeds if theirs[s][0] != ref[s][0]]
        if off:
            raise ValueError(
                f"{base} scored otherwise here than in the protocol on seeds {off[:5]}: not "
                "the same episodes (other settings or code?)"
            )
        for p in protocol["episodes"]:
            if p != base and p not in rows:
                rows[p] = episode_scores(protocol, p)
    b = np.array([[ref[s][0] for s in seeds]])
    b_goal = float(np.mean([ref[s][1] for s in seeds]))
    out = []
    for p, eps in rows.items():
        a = np.array([[eps[s][0] for s in seeds]])
        diff, _ = paired_difference(a, b)
        goal = float(np.mean([eps[s][1] for s in seeds]))
        out.append((p, diff.value, diff.low, diff.high, goal, b_goal))
    return out


def main(argv: list[str] | None = None) -> int:
    import studies.planner_headroom.planner  # noqa: F401  (registers 'planner')
    from coopnav_env.training.envs import heldout_seeds
    from coopnav_env.training.files import atomic_write_text
    from coopnav_env.training.suite import evaluate_suite

    args = parse_args(argv)
    seeds = heldout_seeds(args.episodes, args.seed_start)
    planner = planner_name(args.base, args.planner_set)
    out = Path(args.out)
    t0 = time.perf_counter()
    result = evaluate_suite(
        [args.base, planner], seeds, args.suite, out, verbose=True, compare=args.base
    )
    wall = time.perf_counter() - t0
    lines = [
        f"| city | `{args.base}` score (goal) | policy | score - `{args.base}` [95 % CI] | "
        f"goal | planner s/step |",
        "|---|---:|---|---|---:|---:|",
    ]
    for city, report in result.reports.items():
        ours = json.loads((out / city / "report.json").read_text())
        pfile = Path(args.protocol) / args.suite / city / "report.json"
        protocol = json.loads(pfile.read_text()) if pfile.exists() else None
        stats = {s.policy: s for s in report.stats}
        base_stats, p_stats = stats[args.base], stats[planner]
        per_step = p_stats.wall_s / max(1, p_stats.length_mean * len(seeds))
        for i, (p, d, lo, hi, goal, b_goal) in enumerate(
            paired_rows(ours, protocol, args.base, seeds)
        ):
            head = (
                f"| {city} | {base_stats.return_mean:.3f} ({b_goal:.2f}) |" if i == 0 else "| | |"
            )
            name = "privileged planner" if p == planner else f"`{p}`"
            step = f"{per_step:.2f}" if p == planner else ""
            lines.append(f"{head} {name} | {d:+.3f} [{lo:+.3f}, {hi:+.3f}] | {goal:.2f} | {step} |")
    given = argv if argv is not None else sys.argv[1:]
    command = " ".join(["python studies/generalisation/planner_reference.py", *given])
    text = (
        "# The privileged planner on the generalisation protocol's episodes\n\n"
        f"Regenerate: `{command}`. Suite `{args.suite}`; planner `{planner}`; "
        f"{len(seeds)} held-out episodes per city (reset seeds {seeds[0]}..{seeds[-1]}), the "
        f"protocol's first. Every row paired with `{args.base}` on these episodes (the other "
        f"rows from the protocol's reports in `{Path(args.protocol).name}/`); 95 % paired "
        f"bootstrap intervals. Wall time {wall / 60:.1f} min.\n\n" + "\n".join(lines) + "\n"
    )
    atomic_write_text(out / "report.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
