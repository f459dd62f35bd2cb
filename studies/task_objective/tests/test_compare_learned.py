"""compare_learned.py: per-policy and per-method scores, spacing and the gap closed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env.training.alignment import fly as fly_scores
from studies.task_objective import compare_learned as cl


def test_compare_writes_the_report_and_its_figures_are_consistent(tmp_path) -> None:
    out = tmp_path / "cmp"
    args = ["--methods", "m=sky,wide@spacing_m=30", "--heuristics", "formation", "wide"]
    args += ["--episodes", "2", "--reps", "50", "--out", str(out)]
    assert cl.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    rows = {r["name"]: r for r in report["rows"]}
    assert set(rows) == {"formation", "wide", "m", "sky", "wide@spacing_m=30"}
    # a policy's score is its mean v1 return; a method's is the mean of its seeds'
    ref = [e.episode_return for e in fly_scores("sky", "urban_canyon_v1", [1_000_100, 1_000_101])]
    assert rows["sky"]["score"][0] == pytest.approx(np.mean(ref), abs=1e-12)
    method = np.mean([rows["sky"]["score"][0], rows["wide@spacing_m=30"]["score"][0]])
    assert rows["m"]["score"][0] == pytest.approx(method, abs=1e-12)
    # the reference closes the whole gap, the baseline none of it
    assert rows["wide"]["gap_closed"][0] == pytest.approx(1.0)
    assert rows["formation"]["gap_closed"][0] == pytest.approx(0.0)
    # the wide column flies farther apart during the cruise than the formation
    assert rows["wide"]["cruise_spacing_m"] > 2 * rows["formation"]["cruise_spacing_m"]
    assert "gap closed" in (out / "report.md").read_text()
    with pytest.raises(SystemExit):  # an existing report needs --overwrite
        cl.main(args)


def test_bad_methods_are_refused(tmp_path) -> None:
    with pytest.raises(SystemExit):
        cl.main(["--methods", "m=", "--out", str(tmp_path / "x")])
