"""Fly trained MASAC actors beside the column heuristics on held-out v1 grid episodes.

Every policy flies the same held-out episodes of ``urban_canyon_v1`` (reset seeds
``--seed-start`` onwards, as ``studies/task_objective/compare_learned.py`` seeds them), each
episode scored by ``compare_learned.fly_policy``: the score (the undiscounted return, mean over
UAVs), goal and collision rates, navigation error, steps, and the cruise's nearest-UAV spacing
and altitude. The MASAC actors (``--policies``, one saved ``policy/`` folder per training seed,
written by ``train_masac.py``) fly deterministically in the environment they were trained in
(route frame, decisions held); the method's row averages its seeds per episode. Beside them:
``formation`` (the gap's baseline, 0), ``high_wide_column``
(``wide@spacing_m=60,cruise_speed_mps=10,ceiling_margin_m=-10``, the reference, 1) and the
untrained actor (MASAC's initial weights for training seed 0, flown the same way: what the
route frame gives before any learning). Each row has its score with a 95 % bootstrap interval,
the paired difference to the reference and to the baseline (95 %, training runs resampled too)
and the share of the gap closed (paired bootstrap over episodes). The training runs' budget and
throughput (from each actor's ``actor.json``) are tabled below.

Example::

    python studies/off_policy/evaluate_masac.py \\
        --policies studies/off_policy/policies/masac_s0 studies/off_policy/policies/masac_s1 \\
        --episodes 100 --seed-start 1000100 --out studies/off_policy
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from studies.off_policy.masac import (
    POLICY_FILES,
    MasacPolicy,
    MasacSettings,
    build_experiment,
    load_actor,
)
from studies.task_objective.compare_learned import (
    CRUISE,
    KEYS,
    SCORE_NEUTRAL_SETTINGS,
    add_report_arguments,
    fly,
    fly_policy,
    one_torch_thread,
    report_folder,
    to_markdown,
    write_report,
)

BASELINE = "formation"
REFERENCE = "wide@spacing_m=60,cruise_speed_mps=10,ceiling_margin_m=-10"
REFERENCE_LABEL = "high_wide_column"
METHOD = "masac"
UNTRAINED = "masac_untrained"


def check_env_settings(env: Mapping[str, Any]) -> None:
    """``ValueError`` unless ``env`` differs from ``urban_canyon_v1``'s defaults only in
    settings that leave its episodes and score unchanged (``SCORE_NEUTRAL_SETTINGS``)."""
    from coopnav_env import urban_canyon_v1

    default_env = urban_canyon_v1.parallel_env()
    default = default_env.config
    default_env.close()
    other = sorted(
        k
        for k, v in env.items()
        if k not in SCORE_NEUTRAL_SETTINGS and getattr(default, k, object()) != v
    )
    if other:
        raise ValueError(
            f"the actor was trained with env settings {other} that change the episodes; only "
            f"{sorted(SCORE_NEUTRAL_SETTINGS)} may differ from urban_canyon_v1's defaults"
        )


def fly_actor(module: Any, settings: MasacSettings, name: str, seeds: Sequence[int]) -> list:
    """Per-episode figures (``fly_policy``) of a MASAC policy module flown in its training
    environment on ``seeds``, torch on one thread."""
    from coopnav_env import urban_canyon_v1

    check_env_settings(settings.env)
    env = urban_canyon_v1.parallel_env(**settings.env)
    try:
        policy = MasacPolicy(module, env.possible_agents, settings.hold, name)
        with one_torch_thread():
            return fly_policy(env, policy, seeds)
    finally:
        env.close()


def fly_saved(folder: Path, seeds: Sequence[int]) -> tuple[list, dict[str, Any]]:
    """Per-episode figures of the actor saved in ``folder`` and its ``actor.json``."""
    with tempfile.TemporaryDirectory() as scratch:
        module, settings = load_actor(folder, Path(scratch))
        rows = fly_actor(module, settings, str(folder), seeds)
    return rows, json.loads((Path(folder) / "actor.json").read_text())


def fly_untrained(settings: MasacSettings, seeds: Sequence[int]) -> list:
    """Per-episode figures of MASAC's initial actor (training seed 0, no update)."""
    import torch

    with tempfile.TemporaryDirectory() as scratch:
        torch.manual_seed(0)
        experiment = build_experiment(settings, 0, Path(scratch), settings.frames_per_batch)
        module = experiment.group_policies["uav"].eval()
        experiment.collector.shutdown()
        return fly_actor(module, settings, UNTRAINED, seeds)


def summarise(
    flown: Mapping[str, list], methods: Mapping[str, Sequence[str]], reps: int
) -> list[dict[str, Any]]:
    """One row per policy and per method (its policies averaged per episode): the figures of
    ``KEYS``, the score's interval, the paired differences and the gap closed."""
    from coopnav_env.training.stats import (
        bootstrap_mean_interval,
        gap_closed,
        paired_difference,
    )

    def matrix(names: Sequence[str], key: str) -> np.ndarray:
        return np.array([[e[key] for e in flown[p]] for p in names], dtype=float)

    groups = {name: [name] for name in flown} | {m: list(ps) for m, ps in methods.items()}
    ref, base = matrix([REFERENCE], "score"), matrix([BASELINE], "score")
    untrained = matrix([UNTRAINED], "score") if UNTRAINED in flown else None
    rows = []
    for name, members in groups.items():
        scores = matrix(members, "score")
        row: dict[str, Any] = {"name": REFERENCE_LABEL if name == REFERENCE else name}
        row["policies"] = members
        row["score"] = list(
            bootstrap_mean_interval(scores.mean(axis=0), reps, np.random.default_rng(0))
        )
        for k in KEYS[1:]:
            row[k] = float(matrix(members, k).mean())
        pairs = [("score_minus_reference", ref), ("score_minus_baseline", base)]
        if untrained is not None:
            pairs.append(("score_minus_untrained", untrained))
        for key, other in pairs:
            iv, _ = paired_difference(scores, other, reps=reps, seed=0)
            row[key] = [iv.value, iv.low, iv.high]
        gap = gap_closed(scores, base, ref, reps=reps, seed=0)
        row["gap_closed"] = [gap.value, gap.low, gap.high]
        rows.append(row)
    return rows


def untrained_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """The paired score difference of every MASAC row to the untrained actor (Markdown)."""
    found = [r for r in rows if "score_minus_untrained" in r and r["name"] != UNTRAINED]
    found = [r for r in found if r["name"] not in (BASELINE, REFERENCE_LABEL)]
    if not found:
        return ""
    lines = [
        "",
        f"What training added: score minus the untrained actor's (`{UNTRAINED}`, the same "
        "actor at its initial weights), paired 95 % interval:",
        "",
        "| policy | score - untrained [95 % CI] |",
        "|---|---|",
    ]
    for r in found:
        v = r["score_minus_untrained"]
        lines.append(f"| `{r['name']}` | {v[0]:+.3f} [{v[1]:+.3f}, {v[2]:+.3f}] |")
    return "\n".join(lines) + "\n"


def training_markdown(training: Sequence[Mapping[str, Any]]) -> str:
    """The training runs' budget and throughput as a Markdown table."""
    lines = [
        "",
        "Training runs (BenchMARL MASAC, CPU, torch on one thread; agent-steps = swarm steps x "
        "UAVs; collect / update: wall time in collection and in gradient steps):",
        "",
        "| run | agent-steps | decisions | gradient steps | wall [s] | agent-steps/s | "
        "collect [s] | update [s] | s per gradient step |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for t in training:
        lines.append(
            f"| `{t['policy']}` | {t['agent_steps']:,} | {t['frames']:,} | "
            f"{t['optimizer_steps']:,} | {t['wall_s']:.0f} | {t['agent_steps_per_s']:.0f} | "
            f"{t['collect_s']:.0f} | {t['train_s']:.0f} | {t['seconds_per_optimizer_step']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def evaluate(
    policies: Sequence[Path], seeds: Sequence[int], reps: int = 2000, untrained: bool = True
) -> dict[str, Any]:
    """Fly the heuristics, the saved actors ``policies`` and (``untrained``) the untrained
    actor on ``seeds`` and summarise (see the module docstring)."""
    from tqdm.auto import tqdm

    flown: dict[str, list] = {}
    for name in (BASELINE, REFERENCE):
        flown[name] = fly(name, seeds)
    training = []
    settings = None
    for folder in tqdm([Path(p) for p in policies], desc="MASAC actors"):
        rows, record = fly_saved(folder, seeds)
        flown[str(folder)] = rows
        settings = settings or MasacSettings.from_json(record["settings"])
        keep = (
            "seed",
            "agent_steps",
            "frames",
            "optimizer_steps",
            "wall_s",
            "agent_steps_per_s",
            "collect_s",
            "train_s",
            "seconds_per_optimizer_step",
            "stopped_by",
        )
        training.append({"policy": str(folder), **{k: record.get(k) for k in keep}})
    if untrained and settings is not None:
        flown[UNTRAINED] = fly_untrained(settings, seeds)
    methods = {METHOD: [str(p) for p in policies]} if len(policies) > 1 else {}
    return {
        "environment": "urban_canyon_v1",
        "seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "reference": REFERENCE_LABEL,
        "reference_policy": REFERENCE,
        "baseline": BASELINE,
        "cruise": list(CRUISE),
        "settings": settings.to_json() if settings is not None else None,
        "rows": summarise(flown, methods, reps),
        "between_methods": [],
        "training": training,
        "episodes_per_policy": flown,
    }


def build_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    from coopnav_env.training.envs import EVAL_SEED_START

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--policies",
        nargs="+",
        required=True,
        help="saved MASAC actors (a run's policy/ folder), one per training seed",
    )
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed-start", type=int, default=EVAL_SEED_START + 100)
    p.add_argument("--reps", type=int, default=2000, help="bootstrap replicates")
    p.add_argument(
        "--no-untrained", action="store_true", help="leave out the untrained actor's row"
    )
    add_report_arguments(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point (``--help``)."""
    from coopnav_env.training.envs import heldout_seeds

    p = build_parser()
    args = p.parse_args(argv)
    out = report_folder(p, args)
    for folder in args.policies:
        missing = [n for n in POLICY_FILES if not (Path(folder) / n).is_file()]
        if missing:
            p.error(f"--policies {folder} is not a saved MASAC actor: it lacks {missing}")
    if args.reps < 1:
        p.error(f"--reps must be >= 1, got {args.reps}")
    try:
        seeds = heldout_seeds(args.episodes, args.seed_start)
    except ValueError as exc:
        p.error(str(exc))
    report = evaluate(args.policies, seeds, args.reps, untrained=not args.no_untrained)
    text = to_markdown(report) + untrained_markdown(report["rows"])
    text += training_markdown(report["training"])
    write_report(out, "MASAC (BenchMARL) from scratch on v1 street grids", report, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
