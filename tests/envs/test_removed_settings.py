"""Removed environment settings are refused with a message saying so (not as a typo)."""

from __future__ import annotations

import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import make_config
from coopnav_env.envs.config import REMOVED_SETTINGS, config_field_names


@pytest.mark.parametrize("name", ["obs_lookahead", "obs_candidate_sky"])
def test_a_removed_setting_is_refused_naming_it(name) -> None:
    assert name in REMOVED_SETTINGS and name not in config_field_names()
    for value in (True, False):
        with pytest.raises(ValueError, match=rf"{name} was removed: .*Drop the setting"):
            urban_canyon_v0.parallel_env(**{name: value})
    with pytest.raises(ValueError, match=rf"{name} was removed"):
        make_config(preset="urban_nlos_3dma", **{name: True})


def test_a_typo_is_still_an_unknown_argument() -> None:
    with pytest.raises(ValueError, match=r"unknown urban_canyon argument\(s\) \['obs_lookahed'\]"):
        make_config(obs_lookahed=True)
