"""benchmarks/bench_simd_lanes.py: the lane layout and its sums equal the scalar ones."""

from __future__ import annotations

import numpy as np
import pytest

from tests.benchmark_scripts import load_benchmark

lanes = load_benchmark("bench_simd_lanes")


def test_problem_g_l_sits_in_lane_l_of_group_g() -> None:
    a = np.arange(6 * 2 * 3, dtype=float).reshape(6, 2, 3)
    out = lanes.to_lanes(a, 3)
    assert out.shape == (2, 2, 3, 3)
    for g in range(2):
        for lane in range(3):
            np.testing.assert_array_equal(out[g, ..., lane], a[g * 3 + lane])


def test_a_small_run_finds_the_sums_identical(capsys) -> None:
    argv = ["--problems", "8", "--rows", "3", "--lanes", "4", "--rounds", "1", "--calls", "1"]
    assert lanes.main(argv) == 0
    out = capsys.readouterr().out
    assert "identical sums: True" in out and "lanes / scalar speed" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [(["--lanes", "0"], "--lanes must be >= 1, got 0"), (["--problems", "6"], "multiple of")],
)
def test_bad_sizes_are_refused(capsys, argv, message) -> None:
    with pytest.raises(SystemExit):
        lanes.main(argv)
    assert message in capsys.readouterr().err
