"""The experimental settings are listed in one place, and each entry names a real setting."""

from __future__ import annotations

import dataclasses

import pytest

from coopnav_env.agents.marl_nets import MARLSettings
from coopnav_env.envs.config import EXPERIMENTAL_SETTINGS, UrbanCanyonConfig

_CLASSES = {"UrbanCanyonConfig": UrbanCanyonConfig, "MARLSettings": MARLSettings}


def _fields(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def test_the_issue_s_study_switches_are_listed() -> None:
    names = {(e.settings, e.name, e.value) for e in EXPERIMENTAL_SETTINGS}
    assert {
        ("UrbanCanyonConfig", "obs_true_error", None),
        ("MARLSettings", "residual_mode", "options"),
        ("MARLSettings", "option_init_prob", None),
        ("MARLSettings", "action_repeat", None),
        ("MARLSettings", "residual_wall_guard", None),
    } <= names
    assert len(names) == len(EXPERIMENTAL_SETTINGS)  # no entry twice


@pytest.mark.parametrize("entry", EXPERIMENTAL_SETTINGS, ids=lambda e: f"{e.settings}.{e.name}")
def test_every_entry_is_a_real_setting_and_documented(entry) -> None:
    cls = _CLASSES[entry.settings]
    fields = _fields(cls)
    assert entry.name in fields, f"{entry.settings} has no field {entry.name!r}"
    assert entry.what and len(entry.what) < 160  # one line
    assert "EXPERIMENTAL_SETTINGS" in (cls.__doc__ or "").split(f"{entry.name} :")[1][:700]
    if entry.value is not None:  # the experimental value is one the class accepts
        kwargs = {entry.name: entry.value}
        if entry.settings == "MARLSettings":
            kwargs["residual_base"] = "wide"
        cls(**kwargs)


def test_the_experimental_settings_are_off_by_default() -> None:
    for entry in EXPERIMENTAL_SETTINGS:
        cls = _CLASSES[entry.settings]
        default = getattr(cls(), entry.name)
        assert entry.value is None or default != entry.value
        if isinstance(default, bool):
            assert default is False


def test_the_environment_page_points_to_the_list() -> None:
    from coopnav_env import urban_canyon_v0

    doc = urban_canyon_v0.__doc__ or ""
    assert "## Experimental settings" in doc and "EXPERIMENTAL_SETTINGS" in doc
