"""``dead_reckoning_noise``: a dead reckoning that drifts as its covariance says it does."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import BatchedUrbanCanyonEnv

HOVER_STEPS = 50


def _hover_errors(noise: bool, seeds) -> np.ndarray:
    """3-D errors of every UAV after HOVER_STEPS steps without any fix (the gate rejects all
    of them), hovering, started at the known launch positions (error 0)."""
    env = urban_canyon_v0.parallel_env(
        max_fix_sigma_m=1e-3, dead_reckoning_noise=noise, max_steps=HOVER_STEPS + 10
    )
    out = []
    for seed in seeds:
        env.reset(seed=int(seed))
        for _ in range(HOVER_STEPS):
            _o, _r, _te, _tr, infos = env.step(
                {a: np.zeros(3, dtype=np.float32) for a in env.agents}
            )
        assert all(infos[a]["nav_source"] == 2 for a in env.agents)  # dead reckoning
        out.append([infos[a]["nav_error_m"] for a in env.possible_agents])
    return np.asarray(out, dtype=float).ravel()


def test_dead_reckoning_drifts_as_a_random_walk_of_the_configured_sigma() -> None:
    cfg = urban_canyon_v0.parallel_env().unwrapped.config
    sigma = cfg.dead_reckoning_sigma_mps * cfg.dt_s
    assert np.all(_hover_errors(False, range(3)) == 0.0)  # off: the true velocity, no drift
    e2 = _hover_errors(True, range(40)) ** 2
    # E|e|^2 = 3 k sigma^2 (k steps of an N(0, sigma^2) per-axis walk); |e|^2 / (k sigma^2)
    # is chi-square(3), variance 6, so the sample mean's standard error is sqrt(6 / n) in
    # those units
    expected = 3.0 * HOVER_STEPS * sigma**2
    se = np.sqrt(6.0 / e2.size) * HOVER_STEPS * sigma**2
    assert abs(e2.mean() - expected) < 4.0 * se, (e2.mean(), expected, se)


def test_dead_reckoning_noise_is_seeded_and_batched_alike() -> None:
    kw = {"preset": "urban_nlos_3dma", "dead_reckoning_noise": True}
    env = urban_canyon_v0.parallel_env(**kw)
    batched = BatchedUrbanCanyonEnv(1, **kw)
    rng = np.random.default_rng(0)
    runs = []
    for _ in range(2):
        env.reset(seed=7)
        runs.append([])
        for _t in range(30):
            act = rng.uniform(-0.05, 0.05, (5, 3)).astype(np.float32)
            obs, *_ = env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
            runs[-1].append(np.stack([obs[a] for a in env.possible_agents]))
        rng = np.random.default_rng(0)
    assert all(np.array_equal(a, b) for a, b in zip(*runs))  # the same seed, the same episode
    batched.reset(seed=[7])
    for t in range(30):
        act = rng.uniform(-0.05, 0.05, (5, 3)).astype(np.float32)
        obs = batched.step(act[None])[0]
        assert np.array_equal(obs[0], runs[0][t])


def test_dead_reckoning_noise_must_be_a_bool() -> None:
    with pytest.raises(ValueError, match="dead_reckoning_noise must be True or False, got 1"):
        urban_canyon_v0.parallel_env(dead_reckoning_noise=1)
