"""Fingerprints of fixed-seed episodes of ``urban_canyon_v0`` (for the bit-identity tests).

:func:`episode_digest` runs ``steps`` steps of random actions from ``reset(seed=seed)``
(resetting without a seed when an episode ends, so resets and the generator's continuation
are covered too) and hashes, in order, every observation, reward, termination, truncation,
info dict (floats by ``repr``, which is exact), the global state and the reset infos.
``python -m tests.envs.golden`` prints the digests of :data:`CASES`.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import numpy as np

#: (name, environment keyword arguments, steps, seed) of the golden episodes.
CASES: tuple[tuple[str, dict[str, Any], int, int], ...] = (
    ("n5_grid", {"n_uavs": 5}, 200, 7),
    ("n20_grid", {"n_uavs": 20}, 200, 11),
    (
        "n6_nlos_fixed_city",
        {"n_uavs": 6, "nlos_probability": 0.3, "max_sats": 9, "city_seed": 3, "t0_random_s": 5e4},
        120,
        5,
    ),
    ("n4_canyon_sdt", {"n_uavs": 4, "city": "canyon", "transfer": "sdt"}, 120, 3),
)


def _update(h: Any, obj: Any) -> None:
    if isinstance(obj, np.ndarray):
        h.update(str((obj.dtype.str, obj.shape)).encode())
        h.update(np.ascontiguousarray(obj).tobytes())
    else:
        h.update(json.dumps(obj, sort_keys=True, default=repr).encode())


def _recorded_layout(infos: dict[str, dict[str, Any]], reset: bool) -> dict[str, Any]:
    """Infos in the layout the digests were recorded with (before the infos became flat).

    The flat infos (same keys at reset and step, ``reward_<term>``, a missing fix as -1 with
    the ``coop_fix`` / ``standalone_fix`` flags) carry the same numbers: converted back, the
    recorded digests still pin every value bit for bit.
    """
    from coopnav_env.envs.urban_canyon import REWARD_TERMS

    out = {}
    for agent, info in infos.items():
        old = {}
        for key, value in info.items():
            if key in ("coop_fix", "standalone_fix") or key.startswith("reward_") or key == "step":
                continue
            if key in ("coop_error_m", "standalone_error_m"):
                value = value if info[key.replace("error_m", "fix")] else float("inf")
            old[key] = value
        if reset:
            out[agent] = {
                "initial": {
                    **old,
                    "reward_terms": {t: 0.0 for t in REWARD_TERMS},
                    "step": info["step"],
                }
            }
        else:
            old["reward_terms"] = {t: info[f"reward_{t}"] for t in REWARD_TERMS}
            old["step"] = info["step"]
            out[agent] = old
    return out


def episode_digest(env_kwargs: dict[str, Any], steps: int, seed: int) -> str:
    """sha256 of everything ``steps`` random-action steps of the environment return."""
    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env(**env_kwargs)
    h = hashlib.sha256()
    rng = np.random.default_rng(seed + 1000)
    obs, infos = env.reset(seed=seed)
    _update(h, [obs[a] for a in env.possible_agents])
    _update(h, _recorded_layout(infos, reset=True))
    for _ in range(steps):
        actions = {a: rng.uniform(-1.0, 1.0, 3).astype(np.float32) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(actions)
        for part in (obs, rew, term, trunc):
            _update(h, [part[a] for a in env.possible_agents])
        _update(h, _recorded_layout(infos, reset=False))
        _update(h, env.state())
        if not env.agents:
            obs, infos = env.reset()
            _update(h, [obs[a] for a in env.possible_agents])
            _update(h, _recorded_layout(infos, reset=True))
    return h.hexdigest()


if __name__ == "__main__":
    for name, kwargs, steps, seed in CASES:
        print(f'"{name}": "{episode_digest(kwargs, steps, seed)}",')
