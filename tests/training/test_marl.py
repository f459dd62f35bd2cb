"""The TorchRL MAPPO/IPPO backend: settings, learning signal, checkpoints, evaluation."""

from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from coopnav_env import urban_canyon_v0  # noqa: E402
from coopnav_env.agents import make_policy  # noqa: E402
from coopnav_env.agents.marl_nets import (  # noqa: E402
    REMOVED_SETTINGS,
    MARLSettings,
    settings_from_record,
)
from coopnav_env.training.cli import main  # noqa: E402
from coopnav_env.training.torchrl_backend import MARLTrainer  # noqa: E402
from tests.fly_alike import assert_fly_alike  # noqa: E402

SMALL = ["--set", "torchrl.n_copies=2", "--set", "torchrl.rollout_steps=8", "--no-progress"]
V0 = ["--env-id", "urban_canyon_v0"]  # tests of v0's torchrl section (a residual over a column)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("algorithm", "qmix"),
        ("n_copies", 0),
        ("learning_rate", 0.0),
        ("gamma", 1.5),
        ("hidden", [64, 32]),
        ("lr_schedule", "cosine"),
        ("action_repeat", 0),
        ("start_hold_decisions", -1),
        ("start_hold_decisions", True),
    ],
)
def test_bad_settings_name_the_field(field, value) -> None:
    with pytest.raises(ValueError, match=field):
        MARLSettings(**{field: value})
    with pytest.raises(ValueError, match="unknown torchrl setting"):
        MARLSettings.from_dict({"lr": 1e-3})


@pytest.mark.parametrize("name", sorted(REMOVED_SETTINGS))
def test_a_removed_setting_is_refused_by_name_saying_it_was_removed(name) -> None:
    with pytest.raises(ValueError, match=rf"\['{name}'\] were removed from coopnav"):
        MARLSettings.from_dict({name: None})
    assert name not in {f.name for f in dataclasses.fields(MARLSettings)}


def test_recorded_settings_of_removed_switches_fly_unless_they_changed_the_flight() -> None:
    """A checkpoint of an earlier release records every setting, removed ones included:
    training-only ones (exploration noise, the objective of held starts) are dropped for
    flight, flight-changing ones refused; resuming refuses any that changed the run."""
    old = {
        "algorithm": "mappo",
        "action_repeat": 4,
        "residual_mode": "velocity",
        "offset_scale_m": [15.0, 8.0, 8.0],
        "option_shifts_m": [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]],
        "option_init_prob": 0.8,
        "residual_wall_guard": False,
        "noise_correlation": 1.0,
        "noise_correlated_decisions": 3,
        "noise_correlated_entries": [0],
        "noise_centred_entries": [0],
        "start_hold_decisions": 4,
        "start_hold_objective": "importance",
    }
    flown = settings_from_record(old, "run/final_model.pt", "fly")
    assert flown == MARLSettings(algorithm="mappo", action_repeat=4, start_hold_decisions=4)
    with pytest.raises(ValueError, match=r"torchrl\.noise_correlation=1\.0.*removed") as info:
        settings_from_record(old, "run/final_model.pt", "resume")
    assert "torchrl.start_hold_objective='importance'" in str(info.value)
    assert "run/final_model.pt" in str(info.value)
    for mode in ("offset", "options"):
        with pytest.raises(
            ValueError, match=rf"residual_mode='{mode}'.*removed.*cannot have it flown"
        ):
            settings_from_record({**old, "residual_mode": mode}, "x.pt", "fly")
    with pytest.raises(ValueError, match="residual_wall_guard=True"):
        settings_from_record({**old, "residual_wall_guard": True}, "x.pt", "fly")
    # held starts of a release before start_hold_objective existed (its record names the
    # other settings it had, removed since) were masked: not resumable
    with pytest.raises(ValueError, match="start_hold_objective='masked'"):
        settings_from_record(
            {"start_hold_decisions": 3, "residual_mode": "velocity"}, "x.pt", "resume"
        )
    # a record of this version names no removed setting: its held starts are the kept ones
    assert settings_from_record({"start_hold_decisions": 3}, "x.pt", "resume") == (
        MARLSettings(start_hold_decisions=3)
    )
    # what stays (held starts logged with the actor's own log-probability, no noise) resumes
    kept = {**old, "noise_correlation": 0.0, "start_hold_objective": "unweighted"}
    assert settings_from_record(kept, "x.pt", "resume") == flown
    assert settings_from_record({"start_hold_objective": "masked"}, "x.pt", "resume") == (
        MARLSettings()
    )


def test_linear_learning_rate_falls_to_zero_over_the_budget(tmp_path) -> None:
    s = MARLSettings(algorithm="ippo", n_copies=2, rollout_steps=8, lr_schedule="linear")
    tr = MARLTrainer(s, {}, seed=0)
    assert tr.learning_rate_at(0, 400) == pytest.approx(3e-4)
    assert tr.learning_rate_at(100, 400) == pytest.approx(2.25e-4)
    assert tr.learning_rate_at(400, 400) == 0.0
    const = MARLTrainer(MARLSettings(algorithm="ippo", n_copies=2, rollout_steps=8), {}, 0)
    assert const.learning_rate_at(300, 400) == pytest.approx(3e-4)
    # through the CLI: progress.csv logs the rate of every iteration, falling linearly
    out = tmp_path / "lin"
    args = ["train", "--backend", "torchrl", "--algorithm", "ippo", "--out", str(out)]
    lin = ["--set", "torchrl.lr_schedule=linear"]
    assert main([*args, "--timesteps", "240", *lin, *SMALL]) == 0
    import csv

    rows = list(csv.DictReader(open(out / "logs" / "progress.csv")))
    lrs = [float(r["learning_rate"]) for r in rows]
    steps = [0.0] + [float(r["agent_steps"]) for r in rows[:-1]]
    assert lrs == pytest.approx([3e-4 * (1 - x / 240) for x in steps], rel=1e-4)
    assert lrs[0] > lrs[-1] > 0.0


def test_the_actor_explores_and_learns() -> None:
    # regression: TorchRL actors return the distribution's mode unless the exploration type
    # is set, which gave zero policy gradients (a - mean = 0) and no exploration
    tr = MARLTrainer(MARLSettings(algorithm="ippo", n_copies=2, rollout_steps=8), {}, seed=0)
    data = tr.collect()
    loc_in = data["agents", "observation"]
    with torch.no_grad():
        mean = tr.actor.module[0](data.clone())["agents", "loc"]
    assert not torch.allclose(data["agents", "action"], mean)  # sampled, not the mean
    before = [p.detach().clone() for p in tr.actor.parameters()]
    tr.update(data)
    moved = [float((p - b).abs().max()) for p, b in zip(tr.actor.parameters(), before)]
    assert all(m > 0.0 for m in moved)  # every actor weight got a gradient
    assert loc_in.shape[-1] == 52


def test_mappo_critic_reads_the_state_and_ippo_does_not() -> None:
    cfg = urban_canyon_v0.parallel_env().config
    m = MARLTrainer(MARLSettings(algorithm="mappo", n_copies=1, rollout_steps=2), {}, 0)
    i = MARLTrainer(MARLSettings(algorithm="ippo", n_copies=1, rollout_steps=2), {}, 0)
    assert m.critic_dim == cfg.obs_dim + cfg.state_dim
    assert i.critic_dim == cfg.obs_dim
    data = m.collect()
    crit = data["agents", "critic_input"][0, 0]  # copy 0, step 0: (N, S + D)
    state = torch.as_tensor(m.venv.envs[0].state())  # not the same step, but the same layout
    assert crit.shape == (5, cfg.state_dim + cfg.obs_dim)
    assert torch.equal(crit[0, : cfg.state_dim], crit[4, : cfg.state_dim])  # shared state
    assert state.shape == (cfg.state_dim,)


def test_an_untrained_residual_policy_flies_exactly_like_its_base(tmp_path) -> None:
    s = MARLSettings(algorithm="mappo", n_copies=1, rollout_steps=2, residual_base="spread")
    MARLTrainer(s, {}, seed=0).save(tmp_path / "final_model.pt")
    assert_fly_alike(f"mappo:{tmp_path}", "spread", seed=1_000_003, steps=40)


def test_action_repeat_holds_the_actors_output_and_sums_the_rewards(monkeypatch) -> None:
    import coopnav_env.training.torchrl_backend as backend

    s = MARLSettings(
        algorithm="mappo",
        n_copies=2,
        rollout_steps=4,
        residual_base="ceiling",
        action_repeat=3,
        normalize_reward=False,
    )
    tr = MARLTrainer(s, {"n_uavs": 3, "max_steps": 7}, seed=2)
    raws, steps = [], []
    real_command, real_step = backend.swarm_command, tr.venv.step_arrays

    def command(settings, raw, *args):
        raws.append(np.array(raw))
        return real_command(settings, raw, *args)

    def step(cmd):
        out = real_step(cmd)
        steps.append((out[1].copy(), (out[2] | out[3]).copy()))  # rewards, episode ends
        return out

    monkeypatch.setattr(backend, "swarm_command", command)
    monkeypatch.setattr(tr.venv, "step_arrays", step)
    data = tr.collect()
    assert tr.agent_steps == 2 * 4 * 3 * 3  # copies x decisions x repeat x UAVs
    assert len(steps) == 4 * 3  # 3 swarm steps per decision
    raws = np.array(raws).reshape(4, 3, 2, 3, 3)  # decision, step, copy, UAV, axis
    assert np.all(raws == raws[:, :1])  # held within a decision
    np.testing.assert_array_equal(raws[:, 0], data["agents", "action"].numpy().swapaxes(0, 1))
    rew = data["next", "agents", "reward"].numpy()[..., 0]  # (copy, decision, UAV)
    done = data["next", "agents", "done"].numpy()[..., 0, 0]  # (copy, decision)
    for d in range(4):
        for k in range(2):
            want, ended = np.zeros(3), False
            for j in range(3):  # summed up to the episode's end, nothing after it
                r, e = steps[3 * d + j]
                if not ended:
                    want += r[k]
                ended |= bool(e[k])
            np.testing.assert_allclose(rew[k, d], want, rtol=1e-6)
            assert done[k, d] == ended
    assert done.any()  # an episode of 7 steps ended within the 12 steps
    # the per-decision discount
    assert tr.loss.value_estimator.gamma == pytest.approx(0.99**3)


def _record_commands(tr: MARLTrainer) -> list[np.ndarray]:
    """The list that every swarm command ``tr`` flies from now on is appended to."""
    flown: list[np.ndarray] = []
    step = tr.venv.step_arrays
    tr.venv.step_arrays = lambda cmd: flown.append(cmd.copy()) or step(cmd)
    return flown


def test_exploring_starts_hold_uavs_in_place_logged_as_the_actors_own_draws() -> None:
    from scipy.stats import norm

    s = MARLSettings(algorithm="mappo", n_copies=16, rollout_steps=8, start_hold_decisions=2)
    env = {"n_uavs": 3, "max_steps": 5, "action_frame": "route"}
    tr = MARLTrainer(s, env, seed=5)
    flown = _record_commands(tr)
    data = tr.collect()
    act = data["agents", "action"].numpy()  # (copy, decision, UAV, entry)
    held = act[..., 0] <= -1.0
    cmd = np.stack(flown, axis=1)  # action_repeat 1: one command per decision
    # held decisions fly the speed set-point -1 (in place); every decision flies as stored
    np.testing.assert_array_equal(cmd, np.clip(act, -1.0, 1.0))
    # the logged log-probability is the actor's own of the stored action, held or not
    with torch.no_grad():
        dist = tr.actor.get_dist(data.select(("agents", "observation")))
        pi = dist.log_prob(data["agents", "action"]).numpy()
        mu, sd = dist.base_dist.loc[..., 0].numpy(), dist.base_dist.scale[..., 0].numpy()
    np.testing.assert_allclose(data["agents", "action_log_prob"].numpy(), pi, rtol=1e-5)
    # each UAV is held for the first 0, 1 or 2 decisions of every episode, then released:
    # the actor's own draws reach below -1 only by chance (its tail's probability)
    done = data["next", "agents", "done"].numpy()[:, :, 0, 0]
    starts = np.zeros_like(done)
    starts[:, 1:] = done[:, :-1]
    starts[:, 0] = True
    held_counts = []
    for k in range(16):
        begin = [*np.flatnonzero(starts[k]).tolist(), 8]
        for a, b in itertools.pairwise(begin):
            if b - a < 3:  # an episode cut by the rollout's end
                continue
            for u in range(3):
                h = int(np.argmin(held[k, a:b, u])) if not held[k, a:b, u].all() else b - a
                held_counts.append(h)
    assert set(held_counts) == {0, 1, 2}
    assert done.any()  # some copies met a second episode, with new holds
    tail = norm.cdf((-1.0 - mu) / sd)
    assert tail[:, 2:].mean() < 0.2  # so that the holds above are the exploring starts
    # the update standardises the advantages over every decision (nothing left out)
    assert tr.loss.normalize_advantage
    assert ("agents", "learn") not in data.keys(True)
    tr.update(data)
    # the same seed holds the same UAVs
    tr2 = MARLTrainer(s, env, seed=5)
    np.testing.assert_array_equal(tr2.collect()["agents", "action"].numpy(), act)
    # off by default: nobody is held at the first decision beyond the actor's own tail
    tr0 = MARLTrainer(dataclasses.replace(s, start_hold_decisions=0), env, seed=5)
    first = tr0.collect()["agents", "action"].numpy()[:, 0, :, 0] <= -1.0
    assert first.mean() < 0.3 and held[:, 0].mean() > 0.5  # P(held) = 2/3 with holds
    with pytest.raises(ValueError, match=r"start_hold_decisions.*route"):
        MARLTrainer(s, {"n_uavs": 3}, seed=5)
    with pytest.raises(ValueError, match="start_hold_decisions"):
        MARLSettings(residual_base="wide", start_hold_decisions=2)


def test_an_action_repeat_policy_decides_every_few_steps(tmp_path, monkeypatch) -> None:
    s = MARLSettings(algorithm="ippo", n_copies=1, rollout_steps=2, action_repeat=3)
    MARLTrainer(s, {"n_uavs": 3}, seed=0).save(tmp_path / "final_model.pt")
    env = urban_canyon_v0.parallel_env(n_uavs=3)
    policy = make_policy(f"ippo:{tmp_path}", env)
    calls = []
    real = policy._actor.module[0].forward
    monkeypatch.setattr(policy._actor.module[0], "forward", lambda td: calls.append(1) or real(td))
    obs, _ = env.reset(seed=4)
    policy.reset(4)
    acts = []
    for _ in range(7):
        act = policy.act(obs)
        acts.append(np.stack([act[a] for a in env.possible_agents]))
        obs, *_ = env.step(act)
    assert len(calls) == 3  # decisions at steps 0, 3 and 6
    assert np.array_equal(acts[0], acts[1]) and np.array_equal(acts[0], acts[2])
    policy.reset(5)  # a new episode decides at once
    policy.act(env.reset(seed=5)[0])
    assert len(calls) == 4


def test_train_checkpoint_resume_evaluate_through_the_cli(tmp_path, capsys) -> None:
    out = tmp_path / "run"
    args = ["train", "--backend", "torchrl", "--algorithm", "mappo", "--out", str(out)]
    assert main([*args, "--timesteps", "160", "--checkpoint-freq", "80", *SMALL]) == 0
    ckpts = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert ckpts == ["marl_160_steps.pt", "marl_80_steps.pt"]
    assert (out / "final_model.pt").is_file() and (out / "config.yaml").is_file()
    import json

    run = json.loads((out / "run.json").read_text())
    assert run["algorithm"] == "mappo" and run["agent_steps"] == 160
    assert run["env"]["nav_team_weight"] == 1.0  # the torchrl.env overrides were applied
    resumed = [*args, "--timesteps", "240", "--resume", "latest", *SMALL]
    assert main(resumed) == 0
    assert json.loads((out / "run.json").read_text())["agent_steps"] == 240
    assert (
        main(
            [
                "evaluate",
                "--policies",
                "spread",
                f"mappo:{out}",
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "eval"),
                "--no-plots",
            ]
        )
        == 0
    )
    text = (tmp_path / "eval" / "report.md").read_text()
    assert "mappo:" in text and "nav_team_weight" in text  # evaluated in the run's env
    capsys.readouterr()
    assert main(["train", "--algorithm", "mappo", "--out", str(tmp_path / "x")]) == 2
    assert "--algorithm only applies to --backend torchrl" in capsys.readouterr().err


def test_same_seed_same_weights(tmp_path) -> None:
    weights = []
    for _ in range(2):
        s = MARLSettings(
            algorithm="ippo",
            n_copies=2,
            rollout_steps=4,
            residual_base="sky",
        )
        tr = MARLTrainer(s, {}, seed=3)
        tr.update(tr.collect())
        weights.append(torch.cat([p.detach().ravel() for p in tr.actor.parameters()]))
    assert torch.equal(weights[0], weights[1])


def test_torchrl_wrapper_accepts_the_environment() -> None:
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    for state in (True, False):
        env = PettingZooWrapper(
            urban_canyon_v0.parallel_env(max_steps=20), return_state=state, seed=0
        )
        check_env_specs(env)
        td = env.rollout(5)
        keys = [k for k in td.keys(True, True) if isinstance(k, tuple)]
        # the flat infos arrive as numbers under the agents' group ("uav": uav_0 ... uav_4)
        assert any(k[-1] == "coop_error_m" and "info" in k for k in keys)
        assert any(k[-1] == "coop_fix" and "info" in k for k in keys)
        env.close()


def test_export_keeps_the_actor_and_acts_alike(tmp_path) -> None:
    from coopnav_env.training.torchrl_backend import export_policy

    s = MARLSettings(algorithm="ippo", n_copies=1, rollout_steps=4)
    tr = MARLTrainer(s, {}, seed=0)
    tr.update(tr.collect())
    tr.save(tmp_path / "run" / "final_model.pt")
    (tmp_path / "run" / "config.yaml").write_text("env_id: urban_canyon_v0\nenv: {}\n")
    small = export_policy(tmp_path / "run", tmp_path / "shipped")
    assert small.stat().st_size < 0.3 * (tmp_path / "run" / "final_model.pt").stat().st_size
    # the run's environment travels with it, for coopnav evaluate
    assert (tmp_path / "shipped" / "config.yaml").read_text().startswith("env_id: urban_canyon_v0")
    env_a, env_b = urban_canyon_v0.parallel_env(), urban_canyon_v0.parallel_env()
    full = make_policy(f"ippo:{tmp_path / 'run'}", env_a)
    shipped = make_policy(f"ippo:{tmp_path / 'shipped'}", env_b)
    obs, _ = env_a.reset(seed=1_000_000)
    a, b = full.act(obs), shipped.act(obs)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


def test_export_policy_from_a_checkpoint_takes_the_runs_config_only(tmp_path) -> None:
    from coopnav_env.training.torchrl_backend import export_policy

    s = MARLSettings(algorithm="ippo", n_copies=1, rollout_steps=4)
    tr = MARLTrainer(s, {}, seed=0)
    run = tmp_path / "run"
    tr.save(run / "checkpoints" / "marl_4_steps.pt")
    (run / "config.yaml").write_text("env_id: urban_canyon_v0\nenv: {}\n")
    (run / "run.json").write_text('{"agent_steps": 1000}')
    export_policy(run / "checkpoints" / "marl_4_steps.pt", tmp_path / "early")
    assert (tmp_path / "early" / "config.yaml").read_text().startswith("env_id: urban_canyon_v0")
    assert not (tmp_path / "early" / "run.json").exists()  # it describes the finished run
    make_policy(f"ippo:{tmp_path / 'early'}", urban_canyon_v0.parallel_env())


REPO = Path(__file__).resolve().parents[2]
DEGRADED_STUDY_POLICIES = REPO / "studies" / "learning_under_degraded_navigation" / "policies"
"""Residual policies of a study (trained under degraded navigation), flown by their folder."""


@pytest.mark.parametrize(
    "name",
    [
        "mappo:pretrained",
        "mappo:pretrained/s2",
        "ippo:pretrained/s1",
        f"mappo:{DEGRADED_STUDY_POLICIES / 'mappo_nlos_s2'}",
        f"ippo:{DEGRADED_STUDY_POLICIES / 'ippo_nlos_s1'}",
        f"mappo:{DEGRADED_STUDY_POLICIES / 'mappo_nlos_ceiling_s2'}",
        f"mappo:{DEGRADED_STUDY_POLICIES / 'mappo_nlos_ceiling_lowstd_s1'}",
    ],
)
def test_shipped_policies_load_and_fly(name) -> None:
    env = urban_canyon_v0.parallel_env()
    policy = make_policy(name, env)
    obs, _ = env.reset(seed=1_000_000)
    policy.reset(1_000_000)
    acts = policy.act(obs)
    assert set(acts) == set(env.agents)
    assert all(np.all(np.abs(v) <= 1.0) for v in acts.values())
    with pytest.raises(FileNotFoundError, match="shipped"):
        make_policy("mappo:pretrained/s9", env)


def test_the_recipe_policies_are_named_by_their_folder() -> None:
    from coopnav_env.agents.marl_policy import resolve_marl_checkpoint

    for k in range(3):
        for name in (f"route_s{k}", f"route_scratch_s{k}"):
            path = resolve_marl_checkpoint(f"pretrained/{name}", "mappo")
            assert path.name == "final_model.pt" and path.parent.name == f"mappo_{name}"
            assert (path.parent / "config.yaml").is_file()  # evaluate flies it in its run's env
    with pytest.raises(FileNotFoundError, match=r"shipped: .*mappo:pretrained/route_scratch_s2"):
        resolve_marl_checkpoint("pretrained/s9", "mappo")


def test_train_and_evaluate_with_satellite_sectors(tmp_path) -> None:
    """``--env-set obs_satellite_sectors=true``: the actor's input grows by the 2 A entries,
    the run records the setting, evaluation rebuilds that environment, and the policy refuses
    an environment without the option."""
    out = tmp_path / "run"
    args = ["train", "--backend", "torchrl", "--algorithm", "mappo", *V0, "--out", str(out)]
    env_set = ["--env-set", "obs_satellite_sectors=true"]
    assert main([*args, "--timesteps", "80", *env_set, *SMALL]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["env"]["obs_satellite_sectors"] is True
    ckpt = torch.load(out / "final_model.pt", weights_only=False)
    with_sectors = urban_canyon_v0.parallel_env(**run["env"])
    cfg = with_sectors.config
    assert cfg.obs_dim == 52 + 2 * cfg.obs_sky_azimuths
    policy = make_policy(f"mappo:{out}", with_sectors)
    assert int(ckpt["actor_dim"]) == cfg.obs_dim + policy.settings.actor_extra_inputs
    obs, _ = with_sectors.reset(seed=1)
    actions = policy.act(obs)
    assert all(np.all(np.isfinite(a)) and a.shape == (3,) for a in actions.values())
    without = urban_canyon_v0.parallel_env(**{**run["env"], "obs_satellite_sectors": False})
    with pytest.raises(ValueError, match="does not match the checkpoint's actor input"):
        make_policy(f"mappo:{out}", without)
    report = tmp_path / "eval"
    cmd = ["evaluate", "--policies", f"mappo:{out}", "--episodes", "1", "--out", str(report)]
    assert main([*cmd, "--no-plots"]) == 0
    assert '"obs_satellite_sectors": true' in (report / "report.md").read_text()


def test_command_line_env_settings_win_over_the_backends_env_block(tmp_path) -> None:
    """``--env-set`` (and ``--set env.KEY``) change the environment of the torchrl backend
    too, although its ``torchrl.env`` block of the config file overrides ``env``."""
    import argparse

    from coopnav_env.training.torchrl_backend import settings_of
    from coopnav_env.training.train import add_arguments, config_from_args

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    base = ["--backend", "torchrl", *V0, "--out", str(tmp_path / "run")]
    _, env = settings_of(config_from_args(parser.parse_args(base)))
    assert env["collision_penalty"] == 250.0 and env["nav_reward_weight"] == 1.0  # the block
    args = parser.parse_args(
        [*base, "--env-set", "collision_penalty=700", "--set", "env.nav_reward_weight=0.5"]
    )
    cfg = config_from_args(args)
    _, env = settings_of(cfg)
    assert env["collision_penalty"] == 700 and env["nav_reward_weight"] == 0.5
    assert env["nav_team_weight"] == 1.0  # the rest of the block stays


def test_action_distribution_is_the_gaussian_whose_mean_the_policy_flies(tmp_path) -> None:
    from coopnav_env import urban_canyon_v1

    env = urban_canyon_v1.parallel_env(
        action_frame="route", nav_team_weight=1.0, obs_agent_index=True
    )
    policy = make_policy("mappo:pretrained/route_s0", env)
    obs, _ = env.reset(seed=1_000_001)
    policy.reset(1_000_001)
    loc, scale = policy.action_distribution(obs)
    assert loc.shape == scale.shape == (len(env.possible_agents), 3)
    assert np.all(scale > 0)
    acts = policy.act(obs)
    np.testing.assert_allclose(
        np.stack([acts[a] for a in env.possible_agents]), np.clip(loc, -1.0, 1.0), atol=1e-6
    )
    with pytest.raises(ValueError, match="expected every agent"):
        policy.action_distribution({env.possible_agents[0]: obs[env.possible_agents[0]]})
    s = MARLSettings(n_copies=1, rollout_steps=2, residual_base="spread")
    MARLTrainer(s, {}, seed=0).save(tmp_path / "final_model.pt")
    residual = make_policy(f"mappo:{tmp_path}", urban_canyon_v0.parallel_env())
    with pytest.raises(ValueError, match="residual policy"):
        residual.action_distribution(obs)


def test_a_run_with_exploring_starts_resumes_and_can_take_a_dual_clip(tmp_path) -> None:
    """A run of this version that holds exploring starts (the packaged route recipes) resumes
    from its checkpoint; the resumed part may add ``torchrl.dual_clip``, which the run then
    records."""
    import json

    out = tmp_path / "run"
    args = ["train", "--backend", "torchrl", "--algorithm", "mappo", "--out", str(out)]
    hold = ["--env-set", "action_frame=route", "--set", "torchrl.start_hold_decisions=2"]
    hold += ["--set", "torchrl.pretrain=null"]
    assert main([*args, "--timesteps", "160", "--checkpoint-freq", "80", *hold, *SMALL]) == 0
    resumed = [*args, "--timesteps", "240", "--resume", "latest", *SMALL]
    assert main([*resumed, "--set", "torchrl.dual_clip=3"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["agent_steps"] == 240
    assert run["settings"]["start_hold_decisions"] == 2
    assert run["settings"]["dual_clip"] == 3


def test_resuming_a_run_trained_with_a_removed_switch_is_refused(tmp_path, capsys) -> None:
    """A checkpoint of an earlier version that explored with correlated noise cannot be
    resumed (the setting is gone); its policy still flies, as it was trained to."""
    from coopnav_env.agents.marl_nets import load_marl_checkpoint

    out = tmp_path / "run"
    args = ["train", "--backend", "torchrl", "--algorithm", "ippo", *V0, "--out", str(out)]
    assert main([*args, "--timesteps", "160", "--checkpoint-freq", "0", *SMALL]) == 0
    d = load_marl_checkpoint(out / "final_model.pt")
    d["settings"] |= {"noise_correlation": 0.9, "noise_centred_entries": [0]}
    torch.save(d, out / "final_model.pt")
    capsys.readouterr()
    assert main([*args, "--timesteps", "320", "--resume", "latest", *SMALL]) == 2
    err = capsys.readouterr().err
    assert "torchrl.noise_correlation=0.9, a setting removed from coopnav" in err, err
    assert "cannot have it resumed" in err
    policy = make_policy(f"ippo:{out}", urban_canyon_v0.parallel_env())
    assert policy.recorded_settings["noise_correlation"] == 0.9
    assert not hasattr(policy.settings, "noise_correlation")
    # a fresh run that names a removed setting is refused, naming it
    fresh = [*args[:-1], str(tmp_path / "fresh"), "--set", "torchrl.residual_wall_guard=false"]
    assert main([*fresh, *SMALL]) == 2
    assert "['residual_wall_guard'] were removed from coopnav" in capsys.readouterr().err


@pytest.mark.parametrize("residual_base", [None, "ceiling"])
def test_the_command_of_k_swarms_at_once_is_each_swarms_own(residual_base) -> None:
    from coopnav_env.agents.marl_nets import swarm_command

    s = MARLSettings(residual_base=residual_base, residual_scale=0.5)
    rng = np.random.default_rng(7)
    raw = rng.normal(0.0, 1.5, (6, 4, 3)).astype(np.float32)  # K swarms, N UAVs
    base = rng.uniform(-1.0, 1.0, (6, 4, 3)).astype(np.float32)
    base = None if residual_base is None else base
    together = swarm_command(s, raw, None, base)
    alone = [swarm_command(s, raw[k], None, None if base is None else base[k]) for k in range(6)]
    assert together.shape == (6, 4, 3)
    assert together.dtype == alone[0].dtype
    assert together.tobytes() == np.stack(alone).tobytes()
    assert np.abs(together).max() <= 1.0 and np.abs(raw).max() > 1.0  # clipping was exercised


def test_the_episode_log_of_a_rollout_matches_the_step_infos() -> None:
    """The episode figures read from arrays equal those summed from every UAV's info."""

    def infos_from_arrays(agents: list[str], info: dict) -> list[dict]:
        """Each copy's per-agent info dicts, read from the (K, N) info arrays."""
        n_copies = next(iter(info.values())).shape[0]
        return [
            {a: {key: arr[k, i] for key, arr in info.items()} for i, a in enumerate(agents)}
            for k in range(n_copies)
        ]

    s = MARLSettings(algorithm="mappo", n_copies=3, rollout_steps=12, action_repeat=2)
    tr = MARLTrainer(s, {"n_uavs": 3, "max_steps": 9}, seed=4)
    seen: list[tuple[np.ndarray, np.ndarray, list]] = []
    step = tr.venv.step_arrays

    def record(cmd):
        out = step(cmd)
        infos = infos_from_arrays(tr.venv.possible_agents, out.info)
        seen.append((out.rewards.copy(), out.terminated | out.truncated, infos))
        return out

    tr.venv.step_arrays = record
    tr.collect()
    want, ret, errs = [], np.zeros(3), [[] for _ in range(3)]
    for rew, done, infos in seen:
        ret += rew.mean(axis=1)
        for k, info in enumerate(infos):
            errs[k] += [v["coop_error_m"] for v in info.values() if v["coop_fix"]]
            if done[k]:
                want.append(
                    {
                        "return": ret[k],
                        "goal": float(all(v["in_goal"] for v in info.values())),
                        "collision": float(any(v["collided"] for v in info.values())),
                        "coop_error_m": sum(errs[k]) / max(len(errs[k]), 1),
                        "length": float(info["uav_0"]["step"]),
                    }
                )
                ret[k], errs[k] = 0.0, []
    assert len(want) >= 3  # episodes of 9 steps ended within the 24 steps
    assert [e["length"] for e in tr.episode_log] == [e["length"] for e in want]
    for got, w in zip(tr.episode_log, want, strict=True):
        assert got == pytest.approx(w, rel=1e-12)
