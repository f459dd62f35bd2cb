"""One epoch of the urban world: world -> measurements -> navigation solutions.

This module is the engine of the ``urban_canyon_v0`` environment without any PettingZoo: a
swarm of UAVs flies through a city from a start area to a goal area while the GNSS satellites
move overhead, and at every epoch each UAV measures pseudoranges to the satellites it can see,
relative positions to the UAVs in sensing range, and navigates standalone and cooperatively.

The flow of one epoch (:meth:`UrbanWorld.step`)
-----------------------------------------------
1. **Kinematics.** The velocity commands move the UAVs
   (:func:`~coopnav_env.sim.swarm.step_kinematics`: point masses, speed and acceleration
   limits, altitude band). The horizontal position is clamped to the city extent (a virtual
   fence; the velocity component pushing out is zeroed).
   A UAV whose swept sphere touches a building (:func:`~coopnav_env.sim.swarm.swept_collisions`)
   has *crashed*: it stays where it was at the start of the step with zero velocity, and the
   flag ``collided`` is set (the environment ends the episode). UAVs closer than
   ``min_separation_m`` are flagged (``separation_violation``); they do not bounce.
2. **Satellites.** The nominal GPS + BeiDou-3 constellation
   (:func:`~coopnav_env.gnss.default_constellation`) at ``t = t0 + k dt``; one step advances the
   GNSS epoch by the kinematic time step ``dt_s`` (default 1 s).
3. **Visibility.** Azimuth and elevation of every satellite at the geodetic origin give its ENU
   direction (the city spans a few hundred metres, where directions differ by micro-radians);
   a satellite is in line of sight of a UAV when it is above ``elevation_mask_deg`` and the
   ray toward it misses every building (:func:`~coopnav_env.sim.city.line_of_sight`).
   Optionally a blocked satellite is still received through a reflection with probability
   ``nlos_probability`` and a positive range bias (:func:`~coopnav_env.sim.city.draw_nlos`);
   the navigation does not know which measurements are NLOS. Optionally a receiver tracks only
   its ``max_sats`` highest satellites (:func:`~coopnav_env.gnss.select_highest`). Optionally
   (``nlos_exclusion="map"``) a UAV does not use the satellites that the city model predicts
   may be blocked around the position it believes it is at
   (:mod:`~coopnav_env.sim.map_aided`, 3D-mapping-aided NLOS exclusion).
4. **Measurements.** Pseudoranges by :func:`~coopnav_env.gnss.simulate_pseudoranges` (paper
   Eq. 1-8; the common clock/ephemeris/troposphere error is drawn once per satellite and
   shared by the swarm, and redrawn each epoch; the NLOS bias goes in ``extra_bias_m``);
   receiver clock biases are drawn once per episode. Relative positions by
   :func:`~coopnav_env.sim.swarm.measure_relative_positions` (Eq. 9), rotated to ECEF as
   :meth:`~coopnav_env.nav.RelativePositions.from_enu` does (the isotropic covariance
   ``sigma_d^2 I`` is the same in both frames).
5. **Navigation.** :func:`~coopnav_env.nav.solve_standalone` for every UAV and
   :func:`~coopnav_env.nav.solve_cooperative` (paper Eq. 10-23) with the configured transfer
   (DDT/SDT), covariance model (exact/paper) and centroid:

   * ``"self"`` (the paper's choice): every UAV is its own centroid and gets its own solution
     from all UAVs in range of it. Its cost grows as ``N^2`` (solver time on a laptop-class
     core: about 4-5 ms for 5 UAVs, 0.1 s for 50).
   * ``"shared"``: one centroid at the UAV that sees the most satellites (ties: lowest index);
     every UAV in range of it is located from it. Its cost grows as ``N`` (about 3 ms for
     5 UAVs, 4-6 ms for 50).
   * ``"auto"`` (default): ``"self"`` up to :data:`AUTO_SHARED_MIN_UAVS` - 1 UAVs,
     ``"shared"`` from :data:`AUTO_SHARED_MIN_UAVS` on.

   Both solvers are warm-started from each UAV's previous estimate moved by its velocity
   times ``dt`` (a UAV knows its own velocity), so they converge in one or two Gauss-Newton
   iterations; the first epoch of an episode starts from the known launch positions. The start
   point matters: a fix with no redundancy (as many pseudoranges as unknowns, e.g. 5 GPS + BDS
   satellites for 3 coordinates and 2 clocks) has two exact solutions, and Gauss-Newton
   started at the Earth's centre (the solvers' default) can converge to the far one, tens of
   thousands of km away, which the solvers report as ``IMPLAUSIBLE_POSITION``
   (``tests/sim/test_scenario.py`` has a case). Started within a few kilometres of the truth
   it finds the near one.

   The estimate a UAV *uses* (``nav_*``, what the environment observes and rewards) is its
   cooperative fix when that is valid, else its standalone fix (a UAV out of relative range of
   its centroid navigates standalone), else dead reckoning: the previous estimate moved by the
   velocity, with its covariance grown by ``(dead_reckoning_sigma_mps * dt)^2`` per axis.
   Degenerate geometry is a reported :class:`~coopnav_env.nav.NavStatus`, never an exception.

   *Integrity monitoring* (``integrity="raim"`` or ``"fde"``, off by default): before the
   selection every standalone and cooperative fix goes through the residual (chi-square)
   test of :mod:`coopnav_env.nav.integrity` with its exact covariance; with ``"fde"`` the
   measurement the test identifies is excluded and the fix re-solved until the test passes.
   A fault that cannot be cleared makes the fix ``FAULT_DETECTED`` (not valid), and the
   protection levels of the estimate used are reported in the epoch (``hpl_m``, ``vpl_m``).

   *Integrity gate.* A fix is valid when its solver reports OK **and** its predicted 3-D
   sigma ``sqrt(trace(cov))`` is at most ``max_fix_sigma_m`` (default 30 m). Fixes from
   barely enough satellites in a canyon (4-5 measurements for 4-5 unknowns, all from a narrow
   strip of sky) are least-squares solutions with hardly any redundancy: their geometry makes
   the error tens to hundreds of metres, and their covariance says so (predicted 3-D sigma
   of the same order as the error). The gate rejects them (``*_rejected``; reported as no fix)
   instead of letting one such fix move a UAV's estimate by hundreds of metres and
   warm-start the next epoch from there.
6. **Route.** At reset the world plans the shortest street route from the formation centre to
   the goal (:func:`~coopnav_env.sim.route.street_route`, ``route_xy_m``). After the
   navigation each UAV's next waypoint (``next_waypoint``) advances once its *estimated*
   position has reached or passed it (:func:`~coopnav_env.sim.route.advance_waypoints`,
   ``route_reach_m``).

Random draws per step, in this order: NLOS (only when ``nlos_probability > 0``), pseudoranges,
relative positions. Every draw comes from the generator passed to :meth:`UrbanWorld.reset` /
:meth:`UrbanWorld.step`; the same generator state gives the same epoch bit for bit.

Frames: the city's local ENU frame at the geodetic origin ``(lat_deg, lon_deg, alt_m)``, metres,
``z`` up with the ground at 0. Navigation solutions are computed in ECEF and reported in ENU.
"""

from __future__ import annotations

import datetime
import functools
import math
import warnings
from dataclasses import dataclass, field, fields
from enum import IntEnum
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from coopnav_env.constants import (
    FILE_SYSTEMS,
    SHANGHAI_ALT_M,
    SHANGHAI_LAT_DEG,
    SHANGHAI_LON_DEG,
    SYSTEMS,
)
from coopnav_env.gnss import (
    ErrorModel,
    azimuth_elevation,
    default_constellation,
    direction_enu,
    draw_clock_biases,
    enu_rotation,
    geodetic_to_ecef,
    select_highest,
)
from coopnav_env.gnss.errors import (
    DEFAULT_CLOCK_SIGMA_M,
    _iono_factors,
    _range_azimuth_elevation,
    _simulate_pseudoranges,
)
from coopnav_env.gnss.rinex import (
    FEW_SATELLITES_FRACTION,
    MIN_SATELLITES,
    BroadcastConstellation,
    RinexWarning,
    load_broadcast_constellation,
)
from coopnav_env.nav import (
    CooperativeSolution,
    GnssObservations,
    NavStatus,
    RelativePositions,
    solve_cooperative,
    solve_standalone,
)
from coopnav_env.nav.cooperative import _solve_isotropic
from coopnav_env.nav.types import PLAUSIBLE_RADIUS_M
from coopnav_env.nav.wls import _radius_args
from coopnav_env.sim import _integrity
from coopnav_env.sim import _kernels as _sim_kernels
from coopnav_env.sim.city import (
    BoolArray,
    Buildings,
    City,
    CityConfig,
    FloatArray,
    SkyDirections,
    _check_int,
    _check_real,
    _trace_line_of_sight,
    canyon_city,
    draw_nlos,
    generate_city,
    is_inside_building,
    ray_directions,
    sky_directions,
)
from coopnav_env.sim.city_families import (
    FAMILIES,
    FAMILY_PREFIX,
    family_name,
    family_of_seed,
    seeded_family_city,
)
from coopnav_env.sim.file_city import (
    CLEARANCE_M,
    DEFAULT_HEIGHT_M,
    GEOJSON_PREFIX,
    OSM_PREFIX,
    STOREY_HEIGHT_M,
    FileCity,
    _check_bbox,
    _check_heights,
    load_file_city,
    sample_city_path,
)
from coopnav_env.sim.map_aided import predicted_line_of_sight
from coopnav_env.sim.route import advance_waypoints, route_tail_lengths_m, street_route
from coopnav_env.sim.swarm import (
    KinematicsConfig,
    RelativeSensingConfig,
    _measure_relative,
)

__all__ = [
    "AUTO_SHARED_MIN_UAVS",
    "Epoch",
    "NavSource",
    "ScenarioConfig",
    "UrbanWorld",
    "formation_offsets",
    "make_city",
]

_INTEGRITY_FIELDS = ("hpl_m", "vpl_m", "integrity_status", "fault_detected", "fde_excluded")

AUTO_SHARED_MIN_UAVS: int = 11
"""With ``centroid="auto"``, swarms of at least this many UAVs use one shared centroid (cost
linear in N) instead of one centroid per UAV (cost quadratic in N)."""

CityKind = Literal["grid", "canyon"]
CentroidMode = Literal["auto", "self", "shared"]


class NavSource(IntEnum):
    """Where the position estimate a UAV uses comes from (``Epoch.nav_source``)."""

    COOPERATIVE = 0
    """A valid cooperative fix (virtual-centroid solution)."""
    STANDALONE = 1
    """No valid cooperative fix (or no relative link to the centroid): the UAV's own WLS fix."""
    DEAD_RECKONING = 2
    """No fix at all: the previous estimate moved by the velocity, covariance grown."""


# --------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------


def _check_choice(owner: str, name: str, value: Any, allowed: tuple[Any, ...]) -> Any:
    if isinstance(value, bool) or value not in allowed:
        raise ValueError(f"{owner}.{name} must be one of {allowed}, got {value!r}")
    return value


def _check_bool(owner: str, name: str, value: Any) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{owner}.{name} must be True or False, got {value!r}")
    return bool(value)


def _coerce_sub_config(owner: str, name: str, value: Any, cls: type) -> Any:
    """Accept an instance of the dataclass ``cls`` or a dict of its fields (e.g. from YAML)."""
    if isinstance(value, cls):
        return value
    if isinstance(value, dict):
        valid = [f.name for f in fields(cls)]
        unknown = sorted(set(value) - set(valid))
        if unknown:
            raise ValueError(
                f"{owner}.{name}: unknown {cls.__name__} field(s) {unknown}; valid: {valid}"
            )
        return cls(**value)
    raise ValueError(f"{owner}.{name} must be a {cls.__name__} or a dict, got {value!r}")


@dataclass(frozen=True)
class ScenarioConfig:
    """Configuration of the urban world (validated on construction; frozen).

    Sub-configurations (``city_config``, ``kinematics``, ``relative_sensing``,
    ``error_model``) may be given as the dataclass or as a dict of its fields.

    Parameters
    ----------
    n_uavs : int, default 5
        Number of UAVs, in [1, 256].
    city : {"grid", "canyon"}, "geojson:PATH", "osm:PATH" or "family:NAME", default "grid"
        ``"grid"``: a random street grid with open squares (:func:`generate_city` with
        ``city_config``). ``"canyon"``: the paper's single straight canyon (Section 4.1,
        :func:`canyon_city` with the ``canyon_*`` fields). ``"geojson:PATH"``: the building
        footprints of a GeoJSON file (:mod:`coopnav_env.sim.file_city`: heights from
        ``height``, else ``building:levels`` x 3 m, else 10 m; the same city every episode;
        start, goal and route in its free space), read and checked on construction (a bad
        file raises naming it, the feature and the problem); ``"geojson:sample"``: the sample
        city shipped with the package. ``"osm:PATH"``: the buildings of an OpenStreetMap
        ``.osm``/``.osm.pbf`` file (:mod:`coopnav_env.sim.osm_city`, the ``osm`` extra);
        ``"osm:helsinki"``, ``"osm:monaco"``: the real extracts shipped with the package
        (:data:`~coopnav_env.sim.osm_city.SHIPPED_OSM_PATHS`). ``"family:NAME"``: a
        generated city of a family (:mod:`coopnav_env.sim.city_families`: ``irregular``,
        ``old_town``, ``high_rise``, ``avenues``, ``courtyards``), flown as a file city, new
        every episode unless ``city_seed`` is set; ``"family:mixed"``: each city of a family
        drawn with it (every family equally often).
    city_config : CityConfig, default CityConfig()
        Street grid parameters (``city="grid"`` only): 6 x 6 blocks of 60 m, 20 m streets,
        roofs 10-150 m (mean 45 m), 10 % open squares; 500 m x 500 m.
    city_seed : int or None, default None
        ``None``: a new grid or family city is drawn from the episode generator at every reset
        (domain randomisation). An int in [0, 2**63): the same city in every episode.
    city_pool : int or None, default None
        Generated family cities (``city="family:..."``) only: each episode's city seed is
        drawn from ``0 .. city_pool - 1``, so that training meets ``city_pool`` distinct
        cities, each built once per process (while
        :data:`~coopnav_env.sim.city_families.SEEDED_CACHE_SIZE` holds them). Held-out
        episodes at the default None draw from all ``2**63`` seeds. In [1, 2**31);
        exclusive with ``city_seed``.
    canyon_h_over_d : float, default sqrt(3)
        ``h/d`` of the canyon at its reference altitude of 15 m (Eq. 25), in (0, 100].
    canyon_street_width_m : float, default 20.0
        Wall-to-wall width of the canyon, in [4, 1000] [m].
    canyon_length_m : float, default 400.0
        Length of the canyon, in [50, 100000] [m].
    lat_deg, lon_deg, alt_m : float, default the paper's Shanghai site
        Geodetic origin of the city's ENU frame [deg, deg, m]; ``lat_deg`` in [-85, 85].
    t0_s : float, default 0.0
        GNSS time of the first epoch, seconds after the constellation's reference epoch, in
        [0, 1e9] [s].
    t0_random_s : float, default 0.0
        Each episode starts at ``t0_s + U(0, t0_random_s)`` (varies the sky), in [0, 1e7] [s].
    systems : tuple of str, default ("GPS", "BDS")
        Constellations, a non-empty subset of ``SYSTEMS``; with ``constellation="rinex:PATH"``
        also ``"GAL"`` (Galileo, from the file's I/NAV records, with its own receiver clock).
    constellation : str, default "nominal"
        Where the satellites come from. ``"nominal"``: the nominal circular-orbit
        constellations (:func:`~coopnav_env.gnss.default_constellation`). ``"rinex:PATH"``:
        the broadcast ephemerides of a RINEX navigation file (RINEX 3, or RINEX 2 GPS; plain
        or gzip-compressed)
        (:class:`~coopnav_env.gnss.rinex.BroadcastConstellation`, the satellites of
        ``systems`` in it; ``"rinex:sample"``: the one-day GPS + BeiDou file shipped with the
        package, made by the project; ``"rinex:igs_brdc"``: a real one, 6 h of IGS merged GPS
        ephemerides, with ``systems=("GPS",)``). The file is read and checked here: a missing
        or bad file, or a time outside its ephemerides' validity, raises ``ValueError`` naming
        the file. With a file, the GNSS time ``t_s`` counts seconds from the start of the
        file's coverage, ``t0_s`` must be 0, and the start of an episode is set by
        ``constellation_start``.
    constellation_start : str, float or None, default None
        Only with ``constellation="rinex:..."``. ``None``: each episode starts at a time drawn
        uniformly from the episode generator among those at which the whole episode lies in
        the file's usable spans at the origin (every system a valid ephemeris, at least 4
        satellites above the cut-off:
        :meth:`~coopnav_env.gnss.rinex.BroadcastConstellation.visibility`);
        ``t0_random_s`` must then be 0. A UTC time as an ISO 8601 string
        (``"2026-12-03T06:00:00Z"``) or GPS seconds (since 1980-01-06): every episode starts
        there, plus ``U(0, t0_random_s)``; the start, spread and episode must lie inside the
        coverage (an episode that leaves the usable spans is flown with a ``RinexWarning``).
    elevation_mask_deg : float, default 10.0
        Elevation cut-off [deg], in [0, 60].
    max_sats : int or None, default None
        Receiver channel limit (the highest satellites are kept), in [4, 200]; None: no limit.
    error_model : ErrorModel, default ErrorModel()
        Pseudorange error budget (Eq. 3-8): sigma_URE 1 m, troposphere, iono-free.
    clock_sigma_m : float, default 3e4
        Standard deviation of the receiver clock biases drawn at reset, in [0, 1e7] [m].
    nlos_probability : float, default 0.0
        Probability that a blocked satellite is received through a reflection, in [0, 1].
    nlos_bias_mean_m, nlos_bias_floor_m : float, default 15.0, 1.0
        NLOS range bias ``floor + Exp(mean)`` [m], each in [0, 1000].
    kinematics : KinematicsConfig, default KinematicsConfig()
        1 s step, 10 m/s, 4 m/s^2, altitude band 5-30 m, radius 1 m, separation 3 m.
    relative_sensing : RelativeSensingConfig, default RelativeSensingConfig()
        200 m range, per-axis sigma 0.1 m + 0.002 m/m.
    transfer : {"ddt", "sdt"}, default "ddt"
        Measurement transfer to the centroid (Eq. 12-13 or Eq. 10-11).
    centroid : {"auto", "self", "shared"}, default "auto"
        Centroid choice, see the module docstring.
    covariance : {"exact", "paper"}, default "exact"
        Covariance of the transferred measurements (exact, or Eq. 18-19 as printed).
    nav_max_iter : int, default 10
        Gauss-Newton iteration limit of both solvers, in [1, 50].
    dead_reckoning_sigma_mps : float, default 1.0
        Growth of the per-axis position sigma while dead reckoning, in [0, 100] [m/s].
    dead_reckoning_noise : bool, default False
        Whether the velocity that carries the previous estimate forward (the prediction that
        dead reckoning uses, and that 3DMA exclusion predicts blockage at) is measured with
        noise: the true velocity plus ``N(0, dead_reckoning_sigma_mps^2)`` per axis, drawn
        afresh every step, so that the prediction's error grows as the random walk its
        covariance already assumes. Off (the default, unchanged episodes): the prediction
        moves by the *true* velocity, so dead reckoning never drifts, and a design that
        rejects fixes is flattered (it keeps the error of its last good fix for ever). Turn it
        on wherever fixes are often rejected (e.g. with the ``urban_nlos_3dma`` preset).
    start_prior_sigma_m : float, default 10.0
        Per-axis sigma of the known launch position, used only when a UAV has no fix at the
        first epoch, in (0, 1000] [m].
    formation_spacing_m : float, default 5.0
        Lattice spacing of the initial formation, in [min_separation_m, 100] [m].
    start_altitude_m : float, default 15.0
        Altitude of the formation centre and of the goal; inside the altitude band [m].
    goal_distance_min_m : float, default 200.0
        Smallest horizontal distance from the start to the goal, in [0, 1e5] [m]; when the
        city is too small, the farthest of 256 candidate street points is taken.
    goal_radius_m : float, default 25.0
        A UAV is in the goal area when its true horizontal distance to the goal is at most
        this, in (0, 1000] [m].
    route_reach_m : float, default 5.0
        Waypoint tracking on the street route planned at reset: a UAV's next waypoint counts
        as reached when its *estimated* position is within this distance of it along both
        East and North, or past it along the leg that arrives at it
        (:func:`~coopnav_env.sim.route.advance_waypoints`), in [0, 1000] [m].
    max_fix_sigma_m : float or None, default 30.0
        Integrity gate: a cooperative or standalone fix whose predicted 3-D sigma
        ``sqrt(trace(cov))`` exceeds this is rejected (reported as no fix, ``*_rejected``)
        and the UAV falls back to the next source (standalone, then dead reckoning), in
        (0, 1e6] [m]; None disables the gate.
    integrity : {"off", "raim", "fde"}, default "off"
        Integrity monitoring of every standalone and cooperative fix
        (:mod:`coopnav_env.nav.integrity`): ``"raim"`` tests each fix's residuals (chi-square
        with the exact covariance) and computes protection levels; a fix that fails is
        reported ``FAULT_DETECTED`` and not used. ``"fde"`` also excludes the measurement the
        test identifies and re-solves, until the test passes or redundancy runs out. The
        protection levels and FDE figures of the estimate used go to
        ``Epoch.hpl_m``/``vpl_m``/``integrity_status``/``fault_detected``/``fde_excluded``.
        Needs ``covariance="exact"``. ``"off"`` (default) runs no residual test and leaves
        every episode as before: a fix's status ``OK`` then says only that the solver
        converged, and a fix that uses a faulty pseudorange (an NLOS or multipath outlier,
        even 1 km) is used, however large its error.
    integrity_p_fa : float, default 1e-3
        False-alarm probability of each residual test, in (0, 0.5].
    integrity_risk : float, default 1e-7
        Integrity risk of a fix, in (0, 0.5]: the missed-detection allocation and the
        fault-free tail of the protection levels.
    integrity_fault_sign : {"any", "positive"}, default "any"
        ``"positive"``: FDE identifies only measurements with a positive residual (faults
        known to be positive range biases, as NLOS reception), see
        :func:`coopnav_env.nav.fde_cooperative`.
    nlos_exclusion : {"off", "map"}, default "off"
        ``"map"``: 3D-mapping-aided NLOS exclusion (:mod:`coopnav_env.sim.map_aided`). Each
        UAV predicts, from the city model and the position it believes it is at (its
        previous estimate moved by its velocity, with that estimate's covariance grown by
        one step of dead reckoning), which satellites may be blocked, and does not use them:
        a satellite is used only when it is in line of sight from the predicted position and
        from the candidates ``nlos_exclusion_margin_sigma`` sigma around it (horizontal
        principal axes and vertical). The excluded ones are ``Epoch.map_excluded``; the
        ``received`` mask, ``n_sats`` and everything downstream (solvers, integrity
        monitoring, observation) count the satellites used. The simulated reception comes
        from the same city, so this map is perfect, which a real one is not (see the
        module). ``"off"`` (default) leaves every episode as before.
    nlos_exclusion_margin_sigma : float, default 2.0
        Candidates this many sigma from the predicted position, in [0, 10] (0: the predicted
        position only).
    nlos_exclusion_max_margin_m : float, default 10.0
        Cap on each candidate's displacement [m], in [0, 1000].
    city_origin : {"file", "config"}, default "file"
        With ``city="geojson:..."``: ``"file"`` puts the ENU origin at the footprints'
        centroid and sets ``lat_deg``/``lon_deg`` to it on construction (the satellites are
        then seen from the city); ``"config"`` uses ``lat_deg``, ``lon_deg``, ``alt_m`` as
        given. Other cities ignore it.
    city_start_lat_lon, city_goal_lat_lon : (float, float) or None, default None
        With ``city="geojson:..."``: the start (centre of the formation) and the goal
        ``(lat_deg, lon_deg)`` of every episode; None: drawn per episode in the free space.
        A point inside a building, or not in the reachable free space, is refused on
        construction.
    city_bbox : (float, float, float, float) or None, default None
        With a file city: ``(south, west, north, east)`` [deg]; only the buildings whose
        footprint's vertex mean lies inside are read.
    city_repair : bool, default True
        With a file city: invalid rings are repaired (shapely ``make_valid``) and unreadable
        heights read as missing, with one warning counting them; False: every bad feature is
        listed in one error.
    city_default_height_m : float, default 10.0
        With a file city: the roof height of a building without ``height`` or
        ``building:levels``, in [1, 500] [m] (a warning says how many got it).
    city_storey_height_m : float, default 3.0
        With a file city: metres per ``building:levels`` storey, in [2, 10].
    """

    n_uavs: int = 5
    city: CityKind = "grid"
    city_config: CityConfig = field(default_factory=CityConfig)
    city_seed: int | None = None
    city_pool: int | None = None
    canyon_h_over_d: float = math.sqrt(3.0)
    canyon_street_width_m: float = 20.0
    canyon_length_m: float = 400.0
    lat_deg: float = SHANGHAI_LAT_DEG
    lon_deg: float = SHANGHAI_LON_DEG
    alt_m: float = SHANGHAI_ALT_M
    t0_s: float = 0.0
    t0_random_s: float = 0.0
    systems: tuple[str, ...] = SYSTEMS
    constellation: str = "nominal"
    constellation_start: str | float | None = None
    elevation_mask_deg: float = 10.0
    max_sats: int | None = None
    error_model: ErrorModel = field(default_factory=ErrorModel)
    clock_sigma_m: float = DEFAULT_CLOCK_SIGMA_M
    nlos_probability: float = 0.0
    nlos_bias_mean_m: float = 15.0
    nlos_bias_floor_m: float = 1.0
    kinematics: KinematicsConfig = field(default_factory=KinematicsConfig)
    relative_sensing: RelativeSensingConfig = field(default_factory=RelativeSensingConfig)
    transfer: Literal["ddt", "sdt"] = "ddt"
    centroid: CentroidMode = "auto"
    covariance: Literal["exact", "paper"] = "exact"
    nav_max_iter: int = 10
    dead_reckoning_sigma_mps: float = 1.0
    dead_reckoning_noise: bool = False
    start_prior_sigma_m: float = 10.0
    formation_spacing_m: float = 5.0
    start_altitude_m: float = 15.0
    goal_distance_min_m: float = 200.0
    goal_radius_m: float = 25.0
    route_reach_m: float = 5.0
    max_fix_sigma_m: float | None = 30.0
    integrity: Literal["off", "raim", "fde"] = "off"
    integrity_p_fa: float = 1e-3
    integrity_risk: float = 1e-7
    integrity_fault_sign: Literal["any", "positive"] = "any"
    nlos_exclusion: Literal["off", "map"] = "off"
    nlos_exclusion_margin_sigma: float = 2.0
    nlos_exclusion_max_margin_m: float = 10.0
    city_origin: Literal["file", "config"] = "file"
    city_start_lat_lon: tuple[float, float] | None = None
    city_goal_lat_lon: tuple[float, float] | None = None
    city_bbox: tuple[float, float, float, float] | None = None
    city_repair: bool = True
    city_default_height_m: float = DEFAULT_HEIGHT_M
    city_storey_height_m: float = STOREY_HEIGHT_M

    def __post_init__(self) -> None:
        o = type(self).__name__
        setv = object.__setattr__
        _check_int(o, "n_uavs", self.n_uavs, 1, 256)
        if _is_family_city(self.city):
            try:
                family_name(self.city)
            except ValueError as exc:
                raise ValueError(f"{o}.city={self.city!r}: {exc}") from None
        elif not _is_file_city(self.city) and self.city not in ("grid", "canyon"):
            raise ValueError(
                f"{o}.city must be one of ('grid', 'canyon'), 'geojson:PATH' (a GeoJSON file "
                f"of building footprints; 'geojson:sample' for the shipped one) or 'osm:PATH' "
                f"(an OpenStreetMap .osm/.osm.pbf file; 'osm:helsinki' for the shipped one), or "
                f"'family:NAME' (a generated city; {', '.join(FAMILIES)}), got {self.city!r}"
            )
        setv(
            self, "city_config", _coerce_sub_config(o, "city_config", self.city_config, CityConfig)
        )
        if self.city_seed is not None:
            _check_int(o, "city_seed", self.city_seed, 0, 2**63 - 1)
        if self.city_pool is not None:
            _check_int(o, "city_pool", self.city_pool, 1, 2**31 - 1)
            if not _is_family_city(self.city):
                raise ValueError(
                    f"{o}.city_pool={self.city_pool} applies to generated family cities "
                    f"('family:NAME') only, got city={self.city!r}: leave city_pool at None"
                )
            if self.city_seed is not None:
                raise ValueError(
                    f"{o}.city_pool={self.city_pool} and city_seed={self.city_seed} exclude "
                    "each other: city_seed fixes one city, city_pool draws among several"
                )
        _check_real(o, "canyon_h_over_d", self.canyon_h_over_d, 0.0, 100.0, lo_open=True)
        _check_real(o, "canyon_street_width_m", self.canyon_street_width_m, 4.0, 1000.0)
        _check_real(o, "canyon_length_m", self.canyon_length_m, 50.0, 100_000.0)
        _check_real(o, "lat_deg", self.lat_deg, -85.0, 85.0)
        _check_real(o, "lon_deg", self.lon_deg, -180.0, 360.0)
        _check_real(o, "alt_m", self.alt_m, -500.0, 10_000.0)
        _check_city_file_settings(self, o)
        _check_real(o, "t0_s", self.t0_s, 0.0, 1e9)
        _check_real(o, "t0_random_s", self.t0_random_s, 0.0, 1e7)
        systems = self.systems
        if isinstance(systems, str):
            systems = (systems,)
        try:
            systems = tuple(systems)
        except TypeError:
            raise ValueError(f"{o}.systems must be a tuple of names from {SYSTEMS}") from None
        if not systems or len(set(systems)) != len(systems) or set(systems) - set(FILE_SYSTEMS):
            raise ValueError(
                f"{o}.systems must be a non-empty tuple of distinct names from {SYSTEMS} "
                f"(and 'GAL', Galileo, with constellation='rinex:PATH'), got {self.systems!r}"
            )
        spec = self.constellation
        if "GAL" in systems and not (isinstance(spec, str) and spec.startswith("rinex:")):
            raise ValueError(
                f"{o}.systems: Galileo ('GAL') flies only from a navigation file, "
                f"constellation='rinex:PATH' (the nominal constellations are {SYSTEMS}), got "
                f"systems={self.systems!r} with constellation={spec!r}"
            )
        setv(self, "systems", systems)
        _check_real(o, "elevation_mask_deg", self.elevation_mask_deg, 0.0, 60.0)
        if self.max_sats is not None:
            _check_int(o, "max_sats", self.max_sats, 4, 200)
        setv(
            self, "error_model", _coerce_sub_config(o, "error_model", self.error_model, ErrorModel)
        )
        _check_real(o, "clock_sigma_m", self.clock_sigma_m, 0.0, 1e7)
        _check_real(o, "nlos_probability", self.nlos_probability, 0.0, 1.0)
        _check_real(o, "nlos_bias_mean_m", self.nlos_bias_mean_m, 0.0, 1000.0)
        _check_real(o, "nlos_bias_floor_m", self.nlos_bias_floor_m, 0.0, 1000.0)
        kin = _coerce_sub_config(o, "kinematics", self.kinematics, KinematicsConfig)
        setv(self, "kinematics", kin)
        setv(
            self,
            "relative_sensing",
            _coerce_sub_config(o, "relative_sensing", self.relative_sensing, RelativeSensingConfig),
        )
        _check_choice(o, "transfer", self.transfer, ("ddt", "sdt"))
        _check_choice(o, "centroid", self.centroid, ("auto", "self", "shared"))
        _check_choice(o, "covariance", self.covariance, ("exact", "paper"))
        _check_int(o, "nav_max_iter", self.nav_max_iter, 1, 50)
        _check_real(o, "dead_reckoning_sigma_mps", self.dead_reckoning_sigma_mps, 0.0, 100.0)
        _check_bool(o, "dead_reckoning_noise", self.dead_reckoning_noise)
        _check_real(o, "start_prior_sigma_m", self.start_prior_sigma_m, 0.0, 1000.0, lo_open=True)
        _check_real(o, "formation_spacing_m", self.formation_spacing_m, kin.min_separation_m, 100.0)
        if not self.formation_spacing_m > 0:  # min_separation_m = 0 admits 0: no lattice
            raise ValueError(
                f"{o}.formation_spacing_m must be > 0, got {self.formation_spacing_m!r}"
            )
        _check_real(
            o, "start_altitude_m", self.start_altitude_m, kin.altitude_min_m, kin.altitude_max_m
        )
        _check_real(o, "goal_distance_min_m", self.goal_distance_min_m, 0.0, 1e5)
        _check_real(o, "goal_radius_m", self.goal_radius_m, 0.0, 1000.0, lo_open=True)
        _check_real(o, "route_reach_m", self.route_reach_m, 0.0, 1000.0)
        if self.max_fix_sigma_m is not None:
            _check_real(o, "max_fix_sigma_m", self.max_fix_sigma_m, 0.0, 1e6, lo_open=True)
        _check_choice(o, "integrity", self.integrity, ("off", "raim", "fde"))
        _check_real(o, "integrity_p_fa", self.integrity_p_fa, 0.0, 0.5, lo_open=True)
        _check_real(o, "integrity_risk", self.integrity_risk, 0.0, 0.5, lo_open=True)
        _check_choice(o, "integrity_fault_sign", self.integrity_fault_sign, ("any", "positive"))
        _check_choice(o, "nlos_exclusion", self.nlos_exclusion, ("off", "map"))
        _check_real(o, "nlos_exclusion_margin_sigma", self.nlos_exclusion_margin_sigma, 0.0, 10.0)
        _check_real(o, "nlos_exclusion_max_margin_m", self.nlos_exclusion_max_margin_m, 0.0, 1000.0)
        if self.integrity != "off" and self.covariance != "exact":
            raise ValueError(
                f"{o}.integrity={self.integrity!r} needs covariance='exact' (the residual "
                f"test's distribution is known only with the exact covariance), got "
                f"covariance={self.covariance!r}"
            )
        _check_sky_settings(self, o)  # last: it needs the kinematics' dt_s

    @property
    def dt_s(self) -> float:
        """Time step of the kinematics and of the GNSS epochs [s]."""
        return float(self.kinematics.dt_s)

    def episode_horizon_s(self) -> float:
        """GNSS time an episode may span after its start [s] (0 here: the world alone has no
        episode length; the environment's config returns ``max_steps * dt_s``). A RINEX sky
        must cover ``[start, start + t0_random_s + episode_horizon_s()]``."""
        return 0.0

    @property
    def centroid_mode(self) -> Literal["self", "shared"]:
        """The centroid mode actually used (``"auto"`` resolved for ``n_uavs``)."""
        if self.centroid == "auto":
            return "self" if self.n_uavs < AUTO_SHARED_MIN_UAVS else "shared"
        return self.centroid  # type: ignore[return-value]

    def scenario_fields(self) -> dict[str, Any]:
        """The :class:`ScenarioConfig` fields of this config (also for subclasses)."""
        return {f.name: getattr(self, f.name) for f in fields(ScenarioConfig)}


# --------------------------------------------------------------------------------------------
# city, formation, start and goal
# --------------------------------------------------------------------------------------------


def _is_file_city(spec: Any) -> bool:
    """Whether a ``city`` setting names a file (``"geojson:..."`` or ``"osm:..."``)."""
    return isinstance(spec, str) and spec.startswith((GEOJSON_PREFIX, OSM_PREFIX))


def _is_family_city(spec: Any) -> bool:
    """Whether a ``city`` setting names a generated city family (``"family:NAME"``)."""
    return isinstance(spec, str) and spec.startswith(FAMILY_PREFIX)


def _file_city(cfg: ScenarioConfig, *, warn: bool = False) -> FileCity:
    """The city of ``cfg.city = "geojson:PATH"`` or ``"osm:PATH"`` (read once per file
    version and reading settings)."""
    if cfg.city.startswith(OSM_PREFIX):
        spec = cfg.city[len(OSM_PREFIX) :]
        from coopnav_env.sim.osm_city import resolve_osm_path

        spec = str(resolve_osm_path(spec))
        path = OSM_PREFIX + spec
    else:
        spec = cfg.city[len(GEOJSON_PREFIX) :]
        path = str(sample_city_path()) if spec == "sample" else spec
    origin = None if cfg.city_origin == "file" else (cfg.lat_deg, cfg.lon_deg)
    return load_file_city(
        path,
        origin_lat_lon=origin,
        alt_m=cfg.alt_m,
        default_height_m=cfg.city_default_height_m,
        storey_height_m=cfg.city_storey_height_m,
        repair=cfg.city_repair,
        bbox=cfg.city_bbox,
        warn=warn,
    )


def _check_city_file_settings(cfg: ScenarioConfig, o: str) -> None:
    """Validate ``city="geojson:..."`` (reading the file), ``city_origin`` and the start and
    goal points; with ``city_origin="file"``, set ``lat_deg``/``lon_deg`` to the city's."""
    setv = object.__setattr__
    _check_choice(o, "city_origin", cfg.city_origin, ("file", "config"))
    ends: dict[str, tuple[float, float]] = {}
    for name in ("city_start_lat_lon", "city_goal_lat_lon"):
        value = getattr(cfg, name)
        if value is None:
            continue
        try:
            pair = tuple(float(v) for v in value)
        except (TypeError, ValueError):
            pair = ()
        if not (len(pair) == 2 and all(math.isfinite(v) for v in pair) and abs(pair[0]) <= 90.0):
            raise ValueError(f"{o}.{name} must be (lat_deg, lon_deg), got {value!r}")
        setv(cfg, name, pair)
        ends[name] = pair  # type: ignore[assignment]
    try:
        setv(cfg, "city_bbox", _check_bbox(cfg.city_bbox))
        _check_heights(cfg.city_storey_height_m, cfg.city_default_height_m)
    except ValueError as exc:
        raise ValueError(f"{o}.city_{exc}") from None
    if not isinstance(cfg.city_repair, bool):
        raise ValueError(f"{o}.city_repair must be True or False, got {cfg.city_repair!r}")
    if not _is_file_city(cfg.city):
        changed = [
            name
            for name, default in (
                ("city_origin", "file"),
                ("city_bbox", None),
                ("city_repair", True),
                ("city_default_height_m", DEFAULT_HEIGHT_M),
                ("city_storey_height_m", STOREY_HEIGHT_M),
            )
            if getattr(cfg, name) != default
        ]
        if changed or ends:
            name = next(iter(ends), changed[0] if changed else "city_origin")
            raise ValueError(
                f"{o}.{name} needs city='geojson:PATH' or 'osm:PATH', got city={cfg.city!r}"
            )
        return
    if not cfg.city.partition(":")[2].strip():
        raise ValueError(f"{o}.city={cfg.city!r} names no file")
    try:
        city = _file_city(cfg, warn=True)
    except ValueError as exc:
        raise ValueError(f"{o}.city={cfg.city!r}: {exc}") from None
    if cfg.city_origin == "file":
        setv(cfg, "lat_deg", city.origin[0])
        setv(cfg, "lon_deg", city.origin[1])
    for name, (lat, lon) in ends.items():
        xy = city.lat_lon_to_xy(lat, lon)
        inside = bool(is_inside_building(city.buildings, np.array([[xy[0], xy[1], 1.0]]))[0])
        if inside or not city.is_free_xy(xy)[0]:
            why = "inside a building"
            if not inside:
                why = (
                    f"not in the reachable free space (within {CLEARANCE_M:g} m of a wall, "
                    "outside the map or cut off from it)"
                )
            raise ValueError(
                f"{o}.{name}=({lat}, {lon}) lies {why} of {city.source} (at East "
                f"{xy[0]:.1f} m, North {xy[1]:.1f} m of its origin)"
            )
    if len(ends) == 2:
        start_xy = city.lat_lon_to_xy(*ends["city_start_lat_lon"])
        goal_xy = city.lat_lon_to_xy(*ends["city_goal_lat_lon"])
        apart_m = float(np.hypot(*(goal_xy - start_xy)))
        if apart_m <= cfg.goal_radius_m:
            raise ValueError(
                f"{o}.city_goal_lat_lon={ends['city_goal_lat_lon']} is {apart_m:.1f} m from "
                f"city_start_lat_lon={ends['city_start_lat_lon']}, within goal_radius_m "
                f"{cfg.goal_radius_m:g}: every episode would end at its first step; give a goal "
                "farther from the start"
            )
    x0, x1, y0, y1 = city.extent_m
    if "city_goal_lat_lon" not in ends and math.hypot(x1 - x0, y1 - y0) < cfg.goal_distance_min_m:
        raise ValueError(
            f"{o}.goal_distance_min_m={cfg.goal_distance_min_m:g} is more than the "
            f"{math.hypot(x1 - x0, y1 - y0):.0f} m across {city.source}: no goal can be that "
            "far from the start; lower goal_distance_min_m, give city_goal_lat_lon, or use a "
            "larger city"
        )


def _check_sky_settings(cfg: ScenarioConfig, o: str) -> None:
    """Validate ``constellation`` and ``constellation_start`` (reading a RINEX file)."""
    spec, start = cfg.constellation, cfg.constellation_start
    if spec == "nominal":
        if start is not None:
            raise ValueError(
                f"{o}.constellation_start needs constellation='rinex:PATH', got "
                f"constellation_start={start!r} with constellation='nominal'"
            )
        return
    if not isinstance(spec, str) or not spec.startswith("rinex:") or not spec[6:].strip():
        raise ValueError(
            f"{o}.constellation must be 'nominal' or 'rinex:PATH' (a RINEX navigation file; "
            f"'rinex:sample' for the shipped one), got {spec!r}"
        )
    try:
        sky = world_constellation(cfg)
    except ValueError as exc:
        raise ValueError(f"{o}.constellation={spec!r}: {exc}") from None
    if isinstance(start, datetime.date):  # a datetime too (YAML reads ISO times as them)
        start = start.isoformat()
        object.__setattr__(cfg, "constellation_start", start)
    if cfg.t0_s != 0.0:
        raise ValueError(
            f"{o}.t0_s must be 0 with constellation={spec!r} (t_s counts from the start of the "
            f"file's coverage); give the start as constellation_start, got t0_s={cfg.t0_s!r}"
        )
    horizon = cfg.episode_horizon_s()
    lo, hi = sky.coverage_s
    view = _sky_view(cfg, sky)
    where = f"({cfg.lat_deg:g}, {cfg.lon_deg:g})"
    if view.seen_fraction < FEW_SATELLITES_FRACTION:
        warnings.warn(
            f"{o}.constellation={spec!r}: at the origin {where} on average "
            f"{view.visible_mean:.1f} satellites with a valid ephemeris are above the "
            f"{cfg.elevation_mask_deg:g} deg cut-off, of {view.above_mean:.1f} of the file's "
            f"satellites above it ({view.seen_fraction:.0%}): the file holds what its "
            "station tracked. Fly near the station (lat_deg, lon_deg) or use a merged "
            "broadcast file (BRDC...MN.rnx)",
            RinexWarning,
            stacklevel=4,
        )
    if start is None:
        if cfg.t0_random_s != 0.0:
            raise ValueError(
                f"{o}.t0_random_s must be 0 with constellation={spec!r} and no "
                f"constellation_start (episodes then start anywhere in the file's coverage), "
                f"got {cfg.t0_random_s!r}"
            )
        if hi - lo < horizon:
            raise ValueError(
                f"{o}.constellation={spec!r}: an episode spans {horizon:g} s but the file "
                f"covers only {hi - lo:g} s ({sky.coverage_text()})"
            )
        if not any(b - a >= horizon for a, b in view.spans_s):
            raise ValueError(
                f"{o}.constellation={spec!r}: no {horizon:g} s of the file (an episode) in "
                f"which every system has a valid ephemeris and at least {MIN_SATELLITES} "
                f"satellites are above the {cfg.elevation_mask_deg:g} deg cut-off at {where} "
                f"(usable: {view.spans_text(sky.reference_gps_s)}; coverage "
                f"{sky.coverage_text()}); fly near the file's station or give "
                "constellation_start"
            )
        return
    try:
        t_start = sky.t_s_of(start)
    except ValueError as exc:
        raise ValueError(f"{o}.constellation_start: {exc}") from None
    t_end = t_start + cfg.t0_random_s + horizon
    if not (lo <= t_start and t_end <= hi):
        raise ValueError(
            f"{o}.constellation_start={start!r} (t_s {t_start:g} s) plus t0_random_s "
            f"({cfg.t0_random_s:g} s) and the episode ({horizon:g} s) reach t_s {t_end:g} s, "
            f"outside the validity of the ephemerides in {sky.source}: its coverage is "
            f"{sky.coverage_text()}"
        )
    if not any(a <= t_start and t_end <= b for a, b in view.spans_s):
        warnings.warn(
            f"{o}.constellation_start={start!r}: the episodes (t_s {t_start:g} to {t_end:g} s) "
            f"leave the file's usable spans at the origin {where}, where every system has a "
            f"valid ephemeris and at least {MIN_SATELLITES} satellites are above the "
            f"{cfg.elevation_mask_deg:g} deg cut-off (usable: "
            f"{view.spans_text(sky.reference_gps_s)})",
            RinexWarning,
            stacklevel=4,
        )


def world_constellation(cfg: ScenarioConfig) -> Any:
    """The satellites a world of ``cfg`` flies under: the nominal constellations of
    ``cfg.systems`` or, with ``constellation="rinex:PATH"``, the file's (cached per file).

    Returns
    -------
    Constellation or BroadcastConstellation
    """
    if cfg.constellation == "nominal":
        return default_constellation(cfg.systems)
    return load_broadcast_constellation(cfg.constellation[6:].strip(), cfg.systems)


def _sky_view(cfg: ScenarioConfig, sky: Any) -> Any:
    """What the origin sees of a RINEX sky (:meth:`BroadcastConstellation.visibility`)."""
    return sky.visibility(
        cfg.lat_deg, cfg.lon_deg, cfg.alt_m, cfg.elevation_mask_deg, MIN_SATELLITES
    )


def episode_start_s(cfg: ScenarioConfig, sky: Any, rng: np.random.Generator) -> float:
    """GNSS time ``t_s`` of an episode's first epoch (draws from ``rng`` only when random).

    Nominal sky: ``t0_s + U(0, t0_random_s)``. RINEX sky: ``constellation_start`` plus
    ``U(0, t0_random_s)``, or without a start, uniform over the times at which a whole
    episode fits inside the file's usable spans at the origin
    (:meth:`~coopnav_env.gnss.rinex.BroadcastConstellation.visibility`: every system a valid
    ephemeris, at least 4 satellites above the cut-off).
    """
    if cfg.constellation == "nominal":
        return cfg.t0_s + (rng.uniform(0.0, cfg.t0_random_s) if cfg.t0_random_s else 0.0)
    if cfg.constellation_start is None:
        view = _sky_view(cfg, sky)
        horizon = cfg.episode_horizon_s()
        return view.start_s(horizon, rng.uniform(0.0, view.room_s(horizon)))
    t = sky.t_s_of(cfg.constellation_start)
    return t + (rng.uniform(0.0, cfg.t0_random_s) if cfg.t0_random_s else 0.0)


def make_city(config: ScenarioConfig, rng: np.random.Generator) -> City:
    """The city of one episode.

    ``city="canyon"``: :func:`canyon_city` (deterministic). ``city="grid"`` with ``city_seed``:
    the same generated city every time (its own generator, ``rng`` untouched); without:
    :func:`generate_city` drawing from ``rng``. ``city="geojson:PATH"``: the file's city
    (:func:`~coopnav_env.sim.file_city.load_file_city`, cached; ``rng`` untouched).
    ``city="family:NAME"``: :func:`~coopnav_env.sim.city_families.seeded_family_city` of
    ``city_seed``, or without it of a city seed drawn from ``rng`` (one draw, from
    ``0 .. city_pool - 1`` when ``city_pool`` is set; a city is built once per process and
    seed, so that episodes repeated on the same seeds reuse it); ``"family:mixed"``: of the
    family :func:`~coopnav_env.sim.city_families.family_of_seed` names.
    """
    if _is_file_city(config.city):
        return _file_city(config)
    if _is_family_city(config.city):
        name, origin = family_name(config.city), (config.lat_deg, config.lon_deg, config.alt_m)
        seed = config.city_seed
        if seed is None:  # one draw: the episode's city seed (a city is built once per seed)
            high = 2**63 - 1 if config.city_pool is None else config.city_pool
            seed = int(rng.integers(0, high))
        return seeded_family_city(family_of_seed(name, seed), seed, origin)
    if config.city == "canyon":
        return canyon_city(
            h_over_d=config.canyon_h_over_d,
            street_width_m=config.canyon_street_width_m,
            length_m=config.canyon_length_m,
        )
    if config.city_seed is not None:
        return generate_city(config.city_config, np.random.default_rng(config.city_seed))
    return generate_city(config.city_config, rng)


def formation_offsets(
    n: int,
    spacing_m: float,
    half_width_m: float,
    z_centre_m: float,
    z_min_m: float,
    z_max_m: float,
) -> FloatArray:
    """Compact lattice formation in street coordinates (along, across, up).

    Lattice points ``spacing * (i, j, k)`` with ``|across| <= half_width_m`` and the altitude
    in ``[z_min_m, z_max_m]`` are sorted by a distance from the centre that counts vertical
    offsets 1.5 times (formations spread horizontally first); the ``n`` nearest are taken.

    Returns
    -------
    ndarray, shape (n, 3)
        ``(along, across, altitude)`` [m]; ``altitude`` absolute (a new array each call; the
        lattice of each set of arguments is computed once per process).
    """
    return _formation_offsets(
        int(n),
        float(spacing_m),
        float(half_width_m),
        float(z_centre_m),
        float(z_min_m),
        float(z_max_m),
    ).copy()


@functools.lru_cache(maxsize=256)
def _formation_offsets(
    n: int,
    spacing_m: float,
    half_width_m: float,
    z_centre_m: float,
    z_min_m: float,
    z_max_m: float,
) -> FloatArray:
    """:func:`formation_offsets`, cached (a reset of every episode needs the same lattice)."""
    n_across = math.floor(half_width_m / spacing_m)
    k_lo = math.ceil((z_min_m - z_centre_m) / spacing_m - 1e-9)
    k_hi = math.floor((z_max_m - z_centre_m) / spacing_m + 1e-9)
    k_lo, k_hi = min(k_lo, 0), max(k_hi, 0)
    per_slice = (2 * n_across + 1) * (k_hi - k_lo + 1)
    n_along = math.ceil(n / per_slice / 2.0) + 1
    i, j, k = np.meshgrid(
        np.arange(-n_along, n_along + 1),
        np.arange(-n_across, n_across + 1),
        np.arange(k_lo, k_hi + 1),
        indexing="ij",
    )
    lattice = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1).astype(float) * spacing_m
    key = lattice[:, 0] ** 2 + lattice[:, 1] ** 2 + (1.5 * lattice[:, 2]) ** 2
    order = np.argsort(key, kind="stable")[:n]
    out = lattice[order]
    out[:, 2] += z_centre_m
    out.setflags(write=False)
    return out


def _street_frames(
    city: City, rng: np.random.Generator, n: int, margin_m: float
) -> tuple[FloatArray, BoolArray]:
    """``n`` random street points (E, N) and whether each lies on a north-south street.

    The same law as :meth:`City.random_street_points` (streets weighted by length), with the
    street orientation returned so that a formation can be laid along it.
    """
    x0, x1, y0, y1 = city.extent_m
    cdf, centres = _street_distribution(city)
    u_street = rng.random(n)
    u_along = rng.random(n)
    extent = (float(x0), float(x1), float(y0), float(y1))
    return _sim_kernels.street_frames(
        cdf, u_street, u_along, centres, city.street_centres_x_m.size, extent, float(margin_m)
    )


_STREET_DISTRIBUTIONS: dict[tuple, tuple] = {}
"""``(id(street_x), id(street_y), extent) -> (street_x, street_y, cdf, centres)`` of
:func:`_street_distribution` (the entry keeps the arrays, so their ids stay theirs)."""


def _street_distribution(city: City) -> tuple[FloatArray, FloatArray]:
    """The cumulative distribution of a city's streets weighted by their lengths (the
    north-south streets first) and their centre lines, ``(S,)`` each; remembered per pair of
    street arrays and extent (every grid city of one configuration shares its streets)."""
    x0, x1, y0, y1 = city.extent_m
    cx, cy = city.street_centres_x_m, city.street_centres_y_m
    key = (id(cx), id(cy), x0, x1, y0, y1)
    hit = _STREET_DISTRIBUTIONS.get(key)
    if hit is not None:  # (the entry holds cx and cy: no other array can have their ids)
        return hit[2], hit[3]
    lengths = np.empty(cx.size + cy.size)
    lengths[: cx.size] = y1 - y0
    lengths[cx.size :] = x1 - x0
    # rng.choice(lengths.size, size=n, p=p) without its checks of p: the same cumulative
    # distribution and the same uniform draws (one rng.random(n)), so the same streets
    cdf = (lengths / lengths.sum()).cumsum()
    cdf /= cdf[-1]
    centres = np.concatenate([cx, cy])
    cdf.setflags(write=False)
    centres.setflags(write=False)
    if len(_STREET_DISTRIBUTIONS) >= 64:  # cities of many street layouts: start again
        _STREET_DISTRIBUTIONS.clear()
    _STREET_DISTRIBUTIONS[key] = (cx, cy, cdf, centres)
    return cdf, centres


_NO_BOXES = np.zeros((0, 3))
_NO_BOXES.setflags(write=False)

_DIAG3 = np.arange(3)
"""Indices of a 3 x 3 matrix's diagonal."""


def _world_motion(
    pos0: FloatArray,
    vel0: FloatArray,
    cmd: FloatArray,
    kin: KinematicsConfig,
    lo: FloatArray,
    hi: FloatArray,
    buildings: Any,
) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """One motion step of every UAV: ``pos1, vel1`` (N, 3), ``hit`` and ``sep`` (N,).

    :func:`~coopnav_env.sim.swarm.step_kinematics` of the commands ``cmd`` (N, 3), the fence
    (positions clipped to ``[lo, hi]`` (2,) east-north, the velocity across a fence zeroed),
    the swept collisions with ``buildings`` (a UAV that hits one stays where it was, at rest)
    and the separation violations of the new positions, in one compiled call
    (:func:`coopnav_env.sim._kernels.world_motion`). A file city's extruded polygons collide
    through their own :meth:`swept_collisions` after it.
    """
    if cmd.shape != pos0.shape:
        raise ValueError(f"cmd must have shape {pos0.shape}, got {cmd.shape}")
    if not np.all(np.isfinite(cmd)):
        raise ValueError("cmd must be finite")
    polygons = not isinstance(buildings, Buildings)  # a file city's extruded polygons
    r = kin.uav_radius_m
    limits = (
        float(kin.max_speed_mps),
        float(kin.max_accel_mps2 * kin.dt_s),
        float(kin.dt_s),
        float(kin.altitude_min_m),
        float(kin.altitude_max_m),
        float(r),
        float(kin.min_separation_m),
    )
    boxes = (_NO_BOXES, _NO_BOXES) if polygons else (buildings.min_m, buildings.max_m)
    pos1, vel1, hit, sep = _sim_kernels.world_motion(
        pos0, vel0, np.ascontiguousarray(cmd), limits, (lo, hi), boxes
    )
    if polygons:  # the motion above met no building: collide with the polygons
        hit = buildings.swept_collisions(pos0, pos1, r)
        pos1[hit] = pos0[hit]
        vel1[hit] = 0.0
        sep = _sim_kernels.separation_violations(pos1, float(kin.min_separation_m))
    return pos1, vel1, hit, sep


def _file_city_start_goal(
    city: FileCity,
    rng: np.random.Generator,
    config: ScenarioConfig,
    start_pos_enu_m: ArrayLike | None,
    goal_enu_m: ArrayLike | None,
) -> tuple[FloatArray, FloatArray]:
    """True start positions (N, 3) and goal (3,) in a file city's free space.

    256 candidate points are drawn in the reachable free space
    (:meth:`~coopnav_env.sim.file_city.FileCity.random_street_points`). The formation
    (:func:`formation_offsets`, ``formation_spacing_m`` apart, up to one spacing across) is
    centred on the first candidate (or on ``city_start_lat_lon``) where every UAV lies in the
    free space and at least its radius plus one spacing from every wall (failing that, its
    radius plus 1 m), laid along East, else along North; failing that, as a single file. The goal is
    the first later candidate at least ``goal_distance_min_m`` from the start (the farthest if
    none is), or ``city_goal_lat_lon``.
    """
    cfg = config
    n = cfg.n_uavs
    kin = cfg.kinematics
    cand = city.random_street_points(rng, 256, margin_m=0.0)[:, :2]
    if start_pos_enu_m is None:
        if cfg.city_start_lat_lon is not None:
            centres = city.lat_lon_to_xy(*cfg.city_start_lat_lon)[None, :]
        else:
            centres = cand
        pos = None
        tries = [
            (half_width, clear)
            for half_width in (cfg.formation_spacing_m, 0.0)
            # every UAV a spacing plus its radius clear of the walls where possible, else 1 m
            for clear in (cfg.formation_spacing_m + kin.uav_radius_m, kin.uav_radius_m + 1.0)
        ]
        for half_width, clear in tries:
            off = formation_offsets(
                n,
                cfg.formation_spacing_m,
                half_width,
                cfg.start_altitude_m,
                kin.altitude_min_m + kin.uav_radius_m,
                kin.altitude_max_m - kin.uav_radius_m,
            )
            for c in centres:
                for along, across in ((0, 1), (1, 0)):
                    xy = np.empty((n, 2))
                    xy[:, along], xy[:, across] = c[along] + off[:, 0], c[across] + off[:, 1]
                    if city.is_free_xy(xy).all():
                        trial = np.column_stack([xy, off[:, 2]])
                        if not city.buildings.swept_collisions(trial, trial, clear).any():
                            pos = trial
                            break
                if pos is not None:
                    break
            if pos is not None:
                break
        if pos is None:
            raise ValueError(
                f"no room for a formation of {n} UAVs {cfg.formation_spacing_m:g} m apart in "
                f"the free space of {city.source} at the start"
            )
    else:
        pos = np.array(start_pos_enu_m, dtype=float)
        if pos.shape != (n, 3) or not np.all(np.isfinite(pos)):
            raise ValueError(f"start_pos_enu_m must be finite with shape ({n}, 3)")
    if goal_enu_m is not None:
        goal = np.array(goal_enu_m, dtype=float)
        if goal.shape != (3,) or not np.all(np.isfinite(goal)):
            raise ValueError("goal_enu_m must be finite with shape (3,)")
    elif cfg.city_goal_lat_lon is not None:
        goal = np.r_[city.lat_lon_to_xy(*cfg.city_goal_lat_lon), cfg.start_altitude_m]
    else:
        centre = pos[:, :2].mean(axis=0)
        dist = np.hypot(*(cand[1:] - centre).T)
        ok = dist >= cfg.goal_distance_min_m
        if not np.any(ok):
            warnings.warn(
                f"{city.source}: no free point is goal_distance_min_m from this start; the goal "
                "is the farthest one drawn, nearer than goal_distance_min_m (lower it, or give "
                "city_goal_lat_lon)",
                stacklevel=2,
            )
        pick = int(np.argmax(ok)) if np.any(ok) else int(np.argmax(dist))
        goal = np.r_[cand[1 + pick], cfg.start_altitude_m]
    return pos, goal


def _place_formation(
    city: City, centre_xy: FloatArray, north_south: bool, config: ScenarioConfig
) -> FloatArray:
    """True start positions (N, 3) of a formation centred on a street point, along the street."""
    kin = config.kinematics
    margin = kin.uav_radius_m + 1.0
    half_width = max(float(city.street_width_m) / 2.0 - margin, 0.0)
    off = formation_offsets(
        config.n_uavs,
        config.formation_spacing_m,
        half_width,
        config.start_altitude_m,
        kin.altitude_min_m + kin.uav_radius_m,
        kin.altitude_max_m - kin.uav_radius_m,
    )
    x0, x1, y0, y1 = city.extent_m
    along = off[:, 0].tolist()
    a_lo, a_hi = min(along), max(along)
    # np.clip of one number: the larger of it and the low bound, then the smaller of that
    # and the high bound
    pos = np.empty((off.shape[0], 3))
    if north_south:
        c = min(max(float(centre_xy[1]), y0 + margin - a_lo), y1 - margin - a_hi)
        pos[:, 0] = centre_xy[0] + off[:, 1]
        pos[:, 1] = c + off[:, 0]
    else:
        c = min(max(float(centre_xy[0]), x0 + margin - a_lo), x1 - margin - a_hi)
        pos[:, 0] = c + off[:, 0]
        pos[:, 1] = centre_xy[1] + off[:, 1]
    pos[:, 2] = off[:, 2]
    return pos


# --------------------------------------------------------------------------------------------
# one epoch
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Epoch:
    """Everything that happened at one epoch (ENU [m] unless stated; N UAVs, S satellites).

    Attributes
    ----------
    t_s : float
        GNSS time [s] (seconds after the constellation's reference epoch).
    pos_enu_m, vel_enu_mps : ndarray, shape (N, 3)
        True positions [m] and velocities [m/s].
    goal_enu_m : ndarray, shape (3,)
        Centre of the goal area [m].
    sv_az_deg, sv_el_deg : ndarray, shape (S,)
        Satellite azimuth and elevation at the origin [deg]. Only the ``S`` satellites above
        the elevation cut-off appear in the per-satellite arrays.
    system : ndarray of int, shape (S,)
        Constellation index into ``SYSTEMS``.
    sv_index : ndarray of int, shape (S,)
        Index of each satellite in the world's constellation (``UrbanWorld.constellation``).
    los : ndarray of bool, shape (N, S)
        Line of sight (not blocked by a building).
    received : ndarray of bool, shape (N, S)
        Satellites whose pseudorange the UAV uses (line of sight or NLOS, channel limit;
        with ``nlos_exclusion="map"``, not those in ``map_excluded``).
    nlos : ndarray of bool, shape (N, S)
        Received through a reflection (biased; unknown to the navigation).
    n_above_mask : int
        ``S``: satellites above the elevation cut-off (what an open-sky receiver would see).
    n_sats : ndarray of int, shape (N,)
        Satellites received by each UAV.
    n_sats_swarm : ndarray of int, shape (N,)
        Distinct satellites received by the UAV or by a UAV in relative range of it.
    rel_enu_m : ndarray, shape (N, N, 3)
        Measured relative positions, ``rel[b, q] ~ pos[q] - pos[b]`` [m]; 0 where unavailable.
    rel_available : ndarray of bool, shape (N, N)
        Relative measurement available (within range; False on the diagonal).
    standalone_pos_enu_m, coop_pos_enu_m, nav_pos_enu_m : ndarray, shape (N, 3)
        Standalone fix, cooperative fix (NaN where not OK) and the estimate used [m].
    standalone_cov_enu_m2, coop_cov_enu_m2, nav_cov_enu_m2 : ndarray, shape (N, 3, 3)
        Their covariances in ENU [m^2]; the cooperative one is ``H_p`` (Eq. 19-23).
    standalone_status, coop_status : ndarray of int, shape (N,)
        :class:`~coopnav_env.nav.NavStatus` of each fix, as the solver reported it.
    standalone_rejected, coop_rejected : ndarray of bool, shape (N,)
        The solver reported OK but the integrity gate rejected the fix (predicted 3-D sigma
        above ``max_fix_sigma_m``); its position and covariance are NaN like a missing fix.
    nav_source : ndarray of int, shape (N,)
        :class:`NavSource` of the estimate used.
    centroid_uav : int
        UAV of the shared centroid, or -1 when every UAV is its own centroid.
    collided : ndarray of bool, shape (N,)
        The UAV hit a building during this step (it is stopped where the step started).
    separation_violation : ndarray of bool, shape (N,)
        Another UAV is closer than the minimum separation.
    out_of_contact : ndarray of bool, shape (N,)
        No other UAV in relative-sensing range (always False for a single UAV).
    n_iter_standalone, n_iter_coop : int
        Gauss-Newton iterations run by the two solvers (1-2 when warm-started).
    next_waypoint : ndarray of int, shape (N,)
        Index into ``UrbanWorld.route_xy_m`` of each UAV's next waypoint, after this epoch's
        update from the estimates used.
    hpl_m, vpl_m : ndarray, shape (N,), or None
        With ``integrity`` on: horizontal and vertical protection levels of the estimate
        used [m] (inf: not available, dead reckoning included); None otherwise.
    integrity_status : ndarray of int, shape (N,), or None
        :class:`~coopnav_env.nav.IntegrityStatus` of the fix used (``NO_FIX`` for dead
        reckoning); None with ``integrity="off"``.
    fault_detected : ndarray of bool, shape (N,), or None
        The UAV's cooperative or standalone test detected a fault this epoch.
    fde_excluded : ndarray of int, shape (N,), or None
        Pseudoranges excluded from the fix used.
    map_excluded : ndarray of bool, shape (N, S), or None
        With ``nlos_exclusion="map"``: satellites received but not used because the city
        model predicts they may be blocked (not in ``received``); None otherwise.
    """

    t_s: float
    pos_enu_m: FloatArray
    vel_enu_mps: FloatArray
    goal_enu_m: FloatArray
    sv_az_deg: FloatArray
    sv_el_deg: FloatArray
    system: np.ndarray
    sv_index: np.ndarray
    los: BoolArray
    received: BoolArray
    nlos: BoolArray
    n_above_mask: int
    n_sats: np.ndarray
    n_sats_swarm: np.ndarray
    rel_enu_m: FloatArray
    rel_available: BoolArray
    standalone_pos_enu_m: FloatArray
    standalone_cov_enu_m2: FloatArray
    standalone_status: np.ndarray
    coop_pos_enu_m: FloatArray
    coop_cov_enu_m2: FloatArray
    coop_status: np.ndarray
    nav_pos_enu_m: FloatArray
    nav_cov_enu_m2: FloatArray
    nav_source: np.ndarray
    centroid_uav: int
    collided: BoolArray
    separation_violation: BoolArray
    out_of_contact: BoolArray
    n_iter_standalone: int
    n_iter_coop: int
    standalone_rejected: BoolArray
    coop_rejected: BoolArray
    next_waypoint: np.ndarray
    hpl_m: FloatArray | None = None
    vpl_m: FloatArray | None = None
    integrity_status: np.ndarray | None = None
    fault_detected: BoolArray | None = None
    fde_excluded: np.ndarray | None = None
    map_excluded: BoolArray | None = None

    @property
    def n_uavs(self) -> int:
        """Number of UAVs N."""
        return int(self.pos_enu_m.shape[0])

    @property
    def coop_ok(self) -> BoolArray:
        """Valid cooperative fix (solver OK and accepted by the integrity gate), shape (N,)."""
        return (self.coop_status == NavStatus.OK) & ~self.coop_rejected

    @property
    def standalone_ok(self) -> BoolArray:
        """Valid standalone fix (solver OK and accepted by the integrity gate), shape (N,)."""
        return (self.standalone_status == NavStatus.OK) & ~self.standalone_rejected

    @property
    def coop_error_m(self) -> FloatArray:
        """3-D error of the cooperative fix [m], shape (N,); NaN without a valid fix."""
        return np.linalg.norm(self.coop_pos_enu_m - self.pos_enu_m, axis=1)

    @property
    def standalone_error_m(self) -> FloatArray:
        """3-D error of the standalone fix [m], shape (N,); NaN without a valid fix."""
        return np.linalg.norm(self.standalone_pos_enu_m - self.pos_enu_m, axis=1)

    @property
    def nav_error_m(self) -> FloatArray:
        """3-D error of the estimate used [m], shape (N,); always finite."""
        return np.linalg.norm(self.nav_pos_enu_m - self.pos_enu_m, axis=1)

    @property
    def nav_sigma_enu_m(self) -> FloatArray:
        """Predicted standard deviation per ENU axis of the estimate used [m], shape (N, 3)."""
        return np.sqrt(np.clip(np.einsum("nii->ni", self.nav_cov_enu_m2), 0.0, None))

    @property
    def goal_distance_m(self) -> FloatArray:
        """True horizontal distance of each UAV to the goal centre [m], shape (N,)."""
        d = self.pos_enu_m[:, :2] - self.goal_enu_m[None, :2]
        return np.hypot(d[:, 0], d[:, 1])


# --------------------------------------------------------------------------------------------
# the world
# --------------------------------------------------------------------------------------------


class UrbanWorld:
    """The urban world of one swarm: state plus the epoch pipeline of the module docstring.

    The world holds the episode state (city, true positions and velocities, clocks, previous
    estimates) and advances it with :meth:`step`; all randomness comes from the generator
    passed to :meth:`reset` and :meth:`step`. Instances pickle (the state is plain arrays and
    frozen dataclasses).

    Parameters
    ----------
    config : ScenarioConfig
        Any :class:`ScenarioConfig` (subclasses such as the environment's config included).
    city : City, optional
        A fixed city for every episode, overriding ``config.city`` (tests, hand-made maps).
    """

    def __init__(self, config: ScenarioConfig, city: City | None = None) -> None:
        if not isinstance(config, ScenarioConfig):
            raise ValueError(f"config must be a ScenarioConfig, got {type(config).__name__}")
        if city is not None and not isinstance(city, City):
            raise ValueError(f"city must be a City or None, got {type(city).__name__}")
        self.config = config
        self.fixed_city = city
        self.constellation = world_constellation(config)
        self._cached_constellation = self.constellation  # the one the sky cache keys stand for
        self.origin_ecef_m = geodetic_to_ecef(config.lat_deg, config.lon_deg, config.alt_m)
        self.rot_enu = enu_rotation(config.lat_deg, config.lon_deg)  # d_enu = R d_ecef
        self.city: City | None = None
        self.last: Epoch | None = None

    def _sky(self, t_s: float) -> _SkyEpoch:
        """The satellites above the cut-off at ``t_s`` (:func:`_sky_epoch`, cached).

        The cache key names the constellation of ``config.systems`` and ``config.constellation``
        (a RINEX sky by its file's digest); a world whose ``constellation`` was replaced
        computes its sky without the cache.
        """
        cfg = self.config
        if self.constellation is not self.__dict__.get("_cached_constellation"):
            return _sky_epoch(self.constellation, self.origin_ecef_m, cfg.elevation_mask_deg, t_s)
        sky_id = getattr(self.constellation, "digest", "nominal")
        origin = (cfg.lat_deg, cfg.lon_deg, cfg.alt_m)
        key = (cfg.systems, sky_id, *origin, cfg.elevation_mask_deg, t_s)
        return _SKY_CACHE.get(key, self.constellation, self.origin_ecef_m, self._times_ahead(t_s))

    def _times_ahead(self, t_s: float) -> list[float] | None:
        """The epochs after ``t_s`` that an episode reaching ``t_s`` meets next (``t + dt_s``
        added as :meth:`step` adds it), inside a navigation file's coverage; None for a
        nominal sky (its times repeat from episode to episode: the cache holds them)."""
        sky = self.constellation
        if not isinstance(sky, BroadcastConstellation):
            return None
        end = sky.coverage_s[1]
        dt = self.config.dt_s
        times: list[float] = []
        t = t_s
        for _ in range(SKY_LOOKAHEAD_EPOCHS - 1):
            t = t + dt
            if not t <= end:
                break
            times.append(t)
        return times

    def map_line_of_sight(
        self,
        points: np.ndarray,
        cov: np.ndarray | None = None,
        *,
        margin_sigma: float = 0.0,
        max_margin_m: float = 0.0,
    ) -> BoolArray:
        """``(P, S)`` bool: the satellites above the mask at ``t_s`` that the city model puts
        in line of sight from each of ``points`` ``(P, 3)`` [m] by
        :func:`~coopnav_env.sim.map_aided.predicted_line_of_sight` (covariances ``cov``
        ``(P, 3, 3)``, default none; the margin in sigma and its cap; the flight band), none
        from a point inside a building. What a receiver that has the city map can predict:
        the column heuristics' route choice
        (:func:`coopnav_env.agents.heuristics.poor_geometry_share`) uses it."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        cov = np.zeros((pts.shape[0], 3, 3)) if cov is None else cov
        kin = self.config.kinematics
        los = predicted_line_of_sight(
            self.city.buildings,
            self._sky(self.t_s).directions,
            pts,
            cov,
            margin_sigma=margin_sigma,
            max_margin_m=max_margin_m,
            altitude_band_m=(kin.altitude_min_m, kin.altitude_max_m),
        )
        return los & ~is_inside_building(self.city.buildings, pts)[:, None]

    # ---- frames -----------------------------------------------------------------------------

    def enu_to_ecef(self, pos_enu_m: np.ndarray) -> np.ndarray:
        """ENU (..., 3) of this world's origin to ECEF [m] (NaN propagates)."""
        return self.origin_ecef_m + pos_enu_m @ self.rot_enu

    def ecef_to_enu(self, pos_ecef_m: np.ndarray) -> np.ndarray:
        """ECEF (..., 3) to this world's ENU [m] (NaN propagates)."""
        return (pos_ecef_m - self.origin_ecef_m) @ self.rot_enu.T

    def cov_ecef_to_enu(self, cov_ecef_m2: np.ndarray) -> np.ndarray:
        """Covariances (..., 3, 3) from ECEF to ENU [m^2] (NaN propagates)."""
        return self.rot_enu @ cov_ecef_m2 @ self.rot_enu.T

    def sky_and_walls(
        self, pos_enu_m: np.ndarray, az_deg: np.ndarray
    ) -> tuple[FloatArray, FloatArray]:
        """Skyline elevation [deg] and nearest-wall distance [m] along each azimuth ``az_deg``
        (A,) from positions of this world's swarm (``Epoch.pos_enu_m``, finite by
        construction), ``(n, A)`` each: :meth:`City.sky_and_walls` without re-checking the
        positions (the numbers are the same, bit for bit)."""
        b = self.city.buildings
        if not isinstance(b, Buildings):  # extruded polygons (sim.file_city)
            return self.city.sky_and_walls(pos_enu_m, az_deg)
        tan_max, walls = _sim_kernels.sky_and_walls(
            np.ascontiguousarray(pos_enu_m), ray_directions(az_deg), b.min_m, b.max_m
        )
        return np.degrees(np.arctan(tan_max)), walls

    def _relative_ecef(
        self,
        rel_enu_m: np.ndarray,
        var_m2: np.ndarray,
        available: np.ndarray,
        row: int | None = None,
    ) -> RelativePositions:
        """:meth:`RelativePositions.from_enu` at the origin for the isotropic relative sensing.

        ``var_m2`` (N, N) is the per-axis variance of each pair (``cov_enu = var I``); its
        ECEF covariance is ``R^T (var I) R = var I``, so only the vectors are rotated (as
        matmuls). With ``row = a`` only the measurements relative to UAV ``a`` are kept (all a
        shared centroid at ``a`` needs); the other pairs are marked unavailable.
        """
        r = self.rot_enu
        if row is None:
            cov = var_m2[:, :, None, None] * np.eye(3)
            return RelativePositions._trusted(rel_enu_m @ r, cov, available)
        n = available.shape[0]
        rel = np.zeros((n, n, 3))
        cov = np.zeros((n, n, 3, 3))
        avail = np.zeros((n, n), dtype=bool)
        rel[row] = rel_enu_m[row] @ r
        cov[row] = var_m2[row][:, None, None] * np.eye(3)
        avail[row] = available[row]
        return RelativePositions._trusted(rel, cov, avail)

    def _centroids(self, n_sats: np.ndarray, avail: BoolArray) -> tuple[str | int, BoolArray, int]:
        """The epoch's centroid (``"self"``, or the shared UAV receiving the most satellites),
        which UAVs have the relative link a cooperative fix needs, and ``Epoch.centroid_uav``."""
        n = self.config.n_uavs
        if self.config.centroid_mode == "shared" or n == 1:
            a = int(np.argmax(n_sats))
            linked = avail[a].copy()
            linked[a] = True
            return a, linked, a
        # a UAV out of range of every other one navigates standalone
        return "self", avail.any(axis=1) | (n == 1), -1

    def _relative_rows(
        self, rel_enu_m: np.ndarray, var_m2: np.ndarray, available: BoolArray, centroid: str | int
    ) -> tuple[np.ndarray, np.ndarray, BoolArray]:
        """The relative positions (rotated to ECEF by numpy matmuls), per-axis variances and
        links the cooperative solve of ``centroid`` uses: all pairs ``(N, N)`` for ``"self"``,
        UAV ``a``'s row ``(N,)`` for a shared centroid ``a``."""
        if isinstance(centroid, str):
            return rel_enu_m @ self.rot_enu, var_m2, available
        return rel_enu_m[centroid] @ self.rot_enu, var_m2[centroid], available[centroid]

    def _solve_cooperative(
        self,
        obs: GnssObservations,
        rel_enu_m: np.ndarray,
        var_m2: np.ndarray,
        available: np.ndarray,
        centroid: str | int,
        x0_ecef_m: np.ndarray,
    ) -> CooperativeSolution:
        """The cooperative fixes of an epoch (``centroid``: ``"self"`` or the shared UAV).

        :func:`solve_cooperative` on :meth:`_relative_ecef`'s relative positions; with the
        exact covariance, through its one-call compiled form
        (``coopnav_env.nav.cooperative._solve_isotropic``: same kernels, same arguments, same
        result) on the same rotated vectors.
        """
        cfg = self.config
        if cfg.covariance == "exact":
            rel_ecef, var, avail = self._relative_rows(rel_enu_m, var_m2, available, centroid)
            co = _solve_isotropic(
                obs, rel_ecef, var, avail, centroid, cfg.transfer, x0_ecef_m, cfg.nav_max_iter
            )
            if co is not None:
                return co
        row = None if isinstance(centroid, str) else centroid
        return solve_cooperative(
            obs,
            self._relative_ecef(rel_enu_m, var_m2, available, row=row),
            transfer=cfg.transfer,
            centroid=centroid,
            covariance=cfg.covariance,
            x0_ecef_m=x0_ecef_m,
            max_iter=cfg.nav_max_iter,
        )

    # ---- episode ----------------------------------------------------------------------------

    def reset(
        self,
        rng: np.random.Generator,
        *,
        start_pos_enu_m: ArrayLike | None = None,
        goal_enu_m: ArrayLike | None = None,
    ) -> Epoch:
        """Start an episode: city, formation, goal, clocks, first epoch.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of every random draw of the episode.
        start_pos_enu_m : array_like, shape (N, 3), optional
            True start positions [m] instead of a random formation on a street.
        goal_enu_m : array_like, shape (3,), optional
            Goal centre [m] instead of a random street point.

        Returns
        -------
        Epoch
            The first epoch (cold-started solvers).
        """
        self._begin_episode(rng, start_pos_enu_m, goal_enu_m)
        return self._first_epoch(rng)

    def _first_epoch(self, rng: np.random.Generator) -> Epoch:
        """:meth:`reset` after :meth:`_begin_episode`: the episode's first epoch."""
        zeros = np.zeros(self.config.n_uavs, dtype=bool)
        self.last = self._epoch(rng, zeros, zeros)
        return self.last

    def _begin_episode(
        self,
        rng: np.random.Generator,
        start_pos_enu_m: ArrayLike | None = None,
        goal_enu_m: ArrayLike | None = None,
    ) -> None:
        """:meth:`reset` up to its first epoch: city, clocks, formation, goal, route, priors."""
        cfg = self.config
        n = cfg.n_uavs
        self.city = self.fixed_city if self.fixed_city is not None else make_city(cfg, rng)
        city = self.city
        self.t_s = episode_start_s(cfg, self.constellation, rng)
        margin = cfg.kinematics.uav_radius_m + 1.0
        if isinstance(city, FileCity):
            pos, goal = _file_city_start_goal(city, rng, cfg, start_pos_enu_m, goal_enu_m)
        else:
            pos, goal = self._street_start_goal(city, rng, margin, start_pos_enu_m, goal_enu_m)
        self.goal_enu_m = goal
        self.route_xy_m = street_route(city, pos[:, :2].mean(axis=0), goal[:2])
        self.route_tail_m = route_tail_lengths_m(self.route_xy_m)  # route left after each point
        self.next_wp = np.full(n, min(1, self.route_xy_m.shape[0] - 1), dtype=np.int64)
        self.start_enu_m = pos.copy()
        self.pos_enu_m = pos
        self.vel_enu_mps = np.zeros((n, 3))
        self.clock_bias_m = draw_clock_biases(rng, n, len(SYSTEMS), cfg.clock_sigma_m)
        if "GAL" in cfg.systems:  # Galileo's clock drawn after the others' (theirs unchanged)
            gal_clock_m = draw_clock_biases(rng, n, 1, cfg.clock_sigma_m)
            self.clock_bias_m = np.concatenate([self.clock_bias_m, gal_clock_m], axis=1)
        # prior of the dead-reckoning fallback at the first epoch: the known launch position
        self.nav_pos_enu_m = pos.copy()
        self.nav_cov_enu_m2 = np.zeros((n, 3, 3))
        self.nav_cov_enu_m2[:, _DIAG3, _DIAG3] = 1.0 * cfg.start_prior_sigma_m**2
        self._warm = False

    def _street_start_goal(
        self,
        city: City,
        rng: np.random.Generator,
        margin: float,
        start_pos_enu_m: ArrayLike | None,
        goal_enu_m: ArrayLike | None,
    ) -> tuple[FloatArray, FloatArray]:
        """True start positions (N, 3) and goal (3,) on a street city's streets."""
        cfg = self.config
        n = cfg.n_uavs
        cand, ns = _street_frames(city, rng, 256, margin)
        if start_pos_enu_m is None:
            pos = _place_formation(city, cand[0], bool(ns[0]), cfg)
        else:
            pos = np.array(start_pos_enu_m, dtype=float)
            if pos.shape != (n, 3) or not np.all(np.isfinite(pos)):
                raise ValueError(f"start_pos_enu_m must be finite with shape ({n}, 3)")
        if goal_enu_m is None:
            centre = pos[:, :2].mean(axis=0)
            # the first candidate far enough from the formation, else the farthest
            pick = _sim_kernels.far_candidate(cand[1:], centre, float(cfg.goal_distance_min_m))
            goal = np.array([*cand[1 + pick].tolist(), float(cfg.start_altitude_m)])
        else:
            goal = np.array(goal_enu_m, dtype=float)
            if goal.shape != (3,) or not np.all(np.isfinite(goal)):
                raise ValueError("goal_enu_m must be finite with shape (3,)")
        return pos, goal

    def step(self, cmd: ArrayLike, rng: np.random.Generator) -> Epoch:
        """Advance one time step with velocity commands ``cmd`` (N, 3) in [-1, 1] (clipped).

        Returns
        -------
        Epoch
        """
        if self.last is None:
            raise RuntimeError("UrbanWorld.step called before reset")
        cfg = self.config
        kin = cfg.kinematics
        cmd = np.asarray(cmd, dtype=float)
        pos0, vel0 = self.pos_enu_m, self.vel_enu_mps
        # virtual fence at the city extent
        x0, x1, y0, y1 = self.city.extent_m
        r = kin.uav_radius_m
        lo = np.array([x0 + r, y0 + r])
        hi = np.array([x1 - r, y1 - r])
        pos1, vel1, hit, sep = _world_motion(pos0, vel0, cmd, kin, lo, hi, self.city.buildings)
        self.pos_enu_m, self.vel_enu_mps = pos1, vel1
        self.t_s = self.t_s + cfg.dt_s
        self.last = self._epoch(rng, hit, sep)
        return self.last

    # ---- measurements and navigation ---------------------------------------------------------

    def _epoch(self, rng: np.random.Generator, collided: BoolArray, sep: BoolArray) -> Epoch:
        cfg = self.config
        n = cfg.n_uavs
        pos = self.pos_enu_m
        dt = cfg.dt_s

        # satellites and visibility
        # Only the satellites above the cut-off (at the origin) enter the arrays: the others
        # can never be received, and dropping them makes everything downstream cheaper.
        sky = self._sky(self.t_s)
        sv_index, system, az, el = sky.sv_index, sky.system, sky.az, sky.el
        los = _trace_line_of_sight(self.city.buildings, pos, sky.directions)
        if cfg.nlos_probability > 0.0:
            received, bias = draw_nlos(
                rng, ~los, cfg.nlos_probability, cfg.nlos_bias_mean_m, cfg.nlos_bias_floor_m
            )
        else:
            received, bias = los, None
        if cfg.max_sats is not None:
            received = select_highest(np.broadcast_to(el, received.shape), received, cfg.max_sats)

        # measurements and navigation
        # warm start: the previous estimates moved by the velocity; at the first epoch of an
        # episode, the known launch positions
        pred_enu = self.nav_pos_enu_m + self.vel_enu_mps * dt if self._warm else self.nav_pos_enu_m
        if cfg.dead_reckoning_noise and self._warm:  # measured velocity: truth + noise
            pred_enu = pred_enu + rng.normal(0.0, cfg.dead_reckoning_sigma_mps * dt, (n, 3))
        dr_var = (cfg.dead_reckoning_sigma_mps * dt) ** 2 * (1.0 if self._warm else 0.0)
        map_excluded = None
        if cfg.nlos_exclusion == "map":  # 3DMA: not used where the city model predicts NLOS
            kin = cfg.kinematics
            predicted = predicted_line_of_sight(
                self.city.buildings,
                sky.directions,
                pred_enu,
                self.nav_cov_enu_m2 + np.eye(3) * dr_var,
                margin_sigma=cfg.nlos_exclusion_margin_sigma,
                max_margin_m=cfg.nlos_exclusion_max_margin_m,
                altitude_band_m=(kin.altitude_min_m, kin.altitude_max_m),
            )
            map_excluded = received & ~predicted
            received = received & predicted
        nlos = received & ~los
        fused = cfg.covariance == "exact" and sky.grouped
        navigate = self._navigate_fused if fused else self._navigate
        (
            rel_enu,
            avail,
            n_sats,
            centroid_uav,
            sa_status,
            sa_n_iter,
            co_n_iter,
            (sa_pos, sa_cov, co_pos, co_cov, co_status, source, nav_pos, nav_cov, sa_rej, co_rej),
            next_wp,
            n_swarm,
            integrity,
        ) = navigate(rng, pos, sky, received, bias, pred_enu, dr_var)
        self.nav_pos_enu_m, self.nav_cov_enu_m2 = nav_pos, nav_cov
        self._warm = True
        self.next_wp = next_wp
        return Epoch(
            t_s=float(self.t_s),
            pos_enu_m=pos.copy(),
            vel_enu_mps=self.vel_enu_mps.copy(),
            goal_enu_m=self.goal_enu_m.copy(),
            sv_az_deg=az,
            sv_el_deg=el,
            system=system,
            sv_index=sv_index,
            los=los,
            received=received,
            nlos=nlos,
            n_above_mask=int(sv_index.size),
            n_sats=n_sats,
            n_sats_swarm=n_swarm,
            rel_enu_m=rel_enu,
            rel_available=avail,
            standalone_pos_enu_m=sa_pos,
            standalone_cov_enu_m2=sa_cov,
            standalone_status=sa_status,
            coop_pos_enu_m=co_pos,
            coop_cov_enu_m2=co_cov,
            coop_status=np.asarray(co_status, dtype=np.int64),
            nav_pos_enu_m=nav_pos,
            nav_cov_enu_m2=nav_cov,
            nav_source=source,
            centroid_uav=centroid_uav,
            collided=np.asarray(collided, dtype=bool),
            separation_violation=np.asarray(sep, dtype=bool),
            out_of_contact=~avail.any(axis=1) if n > 1 else np.zeros(n, dtype=bool),
            n_iter_standalone=int(sa_n_iter),
            n_iter_coop=int(co_n_iter),
            standalone_rejected=sa_rej,
            coop_rejected=co_rej,
            next_waypoint=self.next_wp.copy(),
            **({} if integrity is None else dict(zip(_INTEGRITY_FIELDS, integrity))),
            map_excluded=map_excluded,
        )

    def _navigate(self, rng, pos, sky, received, bias, pred_enu, dr_var):
        """Pseudoranges, relative sensing, both solvers, the estimate selection and the
        waypoints of one epoch, function by function (the definition of
        :meth:`_navigate_fused`). Returns ``rel_enu, avail, n_sats, centroid_uav, sa_status,
        sa_n_iter, co_n_iter, the selection's ten arrays, next_wp, n_swarm, integrity``
        (``integrity``: None, or with ``config.integrity`` on the FDE of both solutions by
        :func:`coopnav_env.sim._integrity.modular_fde` before the selection and the figures
        of the estimates used)."""
        cfg = self.config
        n = cfg.n_uavs
        rx_ecef = self.enu_to_ecef(pos)
        # simulate_pseudoranges without re-validating the world's own arrays
        pr = _simulate_pseudoranges(
            rng,
            rx_ecef,
            sky.sv_ecef,
            sky.system_idx,
            received,
            cfg.error_model,
            self.clock_bias_m,
            bias,
        )
        obs = GnssObservations._trusted_from_epoch(pr, n_systems=self.clock_bias_m.shape[1])
        rel_enu, rel_var, avail = _measure_relative(rng, pos, cfg.relative_sensing)
        x0 = self.enu_to_ecef(pred_enu)

        sa = solve_standalone(obs, x0, max_iter=cfg.nav_max_iter)
        n_sats = received.sum(axis=1)
        centroid, linked, centroid_uav = self._centroids(n_sats, avail)
        x0_co = x0 if isinstance(centroid, str) else x0[centroid]
        co = self._solve_cooperative(obs, rel_enu, rel_var, avail, centroid, x0_co)
        if cfg.integrity != "off":  # the FDE of the fused path, by the public functions
            rows = self._relative_rows(rel_enu, rel_var, avail, centroid)
            sa, co, used = _integrity.modular_fde(self, obs, sa, co, *rows, centroid)

        sel = _select_navigation(self, sa, co, linked, pred_enu, dr_var)
        integrity = used(sel[5]) if cfg.integrity != "off" else None
        next_wp = advance_waypoints(self.route_xy_m, sel[6][:, :2], self.next_wp, cfg.route_reach_m)
        link_or_self = avail | np.eye(n, dtype=bool)
        n_swarm = (link_or_self.astype(np.int64) @ received.astype(np.int64) > 0).sum(axis=1)
        sa_status = np.asarray(sa.status, dtype=np.int64)
        return (
            rel_enu,
            avail,
            n_sats,
            centroid_uav,
            sa_status,
            sa.n_iter,
            co.n_iter,
            sel,
            next_wp,
            n_swarm,
            integrity,
        )

    def _navigate_fused(self, rng, pos, sky, received, bias, pred_enu, dr_var):
        """:meth:`_navigate` in three compiled calls: the receiver geometry (whose errors
        raise here, as in the modular path), relative sensing, then everything else in
        :func:`coopnav_env.sim._kernels.epoch_navigation` (the same kernels on the same
        arguments, so the same results bit for bit). The random draws are those of the
        modular path, in its order; the rotations to ECEF stay numpy matmuls (their rounding
        is numpy's). With ``config.integrity`` on, the call takes the integrity settings
        (``fde``: the FDE of both solutions before the selection, in the same call)."""
        cfg = self.config
        n = cfg.n_uavs
        model = cfg.error_model
        rx_ecef = self.enu_to_ecef(pos)
        sv = sky.sv_ecef
        n_sv = sv.shape[0]
        range_m, _az, el_deg = _range_azimuth_elevation(rx_ecef, sv)
        z_common = rng.standard_normal(n_sv)  # the draws of _simulate_pseudoranges
        z_user = rng.standard_normal((n, n_sv))
        rel_enu, rel_var, avail = _measure_relative(rng, pos, cfg.relative_sensing)
        x0 = self.enu_to_ecef(pred_enu)
        n_sats = received.sum(axis=1)
        centroid, linked, centroid_uav = self._centroids(n_sats, avail)
        rel_b, var_b, avail_b = self._relative_rows(rel_enu, rel_var, avail, centroid)
        if isinstance(centroid, str):
            cen, x0_co = np.arange(n, dtype=np.int64), x0
        else:  # one centroid problem: the kernel takes (B = 1, ...) arrays
            rel_b, var_b, avail_b = rel_b[None], var_b[None], avail_b[None]
            cen, x0_co = np.array([centroid], dtype=np.int64), x0[centroid][None]
        gate = cfg.max_fix_sigma_m
        args = (
            _sim_kernels.Geometry(range_m, el_deg, sv, sky.system_idx, received),
            _sim_kernels.Pseudoranges(
                self.clock_bias_m,
                _iono_factors(model),
                z_common,
                z_user,
                np.zeros((n, n_sv)) if bias is None else np.ascontiguousarray(bias, dtype=float),
                np.full(n_sv, np.nan),
                float(model.sigma_ure_m),
                bool(model.tropo),
                bool(model.differential),
                self.clock_bias_m.shape[1],  # clock states: the systems, Galileo's if flown
            ),
            _sim_kernels.Centroids(
                np.ascontiguousarray(rel_b),
                np.ascontiguousarray(var_b),
                np.ascontiguousarray(avail_b),
                cen,
                np.ascontiguousarray(x0_co),
                cfg.transfer == "ddt",
                linked,
                avail,
            ),
            _sim_kernels.Solving(
                int(cfg.nav_max_iter),
                1e-4,  # tol_m and plausible radii: the solvers' defaults, as _navigate uses them
                *_radius_args(PLAUSIBLE_RADIUS_M),
                gate is not None,
                float(gate) ** 2 if gate is not None else 0.0,
            ),
            _sim_kernels.Prior(
                x0,
                self.origin_ecef_m,
                self.rot_enu,
                np.ascontiguousarray(pred_enu, dtype=np.float64),
                np.ascontiguousarray(self.nav_cov_enu_m2, dtype=np.float64),
                float(dr_var),
            ),
            _sim_kernels.Waypoints(
                np.ascontiguousarray(self.route_xy_m, dtype=np.float64),
                self.next_wp,
                float(cfg.route_reach_m),
            ),
        )
        args = tuple(tuple(a) for a in args)  # plain tuples: numba types them faster
        if cfg.integrity == "off":
            *out, _none = _sim_kernels.epoch_navigation(*args)
            integrity = None
        else:  # with RAIM / FDE between the solvers and the selection
            fde = _integrity.fused_arguments(cfg, received)
            *out, packed = _sim_kernels.epoch_navigation(*args, fde)
            integrity = _integrity.unpack(packed)
        sa_status, sa_n_iter, co_n_iter, sel, next_wp, n_swarm = out
        return (
            rel_enu,
            avail,
            n_sats,
            centroid_uav,
            sa_status,
            sa_n_iter,
            co_n_iter,
            sel,
            next_wp,
            n_swarm,
            integrity,
        )


def _select_navigation(world, sa, co, linked, pred_enu, dr_var):
    """The estimate each UAV uses (compiled :func:`coopnav_env.sim._kernels.select_navigation`).

    Returns the standalone and cooperative fixes in ENU (NaN where not used), the cooperative
    status (``NO_RELATIVE_POSITION`` for an unlinked UAV), the source, the estimate and its
    covariance, and the fixes the integrity gate rejected.
    """
    cfg = world.config
    gate = cfg.max_fix_sigma_m
    fixes = (
        np.ascontiguousarray(sa.status, dtype=np.int64),
        np.ascontiguousarray(sa.pos_ecef_m, dtype=np.float64),
        np.ascontiguousarray(sa.cov_ecef_m2, dtype=np.float64),
        np.ascontiguousarray(co.status, dtype=np.int64),
        np.ascontiguousarray(co.pos_ecef_m, dtype=np.float64),
        np.ascontiguousarray(co.cov_ecef_m2, dtype=np.float64),
    )
    dead_reckoning = (
        np.ascontiguousarray(pred_enu, dtype=np.float64),
        np.ascontiguousarray(world.nav_cov_enu_m2, dtype=np.float64),
        float(dr_var),
    )
    return _sim_kernels.select_navigation(
        fixes,
        np.ascontiguousarray(linked, dtype=bool),
        (gate is not None, float(gate) ** 2 if gate is not None else 0.0),
        (world.origin_ecef_m, world.rot_enu),
        dead_reckoning,
    )


@dataclass(frozen=True, eq=False)
class _SkyEpoch:
    """The satellites above the elevation cut-off at the world's origin at one GNSS time."""

    sv_index: np.ndarray  # (S,) indices into the constellation
    sv_ecef: FloatArray  # (S, 3) positions [m]
    system: np.ndarray  # (S,) constellation of each
    system_idx: np.ndarray  # (S,) the same as intp (what simulate_pseudoranges works with)
    az: FloatArray  # (S,) azimuth at the origin [deg]
    el: FloatArray  # (S,) elevation at the origin [deg]
    directions: SkyDirections  # the same, prepared for line of sight
    grouped: bool  # satellites ordered by constellation (what the solvers' kernels work on)


def _sky_epoch(constellation: Any, origin_ecef_m: np.ndarray, mask_deg: float, t_s: float):
    """Satellite positions and directions at the origin at ``t_s``, the ones above the mask
    (a broadcast sky's satellites with no valid ephemeris at ``t_s``, NaN, are left out)."""
    sv_all = constellation.positions_ecef(t_s)
    known = np.isfinite(sv_all).all(axis=1)
    if not known.all():
        sv_all = np.where(known[:, None], sv_all, 0.0)  # azimuth of the Earth's centre: dropped
    az_all, el_all = azimuth_elevation(origin_ecef_m[None], sv_all)
    sv_index = np.flatnonzero((el_all[0] > mask_deg) & known)
    az, el = az_all[0, sv_index], el_all[0, sv_index]
    sky = _SkyEpoch(
        sv_index=sv_index,
        sv_ecef=sv_all[sv_index],
        system=np.asarray(constellation.system)[sv_index],
        system_idx=np.asarray(constellation.system)[sv_index].astype(np.intp),
        az=az,
        el=el,
        directions=sky_directions(direction_enu(az, el)),
        grouped=bool(np.all(np.diff(np.asarray(constellation.system)[sv_index]) >= 0)),
    )
    for arr in (sky.sv_index, sky.sv_ecef, sky.system, sky.system_idx, sky.az, sky.el):
        arr.setflags(write=False)
    return sky


def _sky_epochs(
    constellation: Any, origin_ecef_m: np.ndarray, mask_deg: float, times_s: list[float]
) -> list[_SkyEpoch]:
    """:func:`_sky_epoch` at each of ``times_s``, with one vectorised evaluation of the
    satellites' orbits, azimuths and elevations for all the times.

    Every value is what :func:`_sky_epoch` gives at that time, bit for bit: the arithmetic is
    element by element (numpy's functions give a value's result wherever it sits in an
    array), and ``tests/sim/test_sky_epochs.py`` checks it over whole navigation files.
    """
    t = np.asarray(times_s, dtype=np.float64)
    sv_all = constellation.positions_ecef(t)  # (n_t, n_sv, 3)
    known = np.isfinite(sv_all).all(axis=2)
    if not known.all():
        sv_all = np.where(known[..., None], sv_all, 0.0)  # azimuth of the Earth's centre: dropped
    n_t, n_sv = known.shape
    az_flat, el_flat = azimuth_elevation(origin_ecef_m[None], sv_all.reshape(-1, 3))
    az_all, el_all = az_flat.reshape(n_t, n_sv), el_flat.reshape(n_t, n_sv)
    dir_all = direction_enu(az_all, el_all)  # (n_t, n_sv, 3)
    system_all = np.asarray(constellation.system)
    skies = []
    for k in range(n_t):
        sv_index = np.flatnonzero((el_all[k] > mask_deg) & known[k])
        system = system_all[sv_index]
        sky = _SkyEpoch(
            sv_index=sv_index,
            sv_ecef=sv_all[k, sv_index],
            system=system,
            system_idx=system.astype(np.intp),
            az=az_all[k, sv_index],
            el=el_all[k, sv_index],
            directions=sky_directions(dir_all[k, sv_index]),
            grouped=bool(np.all(np.diff(system) >= 0)),
        )
        for arr in (sky.sv_index, sky.sv_ecef, sky.system, sky.system_idx, sky.az, sky.el):
            arr.setflags(write=False)
        skies.append(sky)
    return skies


SKY_LOOKAHEAD_EPOCHS: int = 32
"""Epochs of a sky from a navigation file computed at once (:class:`_SkyCache`): the one asked
for and the next ``SKY_LOOKAHEAD_EPOCHS - 1`` of the same episode."""


class _SkyCache:
    """Process-wide cache of :func:`_sky_epoch`, keyed by the sky's settings and the time.

    The satellites' geometry depends only on the constellation, the origin, the cut-off and
    the GNSS time, not on the UAVs or the city; with the default ``t0_random_s = 0`` every
    episode replays the same times, and copies of an environment (vector environments) share
    them. The cached arrays are read-only. At most ``max_size`` entries are kept (the oldest
    goes first); an entry is about 3 kB, so the default bounds the cache to about 6 MB (with a
    random start time, ``t0_random_s > 0``, it rarely hits and only costs the inserts).

    A caller that knows the times that follow (:meth:`get`'s ``times_ahead_s``: the next
    epochs of an episode) has them computed with the one asked for, in one vectorised call
    (:func:`_sky_epochs`): a sky from a navigation file, whose episodes start at times drawn
    at random, then costs a fraction of an evaluation per epoch. Those epochs wait in a
    second store until asked for (then they move to the cache); at most ``max_ahead`` wait
    (the oldest, those of episodes that ended early, go first).
    """

    def __init__(self, max_size: int = 2048, max_ahead: int = 8192) -> None:
        self.max_size = int(max_size)
        self.max_ahead = int(max_ahead)
        self._data: dict[tuple, _SkyEpoch] = {}
        self._ahead: dict[tuple, _SkyEpoch] = {}

    def _insert(self, key: tuple, sky: _SkyEpoch) -> None:
        if len(self._data) >= self.max_size:
            self._data.pop(next(iter(self._data)), None)
        self._data[key] = sky

    def get(
        self,
        key: tuple,
        constellation: Any,
        origin_ecef_m: np.ndarray,
        times_ahead_s: list[float] | None = None,
    ) -> _SkyEpoch:
        """The sky of ``key`` (its last two items: the cut-off [deg] and the time [s]).

        ``times_ahead_s``: times likely asked for next (computed now with this one when it
        is missing).
        """
        hit = self._data.get(key)
        if hit is not None:
            return hit
        hit = self._ahead.pop(key, None)
        if hit is None:
            mask_deg, t_s = key[-2], key[-1]
            if not times_ahead_s:
                hit = _sky_epoch(constellation, origin_ecef_m, mask_deg, t_s)
            else:
                head = key[:-1]
                later = [t for t in times_ahead_s if (*head, t) not in self._data]
                skies = _sky_epochs(constellation, origin_ecef_m, mask_deg, [t_s, *later])
                hit = skies[0]
                for t, sky in zip(later, skies[1:], strict=True):
                    self._ahead[(*head, t)] = sky
                while len(self._ahead) > self.max_ahead:
                    self._ahead.pop(next(iter(self._ahead)), None)
        self._insert(key, hit)
        return hit

    def clear(self) -> None:
        """Drop every entry."""
        self._data.clear()
        self._ahead.clear()


_SKY_CACHE = _SkyCache()
