"""``coopnav reproduce``: run the reproduction and write its files (:func:`reproduce`).

Everything goes to ``--out DIR``: ``config.json`` (``--config`` reruns it exactly),
``results.json``, ``report.md`` and the ``fig*.png`` figures. The command claims ``DIR``
before any work (:func:`coopnav_env.training.files.claim_output_folder`: a lock, and
``command.json`` recording the configuration): a folder of another command, a training run,
a result of another configuration or this very finished result is refused; ``--overwrite``
replaces the outputs of the command (or the earlier reproduction) that ``DIR`` holds, never a
training run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.reproduction.config import ReproduceConfig
from coopnav_env.reproduction.figures import write_figures
from coopnav_env.reproduction.report import report_markdown
from coopnav_env.reproduction.scenario import (
    PaperScenario,
)
from coopnav_env.reproduction.simulation import json_float, run_studies
from coopnav_env.reproduction.tables import summarize
from coopnav_env.training.files import (
    atomic_write_text,
    claim_output_folder,
    ensure_folder,
    write_json,
)

__all__ = [
    "REPRODUCE_OUTPUTS",
    "add_arguments",
    "build_config",
    "reproduce",
    "run",
]

REPRODUCE_OUTPUTS: tuple[str, ...] = (
    "config.json",
    "results.json",
    "report.md",
    "fig*.png",
    "table*.png",
)
"""Glob patterns of the files ``coopnav reproduce`` writes into its ``--out``."""


def _json_default(o: Any) -> Any:
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return json_float(float(o))
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def reproduce(config: ReproduceConfig, out_dir: str | Path = "reproduce_out") -> Path:
    """Run the reproduction and write results, report, figures and config to ``out_dir``.

    Parameters
    ----------
    config : ReproduceConfig
    out_dir : str or Path
        Output directory (created if needed; files in it are overwritten).

    Returns
    -------
    Path
        ``out_dir``.
    """
    out = Path(out_dir)
    _write_reproduction(config, out)
    return out


def _write_reproduction(config: ReproduceConfig, out_dir: str | Path) -> list[Path]:
    """:func:`reproduce`, returning the paths of the files it wrote."""
    if not isinstance(config, ReproduceConfig):
        raise ValueError(f"config must be a ReproduceConfig, got {type(config).__name__}")
    out = ensure_folder(out_dir)
    t0 = time.perf_counter()
    cfg_dict = config.to_dict()
    write_json(out / "config.json", cfg_dict)
    raw = run_studies(config)
    t_sim = time.perf_counter() - t0
    summary = summarize(config, raw)
    figs = write_figures(config, raw, summary, out) if config.figures else []
    runtime = time.perf_counter() - t0
    results = {
        "config": cfg_dict,
        **summary,
        "timing": {"simulation_s": round(t_sim, 2), "total_s": round(runtime, 2)},
    }
    atomic_write_text(
        out / "results.json",
        json.dumps(results, indent=1, default=_json_default, allow_nan=False) + "\n",
    )
    atomic_write_text(out / "report.md", report_markdown(config, summary, figs, runtime))
    written = [out / "config.json", *(out / name for name, _ in figs)]
    return [*written, out / "results.json", out / "report.md"]


def _parse_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def build_config(args: argparse.Namespace) -> ReproduceConfig:
    """The configuration from the command line (``--config``, ``--quick``, ``--set``...)."""
    data: dict[str, Any] = {}
    if args.config:
        try:
            data = json.loads(Path(args.config).read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"--config {args.config} is not valid JSON: {exc}") from exc
        if not isinstance(data, dict):
            raise ValueError(f"--config {args.config} must hold a JSON object")
    elif args.quick:
        data = ReproduceConfig.quick().to_dict()
    scen = dict(data.pop("scenario", {}))
    fields = {f.name for f in dataclasses.fields(ReproduceConfig)} - {"scenario"}
    sfields = set(PaperScenario.__dataclass_fields__)
    for item in args.set or []:
        if "=" not in item:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        key = key.strip().removeprefix("scenario.")
        if key in fields:
            data[key] = _parse_value(value)
        elif key in sfields:
            scen[key] = _parse_value(value)
        else:
            raise ValueError(f"unknown --set key {key!r}; allowed: {sorted(fields | sfields)}")
    if args.seed is not None:
        data["seed"] = args.seed
    if args.no_figures:
        data["figures"] = False
    if args.no_sensitivity:
        data["sensitivity"] = False
    if args.no_progress:
        data["progress"] = False
    data["scenario"] = scen
    return ReproduceConfig.from_dict(data)


def _defaults_epilog() -> str:
    """The configuration's defaults, for ``--help`` (every ``--set`` key with its value)."""
    cfg = ReproduceConfig().to_dict()
    scen = cfg.pop("scenario")

    def items(d: dict[str, Any]) -> str:
        return textwrap.fill(
            ", ".join(f"{k}={json.dumps(v, separators=(',', ':'))}" for k, v in d.items()),
            width=92,
            initial_indent="  ",
            subsequent_indent="  ",
        )

    return (
        "configuration defaults (ReproduceConfig; change with --set KEY=VALUE):\n"
        + items(cfg)
        + "\n\nscenario defaults (PaperScenario; change with --set KEY=VALUE):\n"
        + items(scen)
        + "\n\n--quick (a smoke run) starts from ReproduceConfig.quick() instead, which changes:\n"
        + items(_quick_changes())
    )


def _quick_changes() -> dict[str, Any]:
    """The fields ``--quick`` changes, with their values."""
    full, quick = ReproduceConfig().to_dict(), ReproduceConfig.quick().to_dict()
    return {k: v for k, v in quick.items() if full[k] != v}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``coopnav reproduce`` (defaults shown by ``--help``)."""
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = _defaults_epilog()
    parser.add_argument(
        "--out",
        required=True,
        help="output directory, of this reproduction alone: a folder of another command, of "
        "another configuration, or holding this finished reproduction is refused (required)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of the command (or the earlier reproduction) that --out "
        "holds; a training run is never replaced; default: %(default)s (refuse)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smoke run, not the reproduction: the small ReproduceConfig.quick() configuration "
        "(well under a minute; its report says so); default: %(default)s",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="random seed; default: %(default)s, i.e. the seed of --config, else "
        f"{ReproduceConfig().seed}",
    )
    parser.add_argument(
        "--config",
        default=None,
        help="JSON configuration, e.g. a previous run's config.json; default: %(default)s "
        "(the defaults listed below, or --quick's)",
    )
    parser.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a configuration field (ReproduceConfig or PaperScenario;"
        " VALUE parsed as JSON), e.g. --set covariance=exact "
        "--set h_over_d=2 --set 'gaps_deg=[]'; repeatable; default: none",
    )
    parser.add_argument(
        "--no-figures", action="store_true", help="skip the PNG figures; default: %(default)s"
    )
    parser.add_argument(
        "--no-sensitivity",
        action="store_true",
        help="skip the sensitivity study; default: %(default)s",
    )
    parser.add_argument(
        "--no-progress", action="store_true", help="no progress bar; default: %(default)s"
    )


def run(args: argparse.Namespace) -> int:
    """``coopnav reproduce``: returns the process exit status (errors: one line and exit 2
    for a bad configuration, see :mod:`coopnav_env.training.cli`)."""
    cfg = build_config(args)
    settings = {k: v for k, v in cfg.to_dict().items() if k != "progress"}  # not the result's
    with claim_output_folder(
        args.out,
        "coopnav reproduce",
        settings,
        outputs=REPRODUCE_OUTPUTS,
        overwrite=args.overwrite,
    ) as claim:  # --out is claimed (locked, checked, recorded) before any work
        claim.finish(_write_reproduction(cfg, args.out))
    out = Path(args.out)
    extra = " and the figures" if cfg.figures else ""
    smoke = " (a smoke run, not the reproduction)" if cfg.smoke_reasons() else ""
    print(f"wrote report.md, results.json, config.json{extra} to {out}{smoke}")
    return 0
