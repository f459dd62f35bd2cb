"""The ``obs_satellite_sectors`` observation option: satellites tracked and missed per sector."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import make_config, obs_layout, preset_config
from tests.batched_alike import assert_batched_obs_equal_separate
from tests.env_flight import assert_layout_bounds_are_the_space
from tests.envs import oracles

CASES = [
    {"n_uavs": 5},
    {"n_uavs": 4, "city": "canyon", "obs_sky_azimuths": 4},
    {"n_uavs": 6, "nlos_probability": 0.3, "obs_sky_azimuths": 5},
    {"n_uavs": 3, "max_sats": 6, "obs_sky_azimuths": 12},
    {"config": preset_config("urban_nlos_3dma", n_uavs=4, obs_protection_level=True)},
]


def _env(kwargs, **extra):
    return urban_canyon_v0.parallel_env(**{**kwargs, "obs_satellite_sectors": True, **extra})


def _sector_counts(az_deg, mask, n_az):
    """Satellites of ``mask`` (N, S) per sector, counted from the angular distance to each
    sector centre ``360 i / n_az`` (within half a sector width, the lower edge included): a
    formulation independent of the environment's ``floor(az n_az / 360 + 1/2) mod n_az``."""
    centres = np.arange(n_az) * 360.0 / n_az
    d = (az_deg[:, None] - centres[None, :] + 180.0) % 360.0 - 180.0  # (S, A) in [-180, 180)
    inside = (d >= -180.0 / n_az) & (d < 180.0 / n_az)
    assert np.all(inside.sum(axis=1) == 1)  # every satellite in exactly one sector
    return mask.astype(int) @ inside.astype(int)


def _rollout(env, seed, steps, act_seed=1):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(act_seed)
    yield obs
    for _ in range(steps):
        if not env.agents:
            obs, _ = env.reset()
        else:
            obs, *_ = env.step({a: rng.uniform(-1.0, 1.0, 3) for a in env.agents})
        yield obs


def test_option_is_validated_and_off_by_default() -> None:
    assert make_config().obs_satellite_sectors is False
    with pytest.raises(ValueError, match="obs_satellite_sectors must be True or False, got 1"):
        make_config(obs_satellite_sectors=1)
    cfg = make_config(obs_satellite_sectors=True, obs_sky_azimuths=6, obs_neighbours=3)
    assert cfg.obs_dim == 20 + 2 * 6 + 4 * 3 + 2 * 6


@pytest.mark.parametrize("kwargs", CASES)
def test_counts_per_sector_are_the_tracked_and_missed_satellites(kwargs) -> None:
    """At every step the entries are the counts of an independent formulation / 4, clipped;
    summed over sectors (when no sector clips) they are the satellites tracked and the ones
    above the cut-off missed."""
    env = _env(kwargs)
    cfg = env.config
    a = cfg.obs_sky_azimuths
    layout = obs_layout(env)
    rec, blk = layout["satellites_received_sector"], layout["satellites_blocked_sector"]
    assert (rec.start, blk.stop) == (cfg.obs_dim - 2 * a, cfg.obs_dim)  # last in the vector
    space = env.observation_space("uav_0")
    missed = excluded = unclipped = 0
    for obs in _rollout(env, seed=7, steps=40):
        ep = env._epoch
        o = np.stack([obs[u] for u in env.possible_agents])
        assert o.shape == (cfg.n_uavs, cfg.obs_dim) and all(space.contains(r) for r in o)
        tracked = ep.received if ep.map_excluded is None else ep.received | ep.map_excluded
        want_r = _sector_counts(ep.sv_az_deg, tracked, a)
        want_b = _sector_counts(ep.sv_az_deg, ~tracked, a)
        np.testing.assert_array_equal(o[:, rec.slice], np.minimum(want_r / 4.0, 1.0))
        np.testing.assert_array_equal(o[:, blk.slice], np.minimum(want_b / 4.0, 1.0))
        n_map = np.zeros(cfg.n_uavs, int) if ep.map_excluded is None else ep.map_excluded.sum(1)
        for i in range(cfg.n_uavs):
            if want_r[i].max() <= 4 and want_b[i].max() <= 4:
                unclipped += 1
                assert rec.decode(o[i]).sum() == ep.n_sats[i] + n_map[i]
                assert blk.decode(o[i]).sum() == ep.n_above_mask - tracked[i].sum()
        missed += int((~tracked).sum())
        excluded += int(np.sum(n_map))
    assert unclipped > 0 and missed > 0  # the case exercises missed satellites
    if cfg.nlos_exclusion == "map":
        assert excluded > 0  # excluded satellites count as tracked, not as blocked


def test_open_sky_blocks_nothing() -> None:
    """A grid city of 0.3 m buildings under UAVs flying at 5 m or more: every satellite above
    the cut-off is received, so the blocked entries are all 0 and the received ones sum to
    the satellites above the cut-off (13 or so in 8 sectors: none reaches the clip at 4 in
    this episode)."""
    flat = {"height_min_m": 0.1, "height_max_m": 0.5, "height_mean_m": 0.3, "height_std_m": 0.0}
    env = _env({"n_uavs": 3, "city_config": flat})
    layout = obs_layout(env)
    for obs in _rollout(env, seed=2, steps=10):
        ep = env._epoch
        assert ep.n_sats.tolist() == [ep.n_above_mask] * 3
        for u in env.possible_agents:
            assert np.all(obs[u][layout["satellites_blocked_sector"].slice] == 0.0)
            counts = layout["satellites_received_sector"].decode(obs[u])
            assert counts.max() < 4 and counts.sum() == ep.n_above_mask


def test_option_appends_only_and_keeps_the_episode() -> None:
    """With the option the first entries are the observation without it, bit for bit, at
    every step (the option draws nothing and changes no episode), and the same seed gives the
    same observations."""
    kwargs = {"n_uavs": 4, "nlos_probability": 0.2}
    base = urban_canyon_v0.parallel_env(**kwargs)
    n = base.config.obs_dim
    on = [np.stack(list(o.values())) for o in _rollout(_env(kwargs), seed=3, steps=30)]
    again = [np.stack(list(o.values())) for o in _rollout(_env(kwargs), seed=3, steps=30)]
    off = [np.stack(list(o.values())) for o in _rollout(base, seed=3, steps=30)]
    assert len(on) == len(off) == 31
    for x, y, z in zip(on, again, off, strict=True):
        assert x.tobytes() == y.tobytes()
        assert x[:, :n].tobytes() == z.tobytes() and x.shape[1] == n + 16


@pytest.mark.parametrize("kwargs", [CASES[0], CASES[2], CASES[4]])
def test_kernel_equals_numpy(monkeypatch, kwargs) -> None:
    """The compiled observations and the numpy oracles agree bit for bit with the option on
    (protection levels too in the last case)."""

    def run():
        return [np.stack(list(o.values())).tobytes() for o in _rollout(_env(kwargs), 5, 40)]

    fast = run()
    with monkeypatch.context() as m:
        calls = oracles.use_oracles_in_env(m)
        assert fast == run()
    assert calls["satellite_sectors"] > 0
    env = _env(kwargs)
    for _ in _rollout(env, seed=5, steps=20):
        fast = env.task.satellite_sectors(env._epoch)
        assert fast.tobytes() == oracles.satellite_sectors(env.task, env._epoch).tobytes()


def test_batched_equals_separate_environments() -> None:
    """Copy k of the batched environment equals a separate environment seeded with seed + k,
    satellite-sector entries included, across episode ends (max_steps=12)."""
    kwargs = {"n_uavs": 3, "max_steps": 12, "obs_satellite_sectors": True}
    batch = assert_batched_obs_equal_separate(kwargs, seed=10)
    assert batch.obs_dim == batch.config.obs_dim == 52 + 16


def test_layout_names_the_optional_blocks() -> None:
    """The layout covers every entry once with both options on, bounds those of the space."""
    cfg = preset_config("urban_nlos", obs_protection_level=True, obs_satellite_sectors=True)
    layout = obs_layout(cfg)
    covered = np.concatenate([np.arange(f.start, f.stop) for f in layout.values()])
    assert covered.tolist() == list(range(cfg.obs_dim)) and cfg.obs_dim == 52 + 2 + 16
    names = list(layout)[-3:]
    assert names == ["protection_level", "satellites_received_sector", "satellites_blocked_sector"]
    assert layout["protection_level"].scale == 2 * cfg.alert_limit_m
    assert layout["satellites_blocked_sector"].components[2] == "90 deg"
    assert_layout_bounds_are_the_space(cfg)


def test_parallel_api_with_the_option() -> None:
    parallel_api_test(_env({"n_uavs": 3}), num_cycles=100)


def test_gymnasium_view_stacks_the_longer_observation() -> None:
    import gymnasium as gym

    env = gym.make("coopnav/UrbanCanyonSwarm-v0", n_uavs=3, obs_satellite_sectors=True)
    obs, _ = env.reset(seed=4)
    d = env.unwrapped.config.obs_dim
    assert d == 52 + 16 and obs.shape == env.observation_space.shape == (3 * d,)
    assert env.observation_space.contains(obs)
    env.close()
