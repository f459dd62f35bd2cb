"""Word settings in a settings file keep the text as typed (issue 35, finding 5).

YAML 1.1 reads an unquoted ``off``/``on``/``yes``/``no`` as a boolean, so ``integrity: off``
in the ``env`` section of a ``--config`` file was refused ("got False"). A setting that takes
words gets the word, as ``--env-set integrity=off`` does; every other boolean stays one.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coopnav_env.envs.config import make_config
from coopnav_env.training.cli import build_parser, main
from coopnav_env.training.config import TrainConfig, load_config, parse_settings_yaml
from coopnav_env.training.runs import recorded_config
from coopnav_env.training.train import config_from_args

SECTION = """\
urban_canyon_v1:
  timesteps: 64
  progress_bar: no
  env:
    preset: urban_nlos_3dma
    integrity: {word}
    nlos_exclusion: {word}
    dead_reckoning_noise: {word}
  torchrl:
    hidden: [16]
    env:
      integrity: {word}
      nlos_exclusion: {word}
      obs_protection_level: {word}
"""


def _config_file(tmp_path: Path, word: str = "off") -> Path:
    path = tmp_path / "train.yaml"
    path.write_text(SECTION.format(word=word))
    return path


@pytest.mark.parametrize("word", ["off", "Off", "on", "yes", "no", "true", "False"])
def test_a_word_setting_in_a_config_file_gets_the_text_as_typed(tmp_path, word):
    section = load_config(_config_file(tmp_path, word))
    flag = word.lower() in ("on", "yes", "true")
    for env in (section["env"], section["torchrl"]["env"]):
        assert env["integrity"] == word and env["nlos_exclusion"] == word
    # a boolean setting, and a boolean outside the environment, still read as booleans
    assert section["env"]["dead_reckoning_noise"] is flag
    assert section["torchrl"]["env"]["obs_protection_level"] is flag
    assert section["progress_bar"] is False and section["timesteps"] == 64


def test_integrity_off_in_a_config_file_switches_a_presets_integrity_off(tmp_path):
    args = build_parser().parse_args(
        ["train", "--config", str(_config_file(tmp_path)), "--out", str(tmp_path / "run")]
    )
    cfg = config_from_args(args)
    assert isinstance(cfg, TrainConfig)
    env = make_config(**cfg.env)
    assert (env.integrity, env.nlos_exclusion, env.dead_reckoning_noise) == ("off", "off", False)
    torchrl_env = make_config(**{**cfg.env, **cfg.torchrl["env"]})
    assert (torchrl_env.integrity, torchrl_env.nlos_exclusion) == ("off", "off")
    # a word the setting does not take is refused, named as typed
    args.config = str(_config_file(tmp_path, "yes"))
    with pytest.raises(ValueError, match=r"integrity must be one of .*got 'yes'"):
        make_config(**config_from_args(args).env)


def test_a_runs_config_and_evaluates_train_config_read_words_too(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("env:\n  integrity: off\n  nlos_exclusion: off\n")
    assert recorded_config(run)["env"] == {"integrity": "off", "nlos_exclusion": "off"}
    config = tmp_path / "config.yaml"
    config.write_text("env:\n  preset: urban_nlos_3dma\n  integrity: off\n  nlos_exclusion: off\n")
    argv = ["evaluate", "--policies", "nope", "--train-config", str(config), "--episodes", "1"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "got False" not in err and "unknown policy 'nope'" in err, err  # env built


def test_a_settings_file_that_is_not_yaml_names_the_file():
    with pytest.raises(ValueError, match=r"train.yaml is not valid YAML \(line 2"):
        parse_settings_yaml("env: [1,\n", "train.yaml")
    assert parse_settings_yaml("a: [yes, {env: {integrity: no}}]\nyes: 1\n", "x") == {
        "a": [True, {"env": {"integrity": "no"}}],
        True: 1,
    }
