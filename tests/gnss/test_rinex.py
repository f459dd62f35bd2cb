"""RINEX 3 navigation files: the parser, and broadcast orbits against an independent oracle.

The oracle (:func:`_oracle_state`) is written here from IS-GPS-200 Table 20-IV and
BDS-SIS-ICD-B1I 5.2.4.12 on a different code path from :mod:`coopnav_env.gnss.rinex`: one
satellite and one time at a time with the ``math`` module, ephemeris chosen by a loop over
the file's records, ``t - toe`` from absolute GPS seconds (not seconds of the week), Kepler's
equation by fixed-point iteration, the GEO rotation as explicit matrices.
"""

from __future__ import annotations

import datetime as dt
import gzip
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.gnss.frames import ecef_to_geodetic
from coopnav_env.gnss.rinex import (
    SAMPLE_NAV_PATH,
    BroadcastConstellation,
    RinexWarning,
    gps_seconds,
    load_broadcast_constellation,
    read_rinex_nav,
)

SPEED_OF_LIGHT = 299_792_458.0
BDT0_GPS_S = 1356 * 604_800 + 14  # BDT 2006-01-01 00:00:00 in GPS seconds


# --------------------------------------------------------------------------------------------
# the oracle
# --------------------------------------------------------------------------------------------


def _oracle_pick(nav, prn: str, t_gps: float):
    """The record of ``prn`` with the closest toe valid at ``t_gps`` (ties: the later toe)."""
    best = None
    for j, p in enumerate(nav.prn):
        if p != prn:
            continue
        gps = p[0] == "G"
        fit = nav.elements["fit_or_aodc"][j]
        half = (max(4.0, fit if gps and fit == fit else 0.0) / 2.0 * 3600.0) if gps else 3600.0
        d = abs(t_gps - nav.toe_gps_s[j])
        if d <= half and (
            best is None or d < best[0] or (d == best[0] and nav.toe_gps_s[j] > best[2])
        ):
            best = (d, j, nav.toe_gps_s[j])
    return None if best is None else best[1]


def _oracle_state(nav, j: int, t_gps: float) -> tuple[np.ndarray, float]:
    """ECEF position [m] and clock offset [s] of record ``j`` at GPS time ``t_gps``."""
    e = {k: float(v[j]) for k, v in nav.elements.items()}
    prn = nav.prn[j]
    bds = prn[0] == "C"
    geo = bds and int(prn[1:]) in (1, 2, 3, 4, 5, 59, 60, 61, 62, 63)
    mu = 3.986004418e14 if bds else 3.986005e14
    we = 7.292115e-5 if bds else 7.2921151467e-5
    tk = t_gps - float(nav.toe_gps_s[j])  # absolute: no week wrap needed
    a = e["sqrt_a_sqrtm"] ** 2
    n = math.sqrt(mu / a**3) + e["delta_n_radps"]
    m = e["m0_rad"] + n * tk
    ecc = e["ecc"]
    ek = m
    for _ in range(200):
        new = m + ecc * math.sin(ek)
        if abs(new - ek) < 1e-15:
            ek = new
            break
        ek = new
    # clock, toc from the record's epoch
    toc_gps = float(nav.toc_gps_s[j])
    dtc = t_gps - toc_gps
    clock = (
        e["af0_s"]
        + e["af1_sps"] * dtc
        + e["af2_sps2"] * dtc * dtc
        + (-2.0 * math.sqrt(mu) / SPEED_OF_LIGHT**2) * ecc * e["sqrt_a_sqrtm"] * math.sin(ek)
    )
    v = math.atan2(math.sqrt(1 - ecc * ecc) * math.sin(ek), math.cos(ek) - ecc)
    phi = v + e["omega_rad"]
    du = e["cus_rad"] * math.sin(2 * phi) + e["cuc_rad"] * math.cos(2 * phi)
    dr = e["crs_m"] * math.sin(2 * phi) + e["crc_m"] * math.cos(2 * phi)
    di = e["cis_rad"] * math.sin(2 * phi) + e["cic_rad"] * math.cos(2 * phi)
    u = phi + du
    r = a * (1 - ecc * math.cos(ek)) + dr
    inc = e["i0_rad"] + di + e["idot_radps"] * tk
    xo, yo = r * math.cos(u), r * math.sin(u)
    toe = e["toe_sow"]
    if geo:
        om = e["omega0_rad"] + e["omega_dot_radps"] * tk - we * toe
    else:
        om = e["omega0_rad"] + (e["omega_dot_radps"] - we) * tk - we * toe
    p = np.array(
        [
            xo * math.cos(om) - yo * math.cos(inc) * math.sin(om),
            xo * math.sin(om) + yo * math.cos(inc) * math.cos(om),
            yo * math.sin(inc),
        ]
    )
    if geo:
        f = math.radians(-5.0)
        rx = np.array(
            [[1, 0, 0], [0, math.cos(f), math.sin(f)], [0, -math.sin(f), math.cos(f)]], dtype=float
        )
        z = we * tk
        rz = np.array(
            [[math.cos(z), math.sin(z), 0], [-math.sin(z), math.cos(z), 0], [0, 0, 1]], dtype=float
        )
        p = rz @ (rx @ p)
    return p, clock


@pytest.fixture(scope="module")
def sample():
    nav = read_rinex_nav(SAMPLE_NAV_PATH)
    return nav, BroadcastConstellation.from_navigation(nav)


def test_positions_and_clocks_match_the_oracle_over_a_day(sample) -> None:
    nav, sky = sample
    lo, hi = sky.coverage_s
    # every 10 min of the day, plus the instants where the ephemeris in use changes
    t_s = np.concatenate([np.arange(lo, hi, 600.0), [hi], lo + 3600.0 * np.arange(1, 24) + 7.5])
    pos = sky.positions_ecef(t_s)
    clk = sky.clock_offsets_s(t_s)
    kinds = {"G": 0, "MEO": 0, "IGSO": 0, "GEO": 0}
    worst = dict.fromkeys(kinds, 0.0)
    for i, prn in enumerate(sky.prn):
        kind = "G" if prn[0] == "G" else ("GEO" if sky.is_geo[i] else None)
        if kind is None:
            kind = "IGSO" if nav.elements["sqrt_a_sqrtm"][nav.prn.index(prn)] > 6000 else "MEO"
        for k, t in enumerate(t_s):
            t_gps = sky.reference_gps_s + float(t)
            j = _oracle_pick(nav, prn, t_gps)
            if j is None:
                assert np.all(np.isnan(pos[k, i])), (prn, t)
                continue
            want, want_clk = _oracle_state(nav, j, t_gps)
            err = float(np.linalg.norm(pos[k, i] - want))
            worst[kind] = max(worst[kind], err)
            kinds[kind] += 1
            assert abs(clk[k, i] - want_clk) < 1e-12, (prn, t)  # 0.3 mm of range
    assert min(kinds.values()) > 100, kinds  # every kind of orbit was checked
    assert max(worst.values()) < 0.01, worst  # 1 cm
    # scalar calls agree with the vectorised ones bit for bit
    np.testing.assert_array_equal(sky.positions_ecef(float(t_s[7])), pos[7])


def test_sample_sky_is_plausible(sample) -> None:
    _, sky = sample
    t_s = np.arange(*sky.coverage_s, 900.0)
    pos = sky.positions_ecef(t_s)
    assert not np.any(np.isnan(pos))  # the sample covers every satellite all day
    geo = np.flatnonzero(sky.is_geo)
    assert [sky.prn[j] for j in geo] == ["C59", "C60", "C61"]
    lat, lon, h = ecef_to_geodetic(pos[:, geo].reshape(-1, 3))
    assert np.all(np.abs(lat) < 2.0)
    for k, lon0 in enumerate((80.0, 110.5, 140.0)):  # BDS_GEO_LON_DEG
        assert np.all(np.abs(lon.reshape(-1, 3)[:, k] - lon0) < 0.3)
    assert np.all(np.abs(h - 35_786e3) < 60e3)
    igso = [sky.prn.index(p) for p in ("C38", "C39", "C40")]
    lat, lon, _ = ecef_to_geodetic(pos[:, igso].reshape(-1, 3))
    assert lat.max() > 50 and lat.min() < -50 and np.all(np.abs(lon - 118.0) < 20.0)
    r_gps = np.linalg.norm(pos[:, sky.system == 0], axis=-1)
    assert np.all(np.abs(r_gps - 26_560e3) < 600e3)


def test_shipped_sample_is_what_the_generator_writes() -> None:
    import importlib.util

    path = Path(SAMPLE_NAV_PATH).with_name("make_sample_nav.py")
    spec = importlib.util.spec_from_file_location("make_sample_nav", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    made, shipped = mod.sample_nav_text(), Path(SAMPLE_NAV_PATH).read_text()
    # the same text apart from the last digit a platform's libm may round otherwise
    number = re.compile(r"-?\d\.\d{12}D[+-]\d\d")
    assert number.sub("#", made) == number.sub("#", shipped)
    a, b = (
        np.array([float(x.replace("D", "E")) for x in number.findall(t)]) for t in (made, shipped)
    )
    np.testing.assert_allclose(a, b, rtol=1e-11, atol=0.0)


# --------------------------------------------------------------------------------------------
# time and validity
# --------------------------------------------------------------------------------------------


def test_gps_seconds_of_utc_strings_and_numbers() -> None:
    days = (dt.date(2026, 12, 3) - dt.date(1980, 1, 6)).days
    assert gps_seconds("2026-12-03T00:00:00Z") == days * 86400 + 18
    assert gps_seconds("2026-12-03 06:00:00") == days * 86400 + 18 + 6 * 3600
    assert gps_seconds(dt.datetime(2016, 12, 31, 12)) == (
        (dt.date(2016, 12, 31) - dt.date(1980, 1, 6)).days * 86400 + 12 * 3600 + 17
    )
    assert gps_seconds(1234.5) == 1234.5 and gps_seconds("1234.5") == 1234.5
    for bad in ("yesterday", -1.0, "1979-01-01T00:00:00Z", True, [1]):
        with pytest.raises(ValueError, match=r"time|GPS"):
            gps_seconds(bad)


def test_time_outside_the_coverage_names_the_time_and_the_coverage(sample) -> None:
    _, sky = sample
    lo, hi = sky.coverage_s
    assert sky.positions_ecef(hi).shape == (sky.n_sv, 3)
    with pytest.raises(
        ValueError,
        match=r"t_s = 90086 s \(2026-12-04T00:01:40 GPST\).*sample_nav.rnx.*coverage is 2026",
    ):
        sky.positions_ecef(hi + 100.0)
    with pytest.raises(ValueError, match="outside the validity"):
        sky.positions_ecef(np.array([lo, lo - 1.0]))


def test_subset_and_systems(sample) -> None:
    nav, sky = sample
    bds_first = BroadcastConstellation.from_navigation(nav, ("BDS", "GPS"))
    assert bds_first.prn[0] == "C19" and bds_first.n_sv == sky.n_sv
    t = 4000.0 + sky.reference_gps_s - bds_first.reference_gps_s
    np.testing.assert_array_equal(bds_first.positions_ecef(t)[:30], sky.positions_ecef(4000.0)[24:])
    sub = sky.subset(sky.system == 1)
    assert sub.n_sv == 30 and set(sub.system.tolist()) == {1}
    np.testing.assert_array_equal(sub.positions_ecef(10.0), sky.positions_ecef(10.0)[24:])
    gps_only = load_broadcast_constellation("sample", ("GPS",))
    assert gps_only.n_sv == 24 and gps_only.coverage_s[1] - gps_only.coverage_s[0] == 26 * 3600


# --------------------------------------------------------------------------------------------
# the parser on hand-written records
# --------------------------------------------------------------------------------------------

HEADER = (
    "     3.04           N: GNSS NAV DATA    M: MIXED            RINEX VERSION / TYPE\n"
    "test                                                        PGM / RUN BY / DATE\n"
    "                                                            END OF HEADER\n"
)
# A GPS record as receivers write it; the first orbit line's fields run together, the second
# uses lowercase and 'E' exponents.
GPS_RECORD = (
    "G05 2026 12 03 02 00 00-1.234567890123D-04-2.000000000000D-12 0.000000000000D+00\n"
    "     1.700000000000D+01-1.000000000000D+02 4.500000000000D-09-1.000000000000D+00\n"
    "     1.000000000000d-06 1.000000000000E-02 8.000000000000D-06 5.153700000000D+03\n"
    "     3.528000000000D+05 1.000000000000D-07 2.000000000000D+00-1.000000000000D-07\n"
    "     9.600000000000D-01 2.000000000000D+02 1.000000000000D+00-8.000000000000D-09\n"
    "     1.000000000000D-10 1.000000000000D+00 2.447000000000D+03 0.000000000000D+00\n"
    "     2.000000000000D+00 0.000000000000D+00-5.000000000000D-09 1.700000000000D+01\n"
    "     3.456000000000D+05 4.000000000000D+00\n"
)
GLONASS_RECORD = (
    "R01 2026 12 03 00 15 00 1.000000000000D-05 0.000000000000D+00 3.000000000000D+05\n"
    "     1.000000000000D+04 1.000000000000D+00 0.000000000000D+00 0.000000000000D+00\n"
    "     1.000000000000D+04 1.000000000000D+00 0.000000000000D+00 1.000000000000D+00\n"
    "     1.000000000000D+04 1.000000000000D+00 0.000000000000D+00 0.000000000000D+00\n"
)


def _galileo_record() -> str:
    lines = GPS_RECORD.splitlines(keepends=True)
    return "E11" + lines[0][3:] + "".join(lines[1:])


def _write(tmp_path: Path, body: str, header: str = HEADER) -> Path:
    p = tmp_path / "nav.rnx"
    p.write_text(header + body)
    return p


def test_parser_reads_fields_that_run_together_and_skips_other_systems(tmp_path) -> None:
    glonass_305 = GLONASS_RECORD + GLONASS_RECORD.splitlines(keepends=True)[-1]  # 3.05: 5 lines
    body = GLONASS_RECORD + GPS_RECORD + _galileo_record() + GPS_RECORD + glonass_305
    nav = read_rinex_nav(_write(tmp_path, body))
    assert nav.version == 3.04 and nav.file_system == "M"
    assert nav.skipped == {"R": 2, "E": 1}
    assert nav.prn == ("G05",)  # the repeated broadcast of the same toe is kept once
    el = {k: float(v[0]) for k, v in nav.elements.items()}
    assert el["af0_s"] == -1.234567890123e-04 and el["af1_sps"] == -2e-12
    assert el["crs_m"] == -100.0 and el["delta_n_radps"] == 4.5e-9 and el["m0_rad"] == -1.0
    assert el["cuc_rad"] == 1e-6 and el["ecc"] == 0.01 and el["sqrt_a_sqrtm"] == 5153.7
    assert el["toe_sow"] == 352800.0 and el["week"] == 2447.0 and el["tgd_s"] == -5e-9
    assert el["fit_or_aodc"] == 4.0
    week0 = (dt.date(2026, 11, 29) - dt.date(1980, 1, 6)).days // 7
    assert week0 == 2447
    assert nav.toe_gps_s[0] == 2447 * 604800 + 352800.0
    assert nav.toc_gps_s[0] == nav.toe_gps_s[0]


def test_week_numbers_modulo_1024_and_across_the_week_end(tmp_path) -> None:
    mod = GPS_RECORD.replace(" 2.447000000000D+03", " 3.990000000000D+02")  # 2447 - 2 x 1024
    nav = read_rinex_nav(_write(tmp_path, mod))
    assert nav.toe_gps_s[0] == 2447 * 604800 + 352800.0
    bad = GPS_RECORD.replace(" 2.447000000000D+03", " 2.440000000000D+03")
    with pytest.raises(ValueError, match=r"week 2440 disagrees with its epoch"):
        read_rinex_nav(_write(tmp_path, bad))
    # toc on Saturday 23:59:44, toe 16 s later in the next week (sow 0), week field the toc's
    late = (
        GPS_RECORD.replace("2026 12 03 02 00 00", "2026 12 05 23 59 44")
        .replace("     3.528000000000D+05", "     0.000000000000D+00")
        .replace(" 2.447000000000D+03", " 2.447000000000D+03")
    )
    nav = read_rinex_nav(_write(tmp_path, late))
    assert nav.toe_gps_s[0] == 2448 * 604800.0
    sky = BroadcastConstellation.from_navigation(nav, ("GPS",))
    # t - toe across the week end: one second before toe gives the same as the oracle
    t_s = nav.toe_gps_s[0] - 1.0 - sky.reference_gps_s
    want, _ = _oracle_state(nav, 0, nav.toe_gps_s[0] - 1.0)
    assert np.linalg.norm(sky.positions_ecef(t_s)[0] - want) < 1e-3


def test_unhealthy_ephemerides_are_dropped_and_counted(tmp_path) -> None:
    sick = GPS_RECORD.replace(
        "     2.000000000000D+00 0.000000000000D+00-5",
        "     2.000000000000D+00 6.300000000000D+01-5",
    )
    with pytest.warns(RinexWarning, match=r"left out 1 of 2 .*GPS unhealthy: 1 .*G05: health 63"):
        nav = read_rinex_nav(_write(tmp_path, sick + GPS_RECORD.replace("G05", "G07")))
    assert nav.unhealthy == 1 and nav.prn == ("G07",)


@pytest.mark.parametrize(
    ("body", "header", "match"),
    [
        (GPS_RECORD.replace("G05", "X05"), HEADER, r"line 4: unknown satellite system 'X'"),
        (
            GPS_RECORD.replace("-1.000000000000D+00\n", "-1.0000000000x0D+00\n"),
            HEADER,
            r"line 5: field 'm0_rad' \(columns 62-80\) is not a number",
        ),
        (
            GPS_RECORD.replace(" 5.153700000000D+03", "                   "),
            HEADER,
            r"line 6: field 'sqrt_a_sqrtm' .* is blank",
        ),
        ("".join(GPS_RECORD.splitlines(True)[:5]), HEADER, r"line 4: record of G05 cut short"),
        (
            "".join(GPS_RECORD.splitlines(True)[:5]) + GPS_RECORD,
            HEADER,
            r"line 9: broadcast orbit line 5 of G05 must start with 4 blanks",
        ),
        (GPS_RECORD.replace("2026 12 03", "2026 13 03"), HEADER, r"line 4: epoch"),
        (GPS_RECORD.replace("G05", "G77"), HEADER, r"line 4: satellite number 77 outside"),
        (
            GPS_RECORD.replace(" 1.000000000000E-02", " 1.500000000000E+00"),
            HEADER,
            r"line 4: record of G05: eccentricity 1.5",
        ),
        (GPS_RECORD, HEADER.replace("     3.04", "     4.00"), r"line 1: RINEX version 4.0 is"),
        (GPS_RECORD, HEADER.replace("N: GNSS", "O: GNSS"), r"line 1: file type 'O'"),
        (GPS_RECORD, HEADER.replace("M: MIXED", "Q: WHAT?"), r"unknown satellite system 'Q'"),
        (GPS_RECORD, HEADER.replace("END OF HEADER", "COMMENT      "), r"no 'END OF HEADER'"),
        (GLONASS_RECORD, HEADER, r"no usable GPS or BeiDou ephemeris .*'R': 1"),
    ],
)
def test_bad_files_name_the_file_the_line_and_the_problem(tmp_path, body, header, match) -> None:
    with pytest.raises(ValueError, match=match) as info:
        read_rinex_nav(_write(tmp_path, body, header))
    assert "nav.rnx" in str(info.value)


def test_missing_file_and_missing_system(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"'.*nowhere.rnx' does not exist"):
        load_broadcast_constellation(str(tmp_path / "nowhere.rnx"))
    nav = read_rinex_nav(_write(tmp_path, GPS_RECORD))
    with pytest.raises(ValueError, match=r"nav.rnx: no usable BDS ephemeris"):
        BroadcastConstellation.from_navigation(nav, ("GPS", "BDS"))


def test_beidou_epochs_are_bdt(tmp_path) -> None:
    rec = GPS_RECORD.replace("G05", "C23").replace("3.528000000000D+05", "3.528000000000D+05")
    rec = rec.replace(" 2.447000000000D+03", " 1.091000000000D+03")  # BDT week
    nav = read_rinex_nav(_write(tmp_path, rec))
    # toc 2026-12-03 02:00:00 BDT = 02:00:14 GPST
    days = (dt.date(2026, 12, 3) - dt.date(1980, 1, 6)).days
    assert nav.toc_gps_s[0] == days * 86400 + 2 * 3600 + 14
    assert nav.toe_gps_s[0] == BDT0_GPS_S + 1091 * 604800 + 352800.0
    assert nav.toe_gps_s[0] == nav.toc_gps_s[0]


# --------------------------------------------------------------------------------------------
# real files, bad records, fit intervals
# --------------------------------------------------------------------------------------------

DATA = Path(__file__).resolve().parent / "data"
ELKO = DATA / "ELKO00USA_R_20182100000_01D_MN.rnx.gz"  # RINEX 3.03 mixed, one IGS station
BRDC_211 = DATA / "brdc2420.18n.gz"  # RINEX 2.11 GPS, IGS merged broadcast file


def _rinex_warnings(call):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = call()
    return out, [str(w.message) for w in caught if issubclass(w.category, RinexWarning)]


def test_a_station_file_with_bad_records_loads_with_one_warning() -> None:
    nav, messages = _rinex_warnings(lambda: read_rinex_nav(ELKO))
    assert nav.version == 3.03 and nav.file_system == "M"
    assert nav.skipped == {"R": 494, "E": 1293}
    # the health flag is checked first: the C16 record with sqrt(A) = 1991.78 is unhealthy
    assert nav.rejected == {("BDS", "unhealthy"): 55, ("GPS", "unhealthy"): 8}
    assert len(messages) == 1
    assert "left out 63 of 331 GPS and BeiDou records" in messages[0]
    assert "BDS unhealthy: 55" in messages[0] and "GPS unhealthy: 8" in messages[0]
    assert nav.n_eph > 200 and "C16" not in nav.prn and "G04" not in nav.prn
    assert np.all(nav.elements["health"] == 0.0)
    for systems in (("GPS",), ("GPS", "BDS"), ("BDS",)):
        sky = BroadcastConstellation.from_navigation(nav, systems)
        assert {p[0] for p in sky.prn} == {{"GPS": "G", "BDS": "C"}[s] for s in systems}


def test_an_implausible_healthy_record_is_left_out_not_the_file(tmp_path) -> None:
    lines = gzip.decompress(ELKO.read_bytes()).decode().splitlines(keepends=True)
    rec = 14674  # line 14675: C16 with sqrt(A) = 1991.78 m^0.5 and health 1
    assert lines[rec].startswith("C16 2018 07 31") and "1.991780391693E+03" in lines[rec + 2]
    assert lines[rec + 6][23:42] == " 1.000000000000E+00"  # SatH1
    lines[rec + 6] = lines[rec + 6][:23] + " 0.000000000000E+00" + lines[rec + 6][42:]
    path = tmp_path / "elko.rnx"
    path.write_text("".join(lines))
    nav, messages = _rinex_warnings(lambda: read_rinex_nav(path))
    assert nav.rejected[("BDS", "implausible sqrt(A)")] == 1
    assert nav.rejected[("BDS", "unhealthy")] == 54
    assert len(messages) == 1
    assert "BDS implausible sqrt(A): 1 (first: " in messages[0]
    assert "line 14675: record of C16: sqrt(A) = 1991.780391693 m^0.5" in messages[0]
    gps = BroadcastConstellation.from_navigation(nav, ("GPS",))
    assert gps.n_sv == 31


def test_a_file_of_bad_records_only_says_why_each_was_left_out(tmp_path) -> None:
    sick = GPS_RECORD.replace(
        "     2.000000000000D+00 0.000000000000D+00-5",
        "     2.000000000000D+00 6.300000000000D+01-5",
    )
    bad_a = GPS_RECORD.replace("G05", "G07").replace("5.153700000000D+03", "1.991780000000D+03")
    with pytest.raises(ValueError, match=r"no usable GPS or BeiDou ephemeris") as info:
        read_rinex_nav(_write(tmp_path, sick + bad_a))
    assert "GPS implausible sqrt(A): 1 (first: " in str(info.value)
    assert "GPS unhealthy: 1 (first: " in str(info.value) and "line 4: record of G05" in str(
        info.value
    )


def _gps_record(prn: str, hour: int, fit_h: float, day: int = 3) -> str:
    """GPS_RECORD with toc = toe at ``hour`` of 2026-12-``day`` and the given fit interval."""
    toe = (day - 3 + 4) * 86400 + hour * 3600  # 2026-12-03 is a Thursday (day 4 of the week)
    lines = GPS_RECORD.replace("G05", prn).splitlines(keepends=True)
    lines[0] = lines[0].replace("2026 12 03 02", f"2026 12 {day:02d} {hour:02d}")
    lines[3] = f"     {toe:.12E}".replace("E+0", "D+0") + lines[3][23:]
    lines[7] = lines[7][:23] + f" {fit_h:.12E}".replace("E+0", "D+0").replace("E-0", "D-0")
    return "".join(lines) + "\n"


def test_each_ephemeris_is_used_only_inside_its_fit_interval(tmp_path) -> None:
    """Hand-computed: which record each time uses, and the gaps."""
    body = (
        _gps_record("G05", 2, 4.0)  # A: fit 4 h -> 00:00-04:00
        + _gps_record("G05", 4, 0.0)  # B: fit field 0 -> 4 h -> 02:00-06:00
        + _gps_record("G05", 10, 8.0)  # C: fit 8 h -> 06:00-14:00
        + _gps_record("G05", 20, 4.0)  # D: 18:00-22:00; 14:00-18:00 no valid record
    )
    nav = read_rinex_nav(_write(tmp_path, body))
    assert nav.n_eph == 4 and list(nav.elements["fit_or_aodc"]) == [4.0, 0.0, 8.0, 4.0]
    sky = BroadcastConstellation.from_navigation(nav, ("GPS",))
    day0 = nav.toe_gps_s[0] - 2 * 3600  # 2026-12-03 00:00 GPST
    hour = 3600.0
    assert sky.coverage_gps_s == (day0, day0 + 22 * hour)
    assert sky.valid_spans_gps_s == ((day0, day0 + 14 * hour), (day0 + 18 * hour, day0 + 22 * hour))
    cases = {  # hours after 00:00 -> record (index in the file), None: no valid record
        0.0: 0,
        0.5: 0,
        2.98: 0,  # A's toe is nearer
        3.0: 1,  # equally near A and B: the later toe
        3.02: 1,
        5.99: 1,
        6.0: 1,  # B (2 h from its toe) nearer than C (4 h)
        6.01: 2,  # B has expired
        13.99: 2,
        14.0: 2,
        14.01: None,
        16.0: None,
        17.99: None,
        18.0: 3,
        22.0: 3,
    }
    for h, j in cases.items():
        t_gps = day0 + h * hour
        pos = sky.positions_ecef(t_gps - sky.reference_gps_s)[0]
        if j is None:
            assert np.all(np.isnan(pos)), h
            continue
        want, _ = _oracle_state(nav, j, t_gps)
        assert np.linalg.norm(pos - want) < 1e-3, h
        others = [k for k in range(4) if k != j]
        assert all(np.linalg.norm(pos - _oracle_state(nav, k, t_gps)[0]) > 1.0 for k in others)


def test_beidou_ephemerides_are_valid_one_hour_either_side_and_the_newest_repeat_is_kept(
    tmp_path,
) -> None:
    bds = GPS_RECORD.replace("G05", "C23").replace(" 2.447000000000D+03", " 1.091000000000D+03")
    again = bds.replace("3.456000000000D+05 4.0", "3.457000000000D+05 4.0").replace(
        "-1.000000000000D+00\n", "-1.100000000000D+00\n", 1
    )  # the same toe broadcast again later, another mean anomaly
    nav = read_rinex_nav(_write(tmp_path, bds + again))
    assert nav.n_eph == 1 and nav.elements["m0_rad"][0] == -1.1  # the later broadcast
    sky = BroadcastConstellation.from_navigation(nav, ("BDS",))
    toe = float(nav.toe_gps_s[0])
    assert sky.coverage_gps_s == (toe - 3600.0, toe + 3600.0)
    with pytest.raises(ValueError, match="outside the validity"):
        sky.positions_ecef(toe + 3601.0 - sky.reference_gps_s)


def test_rinex_2_and_gzip_files_are_read_directly(tmp_path) -> None:
    nav_gz, messages = _rinex_warnings(lambda: read_rinex_nav(BRDC_211))
    assert nav_gz.version == 2.11 and nav_gz.file_system == "G"
    assert nav_gz.rejected == {("GPS", "unhealthy"): 1} and len(messages) == 1
    plain = tmp_path / "brdc2420.18n"
    plain.write_bytes(gzip.decompress(BRDC_211.read_bytes()))
    nav = read_rinex_nav(plain, warn=False)
    assert nav.prn == nav_gz.prn and nav.digest == nav_gz.digest
    for f, v in nav.elements.items():
        np.testing.assert_array_equal(v, nav_gz.elements[f])
    # the first record: ' 2 18  8 29 22  0  0.0 1.349905505776D-05...', toe 338400 s, week 2016
    j = nav.prn.index("G02")
    assert nav.toc_gps_s[j] == (dt.date(2018, 8, 29) - dt.date(1980, 1, 6)).days * 86400 + 22 * 3600
    assert nav.toe_gps_s[j] == 2016 * 604800 + 338400.0
    assert nav.elements["af0_s"][j] == 1.349905505776e-05
    assert nav.elements["sqrt_a_sqrtm"][j] == 5.153796899796e03
    sky = BroadcastConstellation.from_navigation(nav, ("GPS",))
    t_gps = float(nav.toe_gps_s[j]) + 1234.5
    want, want_clk = _oracle_state(nav, _oracle_pick(nav, "G02", t_gps), t_gps)
    i = sky.prn.index("G02")
    assert np.linalg.norm(sky.positions_ecef(t_gps - sky.reference_gps_s)[i] - want) < 1e-3
    assert abs(sky.clock_offsets_s(t_gps - sky.reference_gps_s)[i] - want_clk) < 1e-12
    r = np.linalg.norm(sky.positions_ecef(np.arange(*sky.coverage_s, 3600.0)), axis=-1)
    assert np.nanmax(np.abs(r - 26_560e3)) < 800e3  # e up to 0.02


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"\x1f\x9d\x90junk", r"Unix compress \(\.Z\)-compressed; decompress it first"),
        (b"\x1f\x8b\x08\x00cut", r"gzip data is corrupt or cut short"),
        (b"BZh91AY&SY", r"bzip2-compressed"),
    ],
)
def test_other_compressions_are_named(tmp_path, data, match) -> None:
    path = tmp_path / "nav.rnx.Z"
    path.write_bytes(data)
    with pytest.raises(ValueError, match=match):
        read_rinex_nav(path)


def test_visibility_of_a_station_file_near_and_far() -> None:
    nav = read_rinex_nav(ELKO, warn=False)
    sky = BroadcastConstellation.from_navigation(nav)
    near = sky.visibility(40.91, -115.74, 1600.0, 10.0)
    far = sky.visibility(31.23, 121.47, 0.0, 10.0)  # Shanghai
    assert near.seen_fraction > 0.9 > 0.5 > far.seen_fraction
    assert near.visible_mean > 9.0 and far.visible_mean < 6.0
    # BeiDou has no valid ephemeris from 22:00 to 23:00 (hours after the coverage's start)
    assert [(a, b) for a, b in near.spans_s] == [(0.0, 22 * 3600.0), (23 * 3600.0, 26 * 3600.0)]
    assert len(far.spans_s) > 3  # gaps with fewer than 4 satellites above 10 deg
    t = np.concatenate([np.arange(a, b, 600.0) for a, b in far.spans_s])
    pos = sky.positions_ecef(t)
    from coopnav_env.gnss.frames import azimuth_elevation, geodetic_to_ecef

    origin = geodetic_to_ecef(31.23, 121.47, 0.0)[None]
    for k in range(t.size):
        ok = np.isfinite(pos[k, :, 0])
        _, el = azimuth_elevation(origin, pos[k, ok])
        assert np.sum(el > 10.0) >= 4, t[k]
    # the sample sky: one span, the whole coverage
    sample = load_broadcast_constellation("sample")
    assert sample.visibility(31.23, 121.47).spans_s == (sample.coverage_s,)


def test_a_rinex_2_record_reads_as_its_rinex_3_twin(tmp_path) -> None:
    """The same record in RINEX 2.11 layout (I2 PRN, two-digit year, F5.1 seconds, 3-blank
    orbit lines, numbers without a leading zero) and in RINEX 3.04."""
    lines = GPS_RECORD.splitlines()
    epoch = " 5 26 12  3  2  0  0.0" + lines[0][23:]
    orbit = ["   " + line[4:] for line in lines[1:]]
    orbit[0] = orbit[0].replace(" 1.700000000000D+01", "  .170000000000D+02")
    header2 = (
        "     2.11           N: GPS NAV DATA                         RINEX VERSION / TYPE\n"
        "                                                            END OF HEADER\n"
    )
    two = tmp_path / "nav.26n"
    two.write_text(header2 + "\n".join([epoch, *orbit]) + "\n")
    nav2 = read_rinex_nav(two)
    nav3 = read_rinex_nav(_write(tmp_path, GPS_RECORD))
    assert nav2.version == 2.11 and nav2.file_system == "G" and nav2.prn == ("G05",)
    assert nav2.toc_gps_s[0] == nav3.toc_gps_s[0] and nav2.toe_gps_s[0] == nav3.toe_gps_s[0]
    for f, v in nav3.elements.items():
        np.testing.assert_array_equal(nav2.elements[f], v, err_msg=f)
    glonass = header2.replace("N: GPS NAV DATA        ", "G: GLONASS NAV DATA    ")
    two.write_text(glonass + "\n".join([epoch, *orbit]) + "\n")
    with pytest.raises(ValueError, match=r"file type 'G' .*GLONASS navigation files are not"):
        read_rinex_nav(two)
    two.write_text(header2 + epoch.replace(" 26 12", " 26 13") + "\n" + "\n".join(orbit) + "\n")
    with pytest.raises(ValueError, match=r"nav.26n, line 3: epoch \(columns 3-22\)"):
        read_rinex_nav(two)
