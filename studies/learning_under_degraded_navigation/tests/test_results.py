"""The study's README and the index quote the committed reports to the digit."""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def paired(report: dict, method: str, reference: str) -> str:
    """``method - reference`` of a ``coopnav study`` report as the READMEs write it."""
    d = report["summary"]["paired"][method][reference]["error_diff_m"]
    return f"{d['value']:+.2f} m [{d['low']:.2f}, {d['high']:.2f}]"


def _report(name: str) -> dict:
    return json.loads((HERE / "results" / name / "report.json").read_text())


def test_the_headline_is_the_committed_report():
    headline = paired(_report("quiet_residual_over_ceiling_5000"), "mappo_lowstd", "ceiling")
    assert headline == "-0.02 m [-0.09, 0.04]"
    assert headline in (HERE / "README.md").read_text()
    assert headline in (HERE.parent / "README.md").read_text()


def test_the_confirmatory_results_in_the_readme_are_the_reports():
    readme = (HERE / "README.md").read_text()
    # study 1: MAPPO against guarded; study 2: MAPPO over guarded against ceiling
    assert "-0.19 m [-0.36, -0.03]" in readme
    assert paired(_report("residual_over_guarded"), "mappo", "guarded") == "-0.19 m [-0.36, -0.03]"
    assert paired(_report("ceiling_against_learned"), "mappo", "ceiling") == "+0.07 m [-0.09, 0.22]"
    assert "+0.07 m\n[-0.09, 0.22]" in readme or "+0.07 m [-0.09, 0.22]" in readme


def test_every_report_was_written_into_its_own_folder():
    for folder in sorted((HERE / "results").iterdir()):
        command = json.loads((folder / "report.json").read_text())["command"]
        assert command.endswith(f"--out {folder.relative_to(HERE.parents[1]).as_posix()}"), folder
