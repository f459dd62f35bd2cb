"""select_checkpoint.py: every checkpoint from a step count on is flown; the best is kept."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from coopnav_env.agents.marl_policy import PRETRAINED_DIR
from studies.task_objective import select_checkpoint as sc
from studies.task_objective.compare_learned import fly

SEEDS = [sc.VALIDATION_SEED_START, sc.VALIDATION_SEED_START + 1]


def shipped_actors_run(tmp_path, name="run"):
    """A run folder whose checkpoints are two shipped route-frame actors and an early one."""
    run = tmp_path / name
    (run / "checkpoints").mkdir(parents=True)
    src = {100: "mappo_route_scratch_s0", 300: "mappo_route_s0", 50: "mappo_route_s1"}
    for steps, policy in src.items():
        shutil.copyfile(
            PRETRAINED_DIR / policy / "final_model.pt",
            run / "checkpoints" / f"marl_{steps}_steps.pt",
        )
    shutil.copyfile(PRETRAINED_DIR / "mappo_route_s0" / "config.yaml", run / "config.yaml")
    final = PRETRAINED_DIR / "mappo_route_scratch_s1" / "final_model.pt"
    shutil.copyfile(final, run / "final_model.pt")
    (run / "run.json").write_text(json.dumps({"num_timesteps": 400}))
    return run


def test_candidates_start_at_from_steps_and_end_with_the_final_model(tmp_path) -> None:
    run = shipped_actors_run(tmp_path)
    got = sc.candidates(run, from_steps=100)
    assert [s for s, _ in got] == [100, 300, 400]
    assert got[-1][1].name == "final_model.pt"
    with pytest.raises(FileNotFoundError, match="no checkpoint at or after 500"):
        sc.candidates(run, from_steps=500)


def test_the_kept_checkpoint_has_the_highest_validation_score(tmp_path) -> None:
    run = shipped_actors_run(tmp_path)
    out, export = tmp_path / "sel", tmp_path / "policies"
    args = ["--runs", str(run), "--from-steps", "100", "--episodes", "2"]
    assert sc.main([*args, "--out", str(out), "--export", str(export)]) == 0
    report = json.loads((out / "report.json").read_text())
    (r,) = report["runs"]
    assert [c["steps"] for c in r["candidates"]] == [100, 300, 400]
    for c in r["candidates"]:  # each score is the mean v1 return on the validation episodes
        ref = np.mean([e["score"] for e in fly(f"mappo:{c['checkpoint']}", SEEDS)])
        assert c["score"] == pytest.approx(ref, abs=1e-12)
    assert r["chosen"]["score"] == max(c["score"] for c in r["candidates"])
    assert (export / "run" / "final_model.pt").is_file()
    assert (export / "run" / "config.yaml").is_file()
    # a second selection into the same folders is refused without --overwrite
    with pytest.raises(SystemExit):
        sc.main([*args, "--out", str(tmp_path / "sel2"), "--export", str(export)])
