"""Galileo from RINEX navigation files: records read only when asked for, orbits and clocks
against an independent computation, and a position fix with Galileo satellites.

The reference (:func:`_icd_state`) is written here from the Galileo OS SIS ICD (Issue 2.0,
5.1.1 constants, 5.1.3 clock, 5.1.9.1 Table 60 user algorithm): one satellite and one time at
a time with the ``math`` module, the ephemeris chosen by a loop over the file's records,
``t - toe`` from absolute GPS seconds, Kepler's equation by fixed-point iteration, and the
ICD's own literal value of the relativistic clock constant ``F``.
"""

from __future__ import annotations

import gzip
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.gnss.frames import azimuth_elevation, geodetic_to_ecef
from coopnav_env.gnss.rinex import (
    FILE_SYSTEMS,
    GAL_VALIDITY_S,
    BroadcastConstellation,
    load_broadcast_constellation,
    read_rinex_nav,
)
from coopnav_env.nav import GnssObservations, NavStatus, solve_standalone

ELKO = Path(__file__).resolve().parent / "data" / "ELKO00USA_R_20182100000_01D_MN.rnx.gz"
ELKO_ECEF_M = geodetic_to_ecef(40.9157, -115.7375, 1636.0)  # near the station

MU_GAL = 3.986004418e14  # OS SIS ICD 5.1.1 [m^3/s^2]
OMEGA_E_GAL = 7.2921151467e-5  # OS SIS ICD 5.1.1 [rad/s]
F_GAL = -4.442807309e-10  # OS SIS ICD 5.1.3, -2 sqrt(mu) / c^2 [s / m^0.5]


def _icd_pick(nav, prn: str, t_gps: float):
    """The record of ``prn`` with the nearest toe within 4 h of ``t_gps`` (ties: later toe)."""
    best = None
    for j, p in enumerate(nav.prn):
        if p != prn:
            continue
        d = abs(t_gps - float(nav.toe_gps_s[j]))
        if d <= 4 * 3600.0 and (
            best is None or d < best[0] or (d == best[0] and nav.toe_gps_s[j] > best[2])
        ):
            best = (d, j, nav.toe_gps_s[j])
    return None if best is None else best[1]


def _icd_state(nav, j: int, t_gps: float) -> tuple[np.ndarray, float]:
    """ECEF position [m] and clock offset [s] of Galileo record ``j`` at ``t_gps`` (GST taken
    as GPST, as the RINEX week numbering does)."""
    e = {k: float(v[j]) for k, v in nav.elements.items()}
    a = e["sqrt_a_sqrtm"] ** 2
    n0 = math.sqrt(MU_GAL / (a * a * a))
    tk = t_gps - float(nav.toe_gps_s[j])
    n = n0 + e["delta_n_radps"]
    mk = e["m0_rad"] + n * tk
    ecc = e["ecc"]
    ek = mk
    for _ in range(300):
        new = mk + ecc * math.sin(ek)
        if abs(new - ek) < 1e-15:
            ek = new
            break
        ek = new
    dtc = t_gps - float(nav.toc_gps_s[j])
    clock = (
        e["af0_s"]
        + e["af1_sps"] * dtc
        + e["af2_sps2"] * dtc**2
        + F_GAL * ecc * e["sqrt_a_sqrtm"] * math.sin(ek)
    )
    vk = math.atan2(math.sqrt(1.0 - ecc**2) * math.sin(ek), math.cos(ek) - ecc)
    phi = vk + e["omega_rad"]
    uk = phi + e["cus_rad"] * math.sin(2 * phi) + e["cuc_rad"] * math.cos(2 * phi)
    rk = (
        a * (1 - ecc * math.cos(ek))
        + e["crs_m"] * math.sin(2 * phi)
        + e["crc_m"] * math.cos(2 * phi)
    )
    ik = (
        e["i0_rad"]
        + e["idot_radps"] * tk
        + e["cis_rad"] * math.sin(2 * phi)
        + e["cic_rad"] * math.cos(2 * phi)
    )
    xp, yp = rk * math.cos(uk), rk * math.sin(uk)
    om = e["omega0_rad"] + (e["omega_dot_radps"] - OMEGA_E_GAL) * tk - OMEGA_E_GAL * e["toe_sow"]
    pos = np.array(
        [
            xp * math.cos(om) - yp * math.cos(ik) * math.sin(om),
            xp * math.sin(om) + yp * math.cos(ik) * math.cos(om),
            yp * math.sin(ik),
        ]
    )
    return pos, clock


@pytest.fixture(scope="module")
def elko():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the file's unhealthy records
        nav = read_rinex_nav(ELKO, galileo=True)
    return nav, BroadcastConstellation.from_navigation(nav, ("GPS", "BDS", "GAL"))


def test_galileo_records_are_read_only_when_asked_for() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = read_rinex_nav(ELKO)
        with_gal = read_rinex_nav(ELKO, galileo=True)
    assert plain.skipped["E"] == 1293 and "E" not in with_gal.skipped
    gal = FILE_SYSTEMS.index("GAL")
    assert not np.any(plain.system == gal)
    # the I/NAV records are kept, their F/NAV twins (data sources 258) skipped and counted
    assert with_gal.skipped["E F/NAV"] == 656
    sources = with_gal.elements["spare_5_2"][with_gal.system == gal]
    assert set(sources.astype(int).tolist()) == {517}
    assert with_gal.rejected[("GAL", "unhealthy")] == 169  # E14 and E18 among them
    assert not {"E14", "E18"} & {p for p in with_gal.prn if p[0] == "E"}
    # GPS and BeiDou read the same either way
    keep = with_gal.system != gal
    assert plain.prn == tuple(p for p, k in zip(with_gal.prn, keep, strict=True) if k)
    for name, values in plain.elements.items():
        np.testing.assert_array_equal(values, with_gal.elements[name][keep])
    with pytest.raises(ValueError, match=r"no usable GAL ephemeris .*galileo=True"):
        BroadcastConstellation.from_navigation(plain, ("GPS", "GAL"))


def test_a_galileo_record_reads_its_fields(elko) -> None:
    nav, _ = elko
    # E02, epoch 2018-07-28 23:20:00 GST: the file's first Galileo record
    lines = gzip.decompress(ELKO.read_bytes()).decode().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("E02 2018 07 28 23 20"))
    assert lines[first + 2].split()[-1] == "5.440614948273E+03"
    j = next(
        j for j, p in enumerate(nav.prn) if p == "E02" and nav.elements["toe_sow"][j] == 602400.0
    )
    el = {k: float(v[j]) for k, v in nav.elements.items()}
    assert el["af0_s"] == 2.131529618055e-05 and el["af1_sps"] == 1.463718035666e-12
    assert el["sqrt_a_sqrtm"] == 5.440614948273e03 and el["ecc"] == 8.207093924284e-05
    assert el["week"] == 2011.0 and el["accuracy_m"] == 3.12 and el["health"] == 0.0
    assert nav.toe_gps_s[j] == 2011 * 604800.0 + 602400.0


def test_galileo_orbits_and_clocks_match_the_icd_computation(elko) -> None:
    nav, sky = elko
    gal_rows = np.flatnonzero(sky.system == FILE_SYSTEMS.index("GAL"))
    assert gal_rows.size >= 10
    lo, hi = sky.coverage_s
    t_s = np.concatenate([np.arange(lo, hi, 1800.0), [hi], lo + 3600.0 * np.arange(1, 26) + 7.5])
    pos = sky.positions_ecef(t_s)
    clk = sky.clock_offsets_s(t_s)
    worst, worst_clk, n_checked, n_gap = 0.0, 0.0, 0, 0
    for i in gal_rows:
        prn = sky.prn[i]
        assert sky.validity_s[i][np.isfinite(sky.toe_gps_s[i])].tolist() == [GAL_VALIDITY_S] * int(
            np.isfinite(sky.toe_gps_s[i]).sum()
        )
        for k, t in enumerate(t_s):
            t_gps = sky.reference_gps_s + float(t)
            j = _icd_pick(nav, prn, t_gps)
            if j is None:
                assert np.all(np.isnan(pos[k, i])), (prn, t)
                n_gap += 1
                continue
            want, want_clk = _icd_state(nav, j, t_gps)
            worst = max(worst, float(np.linalg.norm(pos[k, i] - want)))
            worst_clk = max(worst_clk, abs(float(clk[k, i]) - want_clk))
            n_checked += 1
            radius = float(np.linalg.norm(want))
            assert 29.0e6 < radius < 30.2e6, (prn, radius)  # Galileo's 29,600 km orbit
    assert n_checked > 300 and n_gap > 0
    assert worst < 1e-3, worst  # 1 mm
    assert worst_clk < 1e-12, worst_clk  # 0.3 mm of range


def test_a_fix_with_galileo_included(elko) -> None:
    _, sky = elko
    gal = FILE_SYSTEMS.index("GAL")
    # the first full hour at which the station sees 4 healthy Galileo satellites above 10 deg
    for t in np.arange(sky.coverage_s[0], sky.coverage_s[1], 3600.0):
        sv = sky.positions_ecef(t)
        known = np.isfinite(sv).all(axis=1)
        _, el = azimuth_elevation(ELKO_ECEF_M[None], np.where(known[:, None], sv, 0.0))
        use = known & (el[0] > 10.0)
        if np.count_nonzero(sky.system[use] == gal) >= 4:
            break
    else:
        pytest.fail("no hour with 4 Galileo satellites above 10 deg")
    system = sky.system[use]
    assert set(system.tolist()) >= {0, gal}
    # pseudoranges of a receiver at ELKO with a receiver clock offset per system (the
    # satellites' clocks taken as corrected) and 0.5 m of noise
    rng = np.random.default_rng(3)
    rx_clock_m = np.array([1.5e4, -2.0e3, 3.7e3])  # GPS, BDS, GAL receiver clocks [m]
    rng_m = np.linalg.norm(sv[use] - ELKO_ECEF_M, axis=1)
    pr = rng_m + rx_clock_m[system] + rng.normal(0.0, 0.5, rng_m.size)
    n_sv = int(use.sum())
    obs = GnssObservations(
        pr_m=pr[None],
        sv_ecef_m=sv[use],
        system=system,
        sigma_user_m=np.full((1, n_sv), 0.5),
        sigma_common_m=np.zeros(n_sv),
        el_deg=el[:, use],
        n_systems=len(FILE_SYSTEMS),
    )
    fix = solve_standalone(obs)
    assert fix.status[0] == NavStatus.OK
    assert np.linalg.norm(fix.pos_ecef_m[0] - ELKO_ECEF_M) < 5.0
    # Galileo alone (its own clock) fixes too
    only = system == gal
    obs_gal = GnssObservations(
        pr_m=pr[None, only],
        sv_ecef_m=sv[use][only],
        system=system[only],
        sigma_user_m=np.full((1, int(only.sum())), 0.5),
        sigma_common_m=np.zeros(int(only.sum())),
        el_deg=el[:, use][:, only],
        n_systems=len(FILE_SYSTEMS),
    )
    fix_gal = solve_standalone(obs_gal)
    assert fix_gal.status[0] == NavStatus.OK
    assert np.linalg.norm(fix_gal.pos_ecef_m[0] - ELKO_ECEF_M) < 20.0


def test_load_with_galileo_keeps_the_default_sky_unchanged() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = load_broadcast_constellation(ELKO, ("GPS", "BDS"))
        with_gal = load_broadcast_constellation(ELKO, ("GPS", "BDS", "GAL"))
    n = default.n_sv
    assert with_gal.prn[:n] == default.prn and with_gal.n_sv > n
    assert with_gal.digest != default.digest
    t = np.arange(*default.coverage_s, 3600.0)
    np.testing.assert_array_equal(with_gal.positions_ecef(t)[:, :n], default.positions_ecef(t))
