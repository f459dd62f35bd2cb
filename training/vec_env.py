"""Parameter-sharing vector environments for Stable-Baselines3, with seeding that works.

SuperSuit turns a PettingZoo ParallelEnv into a vector env with one slot per agent
(``pettingzoo_env_to_vec_env_v1``) and concatenates copies of it
(``concat_vec_envs_v1(..., base_class="stable_baselines3")``), so one SB3 policy is shared by
all UAVs. Three gaps of that path are closed here:

* **Seeding.** SuperSuit's ``SB3VecEnvWrapper`` has no working ``seed()`` (it forwards to a
  gymnasium vector env that has none), so ``PPO(seed=...)`` fails. :class:`SeededVecEnv`
  implements ``seed(seed)``: the next ``reset()`` resets swarm copy ``k`` with reset seed
  ``seed + k``, then every later episode continues each copy's own generator, so two runs
  with the same seed see exactly the same episodes.
* **Distinct seeds across processes.** With ``num_cpus > 1`` SuperSuit gives process ``p``
  the seed ``seed + p`` and its ``j``-th copy ``seed + p + j``: copies collide. Each copy here
  corrects the seed it receives (:class:`_SeedShiftMarkovVectorEnv`), so copy ``k`` gets
  ``seed + k`` whatever the number of processes, exactly as in one process.
* **Terminal infos.** SuperSuit resets a finished swarm inside ``step`` and merges the reset
  infos *over* the final step's infos, so a callback would read the new episode's
  ``goal_reached`` instead of the finished one's. Reset infos are dropped there instead (SB3
  does not use them). Truncation (``max_steps``) is reported to SB3 as
  ``info["TimeLimit.truncated"]`` so that PPO bootstraps the value of the last observation
  instead of treating the time limit as a terminal state.

SB3 counts agent-steps as timesteps: one step of ``n_envs`` swarms of ``n_uavs`` UAVs is
``n_envs * n_uavs`` timesteps.

**From your own script.** PettingZoo's published SuperSuit recipe fails with
``PPO(..., seed=0)`` (``'ConcatVecEnv' object has no attribute 'seed'``) and never sets
``TimeLimit.truncated``; :func:`urban_canyon_vec_env` (``urban_canyon_v0`` from its keyword
arguments) and :func:`make_vec_env` (any PettingZoo ParallelEnv) are the public entry points
that ``coopnav train`` itself uses, with both fixed::

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from coopnav_env.training.vec_env import urban_canyon_vec_env

    torch.set_num_threads(1)  # one torch thread per process: much faster on small machines
    venv = VecMonitor(urban_canyon_vec_env(n_copies=2, n_uavs=3, max_steps=100))
    model = PPO("MlpPolicy", venv, seed=0, device="cpu").learn(10_000)

``examples/sb3_vec_env.py`` is a complete script (tested). ``VecMonitor`` is optional; it
records episode returns (per UAV slot) for SB3's logger.

Two kinds build the same vector environment (``make_vec_env(..., kind=...)``, the
``vec_env`` setting of ``coopnav train``):

* ``"supersuit"`` (any PettingZoo ParallelEnv): SuperSuit's per-agent adapters as above,
  optionally over worker processes.
* ``"batched"`` (``urban_canyon_v0`` only): :class:`BatchedVecEnv` over
  :class:`coopnav_env.envs.BatchedUrbanCanyonEnv`, which steps the ``n_copies`` swarms with
  one ``(K, N, 3)`` action array instead of per-agent dictionaries. Same slots (agent-major
  inside each copy), same seeding (copy ``k`` reset with ``seed + k``, then each copy
  continues its generator), same observations, rewards, dones and infos (including
  ``terminal_observation`` and ``TimeLimit.truncated``) as the SuperSuit kind in one
  process, bit for bit (``tests/training/test_batched_vec_env.py``). Actions are cast to
  float32 first, as SuperSuit does (it copies them into arrays of the action space's dtype).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from pettingzoo import ParallelEnv
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn
from supersuit.vector import MakeCPUAsyncConstructor, MarkovVectorEnv
from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

__all__ = [
    "VEC_ENV_KINDS",
    "BatchedVecEnv",
    "SeededVecEnv",
    "make_vec_env",
    "urban_canyon_vec_env",
]

VEC_ENV_KINDS: tuple[str, ...] = ("supersuit", "batched")
"""Kinds of vector environment :func:`make_vec_env` builds (``coopnav train``'s ``vec_env``)."""


class _SeedShiftMarkovVectorEnv(MarkovVectorEnv):
    """SuperSuit's agents-as-vector adapter with a seed correction and clean terminal infos.

    Parameters
    ----------
    par_env : pettingzoo.ParallelEnv
        One swarm; every agent must stay alive until the whole swarm is done.
    seed_shift : int
        Added to every reset seed this copy receives, so that copy ``k`` is reset with
        ``seed + k`` even when SuperSuit hands it ``seed + p + j`` (process ``p``, slot ``j``).
    """

    def __init__(self, par_env: ParallelEnv, seed_shift: int = 0):
        super().__init__(par_env, black_death=False)
        self.seed_shift = int(seed_shift)
        self._in_step = False

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            seed = int(seed) + self.seed_shift
        obs, infos = super().reset(seed=seed, options=options)
        if self._in_step:  # automatic reset inside step(): keep the final step's infos
            infos = [{} for _ in infos]
        return obs, infos

    def step(self, actions):
        self._in_step = True
        try:
            return super().step(actions)
        finally:
            self._in_step = False


class _CopyFactory:
    """Picklable constructor of swarm copy ``k`` (for SuperSuit's worker processes)."""

    def __init__(self, env_fn: Callable[[], ParallelEnv], seed_shift: int):
        self.env_fn = env_fn
        self.seed_shift = seed_shift

    def __call__(self) -> _SeedShiftMarkovVectorEnv:
        return _SeedShiftMarkovVectorEnv(self.env_fn(), self.seed_shift)


class _SwarmSeeding:
    """``seed()`` of the swarm vector envs: copy ``k`` gets ``seed + k`` at the next reset."""

    num_envs: int
    n_copies: int
    n_agents: int
    _pending_seed: int | None

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset: swarm copy ``k`` gets ``seed + k``; one entry per slot."""
        self._pending_seed = None if seed is None else int(seed)
        if seed is None:
            return [None] * self.num_envs
        return [int(seed) + k for k in range(self.n_copies) for _ in range(self.n_agents)]


class SeededVecEnv(_SwarmSeeding, VecEnvWrapper):
    """SB3 ``VecEnv`` over SuperSuit's concatenated swarms, with a working ``seed()``.

    Parameters
    ----------
    venv : SB3VecEnvWrapper
        What ``concat_vec_envs_v1(..., base_class="stable_baselines3")`` returns.
    n_copies : int
        Number of swarm copies inside (``num_envs`` is ``n_copies * n_agents``).

    Notes
    -----
    ``seed(s)`` takes effect at the next ``reset()`` (as in SB3 since gymnasium 0.26): copy
    ``k`` is reset with ``s + k``. A ``reset()`` without a pending seed continues every
    copy's generator.
    """

    def __init__(self, venv: SB3VecEnvWrapper, n_copies: int):
        super().__init__(venv)
        self.n_copies = int(n_copies)
        self.n_agents = self.num_envs // self.n_copies
        self._pending_seed: int | None = None
        self.reset_infos: list[dict[str, Any]] = []

    @property
    def _gym_venv(self) -> Any:
        """The gymnasium-style vector env under SuperSuit's SB3 adapter."""
        return self.venv.venv

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """Attributes of the sub-envs; ``render_mode`` is the swarm's (SB3 asks for it)."""
        if attr_name == "render_mode":
            return [getattr(self._gym_venv, "render_mode", None)] * self.num_envs
        return self.venv.get_attr(attr_name, indices)

    def reset(self) -> VecEnvObs:
        seed, self._pending_seed = self._pending_seed, None
        obs, self.reset_infos = self._gym_venv.reset(seed=seed)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._gym_venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, terms, truncs, infos = self._gym_venv.step_wait()
        terms = np.asarray(terms, dtype=bool)
        truncs = np.asarray(truncs, dtype=bool)
        dones = terms | truncs
        infos = list(infos)
        for i in np.flatnonzero(truncs & ~terms):
            infos[i] = {**infos[i], "TimeLimit.truncated": True}
        return obs, np.asarray(rewards, dtype=np.float32), dones, infos

    def close(self) -> None:
        self._gym_venv.close()


class BatchedVecEnv(_SwarmSeeding, VecEnv):
    """SB3 ``VecEnv`` over :class:`coopnav_env.envs.BatchedUrbanCanyonEnv` (parameter sharing).

    Slot ``k * N + i`` is UAV ``i`` of swarm copy ``k``, as in :class:`SeededVecEnv`; the
    observations, rewards, dones, infos and seeding are those of the SuperSuit kind (see
    the module docstring).

    Parameters
    ----------
    batch : BatchedUrbanCanyonEnv
    """

    def __init__(self, batch: Any):
        self.batch = batch
        self.n_copies = batch.n_copies
        self.n_agents = batch.n_agents
        self._pending_seed: int | None = None
        self._actions: np.ndarray | None = None
        super().__init__(
            batch.n_copies * batch.n_agents, batch.observation_space, batch.action_space
        )

    def reset(self) -> VecEnvObs:
        seed, self._pending_seed = self._pending_seed, None
        obs, infos = self.batch.reset(seed=seed)
        agents = self.batch.possible_agents
        self.reset_infos = [info.get(a, {}) for info in infos for a in agents]
        return obs.reshape(self.num_envs, -1).copy()

    def step_async(self, actions: np.ndarray) -> None:
        # as SuperSuit: actions are copied into arrays of the action space's dtype (float32)
        self._actions = np.asarray(actions, dtype=self.action_space.dtype)

    def step_wait(self) -> VecEnvStepReturn:
        """Step every copy through ``BatchedUrbanCanyonEnv.step_arrays``.

        The slot infos are built straight from the info arrays (one flat dict per slot, no
        per-copy agent dicts); a finished copy's slots get ``terminal_observation`` and, when
        the time limit ended the episode, ``TimeLimit.truncated``.
        """
        if self._actions is None:
            raise ValueError("step_wait() called without step_async()")
        actions, self._actions = self._actions, None
        step = self.batch.step_arrays(actions.reshape(self.n_copies, self.n_agents, -1))
        done = step.terminated | step.truncated
        keys = list(step.info)
        # each column flattened slot-major (slot k * N + i), as Python numbers
        columns = [a.reshape(-1).tolist() for a in step.info.values()]
        flat_infos: list[dict[str, Any]] = [dict(zip(keys, row)) for row in zip(*columns)]
        if done.any():
            final_obs = step.final_obs.reshape(self.num_envs, -1)
            n = self.n_agents
            for k in np.flatnonzero(done).tolist():
                time_limit = bool(step.truncated[k] and not step.terminated[k])
                for slot in range(k * n, (k + 1) * n):
                    info = flat_infos[slot]
                    info["terminal_observation"] = final_obs[slot].copy()
                    if time_limit:
                        info["TimeLimit.truncated"] = True
        return (
            step.obs.reshape(self.num_envs, -1).copy(),
            step.rewards.reshape(-1).astype(np.float32),
            np.repeat(done, self.n_agents),
            flat_infos,
        )

    def close(self) -> None:
        self.batch.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """Attributes of the swarm copies, one entry per slot (``render_mode`` is None)."""
        idx = self._indices(indices)
        if attr_name == "render_mode":
            return [None] * len(idx)
        return [getattr(self.batch.envs[i // self.n_agents], attr_name) for i in idx]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for k in sorted({i // self.n_agents for i in self._indices(indices)}):
            setattr(self.batch.envs[k], attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        return [
            getattr(self.batch.envs[i // self.n_agents], method_name)(*method_args, **method_kwargs)
            for i in self._indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int | np.integer):
            return [int(indices)]
        return [int(i) for i in indices]


def make_vec_env(
    env_fn: Callable[[], ParallelEnv],
    n_copies: int = 1,
    num_cpus: int = 1,
    kind: str = "supersuit",
) -> SeededVecEnv | BatchedVecEnv:
    """Build the parameter-sharing SB3 vector env of ``n_copies`` swarms.

    Parameters
    ----------
    env_fn : callable
        Returns a fresh PettingZoo ParallelEnv (one swarm). Must be picklable (e.g. a
        ``functools.partial``) when ``num_cpus > 1``.
    n_copies : int, default 1
        Number of independent swarms stepped together, >= 1.
    num_cpus : int, default 1
        Worker processes; 0 or 1 steps everything in this process (best on 2-core machines,
        where the policy update competes with the workers). The batched kind always runs
        in this process and requires 0 or 1.
    kind : {"supersuit", "batched"}, default "supersuit"
        See the module docstring; ``"batched"`` needs ``env_fn`` to return
        ``urban_canyon_v0`` environments.

    Returns
    -------
    SeededVecEnv or BatchedVecEnv
        ``num_envs = n_copies * n_agents`` slots, agent-major inside each copy
        (``uav_0 .. uav_{N-1}`` of copy 0, then copy 1, ...).

    Notes
    -----
    * ``PPO(..., seed=s)`` works: SB3 calls ``seed(s)``, and the next ``reset()`` resets
      swarm copy ``k`` with ``s + k`` (whatever ``num_cpus``); later episodes continue each
      copy's generator, so the same seed gives the same episodes and, in one process, the
      same trained weights.
    * An episode cut by the environment's ``max_steps`` ends with ``done`` and
      ``info["TimeLimit.truncated"] = True`` in every slot of that swarm (and
      ``info["terminal_observation"]``), so that PPO bootstraps the value of the last
      observation instead of treating the time limit as a terminal state; a crash or the
      goal ends the episode without that flag.
    * Both kinds give the same observations, rewards, dones and infos, bit for bit.
    """
    if int(n_copies) < 1:
        raise ValueError(f"n_copies must be >= 1, got {n_copies}")
    if int(num_cpus) < 0:
        raise ValueError(f"num_cpus must be >= 0, got {num_cpus}")
    if kind not in VEC_ENV_KINDS:
        raise ValueError(f"vec_env kind must be one of {VEC_ENV_KINDS}, got {kind!r}")
    if kind == "batched":
        from coopnav_env.envs import BatchedUrbanCanyonEnv

        if int(num_cpus) > 1:
            raise ValueError(
                f"the batched vec_env steps every copy in this process: num_cpus must be 0 or "
                f"1, got {num_cpus}"
            )
        return BatchedVecEnv(BatchedUrbanCanyonEnv.from_envs([env_fn() for _ in range(n_copies)]))
    import supersuit as ss

    n_copies, num_cpus = int(n_copies), min(int(num_cpus), int(n_copies))
    if num_cpus <= 1:
        # one process: ConcatVecEnv resets copy k with seed + k already
        one = _SeedShiftMarkovVectorEnv(env_fn(), 0)
        venv = ss.concat_vec_envs_v1(one, n_copies, num_cpus=0, base_class="stable_baselines3")
    else:
        # SuperSuit's own split of copies over processes (see MakeCPUAsyncConstructor):
        # process p holds copies [p * per_cpu, (p + 1) * per_cpu) and resets its j-th copy
        # with seed + p + j; shift it to seed + k, k = p * per_cpu + j.
        per_cpu = (n_copies + num_cpus - 1) // num_cpus
        fns = [_CopyFactory(env_fn, k - (k // per_cpu + k % per_cpu)) for k in range(n_copies)]
        probe = fns[0]()
        gym_venv = MakeCPUAsyncConstructor(num_cpus)(
            fns, probe.observation_space, probe.action_space
        )
        probe.close()
        venv = SB3VecEnvWrapper(gym_venv)
    return SeededVecEnv(venv, n_copies)


def urban_canyon_vec_env(
    n_copies: int = 1,
    *,
    kind: str = "batched",
    num_cpus: int = 1,
    **env_kwargs: Any,
) -> SeededVecEnv | BatchedVecEnv:
    """The parameter-sharing SB3 vector env of ``n_copies`` ``urban_canyon_v1`` swarms.

    The entry point for training ``urban_canyon_v1`` with Stable-Baselines3 from your own
    script: ``PPO("MlpPolicy", urban_canyon_vec_env(2, n_uavs=3), seed=0)`` works and
    repeats, and time-limit truncation reaches PPO as ``TimeLimit.truncated`` (see
    :func:`make_vec_env`, which this calls, and the module docstring).

    Parameters
    ----------
    n_copies : int, default 1
        Independent swarms stepped together, >= 1 (``num_envs = n_copies * n_uavs``).
    kind : {"batched", "supersuit"}, default "batched"
        ``"batched"``: the environment's own batched stepping (one ``(K, N, 3)`` action array,
        1.3-1.6x as fast); ``"supersuit"``: SuperSuit's per-agent adapters (needed for
        ``num_cpus > 1``). Same episodes either way.
    num_cpus : int, default 1
        Worker processes of the ``"supersuit"`` kind (0 or 1: this process).
    **env_kwargs
        Settings of ``urban_canyon_v1.parallel_env`` (:class:`coopnav_env.envs.config.
        UrbanCanyonConfig`), e.g. ``n_uavs=3, max_steps=100``; an unknown or bad one raises
        ``ValueError`` naming it when the first swarm is built.

    Returns
    -------
    SeededVecEnv or BatchedVecEnv
    """
    from coopnav_env.training.envs import DEFAULT_ENV_ID, make_env_fn

    return make_vec_env(make_env_fn(DEFAULT_ENV_ID, env_kwargs), n_copies, num_cpus, kind=kind)
