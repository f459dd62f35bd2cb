"""The reproduced numbers beside the published ones, and the paper's claims checked.

:func:`summarize` turns the pooled studies of
:func:`coopnav_env.reproduction.simulation.run_studies` into the content of ``results.json``:
Table 1, P(3-D error < 3 m), Table 2, the LOS and relative-error studies, the sensitivity
table, the comparison with :data:`PUBLISHED` and the paper's qualitative claims, each marked
as holding or not.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from coopnav_env.reproduction.config import AXES, PUBLISHED, BoolArray, ReproduceConfig
from coopnav_env.reproduction.simulation import (
    SENSITIVITY,
    Pooled,
    axis_stats,
    exclusions,
    improvement,
    json_float,
    p_within,
    rms3d,
    variant_setting,
)

# --------------------------------------------------------------------------------------------
# Summary: reproduced numbers, published numbers, claims
# --------------------------------------------------------------------------------------------

__all__ = [
    "summarize",
    "table2_distance",
]


def _n_epochs_with(p: Pooled, mask: BoolArray) -> int:
    return int(np.unique(p.epoch[mask]).size)


def _main_summary(p: Pooled, transfer: str) -> dict[str, Any]:
    """Table 1, P(3-D error < 3 m), improvement and exclusions of the main study."""
    out: dict[str, Any] = {}
    both = p.ok["standalone"] & p.ok[transfer]
    out["table1"] = {
        "standalone": axis_stats(p, "standalone", both),
        "cooperative": axis_stats(p, transfer, both),
        "transfer": transfer,
        "n_samples_used": int(both.sum()),
        "n_epochs_used": _n_epochs_with(p, both),
    }
    out["improvement"] = {tr: improvement(p, tr) for tr in ("ddt", "sdt")}
    p3 = {}
    for tr in ("ddt", "sdt"):
        m = p.ok["standalone"] & p.ok[tr]
        p3[tr] = {
            "standalone": json_float(p_within(p, "standalone", m)),
            "cooperative": json_float(p_within(p, tr, m)),
            "n": int(m.sum()),
        }
    out["p3m"] = p3
    out["exclusions"] = exclusions(p, ("standalone", "ddt", "sdt"))
    ep_pdop = p.pdop[:: p.n_samples]
    fin = ep_pdop[np.isfinite(ep_pdop)]
    out["canyon"] = {
        "n_los_histogram": np.bincount(p.n_los[:: p.n_samples], minlength=11).tolist(),
        "pdop_percentiles_10_50_90_99": [
            json_float(x) for x in np.percentile(fin, [10, 50, 90, 99])
        ]
        if fin.size
        else None,
    }
    # robust view: per-epoch SIG3D of each method, median over epochs with both fixes
    sig3 = {}
    for m in ("standalone", transfer):
        v = np.where(both, np.sum(p.var[m], axis=1), np.nan)
        per_ep = [np.nanmean(v[p.epoch == e]) for e in np.unique(p.epoch[both])]
        sig3[m] = json_float(np.sqrt(np.median(per_ep))) if per_ep else None
    out["median_epoch_sig3d_m"] = sig3
    return out


def _slope(x: list[float], y: list[float]) -> float:
    return float(np.polyfit(x, y, 1)[0]) if len(x) >= 2 else float("nan")


def _los_summary(los: dict[bool, Pooled], min_epochs: int, max_n: int) -> dict[str, Any]:
    bins = []
    for n in range(0, max_n + 1):
        row: dict[str, Any] = {"n_los": n}
        for diff, key in ((False, "without"), (True, "with")):
            p = los[diff]
            m = p.n_los == n
            both = m & p.ok["standalone"] & p.ok["ddt"]
            d: dict[str, Any] = {
                "epochs": _n_epochs_with(p, m),
                "epochs_with_standalone_fix": _n_epochs_with(p, m & p.ok["standalone"]),
            }
            for meth in ("standalone", "sdt", "ddt"):
                r, k = rms3d(p, meth, m)
                d[f"rms3d_{meth}_m"] = json_float(r)
                d[f"fix_rate_{meth}"] = json_float(float(p.ok[meth][m].mean())) if m.any() else None
                _ = k
            reported = _n_epochs_with(p, both) >= min_epochs
            for tr in ("ddt", "sdt"):
                imp = improvement(p, tr, mask=m) if reported else {"sig": None, "rms": None}
                d[f"improvement_{tr}"] = {"sig": imp["sig"], "rms": imp["rms"]}
            row[key] = d
        bins.append(row)
    return {"bins": bins, "min_epochs": min_epochs}


def _claim(text: str, holds: bool, detail: str) -> dict[str, Any]:
    return {"claim": text, "holds": bool(holds), "detail": detail}


def _claims(s: dict[str, Any]) -> list[dict[str, Any]]:
    """The paper's qualitative statements, checked against the reproduced numbers."""
    out = []
    main = s["main"]
    imp = main["improvement"]["ddt"]
    p3 = main["p3m"]
    out.append(
        _claim(
            "Cooperative (DDT) navigation beats standalone for the canyon UAV (Fig. 7-8)",
            (imp["rms"] or -1) > 0 and p3["ddt"]["cooperative"] > p3["ddt"]["standalone"],
            f"RMS-3D improvement {imp['rms']:.1f} %, P(<3 m) {p3['ddt']['cooperative']:.1f} % vs "
            f"{p3['ddt']['standalone']:.1f} %",
        )
    )
    gap = abs(p3["sdt"]["cooperative"] - p3["ddt"]["cooperative"])
    out.append(
        _claim(
            "SDT and DDT give about the same accuracy (Fig. 8 a vs b)",
            gap < 5.0,
            f"P(<3 m) SDT {p3['sdt']['cooperative']:.1f} %, DDT {p3['ddt']['cooperative']:.1f} %",
        )
    )
    ratios = [
        main["table1"][m][ax]["sig"] / main["table1"][m][ax]["std"]
        for m in ("standalone", "cooperative")
        for ax in AXES
        if main["table1"][m][ax]["std"]
    ]
    worst = max(abs(r - 1) for r in ratios) if ratios else float("nan")
    out.append(
        _claim(
            "SIG matches the Monte Carlo STD (Fig. 9, Table 1)",
            worst < 0.1,
            f"largest |SIG/STD - 1| over axes and methods: {worst:.3f}",
        )
    )
    for key, label in (("without", "without"), ("with", "with")):
        xs, ys = [], []
        for b in s["los"]["bins"]:
            v = b[key]["improvement_ddt"]["sig"]
            if v is not None:
                xs.append(b["n_los"])
                ys.append(v)
        slope = _slope(xs, ys)
        out.append(
            _claim(
                f"Improvement declines as the canyon UAV sees more satellites, {label} "
                "differential correction (Fig. 10)",
                slope < 0,
                f"least-squares slope {slope:.1f} %/satellite over n_los = {xs}",
            )
        )
    diffs = [
        b["with"]["improvement_ddt"]["sig"] - b["without"]["improvement_ddt"]["sig"]
        for b in s["los"]["bins"]
        if b["with"]["improvement_ddt"]["sig"] is not None
        and b["without"]["improvement_ddt"]["sig"] is not None
    ]
    out.append(
        _claim(
            "Improvement is larger with differential correction (Fig. 10)",
            bool(diffs) and min(diffs) > 0,
            f"with minus without, per n_los bin: {[round(d, 1) for d in diffs]}",
        )
    )
    few = [b for b in s["los"]["bins"] if 1 <= b["n_los"] <= 3 and b["without"]["epochs"]]
    ok_few = bool(few) and all(
        (b["without"]["fix_rate_ddt"] or 0) > 0
        and not (b["without"]["fix_rate_standalone"] or 0)
        and not (b["without"]["fix_rate_sdt"] or 0)
        for b in few
    )
    out.append(
        _claim(
            "With 1-3 LOS satellites only DDT locates the canyon UAV; standalone and SDT cannot "
            "(Fig. 11)",
            ok_few,
            "fix rates (standalone / SDT / DDT) at n_los = 1, 2, 3: "
            + "; ".join(
                f"{b['n_los']}: {b['without']['fix_rate_standalone']:.2f} / "
                f"{b['without']['fix_rate_sdt']:.2f} / {b['without']['fix_rate_ddt']:.2f}"
                for b in few
            ),
        )
    )
    sw = s["swarm"]
    without = [sw["without"][k]["sig"] for k in sw["without"]]
    with_ = [sw["with"][k]["sig"] for k in sw["with"]]
    out.append(
        _claim(
            "Without differential correction the improvement hardly depends on swarm size "
            "(Table 2: 56.2-58.2 %)",
            max(without) - min(without) < 5.0,
            f"range {min(without):.1f}-{max(without):.1f} %",
        )
    )
    out.append(
        _claim(
            "With differential correction the improvement grows with swarm size (Table 2)",
            all(b > a for a, b in itertools.pairwise(with_)),
            f"{[round(v, 1) for v in with_]} % for N = {list(sw['with'])}",
        )
    )
    re_ = s["rel_error"]
    beats = all(
        re_[k][sd]["proposed"]["sig"] > re_[k][sd]["master_slave"]["sig"]
        for k in ("without", "with")
        for sd in re_[k]
    )
    out.append(
        _claim(
            "The proposed method beats master-slave at every relative error (Fig. 12)",
            beats,
            "see the Figure 12 table",
        )
    )
    dec = all(
        all(b <= a + 1e-9 for a, b in itertools.pairwise(v))
        for k in ("without", "with")
        for meth in ("proposed", "master_slave")
        for v in [[re_[k][sd][meth]["sig"] for sd in re_[k]]]
    )
    out.append(
        _claim(
            "The improvement decreases as the relative error grows (Fig. 12)",
            dec,
            "both methods, with and without differential correction",
        )
    )
    big = [sd for sd in re_["with"] if float(sd) > 0.5]
    ms_none = bool(big) and all(re_["with"][sd]["master_slave"]["sig"] <= 0 for sd in big)
    out.append(
        _claim(
            "With differential correction master-slave gives no improvement once the relative "
            "error exceeds 0.5 m (Fig. 12b)",
            ms_none,
            "master-slave improvement at sigma_d = "
            + ", ".join(f"{sd} m: {re_['with'][sd]['master_slave']['sig']:.1f} %" for sd in big),
        )
    )
    return out


def _comparison(s: dict[str, Any]) -> list[dict[str, Any]]:
    """Published value, reproduced value and difference for every published number."""
    rows = []

    def add(name: str, pub: float, rep: float | None, unit: str) -> None:
        rows.append(
            {
                "quantity": name,
                "published": pub,
                "reproduced": rep,
                "difference": None if rep is None else rep - pub,
                "unit": unit,
            }
        )

    t1 = s["main"]["table1"]
    for ax in AXES:
        for scheme, label in (
            ("standalone", "GNSS standalone"),
            ("cooperative", "GNSS + relative"),
        ):
            for stat in ("mean", "std", "sig"):
                add(
                    f"Table 1 {ax} {label} {stat.upper()}",
                    PUBLISHED["table1"][scheme][ax][stat],
                    t1[scheme][ax][stat],
                    "m",
                )
    p3 = s["main"]["p3m"]
    add(
        "P(3-D error < 3 m) standalone (Sec. 4.2, Fig. 8a)",
        PUBLISHED["p3m"]["standalone"],
        p3["sdt"]["standalone"],
        "%",
    )
    add(
        "P(3-D error < 3 m) cooperative SDT (Sec. 4.2, Fig. 8a)",
        PUBLISHED["p3m"]["sdt"],
        p3["sdt"]["cooperative"],
        "%",
    )
    for key, label in (("without", "without"), ("with", "with")):
        for n, pub in PUBLISHED["table2"][key].items():
            rep = s["swarm"][key].get(str(n), {}).get("sig")
            add(f"Table 2 improvement N = {n}, {label} differential correction", pub, rep, "%")
    return rows


def table2_distance(tab: dict[str, Any]) -> dict[str, float | None]:
    """Mean absolute difference [points] of a reproduced Table 2 from the published one.

    ``tab`` maps ``"without"`` / ``"with"`` to ``{str(N): improvement}`` (SIG-based); only the
    published swarm sizes that were run count. ``None`` where none was.
    """
    out: dict[str, float | None] = {}
    for key in ("without", "with"):
        d = [
            abs(tab[key][str(n)]["sig"] - pub)
            for n, pub in PUBLISHED["table2"][key].items()
            if tab[key].get(str(n), {}).get("sig") is not None
        ]
        out[key] = json_float(float(np.mean(d))) if d else None
    return out


def summarize(cfg: ReproduceConfig, raw: dict[str, Any]) -> dict[str, Any]:
    """All statistics of a run (the content of ``results.json`` without timing)."""
    mp = cfg.max_pdop
    s: dict[str, Any] = {"seed": cfg.seed}
    s["main"] = _main_summary(raw["main"].with_pdop_mask(mp), cfg.transfer)
    s["main"]["standalone_solver_failures"] = exclusions(raw["main"], ["standalone"])["standalone"]
    max_n = cfg.scenario.max_sats
    s["los"] = _los_summary(
        {d: p.with_pdop_mask(mp) for d, p in raw["los"].items()}, cfg.los_min_epochs, max_n
    )
    s["los"]["method"] = cfg.los_method
    s["swarm"] = {
        key: {
            str(n): improvement(p.with_pdop_mask(mp), "ddt") for n, p in raw["swarm"][diff].items()
        }
        for diff, key in ((False, "without"), (True, "with"))
    }
    s["rel_error"] = {
        key: {
            f"{sd:g}": {
                "proposed": improvement(p.with_pdop_mask(mp), "ddt"),
                "master_slave": improvement(p.with_pdop_mask(mp), "master_slave"),
            }
            for sd, p in raw["rel_error"][diff].items()
        }
        for diff, key in ((False, "without"), (True, "with"))
    }
    sens = []
    for name, pooled in raw.get("sensitivity", {}).items():
        desc = SENSITIVITY[name][0]
        mpv = variant_setting(cfg, name)[2]
        p0, p1 = pooled[False].with_pdop_mask(mpv), pooled[True].with_pdop_mask(mpv)
        both = p0.ok["standalone"] & p0.ok["ddt"]
        a, b = axis_stats(p0, "standalone", both), axis_stats(p0, "ddt", both)
        m_sdt = p0.ok["standalone"] & p0.ok["sdt"]

        def n3(st: dict[str, dict[str, float | None]], key: str) -> float | None:
            vals = [st[ax][key] for ax in AXES]
            return None if None in vals else float(np.sqrt(sum(v * v for v in vals)))

        sens.append(
            {
                "name": name,
                "description": desc,
                "standalone_sig3d_m": n3(a, "sig"),
                "standalone_std3d_m": n3(a, "std"),
                "cooperative_sig3d_m": n3(b, "sig"),
                "cooperative_std3d_m": n3(b, "std"),
                "improvement_without": improvement(p0, "ddt"),
                "improvement_with": improvement(p1, "ddt"),
                "p3m_standalone": json_float(p_within(p0, "standalone", m_sdt)),
                "p3m_sdt": json_float(p_within(p0, "sdt", m_sdt)),
                "p3m_ddt": json_float(p_within(p0, "ddt", both)),
                "standalone_epochs_without_fix": exclusions(p0, ["standalone"])["standalone"][
                    "epochs_without_fix"
                ],
            }
        )
    s["sensitivity"] = sens
    s["table2_variants"] = {}
    for name, sw in raw.get("swarm_variants", {}).items():
        desc = SENSITIVITY[name][0]
        mpv = variant_setting(cfg, name)[2]
        s["table2_variants"][name] = {"description": desc} | {
            key: {str(n): improvement(p.with_pdop_mask(mpv), "ddt") for n, p in sw[diff].items()}
            for diff, key in ((False, "without"), (True, "with"))
        }
    s["table2_distance"] = {
        name: table2_distance(tab)
        for name, tab in {"default": s["swarm"], **s["table2_variants"]}.items()
    }
    s["comparison"] = _comparison(s)
    s["claims"] = _claims(s)
    s["published"] = {
        "table1": PUBLISHED["table1"],
        "p3m": PUBLISHED["p3m"],
        "table2": {k: {str(n): v for n, v in d.items()} for k, d in PUBLISHED["table2"].items()},
    }
    return s
