"""``coopnav train --backend rllib``: PPO with one shared policy on Ray RLlib.

The same swarm task as :mod:`coopnav_env.training.sb3_backend` (the SB3 backend), distributed
with Ray: every UAV of ``urban_canyon_v0`` is mapped to one policy (``"shared"``: parameter
sharing), the PettingZoo env is wrapped by RLlib's
:class:`~ray.rllib.env.wrappers.pettingzoo_env.ParallelPettingZooEnv`, ``num_env_runners``
Ray actors (processes, possibly on other machines) step swarm copies and send their episodes
to the learner, which runs in this process. With ``num_env_runners = 0`` this process also
samples (no parallelism, but no actor start-up either).

Settings come from the same YAML section as the SB3 backend: the shared keys (``timesteps``,
``seed``, ``checkpoint_freq``, ``torch_threads``, ``env``) plus the ``rllib:`` sub-section
(:class:`RLlibSettings`: env runners, Ray address, ``ppo`` = arguments of
``PPOConfig.training``, ``model`` = fields of RLlib's ``DefaultModelConfig``). The SB3-only
keys (``ppo``, ``n_envs``, ``num_cpus``, ``vec_env``, ``normalize_reward``, ``pretrain``,
``device``, ``verbose``) are ignored and left out of the written ``config.yaml``.

Everything a run produces goes to ``--out DIR``, laid out as for SB3::

    DIR/config.yaml                      resolved settings, seed included, ``backend: rllib``
                                         (a resumed session adds config_resumed_at_<N>.yaml)
    DIR/run.json                         versions, wall time, env- and agent-steps per second
    DIR/final_model/                     RLlib checkpoint of the trained algorithm
                                         (``rllib:DIR/final_model`` in ``coopnav evaluate``)
    DIR/checkpoints/rllib_<N>_steps/     periodic checkpoints (N agent-steps)
    DIR/logs/progress.csv                one row per iteration, every iteration once over
                                         resumed sessions (+ TensorBoard events)
    DIR/ray/                             Ray's session files and logs (local Ray only)

Counting: ``timesteps`` and ``checkpoint_freq`` are *agent*-steps, as for SB3 (one step of a
swarm of 5 UAVs is 5 agent-steps); RLlib's ``train_batch_size_per_learner`` counts *env*-steps
(swarm steps) of all env runners together, so one iteration is about
``train_batch_size_per_learner * n_uavs`` agent-steps. Training stops after the first
iteration that reaches ``timesteps``.

Ray's files never go to the home directory: a local Ray keeps its temp dir in ``DIR/ray``
(through a short symbolic link in the system temp dir when ``DIR`` is too long for a Unix
socket path), the token of Ray's token authentication is passed in the environment instead of
``~/.ray/auth_token``, usage statistics are off, and RLlib's ``~/ray_results`` trial folder is
redirected to a temporary directory. With ``address`` (``--address``) the run joins an existing
cluster, whose files are where its ``ray start --temp-dir`` put them.

Seeds: copy ``j`` of env runner ``i`` first resets with ``seed + i E + j`` (``E`` =
``num_envs_per_env_runner``; runner 0 is this process; see :func:`make_rllib_env`), a resumed
run with ``seed + N`` (``N`` agent-steps done, modulo the training seed range), all below
:data:`coopnav_env.training.envs.EVAL_SEED_START`.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import re
import shutil
import socket
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coopnav_env.training.config import TrainConfig
from coopnav_env.training.envs import DEFAULT_ENV_ID, EVAL_SEED_START, make_env_fn
from coopnav_env.training.files import atomic_path, write_json, write_yaml
from coopnav_env.training.runs import (
    ProgressLog,
    check_same_environment,
    checkpoint_candidates,
    first_loadable,
    install_interrupt_handlers,
    open_run,
)

__all__ = [
    "INSTALL_HINT",
    "SHARED_POLICY",
    "RLlibSettings",
    "check",
    "check_address",
    "check_checkpoint",
    "find_latest_rllib_checkpoint",
    "import_rllib",
    "is_rllib_checkpoint",
    "make_rllib_env",
    "resolve_resume",
    "train",
]

INSTALL_HINT: str = 'pip install -e ".[ray]"'
"""How to install the optional Ray dependencies (the ``ray`` extra of ``pyproject.toml``)."""

SHARED_POLICY: str = "shared"
"""Module id of the one policy every UAV is mapped to."""

STATE_FILE: str = "coopnav_state.json"
"""Written into every checkpoint folder: agent-steps, env-steps and iterations done."""

SB3_ONLY_KEYS: tuple[str, ...] = (
    "ppo",
    "n_envs",
    "num_cpus",
    "normalize_reward",
    "pretrain",
    "device",
    "verbose",
    "vec_env",
)
"""Settings of :class:`coopnav_env.training.config.TrainConfig` that only the SB3 backend reads."""

_CHECKPOINT_RE = re.compile(r"^rllib_(\d+)_steps$")
_MAX_TEMP_DIR_LEN = 40  # Ray adds ~65 characters of session/socket path; AF_UNIX allows 107


# --------------------------------------------------------------------------------------------
# settings
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RLlibSettings:
    """The ``rllib:`` section of the training configuration.

    Parameters
    ----------
    num_env_runners : int, default 2
        Ray actors that step the environment, >= 0 (0: this process samples). Each needs
        ``num_cpus_per_env_runner`` CPUs of the cluster.
    num_envs_per_env_runner : int, default 1
        Swarm copies each env runner steps together, >= 1.
    num_cpus_per_env_runner : float, default 1
        CPUs Ray reserves for each env runner, > 0.
    rollout_fragment_length : int or "auto", default "auto"
        Env-steps each runner collects per request ("auto": the batch split evenly).
    address : str or None, default None
        Ray cluster to join (``HOST:PORT`` of a head started by ``ray start --head``,
        ``ray://HOST:PORT`` for Ray Client, or ``auto``); None starts a local Ray in this
        process. Joining a cluster needs ``num_env_runners >= 1``.
    connect_timeout_s : float, default 10
        How long to wait for ``address`` to answer before giving up, > 0.
    ray_temp_dir : str or None, default None
        Temp dir of a local Ray; None for ``OUT/ray``.
    ppo : dict
        Keyword arguments of ``PPOConfig.training`` (``lr``, ``gamma``, ``lambda_``,
        ``train_batch_size_per_learner``, ``minibatch_size``, ``num_epochs``, ...).
    model : dict
        Fields of RLlib's ``DefaultModelConfig`` (``fcnet_hiddens``, ``fcnet_activation``,
        ``vf_share_layers``, ...).
    """

    num_env_runners: int = 2
    num_envs_per_env_runner: int = 1
    num_cpus_per_env_runner: float = 1.0
    rollout_fragment_length: int | str = "auto"
    address: str | None = None
    connect_timeout_s: float = 10.0
    ray_temp_dir: str | None = None
    ppo: dict[str, Any] = field(default_factory=dict)
    model: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, lo in (("num_env_runners", 0), ("num_envs_per_env_runner", 1)):
            v = getattr(self, name)
            flag = " (--num-env-runners)" if name == "num_env_runners" else ""
            if isinstance(v, bool) or not isinstance(v, int):
                raise ValueError(f"rllib.{name}{flag} must be an integer, got {v!r}")
            if v < lo:
                raise ValueError(f"rllib.{name}{flag} must be >= {lo}, got {v}")
        for name in ("num_cpus_per_env_runner", "connect_timeout_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise ValueError(f"rllib.{name} must be a number > 0, got {v!r}")
            if not math.isfinite(v):
                raise ValueError(f"rllib.{name} must be finite, got {v!r}")
            object.__setattr__(self, name, float(v))
        frag = self.rollout_fragment_length
        if frag != "auto" and (isinstance(frag, bool) or not isinstance(frag, int) or frag < 1):
            raise ValueError(f"rllib.rollout_fragment_length must be 'auto' or >= 1, got {frag!r}")
        if self.address is not None:
            if not isinstance(self.address, str) or not self.address.strip():
                raise ValueError(f"rllib.address must be HOST:PORT or 'auto', got {self.address!r}")
            if self.num_env_runners == 0:
                raise ValueError(
                    f"joining the Ray cluster at {self.address} needs rllib.num_env_runners >= 1 "
                    "(--num-env-runners): with 0 env runners everything runs in this process "
                    "and the cluster would sit idle"
                )
        for name in ("ppo", "model"):
            v = getattr(self, name)
            if v is None:
                object.__setattr__(self, name, {})
            elif not isinstance(v, Mapping):
                raise ValueError(f"rllib.{name} must be a mapping, got {v!r}")
            else:
                object.__setattr__(self, name, dict(v))
        for key in ("train_batch_size_per_learner", "minibatch_size", "num_epochs"):
            v = self.ppo.get(key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
                raise ValueError(f"rllib.ppo.{key} must be an integer >= 1, got {v!r}")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None) -> RLlibSettings:
        """Build from a mapping (None: defaults); unknown keys raise ``ValueError``."""
        data = dict(data or {})
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown rllib setting(s) {unknown}; valid settings: {sorted(names)}")
        return cls(**data)

    def to_dict(self) -> dict[str, Any]:
        """A plain (YAML-serialisable) copy."""
        return dataclasses.asdict(self)


# --------------------------------------------------------------------------------------------
# Ray and the environment
# --------------------------------------------------------------------------------------------


def import_rllib() -> Any:
    """Import and return ``ray``, with a clear message when Ray RLlib is not installed.

    Raises
    ------
    ImportError
        Ray or RLlib (or torch, which RLlib's PPO needs) is missing; the message says how to
        install the ``ray`` extra.
    """
    try:
        import ray
        import ray.rllib
        import torch  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            f"the RLlib backend needs Ray RLlib and torch ({exc}); install the extra with: "
            f"{INSTALL_HINT}"
        ) from exc
    return ray


def make_rllib_env(env_config: Mapping[str, Any]) -> Any:
    """An RLlib ``MultiAgentEnv`` for ``{"env_id": ..., "env_kwargs": {...}}`` (env creator)."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    env_id = str(env_config.get("env_id", DEFAULT_ENV_ID))
    env = ParallelPettingZooEnv(make_env_fn(env_id, dict(env_config.get("env_kwargs") or {}))())
    # RLlib resets env runner i's vector env with seed + i, and gymnasium's vector env gives its
    # copy j seed + i + j: with E > 1 copies per runner, copy j + 1 of runner i and copy j of
    # runner i + 1 would replay the same episodes. Shifting runner i's seeds by i (E - 1) makes
    # them seed + i E + j, distinct for every (runner, copy).
    offset = int(getattr(env_config, "worker_index", 0) or 0) * (
        int(env_config.get("num_envs_per_env_runner", 1)) - 1
    )
    if offset:
        env.reset = functools.partial(_reset_with_seed_offset, env.reset, offset)
    return env


def _reset_with_seed_offset(reset: Any, offset: int, *, seed: int | None = None, options=None):
    return reset(seed=None if seed is None else int(seed) + offset, options=options)


def map_to_shared_policy(agent_id: Any, episode: Any = None, **kwargs: Any) -> str:
    """RLlib policy mapping: every UAV uses :data:`SHARED_POLICY` (parameter sharing)."""
    return SHARED_POLICY


def _on_episode_end(*, episode: Any, metrics_logger: Any = None, **kwargs: Any) -> None:
    """Log the goal and collision rate and the mean cooperative error of each episode."""
    from coopnav_env.envs.urban_canyon import fix_error_m

    if metrics_logger is None:
        return
    try:
        final = episode.get_infos(-1)
        chunks = [*(kwargs.get("prev_episode_chunks") or []), episode]
        errors = [
            fix_error_m(info, "coop_error_m")
            for chunk in chunks
            for agent_ep in chunk.agent_episodes.values()
            for info in agent_ep.get_infos()
            if isinstance(info, Mapping) and info.get("coop_error_m") is not None
        ]
    except Exception:  # pragma: no cover - metrics must never stop training
        return
    if final:
        goal = all(bool(i.get("in_goal", i.get("goal_reached", False))) for i in final.values())
        crash = any(bool(i.get("collided", False)) for i in final.values())
        metrics_logger.log_value("nav_goal_rate", float(goal), reduce="mean", window=100)
        metrics_logger.log_value("nav_collision_rate", float(crash), reduce="mean", window=100)
    finite = [e for e in errors if math.isfinite(e)]
    if finite:
        metrics_logger.log_value(
            "nav_coop_error_mean_m", sum(finite) / len(finite), reduce="mean", window=100
        )


def check_address(address: str, timeout_s: float) -> None:
    """Fail fast when a Ray cluster address does not answer (instead of hanging).

    ``auto`` is left to Ray (it looks for a cluster started on this machine and fails at once
    when there is none). Other addresses must be ``HOST:PORT`` or ``ray://HOST:PORT`` (port
    6379 when omitted) and accept a TCP connection within ``timeout_s``.

    Raises
    ------
    ValueError
        The address is malformed.
    ConnectionError
        Nothing answers at that address in time.
    """
    if address == "auto":
        return
    target = address.split("://", 1)[1] if "://" in address else address
    host, sep, port_text = target.rpartition(":")
    if not sep:
        host, port_text = target, "6379"
    host = host.strip("[]")
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not host or not 0 < port < 65536:
        raise ValueError(
            f"Ray address {address!r} must look like HOST:PORT, ray://HOST:PORT or 'auto'"
        )
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        raise ConnectionError(
            f"cannot reach the Ray cluster at {address} within {timeout_s:g} s ({exc}); start a "
            f"head node there with `ray start --head --port={port}`, or check the host, the port "
            "and the firewall"
        ) from exc


def _needed_cpus(s: RLlibSettings) -> float:
    return s.num_env_runners * s.num_cpus_per_env_runner


@contextmanager
def ray_session(s: RLlibSettings, out: Path) -> Iterator[dict[str, Any]]:
    """Start (or join) Ray for a training run and shut it down afterwards.

    Yields a dict describing the session (``address``, ``temp_dir``, ``cluster_cpus``).
    A Ray already initialised by the caller is used as is and left running.
    """
    ray = import_rllib()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    info: dict[str, Any] = {"address": s.address or "local", "temp_dir": None}
    link_dir: str | None = None
    started = False
    if ray.is_initialized():
        info["address"] = "existing session"
    elif s.address is not None:
        check_address(s.address, s.connect_timeout_s)
        try:
            ray.init(address=s.address, logging_level="ERROR", log_to_driver=False)
        except Exception as exc:
            raise ConnectionError(f"could not join the Ray cluster at {s.address}: {exc}") from exc
        started = True
    else:
        temp = Path(s.ray_temp_dir) if s.ray_temp_dir else out / "ray"
        temp = temp.expanduser().absolute()
        temp.mkdir(parents=True, exist_ok=True)
        info["temp_dir"] = str(temp)
        use = str(temp)
        if len(use) > _MAX_TEMP_DIR_LEN:
            # Unix socket paths are limited to 107 bytes: point a short link at `temp`
            base = tempfile.gettempdir()
            link_dir = tempfile.mkdtemp(prefix="coopnav-", dir=base if len(base) < 16 else "/tmp")
            use = os.path.join(link_dir, "ray")
            os.symlink(temp, use)
        _use_in_memory_auth_token()
        needed = 1 + _needed_cpus(s)
        try:
            ray.init(
                address="local",
                num_cpus=max(os.cpu_count() or 1, math.ceil(needed)),
                _temp_dir=use,
                include_dashboard=False,
                logging_level="ERROR",
                log_to_driver=False,
            )
        except Exception:
            _remove_link(link_dir, temp)
            raise
        started = True
    try:
        info["cluster_cpus"] = float(ray.cluster_resources().get("CPU", 0.0))
        if s.address is not None and info["cluster_cpus"] < _needed_cpus(s):
            raise ValueError(
                f"the Ray cluster at {s.address} has {info['cluster_cpus']:g} CPUs; "
                f"{s.num_env_runners} env runners x {s.num_cpus_per_env_runner:g} CPUs need "
                f"{_needed_cpus(s):g}: add nodes, or lower --num-env-runners or "
                "rllib.num_cpus_per_env_runner"
            )
        yield info
    finally:
        if started:
            ray.shutdown()
        _remove_link(link_dir, Path(info["temp_dir"]) if info["temp_dir"] else None)


def _use_in_memory_auth_token() -> None:
    """Give a new local Ray its authentication token in the environment, not in ``~/.ray``.

    Ray >= 2.5x enables token authentication for a cluster started by ``ray.init()`` and
    writes a generated token to ``~/.ray/auth_token``; an existing token (file, or the
    ``RAY_AUTH_TOKEN``/``RAY_AUTH_TOKEN_PATH`` variables) or ``RAY_AUTH_MODE`` are respected.
    The token is kept for the life of this process (Ray caches it).
    """
    import secrets

    if any(k in os.environ for k in ("RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_AUTH_MODE")):
        return
    if (Path.home() / ".ray" / "auth_token").is_file():
        return
    os.environ["RAY_AUTH_TOKEN"] = secrets.token_hex(32)


def _remove_link(link_dir: str | None, temp: Path | None) -> None:
    if link_dir is None:
        return
    shutil.rmtree(link_dir, ignore_errors=True)  # the link only, not its target
    if temp is not None:
        latest = temp / "session_latest"
        if latest.is_symlink() and not latest.exists():  # pointed through the link
            latest.unlink()


@contextmanager
def _trainable_logdir_in(folder: Path) -> Iterator[None]:
    """Make RLlib's Algorithm create its (unused) trial folder in ``folder``, not ~/ray_results."""
    try:
        import ray.tune.trainable.trainable as trainable_mod
    except ImportError:  # pragma: no cover - layout of another Ray version
        yield
        return
    old = getattr(trainable_mod, "DEFAULT_STORAGE_PATH", None)
    trainable_mod.DEFAULT_STORAGE_PATH = str(folder)
    try:
        yield
    finally:
        trainable_mod.DEFAULT_STORAGE_PATH = old


@contextmanager
def _quiet_rllib() -> Iterator[None]:
    """Hide RLlib's start-up warnings (e.g. "running PPO on the new API stack") while building."""
    import logging

    log = logging.getLogger("ray.rllib")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


# --------------------------------------------------------------------------------------------
# algorithm configuration
# --------------------------------------------------------------------------------------------


def _valid_training_keys() -> set[str]:
    import inspect

    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
    from ray.rllib.algorithms.ppo import PPOConfig

    keys = set(inspect.signature(PPOConfig.training).parameters)
    keys |= set(inspect.signature(AlgorithmConfig.training).parameters)
    internal = {
        "self",
        "kwargs",
        "model",
        "learner_class",
        "learner_connector",
        "learner_config_dict",
    }
    internal |= {"add_default_connectors_to_learner_pipeline"}
    # old API stack only or deprecated
    old = {"num_sgd_iter", "max_requests_in_flight_per_sampler_worker", "optimizer"}
    old |= {"train_batch_size", "lr_schedule", "entropy_coeff_schedule", "vf_share_layers"}
    return keys - internal - old


def build_ppo_config(cfg: TrainConfig, s: RLlibSettings, seed: int, env_name: str) -> Any:
    """The ``PPOConfig`` of a run: one shared module, the env registered as ``env_name``.

    Raises
    ------
    ValueError
        Unknown ``rllib.ppo`` or ``rllib.model`` keys (the message lists the valid ones).
    """
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    valid = _valid_training_keys()
    unknown = sorted(set(s.ppo) - valid)
    if unknown:
        raise ValueError(f"unknown rllib.ppo setting(s) {unknown}; valid settings: {sorted(valid)}")
    model_fields = {f.name for f in dataclasses.fields(DefaultModelConfig)}
    unknown = sorted(set(s.model) - model_fields)
    if unknown:
        raise ValueError(
            f"unknown rllib.model setting(s) {unknown}; valid settings: {sorted(model_fields)}"
        )
    return (
        PPOConfig()
        .framework("torch")
        .environment(
            env_name,
            env_config={
                "env_id": cfg.env_id,
                "env_kwargs": dict(cfg.env),
                "num_envs_per_env_runner": s.num_envs_per_env_runner,
            },
            disable_env_checking=True,
        )
        .env_runners(
            num_env_runners=s.num_env_runners,
            num_envs_per_env_runner=s.num_envs_per_env_runner,
            num_cpus_per_env_runner=s.num_cpus_per_env_runner,
            rollout_fragment_length=s.rollout_fragment_length,
        )
        .learners(num_learners=0)
        .multi_agent(policies={SHARED_POLICY}, policy_mapping_fn=map_to_shared_policy)
        .rl_module(model_config=DefaultModelConfig(**s.model))
        .training(**s.ppo)
        .callbacks(on_episode_end=_on_episode_end)
        .debugging(seed=int(seed), log_level="ERROR")
    )


# --------------------------------------------------------------------------------------------
# checkpoints
# --------------------------------------------------------------------------------------------


def is_rllib_checkpoint(path: str | Path) -> bool:
    """Whether ``path`` is a folder written by RLlib's ``save_to_path``."""
    return (Path(path) / "rllib_checkpoint.json").is_file()


def check_checkpoint(path: Path) -> dict[str, int]:
    """The counters of the RLlib checkpoint folder ``path``, after checking that it is one.

    Ray is not started: the folder must hold RLlib's ``rllib_checkpoint.json`` and this
    backend's :data:`STATE_FILE`, both readable JSON (checkpoint folders are written
    atomically, so a complete one has both).

    Raises
    ------
    ValueError
        It is not a complete RLlib checkpoint.
    """
    if not is_rllib_checkpoint(path):
        raise ValueError(f"{path} is not an RLlib checkpoint (no rllib_checkpoint.json)")
    try:
        json.loads((path / "rllib_checkpoint.json").read_text())
        data = json.loads((path / STATE_FILE).read_text())
        return {k: int(data.get(k, 0)) for k in _STATE_KEYS}
    except (OSError, ValueError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path} is not a complete checkpoint: {exc}") from exc


def find_latest_rllib_checkpoint(out: str | Path, final: tuple[int, Path] | None = None) -> Path:
    """The newest complete checkpoint in ``out/checkpoints`` (or ``final``, a finished run's
    final model, when it is newer); newer incomplete ones are skipped and named.

    Raises
    ------
    FileNotFoundError
        There is none.
    """
    folder = Path(out) / "checkpoints"
    candidates = checkpoint_candidates(folder, "rllib_*_steps", _CHECKPOINT_RE, final)
    return first_loadable(candidates, check_checkpoint, folder, "RLlib ")[0]


def resolve_resume(cfg: TrainConfig, finished: Mapping[str, Any] | None = None) -> Path | None:
    """The checkpoint folder ``cfg.resume`` names (``"latest"``: the newest complete one in
    ``cfg.out``, the final model of a ``finished`` run included).

    Raises
    ------
    FileNotFoundError
        No such checkpoint.
    ValueError
        The path is not an RLlib checkpoint folder.
    """
    if cfg.resume is None:
        return None
    if cfg.resume == "latest":
        final = None
        if finished is not None:
            final = (int(finished["num_timesteps"]), Path(cfg.out) / "final_model")
        return find_latest_rllib_checkpoint(cfg.out, final)
    p = Path(cfg.resume)
    if not p.exists():
        raise FileNotFoundError(f"checkpoint to resume from not found: {p}")
    if not is_rllib_checkpoint(p):
        raise ValueError(
            f"{p} is not an RLlib checkpoint (a folder with rllib_checkpoint.json); SB3 "
            "checkpoints (.zip) resume with --backend sb3"
        )
    check_checkpoint(p)
    return p


_STATE_KEYS: tuple[str, ...] = ("agent_steps", "env_steps", "iterations")


def _save(algo: Any, path: Path, state: Mapping[str, int]) -> Path:
    """Save ``algo`` and its counters to the checkpoint folder ``path``, atomically: into a
    temporary folder beside it, renamed into place when complete."""
    with atomic_path(path) as tmp:
        algo.save_to_path(str(tmp.absolute()))
        write_json(tmp / STATE_FILE, dict(state))
    return path


# --------------------------------------------------------------------------------------------
# training
# --------------------------------------------------------------------------------------------

_PROGRESS_COLUMNS: tuple[str, ...] = (
    "iteration",
    "agent_steps",
    "env_steps",
    "time_this_iter_s",
    "env_steps_per_s",
    "episode_return_mean",
    "episode_len_mean",
    "episodes",
    "nav_goal_rate",
    "nav_collision_rate",
    "nav_coop_error_mean_m",
    "rllib_env_steps_lifetime",
)


def _num(x: Any) -> float:
    """A plain float from RLlib's numbers, dicts of numbers (summed) or None (NaN)."""
    if isinstance(x, Mapping):
        return float(sum(_num(v) for v in x.values()))
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def _iteration_row(result: Mapping[str, Any]) -> dict[str, float]:
    er = result.get("env_runners") or {}
    env_steps = _num(er.get("num_env_steps_sampled"))
    agent_steps = _num(er.get("num_agent_steps_sampled"))
    dt = _num(result.get("time_this_iter_s"))
    return {
        "env_steps_iter": env_steps,
        "agent_steps_iter": agent_steps,
        "time_this_iter_s": dt,
        "env_steps_per_s": env_steps / dt if dt > 0 else math.nan,
        "episode_return_mean": _num(er.get("episode_return_mean")),
        "episode_len_mean": _num(er.get("episode_len_mean")),
        "episodes": _num(er.get("num_episodes")),
        "nav_goal_rate": _num(er.get("nav_goal_rate")),
        "nav_collision_rate": _num(er.get("nav_collision_rate")),
        "nav_coop_error_mean_m": _num(er.get("nav_coop_error_mean_m")),
        # RLlib's own counter (restored from a checkpoint with the algorithm's state)
        "rllib_env_steps_lifetime": _num(er.get("num_env_steps_sampled_lifetime")),
    }


def check(cfg: TrainConfig) -> RLlibSettings:
    """Check the settings only this backend reads (``rllib``), before any work; returns them.

    Raises
    ------
    ValueError
        A bad ``rllib`` setting, or a seed whose env seeds would reach the held-out ones.
    """
    s = RLlibSettings.from_dict(cfg.rllib)
    # env seeds: seed + i E + j for runner i <= num_env_runners and copy j < E
    span = (s.num_env_runners + 1) * s.num_envs_per_env_runner
    if cfg.seed + span > EVAL_SEED_START:
        raise ValueError(
            f"seed {cfg.seed} + (env runners + 1) x envs per runner must stay below "
            f"{EVAL_SEED_START} (the held-out evaluation seeds), got {cfg.seed + span}"
        )
    return s


def train(cfg: TrainConfig) -> Path:
    """Train one PPO policy shared by every UAV on Ray RLlib; return the final checkpoint.

    Parameters
    ----------
    cfg : coopnav_env.training.config.TrainConfig
        ``backend`` is not read; ``cfg.rllib`` holds the :class:`RLlibSettings`.

    Returns
    -------
    pathlib.Path
        ``cfg.out / "final_model"`` (an RLlib checkpoint folder).

    Raises
    ------
    ImportError
        Ray RLlib is not installed (the message names the extra to install).
    ValueError
        Bad settings (negative runners, unknown PPO keys, seed too large, ...).
    FileNotFoundError
        ``cfg.resume`` names a checkpoint that does not exist.
    ConnectionError
        ``rllib.address`` cannot be reached.
    KeyboardInterrupt
        Re-raised after writing a checkpoint (``checkpoints/rllib_<N>_steps``).
    """
    s = check(cfg)
    span = (s.num_env_runners + 1) * s.num_envs_per_env_runner
    ray = import_rllib()
    import numpy as np
    import torch

    out = Path(cfg.out)
    probe = make_env_fn(cfg.env_id, cfg.env)()  # validates the env kwargs before any output
    n_agents = len(probe.possible_agents)
    probe.close()
    env_name = f"coopnav_{re.sub(r'[^A-Za-z0-9_]+', '_', cfg.env_id)}"
    build_ppo_config(cfg, s, cfg.seed, env_name)  # checks the PPO and model settings

    with open_run(cfg) as run:
        if cfg.resume == "latest" and run.nothing_to_do(cfg.timesteps):
            run.say_finished()
            return out / "final_model"
        resume_path = resolve_resume(cfg, run.finished)
        start = check_checkpoint(resume_path) if resume_path else dict.fromkeys(_STATE_KEYS, 0)
        if resume_path is not None:
            check_same_environment(cfg, out / "config.yaml")
        seed = cfg.seed
        if start["agent_steps"]:
            seed = (cfg.seed + start["agent_steps"]) % (EVAL_SEED_START - span)
        config = build_ppo_config(cfg, s, seed, env_name)

        torch.set_num_threads(cfg.torch_threads)
        resolved = {k: v for k, v in cfg.to_dict().items() if k not in SB3_ONLY_KEYS}
        resolved["backend"] = "rllib"
        resolved["rllib"] = s.to_dict()
        resolved["resume"] = str(resume_path) if resume_path else None
        resolved["agent_steps_per_env_step"] = n_agents
        n0 = start["agent_steps"]
        write_yaml(out / ("config.yaml" if n0 == 0 else f"config_resumed_at_{n0}.yaml"), resolved)

        logs = out / "logs"
        logs.mkdir(exist_ok=True)
        counters = dict(start)
        setup_t0 = time.perf_counter()
        training = False
        try:
            with (
                ray_session(s, out) as session,
                tempfile.TemporaryDirectory(prefix="coopnav-rllib-") as trial_tmp,
            ):
                from ray.tune.registry import register_env

                install_interrupt_handlers()  # again: ray.init installs its own SIGTERM handler
                register_env(env_name, make_rllib_env)
                with _trainable_logdir_in(Path(trial_tmp)), _quiet_rllib():
                    algo = config.build_algo()
                try:
                    if resume_path is not None:
                        algo.restore_from_path(str(resume_path.absolute()))
                    setup_s = time.perf_counter() - setup_t0
                    training = True  # from here on an interrupt writes a checkpoint
                    wall_s = _train_loop(cfg, algo, out, logs / "progress.csv", counters, n_agents)
                    final = _save(algo, out / "final_model", counters)
                finally:
                    algo.stop()
        except KeyboardInterrupt:
            if not training:
                print(
                    "\ninterrupted while starting Ray and building the algorithm: no checkpoint "
                    f"(nothing was trained in this session); {out / 'config.yaml'} was written",
                    file=sys.stderr,
                )
            raise
        done_agent = counters["agent_steps"] - start["agent_steps"]
        done_env = counters["env_steps"] - start["env_steps"]
        import gymnasium

        info = {
            "backend": "rllib",
            "final_model": str(final),
            "seed": cfg.seed,
            "num_timesteps": counters["agent_steps"],
            "env_steps": counters["env_steps"],
            "iterations": counters["iterations"],
            "session_agent_steps": done_agent,
            "session_env_steps": done_env,
            "session_iterations": counters["iterations"] - start["iterations"],
            "session_wall_s": round(wall_s, 3),
            "setup_s": round(setup_s, 3),
            "agent_steps_per_s": round(done_agent / wall_s, 1) if wall_s > 0 else None,
            "env_steps_per_s": round(done_env / wall_s, 1) if wall_s > 0 else None,
            "num_env_runners": s.num_env_runners,
            "num_envs_per_env_runner": s.num_envs_per_env_runner,
            "train_batch_size_per_learner": int(config.train_batch_size_per_learner),
            "ray": {k: session.get(k) for k in ("address", "temp_dir", "cluster_cpus")},
            "resumed_from": str(resume_path) if resume_path else None,
            "versions": {
                "python": sys.version.split()[0],
                "numpy": np.__version__,
                "torch": torch.__version__,
                "ray": ray.__version__,
                "gymnasium": gymnasium.__version__,
            },
        }
        write_json(out / "run.json", info)
        return final


def _train_loop(
    cfg: TrainConfig,
    algo: Any,
    out: Path,
    progress: Path,
    counters: dict[str, int],
    n_agents: int,
) -> float:
    """Run iterations until ``cfg.timesteps`` agent-steps; returns the wall time [s].

    Updates ``counters`` in place; writes checkpoints and one progress row per iteration.
    """
    writer = None
    try:
        from tensorboardX import SummaryWriter

        writer = SummaryWriter(str(progress.parent))
    except ImportError:  # pragma: no cover - tensorboardX comes with ray[rllib]
        pass
    last_ckpt = counters["agent_steps"]
    t0 = time.perf_counter()
    # one learning curve over resumed sessions: the rows after the checkpoint are dropped
    log = ProgressLog(
        progress, "agent_steps", resumed_at=last_ckpt or None, columns=_PROGRESS_COLUMNS
    )
    try:
        while counters["agent_steps"] < cfg.timesteps:
            row = _iteration_row(algo.train())
            if not row["env_steps_iter"] > 0:
                raise RuntimeError(f"RLlib reported no sampled env-steps: {row}")
            if not math.isfinite(row["agent_steps_iter"]):  # every UAV stepped each time
                row["agent_steps_iter"] = row["env_steps_iter"] * n_agents
            counters["iterations"] += 1
            counters["agent_steps"] += int(row["agent_steps_iter"])
            counters["env_steps"] += int(row["env_steps_iter"])
            row.update(
                iteration=counters["iterations"],
                agent_steps=counters["agent_steps"],
                env_steps=counters["env_steps"],
            )
            log.append({k: _csv(row[k]) for k in _PROGRESS_COLUMNS if k in row})
            if writer is not None:
                for k in _PROGRESS_COLUMNS[3:]:
                    if math.isfinite(row[k]):
                        writer.add_scalar(f"rllib/{k}", row[k], counters["agent_steps"])
            if cfg.progress_bar:
                print(
                    f"iteration {counters['iterations']}: {counters['agent_steps']} / "
                    f"{cfg.timesteps} agent-steps, {row['env_steps_per_s']:.0f} env-steps/s,"
                    f" return {row['episode_return_mean']:.2f}",
                    file=sys.stderr,
                )
            n = counters["agent_steps"]
            freq = cfg.checkpoint_freq
            if freq > 0 and n // freq > last_ckpt // freq:
                _save(algo, out / "checkpoints" / f"rllib_{n}_steps", counters)
                last_ckpt = n
    except KeyboardInterrupt:
        path = out / "checkpoints" / f"rllib_{counters['agent_steps']}_steps"
        _save(algo, path, counters)
        print(
            f"\ninterrupted: checkpoint written to {path}; continue with --resume {path}",
            file=sys.stderr,
        )
        raise
    finally:
        if writer is not None:
            writer.close()
    return time.perf_counter() - t0


def _csv(v: Any) -> Any:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else round(v, 6)
    return v
