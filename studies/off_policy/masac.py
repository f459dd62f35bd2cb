"""MASAC through BenchMARL on ``urban_canyon_v1`` street grids: the task, the run folder, the actor.

The pieces that :mod:`train_masac` and :mod:`evaluate_masac` share:

* :class:`HeldDecisions`, a PettingZoo parallel wrapper that holds each action for ``hold``
  swarm steps and returns the sum of their rewards (one decision per ``hold`` steps, as the
  TorchRL recipes' ``torchrl.action_repeat``), counting the swarm steps it flies;
* :class:`HeldCoopnavClass`, the BenchMARL task ``CoopnavTask.URBAN_CANYON_V1`` of
  ``coopnav_env.training.benchmarl_backend`` with that wrapper between the environment and
  TorchRL's ``PettingZooWrapper``;
* :func:`build_experiment`, the BenchMARL ``Experiment`` of MASAC for given settings (training
  and, with a tiny budget, rebuilding the actor to load saved weights into);
* :class:`MasacPolicy`, a saved actor as a coopnav policy (``reset``/``act``): it decides every
  ``hold`` steps, deterministically, and holds the decision in between, exactly as in training.

BenchMARL lives in a venv of its own (the ``benchmarl`` extra): everything that needs it is
imported inside the functions, so this module imports without it.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from pettingzoo.utils.wrappers.base_parallel import BaseParallelWrapper

ENV_ID = "urban_canyon_v1"
GROUP = "uav"
POLICY_FILES = ("actor.pt", "actor.json")
"""What a saved actor folder holds: the policy's weights and the settings that rebuild it."""


@dataclasses.dataclass(frozen=True)
class MasacSettings:
    """What a MASAC run is: the environment, the decision hold and BenchMARL's knobs.

    Frames are BenchMARL's: one frame is one decision of the swarm (``hold`` swarm steps, each
    ``n_uavs`` agent-steps). Every field is checked on construction (``ValueError`` naming it).

    Attributes
    ----------
    env : dict
        ``urban_canyon_v1.parallel_env`` keywords (BenchMARL's ``CoopnavTask`` config).
    hold : int
        Swarm steps each decision is held for (1: none).
    n_envs : int
        Environment copies stepped in turn by the collector.
    frames_per_batch : int
        Decisions collected per iteration (over all copies).
    optimizer_steps : int
        Gradient steps of the actor, the critics and the temperature per iteration.
    train_batch_size : int
        Decisions sampled from the replay buffer per gradient step.
    memory_size : int
        Replay buffer capacity in decisions.
    init_random_frames : int
        Decisions of uniformly random actions that fill the buffer first.
    lr : float
        Adam's learning rate (all losses).
    alpha_init : float
        The entropy temperature's start (MASAC learns it towards the target entropy).
        BenchMARL's default is 1; the runs start at 0.05, the scale of a decision's reward
        (the score, about 2 per UAV, spread over some 25 decisions), so that the entropy bonus
        does not outweigh the reward while Adam brings the temperature down.
    gamma : float
        Discount per decision (1: the undiscounted return, the task's score).
    num_cells : tuple of int
        Hidden layer widths of the actor's and the critics' MLPs.
    """

    env: Mapping[str, Any]
    hold: int = 4
    n_envs: int = 8
    frames_per_batch: int = 400
    optimizer_steps: int = 100
    train_batch_size: int = 256
    memory_size: int = 200_000
    init_random_frames: int = 0
    lr: float = 3e-4
    alpha_init: float = 0.05
    gamma: float = 1.0
    num_cells: tuple[int, ...] = (256, 256)

    def __post_init__(self) -> None:
        ints = {
            "hold": 1,
            "n_envs": 1,
            "frames_per_batch": 1,
            "optimizer_steps": 1,
            "train_batch_size": 1,
            "memory_size": 1,
            "init_random_frames": 0,
        }
        for name, low in ints.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        if self.frames_per_batch % self.n_envs:
            raise ValueError(
                f"frames_per_batch ({self.frames_per_batch}) must be a multiple of n_envs "
                f"({self.n_envs}): each copy collects the same number of decisions"
            )
        if not (isinstance(self.lr, float) and 0.0 < self.lr < 1.0):
            raise ValueError(f"lr must be a float in (0, 1), got {self.lr!r}")
        if not (isinstance(self.alpha_init, float) and self.alpha_init > 0.0):
            raise ValueError(f"alpha_init must be a positive float, got {self.alpha_init!r}")
        if not (isinstance(self.gamma, float) and 0.0 < self.gamma <= 1.0):
            raise ValueError(f"gamma must be a float in (0, 1], got {self.gamma!r}")
        cells = tuple(self.num_cells)
        if not cells or any(isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in cells):
            raise ValueError(f"num_cells must be positive integers, got {self.num_cells!r}")
        object.__setattr__(self, "num_cells", cells)
        object.__setattr__(self, "env", dict(self.env))

    def to_json(self) -> dict[str, Any]:
        """The settings as plain JSON values (:meth:`from_json` reads them back)."""
        out = dataclasses.asdict(self)
        out["env"] = dict(self.env)
        out["num_cells"] = list(self.num_cells)
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> MasacSettings:
        """Settings from :meth:`to_json`'s dictionary (unknown keys raise ``ValueError``)."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown MASAC settings {unknown}; known: {sorted(names)}")
        fields = dict(data)
        if "num_cells" in fields:
            fields["num_cells"] = tuple(fields["num_cells"])
        return cls(**fields)


def default_env_config() -> dict[str, Any]:
    """The environment of the runs: BenchMARL's v1 default (5 UAVs, 200 steps, team credit,
    agent index) in the route frame with the braking autopilot, as the TorchRL route recipes."""
    from coopnav_env.training.benchmarl_backend import DEFAULT_CONFIGS

    return dict(DEFAULT_CONFIGS["URBAN_CANYON_V1"], action_frame="route", route_turn_brake_mps2=2.0)


class HeldDecisions(BaseParallelWrapper):
    """Hold each action for ``hold`` swarm steps of a PettingZoo parallel env.

    ``step(actions)`` steps the wrapped environment up to ``hold`` times with the same
    actions, stopping when the episode ends, and returns the last observations, terminations,
    truncations and infos with every agent's reward summed over those steps. The class
    attribute :attr:`swarm_steps` counts the swarm steps flown by every instance of this
    process (the training's agent-steps are ``swarm_steps * n_uavs``).

    Parameters
    ----------
    env : pettingzoo.ParallelEnv
        The environment (its agents all end together, as coopnav's).
    hold : int
        Swarm steps per decision, at least 1.
    """

    swarm_steps: int = 0

    def __init__(self, env: Any, hold: int) -> None:
        if isinstance(hold, bool) or not isinstance(hold, int) or hold < 1:
            raise ValueError(f"hold must be an integer >= 1, got {hold!r}")
        super().__init__(env)
        self.hold = hold

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Fly ``actions`` for up to ``hold`` swarm steps (see the class docstring)."""
        total: dict[str, float] = {}
        for _ in range(self.hold):
            obs, rewards, terms, truncs, infos = self.env.step(
                {a: actions[a] for a in self.env.agents}
            )
            HeldDecisions.swarm_steps += 1
            for agent, r in rewards.items():
                total[agent] = total.get(agent, 0.0) + float(r)
            if not self.env.agents:
                break
        return obs, total, terms, truncs, infos


def _make_held_env(config: Mapping[str, Any], hold: int, seed: int | None, device: Any) -> Any:
    """One ``urban_canyon_v1`` with ``config``, held decisions, in TorchRL's wrapper
    (module level: picklable)."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    from coopnav_env import urban_canyon_v1

    return PettingZooWrapper(
        env=HeldDecisions(urban_canyon_v1.parallel_env(**dict(config)), hold),
        return_state=True,
        use_mask=False,
        categorical_actions=False,
        seed=seed,
        device=device,
    )


try:  # BenchMARL's venv (the `benchmarl` extra); without it only the settings and wrapper work
    from coopnav_env.training.benchmarl_backend import CoopnavClass
except ImportError:  # pragma: no cover - the project's usual venv
    CoopnavClass = None

if CoopnavClass is not None:

    class HeldCoopnavClass(CoopnavClass):
        """``CoopnavTask.URBAN_CANYON_V1``'s task class whose environment holds each decision
        ``hold`` swarm steps (:class:`HeldDecisions`); ``config`` is the environment's keywords.
        """

        def __init__(self, name: str, config: dict[str, Any], hold: int) -> None:
            super().__init__(name=name, config=config)
            self.hold = int(hold)

        def get_env_fun(
            self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
        ) -> Callable[[], Any]:
            """A picklable function of no arguments that builds one held environment."""
            if not continuous_actions:
                raise ValueError("coopnav has continuous actions only (continuous_actions=False)")
            return functools.partial(
                _make_held_env, copy.deepcopy(self.config), self.hold, seed, device
            )

        def max_steps(self, env: Any) -> int:
            """Decisions per episode: the environment's ``max_steps`` over ``hold``, rounded up."""
            return math.ceil(super().max_steps(env) / self.hold)


def held_task(env: Mapping[str, Any], hold: int) -> Any:
    """The BenchMARL task of the runs: ``HeldCoopnavClass`` (``CoopnavTask.URBAN_CANYON_V1``
    with each decision held ``hold`` swarm steps) with ``env`` as its config."""
    if CoopnavClass is None:
        raise ImportError("the MASAC runs need BenchMARL: install the `benchmarl` extra")
    return HeldCoopnavClass(name="URBAN_CANYON_V1", config=dict(env), hold=hold)


def build_experiment(
    settings: MasacSettings,
    seed: int,
    save_folder: Path,
    max_n_frames: int,
    callbacks: list[Any] | None = None,
) -> Any:
    """BenchMARL's MASAC ``Experiment`` on :func:`held_task` for ``settings``, from random
    weights, CPU, no evaluation during training, the csv logger only (into ``save_folder``).

    ``max_n_frames`` is the budget in decisions (BenchMARL's frames); a run stopped earlier by
    a callback trains on fewer. MASAC's settings are BenchMARL's ``masac.yaml`` defaults
    (two Q-networks on the global state, a learned temperature, tanh-squashed Gaussian).
    """
    from benchmarl.algorithms import MasacConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    cfg = ExperimentConfig.get_from_yaml()
    cfg.sampling_device = cfg.train_device = cfg.buffer_device = "cpu"
    cfg.gamma = settings.gamma
    cfg.lr = settings.lr
    cfg.max_n_frames = int(max_n_frames)
    cfg.max_n_iters = None
    cfg.off_policy_collected_frames_per_batch = settings.frames_per_batch
    cfg.off_policy_n_envs_per_worker = settings.n_envs
    cfg.off_policy_n_optimizer_steps = settings.optimizer_steps
    cfg.off_policy_train_batch_size = settings.train_batch_size
    cfg.off_policy_memory_size = settings.memory_size
    cfg.off_policy_init_random_frames = settings.init_random_frames
    cfg.parallel_collection = False
    cfg.evaluation = False
    cfg.render = False
    cfg.loggers = ["csv"]
    cfg.create_json = False
    cfg.checkpoint_interval = 0
    cfg.checkpoint_at_end = False
    Path(save_folder).mkdir(parents=True, exist_ok=True)
    cfg.save_folder = str(save_folder)
    model = MlpConfig.get_from_yaml()
    model.num_cells = list(settings.num_cells)
    algorithm = MasacConfig.get_from_yaml()
    algorithm.alpha_init = settings.alpha_init
    return Experiment(
        task=held_task(settings.env, settings.hold),
        algorithm_config=algorithm,
        model_config=model,
        critic_model_config=copy.deepcopy(model),
        seed=int(seed),
        config=cfg,
        callbacks=callbacks or [],
    )


def save_actor(experiment: Any, settings: MasacSettings, folder: Path, record: Mapping) -> None:
    """Write the trained policy of ``experiment`` into ``folder``: ``actor.pt`` (the weights of
    the group's policy) and ``actor.json`` (``settings`` and ``record``), each by temporary
    name and rename."""
    import io

    import torch

    from coopnav_env.training.files import atomic_write_bytes, write_json

    folder.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    torch.save(experiment.group_policies[GROUP].state_dict(), buf)
    atomic_write_bytes(folder / "actor.pt", buf.getvalue())
    write_json(folder / "actor.json", {"settings": settings.to_json(), **dict(record)})


def load_actor(folder: Path, scratch: Path) -> tuple[Any, MasacSettings]:
    """The policy module saved by :func:`save_actor` in ``folder`` and its settings.

    The module is rebuilt as BenchMARL builds it (an ``Experiment`` with the saved settings
    and no budget to speak of, its files under ``scratch``) and the weights are loaded into it.
    """
    import torch

    folder = Path(folder)
    missing = [name for name in POLICY_FILES if not (folder / name).is_file()]
    if missing:
        raise ValueError(f"{folder} is not a saved MASAC actor: it lacks {missing}")
    record = json.loads((folder / "actor.json").read_text())
    settings = MasacSettings.from_json(record["settings"])
    experiment = build_experiment(settings, 0, scratch, max_n_frames=settings.frames_per_batch)
    policy = experiment.group_policies[GROUP]
    policy.load_state_dict(torch.load(folder / "actor.pt", map_location="cpu", weights_only=True))
    policy.eval()
    experiment.collector.shutdown()
    return policy, settings


class MasacPolicy:
    """A saved MASAC actor flown as a coopnav policy (``reset``/``act``).

    Every ``hold`` swarm steps after :meth:`reset` it feeds the UAVs' observations to the actor
    and takes its deterministic action (BenchMARL's evaluation mode); in between it repeats
    that action, as :class:`HeldDecisions` did in training.

    Parameters
    ----------
    module : tensordict module
        The group's policy (:func:`load_actor`).
    agents : list of str
        The environment's ``possible_agents`` (the actor's agent order).
    hold : int
        Swarm steps per decision.
    name : str
        The policy's name in reports.
    """

    def __init__(self, module: Any, agents: list[str], hold: int, name: str) -> None:
        self.module = module
        self.agents = list(agents)
        self.hold = int(hold)
        self.name = name
        self._held: dict[str, np.ndarray] | None = None
        self._since = 0

    def reset(self, seed: int | None = None) -> None:
        """Forget the held decision (the actor is deterministic: ``seed`` is not used)."""
        self._held = None
        self._since = 0

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """One float32 action in [-1, 1] per agent of ``observations``."""
        if self._held is None or self._since >= self.hold:
            self._held = self._decide(observations)
            self._since = 0
        self._since += 1
        return {a: self._held[a] for a in observations}

    def _decide(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        import torch
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        obs = np.stack([np.asarray(observations[a], dtype=np.float32) for a in self.agents])
        td = TensorDict(
            {GROUP: TensorDict({"observation": torch.from_numpy(obs)}, batch_size=[len(obs)])},
            batch_size=[],
        )
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            action = self.module(td)[GROUP, "action"].numpy()
        action = np.clip(action.astype(np.float32), -1.0, 1.0)
        return {a: action[i] for i, a in enumerate(self.agents)}
