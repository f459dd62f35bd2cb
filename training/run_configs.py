"""The training run a trained policy came from, and the environment it recorded.

``coopnav train`` writes ``config.yaml`` into its output folder; a trained policy
(``ppo:``, ``rllib:``, ``mappo:``/``ippo:``/``torchrl:`` followed by a path, or a shipped
``mappo:pretrained/...``) is found beside its run's ``config.yaml``, or one or two folders
below it. ``coopnav evaluate`` (:mod:`coopnav_env.training.evaluate_cli`) and the suite
evaluation (:mod:`coopnav_env.training.suite`) fly a trained policy in the environment of its
run (:func:`train_config_of_policies`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from coopnav_env.training.config import parse_settings_yaml

__all__ = [
    "TRAINED_KINDS",
    "config_of_policy",
    "is_trained",
    "read_train_config",
    "train_config_of_policies",
]


def read_train_config(path: Path) -> dict[str, Any]:
    """The settings of a training run's ``config.yaml`` (a mapping; else ``ValueError``)."""
    data = parse_settings_yaml(path.read_text(), f"training config {path}") or {}
    if not isinstance(data, Mapping):
        raise ValueError(f"training config {path} must be a mapping of settings")
    return dict(data)


TRAINED_KINDS: tuple[str, ...] = ("ppo", "rllib", "mappo", "ippo", "torchrl")
"""Policy prefixes of trained policies, whose run folder records their environment."""


def is_trained(name: str) -> bool:
    """Whether a policy name is a trained policy, ``KIND:PATH`` (KIND in TRAINED_KINDS)."""
    kind, sep, _ = name.partition(":")
    return bool(sep) and kind in TRAINED_KINDS


def config_of_policy(name: str) -> Path | None:
    """The ``config.yaml`` of the run a trained policy came from (None: not found, or the
    policy is not a trained one): beside the model, or one or two folders up (for a shipped
    TorchRL policy, ``mappo:pretrained/...``, in its folder under ``agents/pretrained``)."""
    if not is_trained(name):
        return None
    kind, _, path = name.partition(":")
    model = Path(path)
    shipped = path == "pretrained" or path.startswith("pretrained/")
    if kind in ("mappo", "ippo", "torchrl") and shipped:
        from coopnav_env.agents.marl_policy import resolve_marl_checkpoint

        try:  # a shipped policy: its folder under agents/pretrained
            model = resolve_marl_checkpoint(path, "ippo" if kind == "ippo" else "mappo")
        except FileNotFoundError:
            return None
    for folder in (model, model.parent, model.parent.parent):
        cfg = folder / "config.yaml"
        if cfg.is_file():
            return cfg
    return None


def _flown_environment(data: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """The environment id and settings a run's configuration flies: ``urban_canyon_v1``'s
    settings on top of its defaults (:data:`~coopnav_env.envs.config.V1_DEFAULTS`), so that
    runs recorded before a v1 default existed (e.g. ``crash_free_steps``) compare equal to
    runs that record it at its default."""
    from coopnav_env.envs.config import V1_DEFAULTS
    from coopnav_env.training.envs import DEFAULT_ENV_ID

    env_id = data.get("env_id") or DEFAULT_ENV_ID
    env = dict(data.get("env") or {})
    if env_id == "urban_canyon_v1":
        env = {**V1_DEFAULTS, **env}
    return env_id, env


def train_config_of_policies(policies: Sequence[str]) -> dict[str, Any]:
    """The training configuration a trained policy (``ppo:``, ``rllib:``, ``mappo:``/``ippo:``/
    ``torchrl:``) came from.

    ``coopnav train`` writes ``config.yaml`` into its output directory; a model at
    ``DIR/final_model.zip``, ``DIR/final_model`` (RLlib) or ``DIR/checkpoints/*`` is evaluated
    in the environment it was trained in unless told otherwise (empty if none is found; then
    ``coopnav evaluate`` warns on stderr).
    Trained policies from runs whose environments differ raise ``ValueError`` (settings a
    run leaves out count at their ``urban_canyon_v1`` defaults).
    """
    found: dict[str, Any] | None = None
    for name in policies:
        cfg = config_of_policy(name)
        if cfg is None:
            continue
        data = read_train_config(cfg)
        key = _flown_environment(data)
        if found is not None and key != _flown_environment(found):
            raise ValueError(
                "the PPO policies were trained in different environments "
                f"({found.get('env')} vs {data.get('env')}); pass --train-config or "
                "--env-set explicitly"
            )
        found = data
    return found or {}
