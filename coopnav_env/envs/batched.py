"""K copies of ``urban_canyon_v0`` stepped together, with arrays in and out.

:class:`BatchedUrbanCanyonEnv` holds ``K`` independent swarms (each its own world, city and
random generator) and steps them with one ``(K, N, 3)`` action array, returning
``(K, N, obs_dim)`` observations, ``(K, N)`` rewards and ``(K,)`` episode-end flags; a
finished copy is reset at once (automatic reset), as vector environments do. It is the engine
of the batched Stable-Baselines3 vector environment
(:func:`coopnav_env.training.vec_env.make_vec_env` with ``kind="batched"``, the
``vec_env: batched`` setting of ``coopnav train``).

Equivalence with K separate environments
----------------------------------------
Copy ``k`` behaves exactly like a separate ``urban_canyon_v0.parallel_env`` with the same
settings, bit for bit: ``reset(seed=s)`` resets copy ``k`` with ``s + k`` (a sequence gives
one seed per copy; ``None`` continues each copy's generator, drawing it from OS entropy the
first time), every later episode of a copy continues that copy's generator (what a separate
environment does on ``reset()`` without a seed, and what SuperSuit's vector wrappers do), and
every step of a copy is the step of a separate environment: the parallel environment steps
as a batch of one through the same fused step (:mod:`coopnav_env.envs._fused`).
``tests/envs/test_batched.py`` checks observations, rewards, terminations, truncations, infos
and states against separate environments over episodes that end at different steps, and the
fused step against ``UrbanWorld.step``.

What is batched and what is not
-------------------------------
With the default measurement chain (no NLOS draws, no dead-reckoning noise, no channel limit,
no map exclusion, no integrity monitoring, the exact covariance; velocity or route-frame
commands, the base observation with or without the agent index:
:func:`coopnav_env.envs._fused.fused_settings`), a step of all K copies is three
compiled calls over the copies (:mod:`coopnav_env.envs._batched_kernels`: motion, line of
sight and relative sensing; pseudoranges, both solvers, the estimate selection, waypoints,
reward terms and the skyline and wall sensors; observations and the infos' numbers), run on
every core (threads sharing the copies), with the rotations to ECEF and the skyline's ``arctan`` as
numpy calls on the ``(K, ...)`` arrays between them. Cities of box buildings (the grids) and
of extruded polygons (generated families, GeoJSON and OpenStreetMap files) both take it.
Each copy keeps its own city, satellites
(its own GNSS time), solver problems and generator (one draw call per copy per step, in the
order of ``UrbanWorld``); no problem is padded or stacked with another copy's, so its
arithmetic does not depend on K. Still once per copy in Python: those draws, the copy's
world attributes and a stand-in for its ``Epoch`` (what ``envs[k]`` shows; the epoch's
fields are views made from the step's arrays when one is first read), the infos
dictionaries and the start of each automatic reset (a new city, formation and route); the
first epochs of the copies reset at a step are again the compiled calls over all of them.
Other settings step copy by copy through ``UrbanCanyonEnv._step_arrays``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from coopnav_env.envs._fused import FusedStep, fused_settings, info_arrays, infos_from_arrays
from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.envs.urban_canyon import UrbanCanyonEnv

__all__ = ["BatchedStep", "BatchedUrbanCanyonEnv"]


class BatchedStep(NamedTuple):
    """What :meth:`BatchedUrbanCanyonEnv.step_arrays` returns: arrays only (``K`` copies,
    ``N`` agents).

    Attributes
    ----------
    obs : ndarray, shape (K, N, obs_dim), float32
        After the step; for a copy whose episode ended, the first observation of its next
        episode (automatic reset). A buffer reused by later calls: copy it to keep it.
    rewards : ndarray, shape (K, N), float64
    terminated, truncated : ndarray of bool, shape (K,)
        Whether each copy's episode ended at this step (every agent of a copy ends together).
    info : dict of str to ndarray
        The step infos as arrays: every key of an agent's info dict (``INFO_KEYS`` of
        :mod:`coopnav_env.envs.urban_canyon`, in that order, plus the integrity and map
        exclusion keys where those settings are on), each of shape ``(K, N)``: float64 for
        real numbers, int64 for counts, statuses, waypoints and ``step``, bool for flags.
        ``info[key][k, i]`` equals ``infos[k][agent_i][key]`` of :meth:`~BatchedUrbanCanyonEnv.
        step`; for a finished copy, the values of its final step. New arrays every step.
    final_obs : ndarray, shape (K, N, obs_dim), float32
        The observations of this step before any automatic reset (equal to ``obs`` for copies
        that did not finish).
    """

    obs: np.ndarray
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    info: dict[str, np.ndarray]
    final_obs: np.ndarray


class BatchedUrbanCanyonEnv:
    """``n_copies`` independent ``urban_canyon_v0`` swarms stepped together.

    Parameters
    ----------
    n_copies : int
        Number of swarm copies ``K``, >= 1.
    config : UrbanCanyonConfig, optional
        Settings of every copy; ``**overrides`` are applied on top (as for
        ``urban_canyon_v0.parallel_env``).

    Attributes
    ----------
    envs : list of UrbanCanyonEnv
        The copies (their worlds and generators); copy ``k`` is ``envs[k]``.
    n_copies, n_agents, obs_dim : int
    observation_space, action_space : gymnasium.spaces.Box
        The spaces of one agent.

    Notes
    -----
    Rendering is not supported (``render_mode`` must be None); render a copy through
    ``envs[k]`` after giving it a render mode, or use the parallel environment.
    """

    def __init__(
        self, n_copies: int, config: UrbanCanyonConfig | None = None, **overrides: Any
    ) -> None:
        if isinstance(n_copies, bool) or not isinstance(n_copies, int | np.integer):
            raise ValueError(f"n_copies must be an integer >= 1, got {n_copies!r}")
        if int(n_copies) < 1:
            raise ValueError(f"n_copies must be an integer >= 1, got {n_copies}")
        envs = [UrbanCanyonEnv(config=config, **overrides) for _ in range(int(n_copies))]
        self._init(envs)

    @classmethod
    def from_envs(cls, envs: Sequence[UrbanCanyonEnv]) -> BatchedUrbanCanyonEnv:
        """Batch existing (fresh) parallel environments; they must share one configuration."""
        envs = list(envs)
        if not envs:
            raise ValueError("from_envs needs at least one environment")
        for e in envs:
            if not isinstance(e, UrbanCanyonEnv):
                raise ValueError(
                    f"from_envs batches urban_canyon_v0 environments (UrbanCanyonEnv), got "
                    f"{type(e).__name__}"
                )
        if any(e.config != envs[0].config for e in envs):
            raise ValueError("every batched environment must have the same configuration")
        if any(e is f for i, e in enumerate(envs) for f in envs[i + 1 :]):
            raise ValueError("the batched environments must be distinct objects")
        out = cls.__new__(cls)
        out._init(envs)
        return out

    def _init(self, envs: list[UrbanCanyonEnv]) -> None:
        for e in envs:
            if e.render_mode is not None:
                raise ValueError("BatchedUrbanCanyonEnv does not render: use render_mode=None")
        self.envs = envs
        self.config = envs[0].config
        self.n_copies = len(envs)
        self.n_agents = self.config.n_uavs
        self.obs_dim = self.config.obs_dim
        agent = envs[0].possible_agents[0]
        self.observation_space: spaces.Box = envs[0].observation_space(agent)
        self.action_space: spaces.Box = envs[0].action_space(agent)
        self.possible_agents = list(envs[0].possible_agents)
        self._obs = np.zeros((self.n_copies, self.n_agents, self.obs_dim), dtype=np.float32)
        self._needs_reset = True
        self._fused_step = FusedStep()

    # ---- episodes ---------------------------------------------------------------------------

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.n_copies
        if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
            return [UrbanCanyonEnv.check_seed(seed) + k for k in range(self.n_copies)]
        if isinstance(seed, bool | str | bytes) or not isinstance(seed, Sequence | np.ndarray):
            raise ValueError(f"seed must be an int or {self.n_copies} seeds, got {seed!r}")
        seeds = list(seed)
        if len(seeds) != self.n_copies:
            raise ValueError(f"seed must be an int or {self.n_copies} seeds, got {len(seeds)}")
        return [None if s is None else UrbanCanyonEnv.check_seed(s) for s in seeds]

    def reset(
        self, seed: int | Sequence[int | None] | None = None
    ) -> tuple[np.ndarray, list[dict[str, dict[str, Any]]]]:
        """Reset every copy; copy ``k`` gets ``seed + k`` (or ``seed[k]``; None continues).

        Returns
        -------
        obs : ndarray, shape (K, N, obs_dim), float32
            A buffer reused by later calls: copy it to keep it.
        infos : list of K dicts
            Each copy's reset infos (``{agent: {...}}``, as ``reset`` returns).
        """
        infos = []
        for k, s in enumerate(self._seeds(seed)):
            self._obs[k] = self.envs[k]._reset_arrays(s)
            infos.append(self.envs[k]._reset_infos())
        self._needs_reset = False
        return self._obs, infos

    def _actions(self, actions: Any) -> np.ndarray:
        shape = (self.n_copies, self.n_agents, 3)
        try:
            cmd = np.asarray(actions)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"actions must be a numeric array of shape {shape}") from exc
        if cmd.dtype.kind not in "biuf":  # strings and complex numbers are not commands
            raise ValueError(
                f"actions must be a real numeric array of shape {shape}, got dtype {cmd.dtype}"
            )
        cmd = cmd.astype(np.float64, copy=False)
        flat = (self.n_copies * self.n_agents, 3)
        if cmd.shape == flat:  # copy-major: row k * N + i is UAV i of copy k
            cmd = cmd.reshape(shape)
        elif cmd.shape != shape:
            # the shape is checked exactly: a transposed (N, K, 3) array has as many entries
            # but would drive the wrong UAVs
            raise ValueError(f"actions must have shape {shape} or {flat}, got {cmd.shape}")
        if not np.all(np.isfinite(cmd)):
            bad = sorted({int(k) for k in np.nonzero(~np.isfinite(cmd))[0]})
            raise ValueError(f"actions contain NaN or inf (copies {bad})")
        return np.clip(cmd, -1.0, 1.0)

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict[str, dict]], np.ndarray]:
        """Step every copy with ``actions`` of shape ``(K, N, 3)`` (or ``(K * N, 3)``, copy-major).

        Actions are clipped to ``[-1, 1]``; NaN or inf, or any other shape (a transposed
        ``(N, K, 3)`` array included), raises ``ValueError``. :meth:`step_arrays` is the same
        step with the infos as arrays (no per-agent dicts).

        Returns
        -------
        obs : ndarray, shape (K, N, obs_dim), float32
            After the step; for a copy whose episode ended, the first observation of its next
            episode (automatic reset; the buffer is reused by later calls).
        rewards : ndarray, shape (K, N), float64
        terminated, truncated : ndarray of bool, shape (K,)
            Whether each copy's episode ended at this step (every agent of a copy ends
            together).
        infos : list of K dicts
            Each copy's step infos ``{agent: {...}}``: for a finished copy, those of its final
            step (the reset infos of the next episode are not merged in).
        final_obs : ndarray, shape (K, N, obs_dim), float32
            The observations of this step before any automatic reset (equal to ``obs`` for
            copies that did not finish).
        """
        obs, rewards, terminated, truncated, info, final_obs = self._step(actions)
        infos = infos_from_arrays(self.possible_agents, info) if isinstance(info, dict) else info
        return obs, rewards, terminated, truncated, infos, final_obs

    def step_arrays(self, actions: Any) -> BatchedStep:
        """:meth:`step` with the infos as arrays ``key -> (K, N)`` (see :class:`BatchedStep`).

        The same step as :meth:`step`, bit for bit; it builds no per-agent dicts, so it is
        the one to use where arrays are wanted (trainers that stack infos into tensors).
        """
        obs, rewards, terminated, truncated, info, final_obs = self._step(actions)
        if not isinstance(info, dict):
            info = self.info_arrays(info)
        return BatchedStep(obs, rewards, terminated, truncated, info, final_obs)

    def info_arrays(self, infos: Sequence[dict[str, dict[str, Any]]]) -> dict[str, np.ndarray]:
        """Per-copy infos ``[{agent: {key: number}}]`` (as :meth:`reset` or :meth:`step`
        return them) as arrays ``key -> (K, N)``, with the dtypes of
        :attr:`BatchedStep.info`."""
        if len(infos) != self.n_copies:
            raise ValueError(f"info_arrays needs {self.n_copies} copies' infos, got {len(infos)}")
        agents = self.possible_agents
        keys = list(infos[0][agents[0]])
        out = {}
        for key in keys:
            values = [[copy[a][key] for a in agents] for copy in infos]
            kind = type(values[0][0])
            dtype = bool if kind is bool else np.int64 if kind is int else np.float64
            out[key] = np.array(values, dtype=dtype)
        return out

    def _step(self, actions: Any):
        """:meth:`step` with the infos as arrays (the fused step) or per-copy dicts."""
        if self._needs_reset:
            raise ValueError("step() called before reset(): call reset() first")
        cmd = self._actions(actions)
        if not fused_settings(self.config):
            return self._step_copies(cmd)
        reset_obs: dict[int, np.ndarray] = {}

        def begin(done: np.ndarray) -> None:  # beside the navigation kernel
            reset_obs.update(self._reset_copies(np.flatnonzero(done).tolist()))

        out = self._fused_step.run(self.envs, cmd, begin)
        if out is None:
            return self._step_copies(cmd)
        obs, rewards, terminated, truncated, _terms, _in_goal, parts = out
        info = info_arrays(*parts)
        if sorted(reset_obs) != np.flatnonzero(terminated | truncated).tolist():
            raise RuntimeError("the copies reset beside the step are not those it ended")
        final_obs = obs
        obs = self._obs
        obs[:] = final_obs
        for k, row in reset_obs.items():
            obs[k] = row
        return obs, rewards, terminated, truncated, info, final_obs

    def _reset_copies(self, done: list[int]) -> dict[int, np.ndarray]:
        """Automatic reset of the copies ``done`` (the next episode continues each copy's
        generator): ``UrbanCanyonEnv._reset_arrays`` with the first epochs, first
        observations and route lengths of all of them in the fused step's compiled calls on
        this thread alone (it runs beside the step's navigation kernel; else each world's
        own). Returns each copy's first observations."""
        envs = [self.envs[k] for k in done]
        for e in envs:
            e._begin_reset(None)
            e.world._begin_episode(e._rng)
            e._episode_scales()
        first = self._fused_step.first_epochs(envs) if envs else None
        if first is None:
            for e in envs:
                e._epoch = e.world._first_epoch(e._rng)
            return {k: e._finish_reset() for k, e in zip(done, envs)}
        obs, route_m = first
        return {
            k: e._finish_reset((obs[i], route_m[i])) for i, (k, e) in enumerate(zip(done, envs))
        }

    def _step_copies(
        self, cmd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict[str, dict]], np.ndarray]:
        """:meth:`step` copy by copy through ``UrbanCanyonEnv._step_arrays`` (any settings)."""
        k_n = (self.n_copies, self.n_agents)
        rewards = np.empty(k_n)
        terminated = np.zeros(self.n_copies, dtype=bool)
        truncated = np.zeros(self.n_copies, dtype=bool)
        infos = []
        obs = self._obs
        for k, env in enumerate(self.envs):
            obs[k], rewards[k], terminated[k], truncated[k], terms, in_goal = env._step_arrays(
                cmd[k]
            )
            infos.append(env._infos(terms, in_goal))
        final_obs = obs.copy()
        done = terminated | truncated
        for k in np.flatnonzero(done).tolist():
            # automatic reset: the next episode continues the copy's generator
            obs[k] = self.envs[k]._reset_arrays(None)
        return obs, rewards, terminated, truncated, infos, final_obs

    def close(self) -> None:
        """Close every copy."""
        for e in self.envs:
            e.close()
