"""Test helper: the batched environment's copies against separate environments."""

from __future__ import annotations

from typing import Any

import numpy as np

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import BatchedUrbanCanyonEnv


def assert_batched_obs_equal_separate(
    kwargs: dict[str, Any], seed: int, copies: int = 2, steps: int = 30
) -> BatchedUrbanCanyonEnv:
    """Copy ``k`` of ``BatchedUrbanCanyonEnv(copies, **kwargs)`` reset with ``seed`` gives the
    observations, bit for bit, of a separate environment reset with ``seed + k``, for
    ``steps`` random commands, across episode ends. Returns the batched environment."""
    batch = BatchedUrbanCanyonEnv(copies, **kwargs)
    separate = [urban_canyon_v0.parallel_env(**kwargs) for _ in range(copies)]
    n = batch.n_agents
    obs, _ = batch.reset(seed=seed)
    ref = [e.reset(seed=seed + k)[0] for k, e in enumerate(separate)]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        for k in range(copies):
            assert obs[k].tobytes() == np.stack(list(ref[k].values())).tobytes()
        cmd = rng.uniform(-1.0, 1.0, (copies, n, 3))
        obs, *_ = batch.step(cmd)
        for k, e in enumerate(separate):
            ref[k], _, term, trunc, _ = e.step(dict(zip(e.agents, cmd[k])))
            if any(term.values()) or any(trunc.values()):
                ref[k], _ = e.reset()
    return batch
