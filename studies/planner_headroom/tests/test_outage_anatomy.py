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

    env = urban_canyon_v0.parallel_env(n_uavs=2)
    env.reset(seed=3)
    pts = mod.candidate_points(env)
    cmd = {a: np.zeros(3, np.float32) for a in env.agents}

    def with_counts(own, pooled):
        return {a: np.r_[own, pooled].astype(float) for a in env.agents}

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


def test_candidates_are_here_ahead_left_right_and_far() -> None:
    from coopnav_env import urban_canyon_v0
    from tests.env_flight import fly_random

    mod = _module()
    env = urban_canyon_v0.parallel_env(n_uavs=4)
    kin = env.config.kinematics
    checked = 0
    for seed, steps in ((3, 0), (3, 25), (8, 40)):
        fly_random(env, seed, steps)
        if not env.agents:
            continue
        est = env._epoch.nav_pos_enu_m
        pts = mod.candidate_points(env)
        assert pts.shape == (5, 4, 3)
        z = np.clip(est[:, 2], kin.altitude_min_m, kin.altitude_max_m)
        assert np.all(pts[:, :, 2] == z)  # every candidate at the estimated altitude, in the band
        np.testing.assert_array_equal(pts[0, :, :2], est[:, :2])
        route = mod.route_points(env, (mod.CANDIDATE_AHEAD_M, mod.CANDIDATE_FAR_M))
        np.testing.assert_array_equal(pts[1], route[0])
        np.testing.assert_array_equal(pts[4], route[1])
        for i in range(4):
            fwd = pts[1, i, :2] - est[i, :2]
            side_l = pts[2, i, :2] - pts[1, i, :2]
            np.testing.assert_allclose(np.hypot(*side_l), mod.CANDIDATE_SIDE_M)
            np.testing.assert_allclose(side_l, -(pts[3, i, :2] - pts[1, i, :2]))
            if np.hypot(*fwd) > 1e-6:  # left of the way ahead: a positive cross product
                assert fwd[0] * side_l[1] - fwd[1] * side_l[0] > 0.0
        checked += 1
    assert checked >= 2


def test_candidate_counts_are_what_the_receiver_would_use_there() -> None:
    from coopnav_env import urban_canyon_v0
    from coopnav_env.envs import preset_config
    from tests.env_flight import fly_random

    mod = _module()
    env = urban_canyon_v0.parallel_env(
        config=preset_config("urban_nlos_3dma", n_uavs=3, dead_reckoning_noise=True)
    )
    cfg = env.config
    fly_random(env, 11, 10)
    pts = mod.candidate_points(env)
    dr_var = (cfg.dead_reckoning_sigma_mps * cfg.dt_s) ** 2
    cov = env.world.nav_cov_enu_m2 + np.eye(3) * dr_var

    def usable(p, c):
        return env.world.map_line_of_sight(
            p,
            c,
            margin_sigma=cfg.nlos_exclusion_margin_sigma,
            max_margin_m=cfg.nlos_exclusion_max_margin_m,
        )

    cols = mod.candidate_sky(env)
    assert cols.shape == (3, 10) and cols.dtype == np.float32
    ahead = usable(pts[1], cov)
    for i in range(3):
        for c in range(5):
            use = usable(pts[c, i][None], cov[i][None])[0]
            assert cols[i, c] == pytest.approx(min(use.sum() / 20.0, 1.0))
            pooled = use | np.delete(ahead, i, axis=0).any(axis=0)
            assert cols[i, 5 + c] == pytest.approx(min(pooled.sum() / 20.0, 1.0))
            assert cols[i, 5 + c] >= cols[i, c]  # the swarm keeps at least what the UAV keeps
    counts = mod.candidate_counts(env)
    np.testing.assert_array_equal(counts["uav_1"], cols[1] * 20.0)
