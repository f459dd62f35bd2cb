"""GNSS simulation: frames, constellations, error models and pseudorange simulation.

Modules
-------
``frames``         WGS 84 geodetic / ECEF / ENU conversions, line of sight, azimuth/elevation.
``constellation``  circular-orbit GPS (SPS PS 24-slot) and BeiDou-3 constellations.
``errors``         paper Eq. 1-8 error models and ``simulate_pseudoranges``.
"""

from __future__ import annotations

from coopnav_env.constants import SYSTEMS
from coopnav_env.gnss.constellation import (
    Constellation,
    beidou3_constellation,
    default_constellation,
    gps_nominal_constellation,
    select_highest,
)
from coopnav_env.gnss.errors import (
    ErrorModel,
    PseudorangeEpoch,
    draw_clock_biases,
    iono_free_factor,
    sigma_multipath_m,
    sigma_noise_m,
    sigma_tropo_m,
    sigma_ure_m,
    sigma_user_m,
    simulate_pseudoranges,
)
from coopnav_env.gnss.frames import (
    azimuth_elevation,
    cov_ecef_to_enu,
    cov_enu_to_ecef,
    direction_enu,
    ecef_to_enu,
    ecef_to_geodetic,
    enu_rotation,
    enu_to_ecef,
    geodetic_to_ecef,
    line_of_sight,
)

__all__ = [
    "SYSTEMS",
    "Constellation",
    "ErrorModel",
    "PseudorangeEpoch",
    "azimuth_elevation",
    "beidou3_constellation",
    "cov_ecef_to_enu",
    "cov_enu_to_ecef",
    "default_constellation",
    "direction_enu",
    "draw_clock_biases",
    "ecef_to_enu",
    "ecef_to_geodetic",
    "enu_rotation",
    "enu_to_ecef",
    "geodetic_to_ecef",
    "gps_nominal_constellation",
    "iono_free_factor",
    "line_of_sight",
    "select_highest",
    "sigma_multipath_m",
    "sigma_noise_m",
    "sigma_tropo_m",
    "sigma_ure_m",
    "sigma_user_m",
    "simulate_pseudoranges",
]
