"""The experimental settings are listed in one place per layer, off by default, and each entry
names a real setting.

The environment's list is ``coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`` (settings of
``UrbanCanyonConfig``), the trainers' ``coopnav_env.training.config.EXPERIMENTAL_SETTINGS``
(settings of a backend, e.g. ``MARLSettings``).
"""

from __future__ import annotations

import dataclasses

import pytest

from coopnav_env.agents.marl_nets import REMOVED_SETTINGS, MARLSettings
from coopnav_env.envs.config import EXPERIMENTAL_SETTINGS as ENV_LIST
from coopnav_env.envs.config import ExperimentalSetting, UrbanCanyonConfig
from coopnav_env.training.config import EXPERIMENTAL_SETTINGS as TRAINER_LIST

LISTS = {
    "environment": (ENV_LIST, {"UrbanCanyonConfig"}),
    "trainer": (TRAINER_LIST, {"MARLSettings"}),
}
CLASSES = {"UrbanCanyonConfig": UrbanCanyonConfig, "MARLSettings": MARLSettings}
ENTRIES = [(layer, e) for layer, (entries, _) in LISTS.items() for e in entries]


def _id(item) -> str:
    layer, entry = item
    return f"{layer}:{entry.settings}.{entry.name}"


def _names_a_field(entry: ExperimentalSetting) -> bool:
    return entry.name in {f.name for f in dataclasses.fields(CLASSES[entry.settings])}


def _off_by_default(entry: ExperimentalSetting) -> bool:
    """The field's default is the entry's 'off' value (equal, and of its type)."""
    default = getattr(CLASSES[entry.settings](), entry.name)
    return default == entry.off and type(default) is type(entry.off)


def test_the_lists_are_what_the_layers_keep_experimental() -> None:
    assert "obs_true_error" in {e.name for e in ENV_LIST}
    assert {e.name for e in ENV_LIST} <= {"obs_true_error"}
    # the recipe's settings are supported, the removed ones gone
    assert not {e.name for e in TRAINER_LIST} & {"action_repeat", "start_hold_decisions"}
    assert not {e.name for e in TRAINER_LIST} & set(REMOVED_SETTINGS)
    for entries, _ in LISTS.values():
        names = [(e.settings, e.name) for e in entries]
        assert len(set(names)) == len(names)  # no entry twice


@pytest.mark.parametrize("item", ENTRIES, ids=_id)
def test_every_entry_is_a_real_setting_of_its_layer_and_documented(item) -> None:
    layer, entry = item
    assert entry.settings in LISTS[layer][1], f"the {layer} list names {entry.settings}"
    cls = CLASSES[entry.settings]
    assert _names_a_field(entry), f"{entry.settings} has no field {entry.name!r}"
    assert entry.what and len(entry.what) < 160  # one line
    assert "EXPERIMENTAL_SETTINGS" in (cls.__doc__ or "").split(f"{entry.name} :")[1][:700]


@pytest.mark.parametrize("item", ENTRIES, ids=_id)
def test_every_entry_is_off_by_default(item) -> None:
    _, entry = item
    assert _off_by_default(entry), f"{entry.settings}.{entry.name} is not {entry.off!r} by default"


def test_the_checks_catch_an_entry_on_by_default_or_naming_no_field() -> None:
    on = ExperimentalSetting("UrbanCanyonConfig", "obs_true_error", True, "on by default?")
    zero = ExperimentalSetting("MARLSettings", "start_hold_decisions", 0.0, "0.0 is not 0")
    assert not _off_by_default(on) and not _off_by_default(zero)
    assert _off_by_default(ExperimentalSetting("MARLSettings", "start_hold_decisions", 0, "-"))
    assert not _names_a_field(ExperimentalSetting("MARLSettings", "noise_correlation", 0.0, "-"))


def test_the_environment_page_points_to_the_list() -> None:
    from coopnav_env import urban_canyon_v0

    doc = urban_canyon_v0.__doc__ or ""
    assert "## Experimental settings" in doc and "EXPERIMENTAL_SETTINGS" in doc
