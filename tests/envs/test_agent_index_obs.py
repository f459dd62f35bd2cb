"""The ``obs_agent_index`` observation option: every UAV's one-hot index, appended last."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import make_config, obs_layout
from tests.batched_alike import assert_batched_obs_equal_separate
from tests.env_flight import assert_layout_bounds_are_the_space, fly_random


def test_option_is_validated_off_by_default_and_named_last_in_the_layout() -> None:
    assert make_config().obs_agent_index is False
    with pytest.raises(ValueError, match="obs_agent_index must be True or False, got 1"):
        make_config(obs_agent_index=1)
    cfg = make_config(n_uavs=4, obs_true_error=True, obs_agent_index=True)
    assert cfg.obs_dim == 52 + 3 + 4
    layout = obs_layout(cfg)
    assert list(layout)[-2:] == ["true_error", "agent_index"]
    assert layout["agent_index"].stop == cfg.obs_dim
    low, high = assert_layout_bounds_are_the_space(cfg)
    np.testing.assert_array_equal(low[-4:], 0.0)
    np.testing.assert_array_equal(high[-4:], 1.0)


def test_entries_are_the_one_hot_index_and_nothing_else_changes() -> None:
    kw = {"n_uavs": 3, "max_steps": 40}
    plain = urban_canyon_v0.parallel_env(**kw)
    indexed = urban_canyon_v0.parallel_env(obs_agent_index=True, **kw)
    checked = 0
    for seed, steps in ((3, 0), (3, 20), (8, 35)):
        obs_p = fly_random(plain, seed, steps)
        obs_i = fly_random(indexed, seed, steps)
        for a in indexed.agents:
            i = indexed.possible_agents.index(a)
            np.testing.assert_array_equal(obs_i[a][:-3], obs_p[a])  # the option only appends
            np.testing.assert_array_equal(obs_i[a][-3:], np.eye(3, dtype=np.float32)[i])
            checked += 1
    assert checked > 0


def test_batched_equals_separate_environments_and_the_api_holds() -> None:
    kwargs = {"n_uavs": 3, "max_steps": 12, "obs_agent_index": True}
    batch = assert_batched_obs_equal_separate(kwargs, seed=21)
    assert batch.obs_dim == 55
    parallel_api_test(urban_canyon_v0.parallel_env(n_uavs=3, obs_agent_index=True), num_cycles=50)
