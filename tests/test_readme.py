"""The README's commands and the CI script stay in sync."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```bash\n(.*?)```", text, re.S).group(1)
    return [line for line in block.splitlines() if line and not line.startswith("#")]


def test_readme_starts_with_two_commands():
    cmds = _readme_commands()
    assert len(cmds) == 2
    assert all(c.startswith("python3 -m venv .venv") for c in cmds)
    assert "pip install torch==2.13.0" in cmds[0] and "pip install torch==2.13.0" in cmds[1]


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    assert _readme_commands()[1] in ci.splitlines()


def test_torch_requirement_admits_the_cpu_build():
    text = (ROOT / "pyproject.toml").read_text()
    spec = re.search(r'"torch(>=[0-9.]+),(<[0-9.]+)"', text)
    assert spec is not None
    lo = tuple(int(x) for x in spec.group(1)[2:].split("."))
    hi = tuple(int(x) for x in spec.group(2)[1:].split("."))
    assert lo <= (2, 13, 0) < hi
