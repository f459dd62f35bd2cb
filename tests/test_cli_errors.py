"""Bad invocations of ``coopnav`` end in a clear one-line message, never a traceback (issue 15).

Each row is one bad invocation: the exit status it must give (2: a usage error; argparse's
own errors are 2 as well), a fragment of the message that names the setting or the file, and
no ``Traceback`` on stderr. ``--debug`` (or ``COOPNAV_DEBUG=1``) shows the traceback.
Invocations are run in this process (``coopnav_env.training.cli.main``); none of them starts
training.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

from coopnav_env.training.cli import main
from tests.training.toy_env import TOY_ENV_ID, TOY_TRAINING

ROOT = Path(__file__).resolve().parents[1]

TOY = TOY_ENV_ID
TOY_SECTION = TOY_TRAINING


_V1 = "urban_canyon_v1"

#: (id, argv with {tmp} placeholders, exit status, message fragment)
CASES: list[tuple[str, list[str], int, str]] = [
    # configuration files and --set / --env-set values
    ("yaml-config-malformed", ["train", "--config", "{tmp}/bad.yaml"], 2, "not valid YAML"),
    ("yaml-config-missing", ["train", "--config", "{tmp}/none.yaml"], 2, "not found"),
    ("yaml-config-list", ["train", "--config", "{tmp}/list.yaml"], 2, "must be a mapping"),
    ("yaml-section-list", ["train", "--config", "{tmp}/section.yaml"], 2, "must be a mapping"),
    ("yaml-set-malformed", ["train", "--set", "ppo.n_steps=[1,"], 2, "not valid YAML"),
    ("yaml-env-set-malformed", ["train", "--env-set", "city={a"], 2, "not valid YAML"),
    ("set-no-equals", ["train", "--set", "timesteps"], 2, "key=value"),
    # issue 35, finding 12: a bad --set value is an error even where a flag replaces it
    (
        "set-timesteps-abc-flag",
        ["train", "{toy}", "--set", "timesteps=abc", "--timesteps", "64"],
        2,
        "timesteps must be an integer, got 'abc'",
    ),
    (
        "set-seed-neg-flag",
        ["train", "{toy}", "--set", "seed=-3", "--seed", "1"],
        2,
        "seed must be in [0,",
    ),
    ("env-list", ["train", "--set", "env=[1,2]"], 2, "env must be a mapping"),
    ("ppo-list", ["train", "--set", "ppo=[1]"], 2, "ppo must be a mapping"),
    ("unknown-setting", ["train", "--set", "bogus=1"], 2, "unknown training setting"),
    # SB3 settings SB3 rejects late (or not at all)
    ("lr-abc", ["train", "--set", "ppo.learning_rate=abc"], 2, "ppo.learning_rate must be"),
    ("lr-zero", ["train", "--set", "ppo.learning_rate=0"], 2, "ppo.learning_rate must be"),
    ("n-steps-0", ["train", "--set", "ppo.n_steps=0"], 2, "ppo.n_steps must be an integer"),
    ("batch-size-neg", ["train", "--set", "ppo.batch_size=-1"], 2, "ppo.batch_size must be"),
    ("n-epochs-1.5", ["train", "--set", "ppo.n_epochs=1.5"], 2, "ppo.n_epochs must be"),
    ("gamma-2", ["train", "--set", "ppo.gamma=2"], 2, "ppo.gamma must be a number in (0, 1]"),
    ("gae-lambda", ["train", "--set", "ppo.gae_lambda=-0.1"], 2, "ppo.gae_lambda must be"),
    ("clip-range-0", ["train", "--set", "ppo.clip_range=0"], 2, "ppo.clip_range must be"),
    ("ent-coef-nan", ["train", "--set", "ppo.ent_coef=.nan"], 2, "ppo.ent_coef must be"),
    ("net-arch-abc", ["train", "--set", "ppo.policy_kwargs.net_arch=abc"], 2, "net_arch must"),
    ("net-arch-0", ["train", "--set", "ppo.policy_kwargs.net_arch=[0]"], 2, "net_arch must"),
    ("net-arch-top", ["train", "--set", "ppo.net_arch=[64]"], 2, "unknown PPO setting"),
    ("activation", ["train", "--set", "ppo.policy_kwargs.activation_fn=relu"], 2, "class"),
    ("policy-kw", ["train", "--set", "ppo.policy_kwargs.foo=1"], 2, "policy_kwargs setting"),
    ("policy-name", ["train", "--set", "ppo.policy=Foo"], 2, "ppo.policy must be one of"),
    ("device-foo", ["train", "--set", "device=foo"], 2, "device must be a PyTorch device"),
    ("log-std", ["train", "--set", "ppo.policy_kwargs.log_std_init=x"], 2, "log_std_init"),
    # run settings
    ("timesteps-neg", ["train", "--timesteps", "-1"], 2, "timesteps must be >= 1"),
    ("timesteps-abc", ["train", "--timesteps", "abc"], 2, "invalid int value"),
    ("seed-neg", ["train", "--seed", "-1"], 2, "seed must be in [0,"),
    ("seed-huge", ["train", "--seed", "1000000"], 2, "seed must be in [0,"),
    ("n-envs-0", ["train", "--n-envs", "0"], 2, "n_envs must be >= 1"),
    ("num-cpus-neg", ["train", "--num-cpus", "-1"], 2, "num_cpus must be >= 0"),
    ("threads-0", ["train", "--set", "torch_threads=0"], 2, "torch_threads must be >= 1"),
    ("verbose-5", ["train", "--verbose", "5"], 2, "verbose must be in [0, 2]"),
    ("ckpt-freq-neg", ["train", "--checkpoint-freq", "-1"], 2, "checkpoint_freq must be"),
    ("n-envs-abc", ["train", "--set", "n_envs=abc"], 2, "n_envs must be an integer"),
    ("batched-cpus", ["train", "--vec-env", "batched", "--num-cpus", "2"], 2, "num_cpus"),
    ("vec-env-bad", ["train", "--vec-env", "fast"], 2, "invalid choice"),
    ("backend-bad", ["train", "--backend", "jax"], 2, "invalid choice"),
    ("pretrain-0", ["train", "--set", "pretrain.episodes=0"], 2, "pretrain.episodes"),
    ("normalize", ["train", "--set", "normalize_reward=maybe"], 2, "normalize_reward"),
    ("render-mode", ["train", "--env-set", "render_mode=human"], 2, "does not render"),
    ("env-unknown", ["train", "--env-set", "bogus=1"], 2, "bogus"),
    ("n-uavs-0", ["train", "--n-uavs", "0"], 2, "n_uavs"),
    ("runners-sb3", ["train", "--num-env-runners", "2"], 2, "only apply to --backend rllib"),
    ("runners-neg", ["train", "--backend", "rllib", "--num-env-runners", "-1"], 2, ">= 0"),
    ("overwrite-resume", ["train", "--overwrite", "--resume", "latest"], 2, "contradict"),
    # run folders and checkpoints
    ("out-is-file", ["train", "--out", "{tmp}/afile", "{toy}"], 2, "is a file"),
    ("resume-missing", ["train", "--resume", "{tmp}/nope.zip", "{toy}"], 2, "not found"),
    ("resume-none", ["train", "--resume", "latest", "{toy}"], 2, "no checkpoint to resume"),
    ("resume-corrupt", ["train", "--resume", "{tmp}/corrupt.zip", "{toy}"], 2, "does not load"),
    ("resume-empty", ["train", "--resume", "{tmp}/empty.zip", "{toy}"], 2, "does not load"),
    # coopnav evaluate
    ("eval-policy", ["evaluate", "--policies", "nope"], 2, "unknown policy 'nope'"),
    ("eval-episodes-0", ["evaluate", "--episodes", "0"], 2, "episodes must be >= 1"),
    ("eval-seed-start", ["evaluate", "--seed-start", "5"], 2, "evaluation seeds must be"),
    ("eval-seeds-neg", ["evaluate", "--seeds", "-1"], 2, "--seeds must be >= 0"),
    ("eval-ppo-missing", ["evaluate", "--policies", "ppo:{tmp}/nope.zip"], 2, "nope.zip"),
    ("eval-ppo-corrupt", ["evaluate", "--policies", "ppo:{tmp}/corrupt.zip"], 2, "corrupt.zip"),
    ("eval-ppo-empty", ["evaluate", "--policies", "ppo:{tmp}/empty.zip"], 2, "empty.zip"),
    ("eval-train-cfg", ["evaluate", "--train-config", "{tmp}/none.yaml"], 2, "not found"),
    ("eval-train-bad", ["evaluate", "--train-config", "{tmp}/bad.yaml"], 2, "not valid YAML"),
    ("eval-env-set", ["evaluate", "--env-set", "n_uavs=[1"], 2, "not valid YAML"),
    ("eval-n-uavs", ["evaluate", "--n-uavs", "0", "--episodes", "1"], 2, "n_uavs"),
    ("eval-option", ["evaluate", "--policies", "waypoint@foo=1"], 2, "bad option"),
    (
        "eval-out-file",
        [
            "evaluate",
            "--policies",
            "random",
            "--out",
            "{tmp}/afile",
            "--env-id",
            TOY,
            "--episodes",
            "1",
            "--no-plots",
        ],
        2,
        "afile",
    ),
    # coopnav reproduce
    ("repro-set", ["reproduce", "--out", "{tmp}/r", "--set", "n_epochs=abc"], 2, "n_epochs"),
    ("repro-key", ["reproduce", "--out", "{tmp}/r", "--set", "bogus=1"], 2, "unknown --set key"),
    ("repro-set-eq", ["reproduce", "--out", "{tmp}/r", "--set", "bogus"], 2, "KEY=VALUE"),
    ("repro-seed", ["reproduce", "--out", "{tmp}/r", "--seed", "-1"], 2, "seed"),
    ("repro-config", ["reproduce", "--out", "{tmp}/r", "--config", "{tmp}/none.json"], 2, "none"),
    ("repro-json", ["reproduce", "--out", "{tmp}/r", "--config", "{tmp}/bad.yaml"], 2, "JSON"),
    (
        "repro-json-list",
        ["reproduce", "--out", "{tmp}/r", "--config", "{tmp}/list.json"],
        2,
        "JSON object",
    ),
    (
        "repro-out-file",
        ["reproduce", "--out", "{tmp}/afile", "--quick", "--no-progress"],
        2,
        "afile",
    ),
    ("repro-no-out", ["reproduce"], 2, "--out"),
    # coopnav demo
    ("demo-epochs-0", ["demo", "--epochs", "0"], 2, "--epochs"),
    ("demo-epochs-neg", ["demo", "--epochs", "-3"], 2, "--epochs"),
    ("demo-dt-nan", ["demo", "--dt", "nan"], 2, "--dt"),
    ("demo-dt-inf", ["demo", "--dt", "inf"], 2, "--dt"),
    ("demo-dt-0", ["demo", "--dt", "0"], 2, "--dt"),
    ("demo-seed-neg", ["demo", "--seed", "-1"], 2, "--seed"),
    ("demo-epochs-abc", ["demo", "--epochs", "abc"], 2, "invalid int value"),
    # issue 45, findings 4 and 5: an --env-id that cannot apply is refused, naming the run's
    ("env-id-empty", ["train", "--env-id", ""], 2, "--env-id is empty"),
    ("eval-env-id-empty", ["evaluate", "--policies", "random", "--env-id", ""], 2, "is empty"),
    (
        "resume-other-env-id",
        ["train", "--resume", "latest", "--env-id", "urban_canyon_v1", "--out", "{tmp}/v0run"],
        2,
        "holds a run of urban_canyon_v0 (its config.yaml), which --resume continues in",
    ),
    (
        "eval-other-env-id",
        ["evaluate", "--policies", "ppo:{tmp}/v0run/final_model.zip", "--env-id", _V1],
        2,
        "the policies' training run is a run of urban_canyon_v0",
    ),
    (
        "eval-train-config-other-env-id",
        ["evaluate", "--train-config", "{tmp}/v0run/config.yaml", "--env-id", "urban_canyon_v1"],
        2,
        "v0run/config.yaml says env_id: urban_canyon_v0); evaluate them in urban_canyon_v0",
    ),
    # issue 45, finding 6: a backend's section given for another backend is refused
    (
        "torchrl-set-with-sb3",
        ["train", "--set", "torchrl.start_hold_decisions=-1"],
        2,
        "--set torchrl.start_hold_decisions=-1: torchrl.* settings apply to --backend torchrl",
    ),
    ("rllib-set-with-sb3", ["train", "--set", "rllib.num_env_runners=2"], 2, "--backend rllib"),
    # issue 45, finding 10: duplicates and an option larger than the set it takes from
    (
        "alignment-policy-twice",
        ["alignment", "--policies", "column", "column", "sky_column", "--out", "{tmp}/al"],
        2,
        "--policies: 'column' given twice",
    ),
    (
        "alignment-setting-twice",
        ["alignment", "--policies", "random", "column", "sky_column", "--settings", "v1", "v1"],
        2,
        "--settings: 'v1' given twice",
    ),
    # the command itself
    ("no-such-command", ["fly"], 2, "invalid choice"),
]


@pytest.fixture
def files(tmp_path):
    """The files the invocations name: malformed YAML/JSON, a file, damaged checkpoints."""
    (tmp_path / "bad.yaml").write_text("urban_canyon_v1: [unclosed\n  timesteps: 3\n")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    (tmp_path / "section.yaml").write_text("urban_canyon_v1: [1, 2]\n")
    (tmp_path / "list.json").write_text("[1, 2]\n")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "v0run").mkdir()  # a run of urban_canyon_v0 (its settings as recorded)
    v0_settings = {"env_id": "urban_canyon_v0", "env": {"nav_reward": "sigma"}, "timesteps": 64}
    (tmp_path / "v0run" / "config.yaml").write_text(yaml.safe_dump(v0_settings))
    (tmp_path / "empty.zip").write_bytes(b"")
    with zipfile.ZipFile(tmp_path / "corrupt.zip", "w") as z:  # SB3's layout, broken weights
        z.writestr("data", "{}")
        z.writestr("policy.pth", b"not torch")
        z.writestr("pytorch_variables.pth", b"")
    (tmp_path / "toy.yaml").write_text(yaml.safe_dump({TOY: TOY_SECTION}))
    # run folders with a damaged record: run.json a JSON list; a train-routes run's episodes
    (tmp_path / "listrun").mkdir()
    (tmp_path / "listrun" / "final_model.zip").write_bytes(b"PK")
    (tmp_path / "listrun" / "run.json").write_text("[1, 2]\n")
    (tmp_path / "routes_list").mkdir()
    (tmp_path / "routes_list" / "run.json").write_text("[1, 2]\n")
    from studies.route_choice.routes import ROUTE_FEATURES

    settings = {"env": {}, "base": "ceiling_column", "first_seed": 500_000, "episodes": 5}
    settings |= {"max_turns": 3, "features": list(ROUTE_FEATURES)}
    for name in ("routes_npz_bad", "routes_npz_keys"):
        (tmp_path / name).mkdir()
        record = {"settings": settings, "status": "collecting"}
        (tmp_path / name / "run.json").write_text(json.dumps(record))
    (tmp_path / "routes_npz_bad" / "episodes.npz").write_bytes(b"PK\x03\x04 truncated")
    with open(tmp_path / "routes_npz_keys" / "episodes.npz", "wb") as fh:
        np.savez(fh, seed=np.arange(3))
    return tmp_path


def _argv(template: list[str], tmp) -> list[str]:
    argv = []
    for item in template:
        if item == "{toy}":
            argv += ["--config", str(tmp / "toy.yaml"), "--env-id", TOY]
        else:
            argv.append(item.replace("{tmp}", str(tmp)))
    if argv[0] == "train-routes" and "--out" not in argv:
        argv += ["--out", str(tmp / "routes")]
    if argv[0] == "train":
        if "--out" not in argv:
            argv += ["--out", str(tmp / "run")]
        # should a row pass validation after all, it trains for seconds, not an hour
        safe = ["--set", "pretrain=null"] + ([] if "--timesteps" in argv else ["--timesteps", "64"])
        argv = [argv[0], *safe, *argv[1:]]
    return argv


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # argparse's own usage errors
        return int(exc.code)


@pytest.mark.parametrize(
    ("argv", "code", "message"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_invocation_ends_in_a_clear_message(files, capsys, argv, code, message):
    rc = _run(_argv(argv, files))
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert rc == code, err
    assert message in err, err
    lines = [line for line in err.splitlines() if line.startswith("coopnav ")]
    if "invalid" not in message and "--out" != message:
        assert lines and len(lines[-1]) > len("coopnav x: error: "), err  # one line, ours


def test_case_count():
    """The table the closing note of issue 15 quotes (kept honest by this test)."""
    assert len(CASES) == len({c[0] for c in CASES}) >= 80


def test_debug_shows_the_traceback(files, capsys, monkeypatch):
    argv = _argv(["train", "--set", "ppo.gamma=2"], files)
    with pytest.raises(ValueError, match=r"ppo\.gamma"):
        main([*argv, "--debug"])
    with pytest.raises(ValueError, match=r"ppo\.gamma"):
        main(["--debug", *argv])
    monkeypatch.setenv("COOPNAV_DEBUG", "1")
    with pytest.raises(ValueError, match=r"ppo\.gamma"):
        main(argv)
    monkeypatch.setenv("COOPNAV_DEBUG", "0")
    assert main(argv) == 2
    capsys.readouterr()


# --------------------------------------------------------------------------------------------
# issue 35, finding 5: YAML 1.1 reads off/on/yes/no as booleans
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("prefix", ["", "env.", "torchrl.env."])
@pytest.mark.parametrize("word", ["off", "on", "yes", "no", "true", "false", "Off"])
def test_a_word_setting_gets_the_text_as_typed(prefix, word):
    """``integrity``/``nlos_exclusion`` take words: ``--env-set integrity=off`` means "off"
    (YAML alone would read False); a boolean setting still reads the YAML boolean."""
    from coopnav_env.training.config import apply_overrides

    items = [f"{prefix}integrity={word}", f"{prefix}nlos_exclusion={word}"]
    items.append(f"{prefix}dead_reckoning_noise={word}")
    out = apply_overrides({}, items)
    for part in prefix.split(".")[:-1]:
        out = out[part]
    assert out["integrity"] == word and out["nlos_exclusion"] == word
    assert out["dead_reckoning_noise"] is (word.lower() in ("on", "yes", "true"))


def test_integrity_off_from_the_command_line_switches_a_presets_integrity_off():
    from coopnav_env.envs.config import make_config
    from studies.route_choice.route_learning import env_kwargs_from_overrides

    on = make_config(**env_kwargs_from_overrides(["preset=urban_nlos_3dma"]))
    assert on.integrity == "fde" and on.nlos_exclusion == "map"
    kwargs = env_kwargs_from_overrides(
        ["preset=urban_nlos_3dma", "integrity=off", "nlos_exclusion=off", "dead_reckoning_noise=no"]
    )
    cfg = make_config(**kwargs)
    assert (cfg.integrity, cfg.nlos_exclusion, cfg.dead_reckoning_noise) == ("off", "off", False)
    # a word the setting does not take is named as typed, with the allowed words
    for word in ("on", "yes", "true"):
        with pytest.raises(ValueError, match=rf"integrity must be one of .*'raim'.*got '{word}'"):
            env_kwargs_from_overrides([f"integrity={word}"])


def test_evaluate_accepts_env_set_integrity_off(capsys):
    argv = ["evaluate", "--policies", "nope", "--env-set", "preset=urban_nlos_3dma"]
    argv += ["--env-set", "integrity=off", "--env-set", "nlos_exclusion=off"]
    assert _run([*argv, "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert "got False" not in err and "unknown policy 'nope'" in err, err  # env built


# --------------------------------------------------------------------------------------------
# issue 45, finding 2: Ctrl-C at start-up (the subcommands' imports) ends in one line
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("command", ["train", "evaluate"])
def test_an_interrupt_while_starting_ends_in_one_line(monkeypatch, capsys, command):
    """SIGINT while the subcommands' modules are imported: status 130, one line."""
    import importlib

    from coopnav_env.training import cli

    real = importlib.import_module

    def interrupted(name, *args, **kwargs):
        if name == cli.COMMANDS[command][0]:
            raise KeyboardInterrupt
        return real(name, *args, **kwargs)

    monkeypatch.setattr(cli.importlib, "import_module", interrupted)
    assert main([command, "--help"]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.strip() == "coopnav: interrupted while starting; nothing was done", err


def test_an_interrupt_in_a_command_ends_in_one_line(monkeypatch, capsys):
    """SIGINT while ``coopnav evaluate`` runs (before it wrote anything): 130 and one line."""
    from coopnav_env.training import evaluate_cli

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(evaluate_cli, "run", interrupted)
    assert main(["evaluate", "--policies", "random"]) == 130
    err = capsys.readouterr().err
    assert err.strip() == "coopnav evaluate: interrupted", err


def test_start_hold_decisions_must_leave_decisions_to_learn(files, capsys):
    """issue 45, finding 6: holding every decision of an episode learns nothing."""
    pytest.importorskip("torchrl")
    argv = ["train", "--backend", "torchrl", "--env-id", "urban_canyon_v1"]
    argv += ["--set", "env.action_frame=route", "--set", "torchrl.start_hold_decisions=1000000"]
    argv += ["--set", "torchrl.pretrain=null", "--out", str(files / "hold")]
    assert _run(_argv(argv, files)) == 2
    err = capsys.readouterr().err
    assert "torchrl.start_hold_decisions must be < the decisions of an episode" in err, err
    assert "got 1000000" in err and not (files / "hold").exists()


def _sigint_by_default() -> None:
    """In the child before it runs: SIGINT to its default disposition, so that Python installs
    its own handler whatever the test runner inherited (a shell starting a job in the
    background, ``cmd &``, has it ignored, and Python then leaves it ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _sigint_ignored() -> None:
    """In the child before it runs: SIGINT ignored, as a shell leaves it for ``cmd &``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_child(argv: list[str], start=_sigint_by_default) -> subprocess.CompletedProcess:
    return subprocess.run(
        argv, capture_output=True, text=True, timeout=300, cwd=ROOT, preexec_fn=start
    )


def _python(code: str) -> subprocess.CompletedProcess:
    return _run_child([sys.executable, "-c", code])


def test_an_interrupt_while_the_command_loads_the_package_is_one_line():
    """As the ``coopnav`` command, Ctrl-C while ``coopnav_env`` loads (before ``main`` runs)
    ends with one line and status 130; ``main`` then restores Python's own handling."""
    loading = (
        "import os, signal, sys, time\n"
        "sys.argv[0] = '/venv/bin/coopnav'\n"
        "import coopnav_env\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(30)\n"
    )
    res = _python(loading)
    assert res.returncode == 128 + signal.SIGINT, res.stderr
    assert res.stderr.strip() == "coopnav: interrupted while starting; nothing was done"
    after = (
        "import signal, sys\n"
        "sys.argv[0] = 'coopnav'\n"
        "from coopnav_env.training.cli import main\n"
        "main([])\n"
        "assert signal.getsignal(signal.SIGINT) is signal.default_int_handler\n"
    )
    assert _python(after).returncode == 0


def test_a_command_started_with_the_interrupt_ignored_keeps_it_ignored():
    """``nohup coopnav train ... &``: the shell has the command ignore SIGINT. Neither the
    package's start-up handling nor ``main`` installs a handler over that, so a Ctrl-C meant
    for the shell's foreground job does not reach the background run."""
    code = (
        "import os, signal, sys, time\n"
        "sys.argv[0] = '/venv/bin/coopnav'\n"
        "import coopnav_env\n"
        "assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN\n"
        "from coopnav_env.training.cli import main\n"
        "main([])\n"
        "assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(0.2)\n"
    )
    res = _run_child([sys.executable, "-c", code], start=_sigint_ignored)
    assert res.returncode == 0, res.stderr
    assert "interrupted" not in res.stderr, res.stderr


def test_a_worker_process_of_the_command_keeps_python_s_interrupt_handling():
    """A worker that ``multiprocessing`` spawns gets the command's ``sys.argv``; importing the
    package there leaves SIGINT to Python (the command's parent handles the interrupt)."""
    code = (
        "import multiprocessing as mp, signal, sys\n"
        "def handler_is_python_s():\n"
        "    import coopnav_env\n"
        "    return signal.getsignal(signal.SIGINT) is signal.default_int_handler\n"
        "if __name__ == '__main__':\n"
        "    sys.argv[0] = 'coopnav'\n"
        "    with mp.get_context('spawn').Pool(1) as pool:\n"
        "        assert pool.apply(handler_is_python_s)\n"
    )
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "worker_probe.py"
        path.write_text(code)
        res = _run_child([sys.executable, str(path)])
    assert res.returncode == 0, res.stderr


def test_importing_the_library_leaves_the_interrupt_handler_alone():
    code = (
        "import signal\n"
        "import coopnav_env, coopnav_env.training.cli\n"
        "assert signal.getsignal(signal.SIGINT) is signal.default_int_handler\n"
    )
    res = _python(code)
    assert res.returncode == 0, res.stderr
