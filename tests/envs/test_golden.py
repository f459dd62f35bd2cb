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
below pins that: an episode run with the numpy oracles of every kernel (``tests/*/oracles.py``)
stays within those bounds of the same episode with the kernels.

Regenerated again (third session of 2026-11-30) when the receiver-satellite geometry moved
into a compiled kernel (libm's arctan2/arcsin/sin/cos instead of numpy's: elevations differ by
~1e-13 deg), the relative covariances in ECEF became exactly ``sigma_d^2 I`` (they were
``R^T sigma_d^2 I R``, off by ~1e-16 relative), and the UAV covariance cross terms and the
ECEF-to-ENU rotation of the selected fixes became compiled loops: against the previous
digests' episodes, navigation errors moved by at most 3.4e-8 m, rewards by 3e-10 and
observations by one float32 ulp in a handful of entries. The compiled relative sensing,
statuses, solver set-up masks, nuisance-clock count, waypoint advance and observation builder
are bit-identical to their numpy formulations.

Unchanged (fourth session of 2026-11-30) by the world's cooperative solve in one compiled call
and then the whole navigation of an epoch in one (``UrbanWorld._navigate_fused``): the same
kernels on the same arguments; the test below runs the episodes both ways.

Unchanged by the fused step of every swarm of a batch (``coopnav_env.envs._fused``, which the
parallel environment takes as a batch of one): the same kernels on each swarm's own slices,
its draws in the same order, the rotations still numpy matmuls.
"""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import _fused
from tests.envs.golden import CASES, episode_digest
from tests.envs.oracles import use_all_oracles
from tests.sim.oracles import navigate_function_by_function
from tests.sim.test_fast_paths import count_fused_calls

GOLDEN: dict[str, str] = {
    "n5_grid": "d8f0692738c0173a6bf03e99fc9940188f7ec940262cc0f75be36d2e7f4cf5a1",
    "n20_grid": "d70c1acc772d3d3338082be1ee838278674d4a9ff46b80d1ea3c2fec9d4ab868",
    "n6_nlos_fixed_city": "318bedf1d2f6fec63c7971ce33745abd3acaa5471df4b3e2759896db437ad3e1",
    "n4_canyon_sdt": "d553f3ef7eab774abc40ffcafbae684070679b07b0be7acf42dbef740d580156",
}


@pytest.mark.parametrize(("name", "kwargs", "steps", "seed"), CASES, ids=[c[0] for c in CASES])
def test_episode_is_bit_identical_to_the_recorded_one(name, kwargs, steps, seed) -> None:
    assert episode_digest(kwargs, steps, seed) == GOLDEN[name]


@pytest.mark.parametrize(("name", "kwargs", "steps", "seed"), CASES, ids=[c[0] for c in CASES])
def test_fused_epoch_equals_the_modular_kernels(monkeypatch, name, kwargs, steps, seed) -> None:
    """The one-call navigation of an epoch (``UrbanWorld._navigate_fused``) against the same
    kernels called one by one from Python (``_navigate``): the same episodes, bit for bit
    (self and shared centroids, DDT and SDT, NLOS biases and the channel limit)."""
    # the world's own steps (the environment's fused step of every copy off)
    monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
    calls = count_fused_calls(monkeypatch)
    short = min(steps, 60)
    fast = episode_digest(kwargs, short, seed)
    assert calls["fused"] > short  # every epoch, resets included, went through it
    navigate_function_by_function(monkeypatch)
    calls["fused"] = 0
    assert episode_digest(kwargs, short, seed) == fast
    assert calls["fused"] == 0


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
    oracle_calls = use_all_oracles(monkeypatch)  # no compiled kernel of the library's own
    ref_obs, ref_rew = _episode(n_uavs, seed, 150, **kwargs)
    unused = {"predicted", "satellite_sectors"}  # no map-aided exclusion, no sector columns
    assert all(oracle_calls[name] > 0 for name in oracle_calls if name not in unused)
    assert fast_obs.shape == ref_obs.shape
    # at most one float32 ulp of the value, or 1e-7 for values near zero (differences of
    # larger numbers, whose own rounding is that large)
    tol = np.maximum(np.spacing(np.abs(ref_obs).astype(np.float32)), 1e-7)
    assert np.all(np.abs(fast_obs - ref_obs) <= tol)
    assert np.abs(fast_rew - ref_rew).max() < 1e-8
