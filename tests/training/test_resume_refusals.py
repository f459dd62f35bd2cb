"""A resume refused before training leaves its --out as it found it (issue 45, finding 9).

One tiny TorchRL run (2 UAVs, 2 swarm copies, 4 steps per rollout, seconds); its final
checkpoint, with one weight matrix of another shape than its settings make, is resumed.
"""

from __future__ import annotations

import warnings

import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from coopnav_env.training.cli import main  # noqa: E402

TINY = ["--backend", "torchrl", "--env-set", "n_uavs=2", "--set", "torchrl.n_copies=2"]
TINY += ["--set", "torchrl.rollout_steps=4", "--set", "torchrl.epochs=1", "--no-progress"]
TINY += ["--set", "torchrl.pretrain=null"]


def test_a_checkpoint_that_does_not_fit_is_named_and_leaves_no_run(tmp_path, capsys):
    torch.set_num_threads(1)
    run = tmp_path / "run"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        args = ["--timesteps", "16", "--set", "torchrl.hidden=[16,16]"]
        assert main(["train", "--out", str(run), *TINY, *args]) == 0
    d = torch.load(run / "final_model.pt", weights_only=True)
    name = next(k for k, v in d["actor"].items() if v.ndim == 2)
    d["actor"][name] = torch.zeros(3, 3)  # a weight of another shape
    wrong = tmp_path / "wrong_shape.pt"
    torch.save(d, wrong)
    capsys.readouterr()
    new = tmp_path / "new" / "run"
    argv = ["train", "--out", str(new), *TINY, "--timesteps", "64", "--resume", str(wrong)]
    assert main([*argv, "--set", "torchrl.hidden=[16,16]"]) == 2
    err = capsys.readouterr().err
    assert f"cannot resume from {wrong}: the checkpoint does not fit the networks" in err, err
    assert not (tmp_path / "new").exists()  # no config.yaml, logs/ nor lock left behind
    # into the run's own folder: its config_resumed_at_*.yaml is not left behind either
    before = sorted(p.name for p in run.rglob("*") if p.name != ".coopnav.lock")
    argv = ["train", "--out", str(run), *TINY, "--timesteps", "64", "--resume", str(wrong)]
    assert main([*argv, "--set", "torchrl.hidden=[16,16]"]) == 2
    assert sorted(p.name for p in run.rglob("*") if p.name != ".coopnav.lock") == before
