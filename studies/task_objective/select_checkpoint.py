"""Pick each training run's checkpoint by its score on validation episodes.

A PPO run's return can wander between checkpoints, so that its last checkpoint is one draw
from that wander. This script flies every checkpoint of each run from ``--from-steps`` on
(and the run's final model) on *validation* episodes of ``urban_canyon_v1`` (reset seeds
``--seed-start`` on, by default 1,001,000 on: disjoint from the training seeds, below
1,000,000, and from the held-out test episodes of the studies, 1,000,100-1,000,199), and
keeps, per run, the checkpoint with the highest mean score. With ``--export DIR`` the kept
checkpoints are exported as policies ``DIR/<run folder name>``
(:func:`coopnav_env.training.torchrl_backend.export_policy`), to be compared on the test
episodes by ``compare_learned.py``.

Example::

    python studies/task_objective/select_checkpoint.py \\
        --runs runs/scratch16m_s0 runs/scratch16m_s1 runs/scratch16m_s2 \\
        --from-steps 8000000 --episodes 50 --out studies/task_objective/checkpoint_selection \\
        --export studies/task_objective/policies --algorithm mappo
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from studies.task_objective.compare_learned import (
    add_report_arguments,
    fly,
    report_folder,
    write_report,
)

VALIDATION_SEED_START = 1_001_000
"""First reset seed of the validation episodes (see the module docstring)."""

_STEPS = re.compile(r"marl_(\d+)_steps\.pt$")


def candidates(run: Path, from_steps: int) -> list[tuple[int, Path]]:
    """``(agent-steps, checkpoint)`` of ``run``'s ``checkpoints/marl_<N>_steps.pt`` with
    ``N >= from_steps``, and its ``final_model.pt`` (at the agent-steps its ``run.json``
    records, when that is ``>= from_steps`` and no checkpoint has the same count), in order
    of steps. Raises ``FileNotFoundError`` when there is none."""
    import json

    out = []
    for p in (run / "checkpoints").glob("marl_*_steps.pt"):
        m = _STEPS.search(p.name)
        if m and int(m.group(1)) >= from_steps:
            out.append((int(m.group(1)), p))
    final = run / "final_model.pt"
    if final.exists():
        steps = int(json.loads((run / "run.json").read_text())["num_timesteps"])
        if steps >= from_steps and steps not in {s for s, _ in out}:
            out.append((steps, final))
    if not out:
        raise FileNotFoundError(f"{run}: no checkpoint at or after {from_steps} agent-steps")
    return sorted(out)


def run_folders(parser: argparse.ArgumentParser, names: Sequence[str]) -> list[Path]:
    """``names`` (the ``--runs`` option) as folders; ``parser.error`` (exit 2) naming the first
    that is not one."""
    runs = [Path(r) for r in names]
    for r in runs:
        if not r.is_dir():
            parser.error(f"--runs: {r} is not a run folder")
    return runs


def select(
    runs: Sequence[Path], algorithm: str, from_steps: int, seeds: Sequence[int]
) -> dict[str, Any]:
    """Fly every candidate (:func:`candidates`) of every run on ``seeds`` and keep the one
    with the highest mean score per run (the earliest of equals)."""
    from tqdm.auto import tqdm

    report: dict[str, Any] = {
        "environment": "urban_canyon_v1",
        "algorithm": algorithm,
        "validation_seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "from_steps": from_steps,
        "runs": [],
    }
    for run in runs:
        rows = []
        for steps, path in tqdm(candidates(run, from_steps), desc=run.name):
            flown = fly(f"{algorithm}:{path}", seeds)
            scores = np.array([e["score"] for e in flown])
            rows.append(
                {
                    "steps": steps,
                    "checkpoint": str(path),
                    "score": float(scores.mean()),
                    "score_se": float(scores.std(ddof=1) / np.sqrt(len(scores))),
                    "goal": float(np.mean([e["goal"] for e in flown])),
                    "cruise_spacing_m": float(np.mean([e["cruise_spacing_m"] for e in flown])),
                }
            )
        best = max(range(len(rows)), key=lambda i: (rows[i]["score"], -i))
        report["runs"].append({"run": str(run), "chosen": rows[best], "candidates": rows})
    return report


def to_markdown(report: Mapping[str, Any]) -> str:
    """The report as Markdown: the chosen checkpoint per run, then every candidate."""
    lo, hi = report["validation_seeds"]
    lines = [
        f"{report['algorithm'].upper()} checkpoints from {report['from_steps']:,} agent-steps on, "
        f"flown on {report['episodes']} validation episodes of urban_canyon_v1 (reset seeds "
        f"{lo}-{hi}); the checkpoint of the highest mean score is kept per run.",
        "",
        "| run | chosen (agent-steps) | validation score | goal | cruise spacing [m] "
        "| last checkpoint's score |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in report["runs"]:
        c, last = r["chosen"], r["candidates"][-1]
        lines.append(
            f"| {Path(r['run']).name} | {c['steps']:,} | {c['score']:.3f} +- {c['score_se']:.3f} "
            f"| {c['goal']:.2f} | {c['cruise_spacing_m']:.1f} | {last['score']:.3f} |"
        )
    for r in report["runs"]:
        head = "| agent-steps | score | goal | cruise spacing [m] |"
        lines += ["", f"## {Path(r['run']).name}", "", head]
        lines.append("|---:|---:|---:|---:|")
        for c in r["candidates"]:
            lines.append(
                f"| {c['steps']:,} | {c['score']:.3f} +- {c['score_se']:.3f} | {c['goal']:.2f} "
                f"| {c['cruise_spacing_m']:.1f} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", nargs="+", required=True, help="TorchRL run folders")
    p.add_argument("--algorithm", choices=("mappo", "ippo"), default="mappo")
    p.add_argument(
        "--from-steps", type=int, default=0, help="first agent-step count considered (default 0)"
    )
    p.add_argument("--episodes", type=int, default=50, help="validation episodes (default 50)")
    p.add_argument(
        "--seed-start",
        type=int,
        default=VALIDATION_SEED_START,
        help=f"first validation reset seed (default {VALIDATION_SEED_START})",
    )
    p.add_argument("--export", help="export each kept checkpoint as DIR/<run folder name>")
    add_report_arguments(p)
    args = p.parse_args(argv)
    if args.episodes < 2:
        p.error(f"--episodes must be at least 2, got {args.episodes}")
    runs = run_folders(p, args.runs)
    out = report_folder(p, args)
    if args.export and not args.overwrite:
        taken = [str(d) for r in runs if (d := Path(args.export) / r.name).exists()]
        if taken:
            p.error(f"--export: {', '.join(taken)} exist already; pass --overwrite to replace them")
    seeds = list(range(args.seed_start, args.seed_start + args.episodes))
    report = select(runs, args.algorithm, args.from_steps, seeds)
    if args.export:
        from coopnav_env.training.torchrl_backend import export_policy

        dests = [Path(args.export) / Path(r["run"]).name for r in report["runs"]]
        for r, dest in zip(report["runs"], dests):
            r["exported"] = str(export_policy(r["chosen"]["checkpoint"], dest))
    write_report(out, "Checkpoints chosen on validation episodes", report, to_markdown(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
