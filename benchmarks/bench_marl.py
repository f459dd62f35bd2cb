"""Benchmark: MAPPO (TorchRL) throughput of a training configuration and its collection ceilings.

Builds the trainer of ``coopnav train --backend torchrl --config NAME`` (no warm start) in
this process and times, over ``--iterations`` iterations after a first untimed one:

* **train** -- agent-steps per second of an iteration, collection and PPO update together
  (what ``logs/progress.csv`` of a run reports as ``collect_s`` and ``update_s``);
* **collect-only** -- agent-steps per second of the collection alone (the actor's sampling,
  exploring starts, held decisions, rewards and critic inputs included): the ceiling of
  training with free updates;
* **env-only** -- agent-steps per second of the batched environment alone
  (``BatchedUrbanCanyonEnv.step_arrays`` with random actions in ``[-1, 1]``, automatic
  resets): the ceiling of collection with a free policy.

A configuration of family cities drawn from a pool (``city: family:NAME`` with ``city_pool``)
has the pool's cities built before the first iteration, as a long run has them after its
first few hundred episodes (a city is built once per process and seed); else a few
iterations would time mostly the building of new cities. One thread for torch (the packaged
``torch_threads``). Timings are noisy on a shared machine
(its load is printed). Usage: ``python benchmarks/bench_marl.py [--config mappo_route_scratch]
[--iterations 5]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coopnav_env.training.config import TrainConfig, load_config
from coopnav_env.training.torchrl_backend import MARLTrainer, settings_of


def build_city_pool(env_cfg) -> None:
    """Build every city of a family city pool (``city_pool`` cities of ``city=family:NAME``)
    now, as ``make_city`` would build them (nothing for other cities)."""
    from coopnav_env.sim.city_families import family_of_seed, seeded_family_city

    pool = getattr(env_cfg, "city_pool", None)
    if pool is None or env_cfg.city_seed is not None or not env_cfg.city.startswith("family:"):
        return
    origin = (env_cfg.lat_deg, env_cfg.lon_deg, env_cfg.alt_m)
    t0 = time.perf_counter()
    for seed in range(pool):
        seeded_family_city(family_of_seed(env_cfg.city, seed), seed, origin)
    print(f"built the {pool} cities of the city pool first ({time.perf_counter() - t0:.0f} s)")


def main() -> None:
    import torch

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="mappo_route_scratch", help="a packaged configuration")
    ap.add_argument("--iterations", type=int, default=5, help="timed iterations (>= 1)")
    args = ap.parse_args()
    if args.iterations < 1:
        raise SystemExit(f"--iterations must be >= 1, got {args.iterations}")
    data = load_config(args.config)
    data["out"] = os.devnull  # nothing is written
    cfg = TrainConfig.from_dict(data)
    torch.set_num_threads(cfg.torch_threads)
    settings, env_kwargs = settings_of(cfg)
    trainer = MARLTrainer(settings, env_kwargs, seed=cfg.seed)
    build_city_pool(trainer.venv.envs[0].config)
    trainer.update(trainer.collect())  # compiles, warms the caches and torch
    collect_s = update_s = 0.0
    steps0 = trainer.agent_steps
    for _ in range(args.iterations):
        t0 = time.perf_counter()
        data_td = trainer.collect()
        t1 = time.perf_counter()
        trainer.update(data_td)
        collect_s += t1 - t0
        update_s += time.perf_counter() - t1
    steps = trainer.agent_steps - steps0
    venv = trainer.venv
    k_, n_ = venv.n_copies, venv.n_agents
    n_env = steps // (k_ * n_)  # as many swarm steps as the timed collections made
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (n_env, k_, n_, 3))
    t0 = time.perf_counter()
    for a in actions:
        venv.step_arrays(a)
    env_s = time.perf_counter() - t0
    print(
        f"{args.config}: {k_} swarms of {n_} UAVs, {steps // args.iterations} agent-steps per "
        f"iteration, {args.iterations} timed iterations; load average {os.getloadavg()[0]:.2f} "
        f"on {os.cpu_count()} CPUs"
    )
    print(f"  train (collect + update): {steps / (collect_s + update_s):9,.0f} agent-steps/s")
    print(f"  collect-only:             {steps / collect_s:9,.0f} agent-steps/s")
    print(f"  env-only (random actions):{n_env * k_ * n_ / env_s:9,.0f} agent-steps/s")
    print(
        f"  per iteration: collect {collect_s / args.iterations:.3f} s, "
        f"update {update_s / args.iterations:.3f} s"
    )


if __name__ == "__main__":
    main()
