"""Physical constants used throughout coopnav.

Every constant carries its unit in its name or docstring. Values are the public
WGS 84 / IS-GPS-200 / BDS-SIS-ICD figures listed in ``shared/gnss-facts.md``.
"""

from __future__ import annotations

SPEED_OF_LIGHT_MPS: float = 299_792_458.0
"""Speed of light in vacuum [m/s]."""

OMEGA_EARTH_RADPS: float = 7.2921151467e-5
"""WGS 84 Earth rotation rate [rad/s]."""

GM_EARTH_M3PS2: float = 3.986004418e14
"""WGS 84 Earth gravitational parameter GM [m^3/s^2]."""

WGS84_A_M: float = 6_378_137.0
"""WGS 84 semi-major axis [m]."""

WGS84_INV_F: float = 298.257223563
"""WGS 84 inverse flattening [-]."""

WGS84_F: float = 1.0 / WGS84_INV_F
"""WGS 84 flattening [-]."""

WGS84_B_M: float = WGS84_A_M * (1.0 - WGS84_F)
"""WGS 84 semi-minor axis [m]."""

WGS84_E2: float = WGS84_F * (2.0 - WGS84_F)
"""WGS 84 first eccentricity squared [-]."""

# Carrier frequencies [Hz]
FREQ_GPS_L1_HZ: float = 1575.42e6
FREQ_GPS_L2_HZ: float = 1227.60e6
FREQ_GPS_L5_HZ: float = 1176.45e6
FREQ_BDS_B1I_HZ: float = 1561.098e6
FREQ_BDS_B1C_HZ: float = 1575.42e6
FREQ_BDS_B2A_HZ: float = 1176.45e6
FREQ_BDS_B2B_HZ: float = 1207.14e6
FREQ_BDS_B3I_HZ: float = 1268.52e6
FREQ_GAL_E1_HZ: float = 1575.42e6
FREQ_GAL_E5A_HZ: float = 1176.45e6

SYSTEMS: tuple[str, ...] = ("GPS", "BDS")
"""Constellation names; a satellite's ``system`` index points into this tuple."""

FILE_SYSTEMS: tuple[str, ...] = (*SYSTEMS, "GAL")
"""``SYSTEMS`` and Galileo (``"GAL"``), which only a sky from a RINEX navigation file holds,
when asked for; a satellite's ``system`` index points into this tuple (the same index as in
``SYSTEMS`` for GPS and BeiDou)."""

SHANGHAI_LAT_DEG: float = 31.0252
"""Default geodetic origin: Shanghai Jiao Tong University, Minhang (the paper's site) [deg]."""
SHANGHAI_LON_DEG: float = 121.4337
"""Default geodetic origin longitude [deg]."""
SHANGHAI_ALT_M: float = 10.0
"""Default geodetic origin ellipsoidal height [m]."""
