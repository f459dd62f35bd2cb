"""Hand-written swarm policies for ``urban_canyon_v0``: one column policy with named settings,
and a waypoint follower.

:class:`ColumnPolicy` flies the street network to the goal as a *column* (a line formation
along the street centre line, ``spacing_m`` between slots), which keeps every UAV far from
the walls and in relative-sensing range of its neighbours. It uses what a real swarm would
have on board: the city map and the goal (from the environment's world, planned once per
episode), and each UAV's own observation: its *estimated* position and velocity, its sky
openness, its range sensor and its neighbours. It never reads the true positions.

Its settings say how the column flies: how far apart its UAVs are en route and at the goal,
at what altitude (the start altitude, or near the top of the altitude band, where more of
the sky clears the roofs), whether each UAV shifts across the street toward the open side of
the sky, whether a wall guard keeps it off walls its range sensor sees, and which of the
equally short street routes it takes. :data:`COLUMN_PRESETS` names useful
combinations, each by what it does; :func:`column_policy` makes one, with options on top,
and :func:`coopnav_env.agents.make_policy` accepts the same names:

======================  ===========================================================================
preset                  the column
======================  ===========================================================================
``column``              7 m apart at 7 m/s, at the start altitude, on the street centre line:
                        ignores navigation quality
``sky_column``          7 m apart; climbs to 2 m below the top of the altitude band, shifts each
                        UAV up to 4 m away from the higher skyline, and waits for a UAV that
                        loses contact
``stretched_column``    20 m apart en route, closing to 6 m over the last 80 m; shifts up to
                        6 m, 0.5 m below the band's top, waits for contact
``wide_column``         45 m apart, opening ahead of the start (the tail holds) and closing to
                        6 m over the last 4 spacings; shifts up to 6 m, 0.5 m below the top,
                        waits for contact
``high_wide_column``    ``wide_column`` 60 m apart at 10 m/s whose altitude target lies 10 m
                        above the altitude band (``ceiling_margin_m=-10``): it climbs at once
                        and holds the band's top whatever its estimated altitude reads
``guarded_column``      ``wide_column`` with a wall guard (8 m, 4/s) and soft slot tracking
                        (gain 0.2/s), for degraded navigation
``ceiling_column``      ``guarded_column`` whose altitude target lies 10 m above the band
                        (``ceiling_margin_m=-10``): it climbs at once and holds the band's top
``best_sky_route``      ``ceiling_column`` on the equally short street route with the fewest
                        points of poor predicted satellite geometry (``route_choice="pdop_gt3"``)
======================  ===========================================================================

:data:`COLUMN_PRESETS` holds each preset's full settings. The earlier names
(:data:`COLUMN_ALIASES`: ``formation``, ``sky``, ``spread``, ``wide``, ``guarded``,
``ceiling``, ``skyroute``) are still accepted for one release, with a ``DeprecationWarning``
naming the new name; a policy made under an earlier name keeps it as its ``name`` (so that
reports say what was asked for).

:class:`WaypointPolicy` (``waypoint``) is simpler still: each UAV flies toward its next route
waypoint from its own observation only.

Route: the street grid is a Manhattan graph (every street spans the city), so the shortest
route from one street point to another has at most two turns
(:func:`coopnav_env.sim.route.street_route`, re-exported here with
:class:`~coopnav_env.sim.route.Polyline`). The column advances along it at
``cruise_speed_mps``, slows down before corners so that the turn stays inside the
intersection, and stops centred on the goal.

The classes of the earlier names (:class:`FormationPolicy`, :class:`SkySeekingPolicy`,
:class:`SpreadColumnPolicy`, :class:`WideColumnPolicy`, :class:`GuardedColumnPolicy`,
:class:`CeilingColumnPolicy`, :class:`SkyRoutePolicy`) remain for one release: each makes a
:class:`ColumnPolicy` with its preset and warns (``DeprecationWarning``).
"""

from __future__ import annotations

import inspect
import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from coopnav_env.envs.autopilot import pursuit_velocity
from coopnav_env.envs.observation_layout import obs_layout
from coopnav_env.nav import pdop
from coopnav_env.sim.file_city import FileCity
from coopnav_env.sim.route import Polyline, extend_route, street_route, street_routes

__all__ = [
    "COLUMN_ALIASES",
    "COLUMN_OPTIONS",
    "COLUMN_PRESETS",
    "FILE_CITY_FULL_TURN_DEG",
    "ROUTE_CHOICES",
    "SETPOINT_OPTIONS",
    "WAYPOINT_OPTIONS",
    "CeilingColumnPolicy",
    "ColumnPolicy",
    "Derived",
    "FormationPolicy",
    "GuardedColumnPolicy",
    "Polyline",
    "SetPointPolicy",
    "SkyRoutePolicy",
    "SkySeekingPolicy",
    "SpreadColumnPolicy",
    "WaypointPolicy",
    "WideColumnPolicy",
    "column_policy",
    "poor_geometry_share",
    "setpoint_policy",
    "street_route",
    "waypoint_policy",
]


FILE_CITY_FULL_TURN_DEG: float = 60.0
"""The turn [deg] from which a vertex of a file city's route is a full corner for the column
(``ColumnPolicy(full_turn_deg="auto")``); a smaller bend slows it less."""


def _world_of(env: Any) -> Any:
    base = getattr(env, "unwrapped", env)
    world = getattr(base, "world", None)
    config = getattr(base, "config", None)
    if world is None or config is None or not hasattr(config, "obs_sky_azimuths"):
        raise ValueError(
            "the column and waypoint heuristics need an urban_canyon_v0 environment (a world "
            f"with a city map and a goal); got {type(base).__name__}"
        )
    frame = getattr(config, "action_frame", "velocity")
    if frame != "velocity":
        raise ValueError(
            "the column and waypoint heuristics command velocities: they need "
            f"action_frame='velocity', got action_frame={frame!r}"
        )
    return base


def _number(
    name: str,
    value: Any,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    unit: str = "",
) -> float:
    """``value`` as a float, or ValueError naming it unless it is a finite number in the range
    ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``)."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    x = float(value) if ok else math.nan
    if not (math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi):
        left = "(" if lo_open else "["
        if math.isfinite(hi):
            where = f"in {left}{lo:g}, {hi:g}]"
        else:
            where = f"{'>' if lo_open else '>='} {lo:g}"
        raise ValueError(f"{name} must be {where}{unit}, got {value!r}")
    return x


ROUTE_CHOICES: tuple[str, ...] = ("first", "pdop_gt3")
"""Values of :class:`ColumnPolicy`'s ``route_choice``."""

PDOP_CAP = 30.0
"""PDOP counted where the satellites predicted in line of sight cannot fix a position."""


def poor_geometry_share(
    world: Any, route_xy_m: np.ndarray, altitude_m: float, *, step_m: float = 5.0
) -> float:
    """Share of the points along a route where the predicted satellite geometry is poor.

    Points every ``step_m`` along the route (from its start, at ``altitude_m`` clamped to the
    flight band); at each, the satellites the city map predicts in line of sight
    (:meth:`coopnav_env.sim.scenario.UrbanWorld.map_line_of_sight`, at the world's current
    time) and their PDOP (:func:`coopnav_env.nav.pdop`, one receiver clock per
    constellation; :data:`PDOP_CAP` where they are too few to fix). Returns the share of
    points whose PDOP is above 3. On board only: the map, the satellites' directions, the
    route; no true position.

    Parameters
    ----------
    world : coopnav_env.sim.scenario.UrbanWorld
        The world at planning time.
    route_xy_m : ndarray, shape (k, 2)
        The route's waypoints, East/North [m].
    altitude_m : float
        Altitude the satellites are predicted at [m].
    step_m : float, default 5.0
        Distance between the points, > 0 [m].
    """
    if not (math.isfinite(step_m) and step_m > 0.0):
        raise ValueError(f"step_m must be finite and > 0 [m], got {step_m!r}")
    kin = world.config.kinematics
    z = float(np.clip(altitude_m, float(kin.altitude_min_m), float(kin.altitude_max_m)))
    route = np.asarray(route_xy_m, dtype=float).reshape(-1, 2)
    if route.shape[0] < 2:
        route = np.vstack([route, route + np.array([0.0, 1e-3])])
    path = Polyline(route)
    s = np.arange(0.0, path.length + 1e-9, step_m)
    xy = path.point(s)
    los = world.map_line_of_sight(np.column_stack([xy, np.full(len(xy), z)]))
    sky = world._sky(world.t_s)
    az, el = np.radians(sky.az), np.radians(sky.el)
    unit = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)
    system = np.asarray(sky.system)
    dop = np.array([min(pdop(unit[use], system[use]), PDOP_CAP) for use in los])
    return float((dop > 3.0).mean())


@dataclass(frozen=True)
class Derived:
    """A setting of a preset computed from the column's other settings when it is made.

    ``rule(settings, n_uavs)`` gets the column's settings (``spacing_m`` and
    ``goal_spacing_m`` already resolved to floats) and the number of UAVs, and returns the
    value. An option given explicitly always replaces it.
    """

    rule: Callable[[Mapping[str, Any], int], Any]
    text: str

    def __repr__(self) -> str:
        return f"Derived({self.text!r})"


class ColumnPolicy:
    """The swarm flies its street route to the goal as a column (see the module doc).

    Every option has a default, which together fly the plain ``column``;
    :data:`COLUMN_PRESETS` names other combinations and :func:`column_policy` makes them.

    Parameters
    ----------
    env : urban_canyon_v0 ParallelEnv
    spacing_m : float, default 7.0
        Distance between consecutive UAVs of the column en route, > 0 [m] (a column of 5 at
        7 m spans 28 m and stops centred on the goal, inside the default 25 m goal radius).
    cruise_speed_mps : float, default 7.0
        Speed of the column on straight legs, > 0 [m/s] (at most the maximum speed).
    turn_speed_mps, brake_mps2 : float, default 2.0, 1.0
        Speed at a corner and deceleration used to approach it, > 0.
    gain_per_s : float, default 0.6
        Proportional gain from slot error (and altitude error) to velocity, > 0 [1/s].
    max_lag_m : float, default 10.0
        The column slows down when a UAV is farther than this behind its slot, > 0 [m].
    goal_spacing_m : float, optional
        Spacing at the goal, > 0 [m]; default ``spacing_m``. With a wider ``spacing_m`` the
        column flies stretched (its UAVs see different parts of the sky, which the
        cooperative solution pools) and closes up to this spacing over the last
        ``close_distance_m`` so that it fits the goal area.
    close_distance_m : float, default 60.0
        Distance before the end of the route over which the spacing closes, > 0 [m].
    open_distance_m : float or None, default None
        With a value (> 0 [m]), the column starts at ``goal_spacing_m`` and opens to
        ``spacing_m`` over the head's first ``open_distance_m`` of route, the leader going
        ahead while the tail holds (``(N - 1) (spacing_m - goal_spacing_m)`` keeps the last
        UAV still): a wide column then forms ahead of the start instead of sending its rear
        UAVs back along the route's backward extension, which in a dead end or at a wall is
        a crash. None (default) forms the column around the start at once.
    wall_margin_m : float or None, default None
        With a value in (0, 50] m, a wall guard: each UAV is pushed away from every wall its
        range sensor (the ``wall_distance`` field, true distances) puts closer than this, by
        ``wall_gain_per_s`` times the intrusion (m/s per m), on top of its slot tracking. The
        slots are tracked with the *estimated* position, which under degraded navigation
        (fixes rejected, dead reckoning drifting) can lead a UAV into a wall; the guard is
        what keeps it off. None (default): no guard.
    wall_gain_per_s : float, default 1.0
        Gain of the wall guard, in [0, 100] [1/s].
    route_max_turns : int, default 3
        Most turns of a candidate route, in [0, 8] (read when the route is chosen among the
        equally short ones).
    route_choice : str, default "first"
        Which of the equally short street routes to fly (planned at the first step from the
        estimated centre of the swarm): ``"first"`` the one of :func:`street_route`;
        ``"pdop_gt3"`` the one of :func:`street_routes` with the smallest share of points
        where the satellites the city map predicts in line of sight give a PDOP above 3
        (:func:`poor_geometry_share`, at the column's altitude). On board: the map, the
        satellites' directions and the estimated positions only. A subclass chooses other
        routes by overriding :meth:`choose_routes`.
    max_offset_m : float or None, default None
        With a value (>= 0 [m]), each UAV shifts across the street toward the open side of
        the sky, by at most this much from the centre line: the skylines to the left and
        right of its direction of travel (the ``skyline`` field of
        :func:`coopnav_env.envs.obs_layout`, a fraction of 90 deg, interpolated) give the
        shift ``-max_offset_m * tanh(4 (left - right))``, away from the higher side. None
        (default): the centre line.
    smoothing : float, default 0.7
        Low-pass factor of that lateral shift between steps, in [0, 1).
    ceiling_margin_m : float or None, default None
        With a value in [-50, 50] m, the column flies ``ceiling_margin_m`` below the top of
        the altitude band (never below the start altitude) instead of at the start altitude
        (None, default). The altitude is held by a proportional term on the *estimated*
        altitude; a negative margin puts the target above the band, so that the UAVs climb
        and stay at the band's top (the world clamps them there) whatever their estimated
        altitude reads.
    hold_contact : bool, default False
        The head of the column stops while any UAV has no neighbour in relative-sensing
        range, until contact is back.
    full_turn_deg : float, None or "auto", default "auto"
        How the column slows at a vertex of its route. With a value in (0, 180] [deg], a
        vertex is a full corner (``turn_speed_mps``) where the route turns by this angle or
        more, and a bend of a smaller angle ``a`` is taken at ``turn_speed_mps + (cruise -
        turn_speed_mps) (1 - a / full_turn_deg)`` (:func:`v_corner_at`); the A* routes of a
        file city bend at every angle. None: every vertex is a full corner. ``"auto"``: 60 deg
        on a file city's route, None on a grid's (whose routes turn at right angles).
    """

    name = "column"

    def __init__(
        self,
        env: Any,
        spacing_m: float = 7.0,
        cruise_speed_mps: float = 7.0,
        turn_speed_mps: float = 2.0,
        brake_mps2: float = 1.0,
        gain_per_s: float = 0.6,
        max_lag_m: float = 10.0,
        goal_spacing_m: float | None = None,
        close_distance_m: float = 60.0,
        open_distance_m: float | None = None,
        wall_margin_m: float | None = None,
        wall_gain_per_s: float = 1.0,
        route_max_turns: int = 3,
        route_choice: str = "first",
        max_offset_m: float | None = None,
        smoothing: float = 0.7,
        ceiling_margin_m: float | None = None,
        hold_contact: bool = False,
        full_turn_deg: float | str | None = "auto",
    ):
        given = {k: v for k, v in locals().items() if k not in ("self", "env", "__class__")}
        self.env = env
        self.base = _world_of(env)
        cfg = self.base.config
        self.cfg = cfg
        s = self._resolve(given, len(self.base.possible_agents))
        self.spacing_m = s["spacing_m"]
        self.goal_spacing_m = s["goal_spacing_m"]
        self.cruise_speed_mps = float(
            min(
                _number("cruise_speed_mps", s["cruise_speed_mps"], 0.0, lo_open=True, unit=" m/s"),
                cfg.kinematics.max_speed_mps,
            )
        )
        self.turn_speed_mps = _number(
            "turn_speed_mps", s["turn_speed_mps"], 0.0, lo_open=True, unit=" m/s"
        )
        self.brake_mps2 = _number("brake_mps2", s["brake_mps2"], 0.0, lo_open=True, unit=" m/s2")
        self.gain_per_s = _number("gain_per_s", s["gain_per_s"], 0.0, lo_open=True, unit=" 1/s")
        self.max_lag_m = _number("max_lag_m", s["max_lag_m"], 0.0, lo_open=True, unit=" m")
        self.close_distance_m = _number(
            "close_distance_m", s["close_distance_m"], 0.0, lo_open=True, unit=" m"
        )
        open_distance_m = s["open_distance_m"]
        if open_distance_m is not None and not (
            isinstance(open_distance_m, (int, float, np.integer, np.floating))
            and not isinstance(open_distance_m, bool)
            and 0.0 < float(open_distance_m) < math.inf
        ):
            raise ValueError(f"open_distance_m must be > 0 m or None, got {open_distance_m!r}")
        self.open_distance_m = None if open_distance_m is None else float(open_distance_m)
        wall_margin_m = s["wall_margin_m"]
        self.wall_margin_m = (
            None
            if wall_margin_m is None
            else _number("wall_margin_m", wall_margin_m, 0.0, 50.0, lo_open=True, unit=" m")
        )
        self.wall_gain_per_s = _number(
            "wall_gain_per_s", s["wall_gain_per_s"], 0.0, 100.0, unit=" 1/s"
        )
        self._set_routes(s)
        max_offset_m = s["max_offset_m"]
        self.max_offset_m = (
            None
            if max_offset_m is None
            else _number("max_offset_m", max_offset_m, 0.0, 50.0, unit=" m")
        )
        smoothing = _number("smoothing", s["smoothing"], 0.0, 1.0)
        if smoothing >= 1.0:
            raise ValueError(f"smoothing must be in [0, 1), got {s['smoothing']!r}")
        self.smoothing = smoothing
        margin = s["ceiling_margin_m"]
        self.ceiling_margin_m = (
            None if margin is None else _number("ceiling_margin_m", margin, -50.0, 50.0, unit=" m")
        )
        if not isinstance(s["hold_contact"], (bool, np.bool_)):
            raise ValueError(f"hold_contact must be True or False, got {s['hold_contact']!r}")
        self.hold_contact = bool(s["hold_contact"])
        full_turn = s["full_turn_deg"]
        if full_turn is not None and full_turn != "auto":
            full_turn = _number("full_turn_deg", full_turn, 0.0, 180.0, lo_open=True, unit=" deg")
        self.full_turn_deg = full_turn
        self._full_turn_now: float | None = None  # full_turn_deg resolved for the route flown
        self._index = {a: i for i, a in enumerate(self.base.possible_agents)}
        self.layout = obs_layout(cfg)
        self._walls = self.layout["wall_distance"]
        az = np.radians(np.arange(self._walls.size) * 360.0 / self._walls.size)
        self._wall_dirs = np.stack([np.sin(az), np.cos(az)], axis=1)  # (A, 2) East, North
        self._position = self.layout["position_to_goal"]
        self._sky = self.layout["skyline"].slice
        self._present = self.layout.neighbour_present_indices()
        self._path: Polyline | None = None
        self._paths: list[Polyline] = []  # one per sub-column (one without a split)
        self._shifts: np.ndarray | None = None  # learned slot shifts (set_slot_shifts)
        self._offset = np.zeros(len(self._index))  # lateral shifts toward open sky

    @staticmethod
    def _resolve(given: dict[str, Any], n_uavs: int) -> dict[str, Any]:
        """The settings with the spacings checked and every :class:`Derived` value computed."""
        s = dict(given)
        s["spacing_m"] = _number("spacing_m", s["spacing_m"], 0.0, lo_open=True, unit=" m")
        goal = s["goal_spacing_m"]
        s["goal_spacing_m"] = (
            s["spacing_m"]
            if goal is None
            else _number("goal_spacing_m", goal, 0.0, lo_open=True, unit=" m")
        )
        for key, value in given.items():
            if isinstance(value, Derived):
                s[key] = value.rule(s, n_uavs)
        return s

    def _set_routes(self, s: Mapping[str, Any]) -> None:
        """Check and keep the route settings (``route_*``)."""
        route_max_turns = s["route_max_turns"]
        route_choice = s["route_choice"]
        if isinstance(route_max_turns, bool) or not isinstance(route_max_turns, (int, np.integer)):
            raise ValueError(f"route_max_turns must be an int in [0, 8], got {route_max_turns!r}")
        if not 0 <= route_max_turns <= 8:
            raise ValueError(f"route_max_turns must be in [0, 8], got {route_max_turns}")
        self.route_max_turns = int(route_max_turns)
        if route_choice not in ROUTE_CHOICES:
            raise ValueError(
                f"route_choice must be one of {list(ROUTE_CHOICES)}, got {route_choice!r}"
            )
        self.route_choice = route_choice
        self.route_candidates: list[np.ndarray] = []  # the routes of the last plan
        self.route_chosen = 0  # index of the flown one among them

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore a pickled column, also one pickled before the settings ``max_offset_m``,
        ``ceiling_margin_m`` and ``hold_contact`` existed (the sky-seeking columns had the
        first two and held contact)."""
        sky = "max_offset_m" in state
        state.setdefault("max_offset_m", None)
        state.setdefault("ceiling_margin_m", None)
        state.setdefault("smoothing", 0.7)
        state.setdefault("hold_contact", sky)
        state.setdefault("full_turn_deg", None)  # pickled before bends: every vertex a corner
        state.setdefault("_full_turn_now", None)
        if "_offset" not in state and "_index" in state:
            state["_offset"] = np.zeros(len(state["_index"]))
        self.__dict__.update(state)

    # -- altitude, lateral shift, contact ---------------------------------------------------

    def _altitude_m(self) -> float:
        if self.ceiling_margin_m is None:
            return float(self.cfg.start_altitude_m)
        kin = self.cfg.kinematics
        return float(max(kin.altitude_max_m - self.ceiling_margin_m, self.cfg.start_altitude_m))

    def _sky_at(self, sky: np.ndarray, az_deg: np.ndarray) -> np.ndarray:
        """Skyline (fraction of 90 deg) per UAV at azimuths ``az_deg``, circular interpolation."""
        a = sky.shape[1]
        pos = np.mod(az_deg, 360.0) / (360.0 / a)
        k0 = np.floor(pos).astype(int) % a
        k1 = (k0 + 1) % a
        w = pos - np.floor(pos)
        rows = np.arange(sky.shape[0])
        return (1.0 - w) * sky[rows, k0] + w * sky[rows, k1]

    def _lateral_offsets_m(self, obs: np.ndarray, tangent: np.ndarray) -> np.ndarray:
        if self.max_offset_m is None:
            return np.zeros(obs.shape[0])
        sky = obs[:, self._sky]
        az_travel = np.degrees(np.arctan2(tangent[:, 0], tangent[:, 1]))  # from North, cw
        left = self._sky_at(sky, az_travel - 90.0)
        right = self._sky_at(sky, az_travel + 90.0)
        want = -self.max_offset_m * np.tanh(4.0 * (left - right))
        idx = self._cur_idx
        new = self.smoothing * self._offset[idx] + (1.0 - self.smoothing) * want
        self._offset[idx] = new
        return new

    def _contact_factor(self, obs: np.ndarray) -> float:
        if not self.hold_contact or self._present.size == 0 or obs.shape[0] < 2:
            return 1.0
        flags = obs[:, self._present]
        return 0.0 if np.any(flags.max(axis=1) < 0.5) else 1.0

    # -- protocol -------------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        """Forget the route (planned at the first :meth:`act` of the episode) and the
        lateral shifts."""
        self._path = None
        self._offset = np.zeros(len(self._index))

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Velocity commands that keep each UAV on its slot of the column."""
        agents = list(observations)
        if not agents:
            return {}
        base = self.base
        world = base.world
        city = world.city
        goal = np.asarray(world.goal_enu_m, dtype=float)
        vmax = float(self.cfg.kinematics.max_speed_mps)
        idx = np.array([self._index[a] for a in agents])
        obs = np.stack([np.asarray(observations[a], dtype=np.float64) for a in agents])
        est = goal + self._position.decode(obs)  # estimated positions, never the truth
        if self._path is None or self._n != len(self._index):
            self._plan(est, idx, city, goal)
        slot = self._slot[idx]
        self._cur_idx = idx
        groups = self._groups_of(idx)

        # progress of every UAV along its route (window around its last value)
        s_prev = self._s[idx]
        s = self._on_paths(groups, "project", est[:, :2], s_prev - 20.0, s_prev + 40.0)
        self._s[idx] = s

        # advance the head of the column: cruise, brake before corners, wait for laggards
        spacing = self._spacing_now()
        shift = self._slot_shift(idx)  # (along, lateral, up) per live UAV; zeros by default
        off = self._s_offset[groups]  # the sub-columns' arc lengths relative to the first's
        slot_s = self._head - slot * spacing + shift[:, 0] + off
        ref = np.minimum(np.maximum(slot_s, 0.0), s)
        v_corner = self._on_paths(
            groups, "corner", ref, self.turn_speed_mps, self.brake_mps2, self.cruise_speed_mps
        )
        speed = float(np.min(v_corner))
        lag = float(np.max(slot_s - s))
        if lag > self.max_lag_m:
            speed *= max(0.0, 1.0 - (lag - self.max_lag_m) / self.max_lag_m)
        speed *= self._contact_factor(obs)
        self._head = min(self._head + speed * float(self.cfg.dt_s), self._head_end)
        if self._head >= self._head_end:
            speed = 0.0

        slot_s = self._head - slot * self._spacing_now() + shift[:, 0] + off
        tangent = self._on_paths(groups, "tangent", slot_s)
        normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)  # left of travel
        lateral = self._lateral_offsets_m(obs, tangent) + shift[:, 1]
        target_xy = self._on_paths(groups, "point", slot_s) + normal * lateral[:, None]
        v = np.zeros((len(agents), 3))
        v[:, :2] = tangent * speed + self.gain_per_s * (target_xy - est[:, :2])
        v[:, 2] = self.gain_per_s * (self._altitude_m() + shift[:, 2] - est[:, 2])
        h = np.linalg.norm(v[:, :2], axis=1)
        cap = self._on_paths(groups, "corner", s, self.turn_speed_mps, self.brake_mps2, vmax)
        v[:, :2] *= np.minimum(1.0, cap / np.maximum(h, 1e-9))[:, None]
        if self.wall_margin_m is not None:
            # wall guard, from the range sensor (true distances, unlike the estimated position
            # the slots are tracked with): push away from every wall closer than the margin
            near = np.maximum(self.wall_margin_m - self._walls.decode(obs), 0.0)  # (n, A)
            v[:, :2] -= self.wall_gain_per_s * near @ self._wall_dirs
        cmd = np.clip(v / vmax, -1.0, 1.0).astype(np.float32)
        return {a: cmd[i] for i, a in enumerate(agents)}

    def guard_delta(self, obs: np.ndarray, delta: np.ndarray, time_s: float = 2.0) -> np.ndarray:
        """``delta`` (N, 3), a change to the column's commands, limited so that it does not
        close on any wall the range sensor sees faster than the wall guard allows.

        ``obs`` (N, obs_dim) holds the observations of the same UAVs, row for row. The wall
        guard of :meth:`act` pushes a UAV away from walls closer than ``wall_margin_m``; a
        residual or a planner's offset added to the command afterwards can cancel that push
        or, at several metres per second, carry a UAV from beyond the margin into the wall
        within a step, and under degraded navigation that is what flies UAVs into walls.
        Here the horizontal part of ``delta`` toward the wall of each range-sensor sector
        (its azimuth; distance ``d``) is cut to at most ``(d - wall_margin_m) / time_s``
        [m/s] (in command units, divided by the maximum speed): nothing toward a wall inside
        the margin, and toward a wall beyond it no faster than reaches the margin in
        ``time_s`` seconds (a sector that sees no wall within the sensor's range limits
        nothing). Two passes, so that a corner's two walls are both respected;
        the vertical part and every part along or away from walls are kept. Uses only
        on-board data (the range sensor, true distances). Without a wall margin
        (``wall_margin_m=None``) ``delta`` is returned unchanged.
        """
        delta = np.array(delta, dtype=np.float64, copy=True)
        obs = np.asarray(obs, dtype=np.float64)
        if delta.ndim != 2 or delta.shape[1] != 3 or obs.shape[0] != delta.shape[0]:
            raise ValueError(
                f"guard_delta needs delta (N, 3) and obs (N, obs_dim) with the same N, got "
                f"{delta.shape} and {obs.shape}"
            )
        if not (float(time_s) > 0.0):
            raise ValueError(f"guard_delta time_s must be > 0 [s], got {time_s!r}")
        if self.wall_margin_m is None:
            return delta
        vmax = float(self.cfg.kinematics.max_speed_mps)
        dist = self._walls.decode(obs)
        allowed = np.maximum(dist - self.wall_margin_m, 0.0) / (float(time_s) * vmax)
        # command units toward each sector's wall; none where the sensor sees no wall
        allowed[dist >= self._walls.scale] = np.inf
        for _ in range(2):
            for k in range(self._wall_dirs.shape[0]):
                d = self._wall_dirs[k]
                excess = delta[:, :2] @ d - allowed[:, k]
                hit = excess > 0.0
                delta[hit, :2] -= excess[hit, None] * d
        return delta

    def set_slot_shifts(self, shifts_m: np.ndarray | None) -> None:
        """Move every UAV's slot by ``shifts_m`` (N, 3) [m] (along the route, to the left of
        travel, up) from the next :meth:`act` on; None removes the shifts.

        The hook a learned policy uses to shape the formation (``residual_mode: offset`` of
        the TorchRL backend): the column keeps planning the route and pacing, the learned
        policy decides where in the street each UAV sits. Altitudes stay inside the
        environment's band (the world clamps them).
        """
        if shifts_m is None:
            self._shifts = None
            return
        arr = np.asarray(shifts_m, dtype=np.float64)
        n = len(self._index)
        if arr.shape != (n, 3) or not np.all(np.isfinite(arr)):
            raise ValueError(f"slot shifts must be a finite ({n}, 3) array, got {arr.shape}")
        self._shifts = arr

    def _slot_shift(self, idx: np.ndarray) -> np.ndarray:
        if self._shifts is None:
            return np.zeros((idx.size, 3))
        return self._shifts[idx]

    def _spacing_now(self) -> float:
        """Slot spacing: ``spacing_m`` en route, closing linearly to ``goal_spacing_m`` over
        the last ``close_distance_m`` of the head's way to its end point; with
        ``open_distance_m`` set, the column also starts at ``goal_spacing_m`` and opens
        linearly to ``spacing_m`` over the head's first ``open_distance_m``."""
        if self.goal_spacing_m == self.spacing_m:
            return self.spacing_m
        w = min(max((self._head_end - self._head) / self.close_distance_m, 0.0), 1.0)
        if self.open_distance_m is not None:
            w = min(w, max((self._head - self._head0) / self.open_distance_m, 0.0))
        return self.goal_spacing_m + (self.spacing_m - self.goal_spacing_m) * w

    def choose_routes(
        self, city: Any, centre_xy_m: np.ndarray, goal_xy_m: np.ndarray
    ) -> list[np.ndarray]:
        """The routes of the episode, planned at its first :meth:`act` from the estimated
        centre of the swarm ``centre_xy_m`` (2,) to the goal ``goal_xy_m`` (2,) [m].

        Returns one route (waypoints ``(k, 2)``, East/North [m]): :func:`street_route`'s, or
        with ``route_choice="pdop_gt3"`` the equally short route of :func:`street_routes`
        with the smallest :func:`poor_geometry_share` (the first of those tied). Records the
        candidates in :attr:`route_candidates` and the index flown in :attr:`route_chosen`.

        A subclass may return two equally short routes: the column then flies split, slots
        0, 2, 4, ... (the leader's) on the first and 1, 3, ... on the second, at the same arc
        length.
        """
        if self.route_choice == "first":
            self.route_candidates, self.route_chosen = [], 0
            return [street_route(city, centre_xy_m, goal_xy_m)]
        routes = street_routes(city, centre_xy_m, goal_xy_m, self.route_max_turns)
        k = 0
        if len(routes) > 1:
            alt = self._altitude_m()
            share = np.array([poor_geometry_share(self.base.world, r, alt) for r in routes])
            k = int(np.argmax(-share))
        self.route_candidates, self.route_chosen = routes, k
        return [routes[k]]

    def _groups_of(self, idx: np.ndarray) -> np.ndarray:
        return self._group[idx]

    def _on_paths(self, groups: np.ndarray, op: str, *args: Any) -> np.ndarray:
        """Apply a path operation per UAV on its own sub-column's path.

        ``op``: ``project`` (xy, lo, hi), ``tangent`` (s), ``point`` (s) or ``corner`` (s,
        v_turn, brake, vmax: :func:`v_corner_at`, with the full turn of the route flown);
        array arguments are per UAV, row for row with ``groups``. One path (no split): one
        call on the whole arrays."""

        def call(path: Polyline, *a: Any) -> np.ndarray:
            if op == "corner":
                return v_corner_at(path, *a, full_turn_deg=self._full_turn_now)
            return getattr(path, op)(*a)

        if len(self._paths) == 1:
            return call(self._paths[0], *args)
        n = groups.size
        out: np.ndarray | None = None
        for g, path in enumerate(self._paths):
            m = groups == g
            if not m.any():
                continue
            sub = [x[m] if isinstance(x, np.ndarray) and x.shape[:1] == (n,) else x for x in args]
            r = call(path, *sub)
            if out is None:
                out = np.zeros((n, *r.shape[1:]))
            out[m] = r
        assert out is not None
        return out

    def _plan(self, est: np.ndarray, idx: np.ndarray, city: Any, goal: np.ndarray) -> None:
        n = len(self._index)
        self._n = n
        full_turn = self.full_turn_deg
        if full_turn == "auto":
            full_turn = FILE_CITY_FULL_TURN_DEG if isinstance(city, FileCity) else None
        self._full_turn_now = full_turn
        centre = est[:, :2].mean(axis=0)
        routes = self.choose_routes(city, centre, goal[:2])
        if len(routes) not in (1, 2):
            raise ValueError(f"choose_routes must return one or two routes, got {len(routes)}")
        wide = max(self.spacing_m, self.goal_spacing_m)
        back = (n + 1) * wide + 10.0
        fwd = (n - 1) * self.goal_spacing_m / 2.0 + 5.0
        self._paths = []
        s_goals = []
        for r in routes:
            path = Polyline(extend_route(r, back, fwd, city.extent_m))
            # arc length of the (snapped) goal on the extended path
            s_goals.append(float(path.project(r[-1:], np.zeros(1), np.full(1, path.length))[0]))
            self._paths.append(path)
        path = self._paths[0]
        s_goal = s_goals[0]
        self._s_offset = np.asarray(s_goals) - s_goal
        s0 = path.project(est[:, :2], np.zeros(len(idx)), np.full(len(idx), s_goal))
        order = np.argsort(-s0, kind="stable")  # the UAV farthest along leads
        slot = np.zeros(n)
        self._s = np.zeros(n)
        slot[idx[order]] = np.arange(len(idx))
        # sub-columns: slots alternate between the routes (the leader on the first)
        self._group = (slot.astype(np.int64) % len(routes)).astype(np.int64)
        if len(routes) > 1:
            g = self._group[idx]
            s0 = self._on_paths(
                g, "project", est[:, :2], np.zeros(len(idx)), np.full(len(idx), 1e9)
            )
            s0 = np.minimum(s0, np.asarray(s_goals)[g]) - self._s_offset[g]
        self._s[idx] = s0 + (self._s_offset[self._group[idx]] if len(routes) > 1 else 0.0)
        self._slot = slot
        self._head_end = min(s_goal + (n - 1) * self.goal_spacing_m / 2.0, path.length)
        for g in range(1, len(routes)):
            self._head_end = min(
                self._head_end,
                s_goals[g] + (n - 1) * self.goal_spacing_m / 2.0 - self._s_offset[g],
                self._paths[g].length - self._s_offset[g],
            )
        start = self.spacing_m if self.open_distance_m is None else self.goal_spacing_m
        self._head = float(np.mean(s0 + slot[idx] * start))  # spacing at the start
        self._head0 = self._head
        self._path = path


def v_corner_at(
    path: Polyline,
    s: np.ndarray,
    v_turn: float,
    brake: float,
    vmax: float,
    full_turn_deg: float | None = None,
) -> np.ndarray:
    """Speed limit before the corners ahead, at most ``vmax``.

    ``v_c + sqrt(2 brake (d - 3 m))`` at an arc length ``d`` before a vertex whose speed is
    ``v_c``, the smallest over the vertices ahead: the 3 m margin accounts for the step of
    travel before the next command (``dt = 1 s``). With ``full_turn_deg`` None every interior
    vertex is a corner, ``v_c = v_turn`` (then the next one binds). With a value, a vertex
    where the route turns by ``a >= full_turn_deg`` is a corner and a bend of ``a`` below it
    gets ``v_c = v_turn + (vmax - v_turn) (1 - a / full_turn_deg)``.
    """
    if full_turn_deg is None:
        d = path.distance_to_corner(np.maximum(s, 0.0))
        d = np.where(np.isfinite(d), np.maximum(d - 3.0, 0.0), 1e9)
        return np.minimum(vmax, v_turn + np.sqrt(2.0 * brake * d))
    s = np.maximum(np.asarray(s, dtype=float), 0.0)
    corners = path.s[1:-1]
    if corners.size == 0:
        return np.full(s.shape, float(vmax))
    cos_turn = np.clip(np.sum(path.seg_dir[:-1] * path.seg_dir[1:], axis=1), -1.0, 1.0)
    share = np.minimum(np.degrees(np.arccos(cos_turn)) / full_turn_deg, 1.0)
    v_c = v_turn + max(vmax - v_turn, 0.0) * (1.0 - share)
    ahead = corners[None, :] - s.reshape(-1, 1)
    ahead = np.where(ahead >= -1e-9, np.maximum(ahead - 3.0, 0.0), np.inf)
    v = np.min(v_c[None, :] + np.sqrt(2.0 * brake * ahead), axis=1)
    return np.minimum(vmax, v).reshape(s.shape)


def _tail_holds(s: Mapping[str, Any], n_uavs: int) -> float:
    return max(n_uavs - 1, 1) * max(s["spacing_m"] - s["goal_spacing_m"], 1.0)


_FOUR_SPACINGS = Derived(lambda s, n: 4.0 * s["spacing_m"], "4 x spacing_m")
_TAIL_HOLDS = Derived(
    _tail_holds, "(N - 1) x (spacing_m - goal_spacing_m), at least N - 1 m: the tail holds"
)

#: Named settings of :class:`ColumnPolicy`: each preset's full settings, on top of the
#: defaults of :class:`ColumnPolicy` (the table of the module doc says what each column does).
#: A :class:`Derived` value is computed from the other settings when the column is made, so
#: that it follows an option given on top: the wide columns close over 4 spacings and open
#: over ``(N - 1) (spacing_m - goal_spacing_m)`` whatever ``spacing_m`` is given. Options
#: given explicitly replace any value.
COLUMN_PRESETS: dict[str, dict[str, Any]] = {
    # the plain column: every option at its default (7 m apart at 7 m/s, start altitude)
    "column": {},
    "sky_column": {
        "max_offset_m": 4.0,
        "ceiling_margin_m": 2.0,
        "hold_contact": True,
    },
    "stretched_column": {
        "spacing_m": 20.0,
        "goal_spacing_m": 6.0,
        "close_distance_m": 80.0,
        "max_offset_m": 6.0,
        "ceiling_margin_m": 0.5,
        "hold_contact": True,
    },
    "wide_column": {
        "spacing_m": 45.0,
        "goal_spacing_m": 6.0,
        "close_distance_m": _FOUR_SPACINGS,
        "open_distance_m": _TAIL_HOLDS,
        "max_offset_m": 6.0,
        "ceiling_margin_m": 0.5,
        "hold_contact": True,
    },
    # wide_column 60 m apart at 10 m/s; its altitude target 10 m above the band's top, so that
    # it climbs at once and holds the top (the world clamps it there)
    "high_wide_column": {
        "spacing_m": 60.0,
        "cruise_speed_mps": 10.0,
        "goal_spacing_m": 6.0,
        "close_distance_m": _FOUR_SPACINGS,
        "open_distance_m": _TAIL_HOLDS,
        "max_offset_m": 6.0,
        "ceiling_margin_m": -10.0,
        "hold_contact": True,
    },
    "guarded_column": {
        "spacing_m": 45.0,
        "goal_spacing_m": 6.0,
        "close_distance_m": _FOUR_SPACINGS,
        "open_distance_m": _TAIL_HOLDS,
        "max_offset_m": 6.0,
        "ceiling_margin_m": 0.5,
        "hold_contact": True,
        "wall_margin_m": 8.0,
        "wall_gain_per_s": 4.0,
        "gain_per_s": 0.2,
    },
    "ceiling_column": {
        "spacing_m": 45.0,
        "goal_spacing_m": 6.0,
        "close_distance_m": _FOUR_SPACINGS,
        "open_distance_m": _TAIL_HOLDS,
        "max_offset_m": 6.0,
        "ceiling_margin_m": -10.0,
        "hold_contact": True,
        "wall_margin_m": 8.0,
        "wall_gain_per_s": 4.0,
        "gain_per_s": 0.2,
    },
    "best_sky_route": {
        "spacing_m": 45.0,
        "goal_spacing_m": 6.0,
        "close_distance_m": _FOUR_SPACINGS,
        "open_distance_m": _TAIL_HOLDS,
        "max_offset_m": 6.0,
        "ceiling_margin_m": -10.0,
        "hold_contact": True,
        "wall_margin_m": 8.0,
        "wall_gain_per_s": 4.0,
        "gain_per_s": 0.2,
        "route_choice": "pdop_gt3",
    },
}

#: Earlier names of the presets, accepted for one release wherever a preset name is
#: (``make_policy``, ``residual_base`` of a learned residual, ``name@option=...`` specs), with
#: a ``DeprecationWarning`` naming the new name.
COLUMN_ALIASES: dict[str, str] = {
    "formation": "column",
    "sky": "sky_column",
    "spread": "stretched_column",
    "wide": "wide_column",
    "guarded": "guarded_column",
    "ceiling": "ceiling_column",
    "skyroute": "best_sky_route",
}

COLUMN_OPTIONS: tuple[str, ...] = tuple(
    p for p in inspect.signature(ColumnPolicy.__init__).parameters if p not in ("self", "env")
)
"""The options of :class:`ColumnPolicy` (and so of every preset, after ``@``)."""


def _check_option_names(policy: str, options: Mapping[str, Any], allowed: tuple[str, ...]) -> None:
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise ValueError(
            f"unknown option(s) {', '.join(map(repr, unknown))} of policy {policy!r}; its "
            f"options are {', '.join(allowed)}"
        )


def column_policy(name: str, env: Any, **options: Any) -> ColumnPolicy:
    """The :class:`ColumnPolicy` of preset ``name`` (:data:`COLUMN_PRESETS`, or an earlier
    name of :data:`COLUMN_ALIASES`, which warns) for ``env``, with ``options`` on top; its
    ``name`` is ``name`` as given.

    Raises
    ------
    ValueError
        An unknown preset or option name (the message lists the valid ones), or a bad value
        (the message names it).
    """
    preset = COLUMN_ALIASES.get(name, name)
    if preset not in COLUMN_PRESETS:
        valid = [*COLUMN_PRESETS, *COLUMN_ALIASES]
        raise ValueError(f"unknown column preset {name!r}; presets are {', '.join(valid)}")
    if preset != name:
        warnings.warn(
            f"policy name {name!r} is deprecated and will be removed in the next release: use "
            f"{preset!r} (the same column)",
            DeprecationWarning,
            stacklevel=3,
        )
    _check_option_names(name, options, COLUMN_OPTIONS)
    policy = ColumnPolicy(env, **{**COLUMN_PRESETS[preset], **options})
    policy.name = name
    return policy


def _deprecated_column_class(old: str, preset: str, alias: str) -> type[ColumnPolicy]:
    def __init__(self: ColumnPolicy, env: Any, **options: Any) -> None:
        warnings.warn(
            f"{old} is deprecated: use coopnav_env.agents.heuristics.column_policy({preset!r}, "
            f"env, ...) or make_policy({preset!r}, env)",
            DeprecationWarning,
            stacklevel=2,
        )
        _check_option_names(alias, options, COLUMN_OPTIONS)
        ColumnPolicy.__init__(self, env, **{**COLUMN_PRESETS[preset], **options})

    doc = (
        f"Deprecated: :class:`ColumnPolicy` with the ``{preset}`` settings "
        f"(:data:`COLUMN_PRESETS`), policy name ``{alias}``; kept so that code and pickles "
        "that name this class keep working."
    )
    return type(old, (ColumnPolicy,), {"__init__": __init__, "__doc__": doc, "name": alias})


FormationPolicy = _deprecated_column_class("FormationPolicy", "column", "formation")
SkySeekingPolicy = _deprecated_column_class("SkySeekingPolicy", "sky_column", "sky")
SpreadColumnPolicy = _deprecated_column_class("SpreadColumnPolicy", "stretched_column", "spread")
WideColumnPolicy = _deprecated_column_class("WideColumnPolicy", "wide_column", "wide")
GuardedColumnPolicy = _deprecated_column_class("GuardedColumnPolicy", "guarded_column", "guarded")
CeilingColumnPolicy = _deprecated_column_class("CeilingColumnPolicy", "ceiling_column", "ceiling")
SkyRoutePolicy = _deprecated_column_class("SkyRoutePolicy", "best_sky_route", "skyroute")


class WaypointPolicy:
    """Each UAV flies toward its next route waypoint, from its own observation only.

    The simplest route follower: the horizontal command points at the next waypoint of the
    environment's street route (the ``next_waypoint`` field of
    :func:`coopnav_env.envs.obs_layout`, the waypoint minus the UAV's *estimated* position) at
    ``cruise_speed_mps``, slowing down within a few metres of it, and a proportional term holds
    ``altitude_m`` (from the estimated altitude, the ``altitude`` field). No map, no
    neighbours, no walls. ``coopnav train`` can start PPO from a behaviour-cloned copy of it
    (``pretrain`` in ``training/configs/sb3.yaml``).

    Parameters
    ----------
    env : urban_canyon_v0 ParallelEnv
    cruise_speed_mps : float, default 7.0
        Speed toward the waypoint, > 0 [m/s] (at most the maximum speed).
    altitude_m : float, optional
        Altitude to hold [m], inside the environment's altitude band
        (``kinematics.altitude_min_m`` to ``altitude_max_m``); default the environment's
        ``start_altitude_m``.
    gain_per_s : float, default 0.6
        Proportional gain on the distance to the waypoint and on the altitude error, > 0
        [1/s].
    """

    name = "waypoint"

    def __init__(
        self,
        env: Any,
        cruise_speed_mps: float = 7.0,
        altitude_m: float | None = None,
        gain_per_s: float = 0.6,
    ):
        base = _world_of(env)
        cfg = self.cfg = base.config
        kin = cfg.kinematics
        self.cruise_speed_mps = float(
            min(
                _number("cruise_speed_mps", cruise_speed_mps, 0.0, lo_open=True, unit=" m/s"),
                kin.max_speed_mps,
            )
        )
        self.altitude_m = (
            float(cfg.start_altitude_m)
            if altitude_m is None
            else _number(
                "altitude_m",
                altitude_m,
                float(kin.altitude_min_m),
                float(kin.altitude_max_m),
                unit=" m (the environment's altitude band)",
            )
        )
        self.gain_per_s = _number("gain_per_s", gain_per_s, 0.0, lo_open=True, unit=" 1/s")
        self.layout = obs_layout(cfg)
        self._waypoint = self.layout["next_waypoint"]
        self._altitude = self.layout["altitude"]

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: the policy has no state."""

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Velocity commands toward each UAV's next waypoint at the set altitude."""
        agents = list(observations)
        if not agents:
            return {}
        kin = self.cfg.kinematics
        obs = np.stack([np.asarray(observations[a], dtype=np.float64) for a in agents])
        to_wp = self._waypoint.decode(obs)
        alt = self._altitude.decode(obs)[:, 0]
        v = pursuit_velocity(to_wp, self.cruise_speed_mps, self.altitude_m - alt, self.gain_per_s)
        cmd = np.clip(v / kin.max_speed_mps, -1.0, 1.0).astype(np.float32)
        return {a: cmd[i] for i, a in enumerate(agents)}


WAYPOINT_OPTIONS: tuple[str, ...] = tuple(
    p for p in inspect.signature(WaypointPolicy.__init__).parameters if p not in ("self", "env")
)
"""The options of :class:`WaypointPolicy` (after ``waypoint@``)."""


def waypoint_policy(env: Any, **options: Any) -> WaypointPolicy:
    """A :class:`WaypointPolicy` for ``env``; an unknown option name raises ValueError listing
    the valid ones."""
    _check_option_names("waypoint", options, WAYPOINT_OPTIONS)
    return WaypointPolicy(env, **options)


class SetPointPolicy:
    """Fixed route-frame set-points for every UAV (``action_frame="route"`` only).

    Each UAV flies along its street route at ``speed_mps`` minus ``k * speed_step_mps`` (``k``
    its index in ``possible_agents``), ``offset_m`` to the left of the centre line, at
    ``altitude_m``; the environment's autopilot tracks them from the UAV's estimate. With
    ``speed_step_mps = 0`` every UAV is given the same set-points, so the swarm flies the
    route together (the `waypoint` follower at a set speed and altitude); with a step > 0 it
    strings out along the route, each UAV slower than the one before.

    Parameters
    ----------
    env : urban_canyon_v1 ParallelEnv with ``action_frame="route"``
    speed_mps : float, default 7.0
        Speed along the route of the first UAV, in [0, ``max_speed_mps``] [m/s].
    altitude_m : float, optional
        Altitude inside the band (default the environment's ``start_altitude_m``) [m].
    offset_m : float, default 0.0
        Offset across the street, in [-``route_offset_max_m``, ``route_offset_max_m``] [m].
    speed_step_mps : float, default 0.0
        How much slower each UAV flies than the one before, >= 0 [m/s]; every UAV's speed must
        stay >= 0.
    """

    name = "setpoints"

    def __init__(
        self,
        env: Any,
        speed_mps: float = 7.0,
        altitude_m: float | None = None,
        offset_m: float = 0.0,
        speed_step_mps: float = 0.0,
    ):
        base = getattr(env, "unwrapped", env)
        cfg = getattr(base, "config", None)
        frame = getattr(cfg, "action_frame", None)
        if frame != "route":
            raise ValueError(
                f"the setpoints policy needs action_frame='route', got action_frame={frame!r}"
            )
        kin = cfg.kinematics
        n = cfg.n_uavs
        v_max = float(kin.max_speed_mps)
        speed = _number("speed_mps", speed_mps, 0.0, v_max, unit=" m/s")
        step = _number("speed_step_mps", speed_step_mps, 0.0, unit=" m/s")
        if speed - (n - 1) * step < 0.0:
            raise ValueError(
                f"speed_step_mps must leave the last of {n} UAVs a speed >= 0: "
                f"{speed:g} - {n - 1} * {step:g} < 0, got speed_step_mps={speed_step_mps!r}"
            )
        lo, hi = float(kin.altitude_min_m), float(kin.altitude_max_m)
        alt = (
            float(cfg.start_altitude_m)
            if altitude_m is None
            else _number("altitude_m", altitude_m, lo, hi, unit=" m (the altitude band)")
        )
        w = float(cfg.route_offset_max_m)
        off = _number("offset_m", offset_m, -w, w, unit=" m (route_offset_max_m)")
        speeds = speed - step * np.arange(n)
        a = np.empty((n, 3), dtype=np.float32)
        a[:, 0] = 2.0 * speeds / v_max - 1.0
        a[:, 1] = off / w if w > 0 else 0.0
        a[:, 2] = 2.0 * (alt - lo) / (hi - lo) - 1.0
        self._action = {agent: a[i] for i, agent in enumerate(base.possible_agents)}

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: the policy has no state."""

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Each live UAV's set-points (copies)."""
        return {agent: self._action[agent].copy() for agent in observations}


SETPOINT_OPTIONS: tuple[str, ...] = tuple(
    p for p in inspect.signature(SetPointPolicy.__init__).parameters if p not in ("self", "env")
)
"""The options of :class:`SetPointPolicy` (after ``setpoints@``)."""


def setpoint_policy(env: Any, **options: Any) -> SetPointPolicy:
    """A :class:`SetPointPolicy` for ``env``; an unknown option name raises ValueError listing
    the valid ones."""
    _check_option_names("setpoints", options, SETPOINT_OPTIONS)
    return SetPointPolicy(env, **options)
