"""The urban world: buildings, visibility and the UAV swarm (no PettingZoo import).

``city``   buildings, street grid, 3-D line of sight, skyline mask, the paper's analytic
           canyon mask (Eq. 25) and NLOS reception.
``route``  shortest street routes, arc-length polylines, waypoint tracking.
``swarm``  UAV kinematics, building and inter-UAV collisions, relative (UWB-like) sensing.
``scenario`` the world of one episode, epoch by epoch: kinematics -> satellites -> visibility
           -> measurements -> standalone and cooperative navigation (:class:`UrbanWorld`).

Everything is in a local ENU frame in metres (x East, y North, z Up, ground at z = 0);
satellites are unit direction vectors.
"""

from __future__ import annotations

from coopnav_env.sim.city import (
    DEFAULT_CANYON_GAPS_DEG,
    Buildings,
    CanyonMask,
    City,
    CityConfig,
    canyon_city,
    draw_nlos,
    generate_city,
    is_inside_building,
    line_of_sight,
    mask_elevation_deg,
    wall_distance_m,
)
from coopnav_env.sim.scenario import (
    AUTO_SHARED_MIN_UAVS,
    Epoch,
    NavSource,
    ScenarioConfig,
    UrbanWorld,
    formation_offsets,
    make_city,
)
from coopnav_env.sim.swarm import (
    KinematicsConfig,
    RelativeSensingConfig,
    building_collisions,
    measure_relative_positions,
    pairwise_ranges_m,
    separation_violations,
    step_kinematics,
    swept_collisions,
)

__all__ = [
    "AUTO_SHARED_MIN_UAVS",
    "DEFAULT_CANYON_GAPS_DEG",
    "Buildings",
    "CanyonMask",
    "City",
    "CityConfig",
    "Epoch",
    "KinematicsConfig",
    "NavSource",
    "RelativeSensingConfig",
    "ScenarioConfig",
    "UrbanWorld",
    "building_collisions",
    "canyon_city",
    "draw_nlos",
    "formation_offsets",
    "generate_city",
    "is_inside_building",
    "line_of_sight",
    "make_city",
    "mask_elevation_deg",
    "measure_relative_positions",
    "pairwise_ranges_m",
    "separation_violations",
    "step_kinematics",
    "swept_collisions",
    "wall_distance_m",
]
