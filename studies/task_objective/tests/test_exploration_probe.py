"""exploration_probe.py: the chance that a learned policy's exploration holds a UAV back."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import norm

from studies.task_objective import exploration_probe as ep


def test_log10_normal_cdf_matches_the_normal_distribution_and_its_far_tail() -> None:
    x = np.array([-3.0, -1.0, 0.0, 2.0])
    np.testing.assert_allclose(ep.log10_normal_cdf(x), np.log10(norm.cdf(x)), rtol=1e-12)
    # far in the tail, where norm.cdf underflows to 0: Phi(x) ~ pdf(x) / |x|
    want = (-0.5 * 60.0**2 - np.log(60.0 * np.sqrt(2 * np.pi))) / np.log(10)
    assert ep.log10_normal_cdf(np.array([-60.0]))[0] == pytest.approx(want, abs=1e-3)


def test_the_chance_under_correlated_noise_matches_the_multivariate_normal() -> None:
    from scipy.stats import multivariate_normal

    x = np.array([-1.0, -0.5, -1.2, 0.3])
    for rho in (0.3, 0.6, 0.9, 0.99):
        cov = rho ** np.abs(np.subtract.outer(np.arange(4), np.arange(4)))
        want = np.log10(multivariate_normal(np.zeros(4), cov).cdf(x))
        assert ep.log10_ar1_all_below(x, rho) == pytest.approx(want, abs=0.02)
    # the limits: independent draws multiply, one draw takes the lowest limit
    deep = np.array([-6.0, -5.0, -6.5])
    assert ep.log10_ar1_all_below(deep, 0.0) == pytest.approx(
        float(np.sum(ep.log10_normal_cdf(deep))), rel=1e-12
    )
    assert ep.log10_ar1_all_below(deep, 1.0) == pytest.approx(ep.log10_normal_cdf(-6.5), rel=1e-12)
    # far in the tail the chance rises with the correlation, from the product to one draw
    chances = [ep.log10_ar1_all_below(deep, r) for r in (0.0, 0.5, 0.9, 0.999, 1.0)]
    assert chances[:4] == sorted(chances[:4]) and chances[0] < chances[2] - 10.0
    assert chances[3] == pytest.approx(chances[4], abs=0.02)  # the grid's error, in log10
    with pytest.raises(ValueError, match="rho"):
        ep.log10_ar1_all_below(deep, 1.5)


def test_probe_reports_the_chance_of_a_held_back_start(tmp_path) -> None:
    out = tmp_path / "probe"
    args = ["--policies", "mappo:pretrained/v1_route_s0", "--episodes", "2"]
    args += ["--hold-s", "4", "--out", str(out)]
    assert ep.main(args) == 0
    (row,) = json.loads((out / "report.json").read_text())["policies"]
    assert row["action_repeat"] == 1 and row["decisions"] == 4
    assert row["noise_correlation"] == 0.0  # what the policy was trained with
    assert 0.0 <= row["mean_speed_setpoint_mps"] <= 10.0
    assert row["speed_setpoint_std_mps"] > 0.0
    assert row["log10_chance_median"] <= row["log10_chance_max"] <= 0.0
    # a faster limit is at least as likely to be sampled
    faster = tmp_path / "faster"
    assert ep.main([*args[:-1], str(faster), "--speed-mps", "9"]) == 0
    (fast,) = json.loads((faster / "report.json").read_text())["policies"]
    assert fast["log10_chance_median"] > row["log10_chance_median"]
    assert "of at most 2 m/s" in (out / "report.md").read_text()


def test_probe_refuses_a_policy_of_the_velocity_frame(tmp_path) -> None:
    args = ["--policies", "mappo:pretrained/v1_s0", "--out", str(tmp_path / "x")]
    with pytest.raises(ValueError, match="not trained in the route frame"):
        ep.main(args)
    assert not (tmp_path / "x").exists()
