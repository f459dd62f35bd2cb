"""The PettingZoo environment ``urban_canyon_v0`` (adapter, task, route autopilot,
configuration, rendering), its Gymnasium single-agent view :class:`UrbanCanyonSwarmEnv` and the
named observation layout :func:`obs_layout`.

Import it through its versioned shim: ``from coopnav_env import urban_canyon_v0``.
"""

from coopnav_env.envs.batched import BatchedUrbanCanyonEnv
from coopnav_env.envs.config import (
    PRESETS,
    UrbanCanyonConfig,
    config_field_names,
    make_config,
    preset_config,
)
from coopnav_env.envs.gym_wrapper import UrbanCanyonSwarmEnv
from coopnav_env.envs.observation_layout import ObsField, ObsLayout, obs_layout
from coopnav_env.envs.urban_canyon import REWARD_TERMS, UrbanCanyonEnv

__all__ = [
    "PRESETS",
    "REWARD_TERMS",
    "BatchedUrbanCanyonEnv",
    "ObsField",
    "ObsLayout",
    "UrbanCanyonConfig",
    "UrbanCanyonEnv",
    "UrbanCanyonSwarmEnv",
    "config_field_names",
    "make_config",
    "obs_layout",
    "preset_config",
]
