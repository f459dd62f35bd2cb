"""Run folders: what every training backend writes, and how it finds it again.

One home for the rules that keep a run's work safe, whatever the backend:

* **Atomic writes.** Every file (and checkpoint folder) goes to a temporary name in the same
  folder and is renamed into place (:func:`atomic_write_text`, :func:`atomic_path`), so a
  crash, a kill or a full disk leaves the previous version, never a truncated one.
* **Checkpoint discovery.** :func:`latest_numbered` finds the newest ``<prefix>_<N>_steps``
  entry of a folder.
* **Same environment on resume.** :func:`check_same_environment` refuses to continue a run
  with other environment settings than it was started with.
* **Signals.** :func:`sigterm_as_interrupt` makes SIGTERM (a scheduler stopping a job) behave
  like Ctrl-C, so that a backend writes its checkpoint for both.
"""

from __future__ import annotations

import json
import os
import re
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from training.config import TrainConfig

__all__ = [
    "atomic_path",
    "atomic_write_text",
    "check_same_environment",
    "latest_numbered",
    "sigterm_as_interrupt",
    "write_json",
    "write_yaml",
]


# --------------------------------------------------------------------------------------------
# atomic writes
# --------------------------------------------------------------------------------------------


@contextmanager
def atomic_path(path: str | Path, *, suffix: str = "") -> Iterator[Path]:
    """A temporary path next to ``path``; on success it is renamed onto ``path``.

    Write the file (or fill the folder) at the yielded path; when the ``with`` block ends
    without an exception, it replaces ``path`` in one ``os.replace`` (a folder: the old one is
    moved aside first and removed after). On an exception the temporary is removed and
    ``path`` is left as it was. ``suffix`` is appended to the temporary name (libraries that
    add an extension themselves, e.g. ``.zip``, need it).
    """
    import shutil

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
        else:
            os.replace(tmp, path)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file in the same folder (see
    :func:`atomic_path`); returns ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp:
        with tmp.open("w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    return path


def write_yaml(path: str | Path, data: Any) -> Path:
    """Write ``data`` as YAML (keys in insertion order), atomically."""
    import yaml

    return atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON with a final newline, atomically."""
    return atomic_write_text(path, json.dumps(data, indent=2) + "\n")


# --------------------------------------------------------------------------------------------
# checkpoints
# --------------------------------------------------------------------------------------------


def latest_numbered(
    folder: Path,
    glob: str,
    pattern: re.Pattern[str],
    kind: str,
    valid: Callable[[Path], bool] | None = None,
) -> Path:
    """The entry of ``folder`` matching ``glob`` whose ``pattern`` group 1 is largest.

    ``valid`` (optional) filters candidates; ``kind`` names them in the error message.

    Raises
    ------
    FileNotFoundError
        There is none.
    """
    found = []
    for p in folder.glob(glob):
        m = pattern.search(p.name)
        if m and (valid is None or valid(p)):
            found.append((int(m.group(1)), p))
    if not found:
        raise FileNotFoundError(f"no {kind}checkpoint to resume from in {folder}")
    return max(found)[1]


def check_same_environment(cfg: TrainConfig, saved: Path) -> None:
    """Refuse to resume in ``cfg.out`` with other environment settings than it was started.

    Raises
    ------
    ValueError
        ``saved`` (the run's ``config.yaml``) names another ``env_id`` or ``env``.
    """
    import yaml

    if not saved.is_file():
        return
    old = yaml.safe_load(saved.read_text()) or {}
    if old.get("env_id") != cfg.env_id or (old.get("env") or {}) != cfg.env:
        raise ValueError(
            f"cannot resume in {cfg.out}: it was trained on {old.get('env_id')} with "
            f"{old.get('env') or {}}, not {cfg.env_id} with {cfg.env}; repeat the original "
            "settings, or use a new --out to fine-tune in another environment"
        )


# --------------------------------------------------------------------------------------------
# signals
# --------------------------------------------------------------------------------------------


def sigterm_as_interrupt() -> Any:
    """Make SIGTERM (a scheduler stopping the job) behave like Ctrl-C; return the old handler.

    Returns None (and changes nothing) outside the main thread, where handlers can't be set.
    """
    if threading.current_thread() is not threading.main_thread():
        return None

    def _raise(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    return signal.signal(signal.SIGTERM, _raise)
