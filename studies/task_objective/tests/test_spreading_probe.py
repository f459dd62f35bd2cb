"""spreading_probe.py: the column at several spacings and a policy slowed UAV by UAV."""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.task_objective import spreading_probe as sp


class _Constant:
    name = "constant"

    def reset(self, seed=None) -> None:
        self.seed = seed

    def act(self, observations):
        return {a: np.array([0.5, -0.4, 0.3], dtype=np.float32) for a in observations}


def test_slowed_policy_scales_the_horizontal_command_by_the_uav_index() -> None:
    agents = ["uav_0", "uav_1", "uav_2"]
    p = sp.SlowedPolicy(_Constant(), agents, 0.2)
    p.reset(seed=4)
    assert p.policy.seed == 4
    out = p.act({a: np.zeros(3) for a in agents})
    for k, a in enumerate(agents):
        f = 1.0 - 0.2 * k
        np.testing.assert_allclose(out[a], [0.5 * f, -0.4 * f, 0.3], rtol=1e-6)
    with pytest.raises(ValueError, match="slowdown must be in"):
        sp.SlowedPolicy(_Constant(), agents, 0.5)  # the last UAV would stop
    with pytest.raises(ValueError, match=r"got -0\.1"):
        sp.SlowedPolicy(_Constant(), agents, -0.1)


def test_probe_writes_both_tables_and_slowing_strings_the_swarm_out(tmp_path) -> None:
    out = tmp_path / "probe"
    args = ["--policy", "waypoint@altitude_m=28", "--slowdowns", "0,0.15"]
    args += ["--spacings", "3,30", "--episodes", "2", "--reps", "50", "--out", str(out)]
    assert sp.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    col, slowed = report["column"], report["slowed"]
    assert [r["spacing_m"] for r in col] == [3.0, 30.0]
    assert col[1]["cruise_spacing_m"] > 3 * col[0]["cruise_spacing_m"]
    assert slowed[0]["score_minus_unslowed"] == [0.0, 0.0, 0.0]
    assert slowed[1]["cruise_spacing_m"] > slowed[0]["cruise_spacing_m"]
    assert "UAV k slowed" in (out / "report.md").read_text()
    with pytest.raises(SystemExit):  # an existing report needs --overwrite
        sp.main(args)
    with pytest.raises(SystemExit):  # the first slowdown must be the policy itself
        sp.main([*args[:2], "--slowdowns", "0.1", "--out", str(tmp_path / "x")])
