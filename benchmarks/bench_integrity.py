"""Benchmark: the cost of integrity monitoring (RAIM / FDE) per environment step.

What it measures, all in one process (so that the machine's load affects every variant alike;
the ratio is the figure to compare across machines): parallel-env steps per second of
``urban_canyon_v1`` at N UAVs (default 5) with uniformly random actions (resetting when an
episode ends; bench_env's ``RandomStepper``), for

* ``off``: the defaults (no integrity monitoring): the reference;
* ``fde``: ``integrity="fde"`` with no fault present (``nlos_probability=0``, the defaults'
  reception): the residual test, the protection levels and the identification quantities of
  every standalone and cooperative fix, no exclusion (a false alarm, p_fa = 1e-3 per test,
  excludes now and then);
* ``raim``: ``integrity="raim"`` (the same test without exclusion);
* ``fde+map``: ``integrity="fde"`` and 3D-mapping-aided NLOS exclusion
  (``nlos_exclusion="map"``: the city model's line-of-sight prediction at seven candidate
  positions per UAV) with no fault present: the cost of the ``urban_nlos_3dma`` defences
  without faults;
* ``fde+nlos``: the ``urban_nlos`` preset (about 40 % of the pseudoranges NLOS in the grid
  city, FDE excluding them): the cost with faults, for information;
* ``3dma+nlos``: the ``urban_nlos_3dma`` preset (the same reception, map exclusion and FDE),
  for information.

The variants run in alternating rounds of ``--steps`` steps each; the best round of each
counts, and the ratio ``step time / step time off`` is printed (the target for ``fde`` without
faults is at most 1.30; ``fde+map`` is measured against the same reference). Two clocks: the
process CPU time (``time.process_time``: what the step costs this process, robust when other
processes load the machine) and the wall clock. Every variant steps the same seeded episodes
(the truth does not depend on the estimates, so the geometry is the same).

Usage::

    python benchmarks/bench_integrity.py                 # about 1 minute on 2 cores
    python benchmarks/bench_integrity.py --n-uavs 5 10 --steps 300 --rounds 4 --json out.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_env import RandomStepper

from coopnav_env import urban_canyon_v1

VARIANTS = ("off", "fde", "raim", "fde+map", "fde+nlos", "3dma+nlos")


def make_env(variant: str, n: int):
    """The environment of one variant at ``n`` UAVs."""
    if variant == "off":
        return urban_canyon_v1.parallel_env(n_uavs=n)
    if variant == "fde":
        return urban_canyon_v1.parallel_env(n_uavs=n, integrity="fde")
    if variant == "raim":
        return urban_canyon_v1.parallel_env(n_uavs=n, integrity="raim")
    if variant == "fde+map":
        return urban_canyon_v1.parallel_env(n_uavs=n, integrity="fde", nlos_exclusion="map")
    if variant == "fde+nlos":
        return urban_canyon_v1.parallel_env(preset="urban_nlos", n_uavs=n)
    if variant == "3dma+nlos":
        return urban_canyon_v1.parallel_env(preset="urban_nlos_3dma", n_uavs=n)
    raise ValueError(f"unknown variant {variant!r}; variants are {VARIANTS}")


def measure(n: int, steps: int, rounds: int, variants: tuple[str, ...]) -> dict:
    """Best CPU and wall time per step of each variant over alternating rounds of ``steps``
    steps, and each one's ratio to ``off``."""
    steppers = {v: RandomStepper(make_env(v, n), seed=0) for v in variants}
    for st in steppers.values():  # compile every kernel before timing
        st.run(50)
    cpu = dict.fromkeys(variants, math.inf)
    wall = dict.fromkeys(variants, math.inf)
    for _ in range(rounds):
        for v, st in steppers.items():
            c0, w0 = time.process_time(), time.perf_counter()
            st.run(steps)
            cpu[v] = min(cpu[v], (time.process_time() - c0) / steps)
            wall[v] = min(wall[v], (time.perf_counter() - w0) / steps)
    return {
        v: {
            "cpu_ms_per_step": 1e3 * cpu[v],
            "wall_ms_per_step": 1e3 * wall[v],
            "cpu_ratio_to_off": cpu[v] / cpu["off"],
            "wall_ratio_to_off": wall[v] / wall["off"],
        }
        for v in variants
    }


def write_json(path: str, data: dict) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".bench_integrity.", suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(data, f, indent=2)
    os.replace(tmp, path)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--n-uavs", type=int, nargs="+", default=[5], help="swarm sizes to measure (default 5)"
    )
    ap.add_argument("--steps", type=int, default=500, help="steps per round (500)")
    ap.add_argument("--rounds", type=int, default=8, help="alternating rounds (8)")
    ap.add_argument(
        "--variants",
        nargs="+",
        default=list(VARIANTS),
        choices=VARIANTS,
        help="variants to measure besides 'off' (default all)",
    )
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    if any(n < 1 for n in args.n_uavs):
        ap.error("--n-uavs must be >= 1")
    if args.steps < 1 or args.rounds < 1:
        ap.error("--steps and --rounds must be >= 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    variants = tuple(dict.fromkeys(["off", *args.variants]))
    out: dict = {"steps": args.steps, "rounds": args.rounds, "results": {}}
    print("integrity monitoring: step cost of urban_canyon_v1 (best of alternating rounds)")
    head = f"{'N':>4} | {'variant':>9} | {'CPU ms/step':>11} {'ratio':>6}"
    print(head + f" | {'wall ms/step':>12} {'ratio':>6}")
    for n in args.n_uavs:
        res = measure(n, args.steps, args.rounds, variants)
        out["results"][str(n)] = res
        for v, r in res.items():
            line = f"{n:>4} | {v:>9} | {r['cpu_ms_per_step']:11.3f} {r['cpu_ratio_to_off']:5.2f}x"
            print(line + f" | {r['wall_ms_per_step']:12.3f} {r['wall_ratio_to_off']:5.2f}x")
    if args.json:
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
