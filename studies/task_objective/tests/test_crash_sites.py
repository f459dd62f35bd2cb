"""crash_sites.py: where along the route UAVs hit buildings."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env import urban_canyon_v1
from studies.task_objective import crash_sites as cs

ROUTE = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 50.0]])


def test_distances_to_the_corners_and_to_the_route() -> None:
    assert cs.distance_to_corners(ROUTE, [103.0, 4.0]) == pytest.approx(5.0)
    assert cs.distance_to_corners(ROUTE[:2], [0.0, 0.0]) == float("inf")  # no turn
    assert cs.distance_to_route(ROUTE, [50.0, 7.0]) == pytest.approx(7.0)  # beside leg 1
    assert cs.distance_to_route(ROUTE, [94.0, 30.0]) == pytest.approx(6.0)  # beside leg 2
    assert cs.distance_to_route(ROUTE, [-3.0, 4.0]) == pytest.approx(5.0)  # before the start


class _LowAndFast:
    """Every UAV at full speed north-east and down: across the blocks, into a building."""

    def reset(self, seed=None) -> None:
        pass

    def act(self, observations):
        return {a: np.array([1.0, 1.0, -1.0], dtype=np.float32) for a in observations}


def test_a_crash_is_found_with_its_uav_step_and_place() -> None:
    env = urban_canyon_v1.parallel_env(n_uavs=3)
    crashes = cs.crashes_in(env, _LowAndFast(), [1_000_000, 1_000_001, 1_000_002])
    assert crashes, "flying low across the blocks must hit a building"
    for c in crashes:
        assert c["uav"] in (0, 1, 2) and c["step"] >= 1
        assert c["off_route_m"] >= 0 and c["corner_m"] > 0
    s = cs.summarise(crashes, 3, corner_m=20.0)
    assert s["crashed_uavs"] == len(crashes)
    assert 1 <= s["episodes_with_crash"] <= 3
    assert sum(s["by_uav"].values()) == len(crashes)


def test_command_line_writes_the_report_and_refuses_to_overwrite(tmp_path) -> None:
    out = tmp_path / "crashes"
    args = ["--policies", "column", "--episodes", "2", "--out", str(out)]
    assert cs.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["policies"]["column"]["episodes"] == 2
    assert "a crash is a UAV touching a building" in (out / "report.md").read_text()
    with pytest.raises(SystemExit):
        cs.main(args)
    with pytest.raises(SystemExit):
        cs.main([*args[:4], "--corner-m", "0", "--out", str(tmp_path / "x")])
