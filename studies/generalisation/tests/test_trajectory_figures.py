"""The learned swarm beside the rule on one episode per city
(studies.generalisation.trajectory_figures)."""

from __future__ import annotations

import pytest

from studies.generalisation.trajectory_figures import main, parse_args


def test_seeds_that_may_have_been_trained_on_are_refused(capsys) -> None:
    with pytest.raises(SystemExit):
        parse_args(["--seed-start", "5"])
    assert "--seed-start must be >= 1000000" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parse_args(["--dpi", "1000"])
    assert main(["--cities", "atlantis", "--out", "unused"]) == 2


def test_one_city_gives_a_small_figure_and_its_episodes(tmp_path) -> None:
    args = ["--cities", "grid", "--learned", "column", "--out", str(tmp_path)]
    assert main(args) == 0
    png = tmp_path / "trajectories_grid.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size < 150_000
    rows = [r for r in (tmp_path / "episodes.md").read_text().splitlines() if "| grid |" in r]
    assert [r.split(" | ")[2] for r in rows] == ["`high_wide_column`", "`column`"]
    assert all(" | 1000200 | " in r for r in rows)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episodes.md", "trajectories_grid.png"]
