"""Paired screening of policy variants on the same episodes (the learning study's exploration).

Flies every policy of every group through the same held-out episodes and prints, per group,
the mean ``nav`` error (the 3-D error of the estimate each UAV used, every UAV-step), the mean
``coop`` error (steps with a cooperative fix), the goal rate and each policy's ``nav`` mean;
then, for every group against the first one, the paired difference of the per-episode errors
(averaged over the group's policies, i.e. its training seeds) with a 95 % bootstrap interval
over episodes (2000 resamples, generator seed 0). A cheaper, plainer cousin of
``coopnav study`` (no stratification over training seeds, no figures) for screening training
variants before a confirmatory study;
``studies/learning_under_degraded_navigation/README.md`` uses it::

    python studies/learning_under_degraded_navigation/paired_variants.py \\
        --episodes 1000 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true \\
        --groups base=guarded ceiling=ceiling

A group is ``NAME=POLICY[,POLICY...]`` with :func:`coopnav_env.agents.make_policy` names, e.g.
``mappo=torchrl:runs/x/mappo_s0,torchrl:runs/x/mappo_s1``; a policy's own options stay with it
(``tuned=ceiling@gain_per_s=0.3,cruise_speed_mps=10`` is one policy).

``--group-env NAME:KEY=VALUE ...`` flies group ``NAME`` in an environment with ``KEY=VALUE``
on top of ``--env-set`` (repeat for several keys), so that a *world or receiver* setting can be
paired too: the same policy, the same reset seeds (the same city, route, satellites and start),
another setting. For example, the fix gate of the receiver
(``studies/planner_headroom/README.md``)::

    python studies/learning_under_degraded_navigation/paired_variants.py \\
        --episodes 1000 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true \\
        --groups ceiling=ceiling gate10=ceiling --group-env gate10:max_fix_sigma_m=10

Only a setting that leaves the observation and action spaces alike can be paired with a
learned policy (the spaces are checked when the policy is loaded).
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _fly(policy: str, env_kwargs: dict[str, Any], seeds: list[int]) -> dict[str, np.ndarray]:
    import torch

    from studies.learning_in_default_setting.learning_study import fly_episodes

    torch.set_num_threads(1)
    eps = fly_episodes(policy, env_kwargs, seeds, keep_positions=False)
    return {
        "nav": np.array([e.nav_error_mean_m for e in eps], dtype=float),
        "coop": np.array([e.coop_error_mean_m for e in eps], dtype=float),
        "goal": np.array([e.success for e in eps], dtype=float),
    }


def _parse_groups(items: list[str]) -> dict[str, list[str]]:
    from studies.learning_in_default_setting.learning_study import parse_named_lists

    try:
        return parse_named_lists(items, "--groups", "NAME=POLICY[,POLICY...]")
    except ValueError as e:
        raise SystemExit(str(e)) from None


def _parse_group_env(
    items: list[str], groups: dict[str, list[str]], env_kwargs: dict[str, Any]
) -> dict[str, dict[str, Any]]:
    """Each group's environment: ``env_kwargs`` plus its ``--group-env`` overrides."""
    from coopnav_env.envs.config import make_config
    from coopnav_env.training.config import apply_overrides

    per: dict[str, list[str]] = {g: [] for g in groups}
    for item in items:
        name, sep, kv = item.partition(":")
        if not sep or "=" not in kv:
            raise SystemExit(f"--group-env entries are NAME:KEY=VALUE, got {item!r}")
        if name not in groups:
            raise SystemExit(f"--group-env: no group {name!r} (the groups are {', '.join(groups)})")
        per[name].append(kv)
    out = {}
    for g, kvs in per.items():
        try:
            out[g] = apply_overrides(dict(env_kwargs), kvs)
            make_config(**out[g])  # an unknown key or a bad value fails here, not in a worker
        except ValueError as e:
            raise SystemExit(f"group {g!r}: {e}") from None
    return out


def paired_table(
    results: dict[str, list[dict[str, np.ndarray]]], reps: int = 2000, seed: int = 0
) -> list[str]:
    """The printed lines: one per group, then each group minus the first (nav, coop)."""
    from coopnav_env.training.stats import bootstrap_mean_interval

    rng = np.random.default_rng(seed)
    stats = {}
    lines = []
    for name, runs in results.items():
        nav = np.mean([r["nav"] for r in runs], axis=0)
        coop = np.mean([r["coop"] for r in runs], axis=0)
        goal = np.mean([r["goal"] for r in runs], axis=0)
        per = [round(float(np.nanmean(r["nav"])), 2) for r in runs]
        stats[name] = (nav, coop)
        lines.append(
            f"{name:14s} nav {np.nanmean(nav):.3f} coop {np.nanmean(coop):.3f} "
            f"goal {goal.mean():.3f} per-seed {per}"
        )
    base = next(iter(results))
    for name in results:
        if name == base:
            continue
        for j, label in ((0, "nav"), (1, "coop")):
            d = stats[name][j] - stats[base][j]
            mean, lo, hi = bootstrap_mean_interval(d[np.isfinite(d)], reps, rng)
            lines.append(f"  {name} - {base} {label}: {mean:+.3f} [{lo:+.3f},{hi:+.3f}]")
    return lines


def main(argv: list[str] | None = None) -> int:
    from coopnav_env.training.config import apply_overrides

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--groups", nargs="+", required=True, help="NAME=POLICY[,POLICY...]")
    p.add_argument("--episodes", type=int, default=300, help="episodes (default: 300)")
    p.add_argument(
        "--first-seed", type=int, default=1_000_000, help="first reset seed (default: 1000000)"
    )
    p.add_argument("--env-set", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument(
        "--group-env",
        nargs="*",
        default=[],
        metavar="NAME:KEY=VALUE",
        help="an environment override for one group only, on top of --env-set",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    groups = _parse_groups(args.groups)
    env_kwargs = apply_overrides({}, args.env_set)
    group_env = _parse_group_env(args.group_env, groups, env_kwargs)
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    units = [(g, pol) for g, pols in groups.items() for pol in pols]
    if args.jobs <= 1:
        flown = [_fly(pol, dict(group_env[g]), seeds) for g, pol in units]
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(_fly, pol, dict(group_env[g]), seeds) for g, pol in units]
            flown = [f.result() for f in futures]
    results: dict[str, list[dict[str, np.ndarray]]] = {g: [] for g in groups}
    for (g, _), r in zip(units, flown):
        results[g].append(r)
    print("\n".join(paired_table(results)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
