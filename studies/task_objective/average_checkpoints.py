"""Average each training run's actor over its checkpoints, and export it as a policy.

A PPO run's return wanders between checkpoints, so that its last checkpoint is one draw from
that wander (:mod:`studies.task_objective.select_checkpoint`). This script takes, per run, the
uniform average of the actor's parameters over every checkpoint from ``--from-steps`` on and
the run's final model (stochastic weight averaging, applied after training: the average of the
checkpoints' weights is a policy of the same network), and exports it as the policy ``DIR/<run
folder name>_avg`` with the final model's settings
(:func:`coopnav_env.training.torchrl_backend.export_policy`), to be compared on the test
episodes by ``compare_learned.py``. Nothing is flown here.

Example::

    python studies/task_objective/average_checkpoints.py \\
        --runs runs/scratch16m_s0 runs/scratch16m_s1 runs/scratch16m_s2 \\
        --from-steps 8000000 --export studies/task_objective/policies
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from studies.task_objective.select_checkpoint import candidates, run_folders


def averaged_actor(paths: Sequence[Path]) -> dict[str, Any]:
    """The uniform average of the ``actor`` parameters of the checkpoints ``paths`` (summed
    in float64 in the order given, then cast to each parameter's own dtype). Raises
    ``ValueError`` when the checkpoints' actors differ in names or shapes."""
    import torch

    from coopnav_env.agents.marl_policy import load_checked_checkpoint

    total: dict[str, Any] = {}
    dtypes: dict[str, Any] = {}
    for path in paths:
        actor = load_checked_checkpoint(path, "fly")["actor"]
        if total and (
            set(actor) != set(total) or any(actor[k].shape != total[k].shape for k in total)
        ):
            raise ValueError(f"{path}: its actor's parameters differ from {paths[0]}'s")
        for name, value in actor.items():
            if name not in total:
                total[name] = torch.zeros(value.shape, dtype=torch.float64)
                dtypes[name] = value.dtype
            total[name] += value.to(torch.float64)
    return {name: (s / len(paths)).to(dtypes[name]) for name, s in total.items()}


def export_average(run: Path, from_steps: int, dest: Path) -> dict[str, Any]:
    """Export the actor of ``run`` averaged over its checkpoints from ``from_steps`` on
    (:func:`select_checkpoint.candidates`) as the policy ``dest``; returns what was averaged."""
    import torch

    from coopnav_env.agents.marl_policy import load_checked_checkpoint
    from coopnav_env.training.torchrl_backend import export_policy

    found = candidates(run, from_steps)
    paths = [p for _, p in found]
    last = load_checked_checkpoint(paths[-1], "fly")
    last["actor"] = averaged_actor(paths)
    with tempfile.TemporaryDirectory() as tmp:  # a run-shaped folder for export_policy
        stage = Path(tmp)
        (stage / "checkpoints").mkdir()
        if (run / "config.yaml").is_file():
            shutil.copyfile(run / "config.yaml", stage / "config.yaml")
        src = stage / "checkpoints" / "averaged.pt"
        torch.save(last, src)
        exported = export_policy(src, dest)
    return {
        "run": str(run),
        "averaged_steps": [s for s, _ in found],
        "checkpoints": [str(p) for p in paths],
        "exported": str(exported),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", nargs="+", required=True, help="TorchRL run folders")
    p.add_argument(
        "--from-steps",
        type=int,
        default=0,
        help="first checkpoint's agent-step count averaged (default 0: every checkpoint)",
    )
    p.add_argument(
        "--export", required=True, help="write each average as DIR/<run folder name>_avg"
    )
    p.add_argument("--overwrite", action="store_true", help="replace existing policy folders")
    args = p.parse_args(argv)
    if args.from_steps < 0:
        p.error(f"--from-steps must be >= 0, got {args.from_steps}")
    runs = run_folders(p, args.runs)
    dests = [Path(args.export) / f"{r.name}_avg" for r in runs]
    taken = [str(d) for d in dests if d.exists()]
    if taken and not args.overwrite:
        p.error(f"--export: {', '.join(taken)} exist already; pass --overwrite to replace them")
    for run, dest in zip(runs, dests):
        try:
            done = export_average(run, args.from_steps, dest)
        except (FileNotFoundError, ValueError) as exc:
            p.error(str(exc))
        steps = done["averaged_steps"]
        print(f"{run.name}: {len(steps)} checkpoints ({steps[0]:,}-{steps[-1]:,}) -> {dest}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
