"""Evaluation that does not mislead (issue 16): settings said loudly, plots that explain."""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil

import numpy as np
import pytest

from coopnav_env.training.envs import heldout_seeds
from coopnav_env.training.eval_plots import (
    CDF_CAPTION,
    distance_along_route,
    error_cdf_figure,
    short_label,
    short_labels,
    trajectory_comparison_figure,
    trajectory_figure,
)
from coopnav_env.training.evaluate import EpisodeRecord, evaluate
from tests.training.toy_env import TOY_ENV_ID, TOY_TRAINING

pytest.importorskip("matplotlib")
HAS_ENV = importlib.util.find_spec("coopnav_env.urban_canyon_v0") is not None
TOY_ENV = {"n_uavs": 2, "max_steps": 6}


# --------------------------------------------------------------------------------------------
# labels and geometry
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "label"),
    [
        ("sky", "sky"),
        ("waypoint@altitude_m=28", "waypoint (tuned)"),
        ("waypoint@altitude_m=28,speed=3", "waypoint (tuned)"),
        ("ppo:runs/quick/final_model.zip", "ppo (quick)"),
        ("rllib:/abs/runs/big/final_model", "rllib (big)"),
        ("ppo:runs/quick/checkpoints/ppo_30000_steps.zip", "ppo (quick, ppo_30000_steps)"),
        ("mappo:runs/study/mappo_s0", "mappo (mappo_s0)"),
        ("ppo:model.zip", "ppo (model)"),
    ],
)
def test_short_labels(name: str, label: str) -> None:
    assert short_label(name) == label


def test_short_labels_stay_distinct() -> None:
    names = ["waypoint@altitude_m=28", "waypoint@altitude_m=15", "ppo:runs/a/final_model.zip"]
    assert short_labels(names) == {
        "waypoint@altitude_m=28": "waypoint@altitude_m=28",  # both would read "waypoint (tuned)"
        "waypoint@altitude_m=15": "waypoint@altitude_m=15",
        "ppo:runs/a/final_model.zip": "ppo (a)",
    }


def test_distance_along_an_l_shaped_route() -> None:
    route = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 20.0]])
    xy = np.array([[[-5.0, 1.0], [4.0, -2.0]], [[11.0, 15.0], [30.0, 50.0]]])
    np.testing.assert_allclose(distance_along_route(xy, route), [[0.0, 4.0], [25.0, 30.0]])


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------


def _inside(fig, ax, legend) -> bool:
    """Whether the legend's box overlaps the axes' data area (after drawing)."""
    fig.canvas.draw()
    a, b = ax.get_window_extent(), legend.get_window_extent()
    return a.overlaps(b)


def _record(collided: bool, goal: list[bool], pos: np.ndarray) -> EpisodeRecord:
    n = pos.shape[1]
    z = np.zeros((pos.shape[0] - 1, n))
    return EpisodeRecord(7, z, z, z, z, z, pos, np.array(goal), False, collided, 0.0, len(z))


def test_trajectory_figure_has_a_side_view_and_explains_its_markers() -> None:
    from tests.training.toy_env import ToyParallelEnv

    t = np.linspace(0.0, 1.0, 5)
    pos = np.stack([np.c_[3 * t, t, 10 + 5 * t], np.c_[2 * t, 0 * t, 12 - t]], axis=1)
    crash = trajectory_figure(ToyParallelEnv(2), _record(True, [False, False], pos), "x")
    top, side = crash.axes
    assert side.get_ylabel() == "altitude [m]"
    assert side.get_xlabel() == "horizontal distance flown [m]"  # the toy env has no route
    np.testing.assert_allclose(side.lines[0].get_ydata(), pos[:, 0, 2])  # altitudes of uav_0
    legend = crash.legends[0]
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts == ["uav_0", "uav_1", "start", "end: the episode ended in a crash"]
    assert not _inside(crash, top, legend) and not _inside(crash, side, legend)
    done = trajectory_figure(ToyParallelEnv(2), _record(False, [True, False], pos), "x")
    texts = [t.get_text() for t in done.legends[0].get_texts()]
    assert texts[2:] == ["start", "end: reached the goal area", "end: did not reach the goal area"]


def test_a_comparison_figure_puts_each_episode_in_its_column_on_one_altitude_scale() -> None:
    from tests.training.toy_env import ToyParallelEnv

    t = np.linspace(0.0, 1.0, 5)
    low = np.stack([np.c_[3 * t, t, 10 + 5 * t], np.c_[2 * t, 0 * t, 12 - t]], axis=1)
    high = low + np.array([0.0, 0.0, 40.0])
    panels = [
        ("rule", ToyParallelEnv(2), _record(False, [True, True], low)),
        ("learned", ToyParallelEnv(2), _record(True, [False, False], high)),
    ]
    fig = trajectory_comparison_figure(panels, "same episode")
    top_rule, top_learned, side_rule, side_learned = fig.axes
    assert top_rule.get_title().startswith("rule\n4 steps, 2 of 2 UAVs reached")
    assert top_learned.get_title() == "learned\n4 steps, ended by a crash"
    np.testing.assert_allclose(side_learned.lines[0].get_ydata(), high[:, 0, 2])
    assert side_rule.get_ylim() == side_learned.get_ylim()
    assert side_rule.get_ylim()[0] <= 11.0 and side_rule.get_ylim()[1] >= 55.0
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts == [
        "uav_0",
        "uav_1",
        "start",
        "end: the episode ended in a crash",
        "end: reached the goal area",
    ]
    assert fig._suptitle.get_text() == "same episode"
    with pytest.raises(ValueError, match="at least one"):
        trajectory_comparison_figure([])
    none = _record(False, [True, True], low)
    none.pos_enu_m = None
    with pytest.raises(ValueError, match="'rule' has no true positions"):
        trajectory_comparison_figure([("rule", ToyParallelEnv(2), none)])


@pytest.mark.skipif(not HAS_ENV, reason="urban_canyon_v0 not available")
def test_urban_trajectory_runs_along_the_planned_route() -> None:
    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env(n_uavs=2, max_steps=8)
    rep = evaluate(["sky"], heldout_seeds(1), {"n_uavs": 2, "max_steps": 8}, None, plots=False)
    fig = trajectory_figure(env, rep.episodes["sky"][0], "sky")
    side = fig.axes[1]
    assert side.get_xlabel() == "distance along the planned street route [m]"
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"goal", "planned route", "median building height", "start"} <= set(texts)
    env.close()


def test_cdf_says_why_curves_stop_below_one_and_labels_3_m() -> None:
    rep = evaluate(["random"], heldout_seeds(2), TOY_ENV, None, env_id=TOY_ENV_ID)
    fig = error_cdf_figure(rep.episodes, 3.0)
    ax = fig.axes[0]
    assert "without a fix counts as a failure" in CDF_CAPTION
    assert CDF_CAPTION in [t.get_text() for t in fig.texts]
    assert "3 m" in [t.get_text() for t in ax.texts]  # the label at the line
    legend = fig.legends[0]
    assert "3 m (the table's P(< 3 m))" in [t.get_text() for t in legend.get_texts()]
    assert not _inside(fig, ax, legend)


# --------------------------------------------------------------------------------------------
# which environment settings were used
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def toy_run(tmp_path_factory):
    pytest.importorskip("stable_baselines3")
    from coopnav_env.training.config import TrainConfig, load_config
    from coopnav_env.training.sb3_backend import train

    out = tmp_path_factory.mktemp("toy") / "run"
    data = {**load_config(), "env_id": TOY_ENV_ID, "out": str(out), **TOY_TRAINING}
    data.update(timesteps=100, env=dict(TOY_ENV))
    return train(TrainConfig.from_dict(data))


def _evaluate_cli(*argv: str) -> int:
    from coopnav_env.training import evaluate_cli as ev

    parser = argparse.ArgumentParser()
    ev.add_arguments(parser)
    return ev.run(parser.parse_args(["--episodes", "1", "--no-plots", *argv]))


def test_a_policy_without_its_run_settings_is_flagged(toy_run, tmp_path, capsys) -> None:
    lone = tmp_path / "lone" / "model.zip"
    lone.parent.mkdir()
    shutil.copy(toy_run, lone)
    out = tmp_path / "ev"
    assert (
        _evaluate_cli("--policies", f"ppo:{lone}", "--env-id", TOY_ENV_ID, "--out", str(out)) == 0
    )
    got = capsys.readouterr()
    assert "coopnav evaluate: warning: no config.yaml of a training run" in got.err
    assert f"ppo:{lone}" in got.err and "not comparable" in got.err
    head = got.out.splitlines()[0]
    assert head.startswith(f"Environment `{TOY_ENV_ID}`, settings `{{}}`")
    assert "NO config.yaml of the trained policy's run" in head
    assert head in (out / "report.md").read_text()  # the same header as the report's


def test_the_run_settings_are_named_in_the_header(toy_run, tmp_path, capsys) -> None:
    assert _evaluate_cli("--policies", "random", f"ppo:{toy_run}") == 0
    got = capsys.readouterr()
    assert "warning" not in got.err
    head = got.out.splitlines()[0]
    want = 'settings `{"n_uavs": 2, "max_steps": 6}` (all others at their defaults; from '
    assert want in head and str(toy_run.parent / "config.yaml") in head
    # an explicit --train-config is named, and a policy without a config.yaml is then fine
    config = toy_run.parent / "config.yaml"
    lone = tmp_path / "model.zip"
    shutil.copy(toy_run, lone)
    assert _evaluate_cli("--policies", f"ppo:{lone}", "--train-config", str(config)) == 0
    got = capsys.readouterr()
    assert "warning" not in got.err
    assert f"from --train-config {config}" in got.out.splitlines()[0]


@pytest.mark.skipif(not HAS_ENV, reason="urban_canyon_v0 not available")
def test_the_warning_names_thereward_settings() -> None:
    from coopnav_env.training.evaluate_cli import reward_settings

    text = reward_settings("urban_canyon_v0", {"n_uavs": 3, "collision_penalty": 7.0})
    assert "n_uavs=3" in text and "collision_penalty=7.0" in text
    assert "nav_reward='error'" in text and "max_steps=200" in text
    assert reward_settings("urban_canyon_v0", {"bogus": 1}) == ""  # the evaluation says why


def test_a_run_trained_on_a_city_pool_is_evaluated_on_unseen_cities(tmp_path, capsys) -> None:
    """The shipped families policy trained on ``city_pool: 200``: ``coopnav evaluate`` flies
    it on cities drawn from every seed and says so; ``--env-set`` may name a pool again."""
    policy = "mappo:pretrained/families_scratch_s0"
    out = tmp_path / "ev"
    argv = ("--policies", policy, "--out", str(out), "--env-set", "max_steps=5")
    assert _evaluate_cli(*argv) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert "city_pool=200 of the run dropped: unseen cities" in head
    env = json.loads((out / "report.json").read_text())["env_kwargs"]
    assert env["city"] == "family:mixed" and "city_pool" not in env
    pooled = tmp_path / "pooled"
    argv = ("--policies", policy, "--out", str(pooled), "--env-set", "city_pool=3")
    assert _evaluate_cli(*argv, "--env-set", "max_steps=5") == 0
    assert json.loads((pooled / "report.json").read_text())["env_kwargs"]["city_pool"] == 3
