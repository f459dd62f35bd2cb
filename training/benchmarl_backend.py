"""BenchMARL tasks for coopnav: train BenchMARL's algorithms (MAPPO, IPPO, MASAC, ...) on it.

`BenchMARL <https://github.com/facebookresearch/BenchMARL>`_ runs its algorithms on *tasks*: a
:class:`~benchmarl.environments.Task` enum whose members name the tasks, and a
:class:`~benchmarl.environments.TaskClass` that builds a TorchRL environment for one of them.
This module provides both for coopnav:

* :class:`CoopnavTask`, with the members ``URBAN_CANYON_V1`` (the reward is the task's score;
  the one to train on) and ``URBAN_CANYON_V0`` (v0's shaped per-step reward);
* :class:`CoopnavClass`, which wraps ``coopnav_env.urban_canyon_v1.parallel_env(**config)``
  (or ``urban_canyon_v0``) in TorchRL's ``PettingZooWrapper`` with continuous actions, no
  action mask and the global ``state`` for centralised critics (MAPPO, MASAC, ...).

The task's ``config`` is the environment's keyword arguments: any
:class:`~coopnav_env.envs.config.UrbanCanyonConfig` field (``n_uavs``, ``max_steps``,
``city``, ...), ``preset``, and ``render_mode`` (``"rgb_array"`` turns on BenchMARL's
evaluation rendering; it needs ``matplotlib``, the ``plot`` extra). ``task.get_task()``
(no argument) gives :data:`DEFAULT_CONFIGS`; ``task.get_task(config)`` uses ``config`` as it
is. The UAVs form one BenchMARL group, ``"uav"`` (``uav_0`` ... ``uav_{N-1}``): with
``share_policy_params`` (BenchMARL's default) they share one network, hence the one-hot agent
index in the observation (``obs_agent_index``) of the v1 default.

**Discount.** The undiscounted return of an ``urban_canyon_v1`` episode *is* the task's score
(see ``coopnav_env.urban_canyon_v1``, "Discounting"); BenchMARL discounts at
``ExperimentConfig.gamma`` (0.99 in its yaml), so set ``experiment_config.gamma = 1.0`` for
``urban_canyon_v1``, as the project's own v1 training configurations do.

Install: BenchMARL pins ``torchrl<0.12``, so it lives in a venv of its own, the ``benchmarl``
extra (not beside the ``marl`` extra's TorchRL 0.14)::

    pip install torch==2.13.0 torchvision==0.28.0 && pip install -e ".[benchmarl]"

Without BenchMARL, importing this module raises an :class:`ImportError` that says so. (PyPI's
torchvision 0.28.0 is a CUDA build that does not import beside the CPU torch; nothing here
needs it, only TorchRL's mp4 video writing does.)

Example::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from coopnav_env.training.benchmarl_backend import CoopnavTask

    experiment_config = ExperimentConfig.get_from_yaml()
    experiment_config.gamma = 1.0  # urban_canyon_v1: the undiscounted return is the score
    experiment = Experiment(
        task=CoopnavTask.URBAN_CANYON_V1.get_task(),  # or .get_task({"n_uavs": 3, ...})
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=experiment_config,
    )
    experiment.run()
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable
from typing import Any

try:
    from benchmarl.environments.common import Task, TaskClass
    from torchrl.data import Composite
    from torchrl.envs import EnvBase
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
except ImportError as exc:  # a venv without BenchMARL (tests/training/test_benchmarl_backend.py)
    raise ImportError(
        "coopnav_env.training.benchmarl_backend needs BenchMARL (missing module: "
        f"{getattr(exc, 'name', None) or exc}). Install the `benchmarl` extra in a venv of its "
        "own (BenchMARL pins torchrl<0.12, so it cannot share a venv with the `marl` extra): "
        'pip install torch==2.13.0 torchvision==0.28.0 && pip install -e ".[benchmarl]"'
    ) from exc

from coopnav_env import urban_canyon_v0, urban_canyon_v1

__all__ = ["DEFAULT_CONFIGS", "DEFAULT_MAX_STEPS", "CoopnavClass", "CoopnavTask"]

DEFAULT_MAX_STEPS = 200
"""The environment's default ``max_steps`` (``UrbanCanyonConfig.max_steps``)."""

DEFAULT_CONFIGS: dict[str, dict[str, Any]] = {
    "URBAN_CANYON_V1": {
        "n_uavs": 5,
        "max_steps": DEFAULT_MAX_STEPS,
        # team credit: each UAV's navigation term is the swarm's mean (the score is unchanged)
        "nav_team_weight": 1.0,
        # each UAV sees its one-hot index, so that a shared network can tell the UAVs apart
        "obs_agent_index": True,
    },
    "URBAN_CANYON_V0": {"n_uavs": 5, "max_steps": DEFAULT_MAX_STEPS},
}
"""Task name -> the default ``config`` (environment keyword arguments) of
``CoopnavTask.<name>.get_task()``; the v1 one is the project's v1 training setting."""

_MAKERS: dict[str, Callable[..., Any]] = {
    "URBAN_CANYON_V1": urban_canyon_v1.parallel_env,
    "URBAN_CANYON_V0": urban_canyon_v0.parallel_env,
}


def _make_env(name: str, config: dict[str, Any], seed: int | None, device: Any) -> EnvBase:
    """One coopnav environment in TorchRL's ``PettingZooWrapper`` (module level: picklable)."""
    fields = dict(config)
    render_mode = fields.pop("render_mode", None)
    return PettingZooWrapper(
        env=_MAKERS[name](render_mode=render_mode, **fields),
        return_state=True,
        use_mask=False,
        categorical_actions=False,
        seed=seed,
        device=device,
    )


def _coopnav_config(env: EnvBase) -> Any:
    """The ``UrbanCanyonConfig`` of the coopnav environment inside ``env`` (through TorchRL
    transforms and the wrapper), or None."""
    while hasattr(env, "base_env"):
        env = env.base_env
    return getattr(getattr(env, "_env", None), "config", None)


def _keep_only(spec: Composite, groups: list[str], key: str) -> Composite:
    """``spec`` with only ``(group, key)`` under each group and no ``state``."""
    spec = spec.clone()
    for group in groups:
        group_spec = spec[group]
        for k in list(group_spec.keys()):
            if k != key:
                del group_spec[k]
    if "state" in spec.keys():
        del spec["state"]
    return spec


class CoopnavClass(TaskClass):
    """A coopnav task for BenchMARL: builds the environment and describes its specs.

    Parameters
    ----------
    name : str
        The :class:`CoopnavTask` member's name (``"URBAN_CANYON_V1"`` or ``"URBAN_CANYON_V0"``).
    config : dict
        The environment's keyword arguments (``UrbanCanyonConfig`` fields, ``preset``,
        ``render_mode``). Usually made by ``CoopnavTask.URBAN_CANYON_V1.get_task(config)``.

    The environment has continuous actions only ((3,) in [-1, 1] per UAV), one agent group
    (``"uav"``), the observation under ``("uav", "observation")``, the infos under
    ``("uav", "info")`` and the global state under ``"state"``.
    """

    def get_env_fun(
        self,
        num_envs: int,
        continuous_actions: bool,
        seed: int | None,
        device: Any,
    ) -> Callable[[], EnvBase]:
        """A picklable function of no arguments that builds one wrapped environment.

        ``num_envs`` is ignored (the environment is not vectorised: BenchMARL puts copies in a
        ``SerialEnv``/``ParallelEnv``); ``continuous_actions`` must be True.
        """
        if not continuous_actions:
            raise ValueError("coopnav has continuous actions only (continuous_actions=False)")
        return functools.partial(_make_env, self.name, copy.deepcopy(self.config), seed, device)

    def supports_continuous_actions(self) -> bool:
        """True: each UAV's action is a (3,) velocity command in [-1, 1]."""
        return True

    def supports_discrete_actions(self) -> bool:
        """False: there is no discrete action space."""
        return False

    def has_render(self, env: EnvBase) -> bool:
        """True when the config asks for ``render_mode="rgb_array"`` (evaluation videos)."""
        return self.config.get("render_mode") == "rgb_array"

    def max_steps(self, env: EnvBase) -> int:
        """The episode's step limit: the environment's ``max_steps`` (200 by default)."""
        cfg = _coopnav_config(env)
        if cfg is not None:
            return int(cfg.max_steps)
        return int(self.config.get("max_steps", self.config.get("max_cycles", DEFAULT_MAX_STEPS)))

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        """The wrapper's groups: ``{"uav": ["uav_0", ..., "uav_{N-1}"]}``."""
        return env.group_map

    def observation_spec(self, env: EnvBase) -> Composite:
        """``(group, "observation")`` of every group."""
        return _keep_only(env.observation_spec, list(self.group_map(env)), "observation")

    def info_spec(self, env: EnvBase) -> Composite | None:
        """``(group, "info")`` of every group: the environment's flat numeric infos."""
        return _keep_only(env.observation_spec, list(self.group_map(env)), "info")

    def state_spec(self, env: EnvBase) -> Composite | None:
        """``"state"``: the environment's global state (truth included), for critics."""
        if "state" in env.observation_spec.keys():
            return Composite({"state": env.observation_spec["state"].clone()})
        return None

    def action_spec(self, env: EnvBase) -> Composite:
        """``(group, "action")`` of every group."""
        return env.full_action_spec

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        """None: every action is always allowed."""
        return None

    @staticmethod
    def env_name() -> str:
        """``"coopnav"``."""
        return "coopnav"


class CoopnavTask(Task):
    """The coopnav tasks: ``URBAN_CANYON_V1`` (the score as reward) and ``URBAN_CANYON_V0``.

    ``CoopnavTask.URBAN_CANYON_V1.get_task()`` gives a :class:`CoopnavClass` with
    :data:`DEFAULT_CONFIGS` (BenchMARL ships no yaml for coopnav); ``get_task(config)`` uses
    ``config``, and ``get_from_yaml(path)`` reads it from a yaml file.
    """

    URBAN_CANYON_V1 = None
    URBAN_CANYON_V0 = None

    @staticmethod
    def associated_class() -> type[CoopnavClass]:
        """:class:`CoopnavClass`."""
        return CoopnavClass

    def get_from_yaml(self, path: str | None = None) -> CoopnavClass:
        """The task with the config of the yaml file ``path``, or :data:`DEFAULT_CONFIGS`."""
        if path is None:
            return self.get_task(config=copy.deepcopy(DEFAULT_CONFIGS[self.name]))
        return super().get_from_yaml(path)
