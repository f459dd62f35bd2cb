"""Bit-identity of fixed-seed ``urban_canyon_v1`` episodes across performance work.

The v0 digests (``test_golden.py``) do not reach v1's own path: the navigated-distance reward,
the route autopilot, generated family cities and file cities with their real sky. These
digests do. Each case flies random actions from ``reset(seed=...)``, resetting without a seed
when an episode ends, and hashes every observation, reward, termination, truncation and info
(floats by ``repr``, which is exact) and the global state. ``python -m
tests.envs.test_golden_v1`` prints them. A change that keeps every episode bit for bit leaves
them alone; one that changes the order of floating-point operations must say so and update
them.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

from coopnav_env.sim.real_suite import REAL_SUITE
from tests.envs.golden import _update

#: (name, environment keyword arguments, steps, seed) of the golden v1 episodes.
CASES_V1: tuple[tuple[str, dict[str, Any], int, int], ...] = (
    ("v1_n5_grid", {"n_uavs": 5}, 300, 11),
    ("v1_n5_route", {"n_uavs": 5, "action_frame": "route", "route_turn_brake_mps2": 2.0}, 300, 12),
    ("v1_n3_families", {"n_uavs": 3, "city": "family:mixed", "city_pool": 4}, 150, 13),
    ("v1_n4_monte_carlo_rinex", {"n_uavs": 4, **REAL_SUITE[1].env_settings()}, 120, 14),
)

GOLDEN_V1: dict[str, str] = {
    "v1_n5_grid": "c93ea95e5f5367ebef49fbebce2f73fcca6cbff5ed13a684bc939e1f70fe77ca",
    "v1_n5_route": "2f77c79edafbaf588d9844df59a843aa54d33c13adcfce3ec3ab0425dd1115d2",
    "v1_n3_families": "5131fb7b950d4ef90c5512ba7715da0d7a2549ed7266e1f70736aeefa57da1f5",
    "v1_n4_monte_carlo_rinex": "98f4ba248770e0c428f5eb458c1d657dd560ab1ab52a110e98b38200dcb7affa",
}


def episode_digest_v1(env_kwargs: dict[str, Any], steps: int, seed: int) -> str:
    """sha256 of everything ``steps`` random-action steps of ``urban_canyon_v1`` return."""
    from coopnav_env import urban_canyon_v1

    env = urban_canyon_v1.parallel_env(**env_kwargs)
    h = hashlib.sha256()
    rng = np.random.default_rng(seed + 1000)
    obs, infos = env.reset(seed=seed)
    _update(h, [obs[a] for a in env.possible_agents])
    _update(h, infos)
    for _ in range(steps):
        if not env.agents:
            obs, infos = env.reset()
            _update(h, [obs[a] for a in env.possible_agents])
            _update(h, infos)
        actions = {a: rng.uniform(-1.0, 1.0, 3).astype(np.float32) for a in env.agents}
        obs, rewards, terms, truncs, infos = env.step(actions)
        _update(h, [obs[a] for a in env.possible_agents])
        _update(h, [rewards, terms, truncs, infos])
        _update(h, env.state())
    return h.hexdigest()


@pytest.mark.parametrize(
    ("name", "kwargs", "steps", "seed"), CASES_V1, ids=[c[0] for c in CASES_V1]
)
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_v1_episode_is_bit_identical_to_the_recorded_one(name, kwargs, steps, seed) -> None:
    assert episode_digest_v1(kwargs, steps, seed) == GOLDEN_V1[name]


if __name__ == "__main__":
    for case in CASES_V1:
        print(f'    "{case[0]}": "{episode_digest_v1(*case[1:])}",')
