"""``coopnav train``: train one PPO policy shared by every UAV, with the backend of choice.

This module is the command line: it merges the YAML section, ``--set``/``--env-set`` and the
explicit flags into a :class:`coopnav_env.training.config.TrainConfig` (validated before any
work starts) and hands it to the backend's module
(:data:`coopnav_env.training.config.BACKENDS`): :mod:`coopnav_env.training.sb3_backend`
(Stable-Baselines3, default) or :mod:`coopnav_env.training.rllib_backend` (Ray RLlib). The
run folder (``--out``) is laid out alike for every backend; see the backend
modules for what goes in it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path

from coopnav_env.training.compile_notice import compile_notice, warm_up_env
from coopnav_env.training.config import (
    BACKENDS,
    VEC_ENVS,
    TrainConfig,
    apply_overrides,
    backend_module,
    check_backend_settings,
    check_replaced_settings,
    load_config,
    named_configs,
)
from coopnav_env.training.envs import DEFAULT_ENV_ID, make_env_fn
from coopnav_env.training.runs import recorded_config

__all__ = ["add_arguments", "config_from_args", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``coopnav train``."""
    parser.add_argument("--out", default="runs/ppo", help="output directory (default: %(default)s)")
    named = "; ".join(f"{name}: {about}" for name, about in named_configs().items())
    parser.add_argument(
        "--config",
        default=None,
        metavar="NAME|FILE",
        help="a packaged training configuration by name, or a hyperparameter YAML file "
        f"(default: the packaged settings of --env-id). Packaged: {named}. Flags and --set "
        "change single settings on top",
    )
    parser.add_argument(
        "--env-id",
        default=None,
        help=f"environment (section of --config; default: {DEFAULT_ENV_ID}, or the run's own "
        "with --resume)",
    )
    parser.add_argument(
        "--timesteps",
        type=int,
        default=None,
        help="total agent-steps, SB3 timesteps (default: the --config file's)",
    )
    parser.add_argument(
        "--seed", type=int, default=None, help="training seed (default: the --config file's)"
    )
    parser.add_argument(
        "--n-envs",
        type=int,
        default=None,
        help="swarm copies stepped together (default: the --config file's)",
    )
    parser.add_argument(
        "--num-cpus",
        type=int,
        default=None,
        help="worker processes (default: the --config file's, 1 in the packaged one)",
    )
    parser.add_argument(
        "--vec-env",
        choices=VEC_ENVS,
        default=None,
        help="vector environment: auto (default: batched for urban_canyon_v1 or v0 in one "
        "process, else supersuit), supersuit, or batched (urban_canyon_v1 or v0 only)",
    )
    parser.add_argument(
        "--checkpoint-freq",
        type=int,
        default=None,
        help="agent-steps between checkpoints (default: the --config file's)",
    )
    parser.add_argument(
        "--n-uavs",
        type=int,
        default=None,
        help="UAVs per swarm, env setting n_uavs (default: the --config file's, else the "
        "environment's)",
    )
    parser.add_argument(
        "--city",
        default=None,
        help="city layout, env setting 'city' (default: the --config file's, else the "
        "environment's)",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a setting, e.g. ppo.learning_rate=1e-4 or n_envs=4 (repeatable; "
        "default: none)",
    )
    parser.add_argument(
        "--env-set",
        dest="env_overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override an environment setting, e.g. max_steps=300 (repeatable; default: none)",
    )
    parser.add_argument(
        "--resume",
        default=None,
        metavar="CHECKPOINT",
        help="continue the run in OUT from a checkpoint (SB3: a .zip; rllib: a checkpoint "
        "folder rllib_<N>_steps) or 'latest' (the newest that loads; a finished run: its final "
        "model, if --timesteps asks for more). The run keeps the settings recorded in "
        "OUT/config.yaml (--config is not read); flags and --set change single ones "
        "(default: a fresh run)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="start a fresh run in an OUT that holds an earlier run, removing that run's "
        "outputs (without it, or --resume, such a start is refused) (default: off)",
    )
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="hide the progress bars (default: shown, unless the config's progress_bar is false)",
    )
    parser.add_argument(
        "--verbose",
        type=int,
        default=None,
        help="SB3 verbosity, 0-2 (default: the --config file's)",
    )
    parser.add_argument(
        "--backend",
        choices=list(BACKENDS),
        default=None,
        help=f"training backend, one of: {', '.join(BACKENDS)} (default: sb3, Stable-Baselines3 "
        'in this process; rllib: Ray RLlib, needs pip install -e ".[ray]")',
    )
    parser.add_argument(
        "--algorithm",
        choices=["mappo", "ippo"],
        default=None,
        help="torchrl: MAPPO (critic on the global state) or IPPO (critic on the UAV's own "
        "observation) (default: the config's torchrl.algorithm, mappo)",
    )
    parser.add_argument(
        "--num-env-runners",
        type=int,
        default=None,
        help="rllib: Ray actors stepping the environment, 0: this process samples (default: "
        "the --config file's rllib.num_env_runners)",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="rllib: join the Ray cluster at HOST:PORT (see `ray start --head`) or 'auto' "
        "(default: start a local Ray)",
    )


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """Merge the settings, ``--set``/``--env-set`` and explicit flags (in that order).

    The settings are the YAML section of ``--config`` (default: the packaged file), or, with
    ``--resume`` in a folder that holds a run, the settings that run recorded
    (:func:`coopnav_env.training.runs.recorded_config`), so that a resumed run continues under
    its own settings and its own ``timesteps`` unless a flag or ``--set`` changes one.
    """
    if args.env_id is not None and not args.env_id.strip():
        raise ValueError(
            f"--env-id is empty; give an environment id (e.g. {DEFAULT_ENV_ID}) or leave "
            "--env-id out"
        )
    recorded = recorded_config(args.out) if args.resume is not None else None
    if recorded is not None:
        run_env_id = recorded.get("env_id") or DEFAULT_ENV_ID
        if args.env_id is not None and args.env_id != run_env_id:
            raise ValueError(
                f"--env-id {args.env_id}: {args.out} holds a run of {run_env_id} (its "
                f"config.yaml), which --resume continues in {run_env_id}; leave --env-id out, "
                f"or train {args.env_id} in another --out"
            )
        names = {f.name for f in dataclasses.fields(TrainConfig)}
        base = {
            k: v for k, v in recorded.items() if k in names and k not in ("resume", "overwrite")
        }
    else:
        base = load_config(args.config, args.env_id)
    base["env_id"] = args.env_id or base.get("env_id") or DEFAULT_ENV_ID
    base["out"] = args.out
    data = apply_overrides(base, args.overrides)
    data = apply_overrides(data, [f"env.{item}" for item in args.env_overrides])
    # environment settings given on the command line (--env-set KEY=VALUE, --set env.KEY=VALUE)
    # also win over the torchrl backend's own env block, which otherwise overrides env
    cli_env = [i[len("env.") :] for i in args.overrides if i.startswith("env.")]
    cli_env += list(args.env_overrides)
    torchrl_section = data.get("torchrl")
    if cli_env and isinstance(torchrl_section, Mapping) and torchrl_section.get("env"):
        data = apply_overrides(data, [f"torchrl.env.{item}" for item in cli_env])
    flags = {
        "timesteps": args.timesteps,
        "seed": args.seed,
        "n_envs": args.n_envs,
        "num_cpus": args.num_cpus,
        "vec_env": args.vec_env,
        "checkpoint_freq": args.checkpoint_freq,
        "resume": args.resume,
        "verbose": args.verbose,
    }
    check_replaced_settings(data, flags)  # a bad --set timesteps=abc is refused all the same
    data.update({k: v for k, v in flags.items() if v is not None})
    if args.backend is not None:
        data["backend"] = args.backend
    backend = data.get("backend", "sb3")
    for item in args.overrides:  # a backend's own section, given for another backend
        section = item.partition("=")[0].split(".")[0].strip()
        if section in ("torchrl", "rllib") and section != backend:
            raise ValueError(
                f"--set {item}: {section}.* settings apply to --backend {section} only, and "
                f"this run trains with --backend {backend}; add --backend {section} or drop it"
            )
    rllib_flags = {"num_env_runners": args.num_env_runners, "address": args.address}
    given = {k: v for k, v in rllib_flags.items() if v is not None}
    if given and data.get("backend", "sb3") != "rllib":
        flags_text = ", ".join("--" + k.replace("_", "-") for k in given)
        raise ValueError(f"{flags_text} only apply to --backend rllib")
    if given:
        data["rllib"] = {**(data.get("rllib") or {}), **given}
    if args.algorithm is not None:
        if data.get("backend", "sb3") != "torchrl":
            raise ValueError("--algorithm only applies to --backend torchrl")
        data["torchrl"] = {**(data.get("torchrl") or {}), "algorithm": args.algorithm}
    env = data.get("env") or {}
    if not isinstance(env, Mapping):
        raise ValueError(f"TrainConfig.env must be a mapping, got {env!r}")
    env = dict(env)
    if args.n_uavs is not None:
        env["n_uavs"] = args.n_uavs
    if args.city is not None:
        env["city"] = args.city
    data["env"] = env
    if args.no_progress:
        data["progress_bar"] = False
    if args.overwrite:
        data["overwrite"] = True
    return TrainConfig.from_dict(data)


def run(args: argparse.Namespace) -> int:
    """Run ``coopnav train``; returns the exit status.

    Errors propagate to :func:`coopnav_env.training.cli.main`, which turns them into one-line
    messages and exit statuses (2 for a usage error, 130/143 after an interrupt).
    """
    cfg = config_from_args(args)
    check_backend_settings(cfg)  # the backend's own settings, before the minute of compiling
    with compile_notice("about a minute", prefix="coopnav train"):
        warm_up_env(make_env_fn(cfg.env_id, cfg.env))
    final = backend_module(cfg.backend).train(cfg)
    info = json.loads((Path(cfg.out) / "run.json").read_text())
    print(
        f"final model: {final}  ({info['num_timesteps']} agent-steps, "
        f"{info['agent_steps_per_s']} agent-steps/s)"
    )
    return 0
