"""Integrity monitoring in the world and the environment (``integrity`` options, the preset)."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import (
    PRESETS,
    BatchedUrbanCanyonEnv,
    UrbanCanyonConfig,
    make_config,
    preset_config,
)
from coopnav_env.nav import IntegrityStatus, NavStatus, integrity_rates
from coopnav_env.sim import NavSource
from tests.sim.oracles import navigate_function_by_function
from tests.sim.test_fast_paths import _assert_epochs_identical, _world_epochs, count_fused_calls

INTEGRITY_KEYS = (
    "hpl_m",
    "vpl_m",
    "nav_h_error_m",
    "nav_v_error_m",
    "integrity_status",
    "fault_detected",
    "fde_excluded",
)


def _episode(env, steps, seed):
    """``steps`` steps of random actions from ``reset(seed)``; the infos of every step."""
    rng = np.random.default_rng(seed + 100)
    _obs, infos = env.reset(seed=seed)
    out = []
    for _ in range(steps):
        if not env.agents:
            env.reset()
        actions = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        obs, rew, _t, _tr, infos = env.step(actions)
        out.append((obs, rew, infos, env.unwrapped.world.last))
    return out


def test_defaults_leave_the_environment_as_it_was() -> None:
    cfg = UrbanCanyonConfig()
    assert cfg.integrity == "off" and cfg.obs_dim == 52
    env = urban_canyon_v0.parallel_env()
    _obs, _rew, infos, ep = _episode(env, 3, seed=0)[-1]
    info = infos["uav_0"]
    assert not set(INTEGRITY_KEYS) & set(info)
    assert "reward_integrity" not in info
    assert ep.hpl_m is None and ep.integrity_status is None


@pytest.mark.parametrize(
    "kw",
    [
        {"n_uavs": 5, "integrity": "fde", "nlos_probability": 0.4, "nlos_bias_mean_m": 40.0},
        {
            "n_uavs": 5,
            "integrity": "fde",
            "nlos_probability": 0.5,
            "integrity_fault_sign": "positive",
        },
        {"n_uavs": 5, "integrity": "raim", "nlos_probability": 0.4, "centroid": "shared"},
        {"n_uavs": 4, "integrity": "fde", "nlos_probability": 0.4, "transfer": "sdt"},
        {"n_uavs": 1, "integrity": "fde", "nlos_probability": 0.3},
    ],
)
def test_fused_path_equals_the_public_functions(monkeypatch, kw) -> None:
    """With integrity on, the one-call epoch (``epoch_navigation_fde``) and the modular path
    (``fde_standalone`` / ``fde_cooperative`` between the solvers and the selection) give
    every field of every epoch bit for bit; NLOS faults make both exclude."""
    calls = count_fused_calls(monkeypatch)
    fast = _world_epochs(kw, steps=15)
    assert calls["fused"] == len(fast)
    navigate_function_by_function(monkeypatch)
    ref = _world_epochs(kw, steps=15)
    _assert_epochs_identical(fast, ref)
    assert any(e.fault_detected.any() for e in fast)
    if kw["integrity"] == "fde":
        assert sum(int(e.fde_excluded.sum()) for e in fast) > 0


def test_infos_observation_and_reward_with_integrity() -> None:
    env = urban_canyon_v0.parallel_env(
        config=preset_config("urban_nlos", obs_protection_level=True, integrity_penalty=0.05)
    )
    assert env.observation_space("uav_0").shape == (54,)
    saw_excl = False
    for obs, rew, infos, ep in _episode(env, 60, seed=3):
        for i, a in enumerate(env.possible_agents):
            info = infos[a]
            assert set(INTEGRITY_KEYS) <= set(info)
            assert env.observation_space(a).contains(obs[a])
            hpl, vpl = info["hpl_m"], info["vpl_m"]
            assert np.isfinite(hpl) and np.isfinite(vpl)  # infos are finite: -1 = none
            hpl = hpl if hpl >= 0 else np.inf
            vpl = vpl if vpl >= 0 else np.inf
            assert obs[a][-2] == np.float32(min(hpl / 60.0, 1.0))
            assert obs[a][-1] == np.float32(min(vpl / 60.0, 1.0))
            usable = info["integrity_status"] in (IntegrityStatus.OK, IntegrityStatus.EXCLUDED)
            # not usable: no protection; usable: finite, unless a fault the residuals cannot
            # see would move the fix (a row without redundancy), then also infinite
            assert (usable or np.isinf(hpl)) and hpl > 0 and vpl > 0
            if ep.nav_source[i] == NavSource.DEAD_RECKONING:
                assert info["integrity_status"] == IntegrityStatus.NO_FIX and hpl == np.inf
            bad = not (info["nav_h_error_m"] <= hpl <= 30.0)
            assert info["reward_integrity"] == (-0.05 if bad else 0.0)
            terms = [v for k, v in info.items() if k.startswith("reward_")]
            assert len(terms) == 7 and rew[a] == pytest.approx(sum(terms), abs=1e-12)
            saw_excl |= info["fde_excluded"] > 0
            d = ep.nav_pos_enu_m[i] - ep.pos_enu_m[i]
            assert info["nav_h_error_m"] == pytest.approx(np.hypot(d[0], d[1]))
        # a fix whose fault was not cleared is never the one used
        co_bad = ep.coop_status == NavStatus.FAULT_DETECTED
        assert not np.any(co_bad & (ep.nav_source == NavSource.COOPERATIVE))
    assert saw_excl


def test_preset_and_its_determinism() -> None:
    cfg = preset_config("urban_nlos", n_uavs=4)
    for name, value in PRESETS["urban_nlos"].items():
        assert getattr(cfg, name) == value
    assert cfg.n_uavs == 4 and cfg.integrity == "fde" and cfg.nlos_probability > 0
    with pytest.raises(ValueError, match="unknown preset"):
        preset_config("rural")
    # the same preset named as an argument (as a training config or --env-set names it)
    assert urban_canyon_v0.parallel_env(preset="urban_nlos", n_uavs=4).unwrapped.config == cfg
    assert urban_canyon_v0.parallel_env(preset=None).unwrapped.config == UrbanCanyonConfig()
    over = urban_canyon_v0.parallel_env(preset="urban_nlos", nlos_probability=0.2)
    assert over.unwrapped.config.nlos_probability == 0.2  # overrides go on top
    assert BatchedUrbanCanyonEnv(2, preset="urban_nlos", n_uavs=4).config == cfg
    with pytest.raises(ValueError, match="unknown preset 'rural'"):
        urban_canyon_v0.parallel_env(preset="rural")
    a = _episode(urban_canyon_v0.parallel_env(config=cfg), 25, seed=9)
    b = _episode(urban_canyon_v0.parallel_env(config=cfg), 25, seed=9)
    for (oa, ra, ia, _ea), (ob, rb, ib, _eb) in zip(a, b):
        assert ra == rb and ia == ib
        assert all(np.array_equal(oa[k], ob[k]) for k in oa)


def test_integrity_options_are_validated() -> None:
    with pytest.raises(ValueError, match="covariance='exact'"):
        make_config(integrity="fde", covariance="paper")
    with pytest.raises(ValueError, match="integrity_penalty needs integrity"):
        make_config(integrity_penalty=0.1)
    with pytest.raises(ValueError, match="obs_protection_level needs integrity"):
        make_config(obs_protection_level=True)
    with pytest.raises(ValueError, match="integrity must be one of"):
        make_config(integrity="on")
    with pytest.raises(ValueError, match="integrity_p_fa"):
        make_config(integrity="raim", integrity_p_fa=0.0)
    with pytest.raises(ValueError, match="integrity_risk"):
        make_config(integrity="raim", integrity_risk=0.9)
    with pytest.raises(ValueError, match="integrity_fault_sign"):
        make_config(integrity="fde", integrity_fault_sign="negative")
    with pytest.raises(ValueError, match="alert_limit_m"):
        make_config(alert_limit_m=-1.0)
    with pytest.raises(ValueError, match="obs_protection_level"):
        make_config(integrity="fde", obs_protection_level=1)


@pytest.mark.slow
def test_fde_removes_the_large_nlos_errors_of_the_same_measurements() -> None:
    """The world draws the same measurements with and without FDE (the monitor consumes no
    random numbers and the truth does not depend on the estimates). 150 epochs of a 5-UAV
    swarm with the reception of the urban NLOS preset (about 40 % of the pseudoranges NLOS):
    without FDE 482 of 755 cooperative fixes reported OK are off by more than 30 m (95th
    percentile 68 m); with the preset's FDE 18 of 752 (95th percentile 21 m), and the
    monitor's misleading-information rate (horizontal error above the HPL of the estimate
    used) is 0. Two-sided identification does much worse under so many simultaneous
    faults (122 fixes beyond 30 m, MI rate 8 %): the fix is pulled toward the NLOS
    measurements and good ones show the largest residuals."""
    reception = {k: PRESETS["urban_nlos"][k] for k in ("nlos_probability", "nlos_bias_mean_m")}
    base = {"n_uavs": 5, "max_fix_sigma_m": None, "nlos_bias_floor_m": 3.0, **reception}
    fde = {"integrity": "fde", "integrity_fault_sign": "positive"}
    off = _world_epochs(base, steps=150)
    on = _world_epochs({**base, **fde}, steps=150)
    two_sided = _world_epochs({**base, "integrity": "fde"}, steps=150)
    assert np.array_equal(off[-1].pos_enu_m, on[-1].pos_enu_m)

    def coop_errors(epochs):
        return np.concatenate([e.coop_error_m[e.coop_ok] for e in epochs])

    def mi_rate(epochs):
        h_err = np.concatenate(
            [np.hypot(*(e.nav_pos_enu_m - e.pos_enu_m)[:, :2].T) for e in epochs]
        )
        return integrity_rates(h_err, np.concatenate([e.hpl_m for e in epochs]), 30.0)

    err_off, err_on, err_two = coop_errors(off), coop_errors(on), coop_errors(two_sided)
    assert err_on.size > 0.95 * err_off.size  # FDE keeps the fixes available
    assert (err_on > 30.0).sum() * 10 < (err_off > 30.0).sum()
    assert np.percentile(err_on, 95) < 0.5 * np.percentile(err_off, 95)
    assert (err_on > 30.0).sum() < (err_two > 30.0).sum()
    assert mi_rate(on).misleading_rate < 0.01 < mi_rate(two_sided).misleading_rate
