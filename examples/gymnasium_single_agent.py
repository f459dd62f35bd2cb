"""One Gymnasium agent commands the whole swarm: ``gymnasium.make("coopnav/UrbanCanyonSwarm-v1")``.

``import coopnav_env`` registers the id. The observation stacks every UAV's observation
(``obs.reshape(n_uavs, obs_dim)``: one row per UAV, ``uav_0`` first), the action every UAV's
velocity command (``action.reshape(n_uavs, 3)``), the reward is the swarm's mean (or, with
``reward="sum"``, summed) reward. Keywords go to the environment's configuration. Run it::

    python examples/gymnasium_single_agent.py --episodes 2
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np

import coopnav_env  # registers coopnav/UrbanCanyonSwarm-v1 (coopnav_env.GYM_ENV_ID)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=2, help="episodes (default: %(default)s)")
    parser.add_argument(
        "--max-steps", type=int, default=200, help="steps per episode (default: %(default)s)"
    )
    parser.add_argument("--n-uavs", type=int, default=3, help="UAVs (default: %(default)s)")
    parser.add_argument(
        "--seed", type=int, default=0, help="first reset seed (default: %(default)s)"
    )
    args = parser.parse_args(argv)

    env = gymnasium.make(
        coopnav_env.GYM_ENV_ID, n_uavs=args.n_uavs, max_steps=args.max_steps, reward="sum"
    )
    n = env.unwrapped.config.n_uavs
    layout = env.unwrapped.layout  # the layout of one UAV's row
    print(f"observation {env.observation_space.shape}, action {env.action_space.shape}")

    for episode in range(args.episodes):
        obs, _ = env.reset(seed=args.seed + episode)
        total, steps, done = 0.0, 0, False
        while not done:
            rows = obs.reshape(n, layout.dim)
            to_wp = layout["next_waypoint"].decode(rows)  # (n, 2) [m]
            speed = np.linalg.norm(to_wp, axis=1, keepdims=True)
            cmd = np.zeros((n, 3), dtype=np.float32)
            cmd[:, :2] = 0.6 * to_wp / np.maximum(speed, 1e-6)  # 60 % of the top speed
            obs, reward, terminated, truncated, _ = env.step(cmd.reshape(-1))
            total += reward
            steps += 1
            done = terminated or truncated
        how = "terminated" if terminated else "truncated"
        print(f"episode {episode}: {steps} steps ({how}), swarm return {total:.1f}")
    env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
