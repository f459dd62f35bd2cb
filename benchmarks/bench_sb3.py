"""SB3 PPO throughput on ``urban_canyon_v1`` beside its collection-only ceilings.

For each number of swarm copies ``K`` (``--n-envs``) this times, in alternating rounds in
one process:

* ``env``: :class:`coopnav_env.training.vec_env.BatchedVecEnv` stepped with random actions
  (the vector env alone, infos included);
* ``collect``: SB3's ``collect_rollouts`` (the env plus the policy's forward pass and the
  rollout buffer), no update;
* ``learn``: ``PPO.learn`` for whole rollouts (collection plus the update), with the
  packaged PPO settings and, with ``--batch-size``, a larger minibatch; with
  ``--torch-threads``, once per number of PyTorch threads (the gradient updates use them;
  the vector env's compiled kernels run on every core whatever this is).

Settings are those of ``coopnav train --backend sb3`` (urban_canyon_v1 with the packaged
``env`` overrides, no warm start). Prints agent-steps per second, medians over the rounds,
and each ``learn`` row's ratio to the first one (the first ``K``, minibatch and thread count
given: with the defaults, the packaged settings).

Usage::

    python benchmarks/bench_sb3.py --n-envs 2 16 --batch-size 256 2048 --torch-threads 1 2
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
    p.add_argument("--n-envs", type=int, nargs="+", default=[2, 16], help="swarm copies K")
    p.add_argument("--batch-size", type=int, nargs="+", default=[256], help="PPO minibatches")
    p.add_argument(
        "--torch-threads",
        type=int,
        nargs="+",
        default=[1],
        help="PyTorch threads of the learn timings (coopnav train's torch_threads)",
    )
    p.add_argument("--rounds", type=int, default=2, help="alternating rounds (medians count)")
    p.add_argument("--rollouts", type=int, default=2, help="PPO rollouts per learn timing")
    a = p.parse_args()
    for name in ("n_envs", "batch_size", "torch_threads", "rounds", "rollouts"):
        bad = [v for v in np.atleast_1d(getattr(a, name)) if v < 1]
        if bad:
            p.error(f"--{name.replace('_', '-')} must be at least 1, got {bad[0]}")
    rows: dict[str, list[float]] = {}
    for _ in range(a.rounds):
        for k in a.n_envs:
            torch.set_num_threads(1)
            rows.setdefault(f"K={k} env", []).append(env_rate(k, 200))
            for b in a.batch_size:
                torch.set_num_threads(1)
                rows.setdefault(f"K={k} collect batch={b}", []).append(collect_rate(k, b))
                for t in a.torch_threads:
                    torch.set_num_threads(t)
                    name = f"K={k} learn batch={b} threads={t}"
                    rows.setdefault(name, []).append(learn_rate(k, b, a.rollouts))
    first_learn = next(np.median(v) for n, v in rows.items() if " learn " in n)
    for name, v in rows.items():
        ratio = f"{np.median(v) / first_learn:5.2f}x" if " learn " in name else "      "
        print(
            f"{name:38s} {np.median(v):9.0f} agent-steps/s {ratio} "
            f"(rounds: {[round(x) for x in v]})"
        )


if __name__ == "__main__":
    main()
