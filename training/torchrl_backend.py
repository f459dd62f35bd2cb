"""MAPPO and IPPO on TorchRL: a centralised critic on ``state()``, parameter sharing, team credit.

``coopnav train --backend torchrl --algorithm mappo`` (or ``ippo``) trains one policy shared by
every UAV with TorchRL's multi-agent building blocks:

* the actor is a :class:`torchrl.modules.MultiAgentMLP` (``share_params=True``, decentralised:
  each UAV acts on its own observation) followed by a state-independent Gaussian scale
  (:class:`tensordict.nn.AddStateIndependentNormalScale`) inside a
  :class:`torchrl.modules.ProbabilisticActor`;
* the critic is a second :class:`~torchrl.modules.MultiAgentMLP`. **MAPPO** feeds it the
  environment's global state ``env.state()`` (true positions, estimation errors, sigmas,
  satellites: what a centralised critic may see during training and the actor never sees)
  together with the UAV's own observation (the "agent-specific global state" of Yu et al.,
  *The Surprising Effectiveness of PPO in Cooperative Multi-Agent Games*, 2022); **IPPO**
  feeds it the UAV's own observation only;
* the loss is TorchRL's :class:`torchrl.objectives.ClipPPOLoss` and the advantages its
  :class:`torchrl.objectives.value.GAE`.

Why not BenchMARL
-----------------
BenchMARL 1.5 pins ``torchrl<0.12`` and needs ``torchvision``, so it cannot share a venv with
this backend's TorchRL 0.14; it has an extra and a venv of its own (``benchmarl``), and
:mod:`coopnav_env.training.benchmarl_backend` is its coopnav task. This backend uses TorchRL
directly. The environment passes TorchRL's ``check_env_specs`` through its
``PettingZooWrapper`` with and without ``state`` (tested).

Collection
----------
Rollouts come from :class:`coopnav_env.envs.BatchedUrbanCanyonEnv` (``n_copies`` swarms
stepped with one array; copy ``k`` reset with ``seed + k``), not from TorchRL's
``PettingZooWrapper``: the wrapper's per-step tensordict plumbing costs about three times the
environment's own step here. The collected arrays are put in a ``TensorDict`` with TorchRL's
multi-agent layout (``("agents", "observation")`` etc., batch ``[K, T]``, agents ``N``) for the
loss and the advantage estimator.

Episode ends
------------
A truncated episode (``max_steps``) is treated as terminal by the advantage estimator (no
bootstrap from the last state): the batched environment resets a finished copy inside its
step, so the state after the last step is gone. Episodes end at the goal or in a crash well
before the default 200 steps in almost every training episode, so the bias is small.

Behaviour-cloning warm start
----------------------------
With ``pretrain`` set in the ``torchrl:`` section (:class:`WarmStart`), a new run (never a
resumed one) first flies a heuristic teacher (:func:`coopnav_env.agents.make_policy`) in the
same batched environment, on training reset seeds, fits the actor's mean to the teacher's
actions and the critic to the teacher's return-to-go, and only then starts PPO
(:meth:`MARLTrainer.warm_start`). ``run.json`` records it under ``warm_start``. It needs a
policy without a residual base (the teacher's command is what the actor outputs).

Residual policies
-----------------
With ``residual_base`` set (e.g. ``"sky_column"``), the learned action is added to the command of a
hand-written base policy (:func:`coopnav_env.agents.make_policy`), clipped to ``[-1, 1]``:
residual policy learning (Silver et al. 2018; Johannink et al. 2019). The network's output
is scaled by ``residual_scale`` and its last layer starts at zero, so training starts from
the base policy's behaviour and RL only has to find what to change. The base command is part
of the actor's input. With ``residual_base: null`` the policy flies on its own.

Held decisions and exploring starts
-----------------------------------
``action_repeat`` holds each of the actor's outputs for several swarm steps (one PPO
transition per decision). ``start_hold_decisions`` gives training episodes exploring starts:
each UAV is held in place for a random number of its first decisions, decisions the actor is
credited with as if it had drawn them (:class:`coopnav_env.agents.marl_nets.MARLSettings`
describes every setting).
"""

from __future__ import annotations

import dataclasses
import math
import re
import shutil
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from coopnav_env.agents.marl_nets import (
    CHECKPOINT_FORMAT,
    MARLSettings,
    base_command_before,
    build_modules,
    settings_from_record,
    swarm_command,
)
from coopnav_env.agents.marl_policy import load_checked_checkpoint
from coopnav_env.training.envs import EVAL_SEED_START
from coopnav_env.training.files import atomic_path, write_json, write_yaml
from coopnav_env.training.runs import (
    ProgressLog,
    checkpoint_candidates,
    first_loadable,
    interrupts_deferred,
    open_run,
    raise_if_interrupted,
)

if TYPE_CHECKING:  # pragma: no cover
    from coopnav_env.training.config import TrainConfig

__all__ = [
    "ARCHITECTURE_SETTINGS",
    "MARLSettings",
    "MARLTrainer",
    "WarmStart",
    "check",
    "check_pretrain",
    "check_resumable_settings",
    "export_policy",
    "find_latest_checkpoint",
    "pretrain_of",
    "settings_of",
    "train",
    "train_marl",
]


def _actor_inputs(obs: np.ndarray, base: np.ndarray | None) -> np.ndarray:
    """The actor's input per UAV: its observation, and the base command if residual."""
    return obs if base is None else np.concatenate([obs, base.astype(np.float32)], axis=-1)


def _critic_inputs(obs: np.ndarray, state: np.ndarray | None) -> np.ndarray:
    """The critic's input per UAV: (MAPPO) the global state beside its observation."""
    if state is None:
        return obs
    n = obs.shape[-2]
    tiled = np.broadcast_to(state[..., None, :], (*state.shape[:-1], n, state.shape[-1]))
    return np.concatenate([tiled, obs], axis=-1)


class _RunningStd:
    """Running standard deviation of the discounted return (reward scaling, as SB3's)."""

    def __init__(self, shape: tuple[int, ...], gamma: float) -> None:
        self.gamma = gamma
        self.ret = np.zeros(shape)
        self.mean = 0.0
        self.var = 1.0
        self.count = 1e-4

    def scale(self, reward: np.ndarray, done: np.ndarray) -> np.ndarray:
        self.ret = self.ret * self.gamma + reward
        x = self.ret.ravel()
        b_mean, b_var, b_count = float(x.mean()), float(x.var()), x.size
        delta = b_mean - self.mean
        tot = self.count + b_count
        self.mean += delta * b_count / tot
        m2 = self.var * self.count + b_var * b_count + delta**2 * self.count * b_count / tot
        self.var = m2 / tot
        self.count = tot
        self.ret[done] = 0.0
        return reward / math.sqrt(self.var + 1e-8)

    def state_dict(self) -> dict[str, Any]:
        return {"mean": self.mean, "var": self.var, "count": self.count}

    def load_state_dict(self, d: Mapping[str, Any]) -> None:
        self.mean, self.var, self.count = float(d["mean"]), float(d["var"]), float(d["count"])


WARM_START_KEYS: tuple[str, ...] = (
    "policy",
    "policy_kwargs",
    "episodes",
    "epochs",
    "learning_rate",
)
"""The entries of the ``torchrl.pretrain`` mapping (:class:`WarmStart`)."""

WARM_START_BATCH = 256
"""Agent-samples per gradient step of the warm start's fit."""


@dataclasses.dataclass(frozen=True)
class WarmStart:
    """A behaviour-cloning warm start (``torchrl.pretrain``; :meth:`MARLTrainer.warm_start`).

    Parameters
    ----------
    policy : str
        The teacher: a heuristic policy name of :func:`coopnav_env.agents.make_policy`.
    policy_kwargs : dict
        The teacher's options.
    episodes : int
        Teacher episodes flown, >= 1 (reset seeds ``EVAL_SEED_START // 2 + seed + i``, below
        the held-out evaluation seeds).
    epochs : int
        Passes over the teacher's samples, >= 1.
    learning_rate : float
        Adam's learning rate of the fit, > 0.
    """

    policy: str
    policy_kwargs: dict[str, Any]
    episodes: int
    epochs: int
    learning_rate: float

    @classmethod
    def from_value(cls, value: Any, seed: int = 0) -> WarmStart | None:
        """The warm start of a ``torchrl.pretrain`` value (None: no warm start).

        Every entry must be given. Raises ``ValueError`` naming the entry: unknown or missing
        keys, a teacher that is not a heuristic policy name, ``episodes`` or ``epochs`` below
        1, a learning rate that is not positive, or teacher seeds that would reach the held-out
        evaluation seeds with this ``seed``.
        """
        if value is None:
            return None
        if not isinstance(value, Mapping):
            raise ValueError(
                f"torchrl.pretrain must be null or a mapping with {', '.join(WARM_START_KEYS)}, "
                f"got {value!r}"
            )
        unknown = sorted(set(value) - set(WARM_START_KEYS))
        if unknown:
            raise ValueError(
                f"unknown torchrl.pretrain setting(s) {unknown}; valid: {list(WARM_START_KEYS)}"
            )
        missing = [k for k in WARM_START_KEYS if k not in value]
        if missing:
            raise ValueError(f"torchrl.pretrain lacks {', '.join(missing)}")
        from coopnav_env.agents import POLICY_NAMES

        policy = value["policy"]
        if not isinstance(policy, str) or policy not in POLICY_NAMES:
            raise ValueError(
                f"torchrl.pretrain.policy must be a heuristic policy name (one of "
                f"{', '.join(POLICY_NAMES)}), got {policy!r}"
            )
        kwargs = value["policy_kwargs"]
        if kwargs is None:
            kwargs = {}
        if not isinstance(kwargs, Mapping):
            raise ValueError(
                f"torchrl.pretrain.policy_kwargs must be a mapping of the teacher's options, "
                f"got {kwargs!r}"
            )
        for key in ("episodes", "epochs"):
            v = value[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"torchrl.pretrain.{key} must be an integer >= 1, got {v!r}")
        lr = value["learning_rate"]
        if isinstance(lr, bool) or not isinstance(lr, int | float) or not 0.0 < lr < math.inf:
            raise ValueError(f"torchrl.pretrain.learning_rate must be a number > 0, got {lr!r}")
        first = EVAL_SEED_START // 2 + int(seed)
        if first + int(value["episodes"]) > EVAL_SEED_START:
            raise ValueError(
                f"torchrl.pretrain.episodes: the teacher's reset seeds {first}.."
                f"{first + int(value['episodes']) - 1} would reach the held-out evaluation "
                f"seeds (>= {EVAL_SEED_START}); lower the seed ({seed}) or the episodes"
            )
        return cls(
            str(policy), dict(kwargs), int(value["episodes"]), int(value["epochs"]), float(lr)
        )


def pretrain_of(cfg: TrainConfig) -> WarmStart | None:
    """The run's warm start (``cfg.torchrl["pretrain"]``; None: none, the default)."""
    return WarmStart.from_value(dict(cfg.torchrl).get("pretrain"), seed=cfg.seed)


class TrainingDivergedError(ValueError):
    """A PPO loss that is not finite: the run's settings must change (``torchrl.dual_clip``,
    a lower learning rate) before it can go on from its last checkpoint."""


def _dual_clip_loss_class() -> type:
    """TorchRL's ``ClipPPOLoss`` with dual clipping (:attr:`MARLSettings.dual_clip`): the log
    ratio of the new to the old probability is capped at ``log(dual_clip)`` before the
    clipped surrogate, so that a capped sample adds ``dual_clip`` times its advantage and no
    gradient. Above ``1 + clip_epsilon`` the cap changes only samples whose advantage is
    negative (with a positive one the clipped branch is already the minimum), which is
    dual-clip PPO."""
    from torchrl.objectives import ClipPPOLoss

    class DualClipPPOLoss(ClipPPOLoss):
        def __init__(self, *args: Any, dual_clip: float, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.max_log_weight = math.log(float(dual_clip))

        def _log_weight(self, tensordict: Any, adv_shape: Any) -> Any:
            log_weight, dist, kl_approx, log_is_weight = super()._log_weight(tensordict, adv_shape)
            return log_weight.clamp(max=self.max_log_weight), dist, kl_approx, log_is_weight

    return DualClipPPOLoss


class MARLTrainer:
    """One MAPPO/IPPO training run on the batched environment (see the module docstring).

    Parameters
    ----------
    settings : MARLSettings
    env_kwargs : dict
        ``urban_canyon_v0`` settings of every swarm copy.
    seed : int
        Copy ``k`` is reset with ``seed + k`` at the start; torch is seeded with ``seed``.
    env_seed : int, optional
        Reset seed of the copies instead of ``seed`` (a resumed run: ``seed`` plus the
        agent-steps done, so that it meets new episodes).
    """

    def __init__(
        self,
        settings: MARLSettings,
        env_kwargs: Mapping[str, Any],
        seed: int,
        env_seed: int | None = None,
    ) -> None:
        import torch
        from torchrl.objectives import ClipPPOLoss, ValueEstimators

        from coopnav_env.envs import BatchedUrbanCanyonEnv

        self.settings = settings
        self.env_kwargs = dict(env_kwargs)
        self.seed = int(seed)
        torch.manual_seed(self.seed)
        self.venv = BatchedUrbanCanyonEnv(settings.n_copies, **self.env_kwargs)
        self.n_agents = self.venv.n_agents
        obs_dim = self.venv.obs_dim
        self.actor_dim = obs_dim + settings.actor_extra_inputs
        state_dim = self.venv.config.state_dim if settings.centralised_critic else 0
        self.critic_dim = obs_dim + state_dim
        self.actor, self.critic = build_modules(
            settings, self.n_agents, self.actor_dim, self.critic_dim
        )
        loss_class = ClipPPOLoss if settings.dual_clip is None else _dual_clip_loss_class()
        extra = {} if settings.dual_clip is None else {"dual_clip": settings.dual_clip}
        self.loss = loss_class(
            **extra,
            actor_network=self.actor,
            critic_network=self.critic,
            clip_epsilon=settings.clip_epsilon,
            entropy_bonus=settings.entropy_coef > 0.0,
            entropy_coeff=settings.entropy_coef,
            critic_coeff=settings.critic_coef,
            loss_critic_type="l2",
            normalize_advantage=True,
        )
        self.loss.set_keys(
            reward=("agents", "reward"),
            action=("agents", "action"),
            sample_log_prob=("agents", "action_log_prob"),
            value=("agents", "state_value"),
            done=("agents", "done"),
            terminated=("agents", "terminated"),
            advantage=("agents", "advantage"),
            value_target=("agents", "value_target"),
        )
        # one transition per decision: with action_repeat R it spans R steps, discounted by
        # gamma^R (gamma ** 1 == gamma, so R = 1 is the per-step estimator as before)
        self.loss.make_value_estimator(
            ValueEstimators.GAE,
            gamma=settings.gamma**settings.action_repeat,
            lmbda=settings.gae_lambda,
        )
        if settings.start_hold_decisions > 0:
            if self.venv.config.action_frame != "route":
                raise ValueError(
                    "torchrl.start_hold_decisions needs env.action_frame 'route' (its speed "
                    f"set-point -1 holds a UAV in place), got {self.venv.config.action_frame!r}"
                )
        self.optim = torch.optim.Adam(self.loss.parameters(), lr=settings.learning_rate)
        self.reward_std = _RunningStd((settings.n_copies, self.n_agents), settings.gamma)
        self.agent_steps = 0
        self.iterations = 0
        self._bases = self._make_bases()
        self._env_seed = self.seed if env_seed is None else int(env_seed)
        self.warm_start_info: dict[str, Any] | None = None
        obs, _ = self.venv.reset(seed=self._env_seed)
        self._obs = obs.copy()
        self._start_hold()
        for b in self._bases:
            if b is not None:
                b.reset()
        self._ep_return = np.zeros(settings.n_copies)
        self._ep_err_sum = np.zeros(settings.n_copies)
        self._ep_err_n = np.zeros(settings.n_copies)
        self.episode_log: list[dict[str, float]] = []

    # ---- collection -----------------------------------------------------------------------

    def _make_bases(self) -> list[Any]:
        s = self.settings
        if s.residual_base is None:
            return [None] * s.n_copies
        from coopnav_env.agents import make_policy

        return [make_policy(s.residual_base, e, **s.residual_base_kwargs) for e in self.venv.envs]

    def _states(self, copies: np.ndarray | None = None) -> np.ndarray | None:
        """The global states ``(K, state_dim)`` of every copy (or of the ``copies`` given, in
        that order) for the MAPPO critic; None for IPPO."""
        if not self.settings.centralised_critic:
            return None
        envs = self.venv.envs
        if copies is None:
            return np.stack([e.state() for e in envs])
        if copies.size == 0:
            return np.empty((0, self.venv.config.state_dim), dtype=np.float32)
        return np.stack([envs[k].state() for k in copies.tolist()])

    def collect(self) -> Any:
        """One rollout of ``rollout_steps`` decisions of every copy (``action_repeat`` swarm
        steps each), as a TensorDict."""
        import torch
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        s = self.settings
        k_, t_, n_ = s.n_copies, s.rollout_steps, self.n_agents
        actor_in, critic_in, next_critic_in, acts, logps = [], [], [], [], []
        rewards, dones, terms = [], [], []
        state = self._states()
        for _ in range(t_):
            raise_if_interrupted()  # between steps, never inside a compiled call
            base = self._before()
            a_in = _actor_inputs(self._obs, base)
            c_in = _critic_inputs(self._obs, state)
            td = TensorDict({("agents", "observation"): torch.from_numpy(a_in)}, batch_size=[k_])
            # sample (TorchRL's modules return the distribution's mode unless told otherwise)
            with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
                td = self.actor(td)
            raw, logp = td["agents", "action"].numpy(), td["agents", "action_log_prob"].numpy()
            held = self._hold > 0  # (K, N): exploring starts (start_hold_decisions)
            if held.any():  # stored as flown: a draw from the actor's tail below -1
                raw, logp = self._draw_holds(td, raw, logp, held)
            n_c_in, acc, ended, state = self._act_held(raw, base)
            if s.start_hold_decisions > 0:
                self._advance_hold(ended)
            actor_in.append(a_in)
            critic_in.append(c_in)
            next_critic_in.append(n_c_in)
            acts.append(raw)
            logps.append(logp)
            rewards.append(acc)
            dones.append(ended)
            terms.append(ended)
        self.agent_steps += k_ * t_ * n_ * s.action_repeat

        def stack(xs: list[np.ndarray], dtype: Any = torch.float32) -> Any:
            return torch.as_tensor(np.stack(xs, axis=1), dtype=dtype)  # [K, T, ...]

        done_t = stack(dones, torch.bool)[..., None, None].expand(k_, t_, n_, 1)
        term_t = stack(terms, torch.bool)[..., None, None].expand(k_, t_, n_, 1)
        data = TensorDict(
            {
                ("agents", "observation"): stack(actor_in),
                ("agents", "critic_input"): stack(critic_in),
                ("agents", "action"): stack(acts),
                ("agents", "action_log_prob"): stack(logps),
                ("next", "agents", "critic_input"): stack(next_critic_in),
                ("next", "agents", "reward"): stack(rewards)[..., None],
                ("next", "agents", "done"): done_t.clone(),
                ("next", "agents", "terminated"): term_t.clone(),
            },
            batch_size=[k_, t_],
        )
        return data

    def _draw_holds(
        self, td: Any, raw: np.ndarray, logp: np.ndarray, held: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The held UAVs' speed entry redrawn from the actor's Gaussian below -1 (its tail,
        flown as -1) and their log-probabilities the actor's own of the redrawn action, as if
        the actor had drawn it; the other UAVs' actions and log-probabilities as drawn."""
        import torch

        with torch.no_grad():
            dist = self.actor.get_dist(td.select(("agents", "observation")))
            normal = dist.base_dist
            mu = normal.loc[..., 0].double()
            sd = normal.scale[..., 0].double()
            c = (-1.0 - mu) / sd  # the standardised edge of the tail
            log_tail = torch.special.log_ndtr(c)
            u = torch.from_numpy(self._hold_rng.random(tuple(c.shape)))
            z = torch.special.ndtri(u * torch.exp(log_tail))
            z = torch.where(torch.isfinite(z), torch.minimum(z, c), c)
            action = torch.from_numpy(raw.copy())
            mask = torch.from_numpy(held)
            tail = (mu + sd * z).float().clamp_max(-1.0)
            action[..., 0] = torch.where(mask, tail, action[..., 0])
            actor_logp = dist.log_prob(action)
        return action.numpy(), np.where(held, actor_logp.numpy(), logp)

    def _start_hold(self) -> None:
        """Every copy's held decisions for its first episode (``start_hold_decisions``),
        from a generator of its own seeded with the reset seed."""
        self._hold_rng = np.random.default_rng([self._env_seed, 0x686F6C64])
        self._hold = np.zeros((self.settings.n_copies, self.n_agents), dtype=np.int64)
        self._advance_hold(np.ones(self.settings.n_copies, dtype=bool))

    def _advance_hold(self, ended: np.ndarray) -> None:
        """One decision less to hold for every UAV; a new draw, uniform in ``0, 1, ...,
        start_hold_decisions``, for every UAV of the copies whose episode ``ended``."""
        h = self.settings.start_hold_decisions
        draw = self._hold_rng.integers(0, h + 1, size=self._hold.shape)
        self._hold = np.where(ended[:, None], draw, np.maximum(self._hold - 1, 0))

    def _act_held(
        self, raw: np.ndarray, base: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Fly every copy ``action_repeat`` steps on the actor's output ``raw`` (K, N, 3).

        Returns the critic's input after the decision (at the episode's end for a copy that
        finished within it), the scaled rewards summed over the decision's steps up to that
        end, which copies finished, and the copies' states now (:meth:`_states`, for the
        next decision's critic). ``base``: the base commands before the first step
        (velocity mode), recomputed before every later step.

        A copy's state is read only where it is used: after the step at which the copy's
        episode ends within the decision (the state the copy has then, after its automatic
        reset, beside its final observation) and after the decision's last step.
        """
        s = self.settings
        k_, n_ = s.n_copies, self.n_agents
        acc = np.zeros((k_, n_))
        ended = np.zeros(k_, dtype=bool)
        n_c_in = np.empty((k_, n_, self.critic_dim), dtype=np.float32)
        states = None
        for j in range(s.action_repeat):
            if j > 0:
                base = self._before()
            cmd = swarm_command(s, raw, None, base)  # every copy at once
            obs, rew, terminated, truncated, info, final_obs = self.venv.step_arrays(cmd)
            done = terminated | truncated
            self._log_episodes(rew, done, info)
            scaled = (
                self.reward_std.scale(rew, np.repeat(done[:, None], n_, 1))
                if s.normalize_reward
                else rew
            )
            live = ~ended
            # the critic's input after the step of the copies whose decision ends here; a
            # finished copy has been reset already, so its episode end is treated as
            # terminal (no bootstrap, see the module docstring)
            if j == s.action_repeat - 1:
                states = self._states()
                take = np.flatnonzero(live)
                after = _critic_inputs(final_obs[take], None if states is None else states[take])
            else:
                take = np.flatnonzero(live & done)
                after = _critic_inputs(final_obs[take], self._states(take))
            n_c_in[take] = after
            acc[live] += scaled[live]
            ended |= done
            self._obs = obs.copy()
            if self._bases[0] is not None:
                for kk in np.flatnonzero(done).tolist():
                    self._bases[kk].reset()
        return n_c_in, acc, ended, states

    def _before(self) -> np.ndarray | None:
        """Every copy's base command ``(K, N, 3)`` the actor reads (velocity mode), else None."""
        if self.settings.actor_extra_inputs == 0:
            return None
        agents = self.venv.possible_agents
        return np.stack(
            [
                base_command_before(self.settings, b, dict(zip(agents, o)), agents)
                for b, o in zip(self._bases, self._obs)
            ]
        )

    def _log_episodes(
        self, rew: np.ndarray, done: np.ndarray, info: Mapping[str, np.ndarray]
    ) -> None:
        """Add a step to every copy's running episode figures and log the episodes that
        ended (``info``: the step's infos as ``(K, N)`` arrays,
        :meth:`~coopnav_env.envs.BatchedUrbanCanyonEnv.step_arrays`)."""
        self._ep_return += rew.mean(axis=1)
        err = info["coop_error_m"]
        fix = info["coop_fix"]
        # each copy's sum over its UAVs with a fix, added up UAV after UAV
        step_sum = np.zeros(err.shape[0])
        for i in range(err.shape[1]):
            step_sum += np.where(fix[:, i], err[:, i], 0.0)
        self._ep_err_sum += step_sum
        self._ep_err_n += fix.sum(axis=1)
        if not done.any():
            return
        goal = info["in_goal"].all(axis=1)
        collision = info["collided"].any(axis=1)
        for k in np.flatnonzero(done).tolist():
            self.episode_log.append(
                {
                    "return": float(self._ep_return[k]),
                    "goal": float(goal[k]),
                    "collision": float(collision[k]),
                    "coop_error_m": float(self._ep_err_sum[k] / max(self._ep_err_n[k], 1.0)),
                    "length": float(info["step"][k, 0]),
                }
            )
            self._ep_return[k] = 0.0
            self._ep_err_sum[k] = 0.0
            self._ep_err_n[k] = 0.0

    # ---- warm start -----------------------------------------------------------------------

    def warm_start(self, spec: WarmStart, progress: bool = False) -> dict[str, Any]:
        """Behaviour cloning of a heuristic teacher before the first PPO iteration.

        The teacher (:func:`coopnav_env.agents.make_policy` ``(spec.policy, copy,
        **spec.policy_kwargs)``, one per swarm copy) flies ``spec.episodes`` episodes in this
        trainer's batched environment, ``n_copies`` at a time: episode ``i`` from reset seed
        ``EVAL_SEED_START // 2 + seed + i`` (training seeds, below the held-out ones). Each
        UAV's step gives a sample: its actor input, the teacher's command clipped to
        ``[-1, 1]``, its critic input (with ``state()`` for MAPPO) and its return-to-go
        (the rewards to the episode's end, discounted with ``gamma`` per step).

        With ``normalize_reward`` the teacher's rewards also feed the trainer's running
        return scale (as PPO's rollouts do), and the critic is fitted to the return-to-go
        divided by that scale, so that its values are in the units PPO's value targets will
        have. Then, for ``spec.epochs`` passes (Adam, ``spec.learning_rate``, minibatches of
        :data:`WARM_START_BATCH` agent-samples, shuffled by a generator seeded with ``seed``),
        the actor's mean (the Gaussian's location, whose clipped value is the command) is
        fitted to the teacher's commands and the critic to the scaled return-to-go, both by
        mean squared error. The log standard deviation is left as it was, so PPO explores
        around the teacher. Afterwards the environment is reset with the run's own seed, so
        PPO meets the episodes it would have met without the warm start.

        Interrupts are taken between steps and between minibatches
        (:func:`coopnav_env.training.runs.raise_if_interrupted`).

        Returns
        -------
        dict
            What ``run.json`` records under ``warm_start``: the teacher and its options,
            episodes, epochs, learning rate, samples, the teacher's goal rate, the return
            scale, and the actor's mean squared error to the teacher's commands before and
            after the fit (``action_mse_before``, ``action_mse_after``), the critic's after,
            and the wall-clock seconds it took (not part of ``run.json``'s ``train_s``).

        Raises
        ------
        ValueError
            A residual policy (its output is not the command), or teacher options the policy
            rejects.
        """
        import torch
        from tensordict import TensorDict
        from tensordict.nn import AddStateIndependentNormalScale

        from coopnav_env.agents import make_policy

        s = self.settings
        if s.residual_base is not None:
            raise ValueError(
                "torchrl.pretrain needs torchrl.residual_base null: a residual policy's output "
                "is not the command the teacher gives"
            )
        k_, n_ = s.n_copies, self.n_agents
        agents = self.venv.possible_agents
        try:
            teachers = [make_policy(spec.policy, e, **spec.policy_kwargs) for e in self.venv.envs]
        except TypeError as exc:
            raise ValueError(
                f"torchrl.pretrain.policy_kwargs: the {spec.policy!r} teacher does not take "
                f"{spec.policy_kwargs} ({exc})"
            ) from None
        first_seed = EVAL_SEED_START // 2 + self.seed
        t_start = time.perf_counter()
        actor_in: list[np.ndarray] = []
        critic_in: list[np.ndarray] = []
        acts: list[np.ndarray] = []
        rtg: list[np.ndarray] = []
        goals = 0
        waves = -(-spec.episodes // k_)
        bar = _steps_bar(spec.episodes, progress, "warm start: teacher", "episode")
        for w in range(waves):
            obs, _ = self.venv.reset(seed=first_seed + w * k_)
            obs = obs.copy()
            for k, t in enumerate(teachers):
                t.reset(seed=first_seed + w * k_ + k)
            # copy k records its first episode of the wave (the last wave: only those needed)
            recording = np.arange(k_) < spec.episodes - w * k_
            ep: list[dict[str, list[np.ndarray]]] = [
                {"a_in": [], "c_in": [], "act": [], "rew": []} for _ in range(k_)
            ]
            state = self._states()
            while recording.any():
                raise_if_interrupted()  # between steps (see runs.interrupts_deferred)
                obs_d = [dict(zip(agents, obs[k])) for k in range(k_)]
                cmd = np.stack(
                    [np.stack([teachers[k].act(obs_d[k])[a] for a in agents]) for k in range(k_)]
                ).astype(np.float64)
                cmd = np.clip(cmd, -1.0, 1.0)
                c_in = _critic_inputs(obs, state)
                for k in np.flatnonzero(recording).tolist():
                    ep[k]["a_in"].append(obs[k].copy())
                    ep[k]["c_in"].append(c_in[k].copy())
                    ep[k]["act"].append(cmd[k].astype(np.float32))
                nxt, rew, terminated, truncated, info, _ = self.venv.step_arrays(cmd)
                done = terminated | truncated
                if s.normalize_reward:
                    self.reward_std.scale(rew, np.repeat(done[:, None], n_, 1))
                for k in np.flatnonzero(recording).tolist():
                    ep[k]["rew"].append(rew[k].copy())
                    if done[k]:
                        recording[k] = False
                        goals += bool(info["in_goal"][k].all())
                        rewards = np.stack(ep[k]["rew"])  # (T, N)
                        togo = np.zeros_like(rewards)
                        acc = np.zeros(n_)
                        for t in range(len(rewards) - 1, -1, -1):
                            acc = rewards[t] + s.gamma * acc
                            togo[t] = acc
                        actor_in.append(np.stack(ep[k]["a_in"]))
                        critic_in.append(np.stack(ep[k]["c_in"]))
                        acts.append(np.stack(ep[k]["act"]))
                        rtg.append(togo)
                        if bar is not None:
                            bar.update(1)
                for k in np.flatnonzero(done).tolist():
                    teachers[k].reset()
                obs = nxt.copy()
                state = self._states()
        if bar is not None:
            bar.close()
        # the accumulated discounted returns start again at zero, as in a run without it
        self.reward_std.ret = np.zeros_like(self.reward_std.ret)
        ret_scale = math.sqrt(self.reward_std.var + 1e-8) if s.normalize_reward else 1.0

        def rows(xs: list[np.ndarray], width: int) -> Any:
            return torch.as_tensor(np.concatenate(xs).reshape(-1, width), dtype=torch.float32)

        x, y, xc = rows(actor_in, self.actor_dim), rows(acts, 3), rows(critic_in, self.critic_dim)
        v = torch.as_tensor(np.concatenate(rtg).reshape(-1) / ret_scale, dtype=torch.float32)
        actor_module = self.actor.module[0]  # writes ("agents", "loc") and ("agents", "scale")
        critic_net = self.critic.module

        def mean_of(rows: Any) -> Any:
            td = TensorDict({("agents", "observation"): rows}, batch_size=[rows.shape[0]])
            return actor_module(td)["agents", "loc"]

        scale_ids = {
            id(p)
            for m in self.actor.modules()
            if isinstance(m, AddStateIndependentNormalScale)
            for p in m.parameters()
        }
        params = [p for p in self.actor.parameters() if id(p) not in scale_ids]
        params += list(critic_net.parameters())
        opt = torch.optim.Adam(params, lr=spec.learning_rate)
        gen = torch.Generator().manual_seed(self.seed)
        with torch.no_grad():
            mse_before = float(torch.mean((mean_of(x) - y) ** 2))
        ebar = _steps_bar(spec.epochs, progress, "warm start: fitting", "epoch")
        for _ in range(spec.epochs):
            perm = torch.randperm(x.shape[0], generator=gen)
            for i in range(0, x.shape[0], WARM_START_BATCH):
                raise_if_interrupted()
                idx = perm[i : i + WARM_START_BATCH]
                loss_pi = torch.mean((mean_of(x[idx]) - y[idx]) ** 2)
                loss_vf = torch.mean((critic_net(xc[idx]).squeeze(-1) - v[idx]) ** 2)
                opt.zero_grad()
                (loss_pi + loss_vf).backward()
                opt.step()
            if ebar is not None:
                ebar.update(1)
        if ebar is not None:
            ebar.close()
        with torch.no_grad():
            mse_after = float(torch.mean((mean_of(x) - y) ** 2))
            vf_after = float(torch.mean((critic_net(xc).squeeze(-1) - v) ** 2))
        # PPO starts from the run's own episodes
        obs, _ = self.venv.reset(seed=self._env_seed)
        self._obs = obs.copy()
        for b in self._bases:
            if b is not None:
                b.reset()
        self.warm_start_info = {
            "teacher": spec.policy,
            "policy_kwargs": dict(spec.policy_kwargs),
            "episodes": spec.episodes,
            "epochs": spec.epochs,
            "learning_rate": spec.learning_rate,
            "first_seed": first_seed,
            "samples": int(x.shape[0]),
            "teacher_goal_rate": goals / spec.episodes,
            "return_scale": ret_scale,
            "action_mse_before": mse_before,
            "action_mse_after": mse_after,
            "value_mse_after": vf_after,
            "seconds": round(time.perf_counter() - t_start, 1),
        }
        return dict(self.warm_start_info)

    # ---- update ---------------------------------------------------------------------------

    def update(self, data: Any) -> dict[str, float]:
        """PPO epochs over one rollout; returns the mean losses."""
        import torch

        s = self.settings
        with torch.no_grad():
            self.loss.value_estimator(
                data,
                params=self.loss.critic_network_params,
                target_params=self.loss.target_critic_network_params,
            )
        flat = data.reshape(-1)
        n = flat.shape[0]
        mb = max(1, s.minibatch_size // self.n_agents)
        sums: dict[str, float] = {}
        count = 0
        for _ in range(s.epochs):
            perm = torch.randperm(n)
            for i in range(0, n, mb):
                sub = flat[perm[i : i + mb]]
                out = self.loss(sub)
                total = out["loss_objective"] + out["loss_critic"]
                if "loss_entropy" in out.keys():
                    total = total + out["loss_entropy"]
                if not bool(torch.isfinite(total)):
                    raise TrainingDivergedError(
                        f"the PPO loss is not finite at iteration {self.iterations + 1} "
                        f"(agent-step {self.agent_steps}; objective "
                        f"{float(out['loss_objective']):.3g}, critic "
                        f"{float(out['loss_critic']):.3g}): the policy's probability ratios "
                        "ran away, and this minibatch's update was not applied. Resume from a "
                        "checkpoint from before the objective grew (loss_objective in "
                        "logs/progress.csv) with --set torchrl.dual_clip=3 (dual-clip PPO caps "
                        "the ratio), or lower torchrl.learning_rate"
                    )
                self.optim.zero_grad()
                total.backward()
                torch.nn.utils.clip_grad_norm_(self.loss.parameters(), s.max_grad_norm)
                self.optim.step()
                for key in ("loss_objective", "loss_critic"):
                    sums[key] = sums.get(key, 0.0) + float(out[key])
                count += 1
        self.iterations += 1
        return {k: v / max(count, 1) for k, v in sums.items()}

    def learning_rate_at(self, agent_steps: int, total_agent_steps: int) -> float:
        """The learning rate of the iteration that starts at ``agent_steps`` (``lr_schedule``)."""
        s = self.settings
        if s.lr_schedule == "constant":
            return float(s.learning_rate)
        frac = 1.0 - agent_steps / max(int(total_agent_steps), 1)
        return float(s.learning_rate) * min(max(frac, 0.0), 1.0)

    def set_learning_rate(self, lr: float) -> None:
        """Set the optimiser's learning rate (every parameter group)."""
        for group in self.optim.param_groups:
            group["lr"] = lr

    # ---- checkpoints ----------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Everything a resumed run or an evaluation needs."""
        return {
            "format": CHECKPOINT_FORMAT,
            "settings": dataclasses.asdict(self.settings),
            "env_kwargs": self.env_kwargs,
            "n_agents": self.n_agents,
            "actor_dim": self.actor_dim,
            "critic_dim": self.critic_dim,
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "optimizer": self.optim.state_dict(),
            "reward_std": self.reward_std.state_dict(),
            "agent_steps": self.agent_steps,
            "iterations": self.iterations,
            "seed": self.seed,
            **({} if self.warm_start_info is None else {"warm_start": self.warm_start_info}),
        }

    def load_state_dict(self, d: Mapping[str, Any]) -> None:
        """Continue from :meth:`state_dict` (weights, optimiser, reward scale, counters)."""
        from coopnav_env.agents.marl_policy import check_marl_checkpoint

        check_marl_checkpoint(d, "this checkpoint", "resume")  # entries, finite weights
        try:
            self.actor.load_state_dict(d["actor"])
            self.critic.load_state_dict(d["critic"])
            self.optim.load_state_dict(d["optimizer"])
            self.reward_std.load_state_dict(d["reward_std"])
        except (RuntimeError, KeyError, TypeError, ValueError) as exc:
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
            raise ValueError(
                f"the checkpoint does not fit the networks of these settings ({first})"
            ) from exc
        self.agent_steps = int(d["agent_steps"])
        self.iterations = int(d["iterations"])
        self.warm_start_info = d.get("warm_start")

    def save(self, path: str | Path) -> Path:
        """Write :meth:`state_dict` to ``path`` atomically (temporary file, then rename)."""
        return _save_torch(self.state_dict(), path)

    def train(
        self,
        total_agent_steps: int,
        on_iteration: Callable[[dict[str, float]], None] | None = None,
    ) -> None:
        """Iterate collect/update until ``total_agent_steps`` agent-steps are reached.

        With ``lr_schedule: linear`` the learning rate of each iteration is
        ``learning_rate * (1 - agent_steps / total_agent_steps)`` at the iteration's start (a
        function of the step count only, so a resumed run continues the same schedule).
        """
        while self.agent_steps < total_agent_steps:
            raise_if_interrupted()  # between iterations (see runs.interrupts_deferred)
            self.set_learning_rate(self.learning_rate_at(self.agent_steps, total_agent_steps))
            t0 = time.perf_counter()
            data = self.collect()
            t1 = time.perf_counter()
            losses = self.update(data)
            t2 = time.perf_counter()
            recent = self.episode_log[-64:]
            row = {
                "iteration": float(self.iterations),
                "agent_steps": float(self.agent_steps),
                "learning_rate": float(self.optim.param_groups[0]["lr"]),
                "collect_s": t1 - t0,
                "update_s": t2 - t1,
                **losses,
            }
            if recent:
                for key in ("return", "goal", "collision", "coop_error_m", "length"):
                    row[f"ep_{key}"] = float(np.mean([e[key] for e in recent]))
            if on_iteration is not None:
                on_iteration(row)


def _steps_bar(total: int, show: bool, desc: str, unit: str) -> Any:
    """A ``tqdm`` bar on stderr of ``total`` units when ``show`` (and tqdm is there), else None."""
    if not show:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a training dependency
        return None
    return tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True, mininterval=0.5)


def _save_torch(obj: Any, path: str | Path) -> Path:
    """``torch.save(obj)`` to ``path`` atomically; a failed write is an ``OSError``.

    torch reports a failed write (a full disk, a file-size limit) as ``RuntimeError:
    [enforce fail at inline_container.cc]``; it becomes an ``OSError`` naming the file (the
    command line's exit status 1). The earlier file of that name is left as it was.
    """
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(path) as tmp:
            torch.save(obj, tmp)
    except RuntimeError as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise OSError(
            f"cannot write {path} (a full disk or a file-size limit?): {first}; the earlier "
            "file of that name, if any, is unchanged"
        ) from exc
    return path


CHECKPOINT_RE = re.compile(r"^marl_(\d+)_steps\.pt$")

ARCHITECTURE_SETTINGS: tuple[str, ...] = ("algorithm", "hidden", "residual_base")
"""Settings that shape the networks: a run resumes only with the values it was trained with."""


def check_resumable_settings(
    checkpoint: Mapping[str, Any], settings: MARLSettings, path: str | Path
) -> None:
    """Refuse to resume ``checkpoint`` (read from ``path``) with other network settings.

    Raises
    ------
    ValueError
        Naming each of :data:`ARCHITECTURE_SETTINGS` that differs, with both values; or a
        removed setting the checkpoint was trained with
        (:func:`coopnav_env.agents.marl_nets.settings_from_record`).
    """
    try:
        old = settings_from_record(checkpoint["settings"], path, "resume")
    except TypeError as exc:
        raise ValueError(f"{path} holds settings this version does not read: {exc}") from exc
    diff = [
        (name, getattr(old, name), getattr(settings, name))
        for name in ARCHITECTURE_SETTINGS
        if getattr(old, name) != getattr(settings, name)
    ]
    if diff:
        now = ", ".join(f"torchrl.{n}={new!r}" for n, _, new in diff)
        then = ", ".join(f"torchrl.{n}={was!r}" for n, was, _ in diff)
        raise ValueError(
            f"cannot resume from {path} with {now}: it was trained with {then}, and these "
            "settings shape the networks; resume without changing them (e.g. no --algorithm), "
            "or start a new run in another --out"
        )


def settings_of(cfg: TrainConfig) -> tuple[MARLSettings, dict[str, Any]]:
    """The backend's settings and the environment settings of a run configuration.

    ``cfg.torchrl`` holds :class:`MARLSettings` fields plus an optional ``env`` mapping whose
    entries override ``cfg.env`` for this backend (the learning study's rewards) and an
    optional ``pretrain`` mapping (the warm start, read by :func:`pretrain_of`).

    A fresh run refuses the settings of
    :data:`~coopnav_env.agents.marl_nets.REMOVED_SETTINGS`; a resumed one (``cfg.resume``)
    reads what its run recorded, refusing a removed setting only where its value changed
    what the run did (:func:`~coopnav_env.agents.marl_nets.settings_from_record`).
    """
    from coopnav_env.envs.config import V1_DEFAULTS

    d = dict(cfg.torchrl)
    env_over = d.pop("env", None) or {}
    d.pop("pretrain", None)  # the warm start: pretrain_of
    if not isinstance(env_over, Mapping):
        raise ValueError(f"torchrl.env must be a mapping of environment settings, got {env_over!r}")
    # the batched environment is built from settings alone: name urban_canyon_v1's own
    v1 = V1_DEFAULTS if cfg.env_id == "urban_canyon_v1" else {}
    if cfg.resume is not None:
        settings = settings_from_record(d, f"the run in {cfg.out}", "resume")
    else:
        settings = MARLSettings.from_dict(d)
    return settings, {**v1, **cfg.env, **env_over}


def check_pretrain(
    cfg: TrainConfig, settings: MARLSettings, env_kwargs: Mapping[str, Any]
) -> WarmStart | None:
    """The run's warm start (:func:`pretrain_of`), checked against the other settings.

    Raises
    ------
    ValueError
        A bad ``torchrl.pretrain`` entry (named), a residual policy (its output is not the
        command the teacher gives), or teacher options the teacher rejects.
    """
    pretrain = pretrain_of(cfg)
    if pretrain is not None:
        if settings.residual_base is not None:
            raise ValueError(
                "torchrl.pretrain needs torchrl.residual_base null: a residual policy's output "
                f"is not the command the teacher gives (residual_base is "
                f"{settings.residual_base!r})"
            )
        from coopnav_env.agents import make_policy
        from coopnav_env.envs import UrbanCanyonEnv

        env = UrbanCanyonEnv(**env_kwargs)
        try:
            make_policy(pretrain.policy, env, **pretrain.policy_kwargs)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"torchrl.pretrain.policy_kwargs: the {pretrain.policy!r} teacher with "
                f"{pretrain.policy_kwargs} cannot fly this environment: {exc}"
            ) from None
        finally:
            env.close()
    return pretrain


def check(cfg: TrainConfig) -> None:
    """Validate the backend's settings before any work (``ValueError`` naming the setting)."""
    settings, env_kwargs = settings_of(cfg)
    try:
        import tensordict  # noqa: F401
        import torchrl  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            "the torchrl backend needs TorchRL: pip install torch==2.13.0 && "
            'pip install -e ".[marl]"'
        ) from exc
    from coopnav_env.envs import make_config

    env_config = make_config(**env_kwargs)  # environment settings
    decisions = -(-env_config.max_steps // settings.action_repeat)  # of a whole episode
    if settings.start_hold_decisions >= decisions:
        raise ValueError(
            f"torchrl.start_hold_decisions must be < the decisions of an episode, {decisions} "
            f"(env.max_steps {env_config.max_steps} / torchrl.action_repeat "
            f"{settings.action_repeat}), got {settings.start_hold_decisions}: that many would hold "
            "every decision, and nothing would be learned"
        )
    check_pretrain(cfg, settings, env_kwargs)
    if settings.residual_base is not None:
        from coopnav_env.agents import POLICY_NAMES

        if settings.residual_base.split("@")[0] not in POLICY_NAMES:
            raise ValueError(
                f"torchrl.residual_base must be a heuristic policy name, got "
                f"{settings.residual_base!r}"
            )


def find_latest_checkpoint(out: str | Path) -> Path:
    """The newest ``checkpoints/marl_<N>_steps.pt`` of a run folder that loads.

    Checkpoints that do not load (a truncated file) are skipped with a warning naming them.
    """
    import warnings

    folder = Path(out) / "checkpoints"
    found = sorted(
        (int(m.group(1)), p)
        for p in folder.glob("marl_*_steps.pt")
        if (m := CHECKPOINT_RE.match(p.name))
    )
    for _, p in reversed(found):
        try:
            load_checked_checkpoint(p, "resume")
        except ValueError as exc:
            warnings.warn(f"skipping a checkpoint that does not load: {exc}", stacklevel=2)
            continue
        return p
    raise FileNotFoundError(f"no TorchRL checkpoint to resume from in {folder}")


def export_policy(checkpoint: str | Path, out_dir: str | Path) -> Path:
    """Write the acting part of a run into ``out_dir``: ``final_model.pt`` (the actor, its
    settings and the environment; no critic, no optimiser: about 100 kB instead of 700),
    and the run's ``run.json``, ``config.yaml`` and ``logs/progress.csv`` when they exist
    beside it (``coopnav evaluate`` reads the environment from ``config.yaml``).

    ``checkpoint`` is a run folder (its ``final_model.pt``) or a checkpoint file. The result is
    a folder that ``coopnav evaluate --policies mappo:OUT_DIR`` and a study's ``--runs``
    read like a run; it cannot be resumed. From an intermediate checkpoint
    (``RUN/checkpoints/marl_<N>_steps.pt``) only the run's ``config.yaml`` is copied: its
    ``run.json`` and learning curve describe the finished run, not the checkpoint.
    """
    src = Path(checkpoint)
    if src.is_dir():
        run_dir, src = src, src / "final_model.pt"
    else:
        run_dir = src.parent.parent if src.parent.name == "checkpoints" else src.parent
    final = src.name == "final_model.pt"
    beside = ("run.json", "config.yaml", "logs/progress.csv") if final else ("config.yaml",)
    d = load_checked_checkpoint(src, "fly")
    small = {
        k: d[k]
        for k in (
            "format",
            "settings",
            "env_kwargs",
            "n_agents",
            "actor_dim",
            "critic_dim",
            "actor",
            "agent_steps",
            "seed",
        )
    }
    small["policy_only"] = True
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _save_torch(small, out / "final_model.pt")
    for name in beside:
        f = run_dir / name
        if f.is_file():
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(out / name) as tmp:
                shutil.copyfile(f, tmp)
    return out / "final_model.pt"


def train(cfg: TrainConfig) -> Path:
    """``coopnav train --backend torchrl``: train and return the final model's path.

    Writes ``config.yaml`` (resolved settings; ``env`` is what the policy was trained in, read
    by ``coopnav evaluate``; a resumed session that finds one adds
    ``config_resumed_at_<N>.yaml``), ``logs/progress.csv`` (one row per iteration:
    agent-steps, losses, return, goal and collision rate and mean cooperative error of the
    latest training episodes; every iteration once over interrupted and resumed sessions),
    ``checkpoints/marl_<N>_steps.pt`` every ``checkpoint_freq`` agent-steps and on Ctrl-C /
    SIGTERM, ``final_model.pt`` and ``run.json`` (agent-steps per second).

    Interrupts are taken between steps (:func:`coopnav_env.training.runs.interrupts_deferred`),
    start-up included; one that arrives before the networks exist leaves the folder as it
    was before the command (a fresh run's ``config.yaml`` is removed again), so that the same
    command can simply be run again.

    Raises
    ------
    ValueError
        A checkpoint that does not load, lacks entries or holds NaN weights; one trained with
        other environment or network settings (named); ``timesteps`` below the checkpoint's
        agent-steps.
    FileNotFoundError
        ``--resume latest`` in a folder with no checkpoint (the message says whether nothing
        was trained there yet).
    """
    import torch

    settings, env_kwargs = settings_of(cfg)
    pretrain = check_pretrain(cfg, settings, env_kwargs)  # before anything is written
    out = Path(cfg.out)
    with open_run(cfg) as run, interrupts_deferred():
        if cfg.resume == "latest" and run.nothing_to_do(cfg.timesteps):
            run.say_finished()
            return out / "final_model.pt"
        resume_path, resume = _resume_point(cfg, run.finished)
        if resume is not None:
            if resume["env_kwargs"] != env_kwargs:
                raise ValueError(
                    f"cannot resume in {out}: the checkpoint {resume_path} was trained with "
                    f"{resume['env_kwargs']}, not {env_kwargs}"
                )
            check_resumable_settings(resume, settings, resume_path)
            if run.nothing_to_do(cfg.timesteps):  # e.g. --resume RUN/final_model
                run.say_finished()
                return out / "final_model.pt"
            steps = int(resume["agent_steps"])
            if steps > cfg.timesteps:
                raise ValueError(
                    f"--timesteps {cfg.timesteps} is below the {steps} agent-steps of the "
                    f"checkpoint {resume_path}: nothing would be trained; ask for more "
                    f"(--timesteps M with M > {steps})"
                )
        torch.set_num_threads(cfg.torch_threads)
        resolved = cfg.to_dict()
        resolved["env"] = env_kwargs
        resolved["backend"] = "torchrl"
        wrote_config = None
        if resume is None or not (out / "config.yaml").is_file():
            # a run resumed from another folder's checkpoint, or whose config.yaml is gone,
            # records its settings too: `coopnav evaluate` reads the environment from it
            wrote_config = write_yaml(out / "config.yaml", resolved)
        else:
            resolved["resume"] = str(resume_path)
            wrote_config = out / f"config_resumed_at_{int(resume['agent_steps'])}.yaml"
            wrote_config = write_yaml(wrote_config, resolved)
        try:
            return train_marl(
                out,
                settings,
                env_kwargs,
                cfg.seed,
                cfg.timesteps,
                checkpoint_freq=cfg.checkpoint_freq,
                resume=resume,
                progress=cfg.progress_bar,
                pretrain=pretrain,
            )
        except _NotResumable as exc:  # refused before training: leave the folder as it was
            _remove_start_of_run(out, wrote_config)
            raise ValueError(
                f"cannot resume from {resume_path}: {exc}; give a checkpoint that `coopnav "
                "train` wrote with these settings, or start a new run without --resume"
            ) from None
        except _NothingTrained:
            if resume is None and wrote_config is not None:
                _remove_start_of_run(out, wrote_config)
                print(
                    f"\ninterrupted before training started: nothing was trained, and {out} "
                    "is as it was before this command; run the same command again to start",
                    file=sys.stderr,
                )
            else:
                print(
                    f"\ninterrupted before training continued: nothing new was trained; "
                    f"continue with --resume {cfg.resume}",
                    file=sys.stderr,
                )
            raise


class _NotResumable(ValueError):
    """The checkpoint to resume from does not load into the trainer (nothing was trained)."""


class _NothingTrained(KeyboardInterrupt):
    """An interrupt that arrived before the trainer existed (nothing to save)."""

    def __init__(self, cause: KeyboardInterrupt) -> None:
        super().__init__(*cause.args)
        self.signum = int(getattr(cause, "signum", 2))


def _remove_start_of_run(out: Path, config: Path) -> None:
    """Remove what a fresh run wrote before it trained anything (its config.yaml and the
    empty folders), so that the folder holds no run and the same command can start again."""
    config.unlink(missing_ok=True)
    for name in ("logs", "checkpoints"):
        folder = out / name
        if folder.is_dir() and not any(folder.iterdir()):
            shutil.rmtree(folder, ignore_errors=True)


def _resolve_checkpoint_path(text: str) -> Path:
    """The file ``--resume`` names: a ``.pt`` file, the same without ``.pt``, or a run
    folder (its ``final_model.pt``)."""
    p = Path(text)
    if p.is_dir():
        p = p / "final_model.pt"
    elif not p.is_file() and p.with_suffix(".pt").is_file():
        p = p.with_suffix(".pt")
    return p


def _resume_point(
    cfg: TrainConfig, finished: Mapping[str, Any] | None
) -> tuple[Path | None, dict[str, Any] | None]:
    """(checkpoint file, its contents) to resume from, or (None, None) for a fresh run.

    ``latest``: the newest checkpoint that loads (or a finished run's final model); newer
    ones that do not load, lack entries or hold NaN weights are skipped with a warning.
    """
    if cfg.resume is None:
        return None, None
    out = Path(cfg.out)
    if cfg.resume != "latest":
        path = _resolve_checkpoint_path(cfg.resume)
        return path, load_checked_checkpoint(path, "resume")
    final = None
    if finished is not None and (out / "final_model.pt").is_file():
        final = (int(finished["num_timesteps"]), out / "final_model.pt")
    folder = out / "checkpoints"
    candidates = checkpoint_candidates(folder, "marl_*_steps.pt", CHECKPOINT_RE, final)
    if not candidates:
        if (out / "config.yaml").is_file():
            raise FileNotFoundError(
                f"nothing was trained in {out} yet: it holds the settings of a run "
                f"(config.yaml) but no TorchRL checkpoint in {folder} and no final model; "
                "start it again with --overwrite"
            )
        raise FileNotFoundError(f"no TorchRL checkpoint to resume from in {folder}")
    return first_loadable(
        candidates, lambda p: load_checked_checkpoint(p, "resume"), folder, "TorchRL "
    )


def train_marl(
    out: str | Path,
    settings: MARLSettings,
    env_kwargs: Mapping[str, Any],
    seed: int,
    timesteps: int,
    checkpoint_freq: int = 0,
    resume: Mapping[str, Any] | None = None,
    progress: bool = True,
    pretrain: WarmStart | None = None,
) -> Path:
    """Train and write ``out``: ``logs/progress.csv``, ``checkpoints/``, ``final_model.pt``.

    ``timesteps`` and ``checkpoint_freq`` count agent-steps. Returns the final model's path.
    ``pretrain``: a behaviour-cloning warm start (:meth:`MARLTrainer.warm_start`) before the
    first iteration of a new run; a resumed run (``resume``) never runs it again. SIGINT and
    SIGTERM are taken between steps: the trainer's state is saved as
    ``checkpoints/marl_<N>_steps.pt`` and the interrupt re-raised (an interrupt before the
    trainer exists or during the warm start raises a ``KeyboardInterrupt`` with nothing
    saved).
    """
    import warnings

    out = Path(out)
    trainer = None
    bar = None
    t_start = time.perf_counter()
    try:
        with interrupts_deferred():
            (out / "logs").mkdir(parents=True, exist_ok=True)
            # a resumed run continues with new episodes (training seeds below the held-out)
            env_seed = None
            if resume is not None:
                env_seed = (seed + int(resume["agent_steps"])) % (
                    EVAL_SEED_START - settings.n_copies
                )
            try:
                built = MARLTrainer(settings, env_kwargs, seed, env_seed=env_seed)
                if resume is not None:
                    try:
                        built.load_state_dict(resume)
                    except ValueError as exc:
                        raise _NotResumable(str(exc)) from exc
                elif pretrain is not None:
                    print(
                        f"behaviour-cloning warm start: {pretrain.episodes} episodes of the "
                        f"{pretrain.policy} teacher, {pretrain.epochs} epochs",
                        file=sys.stderr,
                        flush=True,
                    )
                    built.warm_start(pretrain, progress=progress)
            except KeyboardInterrupt as exc:
                raise _NothingTrained(exc) from None
            trainer = built
            log = ProgressLog(
                out / "logs" / "progress.csv",
                "agent_steps",
                resumed_at=None if resume is None else trainer.agent_steps,
                decimals=6,
            )
            next_ckpt = [
                (trainer.agent_steps // checkpoint_freq + 1) * checkpoint_freq
                if checkpoint_freq
                else 0
            ]
            t_start = time.perf_counter()
            steps_start = trainer.agent_steps
            if progress:
                try:
                    from tqdm import tqdm

                    bar = tqdm(total=timesteps, initial=trainer.agent_steps, unit="agent-step")
                except ImportError:  # pragma: no cover
                    bar = None

            def on_iteration(row: dict[str, float]) -> None:
                row["wall_s"] = time.perf_counter() - t_start
                log.append(row)
                if bar is not None:
                    bar.update(int(row["agent_steps"]) - bar.n)
                    bar.set_postfix(
                        ret=f"{row.get('ep_return', float('nan')):.1f}",
                        goal=f"{row.get('ep_goal', float('nan')):.2f}",
                        err=f"{row.get('ep_coop_error_m', float('nan')):.2f}",
                    )
                if checkpoint_freq and trainer.agent_steps >= next_ckpt[0]:
                    trainer.save(out / "checkpoints" / f"marl_{trainer.agent_steps}_steps.pt")
                    next_ckpt[0] = (trainer.agent_steps // checkpoint_freq + 1) * checkpoint_freq

            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*advantage normalization.*")
                warnings.filterwarnings("ignore", message=".*requires_grad.*")
                trainer.train(timesteps, on_iteration)
    except _NothingTrained:
        raise
    except KeyboardInterrupt as exc:
        if bar is not None:
            bar.close()
        if trainer is None:
            raise _NothingTrained(exc) from None
        saved = trainer.save(out / "checkpoints" / f"marl_{trainer.agent_steps}_steps.pt")
        print(
            f"\ninterrupted: saved the policy after {trainer.agent_steps} agent-steps to "
            f"{saved}; continue with --resume latest",
            file=sys.stderr,
        )
        raise
    if bar is not None:
        bar.close()
    final = trainer.save(out / "final_model.pt")
    elapsed = time.perf_counter() - t_start
    trained = trainer.agent_steps - steps_start
    run = {
        "backend": "torchrl",
        "algorithm": settings.algorithm,
        "seed": seed,
        "agent_steps": trainer.agent_steps,
        "num_timesteps": trainer.agent_steps,
        "iterations": trainer.iterations,
        "session_agent_steps": trained,
        "train_s": elapsed,
        "agent_steps_per_s": round(trained / max(elapsed, 1e-9), 1) if trained > 0 else None,
        "settings": dataclasses.asdict(settings),
        "env": dict(env_kwargs),
        # a behaviour-cloning warm start of this run (None: it started from random weights)
        "warm_start": trainer.warm_start_info,
        "finished": True,
    }
    write_json(out / "run.json", run)
    return final
