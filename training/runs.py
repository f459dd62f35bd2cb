"""Run folders: the rules that keep a training run's work safe, for every backend.

A run folder (``--out``) holds one training run: ``config.yaml`` (its settings),
``checkpoints/``, ``logs/``, the final model and ``run.json`` (written last, when the run is
finished). :func:`open_run` applies these rules before a backend does any work:

* **The folder is usable**: a path that is a file, or a folder that cannot be written, is a
  clear error (:class:`RunFolderError`, a ``ValueError``) before anything starts.
* **One run at a time**: the run holds an exclusive lock (``fcntl.flock`` on
  ``OUT/.coopnav.lock``) for its whole life; a second run into the same folder fails at once,
  naming the process that holds it. The operating system releases the lock when the process
  ends, however it ends (SIGKILL included), so a lock is never left behind.
* **Fresh, overwrite or resume**: a fresh run into a folder that already holds run outputs is
  refused unless ``overwrite`` (the old outputs are removed first; other files are left
  alone) or ``resume`` (continue the run in it) says what is meant.
* **A finished run** (``run.json`` and its final model present) is recognised: resuming it
  does nothing unless a larger ``timesteps`` asks for more training, which then continues
  from the final model.
* **Interrupts**: SIGINT and SIGTERM raise :class:`Interrupted` (a ``KeyboardInterrupt``)
  from the moment the folder is opened, so a backend writes a checkpoint and says what it
  saved for both, in every phase (the behaviour-cloning warm start included); the command
  exits with ``128 + signal number`` (130, 143). While a backend trains
  (:func:`interrupts_deferred`), a signal only sets a flag that the backend checks between
  steps (:func:`raise_if_interrupted`): an exception raised inside compiled (numba) code or
  inside a destructor would otherwise end in a ``SystemError`` or be swallowed. A second
  signal raises at once.
* **A folder of its own**: a folder another command claimed (``command.json`` of ``coopnav
  study``, ``coopnav evaluate`` or ``coopnav reproduce``, see
  :func:`coopnav_env.training.files.claim_output_folder`) or one holding a route or split
  model run or a study's flights (:data:`OTHER_RUN_FILES`) is refused, naming the command,
  with ``overwrite`` and ``resume`` too: a training run never mixes with another command's
  outputs nor removes them.
* **A backend that matches**: resuming a folder with another ``--backend`` than its run was
  trained with is refused, naming both.
* **The learning curve**: ``logs/progress.csv`` holds every iteration once, in order, however
  often the run was interrupted and resumed (:class:`ProgressLog`: a resumed session keeps
  the rows up to its checkpoint and drops those after it, which it trains again).

Checkpoints: :func:`checkpoint_candidates` lists a folder's ``<prefix>_<N>_steps`` entries
(and a finished run's final model), :func:`first_loadable` takes the newest one that loads
and names every newer one it had to skip. Every file is written atomically
(:mod:`coopnav_env.training.files`).
"""

from __future__ import annotations

import json
import re
import shutil
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coopnav_env.training.config import parse_settings_yaml, parse_yaml
from coopnav_env.training.files import (
    CLAIM_NAME,
    LOCK_NAME,
    atomic_path,
    atomic_write_text,
    ensure_folder,
    folder_lock,
    write_json,
    write_yaml,
)

if TYPE_CHECKING:  # pragma: no cover
    from coopnav_env.training.config import TrainConfig

__all__ = [  # atomic_path ... write_yaml: coopnav_env.training.files, also importable from here
    "LOCK_NAME",
    "OTHER_RUN_FILES",
    "RUN_OUTPUTS",
    "Interrupted",
    "ProgressLog",
    "RunFolderError",
    "RunState",
    "atomic_path",
    "atomic_write_text",
    "check_same_environment",
    "checkpoint_candidates",
    "claiming_command",
    "finished_run",
    "first_loadable",
    "install_interrupt_handlers",
    "interrupts_deferred",
    "interrupts_raise",
    "open_run",
    "raise_if_interrupted",
    "recorded_backend",
    "recorded_config",
    "run_outputs",
    "sigterm_as_interrupt",
    "write_json",
    "write_yaml",
]


RUN_OUTPUTS: tuple[str, ...] = (
    "config.yaml",
    "config_resumed_at_*.yaml",
    "run.json",
    "pretrain.json",
    "final_model*",
    "checkpoints",
    "logs",
    "*monitor.csv",
    "ray",
)
"""Glob patterns of what a training run writes into its folder (any backend)."""

OTHER_RUN_FILES: tuple[str, ...] = (
    "route_model.json",
    "split_model.json",
    "episodes.npz",
    "settings.json",
)
"""Files of a run of another command, which ``coopnav train`` never writes into: a route or
split model run (``route_learning.py`` of ``studies/route_choice``) and the flights of a study
(:func:`coopnav_env.training.files.claim_run_folder`)."""


class RunFolderError(ValueError):
    """The output folder cannot be used as asked (a usage error: the command exits 2)."""


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; ``signum`` says which (the exit status is 128 + signum)."""

    def __init__(self, signum: int):
        super().__init__(f"signal {signum}")
        self.signum = int(signum)


# --------------------------------------------------------------------------------------------
# what a folder holds
# --------------------------------------------------------------------------------------------


def run_outputs(out: str | Path) -> list[Path]:
    """The entries of ``out`` that a training run wrote (see :data:`RUN_OUTPUTS`)."""
    out = Path(out)
    if not out.is_dir():
        return []
    found = {p for pattern in RUN_OUTPUTS for p in out.glob(pattern)}
    return sorted(found)


def claiming_command(out: str | Path) -> str | None:
    """The command that claimed the folder ``out`` (``"coopnav evaluate"``, ...), or None.

    Read from its ``command.json`` (:func:`coopnav_env.training.files.claim_output_folder`);
    a ``command.json`` that cannot be read or names no command gives ``"an unknown
    command"``: the folder is claimed all the same.
    """
    path = Path(out) / CLAIM_NAME
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return "an unknown command"
    command = record.get("command") if isinstance(record, dict) else None
    return command if isinstance(command, str) and command else "an unknown command"


def _refuse_another_command(out: Path) -> None:
    """Refuse ``out`` if it belongs to another command than ``coopnav train`` (see the
    module docstring); ``--overwrite`` and ``--resume`` do not change that."""
    how = (
        "`coopnav train` writes a training run into a folder of its own (neither --overwrite "
        "nor --resume takes another command's folder): choose another --out"
    )
    owner = claiming_command(out)
    if owner is not None:
        raise RunFolderError(f"{out} holds the outputs of `{owner}` ({CLAIM_NAME}); {how}")
    others = sorted({p for pattern in OTHER_RUN_FILES for p in out.glob(pattern)})
    if others:
        names = ", ".join(p.name for p in others)
        raise RunFolderError(
            f"{out} holds the run of another command ({names}: a route-model run, "
            f"route_learning.py, formerly train-routes, or a study's flights); {how}"
        )


def finished_run(out: str | Path) -> dict[str, Any] | None:
    """``run.json`` of a finished run in ``out`` (its final model present), else None.

    ``run.json`` is written last, after the final model, so its presence means the run
    completed; an unreadable one counts as not finished.
    """
    path = Path(out) / "run.json"
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(info, dict) or not isinstance(info.get("num_timesteps"), int):
        return None
    final = info.get("final_model")
    if final:
        return info if (Path(out) / Path(final).name).exists() else None
    return info if any(Path(out).glob("final_model*")) else None


def recorded_config(out: str | Path) -> dict[str, Any] | None:
    """The settings a run in ``out`` was started with (its ``config.yaml``), or None.

    ``timesteps`` is the largest the run was asked for (sessions that trained it further
    record theirs in ``config_resumed_at_<N>.yaml``).

    Raises
    ------
    RunFolderError
        The file exists but is not a YAML mapping.
    """
    path = Path(out) / "config.yaml"
    if not path.is_file():
        return None
    data = parse_settings_yaml(path.read_text(), f"the run's settings {path}")
    if not isinstance(data, dict):
        raise RunFolderError(f"{path} does not hold the settings of a run (not a mapping)")
    # a run trained further (--resume --timesteps M) records M in config_resumed_at_*.yaml
    for extra in Path(out).glob("config_resumed_at_*.yaml"):
        try:
            more = parse_yaml(extra.read_text(), str(extra))
        except (OSError, ValueError):
            continue
        steps = more.get("timesteps") if isinstance(more, dict) else None
        if isinstance(steps, int) and steps > data.get("timesteps", 0):
            data["timesteps"] = steps
    return data


def check_same_environment(cfg: TrainConfig, saved: Path) -> None:
    """Refuse to resume in ``cfg.out`` with other environment settings than it was started.

    Raises
    ------
    ValueError
        ``saved`` (the run's ``config.yaml``) names another ``env_id`` or ``env``.
    """
    old = recorded_config(saved.parent) if saved.name == "config.yaml" else None
    if old is None:
        return
    if old.get("env_id") != cfg.env_id or (old.get("env") or {}) != cfg.env:
        raise ValueError(
            f"cannot resume in {cfg.out}: it was trained on {old.get('env_id')} with "
            f"{old.get('env') or {}}, not {cfg.env_id} with {cfg.env}; repeat the original "
            "settings, or use a new --out to fine-tune in another environment"
        )
    backend = old.get("backend", "sb3")
    if backend != cfg.backend:
        raise ValueError(
            f"cannot resume in {cfg.out} with --backend {cfg.backend}: the run there was "
            f"trained with --backend {backend}"
        )


def recorded_backend(out: str | Path) -> str | None:
    """The backend the run in ``out`` was trained with, or None (no run there).

    Read from its ``config.yaml``; without one, from its final model (``final_model.zip``:
    sb3, ``final_model.pt``: torchrl, a ``final_model`` folder: rllib).
    """
    out = Path(out)
    try:
        old = recorded_config(out)
    except ValueError:
        old = None
    if old is not None:
        return str(old.get("backend", "sb3"))
    if (out / "final_model.zip").is_file():
        return "sb3"
    if (out / "final_model.pt").is_file():
        return "torchrl"
    if (out / "final_model").is_dir():
        return "rllib"
    return None


# --------------------------------------------------------------------------------------------
# the learning curve
# --------------------------------------------------------------------------------------------


class ProgressLog:
    """``logs/progress.csv`` of a run: one row per iteration, every iteration once, in order.

    A fresh run starts an empty log. A resumed run (``resumed_at``: the agent-steps of the
    checkpoint it continues from) keeps the earlier sessions' rows up to that checkpoint
    and drops the rows after it (their iterations are trained again), so that the file
    holds one learning curve however often the run was interrupted and resumed. Every row
    rewrites the whole file atomically (:func:`atomic_write_text`): an interrupt or a full
    disk leaves the previous version, never a truncated one.

    Parameters
    ----------
    path : Path
        The CSV file (``OUT/logs/progress.csv``).
    step_key : str
        The column that counts agent-steps (``agent_steps``; SB3: ``time/total_timesteps``).
    resumed_at : int, optional
        None: a fresh run (any earlier file is replaced at the first row).
    columns : sequence of str, optional
        Columns in this order first (others follow in order of appearance).
    decimals : int, optional
        Round floats to this many decimals (None: written in full).
    """

    def __init__(
        self,
        path: str | Path,
        step_key: str,
        resumed_at: int | None = None,
        columns: Sequence[str] = (),
        decimals: int | None = None,
    ) -> None:
        import csv

        self.path = Path(path)
        self.step_key = step_key
        self.decimals = decimals
        self.columns: list[str] = list(columns)
        self.rows: list[dict[str, Any]] = []
        if resumed_at is not None and self.path.is_file():
            with self.path.open(newline="") as fh:
                reader = csv.DictReader(fh)
                for name in reader.fieldnames or []:
                    if name not in self.columns:
                        self.columns.append(name)
                for row in reader:
                    try:
                        step = float(row.get(step_key) or "nan")
                    except ValueError:
                        continue
                    if step <= resumed_at:  # NaN (a row without a step count) is dropped
                        self.rows.append(row)
            self._write()

    def append(self, row: dict[str, Any]) -> None:
        """Add one iteration's row and rewrite the file."""
        for key in row:
            if key not in self.columns:
                self.columns.append(key)
        self.rows.append(dict(row))
        self._write()

    def _write(self) -> None:
        import csv
        import io

        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=self.columns, extrasaction="ignore")
        w.writeheader()
        for r in self.rows:
            w.writerow({k: _csv_value(v, self.decimals) for k, v in r.items()})
        atomic_write_text(self.path, buf.getvalue())


def _csv_value(value: Any, decimals: int | None) -> Any:
    if hasattr(value, "item") and callable(value.item):  # a numpy scalar
        value = value.item()
    if isinstance(value, float) and decimals is not None:
        return round(value, decimals)
    return "" if value is None else value


# --------------------------------------------------------------------------------------------
# checkpoints
# --------------------------------------------------------------------------------------------


def checkpoint_candidates(
    folder: Path, glob: str, pattern: re.Pattern[str], final: tuple[int, Path] | None = None
) -> list[tuple[int, Path]]:
    """``(agent-steps, path)`` of the checkpoints in ``folder``, newest first.

    Entries matching ``glob`` whose name matches ``pattern`` (group 1: the step count), plus
    ``final`` (a finished run's final model and its step count) when given. Temporary files
    of an unfinished atomic write (hidden names) never match.
    """
    found = []
    for p in folder.glob(glob):
        m = pattern.search(p.name)
        if m and not p.name.startswith("."):
            found.append((int(m.group(1)), p))
    if final is not None:
        found.append(final)
    # newest first; at equal steps the final model before a checkpoint
    return sorted(found, key=lambda x: (x[0], x[1].name.startswith("final")), reverse=True)


def first_loadable(
    candidates: Sequence[tuple[int, Path]],
    load: Callable[[Path], Any],
    where: Path,
    kind: str = "",
) -> tuple[Path, Any]:
    """The newest candidate that ``load`` accepts, and what it returned.

    ``kind`` (e.g. ``"RLlib "``) qualifies "checkpoint" in the messages.

    Every newer candidate that fails to load is skipped with a warning on stderr that names
    it and says why (a truncated file, a corrupt ``policy.pth``, ...).

    Raises
    ------
    FileNotFoundError
        No candidate loads (the message lists the skipped ones).
    """
    skipped = []
    for _, path in candidates:
        try:
            return path, load(path)
        except Exception as exc:  # any failure to load means: not usable
            reason = f"{type(exc).__name__}: {exc}".strip().splitlines()[0][:200]
            skipped.append(f"{path} ({reason})")
            print(
                f"coopnav train: warning: skipping {kind}checkpoint {path}: it does not load "
                f"({reason})",
                file=sys.stderr,
            )
    extra = f"; skipped (they do not load): {', '.join(skipped)}" if skipped else ""
    raise FileNotFoundError(f"no {kind}checkpoint to resume from in {where}{extra}")


# --------------------------------------------------------------------------------------------
# opening a run folder
# --------------------------------------------------------------------------------------------


@dataclass
class RunState:
    """What :func:`open_run` found in the folder.

    Attributes
    ----------
    out : Path
    finished : dict or None
        ``run.json`` of a finished run in the folder (None: not finished, or a fresh run).
    """

    out: Path
    finished: dict[str, Any] | None = None

    def nothing_to_do(self, timesteps: int) -> bool:
        """Whether a resumed run is already finished with at least ``timesteps`` agent-steps
        (then it stays untouched and a message says so)."""
        return self.finished is not None and self.finished["num_timesteps"] >= timesteps

    def say_finished(self) -> None:
        """Tell the user that the finished run is left as it is, and how to train further."""
        n = self.finished["num_timesteps"] if self.finished else 0
        print(
            f"coopnav train: {self.out} holds a finished run ({n} agent-steps); nothing to do. "
            f"Train it further with --resume latest --timesteps M (M > {n}).",
            file=sys.stderr,
        )


@contextmanager
def _folder_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``out`` (see the module docstring)."""
    with folder_lock(out, holder_kind="another training run", error=RunFolderError):
        yield


def _describe(outputs: Sequence[Path], out: Path) -> str:
    done = finished_run(out)
    state = f"a finished run ({done['num_timesteps']} agent-steps)" if done else "a run"
    names = ", ".join(p.name for p in outputs[:4]) + (", ..." if len(outputs) > 4 else "")
    return f"{out} already holds {state} ({names})"


def _remove(paths: Sequence[Path]) -> None:
    for p in paths:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)


@contextmanager
def interrupts_raise() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` inside the block (main thread only).

    The previous handlers come back afterwards. Outside the main thread, where handlers
    can't be set, nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    install_interrupt_handlers()
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def install_interrupt_handlers() -> None:
    """Make SIGINT and SIGTERM raise :class:`Interrupted` (again: a library such as Ray may
    have installed its own). Main thread only; elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, _raise_interrupted)
    signal.signal(signal.SIGTERM, _raise_interrupted)


def _raise_interrupted(signum: int, frame: Any) -> None:
    raise Interrupted(signum)


_pending_signals: list[int] = []
"""Signals received inside :func:`interrupts_deferred` and not yet raised."""


def _defer_interrupt(signum: int, frame: Any) -> None:
    if _pending_signals:  # a second signal: stop at once
        raise Interrupted(signum)
    _pending_signals.append(int(signum))
    print(
        "\ncoopnav: interrupt received; stopping after the current step (again: at once)",
        file=sys.stderr,
        flush=True,
    )


def raise_if_interrupted() -> None:
    """Raise :class:`Interrupted` if SIGINT or SIGTERM arrived inside
    :func:`interrupts_deferred` (call it where stopping is safe: between steps)."""
    if _pending_signals:
        signum = _pending_signals.pop()
        _pending_signals.clear()
        raise Interrupted(signum)


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Inside the block, SIGINT and SIGTERM set a flag instead of raising.

    The code in the block calls :func:`raise_if_interrupted` between steps, which raises
    :class:`Interrupted` there; so an interrupt never lands inside a compiled (numba) call,
    where it ends in ``SystemError: CPUDispatcher(...)``, nor in a destructor, where Python
    ignores it. A second signal raises at once. A signal that comes after the block's last
    check (its work is done) is reported and dropped. Blocks nest (the outermost rules);
    outside the main thread nothing changes.
    """
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is _defer_interrupt  # nested: the outer block rules
    ):
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _pending_signals.clear()
    signal.signal(signal.SIGINT, _defer_interrupt)
    signal.signal(signal.SIGTERM, _defer_interrupt)
    try:
        yield
        if _pending_signals:  # it came after the last check: the work is done, nothing lost
            print("coopnav: the interrupt came as the work finished", file=sys.stderr)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _pending_signals.clear()


def sigterm_as_interrupt() -> Any:
    """Make SIGTERM raise :class:`Interrupted` (as Ctrl-C does); return the old handler.

    For a backend that manages its handlers itself; :func:`open_run` installs both SIGINT and
    SIGTERM handlers for the whole run. Returns None (and changes nothing) outside the main
    thread, where handlers can't be set.
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_interrupted)


@contextmanager
def open_run(cfg: TrainConfig) -> Iterator[RunState]:
    """Open ``cfg.out`` for a training run: check, lock, apply the fresh/overwrite/resume rules.

    Inside the block the folder is locked and SIGINT/SIGTERM raise :class:`Interrupted`.

    Raises
    ------
    RunFolderError
        ``cfg.out`` is a file or not writable, another run holds it, it holds a run and
        neither ``cfg.overwrite`` nor ``cfg.resume`` is set, ``cfg.resume`` asks to
        continue a run of another backend, or it belongs to another command (whatever
        ``cfg.overwrite`` and ``cfg.resume`` say).
    """
    out = Path(cfg.out)
    created = [p for p in (out, *out.parents) if not p.exists()]  # deepest first
    try:
        with interrupts_raise():
            ensure_folder(out)
            with _folder_lock(out):
                yield from _open_locked_run(cfg, out)
    except (ValueError, TypeError, LookupError, FileNotFoundError, ImportError):
        # refused (a usage error) with nothing left in the folders it created: remove them
        if created and out.is_dir() and {p.name for p in out.iterdir()} <= {LOCK_NAME}:
            (out / LOCK_NAME).unlink(missing_ok=True)
            for folder in created:
                try:
                    folder.rmdir()
                except OSError:
                    break
        raise


def _open_locked_run(cfg: TrainConfig, out: Path) -> Iterator[RunState]:
    """:func:`open_run` in the locked folder ``out``."""
    _refuse_another_command(out)
    outputs = run_outputs(out)
    if cfg.resume is not None:
        backend = recorded_backend(out)
        if backend is not None and backend != cfg.backend:
            raise RunFolderError(
                f"cannot resume {out} with --backend {cfg.backend}: the run there was "
                f"trained with --backend {backend}; resume it with --backend {backend}, "
                "or choose another --out"
            )
    if cfg.resume is None and outputs:
        if not cfg.overwrite:
            raise RunFolderError(
                f"{_describe(outputs, out)}; continue it with --resume latest, replace "
                "it with --overwrite, or choose another --out"
            )
        _remove(outputs)
        print(
            f"coopnav train: --overwrite: removed the earlier run's outputs in {out}",
            file=sys.stderr,
        )
    yield RunState(out, finished_run(out) if cfg.resume is not None else None)
