"""Benchmark: the navigation of one swarm-step (``epoch_navigation``) on recorded inputs.

It flies ``urban_canyon_v1`` episodes (default settings: N = 5, GPS + BeiDou, DDT, every UAV
its own centroid) with the ``waypoint`` heuristic (``--policy random``: uniformly random
commands, as ``bench_env.py`` flies them, whose episodes end at a wall after a few steps and
so include many first epochs), records the arguments of every call of
:func:`coopnav_env.sim._kernels.epoch_navigation` (the world's one-call navigation, the same
computation the batched step runs per swarm), then times the kernel on those inputs:

* **total**: microseconds per swarm-step of ``epoch_navigation`` (mean over the recorded
  epochs; each epoch's figure is the best of ``--rounds`` rounds of ``--repeats`` calls made
  from a compiled loop, so Python's call overhead is not counted);
* **split**: the stages it is made of, each timed the same way on the same inputs: the
  pseudorange model, standalone WLS, the cooperative set-up (baselines and masks), the
  cooperative Gauss-Newton loop, the cooperative finish (statuses, every UAV's covariance),
  the selection and the waypoints; beside them the iterations (per receiver, per centroid)
  and the problem sizes (satellites in the sky, received per UAV, used per centroid);
* with ``--compare REF``: the same total for the kernels of git revision ``REF``
  (``coopnav_env/gnss/_kernels.py``, ``coopnav_env/nav/_kernels.py`` and
  ``coopnav_env/sim/_kernels.py`` as committed there, loaded beside this checkout's), in
  alternating rounds in this process, the ratio of the two, and whether both give the same
  outputs bit for bit on every recorded epoch (a revision whose ``epoch_navigation`` took
  its 39 arguments one by one, before the records of :mod:`coopnav_env.sim._kernels`, gets
  them so: :func:`positional`).

On a shared machine the best round is the one least disturbed by the neighbours; compare
figures from one run (ratios) rather than across runs.

Usage::

    python benchmarks/bench_nav.py                      # about 1-2 minutes after compiling
    python benchmarks/bench_nav.py --episodes 1 --compare main
    python benchmarks/bench_nav.py --policy random --episodes 40
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coopnav_env.gnss import _kernels as gnss_k
from coopnav_env.nav import _kernels as nav_k
from coopnav_env.sim import _kernels as sim_k

# --------------------------------------------------------------------------------------------
# recording
# --------------------------------------------------------------------------------------------


def record_epochs(
    episodes: int, max_steps: int, seed: int, policy: str = "waypoint"
) -> list[tuple]:
    """The arguments of every ``epoch_navigation`` call of ``episodes`` v1 episodes flown by
    ``policy`` (``"waypoint"``: the waypoint heuristic; ``"random"``: commands drawn uniformly
    from [-1, 1] with a generator seeded by ``seed``), through the per-copy step path, whose
    one-call navigation is that of the batched step; copied."""
    if policy not in ("waypoint", "random"):
        raise ValueError(f"policy must be 'waypoint' or 'random', got {policy!r}")
    from coopnav_env import urban_canyon_v1
    from coopnav_env.agents.heuristics import WaypointPolicy
    from coopnav_env.envs import _fused
    from coopnav_env.sim import scenario

    calls: list[tuple] = []

    def recording(*args):
        calls.append(_copied(args))
        return sim_k.epoch_navigation(*args)

    saved_settings, saved_kernels = _fused.fused_settings, scenario._sim_kernels
    _fused.fused_settings = lambda cfg: False  # every step through UrbanWorld.step
    scenario._sim_kernels = SimpleNamespace(
        **{k: getattr(sim_k, k) for k in dir(sim_k) if not k.startswith("__")}
    )
    scenario._sim_kernels.epoch_navigation = recording
    try:
        env = urban_canyon_v1.parallel_env(max_steps=max_steps)
        heuristic = WaypointPolicy(env)
        rng = np.random.default_rng(seed)
        for e in range(episodes):
            obs, _ = env.reset(seed=seed + e)
            while env.agents:
                if policy == "random":
                    act = {a: rng.uniform(-1.0, 1.0, 3).astype(np.float32) for a in env.agents}
                else:
                    act = heuristic.act(obs)
                obs, *_ = env.step(act)
    finally:
        _fused.fused_settings, scenario._sim_kernels = saved_settings, saved_kernels
    return calls


# --------------------------------------------------------------------------------------------
# compiled repeat loops (no Python call overhead in the timings)
# --------------------------------------------------------------------------------------------


def repeater(fn: Any) -> Any:
    """A compiled ``loop(reps, args)`` calling ``fn(*args)`` ``reps`` times."""

    @njit
    def loop(reps, args):
        out = fn(*args)
        for _ in range(reps - 1):
            out = fn(*args)
        return out

    return loop


def best_time(loop: Any, args: tuple, repeats: int) -> float:
    """Seconds per call of one round of ``repeats`` calls."""
    t0 = time.perf_counter()
    loop(repeats, args)
    return (time.perf_counter() - t0) / repeats


# --------------------------------------------------------------------------------------------
# the stages of epoch_navigation, with their inputs
# --------------------------------------------------------------------------------------------


def _copied(args: Any) -> Any:
    """``args`` with every array copied (tuples and records of them, nested)."""
    if isinstance(args, tuple):
        return tuple(_copied(a) for a in args)
    return args.copy() if isinstance(args, np.ndarray) else args


def positional(args: tuple) -> tuple:
    """The records of an ``epoch_navigation`` call (:class:`~coopnav_env.sim._kernels.
    Geometry`, ``Pseudoranges``, ``Centroids``, ``Solving``, ``Prior``, ``Waypoints``) as the
    39 positional arguments the kernel took before it took records (revisions before them, for
    ``--compare``)."""
    geometry, pseudoranges, centroids, solving, prior, waypoints = args[:6]
    rel_b, var_b, avail_b, cen, x0_co, ddt, linked, links = centroids
    max_iter, tol_m, check, r_lo, r_hi, gate_on, gate2 = solving
    x0, origin, rot, pred_enu, prev_cov, dr_var = prior
    return (
        *geometry,
        *pseudoranges,
        x0,
        rel_b,
        var_b,
        avail_b,
        cen,
        x0_co,
        ddt,
        max_iter,
        tol_m,
        check,
        r_lo,
        r_hi,
        linked,
        gate_on,
        gate2,
        origin,
        rot,
        pred_enu,
        prev_cov,
        dr_var,
        *waypoints,
        links,
    )


def stage_inputs(args: tuple) -> tuple[dict[str, tuple], dict[str, Any]]:
    """The arguments of each stage of ``epoch_navigation`` for the epoch ``args`` (computed
    by the same kernels, in the order ``epoch_navigation`` calls them), and the problem
    sizes."""
    geometry, pseudoranges, centroids, solving, prior, waypoints = args[:6]
    range_m, el_deg, sv, system, received = geometry
    clock, iono, z_common, z_user, extra, el_ref, sigma_ure, tropo, differential, n_sys = (
        pseudoranges
    )
    rel_b, var_b, avail_b, cen, x0_co, ddt, linked, _links = centroids
    max_iter, tol_m, check, r_lo, r_hi, gate_on, gate2 = solving
    x0, origin, rot, pred_enu, prev_cov, dr_var = prior
    route, next_wp, reach_m = waypoints
    st: dict[str, tuple] = {}
    st["pseudoranges"] = (
        range_m,
        el_deg,
        system,
        received,
        gnss_k.ErrorDraws(clock, z_common, z_user, extra),
        gnss_k.ErrorBudget(iono, el_ref, sigma_ure, tropo, differential),
    )
    _sc, su_raw, _ce, _ue, pr = gnss_k.pseudorange_model(*st["pseudoranges"])
    vis = np.isfinite(pr)
    su = np.where(vis, su_raw, np.nan)
    el = np.where(vis, el_deg, np.nan)
    st["standalone"] = (
        nav_k.Measured(pr, vis, sv, system, su, _sc, el, n_sys),
        x0.copy(),
        nav_k.SolverLimits(max_iter, tol_m, check, r_lo, r_hi),
    )
    sa = nav_k.standalone_solve(*st["standalone"])
    _n, s = vis.shape
    st["co_setup"] = (rel_b, var_b, avail_b, cen, vis, system, el, n_sys, ddt)
    bavail, base, bcov, froot = nav_k.isotropic_setup(rel_b, var_b, avail_b, cen)
    ref, used, has_clock, _pivot, too_few = nav_k.setup_masks(
        vis, bavail, cen, system, el, n_sys, ddt, -1
    )
    pr0 = np.where(vis, pr, 0.0)[None]
    st["co_gauss_newton"] = (
        (pr0, sv, vis, su, _sc, system),
        (used, base, froot, ref, has_clock, ~too_few, x0_co),
        max_iter,
        tol_m,
    )
    pos, clk, inv, cross, converged, singular, iters = nav_k.cooperative_gauss_newton(
        *st["co_gauss_newton"]
    )
    n_nuis = nav_k.n_nuisance(used, system, ref, n_sys)
    st["co_finish"] = (
        (pos, clk, inv, cross, converged, singular),
        (used, n_nuis, too_few, has_clock, base, bcov, froot, bavail),
        check,
        r_lo,
        r_hi,
        cen.shape[0] == 1,
    )
    co = nav_k.cooperative_finish(*st["co_finish"])
    if cen.shape[0] == 1:
        co_pos, co_cov, co_status = co[6][0], co[7][0], co[8][0]
    else:
        co_pos, co_cov, co_status = co[0], co[1], co[3].copy()
    st["selection"] = (
        (sa[3], sa[0], sa[1], co_status, co_pos, co_cov),
        linked,
        (gate_on, gate2),
        (origin, rot),
        (pred_enu, prev_cov, dr_var),
    )
    sel = sim_k.select_navigation(*st["selection"])
    xy = np.ascontiguousarray(sel[6][:, :2])
    st["waypoints"] = (route, xy, next_wp.copy(), reach_m)
    sizes = {
        "flops": flop_count(used, ref, iters, vis, sa[5], cen.shape[0] == 1, n_sys),
        "sky": s,
        "received": vis.sum(axis=1),
        "used": used.sum(axis=(1, 2)),
        "used_sats": used.any(axis=1).sum(axis=1),
        "co_iter": iters,
    }
    return st, sizes


def flop_count(used, ref, iters, vis, sa_iters, shared, n_sys) -> dict[str, float]:
    """Floating-point operations of one epoch's navigation, counted from the loops of the
    structured solve (a multiply, add, divide or square root is one flop each).

    Cooperative, per centroid and Gauss-Newton iteration, with ``m_q`` rows of UAV q,
    ``R = sum m_q``, ``S_u`` satellites in use, ``P = 3 + n_sys`` unknowns: per row 225
    (geometry 12, the relative-error column 15, residual and weights 11, nuisance-clock
    removal 28, the rank-3 latent M3 18, T3 36, G3 15, the projected row 36, A^T P [A a]
    48, the satellite sums 6), per pair of rows of a UAV 9 (nuisance pair and Woodbury
    terms of sum_n P_n), per UAV 40 (the 3x3 inverse); the common errors ``3 S_u^2``
    (I + E^T P E) ``+ S_u^3`` (its Cholesky inverse) ``+ 2 P S_u^2 + 3 P S_u + 2 P^2 S_u``
    (G, the right side, the reduced normal matrix), the cross terms ``9 P R`` and the P x P
    update 450. Standalone, per receiver and iteration: 52 per received satellite and 450
    for the update. The finish: 200 per (centroid, UAV). ``iters`` per centroid,
    ``sa_iters`` the largest standalone count (the receivers iterate about as often).
    """
    p = 3 + n_sys
    co = 0.0
    n_b, n, _s = used.shape
    for b in range(n_b):
        m = used[b].sum(axis=1).astype(float)
        r = m.sum()
        s_u = used[b].any(axis=0).sum()
        per_it = (
            225 * r
            + 9 * (m * m).sum()
            + 40 * (m > 0).sum()
            + 3 * s_u**2
            + s_u**3
            + 2 * p * s_u**2
            + 3 * p * s_u
            + 2 * p * p * s_u
            + 9 * p * r
            + 450
        )
        co += per_it * iters[b]
    sa = float(sa_iters) * (52 * vis.sum() + 450 * vis.shape[0])
    finish = 200.0 * n_b * n
    return {"cooperative": co, "standalone": sa, "finish": finish}


@njit
def _co_setup(rel_b, var_b, avail_b, cen, vis, system, el, n_sys, ddt):
    """The cooperative set-up stage of ``cooperative_isotropic`` (baselines, masks)."""
    bavail, _base, _bcov, _froot = nav_k.isotropic_setup(rel_b, var_b, avail_b, cen)
    return nav_k.setup_masks(vis, bavail, cen, system, el, n_sys, ddt, -1)


STAGE_FUNCS = {
    "pseudoranges": gnss_k.pseudorange_model,
    "standalone": nav_k.standalone_solve,
    "co_setup": _co_setup,
    "co_gauss_newton": nav_k.cooperative_gauss_newton,
    "co_finish": nav_k.cooperative_finish,
    "selection": sim_k.select_navigation,
    "waypoints": sim_k.advance_waypoints,
}


# --------------------------------------------------------------------------------------------
# the kernels of another git revision
# --------------------------------------------------------------------------------------------


def load_revision(ref: str) -> Any:
    """``coopnav_env/sim/_kernels.py`` of git revision ``ref`` with the
    ``coopnav_env/gnss/_kernels.py`` and ``coopnav_env/nav/_kernels.py`` of that revision, as
    separate modules (the sim module's imports of the two rewritten to them, so that it calls
    the kernels of its own revision, whatever their arguments were there); returns the sim
    module (its ``epoch_navigation``)."""
    tmp = Path(tempfile.mkdtemp(prefix="bench_nav_"))
    tag = "".join(c if c.isalnum() else "_" for c in ref)
    names = {}
    for rel, key in (
        ("coopnav_env/gnss/_kernels.py", "gnss"),
        ("coopnav_env/nav/_kernels.py", "nav"),
        ("coopnav_env/sim/_kernels.py", "sim"),
    ):
        text = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{ref}:{rel}"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
        names[key] = f"_bench_nav_{tag}_{key}"
        if key == "sim":
            for sub in ("gnss", "nav"):
                text = text.replace(
                    f"from coopnav_env.{sub} import _kernels as _{sub}_kernels",
                    f"import {names[sub]} as _{sub}_kernels",
                )
        (tmp / f"{names[key]}.py").write_text(text)
    sys.path.insert(0, str(tmp))
    mods = {}
    for key in ("gnss", "nav", "sim"):
        spec = importlib.util.spec_from_file_location(names[key], tmp / f"{names[key]}.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[names[key]] = mod
        spec.loader.exec_module(mod)
        mods[key] = mod
    return mods["sim"]


def _flatten(out: Any) -> list[bytes]:
    """The bytes of every array (and the repr of every scalar) in a nested result."""
    if isinstance(out, tuple):
        return [b for o in out for b in _flatten(o)]
    if isinstance(out, np.ndarray):
        return [out.dtype.str.encode() + str(out.shape).encode() + out.tobytes()]
    return [repr(out).encode()]


# --------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--episodes", type=int, default=2, help="recorded episodes (default 2)")
    ap.add_argument("--max-steps", type=int, default=200, help="steps per episode (200)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    ap.add_argument(
        "--policy",
        choices=("waypoint", "random"),
        default="waypoint",
        help="who flies the recorded episodes: the waypoint heuristic (default) or uniformly "
        "random commands (the batched benchmark's)",
    )
    ap.add_argument("--repeats", type=int, default=20, help="calls per round and epoch (20)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds (best counts) (3)")
    ap.add_argument("--every", type=int, default=1, help="time every k-th recorded epoch")
    ap.add_argument("--no-split", action="store_true", help="time the total only")
    ap.add_argument(
        "--compare", metavar="REF", help="also time the kernels of git revision REF (A/B)"
    )
    opt = ap.parse_args(argv)
    for name in ("episodes", "max_steps", "repeats", "rounds", "every"):
        if getattr(opt, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(opt, name)}")

    t0 = time.perf_counter()
    epochs = record_epochs(opt.episodes, opt.max_steps, opt.seed, opt.policy)[:: opt.every]
    print(f"recorded {len(epochs)} epochs in {time.perf_counter() - t0:.1f} s")

    variants = {"this checkout": repeater(sim_k.epoch_navigation)}
    inputs = {"this checkout": epochs}
    if opt.compare:
        other = load_revision(opt.compare)
        variants[opt.compare] = repeater(other.epoch_navigation)
        # a revision before the records takes the same arguments one by one
        inputs[opt.compare] = (
            epochs if hasattr(other, "Geometry") else [positional(a) for a in epochs]
        )
        same = 0
        for a, b in zip(epochs, inputs[opt.compare], strict=True):
            if _flatten(sim_k.epoch_navigation(*a)) == _flatten(other.epoch_navigation(*b)):
                same += 1
        print(f"outputs identical bit for bit to {opt.compare}: {same} of {len(epochs)} epochs")
    t0 = time.perf_counter()
    for k, loop in variants.items():
        loop(1, inputs[k][0])  # compile
    print(f"compiled the timing loops in {time.perf_counter() - t0:.1f} s")

    best = {k: np.full(len(epochs), np.inf) for k in variants}
    for _ in range(opt.rounds):  # alternating rounds, epoch by epoch
        for i in range(len(epochs)):
            for k, loop in variants.items():
                best[k][i] = min(best[k][i], best_time(loop, inputs[k][i], opt.repeats))
    print("\nepoch_navigation, us per swarm-step (mean over epochs of the best round):")
    for k in variants:
        print(f"  {k:>16}: {1e6 * best[k].mean():8.1f}   (median {1e6 * np.median(best[k]):.1f})")
    if opt.compare:
        ratio = best[opt.compare].mean() / best["this checkout"].mean()
        print(f"  speed-up of this checkout over {opt.compare}: {ratio:.3f}x")

    if opt.no_split:
        return 0
    loops = {k: repeater(f) for k, f in STAGE_FUNCS.items()}
    stage_t = {k: np.zeros(len(epochs)) for k in STAGE_FUNCS}
    sizes = []
    for i, a in enumerate(epochs):
        st, sz = stage_inputs(a)
        sizes.append(sz)
        for k, loop in loops.items():
            t = np.inf
            for _ in range(opt.rounds):
                t = min(t, best_time(loop, st[k], opt.repeats))
            stage_t[k][i] = t
    total = sum(v.mean() for v in stage_t.values())
    print("\nsplit (each stage timed alone on the same inputs), us per swarm-step:")
    for k, v in stage_t.items():
        print(f"  {k:>16}: {1e6 * v.mean():8.1f}  ({100 * v.mean() / total:4.1f} %)")
    print(f"  {'sum of stages':>16}: {1e6 * total:8.1f}")
    co_it = np.concatenate([s["co_iter"] for s in sizes])
    sa_it = np.array([a[1] for a in (sim_k.epoch_navigation(*e)[:2] for e in epochs)])
    print("\nproblem sizes (mean over epochs):")
    print(f"  satellites in the sky S: {np.mean([s['sky'] for s in sizes]):.1f}")
    rec = np.concatenate([s["received"] for s in sizes])
    print(f"  received per UAV: {rec.mean():.1f} (min {rec.min()}, max {rec.max()})")
    used = np.concatenate([s["used"] for s in sizes])
    print(f"  used measurements per centroid: {used.mean():.1f}")
    used_s = np.concatenate([s["used_sats"] for s in sizes])
    print(f"  satellites used per centroid: {used_s.mean():.1f}")
    print(f"  centroids per epoch: {len(co_it) / len(sizes):.1f}")
    print(
        f"  Gauss-Newton iterations per centroid: mean {co_it.mean():.2f}, "
        f"histogram {np.bincount(co_it).tolist()}"
    )
    print(f"  standalone iterations (largest per epoch): mean {sa_it.mean():.2f}")
    gn_per_iter = stage_t["co_gauss_newton"].mean() / max(
        1.0, co_it.mean() * (len(co_it) / len(sizes))
    )
    print(f"  cooperative Gauss-Newton per centroid-iteration: {1e6 * gn_per_iter:.2f} us")
    fl = {k: np.mean([s["flops"][k] for s in sizes]) for k in sizes[0]["flops"]}
    total_fl = sum(fl.values())
    print("\nflops per swarm-step (counted from the loops; bench_nav.flop_count):")
    for k, v in fl.items():
        print(f"  {k:>16}: {v:9.0f}")
    print(f"  {'total':>16}: {total_fl:9.0f}")
    t_co = stage_t["co_gauss_newton"].mean()
    print(
        f"  cooperative Gauss-Newton: {fl['cooperative'] / (1e9 * t_co):.2f} flop/ns measured; "
        f"epoch_navigation: {total_fl / (1e9 * best['this checkout'].mean()):.2f} flop/ns"
    )
    print(
        f"  time at 1 flop/ns: {total_fl / 1e3:.1f} us; at 2.6 flop/ns (one scalar flop per "
        f"cycle at 2.6 GHz): {total_fl / 2.6e3:.1f} us"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
