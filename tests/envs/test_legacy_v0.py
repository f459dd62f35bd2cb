"""urban_canyon_v1 is the environment at the front door; urban_canyon_v0 is legacy.

v0 stays importable for the studies that used it: its page says first that it is legacy,
making it warns once per process, and no default of the library names it.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import warnings
from pathlib import Path

from coopnav_env import urban_canyon_v0, urban_canyon_v1

ROOT = Path(__file__).resolve().parents[2]

#: the installed package folders (agents, training and reproduction install under coopnav_env)
LIBRARY = ("coopnav_env", "agents", "training", "reproduction")

LEGACY_IDS = {"urban_canyon_v0", "coopnav/UrbanCanyonSwarm-v0"}

#: modules that fly v0 without being told to, and why that is allowed (not a default)
IMPORTS_ALLOWED = {
    # BenchMARL's legacy task URBAN_CANYON_V0 beside URBAN_CANYON_V1: the user names it
    "training/benchmarl_backend.py",
}


def _legacy(node: ast.AST | None) -> bool:
    return isinstance(node, ast.Constant) and node.value in LEGACY_IDS


def _defaults_naming_v0(tree: ast.AST) -> list[str]:
    """Where ``tree`` gives a legacy id as a default: argument defaults, class-level field
    defaults, ``default=`` keywords, ``mapping.get(key, <id>)``, ``x or <id>``, assignments
    to a ``*DEFAULT*`` name and ``make_env_fn(<id>, ...)``; and imports of the v0 module."""
    found = []
    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            defaults = [*node.args.defaults, *node.args.kw_defaults]
            found += [f"{line}: default of {node.name}()" for d in defaults if _legacy(d)]
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.AnnAssign) and _legacy(item.value):
                    found.append(f"{item.lineno}: field default in class {node.name}")
        elif isinstance(node, ast.Call):
            found += [
                f"{line}: default= keyword"
                for k in node.keywords
                if k.arg == "default" and _legacy(k.value)
            ]
            func = node.func
            if isinstance(func, ast.Attribute) and func.attr == "get" and len(node.args) > 1:
                found += [f"{line}: .get(..., default)"] if _legacy(node.args[1]) else []
            elif isinstance(func, ast.Name) and func.id == "make_env_fn" and node.args:
                found += [f"{line}: make_env_fn(<v0>)"] if _legacy(node.args[0]) else []
        elif isinstance(node, ast.BoolOp) and isinstance(node.op, ast.Or):
            found += [f"{line}: `or` fallback" for v in node.values if _legacy(v)]
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and _legacy(node.value):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names = [t.id for t in targets if isinstance(t, ast.Name)]
            found += [f"{line}: {n}" for n in names if "DEFAULT" in n.upper()]
        elif isinstance(node, ast.ImportFrom) and node.module == "coopnav_env":
            found += [f"{line}: import" for a in node.names if a.name == "urban_canyon_v0"]
        elif isinstance(node, ast.Import):
            found += [f"{line}: import" for a in node.names if a.name.endswith("urban_canyon_v0")]
    return found


def test_no_library_default_names_v0() -> None:
    """No default of the installed library names urban_canyon_v0 (outside v0's own page)."""
    files = sorted(p for d in LIBRARY for p in (ROOT / d).rglob("*.py"))
    assert len(files) > 50
    offenders = {}
    for path in files:
        rel = path.relative_to(ROOT).as_posix()
        if rel == "coopnav_env/urban_canyon_v0.py":
            continue
        found = _defaults_naming_v0(ast.parse(path.read_text(), filename=rel))
        if rel in IMPORTS_ALLOWED:
            found = [f for f in found if not f.endswith(": import")]
        if found:
            offenders[rel] = found
    assert not offenders, offenders


def test_the_checker_finds_defaults_naming_v0() -> None:
    """The scan above would see each kind of default (a check that it can fail)."""
    code = (
        "import argparse\n"
        "from coopnav_env import urban_canyon_v0\n"
        "def f(env_id='urban_canyon_v0'): ...\n"
        "class C:\n    env_id: str = 'urban_canyon_v0'\n"
        "argparse.ArgumentParser().add_argument('--env-id', default='urban_canyon_v0')\n"
        "x = {}.get('env_id', 'coopnav/UrbanCanyonSwarm-v0')\n"
        "y = None or 'urban_canyon_v0'\n"
        "DEFAULT_ENV = 'urban_canyon_v0'\n"
        "make_env_fn('urban_canyon_v0', {})\n"
    )
    assert len(_defaults_naming_v0(ast.parse(code))) == 8


def test_training_defaults_and_help_name_v1() -> None:
    from coopnav_env.training.cli import build_parser
    from coopnav_env.training.config import TrainConfig, load_config
    from coopnav_env.training.envs import DEFAULT_ENV_ID

    assert DEFAULT_ENV_ID == "urban_canyon_v1"
    assert TrainConfig(out="-").env_id == "urban_canyon_v1"
    assert load_config()["env_id"] == "urban_canyon_v1"
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    help_text = sub.choices["train"].format_help()
    assert "urban_canyon_v1" in help_text and "urban_canyon_v0" not in help_text


def test_v0_page_says_first_that_it_is_legacy() -> None:
    first = urban_canyon_v0.__doc__.strip().splitlines()[0]
    assert "legacy" in first and "coopnav_env.urban_canyon_v1" in first
    assert "legacy" not in urban_canyon_v1.__doc__.strip().splitlines()[0]


def test_making_v0_warns_once_per_process() -> None:
    """``urban_canyon_v0.parallel_env`` and ``env`` warn (FutureWarning) the first time in a
    process only; v1 never does. (In a fresh interpreter: the flag is per process.)"""
    code = (
        "import warnings\n"
        "from coopnav_env import urban_canyon_v0, urban_canyon_v1\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    urban_canyon_v1.parallel_env(n_uavs=2)\n"
        "    assert not caught, [str(w.message) for w in caught]\n"
        "    urban_canyon_v0.parallel_env(n_uavs=2)\n"
        "    urban_canyon_v0.env(n_uavs=2)\n"
        "    urban_canyon_v0.parallel_env(n_uavs=2)\n"
        "assert len(caught) == 1 and caught[0].category is FutureWarning, caught\n"
        "message = str(caught[0].message)\n"
        "assert 'legacy' in message and 'urban_canyon_v1' in message\n"
        "assert caught[0].filename == '<string>'\n"  # points at the caller's line
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr


def test_v0_still_flies_as_before() -> None:
    """The legacy module keeps its constructors and class (its studies rebuild their envs)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # tested above, in a fresh process
        env = urban_canyon_v0.parallel_env(n_uavs=2, max_steps=3)
    assert isinstance(env, urban_canyon_v0.raw_env)
    assert env.metadata["name"] == "urban_canyon_v0" and env.config.crash_free_steps == 0
    env.reset(seed=0)
    assert urban_canyon_v1.parallel_env(n_uavs=2).config.crash_free_steps == 3
