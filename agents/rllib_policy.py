"""A policy trained on Ray RLlib (``coopnav train --backend rllib``) behind the policy protocol.

``rllib:<path>`` in :func:`coopnav_env.agents.make_policy` and ``coopnav evaluate``. The path
may be an algorithm checkpoint (``DIR/final_model``, ``DIR/checkpoints/rllib_<N>_steps``), a
run folder (its ``final_model``), or the checkpoint of the RLModule itself. Only the RLModule
is loaded: no Ray cluster is started.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["RLlibPolicy", "resolve_rllib_module"]

_MODULE_SUBDIR = ("learner_group", "learner", "rl_module")


def resolve_rllib_module(path: str | Path, module_id: str = "shared") -> Path:
    """The folder of the RLModule ``module_id`` saved under ``path``.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist, or holds no RLlib checkpoint of that module; the message
        names the path.
    """
    p = Path(path).expanduser()
    if not p.exists():
        raise FileNotFoundError(f"RLlib checkpoint not found: {p}")
    if (p / "final_model").is_dir() and not (p / "rllib_checkpoint.json").is_file():
        p = p / "final_model"  # a run folder
    candidates = [p.joinpath(*_MODULE_SUBDIR, module_id), p / module_id, p]
    for c in candidates:
        if (c / "module_state.pkl").is_file() or any(c.glob("module_state*")):
            return c
    raise FileNotFoundError(
        f"no RLlib policy {module_id!r} in {p} (expected an algorithm checkpoint written by "
        "`coopnav train --backend rllib`, e.g. RUN/final_model or RUN/checkpoints/rllib_<N>_steps)"
    )


class RLlibPolicy:
    """Actions of the shared RLModule of a run of ``coopnav train --backend rllib``.

    Every UAV is driven by the same network (parameter sharing): the observations of the
    agents are stacked into one batch and passed to ``forward_inference``.

    Parameters
    ----------
    env : pettingzoo.ParallelEnv
        The environment the policy will act in; its observation and action spaces must match
        the module's.
    path : str or Path
        Checkpoint (see :func:`resolve_rllib_module`).
    deterministic : bool, default True
        Use the mode of the action distribution (True) or sample from it (False; then seeded
        by :meth:`reset` through torch's global generator).
    module_id : str, default "shared"

    Raises
    ------
    FileNotFoundError
        No such checkpoint.
    ImportError
        Ray RLlib is not installed (the message says how to install it).
    ValueError
        The module was trained on different observation or action spaces.
    """

    def __init__(
        self,
        env: Any,
        path: str | Path,
        deterministic: bool = True,
        module_id: str = "shared",
    ):
        self.path = resolve_rllib_module(path, module_id)  # before the slow imports
        try:
            import torch
            from ray.rllib.core import Columns
            from ray.rllib.core.rl_module.rl_module import RLModule
        except ImportError as exc:
            raise ImportError(
                f"policy 'rllib:{path}' needs Ray RLlib and torch ({exc}); install the extra "
                'with: pip install -e ".[ray]"'
            ) from exc

        self._torch = torch
        self._columns = Columns
        self.name = f"rllib:{path}"
        self.deterministic = bool(deterministic)
        self.module = RLModule.from_checkpoint(str(self.path.absolute()))
        self.module.eval()
        self._dist_cls = self.module.get_inference_action_dist_cls()
        agent = env.possible_agents[0]
        obs_space, act_space = env.observation_space(agent), env.action_space(agent)
        m_obs, m_act = self.module.observation_space, self.module.action_space
        if m_obs is not None and m_obs.shape != obs_space.shape:
            raise ValueError(
                f"{self.path} was trained on observations of shape {m_obs.shape}, the "
                f"environment gives {obs_space.shape} (different n_uavs or observation settings?)"
            )
        if m_act is not None and m_act.shape != act_space.shape:
            raise ValueError(
                f"{self.path} was trained on actions of shape {m_act.shape}, the environment "
                f"expects {act_space.shape}"
            )
        self._low = np.asarray(act_space.low, dtype=np.float64)
        self._high = np.asarray(act_space.high, dtype=np.float64)

    def reset(self, seed: int | None = None) -> None:
        """Nothing to do for deterministic actions; seeds torch when sampling."""
        if not self.deterministic and seed is not None:
            self._torch.manual_seed(seed)

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The policy's actions for the stacked observations of all agents.

        RLlib trains in the normalised action space ``[-1, 1]`` (``normalize_actions``) and
        maps to the env's bounds when acting; this does the same (clip, then rescale).
        """
        agents = list(observations)
        if not agents:
            return {}
        torch = self._torch
        batch = np.stack([np.asarray(observations[a], dtype=np.float32) for a in agents])
        with torch.no_grad():
            out = self.module.forward_inference({self._columns.OBS: torch.from_numpy(batch)})
            dist = self._dist_cls.from_logits(out[self._columns.ACTION_DIST_INPUTS])
            if self.deterministic:
                dist = dist.to_deterministic()
            actions = dist.sample().cpu().numpy().astype(np.float64).reshape(len(agents), -1)
        actions = np.clip(actions, -1.0, 1.0)
        actions = self._low + (actions + 1.0) * 0.5 * (self._high - self._low)
        return {a: actions[i].astype(np.float32) for i, a in enumerate(agents)}
