"""``coopnav alignment``: the v1 return is the score and ranks a small family as the score does."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env.training import alignment as al
from coopnav_env.training.cli import main

FAST_CLUMP = "formation@cruise_speed_mps=10,spacing_m=3"
SEEDS = [1_000_000 + i for i in range(4)]


def test_spearman_and_discounted_return() -> None:
    assert al.spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert al.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert al.spearman([1, 1, 2, 3], [1, 2, 3, 4]) == pytest.approx(
        np.corrcoef([0.5, 0.5, 2, 3], [0, 1, 2, 3])[0, 1]
    )
    with pytest.raises(ValueError, match="constant"):
        al.spearman([1, 1, 1], [1, 2, 3])
    with pytest.raises(ValueError, match="same length >= 3"):
        al.spearman([1, 2], [1, 2])
    assert al.discounted_return([1.0, 1.0, 1.0], 0.5) == pytest.approx(1.75)
    assert al.discounted_return([1.0, 2.0], 1.0) == pytest.approx(3.0)


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="at least 3 policies"):
        al.alignment(["wide", "sky"], SEEDS)
    with pytest.raises(ValueError, match="unknown reward setting"):
        al.alignment(["wide", "sky", "formation"], SEEDS, settings=["v2"])
    with pytest.raises(ValueError, match=r"discounts must be in \(0, 1\]"):
        al.alignment(["wide", "sky", "formation"], SEEDS, gammas=[1.5])
    with pytest.raises(ValueError, match="change the reward"):
        al.alignment(["wide", "sky", "formation"], SEEDS, env_kwargs={"goal_bonus": 3.0})


@pytest.fixture(scope="module")
def small_family() -> al.AlignmentReport:
    return al.alignment(["wide", "formation", FAST_CLUMP], SEEDS, ["v0", "v1"], [0.99, 1.0])


def test_the_v1_return_is_the_score_and_keeps_the_ranking(small_family) -> None:
    rows = {r["policy"]: r for r in small_family.rows}
    for r in rows.values():
        assert r["v1:return"] == r["score"] == r["v1:disc@1"]
    # the swarm that navigates best scores above the fast clump, and the shipped discount
    # (1, training/configs/*.yaml, section urban_canyon_v1) ranks the family as the score
    assert rows["wide"]["score"] > rows[FAST_CLUMP]["score"]
    assert rows["wide"]["score"] > rows["formation"]["score"]
    assert rows["wide"]["nav_error_m"] < rows[FAST_CLUMP]["nav_error_m"]
    assert small_family.correlations["v1:disc@1"] == pytest.approx(1.0)
    # v0's discounted return ranks the fast clump above the best-navigating swarm
    assert rows[FAST_CLUMP]["v0:disc@0.99"] > rows["wide"]["v0:disc@0.99"]


def test_the_shipped_v1_discount_is_one() -> None:
    from coopnav_env.training.config import load_config

    section = load_config(env_id="urban_canyon_v1")
    assert section["ppo"]["gamma"] == 1.0
    assert section["torchrl"]["gamma"] == 1.0
    assert section["rllib"]["ppo"]["gamma"] == 1.0
    assert section["torchrl"]["residual_base"] is None


def test_cli_writes_the_report(tmp_path, capsys) -> None:
    out = tmp_path / "align"
    args = ["alignment", "--policies", "wide", "formation", "sky", "--episodes", "1"]
    assert main([*args, "--settings", "v1", "--gammas", "1", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["episodes"] == 1 and len(report["rows"]) == 3
    assert "Spearman" in (out / "report.md").read_text()
    # an existing report is not overwritten without --overwrite
    assert main([*args, "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_reward_settings_are_flown_in_v1_s_world() -> None:
    """v1's crash-free start is part of the world, not of the reward: a policy whose UAV meets
    a wall in the first steps (the fast clump, seed 1000031) flies the same under v0's reward
    as under v1's, so the settings compare rewards of the same flights."""
    clump = "column@cruise_speed_mps=10,spacing_m=3"
    v0 = al.fly(clump, "urban_canyon_v0", [1000031], {})[0]
    v1 = al.fly(clump, "urban_canyon_v1", [1000031], {})[0]
    assert not np.array_equal(v0.error_trace, v1.error_trace)  # the worlds differ by default
    al.alignment([clump, "column", "sky_column"], [1000031], ["v0", "v1"], [1.0])  # no refusal
    with pytest.raises(ValueError, match=r"\['goal_bonus'\] change the reward"):
        al.alignment([clump, "column", "sky_column"], [1], ["v0"], [1.0], {"goal_bonus": 2.0})
