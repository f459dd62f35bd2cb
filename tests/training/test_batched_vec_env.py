"""The batched SB3 vector environment equals the SuperSuit one, step for step and in training."""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from coopnav_env import urban_canyon_v0
from coopnav_env.training.config import TrainConfig, load_config
from coopnav_env.training.sb3_backend import train
from coopnav_env.training.train import add_arguments, config_from_args
from coopnav_env.training.vec_env import BatchedVecEnv, SeededVecEnv, make_vec_env
from tests.training.test_train_eval import params, toy_cfg, urban_cfg
from tests.training.toy_env import ToyParallelEnv


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return type(a) is type(b) and a == b


def test_batched_equals_supersuit_step_for_step() -> None:
    fn = functools.partial(urban_canyon_v0.parallel_env, n_uavs=3, max_steps=5)
    ref = make_vec_env(fn, 3, kind="supersuit")
    new = make_vec_env(fn, 3, kind="batched")
    assert isinstance(ref, SeededVecEnv) and isinstance(new, BatchedVecEnv)
    assert new.num_envs == ref.num_envs == 9
    assert new.seed(4) == ref.seed(4)
    assert np.array_equal(new.reset(), ref.reset())
    assert all(_same(a, b) for a, b in zip(ref.reset_infos, new.reset_infos))
    rng = np.random.default_rng(1)
    done_slots = 0
    for _ in range(30):
        act = rng.uniform(-1.2, 1.2, (9, 3))  # float64: both cast to the space's float32
        o1, r1, d1, i1 = ref.step(act)
        o2, r2, d2, i2 = new.step(act)
        assert o2.dtype == o1.dtype and np.array_equal(o1, o2)
        assert r2.dtype == r1.dtype and np.array_equal(r1, r2)
        assert np.array_equal(d1, d2)
        assert all(_same(a, b) for a, b in zip(i1, i2))
        done_slots += int(d1.sum())
    assert done_slots > 0  # automatic resets covered (terminal_observation, truncation flag)
    assert new.get_attr("render_mode") == [None] * 9
    assert new.get_attr("config", [0, 8])[1].n_uavs == 3
    ref.close()
    new.close()


def test_training_is_identical_with_either_vec_env(tmp_path) -> None:
    a = params(train(urban_cfg(tmp_path / "a", seed=5, timesteps=300, vec_env="supersuit")))
    b = params(train(urban_cfg(tmp_path / "b", seed=5, timesteps=300, vec_env="batched")))
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    assert json.loads((tmp_path / "a" / "run.json").read_text())["vec_env"] == "supersuit"
    assert json.loads((tmp_path / "b" / "run.json").read_text())["vec_env"] == "batched"


def test_auto_vec_env_is_batched_where_it_applies(tmp_path) -> None:
    """ "auto" (the default): the batched vector env for urban_canyon_v0 in one process,
    SuperSuit for worker processes or another environment; train() records which."""
    assert urban_cfg(tmp_path).vec_env == "auto"
    assert urban_cfg(tmp_path).vec_env_kind() == "batched"
    assert urban_cfg(tmp_path, num_cpus=0).vec_env_kind() == "batched"
    assert urban_cfg(tmp_path, num_cpus=2).vec_env_kind() == "supersuit"
    rendering = {**urban_cfg(tmp_path).env, "render_mode": "rgb_array"}
    with pytest.raises(ValueError, match="training does not render"):
        urban_cfg(tmp_path, env=rendering)  # issue 15: training refuses render modes
    assert urban_cfg(tmp_path, vec_env="supersuit").vec_env_kind() == "supersuit"
    assert toy_cfg(tmp_path / "toy").vec_env_kind() == "supersuit"
    train(toy_cfg(tmp_path / "toy", timesteps=64))  # auto -> supersuit: the toy env trains
    assert json.loads((tmp_path / "toy" / "run.json").read_text())["vec_env"] == "supersuit"


def test_bad_vec_env_settings(tmp_path) -> None:
    with pytest.raises(ValueError, match="vec_env must be one of"):
        urban_cfg(tmp_path, vec_env="fast")
    with pytest.raises(ValueError, match="num_cpus must be 0 or 1"):
        urban_cfg(tmp_path, vec_env="batched", num_cpus=2)
    with pytest.raises(ValueError, match="urban_canyon_v0"):
        make_vec_env(functools.partial(ToyParallelEnv, n_uavs=2), 2, kind="batched")
    with pytest.raises(ValueError, match="vec_env kind"):
        make_vec_env(functools.partial(ToyParallelEnv, n_uavs=2), 2, kind="fast")
    with pytest.raises(ValueError, match="urban_canyon_v0"):
        train(toy_cfg(tmp_path / "toy", vec_env="batched"))
    assert TrainConfig.from_dict({**load_config(), "out": str(tmp_path)}).vec_env == "auto"


def test_cli_vec_env_flag(tmp_path) -> None:
    import argparse

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--out", str(tmp_path), "--vec-env", "batched"])
    assert config_from_args(args).vec_env == "batched"
    args = parser.parse_args(["--out", str(tmp_path)])
    assert config_from_args(args).vec_env == "auto"
