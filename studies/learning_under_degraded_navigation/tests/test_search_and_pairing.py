"""search_heuristics.py and paired_variants.py: the screening scripts of the learning studies."""

from __future__ import annotations

import pytest

from studies.learning_under_degraded_navigation import paired_variants, search_heuristics


def test_heuristic_search_script_prints_its_table(capsys) -> None:
    """search_heuristics.py: one row per variant, the scores of the study."""
    mod = search_heuristics
    variants = ["--variants", "column", "wide_column@spacing_m=30", "--episodes", "2"]
    assert mod.main([*variants, "--env-set", "n_uavs=3", "integrity_p_fa=1e-3"]) == 0
    out = capsys.readouterr().out
    assert "'integrity_p_fa': 0.001" in out  # a float, not YAML's string "1e-3"
    rows = [line for line in out.splitlines() if line.startswith("| `")]
    assert [r.split("|")[1].strip() for r in rows] == ["`column`", "`wide_column@spacing_m=30`"]
    assert "'n_uavs': 3" in out
    with pytest.raises(SystemExit, match="--episodes must be >= 2"):
        mod.main(["--variants", "column", "--episodes", "1"])
    with pytest.raises(SystemExit, match="--env-set: override 'n_uavs' must look like key=value"):
        mod.main([*variants, "--env-set", "n_uavs"])


def test_paired_variants_script_pairs_groups_by_episode(capsys) -> None:
    """paired_variants.py: a group against itself differs by exactly zero; a group
    of two policies averages them episode by episode."""
    mod = paired_variants
    groups = ["--groups", "a=formation", "same=formation", "two=formation,wide"]
    args = [*groups, "--episodes", "2", "--jobs", "1", "--env-set", "n_uavs=3", "max_steps=20"]
    assert mod.main(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines[:3]] == ["a", "same", "two"]
    assert "  same - a nav: +0.000 [+0.000,+0.000]" in lines
    per = [float(x) for x in lines[2].split("per-seed [")[1].rstrip("]").split(",")]
    a_nav = float(lines[0].split("nav ")[1].split()[0])
    two_nav = float(lines[2].split("nav ")[1].split()[0])
    assert per[0] == pytest.approx(a_nav, abs=0.006)  # its first policy is formation again
    assert two_nav == pytest.approx(sum(per) / 2, abs=0.006)
    with pytest.raises(SystemExit, match="NAME=POLICY"):
        mod.main(["--groups", "column"])
    with pytest.raises(SystemExit, match="'a' is given twice"):
        mod.main(["--groups", "a=formation", "a=wide"])
    with pytest.raises(SystemExit, match="--episodes must be >= 1"):
        mod.main(["--groups", "a=formation", "--episodes", "0"])


def test_paired_variants_group_env_pairs_a_setting(capsys) -> None:
    """``--group-env``: a group flown with a setting equal to the default differs by exactly
    zero; one with another setting differs; bad entries are errors that name the problem."""
    mod = paired_variants
    common = ["--episodes", "2", "--jobs", "1", "--env-set", "n_uavs=3", "max_steps=20"]
    groups = ["--groups", "a=formation", "same=formation", "other=formation"]
    genv = ["--group-env", "same:max_fix_sigma_m=30", "other:n_uavs=2"]
    assert mod.main([*groups, *common, *genv]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "  same - a nav: +0.000 [+0.000,+0.000]" in lines
    other = next(ln for ln in lines if ln.startswith("  other - a nav:"))
    assert "+0.000 [+0.000,+0.000]" not in other
    with pytest.raises(SystemExit, match="NAME:KEY=VALUE"):
        mod.main([*groups, *common, "--group-env", "same=1"])
    with pytest.raises(SystemExit, match="no group 'x'"):
        mod.main([*groups, *common, "--group-env", "x:n_uavs=2"])
    with pytest.raises(SystemExit, match=r"group 'same'.*max_fix_sigma_m"):
        mod.main([*groups, *common, "--group-env", "same:max_fix_sigma_m=-1"])
    with pytest.raises(SystemExit, match=r"group 'same'.*unknown"):
        mod.main([*groups, *common, "--group-env", "same:not_a_field=1"])
