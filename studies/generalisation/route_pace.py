"""How each policy's pace follows the length of its street route, per protocol city.

Flies ``--learned`` and ``--rule`` through the same ``--episodes`` held-out episodes (reset
seeds from ``--seed-start``) of every city of the protocol's suites, each with the settings
of its training run under the suite's city and sky (as ``coopnav evaluate --suite`` flies
it), and writes to ``--out`` (markdown), per city and policy: the range of the planned route's
length, the range of the episode's steps and of its cruise speed
(:func:`coopnav_env.training.behaviour.cruise_behaviour`), the correlation of each with the
route's length, and the goal rate; then every episode of the cities named in ``--detail``.

Usage::

    python studies/generalisation/route_pace.py --episodes 50
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from coopnav_env.training.envs import EVAL_SEED_START

HERE = Path(__file__).resolve().parent
LEARNED = "mappo:pretrained/families_scratch_s0"
RULE = "high_wide_column"
SUITES = ("grid", "families", "real")


def route_length_m(route_xy_m: np.ndarray) -> float:
    """Length of a route polyline (K, 2) [m]."""
    route = np.asarray(route_xy_m, dtype=float)
    if route.ndim != 2 or route.shape[1] != 2 or route.shape[0] < 2:
        raise ValueError(f"route_xy_m must have shape (K >= 2, 2), got {route.shape}")
    return float(np.linalg.norm(np.diff(route, axis=0), axis=1).sum())


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description="Route length against steps and speed of the learned swarm and the rule "
        "on the protocol's held-out episodes.",
    )
    ap.add_argument("--learned", default=LEARNED, help=f"the learned policy ({LEARNED})")
    ap.add_argument("--rule", default=RULE, help=f"the rule beside it ({RULE})")
    ap.add_argument("--cities", nargs="+", default=None, help="suite cities (default: all)")
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes per city (50)")
    ap.add_argument(
        "--seed-start",
        type=int,
        default=EVAL_SEED_START + 200,
        help=f"first held-out reset seed, >= {EVAL_SEED_START} ({EVAL_SEED_START + 200})",
    )
    ap.add_argument(
        "--detail", nargs="*", default=["old_town"], help="cities listed episode by episode"
    )
    ap.add_argument(
        "--out",
        default=str(HERE / "trained_on_families" / "route_pace.md"),
        help="output file (trained_on_families/route_pace.md beside this script)",
    )
    args = ap.parse_args(argv)
    if args.seed_start < EVAL_SEED_START:
        ap.error(f"--seed-start must be >= {EVAL_SEED_START}, got {args.seed_start}")
    if args.episodes < 3:
        ap.error(f"--episodes must be >= 3 (a correlation needs them), got {args.episodes}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from coopnav_env.agents import make_policy
    from coopnav_env.sim.real_suite import suite_cities
    from coopnav_env.training.evaluate import run_episode
    from coopnav_env.training.files import atomic_write_text
    from studies.generalisation.trajectory_figures import policy_env

    cities = [c for s in SUITES for c in suite_cities(s)]
    known = [c.name for c in cities]
    unknown = [c for c in [*(args.cities or []), *args.detail] if c not in known]
    if unknown:
        print(f"unknown cities {unknown}; the suites' cities are {known}", file=sys.stderr)
        return 2
    seeds = list(range(args.seed_start, args.seed_start + args.episodes))
    summary = [
        "| city | route [m] | policy | steps | corr(route, steps) | speed [m/s] "
        "| corr(route, speed) | goal rate |",
        "|---|---|---|---|---:|---|---:|---:|",
    ]
    detail: list[tuple[int, int, str]] = []  # (city, seed, row), the rule's row first
    t_all = time.perf_counter()
    for city in [c for c in cities if c.name in (args.cities or known)]:
        t0 = time.perf_counter()
        for name in (args.rule, args.learned):
            env = policy_env(name, city)
            policy = make_policy(name, env)
            length, steps, speed, goal = [], [], [], []
            for seed in seeds:
                rec = run_episode(env, policy, seed)
                b = rec.behaviour()
                length.append(route_length_m(rec.route_xy_m))
                steps.append(rec.length)
                speed.append(b["speed_mps"])
                goal.append(rec.success)
                if city.name in args.detail:
                    row = (
                        f"| {city.name} | {seed} | {length[-1]:.0f} | `{name}` | {rec.length} "
                        f"| {b['speed_mps']:.1f} | {b['spacing_m']:.1f} | "
                        f"{'yes' if rec.success else 'no'} |"
                    )
                    detail.append((known.index(city.name), seed, row))
            env.close()
            L, n, v = np.array(length), np.array(steps, dtype=float), np.array(speed)
            summary.append(
                f"| {city.name} | {L.min():.0f}-{L.max():.0f} | `{name}` | "
                f"{n.min():.0f}-{n.max():.0f} | {np.corrcoef(L, n)[0, 1]:+.2f} | "
                f"{v.min():.1f}-{v.max():.1f} | {np.corrcoef(L, v)[0, 1]:+.2f} | "
                f"{np.mean(goal):.2f} |"
            )
            print(summary[-1], flush=True)
        print(f"  {city.name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    given = argv if argv is not None else sys.argv[1:]
    command = " ".join(["python studies/generalisation/route_pace.py", *given])
    text = (
        "# Route length, steps and speed per city and policy\n\n"
        f"Regenerate: `{command}` ({(time.perf_counter() - t_all) / 60:.1f} min). "
        f"{args.episodes} held-out episodes per city (reset seeds {seeds[0]}..{seeds[-1]}), "
        "the same for both policies; route: the planned street route's length; speed: the "
        "mean horizontal speed of a UAV over the cruise (the middle 60 % of the steps); "
        "correlations over the episodes (Pearson).\n\n" + "\n".join(summary) + "\n"
    )
    if detail:
        rows = [
            "| city | reset seed | route [m] | policy | steps | speed [m/s] | spacing [m] | goal |",
            "|---|---:|---:|---|---:|---:|---:|---|",
            *(row for _city, _seed, row in sorted(detail, key=lambda d: d[:2])),
        ]
        text += "\n## Every episode\n\n" + "\n".join(rows) + "\n"
    atomic_write_text(Path(args.out), text)
    print(args.out, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
