"""The planner reference of the generalisation protocol: pairing with the protocol's rows."""

from __future__ import annotations

import pytest

from studies.generalisation.planner_reference import paired_rows, planner_name


def _report(rows: dict[str, list[tuple[int, float, bool]]]) -> dict:
    return {
        "episodes": {
            p: [{"seed": s, "return": r, "success": g} for s, r, g in eps]
            for p, eps in rows.items()
        }
    }


BASE = [(1, 1.0, True), (2, 1.5, True), (3, 0.5, False)]


def test_rows_are_paired_with_the_base_on_the_given_seeds() -> None:
    ours = _report({"rule": BASE, "plan": [(1, 1.1, True), (2, 1.6, True), (3, 0.6, True)]})
    protocol = _report(
        {
            "rule": [*BASE, (4, 9.0, True)],
            "learned": [(1, 0.0, False), (2, 1.5, True), (3, 0.5, False), (4, 0.0, False)],
        }
    )
    rows = {r[0]: r for r in paired_rows(ours, protocol, "rule", [1, 2, 3])}
    assert set(rows) == {"plan", "learned"}
    assert rows["plan"][1] == pytest.approx(0.1)
    assert rows["plan"][2] == pytest.approx(0.1) and rows["plan"][3] == pytest.approx(0.1)
    assert rows["plan"][4] == 1.0 and rows["plan"][5] == pytest.approx(2 / 3)
    assert rows["learned"][1] == pytest.approx(-1 / 3)  # seed 4 is not among the seeds


def test_a_protocol_of_other_episodes_is_refused() -> None:
    ours = _report({"rule": BASE, "plan": BASE})
    other = _report({"rule": [(1, 1.0, True), (2, 1.4, True), (3, 0.5, False)]})
    with pytest.raises(ValueError, match="scored otherwise"):
        paired_rows(ours, other, "rule", [1, 2, 3])
    with pytest.raises(ValueError, match="lacks seeds"):
        paired_rows(ours, _report({"rule": BASE[:2]}), "rule", [1, 2, 3])


def test_planner_name_quotes_the_base() -> None:
    assert planner_name("high_wide_column", ["horizon=3"]) == (
        "planner@base='high_wide_column',horizon=3"
    )
