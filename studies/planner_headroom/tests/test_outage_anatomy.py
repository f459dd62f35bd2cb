"""outage_anatomy.py: why the cooperative fix is lost, and a greedy use of counts."""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.planner_headroom import outage_anatomy


def _module():
    return outage_anatomy


def test_auc_ranks_and_handles_ties_and_one_class() -> None:
    mod = _module()
    label = np.array([False, False, True, True])
    assert mod.auc(np.array([0.1, 0.2, 0.3, 0.4]), label) == 1.0
    assert mod.auc(np.array([0.4, 0.3, 0.2, 0.1]), label) == 0.0
    assert mod.auc(np.array([1.0, 1.0, 1.0, 1.0]), label) == 0.5  # ties: mid-ranks
    assert np.isnan(mod.auc(np.array([0.1, 0.2]), np.array([True, True])))
    rng = np.random.default_rng(0)  # a random score: 0.5 within a few standard errors
    lab = rng.random(4000) < 0.3
    assert abs(mod.auc(rng.random(4000), lab) - 0.5) < 4 * 0.5 / np.sqrt(0.3 * 0.7 * 4000)


def test_anatomy_counts_statuses_outages_and_onsets() -> None:
    mod = _module()
    from coopnav_env.nav import NavStatus

    few, sing = int(NavStatus.TOO_FEW_SATELLITES), int(NavStatus.SINGULAR_GEOMETRY)
    # one episode: fix, fix, outage (both UAVs), fix; counts fall before the outage
    steps = [
        {
            "episode": 7,
            "fix": [True, True],
            "status": [0, 0],
            "n_sats": 9,
            "ahead": 9,
            "pooled": 12,
        },
        {"episode": 7, "fix": [True, True], "status": [0, 0], "n_sats": 5, "ahead": 3, "pooled": 5},
        {
            "episode": 7,
            "fix": [False, False],
            "status": [few, sing],
            "n_sats": 3,
            "ahead": 2,
            "pooled": 3,
        },
        {
            "episode": 7,
            "fix": [True, False],
            "status": [0, few],
            "n_sats": 6,
            "ahead": 6,
            "pooled": 9,
        },
    ]
    out = mod.anatomy(steps)
    assert out["uav_steps_without_fix"] == 3
    assert out["no_fix_status_shares"] == pytest.approx(
        {"TOO_FEW_SATELLITES": 2 / 3, "SINGULAR_GEOMETRY": 1 / 3}
    )
    assert out["swarm_wide_outage_share"] == 0.25
    # within 1 step: from steps 0 and 1 (step 2 is an outage, step 3 has no next step)
    row = out["onset_auc"]["within_1"]
    assert row["onset_rate"] == 0.5
    assert row["n_sats"] == row["ahead"] == row["pooled"] == 1.0  # fewer counts: the onset


def test_the_greedy_push_goes_sideways_or_back_and_only_when_short(monkeypatch) -> None:
    mod = _module()
    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env(n_uavs=2, obs_candidate_sky=True)
    obs, _ = env.reset(seed=3)
    pts = env._candidate_points()
    cmd = {a: np.zeros(3, np.float32) for a in env.agents}

    def with_counts(own, pooled):
        return {a: np.concatenate([obs[a][:-10], np.r_[own, pooled] / 20.0]) for a in env.agents}

    # plenty ahead: no push
    out = mod._steered(env, with_counts([5] * 5, [12] * 5), cmd, 0.3, 7)
    assert all(np.all(out[a] == 0.0) for a in env.agents)
    # short ahead, the left candidate best: a push of 0.3 toward it, sideways
    out = mod._steered(env, with_counts([2, 2, 6, 2, 2], [4, 4, 9, 4, 4]), cmd, 0.3, 7)
    for i, a in enumerate(env.possible_agents):
        d = pts[2, i, :2] - pts[1, i, :2]
        np.testing.assert_allclose(out[a][:2], 0.3 * d / np.hypot(*d), atol=1e-6)
        assert out[a][2] == 0.0
    # short ahead, where it is now best: braking, toward the estimate
    out = mod._steered(env, with_counts([6, 2, 2, 2, 2], [9, 4, 4, 4, 4]), cmd, 0.3, 7)
    for i, a in enumerate(env.possible_agents):
        d = pts[0, i, :2] - pts[1, i, :2]
        np.testing.assert_allclose(out[a][:2], 0.3 * d / np.hypot(*d), atol=1e-6)


def test_command_line_runs_and_writes_its_report(tmp_path, capsys) -> None:
    mod = _module()
    out = tmp_path / "anatomy.json"
    args = ["--episodes", "2", "--jobs", "1", "--steer", "0.2:8", "--out", str(out)]
    args += ["--env-set", "n_uavs=3", "preset=urban_nlos_3dma"]
    assert mod.main(args) == 0
    printed = capsys.readouterr().out
    assert "onset of a swarm-wide outage" in printed and "steer 0.2:8" in printed
    report = json.loads(out.read_text())
    assert report["episodes"] == 2 and len(report["variants"]) == 2
    # the settings reach the environment the episodes are flown in
    assert report["env_kwargs"] == {"n_uavs": 3, "preset": "urban_nlos_3dma"}
    assert report["n_uavs"] == 3 and report["nlos_exclusion"] == "map"
    assert not list(tmp_path.glob("*.tmp"))
    with pytest.raises(SystemExit, match="GAIN:THRESHOLD"):
        mod.main(["--steer", "fast"])
    with pytest.raises(SystemExit, match="--episodes must be >= 1, got 0"):
        mod.main(["--episodes", "0"])
    with pytest.raises(SystemExit, match="--jobs must be >= 1, got 0"):
        mod.main(["--jobs", "0"])
    with pytest.raises(SystemExit, match="THRESHOLD in"):
        mod.main(["--steer", "0.2:99"])
