"""An output folder belongs to one command (issue 35, finding 3).

``learning_study.py`` and ``coopnav evaluate`` claim their ``--out`` before any work, the way
``coopnav train`` and ``route_learning.py`` (``studies/route_choice``) do: another command's
folder, a training run, a result
of other settings and a finished result are refused with a message naming what the folder
holds; ``--overwrite`` replaces a report (never a training run); a second command into a
locked folder fails at once; a rerun after an interrupt is taken. The flights are replaced by
a stub where only the claim is under test (a study that flies would take minutes).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from coopnav_env.training.cli import main
from coopnav_env.training.files import CLAIM_NAME, claim_output_folder, folder_lock
from studies.learning_in_default_setting import learning_study
from studies.route_choice import route_learning

STUDY = ["--heuristics", "formation", "--episodes", "1", "--planner-episodes", "0"]
STUDY += ["--reps", "20"]
EVALUATE = ["evaluate", "--policies", "formation", "--episodes", "1", "--no-plots"]
EVALUATE += ["--env-set", "n_uavs=2"]


@pytest.fixture
def no_flights(monkeypatch):
    """The study's flying and writing replaced: it records the call and writes a report."""
    calls: list[Path] = []

    def fake(args, groups, env_kwargs, seeds, units, out, t0):
        calls.append(out)
        (out / "report.json").write_text("{}")
        (out / "report.md").write_text("# study\n")
        (out / "errors.png").write_bytes(b"png")
        return [out / "report.json", out / "report.md", out / "errors.png"]

    monkeypatch.setattr(learning_study, "_fly_and_report", fake)
    return calls


def _never_fly(monkeypatch) -> None:
    """Make any flight of the study fail the test (the claim must come first)."""

    def fly(*a, **kw):
        raise AssertionError("the study flew episodes before checking --out")

    monkeypatch.setattr(learning_study, "_fly_all", fly)


def test_study_refuses_an_evaluate_folder_before_flying(tmp_path, capsys, monkeypatch):
    out = tmp_path / "shared"
    assert main([*EVALUATE, "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert "report.json" in before
    _never_fly(monkeypatch)
    capsys.readouterr()
    assert learning_study.main([*STUDY, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out} holds the outputs of `coopnav evaluate`" in err and "--overwrite" in err
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert after == before  # the evaluation's report untouched


def test_evaluate_refuses_a_study_folder_and_overwrite_replaces_it(tmp_path, capsys, no_flights):
    out = tmp_path / "shared"
    assert learning_study.main([*STUDY, "--out", str(out)]) == 0 and no_flights == [out]
    claim = json.loads((out / CLAIM_NAME).read_text())
    assert claim["command"] == "learning_study.py" and claim["status"] == "finished"
    assert claim["outputs"] == ["errors.png", "report.json", "report.md"]
    capsys.readouterr()
    assert main([*EVALUATE, "--out", str(out)]) == 2
    assert "holds the outputs of `learning_study.py`" in capsys.readouterr().err
    assert (out / "report.md").read_text() == "# study\n"
    # --overwrite: the study's outputs go, the evaluation's come, nothing mixed
    assert main([*EVALUATE, "--out", str(out), "--overwrite"]) == 0
    assert "# Policy evaluation" in (out / "report.md").read_text()
    claim = json.loads((out / CLAIM_NAME).read_text())
    assert claim["command"] == "coopnav evaluate" and claim["status"] == "finished"
    assert "replacing learning_study.py's outputs" in capsys.readouterr().err
    names = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert names == sorted([CLAIM_NAME, *claim["outputs"]]) and "errors.png" not in names


def test_a_failed_overwrite_keeps_the_earlier_outputs(tmp_path, capsys, no_flights, monkeypatch):
    """The outputs an --overwrite replaces stay until the new command finishes."""
    out = tmp_path / "study"
    assert learning_study.main([*STUDY, "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.name != CLAIM_NAME}

    def interrupted(*a, **kw):
        raise KeyboardInterrupt

    from coopnav_env.training import evaluate_cli

    with monkeypatch.context() as patch:
        patch.setattr(evaluate_cli, "evaluate", interrupted)  # Ctrl-C during the episodes
        assert main([*EVALUATE, "--out", str(out), "--overwrite"]) == 130
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.name != CLAIM_NAME}
    assert after == before  # the evaluation's warm-up ran; nothing of the study was removed
    claim = json.loads((out / CLAIM_NAME).read_text())
    assert claim["status"] == "running" and "errors.png" in claim["replacing"]
    # the same evaluation again takes it (no --overwrite needed) and finishes the replacement
    assert main([*EVALUATE, "--out", str(out)]) == 0
    assert not (out / "errors.png").exists()


@pytest.mark.parametrize("kind", ["file", "training run", "foreign files", "old report"])
def test_study_checks_out_before_flying_any_episode(tmp_path, capsys, monkeypatch, kind):
    out = tmp_path / "out"
    if kind == "file":
        out.write_text("x")
        message = "is a file"
    else:
        out.mkdir()
        name = {
            "training run": "final_model.zip",
            "foreign files": "notes.txt",
            "old report": "report.json",  # a committed report of an older version
        }[kind]
        (out / name).write_text("x")
        message = "holds a training run" if kind == "training run" else "already holds files"
    _never_fly(monkeypatch)
    assert learning_study.main([*STUDY, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    if kind == "training run":  # never replaced, not even with --overwrite
        assert learning_study.main([*STUDY, "--out", str(out), "--overwrite"]) == 2
        assert "--overwrite never removes a training run" in capsys.readouterr().err
        assert (out / "final_model.zip").read_text() == "x"


def test_study_rerun_rules(tmp_path, capsys, no_flights):
    out = tmp_path / "study"
    assert learning_study.main([*STUDY, "--out", str(out)]) == 0
    # a finished study with the same settings: a rerun could lose it
    assert learning_study.main([*STUDY, "--out", str(out)]) == 2
    assert "holds the finished result of `learning_study.py` with these settings" in (
        capsys.readouterr().err
    )
    # other settings: refused, naming the setting that differs
    assert learning_study.main([*STUDY, "--score", "nav", "--out", str(out)]) == 2
    assert "result of other settings (score)" in capsys.readouterr().err
    assert len(no_flights) == 1
    assert learning_study.main([*STUDY, "--score", "nav", "--out", str(out), "--overwrite"]) == 0
    assert json.loads((out / CLAIM_NAME).read_text())["settings"]["score"] == "nav"
    # an interrupted study (claimed, not finished) is taken again by the same command
    record = json.loads((out / CLAIM_NAME).read_text())
    (out / CLAIM_NAME).write_text(json.dumps({**record, "status": "running", "outputs": []}))
    assert learning_study.main([*STUDY, "--score", "nav", "--out", str(out)]) == 0
    assert len(no_flights) == 3


def test_a_locked_folder_is_refused_at_once(tmp_path, capsys, monkeypatch):
    out = tmp_path / "busy"
    out.mkdir()
    _never_fly(monkeypatch)
    with folder_lock(out):  # as a running study, evaluation or training holds it
        assert learning_study.main([*STUDY, "--out", str(out)]) == 2
        assert "is in use by another coopnav command (pid" in capsys.readouterr().err
        assert main([*EVALUATE, "--out", str(out)]) == 2
        assert "is in use by another coopnav command" in capsys.readouterr().err


def test_train_routes_locks_its_folder_and_refuses_a_report_folder(tmp_path, capsys, no_flights):
    routes = ["--episodes", "5", "--jobs", "1"]
    busy = tmp_path / "busy"
    busy.mkdir()
    with folder_lock(busy):
        assert route_learning.main([*routes, "--out", str(busy)]) == 2
        assert "is in use by another coopnav command" in capsys.readouterr().err
    assert not (busy / "run.json").exists()
    study = tmp_path / "study"
    assert learning_study.main([*STUDY, "--out", str(study)]) == 0
    assert route_learning.main([*routes, "--out", str(study)]) == 2
    assert "is not a train-routes run folder" in capsys.readouterr().err


def test_a_failed_command_leaves_its_claim_unfinished(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="boom"):
        with claim_output_folder(out, "learning_study.py", {"a": 1}, outputs=["report.*"]):
            raise RuntimeError("boom")
    assert json.loads((out / CLAIM_NAME).read_text())["status"] == "running"
    with claim_output_folder(out, "learning_study.py", {"a": 1}, outputs=["report.*"]) as claim:
        (out / "report.md").write_text("x")
        claim.finish([out / "report.md"])
    with pytest.raises(ValueError, match="finished result"):
        with claim_output_folder(out, "learning_study.py", {"a": 1}, outputs=["report.*"]):
            pass


def test_study_default_out_is_no_committed_folder_and_help_says_models_are_pickles(capsys):
    import argparse

    parser = argparse.ArgumentParser()
    learning_study.add_arguments(parser)
    assert parser.get_default("out") == "runs/study"
    help_text = " ".join(parser.format_help().split())
    assert "is a pickle: loading it runs code from it" in help_text


# --------------------------------------------------------------------------------------------
# coopnav train refuses another command's folder, as study and evaluate refuse a training run
# --------------------------------------------------------------------------------------------


def _toy_train(tmp_path: Path, out: Path, *extra: str) -> int:
    """``coopnav train`` of a few seconds on the toy environment (SB3) into ``out``."""
    pytest.importorskip("stable_baselines3")
    import yaml

    from tests.training.toy_env import TOY_ENV_ID, TOY_TRAINING

    config = tmp_path / "toy.yaml"
    config.write_text(yaml.safe_dump({TOY_ENV_ID: TOY_TRAINING}))
    argv = ["train", "--config", str(config), "--env-id", TOY_ENV_ID, "--out", str(out)]
    return main([*argv, *extra])


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name[0] != "."}


@pytest.mark.parametrize("extra", [[], ["--overwrite"], ["--resume", "latest"]])
def test_train_refuses_a_study_folder_naming_it(tmp_path, capsys, no_flights, extra):
    out = tmp_path / "shared"
    assert learning_study.main([*STUDY, "--out", str(out)]) == 0
    before = _files(out)
    capsys.readouterr()
    assert _toy_train(tmp_path, out, *extra) == 2
    err = capsys.readouterr().err
    assert f"{out} holds the outputs of `learning_study.py` ({CLAIM_NAME})" in err, err
    assert "choose another --out" in err
    assert _files(out) == before  # nothing written, nothing removed
    assert not (out / "config.yaml").exists() and not (out / "checkpoints").exists()


@pytest.mark.parametrize("command", ["coopnav evaluate", "coopnav reproduce"])
def test_train_refuses_a_folder_claimed_by_another_command(tmp_path, capsys, command):
    out = tmp_path / "shared"
    with claim_output_folder(out, command, {"a": 1}, outputs=["report.*"]) as claim:
        (out / "report.md").write_text("# report\n")
        claim.finish([out / "report.md"])
    before = _files(out)
    assert _toy_train(tmp_path, out, "--overwrite") == 2
    assert f"holds the outputs of `{command}`" in capsys.readouterr().err
    assert _files(out) == before


@pytest.mark.parametrize("name", ["route_model.json", "episodes.npz", "settings.json"])
def test_train_refuses_a_route_run_or_a_studys_flights(tmp_path, capsys, name):
    """A train-routes run holds a ``run.json`` too: --overwrite used to remove it (and
    --resume to read it as a training run's)."""
    out = tmp_path / "routes"
    out.mkdir()
    (out / "run.json").write_text(json.dumps({"settings": {}, "status": "collecting"}))
    (out / name).write_bytes(b"flights")
    before = _files(out)
    assert _toy_train(tmp_path, out, "--overwrite") == 2
    err = capsys.readouterr().err
    assert f"holds the run of another command ({name}" in err and "train-routes" in err, err
    assert _files(out) == before


def test_train_takes_its_own_folder_and_train_routes_names_the_claim(tmp_path, capsys):
    """The refusal is of other commands only: a run folder of train is still trained in (the
    rules for one's own run are tested in test_run_safety.py); train-routes refuses a train
    run and a claimed folder, naming the command."""
    out = tmp_path / "run"
    assert _toy_train(tmp_path, out) == 0
    assert not (out / CLAIM_NAME).exists()
    before = _files(out)
    capsys.readouterr()
    assert route_learning.main(["--episodes", "5", "--jobs", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "is not a train-routes run folder: it holds the outputs of `coopnav train`" in err
    assert _files(out) == before  # its run.json untouched
    claimed = tmp_path / "evaluated"
    with claim_output_folder(claimed, "coopnav evaluate", {}, outputs=["report.*"]):
        pass
    routes = ["--episodes", "5", "--jobs", "1", "--out", str(claimed)]
    assert route_learning.main(routes) == 2
    err = capsys.readouterr().err
    assert "is not a train-routes run folder: it holds the outputs of `coopnav evaluate`" in err


# --------------------------------------------------------------------------------------------
# coopnav reproduce claims its --out too
# --------------------------------------------------------------------------------------------

REPRODUCE = ["reproduce", "--quick", "--no-sensitivity", "--no-figures", "--no-progress"]
REPRODUCE += ["--set", "n_epochs=2", "--set", "n_samples=2", "--set", "n_samples_sweep=2"]


def _never_reproduce(monkeypatch) -> None:
    """Make the reproduction's simulation fail the test (the claim must come first)."""
    from coopnav_env.reproduction import cli as reproduce_cli

    def simulate(*a, **kw):
        raise AssertionError("coopnav reproduce simulated before checking --out")

    monkeypatch.setattr(reproduce_cli, "run_studies", simulate)


def test_reproduce_refuses_another_commands_folder_before_any_work(
    tmp_path, capsys, no_flights, monkeypatch
):
    study = tmp_path / "study"
    assert learning_study.main([*STUDY, "--out", str(study)]) == 0
    before = _files(study)
    _never_reproduce(monkeypatch)
    capsys.readouterr()
    assert main([*REPRODUCE, "--out", str(study)]) == 2
    err = capsys.readouterr().err
    assert f"{study} holds the outputs of `learning_study.py`" in err and "--overwrite" in err
    assert _files(study) == before
    trained = tmp_path / "trained"
    trained.mkdir()
    (trained / "final_model.zip").write_text("x")
    assert main([*REPRODUCE, "--out", str(trained), "--overwrite"]) == 2
    assert "--overwrite never removes a training run" in capsys.readouterr().err
    assert _files(trained) == {"final_model.zip": b"x"}
    busy = tmp_path / "busy"
    busy.mkdir()
    with folder_lock(busy):
        assert main([*REPRODUCE, "--out", str(busy)]) == 2
        assert "is in use by another coopnav command" in capsys.readouterr().err


def test_reproduce_claims_its_folder_and_overwrite_replaces_an_old_result(tmp_path, capsys):
    """As the committed reproduction (docs/reproduction): files of an older version without
    a claim are refused; --overwrite replaces the command's outputs and keeps the rest."""
    out = tmp_path / "reproduction"
    out.mkdir()
    (out / "README.md").write_text("# the page\n")
    (out / "results.json").write_text("{}")
    (out / "fig6_skyplot.png").write_bytes(b"old figure")
    assert main([*REPRODUCE, "--out", str(out)]) == 2
    assert "already holds files of no `coopnav reproduce` run" in capsys.readouterr().err
    assert (out / "results.json").read_text() == "{}"
    assert main([*REPRODUCE, "--out", str(out), "--overwrite"]) == 0
    claim = json.loads((out / CLAIM_NAME).read_text())
    assert claim["command"] == "coopnav reproduce" and claim["status"] == "finished"
    assert claim["outputs"] == ["config.json", "report.md", "results.json"]
    assert claim["settings"]["seed"] == 0 and "progress" not in claim["settings"]
    names = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert names == sorted([CLAIM_NAME, "README.md", *claim["outputs"]])  # old figure gone
    assert (out / "README.md").read_text() == "# the page\n"
    assert json.loads((out / "results.json").read_text())["config"]["seed"] == 0
    # a finished reproduction: the same configuration (with or without a progress bar) and
    # another one are refused, naming what differs
    capsys.readouterr()
    again = [a for a in REPRODUCE if a != "--no-progress"]
    assert main([*again, "--out", str(out)]) == 2
    assert "holds the finished result of `coopnav reproduce`" in capsys.readouterr().err
    assert main([*REPRODUCE, "--seed", "1", "--out", str(out)]) == 2
    assert "result of other settings (seed)" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------
# coopnav alignment claims its --out too
# --------------------------------------------------------------------------------------------

ALIGNMENT = ["alignment", "--policies", "formation", "wide", "--episodes", "2"]


@pytest.fixture
def no_alignment_flights(monkeypatch):
    """The alignment's flights replaced by a fixed report (only the claim is under test)."""
    from coopnav_env.training import alignment as alignment_module

    calls: list[tuple] = []

    class Report:
        def to_markdown(self) -> str:
            return "| policy | score |\n"

        def to_json(self) -> dict:
            return {"rows": []}

    def fake(*args, **kw):
        calls.append(args)
        return Report()

    monkeypatch.setattr(alignment_module, "alignment", fake)
    return calls


def test_alignment_claims_its_folder(tmp_path, capsys, no_flights, no_alignment_flights):
    study = tmp_path / "study"
    assert learning_study.main([*STUDY, "--out", str(study)]) == 0
    capsys.readouterr()
    assert main([*ALIGNMENT, "--out", str(study)]) == 2
    assert f"{study} holds the outputs of `learning_study.py`" in capsys.readouterr().err
    assert no_alignment_flights == []  # refused before any flight
    # --overwrite replaces the study's outputs instead of mixing the two reports
    assert main([*ALIGNMENT, "--out", str(study), "--overwrite"]) == 0
    claim = json.loads((study / CLAIM_NAME).read_text())
    assert claim["command"] == "coopnav alignment" and claim["status"] == "finished"
    names = sorted(p.name for p in study.iterdir() if not p.name.startswith("."))
    assert names == [CLAIM_NAME, "report.json", "report.md"]  # the study's errors.png gone
    assert main([*ALIGNMENT, "--out", str(study)]) == 2
    assert "finished result of `coopnav alignment`" in capsys.readouterr().err
    trained = tmp_path / "trained"
    trained.mkdir()
    (trained / "final_model.zip").write_text("x")
    assert main([*ALIGNMENT, "--out", str(trained), "--overwrite"]) == 2
    assert "holds a training run" in capsys.readouterr().err
    assert _files(trained) == {"final_model.zip": b"x"} and len(no_alignment_flights) == 1


# --------------------------------------------------------------------------------------------
# issue 45, finding 3: a command refused before it wrote anything leaves --out as it was
# --------------------------------------------------------------------------------------------


def _tree(root: Path) -> dict[str, bytes | None]:
    return {
        str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None)
        for p in sorted(root.rglob("*"))
    }


@pytest.mark.parametrize(
    "refused",
    [
        ["evaluate", "--policies", "bogus", "--episodes", "1", "--no-plots"],
        ["study", "--heuristics", "bogus", "--episodes", "1", "--planner-episodes", "0"],
        ["alignment", "--policies", "bogus", "column", "--episodes", "1"],
    ],
    ids=["evaluate", "study", "alignment"],
)
def test_a_refused_command_leaves_no_claim(tmp_path, capsys, refused):
    """A refused policy name: no folder (nor its parents), and a present folder unchanged
    (``study``: the learning study's script)."""
    if refused[0] == "study":
        refused = refused[1:]
        run = learning_study.main
    else:
        run = main
    out = tmp_path / "new" / "out"
    assert run([*refused, "--out", str(out)]) == 2
    assert "bogus" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    # a folder that holds a finished result of other settings keeps its claim as it was
    study = tmp_path / "study"
    study.mkdir()
    record = {"command": "coopnav study", "settings": {"a": 1}, "status": "finished"}
    (study / CLAIM_NAME).write_text(json.dumps(record))
    (study / "report.md").write_text("# study\n")
    before = _tree(study)
    assert run([*refused, "--out", str(study), "--overwrite"]) == 2
    assert _tree(study) == before


def test_a_refused_evaluation_does_not_block_the_next_one(tmp_path, capsys):
    out = tmp_path / "F"
    assert main([*EVALUATE[:2], "bogus", *EVALUATE[3:], "--out", str(out)]) == 2
    assert main([*EVALUATE, "--out", str(out)]) == 0, capsys.readouterr().err
    assert json.loads((out / CLAIM_NAME).read_text())["status"] == "finished"
