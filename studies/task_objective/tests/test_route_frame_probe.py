"""route_frame_probe.py: fixed set-points, and learned route-frame policies overridden."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from studies.task_objective import route_frame_probe as rp

# the route-frame policy of this study (its policies/ folder), by absolute path
ROUTE_POLICY = f"mappo:{Path(__file__).resolve().parents[1] / 'policies' / 'mappo_v1_route_s0'}"


class _Constant:
    name = "constant"

    def reset(self, seed=None) -> None:
        self.seed = seed

    def act(self, observations):
        return {a: np.array([0.6, -0.4, 0.2], dtype=np.float32) for a in observations}


def test_overrides_raise_the_altitude_and_scale_the_speed_set_point() -> None:
    agents = ["uav_0", "uav_1", "uav_2"]
    p = rp.OverriddenPolicy(_Constant(), agents, top=True, slowdown=0.2)
    p.reset(seed=3)
    assert p.policy.seed == 3
    out = p.act({a: np.zeros(3) for a in agents})
    for k, a in enumerate(agents):
        speed_share = (0.6 + 1.0) / 2.0 * (1.0 - 0.2 * k)  # of max_speed_mps
        np.testing.assert_allclose(out[a], [2.0 * speed_share - 1.0, -0.4, 1.0], rtol=1e-6)
    same = rp.OverriddenPolicy(_Constant(), agents, top=False, slowdown=0.0)
    for a in agents:
        np.testing.assert_allclose(same.act({a: np.zeros(3)})[a], [0.6, -0.4, 0.2], rtol=1e-6)
    with pytest.raises(ValueError, match="slowdown must be in"):
        rp.OverriddenPolicy(_Constant(), agents, top=False, slowdown=0.5)  # the last would stop


def test_a_held_start_holds_uav_k_for_k_slots_then_lets_the_policy_fly() -> None:
    agents = ["uav_0", "uav_1", "uav_2"]
    p = rp.OverriddenPolicy(_Constant(), agents, top=False, slowdown=0.0, hold_steps=2)
    obs = {a: np.zeros(3) for a in agents}
    for episode in range(2):  # reset starts the hold again
        p.reset(seed=episode)
        acts = [p.act(obs) for _ in range(6)]  # one call per step
        speeds = np.array([[act[a][0] for a in agents] for act in acts])
        held = np.array([[t < 2 * k for k in range(3)] for t in range(6)])
        np.testing.assert_array_equal(speeds[held], -1.0)
        np.testing.assert_allclose(speeds[~held], 0.6, rtol=1e-6)
    with pytest.raises(ValueError, match="hold_steps"):
        rp.OverriddenPolicy(_Constant(), agents, top=False, slowdown=0.0, hold_steps=-1)


def test_probe_writes_both_parts_and_the_overrides_do_what_they_say(tmp_path) -> None:
    out = tmp_path / "probe"
    args = ["--policies", ROUTE_POLICY, "--altitudes", "30"]
    args += ["--steps", "0,1.5", "--episodes", "2", "--reps", "50", "--out", str(out)]
    assert rp.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    fixed, (learned,) = report["fixed"], report["learned"]
    assert [r["step_mps"] for r in fixed] == [0.0, 1.5]
    assert fixed[1]["cruise_spacing_m"] > 3 * fixed[0]["cruise_spacing_m"]
    by = {r["variant"]: r for r in learned["variants"]}
    assert list(by) == list(rp.OVERRIDES)  # no held start unless asked
    assert "hold_s" not in report
    assert "score_minus_as_is" not in by["as is"]
    assert by["top of the band"]["cruise_altitude_m"] > by["as is"]["cruise_altitude_m"]
    assert by["strung out"]["cruise_spacing_m"] > by["as is"]["cruise_spacing_m"]
    assert "overridden" in (out / "report.md").read_text()
    with pytest.raises(SystemExit):  # an existing report needs --overwrite
        rp.main(args)
    # the held start: UAVs opened like a column fly farther apart than as is
    held = [*args[:-1], str(tmp_path / "held"), "--hold-s", "6", "--steps", "0"]
    assert rp.main(held) == 0
    report = json.loads((tmp_path / "held" / "report.json").read_text())
    by = {r["variant"]: r for r in report["learned"][0]["variants"]}
    assert list(by) == list(rp.OVERRIDES + rp.HELD_OVERRIDES)
    assert report["hold_s"] == 6.0
    assert by["held start"]["cruise_spacing_m"] > by["as is"]["cruise_spacing_m"] + 5.0
    with pytest.raises(SystemExit):
        rp.main([*held, "--hold-s", "-1", "--overwrite"])


def test_probe_refuses_a_policy_of_the_velocity_frame(tmp_path) -> None:
    args = ["--policies", "mappo:pretrained/v1_s0", "--episodes", "1"]
    with pytest.raises(ValueError, match="not trained in the route frame"):
        rp.main([*args, "--out", str(tmp_path / "x")])
    assert not (tmp_path / "x").exists()  # refused before its folder was claimed
