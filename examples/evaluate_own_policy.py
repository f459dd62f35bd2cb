"""Evaluate your own policy object next to the built-in heuristics.

A policy is any class with the ``coopnav_env.agents.base.Policy`` protocol: a ``name``,
``reset(seed)`` and ``act(observations) -> actions`` over the PettingZoo dicts of the UAVs
still flying. ``coopnav_env.agents.register_policy`` gives it a name, and
``coopnav_env.training.evaluate.evaluate`` flies it on the same held-out episodes as
``column`` (same cities, satellites and noise), with the same statistics as ``coopnav
evaluate``. Run it::

    python examples/evaluate_own_policy.py --episodes 4 --out runs/own_eval
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from typing import Any

import numpy as np

from coopnav_env.agents import register_policy
from coopnav_env.envs import obs_layout
from coopnav_env.training.evaluate import evaluate


class WallShyWaypointPolicy:
    """Each UAV flies to its next route waypoint and is pushed away from walls closer than
    ``keep_m``, from its own observation only (the waypoint vector, the altitude and the
    wall distances around it, read by name)."""

    name = "wall_shy"

    def __init__(self, env: Any, altitude_m: float = 25.0, keep_m: float = 6.0):
        cfg = env.unwrapped.config
        self.layout = obs_layout(cfg)
        self.altitude_m, self.keep_m = float(altitude_m), float(keep_m)
        self.v_max = cfg.kinematics.max_speed_mps
        a = cfg.obs_sky_azimuths
        az = np.radians(np.arange(a) * 360.0 / a)  # clockwise from North
        self.directions = np.stack([np.sin(az), np.cos(az)], axis=1)  # (A, 2) East, North

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: the policy has no state."""

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Velocity commands, float32 in [-1, 1], one per UAV of ``observations``."""
        actions = {}
        for agent, obs in observations.items():
            to_wp = self.layout["next_waypoint"].decode(obs)  # [m]
            walls = self.layout["wall_distance"].decode(obs)  # [m] per azimuth
            push = np.clip(self.keep_m - walls, 0.0, None) @ self.directions  # away: minus
            horizontal = to_wp * min(1.0, 6.0 / max(float(np.linalg.norm(to_wp)), 1e-6))
            climb = self.altitude_m - self.layout["altitude"].decode(obs)[0]
            velocity = np.array([*(horizontal - push), 0.6 * climb])
            actions[agent] = np.clip(velocity / self.v_max, -1.0, 1.0).astype(np.float32)
        return actions


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=4, help="episodes (default: %(default)s)")
    parser.add_argument(
        "--max-steps", type=int, default=200, help="steps per episode (default: %(default)s)"
    )
    parser.add_argument(
        "--out", default=None, help="folder for the report files and plots (default: none)"
    )
    args = parser.parse_args(argv)

    register_policy("wall_shy", WallShyWaypointPolicy)
    # held-out reset seeds, as `coopnav evaluate` uses them (training stays below 1,000,000)
    seeds = [1_000_000 + i for i in range(args.episodes)]
    report = evaluate(
        ["column", "wall_shy", "wall_shy@altitude_m=15"],
        seeds,
        {"max_steps": args.max_steps},
        out=args.out,
        plots=args.out is not None,
    )
    print(report.to_markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
