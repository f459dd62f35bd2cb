"""SB3 PPO throughput on ``urban_canyon_v1`` beside its collection-only ceilings.

For each number of swarm copies ``K`` (``--n-envs``) this times, in alternating rounds in
one process:

* ``env``: :class:`coopnav_env.training.vec_env.BatchedVecEnv` stepped with random actions
  (the vector env alone, infos included);
* ``collect``: SB3's ``collect_rollouts`` (the env plus the policy's forward pass and the
  rollout buffer), no update;
* ``learn``: ``PPO.learn`` for whole rollouts (collection plus the update), with the
  packaged PPO settings and, with ``--batch-size``, a larger minibatch.

Settings are those of ``coopnav train --backend sb3`` (urban_canyon_v1 with the packaged
``env`` overrides, no warm start). Prints agent-steps per second.

Usage::

    python benchmarks/bench_sb3.py --n-envs 2 16 --batch-size 256 2048
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _settings():
    from coopnav_env.training.config import load_config

    return load_config(None, "urban_canyon_v1")


def _venv(n_envs: int):
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from coopnav_env.training.envs import make_env_fn
    from coopnav_env.training.vec_env import make_vec_env

    cfg = _settings()
    venv = make_vec_env(make_env_fn("urban_canyon_v1", cfg["env"]), n_envs, 1, kind="batched")
    return venv, VecNormalize(VecMonitor(venv), norm_obs=False, norm_reward=True, gamma=1.0)


def env_rate(n_envs: int, steps: int) -> float:
    venv, _ = _venv(n_envs)
    venv.seed(0)
    venv.reset()
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, (steps, venv.num_envs, 3)).astype(np.float32)
    t = time.perf_counter()
    for a in acts:
        venv.step(a)
    return steps * venv.num_envs / (time.perf_counter() - t)


def _model(n_envs: int, batch_size: int):
    from stable_baselines3 import PPO

    cfg = _settings()
    kw = dict(cfg["ppo"])
    policy = kw.pop("policy")
    kw["batch_size"] = batch_size
    _, learn_env = _venv(n_envs)
    return PPO(policy, learn_env, seed=0, device="cpu", **kw)


def collect_rate(n_envs: int, batch_size: int) -> float:
    from stable_baselines3.common.callbacks import CallbackList

    model = _model(n_envs, batch_size)
    model._setup_learn(model.n_steps * model.env.num_envs, CallbackList([]))
    cb = CallbackList([])
    cb.init_callback(model)
    t = time.perf_counter()
    model.collect_rollouts(model.env, cb, model.rollout_buffer, model.n_steps)
    return model.n_steps * model.env.num_envs / (time.perf_counter() - t)


def learn_rate(n_envs: int, batch_size: int, rollouts: int) -> float:
    model = _model(n_envs, batch_size)
    n = rollouts * model.n_steps * model.env.num_envs
    t = time.perf_counter()
    model.learn(n)
    return n / (time.perf_counter() - t)


def main() -> None:
    import torch

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n-envs", type=int, nargs="+", default=[2, 16])
    p.add_argument("--batch-size", type=int, nargs="+", default=[256])
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--rollouts", type=int, default=2, help="PPO rollouts per learn timing")
    a = p.parse_args()
    torch.set_num_threads(1)
    rows: dict[str, list[float]] = {}
    for _ in range(a.rounds):
        for k in a.n_envs:
            rows.setdefault(f"K={k} env", []).append(env_rate(k, 200))
            for b in a.batch_size:
                rows.setdefault(f"K={k} collect", []).append(collect_rate(k, b))
                rows.setdefault(f"K={k} learn batch={b}", []).append(learn_rate(k, b, a.rollouts))
    for name, v in rows.items():
        print(f"{name:28s} {np.median(v):9.0f} agent-steps/s  (rounds: {[round(x) for x in v]})")


if __name__ == "__main__":
    main()
