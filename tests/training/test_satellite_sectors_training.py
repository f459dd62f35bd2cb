"""Training and evaluating a TorchRL policy with the ``obs_satellite_sectors`` observation."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from agents import make_policy  # noqa: E402
from coopnav_env import urban_canyon_v0  # noqa: E402
from training.cli import main  # noqa: E402

SMALL = ["--set", "torchrl.n_copies=2", "--set", "torchrl.rollout_steps=8", "--no-progress"]


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def test_train_and_evaluate_with_satellite_sectors(tmp_path) -> None:
    """``--env-set obs_satellite_sectors=true``: the actor's input grows by the 2 A entries,
    the run records the setting, evaluation rebuilds that environment, and the policy refuses
    an environment without the option."""
    out = tmp_path / "run"
    args = ["train", "--backend", "torchrl", "--algorithm", "mappo", "--out", str(out)]
    env_set = ["--env-set", "obs_satellite_sectors=true"]
    assert main([*args, "--timesteps", "80", *env_set, *SMALL]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["env"]["obs_satellite_sectors"] is True
    ckpt = torch.load(out / "final_model.pt", weights_only=False)
    with_sectors = urban_canyon_v0.parallel_env(**run["env"])
    cfg = with_sectors.config
    assert cfg.obs_dim == 52 + 2 * cfg.obs_sky_azimuths
    policy = make_policy(f"mappo:{out}", with_sectors)
    assert int(ckpt["actor_dim"]) == cfg.obs_dim + policy.settings.actor_extra_inputs
    obs, _ = with_sectors.reset(seed=1)
    actions = policy.act(obs)
    assert all(np.all(np.isfinite(a)) and a.shape == (3,) for a in actions.values())
    without = urban_canyon_v0.parallel_env(**{**run["env"], "obs_satellite_sectors": False})
    with pytest.raises(ValueError, match="does not match the checkpoint's actor input"):
        make_policy(f"mappo:{out}", without)
    report = tmp_path / "eval"
    cmd = ["evaluate", "--policies", f"mappo:{out}", "--episodes", "1", "--out", str(report)]
    assert main([*cmd, "--no-plots"]) == 0
    assert '"obs_satellite_sectors": true' in (report / "report.md").read_text()
