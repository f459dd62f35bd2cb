"""The ``coopnav`` command line.

Each subcommand lives in its own module that defines ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their subcommand runs, so
``coopnav --help`` is instant and needs no optional dependency.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

#: subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("training.demo", "navigation demo: standalone vs cooperative error of a canyon UAV"),
    "reproduce": ("reproduction.cli", "regenerate the paper's tables and figures (Section 4)"),
    "train": (
        "training.train",
        "train a shared policy on urban_canyon_v0 (SB3 PPO, Ray RLlib, or TorchRL MAPPO/IPPO)",
    ),
    "evaluate": ("training.evaluate", "evaluate policies: navigation error, goal rate, plots"),
    "study": (
        "training.marl_study",
        "the learning study: learned swarms vs heuristics and a privileged planner, with CIs",
    ),
    "render": ("training.render", "render one episode of urban_canyon_v0 to PNG frames"),
}


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with one sub-parser per available subcommand."""
    parser = argparse.ArgumentParser(
        prog="coopnav",
        description=(
            "Cooperative GNSS navigation for UAV swarms in urban canyons: navigation demo, "
            "paper reproduction, PPO training and evaluation on the urban_canyon_v0 environment."
        ),
    )
    from coopnav_env import __version__

    parser.add_argument("--version", action="version", version=f"coopnav {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        if importlib.util.find_spec(module) is None:
            continue
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        mod = importlib.import_module(module)
        mod.add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``coopnav`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    mod = importlib.import_module(args._module)
    return int(mod.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
