"""``coopnav_env.training.vec_env.urban_canyon_vec_env``: SB3 from your own script (issue 16)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from coopnav_env.training.vec_env import BatchedVecEnv, SeededVecEnv, urban_canyon_vec_env

ENV = {"n_uavs": 2, "max_steps": 5}


@pytest.mark.parametrize("kind", ["batched", "supersuit"])
def test_time_limit_reaches_sb3_as_truncation(kind: str) -> None:
    venv = urban_canyon_vec_env(2, kind=kind, **ENV)
    assert isinstance(venv, BatchedVecEnv if kind == "batched" else SeededVecEnv)
    assert venv.num_envs == 4
    venv.seed(3)
    venv.reset()
    hover = np.zeros((4, 3), np.float32)  # nobody moves: no crash, no goal, only the limit
    for step in range(1, 6):
        _obs, _rew, dones, infos = venv.step(hover)
        if step < 5:
            assert not dones.any()
            assert not any("TimeLimit.truncated" in i for i in infos)
    assert dones.all()
    assert all(i["TimeLimit.truncated"] is True for i in infos)
    assert all(i["terminal_observation"].shape == venv.observation_space.shape for i in infos)
    venv.close()


def test_ppo_with_a_seed_works_and_repeats() -> None:
    """``PPO(..., seed=0)`` (which SuperSuit's own recipe breaks) trains the same weights."""
    from stable_baselines3 import PPO

    def weights(seed: int = 0) -> dict[str, np.ndarray]:
        venv = urban_canyon_vec_env(2, **ENV)
        model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=seed)
        model.learn(total_timesteps=64)
        venv.close()
        return {k: v.detach().numpy().copy() for k, v in model.policy.state_dict().items()}

    a, b = weights(), weights()
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    other = weights(1)  # and the seed matters
    assert any(not np.array_equal(a[k], other[k]) for k in a)


def test_bad_settings_are_named() -> None:
    with pytest.raises(ValueError, match="n_uav"):
        urban_canyon_vec_env(1, n_uav=3)
    with pytest.raises(ValueError, match="vec_env kind"):
        urban_canyon_vec_env(1, kind="dummy", **ENV)
    with pytest.raises(ValueError, match="n_copies"):
        urban_canyon_vec_env(0, **ENV)
