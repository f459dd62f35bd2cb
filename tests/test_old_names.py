"""One installed package; the old top-level names work for one release, with one warning each."""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
import sysconfig
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

OLD_IMPORTS = """
import warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    {prelude}
    from agents import register_policy
    from training.evaluate import evaluate
    from training.vec_env import VEC_ENV_KINDS, urban_canyon_vec_env
    import agents.heuristics
    import reproduction
import coopnav_env.agents, coopnav_env.agents.heuristics, coopnav_env.training.evaluate
import coopnav_env.training.vec_env, coopnav_env.reproduction
assert register_policy is coopnav_env.agents.register_policy
assert evaluate is coopnav_env.training.evaluate.evaluate
assert urban_canyon_vec_env is coopnav_env.training.vec_env.urban_canyon_vec_env
assert agents.heuristics is coopnav_env.agents.heuristics
assert reproduction is coopnav_env.reproduction
old = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)
       and "top-level package" in str(w.message)]
assert len(old) == 3, old
for name in ("agents", "training", "reproduction"):
    assert sum(f"'{{name}}' is now 'coopnav_env.{{name}}'" in m for m in old) == 1, (name, old)
assert all(w.filename == "<string>" for w in caught if "top-level package" in str(w.message))
print("ok")
"""


@pytest.mark.parametrize(
    ("where", "prelude"),
    [
        ("source checkout", "pass"),  # the repository's folders are found first
        ("anywhere, after coopnav_env", "import coopnav_env"),
    ],
)
def test_old_import_paths_work_and_warn_once(tmp_path: Path, where: str, prelude: str) -> None:
    cwd = ROOT if where == "source checkout" else tmp_path
    code = OLD_IMPORTS.format(prelude=prelude)
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


def test_one_top_level_package_is_installed() -> None:
    dist = importlib.metadata.distribution("coopnav")
    top = (dist.read_text("top_level.txt") or "").split()
    assert top == ["coopnav_env"]
    site = Path(sysconfig.get_paths()["purelib"])
    for name in ("agents", "training", "reproduction"):
        assert not (site / name).exists(), name
    assert dist.entry_points.select(group="console_scripts")["coopnav"].value == (
        "coopnav_env.training.cli:main"
    )


def test_a_missing_old_submodule_is_not_found() -> None:
    import coopnav_env  # noqa: F401 (installs the redirection)

    with warnings.catch_warnings(), pytest.raises(ModuleNotFoundError):
        warnings.simplefilter("ignore", DeprecationWarning)
        __import__("training.no_such_module")
