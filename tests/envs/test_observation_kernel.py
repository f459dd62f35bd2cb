"""The compiled observation builder, infos and rewards equal their numpy oracles
(``tests/envs/oracles.py``) bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from tests.envs import oracles


@pytest.mark.parametrize(
    "kwargs",
    [
        {"n_uavs": 5},
        {"n_uavs": 1},
        {"n_uavs": 3, "obs_neighbours": 6},  # more slots than neighbours
        {"n_uavs": 12, "nlos_probability": 0.3, "obs_sky_azimuths": 5},
        {"n_uavs": 4, "city": "canyon", "transfer": "sdt"},
    ],
)
def test_observation_kernel_matches_numpy(kwargs) -> None:
    env = urban_canyon_v0.parallel_env(**kwargs)
    env.reset(seed=3)
    rng = np.random.default_rng(1)
    for _ in range(60):
        fast, ref = (
            env._observation_array(),
            oracles.observation_rows(env.task, env.world, env._epoch, env._steps, env._obs_params),
        )
        assert fast.dtype == ref.dtype == np.float32 and fast.shape == ref.shape
        assert fast.tobytes() == ref.tobytes()  # signed zeros included
        env.step({a: rng.uniform(-1.5, 1.5, 3) for a in env.agents})
        if not env.agents:
            env.reset()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"n_uavs": 5},
        {"n_uavs": 12, "nlos_probability": 0.3, "max_fix_sigma_m": 3.0},  # gated fixes: NaN
        {"n_uavs": 4, "city": "canyon", "transfer": "sdt"},
    ],
)
def test_info_kernel_matches_numpy(kwargs) -> None:
    """The infos' real numbers (errors, sigmas, goal distance), bit for bit, fixes missing
    (inf errors) included."""
    env = urban_canyon_v0.parallel_env(**kwargs)
    env.reset(seed=4)
    rng = np.random.default_rng(3)
    missing = 0
    for _ in range(60):
        fast, ref = env._info_floats(), oracles.info_floats(env)
        assert fast.shape == ref.shape == (8, env._epoch.n_uavs)
        assert fast.tobytes() == ref.tobytes()
        missing += int(np.isinf(ref[1:3]).sum())
        env.step({a: rng.uniform(-1.5, 1.5, 3) for a in env.agents})
        if not env.agents:
            env.reset()
    if "max_fix_sigma_m" in kwargs:
        assert missing > 0  # the case exercises fixes that are not used


def test_navigated_distance_kernel_matches_numpy() -> None:
    """The fused step's ``navigated_distance`` terms equal their numpy oracle bit for bit, on
    random swarms with missing estimates (NaN), errors beyond the cap, routes paid off
    (negative remainders clipped) and swarms that arrived."""
    from coopnav_env.envs import _batched_kernels

    rng = np.random.default_rng(5)
    k, n, r = 64, 5, 9
    pos = rng.uniform(-300.0, 300.0, (k, n, 3))
    nav_pos = pos + rng.normal(0.0, 20.0, (k, n, 3))
    nav_pos[rng.random((k, n)) < 0.2] = np.nan  # no estimate
    route = rng.uniform(-300.0, 300.0, (k, r, 2))
    tail = np.sort(rng.uniform(0.0, 900.0, (k, r)), axis=1)[:, ::-1].copy()
    wp = rng.integers(0, r, (k, n))
    reached = rng.random(k) < 0.3
    route_len = rng.uniform(100.0, 1500.0, (k, n))
    unpaid = route_len * rng.uniform(0.0, 1.0, (k, n))
    unpaid[rng.random((k, n)) < 0.2] = 0.0  # paid off
    terms = np.zeros((k, 6, n))
    after = np.empty((k, n))
    # the kernel's records (_batched_kernels.Routes, DistanceInputs, Paid) as plain tuples
    _batched_kernels.navigated_distance_terms(
        (route, tail, np.full(k, r), np.zeros((k, 3))),
        (pos, nav_pos, wp, reached, unpaid, route_len),
        25.0,
        (terms, after),
    )
    nav, progress, ref_after = oracles.navigated_distance_rows(
        pos, nav_pos, route, tail, wp, reached, unpaid, route_len, 25.0
    )
    assert terms[:, 0].tobytes() == nav.tobytes()
    assert terms[:, 1].tobytes() == progress.tobytes()
    assert after.tobytes() == ref_after.tobytes()
    assert not terms[:, 2:].any()  # the other terms' rows untouched
    assert (nav == 0.0).any() and (nav < 0.0).any() and (progress > 0.0).any()


def test_observation_kernel_with_isolated_uavs() -> None:
    """Out of relative-sensing range of everyone: empty neighbour slots, same as numpy."""
    from coopnav_env.sim import RelativeSensingConfig

    env = urban_canyon_v0.parallel_env(
        n_uavs=4, relative_sensing=RelativeSensingConfig(max_range_m=1.0)
    )
    env.reset(seed=0)
    fast, ref = (
        env._observation_array(),
        oracles.observation_rows(env.task, env.world, env._epoch, env._steps, env._obs_params),
    )
    assert not env._epoch.rel_available.any()
    assert fast.tobytes() == ref.tobytes()


@pytest.mark.parametrize("nav_reward", ["error", "sigma"])
def test_reward_kernel_matches_numpy(monkeypatch, nav_reward) -> None:
    """Rewards, terms, in-goal flags and episode ends: identical with the kernels (the fused
    step) and with the oracles (the environment's own step)."""

    def run(use_oracles: bool):
        calls = oracles.use_oracles_in_env(monkeypatch) if use_oracles else None
        env = urban_canyon_v0.parallel_env(n_uavs=6, nav_reward=nav_reward, goal_radius_m=80.0)
        env.reset(seed=5)
        rng = np.random.default_rng(2)
        out = []
        for _ in range(60):
            cmd = rng.uniform(-1.0, 1.0, (6, 3))
            out.append(env._step_arrays(cmd))
            if out[-1][2] or out[-1][3]:
                env._reset_arrays(None)
        assert calls is None or calls["reward_terms"] == 60
        return out

    fast, ref = run(False), run(True)
    ends = 0
    for a, b in zip(fast, ref, strict=True):
        assert a[1].tobytes() == b[1].tobytes()  # rewards
        assert (a[2], a[3]) == (b[2], b[3]) and type(a[2]) is bool
        ends += a[2] or a[3]
        assert list(a[4]) == list(b[4])
        for name in a[4]:
            assert (
                np.asarray(a[4][name], dtype=float).tobytes()
                == np.asarray(b[4][name], dtype=float).tobytes()
            ), name
        np.testing.assert_array_equal(a[5], b[5])
    assert ends > 0
