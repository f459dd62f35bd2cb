"""Training runs never lose work (issue 15, data-loss cases 1-6).

Each test reproduces one reported way of losing work, on the tiny toy environment (a few
hundred agent-steps, seconds). The command-line ones run ``coopnav train`` in a subprocess and
interrupt or limit it as a scheduler or a full disk would.
"""

from __future__ import annotations

import io
import json
import os
import resource
import signal
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from coopnav_env.training.cli import main
from coopnav_env.training.config import TrainConfig, load_config
from coopnav_env.training.runs import LOCK_NAME
from coopnav_env.training.sb3_backend import find_latest_checkpoint, train
from tests.training.toy_env import TOY_ENV_ID, TOY_TRAINING

ROOT = Path(__file__).resolve().parents[2]
TOY = TOY_ENV_ID
TOY_SECTION = TOY_TRAINING


def toy_cfg(out: Path, **kw) -> TrainConfig:
    return TrainConfig.from_dict(
        {**load_config(), "env_id": TOY, "out": str(out), **TOY_SECTION, **kw}
    )


def toy_yaml(tmp_path: Path, **kw) -> Path:
    """A hyperparameter file whose section for the toy env is ``TOY_SECTION`` updated by kw."""
    path = tmp_path / "toy.yaml"
    path.write_text(yaml.safe_dump({TOY: {**TOY_SECTION, **kw}}))
    return path


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Content and modification time of every file under ``folder`` (the lock aside)."""
    return {
        str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != LOCK_NAME
    }


def loads(path: Path) -> bool:
    from stable_baselines3 import PPO

    try:
        PPO.load(path, device="cpu")
    except Exception:
        return False
    return True


def popen_train(tmp_path: Path, *args: str, **kw) -> subprocess.Popen:
    """``coopnav train`` on the toy env in a subprocess (stderr piped, text)."""
    cmd = [sys.executable, "-m", "coopnav_env.training.cli", "train", "--env-id", TOY, *args]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(cmd, cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True, **kw)


def wait_for(predicate, timeout_s: float = 60.0) -> None:
    t0 = time.monotonic()
    while not predicate():
        assert time.monotonic() - t0 < timeout_s, "timed out"
        time.sleep(0.05)


def wait_for_line(proc: subprocess.Popen, text: str, timeout_s: float = 60.0) -> None:
    """Wait until a line of the process's stderr contains ``text`` (read by a thread, so a
    silent process cannot block the test); the lines stay readable by ``communicate``."""
    seen = threading.Event()
    lines: list[str] = []

    def read() -> None:
        for line in proc.stderr:
            lines.append(line)
            if text in line:
                seen.set()
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert seen.wait(timeout_s), f"{text!r} never appeared; stderr so far:\n{''.join(lines)}"


# --------------------------------------------------------------------------------------------
# 1. checkpoints are written atomically; --resume latest skips one that does not load
# --------------------------------------------------------------------------------------------


def test_a_failing_checkpoint_write_leaves_no_damaged_checkpoint(tmp_path, monkeypatch):
    """A full disk during the second checkpoint: the write fails, but no truncated file is
    left under a checkpoint's name (today's code left a damaged ``ppo_<N>_steps.zip``)."""
    from stable_baselines3 import PPO

    real_save = PPO.save
    calls = []

    def disk_full_on_second_save(self, path, *a, **kw):
        calls.append(path)
        if len(calls) == 2:
            Path(path).write_bytes(b"PK\x03\x04 truncated")  # what a full disk leaves
            raise OSError(28, "No space left on device")
        return real_save(self, path, *a, **kw)

    monkeypatch.setattr(PPO, "save", disk_full_on_second_save)
    out = tmp_path / "run"
    with pytest.raises(OSError, match="No space left"):
        train(toy_cfg(out, timesteps=1200, checkpoint_freq=200))
    monkeypatch.setattr(PPO, "save", real_save)
    names = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert len(names) == 1 and names[0].startswith("ppo_")  # the first one; no temporary left
    assert loads(out / "checkpoints" / names[0])


def _interrupted_run(out: Path) -> Path:
    """A toy run with checkpoints and no final model (as after an interrupt)."""
    train(toy_cfg(out, timesteps=800, checkpoint_freq=300))
    (out / "run.json").unlink()
    (out / "final_model.zip").unlink()
    return find_latest_checkpoint(out)


def test_resume_latest_skips_checkpoints_that_do_not_load(tmp_path, capsys):
    out = tmp_path / "run"
    good = _interrupted_run(out)
    ckpts = out / "checkpoints"
    (ckpts / "ppo_99999_steps.zip").write_bytes(b"")  # SIGKILL while saving (before the fix)
    (ckpts / "ppo_5000_steps.zip").write_bytes(good.read_bytes()[:300])  # a full disk
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(ckpts / "ppo_4000_steps.zip", "w") as dst:
        for item in src.infolist():  # a corrupt policy.pth inside a well-formed zip
            data = b"not torch" if item.filename == "policy.pth" else src.read(item)
            dst.writestr(item, data)
    capsys.readouterr()
    final = train(toy_cfg(out, timesteps=1200, resume="latest"))
    assert json.loads((out / "run.json").read_text())["resumed_from"] == str(good)
    assert loads(final)
    err = capsys.readouterr().err
    for name in ("ppo_99999_steps.zip", "ppo_5000_steps.zip", "ppo_4000_steps.zip"):
        assert f"skipping checkpoint {ckpts / name}: it does not load" in err
    # an explicit checkpoint that does not load is a clear error, not a traceback
    assert main(["train", "--out", str(out), "--resume", str(ckpts / "ppo_5000_steps.zip")]) == 2
    assert "does not load" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------
# 2. resuming a finished run trains nothing and touches nothing (unless asked for more)
# --------------------------------------------------------------------------------------------


def test_resume_latest_of_a_finished_run_touches_nothing(tmp_path, capsys):
    config = toy_yaml(tmp_path, checkpoint_freq=300)
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--env-id", TOY, "--out", str(out)]) == 0
    before = snapshot(out)
    capsys.readouterr()
    # the run's own timesteps (600, recorded in its config.yaml) are done: nothing to do
    assert main(["train", "--env-id", TOY, "--out", str(out), "--resume", "latest"]) == 0
    assert "holds a finished run" in capsys.readouterr().err
    assert snapshot(out) == before
    # asked for more: it continues from the final model, not from the last checkpoint
    args = ["train", "--env-id", TOY, "--out", str(out), "--resume", "latest"]
    assert main([*args, "--timesteps", "1000"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["resumed_from"] == str(out / "final_model.zip") and info["num_timesteps"] >= 1000


# --------------------------------------------------------------------------------------------
# 3. two trainings into one folder: the second fails at once
# --------------------------------------------------------------------------------------------


def test_a_second_run_into_a_locked_folder_fails_at_once(tmp_path, capsys):
    config = toy_yaml(tmp_path, timesteps=10_000_000)
    out = tmp_path / "run"
    first = popen_train(tmp_path, "--config", str(config), "--out", str(out))
    try:
        wait_for(lambda: (out / "logs" / "progress.csv").is_file())
        t0 = time.monotonic()
        rc = main(["train", "--config", str(config), "--env-id", TOY, "--out", str(out)])
        assert rc == 2 and time.monotonic() - t0 < 10
        assert f"in use by another training run (pid {first.pid})" in capsys.readouterr().err
        assert main(["train", "--env-id", TOY, "--out", str(out), "--resume", "latest"]) == 2
        assert "in use by another training run" in capsys.readouterr().err
    finally:
        first.send_signal(signal.SIGINT)
        _, err = first.communicate(timeout=60)
    assert first.returncode == 130, err
    assert b"\x00" not in (out / "logs" / "progress.csv").read_bytes()
    assert loads(find_latest_checkpoint(out))


# --------------------------------------------------------------------------------------------
# 4. a fresh run into a folder with an older run is refused; resume uses the run's settings
# --------------------------------------------------------------------------------------------


def test_a_fresh_run_into_an_old_run_folder_is_refused(tmp_path, capsys):
    config = toy_yaml(tmp_path, checkpoint_freq=300)
    out = tmp_path / "run"
    (out / "eval").mkdir(parents=True)
    (out / "eval" / "notes.txt").write_text("mine")  # not a run output: left alone
    base = ["train", "--config", str(config), "--env-id", TOY, "--out", str(out)]
    assert main(base) == 0
    before = snapshot(out)
    capsys.readouterr()
    assert main([*base, "--seed", "3"]) == 2
    err = capsys.readouterr().err
    assert "already holds a finished run" in err and "--overwrite" in err and "--resume" in err
    assert snapshot(out) == before
    assert main([*base, "--seed", "3", "--overwrite", "--resume", "latest"]) == 2
    assert "contradict" in capsys.readouterr().err

    # the settings file changes after the run started: a resumed run keeps its own settings
    toy_yaml(tmp_path, checkpoint_freq=300, env={"n_uavs": 2, "max_steps": 12})
    assert main([*base, "--resume", "latest", "--timesteps", "900"]) == 0
    resumed = next(out.glob("config_resumed_at_*.yaml"))
    assert yaml.safe_load(resumed.read_text())["env"] == {"n_uavs": 3, "max_steps": 12}
    # ... and refuses to continue in another environment
    assert main([*base, "--resume", "latest", "--timesteps", "2000", "--n-uavs", "2"]) == 2
    assert "cannot resume" in capsys.readouterr().err

    assert main([*base, "--seed", "3", "--overwrite"]) == 0  # replaces the run
    assert yaml.safe_load((out / "config.yaml").read_text())["seed"] == 3
    assert not list(out.glob("config_resumed_at_*.yaml"))  # the old run's files are gone
    assert (out / "eval" / "notes.txt").read_text() == "mine"


def test_out_that_is_a_file_or_read_only_is_a_clear_error(tmp_path, capsys):
    config = toy_yaml(tmp_path)
    target = tmp_path / "afile"
    target.write_text("x")
    assert main(["train", "--config", str(config), "--env-id", TOY, "--out", str(target)]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        assert main(["train", "--config", str(config), "--env-id", TOY, "--out", str(ro)]) == 2
        assert "not writable" in capsys.readouterr().err
    finally:
        ro.chmod(0o700)


# --------------------------------------------------------------------------------------------
# 6. interrupts: handlers before any work, a checkpoint in every phase
# --------------------------------------------------------------------------------------------


def test_sigterm_during_the_warm_start_saves_a_checkpoint(tmp_path):
    """SIGTERM in the behaviour-cloning warm start: exit 143 after saving (today: killed,
    no checkpoint)."""
    pretrain = {"policy": "random", "episodes": 2, "epochs": 1_000_000}
    config = toy_yaml(tmp_path, pretrain=pretrain)
    out = tmp_path / "run"
    proc = popen_train(tmp_path, "--config", str(config), "--out", str(out))
    try:
        wait_for_line(proc, "behaviour-cloning warm start", timeout_s=60)
        time.sleep(0.5)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "interrupted during the behaviour-cloning warm start" in err
    assert loads(out / "checkpoints" / "ppo_0_steps.zip")


def test_interrupt_before_the_first_periodic_checkpoint_saves_one(tmp_path):
    """--timesteps below checkpoint_freq: Ctrl-C still leaves a checkpoint that loads."""
    config = toy_yaml(tmp_path, checkpoint_freq=100_000_000)
    out = tmp_path / "run"
    proc = popen_train(
        tmp_path, "--config", str(config), "--out", str(out), "--timesteps", "50000000"
    )
    try:
        wait_for(lambda: (out / "logs" / "progress.csv").is_file())
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "saved the policy after" in err
    assert loads(find_latest_checkpoint(out))


# --------------------------------------------------------------------------------------------
# issue 35: one learning curve over interrupts and resumes; no interrupt inside a step
# --------------------------------------------------------------------------------------------


def _sigint_on_update(monkeypatch, *calls: int) -> None:
    """Send SIGINT during PPO's update number ``calls`` (counted from 1) of this session."""
    from stable_baselines3 import PPO

    real = PPO.train
    seen = [0]

    def update(self):
        seen[0] += 1
        if seen[0] in calls:
            os.kill(os.getpid(), signal.SIGINT)
        return real(self)

    monkeypatch.setattr(PPO, "train", update)


def test_progress_csv_keeps_every_iteration_over_interrupts_and_resumes(tmp_path, monkeypatch):
    """Interrupt, kill (the interrupt checkpoint removed), resume twice: logs/progress.csv
    holds every iteration once, in order (today each resumed session wrote another file and
    progress.csv kept the rows after the checkpoint that the resumed run trained again)."""
    config = toy_yaml(tmp_path, timesteps=1920, checkpoint_freq=384)  # 192 agent-steps a rollout
    out = tmp_path / "run"
    args = ["train", "--config", str(config), "--env-id", TOY, "--out", str(out)]
    _sigint_on_update(monkeypatch, 7)  # interrupted after 1344 agent-steps
    assert main(args) == 130
    (out / "checkpoints" / "ppo_1344_steps.zip").unlink()  # as if killed: resumes at 1152
    monkeypatch.undo()
    _sigint_on_update(monkeypatch, 2)  # interrupted after 1536
    assert main([*args, "--resume", "latest"]) == 130
    monkeypatch.undo()
    assert main([*args, "--resume", "latest"]) == 0
    text = (out / "logs" / "progress.csv").read_text().splitlines()
    col = text[0].split(",").index("time/total_timesteps")
    steps = [int(float(line.split(",")[col])) for line in text[1:]]
    assert steps == list(range(192, 1921, 192))
    assert not list((out / "logs").glob("progress_*.csv"))


def _interrupt_inside_step(monkeypatch, at_call: int) -> dict[str, int]:
    """SIGINT while the toy env's step runs (the stand-in for a compiled call): returns the
    counts of steps started and finished."""
    from tests.training.toy_env import ToyParallelEnv

    real = ToyParallelEnv.step
    calls = {"started": 0, "finished": 0}

    def step(self, actions):
        calls["started"] += 1
        if calls["started"] == at_call:
            os.kill(os.getpid(), signal.SIGINT)
        result = real(self, actions)
        calls["finished"] += 1
        return result

    monkeypatch.setattr(ToyParallelEnv, "step", step)
    return calls


@pytest.mark.parametrize("phase", ["warm start", "PPO"])
def test_sigint_inside_a_step_is_taken_after_it(tmp_path, monkeypatch, capsys, phase):
    """An interrupt that arrives inside an environment step (in the real env: a numba call,
    where it ended in ``SystemError: CPUDispatcher(...)`` with no checkpoint) is taken after
    the step: the step completes, a checkpoint is saved, exit 130."""
    pretrain = {"policy": "random", "episodes": 3, "epochs": 2} if phase == "warm start" else None
    config = toy_yaml(tmp_path, pretrain=pretrain)
    out = tmp_path / "run"
    calls = _interrupt_inside_step(monkeypatch, at_call=5 if phase == "warm start" else 100)
    assert main(["train", "--config", str(config), "--env-id", TOY, "--out", str(out)]) == 130
    assert calls["started"] >= 5 and calls["finished"] == calls["started"]
    err = capsys.readouterr().err
    assert "interrupted during" in err and "continue with --resume latest" in err
    assert loads(find_latest_checkpoint(out))
    if phase == "warm start":
        assert "interrupted during the behaviour-cloning warm start" in err


def test_resume_of_a_finished_model_or_below_its_checkpoint_is_said(tmp_path, capsys):
    """An explicit --resume of a finished run's final model touches nothing (today: run.json
    rewritten with 0 agent-steps/s); --timesteps below the checkpoint's steps is refused
    (today: 0 steps trained silently and the run marked finished)."""
    config = toy_yaml(tmp_path, checkpoint_freq=192)
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--env-id", TOY, "--out", str(out)]) == 0
    before = snapshot(out)
    capsys.readouterr()
    args = ["train", "--env-id", TOY, "--out", str(out)]
    assert main([*args, "--resume", str(out / "final_model.zip")]) == 0
    assert "holds a finished run (768 agent-steps); nothing to do" in capsys.readouterr().err
    assert snapshot(out) == before
    (out / "run.json").unlink()
    (out / "final_model.zip").unlink()
    assert main([*args, "--resume", "latest", "--timesteps", "200"]) == 2
    assert "--timesteps 200 is below the 576 agent-steps of the checkpoint" in (
        capsys.readouterr().err
    )
    assert not (out / "final_model.zip").exists()


def test_training_refuses_render_modes(tmp_path, capsys):
    config = toy_yaml(tmp_path)
    args = ["train", "--config", str(config), "--env-id", TOY, "--out", str(tmp_path / "r")]
    assert main([*args, "--env-set", "render_mode=human"]) == 2
    assert "training does not render" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


# --------------------------------------------------------------------------------------------
# 5. a failed write (file-size limit) leaves the earlier reports and figures intact
# --------------------------------------------------------------------------------------------


REPRO_TINY = ["--set", "n_epochs=2", "--set", "n_samples=2", "--set", "n_samples_sweep=2"]


def _limited(limit_bytes: int):
    def preexec() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes fail with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return preexec


def _coopnav(args: list[str], limit_bytes: int | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "coopnav_env.training.cli", *args],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limited(limit_bytes) if limit_bytes else None,
    )


@pytest.mark.parametrize(
    ("command", "first_only"),
    [
        (
            ["evaluate", "--policies", "random", "--env-id", TOY, "--env-set", "n_uavs=3"],
            ["--episodes", "4"],
        ),
        (
            [
                "reproduce",
                "--quick",
                "--no-sensitivity",
                "--no-progress",
                "--set",
                "n_epochs=2",
                "--set",
                "n_samples=2",
                "--set",
                "n_samples_sweep=2",
            ],
            ["--seed", "1"],
        ),
    ],
    ids=["evaluate", "reproduce"],
)
def test_a_failed_rewrite_keeps_the_earlier_outputs(tmp_path, command, first_only):
    """Rerunning into a folder under a file-size limit: each file is either the earlier
    version or a complete new one (today's code left truncated reports and figures)."""
    out = tmp_path / "out"
    first = _coopnav([*command, *first_only, "--out", str(out)])
    assert first.returncode == 0, first.stderr
    before = {k: v[0] for k, v in snapshot(out).items()}
    limit = 8192
    assert any(len(data) > limit for data in before.values())
    rerun = ["--overwrite"]  # other settings (issue 35)
    again = _coopnav([*command, *rerun, "--out", str(out)], limit_bytes=limit)
    assert again.returncode == 1, again.stderr  # a failure of the system, not of usage
    assert "File too large" in again.stderr and "Traceback" not in again.stderr
    reference = _coopnav([*command, "--out", str(tmp_path / "reference")])  # no limit
    new = {k: v[0] for k, v in snapshot(tmp_path / "reference").items()}
    after = {k: v[0] for k, v in snapshot(out).items()}
    assert after.keys() == before.keys() and reference.returncode == 0
    for name, data in after.items():  # never a truncated file
        assert data == before[name] or complete(name, data, new[name]), name
    kept = [n for n in after if after[n] == before[n] != new[n]]
    assert kept  # the write that failed left the earlier version


def complete(name: str, data: bytes, reference: bytes) -> bool:
    """Whether ``data`` is a whole file of its kind (``reference``: one written without a
    limit; reports differ from it only in their timings)."""
    if name.endswith(".json"):
        try:
            json.loads(data)
        except ValueError:
            return False
        return True
    if name.endswith(".png"):
        return data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82")
    if name.endswith(".npz"):
        try:
            with zipfile.ZipFile(io.BytesIO(data)) as z:
                return z.testzip() is None
        except zipfile.BadZipFile:
            return False
    return data.endswith(b"\n") and data.count(b"\n") == reference.count(b"\n")
