"""The old top-level import names ``agents``, ``training`` and ``reproduction``.

These packages install as ``coopnav_env.agents``, ``coopnav_env.training`` and
``coopnav_env.reproduction``; nothing is installed under the generic top-level names. For one
release the old names keep working: ``import agents.heuristics`` (or ``from training.evaluate
import evaluate``) gives the very module object of the new name, with one
:class:`DeprecationWarning` per old name that names the new path.

The redirection is a :class:`importlib.abc.MetaPathFinder` at the front of ``sys.meta_path``.
It is installed when ``coopnav_env`` is imported, and by the top-level folders of a source
checkout when one of them is imported under its old name first (their ``__init__`` calls
:func:`redirect`).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from types import ModuleType

OLD_NAMES: dict[str, str] = {
    "agents": "coopnav_env.agents",
    "training": "coopnav_env.training",
    "reproduction": "coopnav_env.reproduction",
}
"""Old top-level name -> the package it now is."""

_warned: set[str] = set()


def _new_name(fullname: str) -> str | None:
    top, _, rest = fullname.partition(".")
    if top not in OLD_NAMES:
        return None
    return OLD_NAMES[top] + ("." + rest if rest else "")


def _outside_stacklevel() -> int:
    """The ``stacklevel`` of the first frame outside the import machinery and this module."""
    frame, level = sys._getframe(2), 2
    while frame is not None and (
        "importlib" in frame.f_code.co_filename
        or frame.f_code.co_filename == __file__
        or frame.f_globals.get("__name__") in OLD_NAMES
    ):
        # warnings.warn skips the import machinery's own frames when it counts
        internal = (
            "importlib" in frame.f_code.co_filename and "_bootstrap" in frame.f_code.co_filename
        )
        frame, level = frame.f_back, level + (0 if internal else 1)
    return level


def _warn_once(top: str) -> None:
    if top in _warned:
        return
    _warned.add(top)
    warnings.warn(
        f"the top-level package {top!r} is now {OLD_NAMES[top]!r}: import it from there "
        f"(the old name works for this release only)",
        DeprecationWarning,
        stacklevel=_outside_stacklevel(),
    )


class _AliasLoader(importlib.abc.Loader):
    """Loads an old name as the module object of its new name."""

    def __init__(self, new_name: str) -> None:
        self.new_name = new_name

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(self.new_name)
        _warn_once(spec.name.partition(".")[0])
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the module is the new name's, already executed."""


class OldNameFinder(importlib.abc.MetaPathFinder):
    """Finds ``agents``, ``training``, ``reproduction`` and their submodules under their new
    names."""

    def find_spec(self, fullname, path=None, target=None):  # the finder protocol
        new = _new_name(fullname)
        if new is None or importlib.util.find_spec(new) is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(new))


def install() -> None:
    """Put :class:`OldNameFinder` at the front of ``sys.meta_path`` (once)."""
    if not any(isinstance(f, OldNameFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, OldNameFinder())


def redirect(name: str) -> bool:
    """Called by a top-level folder's ``__init__`` with its ``__name__``.

    Returns False when the package is being imported under its new name (the caller then
    defines it). Under an old name it installs the finder, points ``sys.modules[name]`` at the
    new package, warns once and returns True: the rest of the ``__init__`` then runs in a
    module object that the import discards, so it must have no side effects beyond imports.
    """
    if name not in OLD_NAMES:
        return False
    install()
    sys.modules[name] = importlib.import_module(OLD_NAMES[name])
    _warn_once(name)
    return True
