"""The study's table is the committed evaluation report, to the digit."""

from __future__ import annotations

import json
import re
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def test_the_table_is_the_committed_report():
    report = json.loads((HERE / "results" / "report.json").read_text())
    assert report["seeds"] == list(range(1_000_000, 1_000_040))
    rows = {}
    for line in (HERE / "README.md").read_text().splitlines():
        cells = [c.strip().strip("*") for c in line.strip("|").split("|")]
        if len(cells) == 10 and re.fullmatch(r"\d+\.\d\d", cells[1]):
            rows[cells[0].split(" (")[0]] = cells
    assert len(rows) == 6
    for p in report["policies"]:
        name = "PPO" if p["policy"].startswith("ppo:") else p["policy"]
        cells = rows[name]
        assert cells[1] == f"{p['coop_error_mean_m']:.2f}", name
        assert cells[7] == f"{p['goal_rate']:.3f}", name
        assert cells[8] == str(p["collisions"]), name
