"""``coopnav train``: PPO with parameter sharing across the UAVs of ``urban_canyon_v0``.

One Stable-Baselines3 PPO policy drives every UAV: SuperSuit turns the PettingZoo swarm into
a vector env with one slot per UAV and concatenates ``n_envs`` swarms
(:mod:`training.vec_env`, which also makes ``PPO(seed=...)`` work and repeat exactly).
``--backend rllib`` trains on Ray RLlib instead, with env runners on a Ray cluster
(:mod:`training.rllib_train`, same configuration file and output layout).

Hyperparameters come from ``training/configs/ppo.yaml`` (section ``urban_canyon_v0``) and
can be overridden from the command line. Everything a run produces goes to ``--out DIR``::

    DIR/config.yaml              the resolved configuration, seed included
                                 (a resumed session adds config_resumed_at_<N>.yaml)
    DIR/run.json                 versions, wall time, agent-steps per second
    DIR/final_model.zip          the trained policy (``agents.ppo`` / ``ppo:DIR/final_model.zip``)
    DIR/checkpoints/ppo_<N>_steps.zip   periodic checkpoints (N agent-steps)
    DIR/logs/                    TensorBoard events and progress*.csv (learning curve)
    DIR/*monitor.csv             one line per finished UAV-episode (return, length, final infos)

``--resume CHECKPOINT`` (or ``--resume latest``) continues an interrupted run: the model, its
optimizer state and its step count are loaded, and training runs until ``timesteps``
agent-steps in total. Checkpoints are written at the start of a rollout, right after a
policy update, so resuming from one loses no collected experience; Ctrl-C (or SIGTERM) also
writes one, at the step count of the last completed update.

Seeds: training resets its swarm copies with ``seed + k`` (``k < n_envs``), then each copy
continues its own generator; a resumed run reseeds with ``seed + num_timesteps`` (modulo the
training seed range) so it does not replay its first episodes. Training seeds are kept below
:data:`training.evaluate.EVAL_SEED_START`, where the held-out evaluation seeds begin.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import importlib
import json
import math
import re
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from training.evaluate import EVAL_SEED_START

__all__ = [
    "DEFAULT_CONFIG_PATH",
    "TrainConfig",
    "add_arguments",
    "apply_overrides",
    "behaviour_clone",
    "find_latest_checkpoint",
    "load_config",
    "make_env_fn",
    "run",
    "train",
]

DEFAULT_CONFIG_PATH: Path = Path(__file__).resolve().parent / "configs" / "ppo.yaml"
"""The packaged hyperparameter file (one section per environment id)."""

DEFAULT_ENV_ID: str = "urban_canyon_v0"

BACKENDS: tuple[str, ...] = ("sb3", "rllib")
"""Training backends: Stable-Baselines3 (default) and Ray RLlib (``training.rllib_train``)."""

_CHECKPOINT_RE = re.compile(r"_(\d+)_steps\.zip$")

_VEC_ENVS: tuple[str, ...] = ("auto", "supersuit", "batched")
"""Values of ``TrainConfig.vec_env``: ``"auto"`` or a kind of ``training.vec_env.VEC_ENV_KINDS``
(listed here without importing SB3)."""

_PRETRAIN_DEFAULTS: dict[str, Any] = {
    "policy": "waypoint",
    "policy_kwargs": {},
    "episodes": 60,
    "epochs": 30,
    "learning_rate": 1e-3,
}
"""Settings of the optional behaviour-cloning warm start (``pretrain``)."""

_MONITOR_INFO_KEYS: tuple[str, ...] = (
    "in_goal",
    "goal_reached",
    "collided",
    "nav_error_m",
    "coop_error_m",
    "goal_distance_m",
)
"""Final-step infos written to ``monitor*.csv`` for each UAV-episode (those the env has)."""


# --------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run.

    Parameters
    ----------
    out : str
        Output directory (created).
    env_id : str, default "urban_canyon_v0"
        A module ``coopnav_env.<env_id>`` with a ``parallel_env`` function, or
        ``"package.module:callable"`` returning a PettingZoo ParallelEnv (used by the tests).
    timesteps : int, default 1_000_000
        Total agent-steps to train for (SB3 timesteps under parameter sharing), >= 1.
    seed : int, default 0
        Seed of PPO (torch, numpy) and of the environments, in
        ``[0, EVAL_SEED_START - n_envs]``.
    n_envs : int, default 2
        Swarm copies stepped together, >= 1.
    num_cpus : int, default 1
        Worker processes for the swarm copies, >= 0 (0 and 1: all in this process).
    vec_env : {"auto", "supersuit", "batched"}, default "auto"
        How the swarm copies become one SB3 vector environment
        (:func:`~training.vec_env.make_vec_env`): SuperSuit's per-agent adapters (any
        environment, worker processes allowed), or ``urban_canyon_v0``'s batched vector
        environment (one process; the same observations, rewards and seeding bit for bit, so
        the same training). ``"auto"`` takes the batched one where it applies
        (``urban_canyon_v0`` with ``num_cpus`` 0 or 1 and no render mode), SuperSuit otherwise
        (:meth:`vec_env_kind`); ``benchmarks/bench_env.py`` measures both (the batched one
        steps 64 copies about 1.5x as fast; see ``docs/performance.md``).
    checkpoint_freq : int, default 50_000
        Agent-steps between checkpoints, >= 0 (0 disables periodic checkpoints).
    torch_threads : int, default 1
        Threads PyTorch may use, >= 1.
    device : str, default "cpu"
        PyTorch device.
    env : dict
        Keyword arguments of the environment (``UrbanCanyonConfig`` fields, ``n_uavs``,
        ``max_steps``); unknown keys are rejected by the environment.
    ppo : dict
        Keyword arguments of ``stable_baselines3.PPO`` (``policy`` included, default
        ``"MlpPolicy"``); unknown keys raise ``ValueError``.
    resume : str or None, default None
        Checkpoint to continue from, or ``"latest"`` for the newest one in ``out``.
    normalize_reward : bool, default False
        Scale the rewards PPO learns from by a running estimate of the standard deviation of
        the discounted return (SB3 ``VecNormalize(norm_obs=False, norm_reward=True)``, with
        PPO's ``gamma``). Observations are not normalised, so the saved policy needs nothing
        else at inference; episode returns in the logs and ``monitor.csv`` stay unscaled. A
        resumed run restarts the running estimate.
    pretrain : dict or None, default None
        Behaviour cloning before PPO (:func:`behaviour_clone`): ``policy`` (a
        :func:`agents.make_policy` name, e.g. ``"waypoint"``) and its ``policy_kwargs``,
        ``episodes`` (teacher episodes on training seeds), ``epochs`` and ``learning_rate``.
        The policy's mean action is fitted to the teacher's actions (its log-std keeps
        ``log_std_init``) and the value network to the teacher's discounted returns, so that
        PPO starts from a policy that flies the route instead of discovering flight between
        walls by trial and crash. Skipped on resume.
    progress_bar : bool, default True
    verbose : int, default 0
        SB3 verbosity (1 prints the training table).
    backend : {"sb3", "rllib"}, default "sb3"
        Stable-Baselines3 in this process (:func:`train`), or Ray RLlib with env runners on
        a Ray cluster (:func:`training.rllib_train.train_rllib`, needs the ``ray`` extra).
    rllib : dict
        Settings of the RLlib backend (:class:`training.rllib_train.RLlibSettings`: env
        runners, Ray address, ``ppo`` and ``model``); the SB3 backend ignores them.
    """

    out: str
    env_id: str = DEFAULT_ENV_ID
    timesteps: int = 1_000_000
    seed: int = 0
    n_envs: int = 2
    num_cpus: int = 1
    vec_env: str = "auto"
    checkpoint_freq: int = 50_000
    torch_threads: int = 1
    device: str = "cpu"
    env: dict[str, Any] = field(default_factory=dict)
    ppo: dict[str, Any] = field(default_factory=dict)
    resume: str | None = None
    normalize_reward: bool = False
    pretrain: dict[str, Any] | None = None
    progress_bar: bool = True
    verbose: int = 0
    backend: str = "sb3"
    rllib: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        def _int(name: str, lo: int, hi: int | None = None) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int):
                raise ValueError(f"TrainConfig.{name} must be an integer, got {v!r}")
            if v < lo or (hi is not None and v > hi):
                rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
                raise ValueError(f"TrainConfig.{name} must be {rng}, got {v}")

        _int("timesteps", 1)
        _int("n_envs", 1)
        _int("seed", 0, EVAL_SEED_START - self.n_envs)
        _int("num_cpus", 0)
        if self.vec_env not in _VEC_ENVS:
            raise ValueError(
                f"TrainConfig.vec_env must be one of {list(_VEC_ENVS)}, got {self.vec_env!r}"
            )
        if self.vec_env == "batched" and self.num_cpus > 1:
            raise ValueError(
                "TrainConfig.vec_env 'batched' steps every swarm copy in this process: "
                f"num_cpus must be 0 or 1, got {self.num_cpus}"
            )
        _int("checkpoint_freq", 0)
        _int("torch_threads", 1)
        _int("verbose", 0, 2)
        if not isinstance(self.normalize_reward, bool):
            raise ValueError(
                f"TrainConfig.normalize_reward must be true or false, got {self.normalize_reward!r}"
            )
        if not str(self.out):
            raise ValueError("TrainConfig.out must be a directory path")
        if self.backend not in BACKENDS:
            raise ValueError(
                f"TrainConfig.backend must be one of {list(BACKENDS)}, got {self.backend!r}"
            )
        if self.rllib is None:
            object.__setattr__(self, "rllib", {})
        for name in ("env", "ppo", "rllib"):
            if not isinstance(getattr(self, name), Mapping):
                raise ValueError(
                    f"TrainConfig.{name} must be a mapping, got {getattr(self, name)!r}"
                )
        object.__setattr__(self, "env", dict(self.env))
        object.__setattr__(self, "ppo", dict(self.ppo))
        object.__setattr__(self, "rllib", dict(self.rllib))
        if self.pretrain is not None:
            if not isinstance(self.pretrain, Mapping):
                raise ValueError(f"TrainConfig.pretrain must be a mapping, got {self.pretrain!r}")
            unknown = sorted(set(self.pretrain) - set(_PRETRAIN_DEFAULTS))
            if unknown:
                raise ValueError(
                    f"unknown pretrain setting(s) {unknown}; valid: {sorted(_PRETRAIN_DEFAULTS)}"
                )
            pre = {**_PRETRAIN_DEFAULTS, **self.pretrain}
            object.__setattr__(self, "pretrain", pre)
            if not isinstance(pre["policy"], str) or not pre["policy"]:
                raise ValueError(f"pretrain.policy must be a policy name, got {pre['policy']!r}")
            if not isinstance(pre["policy_kwargs"], Mapping):
                raise ValueError(
                    f"pretrain.policy_kwargs must be a mapping, got {pre['policy_kwargs']!r}"
                )
            for key, lo in (("episodes", 1), ("epochs", 0)):
                if not isinstance(pre[key], int) or isinstance(pre[key], bool) or pre[key] < lo:
                    raise ValueError(f"pretrain.{key} must be an integer >= {lo}, got {pre[key]!r}")
            lr = pre["learning_rate"]
            if isinstance(lr, bool) or not isinstance(lr, (int, float)) or not 0 < lr < math.inf:
                raise ValueError(f"pretrain.learning_rate must be > 0, got {lr!r}")
            # the teacher's episodes (seeds EVAL_SEED_START // 2 + seed + i) must stay below the
            # held-out evaluation seeds
            last = EVAL_SEED_START // 2 + self.seed + pre["episodes"]
            if last > EVAL_SEED_START:
                raise ValueError(
                    f"pretrain: the teacher's episode seeds {EVAL_SEED_START // 2 + self.seed}.."
                    f"{last - 1} would reach the held-out evaluation seeds (>= {EVAL_SEED_START}); "
                    f"lower seed ({self.seed}) or pretrain.episodes ({pre['episodes']})"
                )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        """Build from a mapping; unknown keys raise ``ValueError`` listing the valid ones."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(
                f"unknown training setting(s) {unknown}; valid settings: {sorted(names)}"
            )
        return cls(**dict(data))

    def vec_env_kind(self) -> str:
        """The vector environment :func:`train` builds: ``vec_env``, with ``"auto"`` resolved to
        ``"batched"`` for ``urban_canyon_v0`` in one process (``num_cpus`` 0 or 1) without a
        render mode, and to ``"supersuit"`` otherwise (another environment, worker processes,
        or rendering, which the batched one does not do)."""
        if self.vec_env != "auto":
            return self.vec_env
        batched = (
            self.env_id == DEFAULT_ENV_ID
            and self.num_cpus <= 1
            and self.env.get("render_mode") is None
        )
        return "batched" if batched else "supersuit"

    def to_dict(self) -> dict[str, Any]:
        """A plain (YAML-serialisable) copy."""
        return copy.deepcopy(dataclasses.asdict(self))


def load_config(path: str | Path | None = None, env_id: str = DEFAULT_ENV_ID) -> dict[str, Any]:
    """The section ``env_id`` of a YAML hyperparameter file, as a plain dict.

    Parameters
    ----------
    path : path or None
        YAML file with one top-level key per environment; None for
        :data:`DEFAULT_CONFIG_PATH`.
    env_id : str, default "urban_canyon_v0"
        Section to read. A ``module:callable`` env id falls back to the default section.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file holds no such section.
    """
    import yaml

    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    if not p.is_file():
        raise FileNotFoundError(f"hyperparameter file not found: {p}")
    data = yaml.safe_load(p.read_text()) or {}
    key = env_id if env_id in data or ":" not in env_id else DEFAULT_ENV_ID
    if key not in data:
        raise ValueError(f"{p} has no section {env_id!r}; sections: {sorted(data)}")
    section = copy.deepcopy(data[key]) or {}
    section.setdefault("env_id", env_id)
    return section


def apply_overrides(config: Mapping[str, Any], items: Sequence[str]) -> dict[str, Any]:
    """Apply ``key=value`` overrides with dotted keys (``ppo.learning_rate=1e-4``).

    Values are parsed as YAML (``3``, ``1e-4``, ``true``, ``[64, 64]``, ``null``). Nested
    mappings are created as needed; the input is not modified.

    Raises
    ------
    ValueError
        An item without ``=`` or with an empty key.
    """
    import yaml

    out = copy.deepcopy(dict(config))
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise ValueError(f"override {item!r} must look like key=value (dotted keys allowed)")
        value = yaml.safe_load(raw) if raw.strip() else ""
        # YAML 1.1 reads "1e-4" as a string; accept it as a float
        if isinstance(value, str):
            try:
                value = float(value) if re.fullmatch(r"[-+]?[\d.]+[eE][-+]?\d+", value) else value
            except ValueError:
                pass
        node = out
        parts = key.split(".")
        for part in parts[:-1]:
            nxt = node.get(part)
            if not isinstance(nxt, dict):
                nxt = {}
                node[part] = nxt
            node = nxt
        node[parts[-1]] = value
    return out


def make_env_fn(env_id: str, env_kwargs: Mapping[str, Any]) -> Callable[[], Any]:
    """A picklable function returning a fresh ParallelEnv for ``env_id`` and its kwargs."""
    import functools

    if ":" in env_id:
        mod_name, _, attr = env_id.partition(":")
        factory = getattr(importlib.import_module(mod_name), attr)
    else:
        try:
            mod = importlib.import_module(f"coopnav_env.{env_id}")
        except ModuleNotFoundError as exc:
            raise ValueError(
                f"unknown environment {env_id!r} (no module coopnav_env.{env_id})"
            ) from exc
        factory = mod.parallel_env
    return functools.partial(factory, **dict(env_kwargs))


def find_latest_checkpoint(out: str | Path) -> Path:
    """The checkpoint with the most steps in ``out/checkpoints``.

    Raises
    ------
    FileNotFoundError
        There is none.
    """
    return latest_numbered(Path(out) / "checkpoints", "*_steps.zip", _CHECKPOINT_RE, "")


def latest_numbered(
    folder: Path, glob: str, pattern: re.Pattern[str], kind: str, valid: Any = None
) -> Path:
    """The entry of ``folder`` matching ``glob`` whose ``pattern`` group 1 is largest.

    ``valid`` (optional) filters candidates; ``kind`` names them in the error message.

    Raises
    ------
    FileNotFoundError
        There is none.
    """
    found = []
    for p in folder.glob(glob):
        m = pattern.search(p.name)
        if m and (valid is None or valid(p)):
            found.append((int(m.group(1)), p))
    if not found:
        raise FileNotFoundError(f"no {kind}checkpoint to resume from in {folder}")
    return max(found)[1]


def _resolve_resume(cfg: TrainConfig) -> Path | None:
    if cfg.resume is None:
        return None
    if cfg.resume == "latest":
        return find_latest_checkpoint(cfg.out)
    p = Path(cfg.resume)
    if not p.is_file() and p.with_suffix(".zip").is_file():
        p = p.with_suffix(".zip")
    if not p.is_file():
        raise FileNotFoundError(f"checkpoint to resume from not found: {p}")
    return p


# --------------------------------------------------------------------------------------------
# callbacks (SB3 imported lazily: this module is imported by `coopnav --help`)
# --------------------------------------------------------------------------------------------


def _callbacks() -> tuple[Any, Any, Any]:
    """(navigation metrics, rollout checkpoint, progress bar) callback classes bound to SB3."""
    import numpy as np
    from stable_baselines3.common.callbacks import BaseCallback

    from coopnav_env.envs.urban_canyon import fix_error_m

    class NavMetricsCallback(BaseCallback):
        """Log navigation figures of each rollout to TensorBoard (``nav/...``).

        Reads ``infos`` of every agent-step: mean and median cooperative 3-D error,
        P(error < 3 m) (a step without a cooperative fix counts as a failure), mean
        satellites received; and, over the swarm episodes that ended in the rollout, the
        goal rate (every UAV in the goal area: ``in_goal``) and the collision rate (some UAV
        ``collided``). Vector slots ``k * n_agents .. (k + 1) * n_agents - 1`` are the UAVs
        of swarm copy ``k`` (see :mod:`training.vec_env`); they finish together.
        """

        def __init__(self, n_agents: int):
            super().__init__()
            self.n_agents = int(n_agents)

        def _on_rollout_start(self) -> None:
            self._err: list[float] = []
            self._sats: list[float] = []
            self._ended = 0
            self._goals = 0
            self._crashes = 0

        def _on_step(self) -> bool:
            infos = self.locals.get("infos", ())
            dones = np.asarray(self.locals.get("dones", np.zeros(len(infos), dtype=bool)))
            for info in infos:
                if info.get("coop_error_m") is not None:
                    self._err.append(fix_error_m(info, "coop_error_m"))
                n = info.get("n_sats")
                if n is not None:
                    self._sats.append(float(n))
            n = self.n_agents
            for k in range(len(infos) // n):
                if not dones[k * n]:
                    continue
                swarm = infos[k * n : (k + 1) * n]
                self._ended += 1
                self._goals += all(
                    bool(i.get("in_goal", i.get("goal_reached", False))) for i in swarm
                )
                self._crashes += any(bool(i.get("collided", False)) for i in swarm)
            return True

        def _on_rollout_end(self) -> None:
            err = np.asarray(self._err, dtype=float)
            fin = err[np.isfinite(err)]
            if err.size:
                self.logger.record("nav/p_coop_error_lt_3m", float(np.mean(err < 3.0)))
            if fin.size:
                self.logger.record("nav/coop_error_mean_m", float(fin.mean()))
                self.logger.record("nav/coop_error_median_m", float(np.median(fin)))
            if self._sats:
                self.logger.record("nav/n_sats_mean", float(np.mean(self._sats)))
            if self._ended:
                self.logger.record("nav/goal_rate", self._goals / self._ended)
                self.logger.record("nav/collision_rate", self._crashes / self._ended)
                self.logger.record("nav/episodes", self._ended)

    class RolloutCheckpointCallback(BaseCallback):
        """Save ``ppo_<N>_steps.zip`` every ``freq`` agent-steps, right after an update.

        Saving at the start of a rollout (not in the middle of one, as SB3's
        ``CheckpointCallback`` does) means a checkpoint holds the policy trained on every
        step it counts: resuming loses no collected experience.
        """

        def __init__(self, freq: int, folder: Path):
            super().__init__()
            self.freq = int(freq)
            self.folder = folder
            self.rollout_start_timesteps = 0
            self.collecting = False
            self._last = -1

        def _init_callback(self) -> None:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._last = self.model.num_timesteps

        def save(self, num_timesteps: int | None = None) -> Path:
            """Save now (optionally under a smaller step count) and return the path."""
            n = self.model.num_timesteps if num_timesteps is None else int(num_timesteps)
            path = self.folder / f"ppo_{n}_steps.zip"
            saved = self.model.num_timesteps
            self.model.num_timesteps = n
            try:
                self.model.save(path)
            finally:
                self.model.num_timesteps = saved
            return path

        def _on_rollout_start(self) -> None:
            self.collecting = True
            self.rollout_start_timesteps = self.model.num_timesteps
            n = self.model.num_timesteps
            if self.freq > 0 and n // self.freq > max(self._last, 0) // self.freq and n > 0:
                self.save()
                self._last = n

        def _on_rollout_end(self) -> None:
            self.collecting = False

        def _on_step(self) -> bool:
            return True

    class ProgressCallback(BaseCallback):
        """A plain ``tqdm`` progress bar over agent-steps, with the latest episode return.

        SB3's own bar needs ``rich``; this one needs only ``tqdm`` (and prints nothing when
        that is missing).
        """

        def _on_training_start(self) -> None:
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - tqdm is a training dependency
                self.bar = None
                return
            # PPO collects whole rollouts: the run ends at the next multiple of one rollout
            rollout = max(int(getattr(self.model, "n_steps", 1)) * self.training_env.num_envs, 1)
            todo = self.locals["total_timesteps"] - self.model.num_timesteps
            self.bar = tqdm(
                total=-(-todo // rollout) * rollout,
                unit="agent-step",
                unit_scale=True,
                dynamic_ncols=True,
                smoothing=0.1,
                mininterval=0.5,
            )

        def _on_step(self) -> bool:
            if self.bar is not None:
                self.bar.update(self.training_env.num_envs)
            return True

        def _on_rollout_end(self) -> None:
            buf = self.model.ep_info_buffer
            if self.bar is not None and buf:
                self.bar.set_postfix(ep_return=f"{np.mean([e['r'] for e in buf]):.2f}")

        def _on_training_end(self) -> None:
            if self.bar is not None:
                self.bar.close()

    return NavMetricsCallback, RolloutCheckpointCallback, ProgressCallback


# --------------------------------------------------------------------------------------------
# training
# --------------------------------------------------------------------------------------------


def behaviour_clone(
    model: Any, env_fn: Callable[[], Any], spec: Mapping[str, Any], seed: int = 0
) -> dict[str, Any]:
    """Fit a fresh PPO model to a teacher policy (behaviour cloning) before PPO starts.

    The teacher flies ``spec["episodes"]`` episodes of the training environment (reset seeds
    ``EVAL_SEED_START // 2 + seed + i``, below the held-out evaluation seeds). The actor's
    mean action is fitted to the teacher's actions (mean squared error; the log-std is left
    at ``log_std_init``, so PPO keeps exploring), and the critic to the teacher's discounted
    returns (``gamma`` of the model; rewards scaled like ``VecNormalize`` when the model's
    environment normalises them), for ``spec["epochs"]`` passes with Adam.

    Returns
    -------
    dict
        Samples, teacher goal rate and final losses (written to ``pretrain.json``).
    """
    import numpy as np
    import torch

    from agents import make_policy

    env = env_fn()
    teacher = make_policy(str(spec["policy"]), env, **dict(spec.get("policy_kwargs") or {}))
    gamma = float(model.gamma)
    obs_all: list[np.ndarray] = []
    act_all: list[np.ndarray] = []
    ret_all: list[np.ndarray] = []
    goals = 0
    for i in range(int(spec["episodes"])):
        ep_seed = EVAL_SEED_START // 2 + seed + i
        obs, _ = env.reset(seed=ep_seed)
        teacher.reset(seed=ep_seed)
        ep_obs, ep_act, ep_rew = [], [], []
        infos: dict[str, Any] = {}
        while env.agents:
            agents = list(env.agents)
            act = teacher.act(obs)
            ep_obs.append(np.stack([obs[a] for a in agents]))
            ep_act.append(np.stack([np.clip(act[a], -1.0, 1.0) for a in agents]))
            obs, rew, _te, _tr, infos = env.step(act)
            ep_rew.append(np.array([rew[a] for a in agents]))
        goals += bool(infos) and all(bool(v.get("in_goal", False)) for v in infos.values())
        rets = np.zeros_like(np.stack(ep_rew))
        acc = np.zeros(rets.shape[1])
        for t in range(len(ep_rew) - 1, -1, -1):
            acc = ep_rew[t] + gamma * acc
            rets[t] = acc
        obs_all += ep_obs
        act_all += ep_act
        ret_all.append(rets.reshape(-1))
    env.close()
    x = torch.as_tensor(np.concatenate(obs_all), dtype=torch.float32, device=model.device)
    y = torch.as_tensor(np.concatenate(act_all), dtype=torch.float32, device=model.device)
    r = np.concatenate(ret_all)
    ret_scale = float(np.std(r)) if getattr(model.get_env(), "norm_reward", False) else 1.0
    v = torch.as_tensor(r / max(ret_scale, 1e-8), dtype=torch.float32, device=model.device)
    policy = model.policy
    params = [p for name, p in policy.named_parameters() if name != "log_std"]
    opt = torch.optim.Adam(params, lr=float(spec["learning_rate"]))
    gen = torch.Generator().manual_seed(int(seed))
    batch = 256
    pi_loss = vf_loss = float("nan")
    policy.set_training_mode(True)
    for _ in range(int(spec["epochs"])):
        perm = torch.randperm(x.shape[0], generator=gen)
        for k in range(0, x.shape[0], batch):
            idx = perm[k : k + batch]
            features = policy.extract_features(x[idx])
            if isinstance(features, tuple):  # separate actor/critic feature extractors
                latent_pi = policy.mlp_extractor.forward_actor(features[0])
                latent_vf = policy.mlp_extractor.forward_critic(features[1])
            else:
                latent_pi, latent_vf = policy.mlp_extractor(features)
            mean = policy.action_net(latent_pi)
            value = policy.value_net(latent_vf).squeeze(-1)
            loss_pi = torch.mean((mean - y[idx]) ** 2)
            loss_vf = torch.mean((value - v[idx]) ** 2)
            opt.zero_grad()
            (loss_pi + 0.5 * loss_vf).backward()
            opt.step()
            pi_loss, vf_loss = loss_pi.item(), loss_vf.item()
    policy.set_training_mode(False)
    return {
        "teacher": str(spec["policy"]),
        "episodes": int(spec["episodes"]),
        "samples": int(x.shape[0]),
        "teacher_goal_rate": goals / max(int(spec["episodes"]), 1),
        "return_scale": ret_scale,
        "final_action_mse": pi_loss,
        "final_value_mse": vf_loss,
    }


def _terminate_as_interrupt() -> Any:
    """Make SIGTERM (a scheduler stopping the job) behave like Ctrl-C; return the old handler.

    Returns None (and changes nothing) outside the main thread, where handlers can't be set.
    """
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def _raise(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    return signal.signal(signal.SIGTERM, _raise)


def _check_same_environment(cfg: TrainConfig, saved: Path) -> None:
    """Refuse to resume in ``cfg.out`` with other environment settings than it was started.

    Raises
    ------
    ValueError
        ``saved`` (the run's ``config.yaml``) names another ``env_id`` or ``env``.
    """
    import yaml

    if not saved.is_file():
        return
    old = yaml.safe_load(saved.read_text()) or {}
    if old.get("env_id") != cfg.env_id or (old.get("env") or {}) != cfg.env:
        raise ValueError(
            f"cannot resume in {cfg.out}: it was trained on {old.get('env_id')} with "
            f"{old.get('env') or {}}, not {cfg.env_id} with {cfg.env}; repeat the original "
            "settings, or use a new --out to fine-tune in another environment"
        )


def _write_yaml(path: Path, data: Any) -> None:
    import yaml

    path.write_text(yaml.safe_dump(data, sort_keys=False))


def train(cfg: TrainConfig) -> Path:
    """Train a parameter-sharing PPO policy and return the path of the final model.

    Parameters
    ----------
    cfg : TrainConfig

    Returns
    -------
    pathlib.Path
        ``cfg.out / "final_model.zip"``.

    Raises
    ------
    FileNotFoundError
        ``cfg.resume`` names a checkpoint that does not exist.
    ValueError
        Unknown environment or PPO setting.
    KeyboardInterrupt
        Re-raised after writing a checkpoint (``checkpoints/ppo_<N>_steps.zip``).
    """
    import inspect

    import numpy as np
    import stable_baselines3
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat
    from stable_baselines3.common.vec_env import VecMonitor

    from training.vec_env import make_vec_env

    out = Path(cfg.out)
    resume_path = _resolve_resume(cfg)
    ppo_kwargs = dict(cfg.ppo)
    policy = ppo_kwargs.pop("policy", "MlpPolicy")
    valid = set(inspect.signature(PPO.__init__).parameters) - {"self", "policy", "env", "seed"}
    valid -= {"device", "tensorboard_log", "verbose", "_init_setup_model"}
    unknown = sorted(set(ppo_kwargs) - valid)
    if unknown:
        raise ValueError(f"unknown PPO setting(s) {unknown}; valid settings: {sorted(valid)}")

    env_fn = make_env_fn(cfg.env_id, cfg.env)
    probe = env_fn()  # validates the env kwargs before anything is written
    n_agents = len(probe.possible_agents)
    _, probe_infos = probe.reset(seed=0)
    info_keys = set(probe_infos.get(probe.possible_agents[0], {}))
    probe.close()
    monitor_keys = tuple(k for k in _MONITOR_INFO_KEYS if k in info_keys)

    start_steps = 0
    if resume_path is not None:
        model = PPO.load(resume_path, env=None, device=cfg.device)
        start_steps = int(model.num_timesteps)
        del model
        _check_same_environment(cfg, out / "config.yaml")

    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.torch_threads)
    resolved = cfg.to_dict()
    resolved["resume"] = str(resume_path) if resume_path else None
    resolved["agent_steps_per_env_step"] = cfg.n_envs * n_agents
    vec_kind = cfg.vec_env_kind()
    resolved["vec_env_kind"] = vec_kind  # what "auto" became
    # the original config.yaml stays: `coopnav evaluate` reads the environment from it
    name = "config.yaml" if start_steps == 0 else f"config_resumed_at_{start_steps}.yaml"
    _write_yaml(out / name, resolved)

    venv = make_vec_env(env_fn, cfg.n_envs, cfg.num_cpus, kind=vec_kind)
    suffix = "" if start_steps == 0 else f"_resumed_at_{start_steps}"
    monitor = VecMonitor(
        venv,
        # SB3 appends ".monitor.csv" to any other name
        filename=str(
            out / ("monitor.csv" if not suffix else f"resumed_at_{start_steps}.monitor.csv")
        ),
        info_keywords=monitor_keys,
    )
    learn_env: Any = monitor
    if cfg.normalize_reward:
        from stable_baselines3.common.vec_env import VecNormalize

        learn_env = VecNormalize(
            monitor, norm_obs=False, norm_reward=True, gamma=float(ppo_kwargs.get("gamma", 0.99))
        )
    if resume_path is not None:
        model = PPO.load(resume_path, env=learn_env, device=cfg.device)
        env_seed = (cfg.seed + start_steps) % (EVAL_SEED_START - cfg.n_envs)
        model.set_random_seed(env_seed)
    else:
        model = PPO(
            policy, learn_env, seed=cfg.seed, device=cfg.device, verbose=cfg.verbose, **ppo_kwargs
        )
        if cfg.pretrain:
            stats = behaviour_clone(model, env_fn, cfg.pretrain, seed=cfg.seed)
            (out / "pretrain.json").write_text(json.dumps(stats, indent=2) + "\n")
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    formats = [
        TensorBoardOutputFormat(str(logs)),
        CSVOutputFormat(str(logs / f"progress{suffix}.csv")),
    ]
    if cfg.verbose:
        from stable_baselines3.common.logger import HumanOutputFormat

        formats.append(HumanOutputFormat(sys.stdout))
    model.set_logger(Logger(str(logs), formats))

    nav_cls, ckpt_cls, progress_cls = _callbacks()
    ckpt = ckpt_cls(cfg.checkpoint_freq, out / "checkpoints")
    remaining = cfg.timesteps - start_steps
    t0 = time.perf_counter()
    previous_term = _terminate_as_interrupt()
    try:
        if remaining > 0:
            model.learn(
                total_timesteps=remaining,
                callback=[nav_cls(n_agents), ckpt] + ([progress_cls()] if cfg.progress_bar else []),
                reset_num_timesteps=resume_path is None,
            )
    except KeyboardInterrupt:
        n = ckpt.rollout_start_timesteps if ckpt.collecting else model.num_timesteps
        path = ckpt.save(n)
        print(
            f"\ninterrupted: checkpoint written to {path}; continue with --resume {path}",
            file=sys.stderr,
        )
        monitor.close()
        raise
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)
    wall_s = time.perf_counter() - t0
    final = out / "final_model.zip"
    model.save(final)
    done_steps = int(model.num_timesteps) - start_steps
    info = {
        "final_model": str(final),
        "seed": cfg.seed,
        "num_timesteps": int(model.num_timesteps),
        "session_agent_steps": done_steps,
        "session_wall_s": round(wall_s, 3),
        "agent_steps_per_s": round(done_steps / wall_s, 1) if wall_s > 0 else None,
        "vec_env": vec_kind,
        "resumed_from": str(resume_path) if resume_path else None,
        "versions": {
            "python": sys.version.split()[0],
            "numpy": np.__version__,
            "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__,
        },
    }
    (out / "run.json").write_text(json.dumps(info, indent=2) + "\n")
    monitor.close()
    return final


# --------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``coopnav train``."""
    parser.add_argument("--out", default="runs/ppo", help="output directory (default runs/ppo)")
    parser.add_argument(
        "--config", default=None, help=f"hyperparameter YAML (default {DEFAULT_CONFIG_PATH.name})"
    )
    parser.add_argument(
        "--env-id", default=DEFAULT_ENV_ID, help="environment (section of --config)"
    )
    parser.add_argument(
        "--timesteps", type=int, default=None, help="total agent-steps (SB3 timesteps)"
    )
    parser.add_argument("--seed", type=int, default=None, help="training seed")
    parser.add_argument("--n-envs", type=int, default=None, help="swarm copies stepped together")
    parser.add_argument("--num-cpus", type=int, default=None, help="worker processes (default 1)")
    parser.add_argument(
        "--vec-env",
        choices=_VEC_ENVS,
        default=None,
        help="vector environment: auto (default: batched for urban_canyon_v0 in one process, "
        "else supersuit), supersuit, or batched (urban_canyon_v0 only)",
    )
    parser.add_argument(
        "--checkpoint-freq", type=int, default=None, help="agent-steps between checkpoints"
    )
    parser.add_argument("--n-uavs", type=int, default=None, help="UAVs per swarm (env n_uavs)")
    parser.add_argument("--city", default=None, help="city layout (env setting 'city')")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a setting, e.g. ppo.learning_rate=1e-4 or n_envs=4 (repeatable)",
    )
    parser.add_argument(
        "--env-set",
        dest="env_overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override an environment setting, e.g. max_steps=300 (repeatable)",
    )
    parser.add_argument(
        "--resume",
        default=None,
        metavar="CHECKPOINT",
        help="continue from a checkpoint (SB3: a .zip; rllib: a checkpoint folder "
        "rllib_<N>_steps) or 'latest' (the newest in OUT/checkpoints)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument("--verbose", type=int, default=None, help="SB3 verbosity (0-2)")
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default=None,
        help="sb3 (default: Stable-Baselines3 in this process) or rllib (Ray RLlib, needs "
        'pip install -e ".[ray]")',
    )
    parser.add_argument(
        "--num-env-runners",
        type=int,
        default=None,
        help="rllib: Ray actors stepping the environment (0: this process samples)",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="rllib: join the Ray cluster at HOST:PORT (see `ray start --head`) or 'auto' "
        "(default: start a local Ray)",
    )


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """Merge the YAML section, ``--set``/``--env-set`` and explicit flags (in that order)."""
    base = load_config(args.config, args.env_id)
    base["env_id"] = args.env_id
    base["out"] = args.out
    data = apply_overrides(base, args.overrides)
    data = apply_overrides(data, [f"env.{item}" for item in args.env_overrides])
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
    data.update({k: v for k, v in flags.items() if v is not None})
    if args.backend is not None:
        data["backend"] = args.backend
    rllib_flags = {"num_env_runners": args.num_env_runners, "address": args.address}
    given = {k: v for k, v in rllib_flags.items() if v is not None}
    if given and data.get("backend", "sb3") != "rllib":
        flags_text = ", ".join("--" + k.replace("_", "-") for k in given)
        raise ValueError(f"{flags_text} only apply to --backend rllib")
    if given:
        data["rllib"] = {**(data.get("rllib") or {}), **given}
    env = dict(data.get("env") or {})
    if args.n_uavs is not None:
        env["n_uavs"] = args.n_uavs
    if args.city is not None:
        env["city"] = args.city
    data["env"] = env
    if args.no_progress:
        data["progress_bar"] = False
    return TrainConfig.from_dict(data)


def run(args: argparse.Namespace) -> int:
    """Run ``coopnav train``; returns the exit status."""
    try:
        cfg = config_from_args(args)
        if cfg.backend == "rllib":
            from training.rllib_train import train_rllib

            final = train_rllib(cfg)
        else:
            final = train(cfg)
    except (ValueError, FileNotFoundError, ImportError, ConnectionError) as exc:
        print(f"coopnav train: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    info = json.loads((final.parent / "run.json").read_text())
    print(
        f"final model: {final}  ({info['num_timesteps']} agent-steps, "
        f"{info['agent_steps_per_s']} agent-steps/s)"
    )
    return 0
