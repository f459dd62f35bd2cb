"""Benchmark: RLlib training throughput of ``urban_canyon_v1`` against the number of env runners.

For each ``--runners`` count, one short ``coopnav train --backend rllib`` run (a fresh local
Ray in its own process, ``--iterations`` PPO iterations with the packaged hyperparameters
unless overridden with ``--set``) is timed. Reported per run:

* **env-steps/s** -- swarm steps sampled per second of training, over the iterations after
  the first (the first one warms up the env runners and torch); one iteration samples
  ``train_batch_size_per_learner`` env-steps and then runs the PPO update in the driver;
* **agent-steps/s** -- the same times the UAVs per swarm;
* **s / iteration** -- median wall time of a timed iteration (sampling, then the update);
* **setup s** -- Ray start-up and algorithm construction (env runner actors included).

0 runners means the driver samples itself. The runs are sequential; on a shared or small
machine the figures are noisy (the machine and its load are printed with the table).
Usage: ``python benchmarks/bench_rllib.py [--runners 0 1 2] [--iterations 3]
[--set rllib.ppo.train_batch_size_per_learner=256] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coopnav_env.training.config import load_config


def _one_run(runners: int, iterations: int, overrides: list[str], out: Path) -> dict:
    cfg = load_config()
    n_uavs = int((cfg.get("env") or {}).get("n_uavs", 5))
    batch = int(cfg["rllib"]["ppo"]["train_batch_size_per_learner"])
    for item in overrides:
        key, _, value = item.partition("=")
        if key == "rllib.ppo.train_batch_size_per_learner":
            batch = int(value)
        if key in ("env.n_uavs", "n_uavs"):
            n_uavs = int(value)
    # stop after `iterations` iterations: timesteps are agent-steps
    timesteps = iterations * batch * n_uavs
    cmd = [
        sys.executable, "-m", "coopnav_env.training.cli", "train", "--backend", "rllib",
        "--out", str(out), "--num-env-runners", str(runners), "--timesteps", str(timesteps),
        "--checkpoint-freq", "0", "--no-progress",
    ]  # fmt: skip
    for item in overrides:
        cmd += ["--set", item]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stderr[-3000:]}")
    info = json.loads((out / "run.json").read_text())
    with (out / "logs" / "progress.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    timed = rows[1:]  # the first iteration warms up
    env_steps = float(rows[-1]["env_steps"]) - float(rows[0]["env_steps"])
    wall = sum(float(r["time_this_iter_s"]) for r in timed)
    return {
        "runners": runners,
        "iterations": len(rows),
        "batch_env_steps": batch,
        "n_uavs": n_uavs,
        "env_steps_per_s": env_steps / wall if wall > 0 else float("nan"),
        "agent_steps_per_s": env_steps * n_uavs / wall if wall > 0 else float("nan"),
        "setup_s": float(info["setup_s"]),
        "iteration_s": statistics.median(float(r["time_this_iter_s"]) for r in timed),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--runners", type=int, nargs="+", default=[0, 1, 2], help="env runners")
    ap.add_argument("--iterations", type=int, default=3, help="PPO iterations per run (>= 2)")
    ap.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="training setting for every run (as in coopnav train --set)",
    )  # fmt: skip
    ap.add_argument("--keep", default=None, help="keep the run directories here")
    args = ap.parse_args(argv)
    if args.iterations < 2:
        ap.error("--iterations must be >= 2 (the first iteration is not timed)")
    if any(r < 0 for r in args.runners):
        ap.error("--runners must be >= 0")
    base = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench-rllib-"))
    results = []
    for r in args.runners:
        res = _one_run(r, args.iterations, args.overrides, base / f"runners_{r}")
        results.append(res)
        print(f"  {r} env runners: {res['env_steps_per_s']:.0f} env-steps/s", file=sys.stderr)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    first = results[0]
    env_id = load_config().get("env_id", "urban_canyon_v1")
    print(
        f"{env_id}, {first['n_uavs']} UAVs; train batch {first['batch_env_steps']} "
        f"env-steps (= {first['batch_env_steps'] * first['n_uavs']} agent-steps) per iteration; "
        f"{args.iterations} iterations, the first not timed"
    )
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"load average {load:.1f} at the end"
    )
    print()
    print("| env runners | env-steps/s | agent-steps/s | s / iteration | setup s |")
    print("|---:|---:|---:|---:|---:|")
    for res in results:
        print(
            f"| {res['runners']} | {res['env_steps_per_s']:.0f} | "
            f"{res['agent_steps_per_s']:.0f} | {res['iteration_s']:.1f} | {res['setup_s']:.0f} |"
        )
    if not args.keep:
        import shutil

        shutil.rmtree(base, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
