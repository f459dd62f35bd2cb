"""How likely is a held-back start under a learned route-frame policy's own exploration?

The column opens its spacing at the start: every UAV but the first holds back while the one
ahead flies on. In the route frame that is a speed set-point near 0 for the first seconds. PPO
improves only what its Gaussian samples, so this probe asks how often a learned policy's
exploration would sample it. Each learned policy's mean actions are flown on held-out
episodes; at every decision in the first ``--hold-s`` seconds the actor's Gaussian for every
UAV's speed set-point (``MARLPolicy.action_distribution``, what training samples from) gives
the probability that the sample is at most ``--speed-mps``; their product over those decisions
(for a policy trained with ``torchrl.noise_correlation``, the joint chance under that
correlation over the decisions it held it for) is the chance that exploration holds that UAV
back for the whole time.

Per policy: the decisions in the window, the mean speed set-point of the actor's mean and its
standard deviation (in m/s), and the median and the largest (over UAVs and episodes) log10 of
that chance. The study (``studies/task_objective``) runs::

    python studies/task_objective/exploration_probe.py \\
        --policies mappo:studies/task_objective/policies/mappo_route_brake_4m_s2 \\
        --episodes 20 --seed-start 1000100 --out studies/task_objective/exploration_probe
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository (studies/)


def log10_normal_cdf(x: np.ndarray) -> np.ndarray:
    """``log10(Phi(x))`` of the standard normal, accurate far into the lower tail."""
    from scipy.special import log_ndtr

    return log_ndtr(np.asarray(x, dtype=np.float64)) / math.log(10.0)


def log10_ar1_all_below(x: Sequence[float], rho: float) -> float:
    """``log10 P(z_1 <= x_1, ..., z_D <= x_D)`` for standard normal ``z`` whose successive
    entries are correlated ``rho`` in ``[0, 1]`` (the AR(1) noise of
    ``torchrl.noise_correlation``; ``rho = 0``: independent, ``rho = 1``: one draw).

    For ``0 < rho < 1`` the density of ``z_d`` on the event so far is carried on a grid from
    ``min(x) - 8`` to ``max(x)`` (rescaled at every decision, so that chances far in the tail
    do not underflow) and propagated with the Gaussian transition ``N(rho z, 1 - rho**2)``.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return 0.0
    if not 0.0 <= rho <= 1.0:
        raise ValueError(f"rho must be in [0, 1], got {rho!r}")
    if rho == 0.0 or x.size == 1:
        return float(np.sum(log10_normal_cdf(x)))
    if rho == 1.0:
        return float(log10_normal_cdf(np.array([x.min()]))[0])
    sd = math.sqrt(1.0 - rho * rho)
    lo, hi = float(x.min()) - 8.0, float(x.max())
    n = int(min(6000, max(400, math.ceil((hi - lo) / (sd / 20.0)))))
    z = np.linspace(lo, hi, n)
    dz = z[1] - z[0]
    log_f = -0.5 * z * z - 0.5 * math.log(2.0 * math.pi)  # density of z_1
    log_scale = float(log_f.max())
    f = np.exp(log_f - log_scale)
    kernel = np.exp(-0.5 * ((z[:, None] - rho * z[None, :]) / sd) ** 2) / (
        sd * math.sqrt(2 * math.pi)
    )
    for d in range(x.size - 1):
        f = kernel @ (f * (z <= x[d]) * dz)  # density of z_{d+1} on the event so far
        top = float(f.max())
        if top <= 0.0:
            return -math.inf
        f /= top
        log_scale += math.log(top)
    mass = float(np.sum(f * (z <= x[-1])) * dz)
    return -math.inf if mass <= 0.0 else (math.log(mass) + log_scale) / math.log(10.0)


def trained_noise(policy: Any) -> tuple[float, int]:
    """``(noise_correlation, noise_correlated_decisions)`` a TorchRL policy was trained with:
    the exploration noise of an earlier coopnav, which its checkpoint still records
    (``MARLPolicy.recorded_settings``); ``(0.0, 0)``, independent draws, where it records none.
    """
    recorded = getattr(policy, "recorded_settings", None) or {}
    return float(recorded.get("noise_correlation", 0.0)), int(
        recorded.get("noise_correlated_decisions", 0)
    )


def window_steps(env: Any, hold_s: float) -> int:
    """The steps of ``env`` in the first ``hold_s`` seconds of an episode (at least 1)."""
    return max(1, math.ceil(hold_s / float(env.unwrapped.config.dt_s)))


def hold_back_chances(
    policy: Any, env: Any, seed: int, hold_s: float, speed_mps: float
) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Fly ``policy``'s mean actions in ``env`` from ``reset(seed)`` for ``hold_s`` seconds.

    Returns ``(log10_chance, means, stds)``: per UAV, log10 of the chance that the actor's
    Gaussian samples a speed set-point of at most ``speed_mps`` at every decision of the
    window (with the noise correlation ``policy`` was trained with, over the decisions it
    held it for, :func:`log10_ar1_all_below`), and per decision the speed set-point of the
    actor's mean and its standard deviation [m/s] for every UAV. An episode that ends
    earlier ends the window.
    """
    cfg = env.unwrapped.config
    vmax = float(cfg.kinematics.max_speed_mps)
    steps = window_steps(env, hold_s)
    repeat = int(policy.settings.action_repeat)
    a0_limit = 2.0 * speed_mps / vmax - 1.0  # the speed set-point is (a0 + 1) / 2 * vmax
    obs, _ = env.reset(seed=int(seed))
    policy.reset(seed=int(seed))
    limits: list[np.ndarray] = []  # per decision: every UAV's limit in standard deviations
    means: list[np.ndarray] = []
    stds: list[np.ndarray] = []
    for t in range(steps):
        if not env.agents:
            break
        if t % repeat == 0:  # a decision: the actor's Gaussian at this observation
            loc, scale = policy.action_distribution(obs)
            limits.append((a0_limit - loc[:, 0]) / scale[:, 0])
            means.append((np.clip(loc[:, 0], -1.0, 1.0) + 1.0) / 2.0 * vmax)
            stds.append(scale[:, 0] / 2.0 * vmax)
        obs, *_ = env.step(policy.act(obs))
    rho, held = trained_noise(policy)
    held = held or len(limits)
    per_uav = np.stack(limits, axis=1)  # (UAV, decision)
    # correlated over the episode's first `held` decisions, independent draws after them
    chance = np.array(
        [
            log10_ar1_all_below(row[:held], rho) + float(np.sum(log10_normal_cdf(row[held:])))
            for row in per_uav
        ]
    )
    return chance, means, stds


def check_route_frame(policies: Sequence[str]) -> None:
    """``ValueError`` naming a policy that was not trained in the route frame."""
    from studies.task_objective.compare_learned import env_settings_of

    for name in policies:
        if env_settings_of(name).get("action_frame") != "route":
            raise ValueError(f"{name} was not trained in the route frame (action_frame)")


def probe(
    policies: Sequence[str], seeds: Sequence[int], hold_s: float, speed_mps: float
) -> dict[str, Any]:
    """Fly every policy on ``seeds`` (module docstring); returns the report as a dict."""
    from tqdm.auto import tqdm

    from studies.task_objective.compare_learned import policy_in_its_env

    check_route_frame(policies)
    rows = []
    for name in tqdm(policies, desc="policies"):
        chances, means, stds = [], [], []
        with policy_in_its_env(name) as (env, policy):
            if not hasattr(policy, "action_distribution"):
                raise ValueError(f"{name} is not a TorchRL policy (mappo:/ippo:)")
            for seed in seeds:
                c, m, s = hold_back_chances(policy, env, seed, hold_s, speed_mps)
                chances.append(c)
                means += m
                stds += s
            repeat = int(policy.settings.action_repeat)
            decisions = math.ceil(window_steps(env, hold_s) / repeat)
        c = np.concatenate(chances)
        rows.append(
            {
                "policy": name,
                "action_repeat": repeat,
                "noise_correlation": trained_noise(policy)[0],
                "decisions": decisions,
                "mean_speed_setpoint_mps": float(np.mean(means)),
                "speed_setpoint_std_mps": float(np.mean(stds)),
                "log10_chance_median": float(np.median(c)),
                "log10_chance_max": float(np.max(c)),
            }
        )
    return {
        "environment": "urban_canyon_v1",
        "seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "hold_s": hold_s,
        "speed_mps": speed_mps,
        "policies": rows,
    }


def to_markdown(report: Mapping[str, Any]) -> str:
    """The table of ``report`` (:func:`probe`)."""
    lo, hi = report["seeds"]
    lines = [
        f"`urban_canyon_v1`, {report['episodes']} held-out episodes (reset seeds {lo}-{hi}); "
        f"the chance that the actor's exploration holds a UAV at a speed set-point of at most "
        f"{report['speed_mps']:g} m/s at every decision of the first {report['hold_s']:g} s.",
        "",
        "| policy | action repeat | noise correlation | decisions | mean speed set-point [m/s] "
        "| its std [m/s] | log10 chance, median | log10 chance, largest |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in report["policies"]:
        lines.append(
            f"| `{r['policy']}` | {r['action_repeat']} | {r.get('noise_correlation', 0.0):g} "
            f"| {r['decisions']} "
            f"| {r['mean_speed_setpoint_mps']:.1f} | {r['speed_setpoint_std_mps']:.1f} "
            f"| {r['log10_chance_median']:.1f} | {r['log10_chance_max']:.1f} |"
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
    p.add_argument(
        "--policies", nargs="+", required=True, help="learned route-frame TorchRL policies"
    )
    p.add_argument("--hold-s", type=float, default=8.0, help="the window, s (default: 8)")
    p.add_argument(
        "--speed-mps", type=float, default=2.0, help="held back: at most this, m/s (default: 2)"
    )
    p.add_argument("--episodes", type=int, default=20, help="held-out episodes (default: 20)")
    p.add_argument("--seed-start", type=int, default=1_000_000, help="first reset seed")
    add_report_arguments(p)
    args = p.parse_args(argv)
    if not args.hold_s > 0:
        p.error(f"--hold-s must be > 0, got {args.hold_s}")
    if not args.speed_mps >= 0:
        p.error(f"--speed-mps must be >= 0, got {args.speed_mps}")
    check_route_frame(args.policies)  # before the report's folder is claimed
    out = report_folder(p, args)
    seeds = heldout_seeds(args.episodes, args.seed_start)
    report = probe(args.policies, seeds, args.hold_s, args.speed_mps)
    write_report(out, "Exploration: the chance of a held-back start", report, to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
