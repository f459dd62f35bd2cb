"""The ``obs_true_error`` observation option: the privileged diagnostic that hands the actor
the true error of its estimate (what the privileged planner knows and no receiver does)."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import make_config, obs_layout, preset_config
from tests.batched_alike import assert_batched_obs_equal_separate
from tests.env_flight import assert_layout_bounds_are_the_space, fly_random


def test_option_is_validated_off_by_default_and_named_last_in_the_layout() -> None:
    assert make_config().obs_true_error is False
    assert make_config().obs_dim == 52  # the default observation is unchanged
    with pytest.raises(ValueError, match="obs_true_error must be True or False, got 1"):
        make_config(obs_true_error=1)
    cfg = preset_config("urban_nlos_3dma", obs_satellite_sectors=True, obs_true_error=True)
    assert cfg.obs_dim == 52 + 16 + 3
    layout = obs_layout(cfg)
    assert list(layout)[-2:] == ["satellites_blocked_sector", "true_error"]
    assert layout["true_error"].stop == cfg.obs_dim
    low, _ = assert_layout_bounds_are_the_space(cfg)
    np.testing.assert_array_equal(low[-3:], -1.0)


def test_entries_are_the_true_error_of_the_estimate_used_and_nothing_else_changes() -> None:
    kw = {"n_uavs": 3, "dead_reckoning_noise": True, "max_steps": 60}
    plain = urban_canyon_v0.parallel_env(
        config=preset_config("urban_nlos_3dma", obs_true_error=False, **kw)
    )
    with_err = urban_canyon_v0.parallel_env(
        config=preset_config("urban_nlos_3dma", obs_true_error=True, **kw)
    )
    layout = obs_layout(with_err.config)
    scale = with_err.config.obs_sigma_max_m
    checked = 0
    for seed, steps in ((2, 0), (2, 30), (5, 45)):
        obs_p = fly_random(plain, seed, steps)
        obs_e = fly_random(with_err, seed, steps)
        if not with_err.agents:
            continue
        ep = with_err._epoch
        want = np.clip((ep.nav_pos_enu_m - ep.pos_enu_m) / scale, -1.0, 1.0)
        for i, a in enumerate(with_err.agents):
            np.testing.assert_array_equal(obs_e[a][:-3], obs_p[a])  # the option only appends
            got = layout["true_error"].decode(obs_e[a][None])[0]
            np.testing.assert_allclose(got / scale, want[i], atol=1e-6)
            checked += 1
    assert checked > 0


def test_batched_equals_separate_environments_and_the_api_holds() -> None:
    kwargs = {"n_uavs": 3, "max_steps": 12, "obs_true_error": True}
    batch = assert_batched_obs_equal_separate(kwargs, seed=21)
    assert batch.obs_dim == 55
    parallel_api_test(urban_canyon_v0.parallel_env(n_uavs=3, obs_true_error=True), num_cycles=50)
