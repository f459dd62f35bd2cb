"""The TorchRL backend never loses work nor accepts a wrong model (issue 35).

Each test reproduces one reported case on a tiny run (2 UAVs, 2 swarm copies, 4 steps per
rollout: 16 agent-steps an iteration, seconds). Interrupts are sent at chosen points: a
patched function sends SIGINT to this process (``os.kill(os.getpid(), SIGINT)``) on a chosen
call, so every run sees the signal at the same place.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import warnings
from pathlib import Path

import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from coopnav_env.agents import make_policy  # noqa: E402
from coopnav_env.agents.marl_nets import load_marl_checkpoint  # noqa: E402
from coopnav_env.training import torchrl_backend  # noqa: E402
from coopnav_env.training.cli import main  # noqa: E402

TINY = [
    "--backend",
    "torchrl",
    "--env-id",  # the safety checks were written against v0's torchrl section (no warm start)
    "urban_canyon_v0",
    "--env-set",
    "n_uavs=2",
    "--set",
    "torchrl.n_copies=2",
    "--set",
    "torchrl.rollout_steps=4",
    "--set",
    "torchrl.hidden=[16,16]",
    "--set",
    "torchrl.epochs=1",
    "--no-progress",
]
STEP = 16  # agent-steps an iteration of TINY


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def train(out: Path, *args: str) -> int:
    return main(["train", "--out", str(out), *TINY, *args])


def rows(out: Path) -> list[dict[str, str]]:
    with open(out / "logs" / "progress.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def sigint_on_update(monkeypatch, *when: int) -> None:
    """Send SIGINT during the update that starts with ``trainer.iterations`` in ``when``."""
    real = torchrl_backend.MARLTrainer.update

    def update(self, data):
        if self.iterations in when:
            os.kill(os.getpid(), signal.SIGINT)
        return real(self, data)

    monkeypatch.setattr(torchrl_backend.MARLTrainer, "update", update)


# --------------------------------------------------------------------------------------------
# 1. logs/progress.csv holds every iteration once, in order, over interrupts and resumes
# --------------------------------------------------------------------------------------------


def test_progress_csv_keeps_every_iteration_over_interrupts_and_resumes(tmp_path, monkeypatch):
    out = tmp_path / "run"
    sigint_on_update(monkeypatch, 6)  # the 7th update: interrupted after 112 agent-steps
    assert train(out, "--timesteps", "160", "--checkpoint-freq", "48") == 130
    assert (out / "checkpoints" / "marl_112_steps.pt").is_file()
    (out / "checkpoints" / "marl_112_steps.pt").unlink()  # as if killed (SIGKILL) instead
    sigint_on_update(monkeypatch, 8)  # resumed at 96; interrupted again after 144
    assert train(out, "--timesteps", "160", "--resume", "latest") == 130
    monkeypatch.undo()
    assert train(out, "--timesteps", "160", "--resume", "latest") == 0
    got = rows(out)
    assert [int(float(r["agent_steps"])) for r in got] == list(range(STEP, 161, STEP))
    assert [int(float(r["iteration"])) for r in got] == list(range(1, 11))
    # a finished run trained further keeps its curve too
    assert train(out, "--timesteps", "192", "--resume", "latest") == 0
    assert [int(float(r["agent_steps"])) for r in rows(out)] == list(range(STEP, 193, STEP))


# --------------------------------------------------------------------------------------------
# 2. an interrupt never lands inside a compiled call; 6. nor is it lost during start-up
# --------------------------------------------------------------------------------------------


def test_sigint_inside_a_compiled_call_is_taken_after_it(tmp_path, monkeypatch, capsys):
    """SIGINT as a step of the swarms starts its compiled (numba) kernels (the batched
    environment's step, its kernels in threads): the step completes, the interrupt is taken
    after it, a checkpoint is saved and the run resumes (once the interrupt raised inside
    the call: ``SystemError: CPUDispatcher(...)``, no checkpoint)."""
    from coopnav_env.envs import BatchedUrbanCanyonEnv

    real = BatchedUrbanCanyonEnv.step_arrays
    calls = {"started": 0, "finished": 0}

    def compiled_call(self, actions):
        calls["started"] += 1
        if calls["started"] == 10:
            os.kill(os.getpid(), signal.SIGINT)  # lands as the compiled calls start
        result = real(self, actions)
        calls["finished"] += 1
        return result

    monkeypatch.setattr(BatchedUrbanCanyonEnv, "step_arrays", compiled_call)
    out = tmp_path / "run"
    assert train(out, "--timesteps", "160") == 130
    assert calls["started"] >= 10 and calls["finished"] == calls["started"]
    err = capsys.readouterr().err
    assert "interrupted: saved the policy after" in err and "--resume latest" in err
    monkeypatch.undo()
    assert train(out, "--timesteps", "160", "--resume", "latest") == 0


def test_sigint_during_start_up_is_not_swallowed(tmp_path, monkeypatch, capsys):
    """SIGINT while the networks are built, inside a destructor (where Python ignores an
    exception, as in the reported ``Exception ignored in ObjectRef.__del__``): the run stops
    with exit 130 and a checkpoint, instead of training to the end."""
    real = torchrl_backend.build_modules

    class Handle:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)

    def build_modules(*args, **kw):
        h = Handle()
        del h  # the signal arrives inside __del__
        return real(*args, **kw)

    monkeypatch.setattr(torchrl_backend, "build_modules", build_modules)
    out = tmp_path / "run"
    assert train(out, "--timesteps", "160") == 130
    assert not (out / "final_model.pt").exists()
    assert "interrupted: saved the policy after 0 agent-steps" in capsys.readouterr().err
    monkeypatch.undo()
    assert train(out, "--timesteps", "32", "--resume", "latest") == 0  # 7: it resumes


# --------------------------------------------------------------------------------------------
# 7. an interrupt before training started leaves a folder that can be used again
# --------------------------------------------------------------------------------------------


def test_interrupt_before_the_first_iteration_leaves_a_reusable_folder(
    tmp_path, monkeypatch, capsys
):
    """Two SIGINTs (the second stops at once) while the trainer is built, after config.yaml
    was written: nothing was trained, the folder is as before, and the same command runs
    (today: a rerun was refused while --resume said there was no checkpoint)."""
    real = torchrl_backend.build_modules

    def build_modules(*args, **kw):
        assert (out / "config.yaml").is_file()  # written before the trainer is built
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        return real(*args, **kw)

    out = tmp_path / "run"
    monkeypatch.setattr(torchrl_backend, "build_modules", build_modules)
    assert train(out, "--timesteps", "32") == 130
    err = capsys.readouterr().err
    assert "nothing was trained" in err and "run the same command again" in err
    assert not (out / "config.yaml").exists()
    monkeypatch.undo()
    assert train(out, "--timesteps", "32") == 0
    # a folder left so by an older version (settings, no checkpoint) says so plainly
    (out / "run.json").unlink()
    (out / "final_model.pt").unlink()
    for p in (out / "checkpoints").glob("*"):
        p.unlink()
    (out / "logs" / "progress.csv").unlink()
    capsys.readouterr()
    assert train(out, "--timesteps", "32", "--resume", "latest") == 2
    err = capsys.readouterr().err
    assert "nothing was trained" in err and "--overwrite" in err


# --------------------------------------------------------------------------------------------
# 4. resuming with other network settings, or from an incomplete checkpoint, names them
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A finished MAPPO run of 64 agent-steps with checkpoints at 32 and 64 (tests that
    change it work on a copy)."""
    out = tmp_path_factory.mktemp("base") / "run"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.set_num_threads(1)
        assert train(out, "--timesteps", "64", "--checkpoint-freq", "32") == 0
    return out


def copy_run(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(".coopnav.lock"))
    return dst


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (["--algorithm", "ippo"], "torchrl.algorithm='ippo'"),
        (["--set", "torchrl.hidden=[32,32]"], "torchrl.hidden=[32, 32]"),
    ],
    ids=["algorithm", "hidden"],
)
def test_resuming_with_other_network_settings_names_them(
    tmp_path, capsys, finished_run, change, named
):
    out = copy_run(finished_run, tmp_path / "run")
    capsys.readouterr()
    assert train(out, "--timesteps", "96", "--resume", "latest", *change) == 2
    err = capsys.readouterr().err
    assert named in err and "it was trained with" in err and "internal error" not in err


def test_a_checkpoint_with_missing_entries_names_them(tmp_path, capsys, finished_run):
    out = copy_run(finished_run, tmp_path / "run")
    d = load_marl_checkpoint(out / "checkpoints" / "marl_32_steps.pt")
    del d["optimizer"], d["reward_std"]
    bad = tmp_path / "partial.pt"
    torch.save(d, bad)
    capsys.readouterr()
    assert train(out, "--timesteps", "96", "--resume", str(bad)) == 2
    err = capsys.readouterr().err
    assert f"{bad} is not a complete TorchRL checkpoint: it lacks optimizer, reward_std" in err


# --------------------------------------------------------------------------------------------
# 8. NaN weights and the wrong algorithm's label are refused
# --------------------------------------------------------------------------------------------


def test_a_checkpoint_with_nan_weights_is_neither_resumed_nor_flown(tmp_path, capsys, finished_run):
    out = copy_run(finished_run, tmp_path / "run")
    d = load_marl_checkpoint(out / "checkpoints" / "marl_32_steps.pt")
    name = next(k for k, v in d["actor"].items() if v.is_floating_point())
    d["actor"][name] = torch.full_like(d["actor"][name], float("nan"))
    nan = out / "checkpoints" / "marl_80_steps.pt"  # the newest: --resume latest skips it
    torch.save(d, nan)
    capsys.readouterr()
    assert train(out, "--timesteps", "96", "--resume", str(nan)) == 2
    assert f"{nan} holds non-finite weights (NaN or inf) in actor.{name}" in (
        capsys.readouterr().err
    )
    assert train(out, "--timesteps", "96", "--resume", "latest") == 0
    err = capsys.readouterr().err
    assert f"skipping TorchRL checkpoint {nan}" in err
    assert json.loads((out / "run.json").read_text())["agent_steps"] == 96
    assert all(
        torch.isfinite(v).all()
        for v in load_marl_checkpoint(out / "final_model.pt")["actor"].values()
        if v.is_floating_point()
    )
    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env(n_uavs=2)
    with pytest.raises(ValueError, match="non-finite weights"):
        make_policy(f"mappo:{nan}", env)


def test_a_policy_is_not_flown_under_the_other_algorithms_label(tmp_path, finished_run):
    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env(n_uavs=2)
    run = finished_run  # trained as MAPPO (the packaged default)
    with pytest.raises(ValueError, match=r"ippo:.* was trained with MAPPO .* fly it as mappo:"):
        make_policy(f"ippo:{run}", env)
    assert make_policy(f"mappo:{run}", env).name == "mappo"
    assert make_policy(f"torchrl:{run}", env).name == "mappo"  # torchrl: takes either
    with pytest.raises(ValueError, match=r"was trained with IPPO .* fly it as ippo:"):
        make_policy(f"mappo:{marl_policy_dir('ippo_s0')}", env)


def marl_policy_dir(name: str) -> Path:
    from coopnav_env.agents.marl_policy import PRETRAINED_DIR

    return PRETRAINED_DIR / name


# --------------------------------------------------------------------------------------------
# 9. resumes that wrote no config.yaml, reported a missing model, or trained 0 steps silently
# --------------------------------------------------------------------------------------------


def test_a_resume_from_another_folder_or_without_config_writes_config_yaml(tmp_path, finished_run):
    import yaml

    ckpt = finished_run / "checkpoints" / "marl_32_steps.pt"
    new = tmp_path / "new"
    assert train(new, "--timesteps", "64", "--resume", str(ckpt)) == 0
    recorded = yaml.safe_load((new / "config.yaml").read_text())
    assert recorded["env"] == load_marl_checkpoint(ckpt)["env_kwargs"]
    assert recorded["backend"] == "torchrl"
    out = copy_run(finished_run, tmp_path / "run")
    (out / "config.yaml").unlink()
    (out / "run.json").unlink()
    assert train(out, "--timesteps", "96", "--resume", "latest") == 0
    assert yaml.safe_load((out / "config.yaml").read_text())["env"]["n_uavs"] == 2


def test_timesteps_below_the_checkpoint_and_finished_runs_are_said(tmp_path, capsys, finished_run):
    out = copy_run(finished_run, tmp_path / "run")
    before = (out / "run.json").read_bytes()
    capsys.readouterr()
    # an explicit --resume of the finished run's own final model: nothing to do, untouched
    for name in ("final_model.pt", "final_model"):
        assert train(out, "--resume", str(out / name)) == 0
        assert "holds a finished run (64 agent-steps); nothing to do" in capsys.readouterr().err
        assert (out / "run.json").read_bytes() == before
    # fewer agent-steps than the checkpoint holds: said, not a silent run of 0 steps
    (out / "run.json").unlink()
    (out / "final_model.pt").unlink()
    assert train(out, "--resume", "latest", "--timesteps", "40") == 2
    err = capsys.readouterr().err
    assert "--timesteps 40 is below the 64 agent-steps of the checkpoint" in err
    assert not (out / "final_model.pt").exists()


def test_torchrl_resume_of_an_sb3_run_names_the_backend(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    from tests.training.test_run_safety import toy_yaml
    from tests.training.toy_env import TOY_ENV_ID

    config = toy_yaml(tmp_path, timesteps=192)
    out = tmp_path / "sb3"
    assert main(["train", "--config", str(config), "--env-id", TOY_ENV_ID, "--out", str(out)]) == 0
    before = sorted(p.name for p in out.iterdir())
    capsys.readouterr()
    args = ["train", "--out", str(out), "--resume", "latest", "--no-progress"]
    assert main([*args, "--backend", "torchrl"]) == 2
    err = capsys.readouterr().err
    assert "trained with --backend sb3" in err and "final_model.pt" not in err
    assert sorted(p.name for p in out.iterdir()) == before


# --------------------------------------------------------------------------------------------
# 10. a failed checkpoint write is a one-line message and keeps the earlier checkpoint
# --------------------------------------------------------------------------------------------


def test_a_failed_checkpoint_write_is_a_message_and_keeps_the_earlier_one(
    tmp_path, monkeypatch, capsys
):
    real = torch.save
    calls = []

    def save(obj, f, *a, **kw):
        calls.append(f)
        if len(calls) == 2:  # what a file-size limit does inside torch's writer
            Path(f).write_bytes(b"PK\x03\x04 truncated")
            raise RuntimeError("[enforce fail at inline_container.cc:626] . unexpected pos 64 vs 0")
        return real(obj, f, *a, **kw)

    monkeypatch.setattr(torch, "save", save)
    out = tmp_path / "run"
    capsys.readouterr()
    assert train(out, "--timesteps", "96", "--checkpoint-freq", "32") == 1
    err = capsys.readouterr().err
    (line,) = [x for x in err.splitlines() if "error:" in x]
    assert "internal error" not in line and "cannot write" in line and "marl_64_steps.pt" in line
    monkeypatch.undo()
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["marl_32_steps.pt"]
    load_marl_checkpoint(out / "checkpoints" / "marl_32_steps.pt")


# --------------------------------------------------------------------------------------------
# model files are pickles: TorchRL checkpoints are read without running code from them
# --------------------------------------------------------------------------------------------


class _RunsCode:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "code from the checkpoint ran"))


def test_a_checkpoint_is_loaded_without_running_code_from_it(tmp_path):
    from coopnav_env.agents.marl_nets import CHECKPOINT_FORMAT

    marker = tmp_path / "ran.txt"
    evil = tmp_path / "evil.pt"
    torch.save({"format": CHECKPOINT_FORMAT, "payload": _RunsCode(marker)}, evil)
    with pytest.raises(ValueError, match="is not a readable coopnav TorchRL checkpoint"):
        load_marl_checkpoint(evil)
    assert not marker.exists()


def test_evaluate_help_warns_that_model_files_are_pickles(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "pickle" in out and "trust" in out


def test_an_interrupt_that_surfaces_as_a_system_error_exits_130(monkeypatch, capsys):
    """Before any handler is installed (e.g. compiling the kernels), a Ctrl-C inside a
    compiled call surfaces as ``SystemError`` caused by ``KeyboardInterrupt``: an interrupt
    (exit 130), not an internal error."""
    from coopnav_env.training import train as train_cli

    def run(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError(
                "CPUDispatcher(<function epoch_navigation>) returned a result with an exception set"
            ) from exc

    monkeypatch.setattr(train_cli, "run", run)
    assert main(["train", "--out", "x"]) == 130
    assert "internal error" not in capsys.readouterr().err
