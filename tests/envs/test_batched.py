"""BatchedUrbanCanyonEnv: K copies stepped together equal K separate parallel environments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import BatchedUrbanCanyonEnv

SETTINGS = {"n_uavs": 4, "max_steps": 6}


def _same(a, b) -> bool:
    """Equality of nested infos, NaN equal to NaN."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return type(a) is type(b) and a == b


def test_copies_equal_separate_environments_across_episode_ends() -> None:
    k_copies, seed = 3, 10
    batch = BatchedUrbanCanyonEnv(k_copies, **SETTINGS)
    single = [urban_canyon_v0.parallel_env(**SETTINGS) for _ in range(k_copies)]
    obs, infos = batch.reset(seed=seed)
    for k, env in enumerate(single):
        o, i = env.reset(seed=seed + k)
        assert np.array_equal(obs[k], np.stack([o[a] for a in env.possible_agents]))
        assert _same(infos[k], i)
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0}
    for _ in range(25):
        # beyond [-1, 1] on purpose: both clip
        act = rng.uniform(-1.3, 1.3, (k_copies, SETTINGS["n_uavs"], 3)).astype(np.float32)
        obs, rew, term, trunc, infos, final = batch.step(act)
        assert obs.dtype == np.float32 and rew.shape == (k_copies, SETTINGS["n_uavs"])
        for k, env in enumerate(single):
            agents = env.possible_agents
            o, r, te, tr, i = env.step({a: act[k, j] for j, a in enumerate(agents)})
            assert np.array_equal(final[k], np.stack([o[a] for a in agents]))
            assert np.array_equal(rew[k], np.array([r[a] for a in agents]))
            assert term[k] == te[agents[0]] and trunc[k] == tr[agents[0]]
            assert _same(infos[k], i)
            if not env.agents:  # episode over: the batch has reset this copy already
                ends["terminated" if term[k] else "truncated"] += 1
                o, _ = env.reset()
            assert np.array_equal(obs[k], np.stack([o[a] for a in agents]))
    assert ends["terminated"] > 0 and ends["truncated"] > 0  # both kinds of end covered


def test_seed_sequences_and_flat_actions() -> None:
    batch = BatchedUrbanCanyonEnv(2, n_uavs=2, max_steps=3)
    obs, _ = batch.reset(seed=[7, None])
    ref = urban_canyon_v0.parallel_env(n_uavs=2, max_steps=3)
    o, _ = ref.reset(seed=7)
    assert np.array_equal(obs[0], np.stack([o[a] for a in ref.possible_agents]))
    batch.step(np.zeros((4, 3)))  # (K * N, 3) is accepted


def test_bad_use_raises() -> None:
    batch = BatchedUrbanCanyonEnv(2, n_uavs=2)
    with pytest.raises(ValueError, match="before reset"):
        batch.step(np.zeros((2, 2, 3)))
    batch.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        batch.step(np.zeros((2, 3, 3)))
    bad = np.zeros((2, 2, 3))
    bad[1, 0, 2] = np.nan
    with pytest.raises(ValueError, match=r"NaN or inf \(copies \[1\]\)"):
        batch.step(bad)
    with pytest.raises(ValueError, match="2 seeds"):
        batch.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="n_copies"):
        BatchedUrbanCanyonEnv(0)
    with pytest.raises(ValueError, match="same configuration"):
        BatchedUrbanCanyonEnv.from_envs(
            [urban_canyon_v0.parallel_env(n_uavs=2), urban_canyon_v0.parallel_env(n_uavs=3)]
        )
    with pytest.raises(ValueError, match="render"):
        BatchedUrbanCanyonEnv(1, render_mode="rgb_array")
    env = urban_canyon_v0.parallel_env(n_uavs=2)
    with pytest.raises(ValueError, match="distinct"):
        BatchedUrbanCanyonEnv.from_envs([env, env])
