"""The protocol's command line: MASAC actors (``masac:FOLDER``) by row name, and what it refuses.

Flying an actor needs BenchMARL (the ``benchmarl`` extra, a venv of its own): that test skips
where it is not installed.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from studies.generalisation.run_protocol import main, masac_policies, masac_row_name

ACTOR = Path(__file__).resolve().parents[2] / "off_policy" / "policies" / "masac_s0"


def test_a_masac_row_is_named_after_its_folder() -> None:
    assert masac_row_name("masac:studies/x/masac_families_s0") == "masac_families_s0"
    assert masac_row_name("masac:runs/seed-1/policy") == "masac_policy"


def test_rules_alone_fly_with_no_settings_of_their_own() -> None:
    with masac_policies(["column", "high_wide_column"]) as (names, overrides):
        assert (names, overrides) == (["column", "high_wide_column"], {})


def test_bad_masac_policies_are_refused(tmp_path, capsys) -> None:
    out = ["--episodes", "1", "--tune", "1", "--parts", "real", "--out", str(tmp_path / "p")]
    rules = ["column", "high_wide_column"]
    cases = [
        ([*rules, "masac:x/a", "mappo:pretrained/route_s0"], "in a protocol of their own"),
        ([*rules, "masac:x/a", "masac:y/a"], "share a row name"),
        ([*rules, f"masac:{tmp_path}"], "is not a saved MASAC actor"),
    ]
    for policies, message in cases:
        assert main(["--policies", *policies, *out]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


def test_actors_of_different_settings_are_refused(tmp_path, capsys) -> None:
    pytest.importorskip("benchmarl")
    other = tmp_path / "other"
    shutil.copytree(ACTOR, other)
    record = json.loads((other / "actor.json").read_text())
    record["settings"]["env"]["max_steps"] = 150
    (other / "actor.json").write_text(json.dumps(record))
    policies = ["column", "high_wide_column", f"masac:{ACTOR}", f"masac:{other}"]
    assert main(["--policies", *policies, "--out", str(tmp_path / "p")]) == 2
    assert "was trained with" in capsys.readouterr().err
