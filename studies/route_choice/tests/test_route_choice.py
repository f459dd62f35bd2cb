"""route_choice.py: pricing route rules, learned models and the expected-error oracle."""

from __future__ import annotations

import numpy as np
import pytest

from studies.route_choice import route_choice as bench
from studies.route_choice.routes import ROUTE_FEATURES, RouteModel


def test_route_choice_benchmark_prices_rules_and_models_from_one_collection(tmp_path):

    j = ROUTE_FEATURES.index("los_mean")
    k = ROUTE_FEATURES.index("turns")
    eps = []
    for i in range(40):
        f = np.zeros((3, len(ROUTE_FEATURES)))
        f[:, j] = [8.0, 10.0 + (i % 2), 9.0]  # route 1 has the most sky
        f[:, k] = [1.0, 3.0, 2.0]
        eps.append(
            {
                "features": f,
                "nav": np.array([3.0, 2.0, 2.5]) + 0.01 * i,
                "goal": np.array([True, True, i % 4 != 0]),
            }
        )
    eps.append(
        {
            "features": np.full((1, len(ROUTE_FEATURES)), np.nan),
            "nav": np.array([4.0]),
            "goal": np.array([False]),
        }
    )  # one route: nothing to choose
    m = RouteModel(["turns"], [0.0], [1.0], [1.0], 1.0, "ceiling_column")  # fewest turns: route 0
    rep = bench.price_choices(eps, {"fewest": m}, reps=200)
    assert rep["episodes"] == 41 and rep["episodes_with_a_choice"] == 40
    assert rep["best_rule"] == "rule los_mean"
    best = rep["choices"]["rule los_mean"]
    assert best["nav_m"] == pytest.approx(np.mean([2.0 + 0.01 * i for i in range(40)] + [4.0]))
    assert best["vs_first_route_m"][0] == pytest.approx(-40 / 41)
    assert best["vs_best_rule_m"] == [0.0, 0.0, 0.0]
    assert best["differs_from_first"] == pytest.approx(40 / 41)
    model = rep["choices"]["model fewest"]
    assert model["vs_first_route_m"] == [0.0, 0.0, 0.0]  # it picks the first route
    assert rep["choices"]["rule turns"]["goal_rate"] == pytest.approx(40 / 41)
    assert rep["oracle_noise_selected_nav_m"] == pytest.approx(best["nav_m"])
    lines = bench.report_lines(rep)
    assert lines[-1] == "best rule: rule los_mean" and any("model fewest" in x for x in lines)


def test_route_choice_benchmark_expected_error_oracle_holds_out_the_noise_it_is_priced_on():

    j = ROUTE_FEATURES.index("los_mean")
    eps = []
    for _ in range(30):
        f = np.zeros((2, len(ROUTE_FEATURES)))
        f[:, j] = [10.0, 8.0]  # every rule on los_mean picks route 0
        # route 1 is better by 0.2 m in expectation; replicate 0 flatters route 0 by 0.5 m
        reps = np.array([[2.0, 2.5, 2.5], [2.3, 2.3, 2.3]])
        eps.append(
            {"features": f, "nav": reps.mean(axis=1), "goal": np.ones(2, bool), "nav_reps": reps}
        )
    rep = bench.price_choices(eps, {}, reps=100)
    assert rep["best_rule"] == "rule los_mean"
    # held out replicate 0: the others pick route 1 (2.3 vs 2.5) -> 2.3 - 2.0 = +0.3;
    # held out 1 or 2: the others' means are 2.25 vs 2.3 -> route 0, difference 0
    assert rep["oracle_expected_vs_best_rule_m"][0] == pytest.approx(0.1)
    assert rep["oracle_expected_nav_m"] == pytest.approx((2.3 + 2.5 + 2.5) / 3)
    assert any("expected-error oracle" in x for x in bench.report_lines(rep))


def test_route_choice_within_turns_prices_what_routes_with_more_turns_add():

    jp = ROUTE_FEATURES.index("pdop_gt3")
    jt = ROUTE_FEATURES.index("turns")
    eps = []
    for _ in range(20):
        f = np.zeros((3, len(ROUTE_FEATURES)))
        f[:, jt] = [1.0, 2.0, 5.0]
        f[:, jp] = [0.2, 0.3, 0.1]  # the rule takes route 0 within 2 turns, route 2 on all
        reps = np.array([[3.0, 3.0], [2.5, 2.5], [2.8, 2.8]])
        eps.append(
            {"features": f, "nav": reps.mean(axis=1), "goal": np.ones(3, bool), "nav_reps": reps}
        )
    eps.append(
        {
            "features": np.full((1, len(ROUTE_FEATURES)), np.nan),
            "nav": np.array([4.0]),
            "goal": np.array([True]),
            "nav_reps": np.array([[4.0, 4.0]]),
        }
    )
    sub = bench.within_turns(eps, 2)
    assert [len(e["nav"]) for e in sub] == [2] * 20 + [1]
    w = bench.compare_within_turns(eps, "pdop_gt3", 2, reps=100)
    assert w["routes_per_episode_within"] == 2.0 and w["routes_per_episode_all"] == 3.0
    assert w["rule_within_nav_m"] == pytest.approx((3.0 * 20 + 4.0) / 21)
    assert w["rule_all_vs_rule_within_m"][0] == pytest.approx(-0.2 * 20 / 21)
    # both oracles find route 1 (2.5 m): 0.5 m below the rule within 2 turns
    assert w["oracle_within_vs_rule_within_m"][0] == pytest.approx(-0.5 * 20 / 21)
    assert w["oracle_all_vs_oracle_within_m"] == [0.0, 0.0, 0.0]
    rep = bench.price_choices(eps, {}, reps=100)
    rep["within_turns"] = w
    assert any("oracle on all routes - oracle within 2 turns" in x for x in bench.report_lines(rep))
    no_reps = [{k: v for k, v in e.items() if k != "nav_reps"} for e in eps]
    with pytest.raises(ValueError, match="needs noise replicates"):
        bench.compare_within_turns(no_reps, "pdop_gt3", 2)
    with pytest.raises(SystemExit, match="within-turns must be in"):
        bench.main(["--within-turns", "3", "--max-turns", "3", "--noise-replicates", "2"])
    with pytest.raises(SystemExit, match="needs --noise-replicates"):
        bench.main(["--within-turns", "1"])
