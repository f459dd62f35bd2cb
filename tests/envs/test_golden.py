"""Bit-identity of fixed-seed episodes across performance work.

The digests below are fingerprints of fixed-seed episodes (``python -m tests.envs.golden``
prints them). An optimisation that keeps every observation, reward, termination, truncation,
info and state bit for bit leaves them alone; one that changes the order of floating-point
operations must say so and update them.

History: the first digests were recorded before the speed work of issue 6 and held through
the vectorised line of sight, the satellite-geometry cache and the batched vector environment.
They were regenerated when the Gauss-Newton loops of the solvers moved into compiled kernels
(``coopnav_env.nav._kernels``): same algebra, different summation order, so navigation
solutions differ by about 1e-10 m and observations by at most one float32 ulp (or 1e-7
for values near zero). The test
below pins that: an episode run with the numpy formulation of the solvers stays within those
bounds of the same episode with the kernels.
"""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.nav import cooperative, wls
from tests.envs.golden import CASES, episode_digest

GOLDEN: dict[str, str] = {
    "n5_grid": "895711970bba6636a81eccefb9252cf80b2acc956af29c203df90cd4827062fe",
    "n20_grid": "26b0ee5a09d9f478d6411572f878cb87a74a7fb6faf3d38b74040adae6a8407b",
    "n6_nlos_fixed_city": "fa86896b2893bf3c14cb5cc88919349fc880904284151c68d03f14c8540d100f",
    "n4_canyon_sdt": "d5fec23427183069381414a60bf33ccc0f9a85a0f22701cc77684c9e8df477f1",
}


@pytest.mark.parametrize(("name", "kwargs", "steps", "seed"), CASES, ids=[c[0] for c in CASES])
def test_episode_is_bit_identical_to_the_recorded_one(name, kwargs, steps, seed) -> None:
    assert episode_digest(kwargs, steps, seed) == GOLDEN[name]


def _episode(n_uavs: int, seed: int, steps: int, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    env = urban_canyon_v0.parallel_env(n_uavs=n_uavs, **kwargs)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    obs, rew = [], []
    for _ in range(steps):
        act = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        o, r, _, _, _ = env.step(act)
        obs.append(np.stack([o[a] for a in sorted(o)]))
        rew.append([r[a] for a in sorted(r)])
        if not env.agents:
            env.reset()
    return np.concatenate(obs), np.concatenate(rew)


@pytest.mark.parametrize(
    ("n_uavs", "seed", "kwargs"), [(5, 7, {}), (4, 3, {"city": "canyon", "transfer": "sdt"})]
)
def test_compiled_solvers_change_episodes_only_in_the_last_bits(monkeypatch, n_uavs, seed, kwargs):
    fast_obs, fast_rew = _episode(n_uavs, seed, 150, **kwargs)
    monkeypatch.setattr(cooperative, "_USE_KERNEL", False)
    monkeypatch.setattr(wls, "_USE_KERNEL", False)
    ref_obs, ref_rew = _episode(n_uavs, seed, 150, **kwargs)
    assert fast_obs.shape == ref_obs.shape
    # at most one float32 ulp of the value, or 1e-7 for values near zero (differences of
    # larger numbers, whose own rounding is that large)
    tol = np.maximum(np.spacing(np.abs(ref_obs).astype(np.float32)), 1e-7)
    assert np.all(np.abs(fast_obs - ref_obs) <= tol)
    assert np.abs(fast_rew - ref_rew).max() < 1e-8
