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
each step runs the parallel environment's own array core (``UrbanCanyonEnv._step_arrays``:
world step, rewards, observations). ``tests/envs/test_batched.py`` checks observations,
rewards, terminations, truncations and infos against separate environments over episodes
that end at different steps.

What is batched and what is not
-------------------------------
The action checks and clipping, the reward, termination and observation buffers are single
``(K, ...)`` numpy operations. The world step of each copy -- satellites, line of sight,
pseudoranges, the standalone and cooperative navigation solvers, the skyline and wall
sensors -- still runs copy by copy: the copies see different satellites (their episodes
start at different times) and different cities, and stacking their solver problems would
change the floating-point summation order of the solvers (padding to a common satellite
count changes numpy's pairwise sums and LAPACK's blocking), so the episodes would no longer
be those of separate environments. What the batching removes is the per-agent dictionary
plumbing of PettingZoo and SuperSuit (observations, rewards, actions and flags per agent),
not the physics.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from gymnasium import spaces

from coopnav_env.constants import SYSTEMS, WGS84_A_M, WGS84_B_M, WGS84_E2, WGS84_F
from coopnav_env.envs import _batched_kernels
from coopnav_env.envs import urban_canyon as _urban_canyon
from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.envs.urban_canyon import (
    INFO_KEYS,
    NO_FIX_ERROR_M,
    UrbanCanyonEnv,
    _team_mix,
)
from coopnav_env.gnss.errors import _iono_factors
from coopnav_env.gnss.frames import _EP2, _N_BOWRING_ITER
from coopnav_env.nav.types import PLAUSIBLE_RADIUS_M
from coopnav_env.nav.wls import _radius_args
from coopnav_env.sim import city as _city
from coopnav_env.sim import scenario as _scenario
from coopnav_env.sim.city import Buildings
from coopnav_env.sim.scenario import Epoch

__all__ = ["BatchedUrbanCanyonEnv"]


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
        self._fused = _fused_settings(self.config)
        self._state: _SwarmArrays | None = None  # the copies' state for the fused step
        self._skies = _SkyTable()

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
        self._state = None  # loaded from the copies at the next fused step
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
        ``(N, K, 3)`` array included), raises ``ValueError``.

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
        if self._needs_reset:
            raise ValueError("step() called before reset(): call reset() first")
        cmd = self._actions(actions)
        if self._fused and self._fused_ready():
            return self._step_fused(cmd)
        self._state = None  # the copies stepped one by one: reload before a fused step
        return self._step_copies(cmd)

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

    # ---- the fused step -----------------------------------------------------------------------

    def _fused_ready(self) -> bool:
        """Whether every copy can take the fused step now (grid or canyon buildings, the
        world's own cached sky, warm-started navigation); loads their state if needed."""
        if self._state is None:
            worlds = [e.world for e in self.envs]
            if not all(_fused_world(w) for w in worlds):
                return False
            self._state = _SwarmArrays(self.envs)
        return True

    def _step_fused(
        self, cmd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict[str, dict]], np.ndarray]:
        """:meth:`step` as three compiled calls over all copies (:mod:`coopnav_env.envs.
        _batched_kernels`) between the numpy rotations, with each copy's own draws."""
        cfg = self.config
        envs = self.envs
        st = self._state
        n_copies, n = self.n_copies, self.n_agents
        world0 = envs[0].world
        dt = cfg.dt_s
        # the epoch's sky of each copy (its own time)
        t_new = [e.world.t_s + dt for e in envs]
        rows = self._skies.rows(world0, t_new)
        if rows is None:  # a sky whose satellites are not grouped by constellation
            self._state = None
            return self._step_copies(cmd)
        skies, row, n_sv, n_up = rows
        # each copy's draws in the order of UrbanWorld._navigate_fused: pseudoranges
        # (S + N S), relative sensing (N (N - 1) / 2 x 3), as one call per copy
        n_draws = n_sv * (1 + n) + 3 * (n * (n - 1) // 2)
        z = np.empty((n_copies, int(n_draws.max())))
        for k, e in enumerate(envs):
            z[k, : n_draws[k]] = e._rng.standard_normal(n_draws[k])
        los_off = np.zeros(n_copies + 1, dtype=np.int64)
        np.cumsum(n * n_sv, out=los_off[1:])
        tab = self._skies
        rs = cfg.relative_sensing
        pos1 = np.empty((n_copies, n, 3))
        vel1 = np.empty((n_copies, n, 3))
        hit = np.empty((n_copies, n), dtype=bool)
        sep = np.empty((n_copies, n), dtype=bool)
        los_flat = np.empty(int(los_off[-1]), dtype=bool)
        rel = np.empty((n_copies, n, n, 3))
        var = np.empty((n_copies, n, n))
        avail = np.empty((n_copies, n, n), dtype=bool)
        _run_chunks(
            _batched_kernels.motion_sight_relative,
            n_copies,
            st.pos,
            st.vel,
            cmd,
            st.motion,
            st.fence_lo,
            st.fence_hi,
            st.b_lo,
            st.b_hi,
            st.n_b,
            row,
            n_sv,
            tab.up,
            tab.order,
            tab.cot,
            tab.hdir,
            n_up,
            z,
            np.array([rs.sigma0_m, rs.sigma_per_m, rs.max_range_m], dtype=np.float64),
            los_off,
            pos1,
            vel1,
            hit,
            sep,
            los_flat,
            rel,
            var,
            avail,
        )
        # the rotations to ECEF stay numpy matmuls (their rounding is numpy's, as one copy's)
        origin, rot = world0.origin_ecef_m, world0.rot_enu
        rx_ecef = origin + pos1 @ rot
        pred = st.nav_pos + vel1 * dt  # warm start: the previous estimates moved
        x0 = origin + pred @ rot
        rel_ecef = rel @ rot
        dr_var = (cfg.dead_reckoning_sigma_mps * dt) ** 2 * 1.0
        model = cfg.error_model
        gate = cfg.max_fix_sigma_m
        check, r_lo, r_hi = _radius_args(PLAUSIBLE_RADIUS_M)
        shared = cfg.centroid_mode == "shared" or n == 1
        outputs = _navigation_outputs(n_copies, n, envs[0]._rays.shape[0])
        _run_chunks(
            _batched_kernels.navigation_reward_sensors,
            n_copies,
            shared,
            rx_ecef,
            row,
            n_sv,
            tab.sv,
            tab.system,
            los_flat,
            los_off,
            st.clock,
            _iono_factors(model),
            z,
            np.array(
                [model.sigma_ure_m, float(bool(model.tropo)), float(bool(model.differential))]
            ),
            len(SYSTEMS),
            x0,
            rel_ecef,
            var,
            avail,
            cfg.transfer == "ddt",
            int(cfg.nav_max_iter),
            np.array([float(check), r_lo, r_hi]),
            np.array([float(gate is not None), float(gate) ** 2 if gate is not None else 0.0]),
            origin,
            rot,
            pred,
            st.nav_cov,
            float(dr_var),
            st.route,
            st.tail,
            st.n_route,
            st.wp,
            float(cfg.route_reach_m),
            st.pos,
            pos1,
            st.goal,
            hit,
            sep,
            cfg.nav_reward == "sigma",
            envs[0]._reward_params,
            envs[0]._rays,
            st.b_lo,
            st.b_hi,
            st.n_b,
            _WGS84,
            _N_BOWRING_ITER,
            outputs,
        )
        (
            sa_status,
            n_iter,
            sa_pos,
            sa_cov,
            co_pos,
            co_cov,
            co_status,
            source,
            nav_pos,
            nav_cov,
            sa_rej,
            co_rej,
            wp,
            n_swarm,
            n_sats,
            centroid_uav,
            out_of_contact,
            terms,
            in_goal,
            ends,
            tan_max,
            walls,
            bad_geometry,
        ) = outputs
        if bad_geometry.any():
            raise ValueError(
                "a receiver is at the Earth's centre or on a satellite (copies "
                f"{np.flatnonzero(bad_geometry).tolist()})"
            )
        sky_deg = np.degrees(np.arctan(tan_max))
        steps = st.steps + 1
        obs = np.empty((n_copies, n, self.obs_dim), dtype=np.float32)
        floats = np.empty((n_copies, 8, n))
        _run_chunks(
            _batched_kernels.observations_infos,
            n_copies,
            nav_pos,
            st.goal,
            vel1,
            nav_cov,
            n_sats,
            n_swarm,
            n_sv,
            sky_deg,
            rel,
            avail,
            st.route,
            st.tail,
            st.n_route,
            wp,
            source,
            walls,
            steps,
            st.obs_params,
            cfg.obs_neighbours,
            envs[0]._obs_low,
            envs[0]._obs_high,
            pos1,
            co_pos,
            sa_pos,
            obs,
            floats,
        )
        # the copies' worlds and epochs (what their own step would have left)
        pos_c, vel_c, wp_c = pos1.copy(), vel1.copy(), wp.copy()
        nlos = np.zeros(los_flat.shape[0], dtype=bool)
        rewards = np.empty((n_copies, n))
        terminated = np.zeros(n_copies, dtype=bool)
        truncated = np.zeros(n_copies, dtype=bool)
        navigated = cfg.reward_scheme == "navigated_distance"
        for k, e in enumerate(envs):
            w = e.world
            sky = skies[k]
            a, b = los_off[k], los_off[k + 1]
            los = los_flat[a:b].reshape(n, n_sv[k])
            w.pos_enu_m, w.vel_enu_mps, w.t_s = pos1[k], vel1[k], t_new[k]
            w.nav_pos_enu_m, w.nav_cov_enu_m2, w.next_wp = nav_pos[k], nav_cov[k], wp[k]
            ep = Epoch(
                t_s=float(t_new[k]),
                pos_enu_m=pos_c[k],
                vel_enu_mps=vel_c[k],
                goal_enu_m=st.goal_c[k],
                sv_az_deg=sky.az,
                sv_el_deg=sky.el,
                system=sky.system,
                sv_index=sky.sv_index,
                los=los,
                received=los,
                nlos=nlos[a:b].reshape(n, n_sv[k]),
                n_above_mask=int(n_sv[k]),
                n_sats=n_sats[k],
                n_sats_swarm=n_swarm[k],
                rel_enu_m=rel[k],
                rel_available=avail[k],
                standalone_pos_enu_m=sa_pos[k],
                standalone_cov_enu_m2=sa_cov[k],
                standalone_status=sa_status[k],
                coop_pos_enu_m=co_pos[k],
                coop_cov_enu_m2=co_cov[k],
                coop_status=co_status[k],
                nav_pos_enu_m=nav_pos[k],
                nav_cov_enu_m2=nav_cov[k],
                nav_source=source[k],
                centroid_uav=int(centroid_uav[k]),
                collided=hit[k],
                separation_violation=sep[k],
                out_of_contact=out_of_contact[k],
                n_iter_standalone=int(n_iter[k, 0]),
                n_iter_coop=int(n_iter[k, 1]),
                standalone_rejected=sa_rej[k],
                coop_rejected=co_rej[k],
                next_waypoint=wp_c[k],
                map_excluded=None,
            )
            w.last = ep
            e._epoch = ep
            e._steps += 1
            stacked = terms[k]
            crash, reached = bool(ends[k, 0]), bool(ends[k, 1])
            if navigated:
                stacked[0], stacked[1] = e._navigated_distance(ep, reached)
            if cfg.nav_team_weight > 0.0:
                stacked[0] = _team_mix(stacked[0], cfg.nav_team_weight)
            rewards[k] = stacked.sum(axis=0)
            terminated[k] = crash or reached
            truncated[k] = (e._steps >= cfg.max_steps) and not terminated[k]
        infos = _step_infos(
            self.possible_agents,
            floats,
            (n_sats, n_swarm, n_sv, co_status, sa_status, source, wp_c),
            (co_rej, sa_rej, in_goal, hit, sep, out_of_contact),
            terms,
            steps,
        )
        final_obs = obs
        out = self._obs
        out[:] = obs
        st.advance(pos1, vel1, nav_pos, nav_cov, wp, steps)
        done = np.flatnonzero(terminated | truncated).tolist()
        if done:
            st.own()  # copies before rows change: the epochs above keep theirs
            for k in done:
                # automatic reset: the next episode continues the copy's generator
                out[k] = envs[k]._reset_arrays(None)
                if not _fused_world(envs[k].world):
                    self._state = None
                else:
                    st.load(k, envs[k])
        return out, rewards, terminated, truncated, infos, final_obs

    def close(self) -> None:
        """Close every copy."""
        for e in self.envs:
            e.close()


def _step_infos(
    agents: list[str],
    floats: np.ndarray,
    ints: tuple[np.ndarray, ...],
    flags: tuple[np.ndarray, ...],
    terms: np.ndarray,
    steps: np.ndarray,
) -> list[dict[str, dict[str, Any]]]:
    """Every copy's step infos, as ``UrbanCanyonEnv._infos`` builds one copy's (same keys in
    the same order, the same Python numbers), from ``(K, ...)`` arrays: the real numbers of
    :func:`coopnav_env.envs._kernels.info_floats` ``(K, 8, N)``; the satellites received,
    by the swarm, above the mask ``(K,)``, the statuses, sources and next waypoints; the
    rejection, goal, collision, separation and contact flags; the reward terms
    ``(K, 6, N)``; the episode steps ``(K,)``."""
    n = floats.shape[2]
    fixes = np.isfinite(floats[:, 1:3])
    floats[:, 1:3] = np.where(fixes, floats[:, 1:3], NO_FIX_ERROR_M)
    n_sats, n_swarm, n_open, co_status, sa_status, source, wp = ints
    real = floats.tolist()
    fix = fixes.tolist()
    cols_int = [a.tolist() for a in (n_sats, n_swarm, co_status, sa_status, source, wp)]
    cols_flag = [np.asarray(a, dtype=bool).tolist() for a in flags]
    reward = terms.tolist()
    open_sky = n_open.tolist()
    step = steps.tolist()
    keys = INFO_KEYS
    out = []
    for k, (r, fx, rw) in enumerate(zip(real, fix, reward)):
        ci = [c[k] for c in cols_int]
        cf = [c[k] for c in cols_flag]
        cols = (
            *r[:3],
            *fx,
            *r[3:7],
            ci[0],
            ci[1],
            [open_sky[k]] * n,
            ci[2],
            ci[3],
            ci[4],
            r[7],
            ci[5],
            *cf,
            *rw,
            [step[k]] * n,
        )
        out.append({a: dict(zip(keys, row)) for a, row in zip(agents, zip(*cols))})
    return out


def _navigation_outputs(n_copies: int, n: int, n_az: int) -> tuple[np.ndarray, ...]:
    """The arrays :func:`coopnav_env.envs._batched_kernels.navigation_reward_sensors` fills."""
    k, i64 = n_copies, np.int64
    return (
        np.empty((k, n), dtype=i64),  # sa_status
        np.empty((k, 2), dtype=i64),  # n_iter
        np.empty((k, n, 3)),  # sa_pos
        np.empty((k, n, 3, 3)),  # sa_cov
        np.empty((k, n, 3)),  # co_pos
        np.empty((k, n, 3, 3)),  # co_cov
        np.empty((k, n), dtype=i64),  # co_status
        np.empty((k, n), dtype=i64),  # source
        np.empty((k, n, 3)),  # nav_pos
        np.empty((k, n, 3, 3)),  # nav_cov
        np.empty((k, n), dtype=bool),  # sa_rej
        np.empty((k, n), dtype=bool),  # co_rej
        np.empty((k, n), dtype=i64),  # next_wp
        np.empty((k, n), dtype=i64),  # n_swarm
        np.empty((k, n), dtype=i64),  # n_sats
        np.empty(k, dtype=i64),  # centroid_uav
        np.empty((k, n), dtype=bool),  # out_of_contact
        np.empty((k, 6, n)),  # terms
        np.empty((k, n), dtype=bool),  # in_goal
        np.empty((k, 2), dtype=bool),  # ends
        np.empty((k, n, n_az)),  # tan_max
        np.empty((k, n, n_az)),  # walls
        np.zeros(k, dtype=bool),  # bad_geometry
    )


MIN_COPIES_PER_THREAD = 4
"""Fewest copies a thread of the fused step takes (fewer: the thread costs more than it saves)."""

_POOL: list[ThreadPoolExecutor] = []


def _threads() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _run_chunks(kernel: Any, n_copies: int, *args: Any) -> None:
    """``kernel(k0, k1, *args)`` over contiguous chunks of the copies, on every core.

    The kernels release the GIL (``nogil``) and write disjoint rows of their outputs, so
    chunks run in parallel; each copy's arithmetic is the same in any chunk. This thread and
    the pool's threads take the chunks one after another from a shared counter (a core that
    another process holds takes fewer). Threads rather than numba's ``parallel=True``: the
    OpenMP threading layer numba picks by default competes with PyTorch's own OpenMP pool in
    one process (a trainer's), which slowed both severalfold in the benchmark.
    """
    threads = min(_threads(), max(1, n_copies // MIN_COPIES_PER_THREAD))
    if threads == 1:
        kernel(0, n_copies, *args)
        return
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(max_workers=max(1, _threads() - 1)))
    n_chunks = min(4 * threads, max(1, n_copies // MIN_COPIES_PER_THREAD))
    bounds = np.linspace(0, n_copies, n_chunks + 1).astype(int).tolist()
    counter = itertools.count()  # next() is atomic under the GIL

    def work() -> None:
        while (i := next(counter)) < n_chunks:
            kernel(bounds[i], bounds[i + 1], *args)

    futures = [_POOL[0].submit(work) for _ in range(threads - 1)]
    work()
    for f in futures:
        f.result()


_WGS84 = np.array([WGS84_A_M, WGS84_B_M, WGS84_F, WGS84_E2, _EP2], dtype=np.float64)


def _fused_settings(cfg: UrbanCanyonConfig) -> bool:
    """Whether the settings are those the fused step computes: the default measurement and
    navigation chain (exact covariance, no NLOS draws, no dead-reckoning noise, no channel
    limit, no map exclusion, no integrity monitoring), velocity commands and the base
    observation, with every compiled kernel on. Other settings step copy by copy."""
    return (
        cfg.nlos_probability == 0.0
        and not cfg.dead_reckoning_noise
        and cfg.max_sats is None
        and cfg.nlos_exclusion == "off"
        and cfg.integrity == "off"
        and cfg.covariance == "exact"
        and cfg.action_frame == "velocity"
        and not (
            cfg.obs_protection_level
            or cfg.obs_satellite_sectors
            or cfg.obs_lookahead
            or cfg.obs_candidate_sky
            or cfg.obs_true_error
            or cfg.obs_agent_index
        )
        and _scenario._fused_path_on()
        and _urban_canyon._USE_KERNEL
        and _city._USE_KERNEL
    )


def _fused_world(world: Any) -> bool:
    """Whether a copy's world can take the fused step: box buildings (not a file city's
    polygons), its own constellation (the cached sky) and a warm-started navigation."""
    return (
        isinstance(world.city.buildings, Buildings)
        and world.constellation is world.__dict__.get("_cached_constellation")
        and bool(world._warm)
    )


class _SkyTable:
    """The skies of the copies' epochs as padded rows ``(T, S_max, ...)`` for the kernels.

    A row per GNSS time met (``UrbanWorld._sky``, itself cached); at most ``max_rows`` rows
    (the table starts again when full: with random start times few rows repeat).
    """

    def __init__(self, max_rows: int = 4096) -> None:
        self.max_rows = int(max_rows)
        self._index: dict[float, int] = {}
        self._skies: list[Any] = []
        self._alloc(16, 1)

    def _alloc(self, n_rows: int, s_max: int) -> None:
        self.sv = np.zeros((n_rows, s_max, 3))
        self.system = np.zeros((n_rows, s_max), dtype=np.int64)
        self.up = np.zeros((n_rows, s_max), dtype=bool)
        self.order = np.zeros((n_rows, s_max), dtype=np.int64)
        self.cot = np.zeros((n_rows, s_max))
        self.hdir = np.zeros((n_rows, s_max, 2))
        self.n_sv = np.zeros(n_rows, dtype=np.int64)
        self.n_up = np.zeros(n_rows, dtype=np.int64)

    def _grow(self, n_rows: int, s_max: int) -> None:
        old = (self.sv, self.system, self.up, self.order, self.cot, self.hdir, self.n_sv, self.n_up)
        used, s_old = len(self._skies), self.sv.shape[1]
        self._alloc(n_rows, s_max)
        new = (self.sv, self.system, self.up, self.order, self.cot, self.hdir, self.n_sv, self.n_up)
        for dst, src in zip(new, old):
            if src.ndim == 1:
                dst[:used] = src[:used]
            else:
                dst[:used, :s_old] = src[:used]

    def _add(self, sky: Any) -> int:
        i = len(self._skies)
        s, d = sky.sv_index.shape[0], sky.directions
        n_up = d.cot_s.shape[0]
        if i >= self.sv.shape[0] or s > self.sv.shape[1]:
            self._grow(
                max(self.sv.shape[0], 2 * i if i >= self.sv.shape[0] else i + 1),
                max(s, self.sv.shape[1]),
            )
        self.sv[i, :s] = sky.sv_ecef
        self.system[i, :s] = sky.system_idx
        self.up[i, :s] = d.up
        self.order[i, :n_up] = d.order
        self.cot[i, :n_up] = d.cot_s
        self.hdir[i, :n_up] = d.h_dir
        self.n_sv[i], self.n_up[i] = s, n_up
        self._skies.append(sky)
        return i

    def rows(self, world: Any, times: list[float]):
        """``(skies, row, n_sv, n_up)`` of the epochs at ``times`` (one per copy), or None
        where a sky's satellites are not grouped by constellation (the fused navigation
        needs them grouped)."""
        if len(self._index) + len(times) > self.max_rows:
            self._index.clear()
            self._skies.clear()
        index = self._index
        row = np.empty(len(times), dtype=np.int64)
        for k, t in enumerate(times):
            i = index.get(t)
            if i is None:
                sky = world._sky(t)
                if not sky.grouped:
                    return None
                i = index[t] = self._add(sky)
            row[k] = i
        skies = [self._skies[i] for i in row.tolist()]
        return skies, row, self.n_sv[row], self.n_up[row]


class _SwarmArrays:
    """The state of every copy as ``(K, ...)`` arrays, loaded from the copies' worlds.

    Buildings and routes are padded to the largest copy (``n_b``, ``n_route`` give each
    copy's count); :meth:`advance` takes the arrays of a step, :meth:`load` reloads one copy
    after its reset (after :meth:`own`, which copies the arrays the epochs share).
    """

    def __init__(self, envs: list[UrbanCanyonEnv]) -> None:
        cfg = envs[0].config
        kin = cfg.kinematics
        k_n, n = len(envs), cfg.n_uavs
        self.motion = np.array(
            [
                kin.max_speed_mps,
                kin.max_accel_mps2 * kin.dt_s,
                kin.dt_s,
                kin.altitude_min_m,
                kin.altitude_max_m,
                kin.uav_radius_m,
                kin.min_separation_m,
            ],
            dtype=np.float64,
        )
        w0 = envs[0].world
        self.pos = np.empty((k_n, n, 3))
        self.vel = np.empty((k_n, n, 3))
        self.nav_pos = np.empty((k_n, n, 3))
        self.nav_cov = np.empty((k_n, n, 3, 3))
        self.wp = np.empty((k_n, n), dtype=np.int64)
        self.clock = np.empty((k_n, *w0.clock_bias_m.shape))
        self.goal = np.empty((k_n, 3))
        self.fence_lo = np.empty((k_n, 2))
        self.fence_hi = np.empty((k_n, 2))
        self.obs_params = np.empty((k_n, envs[0]._obs_params.shape[0]))
        self.steps = np.empty(k_n, dtype=np.int64)
        self.n_b = np.zeros(k_n, dtype=np.int64)
        self.n_route = np.zeros(k_n, dtype=np.int64)
        b_max = max(e.world.city.buildings.min_m.shape[0] for e in envs)
        r_max = max(e.world.route_xy_m.shape[0] for e in envs)
        self.b_lo = np.zeros((k_n, max(b_max, 1), 3))
        self.b_hi = np.zeros((k_n, max(b_max, 1), 3))
        self.route = np.zeros((k_n, r_max, 2))
        self.tail = np.zeros((k_n, r_max))
        for k, e in enumerate(envs):
            self.load(k, e)

    def own(self) -> None:
        """Copy the arrays that the copies' worlds and epochs share, before :meth:`load`."""
        self.pos = self.pos.copy()
        self.vel = self.vel.copy()
        self.nav_pos = self.nav_pos.copy()
        self.nav_cov = self.nav_cov.copy()
        self.wp = self.wp.copy()

    def advance(self, pos, vel, nav_pos, nav_cov, wp, steps) -> None:
        """Take the state after a fused step (the arrays the worlds now view)."""
        self.pos, self.vel, self.nav_pos, self.nav_cov, self.wp = pos, vel, nav_pos, nav_cov, wp
        self.steps = steps
        self.goal_c = self.goal.copy()

    def load(self, k: int, env: UrbanCanyonEnv) -> None:
        """Copy ``k``'s state from its environment (after a reset)."""
        w = env.world
        r = env.config.kinematics.uav_radius_m
        self.pos[k] = w.pos_enu_m
        self.vel[k] = w.vel_enu_mps
        self.nav_pos[k] = w.nav_pos_enu_m
        self.nav_cov[k] = w.nav_cov_enu_m2
        self.wp[k] = w.next_wp
        self.clock[k] = w.clock_bias_m
        self.goal[k] = w.goal_enu_m
        x0, x1, y0, y1 = w.city.extent_m
        self.fence_lo[k] = (x0 + r, y0 + r)
        self.fence_hi[k] = (x1 - r, y1 - r)
        self.obs_params[k] = env._obs_params
        self.steps[k] = env._steps
        b = w.city.buildings
        nb = b.min_m.shape[0]
        if nb > self.b_lo.shape[1]:
            self.b_lo = _pad(self.b_lo, nb)
            self.b_hi = _pad(self.b_hi, nb)
        self.b_lo[k, :nb] = b.min_m
        self.b_hi[k, :nb] = b.max_m
        self.n_b[k] = nb
        route, tail = w.route_xy_m, w.route_tail_m
        nr = route.shape[0]
        if nr > self.route.shape[1]:
            self.route = _pad(self.route, nr)
            self.tail = _pad(self.tail, nr)
        self.route[k, :nr] = route
        self.tail[k, :nr] = tail
        self.n_route[k] = nr
        self.goal_c = self.goal.copy()


def _pad(a: np.ndarray, size: int) -> np.ndarray:
    """``a`` with its second axis grown to at least ``size`` (zeros; room for more)."""
    out = np.zeros((a.shape[0], max(size, 2 * a.shape[1]), *a.shape[2:]), dtype=a.dtype)
    out[:, : a.shape[1]] = a
    return out
