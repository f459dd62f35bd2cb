"""The PettingZoo environment ``urban_canyon_v0`` (adapter, configuration, rendering).

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
from coopnav_env.envs.urban_canyon import REWARD_TERMS, UrbanCanyonEnv

__all__ = [
    "PRESETS",
    "REWARD_TERMS",
    "BatchedUrbanCanyonEnv",
    "UrbanCanyonConfig",
    "UrbanCanyonEnv",
    "config_field_names",
    "make_config",
    "preset_config",
]
