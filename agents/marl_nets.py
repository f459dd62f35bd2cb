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
    "MARLSettings",
    "base_command_before",
    "build_modules",
    "check_residual_base",
    "load_marl_checkpoint",
    "swarm_command",
]

CHECKPOINT_FORMAT = "coopnav-marl-1"
"""The ``format`` entry of a checkpoint of
:meth:`coopnav_env.training.torchrl_backend.MARLTrainer.save`."""

ALGORITHMS: tuple[str, ...] = ("mappo", "ippo")
"""Algorithms of the TorchRL backend."""


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
        ``residual_mode: velocity``: the network's output (in ``[-1, 1]`` after clipping)
        times this is added to the base command.
    residual_mode : {"velocity", "offset", "options"}
        ``velocity``: the learned action is a velocity residual added to the base command (the
        base command is part of the actor's input). ``offset``: the learned action moves each
        UAV's slot of the base column (along the route, to the left, up) by the action times
        ``offset_scale_m`` (the base must be a column heuristic,
        :class:`~coopnav_env.agents.heuristics.ColumnPolicy`), so the policy shapes the formation
        while the base flies the route. ``options`` (*experimental*, see
        :data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`): each UAV chooses one of a few
        discrete slot shifts (``option_shifts_m``) from a categorical distribution (per-UAV
        logits, shared parameters), usually held for several steps with ``action_repeat``:
        exploration then tries whole manoeuvres (drop back 10 m, move 5 m to the left, ...)
        rather than Gaussian noise around the base, and a policy that keeps choosing the first
        option (no shift) flies exactly like its base. Evaluation takes the most probable
        option.
    offset_scale_m : list of 3 floats
        Largest slot shift along the route, to the left and up [m] (``offset`` mode).
    option_shifts_m : list of [along, left, up] lists
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        The slot shifts [m] the ``options`` mode chooses among (at least 2, each in
        ``[-100, 100]``); by convention the first is no shift.
    option_init_prob : float
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        ``options`` mode: the probability of the first option at the start of training (the
        output layer starts at zero weights and a bias that gives it this probability, the
        others sharing the rest), in ``(0, 1)``.
    action_repeat : int
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        Swarm steps per decision of the actor, >= 1 (default 1: a decision every step). The
        network's output is held for ``action_repeat`` steps while the base heuristic keeps
        acting every step (velocity mode: the held residual is added to each step's base
        command; offset mode: the held slot shifts stay), so that exploration tries a
        manoeuvre held for several seconds, as the privileged planner's look-ahead does.
        Training stores one PPO transition per decision with the rewards of its steps
        summed, and discounts by ``gamma ** action_repeat`` per decision (``gamma`` stays
        the per-step discount). A copy whose episode ends within a decision ends that
        transition there; the copy's next episode starts with the rest of the held output
        (at most ``action_repeat - 1`` steps), which no transition is credited with.
    residual_wall_guard : bool
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        Velocity mode: limit the residual's horizontal part toward walls the range sensor
        sees (:meth:`coopnav_env.agents.heuristics.ColumnPolicy.guard_delta`: nothing toward a
        wall inside the base column's wall margin, toward one beyond it no faster than reaches
        the margin in 2 s), so that neither the learned residual nor exploration noise around
        it can cancel the base's wall guard (default False: no limit). The base must be a
        column heuristic with a wall margin (``guarded_column``, ``ceiling_column``). What the
        policy's log-probability is computed on is the network's raw output; the guard acts on the
        command, like the clipping, and is part of the environment as the actor sees it.
    noise_correlation : float
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        Correlation ``rho`` in ``[0, 1]`` of the exploration noise from one decision to the
        next (default 0: independent draws, TorchRL's own sampling). With ``rho > 0`` every
        UAV's action is ``loc + scale * eps``, where ``eps`` starts each episode as a
        standard normal draw and follows ``eps <- rho * eps + sqrt(1 - rho**2) * eta``
        (``eta`` standard normal) at each later decision, so that its marginal stays standard
        normal: each action is still a draw from the actor's Gaussian, and PPO's
        probability ratios are those of that Gaussian, but a deviation persists for about
        ``1 / (1 - rho)`` decisions (``rho = 1``: the whole episode), so exploration tries
        held manoeuvres (drop back for the first seconds) that independent draws almost never
        produce. Not with ``residual_mode: options``.
    noise_correlated_decisions : int
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        The number of decisions at the start of each episode over which ``noise_correlation``
        holds; later decisions draw independent noise (default 0: the whole episode).
        With ``noise_correlation: 1`` and ``3``, the noise is one draw for the episode's
        first 3 decisions: exploration tries held starts and flies the rest as with
        independent draws.
    noise_correlated_entries : list of int or None
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        Action entries (0, 1, 2) whose noise ``noise_correlation`` correlates (default None:
        every entry); the others draw independent noise at every decision.
    noise_centred_entries : list of int
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        Action entries (0, 1, 2) whose exploration noise is centred over the swarm (default
        none; needs ``noise_correlation > 0``): at every draw the swarm's mean is subtracted
        and the rest scaled by ``sqrt(N / (N - 1))`` (N UAVs), so that each UAV's noise stays
        standard normal but the swarm's noises sum to zero: every draw tries differences
        between the UAVs (some held back, others ahead), never a shift of the whole swarm.
    start_hold_decisions : int
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        Exploring starts for training (default 0: off; needs ``env.action_frame: route`` and
        no residual base). At every training episode's start each UAV draws ``h`` uniformly
        from ``0, 1, ..., start_hold_decisions``, and for its first ``h`` decisions its speed
        set-point is -1 (held in place; its other set-points are the actor's draws). With the
        default ``start_hold_objective: masked`` those decisions are left out of PPO's
        objective (advantage weight 0; the advantages of the others are standardised over the
        rollout's learning decisions), so that to the learner an episode starts where the held
        UAVs are released: a swarm strung out along the route by up to
        ``start_hold_decisions * action_repeat`` steps, or together. The critic learns every
        decision's value. Evaluation and exported policies never hold.
    start_hold_objective : {"masked", "importance", "unweighted"}
        *Experimental* (:data:`coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`: may change or be
        removed).
        What PPO makes of the held decisions of ``start_hold_decisions`` (default
        ``"masked"``: left out, as above). ``"importance"``: a held decision's speed entry is
        drawn from the actor's Gaussian below -1 (its tail, which the clipping flies as -1)
        and its logged log-probability is that of the behaviour, the actor's minus
        ``log P(a0 <= -1)``, so that PPO's ratio is the importance weight ``pi / behaviour``
        of a hold: the held decisions then teach the actor to hold where holding paid,
        weighted by how likely the actor was to hold. ``"unweighted"``: the same draws,
        logged with the actor's own log-probability, as if it had drawn them (PPO's ratio
        starts at 1): a biased estimate that pushes the actor toward holds that paid, and
        away from holds that did not, as strongly as toward its own draws.
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
    residual_mode: str = "velocity"
    offset_scale_m: list[float] = field(default_factory=lambda: [15.0, 8.0, 8.0])
    option_shifts_m: list[list[float]] = field(
        default_factory=lambda: [
            [0.0, 0.0, 0.0],
            [10.0, 0.0, 0.0],
            [-10.0, 0.0, 0.0],
            [0.0, 5.0, 0.0],
            [0.0, -5.0, 0.0],
        ]
    )
    option_init_prob: float = 0.8
    action_repeat: int = 1
    residual_wall_guard: bool = False
    noise_correlation: float = 0.0
    noise_correlated_decisions: int = 0
    noise_correlated_entries: list[int] | None = None
    noise_centred_entries: list[int] = field(default_factory=list)
    start_hold_decisions: int = 0
    start_hold_objective: str = "masked"

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
        if self.residual_mode not in ("velocity", "offset", "options"):
            raise bad("residual_mode", "'velocity', 'offset' or 'options'")
        if self.residual_mode in ("offset", "options") and self.residual_base is None:
            raise bad("residual_mode", "'velocity' when residual_base is null")
        if (
            not isinstance(self.offset_scale_m, list | tuple)
            or len(self.offset_scale_m) != 3
            or any(
                not isinstance(v, int | float) or not 0.0 <= v <= 100.0 for v in self.offset_scale_m
            )
        ):
            raise bad("offset_scale_m", "three numbers in [0, 100] (along, left, up) [m]")
        self.offset_scale_m = [float(v) for v in self.offset_scale_m]
        rows = self.option_shifts_m
        if (
            not isinstance(rows, list | tuple)
            or len(rows) < 2
            or any(
                not isinstance(r, list | tuple)
                or len(r) != 3
                or any(
                    isinstance(v, bool) or not isinstance(v, int | float) or not -100 <= v <= 100
                    for v in r
                )
                for r in rows
            )
        ):
            raise bad(
                "option_shifts_m", "a list of at least 2 [along, left, up] shifts in [-100, 100] m"
            )
        self.option_shifts_m = [[float(v) for v in r] for r in rows]
        if not isinstance(self.option_init_prob, int | float) or not (
            0.0 < float(self.option_init_prob) < 1.0
        ):
            raise bad("option_init_prob", "a number in (0, 1)")
        if (
            isinstance(self.noise_correlation, bool)
            or not isinstance(self.noise_correlation, int | float)
            or not 0.0 <= float(self.noise_correlation) <= 1.0
        ):
            raise bad("noise_correlation", "a number in [0, 1]")
        self.noise_correlation = float(self.noise_correlation)
        if self.noise_correlation > 0.0 and self.residual_mode == "options":
            raise bad("noise_correlation", "0 with residual_mode 'options' (a categorical)")
        k = self.noise_correlated_decisions
        if isinstance(k, bool) or not isinstance(k, int) or k < 0:
            raise bad("noise_correlated_decisions", "an integer >= 0")
        cor = self.noise_correlated_entries
        if cor is not None:
            if (
                not isinstance(cor, list | tuple)
                or not cor
                or any(isinstance(e, bool) or e not in (0, 1, 2) for e in cor)
                or len(set(cor)) != len(cor)
            ):
                raise bad(
                    "noise_correlated_entries",
                    "null (every entry) or a non-empty list of distinct entries 0, 1, 2",
                )
            self.noise_correlated_entries = [int(e) for e in cor]
        ents = self.noise_centred_entries
        if (
            not isinstance(ents, list | tuple)
            or any(isinstance(e, bool) or e not in (0, 1, 2) for e in ents)
            or len(set(ents)) != len(ents)
        ):
            raise bad("noise_centred_entries", "a list of distinct action entries 0, 1, 2")
        self.noise_centred_entries = [int(e) for e in ents]
        h = self.start_hold_decisions
        if isinstance(h, bool) or not isinstance(h, int) or h < 0:
            raise bad("start_hold_decisions", "an integer >= 0")
        if h > 0 and self.residual_base is not None:
            raise bad("start_hold_decisions", "0 with a residual_base (it holds set-points)")
        if self.start_hold_objective not in ("masked", "importance", "unweighted"):
            raise bad("start_hold_objective", "'masked', 'importance' or 'unweighted'")
        if ents and self.noise_correlation == 0.0:
            raise bad("noise_centred_entries", "empty unless noise_correlation > 0")
        if not isinstance(self.residual_wall_guard, bool):
            raise bad("residual_wall_guard", "true or false")
        if self.residual_wall_guard and (
            self.residual_base is None or self.residual_mode != "velocity"
        ):
            raise bad(
                "residual_wall_guard",
                "false unless residual_base is set and residual_mode is 'velocity'",
            )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> MARLSettings:
        """Settings from a mapping; unknown keys raise ``ValueError`` listing the valid ones."""
        d = dict(d or {})
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
        return 3 if (self.residual_base is not None and self.residual_mode == "velocity") else 0

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

    if settings.residual_mode == "options":
        from torchrl.modules import OneHotCategorical

        n_opt = len(settings.option_shifts_m)
        logit_net = mlp(actor_dim, n_opt)
        p0 = float(settings.option_init_prob)
        with torch.no_grad():
            last = logit_net[-1]
            last.weight.zero_()
            last.bias.fill_(float(np.log((1.0 - p0) / (n_opt - 1))))
            last.bias[0] = float(np.log(p0))
        actor = ProbabilisticActor(
            module=TensorDictModule(
                logit_net, in_keys=[("agents", "observation")], out_keys=[("agents", "logits")]
            ),
            in_keys=[("agents", "logits")],
            out_keys=[("agents", "action")],
            distribution_class=OneHotCategorical,
            return_log_prob=True,
            log_prob_key=("agents", "action_log_prob"),
        )
        critic = TensorDictModule(
            mlp(critic_dim, 1),
            in_keys=[("agents", "critic_input")],
            out_keys=[("agents", "state_value")],
        )
        return actor, critic

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
    if settings.residual_base is None or settings.residual_mode != "velocity":
        return None
    acts = base.act(observations)
    return np.stack([acts[a] for a in agents]).astype(np.float32)


def check_residual_base(settings: MARLSettings, base: Any) -> None:
    """``ValueError`` if ``base`` cannot serve ``settings``: the ``offset`` and ``options``
    modes need a column follower (it has slots to shift), ``residual_wall_guard`` one with a
    wall margin (e.g. ``guarded`` or ``ceiling``)."""
    if settings.residual_mode in ("offset", "options") and not hasattr(base, "set_slot_shifts"):
        raise ValueError(
            f"torchrl.residual_mode={settings.residual_mode!r} needs a column follower as "
            f"residual_base (formation, sky, spread, wide, guarded, ceiling), got "
            f"{settings.residual_base!r}"
        )
    if settings.residual_wall_guard and getattr(base, "wall_margin_m", None) is None:
        raise ValueError(
            "torchrl.residual_wall_guard needs a residual_base with a wall guard "
            f"(guarded, ceiling, or a column with wall_margin_m set), got "
            f"{settings.residual_base!r}"
        )


def swarm_command(
    settings: MARLSettings,
    raw: np.ndarray,
    base: Any,
    base_cmd: np.ndarray | None,
    observations: Mapping[str, Any],
    agents: list[str],
) -> np.ndarray:
    """The velocity command ``(N, 3)`` in ``[-1, 1]`` of the network's output ``raw (N, 3)``.

    No base: ``clip(raw)``. Velocity mode: ``clip(base_cmd + residual_scale * clip(raw))``,
    the residual first guarded against walls with ``residual_wall_guard``. Offset mode: the
    base column with every slot moved by ``clip(raw) * offset_scale_m``. Options mode: ``raw``
    is one-hot (N, n_options); every slot moved by its chosen row of ``option_shifts_m``.
    """
    a = np.clip(raw, -1.0, 1.0)
    if settings.residual_base is None:
        return a
    if settings.residual_mode == "velocity":
        assert base_cmd is not None
        delta = settings.residual_scale * a
        if settings.residual_wall_guard:
            obs = np.stack([np.asarray(observations[x], dtype=np.float64) for x in agents])
            delta = base.guard_delta(obs, delta)
        return np.clip(base_cmd + delta, -1.0, 1.0)
    if settings.residual_mode == "options":
        base.set_slot_shifts(raw @ np.asarray(settings.option_shifts_m))  # raw is one-hot
    else:
        base.set_slot_shifts(a * np.asarray(settings.offset_scale_m))
    acts = base.act(observations)
    return np.stack([acts[x] for x in agents]).astype(np.float32)


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
