"""The BenchMARL task of ``coopnav_env.training.benchmarl_backend``.

BenchMARL lives in a venv of its own (the ``benchmarl`` extra: it pins ``torchrl<0.12``), so
the tests that need it skip where it is not installed (``pytest.importorskip("benchmarl")``),
as in the project's usual venv. The last test runs everywhere: without BenchMARL, importing the
module raises an ImportError that names the ``benchmarl`` extra.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys

import pytest

MODULE = "coopnav_env.training.benchmarl_backend"
HAS_BENCHMARL = importlib.util.find_spec("benchmarl") is not None
SMALL = {"n_uavs": 3, "max_steps": 10, "nav_team_weight": 1.0, "obs_agent_index": True}


@pytest.fixture
def task_module():
    """``coopnav_env.training.benchmarl_backend`` (the test skips without BenchMARL), one torch
    thread."""
    pytest.importorskip("benchmarl")
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield importlib.import_module(MODULE)
    torch.set_num_threads(threads)


def test_the_task_builds_an_environment_that_passes_check_env_specs(task_module) -> None:
    from torchrl.envs.utils import check_env_specs

    CoopnavTask = task_module.CoopnavTask
    default = CoopnavTask.URBAN_CANYON_V1.get_task()
    assert default.config == task_module.DEFAULT_CONFIGS["URBAN_CANYON_V1"]
    assert default.config["nav_team_weight"] == 1.0 and default.config["obs_agent_index"] is True
    assert CoopnavTask.URBAN_CANYON_V1.env_name() == "coopnav"

    task = CoopnavTask.URBAN_CANYON_V1.get_task(dict(SMALL))
    assert task.supports_continuous_actions() and not task.supports_discrete_actions()
    with pytest.raises(ValueError, match="continuous"):
        task.get_env_fun(num_envs=1, continuous_actions=False, seed=0, device="cpu")
    env = task.get_env_fun(num_envs=1, continuous_actions=True, seed=0, device="cpu")()
    check_env_specs(env)
    assert task.group_map(env) == {"uav": ["uav_0", "uav_1", "uav_2"]}
    assert task.max_steps(env) == 10
    assert not task.has_render(env)
    obs = task.observation_spec(env)["uav", "observation"]
    assert obs.shape[0] == 3
    assert set(task.observation_spec(env)["uav"].keys()) == {"observation"}
    assert task.action_spec(env)["uav", "action"].shape == (3, 3)
    assert list(task.state_spec(env).keys()) == ["state"]
    assert "coop_error_m" in task.info_spec(env)["uav", "info"].keys()
    assert task.action_mask_spec(env) is None
    td = env.rollout(4, break_when_any_done=False)
    assert td["next", "uav", "reward"].shape == (4, 3, 1)
    env.close()

    # the one-hot agent index: 3 entries more than the same environment without it
    plain = dict(SMALL, obs_agent_index=False)
    env = CoopnavTask.URBAN_CANYON_V1.get_task(plain).get_env_fun(1, True, 0, "cpu")()
    assert task.observation_spec(env)["uav", "observation"].shape[-1] == obs.shape[-1] - 3
    env.close()

    v0 = CoopnavTask.URBAN_CANYON_V0.get_task({"n_uavs": 3, "max_steps": 10})
    check_env_specs(v0.get_env_fun(1, True, 0, "cpu")())


def test_a_tiny_mappo_experiment_runs_to_the_end(task_module, tmp_path) -> None:
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    config = ExperimentConfig.get_from_yaml()
    config.gamma = 1.0  # urban_canyon_v1: the undiscounted return is the score
    config.max_n_frames = 120
    config.on_policy_collected_frames_per_batch = 60
    config.on_policy_n_envs_per_worker = 1
    config.on_policy_n_minibatch_iters = 1
    config.on_policy_minibatch_size = 30
    config.evaluation = True
    config.evaluation_interval = 120
    config.evaluation_episodes = 1
    config.loggers = ["csv"]  # TorchRL's csv logger: no torchvision needed
    config.create_json = False
    config.checkpoint_at_end = False
    config.save_folder = str(tmp_path)
    experiment = Experiment(
        task=task_module.CoopnavTask.URBAN_CANYON_V1.get_task(dict(SMALL, max_steps=20)),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=config,
    )
    assert experiment.max_steps == 20
    assert experiment.state_spec is not None  # MAPPO's critic sees the global state
    experiment.run()
    assert experiment.total_frames == 120
    assert experiment.n_iters_performed == 2
    assert any(p.suffix == ".csv" for p in tmp_path.rglob("*"))  # the logged scalars


def test_import_needs_benchmarl_and_names_the_extra(monkeypatch) -> None:
    """Without BenchMARL the import fails with a message naming the ``benchmarl`` extra; with
    it, the import works (and fails alike when BenchMARL is hidden)."""
    monkeypatch.delitem(sys.modules, MODULE, raising=False)
    if HAS_BENCHMARL:
        module = importlib.import_module(MODULE)
        assert module.CoopnavTask.URBAN_CANYON_V1.get_task().name == "URBAN_CANYON_V1"
        monkeypatch.delitem(sys.modules, MODULE)
        monkeypatch.setitem(sys.modules, "benchmarl", None)
        monkeypatch.setitem(sys.modules, "benchmarl.environments.common", None)
    with pytest.raises(ImportError, match="`benchmarl` extra") as info:
        importlib.import_module(MODULE)
    assert 'pip install -e ".[benchmarl]"' in str(info.value)
    assert "benchmarl" in str(info.value.__cause__)
