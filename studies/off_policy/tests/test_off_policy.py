"""The MASAC study's scripts (studies.off_policy): run folders, arguments, held decisions, and
one tiny training run flown back through the evaluation's policy.

BenchMARL lives in a venv of its own (the ``benchmarl`` extra): the tests that train or load
an actor skip where it is not installed; the folder, argument and wrapper checks run
everywhere.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.off_policy.masac import HeldDecisions, MasacSettings
from studies.off_policy.train_masac import build_parser, check_run_folder, main


def test_a_folder_holding_a_run_is_refused(tmp_path) -> None:
    assert check_run_folder(tmp_path / "new") == tmp_path / "new"
    (tmp_path / "train.log").write_text("a log redirected into the folder\n")
    assert check_run_folder(tmp_path) == tmp_path
    (tmp_path / "config.json").write_text("{}")
    with pytest.raises(ValueError, match="started run"):
        check_run_folder(tmp_path)
    (tmp_path / "run.json").write_text("{}")
    with pytest.raises(ValueError, match="finished run"):
        check_run_folder(tmp_path)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is a file"):
        check_run_folder(tmp_path / "file")


def test_bad_arguments_are_refused(tmp_path, capsys) -> None:
    parser = build_parser()
    ok = ["--seed", "0", "--out", str(tmp_path / "r")]
    assert parser.parse_args([*ok, "--minutes", "1.5"]).minutes == 1.5
    bad = [
        ([*ok], "one of the arguments --minutes --frames is required"),
        ([*ok, "--minutes", "1", "--frames", "8"], "not allowed with argument"),
        ([*ok, "--minutes", "0"], "must be a positive number, got 0"),
        ([*ok, "--frames", "-8"], "must be a positive integer, got -8"),
        (["--seed", "-1", "--out", "x", "--frames", "8"], "must be an integer >= 0, got -1"),
    ]
    for argv, message in bad:
        with pytest.raises(SystemExit) as info:
            parser.parse_args(argv)
        assert info.value.code == 2
        assert message in capsys.readouterr().err
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "run.json").write_text("{}")
    with pytest.raises(SystemExit):
        main([*ok, "--frames", "8"])
    assert "holds a finished run" in capsys.readouterr().err


def test_a_bad_city_is_refused_before_the_run_folder(tmp_path, capsys) -> None:
    ok = ["--seed", "0", "--out", str(tmp_path / "r"), "--frames", "8"]
    args = build_parser().parse_args([*ok, "--city", "family:mixed", "--city-pool", "200"])
    assert (args.city, args.city_pool) == ("family:mixed", 200)
    for extra, message in (
        (["--city", "family:nowhere"], "nowhere"),
        (["--city-pool", "0"], "must be a positive integer, got 0"),
    ):
        with pytest.raises(SystemExit) as info:
            main([*ok, *extra])
        assert info.value.code == 2
        assert message in capsys.readouterr().err
        assert not (tmp_path / "r").exists()  # nothing written


def test_settings_are_checked_and_read_back() -> None:
    s = MasacSettings(env={"n_uavs": 3}, n_envs=2, frames_per_batch=8, num_cells=[16])
    assert MasacSettings.from_json(json.loads(json.dumps(s.to_json()))) == s
    with pytest.raises(ValueError, match="multiple of n_envs"):
        MasacSettings(env={}, n_envs=3, frames_per_batch=8)
    with pytest.raises(ValueError, match="hold must be an integer >= 1, got 0"):
        MasacSettings(env={}, hold=0)
    with pytest.raises(ValueError, match="gamma"):
        MasacSettings(env={}, gamma=1.5)
    with pytest.raises(ValueError, match="unknown MASAC settings"):
        MasacSettings.from_json({"env": {}, "tau": 0.1})


def test_held_decisions_repeat_the_action_and_sum_the_rewards() -> None:
    from coopnav_env import urban_canyon_v1

    config = {"n_uavs": 2, "max_steps": 6}
    action = np.array([0.3, -0.2, 0.1], dtype=np.float32)
    plain = urban_canyon_v1.parallel_env(**config)
    plain.reset(seed=7)
    per_step = []
    while plain.agents:
        _, rewards, *_ = plain.step({a: action for a in plain.agents})
        per_step.append(rewards)
    held = HeldDecisions(urban_canyon_v1.parallel_env(**config), hold=4)
    held.reset(seed=7)
    before = HeldDecisions.swarm_steps
    _, first, *_ = held.step({a: action for a in held.possible_agents})
    assert held.agents  # 4 of 6 steps flown
    _, second, terms, truncs, _ = held.step({a: action for a in held.possible_agents})
    assert not held.agents and (all(truncs.values()) or all(terms.values()))
    assert HeldDecisions.swarm_steps - before == 6
    for agent in held.possible_agents:
        assert first[agent] == pytest.approx(sum(r[agent] for r in per_step[:4]), abs=1e-12)
        assert second[agent] == pytest.approx(sum(r[agent] for r in per_step[4:]), abs=1e-12)
    with pytest.raises(ValueError, match="hold must be an integer >= 1"):
        HeldDecisions(plain, hold=0)


def test_a_tiny_run_trains_saves_and_flies(tmp_path) -> None:
    pytest.importorskip("benchmarl")
    import torch

    from studies.off_policy.evaluate_masac import fly_actor
    from studies.off_policy.masac import MasacPolicy, load_actor

    threads = torch.get_num_threads()
    out = tmp_path / "run"
    tiny = ["--n-envs", "2", "--frames-per-batch", "8", "--optimizer-steps", "2"]
    tiny += ["--train-batch-size", "8", "--num-cells", "16", "--memory-size", "64"]
    try:
        assert main(["--seed", "0", "--frames", "16", "--out", str(out), *tiny]) == 0
        record = json.loads((out / "run.json").read_text())
        assert record["frames"] == 16 and record["iterations"] == 2
        assert record["optimizer_steps"] == 4 and record["stopped_by"] == "frames"
        assert 0 < record["agent_steps"] <= 16 * 4 * 5 and record["torch_threads"] == 1
        assert len((out / "progress.csv").read_text().splitlines()) == 3
        with pytest.raises(SystemExit):
            main(["--seed", "0", "--frames", "16", "--out", str(out), *tiny])

        module, settings = load_actor(out / "policy", tmp_path / "scratch")
        assert settings.hold == 4 and settings.env["action_frame"] == "route"
        policy = MasacPolicy(module, [f"uav_{i}" for i in range(5)], settings.hold, "tiny")
        obs = {f"uav_{i}": np.full(57, 0.1 * i, dtype=np.float32) for i in range(5)}
        policy.reset()
        first = policy.act(obs)
        held = policy.act({a: o + 1.0 for a, o in obs.items()})  # held: the same action
        assert all(np.array_equal(first[a], held[a]) for a in obs)
        assert all(np.all(np.abs(a) <= 1.0) and a.dtype == np.float32 for a in first.values())
        rows = fly_actor(module, settings, "tiny", [1_000_100])
        assert rows[0]["steps"] > 0 and np.isfinite(rows[0]["score"])
    finally:
        torch.set_num_threads(threads)


def test_the_training_curve_finds_quarters_and_the_peak(tmp_path, capsys) -> None:
    from studies.off_policy.training_curve import curve_summary
    from studies.off_policy.training_curve import main as curve_main

    returns = [1.0] * 4 + [2.0] * 2 + [0.5] * 2
    lines = ["iteration,elapsed_s,agent_steps,mean_return"]
    lines += [f"{i + 1},{60.0 * (i + 1)},{1000 * (i + 1)},{r}" for i, r in enumerate(returns)]
    path = tmp_path / "progress.csv"
    path.write_text("\n".join(lines) + "\n")
    s = curve_summary(path, window=2)
    assert s["quarters"] == [1.0, 1.0, 2.0, 0.5]
    peak = (s["peak"], s["peak_minute"], s["peak_agent_steps"], s["last"])
    assert peak == (2.0, 6.0, 6000.0, 0.5)
    assert curve_main([str(path), "--window", "2"]) == 0
    assert "| 8 | 1.00 / 1.00 / 2.00 / 0.50 | 2.000 | 6.0 min" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        curve_main([str(path), "--window", "9"])
    assert "fewer than 9" in capsys.readouterr().err
