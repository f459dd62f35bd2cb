"""arm_choice.py: pricing fixed arms, the expected-error oracle, reusing flown arms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.choice_headroom import arm_choice as bench


def test_arm_choice_benchmark_prices_arms_and_the_expected_error_oracle(tmp_path):

    # 10 episodes, 2 arms, 2 replicates: arm 0 is better on average; in odd episodes arm 1
    # is better in expectation (both of its flights lower)
    flights = np.zeros((10, 2, 2, 2))
    flights[..., 1] = 1.0
    for e in range(10):
        flights[e, 0, :, 0] = [2.0, 2.0]
        flights[e, 1, :, 0] = [1.5, 1.5] if e % 2 else [3.0, 3.0]
    rep = bench.price(flights, ["a", "b"], reps=100)
    assert rep["best_fixed"] == "a" and rep["arms"]["b"]["vs_best_fixed_m"][0] == pytest.approx(
        0.25
    )
    # the oracle takes arm 1 in the odd episodes: -0.5 m in half of them
    assert rep["oracle_expected_vs_best_fixed_m"][0] == pytest.approx(-0.25)
    assert rep["oracle_expected_goal_rate"] == 1.0
    assert any("expected-error oracle" in x for x in bench.report_lines(rep))
    c = bench.compare(flights, ["a", "b"], "a", ["b"], reps=100)
    assert c["difference_m"][0] == pytest.approx(0.25) and c["group_goal_rate"] == 1.0
    with pytest.raises(ValueError, match="not flown"):
        bench.compare(flights, ["a", "b"], "a", ["c"])
    rep["compare"] = c
    assert "b (mean" in bench.report_lines(rep)[-1]
    out = tmp_path / "arms"
    args = ["--episodes", "2", "--noise-replicates", "2", "--jobs", "1", "--out", str(out)]
    assert bench.main(["--arms", "column", "column@spacing_m=12", *args]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["episodes"] == 2 and set(rep["arms"]) == {"column", "column@spacing_m=12"}
    # the same settings again: the flights are reused, not flown again
    stamp = (out / "episodes.npz").stat().st_mtime_ns
    assert bench.main(["--arms", "column", "column@spacing_m=12", *args]) == 0
    assert (out / "episodes.npz").stat().st_mtime_ns == stamp
    # other settings into the same folder: refused, the first run's flights kept
    with pytest.raises(SystemExit, match="belongs to a run with other settings"):
        bench.main(["--arms", "column", "sky_column", *args])
    assert (out / "episodes.npz").stat().st_mtime_ns == stamp
    # --reuse: a new run on the same episodes takes the flown arms and flies only the new one
    both = tmp_path / "both"
    argv2 = [*args[:-1], str(both), "--reuse", str(out)]
    assert bench.main(["--arms", "column@spacing_m=12", "sky_column", "column", *argv2]) == 0
    with np.load(out / "episodes.npz") as d0, np.load(both / "episodes.npz") as d1:
        first, second = d0["flights"], d1["flights"]
    assert second.shape == (2, 3, 2, 2)
    assert np.array_equal(second[:, 0], first[:, 1]) and np.array_equal(second[:, 2], first[:, 0])
    # the reused flights are what flying them gives, bit for bit
    fresh = tmp_path / "fresh"
    assert bench.main(["--arms", "column", "sky_column", *args[:-1], str(fresh)]) == 0
    with np.load(fresh / "episodes.npz") as d2:
        assert np.array_equal(d2["flights"], second[:, [2, 1]])
    with pytest.raises(SystemExit, match="flown on other episodes"):
        bench.main(
            [
                "--arms",
                "column",
                "sky_column",
                "--episodes",
                "3",
                "--noise-replicates",
                "2",
                "--reuse",
                str(out),
            ]
        )
    with pytest.raises(SystemExit, match="no finished run"):
        bench.main(
            [
                "--arms",
                "column",
                "sky_column",
                "--reuse",
                str(tmp_path / "nothing"),
                "--out",
                str(tmp_path / "unclaimed"),
            ]
        )
    assert not (tmp_path / "unclaimed").exists()  # refused before --out is claimed
    with pytest.raises(SystemExit, match="at least 2 policies"):
        bench.main(["--arms", "column"])
    with pytest.raises(SystemExit, match="not in --arms"):
        bench.main(["--arms", "column", "sky_column", "--compare", "column", "ceiling_column"])
    with pytest.raises(ValueError):
        bench.main(["--arms", "column", "nosuchpolicy"])
