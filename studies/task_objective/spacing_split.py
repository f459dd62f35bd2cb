"""How much of a swarm's spacing is horizontal, and how much is height?

``compare_learned.py`` reports the cruise spacing as the 3D distance from each UAV to its
nearest neighbour (mean over the cruise, the middle 20-80 % of the episode, and over UAVs).
UAVs at different altitudes count as spread there. This probe flies each policy on held-out
episodes and splits that figure: the same mean with the horizontal distance only, and the
spread of the UAVs' altitudes (standard deviation over the swarm, mean over the cruise).

Per policy: the 3D spacing (as ``compare_learned.py``), the horizontal spacing, the altitude
spread and the mean altitude, each the mean over episodes. The study
(``studies/task_objective``) runs::

    python studies/task_objective/spacing_split.py \\
        --policies mappo:studies/task_objective/policies/mappo_route_noise_start_bc_4m_s1 \\
        --episodes 100 --seed-start 1000100 --out studies/task_objective/spacing_split
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository (studies/)


def nearest_distances(pos: np.ndarray) -> tuple[float, float]:
    """Mean 3D and mean horizontal distance to the nearest other UAV of ``pos`` (T, N, 3)."""
    pos = np.asarray(pos, dtype=float)
    n = pos.shape[1]
    out = []
    for dims in (slice(0, 3), slice(0, 2)):
        p = pos[..., dims]
        d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)
        d[:, np.arange(n), np.arange(n)] = np.inf
        out.append(float(d.min(axis=2).mean()))
    return out[0], out[1]


def split_episode(env: Any, policy: Any, seed: int) -> dict[str, float]:
    """Fly one episode; the cruise's 3D and horizontal spacing, altitude spread and mean."""
    from coopnav_env.training.evaluate import run_episode
    from studies.task_objective.compare_learned import CRUISE

    rec = run_episode(env, policy, int(seed))
    pos = np.asarray(rec.pos_enu_m, dtype=float)  # (T + 1, N, 3)
    t0, t1 = (round(f * (len(pos) - 1)) for f in CRUISE)
    cruise = pos[max(t0, 1) : max(t1, t0 + 1) + 1]  # the cruise window of compare_learned
    spacing, horizontal = nearest_distances(cruise)
    return {
        "seed": int(seed),
        "spacing_m": spacing,
        "horizontal_spacing_m": horizontal,
        "altitude_spread_m": float(cruise[:, :, 2].std(axis=1).mean()),
        "altitude_m": float(cruise[:, :, 2].mean()),
    }


def probe(policies: Sequence[str], seeds: Sequence[int]) -> dict[str, Any]:
    """Fly every policy on ``seeds``; returns the report as a dict."""
    from tqdm.auto import tqdm

    from studies.task_objective.compare_learned import policy_in_its_env

    rows = []
    for name in tqdm(policies, desc="policies"):
        with policy_in_its_env(name) as (env, policy):
            eps = [split_episode(env, policy, s) for s in seeds]
        row: dict[str, Any] = {"policy": name}
        for key in ("spacing_m", "horizontal_spacing_m", "altitude_spread_m", "altitude_m"):
            row[key] = float(np.mean([e[key] for e in eps]))
        row["episodes"] = eps
        rows.append(row)
    return {
        "environment": "urban_canyon_v1",
        "seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "policies": rows,
    }


def to_markdown(report: Mapping[str, Any]) -> str:
    """The table of ``report`` (:func:`probe`)."""
    lo, hi = report["seeds"]
    lines = [
        f"`urban_canyon_v1`, {report['episodes']} held-out episodes (reset seeds {lo}-{hi}); "
        "the cruise (20-80 % of each episode): mean distance to the nearest UAV in 3D and "
        "horizontally, and the UAVs' altitude spread (standard deviation over the swarm).",
        "",
        "| policy | spacing, 3D [m] | spacing, horizontal [m] | altitude spread [m] "
        "| altitude [m] |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in report["policies"]:
        lines.append(
            f"| `{r['policy']}` | {r['spacing_m']:.1f} | {r['horizontal_spacing_m']:.1f} "
            f"| {r['altitude_spread_m']:.1f} | {r['altitude_m']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (``--help``)."""
    from coopnav_env.training.envs import heldout_seeds
    from studies.task_objective.compare_learned import (
        add_report_arguments,
        report_folder,
        write_report,
    )

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--policies", nargs="+", required=True, help="policies (names as in evaluate)")
    p.add_argument("--episodes", type=int, default=20, help="held-out episodes (default: 20)")
    p.add_argument("--seed-start", type=int, default=1_000_000, help="first reset seed")
    add_report_arguments(p)
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error(f"--episodes must be >= 1, got {args.episodes}")
    out = report_folder(p, args)
    seeds = heldout_seeds(args.episodes, args.seed_start)
    report = probe(args.policies, seeds)
    write_report(out, "Spacing: horizontal and in height", report, to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
