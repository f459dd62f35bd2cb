"""What a learned route-frame swarm leaves on the table: altitude, or spreading out.

Two measurements on held-out episodes of ``urban_canyon_v1`` in the route action frame
(``action_frame="route"``), with the environment settings of the first learned policy
(e.g. ``route_turn_brake_mps2``):

1. **Fixed set-points.** ``setpoints@speed_mps=V,altitude_m=A,speed_step_mps=S`` for every
   altitude ``A`` and speed step ``S`` asked: what constant set-points score as the swarm
   flies higher and strings out (each UAV ``S`` m/s slower than the one before, the first at
   ``V``); ``S = 0`` flies the swarm together.
2. **Learned policies, overridden.** Each learned policy flown as it is, with every UAV's
   altitude set-point at the top of the band (``a2 = 1``), with UAV ``k``'s speed set-point
   scaled by ``1 - k * slowdown`` (strung out, as the set-points above), and with both. The
   paired difference in score to the policy as it is says how much each change, which needs
   nothing new to be learned, would be worth. With ``--hold-s H > 0`` two more variants:
   UAV ``k`` held in place (speed set-point -1) for the episode's first ``k * H`` steps and
   then flown by the policy, as it is and at the top of the band: what the policy makes of
   a swarm opened like the column (one slot of ``H`` seconds per UAV).

Each row gives the mean score with its 95 % bootstrap interval, the goal and collision rates,
the mean navigation error, the mean distance to the nearest UAV during the cruise, the mean
cruise altitude and the steps. The study (``studies/task_objective``) runs::

    python studies/task_objective/route_frame_probe.py \\
        --policies mappo:studies/task_objective/policies/mappo_route_brake_4m_s0 \\
        --episodes 100 --seed-start 1000100 --out studies/task_objective/route_frame_probe
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository (studies/)

SETPOINTS = "setpoints@speed_mps={speed:g},altitude_m={altitude:g},speed_step_mps={step:g}"
"""The fixed set-points of part 1."""

KEYS = (
    "score",
    "goal",
    "collided",
    "nav_error_m",
    "cruise_spacing_m",
    "cruise_altitude_m",
    "steps",
)

OVERRIDES = ("as is", "top of the band", "strung out", "top of the band, strung out")
"""The variants of part 2, in order (the first is the policy itself)."""

HELD_OVERRIDES = ("held start", "held start, top of the band")
"""The variants of part 2 added by ``hold_s > 0``."""


class OverriddenPolicy:
    """A route-frame ``policy`` with some of its set-points replaced.

    Parameters
    ----------
    policy : Policy
        A policy flying an ``action_frame="route"`` environment.
    agents : sequence of str
        ``env.possible_agents``: the order that gives each UAV its ``k``.
    top : bool
        Fly every UAV's altitude set-point at the top of the band (``a2 = 1``).
    slowdown : float
        UAV ``k``'s speed set-point is scaled by ``1 - k * slowdown``, in ``[0, 1 / (N - 1))``.
    hold_steps : int
        UAV ``k``'s speed set-point is -1 (held in place) for the episode's first
        ``k * hold_steps`` steps (default 0: never).
    """

    def __init__(
        self,
        policy: Any,
        agents: Sequence[str],
        top: bool,
        slowdown: float,
        hold_steps: int = 0,
    ) -> None:
        from studies.task_objective.spreading_probe import slowdown_factors

        if hold_steps < 0:
            raise ValueError(f"hold_steps must be >= 0, got {hold_steps!r}")
        self.factor = slowdown_factors(agents, slowdown)
        self.held_for = {agent: k * int(hold_steps) for k, agent in enumerate(agents)}
        self.policy = policy
        self.top = bool(top)
        self.name = getattr(policy, "name", "policy")
        self._t = 0

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed=seed)
        self._t = 0

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for agent, a in self.policy.act(observations).items():
            a = np.clip(np.array(a, dtype=np.float32, copy=True), -1.0, 1.0)
            # the speed set-point is (a0 + 1) / 2 * max_speed_mps
            a[0] = (a[0] + 1.0) * self.factor[agent] - 1.0
            if self._t < self.held_for[agent]:
                a[0] = -1.0
            if self.top:
                a[2] = 1.0
            out[agent] = a
        self._t += 1
        return out


def route_settings(policies: Sequence[str]) -> dict[str, Any]:
    """The ``urban_canyon_v1`` settings the learned ``policies`` were all trained in
    (``{"action_frame": "route"}`` for none); ``ValueError`` for a policy of the velocity
    frame or settings that differ between them."""
    from studies.task_objective.compare_learned import env_settings_of

    settings = env_settings_of(policies[0]) if policies else {"action_frame": "route"}
    if settings.get("action_frame") != "route":
        raise ValueError(f"{policies[0]} was not trained in the route frame (action_frame)")
    for name in policies[1:]:
        if env_settings_of(name) != settings:
            raise ValueError(f"{name} was trained with settings other than {policies[0]}'s")
    return settings


def probe(
    policies: Sequence[str],
    speed_mps: float,
    altitudes_m: Sequence[float],
    steps_mps: Sequence[float],
    slowdown: float,
    seeds: Sequence[int],
    reps: int = 2000,
    hold_s: float = 0.0,
) -> dict[str, Any]:
    """Fly both parts (module docstring); returns the report as a dict."""
    from tqdm.auto import tqdm

    from coopnav_env import urban_canyon_v1
    from coopnav_env.agents import make_policy
    from coopnav_env.training.stats import paired_difference
    from studies.task_objective.compare_learned import (
        fly_policy,
        one_torch_thread,
        policy_in_its_env,
        summarise,
    )

    settings = route_settings(policies)
    fixed = []
    env = urban_canyon_v1.parallel_env(**settings)
    try:
        grid = [(a, s) for a in altitudes_m for s in steps_mps]
        for alt, step in tqdm(grid, desc="set-points"):
            name = SETPOINTS.format(speed=speed_mps, altitude=alt, step=step)
            with one_torch_thread():
                rows = fly_policy(env, make_policy(name, env), seeds)
            fixed.append(
                {"policy": name, "altitude_m": alt, "step_mps": step, **summarise(rows, KEYS, reps)}
            )
    finally:
        env.close()

    learned = []
    for name in tqdm(policies, desc="learned policies"):
        variants = []
        base: np.ndarray | None = None
        with policy_in_its_env(name) as (env, policy):
            hold_steps = round(hold_s / env.config.dt_s)
            labels = OVERRIDES + (HELD_OVERRIDES if hold_steps > 0 else ())
            for label in labels:
                wrapped = OverriddenPolicy(
                    policy,
                    env.possible_agents,
                    top="top" in label,
                    slowdown=slowdown if "strung" in label else 0.0,
                    hold_steps=hold_steps if "held" in label else 0,
                )
                rows = fly_policy(env, wrapped, seeds)
                scores = np.array([r["score"] for r in rows])
                row = {"variant": label, **summarise(rows, KEYS, reps)}
                if base is None:
                    base = scores
                else:
                    iv, _ = paired_difference(scores[None], base[None], reps=reps, seed=0)
                    row["score_minus_as_is"] = [iv.value, iv.low, iv.high]
                variants.append(row)
        learned.append({"policy": name, "variants": variants})
    return {
        "environment": "urban_canyon_v1",
        "env_settings": settings,
        "seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "speed_mps": speed_mps,
        "slowdown": slowdown,
        **({"hold_s": hold_s} if hold_s > 0 else {}),
        "fixed": fixed,
        "learned": learned,
    }


def to_markdown(report: Mapping[str, Any]) -> str:
    """The tables of ``report`` (:func:`probe`)."""

    def iv(v: Sequence[float]) -> str:
        return f"{v[0]:.3f} [{v[1]:.3f}, {v[2]:.3f}]"

    def parts(r: Mapping[str, Any]) -> str:
        return (
            f"{r['goal']:.2f} | {r['collided']:.2f} | {r['nav_error_m']:.2f} "
            f"| {r['cruise_spacing_m']:.1f} | {r['cruise_altitude_m']:.1f} | {r['steps']:.1f} |"
        )

    lo, hi = report["seeds"]
    head = "| goal | collisions | nav error [m] | cruise spacing [m] | altitude [m] | steps |"
    lines = [
        f"`urban_canyon_v1` with `{report['env_settings']}`, {report['episodes']} held-out "
        f"episodes (reset seeds {lo}-{hi}).",
        "",
        f"## Fixed set-points, the first UAV at {report['speed_mps']:g} m/s",
        "",
        "| altitude [m] | speed step [m/s] | score [95 % CI] " + head,
        "|---:|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in report["fixed"]:
        lines.append(f"| {r['altitude_m']:g} | {r['step_mps']:g} | {iv(r['score'])} | {parts(r)}")
    sd = report["slowdown"]
    held = f"; held start: UAV k held {report['hold_s']:g} k s" if "hold_s" in report else ""
    for pol in report["learned"]:
        lines += [
            "",
            f"## `{pol['policy']}` overridden (strung out: UAV k's speed x (1 - {sd:g} k){held})",
            "",
            "| variant | score [95 % CI] | minus as is " + head,
            "|---|---|---|---:|---:|---:|---:|---:|---:|",
        ]
        for r in pol["variants"]:
            d = r.get("score_minus_as_is")
            diff = f"{d[0]:+.3f} [{d[1]:+.3f}, {d[2]:+.3f}]" if d else "n/a"
            lines.append(f"| {r['variant']} | {iv(r['score'])} | {diff} | {parts(r)}")
    return "\n".join(lines) + "\n"


def _numbers(p: argparse.ArgumentParser, flag: str, text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x]
    except ValueError as e:
        p.error(f"{flag} takes comma-separated numbers: {e}")
    if not values:
        p.error(f"{flag} needs at least one number, got {text!r}")
    return values


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (``--help``)."""
    from coopnav_env.training.envs import heldout_seeds
    from studies.task_objective.compare_learned import (
        add_report_arguments,
        report_folder,
        write_report,
    )

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--policies",
        nargs="+",
        required=True,
        help="learned route-frame policies (mappo:<run or actor>, ...), trained with the "
        "same environment settings",
    )
    p.add_argument("--speed", type=float, default=10.0, help="set-points' first speed, m/s")
    p.add_argument("--altitudes", default="20,25,30", help="set-point altitudes, m (20,25,30)")
    p.add_argument("--steps", default="0,0.75,1.5", help="set-point speed steps, m/s (0,0.75,1.5)")
    p.add_argument(
        "--slowdown",
        type=float,
        default=0.15,
        help="the strung-out variants scale UAV k's speed set-point by 1 - k x this "
        "(default: 0.15, the speed steps of 1.5 m/s at 10 m/s)",
    )
    p.add_argument(
        "--hold-s",
        type=float,
        default=0.0,
        help="add the held-start variants: UAV k held in place for the first k x this "
        "many seconds (default: 0, none)",
    )
    p.add_argument("--episodes", type=int, default=40, help="held-out episodes (default: 40)")
    p.add_argument("--seed-start", type=int, default=1_000_000, help="first reset seed")
    p.add_argument("--reps", type=int, default=2000, help="bootstrap replicates")
    add_report_arguments(p)
    args = p.parse_args(argv)
    route_settings(args.policies)  # before the report's folder is claimed
    out = report_folder(p, args)
    altitudes = _numbers(p, "--altitudes", args.altitudes)
    steps = _numbers(p, "--steps", args.steps)
    seeds = heldout_seeds(args.episodes, args.seed_start)
    if args.hold_s < 0:
        p.error(f"--hold-s must be >= 0, got {args.hold_s!r}")
    report = probe(
        args.policies, args.speed, altitudes, steps, args.slowdown, seeds, args.reps, args.hold_s
    )
    title = "The route frame: what altitude and spreading are worth"
    write_report(out, title, report, to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
