"""The analogues of the paper's Figures 6-12 and Table 2, as PNG files (matplotlib)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.reproduction.config import (
    AXES,
    FAIL_PLOT_M,
    PUBLISHED,
    THRESHOLD_3D_M,
    ReproduceConfig,
)
from coopnav_env.reproduction.simulation import epoch_times
from coopnav_env.training.files import atomic_path

# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------

__all__ = [
    "write_figures",
]


def write_figures(
    cfg: ReproduceConfig, raw: dict[str, Any], s: dict[str, Any], out: Path
) -> list[tuple[str, str]]:
    """Write the PNG figures; returns ``(file name, caption)`` pairs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    def plain_log(a: Any) -> None:
        a.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        a.yaxis.set_minor_formatter(NullFormatter())

    figs: list[tuple[str, str]] = []
    colors = {
        "standalone": "tab:blue",
        "ddt": "tab:red",
        "sdt": "tab:orange",
        "master_slave": "tab:green",
    }

    def save(fig: Any, name: str, caption: str) -> None:
        fig.tight_layout()
        with atomic_path(out / name, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=110)
        plt.close(fig)
        figs.append((name, caption))

    # Figure 6: sky plot of the canyon UAV over the day
    scen = dataclasses.replace(cfg.scenario, differential=False)
    fig = plt.figure(figsize=(5.5, 5.5))
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    for t in epoch_times(cfg):
        az, el, system, vis = scen.sky(float(t))
        up = el > 0
        for sysi, col in ((0, "tab:blue"), (1, "tab:red")):
            m = up & vis & (system == sysi)
            ax.scatter(np.radians(az[m]), 90 - el[m], s=3, c=col)
        m = up & ~vis
        ax.scatter(np.radians(az[m]), 90 - el[m], s=3, c="0.75")
    grid = np.linspace(0, 360, 721)
    ax.plot(
        np.radians(grid),
        90 - np.maximum(scen.canyon_mask_deg(grid), scen.elevation_cutoff_deg),
        "k-",
        lw=1.2,
    )
    ax.set_rlim(0, 90)
    ax.set_yticks([0, 30, 60, 90], labels=["90", "60", "30", "0"])
    ax.set_title(
        f"Canyon UAV sky over the day\nGPS blue, BDS red, blocked grey; h/d = {scen.h_over_d:.3g}",
        fontsize=9,
    )
    save(
        fig,
        "fig6_skyplot.png",
        "Figure 6 analogue: satellites seen by the canyon UAV over the simulated day (every "
        "epoch), the Eq. 25 mask with gaps (black line) and the elevation cut-off.",
    )

    # Figure 7: error over time (first realisation of each epoch)
    p = raw["main"].with_pdop_mask(cfg.max_pdop)
    k = p.n_samples
    hours = (p.t_s - p.t_s[0]) / 3600.0
    first = np.arange(p.t_s.size) * k
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for i, name in enumerate(AXES):
        a = axes[i]
        for m, lab in (("standalone", "GNSS standalone"), (cfg.transfer, "GNSS + relative")):
            e = p.err[m][first, i]
            a.plot(hours, np.clip(e, -19.5, 19.5), ".-", ms=3, lw=0.8, color=colors[m], label=lab)
            for sign, mk in ((1, "^"), (-1, "v")):
                off = sign * e > 20
                if off.any():
                    a.plot(hours[off], np.full(off.sum(), sign * 19.5), mk, color=colors[m], ms=5)
        fail = ~p.ok["standalone"][first]
        if fail.any():
            a.plot(
                hours[fail],
                np.full(fail.sum(), FAIL_PLOT_M),
                "o",
                mfc="none",
                mec="gold",
                ms=7,
                label="standalone: no fix"
                + ("" if cfg.max_pdop is None else f" or PDOP > {cfg.max_pdop:g}")
                + " (drawn at 16 m)",
            )
        a.set_ylabel(f"{name} error [m]")
        a.set_ylim(-20, 20)
        a.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower right")
    axes[-1].set_xlabel("time [h]")
    save(
        fig,
        "fig7_error_time.png",
        "Figure 7 analogue: canyon UAV position error (one realisation per epoch) over the "
        "day, standalone vs cooperative; epochs without a standalone fix"
        + ("" if cfg.max_pdop is None else f" (or with PDOP > {cfg.max_pdop:g})")
        + " are drawn at 16 m (yellow circles) as in the paper; the axis is clipped at "
        "+/-20 m.",
    )

    # Figure 8: CDF of the 3-D error, SDT and DDT
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), sharey=True)
    for a, tr in zip(axes, ("sdt", "ddt")):
        m = p.ok["standalone"] & p.ok[tr]
        for meth, lab in (("standalone", "GNSS standalone"), (tr, "GNSS + relative")):
            e3 = np.sort(np.linalg.norm(p.err[meth][m], axis=1))
            a.plot(
                e3,
                np.arange(1, e3.size + 1) / max(e3.size, 1),
                color=colors[meth],
                label=f"{lab}: P(<3 m) = {100 * np.mean(e3 < THRESHOLD_3D_M):.0f} %",
            )
        a.axvline(THRESHOLD_3D_M, color="k", ls=":", lw=1)
        a.set_xlim(0, 15)
        a.set_xlabel("3-D error [m]")
        a.set_title(f"({'a' if tr == 'sdt' else 'b'}) {tr.upper()}")
        a.grid(alpha=0.3)
        a.legend(fontsize=8, loc="lower right")
    axes[0].set_ylabel("cumulative probability")
    save(
        fig,
        "fig8_cdf.png",
        "Figure 8 analogue: cumulative distribution of the canyon UAV's 3-D error, (a) SDT, "
        "(b) DDT; realisations where both methods have a fix. Paper: 78 % vs 37 % within 3 m "
        "(SDT).",
    )

    # Figure 9: per-epoch STD and SIG
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    n_ep = p.t_s.size
    for i, name in enumerate(AXES):
        a = axes[i]
        for m, lab in (("standalone", "standalone"), (cfg.transfer, "cooperative")):
            e = p.err[m][:, i].reshape(n_ep, k)
            v = p.var[m][:, i].reshape(n_ep, k)
            good = p.ok[m].reshape(n_ep, k).all(axis=1)
            std = np.where(good, np.nanstd(np.where(good[:, None], e, 0.0), axis=1), np.nan)
            sig = np.where(
                good, np.sqrt(np.nanmean(np.where(good[:, None], v, 0.0), axis=1)), np.nan
            )
            a.semilogy(hours, std, "o", ms=3, mfc="none", color=colors[m], label=f"STD {lab}")
            a.semilogy(hours, sig, "-", lw=1, color=colors[m], label=f"SIG {lab}")
        a.set_ylabel(f"{name} [m]")
        a.grid(alpha=0.3, which="both")
        plain_log(a)
    axes[0].legend(fontsize=7, ncol=2, loc="upper right")
    axes[-1].set_xlabel("time [h]")
    save(
        fig,
        "fig9_sig_std.png",
        f"Figure 9 analogue: per-epoch Monte Carlo STD ({k} realisations, circles) and SIG "
        "(Eq. 23, lines) of the canyon UAV, standalone and cooperative (log scale).",
    )

    # Figure 10: improvement vs number of LOS satellites
    fig, a = plt.subplots(figsize=(6.5, 4))
    for key, col, lab in (
        ("without", "tab:blue", "without differential"),
        ("with", "tab:red", "with differential"),
    ):
        xs = [b["n_los"] for b in s["los"]["bins"] if b[key]["improvement_ddt"]["sig"] is not None]
        ys = [
            b[key]["improvement_ddt"]["sig"]
            for b in s["los"]["bins"]
            if b[key]["improvement_ddt"]["sig"] is not None
        ]
        yr = [
            b[key]["improvement_ddt"]["rms"]
            for b in s["los"]["bins"]
            if b[key]["improvement_ddt"]["sig"] is not None
        ]
        a.plot(xs, ys, "o-", color=col, label=f"{lab} (SIG)")
        a.plot(xs, yr, "x:", color=col, label=f"{lab} (Monte Carlo RMS)")
    a.set_xlabel("LOS satellites at the canyon UAV")
    a.set_ylabel("improvement [%]")
    a.set_ylim(0, 100)
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    save(
        fig,
        "fig10_improvement_vs_los.png",
        "Figure 10 analogue: improvement of the cooperative (DDT) fix over standalone against "
        "the canyon UAV's number of LOS satellites, with and without differential correction ("
        + (
            "h/d swept over " + ", ".join(f"{h:.3g}" for h in cfg.los_h_over_d)
            if cfg.los_method == "hd_sweep"
            else "satellites thinned at random"
        )
        + ").",
    )

    # Figure 11: error vs number of LOS satellites
    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5), sharex=True)
    for r, tr in enumerate(("sdt", "ddt")):
        for c, (key, lab) in enumerate((("without", "without"), ("with", "with"))):
            a = axes[r, c]
            for meth, name in (("standalone", "GNSS standalone"), (tr, "GNSS + relative")):
                xs = [
                    b["n_los"]
                    for b in s["los"]["bins"]
                    if b[key][f"rms3d_{meth}_m"] is not None and b[key]["epochs"]
                ]
                ys = [
                    b[key][f"rms3d_{meth}_m"]
                    for b in s["los"]["bins"]
                    if b[key][f"rms3d_{meth}_m"] is not None and b[key]["epochs"]
                ]
                a.semilogy(xs, ys, "o-", color=colors[meth], label=name)
            a.set_title(f"({'abcd'[2 * r + c]}) {tr.upper()}, {lab} differential", fontsize=9)
            a.grid(alpha=0.3, which="both")
            plain_log(a)
            a.legend(fontsize=8)
            if c == 0:
                a.set_ylabel("RMS 3-D error [m]")
            if r == 1:
                a.set_xlabel("LOS satellites at the canyon UAV")
    axes[0, 0].set_xticks(range(0, cfg.scenario.max_sats + 1))
    save(
        fig,
        "fig11_error_vs_los.png",
        "Figure 11 analogue: RMS 3-D error of the canyon UAV against its number of LOS "
        "satellites (each method over its own fixes; a missing point means no fix at all).",
    )

    # Figure 12: improvement vs relative error, proposed vs master-slave
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), sharey=True)
    for a, (key, lab) in zip(axes, (("without", "(a) without"), ("with", "(b) with"))):
        sds = [float(x) for x in s["rel_error"][key]]
        for meth, name, col in (
            ("proposed", "proposed (virtual centroid, DDT)", "tab:red"),
            ("master_slave", "traditional master-slave", "tab:blue"),
        ):
            ys = [s["rel_error"][key][x][meth]["sig"] for x in s["rel_error"][key]]
            a.plot(sds, ys, "o-", color=col, label=name)
        a.axhline(0, color="k", lw=0.8)
        a.set_xlabel("relative position error sigma per ENU axis [m]")
        a.set_title(f"{lab} differential correction", fontsize=9)
        a.grid(alpha=0.3)
    axes[0].set_ylabel("improvement [%]")
    axes[0].legend(fontsize=8)
    save(
        fig,
        "fig12_improvement_vs_relerr.png",
        "Figure 12 analogue: improvement over the canyon UAV's standalone fix against the "
        "relative-position error, proposed method vs master-slave.",
    )

    # Table 2 as a figure
    fig, a = plt.subplots(figsize=(6.5, 4))
    for key, col, lab in (
        ("without", "tab:blue", "without differential"),
        ("with", "tab:red", "with differential"),
    ):
        ns = [int(n) for n in s["swarm"][key]]
        a.semilogx(
            ns,
            [s["swarm"][key][str(n)]["sig"] for n in ns],
            "o-",
            color=col,
            label=f"reproduced, {lab}",
        )
        pub = PUBLISHED["table2"][key]
        a.semilogx(
            list(pub), list(pub.values()), "s--", mfc="none", color=col, label=f"published, {lab}"
        )
    a.set_xticks(sorted(set(cfg.swarm_sizes) | set(PUBLISHED["table2"]["with"])))
    a.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    a.xaxis.set_minor_formatter(NullFormatter())
    a.set_xlabel("number of UAVs")
    a.set_ylabel("improvement [%]")
    a.set_ylim(0, 100)
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    save(
        fig,
        "table2_swarm_size.png",
        "Table 2 analogue: improvement against swarm size, reproduced (SIG-based) vs published.",
    )
    return figs
