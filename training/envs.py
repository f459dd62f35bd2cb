"""The environment every backend trains in and every evaluation flies, and its seed ranges.

Reset seeds are split in two ranges so that no evaluation episode was ever seen in training:

* training (every backend, the behaviour-cloning teacher included) resets its environments
  with seeds ``< EVAL_SEED_START``;
* ``coopnav evaluate`` flies the held-out seeds ``EVAL_SEED_START, EVAL_SEED_START + 1, ...``
  (:func:`heldout_seeds`).

:func:`make_env_fn` turns an environment id and its keyword arguments into a picklable
factory of fresh PettingZoo ParallelEnvs (worker processes and Ray actors call it).
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = [
    "BATCHED_ENV_IDS",
    "DEFAULT_ENV_ID",
    "EVAL_SEED_START",
    "heldout_seeds",
    "make_env_fn",
]

DEFAULT_ENV_ID: str = "urban_canyon_v1"
"""The environment of ``coopnav train`` and ``coopnav evaluate`` unless told otherwise.

``urban_canyon_v0`` is legacy: its studies name it with ``--env-id urban_canyon_v0``."""

BATCHED_ENV_IDS: tuple[str, ...] = ("urban_canyon_v1", "urban_canyon_v0")
"""The environments whose swarm copies the SB3 backend steps as one batch (``vec_env=auto``)."""

EVAL_SEED_START: int = 1_000_000
"""First held-out evaluation seed. Training reset seeds are ``< EVAL_SEED_START``."""


def heldout_seeds(n: int, start: int = EVAL_SEED_START) -> list[int]:
    """``n`` held-out evaluation seeds ``start, start + 1, ...``.

    Raises
    ------
    ValueError
        ``n < 1`` or ``start < EVAL_SEED_START`` (such seeds may have been seen in training).
    """
    if int(n) < 1:
        raise ValueError(f"the number of evaluation episodes must be >= 1, got {n}")
    if int(start) < EVAL_SEED_START:
        raise ValueError(
            f"evaluation seeds must be >= {EVAL_SEED_START} (training uses the seeds below), "
            f"got {start}"
        )
    return [int(start) + i for i in range(int(n))]


def make_env_fn(env_id: str, env_kwargs: Mapping[str, Any]) -> Callable[[], Any]:
    """A picklable function returning a fresh ParallelEnv for ``env_id`` and its kwargs.

    ``env_id`` is a module ``coopnav_env.<env_id>`` with a ``parallel_env`` function, or
    ``"package.module:callable"`` returning a PettingZoo ParallelEnv (used by the tests).

    Raises
    ------
    ValueError
        No such environment module.
    """
    if ":" in env_id:
        mod_name, _, attr = env_id.partition(":")
        factory = getattr(importlib.import_module(mod_name), attr)
    else:
        try:
            mod = importlib.import_module(f"coopnav_env.{env_id}")
        except ModuleNotFoundError as exc:
            raise ValueError(
                f"unknown environment {env_id!r} (no module coopnav_env.{env_id})"
            ) from exc
        factory = mod.parallel_env
    return functools.partial(factory, **dict(env_kwargs))
