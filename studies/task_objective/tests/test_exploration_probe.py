"""exploration_probe.py: the chance that a learned policy's exploration holds a UAV back."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from studies.task_objective import exploration_probe as ep

# the route-frame policy of this study (its policies/ folder), by absolute path
ROUTE_POLICY = f"mappo:{Path(__file__).resolve().parents[1] / 'policies' / 'mappo_v1_route_s0'}"


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
    args = ["--policies", ROUTE_POLICY, "--episodes", "2"]
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


class _FixedGaussian:
    """A route-frame actor whose Gaussian is the same at every observation."""

    def __init__(self, rho: float, held: int) -> None:
        from coopnav_env.agents.marl_nets import MARLSettings

        self.settings = MARLSettings()
        # the noise an earlier coopnav trained with, as its checkpoints record it
        self.recorded_settings = {"noise_correlation": rho, "noise_correlated_decisions": held}
        self.loc = np.array([0.2, -0.1, 0.0, 0.3, 0.5], dtype=np.float32)  # speed entry per UAV

    def reset(self, seed=None) -> None:
        pass

    def action_distribution(self, observations):
        n = len(observations)
        return np.stack([self.loc[:n], np.zeros(n), np.zeros(n)], axis=1), np.full((n, 3), 0.4)

    def act(self, observations):
        return {a: np.array([self.loc[0], 0.0, 0.0], dtype=np.float32) for a in observations}


def test_the_chance_is_held_over_the_correlated_decisions_only() -> None:
    from coopnav_env import urban_canyon_v1

    env = urban_canyon_v1.parallel_env(action_frame="route")
    steps = ep.window_steps(env, 4.0)  # one decision per step
    limit = (2.0 * 2.0 / float(env.unwrapped.config.kinematics.max_speed_mps) - 1.0 - 0.2) / 0.4
    per_step = float(ep.log10_normal_cdf(np.array([limit]))[0])  # UAV 0, every decision
    for rho, held, want in (
        (0.0, 0, steps * per_step),
        (1.0, 0, per_step),  # one draw for the whole window
        (1.0, 2, per_step + (steps - 2) * per_step),  # one draw for 2 decisions, then fresh
    ):
        chance, _, _ = ep.hold_back_chances(_FixedGaussian(rho, held), env, 5, 4.0, 2.0)
        assert chance[0] == pytest.approx(want, rel=1e-6)  # float32 actor outputs
