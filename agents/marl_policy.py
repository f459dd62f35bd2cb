"""A policy trained by ``coopnav train --backend torchrl`` (MAPPO or IPPO), for evaluation.

The checkpoint (``final_model.pt`` or ``checkpoints/marl_<N>_steps.pt``, or the run folder)
holds the actor's weights, the backend's settings and the environment settings it was trained
in. :class:`MARLPolicy` acts deterministically (the Gaussian's mean), as PPO evaluations do;
a residual policy (``residual_base``) rebuilds its base heuristic on the evaluation
environment and adds the learned command to it, exactly as in training. The critic is not
needed to act and is not loaded.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.agents.marl_nets import (
    base_command_before,
    build_modules,
    load_marl_checkpoint,
    settings_from_record,
    swarm_command,
)

__all__ = [
    "ACT_KEYS",
    "PRETRAINED_DIR",
    "RESUME_KEYS",
    "MARLPolicy",
    "check_marl_checkpoint",
    "load_checked_checkpoint",
    "resolve_marl_checkpoint",
]

ACT_KEYS: tuple[str, ...] = (
    "settings",
    "env_kwargs",
    "n_agents",
    "actor_dim",
    "critic_dim",
    "actor",
)
"""Entries a checkpoint needs to be flown (an exported policy has these only)."""

RESUME_KEYS: tuple[str, ...] = (
    *ACT_KEYS,
    "critic",
    "optimizer",
    "reward_std",
    "agent_steps",
    "iterations",
)
"""Entries a checkpoint needs to be resumed."""


PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"
"""The shipped TorchRL actors, one folder ``<algorithm>_<name>`` each (``final_model.pt`` holds
the actor only, ``config.yaml`` and ``run.json`` its training run): ``mappo:pretrained/<name>``
flies ``mappo_<name>``, e.g. ``mappo:pretrained/route_s0`` the policy of training seed 0 of the
packaged configuration ``mappo_route``, ``mappo:pretrained/route_scratch_s0`` that of
``mappo_route_scratch``."""


def resolve_marl_checkpoint(path: str | Path, algorithm: str = "mappo") -> Path:
    """The checkpoint file of ``path``: the file itself, or ``final_model.pt`` of a run folder.

    ``pretrained/<name>`` names the shipped policy in the folder ``<algorithm>_<name>`` of
    :data:`PRETRAINED_DIR` (``mappo:pretrained/route_s0``: ``mappo_route_s0``), and
    ``pretrained`` alone that of ``pretrained/s0``.
    """
    text = str(path)
    if text == "pretrained" or text.startswith("pretrained/"):
        seed = text.partition("/")[2] or "s0"
        folder = PRETRAINED_DIR / f"{algorithm}_{seed}"
        if not folder.is_dir():
            have = sorted(
                f"{algorithm}:pretrained/{p.parent.name.removeprefix(algorithm + '_')}"
                for p in PRETRAINED_DIR.glob(f"{algorithm}_*/final_model.pt")
            )
            raise FileNotFoundError(
                f"no shipped policy {algorithm}:{text}; shipped: {', '.join(have) or 'none'}"
            )
        path = folder
    p = Path(path)
    if p.is_dir():
        p = p / "final_model.pt"
    if not p.is_file():
        raise FileNotFoundError(
            f"no TorchRL checkpoint at {path} (expected a .pt file of `coopnav train --backend "
            "torchrl` or its run folder)"
        )
    return p


def check_marl_checkpoint(d: Mapping[str, Any], path: str | Path, purpose: str = "fly") -> None:
    """Refuse a checkpoint that lacks entries or holds non-finite weights.

    Parameters
    ----------
    d : mapping
        What :func:`coopnav_env.agents.marl_nets.load_marl_checkpoint` read from ``path``.
    path : path
        Named in the messages.
    purpose : {"fly", "resume"}
        ``resume`` needs the critic, the optimiser and the counters too (:data:`RESUME_KEYS`);
        ``fly`` the actor and its settings (:data:`ACT_KEYS`).

    Raises
    ------
    ValueError
        Naming the file and the missing entries, or the weights that are NaN or infinite
        (a diverged training).
    """
    import torch

    if purpose not in ("fly", "resume"):
        raise ValueError(f"purpose must be 'fly' or 'resume', got {purpose!r}")
    if purpose == "resume" and d.get("policy_only"):
        raise ValueError(
            f"{path} is an exported policy (actor only, export_policy): it can be evaluated "
            "but not resumed; resume from the run's own checkpoint"
        )
    keys = RESUME_KEYS if purpose == "resume" else ACT_KEYS
    missing = [k for k in keys if k not in d]
    if missing:
        raise ValueError(
            f"{path} is not a complete TorchRL checkpoint: it lacks {', '.join(missing)} "
            f"(needed to {purpose} it)"
        )
    bad = []
    for net in ("actor", "critic") if purpose == "resume" else ("actor",):
        weights = d[net]
        if not isinstance(weights, Mapping):
            raise ValueError(f"{path} is not a TorchRL checkpoint: its {net} holds no weights")
        for name, t in weights.items():
            if torch.is_tensor(t) and t.is_floating_point() and not bool(torch.isfinite(t).all()):
                bad.append(f"{net}.{name}")
    if bad:
        more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
        done = {"fly": "flown", "resume": "resumed"}[purpose]
        raise ValueError(
            f"{path} holds non-finite weights (NaN or inf) in {', '.join(bad[:3])}{more}: the "
            f"training that wrote it diverged, so it cannot be {done}; use an earlier checkpoint"
        )


def load_checked_checkpoint(path: str | Path, purpose: str = "fly") -> dict[str, Any]:
    """:func:`~coopnav_env.agents.marl_nets.load_marl_checkpoint` followed by
    :func:`check_marl_checkpoint` (``ValueError`` naming the file when it fails)."""
    d = load_marl_checkpoint(path)
    check_marl_checkpoint(d, path, purpose)
    return d


class MARLPolicy:
    """Deterministic shared actor of a TorchRL MAPPO/IPPO checkpoint.

    Parameters
    ----------
    env : urban_canyon_v0 ParallelEnv
        The environment to act in (its observation size must match the checkpoint's).
    path : str or Path
        Checkpoint file or run folder.
    algorithm : str, optional
        ``mappo`` or ``ippo``: which shipped policies ``pretrained`` names, and the algorithm
        the checkpoint must have been trained with (a MAPPO run given as ``ippo:`` is refused,
        and the reverse, so that no policy is flown under another label). None: either
        (``pretrained`` then names the MAPPO policy).
    make_base : callable, optional
        ``make_base(name, env, **options)`` builds the base heuristic of a residual policy
        (:func:`coopnav_env.agents.make_policy`, which passes itself).
    """

    name = "mappo"

    def __init__(
        self, env: Any, path: str | Path, make_base: Any = None, algorithm: str | None = None
    ) -> None:
        import torch

        if algorithm is not None and algorithm not in ("mappo", "ippo"):
            raise ValueError(f"algorithm must be 'mappo', 'ippo' or None, got {algorithm!r}")
        file = resolve_marl_checkpoint(path, algorithm or "mappo")
        ckpt = load_checked_checkpoint(file, "fly")
        #: the settings as the checkpoint records them (settings removed since included)
        self.recorded_settings: dict[str, Any] = dict(ckpt["settings"])
        self.settings = settings_from_record(self.recorded_settings, file, "fly")
        if algorithm is not None and self.settings.algorithm != algorithm:
            true = self.settings.algorithm
            raise ValueError(
                f"{algorithm}:{path} was trained with {true.upper()} (torchrl.algorithm {true} "
                f"in {file}), not {algorithm.upper()}: refused, so that it is not flown under "
                f"the wrong label; fly it as {true}:{path}"
            )
        self.name = self.settings.algorithm
        self.env = env
        base_env = getattr(env, "unwrapped", env)
        self.agents = list(base_env.possible_agents)
        n = len(self.agents)
        if n != int(ckpt["n_agents"]):
            raise ValueError(
                f"the checkpoint was trained with {ckpt['n_agents']} UAVs, the environment has {n}"
            )
        obs_dim = int(base_env.observation_space(self.agents[0]).shape[0])
        extra = self.settings.actor_extra_inputs
        if obs_dim + extra != int(ckpt["actor_dim"]):
            raise ValueError(
                f"observation size {obs_dim} does not match the checkpoint's actor input "
                f"{ckpt['actor_dim']} (trained in another environment configuration)"
            )
        self.env_kwargs: dict[str, Any] = dict(ckpt["env_kwargs"])
        actor, _critic = build_modules(
            self.settings, n, int(ckpt["actor_dim"]), int(ckpt["critic_dim"])
        )
        actor.load_state_dict(ckpt["actor"])
        actor.eval()
        self._actor = actor
        self._torch = torch
        self._base = None
        if self.settings.residual_base is not None:
            if make_base is None:
                raise ValueError(
                    "this checkpoint is a residual policy: pass make_base "
                    "(coopnav_env.agents.make_policy)"
                )
            from coopnav_env.agents.heuristics import COLUMN_ALIASES

            # a checkpoint records its base under the name it was trained with: an earlier
            # name of a column is its current one (the user typed neither, so no warning)
            base = COLUMN_ALIASES.get(self.settings.residual_base, self.settings.residual_base)
            self._base = make_base(base, env, **self.settings.residual_base_kwargs)
        self._held: np.ndarray | None = None  # the actor's output, held for action_repeat
        self._since = 0  # steps it has been held

    def reset(self, seed: int | None = None) -> None:
        """Reset the base heuristic and the held output (the network itself has no state)."""
        if self._base is not None:
            self._base.reset(seed)
        self._held = None
        self._since = 0

    def _actor_head(self, observations: Mapping[str, np.ndarray], base_cmd: Any) -> Any:
        """The actor's loc/scale module on the swarm's observations (a batch of
        one swarm)."""
        from tensordict import TensorDict

        obs = np.stack([np.asarray(observations[a], dtype=np.float32) for a in self.agents])
        inp = obs if base_cmd is None else np.concatenate([obs, base_cmd], axis=1)
        td = TensorDict({("agents", "observation"): self._torch.from_numpy(inp[None])}, [1])
        with self._torch.no_grad():
            return self._actor.module[0](td)

    def action_distribution(
        self, observations: Mapping[str, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """The Gaussian the actor samples every UAV's action from in training.

        Parameters
        ----------
        observations : mapping of agent name to observation
            One observation for every agent of ``possible_agents``.

        Returns
        -------
        (loc, scale) : ndarrays, shape (N, action size)
            Mean and standard deviation per UAV (in ``possible_agents`` order) and action
            entry, before the clip to the action box that the environment applies.

        Raises
        ------
        ValueError
            A residual policy (its action adds a base heuristic's command, which this does
            not fly), or observations of other agents than ``possible_agents``.
        """
        if self._base is not None:
            raise ValueError(
                f"a residual policy (base {self.settings.residual_base!r}) has no action "
                "distribution of its own: its action adds the base heuristic's command"
            )
        if list(observations) != self.agents:
            raise ValueError(
                f"observations of {list(observations)}, expected every agent of {self.agents}"
            )
        td = self._actor_head(observations, None)
        return td["agents", "loc"][0].numpy(), td["agents", "scale"][0].numpy()

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The mean action of every UAV, combined with the base policy as in training (a new
        decision every ``action_repeat`` steps after :meth:`reset`, held in between)."""
        live = list(observations)
        if not live:
            return {}
        if live != self.agents:
            raise ValueError(
                "a TorchRL swarm policy acts for the whole swarm at once; got observations of "
                f"{live}, expected {self.agents}"
            )
        base_cmd = base_command_before(self.settings, self._base, observations, self.agents)
        if self._held is None or self._since >= self.settings.action_repeat:
            td = self._actor_head(observations, base_cmd)
            self._held, self._since = td["agents", "loc"][0].numpy(), 0  # the mean
        self._since += 1
        mean = self._held
        cmd = swarm_command(self.settings, mean, self._base, base_cmd, observations, self.agents)
        return {a: cmd[i].astype(np.float32) for i, a in enumerate(self.agents)}
