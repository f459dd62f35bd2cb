"""The networks and checkpoints of the TorchRL MAPPO/IPPO backend (shared by training and
evaluation): :class:`MARLSettings`, :func:`build_modules`, :func:`load_marl_checkpoint`.

The training loop is :mod:`coopnav_env.training.torchrl_backend`; the evaluation policy
:mod:`coopnav_env.agents.marl_policy`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ALGORITHMS",
    "CHECKPOINT_FORMAT",
    "REMOVED_SETTINGS",
    "MARLSettings",
    "base_command_before",
    "build_modules",
    "load_marl_checkpoint",
    "settings_from_record",
    "swarm_command",
]

CHECKPOINT_FORMAT = "coopnav-marl-1"
"""The ``format`` entry of a checkpoint of
:meth:`coopnav_env.training.torchrl_backend.MARLTrainer.save`."""

ALGORITHMS: tuple[str, ...] = ("mappo", "ippo")
"""Algorithms of the TorchRL backend."""

REMOVED_SETTINGS: dict[str, str] = {
    "residual_mode": "flight",
    "offset_scale_m": "flight",
    "option_shifts_m": "flight",
    "option_init_prob": "flight",
    "residual_wall_guard": "flight",
    "noise_correlation": "training",
    "noise_correlated_decisions": "training",
    "noise_correlated_entries": "training",
    "noise_centred_entries": "training",
    "start_hold_objective": "training",
}
"""Settings of earlier releases that were removed, each with what its value changed:
``flight`` (what a trained policy commands) or ``training`` only (the exploration).
Checkpoints and run folders of those releases still record them; :func:`settings_from_record`
reads such a record."""


def _removed_in_effect(d: Mapping[str, Any]) -> dict[str, Any]:
    """The removed settings of a recorded mapping ``d`` whose values changed what the run did,
    each with its value (settings at their "off" value, or that only acted together with
    another removed setting, are left out)."""
    found: dict[str, Any] = {}
    mode = d.get("residual_mode", "velocity")
    if mode != "velocity":
        found["residual_mode"] = mode
    if d.get("residual_wall_guard", False) not in (False, None):
        found["residual_wall_guard"] = d["residual_wall_guard"]
    if float(d.get("noise_correlation", 0.0) or 0.0) > 0.0:
        found["noise_correlation"] = d["noise_correlation"]
    # held starts logged with the actor's own log-probability ("unweighted") is what stays.
    # A record that names none of the removed settings was written by this version, whose
    # holds are that; an earlier release recorded every setting it had (the removed ones
    # among them), and before start_hold_objective existed its holds were left out of the
    # objective ("masked")
    holds = d.get("start_hold_decisions", 0)
    objective = d.get("start_hold_objective")
    if objective is None:
        objective = "masked" if any(k in d for k in REMOVED_SETTINGS) else "unweighted"
    if isinstance(holds, int) and holds > 0 and objective != "unweighted":
        found["start_hold_objective"] = objective
    return found


def settings_from_record(
    d: Mapping[str, Any], where: str | Path, purpose: str = "fly"
) -> MARLSettings:
    """:class:`MARLSettings` from the settings a checkpoint or a run folder recorded,
    which may hold settings of :data:`REMOVED_SETTINGS`.

    Parameters
    ----------
    d : mapping
        The recorded settings (a checkpoint's ``settings``, the ``torchrl`` section of a run's
        ``config.yaml``).
    where : str or path
        The file named in the messages.
    purpose : {"fly", "resume"}
        ``fly``: a removed setting that only changed the exploration during training is
        dropped, so that the policy flies as it was trained to. ``resume``: a removed setting
        whose value changed what the run did is refused (the run cannot go on as it was).

    Raises
    ------
    ValueError
        A removed setting whose recorded value changed what the purpose needs: named, with
        its value, saying that it was removed.
    """
    if purpose not in ("fly", "resume"):
        raise ValueError(f"purpose must be 'fly' or 'resume', got {purpose!r}")
    in_effect = _removed_in_effect(d)
    if purpose == "fly":
        in_effect = {k: v for k, v in in_effect.items() if REMOVED_SETTINGS[k] == "flight"}
    if in_effect:
        named = ", ".join(f"torchrl.{k}={v!r}" for k, v in in_effect.items())
        doing = "flown" if purpose == "fly" else "resumed"
        raise ValueError(
            f"{where} was trained with {named}, a setting removed from coopnav (see the "
            f"changelog): this version cannot have it {doing}; use the coopnav commit that "
            "trained it, or train a new run"
        )
    return MARLSettings.from_dict({k: v for k, v in d.items() if k not in REMOVED_SETTINGS})


@dataclass
class MARLSettings:
    """Settings of the TorchRL MAPPO/IPPO backend (the ``torchrl:`` section of the YAML).

    Parameters
    ----------
    algorithm : {"mappo", "ippo"}
        MAPPO: the critic sees ``env.state()`` and the UAV's observation; IPPO: the
        observation only.
    n_copies : int
        Swarm copies stepped together (``BatchedUrbanCanyonEnv``), >= 1.
    rollout_steps : int
        Decisions per copy and iteration (swarm steps with ``action_repeat`` 1); one
        iteration is ``n_copies * rollout_steps * action_repeat * n_uavs`` agent-steps.
    epochs, minibatch_size : int
        Passes over each rollout and agent-samples per gradient step.
    learning_rate, gamma, gae_lambda, clip_epsilon, entropy_coef, critic_coef, max_grad_norm
        PPO's settings.
    lr_schedule : {"constant", "linear"}
        ``linear``: the learning rate falls linearly from ``learning_rate`` to zero over the
        run's agent-step budget (as in SB3's and MAPPO's reference code), so that the last
        updates only fine-tune; ``constant`` keeps ``learning_rate``.
    hidden : list of int
        Hidden layer sizes of actor and critic (equal widths; depth = len).
    init_log_std : float
        Initial log standard deviation of the action (in the network's output units).
    normalize_reward : bool
        Divide rewards by a running estimate of the discounted return's standard deviation.
    residual_base : str or None
        A :func:`coopnav_env.agents.make_policy` name whose command the learned action is added to.
    residual_base_kwargs : dict
        Options of the base policy.
    residual_scale : float
        The network's output (in ``[-1, 1]`` after clipping) times this is added to the base
        command.
    action_repeat : int
        Swarm steps per decision of the actor, >= 1 (default 1: a decision every step). The
        network's output is held for ``action_repeat`` steps while a residual base keeps
        acting every step (the held residual is added to each step's base command), so that
        exploration tries a manoeuvre held for several seconds. Training stores one PPO
        transition per decision with the rewards of its steps summed, and discounts by
        ``gamma ** action_repeat`` per decision (``gamma`` stays the per-step discount). A
        copy whose episode ends within a decision ends that transition there; the copy's
        next episode starts with the rest of the held output (at most ``action_repeat - 1``
        steps), which no transition is credited with. Evaluation holds the output alike.
    start_hold_decisions : int
        Exploring starts for training (default 0: off; needs ``env.action_frame: route`` and
        no residual base). At every training episode's start each UAV draws ``h`` uniformly
        from ``0, 1, ..., start_hold_decisions``, and for its first ``h`` decisions it is held
        in place: its speed set-point is drawn from the actor's Gaussian below -1 (its tail,
        which the clipping flies as -1; its other set-points are the actor's own draws), and
        the decision is logged with the actor's own log-probability, as if the actor had drawn
        it. PPO then pushes the actor toward the holds that paid and away from those that did
        not, as strongly as toward its own draws, so that the actor learns to open the
        spacing a held start gives (a swarm strung out along the route by up to
        ``start_hold_decisions * action_repeat`` steps). Evaluation and exported policies
        never hold.
    dual_clip : float or None
        Dual-clip PPO's cap ``c`` on the ratio of the new to the old policy's probability of
        a logged action (``> 1 + clip_epsilon``; 3 is the usual value), or None (default:
        plain clipped PPO). A ratio above ``c`` counts as ``c`` and adds no gradient. Plain
        PPO bounds the ratio only where the advantage is positive, so a sample whose ratio
        runs away with a negative advantage (a held exploring start far in the actor's
        tail, once the actor's standard deviation has shrunk) can dominate a minibatch and
        drive the loss to infinity; the cap bounds it. Runs whose ratios never exceed ``c``
        train exactly as without it.
    """

    algorithm: str = "mappo"
    n_copies: int = 16
    rollout_steps: int = 64
    epochs: int = 5
    minibatch_size: int = 2560
    learning_rate: float = 3e-4
    lr_schedule: str = "constant"
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.0
    critic_coef: float = 0.5
    max_grad_norm: float = 0.5
    hidden: list[int] = field(default_factory=lambda: [128, 128])
    init_log_std: float = -1.0
    normalize_reward: bool = True
    residual_base: str | None = None
    residual_base_kwargs: dict[str, Any] = field(default_factory=dict)
    residual_scale: float = 0.5
    action_repeat: int = 1
    start_hold_decisions: int = 0
    dual_clip: float | None = None

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ValueError:
            return ValueError(f"torchrl.{name} must be {allowed}, got {getattr(self, name)!r}")

        if self.algorithm not in ALGORITHMS:
            raise bad("algorithm", f"one of {list(ALGORITHMS)}")
        for name in ("n_copies", "rollout_steps", "epochs", "minibatch_size", "action_repeat"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(name, "an integer >= 1")
        for name, lo, hi in (
            ("learning_rate", 0.0, 1.0),
            ("clip_epsilon", 0.0, 1.0),
            ("max_grad_norm", 0.0, 1e6),
            ("residual_scale", 0.0, 1.0),
        ):
            v = getattr(self, name)
            if not isinstance(v, int | float) or not (lo < float(v) <= hi):
                raise bad(name, f"a number in ({lo}, {hi}]")
        for name in ("gamma", "gae_lambda"):
            v = getattr(self, name)
            if not isinstance(v, int | float) or not (0.0 < float(v) <= 1.0):
                raise bad(name, "a number in (0, 1]")
        for name in ("entropy_coef", "critic_coef"):
            v = getattr(self, name)
            if not isinstance(v, int | float) or not (0.0 <= float(v) <= 100.0):
                raise bad(name, "a number in [0, 100]")
        if not isinstance(self.init_log_std, int | float) or not (
            -10.0 <= float(self.init_log_std) <= 2.0
        ):
            raise bad("init_log_std", "a number in [-10, 2]")
        if (
            not isinstance(self.hidden, list | tuple)
            or not self.hidden
            or any(isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in self.hidden)
            or len(set(self.hidden)) != 1
        ):
            raise bad("hidden", "a non-empty list of equal positive integers, e.g. [128, 128]")
        self.hidden = [int(h) for h in self.hidden]
        if self.residual_base is not None and not isinstance(self.residual_base, str):
            raise bad("residual_base", "null or a policy name such as 'sky'")
        if not isinstance(self.residual_base_kwargs, Mapping):
            raise bad("residual_base_kwargs", "a mapping of policy options")
        self.residual_base_kwargs = dict(self.residual_base_kwargs)
        if self.lr_schedule not in ("constant", "linear"):
            raise bad("lr_schedule", "'constant' or 'linear'")
        h = self.start_hold_decisions
        if isinstance(h, bool) or not isinstance(h, int) or h < 0:
            raise bad("start_hold_decisions", "an integer >= 0")
        if h > 0 and self.residual_base is not None:
            raise bad("start_hold_decisions", "0 with a residual_base (it holds set-points)")
        c = self.dual_clip
        if c is not None and (
            isinstance(c, bool)
            or not isinstance(c, int | float)
            or not (1.0 + float(self.clip_epsilon) < float(c) <= 1e6)
        ):
            raise bad(
                "dual_clip",
                f"null or a number above 1 + clip_epsilon = {1.0 + float(self.clip_epsilon):g} "
                "(3 is the usual value)",
            )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> MARLSettings:
        """Settings from a mapping; unknown keys raise ``ValueError`` listing the valid ones,
        a setting of :data:`REMOVED_SETTINGS` one that says it was removed."""
        d = dict(d or {})
        removed = sorted(set(d) & set(REMOVED_SETTINGS))
        if removed:
            raise ValueError(
                f"torchrl setting(s) {removed} were removed from coopnav (see the changelog); "
                "remove them from the configuration"
            )
        valid = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(d) - set(valid))
        if unknown:
            raise ValueError(
                f"unknown torchrl setting(s) {unknown}; valid settings are {', '.join(valid)}"
            )
        return cls(**d)

    @property
    def actor_extra_inputs(self) -> int:
        """Entries the actor reads beside the observation: the base command (velocity mode)."""
        return 3 if self.residual_base is not None else 0

    @property
    def centralised_critic(self) -> bool:
        """Whether the critic sees the global state (MAPPO)."""
        return self.algorithm == "mappo"


def build_modules(
    settings: MARLSettings, n_agents: int, actor_dim: int, critic_dim: int
) -> tuple[Any, Any]:
    """The actor (ProbabilisticActor) and critic (TensorDictModule) of TorchRL.

    Keys: actor reads ``("agents", "observation")`` and writes ``("agents", "action")`` and
    ``("agents", "action_log_prob")``; the critic reads ``("agents", "critic_input")`` and
    writes ``("agents", "state_value")``.
    """
    import torch
    from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
    from torch import nn
    from torchrl.modules import MLP, IndependentNormal, ProbabilisticActor

    # Parameter sharing with decentralised inputs is one MLP applied to every agent's row
    # (the last dimension), which is what MultiAgentMLP(share_params=True,
    # centralized=False) computes; TorchRL's MLP is used because, with torchrl 0.14,
    # MultiAgentMLP's vmapped parameters receive no gradient through ClipPPOLoss's
    # functional parameters (zero gradient on every weight, checked here).
    def mlp(in_features: int, out_features: int) -> MLP:
        return MLP(
            in_features=in_features,
            out_features=out_features,
            depth=len(settings.hidden),
            num_cells=settings.hidden[0],
            activation_class=nn.Tanh,
        )

    loc_net = mlp(actor_dim, 3)
    if settings.residual_base is not None:
        # start exactly at the base policy: the output layer is zero (its weight still gets
        # a gradient, the hidden layers do once it is no longer zero)
        with torch.no_grad():
            last = loc_net[-1]
            last.weight.zero_()
            last.bias.zero_()
    scale = AddStateIndependentNormalScale(
        3, scale_mapping="exp", init_value=float(settings.init_log_std)
    )
    actor_module = TensorDictModule(
        nn.Sequential(loc_net, scale),
        in_keys=[("agents", "observation")],
        out_keys=[("agents", "loc"), ("agents", "scale")],
    )
    actor = ProbabilisticActor(
        module=actor_module,
        in_keys=[("agents", "loc"), ("agents", "scale")],
        out_keys=[("agents", "action")],
        distribution_class=IndependentNormal,
        return_log_prob=True,
        log_prob_key=("agents", "action_log_prob"),
    )
    critic_net = mlp(critic_dim, 1)
    critic = TensorDictModule(
        critic_net,
        in_keys=[("agents", "critic_input")],
        out_keys=[("agents", "state_value")],
    )
    return actor, critic


def base_command_before(
    settings: MARLSettings, base: Any, observations: Mapping[str, Any], agents: list[str]
) -> np.ndarray | None:
    """The base command ``(N, 3)`` the actor reads (velocity mode), else None.

    Call once per step, before the actor; :func:`swarm_command` then uses it.
    """
    if settings.residual_base is None:
        return None
    acts = base.act(observations)
    return np.stack([acts[a] for a in agents]).astype(np.float32)


def swarm_command(
    settings: MARLSettings,
    raw: np.ndarray,
    base: Any = None,
    base_cmd: np.ndarray | None = None,
    observations: Mapping[str, Any] | None = None,
    agents: list[str] | None = None,
) -> np.ndarray:
    """The velocity command in ``[-1, 1]`` of the network's output ``raw``.

    ``raw`` is ``(N, 3)`` for one swarm or ``(K, N, 3)`` for ``K`` swarms at once (the
    result has its shape; every entry is computed alone, so a swarm's command is the same
    either way). No base: ``clip(raw)``; a residual base: ``clip(base_cmd + residual_scale *
    clip(raw))`` with ``base_cmd`` of :func:`base_command_before` (stacked over the swarms
    for ``(K, N, 3)``), which holds what the base does. ``base``, ``observations`` and
    ``agents`` are not read.
    """
    a = np.clip(raw, -1.0, 1.0)
    if settings.residual_base is None:
        return a
    if base_cmd is None:
        raise ValueError(
            f"swarm_command needs base_cmd (base_command_before) with residual_base "
            f"{settings.residual_base!r}"
        )
    return np.clip(base_cmd + settings.residual_scale * a, -1.0, 1.0)


def load_marl_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :meth:`MARLTrainer.save` (``ValueError`` if it is not one)."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no TorchRL checkpoint at {path}")
    try:
        d = torch.load(path, map_location="cpu", weights_only=True)  # no code from the file
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(f"{path} is not a readable coopnav TorchRL checkpoint: {exc}") from exc
    if not isinstance(d, dict) or d.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{path} is not a coopnav TorchRL checkpoint (format coopnav-marl-1)")
    return d
