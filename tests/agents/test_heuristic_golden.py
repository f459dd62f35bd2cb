"""Golden episodes of the hand-written policies: every step's actions, bit for bit.

Each case flies a policy name accepted by :func:`coopnav_env.agents.make_policy` (the
heuristics, some with ``@`` options, and a residual MARL policy over a column) for a few
short episodes in the default environment and under realistic urban reception, and compares a
hash of every step's actions (agent names and float32 commands) with the ones stored in
``heuristic_golden.npz``; the residual MARL policy's episodes are stored as its actions and
compared within :data:`TORCH_ACTION_ATOL` (torch's CPU kernels round differently on other
processors). (The studies' own policies built on the column heuristics have
golden episodes of their own in their studies' tests, flown by :func:`fly`.)

The stored hashes are what the policies did when the file was written; a change to a policy,
to the environment or to the numerical libraries that changes any action by one bit fails
here, naming the case, the seed and the first step that differs. After an intended change,
regenerate the file with::

    python -m tests.agents.test_heuristic_golden

(:func:`write_golden`) and commit it with the change that explains it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

HAS_ENV = importlib.util.find_spec("coopnav_env.urban_canyon_v0") is not None
HAS_TORCH = importlib.util.find_spec("torch") is not None

GOLDEN_PATH: Path = Path(__file__).with_name("heuristic_golden.npz")
"""The stored step hashes, one array per case and seed (see :func:`case_key`)."""

#: environment settings the cases fly in: the defaults, and realistic urban reception with a
#: drifting dead reckoning (where the wall guard and the ceiling matter)
ENVIRONMENTS: dict[str, dict[str, Any]] = {
    "default": {},
    "urban_nlos_3dma": {"preset": "urban_nlos_3dma", "dead_reckoning_noise": True},
}

_DEFAULT_SEEDS = (1001, 1002, 1003)
_NLOS_SEEDS = (2001, 2002)
_STEPS = 60

#: (policy name, environment, reset seeds, most steps per episode)
CASES: tuple[tuple[str, str, tuple[int, ...], int], ...] = (
    *(
        (name, env, seeds, _STEPS)
        for name in (
            "column",
            "sky_column",
            "stretched_column",
            "wide_column",
            "guarded_column",
            "ceiling_column",
            "best_sky_route",
            "waypoint",
        )
        for env, seeds in (("default", _DEFAULT_SEEDS), ("urban_nlos_3dma", _NLOS_SEEDS))
    ),
    ("column@cruise_speed_mps=5,spacing_m=10", "default", _DEFAULT_SEEDS, _STEPS),
    ("waypoint@altitude_m=28,cruise_speed_mps=5", "default", _DEFAULT_SEEDS, _STEPS),
    (
        "sky_column@max_offset_m=2,smoothing=0.5,ceiling_margin_m=-3",
        "default",
        _DEFAULT_SEEDS,
        _STEPS,
    ),
    ("wide_column@spacing_m=30", "default", _DEFAULT_SEEDS, _STEPS),
    (
        "wide_column@spacing_m=30,goal_spacing_m=8,open_distance_m=50",
        "default",
        _DEFAULT_SEEDS,
        _STEPS,
    ),
    ("guarded_column@ceiling_margin_m=-10", "urban_nlos_3dma", _NLOS_SEEDS, _STEPS),
    ("mappo:pretrained", "default", _DEFAULT_SEEDS[:2], _STEPS),
    ("mappo:{degraded_study}/mappo_nlos_ceiling_s0", "urban_nlos_3dma", _NLOS_SEEDS, _STEPS),
)
"""The golden cases; ``{degraded_study}`` in a name stands for the policies folder of
``studies/learning_under_degraded_navigation`` (:data:`PLACEHOLDERS`)."""

PLACEHOLDERS: dict[str, Path] = {
    "{degraded_study}": Path(__file__).resolve().parents[2]
    / "studies"
    / "learning_under_degraded_navigation"
    / "policies",
}
"""The folders that placeholders in a case's policy name stand for."""


def policy_of_case(name: str) -> str:
    """A case's policy name with its placeholders (:data:`PLACEHOLDERS`) filled in."""
    for placeholder, folder in PLACEHOLDERS.items():
        name = name.replace(placeholder, str(folder))
    return name


def case_key(policy: str, env_name: str, seed: int) -> str:
    """The name of a case's array in the golden file."""
    return f"{env_name}|{policy}|{seed}"


def step_hash(actions: dict[str, np.ndarray]) -> np.uint64:
    """First 8 bytes of the SHA-256 of a step's agent names and float32 actions."""
    h = hashlib.sha256()
    for agent, action in actions.items():
        h.update(agent.encode())
        h.update(np.ascontiguousarray(action, dtype=np.float32).tobytes())
    return np.frombuffer(h.digest()[:8], dtype=np.uint64)[0]


#: policies whose actions come out of torch networks: torch's CPU kernels may sum in another
#: order on another processor (its vector instructions), so their episodes are stored as the
#: actions themselves and compared within :data:`TORCH_ACTION_ATOL` instead of by hash
_TORCH_PREFIXES = ("mappo:", "ippo:")

TORCH_ACTION_ATOL: float = 1e-4
"""Largest difference of a torch policy's action entry (in ``[-1, 1]``) from the stored one:
a float32 network differs by a few units in the last place (about 1e-7) between processors,
which the closed loop can grow over 60 steps; a changed policy, observation or environment
moves actions by far more."""


def is_torch_case(policy_name: str) -> bool:
    """Whether a case's policy is a torch network (:data:`_TORCH_PREFIXES`)."""
    return policy_name.startswith(_TORCH_PREFIXES)


def fly(policy_name: str, env_name: str, seed: int, steps: int) -> np.ndarray:
    """Fly ``policy_name`` for at most ``steps`` steps from reset seed ``seed``: the hash of
    every step's actions (uint64, one per step flown), or for a torch policy
    (:func:`is_torch_case`) the actions themselves (float32, ``(steps, n_uavs * 3)``)."""
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy

    env = urban_canyon_v0.parallel_env(**ENVIRONMENTS[env_name])
    try:
        policy = make_policy(policy_of_case(policy_name), env)
        obs, _ = env.reset(seed=seed)
        policy.reset(seed=seed)
        hashes = []
        for _ in range(steps):
            if not env.agents:
                break
            actions = policy.act(obs)
            if is_torch_case(policy_name):
                hashes.append(np.concatenate([np.asarray(a, np.float32) for a in actions.values()]))
            else:
                hashes.append(step_hash(actions))
            obs, *_ = env.step(actions)
    finally:
        env.close()
    if is_torch_case(policy_name):
        return np.asarray(hashes, dtype=np.float32)
    return np.asarray(hashes, dtype=np.uint64)


def golden_arrays() -> dict[str, np.ndarray]:
    """Fly every case of :data:`CASES`: the arrays :func:`write_golden` stores."""
    return {
        case_key(policy, env_name, seed): fly(policy, env_name, seed, steps)
        for policy, env_name, seeds, steps in CASES
        for seed in seeds
    }


def write_golden(path: Path = GOLDEN_PATH) -> Path:
    """Fly every case and write the step hashes to ``path`` (through a temporary file)."""
    arrays = golden_arrays()
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


def _stored() -> dict[str, np.ndarray]:
    with np.load(GOLDEN_PATH) as data:
        return {k: data[k] for k in data.files}


#: slow cases (torch): with ``-m slow`` only
_SLOW_PREFIXES = _TORCH_PREFIXES


def _params() -> list[Any]:
    return [
        pytest.param(
            case,
            id=f"{case[1]}-{case[0]}",
            marks=[pytest.mark.slow] if case[0].startswith(_SLOW_PREFIXES) else [],
        )
        for case in CASES
    ]


@pytest.mark.skipif(not HAS_ENV, reason="coopnav_env.urban_canyon_v0 not available")
@pytest.mark.parametrize("case", _params())
def test_actions_match_the_golden_episodes(case) -> None:
    policy, env_name, seeds, steps = case
    if policy.startswith("mappo:") and not HAS_TORCH:
        pytest.skip("the residual MARL policy needs torch")
    stored = _stored()
    for seed in seeds:
        want = stored[case_key(policy, env_name, seed)]
        got = fly(policy, env_name, seed, steps)
        assert want.size > 0
        if is_torch_case(policy):
            assert got.shape == want.shape, f"{policy!r}, seed {seed}: flew {got.shape} steps"
            np.testing.assert_allclose(got, want, rtol=0, atol=TORCH_ACTION_ATOL)
            continue
        if got.shape != want.shape or not np.array_equal(got, want):
            n = min(got.size, want.size)
            diff = np.flatnonzero(got[:n] != want[:n])
            first = int(diff[0]) if diff.size else n
            pytest.fail(
                f"{policy!r} in {env_name}, seed {seed}: actions differ from the golden "
                f"episode from step {first} (flew {got.size} steps, stored {want.size})"
            )


def test_the_golden_file_holds_every_case_and_nothing_else() -> None:
    want = {case_key(p, e, s) for p, e, seeds, _ in CASES for s in seeds}
    assert set(_stored()) == want


def test_the_step_hash_sees_one_bit() -> None:
    a = {"uav_0": np.array([0.5, -0.25, 0.0], np.float32)}
    b = {"uav_0": np.nextafter(a["uav_0"], np.float32(1.0))}
    assert step_hash(a) == step_hash({"uav_0": a["uav_0"].copy()})
    assert step_hash(a) != step_hash(b)
    assert step_hash(a) != step_hash({"uav_1": a["uav_0"]})


if __name__ == "__main__":
    print(f"written {write_golden()}")
