"""The backends' old import paths keep working for one release, with a warning.

``coopnav_env.training.marl`` is now ``coopnav_env.training.torchrl_backend`` and
``coopnav_env.benchmarl_task`` is ``coopnav_env.training.benchmarl_backend``; the old name gives
the very module object of the new one and one ``DeprecationWarning`` naming the new path.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys

import pytest

pytest.importorskip("torchrl")


def test_the_old_torchrl_backend_path_is_the_new_module_with_a_warning(monkeypatch) -> None:
    monkeypatch.delitem(sys.modules, "coopnav_env.training.marl", raising=False)
    with pytest.warns(DeprecationWarning, match=r"coopnav_env\.training\.torchrl_backend"):
        old = importlib.import_module("coopnav_env.training.marl")
    new = importlib.import_module("coopnav_env.training.torchrl_backend")
    assert old is new
    from coopnav_env.training.marl import MARLTrainer, export_policy

    assert MARLTrainer is new.MARLTrainer and export_policy is new.export_policy


def test_the_old_benchmarl_task_path_warns_and_names_the_new_module(monkeypatch) -> None:
    monkeypatch.delitem(sys.modules, "coopnav_env.benchmarl_task", raising=False)
    if importlib.util.find_spec("benchmarl") is None:  # the new module's ImportError, unchanged
        with (
            pytest.warns(DeprecationWarning, match=r"coopnav_env\.training\.benchmarl_backend"),
            pytest.raises(ImportError, match="`benchmarl` extra"),
        ):
            importlib.import_module("coopnav_env.benchmarl_task")
        return
    with pytest.warns(DeprecationWarning, match=r"coopnav_env\.training\.benchmarl_backend"):
        old = importlib.import_module("coopnav_env.benchmarl_task")
    assert old is importlib.import_module("coopnav_env.training.benchmarl_backend")
