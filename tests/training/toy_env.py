"""A tiny PettingZoo ParallelEnv with the interface of ``urban_canyon_v0`` (tests only).

``n`` agents on a plane fly toward a goal; each observes its own position, the goal and a
few noise values drawn from the env's generator (so that seeding matters). Infos carry the
navigation figures the evaluation reads (``coop_error_m`` ...). A collision with the square
``[-1, 1]^2`` terminates every agent, ``max_steps`` truncates them all.
"""

from __future__ import annotations

import functools
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

TOY_ENV_ID = "tests.training.toy_env:ToyParallelEnv"
"""The ``env_id`` of this env for ``coopnav train`` and ``TrainConfig``."""

TOY_TRAINING: dict[str, Any] = {
    "timesteps": 600,
    "seed": 0,
    "n_envs": 2,
    "checkpoint_freq": 0,
    "env": {"n_uavs": 3, "max_steps": 12},
    "ppo": {"n_steps": 32, "batch_size": 64, "n_epochs": 2},
    "pretrain": None,
    "progress_bar": False,
}
"""Settings of a training run of a few seconds on this env (a section of a YAML file)."""


class ToyParallelEnv(ParallelEnv):
    """A seeded toy swarm navigation env; see the module docstring."""

    metadata: ClassVar[dict[str, Any]] = {
        "name": "toy_v0",
        "render_modes": [],
        "is_parallelizable": True,
    }

    def __init__(self, n_uavs: int = 3, max_steps: int = 20, render_mode: str | None = None):
        self.n_uavs = n_uavs
        self.max_steps = max_steps
        self.render_mode = render_mode
        self.possible_agents = [f"uav_{i}" for i in range(n_uavs)]
        self.agents: list[str] = []
        self._obs_space = spaces.Box(-np.inf, np.inf, (6,), np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self._rng = np.random.default_rng()

    @functools.cache  # noqa: B019
    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Box:
        return self._act_space

    def _obs(self) -> dict[str, np.ndarray]:
        noise = self._rng.normal(size=(self.n_uavs, 2))
        out = {}
        for i, a in enumerate(self.possible_agents):
            v = np.r_[self.pos[i], self.goal, noise[i]].astype(np.float32)
            out[a] = v
        return out

    def _infos(self) -> dict[str, dict[str, Any]]:
        err = np.abs(self._rng.normal(2.0, 1.0, self.n_uavs))
        return {
            a: {
                "coop_error_m": float(err[i]),
                "standalone_error_m": float(2 * err[i]),
                "n_sats": 6 + i,
                "n_sats_swarm": 12,
                "goal_reached": bool(np.linalg.norm(self.pos[i] - self.goal) < 1.0),
                "collided": self._collided,
                "pos_enu_m": np.r_[self.pos[i], 10.0],
            }
            for i, a in enumerate(self.possible_agents)
        }

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.agents = list(self.possible_agents)
        self.t = 0
        self._collided = False
        self.pos = self._rng.uniform(2.0, 8.0, size=(self.n_uavs, 2))
        self.goal = self._rng.uniform(-8.0, -2.0, size=2)
        return self._obs(), self._infos()

    def step(self, actions: dict[str, np.ndarray]):
        act = np.stack([np.clip(actions[a], -1, 1)[:2] for a in self.agents])
        before = np.linalg.norm(self.pos - self.goal, axis=1)
        self.pos = self.pos + act
        after = np.linalg.norm(self.pos - self.goal, axis=1)
        self.t += 1
        self._collided = bool(np.any(np.all(np.abs(self.pos) < 1.0, axis=1)))
        rew = {a: float(before[i] - after[i]) for i, a in enumerate(self.agents)}
        term = {a: self._collided for a in self.agents}
        trunc = {a: self.t >= self.max_steps and not self._collided for a in self.agents}
        obs, infos = self._obs(), self._infos()
        if self._collided or self.t >= self.max_steps:
            self.agents = []
        return obs, rew, term, trunc, infos
