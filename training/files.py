"""Atomic file writes: every file a command writes appears complete or not at all.

A file (or a folder, such as an RLlib checkpoint) is written under a temporary name in the
same folder and renamed onto its final name in one ``os.replace`` when it is complete. A
crash, a kill (even SIGKILL), a full disk or a file-size limit therefore leaves the previous
version of the file in place, never a truncated one; the temporary is removed when the write
fails with an exception (a killed process can leave a hidden ``.NAME.*.tmp*`` behind, never a
damaged ``NAME``).

Used by ``coopnav train`` (checkpoints, models, ``run.json``, ``config.yaml``), ``coopnav
evaluate`` (reports, plots) and ``coopnav reproduce`` (results, report, figures).

An output folder belongs to one command: :func:`claim_output_folder` (``coopnav evaluate``,
a study's report script) locks it, refuses another command's folder or a training run, and records
the command and its settings in ``command.json`` before any work starts.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = [
    "CLAIM_NAME",
    "LOCK_NAME",
    "OutputClaim",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "claim_output_folder",
    "claim_run_folder",
    "ensure_folder",
    "folder_lock",
    "jsonable",
    "write_json",
    "write_yaml",
]


def ensure_folder(path: str | Path) -> Path:
    """Create the output folder ``path`` if needed and check that files can be written in it.

    Raises
    ------
    ValueError
        ``path`` is a file, cannot be created, or is not writable (the message names it).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"--out {path} is a file, not a folder; choose a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot create the output folder {path}: {exc.strerror}") from exc
    if not os.access(path, os.W_OK | os.X_OK):
        raise ValueError(f"the output folder {path} is not writable; choose another --out")
    return path


@contextmanager
def atomic_path(path: str | Path, *, suffix: str = "") -> Iterator[Path]:
    """A temporary path next to ``path``; renamed onto ``path`` when the block succeeds.

    Write the file (or fill the folder) at the yielded path. When the ``with`` block ends
    without an exception it replaces ``path`` (a folder: the old one is moved aside, the new
    one renamed into place, the old one removed). On an exception the temporary is removed
    and ``path`` is left as it was.

    Parameters
    ----------
    path : path
        The final name. Its folder is created if needed.
    suffix : str
        Appended to the temporary name, for writers that pick the format from the extension
        or add one themselves (``".zip"`` for Stable-Baselines3, ``".png"`` for matplotlib).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=f".tmp{suffix}", dir=path.parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    tmp.unlink()  # the writer creates it (a file or a folder)
    try:
        yield tmp
        if tmp.is_dir():
            old = None
            if path.exists():
                old = path.with_name(f".{path.name}.old-{os.getpid()}")
                if old.exists():
                    shutil.rmtree(old)
                os.replace(path, old)
            os.replace(tmp, path)
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        elif tmp.exists():
            os.replace(tmp, path)
        else:
            raise FileNotFoundError(f"nothing was written for {path}")
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (flushed to disk before the rename)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        with tmp.open("wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def write_yaml(path: str | Path, data: Any) -> Path:
    """Write ``data`` as YAML (keys in insertion order), atomically."""
    import yaml

    return atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as JSON indented by 2 with a final newline, atomically."""
    return atomic_write_text(path, json.dumps(data, indent=2) + "\n")


def jsonable(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays, paths and tuples turned into JSON types;
    non-finite floats become None (JSON has no NaN or inf)."""
    import datetime
    import math

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(float(obj)) else None
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, datetime.date):  # YAML reads an unquoted ISO time as a datetime
        return obj.isoformat()
    return obj


def claim_run_folder(out: str | Path, settings: Any, data_name: str = "episodes.npz") -> bool:
    """Make ``out`` the folder of the run with these ``settings``, or find that it is.

    The data-collection benchmarks keep their flights (``data_name``) and a ``settings.json``
    in ``--out`` and reuse the flights when run again with the same settings (to price them
    anew, e.g. with another ``--compare``). A folder belongs to one run: ``out`` holding the
    ``settings.json`` of *other* settings, or files without a ``settings.json``, is refused
    with a :class:`ValueError` that names it, so that no earlier run's flights are ever
    overwritten. Otherwise the folder is created, ``settings.json`` written (atomically) if it
    is not there, and the return value says whether ``data_name`` is there to reuse.
    """
    out = Path(out)
    sfile = out / "settings.json"
    wanted = json.loads(json.dumps(settings))
    if sfile.is_file():
        old = json.loads(sfile.read_text())
        if old != wanted:
            raise ValueError(
                f"{out} belongs to a run with other settings ({old}), not {wanted}; use "
                "another --out"
            )
        return (out / data_name).is_file()
    if out.is_dir() and any(p for p in out.iterdir() if not p.name.startswith(".")):
        raise ValueError(f"--out {out} exists and holds files of no run of this command")
    ensure_folder(out)
    atomic_write_text(sfile, json.dumps(wanted, indent=1) + "\n")
    return False


# --------------------------------------------------------------------------------------------
# an output folder belongs to one command
# --------------------------------------------------------------------------------------------

LOCK_NAME: str = ".coopnav.lock"
"""The lock file of an output folder: the one ``coopnav train`` locks
(:data:`coopnav_env.training.runs.LOCK_NAME`), so that no two commands write one folder."""

CLAIM_NAME: str = "command.json"
"""The record of the command that owns an output folder (:func:`claim_output_folder`)."""

TRAINING_RUN_FILES: tuple[str, ...] = (
    "config.yaml",
    "run.json",
    "final_model*",
    "checkpoints",
    "route_model.json",
    "split_model.json",
    "episodes.npz",
    "settings.json",
)
"""Glob patterns that mark a folder as a training run (``coopnav train``, a route-model run,
a split chooser, a benchmark's flights): a report command never writes into one."""


@contextmanager
def folder_lock(
    out: str | Path,
    *,
    holder_kind: str = "another coopnav command",
    error: type[ValueError] = ValueError,
) -> Iterator[None]:
    """Hold an exclusive lock on the folder ``out`` (``fcntl.flock`` on ``out/.coopnav.lock``).

    A second command into the same folder fails at once with ``error`` (a :class:`ValueError`)
    naming the process that holds it, as ``holder_kind``; the operating system releases the
    lock when the process ends, however it ends. Not POSIX: no lock.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no locking
        yield
        return
    path = Path(out) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise error(f"cannot create the lock file {path}: {exc.strerror}") from exc
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            raise error(
                f"{out} is in use by {holder_kind} ({holder}); wait for it to end, or choose "
                "another --out"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}\n".encode(), 0)
        try:
            yield
        finally:
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


class OutputClaim:
    """The claim of an output folder by one command (see :func:`claim_output_folder`)."""

    def __init__(
        self,
        out: Path,
        command: str,
        settings: Any,
        patterns: Sequence[str],
        replacing: Iterable[str] = (),
    ):
        self.out = out
        self.command = command
        self.settings = settings
        self.patterns = list(patterns)
        self.replacing = sorted(set(replacing))

    def _write(self, status: str, outputs: Sequence[str]) -> None:
        record = {
            "command": self.command,
            "settings": self.settings,
            "status": status,
            "outputs": list(outputs),
            "patterns": self.patterns,  # what it may have written, should it be interrupted
        }
        if status != "finished" and self.replacing:
            record["replacing"] = self.replacing  # earlier outputs, removed at the end
        write_json(self.out / CLAIM_NAME, record)

    def finish(self, files: Iterable[str | Path]) -> None:
        """Record that the command finished and wrote ``files`` (paths in the folder); the
        earlier outputs it replaces (``--overwrite``) and did not rewrite are removed now."""
        names = sorted({Path(f).name for f in files})
        _remove_entries(self.out / n for n in self.replacing if n not in names)
        self._write("finished", names)


def _names(paths: Sequence[Path]) -> str:
    shown = ", ".join(p.name for p in paths[:4])
    return shown + (", ..." if len(paths) > 4 else "")


def _remove_entries(paths: Iterable[Path]) -> None:
    for p in paths:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)


def _read_claim(path: Path) -> dict[str, Any]:
    try:
        record = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON ({exc}); choose another --out") from exc
    if not isinstance(record, dict) or not isinstance(record.get("command"), str):
        raise ValueError(
            f"{path} is not the record of a coopnav command (a JSON object with a 'command'); "
            "choose another --out"
        )
    return record


@contextmanager
def claim_output_folder(
    out: str | Path,
    command: str,
    settings: Any,
    *,
    outputs: Sequence[str],
    overwrite: bool = False,
) -> Iterator[OutputClaim]:
    """Make ``out`` the output folder of ``command`` run with ``settings``, before any work.

    The folder is created if needed and locked (:func:`folder_lock`) for the whole block;
    ``command.json`` records the command, its settings, and, once
    :meth:`OutputClaim.finish` is called, ``status: finished`` and the files it wrote. The
    rules (a :class:`ValueError` names the folder and what it holds):

    * an empty folder, or one holding only the claim of the same command with the same
      settings that did not finish (an interrupted run), is taken;
    * a folder claimed by another command, by the same command with other settings, or
      holding the finished result of this very command and settings (a rerun could lose
      it: the code may have changed since) is refused; ``overwrite`` takes it and replaces
      the outputs the claim records (the files it wrote and its file patterns);
    * a folder of files without a claim (e.g. the report of an older version) is refused;
      ``overwrite`` takes it and replaces the entries matching ``outputs`` (this command's
      own file patterns), leaving the other files alone;
    * a training run (:data:`TRAINING_RUN_FILES`) is refused even with ``overwrite``: a
      report never replaces a trained model.

    Replaced outputs stay until the command finishes (each new file replaces its namesake
    atomically, and :meth:`OutputClaim.finish` removes the rest), so a command that fails
    or is interrupted leaves the earlier versions in place; its claim (``status:
    running``) lets the same command with the same settings take the folder again. A command
    refused inside the block (a :data:`REFUSALS` error) before it wrote anything leaves the
    folder as it found it: the earlier claim back (or none), the folders it created removed.

    Parameters
    ----------
    out : path
        The ``--out`` folder.
    command : str
        The command, e.g. ``"coopnav evaluate"``.
    settings : JSON-able
        What determines the command's result (compared with a claim's record).
    outputs : sequence of str
        Glob patterns of the files the command writes.
    overwrite : bool
        The command's ``--overwrite``.
    """
    out = Path(out)
    created = [p for p in (out, *out.parents) if not p.exists()]  # deepest first
    out = ensure_folder(out)
    wanted = json.loads(json.dumps(jsonable(settings)))
    lock_found = (out / LOCK_NAME).exists()
    untouched = True  # nothing written into out but the claim
    try:
        with folder_lock(out):
            found = _entries_state(out)
            with _claim_locked(out, command, wanted, outputs, overwrite) as claim:
                try:
                    yield claim
                except REFUSALS:
                    untouched = _entries_state(out, skip=(CLAIM_NAME,)) == {
                        k: v for k, v in found.items() if k != CLAIM_NAME
                    }
                    if untouched:  # refused before writing anything: the old claim back
                        _restore_claim(out, found.get(CLAIM_NAME))
                    raise
    except REFUSALS:
        if untouched and not lock_found:
            (out / LOCK_NAME).unlink(missing_ok=True)
        if untouched:  # the folders ensure_folder created, empty again
            for folder in created:
                try:
                    folder.rmdir()
                except OSError:
                    break
        raise


REFUSALS: tuple[type[BaseException], ...] = (
    ValueError,
    TypeError,
    LookupError,
    FileNotFoundError,
    ImportError,
)
"""Errors that refuse a command's settings (usage errors): raised inside
:func:`claim_output_folder` before anything is written, they leave ``--out`` as it was."""


def _entries_state(out: Path, skip: Sequence[str] = ()) -> dict[str, Any]:
    """Name -> (size, mtime, the bytes of the claim) of ``out``'s entries (not the lock)."""
    state: dict[str, Any] = {}
    for p in out.iterdir():
        if p.name == LOCK_NAME or p.name in skip:
            continue
        st = p.lstat()
        state[p.name] = (st.st_size, st.st_mtime_ns)
        if p.name == CLAIM_NAME and p.is_file():
            state[p.name] = p.read_bytes()
    return state


def _restore_claim(out: Path, old: Any) -> None:
    if isinstance(old, bytes):
        atomic_write_text(out / CLAIM_NAME, old.decode())
    else:
        (out / CLAIM_NAME).unlink(missing_ok=True)


@contextmanager
def _claim_locked(
    out: Path, command: str, wanted: Any, outputs: Sequence[str], overwrite: bool
) -> Iterator[OutputClaim]:
    """:func:`claim_output_folder` in the locked folder ``out``."""
    entries = sorted(p for p in out.iterdir() if not p.name.startswith("."))
    training = sorted({p for pat in TRAINING_RUN_FILES for p in out.glob(pat)})
    if training:
        raise ValueError(
            f"{out} holds a training run ({_names(training)}); `{command}` writes into a "
            "folder of its own (--overwrite never removes a training run): choose another "
            "--out"
        )
    claim_path = out / CLAIM_NAME
    how = "choose another --out, or replace them with --overwrite"
    replacing: set[str] = set()
    if claim_path.is_file():
        record = _read_claim(claim_path)
        owner = record["command"]
        if owner != command:
            problem = f"{out} holds the outputs of `{owner}` ({CLAIM_NAME})"
        elif record.get("settings") != wanted:
            old = record.get("settings")
            keys = sorted(
                k
                for k in set(old or {}) | set(wanted or {})
                if not isinstance(old, dict)
                or not isinstance(wanted, dict)
                or old.get(k) != wanted.get(k)
            )
            problem = f"{out} holds a `{command}` result of other settings ({', '.join(keys)})"
        elif record.get("status") == "finished":
            problem = (
                f"{out} holds the finished result of `{command}` with these settings "
                "(a rerun could change it)"
            )
        else:
            problem = None  # the same command, interrupted: take it again
        # what the claim's command wrote or may have written (before an interrupt), and
        # what it was itself replacing
        replacing = {str(n) for n in record.get("replacing") or []}
        if problem is not None:
            if not overwrite:
                raise ValueError(f"{problem}; {how}")
            replacing |= {str(n) for n in record.get("outputs") or []}
            patterns = [str(g) for g in record.get("patterns") or []]
            replacing |= {p.name for pat in patterns for p in out.glob(pat)}
            print(
                f"{command}: --overwrite: replacing {owner}'s outputs in {out}",
                file=sys.stderr,
            )
    elif entries:
        if not overwrite:
            raise ValueError(
                f"{out} already holds files of no `{command}` run ({_names(entries)}); {how}"
            )
        replacing = {p.name for pat in outputs for p in out.glob(pat)}
        print(f"{command}: --overwrite: replacing the earlier outputs in {out}", file=sys.stderr)
    # names only: nothing outside the folder is ever removed
    replacing = {n for n in replacing if n and "/" not in n and n not in (".", "..")}
    claim = OutputClaim(out, command, wanted, outputs, replacing - {CLAIM_NAME})
    claim._write("running", [])
    yield claim
