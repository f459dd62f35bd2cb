"""Bit-identity of episodes with integrity monitoring on (the integrity-off episodes are pinned
by ``test_golden.py``).

The digests (:func:`tests.envs.golden.episode_digest`: every observation, reward,
termination, truncation, info -- protection levels, integrity status, FDE figures included --
and state) were recorded before the integrity kernels were restructured for speed (the
statistics' loops nested for throughput, the small matrices in scalars, no reference
counting; ``benchmarks/bench_integrity.py``): the restructured kernels must give every
number bit for bit. The cases cover FDE without faults (the default reception), the
``urban_nlos`` reception with one-sided exclusion, the 3D-mapping-aided exclusion, and
detection only (``raim``) at a shared centroid with SDT, the protection levels in the
observation and the integrity penalty in the reward.
"""

from __future__ import annotations

import pytest

from tests.envs.golden import episode_digest

_URBAN_NLOS = {
    "nlos_probability": 0.5,
    "nlos_bias_mean_m": 30.0,
    "nlos_bias_floor_m": 3.0,
    "integrity": "fde",
    "integrity_fault_sign": "positive",
    "alert_limit_m": 30.0,
}

#: (name, environment keyword arguments, steps, seed)
CASES = (
    ("n5_fde", {"n_uavs": 5, "integrity": "fde"}, 150, 7),
    ("n5_urban_nlos", {"n_uavs": 5, **_URBAN_NLOS}, 120, 3),
    (
        "n5_urban_nlos_3dma",
        {"n_uavs": 5, **_URBAN_NLOS, "nlos_exclusion": "map", "max_fix_sigma_m": 15.0},
        120,
        5,
    ),
    (
        "n4_raim_shared_sdt",
        {
            "n_uavs": 4,
            "integrity": "raim",
            "centroid": "shared",
            "transfer": "sdt",
            "nlos_probability": 0.3,
            "integrity_penalty": 0.05,
            "obs_protection_level": True,
        },
        100,
        11,
    ),
)

RECORDED = {
    "n5_fde": "fa0101f097ae26789a2c8cf59e4bf14cd55b9a68169a04745419b7356c6448e6",
    "n5_urban_nlos": "9369ceae286acf3589b949beacc9e060c7dd27006c5c8f5dd101ae60641e00b1",
    "n5_urban_nlos_3dma": "d40d3c8a2521089f5a2e09fc65eacf94f2067e137a605ad8f4285585524628f6",
    "n4_raim_shared_sdt": "2998b23151f2847f98fb4a0bf1ffa30ffbf9e2e9aa02f3fcae8effe51f3d8039",
}


@pytest.mark.parametrize(("name", "kwargs", "steps", "seed"), CASES, ids=[c[0] for c in CASES])
def test_integrity_episode_is_bit_identical_to_the_recorded_one(name, kwargs, steps, seed):
    assert episode_digest(kwargs, steps, seed) == RECORDED[name]


if __name__ == "__main__":  # python -m tests.envs.test_integrity_golden prints the digests
    for name, kwargs, steps, seed in CASES:
        print(f'    "{name}": "{episode_digest(kwargs, steps, seed)}",')
