"""``coopnav evaluate --suite families`` with the per-city rule and paired comparisons
(``coopnav_env.training.suite``): generated cities new every episode, a column preset re-tuned
per city on tuning episodes only, paired score differences on the held-out episodes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.sim.city_families import FAMILIES
from coopnav_env.sim.real_suite import FAMILY_SUITE, GRID_SUITE, SUITES
from coopnav_env.training import suite as suite_module
from coopnav_env.training.cli import main
from coopnav_env.training.envs import EVAL_SEED_START
from coopnav_env.training.evaluate import evaluate
from coopnav_env.training.suite import (
    ALL_CITIES,
    PER_CITY_RULE,
    TUNING_SEED_START,
    Comparison,
    evaluate_suite,
)

SEEDS = [EVAL_SEED_START, EVAL_SEED_START + 1]


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code)


def test_the_family_suite_has_every_family_once():
    assert SUITES["families"] is FAMILY_SUITE
    assert sorted(c.city for c in FAMILY_SUITE) == sorted(f"family:{f}" for f in FAMILIES)
    for c in (*FAMILY_SUITE, *GRID_SUITE):
        assert c.env_settings() == {"city": c.city}
    assert GRID_SUITE[0].env_settings() == {"city": "grid"}  # the environment's default


def test_every_held_out_episode_flies_a_new_city():
    old_town = next(c for c in FAMILY_SUITE if c.city == "family:old_town")
    counts = [old_town.buildings_flown({}, [s]) for s in SEEDS]
    assert counts[0] != counts[1]  # two episodes, two cities
    assert old_town.buildings_flown({}, SEEDS) == pytest.approx(sum(counts) / 2)


def test_the_tuning_episodes_are_never_held_out():
    assert TUNING_SEED_START + 10_000 < EVAL_SEED_START


@pytest.fixture
def one_family(monkeypatch):
    """The families suite cut to its cheapest family (``courtyards``), for time."""
    city = next(c for c in FAMILY_SUITE if c.city == "family:courtyards")
    monkeypatch.setattr(suite_module, "suite_cities", lambda name: (city,))
    return city


def test_the_per_city_rule_is_the_best_preset_on_tuning_episodes(one_family, tmp_path: Path):
    from coopnav_env.agents.heuristics import COLUMN_PRESETS

    n_tune = 2
    result = evaluate_suite(
        ["column"],
        SEEDS,
        "families",
        tmp_path / "out",
        per_city_rule=n_tune,
        compare=PER_CITY_RULE,
    )
    preset, tuning_score = result.picks[one_family.name]
    # the pick: the preset with the best mean score on the tuning episodes, recomputed here
    tune = evaluate(
        list(COLUMN_PRESETS),
        list(range(TUNING_SEED_START, TUNING_SEED_START + n_tune)),
        one_family.env_settings(),
    )
    scores = {s.policy: s.return_mean for s in tune.stats}
    assert tuning_score == max(scores.values()) == scores[preset]
    # flown on the held-out episodes as its own row, with the preset's own figures
    report = result.reports[one_family.name]
    rows = {s.policy: s for s in report.stats}
    assert list(rows) == ["column", PER_CITY_RULE]
    direct = evaluate([preset], SEEDS, one_family.env_settings()).stats[0]
    assert rows[PER_CITY_RULE].return_mean == direct.return_mean
    assert rows[PER_CITY_RULE].goal_rate == direct.goal_rate
    # the paired comparison: the mean of the per-episode differences, inside its interval
    (comp,) = result.comparisons
    assert (comp.policy, comp.reference) == ("column", PER_CITY_RULE)
    col = [e.episode_return for e in report.episodes["column"]]
    rule = [e.episode_return for e in report.episodes[PER_CITY_RULE]]
    d = comp.score_difference
    assert d.value == pytest.approx(float(np.mean(np.subtract(col, rule))), abs=1e-12)
    assert d.low <= d.value <= d.high
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["per_city_rule"][one_family.name]["preset"] == preset
    assert summary["comparisons"][0]["policy"] == "column"
    table = (tmp_path / "out" / "comparison.md").read_text()
    assert f"| {one_family.name} | column | {d.value:+.3f} [" in table
    # over a suite of one city, the suite-level row is that city's row
    (whole,) = result.suite_comparisons
    assert whole == Comparison(ALL_CITIES, "column", PER_CITY_RULE, d, *_goals(comp))
    assert summary["suite_comparisons"][0]["city"] == ALL_CITIES
    assert f"| {ALL_CITIES} | column | {d.value:+.3f} [{d.low:+.3f}, {d.high:+.3f}] |" in table


def _goals(c) -> tuple[float, float]:
    return c.goal_rate, c.reference_goal_rate


def test_the_suite_row_weighs_every_city_equally(monkeypatch, tmp_path: Path):
    cities = (next(c for c in FAMILY_SUITE if c.city == "family:courtyards"), GRID_SUITE[0])
    monkeypatch.setattr(suite_module, "suite_cities", lambda name: cities)
    result = evaluate_suite(
        ["column", "high_wide_column"],
        [EVAL_SEED_START + i for i in (0, 5, 9)],
        "families",
        tmp_path / "out",
        compare="high_wide_column",
    )
    per_city = {c.city: c for c in result.comparisons}
    assert sorted(per_city) == sorted(c.name for c in cities)
    (whole,) = result.suite_comparisons
    assert (whole.city, whole.policy, whole.reference) == (ALL_CITIES, "column", "high_wide_column")
    values = [c.score_difference.value for c in per_city.values()]
    d = whole.score_difference
    assert d.value == pytest.approx(float(np.mean(values)), abs=1e-12)
    assert d.low <= d.value <= d.high
    assert whole.goal_rate == pytest.approx(np.mean([c.goal_rate for c in per_city.values()]))
    assert whole.reference_goal_rate == pytest.approx(
        np.mean([c.reference_goal_rate for c in per_city.values()])
    )
    table = (tmp_path / "out" / "comparison.md").read_text().splitlines()
    # the suite row follows the city rows
    assert table[-1].startswith(f"| {ALL_CITIES} | column | {d.value:+.3f} [{d.low:+.3f}, ")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["suite_comparisons"] == [
        {
            "city": ALL_CITIES,
            "policy": "column",
            "reference": "high_wide_column",
            "score_difference": d.as_dict(),
            "goal_rate": whole.goal_rate,
            "reference_goal_rate": whole.reference_goal_rate,
        }
    ]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"compare": "sky_column"}, "compare must name a flown row"),
        ({"per_city_rule": -1}, "per_city_rule must be >= 0"),
        ({"seeds": [5]}, f"suite seeds must be >= {EVAL_SEED_START}"),
        ({"policies": ["column", PER_CITY_RULE]}, "is the per-city rule's row"),
    ],
)
def test_suite_arguments_are_refused_by_name(kwargs, message):
    args = {"policies": ["column"], "seeds": SEEDS, "suite": "families"} | kwargs
    with pytest.raises(ValueError, match=message):
        evaluate_suite(**args)


@pytest.mark.parametrize("extra", [["--per-city-rule", "3"], ["--compare", "column"]])
def test_suite_flags_without_a_suite_are_refused(extra, capsys):
    rc = _run(["evaluate", "--policies", "column", "--episodes", "1", *extra])
    assert rc == 2 and "need --suite NAME" in capsys.readouterr().err
