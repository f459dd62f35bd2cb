"""Satellite constellations on circular Keplerian orbits around a rotating Earth.

Model
-----
Each satellite ``k`` moves on a circular orbit of semi-major axis ``a_k``,
inclination ``i_k`` and inertial right ascension of the ascending node
``RAAN_k``; its argument of latitude grows uniformly,
``u_k(t) = u_k(0) + n_k t`` with ``n_k = sqrt(GM / a_k^3)``. No perturbations
(J2, drag, solar pressure) are modelled. The Earth turns at ``OMEGA_EARTH`` so
the Greenwich hour angle is ``GHA(t) = GHA_k(0) + OMEGA_EARTH t`` and the
longitude of the ascending node in ECEF is ``RAAN_k - GHA(t)``.

Time ``t_s`` is in seconds since the reference epoch of the GPS SPS Performance
Standard nominal constellation, 1 July 1993 00:00 UTC (GHA 18h 36m 14.4s =
279.06 deg). All built-in constellations share that epoch, so GPS and BDS may be
concatenated and evaluated on one time axis.

System indices point into ``coopnav_env.constants.SYSTEMS`` (0 = GPS, 1 = BDS).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.constants import GM_EARTH_M3PS2, OMEGA_EARTH_RADPS, SYSTEMS, WGS84_A_M
from coopnav_env.gnss._validate import (
    as_bool_matrix,
    as_count,
    as_elevation_deg,
    as_float_array,
    as_index_array,
    readonly,
)

__all__ = [
    "BDS_GEO_LON_DEG",
    "BDS_IGSO_NODE_LON_DEG",
    "BDS_MEO_A_M",
    "GEOSYNC_A_M",
    "GPS_A_M",
    "GPS_GHA0_DEG",
    "Constellation",
    "beidou3_constellation",
    "default_constellation",
    "gps_nominal_constellation",
    "select_highest",
]

GPS_A_M: float = 26_559_700.0
"""GPS nominal semi-major axis [m] (SPS PS Table 3-1)."""

GPS_INCLINATION_DEG: float = 55.0
"""GPS nominal inclination [deg]."""

GPS_GHA0_DEG: float = (18.0 + 36.0 / 60.0 + 14.4 / 3600.0) * 15.0
"""Greenwich hour angle at the reference epoch 1993-07-01 00:00 UTC, 18h 36m 14.4s [deg]."""

GPS_RAAN_DEG: tuple[float, ...] = (272.847, 332.847, 32.847, 92.847, 152.847, 212.847)
"""Inertial RAAN of planes A-F at the reference epoch [deg] (SPS PS Table 3-1)."""

GPS_ARG_LAT_DEG: tuple[tuple[float, ...], ...] = (
    (268.126, 161.786, 11.676, 41.806),  # A1-A4
    (80.956, 173.336, 309.976, 204.376),  # B1-B4
    (111.876, 11.796, 339.666, 241.556),  # C1-C4
    (135.226, 265.446, 35.156, 167.356),  # D1-D4
    (197.046, 302.596, 66.066, 333.686),  # E1-E4
    (238.886, 345.226, 105.206, 135.346),  # F1-F4
)
"""Argument of latitude of slots 1-4 of planes A-F at the reference epoch [deg]."""

BDS_MEO_A_M: float = 27_906_100.0
"""BeiDou-3 MEO semi-major axis [m] (altitude about 21,528 km)."""

BDS_INCLINATION_DEG: float = 55.0
"""BeiDou-3 MEO and IGSO inclination [deg]."""

GEOSYNC_A_M: float = float((GM_EARTH_M3PS2 / OMEGA_EARTH_RADPS**2) ** (1.0 / 3.0))
"""Geosynchronous semi-major axis [m], about 42,164.17 km.

Computed from GM and OMEGA_EARTH so that the mean motion equals the Earth rate
exactly; the rounded 42,164 km would drift about 66 m per hour in ECEF.
"""

BDS_GEO_LON_DEG: tuple[float, ...] = (80.0, 110.5, 140.0)
"""Longitudes of the three BeiDou-3 GEO slots modelled [deg east]."""

BDS_IGSO_NODE_LON_DEG: float = 118.0
"""Geographic longitude of the BeiDou-3 IGSO ascending nodes (ground-track crossing) [deg]."""

BDS_MEO_RAAN0_DEG: float = 0.0
"""Inertial RAAN of BDS MEO plane 1 at the reference epoch [deg] (free choice)."""

BDS_MEO_ARG_LAT0_DEG: float = 0.0
"""Argument of latitude of BDS MEO plane 1, slot 1 at the reference epoch [deg] (free choice)."""


def _float_vector(value: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = as_float_array(value, name)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D (n_sv,), got shape {arr.shape}")
    return arr


@dataclass(frozen=True, eq=False)
class Constellation:
    """Set of satellites on circular orbits, as per-satellite arrays.

    All array fields are stored as read-only copies of shape ``(n_sv,)``.

    Parameters
    ----------
    system : array_like of int, shape (n_sv,)
        Index into ``SYSTEMS`` (0 = GPS, 1 = BDS).
    prn : tuple of str, length n_sv
        Unique satellite labels, e.g. ``"G01"``, ``"C01"``.
    semi_major_axis_m : array_like, shape (n_sv,)
        Orbit radius [m], must exceed the WGS 84 equatorial radius.
    inclination_rad : array_like, shape (n_sv,)
        Inclination [rad], in ``[0, pi]``.
    raan_rad : array_like, shape (n_sv,)
        Inertial right ascension of the ascending node at the reference epoch [rad].
    arg_lat_rad : array_like, shape (n_sv,)
        Argument of latitude at the reference epoch [rad].
    gha0_rad : array_like, shape (n_sv,)
        Greenwich hour angle at the reference epoch [rad] (the same for every
        satellite in the built-in constellations).
    """

    system: NDArray[np.intp]
    prn: tuple[str, ...]
    semi_major_axis_m: NDArray[np.float64]
    inclination_rad: NDArray[np.float64]
    raan_rad: NDArray[np.float64]
    arg_lat_rad: NDArray[np.float64]
    gha0_rad: NDArray[np.float64]

    def __post_init__(self) -> None:
        prn = tuple(self.prn)
        if not all(isinstance(p, str) for p in prn):
            raise ValueError(f"prn must be a tuple of str, got {self.prn!r}")
        if len(set(prn)) != len(prn):
            dup = sorted({p for p in prn if prn.count(p) > 1})
            raise ValueError(f"prn labels must be unique, duplicated: {dup}")
        n_sv = len(prn)
        system = as_index_array(self.system, "system", len(SYSTEMS))
        fields = {"system": system}
        for name in ("semi_major_axis_m", "inclination_rad", "raan_rad", "arg_lat_rad", "gha0_rad"):
            fields[name] = _float_vector(getattr(self, name), name)
        for name, arr in fields.items():
            if arr.shape != (n_sv,):
                raise ValueError(f"{name} must have shape ({n_sv},) like prn, got {arr.shape}")
        if np.any(fields["semi_major_axis_m"] <= WGS84_A_M):
            raise ValueError(
                f"semi_major_axis_m must exceed WGS84_A_M = {WGS84_A_M} m, "
                f"got min {fields['semi_major_axis_m'].min()}"
            )
        inc = fields["inclination_rad"]
        if np.any((inc < 0.0) | (inc > np.pi)):
            raise ValueError(f"inclination_rad must lie in [0, pi], got {inc}")
        object.__setattr__(self, "prn", prn)
        for name, arr in fields.items():
            object.__setattr__(self, name, readonly(arr))

    @property
    def n_sv(self) -> int:
        """Number of satellites."""
        return len(self.prn)

    @property
    def mean_motion_radps(self) -> NDArray[np.float64]:
        """Mean motion ``n = sqrt(GM / a^3)`` [rad/s], shape (n_sv,)."""
        return np.sqrt(GM_EARTH_M3PS2 / self.semi_major_axis_m**3)

    def positions_ecef(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Satellite positions in ECEF.

        Parameters
        ----------
        t_s : float or array_like, shape () or (n_t,)
            Time since the reference epoch [s].

        Returns
        -------
        ndarray, shape (n_sv, 3) for scalar ``t_s``, (n_t, n_sv, 3) for 1-D ``t_s``
            ECEF positions [m].
        """
        t = as_float_array(t_s, "t_s")
        if t.ndim > 1:
            raise ValueError(f"t_s must be a scalar or 1-D array, got shape {t.shape}")
        tt = t[..., None]  # (1,) or (n_t, 1), broadcasts against (n_sv,)
        u = self.arg_lat_rad + self.mean_motion_radps * tt
        node_lon = self.raan_rad - self.gha0_rad - OMEGA_EARTH_RADPS * tt
        cos_u, sin_u = np.cos(u), np.sin(u)
        cos_o, sin_o = np.cos(node_lon), np.sin(node_lon)
        cos_i, sin_i = np.cos(self.inclination_rad), np.sin(self.inclination_rad)
        a = self.semi_major_axis_m
        x = a * (cos_u * cos_o - sin_u * cos_i * sin_o)
        y = a * (cos_u * sin_o + sin_u * cos_i * cos_o)
        z = a * sin_u * sin_i
        return np.stack([x, y, z], axis=-1)

    def subset(self, mask_or_indices: ArrayLike) -> Constellation:
        """Constellation holding a selection of the satellites.

        Parameters
        ----------
        mask_or_indices : array_like
            Boolean mask of shape (n_sv,) or 1-D integer indices into the satellites
            (order kept, repeats not allowed because PRNs must stay unique).

        Returns
        -------
        Constellation
        """
        sel = np.asarray(mask_or_indices)
        if sel.dtype == np.bool_:
            idx = np.flatnonzero(as_bool_matrix(sel, "mask_or_indices", (self.n_sv,)))
        else:
            idx = as_index_array(sel, "mask_or_indices", self.n_sv)
        return Constellation(
            system=self.system[idx],
            prn=tuple(np.asarray(self.prn, dtype=object)[idx].tolist()),
            semi_major_axis_m=self.semi_major_axis_m[idx],
            inclination_rad=self.inclination_rad[idx],
            raan_rad=self.raan_rad[idx],
            arg_lat_rad=self.arg_lat_rad[idx],
            gha0_rad=self.gha0_rad[idx],
        )

    @classmethod
    def concatenate(cls, *constellations: Constellation) -> Constellation:
        """Merge constellations, satellites in argument order (PRNs must stay unique)."""
        if not constellations:
            raise ValueError("concatenate needs at least one Constellation, got none")
        for c in constellations:
            if not isinstance(c, Constellation):
                raise ValueError(f"concatenate accepts Constellation objects, got {type(c)}")
        return cls(
            system=np.concatenate([c.system for c in constellations]),
            prn=tuple(p for c in constellations for p in c.prn),
            semi_major_axis_m=np.concatenate([c.semi_major_axis_m for c in constellations]),
            inclination_rad=np.concatenate([c.inclination_rad for c in constellations]),
            raan_rad=np.concatenate([c.raan_rad for c in constellations]),
            arg_lat_rad=np.concatenate([c.arg_lat_rad for c in constellations]),
            gha0_rad=np.concatenate([c.gha0_rad for c in constellations]),
        )

    def __add__(self, other: Constellation) -> Constellation:
        if not isinstance(other, Constellation):
            return NotImplemented
        return Constellation.concatenate(self, other)


def _build(
    system_name: str,
    prn: list[str],
    a_m: ArrayLike,
    inc_deg: ArrayLike,
    raan_deg: ArrayLike,
    arg_lat_deg: ArrayLike,
) -> Constellation:
    n = len(prn)
    return Constellation(
        system=np.full(n, SYSTEMS.index(system_name), dtype=np.intp),
        prn=tuple(prn),
        semi_major_axis_m=np.broadcast_to(np.asarray(a_m, dtype=np.float64), (n,)),
        inclination_rad=np.radians(np.broadcast_to(np.asarray(inc_deg, dtype=np.float64), (n,))),
        raan_rad=np.radians(np.asarray(raan_deg, dtype=np.float64)),
        arg_lat_rad=np.radians(np.asarray(arg_lat_deg, dtype=np.float64)),
        gha0_rad=np.full(n, np.radians(GPS_GHA0_DEG)),
    )


def gps_nominal_constellation() -> Constellation:
    """The 24-slot nominal GPS constellation (GPS SPS Performance Standard, Table 3-1).

    Circular orbits, a = 26,559.7 km, i = 55 deg, epoch 1993-07-01 00:00 UTC.
    Labels are assigned slot by slot in plane order: A1-A4 -> G01-G04, B1-B4 ->
    G05-G08, ..., F1-F4 -> G21-G24 (slot labels, not the PRNs of live satellites).

    Returns
    -------
    Constellation
        24 satellites, ``system`` = 0.
    """
    arg_lat = np.asarray(GPS_ARG_LAT_DEG)  # (6 planes, 4 slots)
    raan = np.repeat(np.asarray(GPS_RAAN_DEG), arg_lat.shape[1])
    prn = [f"G{k + 1:02d}" for k in range(arg_lat.size)]
    return _build("GPS", prn, GPS_A_M, GPS_INCLINATION_DEG, raan, arg_lat.ravel())


def beidou3_constellation(include_geo_igso: bool = False) -> Constellation:
    """Nominal BeiDou-3 constellation.

    * MEO: Walker 24/3/1, a = 27,906.1 km, i = 55 deg. Plane ``j`` (0..2) has
      inertial RAAN ``BDS_MEO_RAAN0_DEG + 120 j`` at the reference epoch; slot
      ``s`` (0..7) of plane ``j`` has argument of latitude
      ``BDS_MEO_ARG_LAT0_DEG + 45 s + 15 j`` (phasing 360 F / T = 15 deg per
      plane). The two offsets are free choices (0 deg), not the live almanac.
      Labels C01-C08 (plane 1), C09-C16, C17-C24.
    * GEO (optional): i = 0 on the geosynchronous radius ``GEOSYNC_A_M`` over 80,
      110.5 and 140 deg E, constant in ECEF. Labels C25-C27.
    * IGSO (optional): a = ``GEOSYNC_A_M``, i = 55 deg, RAANs 120 deg apart; all
      three ascending nodes lie at geographic longitude 118 deg E, so they share
      one figure-eight ground track. IGSO 1 is at its ascending node at t = 0;
      IGSO 2 and 3 trail it by 120 and 240 deg of argument of latitude (they reach
      the node 8 and 16 sidereal hours later). Labels C28-C30.

    Labels are synthetic slot labels, not the PRNs of live satellites.

    Parameters
    ----------
    include_geo_igso : bool, optional
        Add the 3 GEO and 3 IGSO satellites after the 24 MEO.

    Returns
    -------
    Constellation
        24 (or 30) satellites, ``system`` = 1.
    """
    plane = np.repeat(np.arange(3), 8)
    slot = np.tile(np.arange(8), 3)
    raan = [BDS_MEO_RAAN0_DEG + 120.0 * plane]
    arg_lat = [BDS_MEO_ARG_LAT0_DEG + 45.0 * slot + 15.0 * plane]
    a_m = [np.full(24, BDS_MEO_A_M)]
    inc = [np.full(24, BDS_INCLINATION_DEG)]
    if include_geo_igso:
        # GEO: node longitude in ECEF at t=0 is RAAN - GHA0 = 0, so the ECEF longitude is u.
        geo_lon = np.asarray(BDS_GEO_LON_DEG)
        raan.append(np.full(3, GPS_GHA0_DEG))
        arg_lat.append(geo_lon)
        a_m.append(np.full(3, GEOSYNC_A_M))
        inc.append(np.zeros(3))
        # IGSO: node longitude at crossing time t_j = -u_j / n is RAAN_j - GHA0 + u_j (n = Earth
        # rate), so u_j = 118 + GHA0 - RAAN_j puts every ascending node at 118 deg E.
        igso_raan = GPS_GHA0_DEG + BDS_IGSO_NODE_LON_DEG + 120.0 * np.arange(3)
        raan.append(igso_raan)
        arg_lat.append(BDS_IGSO_NODE_LON_DEG + GPS_GHA0_DEG - igso_raan)
        a_m.append(np.full(3, GEOSYNC_A_M))
        inc.append(np.full(3, BDS_INCLINATION_DEG))
    n = sum(len(r) for r in raan)
    prn = [f"C{k + 1:02d}" for k in range(n)]
    return _build(
        "BDS",
        prn,
        np.concatenate(a_m),
        np.concatenate(inc),
        np.concatenate(raan) % 360.0,
        np.concatenate(arg_lat) % 360.0,
    )


def default_constellation(
    systems: tuple[str, ...] = ("GPS", "BDS"), bds_geo_igso: bool = False
) -> Constellation:
    """Nominal constellation of the named systems, in the order given.

    Parameters
    ----------
    systems : tuple of str, optional
        Names from ``SYSTEMS`` (``"GPS"``, ``"BDS"``), each at most once.
    bds_geo_igso : bool, optional
        Include the BeiDou-3 GEO and IGSO satellites.

    Returns
    -------
    Constellation
        The same object for the same arguments (built once per process: a constellation is
        immutable, a frozen dataclass of read-only arrays, so every world of a configuration
        shares one).
    """
    if isinstance(systems, str):
        systems = (systems,)
    systems = tuple(systems)
    if not systems:
        raise ValueError(f"systems must name at least one of {SYSTEMS}, got {systems!r}")
    for name in systems:
        if name not in SYSTEMS:
            raise ValueError(f"unknown system {name!r}; allowed: {SYSTEMS}")
    if len(set(systems)) != len(systems):
        raise ValueError(f"systems must not repeat a name, got {systems!r}")
    key = (systems, bool(bds_geo_igso))
    cached = _DEFAULT_CONSTELLATIONS.get(key)
    if cached is not None:
        return cached
    builders = {
        "GPS": gps_nominal_constellation,
        "BDS": lambda: beidou3_constellation(include_geo_igso=bds_geo_igso),
    }
    built = Constellation.concatenate(*(builders[name]() for name in systems))
    _DEFAULT_CONSTELLATIONS[key] = built
    return built


_DEFAULT_CONSTELLATIONS: dict[tuple[tuple[str, ...], bool], Constellation] = {}
"""``(systems, bds_geo_igso) -> Constellation`` of :func:`default_constellation` (a few
entries at most: the valid arguments are the orderings of the systems' names)."""


def select_highest(el_deg: ArrayLike, visible: ArrayLike, max_sats: int) -> NDArray[np.bool_]:
    """Keep at most ``max_sats`` visible satellites per receiver, the highest ones.

    Models a receiver with a limited number of channels (the paper: "the maximum
    number of available satellites equals to 10" in open sky).

    Parameters
    ----------
    el_deg : array_like, shape (n_rx, n_sv)
        Elevation [deg]; entries where ``visible`` is false may be NaN.
    visible : array_like of bool, shape (n_rx, n_sv)
        Satellites that can be tracked.
    max_sats : int
        Channel limit, >= 0.

    Returns
    -------
    ndarray of bool, shape (n_rx, n_sv)
        Subset of ``visible``. Among equal elevations the lower satellite index wins.
    """
    el = as_float_array(el_deg, "el_deg", allow_nan=True)
    if el.ndim != 2:
        raise ValueError(f"el_deg must have shape (n_rx, n_sv), got shape {el.shape}")
    vis = as_bool_matrix(visible, "visible", el.shape)
    n_keep = as_count(max_sats, "max_sats", 0)
    if np.any(np.isnan(el) & vis):
        raise ValueError("el_deg must be finite where visible is true, got NaN")
    as_elevation_deg(np.where(vis, el, 0.0), "el_deg")
    key = np.where(vis, -el, np.inf)  # ascending sort: highest visible first, invisible last
    order = np.argsort(key, axis=1, kind="stable")  # stable -> ties broken by index
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(el.shape[1])[None, :], axis=1)
    return vis & (rank < n_keep)
