"""Galileo flown by the environment from a station's navigation file (``systems`` with
``"GAL"``): satellites in view, fixes with them, its own receiver clock, and the three
navigation paths equal bit for bit."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env import urban_canyon_v1
from coopnav_env.constants import FILE_SYSTEMS
from coopnav_env.envs import _fused
from coopnav_env.sim import scenario as S
from tests.sim.oracles import navigate_function_by_function

ELKO = (
    Path(__file__).resolve().parents[1] / "gnss" / "data" / "ELKO00USA_R_20182100000_01D_MN.rnx.gz"
)
AT_ELKO = {"lat_deg": 40.9157, "lon_deg": -115.7375, "alt_m": 1636.0}
GALILEO_SKY = {"constellation": f"rinex:{ELKO}", "systems": ("GPS", "BDS", "GAL"), **AT_ELKO}
GAL = FILE_SYSTEMS.index("GAL")


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the station file's unhealthy records
        yield


def _climb(systems: tuple[str, ...], steps: int = 40) -> tuple[np.ndarray, list]:
    """Every UAV climbing; per step (coop fix, satellites received, in the open sky)."""
    env = urban_canyon_v1.parallel_env(
        n_uavs=4, max_steps=steps, **{**GALILEO_SKY, "systems": systems}
    )
    env.reset(seed=1)
    rows, skies = [], []
    while env.agents:
        _, _, _, _, infos = env.step({a: np.array([0.0, 0.0, 1.0], np.float32) for a in env.agents})
        i = infos[env.possible_agents[0]]
        rows.append([i["coop_fix"], i["n_sats"], i["n_sats_open_sky"]])
        skies.append(env.world._sky(env.world.t_s))
    return np.asarray(rows, dtype=float), skies


def test_galileo_satellites_join_the_sky_and_the_fixes() -> None:
    with_gal, skies = _climb(("GPS", "BDS", "GAL"))
    without, _ = _climb(("GPS", "BDS"))
    assert all(np.any(sky.system_idx == GAL) for sky in skies)
    assert np.all(with_gal[:, 2] > without[:, 2])  # more satellites in the open sky
    assert np.all(with_gal[:, 1] >= without[:, 1]) and with_gal[:, 1].mean() > without[:, 1].mean()
    assert with_gal[10:, 0].mean() >= 0.9  # a cooperative fix once the swarm has climbed


def test_galileo_gets_its_own_receiver_clock_drawn_after_the_others() -> None:
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    plain = S.UrbanWorld(S.ScenarioConfig(n_uavs=3, **{**GALILEO_SKY, "systems": ("GPS", "BDS")}))
    gal = S.UrbanWorld(S.ScenarioConfig(n_uavs=3, **GALILEO_SKY))
    plain.reset(rng_a)
    gal.reset(rng_b)
    assert plain.clock_bias_m.shape == (3, 2) and gal.clock_bias_m.shape == (3, 3)
    # the city and start time come first from the generator, then the clocks: GPS and BeiDou
    # clocks are the draws of a world without Galileo
    np.testing.assert_array_equal(gal.clock_bias_m[:, :2], plain.clock_bias_m)
    assert np.all(np.abs(gal.clock_bias_m[:, 2]) > 0.0)


def test_galileo_needs_a_navigation_file() -> None:
    with pytest.raises(ValueError, match=r"Galileo \('GAL'\) flies only from a navigation file"):
        urban_canyon_v1.parallel_env(systems=("GPS", "GAL"))
    with pytest.raises(ValueError, match=r"distinct names from \('GPS', 'BDS'\)"):
        urban_canyon_v1.parallel_env(systems=("GPS", "GLONASS"))


def test_galileo_epochs_equal_on_the_fused_and_the_modular_navigation(monkeypatch) -> None:
    """``UrbanWorld._navigate_fused`` against ``_navigate``, every field of every epoch."""

    def epochs() -> list:
        world = S.UrbanWorld(S.ScenarioConfig(n_uavs=4, **GALILEO_SKY))
        rng, cmd = np.random.default_rng(7), np.random.default_rng(8)
        out = [world.reset(rng)]
        for _ in range(30):
            out.append(world.step(cmd.uniform(-0.7, 0.7, (4, 3)), rng))
        return out

    fast = epochs()
    navigate_function_by_function(monkeypatch)
    ref = epochs()
    n_gal = 0
    for a, b in zip(fast, ref, strict=True):
        for f in dataclasses.fields(b):
            x, y = np.asarray(getattr(a, f.name)), np.asarray(getattr(b, f.name))
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), f.name
        n_gal += int(np.count_nonzero(np.asarray(b.system) == GAL))
    assert n_gal > 0


def test_galileo_episodes_equal_on_the_fused_step_and_the_world_step(monkeypatch) -> None:
    calls = {"fused": 0}
    run_chunks = _fused._run_threads

    def counted(kernel, *args):
        calls["fused"] += kernel is _fused._batched_kernels.navigation_reward_sensors
        return run_chunks(kernel, *args)

    def run(fused: bool) -> list:
        monkeypatch.setattr(_fused, "_run_threads", counted)
        if not fused:
            monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
        env = urban_canyon_v1.parallel_env(n_uavs=4, max_steps=15, **GALILEO_SKY)
        obs, _ = env.reset(seed=8)
        rng = np.random.default_rng(4)
        out = [obs]
        for _ in range(25):
            out.append(env.step({a: rng.uniform(-1.0, 1.0, 3) for a in env.agents}))
            if not env.agents:
                out.append(env.reset()[0])
        monkeypatch.undo()
        return out

    fused = run(True)
    assert calls["fused"] == 25  # every step took the fused step (three clock states)
    world = run(False)
    assert calls["fused"] == 25
    assert len(fused) == len(world)
    for a, b in zip(fused, world, strict=True):
        if isinstance(b, tuple):
            obs_a, rew_a, _, _, inf_a = a
            obs_b, rew_b, _, _, inf_b = b
            assert all(obs_a[k].tobytes() == obs_b[k].tobytes() for k in obs_b)
            assert rew_a == rew_b
            assert repr(inf_a) == repr(inf_b)
        else:
            assert all(a[k].tobytes() == b[k].tobytes() for k in b)


def test_the_sky_plot_shows_galileo_satellites_in_their_own_colour() -> None:
    pytest.importorskip("matplotlib")
    from matplotlib.axes import Axes

    from coopnav_env.envs.render import SYSTEM_COLOURS

    env = urban_canyon_v1.parallel_env(n_uavs=2, render_mode="rgb_array", **GALILEO_SKY)
    env.reset(seed=1)
    labels: list[tuple[str, str]] = []
    scatter = Axes.scatter

    def record(self, *args, **kwargs):
        if "label" in kwargs and "color" in kwargs:
            labels.append((kwargs["label"], kwargs["color"]))
        return scatter(self, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Axes, "scatter", record)
        env.render()
    gal = [c for label, c in labels if label.startswith("GAL (")]
    assert gal == [SYSTEM_COLOURS["GAL"]]
    assert len(set(SYSTEM_COLOURS.values())) == len(FILE_SYSTEMS)
