"""The README is a front page: its commands and the CI script stay in sync, its quick starts run,
and every figure it keeps names the command that gives it."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README_MAX_CHARS = 10_000


def _readme() -> str:
    return (ROOT / "README.md").read_text()


def _readme_commands() -> list[str]:
    block = re.search(r"```bash\n(.*?)```", _readme(), re.S).group(1)
    return [line for line in block.splitlines() if line and not line.startswith("#")]


def _section(title: str) -> str:
    """The README's ``## title`` section, up to the next ``## `` heading."""
    text = _readme()
    assert f"\n## {title}\n" in text, f"README has no section {title!r}"
    return text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_readme_starts_with_two_commands():
    cmds = _readme_commands()
    assert len(cmds) == 2
    assert all(c.startswith("python3 -m venv .venv") for c in cmds)
    assert "pip install torch==2.13.0" in cmds[0] and "pip install torch==2.13.0" in cmds[1]


def test_the_two_commands_come_first():
    text = _readme()
    first_block = text.index("```bash\n")
    assert text.index("\n## ") > first_block, "a section comes before the two commands"


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


def test_readme_is_a_front_page_of_at_most_10000_characters():
    assert len(_readme()) <= README_MAX_CHARS, len(_readme())


def test_train_and_evaluate_quick_start_is_the_main_job():
    """The quick start's two commands are the ones the first README command runs."""
    main_job = _readme_commands()[0].split(" && ")
    block = re.search(r"```text\n(.*?)```", _section("Quick start: train and evaluate"), re.S)
    shown = block.group(1).strip().splitlines()
    assert [c for c in main_job if c.startswith("coopnav ")] == shown


def _tables(section: str) -> list[list[str]]:
    """The data rows of each table of ``section`` (a table starts at its ``| policy`` header)."""
    tables: list[list[str]] = []
    for r in section.splitlines():
        if r.startswith("| policy"):
            tables.append([])
        elif r.startswith("| ") and tables:
            tables[-1].append(r)
    return tables


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")][1:]


def _numeric_rows(section: str, table: int = 0) -> list[str]:
    rows = _tables(section)[table]
    number = r"-?\d+(\.\d+)?( \[-?\d+\.\d+, -?\d+\.\d+\])?"
    for row in rows:
        cells = _cells(row)
        assert cells and all(re.fullmatch(number, c) for c in cells), row
    return rows


RESULTS_REPORT = ROOT / "studies/task_objective/shipped_recipe/report.json"
"""What the Results section's command writes (committed)."""


def _results_command() -> str:
    command = re.search(r"```text\n(coopnav evaluate .*?)\n```", _section("Results"), re.S)
    assert command is not None
    return command.group(1)


def test_results_name_the_command_that_gives_them():
    """The Results table comes from the command the section names, which writes the committed
    report; the quick start's table from the evaluation of the first README command."""
    command = _results_command()
    assert f"--out {RESULTS_REPORT.parent.relative_to(ROOT)} " in command + " "
    assert "--episodes 100 --seed-start 1000100" in command
    assert len(_numeric_rows(_section("Results"))) >= 4
    quick = _section("Quick start: train and evaluate")
    evaluate = next(c for c in _readme_commands()[0].split(" && ") if c.startswith("coopnav eval"))
    assert evaluate in quick
    assert len(_numeric_rows(quick)) >= 4


def test_results_are_the_committed_report_of_the_shipped_policies():
    """Every row of the Results table quotes the committed report to the digit: a method row
    pools the shipped policies the command names (one per training seed)."""
    report = json.loads(RESULTS_REPORT.read_text())
    command = _results_command()
    gap = {r["name"]: r for r in report["gap"]["rows"]}
    stats = {p["policy"]: p for p in report["policies"]}
    stats |= {name: m["stats"] for name, m in report["methods"].items()}
    for name, method in report["methods"].items():
        assert f"{name}={','.join(method['policies'])}" in command
        assert all(p.startswith("mappo:pretrained/") for p in method["policies"])
    for line in _numeric_rows(_section("Results")):
        name = re.search(r"`([^`]+)`", line).group(1)
        g, st = gap[name], stats[name]
        r, c = g["return"], g["gap_closed"]
        closed = f"{c['value']:.2f}"
        if c["low"] != c["high"]:
            closed += f" [{c['low']:.2f}, {c['high']:.2f}]"
        assert _cells(line) == [
            f"{r['value']:.3f} [{r['low']:.3f}, {r['high']:.3f}]",
            closed,
            f"{st['goal_rate']:.3f}",
            f"{st['cruise_spacing_m']:.1f}",
        ], name


def test_the_quick_start_table_names_its_columns_from_the_report():
    """The quick start's table has the score with its parts: error, goal rate, collisions."""
    header = next(r for r in _section("Quick start: train and evaluate").splitlines() if
                  r.startswith("| policy"))  # fmt: skip
    assert [h.strip() for h in header.strip("|").split("|")] == [
        "policy",
        "score",
        "mean cooperative 3-D error [m]",
        "goal rate",
        "collisions",
    ]


def test_readme_names_the_installed_namespace_only():
    """Imports in README code use the installed names, never the deprecated top-level ones."""
    code = "\n".join(_python_blocks(_readme()))
    assert not re.search(r"^\s*(from|import) (agents|training|reproduction)\b", code, re.M)
    for old in ("agents", "training", "reproduction"):
        assert f"`coopnav_env.{old}`" in _readme(), old


def test_readme_python_quick_starts_run():
    """The PettingZoo and Gymnasium quick starts run as printed, without warnings from this
    package."""
    blocks = _python_blocks(_readme())
    assert len(blocks) == 2
    for block in blocks:
        with warnings.catch_warnings():
            warnings.filterwarnings("error", module=r"coopnav_env(\..*)?$")
            namespace: dict = {}
            exec(compile(block, "README.md", "exec"), namespace)
    assert namespace["obs"].shape == (3 * 52,)
