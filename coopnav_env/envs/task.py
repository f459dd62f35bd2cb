"""The task of ``urban_canyon``: what a step pays, when an episode ends, what the UAVs observe.

The world (:class:`coopnav_env.sim.scenario.UrbanWorld`) advances the swarm one
:class:`~coopnav_env.sim.scenario.Epoch` at a time; the task reads the step from the previous
epoch to the new one and returns

- the reward terms of :data:`REWARD_TERMS` and their sum, computed once each per step:
  ``reward_scheme="per_step"`` (``urban_canyon_v0``) pays the navigation error and the
  progress along the route at every step; ``"navigated_distance"`` (``urban_canyon_v1``) pays
  each metre of the route once, weighted by the navigation quality there, so that the
  undiscounted return of an episode is its score (:func:`navigated_distance`);
- the episode's end (:func:`episode_end`): terminated when a UAV crashes or the whole swarm is
  in the goal, truncated at ``max_steps``;
- the observations, ``(N, obs_dim)`` float32 (the layout is in
  :mod:`coopnav_env.envs.observation_layout`), and the global state of a centralised critic.

:class:`UrbanCanyonTask` holds what a configuration fixes (weights, bounds, the sensors' ray
directions); what changes within an episode (the step count, each UAV's route length and the
part of it not yet paid, the city's scale) is passed in and returned, so that the task keeps no
state of its own. :class:`~coopnav_env.envs.urban_canyon.UrbanCanyonEnv` is the PettingZoo
adapter around the world and this task.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from coopnav_env.envs import _kernels
from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.sim.city import ray_directions
from coopnav_env.sim.route import remaining_route_m
from coopnav_env.sim.scenario import Epoch, UrbanWorld

__all__ = [
    "REWARD_TERMS",
    "StepReward",
    "UrbanCanyonTask",
    "city_scale_m",
    "episode_end",
    "navigated_distance",
    "observation_bounds",
    "state_bounds",
    "team_mix",
    "tracked_satellites",
]

REWARD_TERMS: tuple[str, ...] = ("nav", "progress", "collision", "separation", "contact", "goal")
"""Names of the reward terms; ``infos[agent]["reward_<term>"]`` holds each (their sum is the
reward)."""


class StepReward(NamedTuple):
    """What :meth:`UrbanCanyonTask.reward` returns for one step."""

    reward: np.ndarray
    """``(N,)`` float64: each UAV's reward, the sum of its terms."""
    terms: dict[str, np.ndarray]
    """Term name -> ``(N,)``: :data:`REWARD_TERMS`, then ``"integrity"`` when it is on."""
    in_goal: np.ndarray
    """``(N,)`` bool: the UAV is within ``goal_radius_m`` of the goal (horizontally)."""
    crashed: bool
    """A UAV collided this step."""
    reached: bool
    """Every UAV is in the goal and none collided."""
    unpaid_m: np.ndarray
    """``(N,)``: each UAV's part of the route not yet paid after this step (``reward_scheme=
    "navigated_distance"``; passed through unchanged by ``"per_step"``)."""


def reward_params(cfg: UrbanCanyonConfig) -> np.ndarray:
    """The reward settings the compiled terms read, ``(10,)`` float64: ``nav_reward_weight``,
    ``nav_reward_cap_m``, ``nav_reward_scale_m``, ``progress_reward_weight``, the longest step
    (``max_speed_mps * dt_s``), ``collision_penalty``, ``separation_penalty``,
    ``contact_penalty``, ``goal_radius_m``, ``goal_bonus``."""
    return np.array(
        [
            cfg.nav_reward_weight,
            cfg.nav_reward_cap_m,
            cfg.nav_reward_scale_m,
            cfg.progress_reward_weight,
            cfg.kinematics.max_speed_mps * cfg.dt_s,
            cfg.collision_penalty,
            cfg.separation_penalty,
            cfg.contact_penalty,
            cfg.goal_radius_m,
            cfg.goal_bonus,
        ],
        dtype=np.float64,
    )


def city_scale_m(world: UrbanWorld) -> float:
    """The larger side of the city's extent [m]: the scale of positions in the observations."""
    x0, x1, y0, y1 = world.city.extent_m
    return float(max(x1 - x0, y1 - y0))


def observation_bounds(cfg: UrbanCanyonConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per-index bounds of the observation vector, ``(obs_dim,)`` float32 each (the layout of
    :mod:`coopnav_env.envs.observation_layout`)."""
    a, k = cfg.obs_sky_azimuths, cfg.obs_neighbours
    lo = np.concatenate(
        [
            -np.ones(6),  # position vs goal, velocity
            np.zeros(5 + a),  # sigma, satellite counts, sky
            np.tile([-1.0, -1.0, -1.0, 0.0], k),  # neighbour slots
            np.zeros(3),  # flags, time left
            -np.ones(4),  # next waypoint, leg after it
            np.zeros(2 + a),  # remaining route, altitude, wall distances
            np.zeros(2 if cfg.obs_protection_level else 0),  # HPL, VPL / (2 alert limit)
            np.zeros(2 * a if cfg.obs_satellite_sectors else 0),  # satellites per sector / 4
            -np.ones(3 if cfg.obs_true_error else 0),  # true position error (privileged)
            np.zeros(cfg.n_uavs if cfg.obs_agent_index else 0),  # one-hot index of the UAV
        ]
    )
    hi = np.ones(cfg.obs_dim)
    assert lo.shape == hi.shape
    return lo.astype(np.float32), hi.astype(np.float32)


def state_bounds(cfg: UrbanCanyonConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per-index bounds of the global state (:meth:`UrbanCanyonTask.state`), float32 each."""
    n = cfg.n_uavs
    lo = np.concatenate([-np.ones(6 * n + 3 + 3 * n), np.zeros(3 * n + n + 1)])
    hi = np.ones(cfg.state_dim)
    return lo.astype(np.float32), hi.astype(np.float32)


def navigated_distance(
    route_xy_m: np.ndarray,
    route_tail_m: np.ndarray,
    ep: Epoch,
    unpaid_m: np.ndarray,
    route_m: np.ndarray,
    reached: bool,
    cap_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The terms ``nav`` and ``progress`` of ``reward_scheme="navigated_distance"`` at ``ep``.

    ``progress``: the share of its route a UAV covers for the first time this step (its
    remaining route below its lowest one so far, divided by its route length at reset; all
    that is left when the swarm arrives). ``nav``: minus that share times
    ``min(nav_error_m, cap_m) / cap_m``. Their sum over an episode that arrives is the route's
    distance-weighted navigation quality, whatever the speed: a metre is paid once, at the
    error the UAV had when it first got there, so flying back and forth earns nothing.

    Parameters
    ----------
    route_xy_m, route_tail_m : ndarray, shapes (k, 2) and (k,)
        The street route's waypoints [m] and the route length after each [m].
    ep : Epoch
        The epoch after the step (``pos_enu_m``, ``next_waypoint``, ``nav_error_m``).
    unpaid_m : ndarray, shape (N,)
        Each UAV's remaining route not yet paid before the step [m].
    route_m : ndarray, shape (N,)
        Each UAV's route length at reset [m] (> 0).
    reached : bool
        The swarm reached the goal this step (the rest of every route is paid).
    cap_m : float
        ``nav_reward_cap_m``: an error at or above it (or no estimate) pays nothing.

    Returns
    -------
    nav, progress, unpaid_m : ndarray, shape (N,) each
        The two terms, and the part of each route not yet paid after the step.
    """
    now_m = remaining_route_m(route_xy_m, ep.pos_enu_m[:, :2], ep.next_waypoint, route_tail_m)
    covered_m = unpaid_m if reached else np.clip(unpaid_m - now_m, 0.0, None)
    share = covered_m / route_m
    # np.fmin: an error that is not a number (no estimate) counts as the cap (quality 0)
    shortfall = np.fmin(ep.nav_error_m, cap_m) / cap_m
    return -share * shortfall, share, unpaid_m - covered_m


def team_mix(nav: np.ndarray, weight: float) -> np.ndarray:
    """Team credit: ``(1 - weight) * nav_i + weight * mean(nav)`` (``nav_team_weight``)."""
    return (1.0 - weight) * nav + weight * nav.mean()


def episode_end(steps: int, max_steps: int, crashed: bool, reached: bool) -> tuple[bool, bool]:
    """``(terminated, truncated)`` after ``steps`` steps: terminated when a UAV crashed or the
    swarm reached the goal; otherwise truncated once ``steps >= max_steps``."""
    terminated = bool(crashed or reached)
    return terminated, (steps >= max_steps) and not terminated


def tracked_satellites(ep: Epoch) -> np.ndarray:
    """``(N, S)`` bool: the satellites each UAV's receiver tracks at ``ep``, i.e. those its
    pseudoranges come from (line of sight, or NLOS through a reflection when NLOS reception is
    on; after the ``max_sats`` channel limit) *before* 3D-mapping-aided exclusion: a satellite
    the map excludes is still tracked, only not used."""
    return ep.received if ep.map_excluded is None else ep.received | ep.map_excluded


class UrbanCanyonTask:
    """The task of one configuration: reward terms, episode end, observations and state.

    Parameters
    ----------
    cfg : UrbanCanyonConfig
        The environment's configuration (reward weights and scheme, observation settings).

    Attributes
    ----------
    config : UrbanCanyonConfig
    az_deg : ndarray, shape (A,)
        The skyline and wall sensors' azimuths [deg], ``360 a / A``.
    rays : ndarray, shape (A, 2)
        Their horizontal ray directions (:func:`coopnav_env.sim.city.ray_directions`, those
        the compiled sensors trace).
    reward_params : ndarray, shape (10,)
        The reward settings the compiled terms read (:func:`reward_params`).
    obs_low, obs_high : ndarray, shape (n_base,)
        The bounds of the observation's base columns as float64 (those the compiled builder
        clips to; the optional blocks follow them).
    """

    def __init__(self, cfg: UrbanCanyonConfig) -> None:
        self.config = cfg
        self.az_deg = np.arange(cfg.obs_sky_azimuths) * (360.0 / cfg.obs_sky_azimuths)
        self.rays = ray_directions(self.az_deg)
        self.reward_params = reward_params(cfg)
        lo, hi = observation_bounds(cfg)
        n_base = cfg.obs_base_dim
        self.obs_low = lo[:n_base].astype(np.float64)
        self.obs_high = hi[:n_base].astype(np.float64)

    # ---- episode start ----------------------------------------------------------------------

    def observation_params(self, scale_m: float) -> np.ndarray:
        """The observation scales of an episode whose city is ``scale_m`` across
        (:func:`city_scale_m`), ``(9,)`` float64: city scale, ``max_speed_mps``,
        ``obs_sigma_max_m``, sensing range, ``max_steps``, ``obs_route_scale_m``, the altitude
        band, ``obs_wall_scale_m``."""
        cfg = self.config
        return np.array(
            [
                scale_m,
                cfg.kinematics.max_speed_mps,
                cfg.obs_sigma_max_m,
                cfg.relative_sensing.max_range_m,
                cfg.max_steps,
                cfg.obs_route_scale_m,
                cfg.kinematics.altitude_min_m,
                cfg.kinematics.altitude_max_m,
                cfg.obs_wall_scale_m,
            ],
            dtype=np.float64,
        )

    @staticmethod
    def route_lengths(world: UrbanWorld, ep: Epoch) -> tuple[np.ndarray, np.ndarray]:
        """Each UAV's route length at the episode's first epoch ``ep`` (at least 1e-9 m) and
        the part of it not yet paid (all of it), ``(N,)`` each [m]: the state
        :func:`navigated_distance` starts from."""
        route_m = remaining_route_m(
            world.route_xy_m, ep.pos_enu_m[:, :2], ep.next_waypoint, world.route_tail_m
        )
        return UrbanCanyonTask.unpaid_route(route_m)

    @staticmethod
    def unpaid_route(route_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The route lengths (at least 1e-9 m) and the part not yet paid (a copy) of each
        UAV's remaining route ``route_m`` ``(N,)`` [m] at an episode's first epoch: what
        :meth:`route_lengths` returns."""
        return np.maximum(route_m, 1e-9), route_m.copy()

    # ---- reward and episode end -------------------------------------------------------------

    def reward_terms(
        self, world: UrbanWorld, prev: Epoch, ep: Epoch
    ) -> tuple[np.ndarray, np.ndarray, bool, bool]:
        """The compiled reward terms of the step from ``prev`` to ``ep``, ``(6, N)`` float64 in
        the order of :data:`REWARD_TERMS`, the in-goal flags ``(N,)``, whether a UAV crashed
        and whether the swarm reached the goal.

        ``reward_scheme="per_step"``: all six terms
        (:func:`coopnav_env.envs._kernels.reward_terms`); ``progress`` is the decrease of the
        remaining street route, both ends measured to the waypoint that was next at ``prev``
        (no reward for switching waypoints). ``"navigated_distance"``: the event terms only
        (:func:`coopnav_env.envs._kernels.event_reward_terms`), the rows ``nav`` and
        ``progress`` zero, for :meth:`reward` to fill from :func:`navigated_distance`.
        """
        cfg = self.config
        # the kernels' records (_kernels.RouteAhead, StepPositions, StepEvents) as plain
        # tuples, which numba types faster
        events = (ep.collided, ep.separation_violation, ep.out_of_contact)
        if cfg.reward_scheme == "navigated_distance":
            return _kernels.event_reward_terms(
                ep.pos_enu_m, ep.goal_enu_m, events, self.reward_params
            )
        return _kernels.reward_terms(
            (world.route_xy_m, world.route_tail_m, prev.next_waypoint),
            (
                prev.pos_enu_m[:, :2],
                ep.pos_enu_m,
                ep.goal_enu_m,
                ep.nav_pos_enu_m,
                ep.nav_cov_enu_m2,
            ),
            events,
            cfg.nav_reward == "sigma",
            self.reward_params,
        )

    def reward(
        self,
        world: UrbanWorld,
        prev: Epoch,
        ep: Epoch,
        unpaid_m: np.ndarray,
        route_m: np.ndarray,
    ) -> StepReward:
        """The reward of the step from ``prev`` to ``ep``, each term computed once.

        The terms of :meth:`reward_terms`, with ``nav`` and ``progress`` from
        :func:`navigated_distance` under ``reward_scheme="navigated_distance"`` (``unpaid_m``
        and ``route_m`` its state, see :meth:`route_lengths`), ``nav`` mixed across the team
        (:func:`team_mix`) when ``nav_team_weight > 0``, and with ``integrity`` on the term
        ``integrity``: ``-integrity_penalty`` for a UAV whose estimate is not available or
        misleading (horizontal error above its HPL, or HPL above ``alert_limit_m``).
        """
        cfg = self.config
        stacked, in_goal, crashed, reached = self.reward_terms(world, prev, ep)
        if cfg.reward_scheme == "navigated_distance":
            stacked[0], stacked[1], unpaid_m = navigated_distance(
                world.route_xy_m,
                world.route_tail_m,
                ep,
                unpaid_m,
                route_m,
                bool(reached),
                cfg.nav_reward_cap_m,
            )
        if cfg.nav_team_weight > 0.0:
            stacked[0] = team_mix(stacked[0], cfg.nav_team_weight)
        terms = dict(zip(REWARD_TERMS, stacked))
        reward = stacked.sum(axis=0)
        if cfg.integrity != "off":
            if cfg.integrity_penalty == 0.0:  # the term is reported, and is zero
                terms["integrity"] = np.zeros(reward.shape[0])
            else:
                d = ep.nav_pos_enu_m - ep.pos_enu_m
                h_err = np.hypot(d[:, 0], d[:, 1])
                bad = (h_err > ep.hpl_m) | (ep.hpl_m > cfg.alert_limit_m)  # (hpl is never NaN)
                terms["integrity"] = -cfg.integrity_penalty * bad
                reward = reward + terms["integrity"]
        return StepReward(reward, terms, in_goal, bool(crashed), bool(reached), unpaid_m)

    def zero_terms(self) -> dict[str, np.ndarray]:
        """The reward terms of a reset (all zero): :data:`REWARD_TERMS`, then ``"integrity"``
        when it is on."""
        n = self.config.n_uavs
        terms = {t: np.zeros(n) for t in REWARD_TERMS}
        if self.config.integrity != "off":
            terms["integrity"] = np.zeros(n)
        return terms

    # ---- observations and state -------------------------------------------------------------

    def observations(
        self, world: UrbanWorld, ep: Epoch, steps: int, obs_params: np.ndarray
    ) -> np.ndarray:
        """Every agent's observation at ``ep`` after ``steps`` steps, ``(N, obs_dim)`` float32
        (rows in agent order; ``obs_params`` from :meth:`observation_params`).

        The base columns come from :meth:`observation_rows`. With ``obs_protection_level``
        the two protection-level columns follow, then with ``obs_satellite_sectors`` the
        ``2 A`` satellite-sector columns (:meth:`satellite_sectors`), then with
        ``obs_true_error`` (privileged) the 3 columns of the true position error, then with
        ``obs_agent_index`` the ``N`` columns of the UAV's one-hot index.
        """
        obs = self.observation_rows(world, ep, steps, obs_params)
        cfg = self.config
        if not (
            cfg.obs_protection_level
            or cfg.obs_satellite_sectors
            or cfg.obs_true_error
            or cfg.obs_agent_index
        ):
            return obs
        blocks = [obs]
        if cfg.obs_protection_level:
            scale = 2.0 * cfg.alert_limit_m
            pl = np.clip(np.stack([ep.hpl_m, ep.vpl_m], axis=1) / scale, 0.0, 1.0)
            blocks.append(pl.astype(np.float32))
        if cfg.obs_satellite_sectors:
            blocks.append(self.satellite_sectors(ep))
        if cfg.obs_true_error:  # privileged (a diagnostic): the truth no receiver knows
            err = (ep.nav_pos_enu_m - ep.pos_enu_m) / cfg.obs_sigma_max_m
            blocks.append(np.clip(err, -1.0, 1.0).astype(np.float32))
        if cfg.obs_agent_index:
            blocks.append(np.eye(cfg.n_uavs, dtype=np.float32))
        return np.concatenate(blocks, axis=1)

    def observation_rows(
        self, world: UrbanWorld, ep: Epoch, steps: int, obs_params: np.ndarray
    ) -> np.ndarray:
        """The observation's base columns (without the optional blocks), ``(N, n_base)``
        float32, by the compiled :func:`coopnav_env.envs._kernels.observation_rows` (its numpy
        definition, equal bit for bit, is ``observation_rows`` of ``tests/envs/oracles.py``),
        with the skyline and wall distances at the true positions
        (:meth:`coopnav_env.sim.scenario.UrbanWorld.sky_and_walls`)."""
        sky_deg, walls = world.sky_and_walls(ep.pos_enu_m, self.az_deg)
        figures = (  # the records of the kernel, as plain tuples (numba types them faster)
            ep.nav_pos_enu_m,
            ep.goal_enu_m,
            ep.vel_enu_mps,
            ep.nav_cov_enu_m2,
            ep.n_sats,
            ep.n_sats_swarm,
            max(ep.n_above_mask, 1),
            ep.rel_enu_m,
            ep.rel_available,
            ep.nav_source,
            steps,
        )
        return _kernels.observation_rows(
            figures,
            (sky_deg, walls),
            (world.route_xy_m, world.route_tail_m, ep.next_waypoint),
            (obs_params, self.config.obs_neighbours, self.obs_low, self.obs_high),
        )

    def satellite_sectors(self, ep: Epoch) -> np.ndarray:
        """The ``obs_satellite_sectors`` columns, ``(N, 2 A)`` float32.

        Columns ``0..A-1`` (``satellites_received_sector``): satellites the UAV tracks
        (:func:`tracked_satellites`) whose azimuth falls in sector ``a``; columns ``A..2A-1``
        (``satellites_blocked_sector``): satellites above ``elevation_mask_deg`` it does not
        track, per sector. Each count is divided by 4 and clipped to [0, 1]. Sector ``a`` is
        centred on the skyline azimuth ``360 a / A`` (clockwise from North) and spans
        ``360 / A`` degrees: a satellite at azimuth ``az`` is in sector
        ``floor(az A / 360 + 1/2) mod A``, the skyline direction nearest to it.

        The azimuths are those of the world (``Epoch.sv_az_deg``, computed at the city's
        geodetic origin), in [0, 360). A receiver would compute them from its almanac and its
        approximate position; the satellites are some 20,000 km away, so moving the receiver
        by ``d`` turns the line of sight by at most ``d / 20,000 km`` (0.003 deg for the 1 km
        of a city, or a navigation error of tens of metres far less), far below the sector
        width of ``360 / A`` deg: the origin, the true position and the estimate give the
        same sectors except for a satellite within that hair of a sector boundary (or so
        near the zenith that its azimuth is meaningless anyway). The compiled
        :func:`coopnav_env.envs._kernels.satellite_sectors` computes it (its numpy definition,
        equal bit for bit, is ``satellite_sectors`` of ``tests/envs/oracles.py``).
        """
        return _kernels.satellite_sectors(
            tracked_satellites(ep), ep.sv_az_deg, self.config.obs_sky_azimuths
        )

    def state(
        self,
        world: UrbanWorld,
        ep: Epoch,
        steps: int,
        scale_m: float,
        low: np.ndarray,
        high: np.ndarray,
    ) -> np.ndarray:
        """Global state for centralised critics (truth included), float32, clipped to
        ``[low, high]`` (:func:`state_bounds`).

        ``[(pos - goal) / L (3N), vel / max_speed (3N), (goal - city centre) / (L / 2) (3),
        (estimate - pos) / nav_reward_cap_m (3N), sigma / obs_sigma_max_m (3N),
        satellites received / above cut-off (N), steps left / max_steps (1)]`` with
        ``L = scale_m`` (:func:`city_scale_m`).
        """
        cfg = self.config
        x0, x1, y0, y1 = world.city.extent_m
        centre = np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0, 0.0])
        parts = [
            ((ep.pos_enu_m - ep.goal_enu_m) / scale_m).ravel(),
            (ep.vel_enu_mps / cfg.kinematics.max_speed_mps).ravel(),
            (ep.goal_enu_m - centre) / (scale_m / 2.0),
            ((ep.nav_pos_enu_m - ep.pos_enu_m) / cfg.nav_reward_cap_m).ravel(),
            (ep.nav_sigma_enu_m / cfg.obs_sigma_max_m).ravel(),
            ep.n_sats / max(ep.n_above_mask, 1),
            [1.0 - steps / cfg.max_steps],
        ]
        s = np.concatenate([np.asarray(p, dtype=float) for p in parts])
        return np.clip(s, low, high).astype(np.float32)
