"""The fused step on cities of extruded polygons (generated families, OpenStreetMap files):
copy k of a batch equals a separate environment stepped through ``UrbanWorld.step``."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v1
from coopnav_env.envs import BatchedUrbanCanyonEnv, _fused
from coopnav_env.envs._fused import fused_settings
from coopnav_env.sim.file_city import ExtrudedBuildings
from coopnav_env.sim.real_suite import REAL_SUITE
from tests.envs.test_batched import assert_same_records

pytestmark = [
    pytest.mark.filterwarnings("ignore:city file .* default height:UserWarning"),
    pytest.mark.filterwarnings("ignore:.*left out .* records:UserWarning"),
]


def _batch_and_separate(k_copies: int, settings: dict):
    big = BatchedUrbanCanyonEnv.from_envs(
        [urban_canyon_v1.parallel_env(**settings) for _ in range(k_copies)]
    )
    single = [urban_canyon_v1.parallel_env(**settings) for _ in range(k_copies)]
    return big, single


def _step_alongside(monkeypatch, big, single, seed: int, steps: int, route: bool) -> dict:
    """Step the batch (fused) and the separate environments (``UrbanWorld.step``) with the
    same actions, asserting equal bytes; returns what the episodes met."""
    n = big.n_agents
    agents = single[0].possible_agents
    obs, _ = big.reset(seed=seed)
    for k, env in enumerate(single):
        o, _ = env.reset(seed=seed + k)
        assert obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
    rng = np.random.default_rng(seed)
    met = {"end_steps": set(), "collided": 0, "cities": {k: set() for k in range(len(single))}}
    for step in range(steps):
        act = rng.uniform(-1.2, 1.2, (len(single), n, 3))
        if route:
            act[..., 0] = rng.uniform(0.5, 1.2, act.shape[:2])  # fast: corners crash
        for k, env in enumerate(big.envs):
            met["cities"][k].add(id(env.world.city))
        out = big.step_arrays(act)
        assert big._fused_step.state is not None  # the batch took the fused step
        assert big._fused_step.state.is_poly.all()
        met["collided"] += int(out.info["collided"].sum())
        monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
        for k, env in enumerate(single):
            o, r, te, tr, info = env.step({a: act[k, j] for j, a in enumerate(agents)})
            assert out.final_obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
            assert out.rewards[k].tobytes() == np.array([r[a] for a in agents]).tobytes()
            assert out.terminated[k] == te[agents[0]] and out.truncated[k] == tr[agents[0]]
            for key, arr in out.info.items():
                ref = np.array([info[a][key] for a in agents], dtype=arr.dtype)
                assert ref.tobytes() == arr[k].tobytes(), key
            if not env.agents:  # the batch reset this copy already: to a new city
                o, _ = env.reset()
            assert out.obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
            assert big.envs[k].state().tobytes() == env.state().tobytes()
            assert big.envs[k].world.city.source == env.world.city.source
        monkeypatch.undo()
        if (out.terminated | out.truncated).any():
            met["end_steps"].add(step)
    return met


@pytest.mark.parametrize(("frame", "max_steps", "steps"), [("route", 45, 50), ("velocity", 12, 30)])
def test_family_city_copies_equal_separate_environments_across_new_cities(
    monkeypatch, frame, max_steps, steps
) -> None:
    # the settings of the family MAPPO recipe (city="family:mixed" from a pool of city
    # seeds): copy k of a K = 8 batch through the fused step equals a separate environment
    # reset with seed + k and stepped through UrbanWorld.step, bit for bit, over episodes
    # that end at different steps (crashes, arrivals, truncations) and reset to new cities
    settings = {
        "city": "family:mixed",
        "city_pool": 200,
        "n_uavs": 5,
        "max_steps": max_steps,
        "action_frame": frame,
        "obs_agent_index": True,
        "crash_free_steps": 0,
    }
    if frame == "route":
        settings["route_turn_brake_mps2"] = 0.0
    big, single = _batch_and_separate(8, settings)
    assert fused_settings(big.config)
    met = _step_alongside(monkeypatch, big, single, seed=5, steps=steps, route=frame == "route")
    assert isinstance(big.envs[0].world.city.buildings, ExtrudedBuildings)
    assert len(met["end_steps"]) >= 3  # episodes ended at several different steps
    assert met["collided"] > 0  # the polygons' swept collisions stopped some UAVs
    # automatic resets flew new cities: every copy met more than one
    assert all(len(ids) >= 2 for ids in met["cities"].values())


def test_real_city_copies_equal_separate_environments(monkeypatch) -> None:
    # a city of the real-city suite (an OpenStreetMap extract under a RINEX sky) through the
    # fused step: copy k of a K = 8 batch equals a separate environment, bit for bit
    city = next(c for c in REAL_SUITE if c.name == "monaco_ville")
    settings = {
        **city.env_settings(),
        "n_uavs": 5,
        "max_steps": 10,
        "action_frame": "route",
        "route_turn_brake_mps2": 0.0,
        "crash_free_steps": 0,
    }
    big, single = _batch_and_separate(8, settings)
    met = _step_alongside(monkeypatch, big, single, seed=2, steps=24, route=True)
    assert big.envs[0].world.city.source.endswith("monaco.osm.pbf")
    assert len(met["end_steps"]) >= 2


@pytest.mark.parametrize(
    "settings",
    [
        {"city": "family:mixed", "n_uavs": 5, "max_steps": 12, "crash_free_steps": 0},
        {"city": "family:old_town", "n_uavs": 12, "max_steps": 8, "crash_free_steps": 0},
        {
            "city": "family:mixed",
            "city_pool": 20,
            "n_uavs": 5,
            "max_steps": 12,
            "action_frame": "route",
            "obs_agent_index": True,
        },
    ],
)
def test_fused_step_equals_the_world_step_on_polygons(monkeypatch, settings) -> None:
    # the parallel environment (a batch of one) against UrbanWorld.step: every field of every
    # epoch, the observations, rewards and infos, across resets to new cities
    def run(fused: bool) -> list:
        if not fused:
            monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
        env = urban_canyon_v1.parallel_env(**settings)
        obs, _ = env.reset(seed=8)
        rng = np.random.default_rng(4)
        out = [obs]
        for _ in range(30):
            act = {a: rng.uniform(-1.0, 1.0, 3) for a in env.agents}
            out.append(env.step(act))
            out.append(env.world.last)
            if not env.agents:
                out.append(env.reset()[0])
        assert (_fused._ONE.get(env) is not None) == fused  # which path stepped it
        monkeypatch.undo()
        return out

    fused, world = run(True), run(False)
    assert len(fused) == len(world)
    assert sum(isinstance(b, dict) for b in world) >= 3  # at least two resets
    assert_same_records(fused, world)
