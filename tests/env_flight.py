"""Test helpers: fly an environment on random commands; a point inside a building; the
layout's bounds against the observation space."""

from __future__ import annotations

from typing import Any

import numpy as np


def fly_random(env: Any, seed: int, steps: int, act_seed: int = 1) -> dict[str, np.ndarray]:
    """Reset ``env`` with ``seed`` and fly up to ``steps`` uniform random commands (generator
    seeded with ``act_seed``), stopping early when the episode ends; returns the last
    observations."""
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(act_seed)
    for _ in range(steps):
        if not env.agents:
            break
        obs, *_ = env.step({a: rng.uniform(-1.0, 1.0, 3) for a in env.agents})
    return obs


def point_inside_tallest_building(env: Any) -> np.ndarray:
    """``(3,)``: the centre of the city's tallest building at 5 m, a point inside it (checked
    with :func:`coopnav_env.sim.city.is_inside_building`)."""
    from coopnav_env.sim.city import is_inside_building

    b = env.world.city.buildings
    j = int(np.argmax(b.max_m[:, 2]))
    inside = np.array(
        [(b.min_m[j, 0] + b.max_m[j, 0]) / 2, (b.min_m[j, 1] + b.max_m[j, 1]) / 2, 5.0]
    )
    assert is_inside_building(b, inside[None])[0]
    return inside


def assert_layout_bounds_are_the_space(cfg: Any) -> tuple[np.ndarray, np.ndarray]:
    """Assert that the named layout's bounds for ``cfg`` are the environment's observation
    space (per agent, ``uav_0``), index by index; returns them (low, high)."""
    from coopnav_env import urban_canyon_v0
    from coopnav_env.envs import obs_layout

    low, high = obs_layout(cfg).bounds()
    space = urban_canyon_v0.parallel_env(config=cfg).observation_space("uav_0")
    np.testing.assert_array_equal(low, space.low)
    np.testing.assert_array_equal(high, space.high)
    return low, high
