"""The PettingZoo parallel environment ``urban_canyon_v0`` (the adapter around the world).

The world itself (city, satellites, measurements, navigation) is
:class:`coopnav_env.sim.scenario.UrbanWorld`; this module turns its epochs into observations,
rewards, terminations and frames. The user documentation (agents, spaces, rewards, episode
end, arguments, version history) is the docstring of :mod:`coopnav_env.urban_canyon_v0`.

One step: the command (with ``action_frame="route"``, the route autopilot of
:mod:`coopnav_env.envs.autopilot` turns set-points into velocities) -> ``UrbanWorld.step``
-> the task of :mod:`coopnav_env.envs.task` (reward terms, termination and truncation,
observations, state) -> flat infos. Default settings take the fused step of
:mod:`coopnav_env.envs._fused` (the same numbers, bit for bit), as a batch of one.

Observation layout
------------------
One float32 vector per agent, ``20 + 2 A + 4 K`` long (``A = obs_sky_azimuths``, default 8;
``K = obs_neighbours``, default 4; 52 by default), clipped to its bounds. The index table (with
units and scales) is in the docstring of :mod:`coopnav_env.urban_canyon_v0`; it is built by
:meth:`coopnav_env.envs.task.UrbanCanyonTask.observations`, in the same order. Optional blocks
follow, in this order: the two protection levels (``obs_protection_level``), then the
satellites tracked and the satellites above the cut-off not tracked per skyline azimuth
sector, ``A`` entries each (``obs_satellite_sectors``,
:meth:`~coopnav_env.envs.task.UrbanCanyonTask.satellite_sectors`), then the true position
error, 3 entries (``obs_true_error``), then the UAV's one-hot index, ``N`` entries
(``obs_agent_index``).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from coopnav_env.envs import _kernels
from coopnav_env.envs.autopilot import (
    ROUTE_FRAME_GAIN_PER_S,
    check_route_offset,
    route_frame_command,
    route_offset_room_m,
)
from coopnav_env.envs.config import V1_DEFAULTS, UrbanCanyonConfig, make_config
from coopnav_env.envs.task import (
    REWARD_TERMS,
    UrbanCanyonTask,
    city_scale_m,
    episode_end,
    observation_bounds,
    state_bounds,
)
from coopnav_env.sim.file_city import FileCity
from coopnav_env.sim.scenario import Epoch, UrbanWorld

__all__ = [
    "INFO_KEYS",
    "NO_FIX_ERROR_M",
    "REWARD_TERMS",
    "ROUTE_FRAME_GAIN_PER_S",
    "UrbanCanyonEnv",
    "UrbanCanyonV1Env",
    "aec_env",
    "aec_env_v1",
    "fix_error_m",
    "parallel_env",
    "parallel_env_v1",
    "route_frame_command",
    "route_offset_room_m",
]

NO_FIX_ERROR_M = -1.0
"""``coop_error_m`` / ``standalone_error_m`` in the infos when that fix does not exist (the
flags ``coop_fix`` / ``standalone_fix`` say so); finite, so that averaging loggers stay finite."""

INFO_KEYS: tuple[str, ...] = (
    "nav_error_m",
    "coop_error_m",
    "standalone_error_m",
    "coop_fix",
    "standalone_fix",
    "sig_e_m",
    "sig_n_m",
    "sig_u_m",
    "sig_3d_m",
    "n_sats",
    "n_sats_swarm",
    "n_sats_open_sky",
    "coop_status",
    "standalone_status",
    "nav_source",
    "goal_distance_m",
    "next_waypoint",
    "coop_rejected",
    "standalone_rejected",
    "in_goal",
    "collided",
    "separation_violation",
    "out_of_contact",
    *(f"reward_{t}" for t in REWARD_TERMS),
    "step",
)
"""The keys of ``infos[agent]``, in order: the same at reset and at every step, all numbers."""


class UrbanCanyonEnv(ParallelEnv, EzPickle):
    """A UAV swarm crossing a city with cooperative GNSS navigation (PettingZoo ParallelEnv).

    See :mod:`coopnav_env.urban_canyon_v0` for the documentation page.

    Parameters
    ----------
    config : UrbanCanyonConfig, optional
        Complete configuration; default ``UrbanCanyonConfig()``.
    render_mode : {None, "rgb_array", "human"}
        ``"rgb_array"``: :meth:`render` returns an ``(H, W, 3)`` uint8 frame; ``"human"``: it
        shows the frame in a matplotlib window (and every step draws it).
    **overrides
        Any :class:`UrbanCanyonConfig` field, applied on top of ``config``. An unknown name
        raises ``ValueError`` listing the valid ones.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "urban_canyon_v0",
        "render_modes": ["human", "rgb_array"],
        "is_parallelizable": True,
        "render_fps": 4,
    }

    def __init__(
        self,
        config: UrbanCanyonConfig | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        cfg = make_config(config, **overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        EzPickle.__init__(self, config=cfg, render_mode=render_mode)
        self.config = cfg
        self.render_mode = render_mode
        self.possible_agents = [f"uav_{i}" for i in range(cfg.n_uavs)]
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self.world = UrbanWorld(cfg)
        self._rng: np.random.Generator | None = None  # created at the first reset
        self._epoch: Epoch | None = None
        self._steps = 0
        # the info arrays of the fused step just taken (read once by step())
        self._info_parts: tuple | None = None
        self._trail: list[np.ndarray] = []
        self._window: Any = None

        self.task = UrbanCanyonTask(cfg)
        lo, hi = observation_bounds(cfg)
        self.observation_spaces = {a: _box(lo, hi) for a in self.possible_agents}
        self.action_spaces = {a: _box(-1.0, 1.0, (3,)) for a in self.possible_agents}
        s_lo, s_hi = state_bounds(cfg)
        self.state_space = _box(s_lo, s_hi)
        # the task's constants under the names the fused step reads (coopnav_env.envs._fused)
        self._az_deg = self.task.az_deg
        self._rays = self.task.rays  # the sensors' horizontal ray directions
        self._obs_low, self._obs_high = self.task.obs_low, self.task.obs_high
        self._reward_params = self.task.reward_params

    # ---- spaces -----------------------------------------------------------------------------

    def observation_space(self, agent: str) -> spaces.Box:
        """The observation space of ``agent`` (the same object at every call)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The action space of ``agent``: ``Box(-1, 1, (3,), float32)``, the same object."""
        return self.action_spaces[agent]

    # ---- episode ----------------------------------------------------------------------------

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode; ``seed`` reseeds the environment's only generator.

        The infos hold the first epoch's figures, with the same flat keys as a step's (see
        the documentation page). Without a seed the episode continues the generator's stream
        (a new city, start and goal); the very first reset without a seed draws the generator
        from OS entropy, so that copies of a fresh environment (e.g. made by a vector wrapper)
        do not share a stream.

        ``options`` may hold ``noise_stream``, an integer >= 1 (it needs a ``seed``): the
        episode's scenario (city, satellites, start, goal) and its first epoch are those of
        ``seed``, and every later random draw (pseudorange and relative-sensing noise, NLOS
        and the dead reckoning) comes from a generator seeded with ``(seed, noise_stream)``:
        the same episode under an independent noise realisation, for variance reduction
        (e.g. ``coopnav train-routes --noise-replicates``). ``0`` or no option: the usual
        single stream. Other keys are ignored (PettingZoo's API test passes arbitrary ones).
        """
        stream = self._noise_stream(seed, options)
        obs = dict(zip(self.possible_agents, self._reset_arrays(seed)))
        if stream:
            self._rng = np.random.default_rng([int(seed), stream])  # type: ignore[arg-type]
        infos = self._reset_infos()
        if self.render_mode == "human":
            self.render()
        return obs, infos

    def _noise_stream(self, seed: int | None, options: dict[str, Any] | None) -> int:
        """The ``noise_stream`` reset option (see :meth:`reset`), checked; 0 without it."""
        if options is None:
            return 0
        if not isinstance(options, Mapping):
            raise ValueError(
                "reset options must be a dict (allowed keys: 'noise_stream'; others are "
                f"ignored), got {options!r} ({type(options).__name__})"
            )
        if not options:
            return 0
        if "noise_stream" not in options:  # other keys are ignored (PettingZoo's API test
            return 0  # passes arbitrary options and expects them accepted)
        k = options["noise_stream"]
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
            raise ValueError(f"options['noise_stream'] must be an integer >= 0, got {k!r}")
        if k and seed is None:
            raise ValueError("options['noise_stream'] needs a reset seed")
        return int(k)

    @staticmethod
    def check_seed(seed: Any) -> int:
        """A reset seed as an int, or ``ValueError``: an integer >= 0 (a bool is refused)."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be None or an integer >= 0, got {seed!r}")
        return int(seed)

    def _reset_arrays(self, seed: int | None) -> np.ndarray:
        """Reset (as :meth:`reset`) and return the observations as one ``(N, obs_dim)`` array."""
        self._begin_reset(seed)
        self._epoch = self.world.reset(self._rng)
        self._episode_scales()
        return self._finish_reset()

    def _begin_reset(self, seed: int | None) -> None:
        """:meth:`_reset_arrays` before the world's reset: the generator, agents, step count."""
        if seed is not None:
            self._rng = np.random.default_rng(self.check_seed(seed))
        elif self._rng is None:
            self._rng = np.random.default_rng()
        self.agents = self.possible_agents[:]
        self._steps = 0
        self._route_offset_cap_m = None
        self._info_parts = None

    def _episode_scales(self) -> None:
        """The scales of a new episode from its city (after the world's
        ``_begin_episode``): the route-frame offset check or cap, the city scale and the
        observation kernel's scales."""
        if self.config.action_frame == "route":
            if isinstance(self.world.city, FileCity):  # no single street width: the route's
                self._route_offset_cap_m = route_offset_room_m(
                    self.world.city, self.world.route_xy_m, self.config
                )
            else:
                check_route_offset(self.config, float(self.world.city.street_width_m))
        self._city_scale_m = city_scale_m(self.world)
        # the observation kernel's scales (the city scale changes with the city)
        self._obs_params = self.task.observation_params(self._city_scale_m)

    def _finish_reset(self, first: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """:meth:`_reset_arrays` after the world's first epoch (``_epoch``) and
        :meth:`_episode_scales`: the episode's route lengths and the observations.

        ``first``: the first observations ``(N, obs_dim)`` and each UAV's remaining route
        ``(N,)`` [m] that the batched environment's fused first epochs computed (then they
        are taken as they are)."""
        self._trail = [self._epoch.pos_enu_m] if self.render_mode is not None else []
        # reward_scheme="navigated_distance": each UAV's route length and the part not yet paid
        if first is not None:
            obs, route_m = first
            self._route_m, self._unpaid_m = self.task.unpaid_route(route_m)
            return obs
        self._route_m, self._unpaid_m = self.task.route_lengths(self.world, self._epoch)
        return self._observation_array()

    def _reset_infos(self) -> dict[str, dict[str, Any]]:
        """The infos :meth:`reset` returns for the current (first) epoch.

        The same flat keys as every step's infos (reward terms zero, ``step`` 0), so that
        libraries that build their info specs from the reset (TorchRL's ``PettingZooWrapper``,
        BenchMARL) see every key they will get later.
        """
        in_goal = self._epoch.goal_distance_m <= self.config.goal_radius_m
        return self._infos(self.task.zero_terms(), in_goal)

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Apply one velocity command per live agent and advance one epoch.

        Actions outside ``[-1, 1]`` are clipped. A missing or unknown agent, a wrong shape or a
        non-finite value raises ``ValueError``.
        """
        if self._epoch is None:
            raise ValueError("step() called before reset(): call reset() first")
        if not self.agents:
            raise ValueError("step() called after the episode ended: call reset() first")
        cmd = self._action_array(actions)
        obs_arr, reward, terminated, truncated, terms, in_goal = self._step_arrays(cmd)
        obs = dict(zip(self.possible_agents, obs_arr))
        parts, self._info_parts = self._info_parts, None
        infos = self._infos(terms, in_goal) if parts is None else self._infos_of_arrays(parts)
        agents = self.agents
        rewards = dict(zip(agents, reward.tolist()))
        terms_d = dict.fromkeys(agents, terminated)
        truncs_d = dict.fromkeys(agents, truncated)
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms_d, truncs_d, infos

    def _step_arrays(
        self, cmd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, bool, bool, dict[str, np.ndarray], np.ndarray]:
        """Advance one epoch with a checked, clipped command ``(N, 3)`` (float64).

        The array core of :meth:`step` (and of the batched vector environment): returns the
        observations ``(N, obs_dim)`` float32, the rewards ``(N,)``, terminated, truncated,
        the reward terms and the in-goal flags. It does not change :attr:`agents` and does not
        render.
        """
        from coopnav_env.envs._fused import step_one  # (the fused step imports this module)

        fused = step_one(self, cmd)
        if fused is not None:  # the step of BatchedUrbanCanyonEnv, as a batch of one
            *out, self._info_parts = fused
            return tuple(out)
        self._info_parts = None
        cfg = self.config
        prev = self._epoch
        if cfg.action_frame == "route":
            cap = getattr(self, "_route_offset_cap_m", None)
            cmd = route_frame_command(
                cmd,
                prev.nav_pos_enu_m,
                prev.next_waypoint,
                self.world.route_xy_m,
                cfg,
                offset_max_m=None if cap is None else cap[prev.next_waypoint],
            )
        ep = self.world.step(cmd, self._rng)
        if self._steps < cfg.crash_free_steps and ep.collided.any():
            # the crash-free start: the world stopped the UAV, the episode goes on
            ep = dataclasses.replace(ep, collided=np.zeros_like(ep.collided))
            self.world.last = ep
        self._epoch = ep
        self._steps += 1
        if self.render_mode is not None:
            self._trail.append(ep.pos_enu_m)
            self._trail = self._trail[-60:]

        out = self.task.reward(self.world, prev, ep, self._unpaid_m, self._route_m)
        self._unpaid_m = out.unpaid_m
        terminated, truncated = episode_end(self._steps, cfg.max_steps, out.crashed, out.reached)
        obs = self._observation_array()
        return obs, out.reward, terminated, truncated, out.terms, out.in_goal

    def _action_array(self, actions: dict[str, Any]) -> np.ndarray:
        if not isinstance(actions, dict):
            raise ValueError(
                f"actions must be a dict {{agent: action}}, got {type(actions).__name__}"
            )
        missing = [a for a in self.agents if a not in actions]
        unknown = [a for a in actions if a not in self._index]
        if missing or unknown:
            raise ValueError(
                f"actions must hold one action per live agent; missing: {missing}, "
                f"unknown: {unknown}"
            )
        try:
            cmd = np.asarray([actions[a] for a in self.agents])
        except (TypeError, ValueError):
            cmd = None  # ragged: the shapes say why
        if cmd is None or cmd.dtype.kind not in "biuf":  # strings and complex numbers too
            kinds = {a: np.asarray(actions[a]).dtype.name for a in self.agents}
            shapes = {a: np.shape(actions[a]) for a in self.agents}
            raise ValueError(
                "every action must be a real numeric array of shape (3,), got dtypes "
                f"{kinds} and shapes {shapes}"
            )
        cmd = cmd.astype(np.float64)
        if cmd.shape != (len(self.agents), 3):
            bad = {a: np.shape(actions[a]) for a in self.agents if np.shape(actions[a]) != (3,)}
            raise ValueError(f"every action must have shape (3,), got {bad}")
        if not np.isfinite(cmd).all():
            bad = [a for a, row in zip(self.agents, cmd) if not np.all(np.isfinite(row))]
            raise ValueError(f"actions contain NaN or inf for {bad}")
        # np.clip(cmd, -1, 1) of finite numbers, in place on the copy (two ufunc calls)
        return np.minimum(np.maximum(cmd, -1.0, out=cmd), 1.0, out=cmd)

    # ---- observations, infos, state ---------------------------------------------------------

    def _observation_array(self) -> np.ndarray:
        """Every agent's observation at the current epoch, ``(N, obs_dim)`` float32 (rows in
        agent order): :meth:`coopnav_env.envs.task.UrbanCanyonTask.observations`."""
        return self.task.observations(self.world, self._epoch, self._steps, self._obs_params)

    def _info_floats(self) -> np.ndarray:
        """The per-agent real numbers of the infos, ``(8, N)``, by the compiled
        :func:`coopnav_env.envs._kernels.info_floats`: errors of the estimate used, the
        cooperative and the standalone fix (inf: no fix), sigma E/N/U and 3-D, goal distance
        (its numpy definition, equal bit for bit, is ``info_floats`` of
        ``tests/envs/oracles.py``)."""
        ep = self._epoch
        return _kernels.info_floats(
            ep.pos_enu_m,
            ep.nav_pos_enu_m,
            ep.coop_pos_enu_m,
            ep.standalone_pos_enu_m,
            ep.nav_cov_enu_m2,
            ep.goal_enu_m,
        )

    def _infos(self, terms: dict[str, np.ndarray], in_goal: np.ndarray) -> dict[str, dict]:
        """Flat, numeric infos per agent (keys :data:`INFO_KEYS`, the same at every step).

        A missing fix is reported by its flag (``coop_fix``, ``standalone_fix``) with the
        error set to :data:`NO_FIX_ERROR_M` (-1), never ``inf`` or NaN: loggers average info
        values, and one ``inf`` would make every mean ``inf``. Mask by the flag before
        averaging.
        """
        ep = self._epoch
        # rows of Python ints and bools (tolist per array: no stacked copy)
        ints = [
            a.tolist()
            for a in (
                ep.n_sats,
                ep.n_sats_swarm,
                ep.coop_status,
                ep.standalone_status,
                ep.nav_source,
                ep.next_waypoint,
            )
        ]
        bools = [
            np.asarray(a, dtype=bool).tolist()
            for a in (
                ep.coop_rejected,
                ep.standalone_rejected,
                in_goal,
                ep.collided,
                ep.separation_violation,
                ep.out_of_contact,
            )
        ]
        term_rows = [np.asarray(v, dtype=float).tolist() for v in terms.values()]
        cols = self._info_columns(
            self._info_floats().tolist(), ints, int(ep.n_above_mask), bools, list(terms), term_rows
        )
        if self.config.integrity != "off":
            cols.update(self._integrity_infos())
        if self.config.nlos_exclusion != "off":
            cols["n_map_excluded"] = ep.map_excluded.sum(axis=1).tolist()
        return self._per_agent(cols)

    def _infos_of_arrays(self, parts: tuple) -> dict[str, dict]:
        """:meth:`_infos` of the step that the fused step just took, from its arrays (the
        parts of :func:`coopnav_env.envs._fused.info_arrays`, a batch of one): the same
        numbers, without making the step's :class:`~coopnav_env.sim.scenario.Epoch` (the
        fused step's settings have neither integrity monitoring nor the map exclusion)."""
        floats, ints, flags, terms, _steps = parts
        n_sats, n_swarm, n_open, co_status, sa_status, source, wp = ints
        cols = self._info_columns(
            floats[0].tolist(),
            [a[0].tolist() for a in (n_sats, n_swarm, co_status, sa_status, source, wp)],
            int(n_open[0]),
            [a[0].tolist() for a in flags],
            REWARD_TERMS,
            terms[0].tolist(),
        )
        return self._per_agent(cols)

    def _per_agent(self, cols: dict[str, list]) -> dict[str, dict]:
        """Each agent's flat info dictionary from the columns ``key -> N values``."""
        keys = list(cols)
        return {
            a: dict(zip(keys, row)) for a, row in zip(self.possible_agents, zip(*cols.values()))
        }

    def _info_columns(
        self,
        rows: list[list[float]],
        ints: list[list[int]],
        n_above_mask: int,
        bools: list[list[bool]],
        term_names: Sequence[str],
        term_rows: list[list[float]],
    ) -> dict[str, list]:
        """The infos' columns, each a list of N Python numbers: from the real numbers of
        :func:`coopnav_env.envs._kernels.info_floats` (8 rows), the satellites received by
        each UAV and by the swarm, the statuses, sources and next waypoints (6 rows), the
        satellites above the mask, the rejection, goal, collision, separation and contact
        flags (6 rows) and the reward terms by name."""
        n = len(rows[0])
        # a missing fix: its flag False and its error NO_FIX_ERROR_M (on N Python floats:
        # cheaper than numpy's isfinite and where)
        fix_rows = [[math.isfinite(x) for x in rows[1]], [math.isfinite(x) for x in rows[2]]]
        for r, fixed in zip((1, 2), fix_rows):
            rows[r] = [x if f else NO_FIX_ERROR_M for x, f in zip(rows[r], fixed)]
        cols = {
            "nav_error_m": rows[0],
            "coop_error_m": rows[1],
            "standalone_error_m": rows[2],
            "coop_fix": fix_rows[0],
            "standalone_fix": fix_rows[1],
            "sig_e_m": rows[3],
            "sig_n_m": rows[4],
            "sig_u_m": rows[5],
            "sig_3d_m": rows[6],
            "n_sats": ints[0],
            "n_sats_swarm": ints[1],
            "n_sats_open_sky": [n_above_mask] * n,
            "coop_status": ints[2],
            "standalone_status": ints[3],
            "nav_source": ints[4],
            "goal_distance_m": rows[7],
            "next_waypoint": ints[5],
            "coop_rejected": bools[0],
            "standalone_rejected": bools[1],
            "in_goal": bools[2],
            "collided": bools[3],
            "separation_violation": bools[4],
            "out_of_contact": bools[5],
        }
        for t, v in zip(term_names, term_rows):  # REWARD_TERMS, then "integrity" when it is on
            cols[f"reward_{t}"] = v
        cols["step"] = [self._steps] * n
        return cols

    def _integrity_infos(self) -> dict[str, list]:
        """The integrity figures of the estimate each UAV uses (``integrity`` on): protection
        levels, status, FDE, and its true horizontal and vertical errors (to compare with the
        protection levels, e.g. by :func:`coopnav_env.nav.integrity_rates`)."""
        ep = self._epoch
        d = (ep.nav_pos_enu_m - ep.pos_enu_m).T
        # finite numbers only (loggers average infos): -1 where no protection level exists
        # (per element on the Python floats: cheaper than numpy on N of them)
        return {
            "hpl_m": [x if math.isfinite(x) else -1.0 for x in ep.hpl_m.tolist()],
            "vpl_m": [x if math.isfinite(x) else -1.0 for x in ep.vpl_m.tolist()],
            "nav_h_error_m": np.hypot(d[0], d[1]).tolist(),
            "nav_v_error_m": np.abs(d[2]).tolist(),
            "integrity_status": ep.integrity_status.tolist(),
            "fault_detected": ep.fault_detected.tolist(),
            "fde_excluded": ep.fde_excluded.tolist(),
        }

    def state(self) -> np.ndarray:
        """Global state for centralised critics (truth included), inside ``state_space``.

        ``[(pos - goal) / L (3N), vel / max_speed (3N), (goal - city centre) / (L / 2) (3),
        (estimate - pos) / nav_reward_cap_m (3N), sigma / obs_sigma_max_m (3N),
        satellites received / above cut-off (N), steps left / max_steps (1)]``, float32.
        """
        if self._epoch is None:
            raise ValueError("state() called before reset(): call reset() first")
        return self.task.state(
            self.world,
            self._epoch,
            self._steps,
            self._city_scale_m,
            self.state_space.low,
            self.state_space.high,
        )

    # ---- rendering --------------------------------------------------------------------------

    def render(self) -> np.ndarray | None:
        """Draw the current epoch (see the documentation page); ``None`` without render_mode."""
        if self.render_mode is None:
            return None
        if self._epoch is None:
            raise ValueError("render() called before reset(): call reset() first")
        from coopnav_env.envs.render import render_frame, show_frame

        frame = render_frame(
            self.world,
            self._epoch,
            trail=self._trail,
            sky_uav=self.config.render_sky_uav,
            step=self._steps,
            max_steps=self.config.max_steps,
            size_px=(self.config.render_width_px, self.config.render_height_px),
            env_name=self.metadata["name"],
        )
        if self.render_mode == "human":
            self._window = show_frame(frame, self._window, self.metadata["render_fps"])
            return None
        return frame

    def close(self) -> None:
        """Close the human-mode window, if any."""
        if self._window is not None:
            from coopnav_env.envs.render import close_window

            close_window(self._window)
            self._window = None

    # ---- pickling ---------------------------------------------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        state = EzPickle.__getstate__(self)
        state["_runtime"] = {k: v for k, v in self.__dict__.items() if k != "_window"}
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        EzPickle.__setstate__(self, state)
        self.__dict__.update(state["_runtime"])
        self._window = None


class UrbanCanyonV1Env(UrbanCanyonEnv):
    """``urban_canyon_v1``: :class:`UrbanCanyonEnv` whose defaults pay the task's score.

    The defaults are those of ``urban_canyon_v0`` with :data:`~coopnav_env.envs.config.
    V1_DEFAULTS` on top (``reward_scheme="navigated_distance"``): the undiscounted return of an
    episode is its score. A given ``config`` is used as it is; keyword fields (and a
    ``preset``) apply on top of the v1 defaults. See :mod:`coopnav_env.urban_canyon_v1`.
    """

    metadata: ClassVar[dict[str, Any]] = {**UrbanCanyonEnv.metadata, "name": "urban_canyon_v1"}

    def __init__(
        self,
        config: UrbanCanyonConfig | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        if config is None:
            config, overrides = _v1_config(overrides), {}
        super().__init__(config=config, render_mode=render_mode, **overrides)


def _v1_config(overrides: dict[str, Any]) -> UrbanCanyonConfig:
    """The v1 defaults with ``overrides`` (fields, ``preset``, ``max_cycles``) on top."""
    return make_config(make_config(**V1_DEFAULTS), **overrides)


def parallel_env_v1(
    render_mode: str | None = None, config: UrbanCanyonConfig | None = None, **fields: Any
) -> UrbanCanyonV1Env:
    """The parallel environment ``urban_canyon_v1``; keywords as :func:`parallel_env`."""
    return UrbanCanyonV1Env(config=config, render_mode=render_mode, **fields)


def aec_env_v1(
    render_mode: str | None = None, config: UrbanCanyonConfig | None = None, **fields: Any
) -> AECEnv:
    """The AEC version of ``urban_canyon_v1`` (PettingZoo's conversion of the parallel one)."""
    return parallel_to_aec(parallel_env_v1(render_mode=render_mode, config=config, **fields))


def parallel_env(
    render_mode: str | None = None, config: UrbanCanyonConfig | None = None, **fields: Any
) -> UrbanCanyonEnv:
    """The parallel environment; every keyword is an :class:`UrbanCanyonConfig` field."""
    return UrbanCanyonEnv(config=config, render_mode=render_mode, **fields)


def aec_env(
    render_mode: str | None = None, config: UrbanCanyonConfig | None = None, **fields: Any
) -> AECEnv:
    """The AEC version: :func:`parallel_to_aec` (which adds ``OrderEnforcingWrapper``).

    No out-of-bounds action wrapper is added: the environment clips actions itself.
    """
    return parallel_to_aec(parallel_env(render_mode=render_mode, config=config, **fields))


def _box(low: Any, high: Any, shape: tuple[int, ...] | None = None) -> spaces.Box:
    """``spaces.Box(low, high, shape, dtype=np.float32)``, its bound arrays shared.

    Every Box with the same bounds (the spaces of every agent and every copy of one
    configuration) holds the same ``low``, ``high``, ``bounded_below`` and ``bounded_above``
    arrays and printed forms, those of one template Box per distinct bounds (at most
    :data:`_BOX_TEMPLATES_MAX` kept); each returned Box is an object of its own, with its own
    random generator, so that seeding or sampling one leaves the others as they were.
    """
    low_a, high_a = np.asarray(low), np.asarray(high)
    key = (low_a.dtype.str, low_a.shape, low_a.tobytes(), high_a.dtype.str, high_a.tobytes(), shape)
    template = _BOX_TEMPLATES.get(key)
    if template is None:
        template = spaces.Box(low, high, shape, dtype=np.float32)
        if len(_BOX_TEMPLATES) < _BOX_TEMPLATES_MAX:
            _BOX_TEMPLATES[key] = template
    return copy.copy(template)


_BOX_TEMPLATES: dict[tuple, spaces.Box] = {}
"""Bounds -> the template Box whose arrays the spaces with those bounds share (:func:`_box`);
the templates themselves are never handed out, so their generators are never drawn from."""

_BOX_TEMPLATES_MAX = 256
"""At most this many distinct bounds keep a template (further ones get arrays of their own)."""


def fix_error_m(info: dict[str, Any], key: str) -> float:
    """The error ``info[key]`` of one agent's infos, ``inf`` where the fix does not exist.

    ``key`` is ``"coop_error_m"`` or ``"standalone_error_m"`` (whose flags ``coop_fix`` and
    ``standalone_fix`` say whether the fix exists; other keys, and infos without the flag,
    are returned as they are). Use it to average errors over fixes only.
    """
    value = float(info[key])
    flag = _FIX_FLAGS.get(key)
    if flag is not None and flag in info and not info[flag]:
        return math.inf
    return value


_FIX_FLAGS = {"coop_error_m": "coop_fix", "standalone_error_m": "standalone_fix"}
