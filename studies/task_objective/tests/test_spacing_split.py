"""spacing_split.py: a swarm's spacing split into horizontal distance and height."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from studies.task_objective import compare_learned as cl
from studies.task_objective import spacing_split as ss

# the route-frame policy of this study (its policies/ folder), by absolute path
ROUTE_POLICY = f"mappo:{Path(__file__).resolve().parents[1] / 'policies' / 'mappo_v1_route_s0'}"


def test_nearest_distances_split_height_from_the_horizontal() -> None:
    # two UAVs 3 m apart east and 4 m apart in height, a third 10 m north of the first
    pos = np.array([[[0.0, 0.0, 20.0], [3.0, 0.0, 24.0], [0.0, 10.0, 20.0]]])
    d3, dh = ss.nearest_distances(pos)
    assert d3 == pytest.approx((5.0 + 5.0 + 10.0) / 3)
    assert dh == pytest.approx((3.0 + 3.0 + 10.0) / 3)  # the third: 10 m, not hypot(3, 10)


def test_probe_gives_compare_learned_s_spacing_and_a_horizontal_part(tmp_path) -> None:
    out = tmp_path / "split"
    policy = ROUTE_POLICY
    assert (
        ss.main(
            ["--policies", policy, "--episodes", "2", "--seed-start", "1000100", "--out", str(out)]
        )
        == 0
    )
    (row,) = json.loads((out / "report.json").read_text())["policies"]
    flown = cl.fly(policy, [1_000_100, 1_000_101])
    for ep, want in zip(row["episodes"], flown):
        assert ep["spacing_m"] == pytest.approx(want["cruise_spacing_m"], rel=1e-12)
        assert ep["altitude_m"] == pytest.approx(want["cruise_altitude_m"], rel=1e-12)
        assert 0.0 < ep["horizontal_spacing_m"] <= ep["spacing_m"] + 1e-9
        assert ep["altitude_spread_m"] >= 0.0
    assert "horizontally" in (out / "report.md").read_text()
