"""Heuristic search: fly heuristic variants on the learning study's held-out episodes.

The learning study (``coopnav study``, ``studies/learning_*``) compares learned swarms with the
best heuristic we could build or tune; this script is how the variants were compared. Every
variant (a policy name with options after ``@``, as ``coopnav evaluate`` takes them) flies the
same held-out episodes (reset seeds from 1,000,000) in the given environment, and the script
prints a Markdown table: the mean over episodes of the episode's mean cooperative 3-D error
(the study's ``coop`` score) and of the ``nav`` score (the error of the estimate each UAV
used, every step), the goal and crash rates, and the mean episode length, with the standard
error of the mean of each score (over episodes).

Example (the search of ``studies/learning_under_degraded_navigation``, about 20 s per variant and
300 episodes on one core)::

    python studies/learning_under_degraded_navigation/search_heuristics.py \\
        --env-set preset=urban_nlos_3dma \\
        dead_reckoning_noise=true --episodes 300 --variants wide guarded \\
        "guarded_column@ceiling_margin_m=0"
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _row(name: str, episodes: list, seconds: float) -> str:
    coop = np.array([e.coop_error_mean_m for e in episodes], dtype=float)
    nav = np.array([e.nav_error_mean_m for e in episodes], dtype=float)

    def mean_se(x: np.ndarray) -> str:
        x = x[np.isfinite(x)]
        if x.size == 0:
            return "n/a"
        se = x.std(ddof=1) / math.sqrt(x.size) if x.size > 1 else math.nan
        return f"{x.mean():.2f} +/- {se:.2f}"

    goal = np.mean([e.success for e in episodes])
    crash = np.mean([e.collided for e in episodes])
    length = np.mean([e.length for e in episodes])
    return (
        f"| `{name}` | {mean_se(coop)} | {mean_se(nav)} | {goal:.2f} | {crash:.2f} | "
        f"{length:.0f} | {seconds:.0f} |"
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Fly every variant and print the table (``--help`` for the options)."""
    from coopnav_env.training.config import apply_overrides
    from coopnav_env.training.envs import heldout_seeds
    from studies.learning_in_default_setting.learning_study import fly_episodes

    parser = argparse.ArgumentParser(
        prog="python studies/learning_under_degraded_navigation/search_heuristics.py",
        description=__doc__.split("\n")[0],
    )
    parser.add_argument(
        "--variants",
        nargs="+",
        required=True,
        help="heuristics with options, e.g. wide guarded 'guarded_column@ceiling_margin_m=0'",
    )
    parser.add_argument(
        "--episodes", type=int, default=100, help="held-out episodes (default: %(default)s)"
    )
    parser.add_argument(
        "--env-set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="environment settings, e.g. preset=urban_nlos_3dma dead_reckoning_noise=true",
    )
    args = parser.parse_args(argv)
    if args.episodes < 2:
        raise SystemExit(f"--episodes must be >= 2, got {args.episodes}")
    try:
        env_kwargs = apply_overrides({}, args.env_set)
    except ValueError as exc:
        raise SystemExit(f"--env-set: {exc}") from None
    seeds = heldout_seeds(args.episodes)
    print(f"environment {env_kwargs}; {args.episodes} episodes from seed {seeds[0]}")
    print()
    print("| variant | `coop` error [m] | `nav` error [m] | goal rate | crash rate | steps | s |")
    print("|---|---|---|---:|---:|---:|---:|")
    for name in args.variants:
        t0 = time.perf_counter()
        eps = fly_episodes(name, env_kwargs, seeds, keep_positions=False)
        print(_row(name, eps, time.perf_counter() - t0), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
