"""The PettingZoo environment urban_canyon_v0: API, spaces, determinism, pickling, vector
wrappers, rewards, errors and rendering; PettingZoo's API tests and full heuristic episodes of
urban_canyon_v1 too."""

from __future__ import annotations

import math
import pickle
import re
import warnings

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

from coopnav_env import urban_canyon_v0, urban_canyon_v1
from coopnav_env.envs import REWARD_TERMS, UrbanCanyonConfig, UrbanCanyonEnv, config_field_names
from coopnav_env.envs.urban_canyon import INFO_KEYS, NO_FIX_ERROR_M, fix_error_m
from coopnav_env.nav import NavStatus


def _zeros(env) -> dict:
    return {a: np.zeros(3, dtype=np.float32) for a in env.agents}


def _run_random(env, steps: int, seed: int, check) -> int:
    """Random actions for ``steps`` steps, resetting at episode ends; returns episode count."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    check(obs)
    episodes = 1
    for _ in range(steps):
        actions = {a: rng.uniform(-1.2, 1.2, 3).astype(np.float32) for a in env.agents}
        obs, rewards, _, _, infos = env.step(actions)
        check(obs)
        assert all(math.isfinite(r) for r in rewards.values())
        assert all(math.isfinite(i["nav_error_m"]) for i in infos.values())
        if not env.agents:
            obs, _ = env.reset()
            check(obs)
            episodes += 1
    return episodes


def _checker(env):
    def check(obs: dict) -> None:
        assert set(obs) == set(env.possible_agents)
        for agent, o in obs.items():
            space = env.observation_space(agent)
            assert o.dtype == np.float32 and o.shape == space.shape
            assert not np.any(np.isnan(o))
            assert space.contains(o), (agent, o[(o < space.low) | (o > space.high)])

    return check


# ---- PettingZoo's own tests ---------------------------------------------------------------------


@pytest.mark.parametrize("module", [urban_canyon_v1, urban_canyon_v0], ids=["v1", "v0"])
def test_parallel_api(module) -> None:
    parallel_api_test(module.parallel_env(), num_cycles=300)


@pytest.mark.parametrize(("seed", "max_steps"), [(0, 200), (1, 200), (4, 40)])
def test_full_v1_episodes_flown_by_the_column_heuristic(seed: int, max_steps: int) -> None:
    """Random actions crash within a few steps, so PettingZoo's own tests above never see a
    long episode: here the ``column`` heuristic flies whole v1 episodes, to the goal (at the
    default length) or to truncation (40 steps), every observation inside its space, the
    infos finite, and the return the score's size (at most 2: route plus goal bonus)."""
    from coopnav_env.agents import make_policy

    env = urban_canyon_v1.parallel_env(max_steps=max_steps)
    policy = make_policy("column", env)
    check = _checker(env)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    check(obs)
    steps, score = 0, 0.0
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step(policy.act(obs))
        steps += 1
        check(obs)
        score += float(np.mean(list(rewards.values())))
        assert all(math.isfinite(i["nav_error_m"]) for i in infos.values())
        assert not any(i["collided"] for i in infos.values())
    if max_steps == 200:  # arrived: every UAV in the goal area, terminated well before the limit
        assert all(terms.values()) and not any(truncs.values()) and 30 < steps < max_steps
        assert all(i["in_goal"] for i in infos.values()) and 1.0 < score <= 2.0
    else:  # truncated at the limit, on the way
        assert all(truncs.values()) and not any(terms.values()) and steps == max_steps
        assert 0.0 < score < 1.0


def test_parallel_seed() -> None:
    parallel_seed_test(lambda: urban_canyon_v0.parallel_env(city="canyon"), num_cycles=50)


def test_aec_api() -> None:
    api_test(urban_canyon_v0.env(), num_cycles=200)


def test_metadata_spaces_and_shim() -> None:
    env = urban_canyon_v0.parallel_env()
    assert isinstance(env, urban_canyon_v0.raw_env)
    assert env.metadata["name"] == "urban_canyon_v0"
    assert env.metadata["is_parallelizable"] is True
    assert set(env.metadata["render_modes"]) == {"human", "rgb_array"}
    assert env.possible_agents == [f"uav_{i}" for i in range(5)]
    for a in env.possible_agents:
        assert env.observation_space(a) is env.observation_space(a)
        assert env.action_space(a) is env.action_space(a)
        assert env.observation_space(a).shape == (52,)
        assert env.observation_space(a).dtype == np.float32
        assert env.action_space(a).shape == (3,)
    assert urban_canyon_v0.__all__ == ["env", "parallel_env", "raw_env"]


def test_documented_observation_table_matches_the_code() -> None:
    """The documented index table covers every observation entry exactly once, in order."""
    rows = [line for line in urban_canyon_v0.__doc__.splitlines() if re.match(r"^\| [0-9]", line)]
    cfg = UrbanCanyonConfig()
    a, k_max = cfg.obs_sky_azimuths, cfg.obs_neighbours
    assert cfg.obs_dim == 20 + 2 * a + 4 * k_max == 52

    def value(expr: str, k: int) -> int:
        expr = re.sub(r"(\d)([AKk])", r"\1*\2", expr.strip())
        return int(eval(expr, {"A": a, "K": k_max, "k": k}))

    covered: list[int] = []
    for row in rows:
        index = row.split("|")[1].strip()
        lo, _, hi = (
            index.replace("..", "-").partition("-")
            if ".." in index or re.fullmatch(r"\d+-\d+", index)
            else (index, "", index)
        )
        for k in range(k_max) if "k" in index else [0]:
            covered.extend(range(value(lo, k), value(hi, k) + 1))
    assert sorted(covered) == list(range(cfg.obs_dim))
    for name in config_field_names():
        assert f"`{name}`" in urban_canyon_v0.__doc__, name


# ---- observations --------------------------------------------------------------------------------


def test_observations_stay_in_their_space_n5() -> None:
    env = urban_canyon_v0.parallel_env()
    episodes = _run_random(env, 1000, seed=0, check=_checker(env))
    assert episodes > 1


@pytest.mark.slow
def test_observations_stay_in_their_space_n50() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=50)
    _run_random(env, 1000, seed=1, check=_checker(env))


def test_fifty_uavs_run() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=50)
    check = _checker(env)
    obs, _ = env.reset(seed=3)
    check(obs)
    for _ in range(5):
        obs, *_ = env.step(_zeros(env))
        check(obs)
    assert env.state().shape == (13 * 50 + 4,)


def test_observation_contents() -> None:
    env = urban_canyon_v0.parallel_env(max_steps=10)
    obs, _ = env.reset(seed=5)
    ep = env.unwrapped._epoch
    cfg = env.config
    o = obs["uav_2"]
    L = env.unwrapped._city_scale_m
    np.testing.assert_allclose(o[0:3], (ep.nav_pos_enu_m[2] - ep.goal_enu_m) / L, atol=1e-6)
    np.testing.assert_allclose(o[6:9], ep.nav_sigma_enu_m[2] / cfg.obs_sigma_max_m, atol=1e-6)
    assert o[9] == np.float32(ep.n_sats[2] / ep.n_above_mask)
    # neighbours: nearest first, all present in a 5 m formation
    slots = o[19:35].reshape(4, 4)
    assert np.all(slots[:, 3] == 1.0)
    d = np.linalg.norm(slots[:, :3], axis=1)
    assert np.all(np.diff(d) >= 0)
    assert o[37] == 1.0
    # route: next waypoint and the leg after it (scale 50 m), remaining route, altitude, walls
    world = env.unwrapped.world
    route, wp = world.route_xy_m, ep.next_waypoint[2]
    est = ep.nav_pos_enu_m[2]
    np.testing.assert_allclose(o[38:40], np.clip((route[wp] - est[:2]) / 50.0, -1, 1), atol=1e-6)
    nxt = route[min(wp + 1, len(route) - 1)] - route[wp]
    np.testing.assert_allclose(o[40:42], np.clip(nxt / 50.0, -1, 1), atol=1e-6)
    remaining = (
        np.linalg.norm(route[wp] - est[:2])
        + np.linalg.norm(np.diff(route[wp:], axis=0), axis=1).sum()
    )
    assert o[42] == pytest.approx(min(remaining / (2 * L), 1.0), abs=1e-6)
    assert o[43] == pytest.approx((est[2] - 5.0) / 25.0, abs=1e-6)
    walls = world.city.wall_distance_m(ep.pos_enu_m[2:3], np.arange(8) * 45.0)[0]
    np.testing.assert_allclose(o[44:52], np.minimum(walls / 50.0, 1.0), atol=1e-6)
    assert np.any(np.isfinite(walls))  # the UAV is in a street: it sees some wall
    obs, *_ = env.step(_zeros(env))
    assert obs["uav_2"][37] == np.float32(0.9)


def test_waypoints_advance_along_the_route_to_the_goal() -> None:
    from coopnav_env.agents import make_policy

    env = urban_canyon_v0.parallel_env()
    for seed in range(20):  # an episode whose route turns at least once
        obs, infos0 = env.reset(seed=seed)
        if env.unwrapped.world.route_xy_m.shape[0] >= 3:
            break
    world = env.unwrapped.world
    route = world.route_xy_m
    np.testing.assert_allclose(route[-1], world.goal_enu_m[:2])
    assert [i["next_waypoint"] for i in infos0.values()] == [1] * 5
    policy = make_policy("formation", env)
    policy.reset(seed)
    seen = [np.ones(5, dtype=int)]
    while env.agents:
        obs, _r, _te, _tr, infos = env.step(policy.act(obs))
        seen.append(np.array([infos[a]["next_waypoint"] for a in env.possible_agents]))
    seen = np.array(seen)
    assert np.all(np.diff(seen, axis=0) >= 0)  # never goes back
    assert np.all(seen[-1] == len(route) - 1)  # the goal is the last waypoint
    assert infos["uav_0"]["in_goal"]
    # at the goal the waypoint vector points at the goal and no leg follows
    o = obs["uav_0"]
    assert np.all(o[40:42] == 0.0)


def test_progress_reward_follows_the_street_route() -> None:
    env = urban_canyon_v0.parallel_env(n_uavs=1, city="canyon", goal_distance_min_m=100.0)
    env.reset(seed=0)
    world = env.unwrapped.world
    to_goal = world.goal_enu_m[:2] - world.pos_enu_m[0, :2]
    direction = to_goal / np.linalg.norm(to_goal)
    for _ in range(3):
        *_, infos = env.step({"uav_0": np.r_[direction, 0.0]})
    # flying along the single canyon toward the goal: progress = distance flown / 10 m
    assert infos["uav_0"]["reward_progress"] == pytest.approx(
        np.linalg.norm(world.vel_enu_mps[0, :2]) / 10.0, rel=1e-6
    )
    for _ in range(5):  # turning back (4 m/s^2): the remaining route grows again
        _, _, _, _, infos = env.step({"uav_0": np.r_[-direction, 0.0]})
    assert infos["uav_0"]["reward_progress"] < 0.0


def test_default_rewards_make_crashing_never_pay() -> None:
    cfg = UrbanCanyonConfig()
    assert cfg.worst_episode_penalty == pytest.approx(200 * (0.1 * 10 / 10 + 0.05 + 0.02))
    assert cfg.collision_penalty > cfg.worst_episode_penalty


def test_state_is_inside_state_space() -> None:
    env = urban_canyon_v0.parallel_env()
    env.reset(seed=0)
    for _ in range(3):
        s = env.state()
        assert s.dtype == np.float32 and env.state_space.contains(s)
        env.step(_zeros(env))


# ---- determinism and pickling --------------------------------------------------------------------


def _episode(env, seed: int, steps: int) -> list:
    out = [env.reset(seed=seed)]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        if not env.agents:
            break
        out.append(env.step({a: rng.uniform(-0.5, 0.5, 3) for a in env.agents}))
    return out


def _assert_same(a, b) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert pickle.dumps(x) == pickle.dumps(y)  # bit for bit, infos included


def test_same_seed_same_episode_bit_for_bit() -> None:
    env1 = urban_canyon_v0.parallel_env(nlos_probability=0.2)
    env2 = urban_canyon_v0.parallel_env(nlos_probability=0.2)
    _assert_same(_episode(env1, 7, 20), _episode(env2, 7, 20))
    # reseeding the same environment repeats the episode too
    _assert_same(_episode(env1, 7, 20), _episode(env2, 7, 20))
    a, b = _episode(env1, 7, 5), _episode(env1, 8, 5)
    assert not np.array_equal(a[0][0]["uav_0"], b[0][0]["uav_0"])


def test_pickled_env_continues_identically() -> None:
    env = urban_canyon_v0.parallel_env(render_mode="rgb_array")
    env.reset(seed=1)
    for _ in range(3):
        env.step({a: np.array([0.0, 0.2, 0.05]) for a in env.agents})
    clone = pickle.loads(pickle.dumps(env))
    assert clone.config == env.config and clone.render_mode == "rgb_array"
    rng = np.random.default_rng(0)
    for _ in range(4):
        act = {a: rng.uniform(-0.3, 0.3, 3) for a in env.agents}
        assert pickle.dumps(env.step(act)) == pickle.dumps(clone.step(act))
    # the next episode (unseeded reset) continues the same generator stream
    assert pickle.dumps(env.reset()) == pickle.dumps(clone.reset())


def test_fresh_copies_do_not_share_a_stream() -> None:
    env = urban_canyon_v0.parallel_env()
    a, b = pickle.loads(pickle.dumps(env)), pickle.loads(pickle.dumps(env))
    assert not np.array_equal(a.reset()[0]["uav_0"], b.reset()[0]["uav_0"])


# ---- vector wrappers -----------------------------------------------------------------------------


def test_supersuit_sb3_vec_env_with_crashes() -> None:
    ss = pytest.importorskip("supersuit")
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import VecEnv

    env = urban_canyon_v0.parallel_env(city="canyon", max_steps=50)
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, num_vec_envs=2, num_cpus=1, base_class="stable_baselines3")
    assert isinstance(vec, VecEnv)
    n = 2 * 5
    assert vec.num_envs == n
    obs = vec.reset()
    assert obs.shape == (n, 52) and obs.dtype == np.float32
    east = np.tile([1.0, 0.0, 0.0], (n, 1)).astype(np.float32)  # into the canyon's east wall
    crashes = 0
    for _ in range(25):
        obs, rewards, dones, infos = vec.step(east)
        assert obs.shape == (n, 52) and rewards.shape == (n,) and dones.shape == (n,)
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rewards))
        assert vec.observation_space.contains(obs[0])
        if dones.any():
            # a crash ends the episode for every agent of that sub-environment at once
            assert dones[:5].all() == dones[:5].any() and dones[5:].all() == dones[5:].any()
            done_infos = [infos[i] for i in np.flatnonzero(dones)]
            assert all("terminal_observation" in i for i in done_infos)
            crashes += bool(np.any(rewards[dones.astype(bool)] < -30.0))  # the -40 crash penalty
            # SuperSuit's own auto-reset merges the next episode's reset infos over the
            # terminal step's ({**step, **reset}: the keys are the same): the documented
            # reason to use coopnav_env.training.vec_env.make_vec_env, which keeps the terminal
            # infos
            assert all(i["step"] == 0 for i in done_infos)
    assert crashes >= 2  # crashed, reset automatically, and crashed again
    vec.close()


# ---- episode end and rewards ---------------------------------------------------------------------


def test_truncation_at_max_steps() -> None:
    env = urban_canyon_v0.parallel_env(max_steps=3, city="canyon")
    env.reset(seed=0)
    for _ in range(3):
        _, _, terms, truncs, _ = env.step(_zeros(env))
    assert all(truncs.values()) and not any(terms.values())
    assert env.agents == []
    with pytest.raises(ValueError, match="episode ended"):
        env.step({})


def test_goal_terminates_with_bonus() -> None:
    env = urban_canyon_v0.parallel_env(goal_distance_min_m=0.0, goal_radius_m=1000.0)
    env.reset(seed=0)
    _, _, terms, truncs, infos = env.step(_zeros(env))
    assert all(terms.values()) and not any(truncs.values())
    for a in env.possible_agents:
        assert infos[a]["reward_goal"] == 10.0 and infos[a]["in_goal"]


def test_crash_terminates_everyone_with_a_penalty() -> None:
    env = urban_canyon_v0.parallel_env(city="canyon")
    env.reset(seed=0)
    for _ in range(10):
        _, _, terms, _, infos = env.step({a: [1.0, 0.0, 0.0] for a in env.agents})
        if any(terms.values()):
            break
    assert all(terms.values())
    crashed = [a for a in infos if infos[a]["collided"]]
    assert crashed
    for a in crashed:
        assert infos[a]["reward_collision"] == -40.0


def test_reward_is_the_sum_of_its_terms_and_infos_are_python_numbers() -> None:
    env = urban_canyon_v0.parallel_env(nav_reward="sigma", separation_penalty=2.0)
    env.reset(seed=2)
    _, rewards, _, _, infos = env.step({a: [0.3, 0.3, 0.0] for a in env.agents})
    for a in env.possible_agents:
        info = infos[a]
        assert tuple(info) == INFO_KEYS
        terms = [info[f"reward_{t}"] for t in REWARD_TERMS]
        assert rewards[a] == pytest.approx(sum(terms), abs=1e-12)
        expected = -0.1 * min(info["sig_3d_m"], 10.0) / 10.0
        assert info["reward_nav"] == pytest.approx(expected)
        for key in ("nav_error_m", "coop_error_m", "standalone_error_m", "sig_3d_m"):
            assert type(info[key]) is float and math.isfinite(info[key])
        for key in ("n_sats", "n_sats_swarm", "coop_status", "standalone_status", "nav_source"):
            assert type(info[key]) is int
        assert type(rewards[a]) is float
        if info["coop_status"] != NavStatus.OK:
            assert not info["coop_fix"] and info["coop_error_m"] == NO_FIX_ERROR_M
            assert fix_error_m(info, "coop_error_m") == math.inf


def test_infos_are_flat_with_the_same_keys_at_reset_and_every_step() -> None:
    # TorchRL's PettingZooWrapper (and BenchMARL) build their specs from the reset infos
    env = urban_canyon_v0.parallel_env(city="canyon", max_steps=30)
    _, infos = env.reset(seed=5)
    for info in infos.values():
        assert tuple(info) == INFO_KEYS
        assert all(isinstance(v, (bool, int, float)) for v in info.values())
        assert all(math.isfinite(v) for v in info.values())
        assert info["step"] == 0 and all(info[f"reward_{t}"] == 0.0 for t in REWARD_TERMS)
    seen_no_fix = False
    while env.agents:
        *_, infos = env.step({a: [0.0, 0.0, -1.0] for a in env.agents})  # down into the canyon
        for info in infos.values():
            assert tuple(info) == INFO_KEYS
            assert all(math.isfinite(v) for v in info.values())
            if not info["standalone_fix"]:
                seen_no_fix = True
                assert info["standalone_error_m"] == NO_FIX_ERROR_M
    assert seen_no_fix  # the flag path was exercised


def test_team_credit_mixes_the_navigation_term_with_the_swarm_mean() -> None:
    out = {}
    for w in (0.0, 0.5, 1.0):
        env = urban_canyon_v0.parallel_env(nav_team_weight=w)
        env.reset(seed=3)
        _, rewards, _, _, infos = env.step({a: [0.2, 0.1, 0.0] for a in env.agents})
        out[w] = (
            np.array([infos[a]["reward_nav"] for a in env.possible_agents]),
            np.array([rewards[a] for a in env.possible_agents]),
        )
    own, team = out[0.0][0], out[1.0][0]
    np.testing.assert_allclose(team, np.full(5, own.mean()), rtol=1e-12)
    np.testing.assert_allclose(out[0.5][0], 0.5 * own + 0.5 * own.mean(), rtol=1e-12)
    # only the navigation term changes
    np.testing.assert_allclose(out[1.0][1] - out[0.0][1], team - own, atol=1e-12)
    assert np.ptp(own) > 0.0  # the UAVs' own terms differ, so the test can fail
    with pytest.raises(ValueError, match="nav_team_weight"):
        urban_canyon_v0.parallel_env(nav_team_weight=1.5)


# ---- errors --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_uavs": 0}, r"UrbanCanyonConfig\.n_uavs must be an integer in \[1, 256\], got 0"),
        ({"max_steps": 0}, r"UrbanCanyonConfig\.max_steps .*\[1, 100000\]"),
        ({"nav_reward": "speed"}, r"nav_reward must be one of \('error', 'sigma'\)"),
        ({"goal_bonus": -1.0}, r"goal_bonus must be in \[0.0, 100000.0\], got -1.0"),
        ({"obs_neighbours": 100}, r"obs_neighbours must be an integer in \[0, 64\]"),
        ({"render_sky_uav": 5}, r"render_sky_uav must be an integer in \[-1, 4\]"),
        ({"render_mode": "ascii"}, r"render_mode must be None or one of"),
        ({"n_drones": 3}, r"unknown urban_canyon argument\(s\) \['n_drones'\].*n_uavs"),
    ],
)
def test_bad_configuration_raises(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        urban_canyon_v0.parallel_env(**kwargs)


def test_unknown_argument_message_lists_every_valid_name() -> None:
    with pytest.raises(ValueError) as exc:
        urban_canyon_v0.env(speed=3)
    for name in config_field_names():
        assert name in str(exc.value)


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        ({"uav_0": [np.nan, 0.0, 0.0]}, r"NaN or inf for \['uav_0'\]"),
        ({"uav_0": [0.0, 0.0]}, r"shape \(3,\).*'uav_0': \(2,\)"),
        ({"uav_0": "fast"}, r"numeric array of shape \(3,\)"),
        ({"uav_9": [0.0, 0.0, 0.0]}, r"unknown: \['uav_9'\]"),
        ("drop", r"missing: \['uav_1'\]"),
    ],
)
def test_bad_actions_raise(bad, match) -> None:
    env = urban_canyon_v0.parallel_env()
    env.reset(seed=0)
    actions = _zeros(env)
    if bad == "drop":
        del actions["uav_1"]
    else:
        actions.update(bad)
    with pytest.raises(ValueError, match=match):
        env.step(actions)


def test_step_before_reset_raises() -> None:
    with pytest.raises(ValueError, match="before reset"):
        urban_canyon_v0.parallel_env().step({})


def test_out_of_bounds_actions_are_clipped() -> None:
    a, b = urban_canyon_v0.parallel_env(), urban_canyon_v0.parallel_env()
    a.reset(seed=4)
    b.reset(seed=4)
    big = {u: np.array([5.0, -7.0, 2.0]) for u in a.agents}
    clipped = {u: np.array([1.0, -1.0, 1.0]) for u in a.agents}
    assert pickle.dumps(a.step(big)) == pickle.dumps(b.step(clipped))


def test_config_object_and_overrides() -> None:
    cfg = UrbanCanyonConfig(n_uavs=3, city="canyon")
    env = urban_canyon_v0.parallel_env(config=cfg, max_steps=7)
    assert env.config.n_uavs == 3 and env.config.max_steps == 7
    assert isinstance(urban_canyon_v0.raw_env(cfg), UrbanCanyonEnv)


# ---- rendering -----------------------------------------------------------------------------------


def test_rgb_array_frame_to_png(tmp_path) -> None:
    plt_image = pytest.importorskip("matplotlib.image")
    env = urban_canyon_v0.parallel_env(render_mode="rgb_array", nlos_probability=0.3)
    env.reset(seed=3)
    for _ in range(3):
        env.step({a: [0.2, 0.2, 0.0] for a in env.agents})
    frame = env.render()
    assert frame.shape == (640, 1280, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # not blank
    path = tmp_path / "frame.png"
    plt_image.imsave(path, frame)
    assert path.stat().st_size > 10_000
    assert urban_canyon_v0.parallel_env().render() is None  # no render_mode: nothing


def test_human_render_mode_headless(monkeypatch) -> None:
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.setattr(plt, "pause", lambda interval: None)  # no window, no waiting
    env = urban_canyon_v0.parallel_env(render_mode="human", city="canyon", n_uavs=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # Agg is non-interactive
        env.reset(seed=0)
        assert env.render() is None
        env.step(_zeros(env))
    env.close()
    assert env.unwrapped._window is None


def test_noise_stream_reset_option_keeps_the_scenario_and_redraws_the_noise():
    from coopnav_env import urban_canyon_v0

    def episode(options):
        env = urban_canyon_v0.parallel_env()
        obs, _ = env.reset(seed=11, options=options)
        w = env.unwrapped.world
        scen = (np.array(w.goal_enu_m), np.array(w.route_xy_m), w.t_s)
        first = np.stack([obs[a] for a in env.possible_agents])
        act = {a: np.zeros(3, dtype=np.float32) for a in env.agents}
        errs = []
        for _ in range(5):
            _, _, _, _, infos = env.step(act)
            errs.append([infos[a]["nav_error_m"] for a in env.possible_agents])
        return scen, first, np.array(errs)

    plain, zero, one, one_again, two = (
        episode(o)
        for o in (
            None,
            {"noise_stream": 0},
            {"noise_stream": 1},
            {"noise_stream": 1},
            {"noise_stream": 2},
        )
    )
    # stream 0 is the plain episode, bit for bit; a stream is reproducible
    assert np.array_equal(plain[2], zero[2]) and np.array_equal(one[2], one_again[2])
    # the same scenario and first epoch, other noise afterwards
    for other in (one, two):
        assert all(np.array_equal(a, b) for a, b in zip(plain[0][:2], other[0][:2]))
        assert np.array_equal(plain[1], other[1])
        assert not np.array_equal(plain[2], other[2])
    assert not np.array_equal(one[2], two[2])
    env = urban_canyon_v0.parallel_env()
    with pytest.raises(ValueError, match="needs a reset seed"):
        env.reset(options={"noise_stream": 1})
    with pytest.raises(ValueError, match="noise_stream'\\] must be an integer >= 0"):
        env.reset(seed=1, options={"noise_stream": -1})
    # other keys are ignored, as PettingZoo's API test expects
    obs, _ = env.reset(seed=11, options={"noise": 1})
    assert np.array_equal(np.stack([obs[a] for a in env.possible_agents]), plain[1])
