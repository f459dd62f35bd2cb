"""average_checkpoints.py: the exported actor is the mean of the run's late checkpoints."""

from __future__ import annotations

import pytest
import torch

from coopnav_env.agents.marl_policy import load_checked_checkpoint
from studies.task_objective import average_checkpoints as ac
from studies.task_objective.compare_learned import fly
from studies.task_objective.tests.test_select_checkpoint import SEEDS, shipped_actors_run


def test_the_exported_actor_is_the_mean_of_the_checkpoints_from_the_step_count_on(tmp_path):
    run = shipped_actors_run(tmp_path)  # checkpoints at 50, 100, 300 agent-steps, final at 400
    assert ac.main(["--runs", str(run), "--from-steps", "100", "--export", str(tmp_path)]) == 0
    dest = tmp_path / "run_avg"
    got = load_checked_checkpoint(dest / "final_model.pt", "fly")
    parts = [
        load_checked_checkpoint(run / "checkpoints" / f"marl_{s}_steps.pt", "fly")["actor"]
        for s in (100, 300)
    ] + [load_checked_checkpoint(run / "final_model.pt", "fly")["actor"]]
    for name, value in got["actor"].items():
        mean = sum(p[name].double() for p in parts) / 3
        assert value.dtype == parts[0][name].dtype
        assert torch.allclose(value.double(), mean, rtol=0, atol=1e-6), name
    # the settings are the final model's, and the average flies as a policy
    final = load_checked_checkpoint(run / "final_model.pt", "fly")
    assert got["settings"] == final["settings"] and got["env_kwargs"] == final["env_kwargs"]
    assert (dest / "config.yaml").is_file()
    (flown,) = fly(f"mappo:{dest}", [SEEDS[0]])
    assert set(flown) >= {"score", "goal"}
    # an existing policy folder is not replaced without --overwrite
    with pytest.raises(SystemExit):
        ac.main(["--runs", str(run), "--from-steps", "100", "--export", str(tmp_path)])


def test_actors_of_different_networks_are_not_averaged(tmp_path):
    run = shipped_actors_run(tmp_path)
    other = run / "checkpoints" / "marl_200_steps.pt"
    d = load_checked_checkpoint(run / "checkpoints" / "marl_100_steps.pt", "fly")
    name = next(iter(d["actor"]))
    d["actor"][name] = torch.zeros(7, 7)
    torch.save(d, other)
    with pytest.raises(ValueError, match="differ"):
        ac.averaged_actor([run / "checkpoints" / "marl_100_steps.pt", other])
