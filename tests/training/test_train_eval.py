"""Training (SB3 PPO through SuperSuit) and evaluation.

Most tests run on a tiny PettingZoo env of our own (:mod:`tests.training.toy_env`) so that the
seeding and bookkeeping are checked fast; the ``urban_canyon_v0`` tests train a few thousand
agent-steps on the real environment.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from coopnav_env.training.config import TrainConfig, apply_overrides, load_config
from coopnav_env.training.envs import EVAL_SEED_START, heldout_seeds
from coopnav_env.training.evaluate import evaluate
from coopnav_env.training.sb3_backend import find_latest_checkpoint, train
from coopnav_env.training.train import config_from_args
from coopnav_env.training.vec_env import make_vec_env
from tests.training.toy_env import ToyParallelEnv

TOY = "tests.training.toy_env:ToyParallelEnv"
TOY_ENV = {"n_uavs": 3, "max_steps": 12}
HAS_ENV = importlib.util.find_spec("coopnav_env.urban_canyon_v0") is not None
needs_env = pytest.mark.skipif(not HAS_ENV, reason="coopnav_env.urban_canyon_v0 not available")


def toy_cfg(out, **kw) -> TrainConfig:
    base = load_config()
    data = {
        **base,
        "env_id": TOY,
        "out": str(out),
        "timesteps": 1500,
        "n_envs": 2,
        "checkpoint_freq": 0,
        "env": dict(TOY_ENV),
        "ppo": {**base["ppo"], "n_steps": 32, "batch_size": 64, "n_epochs": 2},
        "pretrain": None,  # the toy env has no route to follow
        "progress_bar": False,
    }
    data.update(kw)
    return TrainConfig.from_dict(data)


def params(path) -> dict[str, np.ndarray]:
    from stable_baselines3 import PPO

    model = PPO.load(path, device="cpu")
    return {k: v.detach().numpy().copy() for k, v in model.policy.state_dict().items()}


# --------------------------------------------------------------------------------------------
# the seeded vector env
# --------------------------------------------------------------------------------------------


def _rollout(venv, seed: int, steps: int) -> list[np.ndarray]:
    venv.seed(seed)
    obs = [venv.reset()]
    act = np.zeros((venv.num_envs, 3), np.float32)
    for _ in range(steps):
        o, _r, _d, _i = venv.step(act)
        obs.append(o)
    return obs


def test_vec_env_seeds_copies_distinctly_and_repeats():
    fn = functools.partial(ToyParallelEnv, **TOY_ENV)
    venv = make_vec_env(fn, n_copies=3)
    assert venv.num_envs == 9
    assert venv.seed(5) == [5, 5, 5, 6, 6, 6, 7, 7, 7]
    a = _rollout(venv, 5, 30)  # crosses two automatic resets (max_steps = 12)
    b = _rollout(venv, 5, 30)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    # each swarm copy got its own seed: the goals (obs[2:4]) differ between copies
    goals = a[0][::3, 2:4]
    assert len({tuple(g) for g in goals}) == 3
    # copy k is reset with seed + k, exactly as a lone env reset with that seed
    lone = ToyParallelEnv(**TOY_ENV)
    obs, _ = lone.reset(seed=6)
    np.testing.assert_array_equal(a[0][3:6, :4], np.stack([obs[x][:4] for x in lone.agents]))
    venv.close()


def test_vec_env_two_processes_match_one():
    """SuperSuit alone gives process p, copy j the seed s + p + j (collisions); we correct it."""
    fn = functools.partial(ToyParallelEnv, **TOY_ENV)
    one = make_vec_env(fn, n_copies=4, num_cpus=1)
    two = make_vec_env(fn, n_copies=4, num_cpus=2)
    try:
        for x, y in zip(_rollout(one, 3, 15), _rollout(two, 3, 15)):
            np.testing.assert_array_equal(x, y)
    finally:
        one.close()
        two.close()


def test_vec_env_keeps_terminal_infos_and_flags_truncation():
    fn = functools.partial(ToyParallelEnv, n_uavs=2, max_steps=3)
    venv = make_vec_env(fn, n_copies=1)
    venv.seed(0)
    venv.reset()
    act = np.zeros((2, 3), np.float32)
    for _ in range(2):
        _o, _r, dones, infos = venv.step(act)
        assert not dones.any()
    _o, _r, dones, infos = venv.step(act)
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] is True
        assert "terminal_observation" in info
        # the final step's figures, not the new episode's reset infos
        np.testing.assert_allclose(info["pos_enu_m"][:2], info["terminal_observation"][:2])
    venv.close()


# --------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------


def test_overrides_parse_yaml_values_and_nest():
    cfg = apply_overrides(
        {"ppo": {"n_steps": 8}},
        ["ppo.learning_rate=1e-4", "n_envs=4", "ppo.policy_kwargs={net_arch: [32]}", "x.y=true"],
    )
    assert cfg["ppo"] == {"n_steps": 8, "learning_rate": 1e-4, "policy_kwargs": {"net_arch": [32]}}
    assert cfg["n_envs"] == 4 and cfg["x"] == {"y": True}
    with pytest.raises(ValueError, match="key=value"):
        apply_overrides({}, ["novalue"])


def test_packaged_config_is_valid():
    cfg = TrainConfig.from_dict({**load_config(), "out": "x"})
    assert cfg.env_id == "urban_canyon_v1" and cfg.timesteps > 0 and "n_steps" in cfg.ppo


def test_cli_flags_override_yaml(tmp_path):
    from coopnav_env.training.train import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(
        ["--out", str(tmp_path), "--timesteps", "1234", "--n-uavs", "3", "--set",
         "ppo.n_steps=16", "--env-set", "max_steps=50", "--seed", "7", "--no-progress"]
    )  # fmt: skip
    cfg = config_from_args(args)
    assert (cfg.timesteps, cfg.seed, cfg.progress_bar) == (1234, 7, False)
    assert cfg.env["n_uavs"] == 3 and cfg.env["max_steps"] == 50 and cfg.ppo["n_steps"] == 16
    for key, value in (load_config()["env"] or {}).items():  # the YAML's env settings are kept
        assert cfg.env[key] == value, key


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"timesteps": -5}, "timesteps must be >= 1"),
        ({"timesteps": 0}, "timesteps must be >= 1"),
        ({"seed": EVAL_SEED_START}, "seed must be in"),
        ({"n_envs": 0}, "n_envs must be >= 1"),
        ({"bogus": 1}, "unknown training setting"),
        ({"pretrain": {"teacher": "waypoint"}}, "unknown pretrain setting"),
        ({"pretrain": "waypoint"}, "pretrain must be a mapping"),
        ({"pretrain": {"episodes": 0}}, r"pretrain.episodes must be an integer >= 1, got 0"),
        ({"pretrain": {"epochs": -1}}, r"pretrain.epochs must be an integer >= 0, got -1"),
        ({"pretrain": {"learning_rate": 0}}, r"pretrain.learning_rate must be > 0, got 0"),
        ({"pretrain": {"policy": 3}}, r"pretrain.policy must be a policy name, got 3"),
        ({"pretrain": {"policy_kwargs": 3}}, r"pretrain.policy_kwargs must be a mapping"),
        (
            {"seed": 499_950, "pretrain": {"episodes": 60}},
            r"teacher's episode seeds 999950..1000009 would reach the held-out",
        ),
        ({"normalize_reward": "yes"}, "normalize_reward must be true or false"),
    ],
)
def test_bad_training_settings(tmp_path, change, match):
    with pytest.raises(ValueError, match=match):
        toy_cfg(tmp_path, **change)


def test_unknown_ppo_setting_and_missing_resume(tmp_path):
    cfg = toy_cfg(tmp_path, ppo={"n_stepz": 3})
    with pytest.raises(ValueError, match=r"unknown PPO setting.*n_stepz"):
        train(cfg)
    with pytest.raises(FileNotFoundError, match=r"nope\.zip"):
        train(toy_cfg(tmp_path, resume=str(tmp_path / "nope.zip")))
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        train(toy_cfg(tmp_path, resume="latest"))


def test_cli_negative_timesteps_is_a_clear_error(tmp_path, capsys):
    from coopnav_env.training.cli import main

    rc = main(["train", "--out", str(tmp_path), "--timesteps", "-1"])
    assert rc == 2
    assert "timesteps must be >= 1, got -1" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------
# training on the toy env
# --------------------------------------------------------------------------------------------


def test_same_seed_same_parameters_toy(tmp_path):
    a = params(train(toy_cfg(tmp_path / "a", seed=3)))
    b = params(train(toy_cfg(tmp_path / "b", seed=3)))
    c = params(train(toy_cfg(tmp_path / "c", seed=4)))
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    assert any(not np.array_equal(a[k], c[k]) for k in a)


def test_outputs_checkpoints_and_resume(tmp_path):
    out = tmp_path / "run"
    final = train(toy_cfg(out, timesteps=800, checkpoint_freq=300))
    assert final == out / "final_model.zip" and final.is_file()
    saved = json.loads((out / "run.json").read_text())
    assert saved["seed"] == 0 and saved["agent_steps_per_s"] > 0
    assert "seed: 0" in (out / "config.yaml").read_text()
    assert list((out / "logs").glob("events.out.tfevents*"))
    header = (out / "logs" / "progress.csv").read_text().splitlines()[0]
    assert "nav/coop_error_mean_m" in header and "rollout/ep_rew_mean" in header
    latest = find_latest_checkpoint(out)
    n_ckpt = int(latest.stem.split("_")[1])
    assert n_ckpt % 192 == 0 and 300 <= n_ckpt <= 800  # saved right after an update

    with pytest.raises(ValueError, match="cannot resume"):
        train(toy_cfg(out, timesteps=1600, resume="latest", env={"n_uavs": 3, "max_steps": 9}))
    # the run is finished: training it further continues from its final model (issue 15:
    # not from the last periodic checkpoint, which would lose the steps after it)
    n_final = saved["num_timesteps"]
    assert n_final > n_ckpt
    final2 = train(toy_cfg(out, timesteps=1600, resume="latest"))
    from stable_baselines3 import PPO

    model = PPO.load(final2, device="cpu")
    assert 1600 <= model.num_timesteps < 1600 + 192
    assert json.loads((out / "run.json").read_text())["resumed_from"] == str(final)
    # one learning curve over both sessions: every iteration once, in order (issue 35)
    text = (out / "logs" / "progress.csv").read_text().splitlines()
    col = text[0].split(",").index("time/total_timesteps")
    steps = [int(float(line.split(",")[col])) for line in text[1:]]
    assert steps == sorted(set(steps)) and steps[-1] >= 1600 and n_final in steps
    assert (out / f"config_resumed_at_{n_final}.yaml").is_file()
    assert (out / f"resumed_at_{n_final}.monitor.csv").is_file()


# --------------------------------------------------------------------------------------------
# evaluation on the toy env
# --------------------------------------------------------------------------------------------


def test_heldout_seeds():
    assert heldout_seeds(3) == [EVAL_SEED_START, EVAL_SEED_START + 1, EVAL_SEED_START + 2]
    with pytest.raises(ValueError, match=">= 1"):
        heldout_seeds(0)
    with pytest.raises(ValueError, match="training uses"):
        heldout_seeds(2, start=5)


def test_evaluate_is_deterministic_and_writes_reports(tmp_path):
    seeds = heldout_seeds(3)
    r1 = evaluate(["random"], seeds, TOY_ENV, tmp_path / "e1", env_id=TOY)
    r2 = evaluate(["random"], seeds, TOY_ENV, None, env_id=TOY)
    assert r1.to_dict() | {"policies": None} == r2.to_dict() | {"policies": None}
    s1, s2 = r1["random"], r2["random"]
    for f in ("coop_error_mean_m", "p_coop_error_lt_3m", "goal_rate", "return_mean"):
        assert getattr(s1, f) == getattr(s2, f)
    assert s1.episodes == 3 and s1.agent_steps > 0
    names = {p.name for p in r1.files.values()}
    assert {"report.json", "report.csv", "report.md", "error_cdf.png"} <= names
    assert "trajectories_random.png" in names
    data = json.loads((tmp_path / "e1" / "report.json").read_text())
    assert data["seeds"] == seeds and data["policies"][0]["policy"] == "random"
    assert "| random |" in (tmp_path / "e1" / "report.md").read_text()
    assert [e["seed"] for e in data["episodes"]["random"]] == seeds
    assert r1.paired_difference("random", "random") == (0.0, 0.0, 3)


def test_paired_difference_by_episode():
    from coopnav_env.training.evaluate import EpisodeRecord, Report

    def record(seed, errors):
        e = np.asarray(errors, dtype=float)
        z = np.zeros_like(e)
        return EpisodeRecord(seed, e, e, z, z, e, None, z > 0, True, False, 0.0, e.shape[0])

    a = [record(1, [[1.0, 3.0]]), record(2, [[5.0, np.nan]]), record(3, [[np.nan, np.nan]])]
    a.append(record(9, [[7.0, 7.0]]))  # flown by "a" only: no pair
    b = [record(2, [[2.0, 2.0]]), record(1, [[1.0, 1.0]]), record(3, [[1.0, 1.0]])]  # by seed
    report = Report([], [1, 2, 3], {}, "x", episodes={"a": a, "b": b})
    diff, se, n = report.paired_difference("a", "b")
    assert n == 2  # episode 3: no fix for "a"
    assert diff == pytest.approx((1.0 + 3.0) / 2)  # per-episode differences 1 and 3
    assert se == pytest.approx(np.std([1.0, 3.0], ddof=1) / np.sqrt(2))


def test_evaluate_bad_policies(tmp_path):
    with pytest.raises(
        ValueError,
        match=r"unknown policy 'greedy'; valid policies: random, column, .*formation, sky,",
    ):
        evaluate(["greedy"], [EVAL_SEED_START], TOY_ENV, None, env_id=TOY)
    with pytest.raises(FileNotFoundError, match=r"missing/model\.zip"):
        evaluate(["ppo:missing/model.zip"], [EVAL_SEED_START], TOY_ENV, None, env_id=TOY)
    with pytest.raises(ValueError, match="at least one evaluation seed"):
        evaluate(["random"], [], TOY_ENV, None, env_id=TOY)


def test_evaluate_cli_reports_unknown_policy(capsys):
    from coopnav_env.training.cli import main

    rc = main(["evaluate", "--policies", "nope", "--env-id", TOY, "--episodes", "1"])
    assert rc == 2 and "unknown policy 'nope'" in capsys.readouterr().err


def test_trained_toy_model_evaluates(tmp_path):
    final = train(toy_cfg(tmp_path / "run", timesteps=600))
    rep = evaluate(
        ["random", f"ppo:{final}"], heldout_seeds(2), TOY_ENV, tmp_path / "ev", env_id=TOY
    )
    assert [s.policy for s in rep.stats] == ["random", f"ppo:{final}"]
    again = evaluate([f"ppo:{final}"], heldout_seeds(2), TOY_ENV, None, env_id=TOY)
    assert again.stats[0].return_mean == rep.stats[1].return_mean


# --------------------------------------------------------------------------------------------
# urban_canyon_v0
# --------------------------------------------------------------------------------------------

URBAN_ENV = {"n_uavs": 3, "max_steps": 40}


def urban_cfg(out, **kw) -> TrainConfig:
    base = load_config()
    data = {
        **base,
        "out": str(out),
        "timesteps": 700,
        "n_envs": 2,
        "checkpoint_freq": 0,
        "env": dict(URBAN_ENV),
        "ppo": {**base["ppo"], "n_steps": 64, "batch_size": 128, "n_epochs": 2},
        "pretrain": None,  # fast tests; behaviour cloning has its own test
        "progress_bar": False,
    }
    data.update(kw)
    return TrainConfig.from_dict(data)


@needs_env
def test_urban_smoke_train_save_reload_evaluate(tmp_path):
    out = tmp_path / "quick"
    final = train(urban_cfg(out, timesteps=1500, checkpoint_freq=700))
    assert final.is_file() and find_latest_checkpoint(out).is_file()
    header = (out / "logs" / "progress.csv").read_text().splitlines()[0]
    for key in ("nav/coop_error_mean_m", "nav/goal_rate", "rollout/ep_rew_mean"):
        assert key in header
    rep = evaluate(
        ["random", "formation", "sky", f"ppo:{final}"], heldout_seeds(2), URBAN_ENV, out / "eval"
    )
    assert [s.episodes for s in rep.stats] == [2, 2, 2, 2]
    for s in rep.stats:
        assert 0.0 <= s.goal_rate <= 1.0 and 0.0 <= s.p_coop_error_lt_3m <= 1.0
        assert s.n_sats_mean > 0
    assert (out / "eval" / "error_cdf.png").is_file()
    assert len(list((out / "eval").glob("trajectories_*.png"))) == 4


@needs_env
def test_urban_behaviour_cloning_warm_start(tmp_path):
    """``pretrain``: the fresh policy is fitted to the waypoint follower before PPO starts."""
    import torch
    from stable_baselines3 import PPO

    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy

    out = tmp_path / "bc"
    cfg = urban_cfg(out, timesteps=1, pretrain={"episodes": 3, "epochs": 20})
    assert cfg.pretrain["policy"] == "waypoint"
    train(cfg)
    stats = json.loads((out / "pretrain.json").read_text())
    assert stats["teacher"] == "waypoint" and stats["samples"] > 50
    assert stats["final_action_mse"] < 0.05
    # the cloned policy's mean action is close to the teacher's (first teacher episode; one
    # short PPO update has run since)
    model = PPO.load(out / "final_model.zip")
    env = urban_canyon_v0.parallel_env(**URBAN_ENV)
    teacher = make_policy("waypoint", env)
    obs, _ = env.reset(seed=EVAL_SEED_START // 2 + cfg.seed)
    x = np.stack([obs[a] for a in env.agents])
    with torch.no_grad():
        mean = model.policy.get_distribution(model.policy.obs_to_tensor(x)[0]).distribution.mean
    want = np.stack([teacher.act(obs)[a] for a in env.agents])
    assert np.abs(mean.numpy() - want).max() < 0.4


@needs_env
def test_urban_same_seed_same_parameters(tmp_path):
    a = params(train(urban_cfg(tmp_path / "a", seed=11)))
    b = params(train(urban_cfg(tmp_path / "b", seed=11)))
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


@needs_env
def test_urban_evaluation_is_deterministic():
    seeds = heldout_seeds(2)
    r1 = evaluate(["random", "sky"], seeds, URBAN_ENV, None)
    r2 = evaluate(["random", "sky"], seeds, URBAN_ENV, None)
    for s1, s2 in zip(r1.stats, r2.stats):
        d1, d2 = s1.__dict__.copy(), s2.__dict__.copy()
        d1.pop("wall_s"), d2.pop("wall_s")
        assert d1 == d2
    e1 = r1.episodes["sky"][0].coop_error_m
    np.testing.assert_array_equal(e1, r2.episodes["sky"][0].coop_error_m)


@needs_env
def test_urban_bad_env_setting_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="unknown urban_canyon argument"):
        train(urban_cfg(tmp_path, env={"n_uav": 3}))
    with pytest.raises(ValueError, match="unknown urban_canyon argument"):
        evaluate(["random"], heldout_seeds(1), {"bogus": 1}, None)


def test_evaluate_cli_uses_the_training_environment(tmp_path, capsys):
    """``coopnav evaluate ppo:RUN/final_model.zip`` runs in the env RUN was trained in."""
    from coopnav_env.training import evaluate_cli as ev

    final = train(toy_cfg(tmp_path / "run", timesteps=200, env={"n_uavs": 2, "max_steps": 5}))
    parser = argparse.ArgumentParser()
    ev.add_arguments(parser)
    out = tmp_path / "ev"
    args = parser.parse_args(
        ["--policies", "random", f"ppo:{final}", "--episodes", "2", "--out", str(out), "--no-plots"]
    )
    assert ev.run(args) == 0
    assert "| random |" in capsys.readouterr().out
    data = json.loads((out / "report.json").read_text())
    assert data["env_id"] == TOY and data["env_kwargs"] == {"n_uavs": 2, "max_steps": 5}
    assert all(p["length_mean"] == 5.0 for p in data["policies"])


def test_clustered_standard_error_of_the_pooled_mean():
    """Episodes as clusters: equals the textbook formula, and ignores NaN (no-fix) samples."""
    from coopnav_env.training.evaluate import clustered_se

    rng = np.random.default_rng(0)
    eps = [rng.normal(3.0 + rng.normal(), 0.5, size=rng.integers(20, 60)) for _ in range(12)]
    eps[3][:5] = np.nan
    finite = [e[np.isfinite(e)] for e in eps]
    total = sum(f.size for f in finite)
    mean = sum(f.sum() for f in finite) / total
    want = np.sqrt(12 / 11 * sum((f.sum() - f.size * mean) ** 2 for f in finite)) / total
    assert clustered_se(eps) == pytest.approx(want, rel=1e-12)
    # the episode-to-episode spread (sd 1 of the episode means) dominates: the naive
    # per-sample SE would be several times smaller
    naive = np.concatenate(finite).std(ddof=1) / np.sqrt(total)
    assert clustered_se(eps) > 2 * naive
    # identical episodes: no spread between clusters
    assert clustered_se([np.ones(5), np.ones(5)]) == 0.0
    assert np.isnan(clustered_se([np.ones(5)]))
