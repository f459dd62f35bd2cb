"""Satellite orbits and clocks from a RINEX navigation file (GPS LNAV, BeiDou D1/D2, Galileo).

Reading
-------
:func:`read_rinex_nav` parses, with numpy only, a RINEX 3.00-3.05 navigation file (``N`` type,
system ``G``, ``C`` or ``M`` for mixed) or a RINEX 2.00-2.11 GPS navigation file (``N``),
plain or gzip-compressed (recognised by its content): the header (version, file type,
satellite system, ``END OF HEADER``), then each record's epoch line and its broadcast-orbit
lines. Fields are fixed-width (19 characters each, four per orbit line after four blanks in
RINEX 3 and three in RINEX 2, three after the epoch of the first line), so numbers that run
together (``1.0D-05-2.0D-07``) are read correctly; ``D``, ``d`` and ``E`` exponents are
accepted. GPS (``G``) and BeiDou (``C``) records are kept (8 lines each), and Galileo (``E``)
I/NAV records when asked (``galileo=True``; their F/NAV twins, which carry the same orbit and
the E5a clock, are skipped); GLONASS (``R``), SBAS (``S``), QZSS (``J``) and NavIC (``I``)
records, and Galileo's when not asked for (an epoch line and its indented orbit lines, however
many the version gives), are skipped and counted (:attr:`NavigationFile.skipped`). Any other
system letter, a bad epoch, or a record cut short raises ``ValueError`` naming the file, the
line number and what is wrong.

A record that cannot be used is left out, not the file, checked in this order:
the satellite flags itself unhealthy (GPS SV health, BeiDou SatH1 or Galileo's health bits not
0); a field is blank
or not a number; the orbit is implausible (``sqrt(A)`` outside 4,472-7,071 m^0.5, a
semi-major axis of 20,000-50,000 km; eccentricity outside [0, 0.5)); ``toe`` lies outside the
week; the week number is not an integer or disagrees with the record's epoch. The records left
out are counted by system and reason (:attr:`NavigationFile.rejected`) and named in one
:class:`RinexWarning` per file. Of repeated broadcasts of one ephemeris (same satellite and
``toe``), the newest (latest transmission time) is kept.

Propagation
-----------
:class:`BroadcastConstellation` evaluates the broadcast Keplerian elements as the interface
specifications do:

* GPS: IS-GPS-200, Table 20-IV (user algorithm for ephemeris determination), ``mu =
  3.986005e14 m^3/s^2``, ``OmegaE = 7.2921151467e-5 rad/s``; ``tk = t - toe`` in seconds of
  the GPS week, brought into [-302400, 302400] s (week crossovers); satellite clock (20.3.3.3.3)
  ``af0 + af1 (t - toc) + af2 (t - toc)^2 + F e sqrt(A) sin(Ek)``, ``F = -2 sqrt(mu) / c^2``,
  without the group delay ``TGD`` (a single-frequency L1 user subtracts it).
* BeiDou: BDS-SIS-ICD-B1I 3.0, 5.2.4.12, ``mu = 3.986004418e14``, ``OmegaE = 7.292115e-5``;
  times in BDT (``BDT = GPST - 14 s``; BDT week 0 began on 2006-01-01 00:00:00 UTC). MEO and
  IGSO satellites as GPS. GEO satellites (PRN C01-C05 and C59-C63) are computed in the
  inertial frame of the ``toe`` (``Omega_k = Omega_0 + OmegaDot tk - OmegaE toe``), rotated by
  -5 deg about X and then by ``OmegaE tk`` about Z into BDCS. BDCS (CGCS2000) and WGS 84 are
  treated as the same frame (they agree to a few centimetres).
* Galileo: OS SIS ICD 2.0, 5.1.1 (GST) and 5.1.9.1 (Table 60, the same Keplerian algorithm as
  GPS), ``mu = 3.986004418e14``, ``OmegaE = 7.2921151467e-5``; the clock (5.1.3) as GPS's,
  without the broadcast group delay ``BGD``. GST weeks are numbered as GPS weeks in RINEX and
  GST - GPST (tens of nanoseconds, broadcast as GGTO) is taken as 0: it moves a satellite
  by well under a millimetre. GTRF and WGS 84 are treated as the same frame.

The week of each ``toe`` is resolved against the record's ``toc`` (its calendar epoch), so
10-bit GPS week numbers and records near a week boundary are placed correctly; a week field
that disagrees with the epoch by more than a week (modulo 1024) is an error.

Time and validity
-----------------
A :class:`BroadcastConstellation` measures time ``t_s`` in seconds after its
``reference_gps_s`` (GPS seconds, since 1980-01-06 00:00:00 GPST), the start of the file's
coverage rounded down to a whole second. Each ephemeris is used only inside its fit interval,
``|t - toe| <= validity``: half the GPS record's fit interval (its last field, in hours; at
least 4 h, the value of a blank or 0 field); 1 h for BeiDou, whose ephemerides are refreshed
hourly; 4 h for Galileo (refreshed every 10 min; RTKLIB's ``MAXDTOE_GAL``). Of the
ephemerides of a satellite valid at ``t``, the one with the nearest ``toe`` is
used (of two equally near, the later ``toe``), as RTKLIB's ``seleph`` does. A satellite with no
valid ephemeris at ``t`` (a gap in the file) has NaN position and clock: it is not
broadcasting. :attr:`BroadcastConstellation.valid_spans_gps_s` are the spans in which every
included system has at least one valid ephemeris; the coverage runs from the first to the
last of them, and a time outside it raises ``ValueError`` naming the time and the coverage.
:meth:`BroadcastConstellation.visibility` says what a place sees over the coverage (sampled
every 30 s): the usable spans, in which every system has a valid ephemeris and at least
:data:`MIN_SATELLITES` satellites are above the cut-off, and how many of the file's
satellites above the cut-off have a valid ephemeris there (a station's file holds the
satellites the station tracked: far from it, few).

References
----------
IS-GPS-200N, Navstar GPS Space Segment / Navigation User Interfaces, 2022, 20.3.3.3.3 and
Table 20-IV. BeiDou Navigation Satellite System Signal In Space Interface Control Document,
Open Service Signal B1I (Version 3.0), 2019, 5.2.4.12. European GNSS (Galileo) Open Service
Signal-In-Space Interface Control Document, Issue 2.0, 2021, 5.1. RINEX, The Receiver Independent
Exchange Format, Version 3.05, 2020, Tables A8 (GPS), A10 (Galileo) and A14 (BDS).
"""

from __future__ import annotations

import datetime as _dt
import functools
import gzip
import hashlib
import os
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.constants import FILE_SYSTEMS, SPEED_OF_LIGHT_MPS, SYSTEMS
from coopnav_env.gnss._validate import as_float_array, as_index_array, readonly
from coopnav_env.gnss.frames import azimuth_elevation, geodetic_to_ecef

__all__ = [
    "BDS_GEO_PRNS",
    "BDS_MU_M3PS2",
    "BDS_OMEGA_E_RADPS",
    "BDS_VALIDITY_S",
    "BDT_MINUS_GPST_S",
    "FEW_SATELLITES_FRACTION",
    "FILE_SYSTEMS",
    "GAL_MU_M3PS2",
    "GAL_OMEGA_E_RADPS",
    "GAL_VALIDITY_S",
    "GPS_MU_M3PS2",
    "GPS_OMEGA_E_RADPS",
    "GPS_VALIDITY_S",
    "MIN_SATELLITES",
    "SAMPLE_NAV_PATH",
    "SHIPPED_NAV_PATHS",
    "BroadcastConstellation",
    "NavigationFile",
    "RinexWarning",
    "SkyVisibility",
    "clear_caches",
    "gps_seconds",
    "load_broadcast_constellation",
    "read_rinex_nav",
]

GPS_MU_M3PS2: float = 3.986005e14
"""GPS value of the Earth's gravitational constant (IS-GPS-200 Table 20-IV) [m^3/s^2]."""

GPS_OMEGA_E_RADPS: float = 7.2921151467e-5
"""GPS value of the Earth's rotation rate (IS-GPS-200 Table 20-IV) [rad/s]."""

BDS_MU_M3PS2: float = 3.986004418e14
"""BeiDou (CGCS2000) gravitational constant (BDS-SIS-ICD-B1I 5.2.4.12) [m^3/s^2]."""

BDS_OMEGA_E_RADPS: float = 7.292115e-5
"""BeiDou (CGCS2000) Earth rotation rate (BDS-SIS-ICD-B1I 5.2.4.12) [rad/s]."""

GAL_MU_M3PS2: float = 3.986004418e14
"""Galileo value of the Earth's gravitational constant (OS SIS ICD 5.1.1) [m^3/s^2]."""

GAL_OMEGA_E_RADPS: float = 7.2921151467e-5
"""Galileo value of the Earth's rotation rate (OS SIS ICD 5.1.1) [rad/s]."""

BDT_MINUS_GPST_S: float = -14.0
"""BDT - GPST [s]: BeiDou time runs 14 s behind GPS time."""

GPS_VALIDITY_S: float = 7200.0
"""Least validity of a GPS ephemeris, ``|t - toe|`` [s] (a 4-hour fit interval)."""

BDS_VALIDITY_S: float = 3600.0
"""Validity of a BeiDou ephemeris, ``|t - toe|`` [s] (refreshed every hour)."""

GAL_VALIDITY_S: float = 14400.0
"""Validity of a Galileo ephemeris, ``|t - toe|`` [s] (4 h, RTKLIB's ``MAXDTOE_GAL``)."""

BDS_GEO_PRNS: frozenset[int] = frozenset((1, 2, 3, 4, 5, 59, 60, 61, 62, 63))
"""BeiDou PRNs of geostationary satellites (C01-C05, C59-C63), propagated as GEO."""

MIN_SATELLITES: int = 4
"""Satellites with a valid ephemeris needed above the cut-off for a time to be usable."""

FEW_SATELLITES_FRACTION: float = 0.5
"""Below this :attr:`SkyVisibility.seen_fraction`, a place sees few of a file's satellites
(the environment warns: the file's station is far away)."""

SAMPLE_NAV_PATH: Path = Path(__file__).resolve().parent.parent / "data" / "sample_nav.rnx"
"""The sample mixed GPS + BeiDou navigation file shipped with the package (one day, made by
``coopnav_env/data/make_sample_nav.py`` from the nominal constellations)."""

SHIPPED_NAV_PATHS: dict[str, Path] = {
    "sample": SAMPLE_NAV_PATH,
    "igs_brdc": SAMPLE_NAV_PATH.with_name("brdc2420.18n.gz"),
}
"""Navigation files shipped with the package, by the name a ``rinex:`` setting gives them:
``"sample"`` (:data:`SAMPLE_NAV_PATH`) and ``"igs_brdc"``, a real one: the IGS merged
broadcast GPS ephemerides (RINEX 2.11, gzip) of 2018-08-30, 6 h of every GPS satellite, usable
anywhere on Earth (source and licence in ``coopnav_env/data/NOTICE-navigation.md``)."""

SECONDS_PER_WEEK: float = 604_800.0
_HALF_WEEK_S = 302_400.0
_BDT_EPOCH_GPS_S = 1356 * 604_800.0 + 14.0  # BDT week 0, second 0, in GPS seconds
_GPS_EPOCH = _dt.datetime(1980, 1, 6, tzinfo=_dt.timezone.utc)
_BDS_GEO_INCLINATION_RAD = np.radians(-5.0)
_KEPLER_ITERATIONS = 12  # Newton steps: e < 0.1 converges to machine precision in <= 6

# GPS - UTC [s] from each date on (leap seconds since the GPS epoch).
_LEAP_SECONDS: tuple[tuple[_dt.date, int], ...] = tuple(
    (_dt.date(y, m, 1), k + 1)
    for k, (y, m) in enumerate(
        (
            (1981, 7),
            (1982, 7),
            (1983, 7),
            (1985, 7),
            (1988, 1),
            (1990, 1),
            (1991, 1),
            (1992, 7),
            (1993, 7),
            (1994, 7),
            (1996, 1),
            (1997, 7),
            (1999, 1),
            (2006, 1),
            (2009, 1),
            (2012, 7),
            (2015, 7),
            (2017, 1),
        )
    )
)

_SQRT_A_RANGE = (float(np.sqrt(20e6)), float(np.sqrt(50e6)))  # semi-major axis 20,000-50,000 km
_KEPT_SYSTEMS = {"G": "GPS", "C": "BDS", "E": "GAL"}
_SYSTEM_WORDS = {"GPS": "GPS", "BDS": "BeiDou", "GAL": "Galileo"}
_SKIPPED_SYSTEMS = frozenset("RSJI")
_GAL_FNAV_ONLY = 0b010  # data sources: bit 0 I/NAV E1-B, bit 1 F/NAV E5a-I, bit 2 I/NAV E5b-I
_HEADER_SYSTEMS = {"G", "C", "R", "E", "J", "I", "S", "M"}

# Columns of the element table (one row per ephemeris) in RINEX order after the epoch line.
_FIELDS: tuple[str, ...] = (
    "af0_s",
    "af1_sps",
    "af2_sps2",
    "iode",
    "crs_m",
    "delta_n_radps",
    "m0_rad",
    "cuc_rad",
    "ecc",
    "cus_rad",
    "sqrt_a_sqrtm",
    "toe_sow",
    "cic_rad",
    "omega0_rad",
    "cis_rad",
    "i0_rad",
    "crc_m",
    "omega_rad",
    "omega_dot_radps",
    "idot_radps",
    "spare_5_2",
    "week",
    "spare_5_4",
    "accuracy_m",
    "health",
    "tgd_s",
    "spare_6_4",
    "transmit_sow",
    "fit_or_aodc",
)
_REQUIRED = frozenset(
    (
        "af0_s",
        "af1_sps",
        "af2_sps2",
        "crs_m",
        "delta_n_radps",
        "m0_rad",
        "cuc_rad",
        "ecc",
        "cus_rad",
        "sqrt_a_sqrtm",
        "toe_sow",
        "cic_rad",
        "omega0_rad",
        "cis_rad",
        "i0_rad",
        "crc_m",
        "omega_rad",
        "omega_dot_radps",
        "idot_radps",
        "week",
    )
)


def gps_seconds(when: Any) -> float:
    """GPS seconds (since 1980-01-06 00:00:00 GPST) of a time given in UTC or GPS seconds.

    Parameters
    ----------
    when : float, int, str or datetime.datetime
        A number (or a string of one): GPS seconds, >= 0. A string in ISO 8601 form
        (``"2026-12-03T06:00:00Z"``, ``"2026-12-03 06:00:00"``) or a ``datetime``: a UTC time
        (a naive one is taken as UTC); GPS - UTC leap seconds are added (18 s from 2017 on).

    Returns
    -------
    float

    Raises
    ------
    ValueError
        For a time before the GPS epoch, or a string that is neither a number nor an ISO time.
    """
    if isinstance(when, bool):
        raise ValueError(f"a time must be GPS seconds or a UTC ISO string, got {when!r}")
    if isinstance(when, (int, float, np.integer, np.floating)):
        value = float(when)
        if not np.isfinite(value) or value < 0.0:
            raise ValueError(f"GPS seconds must be finite and >= 0, got {when!r}")
        return value
    if isinstance(when, str):
        text = when.strip()
        try:
            return gps_seconds(float(text))
        except ValueError as exc:
            if "GPS seconds must" in str(exc):
                raise
        try:
            when = _dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
        except ValueError:
            raise ValueError(
                f"a time must be GPS seconds or a UTC ISO 8601 string such as "
                f"'2026-12-03T06:00:00Z', got {text!r}"
            ) from None
    if isinstance(when, _dt.date) and not isinstance(when, _dt.datetime):
        when = _dt.datetime(when.year, when.month, when.day)
    if not isinstance(when, _dt.datetime):
        raise ValueError(f"a time must be GPS seconds or a UTC ISO string, got {when!r}")
    if when.tzinfo is None:
        when = when.replace(tzinfo=_dt.timezone.utc)
    utc = when.astimezone(_dt.timezone.utc)
    if utc < _GPS_EPOCH:
        raise ValueError(f"time {when.isoformat()} is before the GPS epoch 1980-01-06")
    leap = 0
    for day, n in _LEAP_SECONDS:
        if utc.date() >= day:
            leap = n
    return (utc - _GPS_EPOCH).total_seconds() + leap


def _gps_iso(t_gps_s: float) -> str:
    """A GPS time as an ISO string in GPST (for messages)."""
    t = _GPS_EPOCH.replace(tzinfo=None) + _dt.timedelta(seconds=float(t_gps_s))
    return t.isoformat(timespec="seconds") + " GPST"


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------


class RinexWarning(UserWarning):
    """A navigation file read with records left out, or flown where it sees few satellites."""


@dataclass(frozen=True, eq=False)
class NavigationFile:
    """The GPS and BeiDou (and, when asked for, Galileo) broadcast ephemerides of one RINEX
    navigation file.

    Attributes
    ----------
    path : str
        The file read.
    version : float
        RINEX version (2.00-2.11 or 3.00-3.05).
    file_system : str
        Satellite system of the header (``G``, ``C`` or ``M``; others are accepted but give
        no ephemerides).
    system : ndarray of intp, shape (n_eph,)
        Index into :data:`FILE_SYSTEMS` of each ephemeris (0 = GPS, 1 = BDS, 2 = GAL).
    prn : tuple of str, length n_eph
        Satellite of each ephemeris (``"G05"``, ``"C01"``).
    toc_gps_s : ndarray, shape (n_eph,)
        Clock reference time in GPS seconds (a BeiDou ``toc`` is in BDT in the file).
    toe_gps_s : ndarray, shape (n_eph,)
        Ephemeris reference time in GPS seconds, its week resolved against ``toc``.
    elements : dict of str to ndarray, shape (n_eph,)
        The broadcast fields in RINEX order (``af0_s``, ..., ``sqrt_a_sqrtm``, ``toe_sow``,
        ..., ``week``, ``health``, ``tgd_s``, ``fit_or_aodc``; unread spare fields are NaN),
        plus ``toc_sow``. ``toe_sow`` and ``toc_sow`` are seconds of the GPS week (GPS) or of
        the BDT week (BeiDou).
    skipped : dict of str to int
        Records of other systems skipped, by system letter (``"E"``: Galileo, when not asked
        for; ``"E F/NAV"``: Galileo F/NAV records, when it is).
    unhealthy : int
        Ephemerides dropped because the satellite flagged itself unhealthy.
    rejected : dict of (str, str) to int
        Records of the systems read left out, by ``(system, reason)``: ``"unhealthy"``,
        ``"unreadable field"``, ``"implausible sqrt(A)"``, ``"implausible eccentricity"``,
        ``"toe outside the week"``, ``"bad week number"``, ``"week disagrees with epoch"``.
    digest : str
        SHA-256 of the file's (decompressed) bytes (identifies the sky in caches).
    """

    path: str
    version: float
    file_system: str
    system: NDArray[np.intp]
    prn: tuple[str, ...]
    toc_gps_s: NDArray[np.float64]
    toe_gps_s: NDArray[np.float64]
    elements: dict[str, NDArray[np.float64]]
    skipped: dict[str, int]
    unhealthy: int
    rejected: dict[tuple[str, str], int]
    digest: str

    @property
    def n_eph(self) -> int:
        """Number of ephemerides kept."""
        return len(self.prn)


class _BadValue(ValueError):
    """A field of a record that cannot be read (the record is left out, not the file)."""


def _field(text: str, start: int, where: str, name: str, required: bool) -> float:
    raw = text[start : start + 19].strip()
    if not raw:
        if required:
            raise _BadValue(f"{where}: field {name!r} (columns {start + 1}-{start + 19}) is blank")
        return float("nan")
    try:
        value = float(raw.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise _BadValue(
            f"{where}: field {name!r} (columns {start + 1}-{start + 19}) is not a number: {raw!r}"
        ) from None
    if not np.isfinite(value):
        raise _BadValue(f"{where}: field {name!r} is not finite: {raw!r}")
    return value


def _calendar_gps_s(fields: tuple[str, ...], where: str, system: str, cols: str) -> float:
    """GPS seconds of a record's epoch (year, month, day, hour, minute, second as text)."""
    try:
        year, month, day, hour, minute = (int(x) for x in fields[:5])
        sec = float(fields[5])
        if year < 100:  # RINEX 2: two-digit years, 80-99 -> 1980-1999
            year += 1900 if year >= 80 else 2000
        when = _dt.datetime(year, month, day, hour, minute) + _dt.timedelta(seconds=sec)
    except ValueError:
        raise ValueError(
            f"{where}: epoch (columns {cols}) is not 'YYYY MM DD hh mm ss': {' '.join(fields)!r}"
        ) from None
    seconds = (when - _GPS_EPOCH.replace(tzinfo=None)).total_seconds()
    if system == "C":  # the epoch of a BeiDou record is in BDT
        seconds -= BDT_MINUS_GPST_S
    return seconds


def _decode(raw: bytes, name: str) -> bytes:
    """The bytes of a navigation file, gzip-compressed ones decompressed."""
    if raw[:2] == b"\x1f\x8b":
        try:
            return gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise ValueError(f"{name}: gzip data is corrupt or cut short ({exc})") from None
    for magic, kind in ((b"\x1f\x9d", "Unix compress (.Z)"), (b"BZh", "bzip2"), (b"PK", "zip")):
        if raw[: len(magic)] == magic:
            raise ValueError(
                f"{name}: the file is {kind}-compressed; decompress it first (gzip files, "
                "'.gz', are read directly)"
            )
    return raw


def _read_header(lines: list[str], name: str) -> tuple[float, str, int]:
    if not lines:
        raise ValueError(f"{name}: empty file, expected a RINEX navigation header")
    first = lines[0]
    if first[60:80].strip() != "RINEX VERSION / TYPE":
        raise ValueError(
            f"{name}, line 1: expected 'RINEX VERSION / TYPE' in columns 61-80, got "
            f"{first[60:80].strip()!r}"
        )
    try:
        version = float(first[0:9])
    except ValueError:
        raise ValueError(f"{name}, line 1: RINEX version {first[0:9]!r} is not a number") from None
    if 2.0 <= version < 2.12:
        kind = first[20:21]
        if kind != "N":
            what = {"G": "GLONASS", "H": "SBAS"}.get(kind)
            raise ValueError(
                f"{name}, line 1: file type {kind!r} is not 'N' (a RINEX 2 GPS navigation file)"
                + (f"; {what} navigation files are not read" if what else "")
            )
        file_system = "G"
    elif 3.0 <= version < 3.06:
        if first[20:21] != "N":
            raise ValueError(
                f"{name}, line 1: file type {first[20:21]!r} is not 'N' (a navigation file)"
            )
        file_system = first[40:41]
        if file_system not in _HEADER_SYSTEMS:
            raise ValueError(
                f"{name}, line 1: unknown satellite system {file_system!r} (expected one of "
                f"{sorted(_HEADER_SYSTEMS)})"
            )
    else:
        raise ValueError(
            f"{name}, line 1: RINEX version {version} is not supported (2.00-2.11 GPS and "
            "3.00-3.05 are)"
        )
    for k, line in enumerate(lines[1:], start=1):
        if line[60:80].strip() == "END OF HEADER":
            return version, file_system, k + 1
    raise ValueError(f"{name}: no 'END OF HEADER' line")


@dataclass
class _Record:
    """One GPS or BeiDou record as read, before the per-record checks."""

    prn: str
    line: int  # 1-based line of its epoch line
    toc_gps_s: float
    values: list[float]
    bad_field: str | None  # why a field could not be read, if one could not


def _read_records(
    lines: list[str], body: int, name: str, rinex2: bool, galileo: bool = False
) -> tuple[list[_Record], dict[str, int]]:
    """The GPS and BeiDou (and with ``galileo`` Galileo) records after the header (structure
    checked, values not yet)."""
    # RINEX 3: 'A1,I2.2,1X,I4,5(1X,I2.2)' epoch, 3 fields from column 24, orbit lines 4X,4D19.12
    # RINEX 2: 'I2,5(1X,I2),F5.1' epoch, 3 fields from column 23, orbit lines 3X,4D19.12
    first_field, indent = (22, 3) if rinex2 else (23, 4)
    records: list[_Record] = []
    skipped: dict[str, int] = {}
    k, n_lines = body, len(lines)
    while k < n_lines:
        line = lines[k]
        if not line.strip():
            k += 1
            continue
        where = f"{name}, line {k + 1}"
        if rinex2:
            letter, number_text = "G", line[0:2]
        else:
            letter, number_text = line[0], line[1:3]
            if letter in _SKIPPED_SYSTEMS or (letter == "E" and not galileo):
                # the epoch line and its indented orbit lines
                skipped[letter] = skipped.get(letter, 0) + 1
                k += 1
                while k < n_lines and lines[k][:4] == "    " and lines[k].strip():
                    k += 1
                continue
            if letter not in _KEPT_SYSTEMS:
                raise ValueError(
                    f"{where}: unknown satellite system {letter!r} at the start of a record "
                    f"(expected G, C, R, E, J, I or S): {line.rstrip()!r}"
                )
        try:
            number = int(number_text)
        except ValueError:
            raise ValueError(
                f"{where}: satellite number {number_text!r} is not an integer"
            ) from None
        if not 1 <= number <= 63:
            raise ValueError(f"{where}: satellite number {number} outside 1-63")
        prn = f"{letter}{number:02d}"
        if k + 7 >= n_lines:
            raise ValueError(
                f"{where}: record of {prn} cut short: expected 7 broadcast orbit lines, the "
                f"file has {n_lines - k - 1}"
            )
        if rinex2:
            epoch = (*(line[c : c + 3] for c in (2, 5, 8, 11, 14)), line[17:22])
            toc = _calendar_gps_s(epoch, where, letter, "3-22")
        else:
            epoch = (line[4:8], *(line[c : c + 2] for c in (9, 12, 15, 18, 21)))
            toc = _calendar_gps_s(epoch, where, letter, "5-23")
        cells = [(line, first_field + 19 * j, _FIELDS[j], where) for j in range(3)]
        for m in range(1, 8):
            orbit = lines[k + m]
            owhere = f"{name}, line {k + m + 1}"
            if orbit[:indent].strip():
                raise ValueError(
                    f"{owhere}: broadcast orbit line {m} of {prn} must start with {indent} "
                    f"blanks, got {orbit[:indent]!r} (record cut short?)"
                )
            for j in range(2 if m == 7 else 4):
                cells.append((orbit, indent + 19 * j, _FIELDS[3 + 4 * (m - 1) + j], owhere))
        values: list[float] = []
        bad: str | None = None
        for text, start, fname, at in cells:
            try:
                values.append(_field(text, start, at, fname, fname in _REQUIRED))
            except _BadValue as exc:
                values.append(float("nan"))
                bad = bad or str(exc)
        values.extend([float("nan")] * (len(_FIELDS) - len(values)))
        records.append(_Record(prn, k + 1, toc, values, bad))
        k += 8
    return records, skipped


def _record_problem(el: dict[str, float], where: str) -> tuple[str, str] | None:
    """The reason and message that leave a readable record out, or None for a plausible one."""
    sqrt_a = el["sqrt_a_sqrtm"]
    if not _SQRT_A_RANGE[0] <= sqrt_a <= _SQRT_A_RANGE[1]:
        return "implausible sqrt(A)", (
            f"{where}: sqrt(A) = {sqrt_a} m^0.5 is not a plausible orbit (semi-major axis "
            f"{sqrt_a * sqrt_a / 1e3:.0f} km; {_SQRT_A_RANGE[0] ** 2 / 1e3:.0f}-"
            f"{_SQRT_A_RANGE[1] ** 2 / 1e3:.0f} km expected)"
        )
    if not 0.0 <= el["ecc"] < 0.5:
        return "implausible eccentricity", f"{where}: eccentricity {el['ecc']} outside [0, 0.5)"
    if not 0.0 <= el["toe_sow"] < SECONDS_PER_WEEK:
        return "toe outside the week", (
            f"{where}: toe {el['toe_sow']} s outside the week [0, 604800)"
        )
    if not (el["week"] >= 0.0 and float(el["week"]).is_integer()):
        return "bad week number", f"{where}: week {el['week']} is not a non-negative integer"
    return None


def read_rinex_nav(
    path: str | os.PathLike[str], warn: bool = True, galileo: bool = False
) -> NavigationFile:
    """Read the GPS and BeiDou (and with ``galileo`` Galileo) ephemerides of a RINEX
    navigation file.

    A record that cannot be used is left out, not the file: a satellite that flags itself
    unhealthy (checked first), a field that is not a number, an implausible orbit
    (``sqrt(A)`` outside 4,472-7,071 m^0.5, eccentricity outside [0, 0.5)), a ``toe``
    outside the week, or a week number that disagrees with the record's epoch. The records
    left out are counted by system and reason (:attr:`NavigationFile.rejected`) and named in
    one warning per file.

    Parameters
    ----------
    path : str or path-like
        A RINEX 3.00-3.05 navigation file (``N``; mixed, GPS or BeiDou) or a RINEX 2.00-2.11
        GPS navigation file, plain or gzip-compressed (read by its content, whatever its name).
    warn : bool, default True
        Emit a :class:`RinexWarning` naming the records left out, if any.
    galileo : bool, default False
        Also read Galileo I/NAV records (RINEX 3 ``E``); otherwise they are skipped.

    Returns
    -------
    NavigationFile

    Raises
    ------
    ValueError
        The file is missing or unreadable, compressed otherwise than with gzip, the header is
        not a RINEX 2 GPS or RINEX 3 navigation header, a record has an unknown system letter,
        a bad epoch or is cut short (the message names the file, the line number and the
        problem), or the file holds no usable ephemeris of the systems read (the message
        says why each record was left out).
    """
    p = Path(path)
    name = str(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise ValueError(f"cannot read RINEX navigation file {name}: {exc.strerror}") from None
    raw = _decode(raw, name)
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"{name}: not an ASCII text file (byte {exc.start}); a RINEX navigation file, "
            "plain or gzip-compressed, was expected"
        ) from None
    lines = text.splitlines()
    version, file_system, body = _read_header(lines, name)
    records, skipped = _read_records(lines, body, name, rinex2=version < 3.0, galileo=galileo)
    words = ["GPS", "BeiDou", "Galileo"] if galileo else ["GPS", "BeiDou"]
    systems_read = ", ".join(words[:-1]) + " and " + words[-1]
    rejected: dict[tuple[str, str], int] = {}
    first_of: dict[tuple[str, str], str] = {}

    def reject(rec: _Record, reason: str, message: str) -> None:
        key = (_KEPT_SYSTEMS[rec.prn[0]], reason)
        rejected[key] = rejected.get(key, 0) + 1
        first_of.setdefault(key, message.removeprefix(f"{name}, "))

    kept: list[_Record] = []
    n_fnav = 0
    for rec in records:
        el = dict(zip(_FIELDS, rec.values, strict=True))
        where = f"{name}, line {rec.line}: record of {rec.prn}"
        health = el["health"]
        sources = el["spare_5_2"]  # Galileo: data sources
        if rec.prn[0] == "E" and np.isfinite(sources) and int(sources) & 0b111 == _GAL_FNAV_ONLY:
            skipped["E F/NAV"] = skipped.get("E F/NAV", 0) + 1  # the I/NAV twin is used
            n_fnav += 1
            continue
        if np.isfinite(health) and health != 0.0:  # the health flag first
            reject(rec, "unhealthy", f"{where}: health {health:g}")
        elif rec.bad_field is not None:
            reject(rec, "unreadable field", rec.bad_field)
        elif (problem := _record_problem(el, where)) is not None:
            reject(rec, *problem)
        else:
            kept.append(rec)
    system = np.asarray([FILE_SYSTEMS.index(_KEPT_SYSTEMS[r.prn[0]]) for r in kept], dtype=np.intp)
    toc_gps = np.asarray([r.toc_gps_s for r in kept], dtype=np.float64)
    table = np.asarray([r.values for r in kept], dtype=np.float64).reshape(-1, len(_FIELDS))
    toe_gps, week_ok = _resolve_toe(
        table[:, _FIELDS.index("toe_sow")], table[:, _FIELDS.index("week")], system, toc_gps
    )
    for j in np.flatnonzero(~week_ok):
        rec = kept[j]
        reject(
            rec,
            "week disagrees with epoch",
            f"{name}, line {rec.line}: record of {rec.prn}: week "
            f"{int(table[j, _FIELDS.index('week')])} disagrees with its epoch",
        )
    n_records = len(records) - n_fnav
    summary = "; ".join(
        f"{s} {reason}: {n} (first: {first_of[(s, reason)]})"
        for (s, reason), n in sorted(rejected.items())
    )
    if not np.any(week_ok):
        raise ValueError(
            f"{name}: no usable {systems_read.replace(' and ', ' or ')} ephemeris (records of "
            f"other systems skipped: {skipped}; {systems_read} records left out: "
            f"{summary or 'none'})"
        )
    if rejected and warn:
        warnings.warn(
            f"{name}: left out {sum(rejected.values())} of {n_records} {systems_read} "
            f"records, used the others: {summary}",
            RinexWarning,
            stacklevel=2,
        )
    sel = np.flatnonzero(week_ok)
    kept = [kept[j] for j in sel]
    system, toc_gps, table, toe_gps = system[sel], toc_gps[sel], table[sel], toe_gps[sel]
    elements = {f: table[:, j].copy() for j, f in enumerate(_FIELDS)}
    toc_scale = toc_gps - np.where(system == FILE_SYSTEMS.index("BDS"), _BDT_EPOCH_GPS_S, 0.0)
    elements["toc_sow"] = np.mod(toc_scale, SECONDS_PER_WEEK)
    # one ephemeris per satellite and toe: of repeated broadcasts, the newest (the latest
    # transmission time; of equal ones, the last in the file)
    prns = [r.prn for r in kept]
    transmit = np.nan_to_num(elements["transmit_sow"], nan=-np.inf)
    newest: dict[tuple[str, float], int] = {}
    for j, (prn, toe) in enumerate(zip(prns, toe_gps.tolist(), strict=True)):
        old = newest.get((prn, toe))
        if old is None or transmit[j] >= transmit[old]:
            newest[(prn, toe)] = j
    keep = np.asarray(sorted(newest.values()), dtype=np.intp)
    return NavigationFile(
        path=name,
        version=version,
        file_system=file_system,
        system=readonly(system[keep]),
        prn=tuple(prns[j] for j in keep),
        toc_gps_s=readonly(toc_gps[keep]),
        toe_gps_s=readonly(toe_gps[keep]),
        elements={f: readonly(v[keep]) for f, v in elements.items()},
        skipped=skipped,
        unhealthy=sum(n for (_, reason), n in rejected.items() if reason == "unhealthy"),
        rejected=dict(sorted(rejected.items())),
        digest=hashlib.sha256(raw).hexdigest(),
    )


def _resolve_toe(
    toe_sow: NDArray[np.float64],
    field_week: NDArray[np.float64],
    system: NDArray[np.intp],
    toc_gps: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """``toe`` in GPS seconds: the week that puts it nearest its ``toc``; and whether the week
    field agrees (continuous, or modulo 1024 as some writers give GPS weeks)."""
    is_bds = system == SYSTEMS.index("BDS")
    week_start = np.where(is_bds, _BDT_EPOCH_GPS_S, 0.0)  # week 0 of the record's time scale
    toc_scale = toc_gps - week_start  # toc in the record's own time scale
    week = np.round((toc_scale - toe_sow) / SECONDS_PER_WEEK)
    diff = (week - field_week) % 1024.0
    ok = (diff <= 1.0) | (diff >= 1023.0)
    return week_start + week * SECONDS_PER_WEEK + toe_sow, ok


# --------------------------------------------------------------------------------------------
# propagation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class BroadcastConstellation:
    """Satellites propagated from broadcast ephemerides, with the interface of
    :class:`~coopnav_env.gnss.constellation.Constellation` (``system``, ``prn``, ``n_sv``,
    ``positions_ecef(t_s)``, ``subset``).

    Build it with :func:`load_broadcast_constellation` (or :meth:`from_navigation`). Time
    ``t_s`` is in seconds after ``reference_gps_s`` (see the module docstring).

    Attributes
    ----------
    system : ndarray of intp, shape (n_sv,)
        Index into :data:`FILE_SYSTEMS` per satellite (``SYSTEMS``' own for GPS and BeiDou),
        satellites grouped by system in the order asked.
    prn : tuple of str
        Satellite labels from the file (``"G05"``, ``"C01"``), sorted within a system.
    reference_gps_s : float
        GPS seconds of ``t_s = 0``: the start of the coverage, a whole second.
    coverage_gps_s : tuple of float
        ``(start, end)`` in GPS seconds: from the first to the last time at which every
        included system has a valid ephemeris (there may be gaps inside:
        ``valid_spans_gps_s``).
    valid_spans_gps_s : tuple of (float, float)
        The spans, in GPS seconds and in order, in which every included system has at least
        one satellite with a valid ephemeris.
    toe_gps_s : ndarray, shape (n_sv, n_max)
        ``toe`` of each satellite's ephemerides in GPS seconds, latest first, NaN padded.
    validity_s : ndarray, shape (n_sv, n_max)
        Half-width of each ephemeris' validity [s].
    elements : dict of str to ndarray, shape (n_sv, n_max)
        The broadcast fields of each ephemeris (:attr:`NavigationFile.elements`).
    is_geo : ndarray of bool, shape (n_sv,)
        BeiDou GEO satellites.
    source : str
        The file (for messages).
    digest : str
        SHA-256 of the file plus the systems kept (identifies the sky in caches).
    """

    system: NDArray[np.intp]
    prn: tuple[str, ...]
    reference_gps_s: float
    coverage_gps_s: tuple[float, float]
    valid_spans_gps_s: tuple[tuple[float, float], ...]
    toe_gps_s: NDArray[np.float64]
    validity_s: NDArray[np.float64]
    elements: dict[str, NDArray[np.float64]]
    is_geo: NDArray[np.bool_]
    source: str
    digest: str

    @classmethod
    def from_navigation(
        cls, nav: NavigationFile, systems: tuple[str, ...] = SYSTEMS
    ) -> BroadcastConstellation:
        """The satellites of ``systems`` (names of :data:`FILE_SYSTEMS`, in that order) in a
        :class:`NavigationFile` (Galileo's read with ``galileo=True``).

        Raises
        ------
        ValueError
            For an unknown system name, or a system with no ephemeris in the file.
        """
        if isinstance(systems, str):
            systems = (systems,)
        systems = tuple(systems)
        for s in systems:
            if s not in FILE_SYSTEMS:
                raise ValueError(f"unknown system {s!r}; allowed: {FILE_SYSTEMS}")
        if not systems or len(set(systems)) != len(systems):
            raise ValueError(
                f"systems must name distinct systems of {FILE_SYSTEMS}, got {systems!r}"
            )
        sat_rows: list[tuple[int, str, NDArray[np.intp]]] = []
        fit_h = nav.elements["fit_or_aodc"]
        validity = np.where(
            nav.system == FILE_SYSTEMS.index("GPS"),
            np.maximum(GPS_VALIDITY_S, np.nan_to_num(fit_h, nan=0.0) * 1800.0),
            np.where(nav.system == FILE_SYSTEMS.index("GAL"), GAL_VALIDITY_S, BDS_VALIDITY_S),
        )
        valid_spans: list[tuple[float, float]] | None = None
        for s in systems:
            idx = FILE_SYSTEMS.index(s)
            rows = np.flatnonzero(nav.system == idx)
            if rows.size == 0:
                hint = " (Galileo's records are read with read_rinex_nav(..., galileo=True))"
                raise ValueError(
                    f"{nav.path}: no usable {s} ephemeris in the file"
                    + (hint if s == "GAL" and "E" in nav.skipped else "")
                )
            mine_spans = _union(
                nav.toe_gps_s[rows] - validity[rows], nav.toe_gps_s[rows] + validity[rows]
            )
            valid_spans = mine_spans if valid_spans is None else _intersect(valid_spans, mine_spans)
            prns = sorted({nav.prn[j] for j in rows})
            for prn in prns:
                mine = np.asarray([j for j in rows if nav.prn[j] == prn], dtype=np.intp)
                mine = mine[np.argsort(-nav.toe_gps_s[mine], kind="stable")]  # latest first
                sat_rows.append((idx, prn, mine))
        n_sv = len(sat_rows)
        n_max = max(len(r) for _, _, r in sat_rows)
        toe = np.full((n_sv, n_max), np.nan)
        valid = np.zeros((n_sv, n_max))
        els = {f: np.full((n_sv, n_max), np.nan) for f in nav.elements}
        for i, (_, _, rows) in enumerate(sat_rows):
            toe[i, : rows.size] = nav.toe_gps_s[rows]
            valid[i, : rows.size] = validity[rows]
            for f, v in nav.elements.items():
                els[f][i, : rows.size] = v[rows]
        if not valid_spans:
            raise ValueError(
                f"{nav.path}: the ephemerides of {systems} do not overlap in time (no time at "
                "which every system has a valid ephemeris)"
            )
        start, end = valid_spans[0][0], valid_spans[-1][1]
        prn = tuple(p for _, p, _ in sat_rows)
        is_geo = np.asarray([p[0] == "C" and int(p[1:]) in BDS_GEO_PRNS for p in prn])
        digest = hashlib.sha256((nav.digest + ",".join(systems)).encode()).hexdigest()
        return cls(
            system=readonly(np.asarray([s for s, _, _ in sat_rows], dtype=np.intp)),
            prn=prn,
            reference_gps_s=float(np.floor(start)),
            coverage_gps_s=(start, end),
            valid_spans_gps_s=tuple(valid_spans),
            toe_gps_s=readonly(toe),
            validity_s=readonly(valid),
            elements={f: readonly(v) for f, v in els.items()},
            is_geo=readonly(is_geo),
            source=nav.path,
            digest=digest,
        )

    @property
    def n_sv(self) -> int:
        """Number of satellites."""
        return len(self.prn)

    @property
    def coverage_s(self) -> tuple[float, float]:
        """The coverage as ``t_s`` (seconds after ``reference_gps_s``)."""
        a, b = self.coverage_gps_s
        return a - self.reference_gps_s, b - self.reference_gps_s

    def t_s_of(self, when: Any) -> float:
        """``t_s`` of a time given as GPS seconds or a UTC ISO string (:func:`gps_seconds`)."""
        return gps_seconds(when) - self.reference_gps_s

    def coverage_text(self) -> str:
        """The coverage for messages: GPST times and ``t_s``."""
        a, b = self.coverage_gps_s
        ta, tb = self.coverage_s
        return f"{_gps_iso(a)} to {_gps_iso(b)} (t_s {ta:g} to {tb:g} s)"

    def check_covered(self, t_s: ArrayLike) -> None:
        """Raise ``ValueError`` naming the time and the coverage if any ``t_s`` is outside it."""
        t = np.asarray(t_s, dtype=np.float64)
        lo, hi = self.coverage_s
        bad = ~((t >= lo) & (t <= hi))
        if np.any(bad):
            first = float(t[bad].flat[0])
            raise ValueError(
                f"time t_s = {first:g} s ({_gps_iso(first + self.reference_gps_s)}) is outside "
                f"the validity of every ephemeris in {self.source}: its coverage is "
                f"{self.coverage_text()}"
            )

    def _select(self, t: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """Per time and satellite, the column of the ephemeris used and whether one is valid.

        ``t``: shape (n_t,) [s after reference]; returns shapes (n_t, n_sv)."""
        dt = np.abs((self.reference_gps_s - self.toe_gps_s)[None] + t[:, None, None])
        ok = dt <= self.validity_s[None]  # NaN toe compares False
        key = np.where(ok, dt, np.inf)
        col = np.argmin(key, axis=2)  # first minimum: the later toe on a tie
        has = np.take_along_axis(ok, col[..., None], axis=2)[..., 0]
        return col, has

    def _state(self, t_s: ArrayLike, what: str) -> NDArray[np.float64]:
        t = as_float_array(t_s, "t_s")
        if t.ndim > 1:
            raise ValueError(f"t_s must be a scalar or 1-D array, got shape {t.shape}")
        self.check_covered(t)
        tt = np.atleast_1d(t)
        col, has = self._select(tt)
        rows = np.arange(self.n_sv)[None, :]

        def pick(name: str) -> NDArray[np.float64]:
            return self.elements[name][rows, col]

        out = _propagate(
            pick,
            self.system[None, :],
            self.is_geo[None, :],
            self.reference_gps_s,
            tt[:, None],
            what,
        )
        out = np.where(has[..., None] if out.ndim == 3 else has, out, np.nan)
        return out[0] if t.ndim == 0 else out

    def positions_ecef(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Satellite positions in ECEF (WGS 84; BeiDou's CGCS2000 taken as the same).

        Parameters
        ----------
        t_s : float or array_like, shape () or (n_t,)
            Seconds after ``reference_gps_s`` (GPS time; a BeiDou satellite is evaluated at
            the same instant in BDT).

        Returns
        -------
        ndarray, shape (n_sv, 3) for scalar ``t_s``, (n_t, n_sv, 3) for 1-D ``t_s``
            ECEF positions [m]; NaN rows for satellites with no valid ephemeris at that time.

        Raises
        ------
        ValueError
            For a time outside the coverage (the message names the file and its coverage).
        """
        return self._state(t_s, "position")

    def clock_offsets_s(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Satellite clock offsets ``af0 + af1 dt + af2 dt^2 + dtr`` (no ``TGD``) [s].

        Same time argument as :meth:`positions_ecef`; shape (n_sv,) or (n_t, n_sv).
        """
        return self._state(t_s, "clock")

    def visibility(
        self,
        lat_deg: float,
        lon_deg: float,
        alt_m: float = 0.0,
        elevation_mask_deg: float = 10.0,
        min_sats: int = 4,
    ) -> SkyVisibility:
        """What a receiver at a place sees of this sky over the coverage (cached).

        Sampled every 30 s from the start to the end of the coverage (the end included).
        A time is usable when every included system has at least one satellite with a valid
        ephemeris and at least ``min_sats`` satellites with a valid ephemeris are above
        ``elevation_mask_deg`` at the place.

        Parameters
        ----------
        lat_deg, lon_deg, alt_m : float
            The place (WGS 84) [deg, deg, m].
        elevation_mask_deg : float, default 10.0
            Elevation cut-off [deg].
        min_sats : int, default 4
            Satellites needed above the cut-off.

        Returns
        -------
        SkyVisibility
        """
        return _visibility(
            self,
            float(lat_deg),
            float(lon_deg),
            float(alt_m),
            float(elevation_mask_deg),
            int(min_sats),
        )

    def subset(self, mask_or_indices: ArrayLike) -> BroadcastConstellation:
        """The same sky restricted to a selection of satellites (order kept, no repeats).

        The coverage is kept (it is the file's, not the selection's).
        """
        sel = np.asarray(mask_or_indices)
        if sel.dtype == np.bool_:
            if sel.shape != (self.n_sv,):
                raise ValueError(f"mask must have shape ({self.n_sv},), got {sel.shape}")
            idx = np.flatnonzero(sel)
        else:
            idx = as_index_array(sel, "mask_or_indices", self.n_sv)
            if len(set(idx.tolist())) != idx.size:
                raise ValueError("mask_or_indices must not repeat a satellite")
        return BroadcastConstellation(
            system=readonly(self.system[idx]),
            prn=tuple(self.prn[j] for j in idx),
            reference_gps_s=self.reference_gps_s,
            coverage_gps_s=self.coverage_gps_s,
            valid_spans_gps_s=self.valid_spans_gps_s,
            toe_gps_s=readonly(self.toe_gps_s[idx]),
            validity_s=readonly(self.validity_s[idx]),
            elements={f: readonly(v[idx]) for f, v in self.elements.items()},
            is_geo=readonly(self.is_geo[idx]),
            source=self.source,
            digest=hashlib.sha256(
                (self.digest + ",".join(map(str, idx.tolist()))).encode()
            ).hexdigest(),
        )


def _union(lo: NDArray[np.float64], hi: NDArray[np.float64]) -> list[tuple[float, float]]:
    """The union of the intervals ``[lo_i, hi_i]`` as sorted disjoint intervals."""
    out: list[tuple[float, float]] = []
    for a, b in sorted(zip(lo.tolist(), hi.tolist(), strict=True)):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def _intersect(
    x: list[tuple[float, float]], y: list[tuple[float, float]]
) -> list[tuple[float, float]]:
    """The intersection of two sorted lists of disjoint intervals (empty pieces dropped)."""
    out, i, j = [], 0, 0
    while i < len(x) and j < len(y):
        a, b = max(x[i][0], y[j][0]), min(x[i][1], y[j][1])
        if b > a:
            out.append((a, b))
        if x[i][1] < y[j][1]:
            i += 1
        else:
            j += 1
    return out


@dataclass(frozen=True)
class SkyVisibility:
    """What a place sees of a :class:`BroadcastConstellation` (from
    :meth:`BroadcastConstellation.visibility`).

    Attributes
    ----------
    spans_s : tuple of (float, float)
        The usable spans as ``t_s``, in order: every included system has a satellite with a
        valid ephemeris and at least ``min_sats`` satellites with a valid ephemeris are above
        the cut-off (sampled every 30 s; the spans' ends are sample times or the ends of
        :attr:`BroadcastConstellation.valid_spans_gps_s`).
    visible_mean : float
        Mean number of satellites with a valid ephemeris above the cut-off, over the samples in
        which every system has a valid ephemeris.
    above_mean : float
        Mean number of the file's satellites above the cut-off at the same samples, whether
        their ephemeris is valid then or not (each propagated from its nearest ``toe``).
    """

    spans_s: tuple[tuple[float, float], ...]
    visible_mean: float
    above_mean: float

    @property
    def seen_fraction(self) -> float:
        """``visible_mean / above_mean``: near 1 where the file's station saw what the place
        sees, low far from it (a station's file holds the satellites it tracked)."""
        return self.visible_mean / self.above_mean if self.above_mean > 0 else 0.0

    def room_s(self, duration_s: float) -> float:
        """Total time at which a window of ``duration_s`` seconds can start inside a span."""
        return float(sum(max(0.0, b - a - duration_s) for a, b in self.spans_s))

    def start_s(self, duration_s: float, u: float) -> float:
        """The start of a window of ``duration_s`` seconds, ``u`` seconds into the room the
        spans leave (``0 <= u <= room_s(duration_s)``): spans one after the other."""
        last = None
        for a, b in self.spans_s:
            room = b - a - duration_s
            if room < 0.0:
                continue
            if u <= room:
                return a + u
            u -= room
            last = b - duration_s
        if last is None:
            raise ValueError(f"no usable span holds {duration_s:g} s")
        return last

    def spans_text(self, reference_gps_s: float, limit: int = 4) -> str:
        """The spans for messages (GPST), at most ``limit`` of them."""
        if not self.spans_s:
            return "none"
        parts = [
            f"{_gps_iso(a + reference_gps_s)} to {_gps_iso(b + reference_gps_s)}"
            for a, b in self.spans_s[:limit]
        ]
        more = len(self.spans_s) - limit
        return ", ".join(parts) + (f" and {more} more" if more > 0 else "")


_VISIBILITY_STEP_S = 30.0


@functools.lru_cache(maxsize=64)
def _visibility(
    sky: BroadcastConstellation,
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    mask_deg: float,
    min_sats: int,
) -> SkyVisibility:
    lo, hi = sky.coverage_s
    t = np.arange(lo, hi, _VISIBILITY_STEP_S)
    t = np.append(t[t < hi], hi)
    origin = geodetic_to_ecef(lat_deg, lon_deg, alt_m)[None]
    rows = np.arange(sky.n_sv)[None, :]
    systems = sorted(set(sky.system.tolist()))
    ok, n_visible, n_above = (np.zeros(t.size, dtype=bool), np.zeros(t.size), np.zeros(t.size))
    sys_ok = np.zeros(t.size, dtype=bool)
    for c in range(0, t.size, 256):
        tt = t[c : c + 256]
        col, has = sky._select(tt)
        dt = np.abs((sky.reference_gps_s - sky.toe_gps_s)[None] + tt[:, None, None])
        nearest = np.argmin(np.where(np.isnan(dt), np.inf, dt), axis=2)
        above = []
        for cols in (col, nearest):

            def pick(name: str, cols=cols) -> NDArray[np.float64]:
                return sky.elements[name][rows, cols]

            pos = _propagate(
                pick,
                sky.system[None, :],
                sky.is_geo[None, :],
                sky.reference_gps_s,
                tt[:, None],
                "position",
            )
            _, el = azimuth_elevation(origin, pos.reshape(-1, 3))
            above.append(el.reshape(tt.size, sky.n_sv) > mask_deg)
        visible = above[0] & has
        every = np.all([has[:, sky.system == s].any(axis=1) for s in systems], axis=0)
        sys_ok[c : c + tt.size] = every
        n_visible[c : c + tt.size] = visible.sum(axis=1)
        n_above[c : c + tt.size] = above[1].sum(axis=1)
        ok[c : c + tt.size] = every & (visible.sum(axis=1) >= min_sats)
    runs: list[tuple[float, float]] = []
    idx = np.flatnonzero(ok)
    if idx.size:
        breaks = np.flatnonzero(np.diff(idx) > 1)
        for a, b in zip(
            np.concatenate([[idx[0]], idx[breaks + 1]]),
            np.concatenate([idx[breaks], [idx[-1]]]),
            strict=True,
        ):
            runs.append((float(t[a]), float(t[b])))
    valid = [(a - sky.reference_gps_s, b - sky.reference_gps_s) for a, b in sky.valid_spans_gps_s]
    spans = tuple(_intersect(runs, valid))
    n = max(int(sys_ok.sum()), 1)
    return SkyVisibility(
        spans_s=spans,
        visible_mean=float(n_visible[sys_ok].sum() / n),
        above_mean=float(n_above[sys_ok].sum() / n),
    )


def _wrap_half_week(dt: NDArray[np.float64]) -> NDArray[np.float64]:
    """Seconds-of-week difference brought into [-302400, 302400] (IS-GPS-200 20.3.3.4.3)."""
    dt = np.where(dt > _HALF_WEEK_S, dt - SECONDS_PER_WEEK, dt)
    return np.where(dt < -_HALF_WEEK_S, dt + SECONDS_PER_WEEK, dt)


def _propagate(pick, system, is_geo, ref_gps, t_rel, what: str) -> NDArray[np.float64]:
    """Positions (..., 3) or clock offsets (...) from broadcast elements, vectorised.

    ``pick(name)`` gives an element per (time, satellite); the time is ``ref_gps + t_rel`` in
    GPS seconds (``ref_gps`` a whole second, kept apart so that seconds of the week stay
    exact)."""
    bds = system == FILE_SYSTEMS.index("BDS")
    gal = system == FILE_SYSTEMS.index("GAL")
    mu = np.where(bds, BDS_MU_M3PS2, np.where(gal, GAL_MU_M3PS2, GPS_MU_M3PS2))
    omega_e = np.where(bds, BDS_OMEGA_E_RADPS, np.where(gal, GAL_OMEGA_E_RADPS, GPS_OMEGA_E_RADPS))
    # t in the satellite's own time scale, as seconds of its week (IS-GPS-200 / BDS ICD t - toe)
    ref_sow = np.mod(ref_gps - np.where(bds, _BDT_EPOCH_GPS_S, 0.0), SECONDS_PER_WEEK)
    t_sow = np.mod(ref_sow + t_rel, SECONDS_PER_WEEK)
    toe = pick("toe_sow")
    tk = _wrap_half_week(t_sow - toe)
    sqrt_a = pick("sqrt_a_sqrtm")
    a = sqrt_a * sqrt_a
    ecc = pick("ecc")
    n = np.sqrt(mu / a**3) + pick("delta_n_radps")
    mk = pick("m0_rad") + n * tk
    ek = mk.copy()
    for _ in range(_KEPLER_ITERATIONS):  # Newton on E - e sin E = M
        ek = ek - (ek - ecc * np.sin(ek) - mk) / (1.0 - ecc * np.cos(ek))
    if what == "clock":
        dt_clock = _wrap_half_week(t_sow - pick("toc_sow"))
        rel = -2.0 * np.sqrt(mu) / SPEED_OF_LIGHT_MPS**2 * ecc * sqrt_a * np.sin(ek)
        return pick("af0_s") + pick("af1_sps") * dt_clock + pick("af2_sps2") * dt_clock**2 + rel
    sin_e, cos_e = np.sin(ek), np.cos(ek)
    vk = np.arctan2(np.sqrt(1.0 - ecc * ecc) * sin_e, cos_e - ecc)
    phi = vk + pick("omega_rad")
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    uk = phi + pick("cus_rad") * s2 + pick("cuc_rad") * c2
    rk = a * (1.0 - ecc * cos_e) + pick("crs_m") * s2 + pick("crc_m") * c2
    ik = pick("i0_rad") + pick("cis_rad") * s2 + pick("cic_rad") * c2 + pick("idot_radps") * tk
    xp, yp = rk * np.cos(uk), rk * np.sin(uk)
    omega_dot = pick("omega_dot_radps")
    # MEO/IGSO (and GPS): node longitude in the Earth-fixed frame; GEO: in the toe's inertial frame
    node = np.where(
        is_geo,
        pick("omega0_rad") + omega_dot * tk - omega_e * toe,
        pick("omega0_rad") + (omega_dot - omega_e) * tk - omega_e * toe,
    )
    cos_n, sin_n = np.cos(node), np.sin(node)
    cos_i, sin_i = np.cos(ik), np.sin(ik)
    x = xp * cos_n - yp * cos_i * sin_n
    y = xp * sin_n + yp * cos_i * cos_n
    z = yp * sin_i
    # GEO: R_Z(OmegaE tk) R_X(-5 deg) (BDS-SIS-ICD-B1I 5.2.4.12)
    cf, sf = np.cos(_BDS_GEO_INCLINATION_RAD), np.sin(_BDS_GEO_INCLINATION_RAD)
    y5 = cf * y + sf * z
    z5 = -sf * y + cf * z
    ang = omega_e * tk
    ca, sa = np.cos(ang), np.sin(ang)
    xg = ca * x + sa * y5
    yg = -sa * x + ca * y5
    return np.stack(
        [np.where(is_geo, xg, x), np.where(is_geo, yg, y), np.where(is_geo, z5, z)], axis=-1
    )


@functools.lru_cache(maxsize=16)
def _cached_sky(
    path: str, mtime_ns: int, size: int, systems: tuple[str, ...]
) -> BroadcastConstellation:
    nav = _cached_nav(path, mtime_ns, size, "GAL" in systems)
    return BroadcastConstellation.from_navigation(nav, systems)


@functools.lru_cache(maxsize=8)
def _cached_nav(path: str, mtime_ns: int, size: int, galileo: bool = False) -> NavigationFile:
    """The file read once (and its records' warning given once) for every ``systems``
    (once more with Galileo's records when a sky asks for Galileo)."""
    return read_rinex_nav(path, galileo=galileo)


def clear_caches() -> None:
    """Forget the files read and the skies built from them (a file read again warns again)."""
    _cached_sky.cache_clear()
    _cached_nav.cache_clear()
    _visibility.cache_clear()


def resolve_nav_path(spec: str) -> Path:
    """The file a ``rinex:`` setting names: a name of :data:`SHIPPED_NAV_PATHS` (``"sample"``,
    ``"igs_brdc"``) is the shipped file, anything else a path."""
    shipped = SHIPPED_NAV_PATHS.get(spec)
    return shipped if shipped is not None else Path(spec).expanduser()


def load_broadcast_constellation(
    path: str | os.PathLike[str], systems: tuple[str, ...] = SYSTEMS
) -> BroadcastConstellation:
    """The sky of a RINEX navigation file (cached per file content and ``systems``).

    Parameters
    ----------
    path : str or path-like
        The navigation file; a name of :data:`SHIPPED_NAV_PATHS` (``"sample"``, ``"igs_brdc"``):
        the one shipped with the package.
    systems : tuple of str, optional
        Systems to keep, in this order (names from :data:`FILE_SYSTEMS`: ``"GPS"``,
        ``"BDS"``, and ``"GAL"`` for Galileo, whose records are read only when asked for).

    Returns
    -------
    BroadcastConstellation

    Raises
    ------
    ValueError
        A missing or bad file (:func:`read_rinex_nav`), or a system with no ephemeris.
    """
    p = resolve_nav_path(str(path)) if isinstance(path, str) else Path(path)
    try:
        st = p.stat()
    except OSError:
        raise ValueError(f"RINEX navigation file {str(path)!r} does not exist") from None
    if not p.is_file():
        raise ValueError(f"RINEX navigation file {str(path)!r} is not a file")
    if isinstance(systems, str):
        systems = (systems,)
    return _cached_sky(str(p.resolve()), st.st_mtime_ns, st.st_size, tuple(systems))
