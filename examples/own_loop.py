"""Fly ``urban_canyon_v1`` with your own loop over the PettingZoo parallel API.

A hand-written controller steers every UAV toward its next route waypoint at a chosen altitude.
It reads the observation by name (``coopnav_env.envs.obs_layout``), not by index, so it keeps
working for any number of neighbour slots or sky azimuths. Run it::

    python examples/own_loop.py --episodes 3
"""

from __future__ import annotations

import argparse

import numpy as np

from coopnav_env import urban_canyon_v1
from coopnav_env.envs import obs_layout


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=3, help="episodes (default: %(default)s)")
    parser.add_argument(
        "--max-steps", type=int, default=200, help="steps per episode (default: %(default)s)"
    )
    parser.add_argument(
        "--altitude", type=float, default=25.0, help="altitude to fly at [m] (default: %(default)s)"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="first reset seed (default: %(default)s)"
    )
    args = parser.parse_args(argv)

    # max_cycles is the conventional PettingZoo name of max_steps; both are accepted
    env = urban_canyon_v1.parallel_env(n_uavs=5, max_cycles=args.max_steps)
    layout = obs_layout(env.config)  # what each entry of an observation means
    waypoint, altitude = layout["next_waypoint"], layout["altitude"]
    v_max = env.config.kinematics.max_speed_mps

    for episode in range(args.episodes):
        obs, infos = env.reset(seed=args.seed + episode)
        score, errors, steps = 0.0, [], 0
        while env.agents:  # the episode ends for every UAV at once
            actions = {}
            for agent in env.agents:
                to_wp = waypoint.decode(obs[agent])  # [m] East, North, from the estimate
                climb = args.altitude - altitude.decode(obs[agent])[0]  # [m]
                horizontal = to_wp * min(1.0, 7.0 / max(float(np.linalg.norm(to_wp)), 1e-6))
                velocity = np.array([*horizontal, 0.6 * climb])  # [m/s]
                actions[agent] = np.clip(velocity / v_max, -1.0, 1.0).astype(np.float32)
            obs, rewards, terminations, _, infos = env.step(actions)
            score += sum(rewards.values()) / len(rewards)  # the return, mean over UAVs
            errors += [info["nav_error_m"] for info in infos.values()]
            steps += 1
        how = "terminated: goal or crash" if any(terminations.values()) else "truncated"
        print(
            f"episode {episode}: {steps} steps ({how}), score {score:.3f}, "
            f"mean 3-D navigation error {np.mean(errors):.2f} m"
        )
    env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
