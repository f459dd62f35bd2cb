"""Train Stable-Baselines3 PPO from scratch on the Gymnasium view of the swarm.

One policy sees every UAV's observation and commands the whole swarm
(``coopnav/UrbanCanyonSwarm-v1``). SB3's own vector environment reports ``max_steps``
truncation to PPO as a truncation, so value bootstrapping is right. Torch runs with one thread
per process: on a 2-core machine its default thread pool made the same 2,560 PPO steps take
50 s instead of 3.7 s. Run it (the default 10,240 steps took 13 s on a 2-core VM)::

    python examples/sb3_ppo.py --timesteps 10000 --save runs/sb3_swarm.zip

(``coopnav train`` trains the parameter-shared, one-policy-per-UAV version instead.)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import gymnasium
import numpy as np
import torch
from stable_baselines3 import PPO

import coopnav_env  # registers coopnav/UrbanCanyonSwarm-v1 (coopnav_env.GYM_ENV_ID)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--timesteps", type=int, default=10_000, help="training steps (default: %(default)s)"
    )
    parser.add_argument(
        "--n-steps", type=int, default=512, help="PPO rollout length (default: %(default)s)"
    )
    parser.add_argument(
        "--max-steps", type=int, default=200, help="steps per episode (default: %(default)s)"
    )
    parser.add_argument("--n-uavs", type=int, default=3, help="UAVs (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default: %(default)s)")
    parser.add_argument(
        "--save", type=Path, default=None, help="write the model to this .zip (default: no file)"
    )
    args = parser.parse_args(argv)

    torch.set_num_threads(1)  # one thread per process: much faster on small machines
    env = gymnasium.make(coopnav_env.GYM_ENV_ID, n_uavs=args.n_uavs, max_steps=args.max_steps)
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=args.n_steps,
        batch_size=64,
        seed=args.seed,
        device="cpu",
        verbose=0,
    )
    model.learn(total_timesteps=args.timesteps)
    print(f"trained {model.num_timesteps} steps")

    # one evaluation episode, deterministic actions, a seed training did not use
    obs, _ = env.reset(seed=1_000_000 + args.seed)
    total, steps, done = 0.0, 0, False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total += reward
        steps += 1
        done = terminated or truncated
    # the reward is the UAVs' mean (reward="mean"): the episode's return is its score
    print(f"evaluation episode: {steps} steps, score {total:.3f}")
    assert np.isfinite(total)

    if args.save is not None:  # write to a temporary name, then rename into place
        args.save.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.save.with_name(f".{args.save.stem}.tmp.zip")
        model.save(tmp)
        os.replace(tmp, args.save)
        print(f"saved {args.save}")
    env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
