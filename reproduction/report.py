"""The self-contained Markdown report of a reproduction run (``report.md``)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from coopnav_env.reproduction.config import AXES, PUBLISHED, ReproduceConfig
from coopnav_env.reproduction.simulation import variant_setting

# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------

__all__ = [
    "report_markdown",
]


def _fmt(x: float | None, nd: int = 2) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}"


def _sgn(x: float | None, nd: int = 2) -> str:
    return "n/a" if x is None else f"{x:+.{nd}f}"


def _norm3(st: dict[str, dict[str, float | None]], key: str) -> float | None:
    vals = [st[ax][key] for ax in AXES]
    return None if None in vals else float(np.sqrt(sum(v * v for v in vals)))


def _scenario_lines(cfg: ReproduceConfig) -> list[str]:
    sc = cfg.scenario
    gaps = ", ".join(f"{a:g}-{b:g} deg" for a, b in sc.gaps_deg) or "none"
    hours = cfg.n_epochs * cfg.epoch_spacing_s / 3600
    return [
        f"- Swarm: {sc.n_uavs} UAVs in a fixed cross formation ({2 * sc.spacing_m:g} m across, "
        f"lattice spacing {sc.spacing_m:g} m, {sc.alt_m:g} m above the ellipsoid) at "
        f"{sc.lat_deg:.4f} N, {sc.lon_deg:.4f} E (Shanghai, the authors' site); UAV "
        f"{sc.canyon_uav} (the centre) is in the canyon, the others in open sky.",
        "- Satellites: nominal GPS (24 slots) and BeiDou-3 MEO (24) on circular orbits"
        + (" plus BeiDou GEO/IGSO" if sc.bds_geo_igso else "")
        + f"; elevation cut-off {sc.elevation_cutoff_deg:g} deg; an open-sky UAV keeps the "
        f"{sc.max_sats} {'highest' if sc.open_sky_selection == 'highest' else 'random'} "
        "satellites" + (" (the canyon UAV too)" if sc.canyon_channel_limit else "") + ".",
        f"- Canyon: Eq. 25 with h/d = {sc.h_over_d:.4g}, street azimuth "
        f"{sc.street_azimuth_deg:g} deg, gaps {gaps}.",
        "- Errors: Eq. 4-8 (sigma_URE 1 m, troposphere, multipath and noise), "
        + (
            "without the iono-free factor of Eq. 8 (user error sqrt(sigma_MP^2 + "
            "sigma_Noise^2); see *Where the numbers differ*)"
            if not sc.iono_free
            else "iono-free factor of GPS L1/L2 for both systems (ErrorModel.paper())"
            if sc.frequencies == "paper"
            else "iono-free factor per system: GPS L1/L2 2.98, BDS B1I/B3I 3.53 (ErrorModel())"
        )
        + "; the URE and troposphere errors are common to the swarm, multipath and noise "
        "independent per UAV; differential correction removes the common part.",
        f"- Relative positions: independent N(0, {sc.sigma_rel_m:g}^2) m^2 error per ENU axis "
        "and per pair (Eq. 9).",
        f"- Time: {cfg.n_epochs} epochs every {cfg.epoch_spacing_s:g} s ({hours:g} h); "
        f"{cfg.n_samples} noise realisations per epoch in the main study, "
        f"{cfg.n_samples_sweep} in the others; seed {cfg.seed}.",
        f"- Navigation: standalone WLS (Eq. 14-17); proposed method with "
        f"{cfg.transfer.upper()} (SDT also shown) and the canyon UAV as its own virtual "
        f"centroid; covariance: {cfg.covariance} "
        + ("(ours, exact for DDT)" if cfg.covariance == "exact" else "(the paper's Eq. 18)")
        + "; master-slave with the best open-sky UAV as master.",
        "- Exclusions: "
        + (
            "realisations where the canyon UAV has no standalone fix (status != OK)"
            if cfg.max_pdop is None
            else f"realisations without a standalone fix or with standalone PDOP > {cfg.max_pdop:g}"
        )
        + "; comparisons use realisations where both methods have a fix.",
    ]


def _peak_sentence(s: dict[str, Any]) -> str:
    """Where the standalone error of the LOS study peaks, and why."""
    rows = [
        (b["without"]["rms3d_standalone_m"], b["n_los"])
        for b in s["los"]["bins"]
        if b["without"]["rms3d_standalone_m"] is not None
    ]
    if not rows:
        return ""
    rms, n = max(rows)
    why = (
        ", where a UAV that sees both constellations has as many unknowns (3 + 2) as "
        "measurements and no redundancy at all"
        if n == 5
        else ""
    )
    return (
        f" The study against the number of LOS satellites shows the mechanism: the standalone "
        f"RMS 3-D error peaks at {n} satellites ({rms:.0f} m){why}."
    )


def _misstates(sig: float | None, std: float | None) -> str:
    """'overstates by x %' / 'understates by x %' for a predicted vs a sampled sigma."""
    if sig is None or not std:
        return "misstates the DDT uncertainty"
    if abs(sig / std - 1) < 0.005:
        return "predicts the DDT uncertainty within 0.5 % here"
    word = "overstates" if sig > std else "understates"
    return f"{word} the DDT uncertainty by {100 * abs(sig / std - 1):.0f} %"


def _closeness(rep: float | None, pub: float) -> str:
    """Words for how close a reproduced value is to the published one."""
    if rep is None:
        return "not at all (no value)"
    rel = abs(rep / pub - 1)
    return "closely" if rel < 0.2 else "roughly" if rel < 0.5 else "poorly"


def _uses_default_choices(cfg: ReproduceConfig) -> bool:
    """Whether ``cfg`` makes every modelling choice as the defaults do (sizes may differ)."""
    ref = ReproduceConfig()
    return (cfg.scenario, cfg.covariance, cfg.max_pdop, cfg.transfer) == (
        ref.scenario,
        ref.covariance,
        ref.max_pdop,
        ref.transfer,
    )


def _variant_with(
    cfg: ReproduceConfig, names: list[str], *, covariance: str, iono_free: bool
) -> str | None:
    """The first of ``names`` (sensitivity variants of this run) with these two choices and
    the run's other choices; ``None`` if the run has none."""
    want = (
        dataclasses.replace(cfg.scenario, iono_free=iono_free),
        covariance,
        cfg.max_pdop,
    )
    return next((n for n in names if variant_setting(cfg, n) == want), None)


def _n2(tab: dict[str, Any]) -> tuple[float | None, float | None]:
    """Table 2 improvement at N = 2 (SIG-based): (without, with) differential correction."""
    return (
        tab["without"].get("2", {}).get("sig"),
        tab["with"].get("2", {}).get("sig"),
    )


def _mask_paragraph(cfg: ReproduceConfig, s: dict[str, Any], sens: dict[str, Any]) -> list[str]:
    """The canyon UAV's standalone fix: the PDOP mask and the pooled tails."""
    t1 = s["main"]["table1"]
    sa3 = _norm3(t1["standalone"], "sig")
    pub_sa3 = _norm3(PUBLISHED["table1"]["standalone"], "sig")
    med = s["main"]["median_epoch_sig3d_m"]
    pd = s["main"]["canyon"]["pdop_percentiles_10_50_90_99"]
    ex = s["main"]["exclusions"]["standalone"]
    fail = s["main"]["standalone_solver_failures"]
    pct = (
        f"percentiles 10/50/90/99 % of {', '.join(_fmt(x, 1) for x in pd)}"
        if pd
        else "no finite value"
    )
    text = (
        "**The canyon UAV's standalone fix.** Its pooled 3-D SIG is "
        f"{_fmt(sa3)} m against the paper's {_fmt(pub_sa3)} m (median over epochs "
        f"{_fmt(med['standalone'])} m). Pooled statistics are at the mercy of the few epochs "
        "in which the canyon leaves the UAV about as many satellites as unknowns, badly "
        f"placed: over all epochs, the PDOP of its standalone geometry has {pct}. "
    )
    if cfg.max_pdop is None:
        text += (
            f"This run keeps every fix the solver returns: {ex['epochs_without_fix']} of "
            f"{ex['epochs']} epochs have none and are excluded, as in the paper."
        )
    else:
        text += (
            f"This run counts a standalone fix with PDOP > {cfg.max_pdop:g} as no fix, as a "
            "receiver's PDOP mask would (the paper omits the epochs in which the UAV \"failed "
            f'to locate itself" without saying when it did): {ex["epochs_without_fix"]} of '
            f"{ex['epochs']} epochs are excluded, {fail['epochs_without_fix']} of them because "
            "the solver has no fix at all."
        )
        if "all-fixes" in sens:
            r = sens["all-fixes"]
            text += (
                " Keeping every fix (`all-fixes`) gives a standalone 3-D SIG of "
                f"{_fmt(r['standalone_sig3d_m'])} m and raises the improvement for N = 5 to "
                f"{_fmt(r['improvement_without']['sig'], 1)} % without and "
                f"{_fmt(r['improvement_with']['sig'], 1)} % with differential correction "
                "(published 57.53 % and 59.07 %): the improvement is a ratio to the standalone "
                "error, so the tails carry over to every improvement figure."
            )
    return [text + _peak_sentence(s), ""]


def _default_paragraph(cfg: ReproduceConfig, s: dict[str, Any], sens: dict[str, Any]) -> list[str]:
    """Why the defaults are what they are (only for a run that makes the default choices)."""
    if not _uses_default_choices(cfg):
        return []
    dist = s["table2_distance"]
    holds = sum(c["holds"] for c in s["claims"])
    wo2, w2 = (x if x is not None else float("nan") for x in _n2(s["swarm"]))
    others = [
        f"`{k}` {_fmt(d['without'], 1)} / {_fmt(d['with'], 1)}"
        for k, d in dist.items()
        if k != "default" and d["without"] is not None
    ]
    return [
        "**Choice of the default.** The default is the configuration that reproduces the "
        "paper's numbers best among those we compared: the paper's models with a PDOP mask "
        f"of {cfg.max_pdop:g} on the canyon UAV's standalone fix and Eq. 8 "
        + ("with" if cfg.scenario.iono_free else "without")
        + " its iono-free factor (both discussed below), "
        + ("our exact covariance" if cfg.covariance == "exact" else "the paper's Eq. 18")
        + f", {cfg.transfer.upper()}. Its Table 2 is "
        f"{_fmt(dist['default']['without'], 1)} points from the published row without and "
        f"{_fmt(dist['default']['with'], 1)} points with differential correction on average "
        "(the alternatives: "
        + "; ".join(others)
        + ")"
        + (", it reproduces the order of the two rows at N = 2" if w2 < wo2 else "")
        + f", and {holds} of the paper's {len(s['claims'])} qualitative claims hold."
        + _p3m_caveat(sens),
        "",
    ]


def _p3m_caveat(sens: dict[str, Any]) -> str:
    """Where the iono-free factor fits the paper's P(<3 m) better, say so."""
    if "iono-free" not in sens:
        return ""
    r, d = sens["iono-free"], sens["default"]
    if None in (r["p3m_standalone"], d["p3m_standalone"], r["p3m_sdt"], d["p3m_sdt"]):
        return ""
    off_r = abs(r["p3m_standalone"] - 37) + abs(r["p3m_sdt"] - 78)
    off_d = abs(d["p3m_standalone"] - 37) + abs(d["p3m_sdt"] - 78)
    if off_r >= off_d:
        return ""
    return (
        " It is not closest on everything: P(<3 m), standalone / SDT, is nearer the paper's "
        f"37 / 78 % with the iono-free factor ({_fmt(r['p3m_standalone'], 0)} / "
        f"{_fmt(r['p3m_sdt'], 0)} %, `iono-free` row of the sensitivity table) than "
        f"without (`default` row: {_fmt(d['p3m_standalone'], 0)} / {_fmt(d['p3m_sdt'], 0)} %): "
        "the larger "
        "user error puts fewer fixes within 3 m."
    )


def _iono_paragraph(cfg: ReproduceConfig, s: dict[str, Any], sens: dict[str, Any]) -> list[str]:
    """Table 2 at N = 2: the iono-free factor of Eq. 8 and the paper's Eq. 18."""
    t2v = {"default": s["swarm"], **s.get("table2_variants", {})}
    names = list(t2v)
    combos = {
        (cov, iono): _variant_with(cfg, names, covariance=cov, iono_free=iono)
        for cov in ("exact", "paper")
        for iono in (True, False)
    }
    if None in combos.values():
        return []
    n2 = {k: _n2(t2v[v]) for k, v in combos.items()}
    dist = s["table2_distance"]
    label = {
        ("exact", True): "exact covariance with the factor",
        ("paper", True): "Eq. 18 with the factor",
        ("exact", False): "exact covariance without the factor",
        ("paper", False): "Eq. 18 without the factor",
    }
    pairs = "; ".join(
        f"{label[k]} (`{combos[k]}`) {_fmt(n2[k][1], 1)} % against {_fmt(n2[k][0], 1)} %"
        for k in combos
    )
    no = combos["exact", False]
    rows = ", ".join(f"{_fmt(t2v[no]['with'].get(n, {}).get('sig'), 1)}" for n in t2v[no]["with"])

    pub_gap = PUBLISHED["table2"]["without"][2] - PUBLISHED["table2"]["with"][2]

    def gap(k: tuple[str, bool]) -> float:
        wo, w = n2[k]
        return float("nan") if wo is None or w is None else wo - w

    text = (
        "**Table 2 at N = 2: the iono-free factor of Eq. 8 and the paper's Eq. 18.** The "
        "published improvement at N = 2 is lower with differential correction (33.18 %) "
        f"than without (56.21 %, {pub_gap:.2f} points more), although correction makes it "
        "larger at "
        "every other size. Differential correction removes the errors common to the swarm "
        "and leaves the user error (multipath and noise, Eq. 6-8) and the relative-position "
        "error; with one partner the cooperative fix carries that partner's 0.5 m per axis "
        "relative error in full, so it gains on the corrected standalone fix only as far as "
        "the user error is large against 0.5 m. Eq. 8's iono-free factor multiplies the "
        "user error by 2.98 (GPS) or 3.53 (BDS). Improvement at N = 2 with against without "
        f"differential correction: {pairs}; published 33.18 % against 56.21 %. "
        f"Table 2's mean distance from the published rows (without / with, points): "
        + "; ".join(
            f"`{v}` {_fmt(dist[v]['without'], 1)} / {_fmt(dist[v]['with'], 1)}"
            for v in combos.values()
        )
        + "."
    )
    best = min(combos, key=lambda k: abs(gap(k) - pub_gap) if np.isfinite(gap(k)) else np.inf)
    text += (
        f" The size of that drop comes closest with {label[best]} "
        f"({_fmt(gap(best), 1)} points; published {pub_gap:.2f})."
    )
    if gap(("exact", False)) > 0 and not gap(("exact", True)) > 0:
        text += (
            " Dropping the factor alone reverses the order; the row with correction then "
            f"climbs ({rows} % for N = {', '.join(t2v[no]['with'])}) as the independent "
            "relative errors of more partners average out, as the published one does "
            "(33.18 ... 87.22 %)."
        )
    if gap(("exact", False)) > 0 and gap(("paper", False)) > 0:
        d_no, d_p = dist[combos["exact", False]], dist[combos["paper", False]]
        far = (d_p["without"] or 0) + (d_p["with"] or 0) > (d_no["without"] or 0) + (
            d_no["with"] or 0
        )
        text += (
            " Eq. 18 used as weight and SIG together with dropping the factor reproduces the "
            f"order too, with a drop of {_fmt(gap(('paper', False)), 1)} points against "
            f"{_fmt(gap(('exact', False)), 1)} with the exact covariance (published "
            f"{pub_gap:.2f}); over the whole of Table 2 it is "
            + ("farther from" if far else "closer to")
            + " the paper than the exact covariance without the factor."
        )
    if gap(("paper", True)) > 0:
        text += (
            " Eq. 18 alone also puts N = 2 lower with correction, by "
            f"{_fmt(gap(('paper', True)), 1)} points: it adds sigma_d^2 to the canyon UAV's "
            "own rows (it is its own centroid), "
            "which inflates the SIG of the cooperative fix most where the relative error "
            "matters most, with one partner and differential correction."
        )
    ms_claim = next((c for c in s["claims"] if "master-slave gives no" in c["claim"]), None)
    if ms_claim is not None and ms_claim["holds"] and not cfg.scenario.iono_free:
        text += (
            " Without the factor master-slave also loses its gain beyond 0.5 m of relative "
            "error with correction, as published (Figure 12b, below)."
        )
    if not cfg.scenario.iono_free and gap(("exact", False)) > 0:
        text += (
            " So we read the paper's results as simulated without the factor, although "
            "Eq. 8 prints it, and the default drops it."
        )
    return [text, ""]


def _discussion(cfg: ReproduceConfig, s: dict[str, Any]) -> list[str]:
    """Where and why the reproduction differs, with the numbers of this run."""
    t1 = s["main"]["table1"]
    co3 = _norm3(t1["cooperative"], "sig")
    pub = PUBLISHED["table1"]
    pub_co3 = _norm3(pub["cooperative"], "sig")
    sens = {r["name"]: r for r in s["sensitivity"]}
    lines = [
        "### Where the numbers differ, and why",
        "",
        *_default_paragraph(cfg, s, sens),
        f"**The cooperative fix is reproduced {_closeness(co3, pub_co3)}.** Our cooperative "
        f"3-D SIG is {_fmt(co3)} m against the paper's {_fmt(pub_co3)} m: with the open-sky "
        "UAVs' satellites the centroid's geometry is good and, without differential "
        "correction, its error is set by the swarm-common URE and troposphere errors, which "
        "both simulations model the same way.",
        "",
        *_mask_paragraph(cfg, s, sens),
        *_iono_paragraph(cfg, s, sens),
        "**Other open choices.** The paper's tail behaviour also depends on its constellation "
        "(real ephemerides of about 2020 have many more BeiDou satellites, GEO and IGSO among "
        "them, than the nominal 24 + 24 MEO we simulate) and on the canyon's gaps. The "
        "sensitivity table shows their weight (published for N = 5: 57.53 % and 59.07 %):",
    ]
    for name, text in (
        ("pdop-25", "a PDOP mask of 25"),
        ("pdop-10", "a PDOP mask of 10"),
        ("pdop-6", "a PDOP mask of 6"),
        ("wide-gaps", "wider gaps in the canyon (two of 40 deg instead of 20 deg)"),
    ):
        if name in sens:
            r = sens[name]
            lines.append(
                f"- {text}: standalone 3-D SIG {_fmt(r['standalone_sig3d_m'])} m, "
                f"improvement {_fmt(r['improvement_without']['sig'], 1)} % without "
                f"and {_fmt(r['improvement_with']['sig'], 1)} % with differential correction, "
                f"P(<3 m) {_fmt(r['p3m_standalone'], 0)} % standalone vs "
                f"{_fmt(r['p3m_sdt'], 0)} % SDT."
            )
    if "no-gaps" in sens:
        r = sens["no-gaps"]
        lines.append(
            f"- without gaps the canyon UAV loses its fix far more often (standalone 3-D SIG "
            f"{_fmt(r['standalone_sig3d_m'], 1)} m, {r['standalone_epochs_without_fix']} epochs "
            "without a fix): the gap layout, which the paper does not give, is a strong lever "
            "on every standalone-based number."
        )
    if "bds-geo-igso" in sens:
        r, d = sens["bds-geo-igso"], sens["default"]
        lines.append(
            f"- adding the BeiDou GEO and IGSO satellites gives the canyon UAV plenty of high "
            f"satellites (standalone 3-D SIG {_fmt(r['standalone_sig3d_m'])} m, improvement "
            f"{_fmt(r['improvement_without']['sig'], 1)} % / "
            f"{_fmt(r['improvement_with']['sig'], 1)} %), but it also makes the open-sky "
            "UAVs' ten highest satellites all high in the sky (none low), which weakens the "
            "vertical geometry, so the cooperative "
            "fix "
            + (
                "degrades"
                if (r["cooperative_sig3d_m"] or 0) > (d["cooperative_sig3d_m"] or 0)
                else "improves"
            )
            + f" ({_fmt(r['cooperative_sig3d_m'])} m against "
            f"{_fmt(d['cooperative_sig3d_m'])} m): the channel-limit rule matters as much as "
            "the constellation."
        )
    sw = s["swarm"]
    with_row = ", ".join(_fmt(sw["with"][n]["sig"], 1) for n in sw["with"])
    lines += [
        "",
        "**Table 2's trends.** Without differential correction the improvement hardly depends "
        "on the swarm size (the gain is geometric, and one open-sky UAV already brings it); "
        "with differential correction it grows with N (the cooperative fix averages the "
        "independent multipath, noise and relative-position errors, roughly as 1/sqrt(N)): "
        f"{with_row} % here, 33.18, 59.07, 71.27, 79.76, 87.22 % published.",
        "",
    ]
    one = next((b for b in s["los"]["bins"] if b["n_los"] == 1 and b["without"]["epochs"]), None)
    if one is not None and (one["without"]["fix_rate_ddt"] or 0) < 1:
        lines += [
            "**Few satellites (Figure 11).** DDT locates the canyon UAV from a single satellite, "
            f"as published, but in {100 * (1 - one['without']['fix_rate_ddt']):.0f} % of the "
            "one-satellite realisations it cannot: the satellite is then a low one along the "
            "street that the open-sky UAVs do not track (it is not among their ten highest), "
            "so no partner shares a pivot with the canyon UAV.",
            "",
        ]
    ms = s["rel_error"]["with"]
    big = [sd for sd in ms if float(sd) > 0.5]
    if big:
        vals = ", ".join(f"{sd} m {_fmt(ms[sd]['master_slave']['sig'], 1)} %" for sd in big)
        if all((ms[sd]["master_slave"]["sig"] or 0) <= 0 for sd in big):
            text = (
                "**Master-slave (Figure 12b).** As published, with differential correction "
                "master-slave brings no improvement once the relative error exceeds 0.5 m "
                f"(improvement at {vals}): the master's fix plus a relative error of that "
                "size is worse than the canyon UAV's own corrected fix, whose error is only "
                "the user error"
                + (
                    ". With Eq. 8's iono-free factor (`--set iono_free=true`) that error is "
                    "about three times larger and master-slave keeps a gain there, against "
                    "the paper."
                    if not cfg.scenario.iono_free
                    else "."
                )
            )
        else:
            text = (
                "**Master-slave (Figure 12b).** The paper finds that with differential "
                "correction master-slave brings no improvement once the relative error "
                f"exceeds 0.5 m. Here its improvement is {vals}: the master's open-sky fix "
                "plus a relative error is still better than the canyon UAV's corrected "
                "standalone fix in this configuration."
            )
        lines += [
            text + " The proposed method stays above master-slave at every relative error, "
            "as published.",
            "",
        ]
    lines += _covariance_paragraph(cfg, sens)
    if "L1/L2-for-BDS" in sens and "iono-free" in sens:
        r, d = sens["L1/L2-for-BDS"], sens["iono-free"]
        lines += [
            "**Frequencies of Eq. 8.** Eq. 8 names only L1/L2; with its iono-free factor, "
            "using that of L1/L2 (2.98) for BeiDou instead of B1I/B3I's 3.53 lowers the "
            "BeiDou user errors by 16 %: standalone 3-D SIG "
            f"{_fmt(r['standalone_sig3d_m'])} m against {_fmt(d['standalone_sig3d_m'])} m, "
            f"cooperative {_fmt(r['cooperative_sig3d_m'])} m against "
            f"{_fmt(d['cooperative_sig3d_m'])} m (`L1/L2-for-BDS` vs `iono-free`). Without "
            "the factor the frequencies do not matter.",
            "",
        ]
    lines += [
        '**Table 1\'s "Mean".** It is the mean absolute error: its ratio to the STD is '
        "0.77-0.80 in every published row (sqrt(2/pi) = 0.80 for a zero-mean Gaussian); ours "
        "is "
        + ", ".join(
            f"{(t1[m][ax]['mean'] or 0) / (t1[m][ax]['std'] or 1):.2f}"
            for m in ("standalone", "cooperative")
            for ax in AXES
        )
        + " (standalone E, N, U, cooperative E, N, U); heavier tails make a ratio smaller.",
        "",
        "**Improvement definition.** The published 57.53 % (Table 2, N = 5, no differential "
        "correction) equals 1 - |SIG(coop)| / |SIG(standalone)| computed from Table 1's SIG "
        "column exactly (57.53 %), while the STD column gives 57.43 % and the Mean column "
        "56.0 %. So we use the covariance-based definition for the comparison and report the "
        "Monte Carlo RMS-based one beside it.",
    ]
    return lines


def _covariance_paragraph(cfg: ReproduceConfig, sens: dict[str, Any]) -> list[str]:
    """Exact covariance against the paper's Eq. 18, from the sensitivity rows."""
    rows = {cfg.covariance: sens.get("default")}
    rows["paper" if cfg.covariance == "exact" else "exact"] = sens.get(
        "paper-covariance" if cfg.covariance == "exact" else "exact-covariance"
    )
    r, d = rows["paper"], rows["exact"]
    if r is None or d is None:
        return []
    return [
        "**Covariance model.** With the paper's Eq. 18 (which ignores the correlations "
        "that the DDT pivot satellite creates between rows and adds sigma_d^2 to the "
        "centroid UAV's own rows) the cooperative 3-D SIG is "
        f"{_fmt(r['cooperative_sig3d_m'])} m for a Monte Carlo STD of "
        f"{_fmt(r['cooperative_std3d_m'])} m, against {_fmt(d['cooperative_sig3d_m'])} / "
        f"{_fmt(d['cooperative_std3d_m'])} m with our exact covariance: Eq. 18 "
        + _misstates(r["cooperative_sig3d_m"], r["cooperative_std3d_m"])
        + ", its weights give a "
        + (
            "larger"
            if (r["cooperative_std3d_m"] or 0) > (d["cooperative_std3d_m"] or 0)
            else "smaller"
        )
        + " actual error than the exact ones, and SIG-based improvements computed with it "
        "inherit that error.",
        "",
    ]


def report_markdown(
    cfg: ReproduceConfig, s: dict[str, Any], figs: list[tuple[str, str]], runtime_s: float
) -> str:
    """The Markdown report."""
    t1, p3 = s["main"]["table1"], s["main"]["p3m"]
    pub = PUBLISHED["table1"]
    sw = s["swarm"]
    imp = s["main"]["improvement"]
    smoke = cfg.smoke_reasons()
    L: list[str] = [
        ("# Smoke run (not the reproduction) of" if smoke else "# Reproduction of")
        + ' Section 4 of Liu, Zhan, Wang & Zhai, "Measurement-Domain '
        'Cooperative Navigation for Multi-UAV Systems Augmented by Relative Positions"',
        "",
        "Generated by `coopnav reproduce` (`reproduction/`) in "
        f"{runtime_s:.0f} s; configuration in `config.json`, every number in `results.json`.",
        "",
        "## Headline",
        "",
    ]
    if smoke:
        L += [
            "**This is a smoke run, not the reproduction**: "
            + "; ".join(smoke)
            + ". It runs every study of the reproduction to check that they work, but on too "
            "few epochs and realisations for its numbers to be compared with the paper's. The "
            "reproduction is `coopnav reproduce --out DIR` (a few minutes).",
            "",
        ]
    L += [
        "| quantity | published | reproduced | difference |",
        "|---|---:|---:|---:|",
        f"| P(3-D error < 3 m), standalone | 37 % | {_fmt(p3['sdt']['standalone'], 1)} % | "
        f"{_sgn(p3['sdt']['standalone'] - 37, 1)} |",
        f"| P(3-D error < 3 m), cooperative SDT | 78 % | {_fmt(p3['sdt']['cooperative'], 1)} % | "
        f"{_sgn(p3['sdt']['cooperative'] - 78, 1)} |",
        f"| P(3-D error < 3 m), cooperative DDT | (about as SDT) | "
        f"{_fmt(p3['ddt']['cooperative'], 1)} % | |",
    ]
    for key, n, label in (("without", "5", "without"), ("with", "5", "with")):
        rep = sw[key].get(n, {}).get("sig")
        pubv = PUBLISHED["table2"][key][5]
        L.append(
            f"| improvement, N = 5, {label} differential correction | {pubv:.2f} % | "
            f"{_fmt(rep)} % | {_sgn(None if rep is None else rep - pubv)} |"
        )
    for scheme, label in (("standalone", "standalone"), ("cooperative", "cooperative")):
        rep, pv = _norm3(t1[scheme], "sig"), _norm3(pub[scheme], "sig")
        L.append(
            f"| 3-D SIG, {label} (from Table 1) | {pv:.2f} m | {_fmt(rep)} m | "
            f"{_sgn(None if rep is None else rep - pv)} |"
        )
    holds = sum(c["holds"] for c in s["claims"])
    sa3, co3 = _norm3(t1["standalone"], "sig"), _norm3(t1["cooperative"], "sig")
    pub_sa3, pub_co3 = _norm3(pub["standalone"], "sig"), _norm3(pub["cooperative"], "sig")
    L += [
        "",
        f"{holds} of {len(s['claims'])} qualitative claims of the paper hold in this run "
        f"(see below). The cooperative precision is reproduced {_closeness(co3, pub_co3)}, "
        f"the canyon UAV's pooled standalone precision {_closeness(sa3, pub_sa3)} "
        f"({_fmt(sa3)} m against {pub_sa3:.2f} m)"
        + (
            ", which " + ("raises" if (sa3 or 0) > pub_sa3 else "lowers") + " every improvement"
            if _closeness(sa3, pub_sa3) == "poorly"
            else ""
        )
        + f"; P(<3 m) is {_fmt(p3['sdt']['standalone'], 0)} % standalone and "
        f"{_fmt(p3['sdt']['cooperative'], 0)} % SDT against the published 37 % and 78 %. "
        "See *Where the numbers differ*.",
        "",
        "## What was simulated",
        "",
        *_scenario_lines(cfg),
        "",
        "## Definitions",
        "",
        "- All statistics are of the canyon UAV, pooled over epochs and noise realisations.",
        "- **Mean**: mean absolute error per ENU axis. **STD**: standard deviation of the "
        "pooled errors (Monte Carlo). **SIG**: sqrt(mean over the same realisations of the "
        "diagonal of the solver's ENU covariance), Eq. 23 averaged as variances (the root mean "
        "square of the per-epoch sigmas), which is what the pooled STD estimates.",
        "- **Improvement** = 1 - SIG3D(method) / SIG3D(standalone), SIG3D = sqrt(SIG_E^2 + "
        "SIG_N^2 + SIG_U^2), over realisations where both have a fix: this reproduces Table 2's "
        "57.53 % from Table 1's SIG column exactly. The Monte Carlo counterpart 1 - RMS3D(method) "
        '/ RMS3D(standalone) is given beside it ("MC").',
        "- A realisation in which a method has no fix is excluded from that method's statistics "
        "(and from comparisons involving it), as the paper does. Main study: "
        + "; ".join(
            f"{m} {e['epochs_without_fix']}/{e['epochs']} epochs without a fix"
            for m, e in s["main"]["exclusions"].items()
        )
        + ".",
        "",
        "## Table 1: precision of the canyon UAV (no differential correction, "
        f"{t1['transfer'].upper()}, {t1['n_epochs_used']} epochs, {t1['n_samples_used']} "
        "realisations)",
        "",
        "| axis | scheme | Mean pub. | Mean rep. | STD pub. | STD rep. | SIG pub. | SIG rep. |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for ax in AXES:
        for scheme, label in (
            ("standalone", "GNSS standalone"),
            ("cooperative", "GNSS + relative"),
        ):
            r, pb = t1[scheme][ax], pub[scheme][ax]
            L.append(
                f"| {ax} | {label} | {pb['mean']:.3f} | {_fmt(r['mean'], 3)} | "
                f"{pb['std']:.3f} | {_fmt(r['std'], 3)} | {pb['sig']:.3f} | "
                f"{_fmt(r['sig'], 3)} |"
            )
    L += [
        "",
        f"Improvement (DDT): {_fmt(imp['ddt']['sig'], 1)} % (MC {_fmt(imp['ddt']['rms'], 1)} %); "
        f"SDT: {_fmt(imp['sdt']['sig'], 1)} % (MC {_fmt(imp['sdt']['rms'], 1)} %). Median over "
        "epochs of the per-epoch 3-D SIG: standalone "
        f"{_fmt(s['main']['median_epoch_sig3d_m']['standalone'])} m, cooperative "
        f"{_fmt(s['main']['median_epoch_sig3d_m'][t1['transfer']])} m.",
        "",
        "## P(3-D error < 3 m) (Figure 8)",
        "",
        "| transfer | standalone pub. | standalone rep. | cooperative pub. | cooperative rep. |",
        "|---|---:|---:|---:|---:|",
        f"| SDT | 37 % | {_fmt(p3['sdt']['standalone'], 1)} % | 78 % | "
        f"{_fmt(p3['sdt']['cooperative'], 1)} % |",
        f"| DDT | (37 %) | {_fmt(p3['ddt']['standalone'], 1)} % | (no distinct difference) | "
        f"{_fmt(p3['ddt']['cooperative'], 1)} % |",
        "",
        "## Table 2: improvement against swarm size (DDT)",
        "",
        "| N | without pub. | without rep. (MC) | diff. | with pub. | with rep. (MC) | diff. |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n in sorted({int(x) for x in sw["without"]} | set(PUBLISHED["table2"]["with"])):
        cells = [str(n)]
        for key in ("without", "with"):
            pv = PUBLISHED["table2"][key].get(n)
            r = sw[key].get(str(n))
            cells += [
                "" if pv is None else f"{pv:.2f} %",
                "not run" if r is None else f"{_fmt(r['sig'])} % ({_fmt(r['rms'], 1)})",
                "" if pv is None or r is None or r["sig"] is None else _sgn(r["sig"] - pv),
            ]
        L.append("| " + " | ".join(cells) + " |")
    if s.get("table2_variants"):
        ns = [str(n) for n in sorted(int(x) for x in sw["without"])]
        L += [
            "",
            "The same study under alternative choices (SIG-based improvement, %; the last "
            "column is the mean absolute difference from the published row, in points; "
            "descriptions in the sensitivity table):",
            "",
            "| variant | differential | "
            + " | ".join(f"N = {n}" for n in ns)
            + " | mean abs. diff. |",
            "|---|---|" + "---:|" * (len(ns) + 1),
        ]
        pub_tab = {
            k: {str(n): {"sig": v} for n, v in d.items()} for k, d in PUBLISHED["table2"].items()
        }
        rows = [("*published*", pub_tab, {"without": None, "with": None})]
        rows += [("default", sw, s["table2_distance"]["default"])]
        rows += [(f"`{k}`", v, s["table2_distance"][k]) for k, v in s["table2_variants"].items()]
        for name, tab, dist in rows:
            for key in ("without", "with"):
                vals = [_fmt(tab[key].get(n, {}).get("sig"), 1) for n in ns]
                d = "" if dist[key] is None else _fmt(dist[key], 1)
                L.append(f"| {name} | {key} | " + " | ".join(vals) + f" | {d} |")
    L += [
        "",
        "## Figures 10-12 and the paper's qualitative claims",
        "",
        "| claim | holds | detail |",
        "|---|:---:|---|",
    ]
    for c in s["claims"]:
        L.append(f"| {c['claim']} | {'yes' if c['holds'] else '**no**'} | {c['detail']} |")
    L += [
        "",
        "Figure 10/11 data (DDT; improvement SIG-based, MC in brackets; RMS 3-D error in m;"
        " `-` where no fix or fewer than "
        f"{s['los']['min_epochs']} epochs):",
        "",
        "| LOS sats | epochs (all settings) | improvement without | improvement with | "
        "RMS standalone / SDT / DDT without | RMS standalone / SDT / DDT with |",
        "|---:|---:|---:|---:|---|---|",
    ]
    for b in s["los"]["bins"]:
        if not b["without"]["epochs"]:
            continue

        def cell(d: dict[str, Any]) -> str:
            i = d["improvement_ddt"]
            return "-" if i["sig"] is None else f"{i['sig']:.1f} ({i['rms']:.1f})"

        def errs(d: dict[str, Any]) -> str:
            return " / ".join(
                "-" if d[f"rms3d_{m}_m"] is None else f"{d[f'rms3d_{m}_m']:.2f}"
                for m in ("standalone", "sdt", "ddt")
            )

        L.append(
            f"| {b['n_los']} | {b['without']['epochs']} | {cell(b['without'])} | "
            f"{cell(b['with'])} | {errs(b['without'])} | {errs(b['with'])} |"
        )
    L += [
        "",
        "Figure 12 data (improvement SIG-based, %):",
        "",
        "| sigma_d [m] | proposed without | master-slave without | proposed with | "
        "master-slave with |",
        "|---:|---:|---:|---:|---:|",
    ]
    for sd in s["rel_error"]["without"]:
        a, b = s["rel_error"]["without"][sd], s["rel_error"]["with"][sd]
        L.append(
            f"| {sd} | {_fmt(a['proposed']['sig'], 1)} | "
            f"{_fmt(a['master_slave']['sig'], 1)} | {_fmt(b['proposed']['sig'], 1)} | "
            f"{_fmt(b['master_slave']['sig'], 1)} |"
        )
    if s["sensitivity"]:
        L += [
            "",
            "## Sensitivity to the choices the paper leaves open",
            "",
            f"Each row re-runs the main study ({cfg.n_samples_sweep} realisations per epoch, "
            "same noise draws as the `default` row) with the choices its description names "
            "changed (variants that change nothing in this run are left out). 3-D SIG / STD in "
            "m; improvements (N = 5) SIG-based, MC in brackets; P(<3 m) over realisations "
            "where standalone and SDT both have a fix.",
            "",
            "| variant | standalone SIG / STD | coop SIG / STD | improvement without | "
            "improvement with | P<3 m standalone / SDT / DDT | epochs w/o standalone fix |",
            "|---|---|---|---:|---:|---|---:|",
            "| *published* | 5.70 / 5.73 | 2.42 / 2.44 | 57.53 | 59.07 | 37 / 78 / - | - |",
        ]
        for r in s["sensitivity"]:
            iw, iwd = r["improvement_without"], r["improvement_with"]
            L.append(
                f"| `{r['name']}`: {r['description']} | {_fmt(r['standalone_sig3d_m'])} / "
                f"{_fmt(r['standalone_std3d_m'])} | {_fmt(r['cooperative_sig3d_m'])} / "
                f"{_fmt(r['cooperative_std3d_m'])} | {_fmt(iw['sig'], 1)} ({_fmt(iw['rms'], 1)})"
                f" | {_fmt(iwd['sig'], 1)} ({_fmt(iwd['rms'], 1)}) | "
                f"{_fmt(r['p3m_standalone'], 0)} / {_fmt(r['p3m_sdt'], 0)} / "
                f"{_fmt(r['p3m_ddt'], 0)} | {r['standalone_epochs_without_fix']} |"
            )
    L += ["", *_discussion(cfg, s), ""]
    if figs:
        L += ["## Figures", ""]
        for name, caption in figs:
            L += [f"![{name}]({name})", "", f"*{caption}*", ""]
    L += [
        "## Reproducing this report",
        "",
        "```",
        cfg.command_line(),
        "```",
        "",
        "or `coopnav reproduce --out DIR --config config.json` with this run's `config.json`. "
        "Same seed and configuration give identical numbers (`results.json`, apart from `timing`).",
        "",
    ]
    return "\n".join(L)
