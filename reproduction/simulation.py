"""Simulation of the Section 4 studies and the statistics of their pooled errors.

:func:`simulate_epoch` runs every method (standalone, DDT, SDT, master-slave) on the noise
realisations of one epoch; :func:`run_studies` runs all epochs of every study (main, LOS,
swarm size, relative error, sensitivity) with the one random generator of the run and pools
them per setting (:class:`Pooled`); :func:`axis_stats`, :func:`improvement`,
:func:`p_within`, :func:`rms3d` and :func:`exclusions` are the statistics the tables report
(definitions in :mod:`reproduction`).
"""

from __future__ import annotations

import copy
import dataclasses
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from coopnav_env.nav import (
    GnssObservations,
    NavStatus,
    pdop,
    solve_cooperative_samples,
    solve_master_slave,
    solve_standalone,
)

# --------------------------------------------------------------------------------------------
# One epoch: all methods on K noise realisations
# --------------------------------------------------------------------------------------------
from coopnav_env.reproduction.config import (
    AXES,
    THRESHOLD_3D_M,
    BoolArray,
    FloatArray,
    Method,
    ReproduceConfig,
)
from coopnav_env.reproduction.scenario import (
    PaperEpoch,
    PaperScenario,
)

__all__ = [
    "SENSITIVITY",
    "SENS_METHODS",
    "TABLE2_VARIANTS",
    "EpochResult",
    "Pooled",
    "axis_stats",
    "epoch_times",
    "exclusions",
    "improvement",
    "json_float",
    "p_within",
    "rms3d",
    "run_studies",
    "sensitivity_variants",
    "simulate_epoch",
    "standalone_pdop",
    "variant_setting",
]


@dataclass(frozen=True)
class EpochResult:
    """The canyon UAV's errors for each method at one epoch.

    Attributes
    ----------
    err_enu_m : dict of str to ndarray, shape (K, 3)
        Position error in ENU [m]; NaN where the method has no fix.
    var_enu_m2 : dict of str to ndarray, shape (K, 3)
        Diagonal of the method's covariance in ENU [m^2] (Eq. 23 squared); NaN without a fix.
    ok : dict of str to ndarray of bool, shape (K,)
        ``status == NavStatus.OK``.
    n_los : int
        Satellites tracked by the canyon UAV.
    pdop : float
        PDOP of the canyon UAV's standalone geometry (inf when it cannot be solved).
    t_s : float
        Epoch time [s].
    """

    err_enu_m: dict[str, FloatArray]
    var_enu_m2: dict[str, FloatArray]
    ok: dict[str, BoolArray]
    n_los: int
    pdop: float
    t_s: float


def standalone_pdop(ep: PaperEpoch, uav: int) -> float:
    """Position dilution of precision of one UAV's standalone fix (unit weights).

    State: position and one clock per constellation the UAV sees (Eq. 14). Returns ``inf``
    when there are fewer satellites than unknowns or the geometry is singular.
    """
    vis = ep.visible[uav]
    los = ep.sv_ecef_m[vis] - ep.pos_ecef_m[uav]
    los /= np.linalg.norm(los, axis=1, keepdims=True)
    return pdop(los, ep.system[vis])


def _standalone_rows(ep: PaperEpoch, pr_m: FloatArray, rows: list[int]) -> GnssObservations:
    """Observations of receivers ``rows`` in every sample, stacked as ``K * len(rows)`` rows."""
    k = pr_m.shape[0]
    return GnssObservations(
        pr_m=pr_m[:, rows, :].reshape(k * len(rows), -1),
        sv_ecef_m=ep.sv_ecef_m,
        system=ep.system,
        sigma_user_m=np.tile(ep.sigma_user_m[rows], (k, 1)),
        sigma_common_m=ep.sigma_common_m,
        el_deg=np.tile(ep.el_deg[rows], (k, 1)),
    )


def simulate_epoch(
    ep: PaperEpoch,
    rng: np.random.Generator,
    n_samples: int,
    *,
    methods: tuple[Method, ...] = ("standalone", "ddt"),
    covariance: Literal["exact", "paper"] = "exact",
) -> EpochResult:
    """Draw ``n_samples`` realisations of one epoch and locate the canyon UAV by each method.

    Methods: ``"standalone"`` (its own WLS, Eq. 14-17), ``"ddt"`` / ``"sdt"`` (the proposed
    cooperative fix with the canyon UAV as its own virtual centroid, Section 3.1; computed with
    ``centroid=<canyon index>``, which is identical to ``centroid="self"`` for that UAV and one
    solve instead of N) and ``"master_slave"`` (the traditional scheme of Section 4.2: the best
    open-sky UAV's standalone fix plus the measured relative position, covariance
    ``H_master + C_d``; computed in bulk exactly as :func:`coopnav_env.nav.solve_master_slave`
    does). The solvers start from the formation origin (a receiver's last known position).

    Parameters
    ----------
    ep : PaperEpoch
    rng : numpy.random.Generator
    n_samples : int
        ``K`` >= 1 realisations (common to all methods).
    methods : tuple of str
    covariance : {"exact", "paper"}
        Covariance model of the cooperative solver.

    Returns
    -------
    EpochResult
    """
    smp = ep.draw(rng, n_samples)
    k, c, rot = n_samples, ep.canyon_uav, ep.rot_enu
    truth = ep.pos_ecef_m[c]
    err: dict[str, FloatArray] = {}
    var: dict[str, FloatArray] = {}
    ok: dict[str, BoolArray] = {}

    def put(name: str, pos: FloatArray, cov: FloatArray, status: np.ndarray) -> None:
        good = status == NavStatus.OK
        e = (pos - truth) @ rot.T
        v = np.einsum("ij,kjl,il->ki", rot, cov, rot)
        err[name] = np.where(good[:, None], e, np.nan)
        var[name] = np.where(good[:, None], v, np.nan)
        ok[name] = good

    need_sa = "standalone" in methods or "master_slave" in methods
    master = -1
    rows = [c]
    if "master_slave" in methods:
        master = solve_master_slave(ep.observations(), ep.relative_positions()).master
        rows.append(master)
    if need_sa:
        sa = solve_standalone(_standalone_rows(ep, smp.pr_m, rows), ep.origin_ecef_m)
        pos = sa.pos_ecef_m.reshape(k, len(rows), 3)
        cov = sa.cov_ecef_m2.reshape(k, len(rows), 3, 3)
        st = sa.status.reshape(k, len(rows))
        if "standalone" in methods:
            put("standalone", pos[:, 0], cov[:, 0], st[:, 0])
        if "master_slave" in methods:
            # the pair (c, m) has one measurement: p_c - p_m - eps_cm
            rel = (truth - ep.pos_ecef_m[master])[None] - smp.eps_enu_m[:, master] @ rot
            c_d = ep.sigma_rel_m**2 * np.eye(3)  # isotropic in ENU, hence in ECEF
            put("master_slave", pos[:, 1] + rel, cov[:, 1] + c_d, st[:, 1])
    template = ep.observations()
    rel_t = ep.relative_positions()
    for tr in ("ddt", "sdt"):
        if tr not in methods:
            continue
        sol = solve_cooperative_samples(
            template,
            smp.pr_m,
            rel_t,
            smp.rel_from_canyon_ecef_m,
            centroid=c,
            transfer=tr,
            covariance=covariance,
            x0_ecef_m=ep.origin_ecef_m,
        )
        put(tr, sol.pos_ecef_m[:, c], sol.cov_ecef_m2[:, c], sol.status[:, c])
    return EpochResult(
        err_enu_m=err,
        var_enu_m2=var,
        ok=ok,
        n_los=ep.n_los,
        pdop=standalone_pdop(ep, c),
        t_s=ep.t_s,
    )


@dataclass
class Pooled:
    """Epoch results of one setting concatenated over epochs (``M = n_epochs * K`` rows)."""

    err: dict[str, FloatArray]  # (M, 3)
    var: dict[str, FloatArray]  # (M, 3)
    ok: dict[str, BoolArray]  # (M,)
    n_los: NDArray[np.intp]  # (M,)
    pdop: FloatArray  # (M,) canyon UAV standalone PDOP
    epoch: NDArray[np.intp]  # (M,)
    t_s: FloatArray  # (n_epochs,)
    n_samples: int

    @classmethod
    def of(cls, results: list[EpochResult]) -> Pooled:
        k = next(iter(results[0].ok.values())).shape[0]
        names = results[0].ok.keys()
        return cls(
            err={m: np.concatenate([r.err_enu_m[m] for r in results]) for m in names},
            var={m: np.concatenate([r.var_enu_m2[m] for r in results]) for m in names},
            ok={m: np.concatenate([r.ok[m] for r in results]) for m in names},
            n_los=np.repeat([r.n_los for r in results], k),
            pdop=np.repeat([r.pdop for r in results], k),
            epoch=np.repeat(np.arange(len(results)), k),
            t_s=np.array([r.t_s for r in results]),
            n_samples=k,
        )

    def merge(self, other: Pooled) -> Pooled:
        """Concatenate two pooled sets (epoch indices of ``other`` shifted)."""
        shift = self.t_s.size
        return Pooled(
            err={m: np.concatenate([self.err[m], other.err[m]]) for m in self.err},
            var={m: np.concatenate([self.var[m], other.var[m]]) for m in self.var},
            ok={m: np.concatenate([self.ok[m], other.ok[m]]) for m in self.ok},
            n_los=np.concatenate([self.n_los, other.n_los]),
            pdop=np.concatenate([self.pdop, other.pdop]),
            epoch=np.concatenate([self.epoch, other.epoch + shift]),
            t_s=np.concatenate([self.t_s, other.t_s]),
            n_samples=self.n_samples,
        )

    def with_pdop_mask(self, max_pdop: float | None) -> Pooled:
        """The canyon UAV's standalone fixes with PDOP above ``max_pdop`` counted as no fix."""
        if max_pdop is None:
            return self
        bad = ~(self.pdop <= max_pdop)
        ok = dict(self.ok)
        ok["standalone"] = ok["standalone"] & ~bad
        err = dict(self.err)
        var = dict(self.var)
        err["standalone"] = np.where(bad[:, None], np.nan, err["standalone"])
        var["standalone"] = np.where(bad[:, None], np.nan, var["standalone"])
        return dataclasses.replace(self, ok=ok, err=err, var=var)

    def subset(self, mask: BoolArray) -> Pooled:
        """Rows ``mask`` only (epoch times kept)."""
        return Pooled(
            err={m: v[mask] for m, v in self.err.items()},
            var={m: v[mask] for m, v in self.var.items()},
            ok={m: v[mask] for m, v in self.ok.items()},
            n_los=self.n_los[mask],
            pdop=self.pdop[mask],
            epoch=self.epoch[mask],
            t_s=self.t_s,
            n_samples=self.n_samples,
        )


# --------------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------------


def json_float(x: float) -> float | None:
    """A float for JSON (NaN -> None)."""
    return None if x is None or not np.isfinite(x) else float(x)


def axis_stats(p: Pooled, method: str, mask: BoolArray) -> dict[str, dict[str, float | None]]:
    """Mean absolute error, STD and SIG per ENU axis over the rows ``mask`` [m]."""
    e, v = p.err[method][mask], p.var[method][mask]
    out = {}
    for i, ax in enumerate(AXES):
        if e.shape[0] == 0:
            out[ax] = {"mean": None, "std": None, "sig": None}
            continue
        out[ax] = {
            "mean": json_float(np.mean(np.abs(e[:, i]))),
            "std": json_float(np.std(e[:, i])),
            "sig": json_float(np.sqrt(np.mean(v[:, i]))),
        }
    return out


def improvement(
    p: Pooled, method: str, base: str = "standalone", mask: BoolArray | None = None
) -> dict[str, float | int | None]:
    """Improvement of ``method`` over ``base`` [%] where both have a fix (and ``mask``).

    ``sig``: ``100 (1 - SIG3D(method) / SIG3D(base))`` (the paper's, see module docstring);
    ``rms``: ``100 (1 - RMS3D(method) / RMS3D(base))`` (Monte Carlo). ``n``: realisations used.
    """
    both = p.ok[method] & p.ok[base]
    if mask is not None:
        both = both & mask
    n = int(both.sum())
    if n == 0:
        return {"sig": None, "rms": None, "n": 0}
    sig_m = np.sqrt(np.mean(np.sum(p.var[method][both], axis=1)))
    sig_b = np.sqrt(np.mean(np.sum(p.var[base][both], axis=1)))
    rms_m = np.sqrt(np.mean(np.sum(p.err[method][both] ** 2, axis=1)))
    rms_b = np.sqrt(np.mean(np.sum(p.err[base][both] ** 2, axis=1)))
    return {
        "sig": json_float(100 * (1 - sig_m / sig_b)),
        "rms": json_float(100 * (1 - rms_m / rms_b)),
        "n": n,
    }


def p_within(p: Pooled, method: str, mask: BoolArray, thr_m: float = THRESHOLD_3D_M) -> float:
    """Percentage of rows ``mask`` whose 3-D error is below ``thr_m``."""
    e3 = np.linalg.norm(p.err[method][mask], axis=1)
    return float(100 * np.mean(e3 < thr_m)) if e3.size else float("nan")


def rms3d(p: Pooled, method: str, mask: BoolArray | None = None) -> tuple[float, int]:
    """RMS 3-D error [m] of ``method`` over its own fixes (and ``mask``), and the count."""
    m = p.ok[method] if mask is None else p.ok[method] & mask
    n = int(m.sum())
    if n == 0:
        return float("nan"), 0
    return float(np.sqrt(np.mean(np.sum(p.err[method][m] ** 2, axis=1)))), n


def exclusions(p: Pooled, methods: Iterable[str]) -> dict[str, dict[str, int]]:
    """Epochs and realisations without a fix, per method."""
    out = {}
    n_ep = p.t_s.size
    for m in methods:
        fail = ~p.ok[m]
        ep_fail = np.zeros(n_ep, dtype=bool)
        np.logical_or.at(ep_fail, p.epoch[fail], True)
        out[m] = {
            "epochs_without_fix": int(ep_fail.sum()),
            "epochs": int(n_ep),
            "samples_without_fix": int(fail.sum()),
            "samples": int(fail.size),
        }
    return out


# --------------------------------------------------------------------------------------------
# Studies
# --------------------------------------------------------------------------------------------


class _Progress:
    """A tqdm bar over epoch evaluations (silent when disabled or tqdm is missing)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.bar = None
        if enabled:
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - tqdm is a declared dependency
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(
                    total=total, desc="reproduce", unit="epoch", file=sys.stderr, dynamic_ncols=True
                )

    def step(self, label: str) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(label, refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def epoch_times(cfg: ReproduceConfig) -> FloatArray:
    return cfg.start_time_s + cfg.epoch_spacing_s * np.arange(cfg.n_epochs)


def _run_setting(
    cfg: ReproduceConfig,
    scen: PaperScenario,
    rng: np.random.Generator,
    n_samples: int,
    methods: tuple[Method, ...],
    prog: _Progress,
    label: str,
    *,
    covariance: str | None = None,
    n_los: int | None = None,
) -> Pooled:
    """All epochs of one setting. ``rng`` is consumed."""
    out = []
    for t in epoch_times(cfg):
        ep = scen.epoch(float(t), rng, n_los=n_los)
        out.append(
            simulate_epoch(
                ep, rng, n_samples, methods=methods, covariance=covariance or cfg.covariance
            )
        )
        prog.step(label)
    return Pooled.of(out)


#: Sensitivity variants: name -> (description, scenario overrides, config overrides). Each is
#: the run's configuration with one choice (or one pair of choices) changed; a variant that
#: changes nothing in a given run (its overrides are that run's values) or equals an earlier
#: one is left out of that run (:func:`sensitivity_variants`).
SENSITIVITY: dict[str, tuple[str, dict[str, Any], dict[str, Any]]] = {
    "default": ("the defaults of this run", {}, {}),
    "previous-default": (
        "the earlier default: Eq. 8 with its iono-free factor and every standalone fix kept "
        "(no PDOP mask)",
        {"iono_free": True},
        {"max_pdop": None},
    ),
    "all-fixes": (
        "every standalone fix kept, near-singular geometry included (no PDOP mask)",
        {},
        {"max_pdop": None},
    ),
    "pdop-25": ("standalone fixes with PDOP > 25 count as no fix", {}, {"max_pdop": 25.0}),
    "pdop-10": ("standalone fixes with PDOP > 10 count as no fix", {}, {"max_pdop": 10.0}),
    "pdop-6": ("standalone fixes with PDOP > 6 count as no fix", {}, {"max_pdop": 6.0}),
    "exact-covariance": (
        "our exact covariance of the transferred measurements (weights and SIG)",
        {},
        {"covariance": "exact"},
    ),
    "paper-covariance": (
        "the paper's Eq. 18 covariance (weights and SIG)",
        {},
        {"covariance": "paper"},
    ),
    "L1/L2-for-BDS": (
        "Eq. 8 with its iono-free factor, that of GPS L1/L2 for BDS too (ErrorModel.paper())",
        {"frequencies": "paper", "iono_free": True},
        {},
    ),
    "iono-free": (
        "Eq. 8 with its iono-free factor (user error x 2.98 GPS, x 3.53 BDS)",
        {"iono_free": True},
        {},
    ),
    "no-iono-free": (
        "Eq. 8 without its iono-free factor (user error sqrt(MP^2 + noise^2))",
        {"iono_free": False},
        {},
    ),
    "paper-cov-iono-free": (
        "Eq. 18 covariance and Eq. 8 with its iono-free factor",
        {"iono_free": True},
        {"covariance": "paper"},
    ),
    "paper-cov-no-iono-free": (
        "Eq. 18 covariance and no iono-free factor",
        {"iono_free": False},
        {"covariance": "paper"},
    ),
    "cutoff-5": ("elevation cut-off 5 deg", {"elevation_cutoff_deg": 5.0}, {}),
    "cutoff-15": ("elevation cut-off 15 deg", {"elevation_cutoff_deg": 15.0}, {}),
    "no-gaps": ("canyon without gaps", {"gaps_deg": ()}, {}),
    "wide-gaps": (
        "two 40 deg gaps (30-70, 210-250 deg)",
        {"gaps_deg": ((30.0, 70.0), (210.0, 250.0))},
        {},
    ),
    "street-90": ("east-west street", {"street_azimuth_deg": 90.0}, {}),
    "random-open-sky": (
        "open-sky UAVs keep 10 random satellites, not the 10 highest",
        {"open_sky_selection": "random"},
        {},
    ),
    "bds-geo-igso": ("BeiDou GEO and IGSO satellites added", {"bds_geo_igso": True}, {}),
}

TABLE2_VARIANTS: tuple[str, ...] = (
    "previous-default",
    "all-fixes",
    "pdop-25",
    "pdop-10",
    "pdop-6",
    "exact-covariance",
    "paper-covariance",
    "iono-free",
    "no-iono-free",
    "paper-cov-iono-free",
    "paper-cov-no-iono-free",
    "wide-gaps",
)
"""Sensitivity variants for which the whole swarm-size study (Table 2) is also computed (those
that change only the PDOP mask reuse the swarm-size simulations of their setting)."""

SENS_METHODS: tuple[Method, ...] = ("standalone", "ddt", "sdt")


def variant_setting(cfg: ReproduceConfig, name: str) -> tuple[PaperScenario, str, float | None]:
    """Scenario, covariance and PDOP mask of sensitivity variant ``name`` of run ``cfg``."""
    _, s_over, c_over = SENSITIVITY[name]
    return (
        dataclasses.replace(cfg.scenario, **s_over),
        c_over.get("covariance", cfg.covariance),
        c_over.get("max_pdop", cfg.max_pdop),
    )


def sensitivity_variants(cfg: ReproduceConfig) -> list[str]:
    """The variants run for ``cfg``: ``"default"`` first, then every variant of
    :data:`SENSITIVITY` whose setting differs from the default's and from every earlier one."""
    seen: list[tuple[PaperScenario, str, float | None]] = []
    names = []
    for name in SENSITIVITY:
        setting = variant_setting(cfg, name)
        if setting not in seen:
            seen.append(setting)
            names.append(name)
    return names


def _run_swarm(
    cfg: ReproduceConfig,
    scen: PaperScenario,
    g_swarm: np.random.Generator,
    prog: _Progress,
    label: str,
    *,
    covariance: str | None = None,
) -> dict[bool, dict[int, Pooled]]:
    """The swarm-size study (Table 2) of one scenario; every setting starts from ``g_swarm``."""
    swarm: dict[bool, dict[int, Pooled]] = {False: {}, True: {}}
    for diff in (False, True):
        for n in cfg.swarm_sizes:
            s = dataclasses.replace(
                scen, differential=diff, n_uavs=n, canyon_uav=min(scen.canyon_uav, n - 1)
            )
            swarm[diff][n] = _run_setting(
                cfg,
                s,
                copy.deepcopy(g_swarm),
                cfg.n_samples_sweep,
                ("standalone", "ddt"),
                prog,
                f"{label} N={n} diff={diff}",
                covariance=covariance,
            )
    return swarm


def _table2_variants(cfg: ReproduceConfig) -> list[str]:
    """The Table 2 variants run for ``cfg`` (those of :data:`TABLE2_VARIANTS` it keeps)."""
    kept = sensitivity_variants(cfg)
    return [name for name in TABLE2_VARIANTS if name in kept]


def _n_units(cfg: ReproduceConfig) -> int:
    e = cfg.n_epochs
    n_los = len(cfg.los_h_over_d) if cfg.los_method == "hd_sweep" else cfg.scenario.max_sats
    units = e  # main
    units += 2 * n_los * e + 2 * len(cfg.swarm_sizes) * e + 2 * len(cfg.rel_errors_m) * e
    if cfg.sensitivity:
        sims = {variant_setting(cfg, n)[:2] for n in sensitivity_variants(cfg)}
        units += 2 * len(sims) * e
        swarms = {variant_setting(cfg, n)[:2] for n in _table2_variants(cfg)}
        swarms.discard((cfg.scenario, cfg.covariance))  # the main Table 2 study
        units += 2 * len(swarms) * len(cfg.swarm_sizes) * e
    return units


def run_studies(cfg: ReproduceConfig) -> dict[str, Any]:
    """Run every study and return the pooled raw results (no statistics, no files).

    Randomness: one ``numpy.random.Generator`` from ``cfg.seed``; each study gets a child
    generator spawned from it, and every setting of a study starts from a copy of that child
    (common random numbers: settings differ by what they change, not by their noise draws).
    """
    rng = np.random.default_rng(cfg.seed)
    g_main, g_los, g_swarm, g_rel, g_sens = rng.spawn(5)
    prog = _Progress(_n_units(cfg), cfg.progress)
    scen = cfg.scenario
    nodiff = dataclasses.replace(scen, differential=False)
    raw: dict[str, Any] = {}
    try:
        raw["main"] = _run_setting(
            cfg, nodiff, g_main, cfg.n_samples, ("standalone", "ddt", "sdt"), prog, "main"
        )
        ks = cfg.n_samples_sweep
        los: dict[bool, Pooled] = {}
        for diff in (False, True):
            pooled = None
            settings = (
                [("hd", h) for h in cfg.los_h_over_d]
                if cfg.los_method == "hd_sweep"
                else [("k", k) for k in range(1, scen.max_sats + 1)]
            )
            for kind, val in settings:
                s = dataclasses.replace(scen, differential=diff)
                if kind == "hd":
                    s = dataclasses.replace(s, h_over_d=val)
                p = _run_setting(
                    cfg,
                    s,
                    copy.deepcopy(g_los),
                    ks,
                    ("standalone", "ddt", "sdt"),
                    prog,
                    f"los {kind}={val:.3g} diff={diff}",
                    n_los=val if kind == "k" else None,
                )
                pooled = p if pooled is None else pooled.merge(p)
            los[diff] = pooled
        raw["los"] = los
        raw["swarm"] = _run_swarm(cfg, scen, g_swarm, prog, "swarm")
        rel: dict[bool, dict[float, Pooled]] = {False: {}, True: {}}
        for diff in (False, True):
            for sd in cfg.rel_errors_m:
                s = dataclasses.replace(scen, differential=diff, sigma_rel_m=sd)
                rel[diff][sd] = _run_setting(
                    cfg,
                    s,
                    copy.deepcopy(g_rel),
                    ks,
                    ("standalone", "ddt", "master_slave"),
                    prog,
                    f"rel sigma={sd:g} diff={diff}",
                )
        raw["rel_error"] = rel
        # sensitivity: variants that differ only in the PDOP mask share their simulations
        sens: dict[str, dict[bool, Pooled]] = {}
        variants: dict[str, dict[bool, dict[int, Pooled]]] = {}
        if cfg.sensitivity:
            sims: dict[tuple[PaperScenario, str], dict[bool, Pooled]] = {}
            for name in sensitivity_variants(cfg):
                s_var, cov, _ = variant_setting(cfg, name)
                if (s_var, cov) not in sims:
                    sims[s_var, cov] = {
                        diff: _run_setting(
                            cfg,
                            dataclasses.replace(s_var, differential=diff),
                            copy.deepcopy(g_sens),
                            ks,
                            SENS_METHODS,
                            prog,
                            f"sensitivity {name} diff={diff}",
                            covariance=cov,
                        )
                        for diff in (False, True)
                    }
                sens[name] = sims[s_var, cov]
            swarms = {(scen, cfg.covariance): raw["swarm"]}
            for name in _table2_variants(cfg):
                s_var, cov, _ = variant_setting(cfg, name)
                if (s_var, cov) not in swarms:
                    swarms[s_var, cov] = _run_swarm(
                        cfg, s_var, g_swarm, prog, f"swarm {name}", covariance=cov
                    )
                variants[name] = swarms[s_var, cov]
        raw["sensitivity"] = sens
        raw["swarm_variants"] = variants
    finally:
        prog.close()
    return raw
