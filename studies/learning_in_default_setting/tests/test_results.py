"""The study's README and the index quote the committed report to the digit."""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def paired(report: dict, method: str, reference: str) -> str:
    """``method - reference`` of a ``coopnav study`` report as the READMEs write it."""
    d = report["summary"]["paired"][method][reference]["error_diff_m"]
    return f"{d['value']:+.2f} m [{d['low']:.2f}, {d['high']:.2f}]"


def test_the_headline_is_the_committed_report():
    report = json.loads((HERE / "results" / "report.json").read_text())
    headline = paired(report, "mappo", "wide")
    assert headline == "+0.01 m [-0.04, 0.07]"
    assert headline in (HERE / "README.md").read_text()
    assert headline in (HERE.parent / "README.md").read_text()
    assert report["command"].endswith("--out studies/learning_in_default_setting/results")
