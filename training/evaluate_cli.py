"""``coopnav evaluate``: the command line of :mod:`coopnav_env.training.evaluate`.

Parses the flags, finds the environment to evaluate in and calls
:func:`coopnav_env.training.evaluate.evaluate`. The environment is, in order: the
``config.yaml`` named by ``--train-config``; else the one of the run a trained policy
(``ppo:``, ``rllib:``, ``mappo:``/``ippo:``/``torchrl:`` ...) came from, found beside the
model or one or two folders up
(:func:`~coopnav_env.training.run_configs.train_config_of_policies`); else the environment's
defaults (a run's ``city_pool``, its training cities, is left out: evaluation flies unseen
cities); ``--env-set``, ``--n-uavs`` and ``--city`` then change it. A trained policy flown
without its run's settings gets a warning on stderr naming the settings used instead.
``--suite NAME`` flies the policies on every city of a suite instead
(:func:`coopnav_env.training.suite.evaluate_suite`). The library API
(:func:`~coopnav_env.training.evaluate.evaluate`,
:func:`~coopnav_env.training.evaluate.run_episode`, the report) stays in
:mod:`coopnav_env.training.evaluate`.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from coopnav_env.agents import action_frame_of
from coopnav_env.training.compile_notice import compile_notice, warm_up_env
from coopnav_env.training.config import apply_overrides
from coopnav_env.training.envs import (
    DEFAULT_ENV_ID,
    EVAL_SEED_START,
    heldout_seeds,
    make_env_fn,
)
from coopnav_env.training.evaluate import DEFAULT_EPISODES, check_methods_and_gap, evaluate
from coopnav_env.training.files import claim_output_folder, jsonable
from coopnav_env.training.run_configs import (
    TRAINED_KINDS,
    config_of_policy,
    is_trained,
    read_train_config,
    train_config_of_policies,
)

EVALUATE_OUTPUTS = (
    "report.json",
    "report.csv",
    "report.md",
    "errors.npz",
    "error_cdf.png",
    "trajectories_*.png",
)
"""The files ``coopnav evaluate`` writes into its ``--out``."""

__all__ = [
    "TRAINED_KINDS",
    "add_arguments",
    "parse_methods",
    "reward_settings",
    "run",
    "train_config_of_policies",
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``coopnav evaluate``."""
    parser.add_argument(
        "--policies",
        nargs="+",
        default=["random", "column", "sky_column"],
        help="policies: random, column, sky_column, stretched_column, wide_column, "
        "high_wide_column, guarded_column, ceiling_column, best_sky_route, waypoint, "
        "setpoints (route-frame set-points; when every policy is one, flown with "
        "action_frame=route), "
        "ppo:<path> (SB3 .zip), mappo:<path> / ippo:<path> (TorchRL run or .pt), rllib:<path> "
        "(checkpoint of `coopnav train --backend rllib`); options of a heuristic "
        "after @, e.g. waypoint@altitude_m=28. Model files are pickles: loading an SB3 .zip or "
        "an RLlib checkpoint runs code stored in it, so load only files you trust (TorchRL .pt "
        "files are read with torch's weights_only loader) (default: random column sky_column)",
    )
    parser.add_argument(
        "--out",
        default=None,
        help="directory for report.* and plots, of this evaluation alone: a folder of another "
        "command, of other settings, or holding this finished evaluation is refused "
        "(default: none, only the table is printed)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of the command (or the earlier evaluation) that --out holds; "
        "a training run is never replaced (default: refuse)",
    )
    parser.add_argument(
        "--episodes",
        type=int,
        default=DEFAULT_EPISODES,
        help="held-out episodes per policy (default: %(default)s)",
    )
    parser.add_argument(
        "--seed-start",
        type=int,
        default=EVAL_SEED_START,
        help=f"first held-out reset seed (>= {EVAL_SEED_START}; training uses seeds below) "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=None,
        help="explicit reset seeds, instead of --episodes seeds from --seed-start (default: none)",
    )
    parser.add_argument(
        "--env-id",
        default=None,
        help="environment (default: the one a trained policy's run was trained in, else "
        "urban_canyon_v1)",
    )
    parser.add_argument(
        "--train-config",
        default=None,
        help="config.yaml of a training run: evaluate in its environment (default: the one "
        "in the run folder of the first trained policy; without one, a warning)",
    )
    parser.add_argument(
        "--n-uavs",
        type=int,
        default=None,
        help="UAVs per swarm, env setting n_uavs (default: the training run's, else the "
        "environment's)",
    )
    parser.add_argument(
        "--city",
        default=None,
        help="city layout, env setting 'city' (default: the training run's, else the "
        "environment's)",
    )
    parser.add_argument(
        "--env-set",
        dest="env_overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override an environment setting (repeatable; default: none)",
    )
    parser.add_argument(
        "--no-plots", action="store_true", help="skip the PNG plots (default: plots are made)"
    )
    parser.add_argument(
        "--methods",
        nargs="+",
        default=[],
        metavar="NAME=POLICY[,POLICY...]",
        help="pool policies (e.g. one per training seed) as one method with a row of its own; "
        "its policies are evaluated too, e.g. "
        "mappo_route=mappo:pretrained/route_s0,mappo:pretrained/route_s1 (default: none)",
    )
    parser.add_argument(
        "--suite",
        default=None,
        metavar="NAME",
        help="fly the policies on every city of a suite instead of one environment: 'real' "
        "(real OpenStreetMap places under a real GPS sky) or 'families' (a new generated city "
        "of each family every episode; coopnav_env.sim.real_suite); one report folder per "
        "city in --out, plus summary.md/summary.json; trained policies fly their run's "
        "settings, the suite's city and sky replacing the run's; not with --methods, --gap, "
        "--train-config, --env-id, --city or --n-uavs (default: none)",
    )
    parser.add_argument(
        "--per-city-rule",
        type=int,
        default=0,
        metavar="N",
        help="with --suite: add the row 'per_city_column', in each city the column preset "
        "with the best mean score on N tuning episodes of that city (reset seeds from "
        "900000, never held out) (default: 0, no such row)",
    )
    parser.add_argument(
        "--compare",
        default=None,
        metavar="POLICY",
        help="with --suite: every other row's paired score difference from POLICY (a flown "
        "policy or per_city_column) in each city and over all cities (equal weight), with 95 %% "
        "bootstrap intervals; written as comparison.md (default: none)",
    )
    parser.add_argument(
        "--gap",
        nargs=2,
        default=None,
        metavar=("BASELINE", "REFERENCE"),
        help="add a table of every policy's and method's share of the gap from BASELINE to "
        "REFERENCE (each a policy or a --methods name), with paired 95 %% bootstrap intervals "
        "(default: none)",
    )


def parse_methods(items: Sequence[str]) -> dict[str, list[str]]:
    """``--methods`` items, ``NAME=POLICY[,POLICY...]``, as ``{NAME: [POLICY, ...]}``.

    Raises
    ------
    ValueError
        An item without ``=``, a name or a policy, or a name given twice.
    """
    methods: dict[str, list[str]] = {}
    for item in items:
        name, eq, listed = item.partition("=")
        members = [p.strip() for p in listed.split(",") if p.strip()]
        if not eq or not name.strip() or not members:
            raise ValueError(
                f"--methods {item!r} must look like NAME=POLICY[,POLICY...], e.g. "
                "mappo_route=mappo:pretrained/route_s0,mappo:pretrained/route_s1"
            )
        if name.strip() in methods:
            raise ValueError(f"--methods names {name.strip()!r} twice; give each method once")
        methods[name.strip()] = members
    return methods


def _env_from_args(args: argparse.Namespace) -> tuple[str, dict[str, Any], str]:
    """(env id, env kwargs, where they came from): ``--train-config``, else the run of a
    trained policy, then flags; warns on stderr about a trained policy without its run's
    settings (see :func:`_warn_untracked`)."""
    trained: dict[str, Any] = {}
    if args.env_id is not None and not args.env_id.strip():
        raise ValueError("--env-id is empty; give an environment id or leave --env-id out")
    if args.train_config:
        p = Path(args.train_config)
        if not p.is_file():
            raise FileNotFoundError(f"training config not found: {p}")
        trained = read_train_config(p)
        source = f"from --train-config {p}"
    else:
        trained = train_config_of_policies(args.policies)
        found = [c for c in map(config_of_policy, args.policies) if c is not None]
        if found:
            source = f"from {found[0]}"
        elif any(map(is_trained, args.policies)):
            source = "NO config.yaml of the trained policy's run: maybe not its training settings"
        else:
            source = ""
    run_env_id = trained.get("env_id")
    if args.env_id is not None and run_env_id is not None and args.env_id != run_env_id:
        raise ValueError(
            f"--env-id {args.env_id}: the policies' training run is a run of {run_env_id} "
            f"({source.removeprefix('from ')} says env_id: {run_env_id}); evaluate them in "
            f"{run_env_id} (leave --env-id out)"
        )
    env_id = args.env_id or trained.get("env_id") or DEFAULT_ENV_ID
    run_env = dict(trained.get("env") or {})
    # a run's training cities (city_pool) are not evaluation cities: held-out episodes fly
    # cities drawn from every seed, unless --env-set names a pool itself
    dropped_pool = run_env.pop("city_pool", None)
    env = apply_overrides(run_env, args.env_overrides)
    if args.n_uavs is not None:
        env["n_uavs"] = args.n_uavs
    if args.city is not None:
        env["city"] = args.city
    if dropped_pool is not None and "city_pool" not in env:
        note = f"city_pool={dropped_pool} of the run dropped: unseen cities"
        source = "; ".join(x for x in (source, note) if x)
    flags = bool(args.env_overrides) or args.n_uavs is not None or args.city is not None
    if flags:
        source = "; ".join(x for x in (source, "changed by --env-set/--n-uavs/--city") if x)
    route = [action_frame_of(p) == "route" for p in args.policies]
    if "action_frame" not in env and route and all(route):
        env["action_frame"] = "route"  # heuristics that command route-frame set-points
        source = "; ".join(x for x in (source, "action_frame=route: the policies' frame") if x)
    if not args.train_config:
        _warn_untracked(args.policies, env_id, env, bool(trained))
    return env_id, env, source


def _warn_untracked(
    policies: Sequence[str], env_id: str, env_kwargs: Mapping[str, Any], have_config: bool
) -> None:
    """Say loudly on stderr when a trained policy is flown without its run's settings.

    A policy trained with other rewards (``nav_reward``, weights, collision penalty), another
    number of UAVs or episode length is not comparable with the others in an environment it
    was not trained in: its return, goal rate and crashes mean something else. Names the
    settings used, and the reward settings they resolve to where the environment has a
    ``config`` (``urban_canyon_v0``).
    """
    missing = [n for n in policies if is_trained(n) and config_of_policy(n) is None]
    if not missing:
        return
    where = "the other policy's run settings" if have_config else "the environment's defaults"
    resolved = reward_settings(env_id, env_kwargs)
    print(
        f"coopnav evaluate: warning: no config.yaml of a training run beside (or one or two "
        f"folders above) {', '.join(missing)}: evaluating in {env_id} with {where}, settings "
        f"{json.dumps(jsonable(dict(env_kwargs)))}"
        + (f" (resolved: {resolved})" if resolved else "")
        + ". If it was trained with other settings (rewards, n_uavs, max_steps, ...), its "
        "returns and goal rate are not comparable; pass --train-config RUN/config.yaml or the "
        "settings with --env-set KEY=VALUE.",
        file=sys.stderr,
    )


#: settings of ``urban_canyon_v0`` named in the warning of :func:`_warn_untracked`
_NAMED_SETTINGS: tuple[str, ...] = (
    "n_uavs",
    "max_steps",
    "nav_reward",
    "nav_reward_weight",
    "nav_team_weight",
    "progress_reward_weight",
    "collision_penalty",
    "goal_bonus",
)


def reward_settings(env_id: str, env_kwargs: Mapping[str, Any]) -> str:
    """``key=value`` of the main reward and episode settings the env resolves, or ""."""
    try:
        env = make_env_fn(env_id, env_kwargs)()
    except Exception:  # the evaluation itself reports bad settings, with its own message
        return ""
    config = getattr(getattr(env, "unwrapped", env), "config", None)
    env.close()
    values = [(k, getattr(config, k)) for k in _NAMED_SETTINGS if hasattr(config, k)]
    return ", ".join(f"{k}={v!r}" for k, v in values)


def run(args: argparse.Namespace) -> int:
    """Run ``coopnav evaluate``; returns the exit status (errors: see
    :mod:`coopnav_env.training.cli`)."""
    if getattr(args, "suite", None) is not None:
        return _run_suite(args)
    suite_only = [
        flag
        for flag, value in (
            ("--per-city-rule", getattr(args, "per_city_rule", 0)),
            ("--compare", getattr(args, "compare", None)),
        )
        if value
    ]
    if suite_only:
        raise ValueError(f"{', '.join(suite_only)} need --suite NAME (e.g. --suite families)")
    methods = parse_methods(getattr(args, "methods", None) or [])
    gap = getattr(args, "gap", None)
    listed = list(args.policies)
    members = [p for ps in methods.values() for p in ps if p not in listed]
    args.policies = list(dict.fromkeys([*listed, *members]))  # a method's policies fly too
    check_methods_and_gap(args.policies, methods, gap)  # refused before any work
    seeds = args.seeds if args.seeds else heldout_seeds(args.episodes, args.seed_start)
    if min(seeds) < 0:
        raise ValueError(f"--seeds must be >= 0, got {min(seeds)}")
    if min(seeds) < EVAL_SEED_START:
        print(
            f"coopnav evaluate: warning: seeds below {EVAL_SEED_START} may have been seen "
            "in training",
            file=sys.stderr,
        )
    env_id, env_kwargs, source = _env_from_args(args)
    claim = contextlib.nullcontext(None)
    if args.out is not None:  # --out is claimed (locked, checked, recorded) before any work
        settings = {"policies": args.policies, "seeds": seeds, "env_id": env_id}
        settings |= {"env": env_kwargs, "plots": not args.no_plots}
        if methods:
            settings["methods"] = methods
        if gap is not None:
            settings["gap"] = list(gap)
        claim = claim_output_folder(
            args.out,
            "coopnav evaluate",
            settings,
            outputs=EVALUATE_OUTPUTS,
            overwrite=args.overwrite,
        )
    with claim as folder:
        with compile_notice("about a minute", prefix="coopnav evaluate"):
            warm_up_env(make_env_fn(env_id, env_kwargs))
        report = evaluate(
            args.policies,
            seeds,
            env_kwargs,
            args.out,
            env_id=env_id,
            plots=not args.no_plots,
            verbose=True,
            env_source=source,
            methods=methods,
            gap=gap,
        )
        if folder is not None:
            folder.finish(report.files.values())
    print(report.header())
    print()
    print(report.to_markdown())
    if report.gap is not None:
        print()
        print(report.gap_markdown())
    if report.files:
        print(f"\nwritten to {Path(args.out)}: " + ", ".join(p.name for p in report.files.values()))
    return 0


def _run_suite(args: argparse.Namespace) -> int:
    """``coopnav evaluate --suite NAME``: :func:`coopnav_env.training.suite.evaluate_suite`."""
    from coopnav_env.training.suite import evaluate_suite, suite_outputs

    refused = [
        flag
        for flag, value in (
            ("--methods", args.methods),
            ("--gap", args.gap),
            ("--train-config", args.train_config),
            ("--env-id", args.env_id),
            ("--city", args.city),
            ("--n-uavs", args.n_uavs),
        )
        if value
    ]
    if refused:
        raise ValueError(
            f"--suite {args.suite} sets the city, sky and environment itself: leave out "
            f"{', '.join(refused)} (change a setting of every city with --env-set KEY=VALUE)"
        )
    # an unknown suite is refused here, before any work
    outputs = suite_outputs(args.suite, compare=args.compare is not None)
    seeds = args.seeds if args.seeds else heldout_seeds(args.episodes, args.seed_start)
    if min(seeds) < EVAL_SEED_START:
        raise ValueError(
            f"--seeds must be >= {EVAL_SEED_START} with --suite (seeds below may have been seen "
            f"in training), got {min(seeds)}"
        )
    overrides = apply_overrides({}, args.env_overrides)
    claim = contextlib.nullcontext(None)
    if args.out is not None:
        settings = {"suite": args.suite, "policies": args.policies, "seeds": seeds}
        settings |= {"per_city_rule": args.per_city_rule, "compare": args.compare}
        settings["env_set"] = overrides
        claim = claim_output_folder(
            args.out, "coopnav evaluate", settings, outputs=outputs, overwrite=args.overwrite
        )
    with claim as folder:
        with compile_notice("about a minute", prefix="coopnav evaluate"):
            warm_up_env(make_env_fn(DEFAULT_ENV_ID, {}))
        report = evaluate_suite(
            args.policies,
            seeds,
            args.suite,
            args.out,
            overrides=overrides,
            verbose=True,
            per_city_rule=args.per_city_rule,
            compare=args.compare,
        )
        if folder is not None:
            folder.finish(report.files)
    print(report.header())
    print()
    print(report.to_markdown())
    if report.comparisons:
        print()
        print(report.comparison_markdown())
    if report.files:
        print(f"\nwritten to {Path(args.out)}: " + ", ".join(p.name for p in report.files))
    return 0
