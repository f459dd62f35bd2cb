"""How much spreading out is worth to a swarm, and what it costs a learned one.

Two measurements on held-out episodes of ``urban_canyon_v1``:

1. **A column at several spacings.** The re-tuned column
   (``wide_column@spacing_m=S,cruise_speed_mps=10,ceiling_margin_m=-10``) flown at each spacing
   ``S``: how the score and the navigation error change as the same column spreads out
   (the score's reward for spreading, with the route, speed and altitude held).
2. **A learned policy, slowed UAV by UAV.** The policy's command for UAV ``k`` (its index in
   ``possible_agents``) is flown with its horizontal part scaled by ``1 - k * slowdown``, so
   that the UAVs string out along the route; ``slowdown = 0`` is the policy itself. This
   asks what the learned policy would gain by spreading the way the column does, without
   learning anything new: the paired difference in score against the policy itself, and the
   parts (error, goal, collisions) that make it.

Each row gives the mean score with its 95 % bootstrap interval, the goal and collision rates,
the mean navigation error, the mean distance to the nearest UAV during the cruise and the
steps; rows of part 2 also give the paired difference to ``slowdown = 0`` with its interval.
The study (``studies/task_objective``) runs::

    python studies/task_objective/spreading_probe.py --policy mappo:pretrained/v1_s0 \\
        --out studies/task_objective/spreading_probe
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository (studies/)

COLUMN = "wide_column@spacing_m={spacing:g},cruise_speed_mps=10,ceiling_margin_m=-10"
"""The re-tuned column (``heuristics_v1``) with its spacing left open."""

KEYS = ("score", "goal", "collided", "nav_error_m", "cruise_spacing_m", "steps")


def slowdown_factors(agents: Sequence[str], slowdown: float) -> dict[str, float]:
    """``{agent: 1 - k * slowdown}`` for UAV ``k`` of ``agents``; ``ValueError`` unless
    ``slowdown`` is in ``[0, 1 / (N - 1))`` (the last UAV would stop)."""
    n = len(agents)
    if not 0.0 <= slowdown < 1.0 / max(n - 1, 1):
        raise ValueError(
            f"slowdown must be in [0, 1/(N-1)) = [0, {1 / max(n - 1, 1):.3f}), got {slowdown}"
        )
    return {a: 1.0 - k * slowdown for k, a in enumerate(agents)}


class SlowedPolicy:
    """``policy`` with UAV ``k``'s horizontal command scaled by ``1 - k * slowdown``.

    Parameters
    ----------
    policy : Policy
        Any policy of :func:`coopnav_env.agents.make_policy` flying ``env``.
    agents : sequence of str
        ``env.possible_agents``: the order that gives each UAV its ``k``.
    slowdown : float
        In ``[0, 1 / (N - 1))``: the share of its speed the second UAV gives up, the third
        twice that, and so on.
    """

    def __init__(self, policy: Any, agents: Sequence[str], slowdown: float) -> None:
        self.factor = slowdown_factors(agents, slowdown)
        self.policy = policy
        self.name = f"{getattr(policy, 'name', 'policy')}, slowed by {slowdown:g} per UAV"

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed=seed)

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for agent, a in self.policy.act(observations).items():
            a = np.array(a, dtype=np.float32, copy=True)
            a[:2] *= self.factor[agent]  # East, North; Up unchanged
            out[agent] = a
        return out


def probe(
    policy_name: str,
    slowdowns: Sequence[float],
    spacings_m: Sequence[float],
    seeds: Sequence[int],
    reps: int = 2000,
) -> dict[str, Any]:
    """Fly both parts (module docstring); returns the report as a dict."""
    from tqdm.auto import tqdm

    from coopnav_env.training.stats import paired_difference
    from studies.task_objective.compare_learned import (
        env_settings_of,
        fly,
        fly_policy,
        policy_in_its_env,
        summarise,
    )

    column = []
    for s in tqdm(spacings_m, desc="column spacings"):
        name = COLUMN.format(spacing=s)
        rows = fly(name, seeds)
        column.append({"spacing_m": float(s), "policy": name, **summarise(rows, KEYS, reps)})

    base_scores: np.ndarray | None = None
    slowed = []
    for sd in tqdm(slowdowns, desc="slowdowns"):
        with policy_in_its_env(policy_name) as (env, policy):
            rows = fly_policy(env, SlowedPolicy(policy, env.possible_agents, sd), seeds)
        scores = np.array([r["score"] for r in rows])
        if base_scores is None:
            base_scores = scores if sd == 0 else None
        row = {"slowdown": float(sd), **summarise(rows, KEYS, reps)}
        if base_scores is not None:
            iv, _ = paired_difference(scores[None], base_scores[None], reps=reps, seed=0)
            row["score_minus_unslowed"] = [iv.value, iv.low, iv.high]
        slowed.append(row)
    return {
        "environment": "urban_canyon_v1",
        "policy": policy_name,
        "env_settings": env_settings_of(policy_name),
        "seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "column": column,
        "slowed": slowed,
    }


def to_markdown(report: Mapping[str, Any]) -> str:
    """The two tables of ``report`` (:func:`probe`)."""

    def iv(v: Sequence[float]) -> str:
        return f"{v[0]:.3f} [{v[1]:.3f}, {v[2]:.3f}]"

    lo, hi = report["seeds"]
    lines = [
        f"`urban_canyon_v1`, {report['episodes']} held-out episodes (reset seeds {lo}-{hi}).",
        "",
        "## The column at several spacings",
        "",
        "| spacing [m] | score [95 % CI] | goal | collisions | nav error [m] | cruise spacing [m] "
        "| steps |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in report["column"]:
        lines.append(
            f"| {r['spacing_m']:g} | {iv(r['score'])} | {r['goal']:.2f} | {r['collided']:.2f} "
            f"| {r['nav_error_m']:.2f} | {r['cruise_spacing_m']:.1f} | {r['steps']:.1f} |"
        )
    lines += [
        "",
        f"## `{report['policy']}`, UAV k slowed by k x slowdown",
        "",
        "| slowdown | score [95 % CI] | minus unslowed | goal | collisions | nav error [m] "
        "| cruise spacing [m] | steps |",
        "|---:|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in report["slowed"]:
        d = r.get("score_minus_unslowed")
        diff = f"{d[0]:+.3f} [{d[1]:+.3f}, {d[2]:+.3f}]" if d else "n/a"
        lines.append(
            f"| {r['slowdown']:g} | {iv(r['score'])} | {diff} | {r['goal']:.2f} "
            f"| {r['collided']:.2f} | {r['nav_error_m']:.2f} | {r['cruise_spacing_m']:.1f} "
            f"| {r['steps']:.1f} |"
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
    p.add_argument("--policy", required=True, help="the learned policy to slow down")
    p.add_argument(
        "--slowdowns",
        default="0,0.05,0.1,0.15",
        help="comma-separated slowdowns per UAV, the first 0 (default: 0,0.05,0.1,0.15)",
    )
    p.add_argument(
        "--spacings",
        default="1.5,3,6,12,20,30,60",
        help="comma-separated column spacings in m (default: 1.5,3,6,12,20,30,60)",
    )
    p.add_argument("--episodes", type=int, default=40, help="held-out episodes (default: 40)")
    p.add_argument("--seed-start", type=int, default=1_000_000, help="first reset seed")
    p.add_argument("--reps", type=int, default=2000, help="bootstrap replicates")
    add_report_arguments(p)
    args = p.parse_args(argv)
    out = report_folder(p, args)
    try:
        slowdowns = [float(x) for x in args.slowdowns.split(",") if x]
        spacings = [float(x) for x in args.spacings.split(",") if x]
    except ValueError as e:
        p.error(f"--slowdowns and --spacings take comma-separated numbers: {e}")
    if not slowdowns or slowdowns[0] != 0.0:
        p.error(f"--slowdowns must start with 0 (the policy itself), got {args.slowdowns!r}")
    seeds = heldout_seeds(args.episodes, args.seed_start)
    report = probe(args.policy, slowdowns, spacings, seeds, args.reps)
    title = "Spreading: its worth, and its cost to a learned swarm"
    write_report(out, title, report, to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
