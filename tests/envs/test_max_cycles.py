"""``max_cycles``: the conventional (PettingZoo, BenchMARL) alias of ``max_steps``."""

from __future__ import annotations

import functools
import types

import numpy as np
import pytest
from pettingzoo.test import max_cycles_test

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import UrbanCanyonConfig, make_config


def test_max_cycles_sets_max_steps_and_truncates_there() -> None:
    env = urban_canyon_v0.parallel_env(max_cycles=7)
    assert env.config.max_steps == 7 and env.config.max_cycles == 7
    env.reset(seed=0)
    steps = 0
    while env.agents:
        _, _, terms, truncs, _ = env.step({a: np.zeros(3, np.float32) for a in env.agents})
        steps += 1
    assert steps == 7 and all(truncs.values()) and not any(terms.values())
    # on top of a config object, and through the AEC constructor
    cfg = UrbanCanyonConfig(n_uavs=2, max_steps=50)
    assert make_config(cfg, max_cycles=9) == UrbanCanyonConfig(n_uavs=2, max_steps=9)
    assert urban_canyon_v0.env(max_cycles=3).unwrapped.config.max_steps == 3
    assert UrbanCanyonConfig().max_cycles == 200


def test_max_cycles_and_max_steps_together() -> None:
    assert urban_canyon_v0.parallel_env(max_cycles=8, max_steps=8).config.max_steps == 8
    with pytest.raises(ValueError, match=r"max_cycles is an alias of max_steps.*=5.*=6"):
        urban_canyon_v0.parallel_env(max_cycles=5, max_steps=6)
    with pytest.raises(ValueError, match=r"max_steps must be .*got 0 \(given as max_cycles"):
        urban_canyon_v0.parallel_env(max_cycles=0)
    with pytest.raises(ValueError, match=r"unknown urban_canyon_v0 argument\(s\) \['cycles'\]"):
        urban_canyon_v0.parallel_env(max_cycles=5, cycles=6)


def test_pettingzoo_max_cycles_test() -> None:
    """PettingZoo's own check: ``max_cycles=4`` ends the episode after exactly 4 steps.

    It flies unseeded random actions and counts steps until every agent is done, so a crash
    into a building before step 4 would end the episode early. At 0.5 m/s a UAV moves at most
    2 m in 4 steps; the start formation stands along a 20 m street at most 5 m off its centre
    line (5 m lattice, 1 m radius), at least 4 m from the walls, so the episode can only end by
    truncation.
    """
    slow = {"kinematics": {"max_speed_mps": 0.5}}
    mod = types.SimpleNamespace(
        parallel_env=functools.partial(urban_canyon_v0.parallel_env, **slow),
        env=functools.partial(urban_canyon_v0.env, **slow),
    )
    max_cycles_test(mod)
