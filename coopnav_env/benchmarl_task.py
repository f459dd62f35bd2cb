"""Deprecated import path of :mod:`coopnav_env.training.benchmarl_backend`
(the BenchMARL task); kept for one release.

``import coopnav_env.benchmarl_task`` gives the very module object of the new path, with one
:class:`DeprecationWarning` that names it.
"""

from __future__ import annotations

import importlib
import sys
import warnings

warnings.warn(
    "coopnav_env.benchmarl_task is now coopnav_env.training.benchmarl_backend; "
    "the old import path will be removed in the next release",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = importlib.import_module("coopnav_env.training.benchmarl_backend")
