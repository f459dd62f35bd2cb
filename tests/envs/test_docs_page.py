"""The documentation page of urban_canyon_v0 as help() shows it."""

from __future__ import annotations

import pydoc
import re

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import obs_layout


def test_help_synopsis_is_a_sentence_and_agents_has_one_row() -> None:
    text = pydoc.render_doc(urban_canyon_v0, renderer=pydoc.plaintext)
    name_line = text.splitlines()[text.splitlines().index("NAME") + 1].strip()
    assert name_line.startswith("coopnav_env.urban_canyon_v0 - Urban Canyon: a UAV swarm")
    assert "#" not in name_line
    doc = urban_canyon_v0.__doc__
    assert len([line for line in doc.splitlines() if line.startswith("| Agents ")]) == 1
    assert not doc.lstrip().startswith("#")


def test_page_names_every_observation_field() -> None:
    doc = urban_canyon_v0.__doc__
    for name in obs_layout():
        assert f"`{re.sub(r'_[0-9]+', '_k', name)}`" in doc, name
    assert "`max_cycles`" in doc and "coopnav/UrbanCanyonSwarm-v0" in doc
