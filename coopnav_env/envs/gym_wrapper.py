"""A single-agent Gymnasium view of ``urban_canyon_v1``: one agent commands the whole swarm.

:class:`UrbanCanyonSwarmV1Env` wraps the PettingZoo parallel environment so that single-agent
code (``gymnasium.make``, Stable-Baselines3, any Gymnasium-compatible trainer) can drive the
swarm with one policy. It is registered with Gymnasium when :mod:`coopnav_env` is imported, as
:data:`GYM_ENV_ID`; :class:`UrbanCanyonSwarmEnv` is the same view of the legacy
``urban_canyon_v0`` (:data:`GYM_ENV_ID_V0`, warns once per process)::

    import gymnasium
    import coopnav_env  # registers the id

    env = gymnasium.make("coopnav/UrbanCanyonSwarm-v1", n_uavs=3, reward="sum")
    obs, info = env.reset(seed=0)

Spaces (``N = n_uavs``, ``D = obs_dim = 20 + 2A + 4K`` plus the optional blocks of
``obs_protection_level``, ``obs_satellite_sectors``, ``obs_true_error`` and
``obs_agent_index``):

* observation ``Box((N * D,), float32)``: the agents' observations stacked in the order of
  ``possible_agents`` (``uav_0`` first), so agent ``i`` owns ``obs[i * D : (i + 1) * D]`` and
  ``obs.reshape(N, D)`` gives one row per UAV; the per-agent layout is
  :attr:`UrbanCanyonSwarmEnv.layout` (:func:`~coopnav_env.envs.obs_layout`). Bounds are the
  per-agent bounds tiled N times.
* action ``Box(-1, 1, (N * 3,), float32)``: UAV ``i``'s velocity command (East, North, Up as a
  fraction of the maximum speed) is ``action[3 i : 3 i + 3]``, i.e. ``action.reshape(N, 3)``.

Reward: the mean of the UAVs' rewards of the step (``reward="mean"``, default: the scale of one
UAV's reward, independent of N) or their sum (``reward="sum"``: the swarm's return, as the
project's own evaluation reports it). The per-UAV rewards are in ``info["agent_rewards"]``.

Episode end: ``terminated`` when the swarm episode terminates (a crash, or the whole swarm in
the goal area), ``truncated`` when it is truncated at ``max_steps`` (alias ``max_cycles``); the
wrapper does not add a ``TimeLimit`` of its own.

Departed agents: ``urban_canyon_v1`` (as v0) ends the episode for every UAV at once (a crash
terminates everyone), so today every row is always filled. Should an agent leave
``env.agents`` while the others fly on (PettingZoo allows it), the stack keeps its fixed size:
the agent's row holds its final observation at the step it leaves, then zeros (zero lies inside
every entry's bounds), its actions are ignored, its reward is no longer counted in the mean or
the sum (``info["agent_rewards"]`` holds 0 for it) and ``info["active"][i]`` is False.

Seeding: ``reset(seed=s)`` reseeds the underlying environment with ``s``, so an episode equals,
bit for bit, the PettingZoo episode ``parallel_env(...).reset(seed=s)`` driven by the same
actions; ``reset()`` without a seed continues the stream (a new episode).

``info``: ``"agent_infos"`` (the PettingZoo per-agent infos of the step, unchanged),
``"agent_rewards"`` (``(N,)`` float64), ``"active"`` (``(N,)`` bool, the UAVs still flying).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces

from coopnav_env import GYM_ENV_ID, GYM_ENV_ID_V0, GYM_ENV_ID_V1
from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.envs.observation_layout import ObsLayout, obs_layout
from coopnav_env.envs.urban_canyon import UrbanCanyonEnv, UrbanCanyonV1Env

__all__ = [
    "GYM_ENV_ID",
    "GYM_ENV_ID_V0",
    "GYM_ENV_ID_V1",
    "REWARD_MODES",
    "UrbanCanyonSwarmEnv",
    "UrbanCanyonSwarmV1Env",
]

REWARD_MODES: tuple[str, ...] = ("mean", "sum")
"""Values of the ``reward`` argument: the swarm's mean or summed reward per step."""


class UrbanCanyonSwarmEnv(gymnasium.Env):
    """The legacy ``urban_canyon_v0`` as one Gymnasium agent that commands every UAV (see
    module doc); :class:`UrbanCanyonSwarmV1Env` is the same view of ``urban_canyon_v1``.

    Parameters
    ----------
    render_mode : {None, "rgb_array", "human"}
        Passed to the PettingZoo environment (``render()`` returns its frame).
    reward : {"mean", "sum"}, default "mean"
        Step reward: the mean or the sum of the UAVs' rewards.
    config : UrbanCanyonConfig, optional
        Complete configuration; default ``UrbanCanyonConfig()``.
    **fields
        Any :class:`~coopnav_env.envs.UrbanCanyonConfig` field (and ``max_cycles``), as for
        ``parallel_env`` of the environment's module; an unknown name raises ``ValueError``.

    Attributes
    ----------
    par_env : UrbanCanyonEnv
        The PettingZoo parallel environment underneath.
    layout : ObsLayout
        Layout of one agent's block of the observation.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": list(UrbanCanyonEnv.metadata["render_modes"]),
        "render_fps": UrbanCanyonEnv.metadata["render_fps"],
    }
    parallel_class: ClassVar[type[UrbanCanyonEnv]] = UrbanCanyonEnv
    """The PettingZoo environment underneath (``urban_canyon_v0``'s here, legacy)."""

    def __init__(
        self,
        render_mode: str | None = None,
        reward: str = "mean",
        config: UrbanCanyonConfig | None = None,
        **fields: Any,
    ) -> None:
        if reward not in REWARD_MODES:
            raise ValueError(f"reward must be one of {REWARD_MODES}, got {reward!r}")
        if self.parallel_class is UrbanCanyonEnv:
            from coopnav_env.urban_canyon_v0 import warn_legacy

            warn_legacy()
        self.par_env = self.parallel_class(config=config, render_mode=render_mode, **fields)
        self.config: UrbanCanyonConfig = self.par_env.config
        self.render_mode = render_mode
        self.reward_mode = reward
        self.possible_agents: list[str] = list(self.par_env.possible_agents)
        n, d = len(self.possible_agents), self.config.obs_dim
        self._n, self._d = n, d
        space = self.par_env.observation_space(self.possible_agents[0])
        self.observation_space = spaces.Box(
            np.tile(space.low, n), np.tile(space.high, n), dtype=np.float32
        )
        self.action_space = spaces.Box(-1.0, 1.0, (3 * n,), dtype=np.float32)
        self.layout: ObsLayout = obs_layout(self.config)
        self._active = np.zeros(n, dtype=bool)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a swarm episode; ``seed`` reseeds the PettingZoo environment (see module doc)."""
        super().reset(seed=seed)
        obs, infos = self.par_env.reset(seed=seed, options=options)
        self._active = np.ones(self._n, dtype=bool)
        info = {
            "agent_infos": infos,
            "agent_rewards": np.zeros(self._n),
            "active": self._active.copy(),
        }
        return self._stack(obs, self._active), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply ``action.reshape(N, 3)`` to the UAVs still flying and advance one epoch.

        Raises
        ------
        ValueError
            ``action`` is not of shape ``(3 N,)`` (the PettingZoo environment rejects NaN or
            inf and a step after the episode ended, naming the problem).
        """
        act = np.asarray(action)
        if act.shape != (3 * self._n,):
            raise ValueError(
                f"action must have shape ({3 * self._n},) (3 velocity entries per UAV, "
                f"{self._n} UAVs), got shape {act.shape}"
            )
        act = act.reshape(self._n, 3)
        live = set(self.par_env.agents)
        before = self._active & np.array([a in live for a in self.possible_agents])
        actions = {a: act[i] for i, a in enumerate(self.possible_agents) if before[i]}
        obs, rewards, terms, truncs, infos = self.par_env.step(actions)
        per_agent = np.array([float(rewards.get(a, 0.0)) for a in self.possible_agents])
        counted = np.array([a in rewards for a in self.possible_agents])
        total = float(per_agent[counted].sum())
        reward = total if self.reward_mode == "sum" else total / max(int(counted.sum()), 1)
        still = set(self.par_env.agents)
        ended = not still
        terminated = bool(ended and any(terms.values()))
        truncated = bool(ended and not terminated and any(truncs.values()))
        stacked = self._stack(obs, before)  # final observations of the UAVs that flew this step
        self._active = np.array([a in still for a in self.possible_agents])
        info = {
            "agent_infos": infos,
            "agent_rewards": per_agent,
            "active": self._active.copy(),
        }
        return stacked, reward, terminated, truncated, info

    def _stack(self, obs: dict[str, np.ndarray], rows: np.ndarray) -> np.ndarray:
        """``(N * D,)`` float32: agent ``i``'s observation where ``rows[i]``, zeros elsewhere."""
        out = np.zeros((self._n, self._d), dtype=np.float32)
        for i, a in enumerate(self.possible_agents):
            if rows[i] and a in obs:
                out[i] = obs[a]
        return out.reshape(-1)

    def render(self) -> np.ndarray | None:
        """The PettingZoo environment's frame (``rgb_array``) or window (``human``)."""
        return self.par_env.render()

    def close(self) -> None:
        """Close the PettingZoo environment (its window, if any)."""
        self.par_env.close()


class UrbanCanyonSwarmV1Env(UrbanCanyonSwarmEnv):
    """``urban_canyon_v1`` as one Gymnasium agent (``coopnav/UrbanCanyonSwarm-v1``, the
    default id :data:`GYM_ENV_ID`).

    As :class:`UrbanCanyonSwarmEnv` over :class:`~coopnav_env.envs.urban_canyon.
    UrbanCanyonV1Env`: with ``reward="mean"`` (the default) the undiscounted return of an
    episode is its score.
    """

    parallel_class: ClassVar[type[UrbanCanyonEnv]] = UrbanCanyonV1Env
