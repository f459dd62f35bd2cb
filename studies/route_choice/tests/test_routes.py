"""Route choice: candidate routes, their sky features, the hand-written and learned choice."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.agents import make_policy
from coopnav_env.sim.route import street_route, street_routes
from studies.route_choice.routes import (
    FEATURE_SENSE,
    ROUTE_FEATURES,
    RouteModel,
    fit_route_model,
    resolve_route_model,
    route_features,
)


class _Grid:
    street_centres_x_m = np.array([-200.0, -100.0, 0.0, 100.0, 200.0])
    street_centres_y_m = np.array([-200.0, -100.0, 0.0, 100.0, 200.0])


def _length(r: np.ndarray) -> float:
    return float(np.abs(np.diff(r, axis=0)).sum())


def _legs_on_streets(r: np.ndarray) -> bool:
    for p, q in itertools.pairwise(r):
        if np.isclose(p[0], q[0]):
            if not np.isclose(np.abs(_Grid.street_centres_x_m - p[0]).min(), 0.0):
                return False
        elif np.isclose(p[1], q[1]):
            if not np.isclose(np.abs(_Grid.street_centres_y_m - p[1]).min(), 0.0):
                return False
        else:
            return False
    return True


@pytest.mark.parametrize(
    ("start", "goal", "count"),
    [
        # NS -> EW: the L, and three-turn staircases via y = -100, 0, 100 and x = 100
        ((0.0, -150.0), (150.0, 200.0), 4),
        ((0.0, -150.0), (200.0, 150.0), 3),  # NS -> NS via the cross streets y = -100, 0, 100
        ((0.0, -150.0), (0.0, 150.0), 1),  # one street: one route
        ((-150.0, 0.0), (150.0, 100.0), 3),  # EW -> EW via x = -100, 0, 100
    ],
)
def test_street_routes_are_all_shortest_distinct_and_on_streets(start, goal, count):
    routes = street_routes(_Grid, np.array(start), np.array(goal), max_turns=3)
    first = street_route(_Grid, np.array(start), np.array(goal))
    assert np.array_equal(routes[0], first)
    assert len(routes) == count
    keys = {tuple(map(tuple, np.round(r, 6))) for r in routes}
    assert len(keys) == len(routes)
    for r in routes:
        assert _length(r) == pytest.approx(_length(first))
        assert _legs_on_streets(r)
        assert len(r) - 2 <= 3
        assert np.allclose(r[0], first[0]) and np.allclose(r[-1], first[-1])


def test_street_routes_turn_limit_and_bad_values():
    start, goal = np.array([0.0, -150.0]), np.array([150.0, 200.0])
    assert len(street_routes(_Grid, start, goal, max_turns=1)) == 1  # only the L
    assert len(street_routes(_Grid, start, goal, max_turns=5)) > 5  # five-turn staircases too
    for bad in (-1, 9, 2.5, True):
        with pytest.raises(ValueError, match="max_turns"):
            street_routes(_Grid, start, goal, max_turns=bad)


def _env(**kw):
    from coopnav_env import urban_canyon_v0

    return urban_canyon_v0.parallel_env(**kw)


def _multi_route_seed(env, first: int = 0) -> int:
    for seed in range(first, first + 50):
        env.reset(seed=seed)
        w = env.unwrapped.world
        if len(street_routes(w.city, np.asarray(w.route_xy_m)[0], w.goal_enu_m[:2])) >= 3:
            return seed
    raise AssertionError("no episode with three routes in 50 seeds")


def test_route_features_are_bounded_deterministic_and_see_open_sky():
    env = _env()
    seed = _multi_route_seed(env)
    env.reset(seed=seed)
    w = env.unwrapped.world
    routes = street_routes(w.city, np.asarray(w.route_xy_m)[0], w.goal_enu_m[:2])
    f = np.stack([route_features(w, r, 30.0) for r in routes])
    assert f.shape == (len(routes), len(ROUTE_FEATURES))
    assert np.all(np.isfinite(f))
    n_sky = len(w._sky(w.t_s).az)
    col = {n: f[:, i] for i, n in enumerate(ROUTE_FEATURES)}
    assert np.all((col["los_min"] >= 0) & (col["los_min"] <= col["los_mean"]))
    assert np.all(col["los_mean"] <= n_sky) and np.all(col["swarm_mean"] >= col["los_mean"])
    for n in ("los_lt5", "los_lt8", "swarm_lt10", "pdop_gt3", "pdop_gt6"):
        assert np.all((col[n] >= 0.0) & (col[n] <= 1.0))
    assert np.all(col["los_lt5"] <= col["los_lt8"])  # shares below a count grow with it
    assert np.all(col["pdop_gt6"] <= col["pdop_gt3"])
    assert np.array_equal(f[0], route_features(w, routes[0], 30.0))
    # higher is more open: the same route sees at least as many satellites from higher up
    low = route_features(w, routes[0], 10.0)
    assert low[0] <= f[0, 0]
    with pytest.raises(ValueError, match="step_m"):
        route_features(w, routes[0], 30.0, step_m=0.0)


def test_route_model_round_trip_and_errors(tmp_path):
    m = RouteModel(
        features=["los_mean", "turns"],
        mean=[10.0, 1.0],
        scale=[2.0, 1.0],
        weights=[-0.5, 0.1],
        alpha=1.0,
        base="ceiling_column",
        info={"episodes": 3},
    )
    x = np.zeros((2, len(ROUTE_FEATURES)))
    x[:, 0] = [12.0, 8.0]
    x[:, ROUTE_FEATURES.index("turns")] = [1.0, 3.0]
    assert np.allclose(m.predict(x), [-0.5, 0.5 + 0.2])
    path = m.save(tmp_path / "run" / "route_model.json")
    again = RouteModel.load(tmp_path / "run")  # a run folder works too
    assert np.allclose(again.predict(x), m.predict(x)) and again.base == "ceiling_column"
    with pytest.raises(ValueError, match="unknown route features"):
        RouteModel(["sunshine"], [0.0], [1.0], [1.0], 1.0, "ceiling_column")
    with pytest.raises(ValueError, match="one mean"):
        RouteModel(["los_mean"], [0.0, 1.0], [1.0], [1.0], 1.0, "ceiling_column")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**json.loads(path.read_text()), "format": "other"}))
    with pytest.raises(ValueError, match="not a coopnav route model"):
        RouteModel.load(bad)
    with pytest.raises(FileNotFoundError, match="no route model"):
        RouteModel.load(tmp_path / "missing")
    assert resolve_route_model("pretrained").name == "route_s0"
    assert resolve_route_model("pretrained/s2").name == "route_s2"
    with pytest.raises(ValueError, match="pretrained/s<k>"):
        resolve_route_model("pretrained/best")


def test_fit_route_model_finds_a_planted_rule_and_chooses_by_it():
    rng = np.random.default_rng(0)
    feats, errs = [], []
    j = ROUTE_FEATURES.index("swarm_mean")
    for _ in range(300):
        r = int(rng.integers(1, 5))
        f = rng.normal(10.0, 2.0, (r, len(ROUTE_FEATURES)))
        feats.append(f)
        errs.append(3.0 - 0.3 * f[:, j] + rng.normal(0.0, 0.1, r))  # more sky, lower error
    m = fit_route_model(feats, errs, "ceiling_column")
    assert m.info["episodes"] == sum(len(e) > 1 for e in errs)
    chosen = [int(np.argmin(m.predict(f))) for f in feats]
    truth = [int(np.argmax(f[:, j])) for f in feats]
    # the noise (0.1 m) against the planted spread (0.3 m per unit, sd 2) flips hardly any
    assert np.mean(np.array(chosen) == np.array(truth)) > 0.95
    assert m.weights[j] == min(m.weights)  # the planted feature carries the most weight
    cv = m.info["cv_chosen_minus_mean_m"][str(m.alpha)]
    assert cv < -0.3  # the chosen route beats the mean route on held-out episodes
    with pytest.raises(ValueError, match="at least 5 episodes"):
        fit_route_model(feats[:3], errs[:3], "ceiling_column")
    with pytest.raises(ValueError, match="differ in length"):
        fit_route_model(feats, errs[:-1], "ceiling_column")


def test_column_heuristics_choose_routes_by_a_feature_or_a_model(tmp_path):
    env = _env()
    seed = _multi_route_seed(env)
    obs, _ = env.reset(seed=seed)
    p = make_policy("route_column@preset='ceiling_column',route_choice='swarm_mean'", env)
    p.reset(seed)
    p.act(obs)
    table = p.route_feature_table
    assert table is not None and len(p.route_candidates) == table.shape[0] >= 3
    j = ROUTE_FEATURES.index("swarm_mean")
    assert p.route_chosen == int(np.argmax(FEATURE_SENSE["swarm_mean"] * table[:, j]))
    # route_index flies a given candidate; 0 is street_route's
    for k in (0, 2):
        q = make_policy(f"route_column@preset='ceiling_column',route_index={k}", env)
        env.reset(seed=seed)
        q.reset(seed)
        q.act(obs)
        assert np.allclose(q._path.point(np.array([q._path.length * 0.5])), p_path_mid(p, k))
    # a learned model that wants the route with the fewest turns
    m = RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column")
    m.save(tmp_path / "m" / "route_model.json")
    r = make_policy(f"learned_route@model='{tmp_path / 'm'}'", env)
    env.reset(seed=seed)
    r.reset(seed)
    r.act(obs)
    turns = [len(c) - 2 for c in r.route_candidates]
    assert r.route_chosen == int(np.argmin(turns)) and r.route_model is not None
    with pytest.raises(ValueError, match="route_choice must be"):
        make_policy("route_column@preset='ceiling_column',route_choice='shade'", env)
    with pytest.raises(ValueError, match="exclude each other"):
        make_policy(
            "route_column@preset='ceiling_column',route_choice='los_mean',route_index=2", env
        )
    with pytest.raises(FileNotFoundError, match="no route model"):
        make_policy(f"learned_route@model='{tmp_path / 'none'}'", env)


def test_a_split_column_flies_two_routes_abreast_and_reaches_the_goal():
    env = _env()
    seed = _multi_route_seed(env)
    obs, _ = env.reset(seed=seed)
    p = make_policy(
        "route_column@preset='ceiling_column',route_choice='pdop_gt3',route_split='los_mean'", env
    )
    p.reset(seed)
    p.act(obs)
    k, k2 = p.route_chosen, p.route_split_chosen
    assert k2 is not None and k2 != k and len(p._paths) == 2
    # the second route is the best other candidate by the split feature
    j = ROUTE_FEATURES.index("los_mean")
    others = [i for i in range(len(p.route_candidates)) if i != k]
    assert k2 == others[int(np.argmax(p.route_feature_table[others, j]))]
    # slots alternate between the routes, the leader on the first
    order = np.argsort(p._slot)
    assert list(p._group[order]) == [i % 2 for i in range(len(order))]
    # route_split_index walks the other candidates
    q = make_policy(
        "route_column@preset='ceiling_column',route_choice='pdop_gt3',route_split_index=1", env
    )
    env.reset(seed=seed)
    q.reset(seed)
    q.act(obs)
    assert q.route_split_chosen == others[0]
    # flown to the end: the two sub-columns are apart somewhere and both reach the goal
    from coopnav_env.training.evaluate import run_episode

    rec = run_episode(
        env, make_policy("route_column@preset='ceiling_column',route_split_index=1", env), seed
    )
    assert rec.success
    # unsplit policies keep one path
    u = make_policy("route_column@preset='ceiling_column',route_choice='pdop_gt3'", env)
    env.reset(seed=seed)
    u.reset(seed)
    u.act(obs)
    assert len(u._paths) == 1 and u.route_split_chosen is None
    with pytest.raises(ValueError, match="route_split must be"):
        make_policy("route_column@preset='ceiling_column',route_split='wide_column'", env)
    with pytest.raises(ValueError, match="route_split_index must be >= 0"):
        make_policy("route_column@preset='ceiling_column',route_split_index=-1", env)
    with pytest.raises(ValueError, match="exclude each other"):
        make_policy(
            "route_column@preset='ceiling_column',route_split='los_mean',route_split_index=1", env
        )


def test_split_features_of_one_route_match_the_route_features():
    from studies.route_choice.routes import SPLIT_FEATURES, split_features

    env = _env()
    seed = _multi_route_seed(env)
    obs, _ = env.reset(seed=seed)
    p = make_policy("route_column@preset='ceiling_column',route_choice='swarm_mean'", env)
    p.reset(seed)
    p.act(obs)
    world = env.unwrapped.world
    r0, r1 = p.route_candidates[0], p.route_candidates[1]
    one = dict(zip(SPLIT_FEATURES, split_features(world, [r0], 30.0)))
    ref = dict(zip(ROUTE_FEATURES, route_features(world, r0, 30.0)))
    for name in ("swarm_mean", "swarm_lt8", "swarm_lt10", "swarm_lt12", "los_mean", "pdop_gt3"):
        assert one[name] == pytest.approx(ref[name])
    assert one["sep_max"] == 0.0 and one["split"] == 0.0
    two = dict(zip(SPLIT_FEATURES, split_features(world, [r0, r1], 30.0)))
    assert two["split"] == 1.0 and two["sep_max"] > 0.0 and two["sep_mean"] <= two["sep_max"]
    assert 0.0 <= two["spdop_gt3"] <= two["spdop_gt2"] <= 1.0
    with pytest.raises(ValueError, match="equally short"):
        split_features(world, [r0, r0[:2]], 30.0)
    with pytest.raises(ValueError, match="one or two routes"):
        split_features(world, [r0, r1, r0], 30.0)


def p_path_mid(p, k: int) -> np.ndarray:
    """Mid-point of candidate ``k`` of ``p``'s plan, on the extended path a column flies."""
    from coopnav_env.sim.route import Polyline, extend_route

    n = len(p._index)
    wide = max(p.spacing_m, p.goal_spacing_m)
    pts = extend_route(
        p.route_candidates[k],
        (n + 1) * wide + 10.0,
        (n - 1) * p.goal_spacing_m / 2.0 + 5.0,
        p.base.world.city.extent_m,
    )
    path = Polyline(pts)
    return path.point(np.array([path.length * 0.5]))


def test_train_routes_smoke_collects_fits_refuses_to_overwrite_and_resumes(tmp_path):
    from studies.route_choice.route_learning import arrays_to_episodes, episodes_to_arrays, main

    out = tmp_path / "run"
    argv = ["--episodes", "8", "--block", "4", "--jobs", "1"]
    argv += ["--first-seed", "0", "--out", str(out)]
    assert main(argv) == 0
    summary = json.loads((out / "run.json").read_text())
    assert summary["status"] == "finished" and summary["settings"]["episodes"] == 8
    with np.load(out / "episodes.npz") as d:
        arrays = dict(d)
    seeds, eps = arrays_to_episodes(arrays)
    assert seeds == list(range(8))
    again = episodes_to_arrays(seeds, eps)
    assert all(np.array_equal(again[k], arrays[k], equal_nan=True) for k in arrays)
    assert main(argv) == 2  # finished: never overwritten
    model = RouteModel.load(out)
    assert model.base == "ceiling_column" and model.info["first_seed"] == 0
    # resume: a run folder with half the episodes continues and flies the same episodes
    part = tmp_path / "part"
    part.mkdir()
    settings = summary["settings"]
    (part / "run.json").write_text(json.dumps({"settings": settings, "status": "collecting"}))
    half = episodes_to_arrays(seeds[:4], eps[:4])
    with open(part / "episodes.npz", "wb") as fh:
        np.savez(fh, **half)
    assert main([*argv[:-1], str(part)]) == 0
    with np.load(part / "episodes.npz") as d:
        assert all(np.array_equal(d[k], arrays[k], equal_nan=True) for k in arrays)
    # another run's folder is refused
    assert main([*argv[:4], "--first-seed", "10", "--out", str(part)]) == 2
    assert main([*argv[:4], "--first-seed", "999999", "--out", str(tmp_path / "x")]) == 2
    # a base that cannot choose routes, or a bad turn limit, fails before anything is written
    for bad in (["--base", "random"], ["--max-turns", "12"]):
        assert main([*argv[:4], *bad, "--out", str(tmp_path / "y")]) == 2
        assert not (tmp_path / "y").exists()


def test_best_sky_route_is_ceiling_on_the_route_with_the_fewest_poor_geometry_points():
    env = _env()
    seed = _multi_route_seed(env)
    obs, _ = env.reset(seed=seed)
    p = make_policy("best_sky_route", env)
    assert p.name == "best_sky_route" and p.route_choice == "pdop_gt3"
    p.reset(seed)
    p.act(obs)
    # the library's choice (poor_geometry_share) is the route feature pdop_gt3's
    q = make_policy("route_column@preset='best_sky_route'", env)
    q.reset(seed)
    q.act(obs)
    j = ROUTE_FEATURES.index("pdop_gt3")
    assert p.route_chosen == q.route_chosen == int(np.argmin(q.route_feature_table[:, j]))
    assert len(p.route_candidates) == len(q.route_candidates) >= 2
    c = make_policy("ceiling_column", env)
    assert p.cfg is c.cfg and p._altitude_m() == c._altitude_m()  # ceiling's flight
    told = make_policy("route_column@preset='best_sky_route',route_index=1", env)
    assert told.route_choice == "first"


def test_study_accepts_train_routes_runs(tmp_path):
    from studies.learning_in_default_setting.learning_study import (
        parse_runs,
        run_env,
        run_policy_name,
    )

    run = tmp_path / "r"
    run.mkdir()
    RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column").save(run / "route_model.json")
    (run / "run.json").write_text(json.dumps({"settings": {"env": {"max_fix_sigma_m": 8}}}))
    assert parse_runs([f"route={run}"]) == {"route": [run]}
    assert run_policy_name(run) == f"learned_route@model='{run}'"
    assert run_env(run) == {"max_fix_sigma_m": 8}
    with pytest.raises(ValueError, match=r"route_model\.json"):
        parse_runs([f"x={tmp_path}"])
    # a split chooser's folder (split_choice.py --fit-model): its model records the env
    split = tmp_path / "s"
    m = RouteModel(["split"], [0.0], [1.0], [-1.0], 10.0, "best_sky_route", kind="split")
    m.info = {"env": {"preset": "urban_nlos_3dma", "max_fix_sigma_m": 8}}
    m.save(split / "split_model.json")
    assert parse_runs([f"split={split}"]) == {"split": [split]}
    assert run_policy_name(split) == f"learned_split@model='{split}'"
    assert run_env(split) == {"preset": "urban_nlos_3dma", "max_fix_sigma_m": 8}
    shipped = Path(__file__).resolve().parents[2] / "split_choice" / "policies" / "split_s1"
    assert run_env(shipped)["max_fix_sigma_m"] == 8 and run_policy_name(shipped).startswith(
        "learned_split@"
    )


@pytest.mark.parametrize("spacing", [7.0, 45.0, 12.5])
def test_route_features_for_any_column_spacing(spacing):
    env = _env()
    seed = _multi_route_seed(env)
    env.reset(seed=seed)
    w = env.unwrapped.world
    routes = street_routes(w.city, np.asarray(w.route_xy_m)[0], w.goal_enu_m[:2])
    f = route_features(w, routes[1], 30.0, spacing_m=spacing)
    assert f.shape == (len(ROUTE_FEATURES),) and np.all(np.isfinite(f))
    # the features of the route itself do not depend on the column, only the pooled ones
    ref = route_features(w, routes[1], 30.0, spacing_m=45.0)
    own = [ROUTE_FEATURES.index(n) for n in ("los_mean", "los_min", "los_lt6", "pdop_gt3")]
    assert np.array_equal(f[own], ref[own])
    # a 7 m column (formation's) chooses and flies a route too
    p = make_policy("route_column@preset='column',route_choice='swarm_mean'", env)
    obs, _ = env.reset(seed=seed)
    p.reset(seed)
    p.act(obs)
    assert len(p.route_candidates) >= 3


def test_collect_episode_with_noise_replicates_keeps_each_flight_and_their_mean():
    from studies.route_choice.route_learning import (
        arrays_to_episodes,
        collect_episode,
        episodes_to_arrays,
    )

    env = _env()
    seed = _multi_route_seed(env)
    one = collect_episode(env, "ceiling_column", seed)
    two = collect_episode(env, "ceiling_column", seed, replicates=2)
    reps = two["nav_reps"]
    assert reps.shape == (len(one["nav"]), 2)
    # the first flight is the plain episode; the second another noise realisation of it
    assert np.array_equal(reps[:, 0], one["nav"]) and not np.array_equal(reps[:, 0], reps[:, 1])
    assert np.allclose(two["nav"], reps.mean(axis=1))
    assert np.array_equal(two["features"], one["features"])
    seeds, eps = arrays_to_episodes(episodes_to_arrays([seed], [two]))
    assert seeds == [seed] and np.array_equal(eps[0]["nav_reps"], reps)
    with pytest.raises(ValueError, match="replicates must be >= 1"):
        collect_episode(env, "ceiling_column", seed, replicates=0)


def test_train_routes_with_noise_replicates_learns_from_the_mean_of_the_flights(tmp_path):
    from studies.route_choice.route_learning import main

    out = tmp_path / "run"
    argv = ["--episodes", "8", "--jobs", "1", "--first-seed", "0"]
    assert main([*argv, "--noise-replicates", "2", "--out", str(out)]) == 0
    summary = json.loads((out / "run.json").read_text())
    assert summary["settings"]["noise_replicates"] == 2
    with np.load(out / "episodes.npz") as d:
        reps, nav = d["nav_reps"], d["nav"]
    assert reps.shape == (nav.size, 2) and np.allclose(nav, reps.mean(axis=1))
    assert RouteModel.load(out).info["noise_replicates"] == 2
    assert main([*argv, "--noise-replicates", "0", "--out", str(tmp_path / "bad")]) == 2
    assert not (tmp_path / "bad").exists()


def _split_model(weight_on_split: float, base: str = "ceiling_column@route_choice='pdop_gt3'"):
    from studies.route_choice.routes import SPLIT_FEATURES

    k = len(SPLIT_FEATURES)
    w = [0.0] * k
    w[SPLIT_FEATURES.index("split")] = weight_on_split
    return RouteModel(list(SPLIT_FEATURES), [0.0] * k, [1.0] * k, w, 10.0, base, kind="split")


def test_split_models_save_load_and_check_their_kind(tmp_path):
    from studies.route_choice.routes import SPLIT_FEATURES, resolve_route_model

    m = _split_model(-1.0)
    path = m.save(tmp_path / "run" / "split_model.json")
    back = RouteModel.load(tmp_path / "run")  # a folder holding split_model.json
    assert back.kind == "split" and back.weights == m.weights and back.base == m.base
    feats = np.zeros((3, len(SPLIT_FEATURES)))
    feats[1:, SPLIT_FEATURES.index("split")] = 1.0
    assert np.array_equal(back.predict(feats), [0.0, -1.0, -1.0])
    assert json.loads(path.read_text())["kind"] == "split"
    # route models are written as before: no kind key
    r = RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column")
    assert (
        "kind" not in r.to_json() and RouteModel.load(r.save(tmp_path / "r.json")).kind == "route"
    )
    with pytest.raises(ValueError, match="model kind must be one of"):
        RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column", kind="speed")
    with pytest.raises(ValueError, match="unknown split features"):
        RouteModel(["pdop_mean"], [0.0], [1.0], [1.0], 1.0, "ceiling_column", kind="split")
    assert resolve_route_model("pretrained/s2", kind="split").name == "split_s2"
    with pytest.raises(ValueError, match="'pretrained' takes a seed"):
        resolve_route_model("pretrained/x", kind="split")


def test_a_split_model_chooses_whether_and_where_the_column_splits(tmp_path):
    env = _env()
    seed = _multi_route_seed(env)
    obs, _ = env.reset(seed=seed)
    # a model that predicts every split lower than flying unsplit: it splits onto the other
    # route whose split features it scores lowest (all equal here: the first other one)
    p = make_policy(
        "route_column@preset='ceiling_column',route_choice='pdop_gt3'",
        env,
        route_split_model=_split_model(-1.0),
    )
    p.reset(seed)
    p.act(obs)
    others = [i for i in range(len(p.route_candidates)) if i != p.route_chosen]
    assert p.route_split_chosen == others[0] and len(p._paths) == 2
    table = p.split_feature_table
    assert table.shape == (1 + len(others), 14) and table[0, -1] == 0 and np.all(table[1:, -1] == 1)
    # the features it scored are the ones split_choice.py flies and learns from
    o2, t2 = p.split_table(p.route_candidates, p.route_chosen)
    assert o2 == others and np.array_equal(t2, table)
    # a model that predicts flying unsplit lower: one column
    q = make_policy(
        "route_column@preset='ceiling_column',route_choice='pdop_gt3'",
        env,
        route_split_model=_split_model(1.0),
    )
    q.reset(seed)
    q.act(obs)
    assert q.route_split_chosen is None and len(q._paths) == 1
    # the learned_split policy flies a saved model on its base heuristic
    _split_model(-1.0).save(tmp_path / "m" / "split_model.json")
    r = make_policy(f"learned_split@model='{tmp_path / 'm'}'", env)
    r.reset(seed)
    r.act(obs)
    assert r.route_split_chosen == others[0]
    with pytest.raises(ValueError, match="excludes route_split"):
        make_policy(
            "route_column@preset='ceiling_column',route_split='los_mean'",
            env,
            route_split_model=_split_model(1.0),
        )
    with pytest.raises(ValueError, match="must be a split model"):
        make_policy(
            "route_column@preset='ceiling_column'",
            env,
            route_split_model=RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "c"),
        )
    with pytest.raises(FileNotFoundError, match="no route model"):
        make_policy(f"learned_split@model='{tmp_path / 'none'}'", env)


# --------------------------------------------------------------------------------------------
# issue 35, finding 8: corrupt or mismatched model files are refused on load
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("weights", [float("nan"), 0.1], r"weights must be finite numbers, got \[nan, 0\.1\]"),
        ("weights", [float("inf"), 0.1], r"weights must be finite"),
        ("mean", [1.0, float("nan")], r"mean must be finite"),
        ("scale", [0.0, 1.0], r"scale must be finite numbers > 0, got \[0\.0, 1\.0\]"),
        ("scale", [-2.0, 1.0], r"scale must be finite numbers > 0"),
        ("scale", [float("nan"), 1.0], r"scale must be finite numbers > 0"),
        ("alpha", float("nan"), r"alpha must be a finite number >= 0"),
        ("weights", ["a", 1.0], r"weights must be finite numbers"),
        ("weights", None, r"weights must be a list"),
        ("base", 3, r"base must be a policy name"),
    ],
)
def test_route_model_files_with_bad_numbers_are_refused_naming_file_and_field(
    tmp_path, field, value, match
):
    good = RouteModel(
        ["los_mean", "turns"], [10.0, 1.0], [2.0, 1.0], [-0.5, 0.1], 1.0, "ceiling_column"
    )
    data = good.to_json()
    data[field] = value
    path = tmp_path / "route_model.json"
    path.write_text(json.dumps(data))  # Python writes NaN and Infinity as JSON extensions
    with pytest.raises(ValueError, match=match) as info:
        RouteModel.load(path)
    assert str(path) in str(info.value)
    env = _env(n_uavs=2)
    with pytest.raises(ValueError, match=match):
        make_policy(f"learned_route@model='{tmp_path}'", env)


@pytest.mark.parametrize("text", ["[1, 2]", "{not json", '{"format": "coopnav-route-model/1"}'])
def test_route_model_files_that_are_no_model_are_refused_naming_the_file(tmp_path, text):
    path = tmp_path / "route_model.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"route_model\.json") as info:
        RouteModel.load(path)
    assert "Traceback" not in str(info.value)


def test_a_split_model_is_refused_as_a_route_model_and_the_reverse(tmp_path):
    env = _env(n_uavs=2)
    split_dir = tmp_path / "split"
    _split_model(-1.0).save(split_dir / "split_model.json")
    route_dir = tmp_path / "route"
    RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column").save(
        route_dir / "route_model.json"
    )
    for name in (
        f"learned_route@model='{split_dir}'",
        f"learned_route@model='{split_dir / 'split_model.json'}'",
    ):
        with pytest.raises(
            ValueError, match=r"holds a split model.*learned_route.*learned_split"
        ) as info:
            make_policy(name, env)
        assert "split_model.json" in str(info.value)
    for name in (
        f"learned_split@model='{route_dir}'",
        f"learned_split@model='{route_dir / 'route_model.json'}'",
    ):
        with pytest.raises(ValueError, match=r"holds a route model.*learned_split.*learned_route"):
            make_policy(name, env)
    # the right kinds still load
    assert make_policy(f"learned_route@model='{route_dir}'", env).route_model.kind == "route"
    assert make_policy(f"learned_split@model='{split_dir}'", env).route_split_model.kind == "split"
