"""Train BenchMARL's MASAC from scratch on ``urban_canyon_v1``, CPU, one thread.

The training cities are the environment's random street grids, or those of ``--city`` (e.g.
``family:mixed``, a new city of every generated family, from ``--city-pool`` seeds).

No warm start and no heuristic in the policy: the actor and the two critics start from random
weights, and the actor's output is the route-frame command (offset across the street, speed,
altitude; the environment's autopilot turns it into velocity, as in the TorchRL route
recipes), each decision held ``--hold`` swarm steps. The discount is 1: the undiscounted
return is the task's score. The budget is wall-clock minutes (``--minutes``: the run stops at
the first iteration that starts after it) or decisions (``--frames``).

The run folder (``--out``) gets ``config.json`` (the settings, written first),
``progress.csv`` (one row per iteration), ``benchmarl/`` (BenchMARL's own csv logs),
``policy/`` (the trained actor: ``actor.pt`` and ``actor.json``, which
``evaluate_masac.py`` flies) and, last, ``run.json`` with the budget spent: agent-steps,
wall time, agent-steps per second, and the time spent collecting and updating. A folder that
already holds a run (``config.json`` or ``run.json``) is refused, never overwritten.

Example::

    python studies/off_policy/train_masac.py --seed 0 --minutes 20 --out runs/masac_s0
    python studies/off_policy/train_masac.py --seed 0 --minutes 50 --city family:mixed \
        --city-pool 200 --out runs/masac_families_s0
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from studies.off_policy.masac import (
    HeldDecisions,
    MasacSettings,
    build_experiment,
    default_env_config,
    save_actor,
)

try:  # BenchMARL's venv (the `benchmarl` extra)
    from benchmarl.experiment.callback import Callback
except ImportError:  # pragma: no cover - the project's usual venv: the folder checks still work
    Callback = object

RUN_MARKERS = ("config.json", "run.json")
"""Files whose presence says a folder already holds a (started or finished) run."""


class BudgetSpent(Exception):
    """Raised by :class:`RunClock` to stop BenchMARL's loop when the minutes are spent."""


def _one_torch_thread() -> None:
    import torch

    if torch.get_num_threads() != 1:
        torch.set_num_threads(1)


def check_run_folder(out: Path) -> Path:
    """``out`` if it may receive a new run, else ``ValueError``.

    A folder holding ``run.json`` (a finished run) or ``config.json`` (a started one) is
    refused, so that a run is never overwritten; other files (such as a log the caller
    redirects into it) are left alone.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file; give a folder for the run")
    if (out / "run.json").exists():
        raise ValueError(f"--out {out} holds a finished run (run.json); choose another folder")
    if (out / "config.json").exists():
        raise ValueError(
            f"--out {out} holds a started run (config.json); choose another folder or delete it"
        )
    return out


class RunClock(Callback):
    """A BenchMARL callback that times collection and updates, counts the agent-steps trained
    on, writes ``progress.csv`` and stops the run when ``budget_s`` is spent.

    Parameters
    ----------
    out : Path
        The run folder (``progress.csv`` goes there).
    n_uavs : int
        Agents per swarm step.
    budget_s : float or None
        Wall-clock seconds from :meth:`start`; None: no time limit.
    """

    def __init__(self, out: Path, n_uavs: int, budget_s: float | None) -> None:
        super().__init__()
        self.out = out
        self.n_uavs = n_uavs
        self.budget_s = budget_s
        self.collect_s = 0.0
        self.train_s = 0.0
        self.agent_steps = 0
        self.frames = 0
        self.iterations = 0
        self.rows: list[dict[str, float]] = []
        self.torch_threads = 0
        self._t0 = self._mark = time.perf_counter()
        self._steps0 = HeldDecisions.swarm_steps

    def start(self) -> None:
        """Start the clock (call right before ``experiment.run()``) and put torch on one
        thread (TorchRL raises the count when it closes the environments it built to read
        their specs)."""
        import torch

        torch.set_num_threads(1)
        self._t0 = self._mark = time.perf_counter()
        self._steps0 = HeldDecisions.swarm_steps

    def elapsed_s(self) -> float:
        """Seconds since :meth:`start`."""
        return time.perf_counter() - self._t0

    def on_batch_collected(self, batch: Any) -> None:
        """Count the collection time; raise :class:`BudgetSpent` once the budget is spent."""
        now = time.perf_counter()
        self.collect_s += now - self._mark
        self._mark = now
        _one_torch_thread()
        if self.budget_s is not None and now - self._t0 >= self.budget_s:
            raise BudgetSpent

    def on_train_end(self, training_td: Any, group: str) -> None:
        """Count the update time and record the iteration (:meth:`on_iteration`)."""
        now = time.perf_counter()
        self.train_s += now - self._mark
        self._mark = now
        self.on_iteration(self.experiment, training_td)

    def on_iteration(self, experiment: Any, training_td: Any) -> None:
        """Record one finished iteration (collection and update) in ``progress.csv``."""
        import torch

        self.iterations += 1
        self.torch_threads = max(self.torch_threads, torch.get_num_threads())
        self.frames = int(experiment.total_frames)
        self.agent_steps = (HeldDecisions.swarm_steps - self._steps0) * self.n_uavs
        row = {
            "iteration": self.iterations,
            "frames": self.frames,
            "agent_steps": self.agent_steps,
            "elapsed_s": round(self.elapsed_s(), 3),
            "collect_s": round(self.collect_s, 3),
            "train_s": round(self.train_s, 3),
            "mean_return": float(experiment.mean_return),
        }
        for key in ("loss_actor", "loss_qvalue", "alpha", "entropy"):
            if key in training_td.keys():
                row[key] = float(training_td[key].float().mean())
        self.rows.append(row)
        self._write_progress()
        if self.iterations == 1 or self.iterations % 10 == 0:
            print(
                f"iter {self.iterations} agent-steps {self.agent_steps} "
                f"elapsed {row['elapsed_s']:.0f}s collect {self.collect_s:.0f}s "
                f"train {self.train_s:.0f}s mean return {row['mean_return']:.3f}",
                flush=True,
            )

    def _write_progress(self) -> None:
        from coopnav_env.training.files import atomic_write_text

        keys = list(dict.fromkeys(k for r in self.rows for k in r))
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=keys)
        writer.writeheader()
        writer.writerows(self.rows)
        atomic_write_text(self.out / "progress.csv", buf.getvalue())


def train(
    settings: MasacSettings,
    seed: int,
    out: Path,
    minutes: float | None = None,
    frames: int | None = None,
) -> dict[str, Any]:
    """Train MASAC with ``settings`` and ``seed`` into the run folder ``out`` (see the module
    docstring) for ``minutes`` of wall time or ``frames`` decisions (exactly one of them);
    returns what ``run.json`` holds."""
    import torch

    from coopnav_env.training.files import write_json

    if (minutes is None) == (frames is None):
        raise ValueError("give exactly one budget: minutes or frames")
    out = check_run_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    config = {
        "algorithm": "masac",
        "backend": "benchmarl",
        "env_id": "urban_canyon_v1",
        "seed": int(seed),
        "budget": {"minutes": minutes, "frames": frames},
        "torch_threads": 1,
        "warm_start": None,
        "settings": settings.to_json(),
    }
    write_json(out / "config.json", config)
    n_uavs = int(settings.env.get("n_uavs", 5))
    clock = RunClock(out, n_uavs, None if minutes is None else 60.0 * minutes)
    # a frame budget runs to it; a time budget stops through the clock before this cap
    cap = frames if frames is not None else 10**12
    cap = settings.frames_per_batch * max(1, math.ceil(cap / settings.frames_per_batch))
    wall0 = time.perf_counter()
    experiment = build_experiment(
        settings, seed, out / "benchmarl", max_n_frames=cap, callbacks=[clock]
    )
    setup_s = time.perf_counter() - wall0
    stopped_by = "frames"
    clock.start()
    try:
        experiment.run()
    except BudgetSpent:
        stopped_by = "minutes"
        experiment.close()
    train_wall_s = clock.elapsed_s()
    record = {
        "seed": int(seed),
        "stopped_by": stopped_by,
        "iterations": clock.iterations,
        "frames": clock.frames,
        "agent_steps": clock.agent_steps,
        "wall_s": round(train_wall_s, 1),
        "setup_s": round(setup_s, 1),
        "collect_s": round(clock.collect_s, 1),
        "train_s": round(clock.train_s, 1),
        "agent_steps_per_s": round(clock.agent_steps / max(train_wall_s, 1e-9), 1),
        "collect_agent_steps_per_s": round(clock.agent_steps / max(clock.collect_s, 1e-9), 1),
        "optimizer_steps": clock.iterations * settings.optimizer_steps,
        "seconds_per_optimizer_step": round(
            clock.train_s / max(1, clock.iterations * settings.optimizer_steps), 5
        ),
        "final_mean_return": clock.rows[-1]["mean_return"] if clock.rows else None,
        "torch_threads": clock.torch_threads,
    }
    save_actor(experiment, settings, out / "policy", record)
    write_json(out / "run.json", record)
    print(f"done: {record}", flush=True)
    return record


def _positive_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def check_env(env: dict[str, Any]) -> None:
    """``ValueError`` naming the setting if the settings ``env`` do not make an
    ``urban_canyon_v1`` environment (a bad ``--city`` or ``--city-pool``); called before any
    run folder is written."""
    from coopnav_env import urban_canyon_v1

    try:
        urban_canyon_v1.parallel_env(**env).close()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"bad environment settings {env}: {exc}") from None


def _non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    d = MasacSettings(env={})
    p.add_argument("--seed", type=_non_negative_int, required=True, help="training seed")
    budget = p.add_mutually_exclusive_group(required=True)
    budget.add_argument("--minutes", type=_positive_float, help="wall-clock budget")
    budget.add_argument("--frames", type=_positive_int, help="budget in decisions (frames)")
    p.add_argument("--out", required=True, help="new run folder (never overwritten)")
    p.add_argument("--hold", type=_positive_int, default=d.hold, help="swarm steps/decision")
    p.add_argument("--n-envs", type=_positive_int, default=d.n_envs)
    p.add_argument("--frames-per-batch", type=_positive_int, default=d.frames_per_batch)
    p.add_argument("--optimizer-steps", type=_positive_int, default=d.optimizer_steps)
    p.add_argument("--train-batch-size", type=_positive_int, default=d.train_batch_size)
    p.add_argument("--memory-size", type=_positive_int, default=d.memory_size)
    p.add_argument("--init-random-frames", type=_non_negative_int, default=d.init_random_frames)
    p.add_argument("--lr", type=_positive_float, default=d.lr)
    p.add_argument("--alpha-init", type=_positive_float, default=d.alpha_init)
    p.add_argument(
        "--city",
        help="the training cities (an urban_canyon_v1 'city' setting, e.g. family:mixed; "
        "default: the environment's random street grids)",
    )
    p.add_argument(
        "--city-pool",
        type=_positive_int,
        help="draw every training city from this many city seeds (urban_canyon_v1's "
        "'city_pool'; default: a new city every episode)",
    )
    p.add_argument(
        "--num-cells",
        type=_positive_int,
        nargs="+",
        default=list(d.num_cells),
        help="hidden layer widths of the actor and the critics",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point (``--help``)."""
    p = build_parser()
    args = p.parse_args(argv)
    try:
        check_run_folder(Path(args.out))
        cities = {"city": args.city, "city_pool": args.city_pool}
        cities = {k: v for k, v in cities.items() if v is not None}
        check_env(cities)
        settings = MasacSettings(
            env={**default_env_config(), **cities},
            hold=args.hold,
            n_envs=args.n_envs,
            frames_per_batch=args.frames_per_batch,
            optimizer_steps=args.optimizer_steps,
            train_batch_size=args.train_batch_size,
            memory_size=args.memory_size,
            init_random_frames=args.init_random_frames,
            lr=args.lr,
            alpha_init=args.alpha_init,
            num_cells=tuple(args.num_cells),
        )
    except ValueError as exc:
        p.error(str(exc))
    train(settings, args.seed, Path(args.out), minutes=args.minutes, frames=args.frames)
    return 0


if __name__ == "__main__":
    sys.exit(main())
