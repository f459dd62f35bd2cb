"""``max_cycles``: the conventional (PettingZoo, BenchMARL) alias of ``max_steps``."""

from __future__ import annotations

import functools
import types

import numpy as np
import pytest
from pettingzoo.test import max_cycles_test

from coopnav_env import urban_canyon_v0, urban_canyon_v1
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
    with pytest.raises(ValueError, match=r"unknown urban_canyon argument\(s\) \['cycles'\]"):
        urban_canyon_v0.parallel_env(max_cycles=5, cycles=6)


def test_pettingzoo_max_cycles_test_on_v1_as_pettingzoo_runs_it() -> None:
    """PettingZoo's own check on the module itself, 30 times: ``max_cycles=4`` ends the
    episode after exactly 4 steps of unseeded random actions.

    Random UAVs at full speed hit a wall within a few steps; urban_canyon_v1's crash-free start
    (``crash_free_steps=3``) stops them there without ending the episode, so no episode ends
    before step 4.
    """
    for _ in range(30):
        max_cycles_test(urban_canyon_v1)


def test_pettingzoo_max_cycles_test_on_legacy_v0_needs_slow_uavs() -> None:
    """The legacy v0 has no crash-free start: the check passes on it with slow UAVs only.

    At 0.5 m/s a UAV moves at most 2 m in 4 steps; the start formation stands along a 20 m
    street at most 5 m off its centre line (5 m lattice, 1 m radius), at least 4 m from the
    walls, so the episode can only end by truncation.
    """
    slow = {"kinematics": {"max_speed_mps": 0.5}}
    mod = types.SimpleNamespace(
        parallel_env=functools.partial(urban_canyon_v0.parallel_env, **slow),
        env=functools.partial(urban_canyon_v0.env, **slow),
    )
    max_cycles_test(mod)


def _fly_north(crash_free_steps: int, seed: int = 2, steps: int = 12) -> list[tuple]:
    """(true positions, rewards, terminated, collided flags) per step of a swarm flying north
    at full speed from ``reset(seed)``, until the episode ends."""
    env = urban_canyon_v1.parallel_env(crash_free_steps=crash_free_steps)
    env.reset(seed=seed)
    out = []
    while env.agents and len(out) < steps:
        _, rewards, terms, _, infos = env.step(
            {a: np.array([0.0, 1.0, 0.0], np.float32) for a in env.agents}
        )
        pos = env.unwrapped.world.pos_enu_m.copy()
        collided = [infos[a]["collided"] for a in infos]
        out.append((pos, [rewards[a] for a in rewards], any(terms.values()), collided))
    return out


def test_crash_free_start_stops_a_uav_at_the_wall_and_goes_on() -> None:
    """In episode 2 a UAV flying north hits a wall on step 1: without the crash-free start the
    episode ends there; with 3 crash-free steps the UAV stays where it was and the episode
    goes on to step 4, where the next hit ends it as a crash."""
    plain = _fly_north(0)
    assert len(plain) == 1 and plain[0][2] and any(plain[0][3])
    guarded = _fly_north(3)
    assert len(guarded) == 4
    for _pos, rewards, terminated, collided in guarded[:3]:
        assert not terminated and not any(collided) and min(rewards) > -0.5  # no penalty
    stopped = np.all(guarded[0][0] == guarded[2][0], axis=1)  # at the wall since step 1
    assert stopped.any() and not stopped.all()
    assert guarded[3][2] and any(guarded[3][3]) and min(guarded[3][1]) <= -1.0  # a crash
    # an episode without a hit in its first steps is the same with or without it
    assert all(
        np.array_equal(a[0], b[0]) and a[1:] == b[1:]
        for a, b in zip(_fly_north(0, seed=3), _fly_north(3, seed=3))
    )
    with pytest.raises(ValueError, match="crash_free_steps"):
        urban_canyon_v1.parallel_env(crash_free_steps=-1)
