"""``coopnav evaluate``'s cruise spacing, methods (pooled policies) and gap table."""

from __future__ import annotations

import argparse
import importlib.util
import json
import math

import numpy as np
import pytest

from coopnav_env.agents import register_policy
from coopnav_env.training.evaluate import (
    CRUISE,
    cruise_spacing_m,
    evaluate,
)
from coopnav_env.training.stats import bootstrap_mean_interval, gap_closed
from tests.training.toy_env import TOY_ENV_ID

HAS_ENV = importlib.util.find_spec("coopnav_env.urban_canyon_v1") is not None
TOY_ENV = {"n_uavs": 3, "max_steps": 8}
SEEDS = [1_000_000, 1_000_001, 1_000_002, 1_000_003]


# --------------------------------------------------------------------------------------------
# cruise spacing
# --------------------------------------------------------------------------------------------


def test_cruise_spacing_is_the_nearest_neighbour_distance_in_the_middle_of_the_episode() -> None:
    # 11 positions (10 steps): the cruise is steps 2..8; three UAVs on a line, 4 m and 6 m
    # apart there, and 100 m apart before and after (left out)
    t = 11
    pos = np.zeros((t, 3, 3))
    pos[:, 1, 0] = 100.0
    pos[:, 2, 0] = 200.0
    pos[2:9, 1, 0] = 4.0
    pos[2:9, 2, 0] = 10.0
    assert CRUISE == (0.2, 0.8)
    assert cruise_spacing_m(pos) == pytest.approx((4.0 + 4.0 + 6.0) / 3)
    # the nearest neighbour of each UAV, not the mean distance to the others
    pos[2:9, 2, 0] = 1000.0
    assert cruise_spacing_m(pos) == pytest.approx((4.0 + 4.0 + 996.0) / 3)
    # altitude counts: a 3-D distance
    pos[2:9, 1, 2] = 3.0
    assert cruise_spacing_m(pos) == pytest.approx((5.0 + 5.0 + math.hypot(996.0, 3.0)) / 3)


def test_cruise_spacing_without_positions_or_neighbours_is_nan_and_bad_shapes_are_refused() -> None:
    assert math.isnan(cruise_spacing_m(None))
    assert math.isnan(cruise_spacing_m(np.zeros((5, 1, 3))))  # one UAV: no neighbour
    assert math.isnan(cruise_spacing_m(np.zeros((1, 3, 3))))  # the reset only
    two_steps = np.array([[[0.0, 0, 0], [9.0, 0, 0]], [[0.0, 0, 0], [2.0, 0, 0]]])
    assert cruise_spacing_m(two_steps) == pytest.approx(2.0)  # the step after the reset
    with pytest.raises(ValueError, match=r"shape \(T \+ 1, N, 3\)"):
        cruise_spacing_m(np.zeros((5, 3)))


# --------------------------------------------------------------------------------------------
# the share of the gap closed
# --------------------------------------------------------------------------------------------


def test_gap_closed_is_zero_at_the_baseline_one_at_the_reference_and_linear_between() -> None:
    rng = np.random.default_rng(3)
    base = rng.normal(1.4, 0.1, 50)
    ref = base + 0.4 + rng.normal(0.0, 0.02, 50)
    assert gap_closed(base, base, ref).as_dict() == {"value": 0.0, "low": 0.0, "high": 0.0}
    one = gap_closed(ref, base, ref)
    assert one.value == pytest.approx(1.0) and one.low == pytest.approx(1.0)
    quarter = base + 0.25 * (ref - base)
    got = gap_closed(quarter, base, ref, reps=500)
    assert got.value == pytest.approx(0.25)
    assert got.low == pytest.approx(0.25) and got.high == pytest.approx(0.25)  # paired
    noisy = quarter + rng.normal(0.0, 0.05, 50)
    iv = gap_closed(noisy, base, ref, reps=500)
    want = (noisy.mean() - base.mean()) / (ref.mean() - base.mean())
    assert iv.value == pytest.approx(want, rel=1e-12)
    assert iv.low < iv.value < iv.high
    assert iv == gap_closed(noisy, base, ref, reps=500)  # seeded: deterministic
    assert iv != gap_closed(noisy, base, ref, reps=500, seed=1)


def test_gap_closed_averages_training_runs_per_episode() -> None:
    rng = np.random.default_rng(4)
    runs = rng.normal(1.6, 0.1, (3, 40))
    base, ref = rng.normal(1.4, 0.1, 40), rng.normal(1.8, 0.05, 40)
    assert gap_closed(runs, base, ref, reps=300) == gap_closed(runs.mean(axis=0), base, ref, 300)
    assert gap_closed(runs, base[None, :], ref[None, :], 300) == gap_closed(runs, base, ref, 300)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.ones(3), np.zeros(4), np.ones(3)), "same episodes"),
        ((np.ones(3), np.zeros(3), np.zeros(3)), "no gap to close"),
        ((np.ones(3), np.zeros(3), np.array([1.0, np.nan, 1.0])), "reference scores must be"),
        ((np.ones((2, 3, 1)), np.zeros(3), np.ones(3)), r"method must be per-episode scores"),
        ((np.ones(0), np.zeros(0), np.ones(0)), "method must be per-episode scores"),
    ],
)
def test_gap_closed_refuses_what_it_cannot_compare(args, match) -> None:
    with pytest.raises(ValueError, match=match):
        gap_closed(*args)


def test_gap_closed_needs_a_replicate() -> None:
    with pytest.raises(ValueError, match="reps must be at least 1, got 0"):
        gap_closed(np.ones(3), np.zeros(3), np.full(3, 2.0), reps=0)


# --------------------------------------------------------------------------------------------
# evaluate: methods and the gap table
# --------------------------------------------------------------------------------------------


class Homing:
    """Every UAV flies straight at the goal at ``speed`` (of the toy env's unit step)."""

    name = "gap_test_homing"

    def __init__(self, env, speed: float = 1.0) -> None:
        self.speed = float(speed)

    def reset(self, seed=None) -> None:
        pass

    def act(self, observations):
        out = {}
        for agent, obs in observations.items():
            to_goal = np.asarray(obs[2:4], float) - np.asarray(obs[0:2], float)
            step = self.speed * to_goal / max(float(np.linalg.norm(to_goal)), 1e-9)
            out[agent] = np.r_[step, 0.0].astype(np.float32)
        return out


register_policy("gap_test_homing", Homing, overwrite=True)

POLICIES = ["random", "gap_test_homing", "gap_test_homing@speed=0.5"]


@pytest.fixture(scope="module")
def plain():
    return evaluate(["random", "gap_test_homing"], SEEDS, TOY_ENV, env_id=TOY_ENV_ID, plots=False)


def test_the_default_table_gains_only_the_behaviour_descriptors(plain) -> None:
    head = plain.to_markdown().splitlines()[0]
    assert head.endswith(
        "| return | steps | cruise spacing [m] | altitude [m] | spread across route [m] "
        "| speed [m/s] |"
    )
    assert head.startswith("| policy | coop mean [m] |")
    assert len(plain.to_markdown().splitlines()) == 2 + 2  # two policies, no method rows
    assert plain.gap_markdown() == ""
    data = plain.to_dict()
    assert "gap" not in data and "methods" not in data
    s = plain["random"]
    spacing = [cruise_spacing_m(e.pos_enu_m) for e in plain.episodes["random"]]
    assert s.cruise_spacing_m == pytest.approx(np.mean(spacing)) and s.cruise_spacing_m > 0
    assert [e["cruise_spacing_m"] for e in data["episodes"]["random"]] == spacing
    # the toy env flies at 10 m, has no street route and no step length: those are n/a
    assert s.cruise_altitude_m == 10.0
    assert math.isnan(s.cruise_spread_m) and math.isnan(s.cruise_speed_mps)
    assert plain.to_markdown().splitlines()[2].endswith("| 10.0 | n/a | n/a |")
    assert [e["cruise_altitude_m"] for e in data["episodes"]["random"]] == [10.0] * len(SEEDS)


def test_a_method_pools_its_policies_and_the_gap_table_pairs_the_episodes(plain) -> None:
    methods = {"slow_and_fast": ["gap_test_homing", "gap_test_homing@speed=0.5"]}
    rep = evaluate(
        POLICIES,
        SEEDS,
        TOY_ENV,
        env_id=TOY_ENV_ID,
        plots=False,
        methods=methods,
        gap=("random", "gap_test_homing"),
        bootstrap_reps=300,
    )
    # the policies fly as they do alone
    for name in ("random", "gap_test_homing"):
        got = [e.episode_return for e in rep.episodes[name]]
        assert got == [e.episode_return for e in plain.episodes[name]]
    pooled = rep["slow_and_fast"]
    assert pooled.episodes == 2 * len(SEEDS)
    eps = [e for p in methods["slow_and_fast"] for e in rep.episodes[p]]
    assert pooled.return_mean == pytest.approx(np.mean([e.episode_return for e in eps]))
    assert "| slow_and_fast (2 policies) |" in rep.to_markdown()
    # the gap table: every policy, then the method
    rows = {r.name: r for r in rep.gap_rows}
    assert list(rows) == [*POLICIES, "slow_and_fast"]
    assert (
        rows["random"].gap_closed.value == 0.0 and rows["gap_test_homing"].gap_closed.value == 1.0
    )

    def returns(name: str) -> np.ndarray:
        return np.array([e.episode_return for e in rep.episodes[name]])

    both = np.stack([returns(p) for p in methods["slow_and_fast"]])
    want = gap_closed(both, returns("random"), returns("gap_test_homing"), reps=300)
    assert rows["slow_and_fast"].gap_closed == want
    mean = bootstrap_mean_interval(both.mean(axis=0), 300, np.random.default_rng(0))
    assert rows["slow_and_fast"].return_mean.as_dict() == dict(zip(("value", "low", "high"), mean))
    table = rep.gap_markdown()
    assert "from `random` (0) to `gap_test_homing` (1)" in table
    assert "| slow_and_fast (2 policies) |" in table and "| gap_test_homing | " in table
    data = json.loads(json.dumps(rep.to_dict()))
    assert data["gap"]["baseline"] == "random" and data["gap"]["reference"] == "gap_test_homing"
    assert data["methods"]["slow_and_fast"]["policies"] == methods["slow_and_fast"]
    assert data["gap"]["rows"][-1]["gap_closed"]["value"] == want.value


def test_a_method_can_be_the_gaps_reference() -> None:
    rep = evaluate(
        POLICIES[:2],
        SEEDS[:2],
        TOY_ENV,
        env_id=TOY_ENV_ID,
        plots=False,
        methods={"both": ["random", "gap_test_homing"]},
        gap=("random", "both"),
        bootstrap_reps=50,
    )
    assert {r.name: r.gap_closed.value for r in rep.gap_rows}["both"] == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("methods", "gap", "match"),
    [
        ({"m": []}, None, "method 'm' has no policies"),
        ({"m": ["random", "sky"]}, None, r"pools \['sky'\], which are not among the policies"),
        ({"random": ["gap_test_homing"]}, None, "named like a policy"),
        ({"m": ["random", "random"]}, None, "names a policy twice"),
        ({}, ("random", "sky"), "reference 'sky' is neither a policy evaluated nor a method"),
        ({}, ("random", "random"), "give two different ones"),
        ({}, ("random",), "two names"),
    ],
)
def test_bad_methods_and_gaps_are_refused_before_any_episode(methods, gap, match, tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=match):
        evaluate(
            ["random", "gap_test_homing"],
            SEEDS[:1],
            TOY_ENV,
            out,
            env_id=TOY_ENV_ID,
            methods=methods,
            gap=gap,
        )
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# the command line
# --------------------------------------------------------------------------------------------


def _cli(*argv: str) -> int:
    from coopnav_env.training import evaluate_cli as ev

    parser = argparse.ArgumentParser()
    ev.add_arguments(parser)
    args = ["--episodes", "3", "--no-plots", "--env-id", TOY_ENV_ID, *argv]
    return ev.run(parser.parse_args([*args, "--env-set", "max_steps=8"]))


def test_the_command_line_flies_a_methods_policies_and_prints_the_gap(tmp_path, capsys) -> None:
    out = tmp_path / "ev"
    argv = [
        "--policies",
        "random",
        "gap_test_homing",
        "--methods",
        "slow=gap_test_homing@speed=0.5",
    ]
    assert _cli(*argv, "--gap", "random", "gap_test_homing", "--out", str(out)) == 0
    printed = capsys.readouterr().out
    assert "| gap_test_homing@speed=0.5 |" in printed  # a method's policy flies without --policies
    assert "| slow (1 policies) |" in printed
    assert "Share of the gap from `random` (0) to `gap_test_homing` (1)" in printed
    md = (out / "report.md").read_text()
    assert "| slow (1 policies) | " in md and "gap closed [95 % CI]" in md
    data = json.loads((out / "report.json").read_text())
    assert [r["name"] for r in data["gap"]["rows"]] == [
        "random",
        "gap_test_homing",
        "gap_test_homing@speed=0.5",
        "slow",
    ]
    assert "slow" in (out / "report.csv").read_text().splitlines()[-1]


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--methods", "slow"], "must look like NAME=POLICY"),
        (["--methods", "=random"], "must look like NAME=POLICY"),
        (["--methods", "a=random", "a=gap_test_homing"], "names 'a' twice"),
        (["--gap", "random", "sky"], "reference 'sky' is neither"),
    ],
)
def test_the_command_line_refuses_bad_methods_and_gaps(argv, match, tmp_path) -> None:
    out = tmp_path / "ev"
    with pytest.raises(ValueError, match=match):
        _cli("--policies", "random", "gap_test_homing", *argv, "--out", str(out))
    assert not out.exists()  # refused before the folder was claimed


@pytest.mark.skipif(not HAS_ENV, reason="urban_canyon_v1 not available")
def test_an_urban_episode_records_its_route_and_step_for_the_behaviour_descriptors() -> None:
    import coopnav_env.urban_canyon_v1 as v1
    from coopnav_env.agents import make_policy
    from coopnav_env.training.behaviour import cruise_behaviour
    from coopnav_env.training.evaluate import run_episode

    env = v1.parallel_env(max_steps=12)
    rec = run_episode(env, make_policy("column", env), 1_000_000)
    np.testing.assert_array_equal(rec.route_xy_m, env.world.route_xy_m)
    assert rec.dt_s == env.config.dt_s
    b = rec.behaviour()
    assert b == cruise_behaviour(rec.pos_enu_m, env.world.route_xy_m, env.config.dt_s)
    assert all(math.isfinite(v) and v > 0.0 for v in b.values()), b
    rep = evaluate(["column"], [1_000_000], {"max_steps": 12}, env_id="urban_canyon_v1")
    s = rep["column"]
    assert (s.cruise_spacing_m, s.cruise_altitude_m) == (b["spacing_m"], b["altitude_m"])
    assert (s.cruise_spread_m, s.cruise_speed_mps) == (b["lateral_spread_m"], b["speed_mps"])
    env.close()


@pytest.mark.skipif(not HAS_ENV, reason="urban_canyon_v1 not available")
def test_a_heuristic_flies_in_the_frame_it_commands_beside_a_policy_of_another() -> None:
    short = {"max_steps": 3}
    rep = evaluate(["formation", "setpoints"], [1_000_000], short, env_id="urban_canyon_v1")
    assert rep.own_frame == {"setpoints": "route"}
    assert "`setpoints` with action_frame='route'" in rep.header()
    assert rep.to_dict()["own_frame"] == {"setpoints": "route"}
    route = {**short, "action_frame": "route"}
    rep = evaluate(["formation", "setpoints"], [1_000_000], route, env_id="urban_canyon_v1")
    assert rep.own_frame == {"formation": "velocity"}
    assert rep["formation"].length_mean == 3.0
    plain = evaluate(["formation"], [1_000_000], short, env_id="urban_canyon_v1")
    assert plain.own_frame == {} and "frame they command" not in plain.header()
    assert plain["formation"].return_mean == rep["formation"].return_mean


def test_runs_that_differ_only_in_unrecorded_v1_defaults_fly_together(tmp_path) -> None:
    """A run recorded before a v1 default existed (no ``crash_free_steps``) and one that
    records it at the default fly the same environment: evaluated together; a run that sets
    it otherwise is refused, naming both environments."""
    import yaml

    from coopnav_env.envs.config import V1_DEFAULTS
    from coopnav_env.training.run_configs import train_config_of_policies

    def run(name: str, env: dict) -> str:
        folder = tmp_path / name
        folder.mkdir()
        (folder / "final_model.zip").write_bytes(b"")
        text = yaml.safe_dump({"env_id": "urban_canyon_v1", "env": env, "backend": "sb3"})
        (folder / "config.yaml").write_text(text)
        return f"ppo:{folder / 'final_model.zip'}"

    base = {"action_frame": "route", "route_turn_brake_mps2": 2}
    old = run("old", base)
    new = run("new", {**base, "crash_free_steps": V1_DEFAULTS["crash_free_steps"]})
    other = run("other", {**base, "crash_free_steps": V1_DEFAULTS["crash_free_steps"] + 2})
    for pair in ([old, new], [new, old]):
        env = train_config_of_policies(pair)["env"]
        assert {**V1_DEFAULTS, **env} == {**V1_DEFAULTS, **base}
    with pytest.raises(ValueError, match="trained in different environments"):
        train_config_of_policies([old, other])
