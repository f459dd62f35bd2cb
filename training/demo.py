"""``coopnav demo``: standalone vs cooperative error of a UAV in an urban canyon.

A five-UAV formation near Shanghai flies for a while (default one hour of epochs, 60 s apart);
UAV 0 sits in a street canyon (the paper's analytic mask, Eq. 25, h/d = sqrt(3) with gaps), the
others in open sky. Every epoch simulates GPS + BeiDou pseudoranges (Eq. 1-8) and relative
positions (0.5 m per axis), then solves standalone WLS (Eq. 14-17) and the cooperative
virtual-centroid DDT solution (Eq. 10-23) for UAV 0, and prints the errors.

This needs only the core package (numpy); it is the quickest check that an installation works.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from coopnav_env.constants import SHANGHAI_ALT_M, SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG

__all__ = ["DEMO_KERNEL_MODULES", "DemoResult", "add_arguments", "run", "run_demo"]

DEMO_KERNEL_MODULES: tuple[str, ...] = (
    "coopnav_env.gnss._kernels",
    "coopnav_env.nav._kernels",
    "coopnav_env.sim._kernels",
)
"""The kernel modules the demo compiles (see :mod:`coopnav_env.training.compile_notice`)."""


@dataclass(frozen=True)
class DemoResult:
    """Per-epoch 3-D errors [m] of the canyon UAV (NaN where that solver had no fix)."""

    t_s: np.ndarray
    n_sats_canyon: np.ndarray
    standalone_err_m: np.ndarray
    coop_err_m: np.ndarray
    coop_sigma_m: np.ndarray


def run_demo(
    n_epochs: int = 60,
    dt_s: float = 60.0,
    seed: int = 0,
    differential: bool = False,
    progress: bool = True,
) -> DemoResult:
    """Simulate ``n_epochs`` epochs and solve standalone and cooperative fixes of UAV 0.

    Parameters
    ----------
    n_epochs : int
        Number of epochs (>= 1).
    dt_s : float
        Time between epochs [s] (> 0).
    seed : int
        Seed of the one random generator used.
    differential : bool
        Apply differential correction (removes common errors).
    progress : bool
        Show a progress bar (tqdm, if installed), started after the first epoch (which
        compiles or loads the numba kernels; when that takes a while a line on stderr says
        so: :func:`coopnav_env.training.compile_notice.compile_notice`).
    """
    from coopnav_env.gnss import (
        ErrorModel,
        azimuth_elevation,
        default_constellation,
        draw_clock_biases,
        enu_to_ecef,
        select_highest,
        simulate_pseudoranges,
    )
    from coopnav_env.nav import (
        GnssObservations,
        NavStatus,
        RelativePositions,
        solve_cooperative,
        solve_standalone,
    )
    from coopnav_env.sim import CanyonMask, measure_relative_positions
    from coopnav_env.sim.swarm import RelativeSensingConfig

    if isinstance(n_epochs, bool) or not isinstance(n_epochs, int) or n_epochs < 1:
        raise ValueError(f"n_epochs (--epochs) must be an integer >= 1, got {n_epochs!r}")
    if not (isinstance(dt_s, (int, float)) and 0 < dt_s < float("inf")):
        raise ValueError(f"dt_s (--dt) must be a finite number > 0, got {dt_s!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed (--seed) must be an integer >= 0, got {seed!r}")
    rng = np.random.default_rng(seed)
    const = default_constellation()
    model = ErrorModel(differential=differential)
    mask = CanyonMask()
    lat, lon, alt = SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M + 30.0
    enu = np.array([[0, 0, 0], [30, 0, 0], [-30, 0, 0], [0, 30, 0], [0, -30, 0]], dtype=float)
    pos = enu_to_ecef(enu, lat, lon, alt)
    sensing = RelativeSensingConfig(max_range_m=200.0, sigma0_m=0.5, sigma_per_m=0.0)
    clocks = draw_clock_biases(rng, len(enu), 2)
    out = {k: np.full(n_epochs, np.nan) for k in ("sa", "co", "sig", "ns")}
    t = np.arange(n_epochs) * dt_s
    x0 = {"sa": None, "co": None}

    def one_epoch(i: int) -> None:
        sv = const.positions_ecef(float(t[i]))
        az, el = azimuth_elevation(pos, sv)
        vis = el > 10.0
        vis[1:] = select_highest(el[1:], vis[1:], 10)  # open sky: at most 10 satellites
        vis[0] &= mask.visible(az[0], el[0])
        epoch = simulate_pseudoranges(rng, pos, sv, const.system, vis, model, clocks)
        obs = GnssObservations.from_epoch(epoch)
        rel_enu, cov_enu, avail = measure_relative_positions(rng, enu, sensing)
        rel = RelativePositions.from_enu(rel_enu, cov_enu, avail, lat, lon)
        sa = solve_standalone(obs.subset_receivers([0]), x0["sa"])
        co = solve_cooperative(obs, rel, centroid=0, x0_ecef_m=x0["co"])
        out["ns"][i] = vis[0].sum()
        if sa.status[0] == NavStatus.OK:
            out["sa"][i] = np.linalg.norm(sa.pos_ecef_m[0] - pos[0])
            x0["sa"] = sa.pos_ecef_m
        if co.status[0] == NavStatus.OK:
            out["co"][i] = np.linalg.norm(co.pos_ecef_m[0] - pos[0])
            out["sig"][i] = np.sqrt(np.trace(co.cov_ecef_m2[0]))
            x0["co"] = co.centroid_pos_ecef_m[0]

    # the first epoch compiles (or loads) the numba kernels: run it before the progress bar
    # starts, so that the bar's rate and ETA measure the epochs, not the compilation
    if progress:
        from coopnav_env.training.compile_notice import compile_notice

        with compile_notice("about 20 s", modules=DEMO_KERNEL_MODULES, prefix="coopnav demo"):
            one_epoch(0)
    else:
        one_epoch(0)
    rest = range(1, n_epochs)
    if progress and n_epochs > 1:
        try:
            from tqdm import tqdm

            rest = tqdm(rest, desc="demo epochs", unit="epoch", initial=1, total=n_epochs)
        except ImportError:
            pass
    for i in rest:
        one_epoch(i)
    return DemoResult(t, out["ns"], out["sa"], out["co"], out["sig"])


def _summary(res: DemoResult) -> str:
    both = np.isfinite(res.standalone_err_m) & np.isfinite(res.coop_err_m)
    lines = [
        "Canyon UAV (paper Eq. 25 mask, h/d = sqrt(3)), 3-D position error [m]",
        f"epochs: {res.t_s.size}; satellites in view: {np.nanmin(res.n_sats_canyon):.0f}-"
        f"{np.nanmax(res.n_sats_canyon):.0f}; standalone fixes: "
        f"{np.isfinite(res.standalone_err_m).sum()}, cooperative fixes: "
        f"{np.isfinite(res.coop_err_m).sum()}",
        "",
        f"{'':24}{'mean':>8}{'median':>8}{'p95':>8}{'P(<3 m)':>9}",
    ]
    for name, e in (("standalone WLS", res.standalone_err_m), ("cooperative DDT", res.coop_err_m)):
        e = e[both]
        if e.size:
            lines.append(
                f"{name:24}{e.mean():8.2f}{np.median(e):8.2f}{np.percentile(e, 95):8.2f}"
                f"{(e < 3).mean():9.0%}"
            )
    if both.any():
        rms_sa = np.sqrt(np.mean(res.standalone_err_m[both] ** 2))
        rms_co = np.sqrt(np.mean(res.coop_err_m[both] ** 2))
        lines.append(f"\nimprovement (1 - RMS coop / RMS standalone): {1 - rms_co / rms_sa:.1%}")
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``coopnav demo``."""
    parser.add_argument(
        "--epochs", type=int, default=60, help="number of epochs (default: %(default)s)"
    )
    parser.add_argument(
        "--dt", type=float, default=60.0, help="seconds between epochs (default: %(default)s)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    parser.add_argument(
        "--differential",
        action="store_true",
        help="apply differential correction (default: off)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the demo and print the summary table."""
    res = run_demo(args.epochs, args.dt, args.seed, args.differential)
    print(_summary(res))
    return 0
