"""Every script in examples/ runs, with short settings, in a fresh process."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

# script -> (short arguments, text its output must contain)
CASES = {
    "own_loop.py": (
        ["--episodes", "2", "--max-steps", "15"],
        ["episode 1: ", "mean 3-D navigation error"],
    ),
    "gymnasium_single_agent.py": (
        ["--episodes", "2", "--max-steps", "15"],
        ["observation (156,), action (9,)", "episode 1: 15 steps (truncated)"],
    ),
    "sb3_ppo.py": (
        ["--timesteps", "256", "--n-steps", "128", "--max-steps", "20", "--save", "{tmp}/m.zip"],
        ["trained 256 steps", "evaluation episode:", "saved "],
    ),
    # 32 steps x 2 swarms x 3 UAVs = 192 agent-steps per rollout: 2 rollouts; 10-step episodes
    "sb3_vec_env.py": (
        ["--timesteps", "200", "--n-steps", "32", "--max-steps", "10", "--save", "{tmp}/v.zip"],
        ["trained 384 agent-steps (6 slots)", "(TimeLimit.truncated)", "evaluation episode:"],
    ),
    "fly_file_city.py": (
        ["--max-steps", "15", "--out", "{tmp}/frames"],
        ["column episode 0 (335 buildings): 15 steps", "frame written to"],
    ),
    "evaluate_own_policy.py": (
        ["--episodes", "1", "--max-steps", "15", "--out", "{tmp}/eval"],
        ["| column |", "| wall_shy |", "| wall_shy@altitude_m=15 |"],
    ),
}


def test_every_example_is_tested() -> None:
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == sorted(CASES)


@pytest.mark.parametrize("script", sorted(CASES))
def test_example_runs(script: str, tmp_path: Path) -> None:
    args, expected = CASES[script]
    args = [a.format(tmp=tmp_path) for a in args]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["MPLBACKEND"] = "Agg"
    res = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env=env,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    for text in expected:
        assert text in res.stdout, (text, res.stdout)
    if script == "sb3_ppo.py":
        assert (tmp_path / "m.zip").stat().st_size > 0
        assert not list(tmp_path.glob(".*tmp*"))  # the temporary name was renamed into place
    if script == "sb3_vec_env.py":
        import re

        ended, truncated = map(int, re.search(r"ended: (\d+), (\d+) of them", res.stdout).groups())
        # 64 steps of each swarm, at most 10 per episode: at least 6 episodes of each of the
        # 2 swarms end; with seed 0 the untrained policy crashed in 15 of 21 and the time
        # limit ended 6 (the run is deterministic; at least one must carry the flag)
        assert ended >= 12 and truncated >= 1, res.stdout
        assert (tmp_path / "v.zip").stat().st_size > 0
    if script == "evaluate_own_policy.py":
        assert (tmp_path / "eval" / "report.md").exists()
        assert (tmp_path / "eval" / "trajectories_wall_shy.png").exists()


def test_examples_print_their_help() -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for script in sorted(CASES):
        res = subprocess.run(
            [sys.executable, str(EXAMPLES / script), "--help"],
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        assert res.returncode == 0 and "(default: " in res.stdout, res.stderr
