"""The run configuration shared by every training backend, and the backend registry.

:class:`TrainConfig` holds everything that defines a training run; :func:`load_config` reads
the packaged settings of an environment, a packaged configuration by name
(:func:`named_configs`) or a YAML file of the user's, and :func:`apply_overrides` applies
``--set key=value`` items. Every setting is validated when the configuration is built, before
any work starts, with a message that names the setting and its allowed values.

Packaged settings
-----------------
The folder :data:`CONFIG_DIR` (``coopnav_env/training/configs``) holds one file per concern,
each with one section per environment id: ``run.yaml`` (the budget, seed, checkpoints,
backend and the environment's settings, read by every backend), ``sb3.yaml``, ``rllib.yaml``
and ``torchrl.yaml`` (each backend's own settings). ``torchrl.yaml`` is split into groups that
change independently, as BenchMARL's configurations are (:data:`TORCHRL_GROUPS`: ``ppo``,
``model``, ``exploration``, beside ``pretrain`` and ``env``); the groups are one namespace,
so a run's configuration names ``torchrl.learning_rate``, not ``torchrl.ppo.learning_rate``.
Packaged configurations (``configs/recipes/NAME.yaml``, ``coopnav train --config NAME``) name
what differs from the packaged settings of their environment.

Backends
--------
:data:`BACKENDS` maps a backend name (``--backend``, the ``backend`` setting) to the module
that implements it; adding a backend is one line there. A backend module defines

``train(cfg: TrainConfig) -> pathlib.Path``
    Train and return the final model (written into ``cfg.out``), following the run-folder
    rules of :mod:`coopnav_env.training.runs` (lock, fresh / ``--overwrite`` / ``--resume``, atomic
    writes, a checkpoint on SIGINT/SIGTERM).
``check(cfg: TrainConfig) -> None`` (optional)
    Validate the backend's own settings without starting any work (``ValueError`` naming
    the setting); :func:`check_backend_settings` calls it.

A backend with settings of its own keeps them in a mapping named after it (``rllib:``).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import importlib
import math
import re
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from coopnav_env.envs.config import ExperimentalSetting
from coopnav_env.training.envs import BATCHED_ENV_IDS, DEFAULT_ENV_ID, EVAL_SEED_START

__all__ = [
    "BACKENDS",
    "CONFIG_DIR",
    "EXPERIMENTAL_SETTINGS",
    "PRETRAIN_DEFAULTS",
    "VEC_ENVS",
    "TrainConfig",
    "apply_overrides",
    "backend_module",
    "check_backend_settings",
    "check_bool",
    "check_number",
    "load_config",
    "named_configs",
    "parse_settings_yaml",
    "parse_yaml",
]

CONFIG_DIR: Path = Path(__file__).resolve().parent / "configs"
"""The packaged settings: ``run.yaml``, one file per backend, and ``recipes/`` (see the module
docstring)."""

_SECTION_FILES: tuple[tuple[str, str | None], ...] = (
    ("run.yaml", None),
    ("sb3.yaml", None),
    ("rllib.yaml", "rllib"),
    ("torchrl.yaml", "torchrl"),
)
"""The packaged files of an environment's settings, each with the key its section goes under
(None: merged into the top level)."""

TORCHRL_GROUPS: tuple[str, ...] = ("ppo", "model", "exploration")
"""The groups of the ``torchrl`` settings in a configuration file, merged into one mapping."""

_MERGED_IN_RECIPES: frozenset[tuple[str, ...]] = frozenset(
    {
        ("env",),
        ("ppo",),
        ("rllib",),
        ("rllib", "ppo"),
        ("rllib", "model"),
        ("torchrl",),
        ("torchrl", "env"),
        *(("torchrl", g) for g in TORCHRL_GROUPS),
    }
)
"""The mappings of a packaged configuration that are merged into the packaged settings entry by
entry; every other entry (``pretrain``, ``policy_kwargs``, ...) replaces the setting whole."""

BACKENDS: dict[str, str] = {
    "sb3": "coopnav_env.training.sb3_backend",
    "rllib": "coopnav_env.training.rllib_backend",
    "torchrl": "coopnav_env.training.torchrl_backend",
}
"""Training backends: name -> module (see the module docstring for what a module defines).
``sb3``: Stable-Baselines3 in this process (default); ``rllib``: Ray RLlib; ``torchrl``:
MAPPO or IPPO on TorchRL (:mod:`coopnav_env.training.torchrl_backend`)."""

EXPERIMENTAL_SETTINGS: tuple[ExperimentalSetting, ...] = ()
"""The trainers' experimental settings, listed as the environment's are
(:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`): a backend setting kept for a study,
off by default, that may change or go without a deprecation period. None at present:
``torchrl.action_repeat`` and ``torchrl.start_hold_decisions``, which the packaged
``mappo_route`` configuration uses, are supported settings."""

VEC_ENVS: tuple[str, ...] = ("auto", "supersuit", "batched")
"""Values of ``TrainConfig.vec_env``: ``"auto"`` or a kind of
``coopnav_env.training.vec_env.VEC_ENV_KINDS`` (listed here without importing SB3)."""

PRETRAIN_DEFAULTS: dict[str, Any] = {
    "policy": "waypoint",
    "policy_kwargs": {},
    "episodes": 60,
    "epochs": 30,
    "learning_rate": 1e-3,
}
"""Settings of the optional behaviour-cloning warm start (``pretrain``)."""


def parse_yaml(text: str, what: str) -> Any:
    """``yaml.safe_load(text)``, with a one-line ``ValueError`` naming ``what`` when the text
    is not valid YAML (where and why)."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ValueError(f"{what} is not valid YAML{where}: {problem}") from None


class _TypedBool(str):
    """A YAML 1.1 boolean (``off``, ``yes``, ...) as typed, until its place says what it is."""


def parse_settings_yaml(text: str, what: str) -> Any:
    """:func:`parse_yaml` for a file of settings: an environment setting that takes words
    keeps the text as typed where YAML 1.1 would read a boolean.

    Under a key ``env`` (a section's ``env`` and ``torchrl.env``), a setting of
    :func:`env_word_settings` (``integrity``, ``nlos_exclusion``, ...) written ``off``,
    ``on``, ``yes`` or ``no`` without quotes is that word, not False or True, as
    :func:`apply_overrides` reads ``--env-set integrity=off``; every other boolean (a
    boolean setting's ``off`` included) stays a boolean.
    """
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_constructor(
        "tag:yaml.org,2002:bool", lambda loader, node: _TypedBool(loader.construct_scalar(node))
    )
    try:
        data = yaml.load(text, Loader=Loader)  # a SafeLoader: builds no arbitrary objects
    except yaml.YAMLError:
        return parse_yaml(text, what)  # the same error, in parse_yaml's words
    return _settle_booleans(data, parent=None)


def _settle_booleans(node: Any, parent: Any) -> Any:
    """``node`` with each :class:`_TypedBool` made a boolean, or left as its text where it
    is the value of a word setting in an ``env`` mapping (``parent``: the key above)."""
    import yaml

    if isinstance(node, _TypedBool):
        return yaml.SafeLoader.bool_values[node.lower()]
    if isinstance(node, dict):
        words = env_word_settings() if parent == "env" else {}
        return {
            _settle_booleans(k, None): (
                str(v) if isinstance(v, _TypedBool) and k in words else _settle_booleans(v, k)
            )
            for k, v in node.items()
        }
    if isinstance(node, list):
        return [_settle_booleans(v, None) for v in node]
    return node


def backend_module(name: str) -> ModuleType:
    """Import and return the module of backend ``name`` (a key of :data:`BACKENDS`).

    Raises
    ------
    ValueError
        Unknown backend.
    """
    if name not in BACKENDS:
        raise ValueError(f"unknown training backend {name!r}; choose one of {list(BACKENDS)}")
    return importlib.import_module(BACKENDS[name])


def check_backend_settings(cfg: TrainConfig) -> None:
    """Run the ``check(cfg)`` of ``cfg.backend``'s module, if it has one.

    Raises
    ------
    ValueError
        A setting of the backend is invalid.
    ImportError
        The backend's optional dependencies are missing.
    """
    check = getattr(backend_module(cfg.backend), "check", None)
    if check is not None:
        check(cfg)


def check_number(
    name: str,
    value: Any,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
    none: bool = False,
) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``value`` is a finite number in the range.

    ``integer`` asks for an int; ``none`` also admits None. Booleans are not numbers here.
    """
    if none and value is None:
        return
    kind = "an integer" if integer else "a number"
    if integer:
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        ok = ok and math.isfinite(value)
    if ok:
        ok = (lo is None or (value > lo if lo_open else value >= lo)) and (
            hi is None or (value < hi if hi_open else value <= hi)
        )
    if not ok:
        if lo is not None and hi is not None:
            rng = f" in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        elif lo is not None:
            rng = f" {'>' if lo_open else '>='} {lo:g}"
        elif hi is not None:
            rng = f" {'<' if hi_open else '<='} {hi:g}"
        else:
            rng = ""
        extra = " (or null)" if none else ""
        raise ValueError(f"{name} must be {kind}{rng}{extra}, got {value!r}")


def check_bool(name: str, value: Any) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``value`` is true or false."""
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")


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
    env_id : str, default "urban_canyon_v1"
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
        (:func:`~coopnav_env.training.vec_env.make_vec_env`): SuperSuit's per-agent adapters (any
        environment, worker processes allowed), or the batched vector environment of
        ``urban_canyon_v1`` and ``urban_canyon_v0`` (one process; the same observations,
        rewards and seeding bit for bit, so the same training). ``"auto"`` takes the batched
        one where it applies (those environments with ``num_cpus`` 0 or 1), SuperSuit otherwise
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
        Checkpoint to continue from, or ``"latest"`` for the newest one in ``out`` that loads
        (a finished run: its final model, when ``timesteps`` asks for more; see
        :mod:`coopnav_env.training.runs`).
    overwrite : bool, default False
        Start a fresh run in an ``out`` that holds an earlier run, removing that run's
        outputs first (without it, or ``resume``, such a start is refused).
    normalize_reward : bool, default False
        Scale the rewards PPO learns from by a running estimate of the standard deviation of
        the discounted return (SB3 ``VecNormalize(norm_obs=False, norm_reward=True)``, with
        PPO's ``gamma``). Observations are not normalised, so the saved policy needs nothing
        else at inference; episode returns in the logs and ``monitor.csv`` stay unscaled. A
        resumed run restarts the running estimate.
    pretrain : dict or None, default None
        Behaviour cloning before PPO
        (:func:`coopnav_env.training.sb3_backend.behaviour_clone`): ``policy`` (a
        :func:`coopnav_env.agents.make_policy` name, e.g. ``"waypoint"``) and its
        ``policy_kwargs``, ``episodes`` (teacher episodes on training seeds), ``epochs`` and
        ``learning_rate``.
        The policy's mean action is fitted to the teacher's actions (its log-std keeps
        ``log_std_init``) and the value network to the teacher's discounted returns, so that
        PPO starts from a policy that flies the route instead of discovering flight between
        walls by trial and crash. Skipped on resume.
    progress_bar : bool, default True
    verbose : int, default 0
        SB3 verbosity (1 prints the training table).
    backend : {"sb3", "rllib"}, default "sb3"
        Stable-Baselines3 in this process (:func:`coopnav_env.training.sb3_backend.train`), or
        Ray RLlib with env runners on a Ray cluster
        (:func:`coopnav_env.training.rllib_backend.train`, needs the ``ray`` extra); the keys of
        :data:`BACKENDS`.
    rllib : dict
        Settings of the RLlib backend
        (:class:`coopnav_env.training.rllib_backend.RLlibSettings`: env runners, Ray address,
        ``ppo`` and ``model``); the SB3 backend ignores them.
    torchrl : dict
        Settings of the TorchRL MAPPO/IPPO backend
        (:class:`coopnav_env.agents.marl_nets.MARLSettings` fields, plus ``env``: environment
        settings that override ``env`` for this backend).
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
    overwrite: bool = False
    normalize_reward: bool = False
    pretrain: dict[str, Any] | None = None
    progress_bar: bool = True
    verbose: int = 0
    backend: str = "sb3"
    rllib: dict[str, Any] = field(default_factory=dict)
    torchrl: dict[str, Any] = field(default_factory=dict)

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
        if self.vec_env not in VEC_ENVS:
            raise ValueError(
                f"TrainConfig.vec_env must be one of {list(VEC_ENVS)}, got {self.vec_env!r}"
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
        if not isinstance(self.out, (str, Path)) or not str(self.out):
            raise ValueError(f"TrainConfig.out must be a directory path, got {self.out!r}")
        if self.resume is not None and (not isinstance(self.resume, str) or not self.resume):
            raise ValueError(
                f"TrainConfig.resume must be a checkpoint path or 'latest', got {self.resume!r}"
            )
        check_bool("TrainConfig.overwrite", self.overwrite)
        if self.overwrite and self.resume is not None:
            raise ValueError(
                "--overwrite (start afresh, removing the earlier run) and --resume (continue "
                "it) contradict each other; give one of them"
            )
        if not isinstance(self.device, str) or not self.device:
            raise ValueError(
                f"TrainConfig.device must be a PyTorch device name, got {self.device!r}"
            )
        if self.backend not in BACKENDS:
            raise ValueError(
                f"TrainConfig.backend must be one of {list(BACKENDS)}, got {self.backend!r}"
            )
        if self.rllib is None:
            object.__setattr__(self, "rllib", {})
        if self.torchrl is None:
            object.__setattr__(self, "torchrl", {})
        for name in ("env", "ppo", "rllib", "torchrl"):
            if not isinstance(getattr(self, name), Mapping):
                raise ValueError(
                    f"TrainConfig.{name} must be a mapping, got {getattr(self, name)!r}"
                )
        object.__setattr__(self, "env", dict(self.env))
        if self.env.get("render_mode") is not None:
            raise ValueError(
                f"env.render_mode={self.env['render_mode']!r}: training does not render (it "
                "would slow training to a few agent-steps per second and stall interrupts); "
                "remove render_mode and render an episode of the trained policy instead"
            )
        object.__setattr__(self, "ppo", dict(self.ppo))
        object.__setattr__(self, "rllib", dict(self.rllib))
        object.__setattr__(self, "torchrl", dict(self.torchrl))
        if self.pretrain is not None:
            if not isinstance(self.pretrain, Mapping):
                raise ValueError(f"TrainConfig.pretrain must be a mapping, got {self.pretrain!r}")
            unknown = sorted(set(self.pretrain) - set(PRETRAIN_DEFAULTS))
            if unknown:
                raise ValueError(
                    f"unknown pretrain setting(s) {unknown}; valid: {sorted(PRETRAIN_DEFAULTS)}"
                )
            pre = {**PRETRAIN_DEFAULTS, **self.pretrain}
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
        """The vector environment the SB3 backend builds: ``vec_env``, with ``"auto"``
        resolved to ``"batched"`` for ``urban_canyon_v1`` and ``urban_canyon_v0`` in one
        process (``num_cpus`` 0 or 1), and to ``"supersuit"`` otherwise (another environment,
        worker processes)."""
        if self.vec_env != "auto":
            return self.vec_env
        batched = self.env_id in BATCHED_ENV_IDS and self.num_cpus <= 1
        return "batched" if batched else "supersuit"

    def to_dict(self) -> dict[str, Any]:
        """A plain (YAML-serialisable) copy."""
        return copy.deepcopy(dataclasses.asdict(self))


def check_replaced_settings(data: Mapping[str, Any], flags: Mapping[str, Any]) -> None:
    """Check the values ``data`` holds for the settings that command-line ``flags`` replace.

    ``coopnav train --set timesteps=abc --timesteps 64`` would otherwise lose the bad value
    silently under the flag's. Each replaced top-level setting (an entry of ``flags`` that is
    not None, whose value in ``data`` differs) is checked on its own, as
    :class:`TrainConfig` checks it; ``ValueError`` names it and says which flag replaces it.
    (``seed`` is checked with one environment, its loosest bound; the whole configuration is
    checked again afterwards.)
    """
    names = {f.name for f in dataclasses.fields(TrainConfig)} - {"out", "resume"}
    for name, value in flags.items():
        if value is None or name not in names or name not in data or data[name] == value:
            continue
        probe: dict[str, Any] = {"out": "-", name: data[name]}
        if name == "seed":
            probe["n_envs"] = 1
        try:
            TrainConfig.from_dict(probe)
        except ValueError as exc:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{exc} (the value {flag} {value} would have replaced)") from None


def _read_settings_file(p: Path, what: str) -> dict[str, Any]:
    """A YAML file of settings (:func:`parse_settings_yaml`) that must hold a mapping."""
    if not p.is_file():
        raise FileNotFoundError(f"{what} not found: {p}")
    data = parse_settings_yaml(p.read_text(), f"{what} {p}") or {}
    if not isinstance(data, Mapping):
        raise ValueError(f"{what} {p} must be a mapping, got {data!r}")
    return dict(data)


def _section_of(p: Path, env_id: str) -> dict[str, Any]:
    """The section ``env_id`` of the file ``p`` of sections (a ``module:callable`` env id
    falls back to the default environment's)."""
    data = _read_settings_file(p, "hyperparameter file")
    key = env_id if env_id in data or ":" not in env_id else DEFAULT_ENV_ID
    if key not in data:
        raise ValueError(f"{p} has no section {env_id!r}; sections: {sorted(data)}")
    section = copy.deepcopy(data[key]) or {}
    if not isinstance(section, Mapping):
        raise ValueError(f"section {key!r} of {p} must be a mapping of settings, got {section!r}")
    return dict(section)


def _packaged_section(env_id: str) -> dict[str, Any]:
    """The packaged settings of ``env_id``, its ``torchrl`` groups not yet merged."""
    out: dict[str, Any] = {}
    for name, under in _SECTION_FILES:
        section = _section_of(CONFIG_DIR / name, env_id)
        if under is not None:
            out[under] = section
            continue
        twice = sorted(set(section) & set(out))
        if twice:
            raise ValueError(f"{CONFIG_DIR / name} sets {twice}, which another file sets too")
        out.update(section)
    return out


def _merge_torchrl_groups(section: dict[str, Any], where: str) -> dict[str, Any]:
    """``section`` with the groups of its ``torchrl`` mapping (:data:`TORCHRL_GROUPS`) merged
    into that mapping (``ValueError`` for a setting given twice)."""
    torchrl = section.get("torchrl")
    if not isinstance(torchrl, Mapping):
        return section
    flat: dict[str, Any] = {}
    for key, value in torchrl.items():
        entries = {key: value}
        if key in TORCHRL_GROUPS:
            if not isinstance(value, Mapping):
                raise ValueError(
                    f"{where}: torchrl.{key} is a group of settings and must be a mapping, "
                    f"got {value!r}"
                )
            entries = dict(value)
        for name, v in entries.items():
            if name in flat:
                raise ValueError(f"{where}: torchrl.{name} is set twice (its groups overlap)")
            flat[name] = v
    return {**section, "torchrl": flat}


def _merge_recipe(
    base: dict[str, Any], recipe: Mapping[str, Any], at: tuple[str, ...] = ()
) -> None:
    """Merge ``recipe`` into ``base`` in place (:data:`_MERGED_IN_RECIPES`)."""
    for key, value in recipe.items():
        here = (*at, key)
        if here in _MERGED_IN_RECIPES and isinstance(value, Mapping):
            inner = base.get(key)
            if not isinstance(inner, dict):
                inner = {}
                base[key] = inner
            _merge_recipe(inner, value, here)
        else:
            base[key] = copy.deepcopy(value)


def named_configs() -> dict[str, str]:
    """The packaged training configurations (``coopnav train --config NAME``): name -> the
    one-line description that opens its file."""
    found = {}
    for p in sorted((CONFIG_DIR / "recipes").glob("*.yaml")):
        lines = p.read_text().splitlines()
        found[p.stem] = lines[0].lstrip("#").strip() if lines else ""
    return found


def load_config(path: str | Path | None = None, env_id: str | None = None) -> dict[str, Any]:
    """The settings of a training run, as one plain dict (what :class:`TrainConfig` takes).

    Parameters
    ----------
    path : path, str or None
        None: the packaged settings of ``env_id`` (:data:`CONFIG_DIR`). The name of a packaged
        configuration (:func:`named_configs`): the packaged settings of its environment with
        the configuration's settings on top. Otherwise a YAML file with one top-level key per
        environment (the packaged files' sections of that environment in one mapping).
    env_id : str or None
        The environment whose section to read (None: the default environment, or a named
        configuration's own). A ``module:callable`` env id falls back to the default section.

    Raises
    ------
    FileNotFoundError
        No such file (and no packaged configuration of that name).
    ValueError
        The file holds no such section; a named configuration asked for another environment
        than its own.
    """
    text = None if path is None else str(path)
    if text is not None and text in named_configs():
        p = CONFIG_DIR / "recipes" / f"{text}.yaml"
        recipe = _read_settings_file(p, f"training configuration {text!r}")
        own = recipe.get("env_id", DEFAULT_ENV_ID)
        if env_id is not None and env_id != own:
            raise ValueError(
                f"the training configuration {text!r} trains {own}, not {env_id}: leave out "
                "--env-id (or set env_id in a configuration file of your own)"
            )
        env_id = own
        section = _packaged_section(own)
        _merge_recipe(section, recipe)
        where = str(p)
    elif text is None:
        env_id = env_id or DEFAULT_ENV_ID
        section, where = _packaged_section(env_id), str(CONFIG_DIR)
    else:
        p = Path(text)
        if not p.is_file() and not p.suffix and "/" not in text:
            raise FileNotFoundError(
                f"no packaged training configuration {text!r} and no file of that name; "
                f"packaged configurations: {', '.join(named_configs())}"
            )
        env_id = env_id or DEFAULT_ENV_ID
        section, where = _section_of(p, env_id), str(p)
    section = _merge_torchrl_groups(section, where)
    section.setdefault("env_id", env_id)
    return section


@functools.cache
def env_word_settings() -> dict[str, tuple[str, ...]]:
    """The ``urban_canyon_v0`` settings whose values are words (a ``Literal`` of strings),
    each with the words it takes, e.g. ``{"integrity": ("off", "raim", "fde"), ...}``."""
    from coopnav_env.envs.config import UrbanCanyonConfig

    hints = typing.get_type_hints(UrbanCanyonConfig)
    return {
        name: tuple(typing.get_args(hint))
        for name, hint in hints.items()
        if typing.get_origin(hint) is typing.Literal
        and all(isinstance(v, str) for v in typing.get_args(hint))
    }


def apply_overrides(config: Mapping[str, Any], items: Sequence[str]) -> dict[str, Any]:
    """Apply ``key=value`` overrides with dotted keys (``ppo.learning_rate=1e-4``).

    Values are parsed as YAML (``3``, ``1e-4``, ``true``, ``[64, 64]``, ``null``); a tuple
    as Python writes it, ``(60.17, 24.94)``, reads as the list ``[60.17, 24.94]``. Nested
    mappings are created as needed; the input is not modified. An environment setting that
    takes a word (:func:`env_word_settings`: ``integrity``, ``nlos_exclusion``, ...; a key of
    its own or under ``env.``) gets the text as typed where YAML 1.1 would read a boolean:
    ``integrity=off`` is ``"off"``, not False (a boolean setting still reads ``off`` as False).

    Raises
    ------
    ValueError
        An item without ``=`` or with an empty key.
    """
    out = copy.deepcopy(dict(config))
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise ValueError(f"override {item!r} must look like key=value (dotted keys allowed)")
        value = parse_yaml(raw, f"the value of {item!r}") if raw.strip() else ""
        if isinstance(value, str) and re.fullmatch(r"\(.*\)", value.strip(), flags=re.S):
            # a tuple as Python writes it, "(60.17, 24.94)": the list YAML writes "[...]"
            value = parse_yaml(f"[{value.strip()[1:-1]}]", f"the value of {item!r}")
        parts = key.split(".")
        if isinstance(value, bool) and parts[-1] in env_word_settings():
            if len(parts) == 1 or parts[-2] == "env":  # an environment setting
                value = raw.strip()  # "off", "no", ...: the setting names the words it takes
        # YAML 1.1 reads "1e-4" as a string; accept it as a float
        if isinstance(value, str):
            try:
                value = float(value) if re.fullmatch(r"[-+]?[\d.]+[eE][-+]?\d+", value) else value
            except ValueError:
                pass
        node = out
        for part in parts[:-1]:
            nxt = node.get(part)
            if not isinstance(nxt, dict):
                nxt = {}
                node[part] = nxt
            node = nxt
        node[parts[-1]] = value
    return out
