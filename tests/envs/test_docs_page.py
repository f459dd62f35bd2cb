"""The documentation pages of urban_canyon_v0 and v1 as help() shows them, and the pages that
show v1's example."""

from __future__ import annotations

import pydoc
import re

from coopnav_env import urban_canyon_v0, urban_canyon_v1
from coopnav_env.envs import obs_layout


def test_help_synopsis_is_a_sentence_and_agents_has_one_row() -> None:
    text = pydoc.render_doc(urban_canyon_v0, renderer=pydoc.plaintext)
    name_line = text.splitlines()[text.splitlines().index("NAME") + 1].strip()
    assert name_line.startswith("coopnav_env.urban_canyon_v0 - Urban Canyon v0 (legacy)")
    assert "#" not in name_line
    doc = urban_canyon_v0.__doc__
    assert len([line for line in doc.splitlines() if line.startswith("| Agents ")]) == 1
    assert not doc.lstrip().startswith("#")


def test_page_names_every_observation_field() -> None:
    doc = urban_canyon_v0.__doc__
    for name in obs_layout():
        assert f"`{re.sub(r'_[0-9]+', '_k', name)}`" in doc, name
    assert "`max_cycles`" in doc and "coopnav/UrbanCanyonSwarm-v0" in doc


def test_environment_docs_point_to_v1s_page_and_show_its_example() -> None:
    """docs/environment.md and the README's PettingZoo quick start show urban_canyon_v1's page
    example (every line of their first code block is a line of it) and name the page."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    doc_lines = {line.strip() for line in urban_canyon_v1.__doc__.splitlines()}
    for name in ("docs/environment.md", "README.md"):
        text = (root / name).read_text()
        assert "coopnav_env/urban_canyon_v1.py" in text, name
        block = re.search(r"```python\n(.*?)```", text, re.S).group(1)
        lines = [line.strip() for line in block.splitlines() if line.strip()]
        assert "from coopnav_env import urban_canyon_v1" in lines, name
        missing = [line for line in lines if line not in doc_lines]
        assert not missing, (name, missing)
    assert (
        (root / "docs/environment.md")
        .read_text()
        .startswith("# The environment: `urban_canyon_v1`")
    )
