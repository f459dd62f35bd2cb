"""The fused step: ``K`` swarms of ``urban_canyon_v0`` advanced by compiled calls over them all.

:class:`FusedStep` is the step of :class:`coopnav_env.envs.BatchedUrbanCanyonEnv` and, as a
batch of one, of the parallel environment :class:`coopnav_env.envs.UrbanCanyonEnv`
(:func:`step_one`): each copy draws from its own generator, in the order of
``UrbanWorld._navigate_fused``, and runs the kernels of :mod:`coopnav_env.envs.
_batched_kernels` on its own slices of ``(K, ...)`` arrays, with the rotations to ECEF and
the skyline's ``arctan`` as numpy calls on those arrays. A copy's arithmetic does not depend
on ``K`` or on the other copies, so copy ``k`` of a batch is the episode of a batch of one,
that is of a separate environment, bit for bit.

It computes the settings of :func:`fused_settings` (the default measurement chain: no NLOS
draws, no dead-reckoning noise, no channel limit, no map exclusion, no integrity
monitoring, the exact covariance; velocity or route-frame commands, the base observation
with or without the agent index) on worlds of box buildings (:class:`~coopnav_env.sim.city.
Buildings`: the grid cities) and of extruded polygons (:class:`~coopnav_env.sim.file_city.
ExtrudedBuildings`: the generated family cities and the cities read from GeoJSON or
OpenStreetMap files), under a nominal or a RINEX sky. Each copy's buildings are padded into
the state arrays (boxes ``(K, B_max, 3)``; polygons as edges ``(K, E_max, 4)``, ring
offsets, roofs and bounding boxes, with each copy's counts), and a copy of polygons runs the
kernels of :mod:`coopnav_env.sim._polygon_kernels` (swept collisions after the motion, line
of sight, the skyline and wall sweep) where the world step calls them, in the same order.
With other settings, or a world it cannot take (a replaced constellation, a sky whose
satellites are not grouped by constellation), the callers step through ``UrbanWorld.step``
as before. A reset begins in the copy's own
Python (``UrbanCanyonEnv._begin_reset``, ``UrbanWorld._begin_episode``: city, formation,
route); the batched environment then computes the first epochs of all the copies it resets
at a step in the same kernels (:meth:`FusedStep.first_epochs`), and does all of it while the
step's navigation kernel runs on the other cores (:meth:`FusedStep.run`'s ``begin``). The
state arrays reload a copy whose world changed since the last fused step (a reset, which may
bring a new city, a step through the other path, an assignment to its world).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import operator
import os
import threading
import weakref
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np

from coopnav_env.constants import WGS84_A_M, WGS84_B_M, WGS84_E2, WGS84_F
from coopnav_env.envs import _batched_kernels
from coopnav_env.envs.autopilot import route_frame_velocity
from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.envs.urban_canyon import (
    INFO_KEYS,
    NO_FIX_ERROR_M,
    REWARD_TERMS,
    ROUTE_FRAME_GAIN_PER_S,
    UrbanCanyonEnv,
)
from coopnav_env.gnss.errors import _iono_factors
from coopnav_env.gnss.frames import _EP2, _N_BOWRING_ITER
from coopnav_env.nav.types import PLAUSIBLE_RADIUS_M
from coopnav_env.nav.wls import _radius_args
from coopnav_env.sim.city import Buildings
from coopnav_env.sim.file_city import ExtrudedBuildings
from coopnav_env.sim.scenario import Epoch


class FusedStep:
    """The fused step of a fixed list of copies (its state arrays and table of skies).

    :meth:`run` advances every copy by one epoch, or returns None (nothing changed) when one
    of them cannot take the fused step now.
    """

    def __init__(self) -> None:
        self.skies = _SkyTable()
        self.first_skies = _SkyTable()  # those of first epochs (computed beside a step's kernel)
        self.state: _SwarmArrays | None = None
        self._seen: list[tuple] = []

    def _load(self, envs: list[UrbanCanyonEnv]) -> bool:
        """Make the state arrays those of the copies' worlds; False if one cannot be taken."""
        if not all(_fused_world(e.world) for e in envs):
            return False
        st = self.state
        if st is None or len(self._seen) != len(envs):
            self.state = _SwarmArrays(envs)
            return True
        stale = [
            k
            for k, (e, seen) in enumerate(zip(envs, self._seen))
            if e._steps != st.steps[k] or any(map(operator.is_not, _fingerprint(e), seen))
        ]
        if stale:
            st.own()  # copies first: the worlds and epochs keep the arrays they view
            for k in stale:
                st.load(k, envs[k])
        return True

    def run(
        self,
        envs: list[UrbanCanyonEnv],
        cmd: np.ndarray,
        begin: Callable[[np.ndarray], None] | None = None,
    ):
        """One epoch of every copy with the clipped commands ``cmd`` ``(K, N, 3)``.

        Updates each copy's world, epoch and step count as ``UrbanCanyonEnv._step_arrays``
        does, and returns ``obs (K, N, obs_dim) float32, rewards (K, N), terminated (K,),
        truncated (K,), terms (K, 6, N), in_goal (K, N)`` and the parts of the infos
        (:func:`info_arrays`); or None, with nothing changed, if a copy cannot take the fused
        step now.

        ``begin(done)``, when given, is called with the copies whose episodes this step ends
        (``(K,)`` bool: ``terminated | truncated``, known once the UAVs have moved) while the
        navigation kernel runs on the other cores: the caller resets those copies there
        (Python and their first epochs' kernels, on this thread beside the pool's). Each
        copy's generator has drawn this step's numbers by then; the step leaves the reset
        copies' worlds and epochs as the reset made them (its results for them are in the
        returned arrays).
        """
        if not self._load(envs):
            return None
        out = self._epochs(envs, cmd, self.state, cold=False, begin=begin)
        if out is not None:
            self._seen = [_fingerprint(e) for e in envs]
        return out

    def first_epochs(self, envs: list[UrbanCanyonEnv]) -> tuple[np.ndarray, np.ndarray] | None:
        """The first epoch of each copy's episode, after ``UrbanCanyonEnv._begin_reset``,
        ``UrbanWorld._begin_episode`` and ``UrbanCanyonEnv._episode_scales`` (what
        ``UrbanWorld.reset`` computes after them: the swarm where it starts, navigation
        cold-started from the launch positions); sets each world's and environment's epoch.

        Returns the copies' first observations ``(R, N, obs_dim)`` float32 and each UAV's
        remaining route at the first epoch ``(R, N)`` [m] (what ``UrbanCanyonEnv.
        _finish_reset`` computes copy by copy, the same numbers bit for bit), or None, with
        nothing changed, if a copy cannot take it (then reset it as usual). Its kernels run on
        this thread alone: it is called inside :meth:`run`'s ``begin``, while the pool's
        threads run the step's kernel."""
        worlds = [e.world for e in envs]
        if not all(_fused_world(w, cold=True) for w in worlds):
            return None
        n = envs[0].config.n_uavs
        cmd = np.zeros((len(envs), n, 3))
        st = _SwarmArrays(envs)
        return self._epochs(envs, cmd, st, cold=True)

    def _epochs(
        self,
        envs: list[UrbanCanyonEnv],
        cmd: np.ndarray,
        st: Any,
        cold: bool,
        begin: Callable[[np.ndarray], None] | None = None,
    ):
        """:meth:`run` (``cold`` False) or :meth:`first_epochs` on the state arrays ``st``
        (``cold``: every kernel on this thread, beside the step's kernel on the pool's)."""
        run = _run_serial if cold else _run_threads
        cfg = envs[0].config
        n_copies, n = len(envs), cfg.n_uavs
        world0 = envs[0].world
        dt = cfg.dt_s
        if not cold and cfg.action_frame == "route":
            cmd = _route_commands(envs, cmd, st)
        # the epoch's sky of each copy (its own time)
        t_new = [e.world.t_s if cold else e.world.t_s + dt for e in envs]
        tab = self.first_skies if cold else self.skies
        rows = tab.rows(world0, t_new)
        if rows is None:  # a sky whose satellites are not grouped by constellation
            return None
        skies, row, n_sv, n_up = rows
        # each copy's draws in the order of UrbanWorld._navigate_fused: pseudoranges
        # (S + N S), relative sensing (N (N - 1) / 2 x 3), as one call per copy
        n_draws = (n_sv * (1 + n) + 3 * (n * (n - 1) // 2)).tolist()
        z = np.empty((n_copies, max(n_draws)))
        for k, e in enumerate(envs):  # straight into the copy's row (the draws of size=n_draws)
            e._rng.standard_normal(out=z[k, : n_draws[k]])
        los_off = np.zeros(n_copies + 1, dtype=np.int64)
        los_off[1:] = (n * n_sv).cumsum()
        # the records go to the kernels as plain tuples (_run_threads), each made once here
        sky = tuple(
            _batched_kernels.SkyRows(
                row, n_sv, n_up, los_off, tab.sv, tab.system, tab.up, tab.order, tab.cot, tab.hdir
            )
        )
        cities, routes = tuple(st.cities), tuple(st.routes)
        moved_arrays = _batched_kernels.Moved(
            pos=np.empty((n_copies, n, 3)),
            vel=np.empty((n_copies, n, 3)),
            hit=np.empty((n_copies, n), dtype=bool),
            sep=np.empty((n_copies, n), dtype=bool),
            los_flat=np.empty(int(los_off[-1]), dtype=bool),
            rel=np.empty((n_copies, n, n, 3)),
            var=np.empty((n_copies, n, n)),
            avail=np.empty((n_copies, n, n), dtype=bool),
            n_rx=np.empty((n_copies, n), dtype=np.int64),
        )
        moved = tuple(moved_arrays)
        motion_settings, nav_settings = st.motion_settings, st.navigation_settings
        if cold:
            motion_settings = st.first_motion_settings
            nav_settings = st.first_navigation_settings
        run(
            _batched_kernels.motion_sight_relative,
            n_copies,
            tuple(motion_settings),
            cities,
            sky,
            tuple(_batched_kernels.MotionInputs(st.pos, st.vel, cmd, z)),
            moved,
        )
        pos1, vel1, hit, sep, los_flat, rel, _var, avail, n_rx = moved_arrays
        if not cold and cfg.crash_free_steps > 0:
            # the crash-free start (UrbanCanyonEnv._step_arrays): a UAV stopped by a wall in
            # the episode's first steps is not a collision, and the episode goes on
            hit[st.steps < cfg.crash_free_steps] = False
        # the rotations to ECEF stay numpy matmuls (their rounding is numpy's, as one copy's)
        origin, rot = world0.origin_ecef_m, world0.rot_enu
        rx_ecef = origin + pos1 @ rot
        # warm start: the previous estimates moved; at an episode's first epoch, the launch
        # positions
        pred = st.nav_pos if cold else st.nav_pos + vel1 * dt
        x0 = origin + pred @ rot
        if st.navigation_settings.shared:  # only the centroid's row: the UAV receiving the most
            centroid = n_rx.argmax(axis=1)
            rel_ecef = (rel[np.arange(n_copies), centroid] @ rot)[:, None]
        else:
            rel_ecef = rel @ rot
        inputs = _batched_kernels.NavigationInputs(
            st.pos, rx_ecef, pred, x0, st.nav_cov, rel_ecef, st.wp, st.clock, z
        )
        outputs = tuple(_batched_kernels.navigation_outputs(n_copies, n, envs[0]._rays.shape[0]))
        nav_args = (tuple(nav_settings), cities, routes, sky, moved, tuple(inputs), outputs)
        predicted, reset = None, None
        if begin is None:  # (always so for first epochs)
            run(_batched_kernels.navigation_reward_sensors, n_copies, *nav_args)
        else:
            # the episodes this step ends, from the moved swarms (what the kernel computes
            # from the same arrays): the caller resets those copies while the kernel runs
            predicted = _batched_kernels.episode_ends(
                pos1, st.goal, hit, float(nav_settings.reward_params[8])
            )
            reset = predicted[:, 0] | predicted[:, 1] | (st.steps + 1 >= cfg.max_steps)
            _run_parallel(
                _batched_kernels.navigation_reward_sensors,
                n_copies,
                nav_args,
                functools.partial(begin, reset),
            )
        (
            sa_status,
            _n_iter,
            sa_pos,
            _sa_cov,
            co_pos,
            _co_cov,
            co_status,
            source,
            nav_pos,
            nav_cov,
            sa_rej,
            co_rej,
            wp,
            n_swarm,
            n_sats,
            _centroid_uav,
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
        if predicted is not None and not np.array_equal(predicted, ends):
            raise RuntimeError("the episode ends known before the navigation kernel differ")
        if cold:
            self._first_epochs(envs, st, t_new, skies, n_sv, los_off, los_flat, outputs, rel, avail)
        sky_deg = np.degrees(np.arctan(tan_max))
        steps = st.steps if cold else st.steps + 1  # (a first epoch's: 0)
        observed = _batched_kernels.Observed(
            obs=np.empty((n_copies, n, cfg.obs_base_dim), dtype=np.float32),
            floats=np.empty((n_copies, 8, n)),
        )
        obs_inputs = _batched_kernels.ObservationInputs(
            pos1,
            vel1,
            rel,
            avail,
            nav_pos,
            nav_cov,
            co_pos,
            sa_pos,
            n_sats,
            n_swarm,
            n_sv,
            wp,
            source,
            walls,
            sky_deg,
            steps,
            st.obs_params,
        )
        run(
            _batched_kernels.observations_infos,
            n_copies,
            tuple(st.observation_settings),
            routes,
            tuple(obs_inputs),
            tuple(observed),
        )
        obs, floats = observed
        if cfg.obs_agent_index:  # each UAV's one-hot index after the kernel's columns
            obs = np.concatenate(
                [obs, np.broadcast_to(np.eye(n, dtype=np.float32), (n_copies, n, n))], axis=2
            )
        if cold:  # the first observations, and each UAV's route at the first epoch
            return obs, _remaining_routes_m(st.route, st.tail, pos1, wp)
        # the copies' worlds and epochs (what their own step would have left)
        pos_c, vel_c, wp_c, goal_c = pos1.copy(), vel1.copy(), wp.copy(), st.goal.copy()
        # the reward of every copy at once (UrbanCanyonEnv._step_arrays' arithmetic, each
        # copy's row reduced as its own array would be)
        unpaid = st.unpaid
        if cfg.reward_scheme == "navigated_distance":
            unpaid = np.empty_like(st.unpaid)
            _batched_kernels.navigated_distance_terms(
                routes,
                tuple(
                    _batched_kernels.DistanceInputs(
                        pos1, nav_pos, wp, ends[:, 1], st.unpaid, st.route_len
                    )
                ),
                float(cfg.nav_reward_cap_m),
                (terms, unpaid),  # Paid
            )
        if cfg.nav_team_weight > 0.0:  # _team_mix of each copy
            weight = cfg.nav_team_weight
            nav = terms[:, 0]
            terms[:, 0] = (1.0 - weight) * nav + weight * nav.mean(axis=1, keepdims=True)
        rewards = terms.sum(axis=1)
        terminated = ends[:, 0] | ends[:, 1]
        truncated = (steps >= cfg.max_steps) & ~terminated
        # each copy's epoch is made when first read (most batched steps read none)
        epochs = _step_epochs(
            t_new,
            skies,
            los_off,
            n_sv,
            los_flat,
            outputs,
            rel,
            avail,
            pos_c,
            vel_c,
            goal_c,
            hit,
            sep,
            wp_c,
        )
        for k, e in enumerate(envs):
            if reset is not None and reset[k]:  # reset beside the kernel: its new episode
                continue
            w = e.world
            w.pos_enu_m, w.vel_enu_mps, w.t_s = pos1[k], vel1[k], t_new[k]
            w.nav_pos_enu_m, w.nav_cov_enu_m2, w.next_wp = nav_pos[k], nav_cov[k], wp[k]
            w.last = e._epoch = _StepEpoch.of(epochs, k)
            e._steps += 1
            e._unpaid_m = unpaid[k]
        st.advance(pos1, vel1, nav_pos, nav_cov, wp, steps, unpaid)
        info_parts = (
            floats,
            (n_sats, n_swarm, n_sv, co_status, sa_status, source, wp_c),
            (co_rej, sa_rej, in_goal, hit, sep, out_of_contact),
            terms,
            steps,
        )
        return obs, rewards, terminated, truncated, terms, in_goal, info_parts

    @staticmethod
    def _first_epochs(envs, st, t_s, skies, n_sv, los_off, los_flat, outputs, rel, avail) -> None:
        """The worlds and epochs after :meth:`first_epochs`' kernels (``UrbanWorld._epoch``
        at a reset: collisions and separation not tested, the positions unchanged)."""
        out = _batched_kernels.Navigated._make(outputs)
        nav_pos, nav_cov, wp = out.nav_pos, out.nav_cov, out.next_wp
        no = np.zeros(nav_pos.shape[:2], dtype=bool)
        # the positions and velocities of the throwaway state arrays (copies of the worlds')
        epochs = _step_epochs(
            t_s,
            skies,
            los_off,
            n_sv,
            los_flat,
            outputs,
            rel,
            avail,
            st.pos,
            st.vel,
            st.goal.copy(),
            no,
            no.copy(),
            wp.copy(),
        )
        for k, e in enumerate(envs):
            w = e.world
            w.nav_pos_enu_m, w.nav_cov_enu_m2, w.next_wp = nav_pos[k], nav_cov[k], wp[k]
            w._warm = True
            w.last = e._epoch = _StepEpoch.of(epochs, k)


def _remaining_routes_m(
    route: np.ndarray, tail: np.ndarray, pos: np.ndarray, next_wp: np.ndarray
) -> np.ndarray:
    """Each UAV's remaining route ``(K, N)`` [m] from the copies' padded routes ``(K, R, 2)``
    and route tails ``(K, R)``, true positions ``(K, N, 3)`` and next waypoints ``(K, N)``:
    :func:`coopnav_env.sim.route.remaining_route_m` of every copy at once (the same numpy
    operations on each element, so the same numbers bit for bit)."""
    k = np.arange(pos.shape[0])[:, None]
    d = np.linalg.norm(pos[:, :, :2] - route[k, next_wp], axis=2)
    return d + tail[k, next_wp]


class _EpochRows(NamedTuple):
    """The ``(K, ...)`` arrays of a fused step whose row ``k`` is that field of copy ``k``'s
    epoch (the fields of :class:`~coopnav_env.sim.scenario.Epoch` of these names)."""

    pos_enu_m: np.ndarray
    vel_enu_mps: np.ndarray
    goal_enu_m: np.ndarray
    n_sats: np.ndarray
    n_sats_swarm: np.ndarray
    rel_enu_m: np.ndarray
    rel_available: np.ndarray
    standalone_pos_enu_m: np.ndarray
    standalone_cov_enu_m2: np.ndarray
    standalone_status: np.ndarray
    coop_pos_enu_m: np.ndarray
    coop_cov_enu_m2: np.ndarray
    coop_status: np.ndarray
    nav_pos_enu_m: np.ndarray
    nav_cov_enu_m2: np.ndarray
    nav_source: np.ndarray
    collided: np.ndarray
    separation_violation: np.ndarray
    out_of_contact: np.ndarray
    standalone_rejected: np.ndarray
    coop_rejected: np.ndarray
    next_waypoint: np.ndarray


class _StepEpochs:
    """Every copy's epoch of one fused step, as the step's arrays: :meth:`fields` makes copy
    ``k``'s (what :class:`_StepEpoch` reads when one of its fields is first read).

    The arrays are the step's own (later steps make new ones; the state arrays that the next
    step reads are never written), so an epoch read any time later is the one of its step.
    """

    def __init__(
        self,
        n: int,
        t_s: list[float],
        skies: list[Any],
        los_bounds: list[int],
        n_above: list[int],
        los_flat: np.ndarray,
        nlos_flat: np.ndarray,
        centroids: list[int],
        iterations: list[list[int]],
        rows: _EpochRows,
    ) -> None:
        self.n, self.t_s, self.skies = n, t_s, skies
        self.los_bounds, self.n_above = los_bounds, n_above
        self.los_flat, self.nlos_flat = los_flat, nlos_flat
        self.centroids, self.iterations = centroids, iterations
        self.rows = rows

    def fields(self, k: int) -> dict[str, Any]:
        """Copy ``k``'s epoch fields, in the order of :class:`~coopnav_env.sim.scenario.Epoch`
        (each array a view of its row of the step's arrays)."""
        r, sky = self.rows, self.skies[k]
        a, b, n_above = self.los_bounds[k], self.los_bounds[k + 1], self.n_above[k]
        los = self.los_flat[a:b].reshape(self.n, n_above)
        n_iter_standalone, n_iter_coop = self.iterations[k]
        return dict(
            t_s=float(self.t_s[k]),
            pos_enu_m=r.pos_enu_m[k],
            vel_enu_mps=r.vel_enu_mps[k],
            goal_enu_m=r.goal_enu_m[k],
            sv_az_deg=sky.az,
            sv_el_deg=sky.el,
            system=sky.system,
            sv_index=sky.sv_index,
            los=los,
            received=los,
            nlos=self.nlos_flat[a:b].reshape(self.n, n_above),
            n_above_mask=n_above,
            n_sats=r.n_sats[k],
            n_sats_swarm=r.n_sats_swarm[k],
            rel_enu_m=r.rel_enu_m[k],
            rel_available=r.rel_available[k],
            standalone_pos_enu_m=r.standalone_pos_enu_m[k],
            standalone_cov_enu_m2=r.standalone_cov_enu_m2[k],
            standalone_status=r.standalone_status[k],
            coop_pos_enu_m=r.coop_pos_enu_m[k],
            coop_cov_enu_m2=r.coop_cov_enu_m2[k],
            coop_status=r.coop_status[k],
            nav_pos_enu_m=r.nav_pos_enu_m[k],
            nav_cov_enu_m2=r.nav_cov_enu_m2[k],
            nav_source=r.nav_source[k],
            centroid_uav=self.centroids[k],
            collided=r.collided[k],
            separation_violation=r.separation_violation[k],
            out_of_contact=r.out_of_contact[k],
            n_iter_standalone=n_iter_standalone,
            n_iter_coop=n_iter_coop,
            standalone_rejected=r.standalone_rejected[k],
            coop_rejected=r.coop_rejected[k],
            next_waypoint=r.next_waypoint[k],
            **_EPOCH_DEFAULTS,
        )


class _StepEpoch(Epoch):
    """Copy ``k``'s :class:`~coopnav_env.sim.scenario.Epoch` of a fused step, its fields
    filled from the step's arrays (:meth:`_StepEpochs.fields`) when one is first read: an
    epoch whose fields nobody reads costs no view of them. It pickles and copies as the plain
    epoch of those fields."""

    @classmethod
    def of(cls, epochs: _StepEpochs, k: int) -> _StepEpoch:
        """Copy ``k``'s epoch of ``epochs``, its fields not yet filled."""
        out = object.__new__(cls)
        out.__dict__["_pending"] = (epochs, k)
        return out

    def __getattr__(self, name: str) -> Any:
        # called only where the usual lookup fails: before the fields are filled, every field
        pending = self.__dict__.pop("_pending", None)
        if pending is None:
            raise AttributeError(f"'Epoch' object has no attribute {name!r}")
        epochs, k = pending
        self.__dict__.update(epochs.fields(k))
        return getattr(self, name)

    def __reduce__(self) -> tuple[type[Epoch], tuple[Any, ...]]:
        return Epoch, tuple(getattr(self, f) for f in _EPOCH_FIELDS)


def _step_epochs(
    t_s: list[float],
    skies: list[Any],
    los_off: np.ndarray,
    n_sv: np.ndarray,
    los_flat: np.ndarray,
    outputs: tuple[np.ndarray, ...],
    rel: np.ndarray,
    avail: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    goal: np.ndarray,
    collided: np.ndarray,
    separation: np.ndarray,
    next_wp: np.ndarray,
) -> _StepEpochs:
    """The epochs of the copies of a fused step (or of their first epochs), from the step's
    times, skies, line of sight (``los_flat``, copy ``k``'s at ``los_off[k]:los_off[k + 1]``),
    navigation ``outputs`` (the record :class:`~coopnav_env.envs._batched_kernels.Navigated`
    as a tuple), relative sensing and the epochs' own ``(K, ...)`` arrays of positions,
    velocities, goals, collisions, separation violations and next waypoints."""
    out = _batched_kernels.Navigated._make(outputs)
    return _StepEpochs(
        rel.shape[1],
        t_s,
        skies,
        los_off.tolist(),
        n_sv.tolist(),
        los_flat,
        np.zeros(los_flat.shape[0], dtype=bool),
        out.centroid_uav.tolist(),
        out.n_iter.tolist(),
        _EpochRows(
            pos_enu_m=pos,
            vel_enu_mps=vel,
            goal_enu_m=goal,
            n_sats=out.n_sats,
            n_sats_swarm=out.n_swarm,
            rel_enu_m=rel,
            rel_available=avail,
            standalone_pos_enu_m=out.sa_pos,
            standalone_cov_enu_m2=out.sa_cov,
            standalone_status=out.sa_status,
            coop_pos_enu_m=out.co_pos,
            coop_cov_enu_m2=out.co_cov,
            coop_status=out.co_status,
            nav_pos_enu_m=out.nav_pos,
            nav_cov_enu_m2=out.nav_cov,
            nav_source=out.source,
            collided=collided,
            separation_violation=separation,
            out_of_contact=out.out_of_contact,
            standalone_rejected=out.sa_rej,
            coop_rejected=out.co_rej,
            next_waypoint=next_wp,
        ),
    )


def info_arrays(
    floats: np.ndarray,
    ints: tuple[np.ndarray, ...],
    flags: tuple[np.ndarray, ...],
    terms: np.ndarray,
    steps: np.ndarray,
) -> dict[str, np.ndarray]:
    """Every copy's step infos as arrays: :data:`INFO_KEYS` (in order) -> ``(K, N)``.

    From the fused step's ``(K, ...)`` arrays: the real numbers of
    :func:`coopnav_env.envs._kernels.info_floats` ``(K, 8, N)`` (a missing fix's error is
    set to :data:`NO_FIX_ERROR_M` here, in place); the satellites received, by the swarm,
    above the mask ``(K,)``, the statuses, sources and next waypoints; the rejection, goal,
    collision, separation and contact flags; the reward terms ``(K, 6, N)``; the episode
    steps ``(K,)``. Real numbers are float64, counts, statuses and steps int64, flags bool:
    ``tolist()`` of an array gives the Python numbers of ``UrbanCanyonEnv._infos``.
    """
    n_copies, n = floats.shape[0], floats.shape[2]
    fixes = np.isfinite(floats[:, 1:3])
    floats[:, 1:3] = np.where(fixes, floats[:, 1:3], NO_FIX_ERROR_M)
    n_sats, n_swarm, n_open, co_status, sa_status, source, wp = ints
    k_n = (n_copies, n)
    columns = (
        *floats[:, :3].transpose(1, 0, 2),
        *fixes.transpose(1, 0, 2),
        *floats[:, 3:7].transpose(1, 0, 2),
        n_sats,
        n_swarm,
        np.broadcast_to(n_open[:, None], k_n).astype(np.int64),
        co_status,
        sa_status,
        source,
        floats[:, 7],
        wp,
        *(np.asarray(f, dtype=bool) for f in flags),
        *terms.transpose(1, 0, 2),
        np.broadcast_to(steps[:, None], k_n).astype(np.int64),
    )
    return dict(zip(INFO_KEYS, columns, strict=True))


def infos_from_arrays(
    agents: list[str], info: dict[str, np.ndarray]
) -> list[dict[str, dict[str, Any]]]:
    """The per-copy infos ``[{agent: {key: number}}]`` of the info arrays ``key -> (K, N)``
    (the keys in the arrays' order; Python floats, ints and bools, as ``UrbanCanyonEnv.
    _infos`` gives them)."""
    keys = list(info)
    cols = [a.tolist() for a in info.values()]  # each K lists of N Python numbers
    return [
        {a: dict(zip(keys, row)) for a, row in zip(agents, zip(*per_copy))}
        for per_copy in zip(*cols)
    ]


MIN_COPIES_PER_THREAD = 4
"""Fewest copies a thread of the fused step takes (fewer: the thread costs more than it saves)."""

_POOL: list = []
"""The process id and the thread pool it made (a forked child, whose copy has no threads,
makes its own)."""


@functools.cache
def _threads() -> int:
    """The CPU cores this process may run on (when first asked)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _run_serial(kernel: Any, n_copies: int, *args: Any) -> None:
    """``kernel`` over every copy on this thread alone (:func:`_run_parallel` without
    threads)."""
    kernel(_batched_kernels.copy_segments(n_copies, 1), 0, *args)


def _run_threads(kernel: Any, n_copies: int, *args: Any) -> None:
    """``kernel`` over every copy, on every core (:func:`_run_parallel` with no other work)."""
    _run_parallel(kernel, n_copies, args)


def _run_parallel(
    kernel: Any, n_copies: int, args: tuple, work: Callable[[], None] | None = None
) -> None:
    """``work()`` on this thread while ``kernel`` runs over the copies on the pool's threads,
    then ``kernel`` on this thread too until every copy is done.

    The copies are split into one segment per thread of the pool
    (:func:`~coopnav_env.envs._batched_kernels.copy_segments`); each of those threads takes
    its segment's copies from the front, and this thread, after ``work()``, takes them from
    the back of the segments until it meets the others. The cores are thus balanced
    whatever ``work()`` costs, with one call of the kernel per thread. The kernels release
    the GIL (``nogil``); the pool's threads are inside the kernel before ``work()`` starts,
    so that Python on this thread never holds them back. Each copy's arithmetic is the same
    on any thread, so the split changes no result.

    Threads rather than numba's ``parallel=True``: the OpenMP threading layer numba picks by
    default competes with PyTorch's own OpenMP pool in one process (a trainer's), which
    slowed both severalfold in the benchmark. The records of
    :mod:`coopnav_env.envs._batched_kernels` come in ``args`` as plain tuples of their fields
    (``tuple(record)``), which the kernel names again: numba takes a plain tuple in about
    half the time of a named one.
    """
    threads = min(_threads(), max(1, n_copies // MIN_COPIES_PER_THREAD))
    if threads == 1:
        if work is not None:
            work()
        _run_serial(kernel, n_copies, *args)
        return
    claims = _batched_kernels.copy_segments(n_copies, threads - 1)
    started = [threading.Event() for _ in range(threads - 1)]

    def front(s: int) -> None:
        started[s].set()
        kernel(claims, s, *args)

    futures = [_pool().submit(front, s) for s in range(threads - 1)]
    try:
        if work is not None:
            for event in started:  # (waiting releases the GIL: the threads get into the kernel)
                event.wait()
            work()
        kernel(claims, -1, *args)
    finally:  # the pool's threads write the same outputs: never leave them running
        concurrent.futures.wait(futures)
    for f in futures:
        f.result()


def _pool() -> ThreadPoolExecutor:
    """This process's thread pool of the fused step (one thread fewer than its cores)."""
    if not _POOL or _POOL[0] != os.getpid():  # none yet, or a forked child's copy
        _POOL[:] = [os.getpid(), ThreadPoolExecutor(max_workers=max(1, _threads() - 1))]
    return _POOL[1]


_EPOCH_FIELDS = tuple(f.name for f in dataclasses.fields(Epoch))
"""The fields of an epoch, in order."""

_EPOCH_DEFAULTS = {
    f.name: f.default for f in dataclasses.fields(Epoch) if f.default is not dataclasses.MISSING
}
"""The fields an epoch of the fused step leaves at their defaults, in order (the last ones of
an epoch: integrity monitoring and the map-aided exclusion are off there)."""

_N_OBS_PARAMS = 9
"""Entries of ``UrbanCanyonEnv._obs_params`` (the observation kernel's scales)."""

_WGS84 = np.array([WGS84_A_M, WGS84_B_M, WGS84_F, WGS84_E2, _EP2], dtype=np.float64)


def _reward_mode(cfg: UrbanCanyonConfig) -> int:
    """The reward kernel's mode: 2 where ``reward_scheme="navigated_distance"`` computes the
    terms ``nav`` and ``progress`` from the route after the kernel (the kernel computes the
    event terms alone), else 1 for ``nav_reward="sigma"`` and 0 for the error."""
    if cfg.reward_scheme == "navigated_distance":
        return 2
    return int(cfg.nav_reward == "sigma")


def fused_settings(cfg: UrbanCanyonConfig) -> bool:
    """Whether the settings are those the fused step computes: the default measurement and
    navigation chain (exact covariance, no NLOS draws, no dead-reckoning noise, no channel
    limit, no map exclusion, no integrity monitoring), velocity or route-frame commands
    and the base observation (with or without the agent index).
    Other settings step copy by copy."""
    return _fused_config(cfg)


_FUSED_CONFIGS: dict[int, tuple[Any, bool]] = {}
"""``id(config) -> (config, answer)`` of :func:`_fused_config` (a configuration's hash
covers every field, slower than the answer; the entry keeps the object, so its id stays
its own)."""


def _fused_config(cfg: UrbanCanyonConfig) -> bool:
    """The settings part of :func:`fused_settings` (remembered per configuration object:
    configurations are frozen)."""
    hit = _FUSED_CONFIGS.get(id(cfg))
    if hit is not None and hit[0] is cfg:
        return hit[1]
    ok = (
        cfg.nlos_probability == 0.0
        and not cfg.dead_reckoning_noise
        and cfg.max_sats is None
        and cfg.nlos_exclusion == "off"
        and cfg.integrity == "off"
        and cfg.covariance == "exact"
        and not (cfg.obs_protection_level or cfg.obs_satellite_sectors or cfg.obs_true_error)
    )
    if len(_FUSED_CONFIGS) >= 256:  # configurations made in a loop: start again
        _FUSED_CONFIGS.clear()
    _FUSED_CONFIGS[id(cfg)] = (cfg, ok)
    return ok


def _fused_world(world: Any, cold: bool = False) -> bool:
    """Whether a copy's world can take the fused step: box buildings or a file city's
    extruded polygons, its own constellation (the cached sky) and a warm-started navigation
    (with ``cold``: an episode begun, before its first epoch)."""
    return (
        isinstance(world.city.buildings, Buildings | ExtrudedBuildings)
        and world.constellation is world.__dict__.get("_cached_constellation")
        and bool(world._warm) is not cold
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


def _fingerprint(env: UrbanCanyonEnv) -> tuple:
    """The objects of a copy's state that its world replaces when the state changes other
    than by a fused step (compared by identity)."""
    w = env.world
    return (
        w.pos_enu_m,
        w.vel_enu_mps,
        w.nav_pos_enu_m,
        w.nav_cov_enu_m2,
        w.next_wp,
        w.clock_bias_m,
        w.goal_enu_m,
        w.route_xy_m,
        w.city,
        env._obs_params,
    )


_ONE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
"""The fused step of each parallel environment that took one (a batch of one)."""


def step_one(env: UrbanCanyonEnv, cmd: np.ndarray):
    """``UrbanCanyonEnv._step_arrays`` as a batch of one (the batched environment's step),
    followed by the parts of the step's infos (:func:`info_arrays`' arguments, for
    ``UrbanCanyonEnv._infos_of_arrays``), or None where the settings or the world are outside
    the fused step."""
    if not fused_settings(env.config):
        return None
    fused = _ONE.get(env)
    if fused is None:
        fused = _ONE[env] = FusedStep()
    out = fused.run([env], np.ascontiguousarray(cmd, dtype=np.float64)[None])
    if out is None:
        return None
    obs, rewards, terminated, truncated, terms, in_goal, parts = out
    if env.render_mode is not None:
        env._trail.append(env._epoch.pos_enu_m)
        env._trail = env._trail[-60:]
    terms_d = dict(zip(REWARD_TERMS, terms[0]))
    return obs[0], rewards[0], bool(terminated[0]), bool(truncated[0]), terms_d, in_goal[0], parts


class _SwarmArrays:
    """The state of every copy as ``(K, ...)`` arrays, loaded from the copies' worlds.

    Buildings and routes are padded to the largest copy (``n_b``, ``n_route`` give each
    copy's count; a copy of extruded polygons has no boxes, and its polygons are in the
    polygon arrays with ``is_poly`` set); :meth:`advance` takes the arrays of a step,
    :meth:`load` reloads one copy after its reset (after :meth:`own`, which copies the
    arrays the epochs share). The kernels take them as the records of :mod:`coopnav_env.envs.
    _batched_kernels`: :attr:`cities` and :attr:`routes` (rebuilt by :meth:`load`), and the
    settings of each kernel, made once here (``first_*``: those of an episode's first epoch).
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
        rs, model, gate = cfg.relative_sensing, cfg.error_model, cfg.max_fix_sigma_m
        check, r_lo, r_hi = _radius_args(PLAUSIBLE_RADIUS_M)
        self.sensing = np.array([rs.sigma0_m, rs.sigma_per_m, rs.max_range_m], dtype=np.float64)
        self.model = np.array(
            [model.sigma_ure_m, float(bool(model.tropo)), float(bool(model.differential))]
        )
        self.radius = np.array([float(check), r_lo, r_hi])
        self.iono = _iono_factors(model)
        self.gate = np.array(
            [float(gate is not None), float(gate) ** 2 if gate is not None else 0.0]
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
        self.obs_params = np.zeros((k_n, _N_OBS_PARAMS))
        self.steps = np.empty(k_n, dtype=np.int64)
        self.unpaid = np.zeros((k_n, n))
        self.route_len = np.ones((k_n, n))
        self.n_b = np.zeros(k_n, dtype=np.int64)
        self.n_route = np.zeros(k_n, dtype=np.int64)
        boxes = [b for b in (e.world.city.buildings for e in envs) if isinstance(b, Buildings)]
        polys = [b for b in (e.world.city.buildings for e in envs) if not isinstance(b, Buildings)]
        b_max = max((b.min_m.shape[0] for b in boxes), default=0)
        p_max = max((b.n for b in polys), default=0)
        e_max = max((b.edges_m.shape[0] for b in polys), default=0)
        r_max = max(e.world.route_xy_m.shape[0] for e in envs)
        self.b_lo = np.zeros((k_n, max(b_max, 1), 3))
        self.b_hi = np.zeros((k_n, max(b_max, 1), 3))
        self.is_poly = np.zeros(k_n, dtype=bool)
        self.n_poly = np.zeros(k_n, dtype=np.int64)
        self.n_edge = np.zeros(k_n, dtype=np.int64)
        self.edges = np.zeros((k_n, max(e_max, 1), 4))
        self.edge_start = np.zeros((k_n, p_max + 1), dtype=np.int64)
        self.heights = np.zeros((k_n, max(p_max, 1)))
        self.bbox = np.zeros((k_n, max(p_max, 1), 4))
        self.route = np.zeros((k_n, r_max, 2))
        self.tail = np.zeros((k_n, r_max))
        for k, e in enumerate(envs):
            self.load(k, e)
        self.motion_settings = _batched_kernels.MotionSettings(self.motion, self.sensing, True)
        self.first_motion_settings = self.motion_settings._replace(moving=False)
        dr_var = (cfg.dead_reckoning_sigma_mps * cfg.dt_s) ** 2
        self.navigation_settings = _batched_kernels.NavigationSettings(
            shared=cfg.centroid_mode == "shared" or n == 1,
            model=self.model,
            iono=self.iono,
            n_sys=self.clock.shape[-1],  # clock states: the systems flown
            ddt=cfg.transfer == "ddt",
            max_iter=int(cfg.nav_max_iter),
            radius=self.radius,
            gate=self.gate,
            origin=w0.origin_ecef_m,
            rot=w0.rot_enu,
            dr_var=float(dr_var * 1.0),
            reach_m=float(cfg.route_reach_m),
            reward_mode=_reward_mode(cfg),
            reward_params=envs[0]._reward_params,
            rays=envs[0]._rays,
            wgs=_WGS84,
            n_bowring=_N_BOWRING_ITER,
        )
        self.first_navigation_settings = self.navigation_settings._replace(
            dr_var=float(dr_var * 0.0)
        )
        self.observation_settings = _batched_kernels.ObservationSettings(
            cfg.obs_neighbours, envs[0]._obs_low, envs[0]._obs_high
        )

    def own(self) -> None:
        """Copy the arrays that the copies' worlds and epochs share, before :meth:`load`."""
        self.pos = self.pos.copy()
        self.vel = self.vel.copy()
        self.nav_pos = self.nav_pos.copy()
        self.nav_cov = self.nav_cov.copy()
        self.wp = self.wp.copy()
        self.unpaid = self.unpaid.copy()

    def advance(self, pos, vel, nav_pos, nav_cov, wp, steps, unpaid) -> None:
        """Take the state after a fused step (the arrays the worlds now view)."""
        self.pos, self.vel, self.nav_pos, self.nav_cov, self.wp = pos, vel, nav_pos, nav_cov, wp
        self.steps, self.unpaid = steps, unpaid

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
        params = env.__dict__.get("_obs_params")  # none before an environment's first reset
        if params is not None:
            self.obs_params[k] = params
            # the route not yet paid and the route length (reward_scheme="navigated_distance")
            self.unpaid[k] = env._unpaid_m
            self.route_len[k] = env._route_m
        self.steps[k] = env._steps
        b = w.city.buildings
        if isinstance(b, Buildings):
            nb = b.min_m.shape[0]
            if nb > self.b_lo.shape[1]:
                self.b_lo = _pad(self.b_lo, nb)
                self.b_hi = _pad(self.b_hi, nb)
            self.b_lo[k, :nb] = b.min_m
            self.b_hi[k, :nb] = b.max_m
            self.n_b[k] = nb
            self.is_poly[k], self.n_poly[k], self.n_edge[k] = False, 0, 0
        else:  # a file city's extruded polygons (and no boxes)
            self._load_polygons(k, b)
            self.n_b[k] = 0
        route, tail = w.route_xy_m, w.route_tail_m
        nr = route.shape[0]
        if nr > self.route.shape[1]:
            self.route = _pad(self.route, nr)
            self.tail = _pad(self.tail, nr)
        self.route[k, :nr] = route
        self.tail[k, :nr] = tail
        self.n_route[k] = nr
        self.cities = _batched_kernels.Cities(
            self.fence_lo,
            self.fence_hi,
            self.b_lo,
            self.b_hi,
            self.n_b,
            self.is_poly,
            self.edges,
            self.edge_start,
            self.heights,
            self.bbox,
            self.n_poly,
            self.n_edge,
        )
        self.routes = _batched_kernels.Routes(self.route, self.tail, self.n_route, self.goal)

    def _load_polygons(self, k: int, b: ExtrudedBuildings) -> None:
        """Copy ``k``'s extruded polygons into the padded arrays (grown where they are short)."""
        npb, ne = b.n, b.edges_m.shape[0]
        if ne > self.edges.shape[1]:
            self.edges = _pad(self.edges, ne)
        if npb + 1 > self.edge_start.shape[1]:
            self.edge_start = _pad(self.edge_start, npb + 1)
        if npb > self.heights.shape[1]:
            self.heights = _pad(self.heights, npb)
            self.bbox = _pad(self.bbox, npb)
        self.edges[k, :ne] = b.edges_m
        self.edge_start[k, : npb + 1] = b.edge_start
        self.heights[k, :npb] = b.heights_m
        self.bbox[k, :npb] = b.bbox_m
        self.is_poly[k], self.n_poly[k], self.n_edge[k] = True, npb, ne


def _route_commands(envs: list[UrbanCanyonEnv], action: np.ndarray, st: _SwarmArrays) -> np.ndarray:
    """The velocity commands ``(K, N, 3)`` of route-frame set-points ``action`` (``action_frame=
    "route"``): :func:`coopnav_env.envs.autopilot.route_frame_velocity` on every copy's
    previous estimates and next waypoints, with each copy's largest offsets where its
    environment has them (``UrbanCanyonEnv._route_offset_cap_m``), else
    ``route_offset_max_m``: ``route_frame_command`` of each copy, bit for bit."""
    cfg = envs[0].config
    kin = cfg.kinematics
    caps = [getattr(e, "_route_offset_cap_m", None) for e in envs]
    offset: np.ndarray | float = cfg.route_offset_max_m
    if any(c is not None for c in caps):
        offset = np.stack(
            [
                np.full(cfg.n_uavs, cfg.route_offset_max_m) if c is None else c[st.wp[k]]
                for k, c in enumerate(caps)
            ]
        )
    return route_frame_velocity(
        action,
        st.nav_pos,
        st.wp,
        st.route,
        kin.max_speed_mps,
        (kin.altitude_min_m, kin.altitude_max_m),
        offset,
        cfg.route_turn_brake_mps2,
        ROUTE_FRAME_GAIN_PER_S,
        route_lengths=st.n_route,
    )


def _pad(a: np.ndarray, size: int) -> np.ndarray:
    """``a`` with its second axis grown to at least ``size`` (zeros; room for more)."""
    out = np.zeros((a.shape[0], max(size, 2 * a.shape[1]), *a.shape[2:]), dtype=a.dtype)
    out[:, : a.shape[1]] = a
    return out
