"""Numpy oracles of the environment's compiled kernels (:mod:`coopnav_env.envs._kernels`).

The task (:class:`~coopnav_env.envs.task.UrbanCanyonTask`) builds its observations, satellite
sectors and reward terms, and the environment
(:class:`~coopnav_env.envs.urban_canyon.UrbanCanyonEnv`) its info figures, in compiled loops
only. The functions here are their readable numpy definitions, each taking the arguments of
the method it defines (the task and the world's epochs, or the environment); the kernels
perform the same floating-point operations, so the tests compare the two bit for bit.
:func:`use_oracles_in_env` puts them in place of the kernels, and
:func:`use_all_oracles` does so for every layer below too (GNSS, navigation, world).
"""

from __future__ import annotations

from collections import ChainMap

import numpy as np
import pytest

from coopnav_env.envs import _fused, batched
from coopnav_env.envs.task import REWARD_TERMS, UrbanCanyonTask, observation_bounds
from coopnav_env.envs.task import tracked_satellites as _tracked_satellites
from coopnav_env.envs.urban_canyon import UrbanCanyonEnv
from coopnav_env.nav import cooperative as _cooperative
from coopnav_env.sim import scenario as _scenario
from coopnav_env.sim.route import remaining_route_m
from coopnav_env.sim.scenario import Epoch, NavSource, UrbanWorld
from tests.gnss.oracles import use_gnss_oracles
from tests.nav.oracles import use_nav_oracles
from tests.sim.oracles import use_oracles_in_world

__all__ = [
    "info_floats",
    "navigated_distance_rows",
    "observation_rows",
    "reward_terms",
    "satellite_sectors",
    "use_all_oracles",
    "use_oracles_in_env",
]


def observation_rows(
    task: UrbanCanyonTask, world: UrbanWorld, ep: Epoch, steps: int, obs_params: np.ndarray
) -> np.ndarray:
    """Every agent's observation without the optional blocks, ``(N, n_base)`` float32: the
    definition of ``UrbanCanyonTask.observation_rows``."""
    cfg = task.config
    n = cfg.n_uavs
    big = obs_params[0]  # the city's scale
    k = cfg.obs_neighbours
    n_open = max(ep.n_above_mask, 1)
    sky_deg, walls = world.city.sky_and_walls(ep.pos_enu_m, task.az_deg)
    sky = sky_deg / 90.0

    # neighbour slots: nearest (measured) first
    rel, avail = ep.rel_enu_m, ep.rel_available
    dist = np.where(avail, np.linalg.norm(rel, axis=2), np.inf)
    m = min(k, n)
    order = np.argsort(dist, axis=1, kind="stable")[:, :m]
    present = np.take_along_axis(avail, order, axis=1)
    rel_k = np.take_along_axis(rel, order[:, :, None], axis=1)
    rel_k = np.where(present[:, :, None], rel_k / cfg.relative_sensing.max_range_m, 0.0)
    slots = np.zeros((n, k, 4))
    slots[:, :m, :3] = rel_k
    slots[:, :m, 3] = present

    # route: next waypoint and the leg after it, from the estimated position
    route = world.route_xy_m
    wp = ep.next_waypoint
    last = route.shape[0] - 1
    est_xy = ep.nav_pos_enu_m[:, :2]
    to_wp = route[wp] - est_xy
    after = route[np.minimum(wp + 1, last)] - route[wp]  # 0 when the next one is the goal
    remaining = remaining_route_m(route, est_xy, wp, world.route_tail_m)
    kin = cfg.kinematics
    alt = (ep.nav_pos_enu_m[:, 2] - kin.altitude_min_m) / (kin.altitude_max_m - kin.altitude_min_m)

    obs = np.concatenate(
        [
            (ep.nav_pos_enu_m - ep.goal_enu_m) / big,
            ep.vel_enu_mps / cfg.kinematics.max_speed_mps,
            ep.nav_sigma_enu_m / cfg.obs_sigma_max_m,
            (ep.n_sats / n_open)[:, None],
            (ep.n_sats_swarm / n_open)[:, None],
            sky,
            slots.reshape(n, 4 * k),
            (ep.nav_source == NavSource.COOPERATIVE)[:, None],
            (ep.nav_source != NavSource.DEAD_RECKONING)[:, None],
            np.full((n, 1), 1.0 - steps / cfg.max_steps),
            to_wp / cfg.obs_route_scale_m,
            after / cfg.obs_route_scale_m,
            (remaining / (2.0 * big))[:, None],
            alt[:, None],
            np.minimum(walls / cfg.obs_wall_scale_m, 1.0),
        ],
        axis=1,
    )
    low, high = observation_bounds(cfg)
    n_base = obs.shape[1]  # the optional blocks are appended by the caller
    return np.clip(obs, low[:n_base], high[:n_base]).astype(np.float32)


def satellite_sectors(task: UrbanCanyonTask, ep: Epoch) -> np.ndarray:
    """The ``obs_satellite_sectors`` columns, ``(N, 2 A)`` float32: the definition of
    ``UrbanCanyonTask.satellite_sectors`` (tracked, then not tracked, satellites per azimuth
    sector, divided by 4 and clipped to 1)."""
    a = task.config.obs_sky_azimuths
    tracked = _tracked_satellites(ep)
    sector = np.floor(ep.sv_az_deg * (a / 360.0) + 0.5).astype(np.int64) % a
    one_hot = (sector[:, None] == np.arange(a)[None, :]).astype(np.float64)  # (S, A)
    counts = np.concatenate([tracked @ one_hot, ~tracked @ one_hot], axis=1)
    return np.minimum(counts / 4.0, 1.0).astype(np.float32)


def info_floats(env: UrbanCanyonEnv) -> np.ndarray:
    """The per-agent real numbers of the infos, ``(8, N)``: errors of the estimate used, the
    cooperative and the standalone fix (inf: no fix), sigma E/N/U and 3-D, goal distance (the
    definition of ``UrbanCanyonEnv._info_floats``)."""
    ep = env._epoch
    # three errors in one pass: estimate used, cooperative, standalone (inf: no fix)
    err = np.linalg.norm(
        np.stack([ep.nav_pos_enu_m, ep.coop_pos_enu_m, ep.standalone_pos_enu_m]) - ep.pos_enu_m,
        axis=2,
    )
    err[1:] = np.where(np.isfinite(err[1:]), err[1:], np.inf)
    sig = ep.nav_sigma_enu_m
    return np.concatenate(
        [err, sig.T, np.sqrt((sig**2).sum(axis=1))[None], ep.goal_distance_m[None]]
    )


def navigated_distance_rows(
    pos: np.ndarray,
    nav_pos: np.ndarray,
    route: np.ndarray,
    tail: np.ndarray,
    wp: np.ndarray,
    reached: np.ndarray,
    unpaid: np.ndarray,
    route_len: np.ndarray,
    cap_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The terms ``nav`` and ``progress`` ``(K, N)`` of ``reward_scheme="navigated_distance"``
    of every copy and the route not yet paid after the step ``(K, N)`` (the definition of
    ``_batched_kernels.navigated_distance_terms``: :func:`coopnav_env.envs.task.
    navigated_distance` on each copy's rows), from the true positions ``pos`` and estimates
    ``nav_pos`` ``(K, N, 3)``, the padded routes ``route (K, R, 2)`` and ``tail (K, R)``, the
    next waypoints ``wp (K, N)``, whether each swarm arrived ``reached (K,)``, the route not
    yet paid ``unpaid`` and the route lengths ``route_len`` ``(K, N)``."""
    rows = np.arange(pos.shape[0])[:, None]
    # remaining_route_m: straight to the next waypoint, then along the route
    d = np.linalg.norm(pos[:, :, :2] - route[rows, wp], axis=2)
    now_m = d + tail[rows, wp]
    covered = np.where(reached[:, None], unpaid, np.clip(unpaid - now_m, 0.0, None))
    share = covered / route_len
    # np.fmin: an error that is not a number (no estimate) counts as the cap (quality 0)
    shortfall = np.fmin(np.linalg.norm(nav_pos - pos, axis=2), cap_m) / cap_m
    return -share * shortfall, share, unpaid - covered


def reward_terms(
    task: UrbanCanyonTask, world: UrbanWorld, prev: Epoch, ep: Epoch
) -> tuple[np.ndarray, np.ndarray, bool, bool]:
    """``(6, N)`` reward terms (order of :data:`REWARD_TERMS`), in-goal flags, crash and
    reached of the step from ``prev`` to ``ep``: the definition of
    ``UrbanCanyonTask.reward_terms`` (with ``reward_scheme="navigated_distance"`` the rows
    ``nav`` and ``progress`` are zero: the task fills them from the route)."""
    cfg = task.config
    # progress: decrease of the remaining street route, both ends measured to the
    # waypoint that was next at the previous step (no reward for switching waypoints)
    route = world.route_xy_m
    tail = world.route_tail_m
    d_prev = remaining_route_m(route, prev.pos_enu_m[:, :2], prev.next_waypoint, tail)
    d_now = remaining_route_m(route, ep.pos_enu_m[:, :2], prev.next_waypoint, tail)
    in_goal = ep.goal_distance_m <= cfg.goal_radius_m
    crash = bool(ep.collided.any())
    reached = bool(in_goal.all()) and not crash
    if cfg.nav_reward == "error":
        nav_m = ep.nav_error_m
    else:
        nav_m = np.sqrt(np.clip(np.trace(ep.nav_cov_enu_m2, axis1=1, axis2=2), 0.0, None))
    n = cfg.n_uavs
    terms = {
        "nav": -cfg.nav_reward_weight
        * np.minimum(nav_m, cfg.nav_reward_cap_m)
        / cfg.nav_reward_scale_m,
        "progress": cfg.progress_reward_weight
        * (d_prev - d_now)
        / (cfg.kinematics.max_speed_mps * cfg.dt_s),
        "collision": -cfg.collision_penalty * ep.collided,
        "separation": -cfg.separation_penalty * ep.separation_violation,
        "contact": -cfg.contact_penalty * ep.out_of_contact,
        "goal": np.full(n, cfg.goal_bonus if reached else 0.0),
    }
    if cfg.reward_scheme == "navigated_distance":
        terms["nav"] = terms["progress"] = np.zeros(n)
    return np.stack([terms[t] for t in REWARD_TERMS]), in_goal, crash, reached


def use_oracles_in_env(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Make every :class:`UrbanCanyonEnv` (and batch of them) step through its own methods
    (the fused step of a batch off) with the oracles above in place of the compiled
    observation, sector, info and reward kernels, until ``monkeypatch`` undoes it.

    Returns a dict counting the calls of each oracle, so that a test can check they ran.
    """
    calls = dict.fromkeys(
        ("observation_rows", "satellite_sectors", "info_floats", "reward_terms"), 0
    )

    def counted(name, fn):
        def run(*args):
            calls[name] += 1
            return fn(*args)

        return run

    monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
    monkeypatch.setattr(batched, "fused_settings", lambda cfg: False)
    monkeypatch.setattr(
        UrbanCanyonTask, "observation_rows", counted("observation_rows", observation_rows)
    )
    monkeypatch.setattr(
        UrbanCanyonTask, "satellite_sectors", counted("satellite_sectors", satellite_sectors)
    )
    monkeypatch.setattr(UrbanCanyonEnv, "_info_floats", counted("info_floats", info_floats))
    monkeypatch.setattr(UrbanCanyonTask, "reward_terms", counted("reward_terms", reward_terms))
    return calls


def use_all_oracles(monkeypatch: pytest.MonkeyPatch) -> ChainMap[str, int]:
    """:func:`use_oracles_in_env` and, below it, the oracles of the world
    (``tests/sim/oracles.py``, which also makes the world navigate function by function),
    of the navigation solvers (``tests/nav/oracles.py``) and of the GNSS measurements
    (``tests/gnss/oracles.py``): an environment that runs no compiled kernel of the
    library's own (a file city's polygons keep theirs).

    Returns one mapping counting the calls of every oracle, updated as they run.
    """
    uses = (use_oracles_in_env, use_oracles_in_world, use_nav_oracles, use_gnss_oracles)
    calls = ChainMap(*(use(monkeypatch) for use in uses))
    # the world's one-call cooperative solve (imported by name) declines as the nav oracles'
    monkeypatch.setattr(_scenario, "_solve_isotropic", _cooperative._solve_isotropic)
    return calls
