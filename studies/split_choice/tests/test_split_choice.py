"""split_choice.py: pricing split rules, the oracle, and fitting a split chooser."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env.sim.route import street_routes
from studies.route_choice.routes import RouteModel
from studies.split_choice import split_choice as bench


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


def test_split_choice_benchmark_prices_rules_and_the_oracle(tmp_path):
    from studies.route_choice.routes import SPLIT_FEATURES

    j = SPLIT_FEATURES.index("swarm_mean")
    eps = []
    for i in range(20):
        f = np.zeros((3, len(SPLIT_FEATURES)))
        f[:, j] = [10.0, 12.0, 11.0]  # the rule on swarm_mean picks split 1
        nav = np.array([[2.0, 2.0], [1.8, 1.8], [2.4, 1.6]]) + 0.01 * i
        eps.append({"features": f, "nav": nav, "goal": np.ones((3, 2), bool)})
    eps.append(
        {
            "features": np.full((1, len(SPLIT_FEATURES)), np.nan),
            "nav": np.full((1, 2), 3.0),
            "goal": np.zeros((1, 2), bool),
        }
    )
    rep = bench.price(eps, reps=100)
    assert rep["episodes_with_a_split"] == 20
    r = rep["rules"]["swarm_mean (any arm)"]
    assert r["vs_unsplit_m"][0] == pytest.approx(-0.2 * 20 / 21) and r[
        "split_share"
    ] == pytest.approx(20 / 21)
    # held out replicate 0: arm 2's other flight (1.6) wins -> 2.4 - 2.0;
    # held out replicate 1: arm 1 -> 1.8 - 2.0
    assert rep["oracle_expected_vs_unsplit_m"][0] == pytest.approx((0.4 - 0.2) / 2 * 20 / 21)
    assert any("expected-error oracle" in x for x in bench.report_lines(rep))
    # a real, tiny run: flights, files and a report
    env = _env()
    seed = _multi_route_seed(env)
    out = tmp_path / "split"
    assert (
        bench.main(
            [
                "--episodes",
                "1",
                "--first-seed",
                str(seed),
                "--noise-replicates",
                "2",
                "--jobs",
                "1",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rep = json.loads((out / "report.json").read_text())
    assert rep["episodes_with_a_split"] == 1 and (out / "episodes.npz").is_file()
    with pytest.raises(SystemExit, match="noise-replicates must be >= 2"):
        bench.main(["--noise-replicates", "1"])


def test_split_choice_fits_and_prices_a_split_model(tmp_path):
    from studies.route_choice.routes import SPLIT_FEATURES

    j = SPLIT_FEATURES.index("swarm_mean")
    rng = np.random.default_rng(0)
    eps = []
    for _ in range(40):
        f = np.zeros((3, len(SPLIT_FEATURES)))
        f[:, j] = rng.normal(10.0, 1.0, 3)
        f[1:, SPLIT_FEATURES.index("split")] = 1.0
        # more pooled satellites, lower error: 0.1 m per satellite
        nav = (3.0 - 0.1 * f[:, j])[:, None] + np.zeros((3, 2))
        eps.append({"features": f, "nav": nav, "goal": np.ones((3, 2), bool)})
    model = bench.fit_split_model(eps, "best_sky_route", info={"note": "test"})
    assert model.kind == "split" and model.info["note"] == "test"
    picks = [int(np.argmin(model.predict(e["features"]))) for e in eps]
    assert picks == [int(np.argmax(e["features"][:, j])) for e in eps]  # it learned the sense
    rep = bench.price(eps, reps=100, models={"m": model})
    best = np.mean([e["nav"][:, 0].min() - e["nav"][0, 0] for e in eps])
    assert rep["models"]["m"]["vs_unsplit_m"][0] == pytest.approx(best)
    assert any(x.startswith("model m") for x in bench.report_lines(rep))
    with pytest.raises(SystemExit, match="fits on training episodes"):
        bench.main(["--first-seed", "1000000", "--fit-model", str(tmp_path / "m")])
    model.save(tmp_path / "m" / "split_model.json")
    with pytest.raises(SystemExit, match="never overwritten"):
        bench.main(["--first-seed", "0", "--fit-model", str(tmp_path / "m")])
    with pytest.raises(SystemExit, match="takes split models"):
        r = RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column").save(
            tmp_path / "r.json"
        )
        bench.main(["--models", str(r)])
