"""Where each learned policy loses the gap to the reference: failed episodes or flown ones.

Reads reports of ``compare_learned.py`` (their ``report.json``, which keep every policy's
per-episode figures) and splits, for each learned policy, the share of the ``baseline`` ->
``reference`` gap it leaves open into what it loses on the episodes it fails (goal not
reached) and what it loses on the episodes it completes, both against the reference on the
same episodes. On the completed episodes it gives the figures that separate the policies:
navigation error, steps, cruise spacing and cruise altitude, beside the reference's on those
episodes. Nothing is flown.

Example::

    python studies/task_objective/seed_spread.py --report \\
        studies/task_objective/learned_route_hold/report.json \\
        studies/task_objective/learned_route_scratch_16m_valsel/report.json \\
        --out studies/task_objective/seed_spread
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from studies.task_objective.compare_learned import write_report

FIGURES = ("nav_error_m", "steps", "cruise_spacing_m", "cruise_altitude_m")
"""The per-episode figures compared on the completed episodes."""


def _column(episodes: Sequence[Mapping[str, float]], key: str) -> np.ndarray:
    return np.array([float(e[key]) for e in episodes])


def split_gap(report: Mapping[str, Any]) -> list[dict[str, Any]]:
    """One row per learned policy of ``report`` (a ``compare_learned.py`` report): its share
    of the gap closed, its failed episodes, the share of the gap lost on them and on the
    completed ones, and the mean :data:`FIGURES` of the completed episodes (the policy's and
    the reference's on the same episodes).

    The shares are of ``mean(reference) - mean(baseline)`` over the report's episodes, so
    that ``closed + lost_on_failed + lost_on_completed == 1`` for every policy. Raises
    ``ValueError`` when the report has no per-episode figures or the gap is not positive.
    """
    episodes = report.get("episodes_per_policy")
    if not episodes:
        raise ValueError("the report has no per-episode figures (episodes_per_policy)")
    reference, base_name = report["reference"], report["baseline"]
    ref = episodes[reference]
    ref_score = _column(ref, "score")
    base_mean = _column(episodes[base_name], "score").mean()
    gap = ref_score.mean() - base_mean
    if not gap > 0.0:
        raise ValueError(f"the baseline -> reference gap must be positive, got {gap}")
    rows = []
    for name, eps in episodes.items():
        if ":" not in name:  # the heuristics (learned policies are "algorithm:path")
            continue
        score = _column(eps, "score")
        failed = _column(eps, "goal") < 1.0
        n = score.size
        row: dict[str, Any] = {
            "policy": name,
            "closed": float((score.mean() - base_mean) / gap),
            "failed": int(failed.sum()),
            "lost_on_failed": float((ref_score[failed] - score[failed]).sum() / n / gap),
            "lost_on_completed": float((ref_score[~failed] - score[~failed]).sum() / n / gap),
        }
        for key in FIGURES:
            row[key] = float(np.nanmean(_column(eps, key)[~failed]))
            row[f"reference_{key}"] = float(np.nanmean(_column(ref, key)[~failed]))
        rows.append(row)
    return rows


def to_markdown(rows: Sequence[Mapping[str, Any]], source: str) -> str:
    """The rows of :func:`split_gap` as a markdown table, with where they come from."""
    lines = [
        f"From `{source}` (nothing flown). Shares of the baseline -> reference gap; the figures "
        "are means over each policy's completed episodes, the reference's on the same "
        "episodes in brackets.",
        "",
        "| policy | closed | failed episodes | lost on failed | lost on completed "
        "| nav error [m] | steps | cruise spacing [m] | cruise altitude [m] |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        figs = " | ".join(
            f"{r[k]:.{d}f} ({r[f'reference_{k}']:.{d}f})" for k, d in zip(FIGURES, (2, 1, 1, 1))
        )
        lines.append(
            f"| {r['policy'].split('/')[-1]} | {r['closed']:.3f} | {r['failed']} "
            f"| {r['lost_on_failed']:.3f} | {r['lost_on_completed']:.3f} | {figs} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Split each learned policy's open gap into failed and completed episodes "
        "(from a compare_learned.py report; nothing is flown)."
    )
    parser.add_argument(
        "--report", type=Path, nargs="+", required=True, help="compare_learned report.json files"
    )
    parser.add_argument("--out", type=Path, required=True, help="folder of report.md/.json")
    args = parser.parse_args(argv)
    sections, tables = [], []
    for path in args.report:
        try:
            rows = split_gap(json.loads(path.read_text()))
        except (OSError, ValueError, KeyError) as err:
            parser.error(f"cannot read {path}: {err}")
        sections.append({"source": str(path), "rows": rows})
        tables.append(to_markdown(rows, str(path)))
    title = "Where the learned policies lose the gap"
    write_report(args.out, title, {"reports": sections}, "\n".join(tables))
    return 0


if __name__ == "__main__":
    sys.exit(main())
