"""Uniformly random velocity commands (a lower bound for every other policy)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["RandomPolicy"]


class RandomPolicy:
    """Independent uniform actions in each agent's action space.

    Parameters
    ----------
    env : pettingzoo.ParallelEnv
        The environment (for the action spaces).
    seed : int or None, default None
        Used by :meth:`reset` when it is called without a seed.

    Notes
    -----
    One :class:`numpy.random.Generator`, reseeded only in :meth:`reset`; the same seed gives
    the same actions. Draws are made in the order of the ``observations`` mapping.
    """

    name = "random"

    def __init__(self, env: Any, seed: int | None = None):
        self._spaces = {a: env.action_space(a) for a in env.possible_agents}
        self._seed = seed
        self._rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        """Reseed the generator with ``seed`` (or the constructor's seed)."""
        self._rng = np.random.default_rng(self._seed if seed is None else seed)

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """One uniform draw in the action box per agent of ``observations``."""
        out = {}
        for agent in observations:
            space = self._spaces[agent]
            out[agent] = self._rng.uniform(space.low, space.high).astype(np.float32)
        return out
