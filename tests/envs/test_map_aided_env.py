"""3D-mapping-aided NLOS exclusion in the world and the environment (``nlos_exclusion``, the
``urban_nlos_3dma`` preset)."""

from __future__ import annotations

import numpy as np
import pytest

import coopnav_env.sim.scenario as S
from coopnav_env import urban_canyon_v0
from coopnav_env.envs import PRESETS, UrbanCanyonConfig, make_config, preset_config
from coopnav_env.nav import NavStatus
from coopnav_env.sim import UrbanWorld
from tests.sim.oracles import navigate_function_by_function
from tests.sim.test_fast_paths import _assert_epochs_identical, _world_epochs, count_fused_calls


def test_default_is_off() -> None:
    cfg = UrbanCanyonConfig()
    assert cfg.nlos_exclusion == "off"
    env = urban_canyon_v0.parallel_env()
    _obs, infos = env.reset(seed=0)
    assert "n_map_excluded" not in infos["uav_0"]
    assert env.unwrapped.world.last.map_excluded is None


def test_at_the_known_launch_position_the_map_names_every_nlos_satellite() -> None:
    """The first epoch's prediction is made at the known launch positions (the truth): with
    no margin, every satellite received by reflection is excluded and no line-of-sight one
    is; the same draws otherwise (the prediction consumes no random numbers)."""
    base = {"n_uavs": 5, "nlos_probability": 1.0, "nlos_bias_mean_m": 30.0}
    for seed in range(5):
        off = UrbanWorld(S.ScenarioConfig(**base)).reset(np.random.default_rng(seed))
        on = UrbanWorld(
            S.ScenarioConfig(**base, nlos_exclusion="map", nlos_exclusion_margin_sigma=0.0)
        ).reset(np.random.default_rng(seed))
        assert np.array_equal(off.los, on.los) and off.nlos.any()
        assert np.array_equal(on.map_excluded, off.nlos)
        assert np.array_equal(on.received, off.received & off.los)
        assert not on.nlos.any() and np.array_equal(on.n_sats, on.received.sum(axis=1))


@pytest.mark.parametrize(
    "kw",
    [
        {"n_uavs": 5, "nlos_exclusion": "map", "nlos_probability": 0.5},
        {
            "n_uavs": 5,
            "nlos_exclusion": "map",
            "nlos_probability": 0.5,
            "integrity": "fde",
            "integrity_fault_sign": "positive",
        },
        {"n_uavs": 6, "nlos_exclusion": "map", "nlos_probability": 0.4, "centroid": "shared"},
    ],
)
def test_fused_path_equals_the_modular_path(monkeypatch, kw) -> None:
    """The map exclusion happens before the navigation: the one-call epoch and the modular
    path give every field of every epoch bit for bit."""
    calls = count_fused_calls(monkeypatch)
    fast = _world_epochs(kw, steps=15)
    assert calls["fused"] == len(fast)
    assert sum(int(e.map_excluded.sum()) for e in fast) > 0
    navigate_function_by_function(monkeypatch)
    _assert_epochs_identical(fast, _world_epochs(kw, steps=15))


def test_preset_infos_and_determinism() -> None:
    cfg = preset_config("urban_nlos_3dma", n_uavs=4)
    extra = {"nlos_exclusion": "map", "max_fix_sigma_m": 15.0}
    assert PRESETS["urban_nlos_3dma"] == {**PRESETS["urban_nlos"], **extra}
    assert cfg.nlos_exclusion == "map" and cfg.integrity == "fde" and cfg.n_uavs == 4

    def run():
        env = urban_canyon_v0.parallel_env(config=cfg)
        rng = np.random.default_rng(5)
        _obs, infos = env.reset(seed=11)
        out = [infos]
        for _ in range(20):
            if not env.agents:
                break
            act = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
            _obs, _rew, _t, _tr, infos = env.step(act)
            ep = env.unwrapped.world.last
            for i, a in enumerate(env.possible_agents):
                assert infos[a]["n_map_excluded"] == int(ep.map_excluded[i].sum())
                assert infos[a]["n_sats"] == int(ep.received[i].sum())
            assert not np.any(ep.map_excluded & ep.received)
            out.append(infos)
        return out

    first, second = run(), run()
    assert first == second
    assert list(first[-1]["uav_0"])[-1] == "n_map_excluded"
    assert sum(info["uav_0"]["n_map_excluded"] for info in first) > 0


def test_options_are_validated() -> None:
    with pytest.raises(ValueError, match="nlos_exclusion must be one of"):
        make_config(nlos_exclusion="3dma")
    with pytest.raises(ValueError, match="nlos_exclusion_margin_sigma"):
        make_config(nlos_exclusion="map", nlos_exclusion_margin_sigma=-1.0)
    with pytest.raises(ValueError, match="nlos_exclusion_max_margin_m"):
        make_config(nlos_exclusion="map", nlos_exclusion_max_margin_m=float("nan"))


def _hover(cfg: S.ScenarioConfig, seeds: range, steps: int) -> list:
    """The epochs of a swarm hovering at its launch position (geometry fixed, satellites
    moving, measurements redrawn every epoch), one episode per seed."""
    world = UrbanWorld(cfg)
    epochs = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        world.reset(rng)
        epochs += [world.step(np.zeros((cfg.n_uavs, 3)), rng) for _ in range(steps)]
    return epochs


@pytest.mark.slow
def test_the_map_removes_the_misleading_fixes_that_fde_alone_accepts() -> None:
    """The reception and FDE of ``urban_nlos`` (about 40 % of the pseudoranges NLOS, so the
    single-fault residual test is masked), 10 hovering swarms x 60 epochs x 5 UAVs = 3000
    UAV-epochs. Misleading: a cooperative fix reported valid that is off by more than 30 m and
    by more than 3 times its own predicted 3-D sigma. FDE alone (``urban_nlos``): 74 of 2997
    valid fixes (2.5 %); ``urban_nlos_3dma`` (map exclusion, 15 m fix gate): 0 of 1200, and
    none off by more than 30 m at all (its price: fewer satellites, fewer valid fixes). The
    assertions: FDE alone at least 1 % (the epochs are correlated within an episode; across
    the 10 episodes the count is 2-15 per episode), and with the map at most 1 misleading fix:
    were its true rate 0.5 %, 1200 fixes would show at most one with probability about 1.7 %
    (Poisson, mean 6). 15 NLOS rows of 17753 reached the solvers (the others were excluded by
    the map)."""
    fde = _hover(S.ScenarioConfig(**_preset_world("urban_nlos")), range(10), 60)
    mapped = _hover(S.ScenarioConfig(**_preset_world("urban_nlos_3dma")), range(10), 60)

    def misleading(epochs):
        valid = np.concatenate([e.coop_ok for e in epochs])
        err = np.concatenate([e.coop_error_m for e in epochs])[valid]
        sig = np.concatenate([np.sqrt(np.einsum("nii->n", e.coop_cov_enu_m2)) for e in epochs])
        bad = (err > 30.0) & (err > 3.0 * sig[valid])
        return int(bad.sum()), int(valid.sum())

    bad_fde, n_fde = misleading(fde)
    bad_map, n_map = misleading(mapped)
    assert bad_fde >= 0.01 * n_fde, (bad_fde, n_fde)
    assert bad_map <= 1 and n_map >= 1000, (bad_map, n_map)
    # the NLOS rows the prediction lets through: a few of thousands
    nlos_used = sum(int(e.nlos.sum()) for e in mapped)
    assert nlos_used < 0.01 * sum(int(e.map_excluded.sum()) for e in mapped)


@pytest.mark.slow
def test_no_fault_alarm_rate_with_the_map() -> None:
    """No NLOS, detection only at p_fa = 0.05, map exclusion on: the cooperative test
    (``coop_status`` FAULT_DETECTED among the fixes it tested) fails at the configured rate.
    20 hovering swarms x 50 epochs; the 5 UAVs' problems share their measurements, so the SE
    is taken over the 372 epochs with a tested cooperative fix, not the 1834 fixes (measured
    rate 0.062): 4 SE = 4 sqrt(0.05 x 0.95 / 372) = 0.045."""
    cfg = S.ScenarioConfig(n_uavs=5, integrity="raim", integrity_p_fa=0.05, nlos_exclusion="map")
    epochs = _hover(cfg, range(20), 50)
    status = np.concatenate([e.coop_status for e in epochs])
    tested = np.isin(status, (NavStatus.OK, NavStatus.FAULT_DETECTED))
    n_epochs = sum(bool(np.isin(e.coop_status, (0, 6)).any()) for e in epochs)
    rate = float((status == NavStatus.FAULT_DETECTED).sum() / tested.sum())
    assert n_epochs >= 300
    assert abs(rate - 0.05) < 4.0 * np.sqrt(0.05 * 0.95 / n_epochs), rate


def _preset_world(name: str) -> dict:
    """The world fields of a preset (the environment's own fields dropped)."""
    world = {f.name for f in S.fields(S.ScenarioConfig)}
    return {k: v for k, v in PRESETS[name].items() if k in world}
