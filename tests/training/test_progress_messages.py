"""Honest progress (issue 16): the numba compilation is announced, the warm start has bars."""

from __future__ import annotations

import importlib
import io
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from coopnav_env.training import compile_notice as cn
from tests.training.toy_env import TOY_ENV_ID, TOY_TRAINING, ToyParallelEnv

ROOT = Path(__file__).resolve().parents[2]


def test_kernel_module_list_is_complete() -> None:
    found = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts)
        for p in (ROOT / "coopnav_env").rglob("_kernels.py")
    }
    assert set(cn.KERNEL_MODULES) == found


def _write_kernels(folder: Path, name: str, extra: str = "") -> None:
    (folder / f"{name}.py").write_text(
        textwrap.dedent(
            f"""
            from numba import njit

            @njit(cache=True, inline="always")
            def helper(x):  # inlined into its callers: never cached on its own
                return x

            @njit(cache=True)
            def kernel(x):
                return helper(x) + 1
            {extra}
            """
        )
    )


def test_cold_modules_follow_numbas_own_cache(tmp_path, monkeypatch) -> None:
    """Cold before the first call, warm after it, cold again once the source changes."""
    monkeypatch.syspath_prepend(str(tmp_path))
    name = "evalux_kernels_a"
    _write_kernels(tmp_path, name)
    mod = importlib.import_module(name)
    try:
        assert cn.cold_kernel_modules([name]) == [name]
        assert mod.kernel(1) == 2  # compiles and writes the cache
        assert cn.cold_kernel_modules([name]) == []  # the inlined helper has no entry: ignored
        _write_kernels(tmp_path, name, extra="# edited")  # another size: numba's stamp differs
        importlib.reload(mod)
        assert cn.cold_kernel_modules([name]) == [name]
    finally:
        sys.modules.pop(name, None)


def test_cold_cache_is_announced_at_once(tmp_path, monkeypatch) -> None:
    monkeypatch.syspath_prepend(str(tmp_path))
    name = "evalux_kernels_b"
    _write_kernels(tmp_path, name)
    mod = importlib.import_module(name)
    out = io.StringIO()
    try:
        with cn.compile_notice("about 1 s", modules=[name], delay_s=600, stream=out, prefix="x"):
            first = out.getvalue()  # printed on entry, before the compilation
            mod.kernel(1)
    finally:
        sys.modules.pop(name, None)
    assert first == (
        "x: compiling the navigation kernels (numba), once: about 1 s; later runs load them "
        "from the cache\n"
    )
    assert out.getvalue().splitlines()[1].startswith("x: navigation kernels ready (")


def test_warm_cache_is_quiet_unless_slow() -> None:
    quiet = io.StringIO()
    with cn.compile_notice(modules=[], delay_s=5.0, stream=quiet):
        pass
    assert quiet.getvalue() == ""
    slow = io.StringIO()
    with cn.compile_notice(modules=[], delay_s=0.05, stream=slow, prefix="x"):
        time.sleep(0.5)  # 10x the delay: the timer thread has long fired
    lines = slow.getvalue().splitlines()
    assert lines[0].startswith("x: loading or compiling the navigation kernels (numba;")
    assert lines[1].startswith("x: navigation kernels ready (") and len(lines) == 2


def test_no_ready_line_after_an_error() -> None:
    out = io.StringIO()
    with pytest.raises(KeyboardInterrupt):
        with cn.compile_notice(modules=[], delay_s=0.0, stream=out, prefix="x"):
            time.sleep(0.3)
            raise KeyboardInterrupt
    assert "ready" not in out.getvalue() and "loading or compiling" in out.getvalue()


def test_cold_modules_unknown_without_jit(monkeypatch) -> None:
    from numba import config

    monkeypatch.setattr(config, "DISABLE_JIT", True)
    assert cn.cold_kernel_modules() is None


def test_warm_up_env_resets_and_steps_once() -> None:
    calls = []

    class Recorder(ToyParallelEnv):
        def reset(self, seed=None, options=None):
            calls.append(("reset", seed))
            return super().reset(seed=seed, options=options)

        def step(self, actions):
            calls.append(("step", {a: v.tolist() for a, v in actions.items()}))
            return super().step(actions)

        def close(self):
            calls.append(("close", None))

    cn.warm_up_env(lambda: Recorder(n_uavs=2))
    zero = [0.0, 0.0, 0.0]
    assert calls == [("reset", 0), ("step", {"uav_0": zero, "uav_1": zero}), ("close", None)]


def test_train_cli_warms_the_kernels_inside_the_notice(tmp_path, monkeypatch, capsys) -> None:
    pytest.importorskip("stable_baselines3")
    import coopnav_env.training.train as tr
    from coopnav_env.training.cli import main

    events = []

    class Notice:
        def __init__(self, first_time, **kw):
            events.append(("notice", first_time, kw["prefix"]))

        def __enter__(self):
            events.append("enter")

        def __exit__(self, *exc):
            events.append("exit")

    monkeypatch.setattr(tr, "compile_notice", Notice)
    monkeypatch.setattr(tr, "warm_up_env", lambda fn: events.append(("warm", fn().n_uavs)))
    config = tmp_path / "toy.yaml"
    config.write_text(yaml.safe_dump({TOY_ENV_ID: TOY_TRAINING}))
    args = ["train", "--env-id", TOY_ENV_ID, "--config", str(config), "--out", str(tmp_path / "r")]
    args += ["--timesteps", "64", "--env-set", "n_uavs=2"]
    assert main(args) == 0, capsys.readouterr().err
    assert events == [("notice", "about a minute", "coopnav train"), "enter", ("warm", 2), "exit"]


def test_behaviour_cloning_shows_its_progress(capsys) -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from coopnav_env.training.sb3_backend import behaviour_clone
    from coopnav_env.training.vec_env import make_vec_env

    def env_fn():
        return ToyParallelEnv(n_uavs=2, max_steps=6)

    spec = {"policy": "random", "episodes": 3, "epochs": 4, "learning_rate": 1e-3}
    results = []
    for progress in (False, True):
        venv = make_vec_env(env_fn, 1)
        model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, seed=0, device="cpu")
        results.append(behaviour_clone(model, env_fn, spec, seed=0, progress=progress))
        venv.close()
    err = capsys.readouterr().err
    assert "warm start: teacher" in err and "3/3" in err
    assert "warm start: fitting" in err and "4/4" in err
    assert results[0] == results[1]  # the bars change nothing
    assert np.isfinite(results[1]["final_action_mse"])
