"""Golden episodes of the study's route policies (studies.route_choice.routes): every step's
actions, bit for bit, as tests/agents/test_heuristic_golden.py does for the library's
heuristics (its :func:`fly` flies them; the hashes are in ``route_golden.npz``).

After an intended change, regenerate the file with::

    python -m studies.route_choice.tests.test_route_golden
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

import studies.route_choice.routes  # noqa: F401  (registers the study's policies)
from tests.agents.test_heuristic_golden import case_key, fly

GOLDEN_PATH: Path = Path(__file__).with_name("route_golden.npz")

_DEFAULT_SEEDS = (1001, 1002, 1003)
_NLOS_SEEDS = (2001, 2002)
_STEPS = 60

#: (policy name, environment of tests.agents.test_heuristic_golden, reset seeds, most steps)
CASES: tuple[tuple[str, str, tuple[int, ...], int], ...] = (
    ("route_column@preset='stretched_column',route_index=1", "default", _DEFAULT_SEEDS, _STEPS),
    ("route_column@preset='wide_column',route_split_index=1", "default", _DEFAULT_SEEDS, _STEPS),
    (
        "route_column@preset='ceiling_column',route_choice='swarm_mean'",
        "urban_nlos_3dma",
        _NLOS_SEEDS,
        _STEPS,
    ),
    (
        "route_column@preset='best_sky_route',route_split='pdop_gt3'",
        "default",
        _DEFAULT_SEEDS,
        _STEPS,
    ),
    ("learned_route@model='pretrained'", "urban_nlos_3dma", _NLOS_SEEDS, _STEPS),
    ("learned_split@model='pretrained'", "urban_nlos_3dma", _NLOS_SEEDS, _STEPS),
)


def _stored() -> dict[str, np.ndarray]:
    with np.load(GOLDEN_PATH) as data:
        return {k: data[k] for k in data.files}


@pytest.mark.parametrize("case", CASES, ids=[f"{c[1]}-{c[0]}" for c in CASES])
def test_actions_are_bit_identical_to_the_golden_episodes(case) -> None:
    policy, env_name, seeds, steps = case
    stored = _stored()
    for seed in seeds:
        want = stored[case_key(policy, env_name, seed)]
        got = fly(policy, env_name, seed, steps)
        assert want.size > 0
        assert got.shape == want.shape and np.array_equal(got, want), (
            f"{policy!r} in {env_name}, seed {seed}: actions differ from the golden episode"
        )


def test_the_golden_file_holds_every_case_and_nothing_else() -> None:
    assert set(_stored()) == {case_key(p, e, s) for p, e, seeds, _ in CASES for s in seeds}


def write_golden(path: Path = GOLDEN_PATH) -> Path:
    """Fly every case and write the step hashes to ``path`` (through a temporary file)."""
    arrays = {case_key(p, e, s): fly(p, e, s, n) for p, e, seeds, n in CASES for s in seeds}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".npz")
    os.close(fd)
    try:
        np.savez_compressed(tmp, **arrays)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


if __name__ == "__main__":
    print(f"written {write_golden()}")
