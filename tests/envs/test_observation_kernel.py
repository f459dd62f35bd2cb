"""The compiled observation builder equals the numpy formulation bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0


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
        fast, ref = env._observation_array(), env._observation_array_numpy()
        assert fast.dtype == ref.dtype == np.float32 and fast.shape == ref.shape
        assert fast.tobytes() == ref.tobytes()  # signed zeros included
        env.step({a: rng.uniform(-1.5, 1.5, 3) for a in env.agents})
        if not env.agents:
            env.reset()


def test_observation_kernel_with_isolated_uavs() -> None:
    """Out of relative-sensing range of everyone: empty neighbour slots, same as numpy."""
    from coopnav_env.sim import RelativeSensingConfig

    env = urban_canyon_v0.parallel_env(
        n_uavs=4, relative_sensing=RelativeSensingConfig(max_range_m=1.0)
    )
    env.reset(seed=0)
    fast, ref = env._observation_array(), env._observation_array_numpy()
    assert not env._epoch.rel_available.any()
    assert fast.tobytes() == ref.tobytes()
