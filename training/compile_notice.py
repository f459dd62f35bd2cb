"""Say what is happening while numba compiles the navigation kernels, instead of going quiet.

The compiled kernels of :mod:`coopnav_env` (the modules in :data:`KERNEL_MODULES`, numba
``cache=True``) are compiled on their first use after an installation or a change of their
source, about a minute for the environment's on a busy 2-core machine and about 20 s for the
demo's, and loaded from numba's on-disk cache (``__pycache__`` beside each module, or
``NUMBA_CACHE_DIR``) on every later run, in a second or two. Before this module, ``coopnav
train`` printed nothing for the minute of compilation (and the warm start after it), and the
demo's progress bar turned the compilation into an ETA of 20 minutes.

:func:`cold_kernel_modules` tells, cheaply and without compiling anything, which kernel modules
have no usable cache entry at all: it reads the cache index files numba itself reads, with
their version and source stamp (file time and size), so a fresh installation and an edited
module both count as cold. A module counts as cold only when *none* of its kernels has a
cache entry: numba caches each kernel once per argument-type signature, and one command may
need signatures another did not compile (the demo calls the solvers with other array types
than the environment). :func:`compile_notice` therefore also prints a message when the wrapped
first use simply takes longer than ``delay_s``, so that the remaining case still says what is
happening, and then how long it took.
"""

from __future__ import annotations

import importlib
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TextIO

import numpy as np

__all__ = [
    "ENV_KERNEL_MODULES",
    "KERNEL_MODULES",
    "cold_kernel_modules",
    "compile_notice",
    "warm_up_env",
]

KERNEL_MODULES: tuple[str, ...] = (
    "coopnav_env.gnss._kernels",
    "coopnav_env.nav._kernels",
    "coopnav_env.sim._kernels",
    "coopnav_env.envs._kernels",
)
"""Every module of compiled (numba) kernels in :mod:`coopnav_env` (a test checks the list)."""

ENV_KERNEL_MODULES: tuple[str, ...] = KERNEL_MODULES
"""The kernel modules ``urban_canyon_v0`` uses (all of them): ``coopnav train``/``evaluate``."""


def _dispatchers(module: object) -> list[object]:
    """The numba dispatchers defined in ``module`` that numba caches on their own.

    Kernels with ``inline="always"`` are inlined into their callers and never get a cache
    entry of their own, so they are left out.
    """
    from numba.core.dispatcher import Dispatcher

    name = getattr(module, "__name__", "")
    return [
        v
        for v in vars(module).values()
        if isinstance(v, Dispatcher)
        and getattr(v.py_func, "__module__", None) == name
        and v.targetoptions.get("inline") != "always"
    ]


def _has_cache_entry(dispatcher: object) -> bool:
    """Whether numba's on-disk cache holds a fresh entry (any signature) for the kernel."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is None:  # caching off for this kernel: it is compiled on every run
        return False
    return bool(cache_file._load_index())


def cold_kernel_modules(modules: Sequence[str] = KERNEL_MODULES) -> list[str] | None:
    """The kernel modules of which no kernel has a usable entry in numba's on-disk cache.

    Parameters
    ----------
    modules : sequence of str
        Importable module names (default :data:`KERNEL_MODULES`); importing one compiles
        nothing.

    Returns
    -------
    list of str or None
        The cold modules, in the order given (empty: every module has cached kernels, which
        loads in a second or two unless the caller needs a signature not yet compiled);
        None when it cannot be told (numba's JIT disabled, or a numba whose cache internals
        differ: the check reads numba's own cache index, a private interface).
    """
    try:
        from numba import config

        if config.DISABLE_JIT:
            return None
        cold = []
        for name in modules:
            kernels = _dispatchers(importlib.import_module(name))
            if kernels and not any(_has_cache_entry(k) for k in kernels):
                cold.append(name)
        return cold
    except (AttributeError, TypeError, OSError, ValueError, ImportError, EOFError):
        return None


@contextmanager
def compile_notice(
    first_time: str = "about a minute",
    *,
    modules: Sequence[str] = ENV_KERNEL_MODULES,
    delay_s: float = 3.0,
    stream: TextIO | None = None,
    prefix: str = "coopnav",
) -> Iterator[None]:
    """Wrap the first use of the kernels: say that they compile, and how long it took.

    On entry, when :func:`cold_kernel_modules` finds a cold module, prints at once
    ``compiling the navigation kernels (numba), once: <first_time>; later runs load them from
    the cache``; otherwise, if the wrapped block is still running after ``delay_s`` seconds,
    prints ``loading or compiling the navigation kernels ...`` then. After a message, the exit
    prints the time the block took. Nothing is printed when the block is quick and the cache
    warm.

    Parameters
    ----------
    first_time : str, default "about a minute"
        How long the first compilation takes, in words (measured on a busy 2-core machine).
    modules : sequence of str, default ENV_KERNEL_MODULES
        The kernel modules the block uses.
    delay_s : float, default 3.0
        Seconds after which a block with a warm cache is announced anyway.
    stream : text stream or None
        Where to print (default ``sys.stderr`` at the time of the call).
    prefix : str, default "coopnav"
        Start of every line (e.g. ``"coopnav train"``).
    """
    out = stream if stream is not None else sys.stderr
    lock = threading.Lock()
    said = False

    def say(text: str) -> None:
        nonlocal said
        with lock:
            if not said:
                said = True
                print(f"{prefix}: {text}", file=out, flush=True)

    t0 = time.perf_counter()
    timer = None
    if cold_kernel_modules(modules):
        say(
            f"compiling the navigation kernels (numba), once: {first_time}; later runs load "
            "them from the cache"
        )
    else:
        timer = threading.Timer(
            delay_s,
            say,
            args=(
                "loading or compiling the navigation kernels (numba; compiled once for each "
                "new use, then loaded from the cache)",
            ),
        )
        timer.daemon = True
        timer.start()
    finished = False
    try:
        yield
        finished = True
    finally:
        if timer is not None:
            timer.cancel()
        with lock:
            done = said
            said = True  # a timer that fires now stays silent
        if done and finished:
            print(
                f"{prefix}: navigation kernels ready ({time.perf_counter() - t0:.0f} s)",
                file=out,
                flush=True,
            )


def warm_up_env(env_fn: Callable[[], Any]) -> None:
    """Build one environment, reset it and step it once, then close it.

    Every kernel the environment uses is compiled (or loaded from the cache) here, so that a
    progress bar started afterwards measures the work and not the compilation. The
    environment is thrown away; nothing it draws affects later environments (each has its own
    generator, seeded at its reset). The step holds every UAV still (zero action, clipped to
    the action space); environments whose action spaces are not boxes are only reset.
    """
    env = env_fn()
    try:
        env.reset(seed=0)
        actions = {}
        for agent in env.agents:
            space = env.action_space(agent)
            low, high = getattr(space, "low", None), getattr(space, "high", None)
            if low is None or high is None:
                return
            actions[agent] = np.clip(np.zeros(space.shape), low, high).astype(space.dtype)
        if actions:
            env.step(actions)
    finally:
        env.close()
