"""Configuration of the ``urban_canyon_v0`` environment: one typed, frozen, validated dataclass.

:class:`UrbanCanyonConfig` extends the world's :class:`~coopnav_env.sim.scenario.ScenarioConfig`
(city, satellites, errors, kinematics, sensing, navigation, task) with what only the
environment needs (episode length, observation, reward, rendering). Every keyword argument of
``urban_canyon_v0.parallel_env(...)`` is a field of it; unknown names are rejected with the list
of valid ones (:func:`make_config`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Literal

from coopnav_env.sim.city import _check_int, _check_real
from coopnav_env.sim.scenario import ScenarioConfig, _check_bool, _check_choice

__all__ = [
    "ACTION_FRAMES",
    "EXPERIMENTAL_SETTINGS",
    "PER_STEP_REWARD_FIELDS",
    "PRESETS",
    "REWARD_SCHEMES",
    "V1_DEFAULTS",
    "ExperimentalSetting",
    "UrbanCanyonConfig",
    "config_field_names",
    "make_config",
    "preset_config",
]

REWARD_SCHEMES: tuple[str, ...] = ("per_step", "navigated_distance")
"""The values of :attr:`UrbanCanyonConfig.reward_scheme`."""

ACTION_FRAMES: tuple[str, ...] = ("velocity", "route")
"""The values of :attr:`UrbanCanyonConfig.action_frame`."""

PER_STEP_REWARD_FIELDS: tuple[str, ...] = (
    "nav_reward_weight",
    "progress_reward_weight",
    "separation_penalty",
    "contact_penalty",
    "integrity_penalty",
)
"""Weights of per-step reward terms: used by ``reward_scheme="per_step"`` only."""

V1_DEFAULTS: dict[str, Any] = {
    "reward_scheme": "navigated_distance",
    "goal_bonus": 1.0,
    "collision_penalty": 1.0,
    "nav_reward_weight": 0.0,
    "progress_reward_weight": 0.0,
    "separation_penalty": 0.0,
    "contact_penalty": 0.0,
    "crash_free_steps": 3,
}
"""The settings in which ``urban_canyon_v1`` differs from ``urban_canyon_v0``: its reward, and
a crash-free start of 3 steps.

``goal_bonus=1``: arriving is worth as much as the whole route flown at zero error, so a swarm
that arrives scores above one that does not, except one that arrives with nearly no
navigation (quality below the shortfall of the other). ``collision_penalty=1``: a crash
forfeits the rest of the route and the bonus, and costs 1 more, so crashing never pays.
``crash_free_steps=3``: every episode lasts at least 4 steps (PettingZoo's ``max_cycles_test``
flies random actions for ``max_cycles=4`` and counts on it).
"""


@dataclass(frozen=True)
class UrbanCanyonConfig(ScenarioConfig):
    """Every setting of ``urban_canyon_v0`` (world fields inherited from ScenarioConfig).

    A bad value raises ``ValueError`` naming the field, the value and the allowed range. The
    world fields (``n_uavs``, ``city``, ``city_config``, ``city_seed``, ``canyon_*``, origin,
    ``t0_s``, ``systems``, ``elevation_mask_deg``, ``max_sats``, ``error_model``, NLOS,
    ``kinematics``, ``relative_sensing``, ``transfer``, ``centroid``, ``covariance``, ...,
    ``goal_radius_m``) are documented in :class:`~coopnav_env.sim.scenario.ScenarioConfig`.

    Parameters
    ----------
    max_steps : int, default 200
        Episode length; reaching it truncates every agent, in [1, 100000]. ``max_cycles``, the
        name PettingZoo's own environments, its ``max_cycles_test`` and BenchMARL use, is
        accepted as an alias by :func:`make_config` (and so by ``parallel_env(...)``), and
        :attr:`max_cycles` reads it.
    crash_free_steps : int, default 0
        A crash-free start: in the first ``crash_free_steps`` steps of an episode a UAV whose
        move would touch a building is stopped where it was, with zero velocity (as on a
        crash), but the episode goes on: no ``collided`` flag, no collision penalty. So no
        episode ends before step ``crash_free_steps + 1`` (but by arriving). In [0, 100];
        0 (v0) leaves every step as it was; ``urban_canyon_v1`` uses 3.
    obs_neighbours : int, default 4
        Neighbour slots ``K`` in each observation (nearest first, padded), in [0, 64].
    obs_sky_azimuths : int, default 8
        Azimuths of the sky-openness observation, evenly spaced from North, in [1, 72].
    obs_sigma_max_m : float, default 20.0
        Predicted sigma per axis at which the SIG observation saturates at 1, in (0, 1e4] [m].
    obs_route_scale_m : float, default 50.0
        Scale of the route observations (vector to the next waypoint, next leg): a distance
        of this many metres reads 1, in (0, 1e4] [m].
    obs_wall_scale_m : float, default 50.0
        Wall distance at which the range observation saturates at 1, in (0, 1e4] [m].
    reward_scheme : {"per_step", "navigated_distance"}, default "per_step"
        How the reward is paid (``urban_canyon_v1`` sets ``"navigated_distance"``; the
        environment's documentation page has the definitions and the reasons).
        ``"navigated_distance"``: the undiscounted return is the task's score. Each UAV is paid
        for the share of its street route it covers for the first time, weighted by the
        quality of its navigation there, ``1 - min(nav_error, nav_reward_cap_m) /
        nav_reward_cap_m``; the rest of the route is paid at arrival; ``goal_bonus`` when the
        swarm arrives and ``-collision_penalty`` for a UAV that hits a building. The total does
        not depend on how fast the route is flown. It has no per-step terms:
        ``nav_reward_weight``, ``progress_reward_weight``, ``separation_penalty``,
        ``contact_penalty`` and ``integrity_penalty`` must be 0 and ``nav_reward`` must be
        ``"error"``.
        ``"per_step"`` (``urban_canyon_v0``): a navigation cost and a progress payment every
        step, per-step separation and contact penalties, a goal bonus and a collision
        penalty. Its return pays for a short trip as well as for low error.
    nav_reward : {"error", "sigma"}, default "error"
        Navigation reward from the true 3-D error of the estimate a UAV uses, or from its
        predicted 3-D sigma ``sqrt(trace(H_p))``.
    nav_reward_weight : float, default 0.1
        Weight of the navigation term, in [0, 1000].
    nav_reward_scale_m : float, default 10.0
        Error (or sigma) that costs one ``nav_reward_weight``, in (0, 1e4] [m].
    nav_reward_cap_m : float, default 10.0
        The error (or sigma) is capped here before scaling, in (0, 1e5] [m].
    nav_team_weight : float, default 0.0
        Team credit of the navigation term, in [0, 1]: each UAV's ``nav`` term becomes
        ``(1 - w) nav_i + w mean_j(nav_j)``; 0 keeps each UAV's own error, 1 gives every UAV
        the swarm's mean. With a shared (team) term a UAV that holds an open square so that
        its neighbours' fixes improve is paid for it; per-agent PPO cannot otherwise assign
        that credit. The default keeps the own error (episodes of earlier versions unchanged).
    progress_reward_weight : float, default 1.0
        Weight of the progress term (decrease of the remaining street-route length per step,
        divided by ``max_speed_mps * dt_s``, so at most 1 in magnitude), in [0, 1000].
    collision_penalty : float, default 40.0
        Subtracted from a UAV that hits a building (the episode ends), in [0, 1e5]. The
        default is larger than the worst penalty a whole episode can collect without a crash,
        ``max_steps * (nav_reward_weight * nav_reward_cap_m / nav_reward_scale_m +
        separation_penalty + contact_penalty)`` = 200 x (0.1 + 0.05 + 0.02) = 34
        (:attr:`worst_episode_penalty`), so that ending an episode by crashing never pays.
    separation_penalty : float, default 0.05
        Subtracted per step from each UAV closer than ``min_separation_m`` to another, in
        [0, 1e5].
    contact_penalty : float, default 0.02
        Subtracted per step from each UAV with no other UAV in relative-sensing range, in
        [0, 1e5].
    goal_bonus : float, default 10.0
        Added to every UAV when all UAVs are in the goal area (the episode ends), in [0, 1e5].
    render_sky_uav : int, default -1
        UAV shown in the sky plot of a rendered frame; -1: the UAV that receives the fewest
        satellites at that epoch. In [-1, n_uavs - 1].
    render_width_px, render_height_px : int, default 1280, 640
        Size of a rendered frame, each in [320, 4096] [pixel].
    alert_limit_m : float, default 30.0
        Horizontal alert limit of the integrity monitor (``integrity`` on): a UAV's estimate
        is *available* when its horizontal protection level is at most this, in (0, 1e4] [m].
    integrity_penalty : float, default 0.0
        With ``integrity`` on, subtracted per step from each UAV whose estimate is not
        available (HPL above ``alert_limit_m``, dead reckoning included) or misleading (true
        horizontal error above the HPL), reward term ``integrity``; in [0, 1000]. Needs
        ``integrity`` on when > 0.
    obs_protection_level : bool, default False
        Append ``min(HPL / (2 alert_limit_m), 1)`` and ``min(VPL / (2 alert_limit_m), 1)`` of
        the estimate used to the observation (0.5: at the alert limit; 1: beyond twice it or
        none). Needs ``integrity`` on.
    obs_satellite_sectors : bool, default False
        Append two blocks of ``obs_sky_azimuths`` entries after everything else (after the
        protection levels when those are on): per azimuth sector of the skyline, the number
        of satellites the UAV tracks (``satellites_received_sector``) and the number above the
        elevation cut-off it does not track (``satellites_blocked_sector``), each divided by 4
        and clipped to [0, 1]. What a real receiver knows from its almanac and its tracking
        loops: where the satellites it misses are.
    obs_true_error : bool, default False
        *Experimental* (:data:`EXPERIMENTAL_SETTINGS`: may change or be removed).
        **Privileged: a diagnostic, not an on-board observation.** Append three entries last
        (after every other optional block): the UAV's true position error, East, North, Up,
        of the estimate it uses (``nav_error``), each divided by ``obs_sigma_max_m`` and
        clipped to [-1, 1]. No receiver knows this; the privileged planner does (it knows
        where the UAVs are). It tells whether a learned policy falls short of the planner
        for want of information or for want of learning (``studies/planner_headroom``); a
        policy trained with it must never be reported as an on-board one.
    obs_agent_index : bool, default False
        Append ``n_uavs`` entries last (after every other optional block): the one-hot index
        of the UAV (1 at its position in ``possible_agents``, 0 elsewhere). A UAV knows which
        one it is; with one network shared by every UAV (parameter sharing) this is what lets
        the UAVs of a tight group, whose observations are otherwise nearly equal, act
        differently (*agent indication*: Terry et al., *Revisiting Parameter Sharing in
        Multi-Agent Deep Reinforcement Learning*, 2020; the agent id of Yu et al.'s MAPPO).
    action_frame : {"velocity", "route"}, default "velocity"
        What an action ``(a0, a1, a2)`` in ``[-1, 1]`` commands. ``"velocity"``: the desired
        velocity, East, North, Up, as fractions of ``max_speed_mps``. ``"route"``: set-points
        in the frame of the UAV's street route, which its autopilot tracks from its
        *estimated* position (what the UAV knows): ``a0`` the speed along the route,
        ``(a0 + 1) / 2 * max_speed_mps`` (``-1`` holds its place); ``a1`` the offset across
        the street from the route's centre line, ``a1 * route_offset_max_m`` (positive to
        the left of travel); ``a2`` the altitude, from ``altitude_min_m`` (``-1``) to
        ``altitude_max_m`` (``+1``). The autopilot is the `waypoint` follower's: it flies toward
        the UAV's next waypoint, moved by the offset, slowing to ``1 + 0.6 d`` m/s at ``d`` m
        from it, and holds the altitude with a gain of 0.6 per second; the result
        is the velocity command of ``"velocity"``, so kinematics, collisions and everything
        after them are the same. The frame flies a policy along its street route, so that
        what it learns is where along, across and above it each UAV flies (how far apart,
        how high); it does not say where: a constant action flies the UAVs together.
    route_offset_max_m : float, default 4.0
        Largest offset across the street of ``action_frame="route"`` [m], at least 0 and
        less than half the street width minus the UAV radius (checked when the world is
        built).
    route_turn_brake_mps2 : float, default 0.0
        With ``action_frame="route"`` and a value ``b > 0``, the autopilot also limits the
        speed before a waypoint that is not the last (a turn of the route) to
        ``1 + sqrt(2 b max(d - 3, 0))`` m/s at ``d`` m from it, so that a UAV brakes for the
        turn at ``b`` m/s² (the 3 m allow for one step of travel). 0: the `waypoint`
        follower's law only, which leaves a UAV coming at 10 m/s too fast to turn in a 20 m
        street. In [0, 100] [m/s²].
    """

    max_steps: int = 200
    crash_free_steps: int = 0
    obs_neighbours: int = 4
    obs_sky_azimuths: int = 8
    obs_sigma_max_m: float = 20.0
    obs_route_scale_m: float = 50.0
    obs_wall_scale_m: float = 50.0
    reward_scheme: Literal["per_step", "navigated_distance"] = "per_step"
    nav_reward: Literal["error", "sigma"] = "error"
    nav_reward_weight: float = 0.1
    nav_reward_scale_m: float = 10.0
    nav_reward_cap_m: float = 10.0
    nav_team_weight: float = 0.0
    progress_reward_weight: float = 1.0
    collision_penalty: float = 40.0
    separation_penalty: float = 0.05
    contact_penalty: float = 0.02
    goal_bonus: float = 10.0
    render_sky_uav: int = -1
    render_width_px: int = 1280
    render_height_px: int = 640
    alert_limit_m: float = 30.0
    integrity_penalty: float = 0.0
    obs_protection_level: bool = False
    obs_satellite_sectors: bool = False
    obs_true_error: bool = False
    obs_agent_index: bool = False
    action_frame: Literal["velocity", "route"] = "velocity"
    route_offset_max_m: float = 4.0
    route_turn_brake_mps2: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        o = type(self).__name__
        _check_int(o, "max_steps", self.max_steps, 1, 100_000)
        _check_int(o, "crash_free_steps", self.crash_free_steps, 0, 100)
        _check_int(o, "obs_neighbours", self.obs_neighbours, 0, 64)
        _check_int(o, "obs_sky_azimuths", self.obs_sky_azimuths, 1, 72)
        _check_real(o, "obs_sigma_max_m", self.obs_sigma_max_m, 0.0, 1e4, lo_open=True)
        _check_real(o, "obs_route_scale_m", self.obs_route_scale_m, 0.0, 1e4, lo_open=True)
        _check_real(o, "obs_wall_scale_m", self.obs_wall_scale_m, 0.0, 1e4, lo_open=True)
        _check_choice(o, "reward_scheme", self.reward_scheme, REWARD_SCHEMES)
        _check_choice(o, "nav_reward", self.nav_reward, ("error", "sigma"))
        _check_real(o, "nav_reward_weight", self.nav_reward_weight, 0.0, 1000.0)
        _check_real(o, "nav_reward_scale_m", self.nav_reward_scale_m, 0.0, 1e4, lo_open=True)
        _check_real(o, "nav_reward_cap_m", self.nav_reward_cap_m, 0.0, 1e5, lo_open=True)
        _check_real(o, "nav_team_weight", self.nav_team_weight, 0.0, 1.0)
        _check_real(o, "progress_reward_weight", self.progress_reward_weight, 0.0, 1000.0)
        _check_real(o, "collision_penalty", self.collision_penalty, 0.0, 1e5)
        _check_real(o, "separation_penalty", self.separation_penalty, 0.0, 1e5)
        _check_real(o, "contact_penalty", self.contact_penalty, 0.0, 1e5)
        _check_real(o, "goal_bonus", self.goal_bonus, 0.0, 1e5)
        _check_int(o, "render_sky_uav", self.render_sky_uav, -1, self.n_uavs - 1)
        _check_int(o, "render_width_px", self.render_width_px, 320, 4096)
        _check_int(o, "render_height_px", self.render_height_px, 320, 4096)
        _check_real(o, "alert_limit_m", self.alert_limit_m, 0.0, 1e4, lo_open=True)
        _check_real(o, "integrity_penalty", self.integrity_penalty, 0.0, 1000.0)
        _check_bool(o, "obs_protection_level", self.obs_protection_level)
        _check_bool(o, "obs_satellite_sectors", self.obs_satellite_sectors)
        _check_bool(o, "obs_true_error", self.obs_true_error)
        _check_bool(o, "obs_agent_index", self.obs_agent_index)
        _check_choice(o, "action_frame", self.action_frame, ACTION_FRAMES)
        _check_real(o, "route_offset_max_m", self.route_offset_max_m, 0.0, 1000.0)
        _check_real(o, "route_turn_brake_mps2", self.route_turn_brake_mps2, 0.0, 100.0)
        if self.reward_scheme == "navigated_distance":
            self._check_navigated_distance(o)
        if self.integrity == "off":
            for name, on in (
                ("integrity_penalty", self.integrity_penalty > 0.0),
                ("obs_protection_level", self.obs_protection_level),
            ):
                if on:
                    raise ValueError(
                        f"{o}.{name} needs integrity='raim' or 'fde' (protection levels), got "
                        f"integrity='off'"
                    )

    def _check_navigated_distance(self, o: str) -> None:
        """``reward_scheme="navigated_distance"`` has no per-step terms: refuse their weights."""
        if self.nav_reward != "error":
            raise ValueError(
                f"{o}.nav_reward must be 'error' with reward_scheme='navigated_distance' (the "
                f"score weights each metre by the true error), got {self.nav_reward!r}"
            )
        for name in PER_STEP_REWARD_FIELDS:
            value = getattr(self, name)
            if value != 0.0:
                raise ValueError(
                    f"{o}.{name} is a per-step reward weight of reward_scheme='per_step'; "
                    f"reward_scheme='navigated_distance' has no per-step terms (a per-step "
                    f"term pays for a short trip): set it to 0 (urban_canyon_v1 does), got "
                    f"{value!r}"
                )

    @property
    def obs_dim(self) -> int:
        """Length of one agent's observation vector: ``20 + 2 obs_sky_azimuths + 4 K``, plus 2
        with ``obs_protection_level``, plus ``2 obs_sky_azimuths`` with
        ``obs_satellite_sectors``, plus 3 with ``obs_true_error``, plus ``n_uavs`` with
        ``obs_agent_index``."""
        return self.obs_base_dim + self.obs_extra_dim

    @property
    def obs_base_dim(self) -> int:
        """Entries before the optional blocks: ``20 + 2 obs_sky_azimuths + 4 K``."""
        return 20 + 2 * self.obs_sky_azimuths + 4 * self.obs_neighbours

    @property
    def obs_extra_dim(self) -> int:
        """Entries of the optional blocks appended after the base ones: 2 with
        ``obs_protection_level``, ``2 obs_sky_azimuths`` with ``obs_satellite_sectors``, 3
        with ``obs_true_error``, ``n_uavs`` with ``obs_agent_index``."""
        pl = 2 if self.obs_protection_level else 0
        sectors = 2 * self.obs_sky_azimuths if self.obs_satellite_sectors else 0
        index = self.n_uavs if self.obs_agent_index else 0
        return pl + sectors + (3 if self.obs_true_error else 0) + index

    @property
    def max_cycles(self) -> int:
        """``max_steps`` under its conventional PettingZoo name (read-only alias)."""
        return self.max_steps

    def episode_horizon_s(self) -> float:
        """GNSS time an episode spans after its start, ``max_steps * dt_s`` [s] (what a
        RINEX sky, ``constellation="rinex:..."``, must cover)."""
        try:
            return float(int(self.max_steps) * self.dt_s)
        except (TypeError, ValueError):  # a bad max_steps is reported by its own check
            return 0.0

    @property
    def worst_episode_penalty(self) -> float:
        """The most a whole episode without a crash can lose to the per-step penalties.

        ``max_steps * (nav_reward_weight * nav_reward_cap_m / nav_reward_scale_m +
        separation_penalty + contact_penalty + integrity_penalty)``: every step at the capped
        navigation error, too close to another UAV, out of contact and without integrity.
        (The progress term is left out: summed over an episode it is the net decrease of the
        remaining route, which crashing does not improve.) The defaults keep
        ``collision_penalty`` above it.
        """
        per_step = (
            self.nav_reward_weight * self.nav_reward_cap_m / self.nav_reward_scale_m
            + self.separation_penalty
            + self.contact_penalty
            + self.integrity_penalty
        )
        return float(self.max_steps * per_step)

    @property
    def state_dim(self) -> int:
        """Length of the global state vector: ``13 N + 4``."""
        return 13 * self.n_uavs + 4


@dataclass(frozen=True)
class ExperimentalSetting:
    """One entry of a list of experimental settings (:data:`EXPERIMENTAL_SETTINGS`, and the
    trainer's :data:`coopnav_env.training.config.EXPERIMENTAL_SETTINGS`).

    Parameters
    ----------
    settings : str
        The settings class the field belongs to: ``"UrbanCanyonConfig"`` (this module) in the
        environment's list, ``"MARLSettings"``
        (:class:`coopnav_env.agents.marl_nets.MARLSettings`, the ``torchrl:`` section of a
        training config) in the trainer's.
    name : str
        The field.
    off : object
        The value that leaves the setting off; the field's default is this value.
    what : str
        What it does when on, in one line.
    """

    settings: str
    name: str
    off: Any
    what: str


#: The environment's experimental settings: switches kept so that the studies that used them
#: (and any policy trained with them) still run, but not part of the supported surface. Each
#: may change or be removed in a later release without a deprecation period; its default
#: leaves it off. The environment's page (:mod:`coopnav_env.urban_canyon_v0`) and each
#: field's docstring point here.
EXPERIMENTAL_SETTINGS: tuple[ExperimentalSetting, ...] = (
    ExperimentalSetting(
        "UrbanCanyonConfig",
        "obs_true_error",
        False,
        "privileged diagnostic: 3 observation entries with the true error of the estimate "
        "(no receiver knows it)",
    ),
)


#: Settings that were removed, with what they did: constructing an environment with one raises
#: a ``ValueError`` that says so (not the "unknown argument" of a typo).
REMOVED_SETTINGS: dict[str, str] = {
    "obs_lookahead": (
        "its 4 observation entries (the satellites the city model predicted in line of sight "
        "15 m and 30 m ahead along the route) helped no policy that was trained with them"
    ),
    "obs_candidate_sky": (
        "its 10 observation entries (the satellites the receiver would use at five candidate "
        "positions) helped no policy that was trained with them"
    ),
}


def config_field_names() -> list[str]:
    """Names of every :class:`UrbanCanyonConfig` field, in declaration order."""
    return [f.name for f in fields(UrbanCanyonConfig)]


def make_config(config: UrbanCanyonConfig | None = None, **overrides: Any) -> UrbanCanyonConfig:
    """Build (or update) a config from keyword arguments, rejecting unknown names.

    Parameters
    ----------
    config : UrbanCanyonConfig, optional
        Starting point; default ``UrbanCanyonConfig()``.
    **overrides
        Field values. ``max_cycles`` is an alias of ``max_steps`` (PettingZoo's name).
        ``preset=NAME`` starts from a named preset (:data:`PRESETS`; the other overrides go
        on top), so that a training config or a command line can name one:
        ``--env-set preset=urban_nlos_3dma``.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the valid ones), a bad value, an unknown
        preset, or ``max_cycles`` and ``max_steps`` both given with different values.
    """
    if config is not None and not isinstance(config, UrbanCanyonConfig):
        raise ValueError(f"config must be an UrbanCanyonConfig or None, got {config!r}")
    if "preset" in overrides:
        overrides = dict(overrides)
        name = overrides.pop("preset")
        if name is not None:
            if not isinstance(name, str) or name not in PRESETS:
                raise ValueError(f"unknown preset {name!r}; presets are {sorted(PRESETS)}")
            overrides = {**PRESETS[name], **overrides}
    if "max_cycles" in overrides:
        overrides = dict(overrides)
        cycles = overrides.pop("max_cycles")
        if "max_steps" in overrides and overrides["max_steps"] != cycles:
            raise ValueError(
                f"max_cycles is an alias of max_steps: give one of them, or the same value "
                f"(got max_cycles={cycles!r}, max_steps={overrides['max_steps']!r})"
            )
        overrides["max_steps"] = cycles
        try:
            return make_config(config, **overrides)
        except ValueError as exc:
            if "max_steps must" not in str(exc):
                raise
            raise ValueError(f"{exc} (given as max_cycles, the alias of max_steps)") from None
    removed = sorted(set(overrides) & set(REMOVED_SETTINGS))
    if removed:
        raise ValueError(
            "; ".join(f"{name} was removed: {REMOVED_SETTINGS[name]}" for name in removed)
            + ". Drop the setting (a policy trained with it cannot be flown any more)"
        )
    valid = config_field_names()
    unknown = sorted(set(overrides) - set(valid))
    if unknown:
        raise ValueError(
            f"unknown urban_canyon argument(s) {unknown}; valid arguments are "
            f"render_mode, config, preset, {', '.join(valid)} (and max_cycles, an alias of "
            "max_steps)"
        )
    base = config if config is not None else UrbanCanyonConfig()
    return replace(base, **overrides) if overrides else base


#: Named settings on top of the defaults (:func:`preset_config`).
#:
#: ``"urban_nlos"``: realistic urban reception. Half of the satellites a building blocks are still
#: received through a reflection (``nlos_probability=0.5``), with a positive range bias of ``3 m +
#: Exp(30 m)`` (NLOS delays in street canyons are typically metres to a hundred metres; the
#: defaults, 1 m + Exp(15 m), are milder), and the navigation defends itself with residual RAIM
#: and fault detection and exclusion at every fix (``integrity="fde"``, false-alarm probability
#: 1e-3 per test, integrity risk 1e-7, 30 m horizontal alert limit), identifying among positive
#: residuals only (``integrity_fault_sign="positive"``: NLOS delays are positive; with many of
#: them in view, a two-sided choice excludes good measurements). The protection levels and FDE
#: figures are in the infos (``hpl_m``, ``vpl_m``, ``integrity_status``, ``fault_detected``,
#: ``fde_excluded``); the observation and the reward are those of the defaults unless
#: ``obs_protection_level`` / ``integrity_penalty`` are also given.
PRESETS: dict[str, dict[str, Any]] = {
    "urban_nlos": {
        "nlos_probability": 0.5,
        "nlos_bias_mean_m": 30.0,
        "nlos_bias_floor_m": 3.0,
        "integrity": "fde",
        "integrity_fault_sign": "positive",
        "integrity_p_fa": 1e-3,
        "integrity_risk": 1e-7,
        "alert_limit_m": 30.0,
    },
}
#: ``"urban_nlos_3dma"``: the reception and FDE of ``"urban_nlos"``, plus 3D-mapping-aided NLOS
#: exclusion (``nlos_exclusion="map"``, :mod:`coopnav_env.sim.map_aided`): each UAV does not use
#: the satellites the city model predicts blocked within 2 sigma (at most 10 m) of the position
#: it believes it is at; FDE deals with the NLOS rows the prediction lets through. With fewer
#: satellites per fix the geometry is weaker, so the fix gate is tighter: ``max_fix_sigma_m=15``
#: (default 30) rejects fixes whose own predicted 3-D sigma exceeds 15 m. Such a fix is honest
#: (its covariance says how imprecise it is) but often tens of metres off, and once used it
#: moves the position the next epoch's prediction is made at. Far fewer wrong fixes for fewer
#: valid ones (``studies/nlos_defences`` measures both presets side by side, and the gate's
#: share of the effect). The infos add ``n_map_excluded``.
PRESETS["urban_nlos_3dma"] = {
    **PRESETS["urban_nlos"],
    "nlos_exclusion": "map",
    "max_fix_sigma_m": 15.0,
}


def preset_config(name: str, **overrides: Any) -> UrbanCanyonConfig:
    """The config of a named preset (:data:`PRESETS`) with ``overrides`` on top.

    Example: ``urban_canyon_v0.parallel_env(config=preset_config("urban_nlos", n_uavs=8))``.

    Raises
    ------
    ValueError
        For an unknown preset (the message lists them) or a bad override.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; presets are {sorted(PRESETS)}")
    return make_config(**{**PRESETS[name], **overrides})
