"""A trained Stable-Baselines3 PPO policy (parameter sharing) behind the policy protocol."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["PPOPolicy", "resolve_checkpoint"]


def resolve_checkpoint(path: str | Path) -> Path:
    """The checkpoint file for ``path`` (``.zip`` may be omitted).

    Raises
    ------
    FileNotFoundError
        Neither ``path`` nor ``path.zip`` is a file; the message names the path.
    """
    p = Path(path).expanduser()
    if p.is_file():
        return p
    if p.suffix != ".zip" and p.with_name(p.name + ".zip").is_file():
        return p.with_name(p.name + ".zip")
    raise FileNotFoundError(f"PPO checkpoint not found: {p}")


class PPOPolicy:
    """Deterministic actions of a PPO model trained by ``coopnav train``.

    Every UAV is driven by the same network (parameter sharing): the observations of the
    agents are stacked into one batch.

    Parameters
    ----------
    env : pettingzoo.ParallelEnv
        The environment the policy will act in; its observation and action spaces must match
        the model's.
    path : str or Path
        The ``.zip`` saved by SB3 (e.g. ``runs/quick/final_model.zip``).
    device : str, default "cpu"
    deterministic : bool, default True
        Use the mean action (True) or sample from the policy (False; then seeded by
        :meth:`reset` through torch's global generator).

    Raises
    ------
    FileNotFoundError
        The checkpoint does not exist.
    ValueError
        The model was trained on different observation or action spaces.
    """

    def __init__(self, env: Any, path: str | Path, device: str = "cpu", deterministic: bool = True):
        self.path = resolve_checkpoint(path)  # before the slow torch import

        from stable_baselines3 import PPO

        self.name = f"ppo:{path}"
        self.deterministic = bool(deterministic)
        self.model = PPO.load(self.path, device=device)
        agent = env.possible_agents[0]
        obs_space, act_space = env.observation_space(agent), env.action_space(agent)
        if self.model.observation_space.shape != obs_space.shape:
            raise ValueError(
                f"{self.path} was trained on observations of shape "
                f"{self.model.observation_space.shape}, the environment gives {obs_space.shape} "
                "(different n_uavs or observation settings?)"
            )
        if self.model.action_space.shape != act_space.shape:
            raise ValueError(
                f"{self.path} was trained on actions of shape {self.model.action_space.shape}, "
                f"the environment expects {act_space.shape}"
            )

    def reset(self, seed: int | None = None) -> None:
        """Nothing to do for deterministic actions; seeds torch when sampling."""
        if not self.deterministic and seed is not None:
            import torch

            torch.manual_seed(seed)

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The policy's actions for the stacked observations of all agents."""
        agents = list(observations)
        if not agents:
            return {}
        batch = np.stack([np.asarray(observations[a], dtype=np.float32) for a in agents])
        actions, _ = self.model.predict(batch, deterministic=self.deterministic)
        actions = np.asarray(actions, dtype=np.float32).reshape(len(agents), -1)
        return {a: actions[i] for i, a in enumerate(agents)}
