"""Packaged training configurations (``coopnav train --config NAME``) and the packaged settings
in one file per backend.

``mappo_route`` and ``mappo_route_scratch`` must resolve to exactly the settings of the runs
they reproduce, the committed policies of ``studies/task_objective`` (their ``config.yaml``
and ``run.json``): the environment, every TorchRL setting and the warm start, seed by seed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
from pathlib import Path

import pytest
import yaml

from coopnav_env.agents.marl_nets import REMOVED_SETTINGS, MARLSettings
from coopnav_env.envs.config import V1_DEFAULTS
from coopnav_env.training import train
from coopnav_env.training.config import (
    CONFIG_DIR,
    TORCHRL_GROUPS,
    TrainConfig,
    load_config,
    named_configs,
)
from coopnav_env.training.torchrl_backend import pretrain_of, settings_of

ROOT = Path(__file__).resolve().parents[2]
POLICIES = ROOT / "studies" / "task_objective" / "policies"
RUNS = {
    "mappo_route": "mappo_route_hold_unweighted_bc_8m_s{}",
    "mappo_route_scratch": "mappo_route_hold_unweighted_8m_s{}",
}
ITERATION = 16 * 32 * 4 * 5  # agent-steps: copies x decisions x action_repeat x UAVs


def _config(*argv: str) -> TrainConfig:
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    return train.config_from_args(parser.parse_args(list(argv)))


def _without_removed(d: dict) -> dict:
    return {k: v for k, v in d.items() if k not in REMOVED_SETTINGS}


def test_the_named_configurations_are_listed_with_what_they_train() -> None:
    named = named_configs()
    assert set(RUNS) <= set(named)
    assert all(re.search(r"\(urban_canyon_v1, \d+M agent-steps\)$", a) for a in named.values())
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    text = " ".join(parser.format_help().split())
    for name in RUNS:
        assert f"{name}: {named[name]}" in text


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name", sorted(RUNS))
def test_a_named_configuration_resolves_to_the_settings_of_its_committed_run(
    name, seed, tmp_path
) -> None:
    folder = POLICIES / RUNS[name].format(seed)
    recorded = yaml.safe_load((folder / "config.yaml").read_text())
    run = json.loads((folder / "run.json").read_text())
    cfg = _config("--config", name, "--seed", str(seed), "--out", str(tmp_path / "run"))
    # the trainer: every TorchRL setting as recorded (less the removed switches), held starts
    # logged with the actor's own log-probability ("unweighted"), the kept behaviour
    assert recorded["torchrl"]["start_hold_objective"] == "unweighted"
    assert cfg.torchrl == _without_removed(recorded["torchrl"])
    settings, env_kwargs = settings_of(cfg)
    # (with the settings added after these runs at their defaults: no dual clip)
    assert dataclasses.asdict(settings) == {**_without_removed(run["settings"]), "dual_clip": None}
    # the environment it trains in, as config.yaml and run.json record it, with v1's
    # crash-free start (V1_DEFAULTS), which v1 gained after these runs were trained
    assert recorded["env"] == run["env"] and "crash_free_steps" not in run["env"]
    assert env_kwargs == {**recorded["env"], "crash_free_steps": V1_DEFAULTS["crash_free_steps"]}
    # the warm start (or none)
    warm = pretrain_of(cfg)
    if run["warm_start"] is None:
        assert warm is None and recorded["torchrl"]["pretrain"] is None
    else:
        got = (warm.policy, warm.policy_kwargs, warm.episodes, warm.epochs, warm.learning_rate)
        ws = run["warm_start"]
        want = (ws["teacher"], ws["policy_kwargs"], ws["episodes"], ws["epochs"])
        assert got == (*want, ws["learning_rate"])
    # the run's own settings; the budget is the 8M of the resumed run
    for key in ("env_id", "backend", "seed", "checkpoint_freq", "torch_threads", "device"):
        assert getattr(cfg, key) == recorded[key], key
    assert cfg.timesteps == 8_000_000
    assert 0 <= run["agent_steps"] - cfg.timesteps < ITERATION


def test_set_and_flags_change_single_settings_of_a_named_configuration(tmp_path) -> None:
    base = _config("--config", "mappo_route", "--out", str(tmp_path / "a"))
    changed = _config(
        "--config",
        "mappo_route",
        "--set",
        "torchrl.action_repeat=2",
        "--env-set",
        "max_steps=150",
        "--timesteps",
        "20480",
        "--out",
        str(tmp_path / "b"),
    )
    assert changed.torchrl == {**base.torchrl, "action_repeat": 2}
    assert changed.env == {**base.env, "max_steps": 150}
    assert changed.timesteps == 20480 and base.timesteps == 8_000_000
    # scratch is the same run without the warm start
    scratch = _config("--config", "mappo_route_scratch", "--out", str(tmp_path / "c"))
    assert scratch.torchrl == {**base.torchrl, "pretrain": None}
    assert scratch.env == base.env


def test_a_named_configuration_refuses_another_environment_and_unknown_names() -> None:
    with pytest.raises(ValueError, match="'mappo_route' trains urban_canyon_v1, not urban_can"):
        load_config("mappo_route", "urban_canyon_v0")
    with pytest.raises(
        FileNotFoundError, match="packaged configurations: mappo_families_scratch, mappo_route"
    ):
        load_config("mappo_rout")
    with pytest.raises(FileNotFoundError, match="not found"):
        load_config("no/such/file.yaml")


@pytest.mark.parametrize("env_id", ["urban_canyon_v0", "urban_canyon_v1"])
def test_the_packaged_settings_are_one_file_per_backend_in_groups(env_id) -> None:
    files = {p.name for p in CONFIG_DIR.glob("*.yaml")}
    assert files == {"run.yaml", "sb3.yaml", "rllib.yaml", "torchrl.yaml"}
    sections = {n: yaml.safe_load((CONFIG_DIR / n).read_text())[env_id] for n in files}
    # SB3's settings and the run's are disjoint, and the backends' keys go where they belong
    assert not set(sections["run.yaml"]) & set(sections["sb3.yaml"])
    assert "ppo" in sections["sb3.yaml"] and "ppo" in sections["rllib.yaml"]
    grouped = sections["torchrl.yaml"]
    fields = {f.name for f in dataclasses.fields(MARLSettings)}
    seen: list[str] = []
    for group in TORCHRL_GROUPS:
        assert set(grouped[group]) <= fields, group  # every entry of a group is a setting
        seen += list(grouped[group])
    assert len(seen) == len(set(seen))  # the groups are disjoint
    assert set(grouped) <= {*TORCHRL_GROUPS, "pretrain", "env"}
    # composed, the groups are one namespace (`--set torchrl.learning_rate=...`)
    section = load_config(env_id=env_id)
    assert set(section["torchrl"]) == set(seen) | (set(grouped) - set(TORCHRL_GROUPS))
    assert section["rllib"] == sections["rllib.yaml"]
    assert section["ppo"] == sections["sb3.yaml"]["ppo"]
    MARLSettings.from_dict(
        {k: v for k, v in section["torchrl"].items() if k not in ("env", "pretrain")}
    )
    TrainConfig.from_dict({**section, "out": "x"})


def test_every_packaged_settings_file_is_package_data() -> None:
    import fnmatch
    import re

    text = (ROOT / "pyproject.toml").read_text()
    line = re.search(r'^"coopnav_env\.training" = (\[.*\])$', text, re.MULTILINE)
    assert line is not None, "pyproject.toml names no package data of coopnav_env.training"
    patterns = json.loads(line.group(1))
    files = [p.relative_to(CONFIG_DIR.parent).as_posix() for p in CONFIG_DIR.rglob("*.yaml")]
    assert any(f.startswith("configs/recipes/") for f in files)
    for f in files:
        assert any(fnmatch.fnmatch(f, pat) for pat in patterns), f
