"""The TorchRL MAPPO/IPPO backend: settings, learning signal, checkpoints, evaluation."""

from __future__ import annotations

import dataclasses
import itertools
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from coopnav_env import urban_canyon_v0  # noqa: E402
from coopnav_env.agents import make_policy  # noqa: E402
from coopnav_env.agents.marl_nets import MARLSettings  # noqa: E402
from coopnav_env.training.cli import main  # noqa: E402
from coopnav_env.training.marl import MARLTrainer  # noqa: E402
from tests.fly_alike import assert_fly_alike  # noqa: E402

SMALL = ["--set", "torchrl.n_copies=2", "--set", "torchrl.rollout_steps=8", "--no-progress"]


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("algorithm", "qmix"),
        ("n_copies", 0),
        ("learning_rate", 0.0),
        ("gamma", 1.5),
        ("hidden", [64, 32]),
        ("residual_mode", "torque"),
        ("offset_scale_m", [1.0, 2.0]),
        ("lr_schedule", "cosine"),
        ("action_repeat", 0),
        ("residual_wall_guard", True),  # needs a residual base in velocity mode
        ("residual_mode", "options"),  # needs a residual base
        ("option_shifts_m", [[0.0, 0.0, 0.0]]),
        ("option_shifts_m", [[0.0, 0.0], [1.0, 0.0]]),
        ("option_init_prob", 1.0),
        ("noise_correlation", 1.5),
        ("noise_correlation", True),
        ("noise_correlated_decisions", -1),
        ("noise_correlated_entries", []),
        ("noise_correlated_entries", [0, 5]),
        ("noise_centred_entries", [3]),
        ("noise_centred_entries", [0, 0]),
        ("noise_centred_entries", [0]),  # needs noise_correlation > 0
        ("start_hold_decisions", -1),
        ("start_hold_decisions", True),
        ("start_hold_objective", "ignored"),
    ],
)
def test_bad_settings_name_the_field(field, value) -> None:
    with pytest.raises(ValueError, match=field):
        MARLSettings(**{field: value})
    with pytest.raises(ValueError, match="unknown torchrl setting"):
        MARLSettings.from_dict({"lr": 1e-3})


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


def test_an_untrained_offset_policy_flies_exactly_like_its_base(tmp_path) -> None:
    s = MARLSettings(
        algorithm="mappo",
        n_copies=1,
        rollout_steps=2,
        residual_base="spread",
        residual_mode="offset",
    )
    tr = MARLTrainer(s, {}, seed=0)
    tr.save(tmp_path / "final_model.pt")
    assert_fly_alike(f"mappo:{tmp_path}", "spread", seed=1_000_003, steps=40)


def test_the_residual_wall_guard_keeps_the_residual_off_near_walls(tmp_path) -> None:
    from coopnav_env.agents.marl_nets import swarm_command
    from coopnav_env.envs import obs_layout

    env = urban_canyon_v0.parallel_env(n_uavs=3)
    obs, _ = env.reset(seed=1_000_002)
    agents = env.possible_agents
    walls = obs_layout(env.unwrapped.config)["wall_distance"]
    for o in obs.values():
        o[walls.slice] = 1.0
    obs[agents[0]][walls.start + walls.size // 4] = 2.0 / walls.scale  # a wall 2 m East
    guarded = MARLSettings(residual_base="ceiling", residual_wall_guard=True)
    plain = MARLSettings(residual_base="ceiling")
    base = make_policy("ceiling", env)
    base_cmd = np.zeros((3, 3), dtype=np.float32)
    raw = np.tile([1.0, 0.5, 0.2], (3, 1))  # every residual pushes East (and North, up)
    g = swarm_command(guarded, raw, base, base_cmd, obs, agents)
    p = swarm_command(plain, raw, base, base_cmd, obs, agents)
    np.testing.assert_allclose(g[0], [0.0, 0.25, 0.1], atol=1e-7)  # East part removed
    np.testing.assert_allclose(g[1:], p[1:])  # UAVs far from walls: as without the guard
    np.testing.assert_allclose(p[0], [0.5, 0.25, 0.1], atol=1e-7)
    # a base without a wall guard is refused when the trainer builds it, naming the setting
    with pytest.raises(ValueError, match="residual_wall_guard needs a residual_base"):
        MARLTrainer(
            MARLSettings(
                n_copies=1, rollout_steps=2, residual_base="wide", residual_wall_guard=True
            ),
            {},
            seed=0,
        )
    # an untrained guarded residual (zero output) still flies exactly like its base
    s = MARLSettings(n_copies=1, rollout_steps=2, residual_base="ceiling", residual_wall_guard=True)
    MARLTrainer(s, {}, seed=0).save(tmp_path / "final_model.pt")
    assert_fly_alike(f"mappo:{tmp_path}", "ceiling", seed=1_000_003, steps=20)


def test_options_mode_samples_one_hot_choices_and_starts_at_its_base(tmp_path) -> None:
    s = MARLSettings(
        n_copies=2,
        rollout_steps=8,
        residual_base="ceiling",
        residual_mode="options",
        action_repeat=2,
        option_init_prob=0.7,
    )
    tr = MARLTrainer(s, {}, seed=0)
    data = tr.collect()
    act = data["agents", "action"].numpy()
    assert act.shape == (2, 8, 5, len(s.option_shifts_m))
    np.testing.assert_array_equal(act.sum(axis=-1), 1.0)  # one option per UAV and decision
    # the first option has the start probability; 80 draws: 5 standard errors
    share = act[..., 0].mean()
    assert abs(share - 0.7) <= 5.0 * np.sqrt(0.7 * 0.3 / act[..., 0].size)
    logp = data["agents", "action_log_prob"].numpy()
    expected = np.where(act[..., 0] == 1.0, np.log(0.7), np.log(0.3 / 4))
    np.testing.assert_allclose(logp, expected, rtol=1e-5)
    # a chosen option moves the UAV's slot by its row of option_shifts_m
    from coopnav_env.agents.marl_nets import swarm_command

    env = urban_canyon_v0.parallel_env()
    obs, _ = env.reset(seed=1_000_003)
    base = make_policy("ceiling", env)
    seen: list[np.ndarray] = []
    base.set_slot_shifts = lambda shifts: seen.append(np.asarray(shifts))  # type: ignore[method-assign]
    onehot = np.eye(5, dtype=np.float32)[[0, 1, 2, 3, 4]]
    swarm_command(s, onehot, base, None, obs, env.possible_agents)
    np.testing.assert_array_equal(seen[0], np.asarray(s.option_shifts_m))
    # a base without slots to shift is refused, naming the setting
    with pytest.raises(ValueError, match="needs a column follower"):
        MARLTrainer(
            MARLSettings(
                n_copies=1, rollout_steps=2, residual_base="waypoint", residual_mode="options"
            ),
            {},
            seed=0,
        )
    # untrained, the most probable option is no shift: it flies exactly like its base
    tr.save(tmp_path / "final_model.pt")
    assert_fly_alike(f"mappo:{tmp_path}", "ceiling", seed=1_000_003, steps=30)


def test_action_repeat_holds_the_actors_output_and_sums_the_rewards(monkeypatch) -> None:
    import coopnav_env.training.marl as marl

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
    real_command, real_step = marl.swarm_command, tr.venv.step

    def command(settings, raw, *args):
        raws.append(np.array(raw))
        return real_command(settings, raw, *args)

    def step(cmd):
        out = real_step(cmd)
        steps.append((out[1].copy(), (out[2] | out[3]).copy()))  # rewards, episode ends
        return out

    monkeypatch.setattr(marl, "swarm_command", command)
    monkeypatch.setattr(tr.venv, "step", step)
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


def _standardised_noise(tr: MARLTrainer, data) -> np.ndarray:
    """(action - loc) / scale of every stored decision, under the actor's Gaussian now."""
    with torch.no_grad():
        normal = tr.actor.get_dist(data.select(("agents", "observation"))).base_dist
    return ((data["agents", "action"] - normal.loc) / normal.scale).numpy()


def test_correlated_noise_keeps_the_gaussian_and_holds_its_deviation() -> None:
    s = MARLSettings(algorithm="ippo", n_copies=64, rollout_steps=8, noise_correlation=0.9)
    tr = MARLTrainer(s, {"n_uavs": 3, "max_steps": 200}, seed=3)
    data = tr.collect()
    eps = _standardised_noise(tr, data)  # (copy, decision, UAV, axis)
    # each action is a draw of the actor's Gaussian: logged log-probabilities are its own
    with torch.no_grad():
        dist = tr.actor.get_dist(data.select(("agents", "observation")))
        want = dist.log_prob(data["agents", "action"]).numpy()
    np.testing.assert_allclose(data["agents", "action_log_prob"].numpy(), want, rtol=1e-5)
    # marginal standard normal, lag-one correlation rho within episodes: 64*8*3*3 = 4608
    # values, ~4000 pairs; 5 standard errors (sd of the correlation ~ (1 - rho^2) / sqrt(n))
    n = eps.size
    assert abs(eps.mean()) <= 5.0 / np.sqrt(n)
    assert abs(eps.std() - 1.0) <= 5.0 / np.sqrt(2 * n)
    same = ~data["next", "agents", "done"].numpy()[:, :-1, 0, 0]  # (copy, decision)
    a, b = eps[:, :-1][same].ravel(), eps[:, 1:][same].ravel()
    assert a.size >= 3000
    assert abs(np.corrcoef(a, b)[0, 1] - 0.9) <= 5.0 * (1 - 0.81) / np.sqrt(a.size)
    # independent draws (the default) are not correlated
    tr0 = MARLTrainer(MARLSettings(algorithm="ippo", n_copies=64, rollout_steps=8), {}, seed=3)
    e0 = _standardised_noise(tr0, tr0.collect())
    assert abs(np.corrcoef(e0[:, :-1].ravel(), e0[:, 1:].ravel())[0, 1]) <= 5.0 / np.sqrt(a.size)


def test_centred_noise_sums_to_zero_over_the_swarm_and_stays_standard_normal() -> None:
    s = MARLSettings(
        algorithm="ippo",
        n_copies=64,
        rollout_steps=8,
        noise_correlation=0.5,
        noise_centred_entries=[0],
    )
    tr = MARLTrainer(s, {"n_uavs": 5, "max_steps": 200}, seed=4)
    eps = _standardised_noise(tr, tr.collect())  # (copy, decision, UAV, entry)
    np.testing.assert_allclose(eps[..., 0].sum(axis=2), 0.0, atol=1e-4)  # over the UAVs
    assert np.abs(eps[..., 1:].sum(axis=2)).max() > 0.1  # the other entries are not centred
    # each UAV's noise is still standard normal: 64*8*5 = 2560 values, 5 standard errors
    n = eps[..., 0].size
    assert abs(eps[..., 0].std() - 1.0) <= 5.0 / np.sqrt(2 * n / 1.25)


def _noise_of_whole_episodes(s: MARLSettings) -> np.ndarray:
    """:func:`_standardised_noise` of the copies whose first 6 decisions are one episode."""
    tr = MARLTrainer(s, {"n_uavs": 3, "max_steps": 50}, seed=2)
    data = tr.collect()
    one = ~data["next", "agents", "done"].numpy()[:, :5, 0, 0].any(axis=1)
    assert one.any()
    return _standardised_noise(tr, data)[one]


def test_fully_correlated_noise_is_held_for_the_episode_and_redrawn_after_it() -> None:
    s = MARLSettings(algorithm="mappo", n_copies=2, rollout_steps=6, noise_correlation=1.0)
    tr = MARLTrainer(s, {"n_uavs": 3, "max_steps": 4}, seed=1)
    data = tr.collect()
    eps = _standardised_noise(tr, data)
    done = data["next", "agents", "done"].numpy()[:, :, 0, 0]  # (copy, decision)
    assert done[:, :4].any(axis=1).all()  # episodes of at most 4 steps: each copy had a new one
    for k in range(2):
        for d in range(5):
            if done[k, d]:  # a new episode, a new draw
                assert np.all(np.abs(eps[k, d + 1] - eps[k, d]) > 1e-3)
            else:  # held within the episode
                np.testing.assert_allclose(eps[k, d + 1], eps[k, d], atol=1e-4)
    # the same seed gives the same draws
    tr2 = MARLTrainer(s, {"n_uavs": 3, "max_steps": 4}, seed=1)
    np.testing.assert_array_equal(_standardised_noise(tr2, tr2.collect()), eps)
    # held for the first 2 decisions of each episode only
    e3 = _noise_of_whole_episodes(dataclasses.replace(s, noise_correlated_decisions=2))
    np.testing.assert_allclose(e3[:, 1], e3[:, 0], atol=1e-4)
    for d in range(1, 5):  # then a new draw every decision
        assert np.all(np.abs(e3[:, d + 1] - e3[:, d]) > 1e-4)
    # held for the speed entry only: the others are new at every decision
    e4 = _noise_of_whole_episodes(dataclasses.replace(s, noise_correlated_entries=[0]))
    np.testing.assert_allclose(e4[:, 1:, :, 0], e4[:, :1, :, 0].repeat(5, 1), atol=1e-4)
    assert np.all(np.abs(np.diff(e4[..., 1:], axis=1)) > 1e-4)
    with pytest.raises(ValueError, match="noise_correlation"):
        MARLSettings(residual_base="ceiling", residual_mode="options", noise_correlation=0.5)


def _record_commands(tr: MARLTrainer) -> list[np.ndarray]:
    """The list that every swarm command ``tr`` flies from now on is appended to."""
    flown: list[np.ndarray] = []
    step = tr.venv.step
    tr.venv.step = lambda cmd: flown.append(cmd.copy()) or step(cmd)
    return flown


def test_exploring_starts_hold_uavs_in_place_and_leave_them_out_of_the_objective() -> None:
    s = MARLSettings(algorithm="mappo", n_copies=16, rollout_steps=8, start_hold_decisions=2)
    env = {"n_uavs": 3, "max_steps": 5, "action_frame": "route"}
    tr = MARLTrainer(s, env, seed=5)
    flown = _record_commands(tr)
    data = tr.collect()
    learn = data["agents", "learn"].numpy()[..., 0]  # (copy, decision, UAV)
    cmd = np.stack(flown, axis=1)  # (copy, decision, UAV, entry): action_repeat 1
    raw = np.clip(data["agents", "action"].numpy(), -1.0, 1.0)
    # held decisions fly the speed set-point -1 (in place), the others the actor's draw
    assert np.all(cmd[..., 0][~learn] == -1.0)
    np.testing.assert_array_equal(cmd[..., 0][learn], raw[..., 0][learn])
    np.testing.assert_array_equal(cmd[..., 1:], raw[..., 1:])
    # each UAV is held for the first 0, 1 or 2 decisions of every episode, then released
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
                h = int(np.argmax(learn[k, a:b, u])) if learn[k, a:b, u].any() else b - a
                assert learn[k, a + h : b, u].all() and not learn[k, a : a + h, u].any()
                held_counts.append(h)
    assert set(held_counts) == {0, 1, 2}
    assert done.any()  # some copies met a second episode, with new holds
    # the update leaves held decisions out (advantage 0) and standardises the others
    tr.update(data)
    adv = data["agents", "advantage"].numpy()[..., 0]
    assert np.all(adv[~learn] == 0.0)
    assert abs(adv[learn].mean()) < 1e-5 and abs(adv[learn].std(ddof=1) - 1.0) < 1e-4
    # the same seed holds the same UAVs
    tr2 = MARLTrainer(s, env, seed=5)
    np.testing.assert_array_equal(tr2.collect()["agents", "learn"].numpy()[..., 0], learn)
    # off by default: no mask, nothing held
    assert ("agents", "learn") not in MARLTrainer(
        dataclasses.replace(s, start_hold_decisions=0), env, seed=5
    ).collect().keys(True)
    with pytest.raises(ValueError, match=r"start_hold_decisions.*route"):
        MARLTrainer(s, {"n_uavs": 3}, seed=5)
    with pytest.raises(ValueError, match="start_hold_decisions"):
        MARLSettings(residual_base="wide", start_hold_decisions=2)


def test_importance_weighted_holds_draw_the_tail_and_log_the_behaviour() -> None:
    from scipy.stats import norm

    s = MARLSettings(
        algorithm="mappo",
        n_copies=16,
        rollout_steps=4,
        start_hold_decisions=2,
        start_hold_objective="importance",
    )
    env = {"n_uavs": 3, "max_steps": 50, "action_frame": "route"}
    tr = MARLTrainer(s, env, seed=6)
    flown = _record_commands(tr)
    data = tr.collect()
    assert ("agents", "learn") not in data.keys(True)  # every decision learns
    assert tr.loss.normalize_advantage
    act = data["agents", "action"].numpy()
    with torch.no_grad():
        dist = tr.actor.get_dist(data.select(("agents", "observation")))
        pi = dist.log_prob(data["agents", "action"]).numpy()
        mu, sd = dist.base_dist.loc[..., 0].numpy(), dist.base_dist.scale[..., 0].numpy()
    tail = norm.logcdf((-1.0 - mu) / sd)
    logged = data["agents", "action_log_prob"].numpy()
    # the first decision: which UAVs are held is a draw of 0, 1, 2 per UAV (2 of 3 held)
    first = act[:, 0, :, 0] <= -1.0
    assert 0.5 < first.mean() < 0.85  # 48 draws, P(held) = 2/3
    cmd = np.stack(flown, axis=1)
    np.testing.assert_array_equal(cmd[:, 0, :, 0][first], -1.0)
    # held: the behaviour's log-probability (tail-truncated speed draw), else the actor's
    np.testing.assert_allclose(logged[:, 0][first], (pi[:, 0] - tail[:, 0])[first], rtol=1e-4)
    np.testing.assert_allclose(logged[:, 0][~first], pi[:, 0][~first], rtol=1e-5)
    # by the third decision nobody is held: actor's own draws, below -1 only by chance
    np.testing.assert_allclose(logged[:, 2:], pi[:, 2:], rtol=1e-5)
    assert (act[:, 2:, :, 0] <= -1.0).mean() < 0.2
    # unweighted: the same held draws, logged with the actor's own log-probability
    tr_u = MARLTrainer(dataclasses.replace(s, start_hold_objective="unweighted"), env, seed=6)
    data_u = tr_u.collect()
    np.testing.assert_array_equal(data_u["agents", "action"].numpy(), act)
    np.testing.assert_allclose(data_u["agents", "action_log_prob"].numpy(), pi, rtol=1e-5)


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
            residual_mode="velocity",
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
    from coopnav_env.training.marl import export_policy

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
    from coopnav_env.training.marl import export_policy

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
    args = ["train", "--backend", "torchrl", "--algorithm", "mappo", "--out", str(out)]
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

    from coopnav_env.training.marl import settings_of
    from coopnav_env.training.train import add_arguments, config_from_args

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    base = ["--backend", "torchrl", "--out", str(tmp_path / "run")]
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
    s = MARLSettings(n_copies=1, rollout_steps=2, residual_base="spread", residual_mode="offset")
    MARLTrainer(s, {}, seed=0).save(tmp_path / "final_model.pt")
    residual = make_policy(f"mappo:{tmp_path}", urban_canyon_v0.parallel_env())
    with pytest.raises(ValueError, match="residual policy"):
        residual.action_distribution(obs)
