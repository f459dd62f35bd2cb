"""Atomic file writes: every file a command writes appears complete or not at all.

A file (or a folder, such as an RLlib checkpoint) is written under a temporary name in the
same folder and renamed onto its final name in one ``os.replace`` when it is complete. A
crash, a kill (even SIGKILL), a full disk or a file-size limit therefore leaves the previous
version of the file in place, never a truncated one; the temporary is removed when the write
fails with an exception (a killed process can leave a hidden ``.NAME.*.tmp*`` behind, never a
damaged ``NAME``).

Used by ``coopnav train`` (checkpoints, models, ``run.json``, ``config.yaml``), ``coopnav
evaluate`` (reports, plots) and ``coopnav reproduce`` (results, report, figures).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = [
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "claim_run_folder",
    "ensure_folder",
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
