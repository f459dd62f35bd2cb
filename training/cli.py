"""The ``coopnav`` command line.

Each subcommand lives in its own module that defines ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their subcommand runs, so
``coopnav --help`` is instant and needs no optional dependency.

Errors never end in a traceback unless asked for (:func:`main`): a usage error (a bad
setting, a missing file, malformed YAML or JSON, an unusable output folder, a checkpoint that
does not load, a missing optional dependency) prints one line ``coopnav CMD: error: ...`` and
exits 2; a failure of the system (a full disk, a file-size limit) exits 1; an interrupt, at
any moment after the ``coopnav_env`` package is imported (the subcommands' imports included),
prints one line and exits 130 (SIGINT) or 143 (SIGTERM). ``--debug`` (or ``COOPNAV_DEBUG=1``)
shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import signal
import sys
import traceback

#: subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": (
        "coopnav_env.training.demo",
        "navigation demo: standalone vs cooperative error of a canyon UAV",
    ),
    "reproduce": (
        "coopnav_env.reproduction.cli",
        "regenerate the paper's tables and figures (Section 4)",
    ),
    "train": (
        "coopnav_env.training.train",
        "train a shared policy on urban_canyon_v1 (SB3 PPO, RLlib, or TorchRL MAPPO/IPPO)",
    ),
    "evaluate": (
        "coopnav_env.training.evaluate_cli",
        "evaluate policies: navigation error, goal rate, plots",
    ),
    "alignment": (
        "coopnav_env.training.alignment",
        "does a reward rank policies as the task's score does? (return, discounted return)",
    ),
    "city": (
        "coopnav_env.training.city_cli",
        "cities from OpenStreetMap or GeoJSON: convert into a checked GeoJSON city",
    ),
}

DEBUG_ENV: str = "COOPNAV_DEBUG"
"""Environment variable that, set to 1, makes every error show its traceback (as --debug)."""


def usage_errors() -> tuple[type[BaseException], ...]:
    """Exception types that mean "the invocation is wrong" (exit status 2)."""
    errors: list[type[BaseException]] = [
        ValueError,  # bad settings, JSON errors (JSONDecodeError), unusable --out
        TypeError,  # a value of the wrong type deep in a settings mapping
        FileNotFoundError,
        IsADirectoryError,
        NotADirectoryError,
        PermissionError,
        ImportError,
        ConnectionError,
    ]
    try:
        import yaml

        errors.append(yaml.YAMLError)
    except ImportError:  # pragma: no cover - yaml is a training dependency
        pass
    return tuple(errors)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in text:
        text = f"{text}: {exc.filename}"
    return text


def _interrupt_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` that caused ``exc``, if any: an interrupt that arrived inside
    a compiled (numba) call surfaces as ``SystemError: CPUDispatcher(...) returned a result
    with an exception set`` whose cause is the interrupt."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__
    return None


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with one sub-parser per available subcommand."""
    parser = argparse.ArgumentParser(
        prog="coopnav",
        description=(
            "Cooperative GNSS navigation for UAV swarms in urban canyons: navigation demo, "
            "paper reproduction, PPO training and evaluation on the urban_canyon_v1 environment."
        ),
    )
    from coopnav_env import __version__

    parser.add_argument("--version", action="version", version=f"coopnav {__version__}")
    debug_help = f"show the full traceback of an error (also: {DEBUG_ENV}=1)"
    parser.add_argument("--debug", action="store_true", help=debug_help)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        if importlib.util.find_spec(module) is None:
            continue
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=debug_help)
        mod = importlib.import_module(module)
        mod.add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``coopnav`` console script; returns the exit status.

    An interrupt while the subcommands' modules are imported (start-up, before any command
    runs) prints one line and returns 128 + the signal number, as one during a command does.
    """
    if getattr(signal.getsignal(signal.SIGINT), "__name__", "") == (
        "coopnav_interrupted_while_loading"  # the package's, while it loaded: ours from here
    ):
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        parser = build_parser()
    except KeyboardInterrupt as exc:
        if os.environ.get(DEBUG_ENV, "") not in ("", "0"):
            traceback.print_exc()
        print("\ncoopnav: interrupted while starting; nothing was done", file=sys.stderr)
        return 128 + int(getattr(exc, "signum", signal.SIGINT))
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    debug = bool(args.debug) or os.environ.get(DEBUG_ENV, "") not in ("", "0")
    where = f"coopnav {args.command}"
    try:
        mod = importlib.import_module(args._module)
        return int(mod.run(args) or 0)
    except KeyboardInterrupt as exc:
        if debug:
            traceback.print_exc()
        print(f"\n{where}: interrupted", file=sys.stderr)
        return 128 + int(getattr(exc, "signum", signal.SIGINT))
    except usage_errors() as exc:
        if debug:
            raise
        print(f"{where}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:
        if debug:
            raise
        print(f"{where}: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    except Exception as exc:
        interrupt = _interrupt_behind(exc)
        if interrupt is not None:  # Ctrl-C inside a compiled (numba) call: SystemError
            if debug:
                traceback.print_exc()
            print(f"\n{where}: interrupted", file=sys.stderr)
            return 128 + int(getattr(interrupt, "signum", signal.SIGINT))
        if debug:
            raise
        print(
            f"{where}: internal error: {type(exc).__name__}: {_one_line(exc)} (run again with "
            f"--debug or {DEBUG_ENV}=1 for the traceback, and report it)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
