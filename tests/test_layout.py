"""The layout of the application packages stays readable (issue 15).

Checked by reading the source (``ast``), nothing is imported:

* no module of ``training``, ``reproduction``, ``agents`` or ``benchmarks`` (nor their tests)
  imports a private name (``_name``, or a name from a private module) of another module,
  but the kernel benchmarks (:data:`KERNEL_BENCHMARKS`), which time the kernels themselves;
* the imports between the modules of ``training``, ``reproduction`` and ``agents`` (module
  level and inside functions alike) form no cycle;
* every module of ``agents`` and ``training`` is reached from the library: imported (directly
  or through other reached modules) by a module of ``coopnav_env`` or ``reproduction``, by a
  public package ``__init__``, or by a command of the ``coopnav`` CLI. A module that only
  ``studies/`` (or tests) import belongs in its study.

``coopnav_env`` is out of scope: its subpackages share compiled kernels through private
modules (``_kernels``) by design.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ("coopnav_env", "agents", "training", "reproduction", "tests", "benchmarks", "studies")
CHECKED = (
    "training",
    "reproduction",
    "agents",
    "benchmarks",
    "studies",
    "tests/training",
    "tests/agents",
)
ACYCLIC = ("training", "reproduction", "agents")


INSTALLED_AS = {
    "agents": "coopnav_env.agents",
    "training": "coopnav_env.training",
    "reproduction": "coopnav_env.reproduction",
}
"""Top-level folder -> the package it installs as."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    if parts[0] in INSTALLED_AS:
        parts[0] = INSTALLED_AS[parts[0]]
    return ".".join(parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


KERNEL_BENCHMARKS = ("benchmarks/bench_nav.py",)
"""Benchmarks that time the compiled kernels themselves (``coopnav_env.*._kernels``), so they
import them by design: out of the private-name check."""


def _checked_files() -> list[Path]:
    files = [p for d in CHECKED for p in (ROOT / d).rglob("*.py")]
    files = [p for p in files if p.relative_to(ROOT).as_posix() not in KERNEL_BENCHMARKS]
    return sorted(files + list((ROOT / "tests").glob("test_*.py")))


def private_imports(source: str) -> list[tuple[int, str]]:
    """``(line, module.name)`` for every private project name ``source`` imports."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
            continue
        parts = node.module.split(".")
        if parts[0] not in PROJECT:
            continue
        found += [(node.lineno, f"{node.module}.{a.name}") for a in node.names if _private(a.name)]
        if any(_private(p) for p in parts):
            found.append((node.lineno, f"{node.module}.(module)"))
    return found


def import_graph(packages: tuple[str, ...]) -> dict[str, set[str]]:
    """module -> project modules it imports (anywhere in its body), within ``packages``."""
    mods = {_module_name(p): p for d in packages for p in (ROOT / d).rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                targets.add(node.module)
                targets |= {f"{node.module}.{a.name}" for a in node.names}
            elif isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
        graph[name] = {t for t in targets if t in mods and t != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (as a list of modules), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        path.append(v)
        for w in sorted(graph[v]):
            if state.get(w) == 1:
                return [*path[path.index(w) :], w]
            if w not in state and (cycle := visit(w)):
                return cycle
        path.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state and (cycle := visit(v)):
            return cycle
    return None


def test_no_module_imports_a_private_name_of_another():
    found = [
        f"{_module_name(p)}:{line} {name}"
        for p in _checked_files()
        for line, name in private_imports(p.read_text())
    ]
    assert found == []


def test_no_import_cycle():
    graph = import_graph(ACYCLIC)
    expected = {
        "coopnav_env.training.config",
        "coopnav_env.training.sb3_backend",
        "coopnav_env.reproduction.cli",
    }
    assert expected <= set(graph)
    assert find_cycle(graph) is None


LIBRARY_ROOTS = ("coopnav_env", "reproduction")
"""Folders whose every module is library code that may reach ``agents`` and ``training``."""

REACH_CHECKED = ("agents", "training")
"""Folders whose every module must be reached from the library (:func:`unreached_modules`)."""


def deprecated_paths(mods: dict[str, Path]) -> set[str]:
    """The modules that are an earlier import path of another, kept for one release: their
    docstring opens with "Deprecated import path" (roots of the reach check)."""
    return {
        name
        for name, path in mods.items()
        if (ast.get_docstring(ast.parse(path.read_text())) or "").startswith(
            "Deprecated import path"
        )
    }


def _library_modules() -> dict[str, Path]:
    """Every module of the installed package, by its installed name."""
    dirs = (*LIBRARY_ROOTS, *REACH_CHECKED)
    return {
        _module_name(p): p
        for d in dirs
        for p in (ROOT / d).rglob("*.py")
        if "__pycache__" not in p.parts
    }


def cli_modules(pyproject: str, cli_source: str) -> set[str]:
    """The modules a user reaches from the command line: the ``[project.scripts]`` entry
    points of ``pyproject`` and the subcommand modules of the CLI's ``COMMANDS`` table
    (``cli_source``, read with ``ast``: a dict of name -> (module, help))."""
    scripts = re.search(r"^\[project\.scripts\]\n(.*?)(?:^\[|\Z)", pyproject, re.M | re.S)
    found = set()
    if scripts:
        found |= set(re.findall(r'^\s*[\w-]+\s*=\s*"([\w.]+):', scripts.group(1), re.M))
    for node in ast.walk(ast.parse(cli_source)):
        target = node.target if isinstance(node, ast.AnnAssign) else None
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
        if isinstance(target, ast.Name) and target.id == "COMMANDS":
            for value in node.value.values:  # type: ignore[union-attr]
                first = value.elts[0] if isinstance(value, ast.Tuple) else value
                if isinstance(first, ast.Constant) and isinstance(first.value, str):
                    found.add(first.value)
    return found


def unreached_modules(graph: dict[str, set[str]], roots: set[str], checked: set[str]) -> list[str]:
    """The modules of ``checked`` that no path of ``graph`` leads to from ``roots``."""
    seen: set[str] = set()
    todo = [r for r in roots if r in graph]
    while todo:
        v = todo.pop()
        if v in seen:
            continue
        seen.add(v)
        todo += [w for w in graph[v] if w not in seen]
    return sorted(checked - seen)


def reach_graph(packages: tuple[str, ...]) -> dict[str, set[str]]:
    """As :func:`import_graph`, plus the modules a module names in a string constant
    (``importlib.import_module("coopnav_env.training.train")``: the CLI's subcommands, the
    training backends)."""
    graph = import_graph(packages)
    mods = {_module_name(p): p for d in packages for p in (ROOT / d).rglob("*.py")}
    for name, path in mods.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and node.value in mods and node.value != name:
                graph[name].add(node.value)
    return graph


def test_every_agents_and_training_module_is_reached_from_the_library():
    mods = _library_modules()
    graph = reach_graph((*LIBRARY_ROOTS, *REACH_CHECKED))
    checked = {n for n, p in mods.items() if p.relative_to(ROOT).parts[0] in REACH_CHECKED}
    packages = {n for n, p in mods.items() if p.name == "__init__.py"}  # public __init__s
    library = {n for n, p in mods.items() if p.relative_to(ROOT).parts[0] in LIBRARY_ROOTS}
    cli = cli_modules(
        (ROOT / "pyproject.toml").read_text(), (ROOT / "training" / "cli.py").read_text()
    )
    assert "coopnav_env.training.cli" in cli and "coopnav_env.training.train" in cli
    roots = library | packages | {m for m in cli if m in graph}
    roots |= deprecated_paths(mods)
    assert "coopnav_env.training.marl" in deprecated_paths(mods)
    assert unreached_modules(graph, roots, checked) == []


def test_the_checks_can_fail():
    """The checkers see what they are meant to see (on made-up modules)."""
    source = (
        "from coopnav_env.training.evaluate import _slug\nfrom coopnav_env.nav._kernels import x\n"
        "import numpy\nfrom numpy import _core\n"
        "from coopnav_env.training.envs import EVAL_SEED_START\n"
    )
    assert private_imports(source) == [
        (1, "coopnav_env.training.evaluate._slug"),
        (2, "coopnav_env.nav._kernels.(module)"),
    ]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
    graph = {"lib": {"a"}, "a": {"b"}, "b": set(), "study_only": {"b"}}
    assert unreached_modules(graph, {"lib"}, {"a", "b", "study_only"}) == ["study_only"]
    cli = 'COMMANDS: dict = {"x": ("pkg.x", "help"), "y": ("pkg.y", "help")}\n'
    scripts = '[project.scripts]\ntool = "pkg.cli:main"\n\n[tool.x]\nz = "no.thing:f"\n'
    assert cli_modules(scripts, cli) == {"pkg.cli", "pkg.x", "pkg.y"}


@pytest.mark.parametrize("package", ACYCLIC)
def test_every_module_has_a_docstring(package):
    missing = [
        _module_name(p)
        for p in (ROOT / package).rglob("*.py")
        if ast.get_docstring(ast.parse(p.read_text())) is None and p.stat().st_size
    ]
    assert missing == []
