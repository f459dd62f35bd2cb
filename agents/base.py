"""The policy protocol shared by heuristics, random and trained policies.

A policy maps the observations of the UAVs still flying to their actions. It is bound to an
environment when it is made (:func:`coopnav_env.agents.make_policy`), so it knows the agents'
spaces and, for the heuristics, the map and the goal (which a real UAV would have); it never
sees the true positions.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Policy", "clip_actions"]


@runtime_checkable
class Policy(Protocol):
    """What every policy provides.

    Attributes
    ----------
    name : str
        Registry name (``"random"``, ``"column"``, ``"sky_column"``, ``"ppo:<path>"``).
    """

    name: str

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode; ``seed`` makes a stochastic policy repeat exactly."""
        ...

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Actions for the agents present in ``observations``.

        Parameters
        ----------
        observations : mapping of str to ndarray
            One observation per agent still flying (PettingZoo's ``obs`` dict).

        Returns
        -------
        dict of str to ndarray
            One float32 action of shape ``(3,)`` in ``[-1, 1]`` per agent of
            ``observations``.
        """
        ...


def clip_actions(actions: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Clip every action to ``[-1, 1]`` and cast it to float32 (returns new arrays)."""
    return {
        a: np.clip(np.asarray(v, dtype=np.float64), -1.0, 1.0).astype(np.float32)
        for a, v in actions.items()
    }
