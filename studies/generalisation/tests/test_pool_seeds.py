"""Pooling a method's training seeds across protocol reports (studies.generalisation.pool_seeds)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from studies.generalisation.pool_seeds import pooled_table


def _episodes(returns, success=True) -> list[dict]:
    return [
        {"seed": 1000200 + i, "return": r, "success": success, "cruise_spacing_m": 10.0}
        for i, r in enumerate(returns)
    ]


def _report(folder: Path, city: str, episodes: dict[str, list[dict]], suite: str = "real") -> None:
    d = folder / suite / city
    d.mkdir(parents=True)
    (d / "report.json").write_text(json.dumps({"episodes": episodes}))


def test_two_folders_pool_the_seeds_against_the_shared_rule(tmp_path) -> None:
    rule = _episodes([1.0, 1.2, 1.1, 0.9])
    base = _episodes([0.5, 0.6, 0.4, 0.5])
    _report(tmp_path / "a", "x", {"rule": rule, "base": base, "m_s0": _episodes([1.5] * 4)})
    _report(tmp_path / "b", "x", {"rule": rule, "base": base, "m_s1": _episodes([1.3] * 4)})
    table, n = pooled_table([tmp_path / "a", tmp_path / "b"], "m_s", "rule", "base")
    assert n == 2
    row = table.splitlines()[-1].split("|")
    # method mean 1.4, rule mean 1.05: +0.350, every resampled difference positive
    assert row[1].strip() == "x" and row[2].strip() == "2" and row[3].strip() == "1.400"
    assert row[4].strip().startswith("+0.350") and row[5].strip() == "above"
    gap = (1.4 - 0.5) / (1.05 - 0.5)
    assert row[9].strip().startswith(f"{gap:.2f}")
    assert np.isclose(float(row[8]), 10.0)


def test_reports_whose_shared_rows_differ_are_refused(tmp_path) -> None:
    _report(tmp_path / "a", "x", {"rule": _episodes([1.0, 1.1]), "m_s0": _episodes([1.2, 1.2])})
    _report(tmp_path / "b", "x", {"rule": _episodes([1.0, 1.3]), "m_s1": _episodes([1.2, 1.2])})
    with pytest.raises(ValueError, match="episodes of 'rule' differ"):
        pooled_table([tmp_path / "a", tmp_path / "b"], "m_s", "rule", "base")


def test_a_suite_of_several_cities_gets_one_row_weighing_them_equally(tmp_path) -> None:
    # city x: 4 episodes, method - rule = +0.4 each; city y: 2 episodes, -0.2 each. The suite
    # row: (0.4 - 0.2) / 2 = +0.100 (the episode-weighted mean would be +0.200); no spread
    # within a city, so the interval is the point. A suite of one city gets no such row.
    _report(tmp_path / "a", "x", {"rule": _episodes([1.0] * 4), "m_s0": _episodes([1.4] * 4)})
    _report(tmp_path / "a", "y", {"rule": _episodes([1.0] * 2), "m_s0": _episodes([0.8] * 2)})
    _report(
        tmp_path / "a",
        "g",
        {"rule": _episodes([1.0]), "m_s0": _episodes([1.0])},
        suite="grid",
    )
    table, n = pooled_table([tmp_path / "a"], "m_s", "rule", "base")
    lines = table.splitlines()
    assert n == 1 and [line.split("|")[1].strip() for line in lines[2:]] == [
        "g",
        "x",
        "y",
        "real: all cities (equal weight)",
    ]
    row = lines[-1].split("|")
    assert row[2].strip() == "1" and row[3].strip() == "1.100"  # (1.4 + 0.8) / 2
    assert row[4].strip() == "+0.100 [+0.100, +0.100]" and row[5].strip() == "above"
    assert row[6].strip() == "1.00" and row[9].strip() == "n/a"


def test_a_suite_row_needs_the_same_seeds_in_every_city(tmp_path) -> None:
    _report(tmp_path / "a", "x", {"rule": _episodes([1.0]), "m_s0": _episodes([1.2])})
    _report(tmp_path / "a", "y", {"rule": _episodes([1.0]), "m_s1": _episodes([1.2])})
    with pytest.raises(ValueError, match="same seeds in every city"):
        pooled_table([tmp_path / "a"], "m_s", "rule", "base")


def test_a_reference_with_a_star_pools_another_methods_seeds(tmp_path) -> None:
    # new seeds 1.5 and 1.3 (mean 1.4) against old seeds 1.1 and 0.9 (mean 1.0): +0.400; the
    # bootstrap resamples each method's seeds, so a replicate lies in [1.3, 1.5] - [0.9, 1.1];
    # the old method's goal rate is the mean over its seeds (1 and 0: 0.50)
    _report(
        tmp_path / "a",
        "x",
        {
            "new_s0": _episodes([1.5] * 3),
            "new_s1": _episodes([1.3] * 3),
            "old_s0": _episodes([1.1] * 3),
            "old_s1": _episodes([0.9] * 3, success=False),
        },
    )
    table, n = pooled_table([tmp_path / "a"], "new_s", "old_s*", "base")
    row = table.splitlines()[-1].split("|")
    assert n == 2 and row[3].strip() == "1.400"
    value, interval = row[4].strip().split(" ", 1)
    low, high = (float(x) for x in interval.strip(" []").split(","))
    assert value == "+0.400" and 0.2 - 1e-9 <= low < 0.4 < high <= 0.6 + 1e-9
    assert row[5].strip() == "above" and row[6].strip() == "1.00" and row[7].strip() == "0.50"
    # a star that matches nothing gives no row
    assert pooled_table([tmp_path / "a"], "new_s", "none_*", "base")[1] == 0


def test_records_from_an_older_report_agree_on_the_fields_both_have(tmp_path) -> None:
    # the same episodes, one report written before a field was added: pooled; a shared field
    # that differs is still refused
    rule = _episodes([1.0, 1.1])
    newer = [dict(e, cruise_speed_mps=5.0) for e in rule]
    _report(tmp_path / "a", "x", {"rule": rule, "m_s0": _episodes([1.2, 1.2])})
    _report(tmp_path / "b", "x", {"rule": newer, "m_s1": _episodes([1.4, 1.4])})
    assert pooled_table([tmp_path / "a", tmp_path / "b"], "m_s", "rule", "base")[1] == 2
    changed = [dict(e, cruise_speed_mps=5.0) for e in _episodes([1.0, 1.2])]
    _report(tmp_path / "c", "x", {"rule": changed, "m_s2": _episodes([1.4, 1.4])})
    with pytest.raises(ValueError, match="episodes of 'rule' differ"):
        pooled_table([tmp_path / "b", tmp_path / "c"], "m_s", "rule", "base")
