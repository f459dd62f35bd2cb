"""The training return of MASAC runs over their wall time: per quarter, and where it peaked.

Reads the ``progress.csv`` that ``train_masac.py`` writes into each run folder (one row per
iteration: ``elapsed_s``, ``agent_steps``, ``mean_return`` of the iteration's training
episodes, stochastic actor) and prints, per run, the mean training return over each quarter
of its iterations and the peak of its rolling mean over ``--window`` iterations, with the
minute and agent-steps at which that window ends.

Usage::

    python studies/off_policy/training_curve.py runs/masac_s0/progress.csv \
        runs/masac_s1/progress.csv
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def curve_summary(path: Path, window: int) -> dict[str, float | list[float]]:
    """Quarter means and the rolling-mean peak of one ``progress.csv`` (``ValueError`` if
    it holds fewer iterations than ``window`` or four)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if len(rows) < max(window, 4):
        raise ValueError(f"{path} holds {len(rows)} iterations, fewer than {max(window, 4)}")
    ret = np.array([float(r["mean_return"]) for r in rows])
    minutes = np.array([float(r["elapsed_s"]) for r in rows]) / 60.0
    steps = np.array([float(r["agent_steps"]) for r in rows])
    quarters = [float(q.mean()) for q in np.array_split(ret, 4)]
    rolling = np.convolve(ret, np.ones(window) / window, mode="valid")
    peak = int(rolling.argmax())
    end = peak + window - 1
    return {
        "iterations": len(rows),
        "quarters": quarters,
        "peak": float(rolling[peak]),
        "peak_minute": float(minutes[end]),
        "peak_agent_steps": float(steps[end]),
        "last": float(rolling[-1]),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point (``--help``)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("progress", nargs="+", help="progress.csv files of MASAC runs")
    ap.add_argument("--window", type=int, default=30, help="iterations per rolling mean (30)")
    args = ap.parse_args(argv)
    if args.window < 1:
        ap.error(f"--window must be >= 1, got {args.window}")
    print("| run | iterations | training return by quarter | peak (rolling) | at | last |")
    print("|---|---:|---|---:|---|---:|")
    for name in args.progress:
        try:
            s = curve_summary(Path(name), args.window)
        except (OSError, ValueError, KeyError) as exc:
            ap.error(f"{name}: {exc}")
        quarters = " / ".join(f"{q:.2f}" for q in s["quarters"])
        at = f"{s['peak_minute']:.1f} min, {s['peak_agent_steps'] / 1e6:.2f}M agent-steps"
        print(
            f"| {name} | {s['iterations']} | {quarters} | {s['peak']:.3f} | {at} "
            f"| {s['last']:.3f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
