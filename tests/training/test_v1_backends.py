"""Every training backend on ``urban_canyon_v1`` with its packaged section: a smoke run each.

Each run is tiny (3 UAVs, 20-step episodes, one short iteration): it checks that the v1
section trains undiscounted, with the v1 reward, team credit and the agent index, without a
heuristic inside the policy, and that ``coopnav evaluate`` flies the result in the run's own
environment. The studies' full runs are in ``studies/task_objective``.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest
import yaml

from coopnav_env.envs.config import V1_DEFAULTS
from coopnav_env.training.cli import main
from tests.training.ray_cli import isolated_ray_env, run_coopnav

SMALL = [
    "--env-id", "urban_canyon_v1", "--env-set", "n_uavs=3", "--env-set", "max_steps=20",
    "--seed", "3", "--no-progress",
]  # fmt: skip
V1_TRAINING_ENV = {"nav_team_weight": 1.0, "obs_agent_index": True}


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _check_run_config(out: Path) -> dict:
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    assert cfg["env_id"] == "urban_canyon_v1"
    for key, value in V1_TRAINING_ENV.items():
        assert cfg["env"][key] == value, key
    for key, value in V1_DEFAULTS.items():  # the env id implies them; written out or not
        assert cfg["env"].get(key, value) == value, key
    return cfg


def _evaluate(policy: str, out: Path) -> dict:
    assert main(["evaluate", "--policies", policy, "--episodes", "1", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["env_id"] == "urban_canyon_v1"
    assert report["env_kwargs"]["obs_agent_index"] is True  # the run's own environment
    return report


def test_sb3_trains_on_v1_and_evaluates(tmp_path) -> None:
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "sb3"
    args = ["train", "--out", str(out), "--timesteps", "48", *SMALL]
    args += ["--set", "n_envs=1", "--set", "ppo.n_steps=16", "--set", "ppo.batch_size=16"]
    args += ["--set", "pretrain.episodes=1", "--set", "pretrain.epochs=1"]
    assert main(args) == 0
    cfg = _check_run_config(out)
    assert cfg["ppo"]["gamma"] == 1.0
    assert json.loads((out / "pretrain.json").read_text())["teacher"] == "waypoint"
    _evaluate(f"ppo:{out / 'final_model.zip'}", tmp_path / "eval")


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_torchrl_trains_on_v1_from_the_policy_alone_and_evaluates(tmp_path, algorithm) -> None:
    pytest.importorskip("torchrl")
    out = tmp_path / algorithm
    args = ["train", "--out", str(out), "--backend", "torchrl", "--algorithm", algorithm]
    args += ["--timesteps", "24", *SMALL, "--set", "torchrl.n_copies=2"]
    args += ["--set", "torchrl.rollout_steps=4", "--set", "torchrl.hidden=[16,16]"]
    args += ["--set", "torchrl.epochs=1", "--set", "torchrl.pretrain.episodes=2"]
    args += ["--set", "torchrl.pretrain.epochs=1"]
    assert main(args) == 0
    _check_run_config(out)
    run = json.loads((out / "run.json").read_text())
    assert run["algorithm"] == algorithm
    assert run["settings"]["gamma"] == 1.0 and run["settings"]["residual_base"] is None
    assert run["warm_start"]["teacher"] == "waypoint"
    _evaluate(f"{algorithm}:{out}", tmp_path / "eval")


def test_torchrl_trains_in_the_route_frame_and_evaluates_in_it(tmp_path, capsys) -> None:
    """The route-frame configuration of the study: set-point actions, from scratch or warm
    started from fixed set-points; the waypoint teacher, which commands velocities, is
    refused with a message naming the frame."""
    pytest.importorskip("torchrl")
    base = ["train", "--backend", "torchrl", "--algorithm", "mappo", "--timesteps", "24"]
    base += [*SMALL, "--set", "torchrl.n_copies=2", "--set", "torchrl.rollout_steps=4"]
    base += ["--set", "torchrl.hidden=[16,16]", "--set", "torchrl.epochs=1"]
    base += ["--set", "env.action_frame=route", "--set", "torchrl.gae_lambda=1.0"]
    assert main([*base, "--out", str(tmp_path / "refused")]) == 2
    assert "need action_frame='velocity', got action_frame='route'" in capsys.readouterr().err
    out = tmp_path / "route"
    warm = ["--set", "torchrl.pretrain.policy=setpoints", "--set", "torchrl.pretrain.episodes=2"]
    warm += ["--set", "torchrl.pretrain.epochs=1"]
    warm += ["--set", "torchrl.pretrain.policy_kwargs={speed_mps: 7, altitude_m: 28}"]
    assert main([*base, *warm, "--out", str(out)]) == 0
    assert _check_run_config(out)["env"]["action_frame"] == "route"
    run = json.loads((out / "run.json").read_text())
    assert run["warm_start"]["teacher"] == "setpoints"
    report = _evaluate(f"mappo:{out}", tmp_path / "eval")
    assert report["env_kwargs"]["action_frame"] == "route"


@pytest.mark.slow
def test_rllib_trains_on_v1(tmp_path) -> None:
    pytest.importorskip("ray.rllib")
    out = tmp_path / "rl"
    args = ["train", "--backend", "rllib", "--out", str(out), "--num-env-runners", "0"]
    args += ["--timesteps", "192", *SMALL]
    args += ["--set", "rllib.ppo.train_batch_size_per_learner=64"]
    args += ["--set", "rllib.ppo.minibatch_size=64", "--set", "rllib.ppo.num_epochs=1"]
    args += ["--set", "rllib.model.fcnet_hiddens=[16, 16]"]
    run_coopnav(args, isolated_ray_env(tmp_path))
    cfg = _check_run_config(out)
    assert cfg["rllib"]["ppo"]["gamma"] == 1.0
    assert json.loads((out / "run.json").read_text())["backend"] == "rllib"
