"""Test helper: fly two policies side by side from the same seed and compare every action."""

from __future__ import annotations

import numpy as np

from coopnav_env import urban_canyon_v0
from coopnav_env.agents import make_policy


def assert_fly_alike(name_a: str, name_b: str, seed: int, steps: int) -> None:
    """``name_a`` and ``name_b`` give bit-identical actions and rewards for ``steps`` steps."""
    env_a = urban_canyon_v0.parallel_env()
    env_b = urban_canyon_v0.parallel_env()
    pol_a, pol_b = make_policy(name_a, env_a), make_policy(name_b, env_b)
    obs_a, _ = env_a.reset(seed=seed)
    obs_b, _ = env_b.reset(seed=seed)
    pol_a.reset(seed)
    pol_b.reset(seed)
    for _ in range(steps):
        act_a, act_b = pol_a.act(obs_a), pol_b.act(obs_b)
        assert set(act_a) == set(act_b)
        for a in act_a:
            np.testing.assert_array_equal(act_a[a], act_b[a])
        obs_a, rew_a, *_ = env_a.step(act_a)
        obs_b, rew_b, *_ = env_b.step(act_b)
        assert rew_a == rew_b
        if not env_a.agents:
            break
