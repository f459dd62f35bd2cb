"""Write the sample RINEX 3.04 navigation file ``sample_nav.rnx`` (GPS + BeiDou, one day).

The satellites are the project's nominal constellations
(:func:`~coopnav_env.gnss.constellation.gps_nominal_constellation`, 24 GPS slots, and
:func:`~coopnav_env.gnss.constellation.beidou3_constellation` with its 3 GEO and 3 IGSO,
30 BeiDou satellites), each given a small eccentricity, an argument of perigee and harmonic,
drift and clock terms of the sizes real broadcast ephemerides carry, all drawn from a fixed
seed. The file holds the day 2026-12-03 (GPST): GPS ephemerides every 2 h (toe 00:00 ...
22:00) and BeiDou ephemerides every hour (toe 00:00 ... 23:00 BDT), so that every time of the
day is covered. GPS PRNs are the nominal slot labels G01-G24; the BeiDou satellites take
BeiDou-3 numbers: MEO C19-C37 and C41-C45, IGSO C38-C40, GEO C59-C61.

Each satellite's broadcast orbit is one consistent trajectory: for GPS and the BeiDou MEO and
IGSO satellites all ephemerides hold the same orbit referred to their own ``toe`` (mean
anomaly advanced, node and inclination drifted by the broadcast rates), so consecutive
ephemerides give the same positions where they overlap. A BeiDou GEO's orbit is a two-body
orbit fixed in inertial space, written at each ``toe`` in the ICD's frame (the Earth-fixed
axes at ``toe`` tilted by +5 deg about X; elements from the state vector); its small harmonic
and drift terms are the same numbers in every ephemeris, so consecutive ephemerides differ by
a few metres.

Run ``python coopnav_env/data/make_sample_nav.py`` to rewrite the file (the same text every
time; ``tests/gnss/test_rinex.py`` checks that the shipped file is what this writes).
"""

from __future__ import annotations

import datetime as dt
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from coopnav_env.constants import GM_EARTH_M3PS2, OMEGA_EARTH_RADPS
from coopnav_env.gnss.constellation import (
    BDS_GEO_LON_DEG,
    GPS_GHA0_DEG,
    beidou3_constellation,
    gps_nominal_constellation,
)
from coopnav_env.gnss.rinex import (
    BDS_MU_M3PS2,
    BDS_OMEGA_E_RADPS,
    GPS_MU_M3PS2,
    GPS_OMEGA_E_RADPS,
)

DAY = dt.datetime(2026, 12, 3)
"""The day of the file (GPST for GPS records, BDT for BeiDou records)."""

SEED = 20261203
WEEK_S = 604_800.0
GPS_EPOCH = dt.datetime(1980, 1, 6)
BDT_EPOCH = dt.datetime(2006, 1, 1)
NOMINAL_EPOCH_GPS_S = (dt.datetime(1993, 7, 1) - GPS_EPOCH).total_seconds() + 9.0
"""The nominal constellations' reference epoch (1993-07-01 00:00 UTC) in GPS seconds."""

BDS_MEO_PRNS = (*range(19, 38), *range(41, 46))  # 24 MEO: C19-C37, C41-C45 (BeiDou-3 MEO)
BDS_IGSO_PRNS = (38, 39, 40)  # BeiDou-3 IGSO
BDS_GEO_PRNS = (59, 60, 61)  # BeiDou-3 GEO


def _fmt(x: float) -> str:
    """One RINEX D19.12 field (``-1.234567890123D-05``)."""
    if x == 0.0:
        return " 0.000000000000D+00"
    m, e = f"{x:.12E}".split("E")
    return f"{m:>15}D{int(e):+03d}"


def _line(values: list[float], first: str = "    ") -> str:
    return first + "".join(_fmt(v) for v in values)


def _elements_from_state(r: np.ndarray, v: np.ndarray, mu: float) -> dict[str, float]:
    """Classical elements (a, e, i, node, perigee, mean anomaly) of a two-body state."""
    h = np.cross(r, v)
    rn, vn = np.linalg.norm(r), np.linalg.norm(v)
    node_vec = np.cross([0.0, 0.0, 1.0], h)
    e_vec = ((vn * vn - mu / rn) * r - np.dot(r, v) * v) / mu
    ecc = float(np.linalg.norm(e_vec))
    a = 1.0 / (2.0 / rn - vn * vn / mu)
    inc = float(np.arccos(h[2] / np.linalg.norm(h)))
    node = float(np.arctan2(node_vec[1], node_vec[0]))
    nn = node_vec / np.linalg.norm(node_vec)
    omega = float(np.arctan2(np.dot(np.cross(nn, e_vec), h) / np.linalg.norm(h), np.dot(nn, e_vec)))
    nu = float(np.arctan2(np.dot(np.cross(e_vec, r), h) / np.linalg.norm(h), np.dot(e_vec, r)))
    ea = 2.0 * np.arctan(np.sqrt((1 - ecc) / (1 + ecc)) * np.tan(nu / 2.0))
    return {
        "a": a,
        "e": ecc,
        "i": inc,
        "node": node,
        "omega": omega,
        "m": float(ea - ecc * np.sin(ea)),
    }


def _kepler_state(a, e, i, node, omega, m, mu):
    """Position and velocity of a two-body orbit (inertial)."""
    ea = m
    for _ in range(30):
        ea = ea - (ea - e * np.sin(ea) - m) / (1 - e * np.cos(ea))
    nu = 2 * np.arctan2(np.sqrt(1 + e) * np.sin(ea / 2), np.sqrt(1 - e) * np.cos(ea / 2))
    p = a * (1 - e * e)
    r = p / (1 + e * np.cos(nu))
    r_pf = np.array([r * np.cos(nu), r * np.sin(nu), 0.0])
    v_pf = np.sqrt(mu / p) * np.array([-np.sin(nu), e + np.cos(nu), 0.0])

    def rot(axis, ang):
        c, s = np.cos(ang), np.sin(ang)
        if axis == 3:
            return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])

    q = rot(3, node) @ rot(1, i) @ rot(3, omega)
    return q @ r_pf, q @ v_pf


def _epoch_line(prn: str, when: dt.datetime, clock: tuple[float, float, float]) -> str:
    head = f"{prn} {when:%Y %m %d %H %M %S}"
    return head + "".join(_fmt(c) for c in clock)


def _record(prn, when, clock, e, week, extra5, line6, line7) -> list[str]:
    return [
        _epoch_line(prn, when, clock),
        _line([e["iode"], e["crs"], e["dn"], e["m0"]]),
        _line([e["cuc"], e["ecc"], e["cus"], e["sqrta"]]),
        _line([e["toe"], e["cic"], e["omega0"], e["cis"]]),
        _line([e["i0"], e["crc"], e["omega"], e["omegadot"]]),
        _line([e["idot"], extra5, float(week), 0.0]),
        _line(line6),
        _line(line7),
    ]


def _wrap(x: float) -> float:
    return float((x + np.pi) % (2 * np.pi) - np.pi)


def _kepler_records(rng, system: str, prns, a_m, inc, node_ecef0, u0, t_ref, toes, mu, omega_e):
    """Records of MEO/IGSO/GPS satellites from circular nominal orbits made slightly eccentric.

    ``node_ecef0``, ``u0``: Earth-fixed node longitude and argument of latitude at ``t_ref``
    (GPS seconds); ``toes``: list of (toe in GPS seconds, toe seconds of week, week, epoch)."""
    out: dict[str, list[list[str]]] = {}
    for k, prn in enumerate(prns):
        gps = system == "G"
        ecc = rng.uniform(0.002, 0.02) if gps else rng.uniform(0.0005, 0.004)
        omega = rng.uniform(-np.pi, np.pi)
        dn = rng.uniform(3.5e-9, 5.5e-9) if a_m[k] < 3e7 else rng.uniform(-2e-10, 2e-10)
        omegadot = rng.uniform(-8.6e-9, -7.6e-9) if a_m[k] < 3e7 else rng.uniform(-3e-9, -1e-9)
        idot = rng.uniform(-6e-10, 6e-10)
        crs, crc = rng.uniform(-120.0, 120.0), rng.uniform(120.0, 360.0)
        cuc, cus = rng.uniform(-8e-6, 8e-6), rng.uniform(-8e-6, 1.2e-5)
        cic, cis = rng.uniform(-2e-7, 2e-7), rng.uniform(-2e-7, 2e-7)
        af0, af1 = rng.uniform(-6e-4, 6e-4), rng.uniform(-1e-11, 1e-11)
        af2 = 0.0
        tgd = rng.uniform(-1.2e-8, 1.2e-8)
        # mean anomaly at t_ref from the nominal argument of latitude (true anomaly u - omega)
        nu = u0[k] - omega
        ea = 2.0 * np.arctan(np.sqrt((1 - ecc) / (1 + ecc)) * np.tan(nu / 2.0))
        m_ref = ea - ecc * np.sin(ea)
        n = np.sqrt(mu / a_m[k] ** 3) + dn
        recs = []
        for iode, (toe_gps, toe_sow, week, when) in enumerate(toes):
            d = toe_gps - t_ref
            node_toe = node_ecef0[k] + (omegadot - omega_e) * d  # Earth-fixed node at toe
            el = {
                "iode": float(iode % 256) if gps else float(iode % 32),
                "crs": crs,
                "dn": dn,
                "m0": _wrap(m_ref + n * d),
                "cuc": cuc,
                "ecc": ecc,
                "cus": cus,
                "sqrta": float(np.sqrt(a_m[k])),
                "toe": toe_sow,
                "cic": cic,
                "omega0": _wrap(node_toe + omega_e * toe_sow),
                "cis": cis,
                "i0": inc[k] + idot * d,
                "crc": crc,
                "omega": omega,
                "omegadot": omegadot,
                "idot": idot,
            }
            clock = (af0 + af1 * d, af1, af2)
            if gps:
                recs.append(
                    _record(
                        prn, when, clock, el, week, 1.0,
                        [2.0, 0.0, tgd, el["iode"]],
                        [toe_sow - 18.0, 4.0],
                    )
                )  # fmt: skip
            else:
                recs.append(
                    _record(
                        prn, when, clock, el, week, 0.0,
                        [2.0, 0.0, tgd, -tgd],
                        [toe_sow - 30.0, el["iode"]],
                    )
                )  # fmt: skip
        out[prn] = recs
    return out


def _geo_records(rng, prns, lon_deg, toes):
    """Records of BeiDou GEO satellites: a two-body orbit near the given longitudes, written in
    the ICD's frame at each toe (tilted +5 deg about X, Earth-fixed axes at toe)."""
    mu, we = BDS_MU_M3PS2, BDS_OMEGA_E_RADPS
    a_geo = (mu / we**2) ** (1.0 / 3.0)
    out: dict[str, list[list[str]]] = {}
    t_ref = toes[0][0]
    for k, prn in enumerate(prns):
        inc = np.radians(rng.uniform(0.5, 1.8))
        node = rng.uniform(-np.pi, np.pi)
        ecc = rng.uniform(0.0002, 0.001)
        omega = rng.uniform(-np.pi, np.pi)
        # inertial frame = Earth-fixed axes at t_ref; the satellite over lon_deg at t_ref
        m0 = np.radians(lon_deg[k]) - node - omega  # mean longitude ~ longitude (small i, e)
        crs, crc = rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0)
        cuc, cus = rng.uniform(-5e-8, 5e-8), rng.uniform(-5e-8, 5e-8)
        cic, cis = rng.uniform(-3e-9, 3e-9), rng.uniform(-3e-9, 3e-9)
        omegadot = rng.uniform(-3e-11, 3e-11)
        idot = rng.uniform(-2e-11, 2e-11)
        af0, af1 = rng.uniform(-6e-4, 6e-4), rng.uniform(-1e-11, 1e-11)
        tgd = rng.uniform(-1.2e-8, 1.2e-8)
        n = np.sqrt(mu / a_geo**3)
        recs = []
        for iode, (toe_gps, toe_sow, week, when) in enumerate(toes):
            d = toe_gps - t_ref
            r, v = _kepler_state(a_geo, ecc, inc, node, omega, m0 + n * d, mu)
            # Earth-fixed axes at toe: rotate the t_ref inertial frame by we * d about Z
            c, s = np.cos(we * d), np.sin(we * d)
            rz = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
            c5, s5 = np.cos(np.radians(5.0)), np.sin(np.radians(5.0))
            rx = np.array([[1.0, 0.0, 0.0], [0.0, c5, s5], [0.0, -s5, c5]])  # R_X(+5 deg)
            el_icd = _elements_from_state(rx @ rz @ r, rx @ rz @ v, mu)
            el = {
                "iode": float(iode % 32),
                "crs": crs,
                "dn": 0.0,
                "m0": _wrap(el_icd["m"]),
                "cuc": cuc,
                "ecc": el_icd["e"],
                "cus": cus,
                "sqrta": float(np.sqrt(el_icd["a"])),
                "toe": toe_sow,
                "cic": cic,
                "omega0": _wrap(el_icd["node"] + we * toe_sow),
                "cis": cis,
                "i0": el_icd["i"],
                "crc": crc,
                "omega": _wrap(el_icd["omega"]),
                "omegadot": omegadot,
                "idot": idot,
            }
            recs.append(
                _record(
                    prn, when, (af0 + af1 * d, af1, 0.0), el, week, 0.0,
                    [2.0, 0.0, tgd, -tgd],
                    [toe_sow - 30.0, el["iode"]],
                )
            )  # fmt: skip
        out[prn] = recs
    return out


def _toes(system: str, step_h: int):
    """(toe GPS seconds, toe seconds of week, week, epoch in the system's time) per toe."""
    scale_epoch = GPS_EPOCH if system == "G" else BDT_EPOCH
    scale_start_gps = 0.0 if system == "G" else (BDT_EPOCH - GPS_EPOCH).total_seconds() + 14.0
    out = []
    for h in range(0, 24, step_h):
        when = DAY + dt.timedelta(hours=h)
        sec = (when - scale_epoch).total_seconds()
        week, sow = divmod(sec, WEEK_S)
        out.append((scale_start_gps + sec, sow, int(week), when))
    return out


def sample_nav_text() -> str:
    """The text of the sample navigation file (deterministic)."""
    rng = np.random.default_rng(SEED)
    gps = gps_nominal_constellation()
    bds = beidou3_constellation(include_geo_igso=True)
    gps_toes = _toes("G", 2)
    bds_toes = _toes("C", 1)

    def nominal_state(con, t_gps):
        t = t_gps - NOMINAL_EPOCH_GPS_S
        node = con.raan_rad - np.radians(GPS_GHA0_DEG) - OMEGA_EARTH_RADPS * t
        u = con.arg_lat_rad + np.sqrt(GM_EARTH_M3PS2 / con.semi_major_axis_m**3) * t
        return node, u

    records: dict[str, list[list[str]]] = {}
    t_ref = gps_toes[0][0]
    node, u = nominal_state(gps, t_ref)
    records.update(
        _kepler_records(
            rng, "G", gps.prn, gps.semi_major_axis_m, gps.inclination_rad, node, u, t_ref,
            gps_toes, GPS_MU_M3PS2, GPS_OMEGA_E_RADPS,
        )
    )  # fmt: skip
    t_ref = bds_toes[0][0]
    node, u = nominal_state(bds, t_ref)
    meo = slice(0, 24)
    igso = slice(27, 30)
    prn_meo = [f"C{p:02d}" for p in BDS_MEO_PRNS]
    prn_igso = [f"C{p:02d}" for p in BDS_IGSO_PRNS]
    for sl, prns in ((meo, prn_meo), (igso, prn_igso)):
        records.update(
            _kepler_records(
                rng, "C", prns, bds.semi_major_axis_m[sl], bds.inclination_rad[sl], node[sl],
                u[sl], t_ref, bds_toes, BDS_MU_M3PS2, BDS_OMEGA_E_RADPS,
            )
        )  # fmt: skip
    prn_geo = [f"C{p:02d}" for p in BDS_GEO_PRNS]
    records.update(_geo_records(rng, prn_geo, BDS_GEO_LON_DEG, bds_toes))
    header = [
        f"{'3.04':>9}{'':11}{'N: GNSS NAV DATA':<20}{'M: MIXED':<20}RINEX VERSION / TYPE",
        f"{'make_sample_nav.py':<20}{'coopnav':<20}{'20261203 000000 UTC':<20}PGM / RUN BY / DATE",
        f"{'Synthetic: nominal GPS + BeiDou-3 orbits (coopnav sample)':<60}COMMENT",
        f"{'':4}{18:6d}{'':50}LEAP SECONDS",
        f"{'':60}END OF HEADER",
    ]
    body = []
    # time order, then G before C, then PRN (as writers of merged files do)
    entries = []
    for prn, recs in records.items():
        toes = gps_toes if prn[0] == "G" else bds_toes
        for (toe_gps, *_), rec in zip(toes, recs, strict=True):
            entries.append((toe_gps, prn[0] != "G", prn, rec))
    for *_, rec in sorted(entries, key=lambda x: x[:3]):
        body.extend(rec)
    return "\n".join(header + body) + "\n"


def write_sample_nav(path: str | os.PathLike[str]) -> Path:
    """Write :func:`sample_nav_text` to ``path`` (through a temporary name and a rename)."""
    p = Path(path)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=p.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w", newline="\n") as fh:
            fh.write(sample_nav_text())
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("sample_nav.rnx")
    print(write_sample_nav(target))
