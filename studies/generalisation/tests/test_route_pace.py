"""Route length against steps and speed (studies.generalisation.route_pace)."""

from __future__ import annotations

import numpy as np
import pytest

from studies.generalisation.route_pace import main, parse_args, route_length_m


def test_route_length_sums_the_legs() -> None:
    assert route_length_m(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 10.0]])) == 11.0
    with pytest.raises(ValueError, match="route_xy_m"):
        route_length_m(np.zeros((1, 2)))


def test_bad_arguments_are_refused(capsys) -> None:
    with pytest.raises(SystemExit):
        parse_args(["--episodes", "2"])
    assert "--episodes must be >= 3" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parse_args(["--seed-start", "0"])
    assert main(["--cities", "atlantis", "--out", "unused.md"]) == 2


def test_one_city_table_lists_both_policies_and_every_episode(tmp_path) -> None:
    out = tmp_path / "pace.md"
    args = ["--cities", "grid", "--episodes", "3", "--learned", "column", "--detail", "grid"]
    assert main([*args, "--out", str(out)]) == 0
    text = out.read_text()
    rows = [r for r in text.splitlines() if r.startswith("| grid |")]
    assert len(rows) == 2 + 2 * 3  # a summary row per policy, then a row per episode
    assert "`high_wide_column`" in rows[0] and "`column`" in rows[1]
    assert [r.split(" | ")[1] for r in rows[2:]] == ["1000200"] * 2 + ["1000201"] * 2 + [
        "1000202"
    ] * 2
