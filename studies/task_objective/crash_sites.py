"""Where learned swarms crash: each crash's UAV, altitude and distance to the route's corners.

A crash in ``urban_canyon_v1`` is a UAV touching a building (UAVs too close to each other are
only flagged); it ends the episode. For every policy, this flies the held-out episodes and
records, for each UAV that crashed:

* its index in ``possible_agents`` (its place in a column: 0 leads);
* its altitude and the height band's top;
* its horizontal distance to the nearest *corner* of the swarm's planned street route (the
  route's interior vertices), and whether that is within ``--corner-m`` (a crash at a turn,
  against one on a straight leg);
* its distance to the route's polyline (how far off the street's centre line it was).

Example::

    python studies/task_objective/crash_sites.py \\
        --policies mappo:studies/task_objective/policies/mappo_bc_wide300_51k_s0 \\
        --episodes 100 --seed-start 1000100 --out studies/task_objective/crash_sites
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository (studies/)


def distance_to_corners(route_xy_m: np.ndarray, xy_m: np.ndarray) -> float:
    """Horizontal distance [m] from ``xy_m`` (2,) to the nearest interior vertex of the route
    ``route_xy_m`` (M, 2); ``inf`` for a route without a turn (M < 3)."""
    route = np.asarray(route_xy_m, dtype=float)
    if route.shape[0] < 3:
        return float("inf")
    return float(np.min(np.linalg.norm(route[1:-1] - np.asarray(xy_m, dtype=float), axis=1)))


def distance_to_route(route_xy_m: np.ndarray, xy_m: np.ndarray) -> float:
    """Horizontal distance [m] from ``xy_m`` (2,) to the polyline ``route_xy_m`` (M >= 2, 2)."""
    route = np.asarray(route_xy_m, dtype=float)
    p = np.asarray(xy_m, dtype=float)
    a, b = route[:-1], route[1:]
    ab = b - a
    t = np.clip(
        np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0, 1
    )
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


def crashes_of(policy_name: str, seeds: Sequence[int]) -> list[dict[str, float]]:
    """:func:`crashes_in` for ``policy_name`` in its run's environment, on one torch thread
    (:func:`~studies.task_objective.compare_learned.policy_in_its_env`)."""
    from studies.task_objective.compare_learned import policy_in_its_env

    with policy_in_its_env(policy_name) as (env, policy):
        return crashes_in(env, policy, seeds)


def crashes_in(env: Any, policy: Any, seeds: Sequence[int]) -> list[dict[str, float]]:
    """One record per crashed UAV of ``policy`` flown in ``env`` (an ``urban_canyon_v1``
    parallel env) on ``seeds``: seed, step, uav, altitude_m, corner_m, off_route_m (the
    position is the one the UAV kept: a crashed UAV stays where the step began)."""
    out: list[dict[str, float]] = []
    for seed in seeds:
        obs, _ = env.reset(seed=int(seed))
        policy.reset(int(seed))
        route = np.asarray(env.unwrapped.world.route_xy_m, dtype=float)
        agents = list(env.possible_agents)
        while env.agents:
            obs, _, _, _, infos = env.step(policy.act(obs))
            pos = np.asarray(env.unwrapped.world.pos_enu_m, dtype=float)
            for k, a in enumerate(agents):
                if a in infos and infos[a].get("collided"):
                    out.append(
                        {
                            "seed": int(seed),
                            "step": int(infos[a]["step"]),
                            "uav": k,
                            "altitude_m": float(pos[k, 2]),
                            "corner_m": distance_to_corners(route, pos[k, :2]),
                            "off_route_m": distance_to_route(route, pos[k, :2]),
                        }
                    )
    return out


def summarise(
    crashes: Sequence[Mapping[str, float]], n_episodes: int, corner_m: float
) -> dict[str, Any]:
    """Counts and shares of ``crashes`` over ``n_episodes`` episodes."""
    n = len(crashes)
    episodes = len({c["seed"] for c in crashes})
    uavs = [int(c["uav"]) for c in crashes]
    return {
        "episodes": n_episodes,
        "episodes_with_crash": episodes,
        "crashed_uavs": n,
        "at_corner": sum(c["corner_m"] <= corner_m for c in crashes),
        "median_corner_m": float(np.median([c["corner_m"] for c in crashes])) if n else None,
        "median_off_route_m": float(np.median([c["off_route_m"] for c in crashes])) if n else None,
        "median_altitude_m": float(np.median([c["altitude_m"] for c in crashes])) if n else None,
        "by_uav": {str(k): uavs.count(k) for k in sorted(set(uavs))},
    }


def to_markdown(report: Mapping[str, Any]) -> str:
    """The report as a markdown table."""
    c = report["corner_m"]
    lines = [
        f"`urban_canyon_v1`, {report['episodes']} held-out episodes (reset seeds "
        f"{report['seeds'][0]}-{report['seeds'][-1]}); a crash is a UAV touching a building. "
        f"At a corner: within {c:g} m of a turn of the planned route.",
        "",
        "| policy | episodes with a crash | crashed UAVs | at a corner | median distance to a "
        "corner [m] | median off the route [m] | median altitude [m] | crashes by UAV index |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]

    def f(x: float | None) -> str:
        return "-" if x is None else f"{x:.1f}"

    for name, s in report["policies"].items():
        by = ", ".join(f"{k}: {v}" for k, v in s["by_uav"].items()) or "-"
        lines.append(
            f"| `{name}` | {s['episodes_with_crash']} | {s['crashed_uavs']} | {s['at_corner']} | "
            f"{f(s['median_corner_m'])} | {f(s['median_off_route_m'])} | "
            f"{f(s['median_altitude_m'])} | {by} |"
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
    p.add_argument("--policies", nargs="+", required=True, help="policy names to fly")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed-start", type=int, default=1_000_100)
    p.add_argument(
        "--corner-m",
        type=float,
        default=20.0,
        help="a crash this close to a turn is at a corner [m]",
    )
    add_report_arguments(p)
    args = p.parse_args(argv)
    if not args.corner_m > 0:
        p.error(f"--corner-m must be > 0, got {args.corner_m}")
    out = report_folder(p, args)
    seeds = heldout_seeds(args.episodes, args.seed_start)
    from tqdm.auto import tqdm

    policies: dict[str, Any] = {}
    records: dict[str, Any] = {}
    for name in tqdm(args.policies, desc="policies"):
        crashes = crashes_of(name, seeds)
        records[name] = crashes
        policies[name] = summarise(crashes, len(seeds), args.corner_m)
    report = {
        "episodes": len(seeds),
        "seeds": [int(s) for s in seeds],
        "corner_m": args.corner_m,
        "policies": policies,
        "crashes": records,
    }
    write_report(out, "Where the swarms crash", report, to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
