"""The privileged planner: copies, not the real episode; the base alone is a candidate."""

from __future__ import annotations

import numpy as np
import pytest

from agents import make_policy
from coopnav_env import urban_canyon_v0


def test_with_only_the_zero_candidate_the_planner_flies_its_base() -> None:
    # one candidate, one round: the offset is zero, so the command is the base's, and the
    # look-ahead in copies must not disturb the real episode (its generator included)
    env_p = urban_canyon_v0.parallel_env()
    env_b = urban_canyon_v0.parallel_env()
    planner = make_policy("planner@n_samples=1,n_elite=1,iterations=1,horizon=2", env_p)
    base = make_policy("spread", env_b)
    obs_p, _ = env_p.reset(seed=1_000_001)
    obs_b, _ = env_b.reset(seed=1_000_001)
    planner.reset(1_000_001)
    base.reset(1_000_001)
    for _ in range(15):
        a_p, a_b = planner.act(obs_p), base.act(obs_b)
        for a in a_p:
            np.testing.assert_array_equal(a_p[a], a_b[a])
        obs_p, r_p, *_ = env_p.step(a_p)
        obs_b, r_b, *_ = env_b.step(a_b)
        assert r_p == r_b


def test_the_planner_chooses_the_cheapest_candidate() -> None:
    env = urban_canyon_v0.parallel_env()
    obs, _ = env.reset(seed=1_000_002)
    planner = make_policy("planner@n_samples=6,n_elite=2,iterations=1,horizon=3", env)
    planner.reset(1_000_002)
    costs = []
    rng = np.random.default_rng(0)
    cands = [np.zeros((5, 3)), *(0.3 * rng.standard_normal((5, 5, 3)))]
    for c in cands:
        costs.append(planner._rollout(c, obs, 123))
    # the same candidate and noise seed give the same cost (common random numbers)
    assert planner._rollout(cands[1], obs, 123) == costs[1]
    assert len(set(costs)) > 1  # the candidates differ, so choosing can matter


@pytest.mark.parametrize("bad", ["horizon=0", "n_samples=2,n_elite=3", "offset_std=-1"])
def test_bad_planner_settings(bad) -> None:
    env = urban_canyon_v0.parallel_env()
    with pytest.raises(ValueError, match="planner"):
        make_policy(f"planner@{bad}", env)
