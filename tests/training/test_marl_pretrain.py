"""The TorchRL backend's behaviour-cloning warm start (``torchrl.pretrain``)."""

from __future__ import annotations

import json
import os
import re
import signal
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from coopnav_env.agents import make_policy  # noqa: E402
from coopnav_env.agents.marl_nets import MARLSettings, load_marl_checkpoint  # noqa: E402
from coopnav_env.envs.config import V1_DEFAULTS  # noqa: E402
from coopnav_env.training.cli import main  # noqa: E402
from coopnav_env.training.envs import EVAL_SEED_START  # noqa: E402
from coopnav_env.training.torchrl_backend import MARLTrainer, WarmStart  # noqa: E402

TINY = [
    "--backend",
    "torchrl",
    "--env-set",
    "n_uavs=2",
    "--env-set",
    "max_steps=30",
    "--set",
    "torchrl.n_copies=2",
    "--set",
    "torchrl.rollout_steps=4",
    "--set",
    "torchrl.hidden=[16,16]",
    "--set",
    "torchrl.epochs=1",
    "--no-progress",
]
V1 = ["--env-id", "urban_canyon_v1"]  # its torchrl section has no residual base
V0 = ["--env-id", "urban_canyon_v0"]  # its torchrl section has no warm start
PRETRAIN = (
    "torchrl.pretrain={policy: waypoint, policy_kwargs: {altitude_m: 28.0}, episodes: 2, "
    "epochs: 1, learning_rate: 1.0e-3}"
)
SPEC = WarmStart("waypoint", {"altitude_m": 28.0}, episodes=4, epochs=1, learning_rate=1e-3)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def train(out: Path, *args: str) -> int:
    return main(["train", "--out", str(out), *TINY, *args])


def weights(path: Path) -> dict[str, torch.Tensor]:
    d = load_marl_checkpoint(path)
    return {f"{net}.{k}": v for net in ("actor", "critic") for k, v in d[net].items()}


def teacher_data(env_kwargs: dict, seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Observations and clipped commands of ``waypoint@altitude_m=28`` flown on ``seeds``."""
    from coopnav_env.envs import UrbanCanyonEnv

    env = UrbanCanyonEnv(**env_kwargs)
    teacher = make_policy("waypoint", env, altitude_m=28.0)
    xs, ys = [], []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        teacher.reset(seed=seed)
        while env.agents:
            agents = list(env.agents)
            act = teacher.act(obs)
            xs.append(np.stack([obs[a] for a in agents]))
            ys.append(np.stack([np.clip(act[a], -1.0, 1.0) for a in agents]))
            obs, *_ = env.step(act)
    return np.concatenate(xs).astype(np.float32), np.concatenate(ys).astype(np.float32)


def actor_mse(trainer: MARLTrainer, x: np.ndarray, y: np.ndarray) -> float:
    """Mean squared error of the actor's mean (the Gaussian's location) to ``y``."""
    from tensordict import TensorDict

    td = TensorDict({("agents", "observation"): torch.from_numpy(x)}, batch_size=[len(x)])
    with torch.no_grad():
        loc = trainer.actor.module[0](td)["agents", "loc"].numpy()
    return float(np.mean((loc - y) ** 2))


# --------------------------------------------------------------------------------------------
# the fit
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_the_warm_start_brings_the_actors_mean_to_the_teachers_commands(algorithm) -> None:
    env_kwargs = {**V1_DEFAULTS, "max_steps": 30}
    settings = MARLSettings(algorithm=algorithm, n_copies=2, rollout_steps=8, gamma=1.0)
    trainer = MARLTrainer(settings, env_kwargs, seed=0)
    # the teacher's own episodes, flown here on the seeds the warm start uses
    first = EVAL_SEED_START // 2
    x, y = teacher_data(env_kwargs, list(range(first, first + SPEC.episodes)))
    before = actor_mse(trainer, x, y)
    critic_before = [p.detach().clone() for p in trainer.critic.parameters()]
    log_std_before = trainer.actor.module[0].module[1].state_independent_scale.detach().clone()
    info = trainer.warm_start(SPEC)
    after = actor_mse(trainer, x, y)
    assert after < 0.6 * before, (before, after)
    # what run.json records agrees with the measurement here, on the same samples
    assert info["teacher"] == "waypoint" and info["policy_kwargs"] == {"altitude_m": 28.0}
    assert info["samples"] == len(x)
    assert info["action_mse_before"] == pytest.approx(before, rel=1e-5)
    assert info["action_mse_after"] == pytest.approx(after, rel=1e-5)
    assert np.isfinite(info["value_mse_after"]) and info["return_scale"] > 0
    # the critic was fitted; the exploration noise was left as it was
    assert any(not torch.equal(a, b) for a, b in zip(critic_before, trainer.critic.parameters()))
    assert torch.equal(log_std_before, trainer.actor.module[0].module[1].state_independent_scale)
    assert trainer.agent_steps == 0 and trainer.episode_log == []


def test_ppo_meets_the_same_episodes_after_the_warm_start() -> None:
    """After the warm start the environment is back at the run's own first episodes."""
    settings = MARLSettings(algorithm="ippo", n_copies=2, rollout_steps=4)
    env_kwargs = {**V1_DEFAULTS, "max_steps": 30}
    plain = MARLTrainer(settings, env_kwargs, seed=4)
    warm = MARLTrainer(settings, env_kwargs, seed=4)
    warm.warm_start(WarmStart("waypoint", {}, episodes=3, epochs=1, learning_rate=1e-3))
    assert np.array_equal(plain._obs, warm._obs)
    assert np.array_equal(plain.reward_std.ret, warm.reward_std.ret)  # zero: a fresh start


# --------------------------------------------------------------------------------------------
# runs: pretrain null changes nothing; resume does not repeat it; interrupts
# --------------------------------------------------------------------------------------------


def test_pretrain_null_trains_bit_for_bit_as_the_plain_trainer(tmp_path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    assert train(a, "--timesteps", "32", "--seed", "2", *V0) == 0
    assert train(b, "--timesteps", "32", "--seed", "2", *V0, "--set", "torchrl.pretrain=null") == 0
    wa, wb = weights(a / "final_model.pt"), weights(b / "final_model.pt")
    assert wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa)
    # the trainer on its own, with no warm-start code on the way
    ckpt = load_marl_checkpoint(a / "final_model.pt")
    assert "warm_start" not in ckpt
    plain = MARLTrainer(MARLSettings.from_dict(ckpt["settings"]), ckpt["env_kwargs"], seed=2)
    plain.train(32)
    wc = {f"{n}.{k}": v for n in ("actor", "critic") for k, v in plain.state_dict()[n].items()}
    assert all(torch.equal(wa[k], wc[k]) for k in wa)
    assert json.loads((a / "run.json").read_text())["warm_start"] is None


def test_a_warm_started_run_reports_it_and_resume_does_not_repeat_it(
    tmp_path, monkeypatch, capsys
) -> None:
    out = tmp_path / "run"
    assert train(out, "--timesteps", "32", *V1, "--set", PRETRAIN) == 0
    assert "behaviour-cloning warm start: 2 episodes of the waypoint teacher" in (
        capsys.readouterr().err
    )
    run = json.loads((out / "run.json").read_text())
    ws = run["warm_start"]
    assert ws["teacher"] == "waypoint" and ws["episodes"] == 2
    assert ws["policy_kwargs"] == {"altitude_m": 28.0}
    assert ws["action_mse_after"] < ws["action_mse_before"]
    first = weights(out / "final_model.pt")

    def refuse(self, *args, **kw):
        raise AssertionError("the warm start ran again on resume")

    monkeypatch.setattr(MARLTrainer, "warm_start", refuse)
    assert train(out, "--timesteps", "64", "--resume", "latest", *V1, "--set", PRETRAIN) == 0
    assert "warm start" not in capsys.readouterr().err
    run = json.loads((out / "run.json").read_text())
    assert run["agent_steps"] == 64 and run["warm_start"] == ws  # kept from the checkpoint
    assert any(not torch.equal(first[k], v) for k, v in weights(out / "final_model.pt").items())


def test_an_interrupt_during_the_warm_start_leaves_a_reusable_folder(
    tmp_path, monkeypatch, capsys
) -> None:
    real = MARLTrainer.warm_start

    def warm_start(self, *args, **kw):
        os.kill(os.getpid(), signal.SIGINT)  # deferred: taken at the teacher's first step
        return real(self, *args, **kw)

    monkeypatch.setattr(MARLTrainer, "warm_start", warm_start)
    out = tmp_path / "run"
    assert train(out, "--timesteps", "32", *V1, "--set", PRETRAIN) == 130
    err = capsys.readouterr().err
    assert "nothing was trained" in err and "run the same command again" in err
    assert not (out / "config.yaml").exists() and not (out / "checkpoints").exists()
    monkeypatch.undo()
    assert train(out, "--timesteps", "32", *V1, "--set", PRETRAIN) == 0
    assert json.loads((out / "run.json").read_text())["warm_start"]["teacher"] == "waypoint"


# --------------------------------------------------------------------------------------------
# settings
# --------------------------------------------------------------------------------------------

GOOD = {
    "policy": "waypoint",
    "policy_kwargs": {},
    "episodes": 2,
    "epochs": 1,
    "learning_rate": 1e-3,
}


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"teacher": "waypoint"}, "teacher"),  # unknown key
        ({"policy": "ppo:runs/x"}, "pretrain.policy"),
        ({"policy": "nonsense"}, "pretrain.policy"),
        ({"policy": 3}, "pretrain.policy"),
        ({"policy_kwargs": [1]}, "pretrain.policy_kwargs"),
        ({"episodes": 0}, "pretrain.episodes"),
        ({"episodes": 2.5}, "pretrain.episodes"),
        ({"epochs": 0}, "pretrain.epochs"),
        ({"epochs": True}, "pretrain.epochs"),
        ({"learning_rate": 0.0}, "pretrain.learning_rate"),
        ({"episodes": EVAL_SEED_START}, "pretrain.episodes"),  # would reach held-out seeds
    ],
)
def test_bad_pretrain_settings_name_the_field(change, field) -> None:
    with pytest.raises(ValueError, match=re.escape(field)):
        WarmStart.from_value({**GOOD, **change})


def test_pretrain_must_be_a_complete_mapping() -> None:
    assert WarmStart.from_value(None) is None
    with pytest.raises(ValueError, match=r"torchrl\.pretrain must be null or a mapping"):
        WarmStart.from_value("waypoint")
    with pytest.raises(ValueError, match=r"torchrl\.pretrain lacks epochs"):
        WarmStart.from_value({k: v for k, v in GOOD.items() if k != "epochs"})


def test_the_command_line_refuses_bad_pretrain_settings_before_writing(tmp_path, capsys) -> None:
    out = tmp_path / "run"
    bad = PRETRAIN.replace("episodes: 2", "episodes: 0")
    assert train(out, "--timesteps", "32", *V1, "--set", bad) == 2
    assert "torchrl.pretrain.episodes" in capsys.readouterr().err
    residual = ["--set", PRETRAIN, "--set", "torchrl.residual_base=sky"]
    assert train(out, "--timesteps", "32", *V1, *residual) == 2
    assert "torchrl.pretrain needs torchrl.residual_base null" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())
    teacher_option = PRETRAIN.replace("altitude_m: 28.0", "no_such_option: 1")
    assert train(out, "--timesteps", "32", *V1, "--set", teacher_option) == 2
    assert "torchrl.pretrain.policy_kwargs" in capsys.readouterr().err


def test_the_shipped_v1_torchrl_section_warm_starts_from_waypoint() -> None:
    from coopnav_env.training.config import load_config

    section = load_config(env_id="urban_canyon_v1")
    spec = WarmStart.from_value(section["torchrl"]["pretrain"], seed=section["seed"])
    assert spec == WarmStart("waypoint", {"altitude_m": 28.0}, 60, 30, 1e-3)
    assert section["torchrl"]["residual_base"] is None
    # every other section trains as before, without a warm start
    assert "pretrain" not in load_config(env_id="urban_canyon_v0").get("torchrl", {})
