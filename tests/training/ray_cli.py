"""Running ``coopnav`` as a subprocess that starts a local Ray of its own (the RLlib tests)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def isolated_ray_env(tmp_path: Path) -> dict[str, str]:
    """The environment of a subprocess whose Ray keeps to ``tmp_path``: ``HOME`` and ``TMPDIR``
    under it, no usage statistics, and no cluster address or token taken from the caller."""
    home, tmp = tmp_path / "home", tmp_path / "tmp"
    home.mkdir()
    tmp.mkdir()
    env = {**os.environ, "HOME": str(home), "TMPDIR": str(tmp), "RAY_USAGE_STATS_ENABLED": "0"}
    for key in ("RAY_ADDRESS", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_AUTH_MODE"):
        env.pop(key, None)
    return env


def run_coopnav(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    """``coopnav ARGS`` from the repository root in ``env``; asserts that it exits 0, showing
    its output when it does not."""
    proc = subprocess.run(
        [sys.executable, "-m", "coopnav_env.training.cli", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=400,
    )
    assert proc.returncode == 0, f"coopnav {' '.join(args)}\n{proc.stdout}\n{proc.stderr}"
    return proc
