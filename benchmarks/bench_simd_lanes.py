"""Benchmark: does numba vectorise the centroid solver's sums with several swarms in the lanes?

The cooperative Gauss-Newton kernel (``coopnav_env.nav._kernels.cooperative_gauss_newton``)
runs at about one scalar flop per cycle. Putting L problems (L swarms' centroid problems) in
the lanes of one vector, the same scalar operations in each lane, would keep every swarm's
bits and could divide the time by up to L, if the compiler emits packed arithmetic for it.
This probe measures that on the kernel's largest sums, written both ways in numba:

* **scalar**: one problem after another, as the kernel does: ``A^T P [A a]`` (a rank-1
  update per measurement row, P = 5 unknowns) and the Woodbury latent's ``M3`` and ``T3``
  sums (3 x 3 and 3 x 6 per row);
* **lanes**: the same sums with ``--lanes`` problems in the innermost axis of every array,
  the lane loop innermost.

It checks that both give the same numbers bit for bit, times them in alternating rounds
(the best round of each counts, as in ``bench_env.py``) on ``--problems`` problems of
``--rows`` rows (small enough to stay in cache), and counts the packed (``ymm``/``zmm``) and
scalar (``sd``) multiplies in the machine code numba emitted for each.

Usage: ``python benchmarks/bench_simd_lanes.py [--problems 64] [--rows 32] [--lanes 4]
[--rounds 5]``.
"""

from __future__ import annotations

import argparse
import re
import time

import numpy as np
from numba import njit

P = 5  # unknowns: 3 position, 2 clocks (GPS + BeiDou)
NX = 3 + P + 1  # a row's columns: [lam (3) | A (P) | a]


@njit(cache=False)
def scalar_sums(x, p0x, m3, t3, atpx):
    """The sums of every problem ``b`` over its rows, one problem after another."""
    n_prob, m = x.shape[0], x.shape[1]
    for b in range(n_prob):
        for i1 in range(3):
            for i2 in range(3):
                m3[b, i1, i2] = 1.0 if i1 == i2 else 0.0
            for j in range(P + 1):
                t3[b, i1, j] = 0.0
        for p in range(P):
            for j in range(P + 1):
                atpx[b, p, j] = 0.0
        for i in range(m):
            for i1 in range(3):
                xi = x[b, i, i1]
                pi = p0x[b, i, i1]
                for i2 in range(3):
                    m3[b, i1, i2] += xi * p0x[b, i, i2]
                for j in range(P + 1):
                    t3[b, i1, j] += pi * x[b, i, 3 + j]
            for p in range(P):
                ap = x[b, i, 3 + p]
                for j in range(P + 1):
                    atpx[b, p, j] += ap * p0x[b, i, 3 + j]


@njit(cache=False)
def lane_sums(x, p0x, m3, t3, atpx):
    """The same sums, the problems of group ``g`` in the last axis (``(G, ..., L)``)."""
    n_grp, m, n_lane = x.shape[0], x.shape[1], x.shape[3]
    for g in range(n_grp):
        for i1 in range(3):
            for i2 in range(3):
                v = 1.0 if i1 == i2 else 0.0
                for lane in range(n_lane):
                    m3[g, i1, i2, lane] = v
            for j in range(P + 1):
                for lane in range(n_lane):
                    t3[g, i1, j, lane] = 0.0
        for p in range(P):
            for j in range(P + 1):
                for lane in range(n_lane):
                    atpx[g, p, j, lane] = 0.0
        for i in range(m):
            for i1 in range(3):
                for i2 in range(3):
                    for lane in range(n_lane):
                        m3[g, i1, i2, lane] += x[g, i, i1, lane] * p0x[g, i, i2, lane]
                for j in range(P + 1):
                    for lane in range(n_lane):
                        t3[g, i1, j, lane] += p0x[g, i, i1, lane] * x[g, i, 3 + j, lane]
            for p in range(P):
                for j in range(P + 1):
                    for lane in range(n_lane):
                        atpx[g, p, j, lane] += x[g, i, 3 + p, lane] * p0x[g, i, 3 + j, lane]


def to_lanes(a: np.ndarray, n_lane: int) -> np.ndarray:
    """``(B, ...)`` -> ``(B / L, ..., L)``: problem ``g * L + l`` in lane ``l`` of group ``g``."""
    g = a.shape[0] // n_lane
    moved = np.moveaxis(a.reshape(g, n_lane, *a.shape[1:]), 1, -1)
    return np.ascontiguousarray(moved)


def multiplies(fn) -> dict[str, int]:
    """Packed and scalar double multiplies (FMA included) in ``fn``'s machine code."""
    asm = fn.inspect_asm(fn.signatures[0])
    mul = re.findall(r"\bv?(?:mul|fmadd\d*|fnmadd\d*)(pd|sd)\s+[^\n]*", asm)
    return {"packed": sum(k == "pd" for k in mul), "scalar": sum(k == "sd" for k in mul)}


def round_time(fn, args, calls: int) -> float:
    """Seconds per call of ``fn(*args)`` over ``calls`` calls."""
    t0 = time.perf_counter()
    for _ in range(calls):
        fn(*args)
    return (time.perf_counter() - t0) / calls


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--problems", type=int, default=64, help="problems per call (64)")
    ap.add_argument("--rows", type=int, default=32, help="measurement rows per problem (32)")
    ap.add_argument("--lanes", type=int, default=4, help="problems per lane group (4)")
    ap.add_argument("--rounds", type=int, default=5, help="alternating timing rounds (5)")
    ap.add_argument("--calls", type=int, default=2000, help="calls per round (2000)")
    args = ap.parse_args(argv)
    for name in ("problems", "rows", "lanes", "rounds", "calls"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    if args.problems % args.lanes:
        ap.error(f"--problems ({args.problems}) must be a multiple of --lanes ({args.lanes})")

    rng = np.random.default_rng(0)
    b, m, n_lane = args.problems, args.rows, args.lanes
    x, p0x = rng.standard_normal((b, m, NX)), rng.standard_normal((b, m, NX))
    s_out = (np.empty((b, 3, 3)), np.empty((b, 3, P + 1)), np.empty((b, P, P + 1)))
    l_in = (to_lanes(x, n_lane), to_lanes(p0x, n_lane))
    l_out = tuple(to_lanes(a, n_lane) for a in s_out)
    scalar_sums(x, p0x, *s_out)
    lane_sums(*l_in, *l_out)
    same = all(np.array_equal(to_lanes(s, n_lane), lo) for s, lo in zip(s_out, l_out, strict=True))
    best = {"scalar": np.inf, "lanes": np.inf}
    for _ in range(args.rounds):
        best["scalar"] = min(best["scalar"], round_time(scalar_sums, (x, p0x, *s_out), args.calls))
        best["lanes"] = min(best["lanes"], round_time(lane_sums, (*l_in, *l_out), args.calls))
    flops = 2 * m * (9 + 3 * (P + 1) + P * (P + 1))
    print(f"{b} problems of {m} rows, {n_lane} per lane group; identical sums: {same}")
    for name, fn in (("scalar", scalar_sums), ("lanes", lane_sums)):
        ns = best[name] / b * 1e9
        mul = multiplies(fn)
        print(
            f"  {name:>6}: {ns:7.0f} ns per problem, {flops / ns:4.1f} flop/ns; "
            f"multiplies in its code: {mul['packed']} packed, {mul['scalar']} scalar"
        )
    print(f"  lanes / scalar speed: {best['scalar'] / best['lanes']:.2f}x")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
