"""The Ray RLlib backend (``coopnav train --backend rllib``) and ``rllib:`` policies.

The fast tests check settings and error messages without starting Ray (several run even
without Ray installed). The slow test trains two iterations with two env runners on a local
Ray, resumes from the checkpoint with a third, and evaluates the RLlib policy next to an SB3
one and a heuristic in one ``coopnav evaluate`` table; every file Ray writes stays under
``tmp_path`` (HOME and TMPDIR point there).
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import socket
import sys
import time
from pathlib import Path

import pytest
import yaml

from coopnav_env.training.config import TrainConfig, load_config
from coopnav_env.training.rllib_backend import (
    INSTALL_HINT,
    RLlibSettings,
    check_address,
    find_latest_rllib_checkpoint,
    import_rllib,
)
from coopnav_env.training.train import add_arguments, config_from_args
from tests.training.ray_cli import isolated_ray_env, run_coopnav

HAS_RAY = importlib.util.find_spec("ray") is not None


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(list(argv))


def _free_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------------------------
# settings and errors (no Ray started)
# --------------------------------------------------------------------------------------------


def test_packaged_config_has_valid_rllib_section():
    data = load_config()
    assert data["backend"] == "sb3"  # the default backend stays SB3
    s = RLlibSettings.from_dict(data["rllib"])
    assert s.num_env_runners >= 1 and s.address is None
    assert s.ppo["train_batch_size_per_learner"] >= 1 and s.model["fcnet_hiddens"]
    cfg = TrainConfig.from_dict({**data, "out": "x"})
    assert cfg.backend == "sb3" and cfg.rllib == data["rllib"]


def test_cli_flags_reach_the_rllib_settings(tmp_path):
    cfg = config_from_args(
        _args("--out", str(tmp_path), "--backend", "rllib", "--num-env-runners", "3",
              "--address", "head:6379", "--set", "rllib.ppo.lr=1e-4")
    )  # fmt: skip
    assert cfg.backend == "rllib"
    s = RLlibSettings.from_dict(cfg.rllib)
    assert (s.num_env_runners, s.address, s.ppo["lr"]) == (3, "head:6379", 1e-4)
    assert s.ppo["num_epochs"] == load_config()["rllib"]["ppo"]["num_epochs"]  # YAML kept
    assert config_from_args(_args("--out", "x", "--set", "backend=rllib")).backend == "rllib"


def test_rllib_flags_need_the_rllib_backend(tmp_path):
    with pytest.raises(ValueError, match=r"--num-env-runners, --address only apply to --backend"):
        config_from_args(_args("--out", "x", "--num-env-runners", "2", "--address", "auto"))
    with pytest.raises(ValueError, match="backend must be one of"):
        TrainConfig(out="x", backend="tune")


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"num_env_runners": -1}, r"num_env_runners \(--num-env-runners\) must be >= 0, got -1"),
        ({"num_env_runners": 1.5}, "num_env_runners .* must be an integer"),
        ({"num_envs_per_env_runner": 0}, "num_envs_per_env_runner must be >= 1"),
        ({"num_cpus_per_env_runner": -2}, "num_cpus_per_env_runner must be a number > 0"),
        ({"connect_timeout_s": 0}, "connect_timeout_s must be a number > 0"),
        ({"rollout_fragment_length": 0}, "rollout_fragment_length must be 'auto' or >= 1"),
        ({"address": "head:6379", "num_env_runners": 0}, "needs rllib.num_env_runners >= 1"),
        ({"address": ""}, "address must be"),
        ({"ppo": {"train_batch_size_per_learner": -64}}, "train_batch_size_per_learner must"),
        ({"ppo": {"minibatch_size": 0}}, "minibatch_size must be an integer >= 1"),
        ({"ppo": [1]}, "rllib.ppo must be a mapping"),
        ({"runners": 2}, r"unknown rllib setting\(s\) \['runners'\]"),
    ],
)
def test_bad_rllib_settings(change, match):
    with pytest.raises(ValueError, match=match):
        RLlibSettings.from_dict(change)


def test_cli_negative_runners_is_a_clear_error(tmp_path, capsys):
    from coopnav_env.training.cli import main

    out = tmp_path / "run"
    assert main(["train", "--backend", "rllib", "--out", str(out), "--num-env-runners", "-2"]) == 2
    err = capsys.readouterr().err
    assert "coopnav train: error: rllib.num_env_runners" in err and ">= 0, got -2" in err
    assert not out.exists()  # nothing written


def test_unreachable_address_fails_fast():
    port = _free_port()
    t0 = time.perf_counter()
    with pytest.raises(ConnectionError, match=rf"cannot reach the Ray cluster at 127.0.0.1:{port}"):
        check_address(f"127.0.0.1:{port}", timeout_s=2.0)
    assert time.perf_counter() - t0 < 5.0
    for bad in ("head:port", "head:0", ":6379", "ray://:1"):
        with pytest.raises(ValueError, match="must look like HOST:PORT"):
            check_address(bad, timeout_s=1.0)
    check_address("auto", timeout_s=1.0)  # left to Ray


def test_missing_ray_is_a_clear_error(monkeypatch, tmp_path, capsys):
    for name in [m for m in sys.modules if m == "ray" or m.startswith("ray.")] + ["ray"]:
        monkeypatch.setitem(sys.modules, name, None)  # `import ray...` raises ImportError
    with pytest.raises(ImportError, match=r"install the extra with: pip install -e \"\.\[ray\]\""):
        import_rllib()
    from coopnav_env.training.cli import main

    out = tmp_path / "run"
    assert main(["train", "--backend", "rllib", "--out", str(out), "--timesteps", "10"]) == 2
    assert INSTALL_HINT in capsys.readouterr().err
    assert not out.exists()

    # a checkpoint-looking folder: the policy loader gives the same hint
    module = tmp_path / "ckpt" / "learner_group" / "learner" / "rl_module" / "shared"
    module.mkdir(parents=True)
    (module / "module_state.pkl").write_bytes(b"")
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy

    with pytest.raises(ImportError, match=r"pip install -e \"\.\[ray\]\""):
        make_policy(f"rllib:{tmp_path / 'ckpt'}", urban_canyon_v0.parallel_env(n_uavs=2))


def test_rllib_policy_and_resume_errors(tmp_path, capsys):
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy
    from coopnav_env.training.cli import main
    from coopnav_env.training.rllib_backend import resolve_resume

    env = urban_canyon_v0.parallel_env(n_uavs=2)
    with pytest.raises(ValueError, match="needs the path of an RLlib checkpoint"):
        make_policy("rllib:", env)
    with pytest.raises(FileNotFoundError, match="RLlib checkpoint not found"):
        make_policy(f"rllib:{tmp_path / 'nope'}", env)
    with pytest.raises(FileNotFoundError, match="no RLlib policy 'shared'"):
        make_policy(f"rllib:{tmp_path}", env)
    assert main(["evaluate", "--policies", f"rllib:{tmp_path / 'nope'}", "--episodes", "1"]) == 2
    assert "RLlib checkpoint not found" in capsys.readouterr().err

    with pytest.raises(FileNotFoundError, match="no RLlib checkpoint to resume from"):
        find_latest_rllib_checkpoint(tmp_path)
    zip_ckpt = tmp_path / "ppo_100_steps.zip"
    zip_ckpt.write_bytes(b"")
    with pytest.raises(ValueError, match=r"not an RLlib checkpoint.*--backend sb3"):
        resolve_resume(TrainConfig(out=str(tmp_path), backend="rllib", resume=str(zip_ckpt)))


def test_evaluate_reads_the_environment_of_an_rllib_run(tmp_path):
    from coopnav_env.training.evaluate_cli import train_config_of_policies

    run = tmp_path / "run"
    (run / "final_model").mkdir(parents=True)
    (run / "checkpoints" / "rllib_10_steps").mkdir(parents=True)
    (run / "config.yaml").write_text(
        yaml.safe_dump({"env_id": "urban_canyon_v0", "env": {"n_uavs": 3}, "backend": "rllib"})
    )
    for path in (run / "final_model", run / "checkpoints" / "rllib_10_steps", run):
        assert train_config_of_policies([f"rllib:{path}"])["env"] == {"n_uavs": 3}


@pytest.mark.skipif(not HAS_RAY, reason="ray[rllib] not installed")
def test_env_creator_wraps_the_swarm_for_rllib():
    from coopnav_env.training.rllib_backend import make_rllib_env, map_to_shared_policy

    env = make_rllib_env({"env_id": "urban_canyon_v0", "env_kwargs": {"n_uavs": 3}})
    obs, _ = env.reset(seed=4)
    assert sorted(obs) == ["uav_0", "uav_1", "uav_2"]
    assert {map_to_shared_policy(a) for a in obs} == {"shared"}
    _, _, terms, truncs, _ = env.step({a: env.action_space[a].sample() * 0 for a in obs})
    assert "__all__" in terms and "__all__" in truncs
    env.close()


@pytest.mark.skipif(not HAS_RAY, reason="ray[rllib] not installed")
def test_env_copies_of_different_runners_get_distinct_seeds():
    """RLlib + gymnasium seed copy j of runner i with seed + i + j; we shift to seed + i E + j."""
    from coopnav_env.training.rllib_backend import make_rllib_env

    class Context(dict):  # RLlib's EnvContext: a dict with the runner's index
        def __init__(self, worker_index: int, copies: int):
            super().__init__(
                env_id="urban_canyon_v0", env_kwargs={"n_uavs": 3}, num_envs_per_env_runner=copies
            )
            self.worker_index = worker_index

    copies, base = 3, 100
    starts = {}
    for runner in range(3):
        for j in range(copies):
            env = make_rllib_env(Context(runner, copies))
            obs, _ = env.reset(seed=base + runner + j)  # what RLlib and gymnasium pass
            starts[(runner, j)] = obs["uav_0"].tobytes()
            env.close()
    assert len(set(starts.values())) == len(starts)  # no two copies replay an episode
    # the mapping is seed + i E + j: runner 1's copy 0 plays the episode of seed base + 3
    env = make_rllib_env(Context(0, 1))
    obs, _ = env.reset(seed=base + copies)
    assert obs["uav_0"].tobytes() == starts[(1, 0)]


# --------------------------------------------------------------------------------------------
# end to end on a local Ray
# --------------------------------------------------------------------------------------------

SMALL = [
    "--env-set", "n_uavs=3", "--env-set", "max_steps=20", "--seed", "5", "--no-progress",
]  # fmt: skip
RLLIB_SMALL = [
    "--set", "rllib.ppo.train_batch_size_per_learner=64",  # env-steps = 192 agent-steps
    "--set", "rllib.ppo.minibatch_size=64",
    "--set", "rllib.ppo.num_epochs=1",
    "--set", "rllib.model.fcnet_hiddens=[32, 32]",
]  # fmt: skip


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_rllib_train_resume_and_evaluate_beside_sb3(tmp_path):
    pytest.importorskip("ray.rllib")
    pytest.importorskip("stable_baselines3")
    env = isolated_ray_env(tmp_path)
    home = Path(env["HOME"])
    rl = tmp_path / "rl"

    # two iterations with two env runners; a checkpoint after each
    run_coopnav(
        ["train", "--backend", "rllib", "--out", str(rl), "--num-env-runners", "2",
         "--timesteps", "384", "--checkpoint-freq", "192", *SMALL, *RLLIB_SMALL],
        env,
    )  # fmt: skip
    info = json.loads((rl / "run.json").read_text())
    assert info["backend"] == "rllib" and info["num_env_runners"] == 2
    assert (info["iterations"], info["env_steps"], info["num_timesteps"]) == (2, 128, 384)
    assert info["env_steps_per_s"] > 0 and info["train_batch_size_per_learner"] == 64
    assert info["ray"]["address"] == "local" and info["ray"]["temp_dir"] == str(rl / "ray")
    cfg = yaml.safe_load((rl / "config.yaml").read_text())
    assert cfg["backend"] == "rllib" and cfg["seed"] == 5 and cfg["env"]["n_uavs"] == 3
    assert "ppo" not in cfg and "pretrain" not in cfg  # SB3-only settings left out
    assert cfg["rllib"]["num_env_runners"] == 2
    assert sorted(p.name for p in (rl / "checkpoints").iterdir()) == [
        "rllib_192_steps",
        "rllib_384_steps",
    ]
    assert (rl / "final_model" / "rllib_checkpoint.json").is_file()
    rows = _rows(rl / "logs" / "progress.csv")
    assert [int(r["agent_steps"]) for r in rows] == [192, 384]
    assert all(r["episode_return_mean"] and r["nav_collision_rate"] for r in rows)
    assert any((rl / "ray").glob("session_*"))  # Ray's files in the output directory
    assert list(home.iterdir()) == []  # ... and none in the home directory

    # the run is finished: resuming it without asking for more changes nothing (issue 15)
    before = (rl / "run.json").read_bytes()
    proc = run_coopnav(["train", "--out", str(rl), "--resume", "latest"], env)
    assert "holds a finished run (384 agent-steps)" in proc.stderr
    assert (rl / "run.json").read_bytes() == before

    # train it further from its final model, in this process (0 env runners), one iteration
    run_coopnav(
        ["train", "--backend", "rllib", "--out", str(rl), "--num-env-runners", "0",
         "--timesteps", "576", "--resume", "latest", *SMALL, *RLLIB_SMALL],
        env,
    )  # fmt: skip
    info = json.loads((rl / "run.json").read_text())
    assert info["resumed_from"] == str(rl / "final_model")
    assert (info["iterations"], info["session_iterations"], info["num_timesteps"]) == (3, 1, 576)
    assert (rl / "config_resumed_at_384.yaml").is_file()
    # one learning curve over both sessions: every iteration once, in order (issue 35)
    rows = _rows(rl / "logs" / "progress.csv")
    assert [int(r["agent_steps"]) for r in rows] == [192, 384, 576]
    row = rows[-1]
    # RLlib's own step counter continues: the algorithm's state was restored
    assert row["iteration"] == "3" and float(row["rllib_env_steps_lifetime"]) == 192

    # an SB3 policy in the same environment, then one evaluation table for all
    from coopnav_env.training.cli import main

    sb3 = tmp_path / "sb3"
    assert main(
        ["train", "--out", str(sb3), "--timesteps", "96", "--checkpoint-freq", "0",
         "--set", "pretrain=null", "--set", "ppo.n_steps=16", "--set", "ppo.batch_size=48",
         "--set", "ppo.n_epochs=1", *SMALL]
    ) == 0  # fmt: skip
    ev = tmp_path / "eval"
    proc = run_coopnav(
        ["evaluate", "--policies", "formation", f"ppo:{sb3 / 'final_model.zip'}",
         f"rllib:{rl / 'final_model'}", f"rllib:{rl / 'checkpoints' / 'rllib_192_steps'}",
         "--episodes", "2", "--no-plots", "--out", str(ev)],
        env,
    )  # fmt: skip
    report = json.loads((ev / "report.json").read_text())
    assert report["env_kwargs"]["n_uavs"] == 3 and report["env_kwargs"]["max_steps"] == 20
    stats = {p["policy"]: p for p in report["policies"]}
    assert set(stats) == {
        "formation",
        f"ppo:{sb3 / 'final_model.zip'}",
        f"rllib:{rl / 'final_model'}",
        f"rllib:{rl / 'checkpoints' / 'rllib_192_steps'}",
    }
    assert all(s["episodes"] == 2 and s["agent_steps"] > 0 for s in stats.values())
    assert f"rllib:{rl / 'final_model'}" in proc.stdout  # in the printed table
    assert list(home.iterdir()) == []
