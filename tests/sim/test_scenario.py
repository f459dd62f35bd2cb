"""The urban world epoch by epoch: configuration, start/goal, determinism, navigation."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from coopnav_env.gnss import ecef_to_enu, enu_to_ecef
from coopnav_env.nav import NavStatus
from coopnav_env.sim import (
    AUTO_SHARED_MIN_UAVS,
    City,
    CityConfig,
    KinematicsConfig,
    NavSource,
    ScenarioConfig,
    UrbanWorld,
    building_collisions,
    canyon_city,
    formation_offsets,
    separation_violations,
)
from coopnav_env.sim import _kernels as _sim_kernels
from coopnav_env.sim.swarm import swept_collisions
from tests.sim import oracles

FIELD = np.array([200.0, 0.0, 0.0])
"""Offset from the canyon's centre line to the open field [m]."""


def _canyon_and_field() -> City:
    """The paper's canyon (x in [-30, 30]) with an open field east of it (x up to 300 m)."""
    cany = canyon_city(h_over_d=math.sqrt(3.0), length_m=400.0)
    return City(
        buildings=cany.buildings,
        extent_m=(-40.0, 300.0, -200.0, 200.0),
        street_centres_x_m=[0.0],
        street_centres_y_m=[],
        open_squares=[[200.0, 0.0]],
        street_width_m=20.0,
    )


def _parked(world: UrbanWorld, pos: np.ndarray, steps: int, seed: int):
    rng = np.random.default_rng(seed)
    world.reset(rng, start_pos_enu_m=pos)
    return [world.step(np.zeros_like(pos), rng) for _ in range(steps)]


# ---- configuration ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_uavs": 0}, r"ScenarioConfig\.n_uavs .*\[1, 256\].*got 0"),
        ({"city": "paris"}, r"ScenarioConfig\.city must be one of \('grid', 'canyon'\)"),
        ({"centroid": "middle"}, r"ScenarioConfig\.centroid must be one of"),
        ({"transfer": "tdt"}, r"ScenarioConfig\.transfer"),
        ({"elevation_mask_deg": 75.0}, r"elevation_mask_deg must be in \[0.0, 60.0\]"),
        ({"max_sats": 2}, r"max_sats must be an integer in \[4, 200\]"),
        ({"nlos_probability": 1.5}, r"nlos_probability"),
        ({"systems": ("GPS", "GLONASS")}, r"systems must be a non-empty tuple"),
        ({"formation_spacing_m": 1.0}, r"formation_spacing_m must be in \[3.0, 100.0\]"),
        ({"start_altitude_m": 50.0}, r"start_altitude_m must be in \[5.0, 30.0\]"),
        ({"city_config": {"n_blocks": 3}}, r"unknown CityConfig field\(s\) \['n_blocks'\]"),
        ({"kinematics": 3}, r"kinematics must be a KinematicsConfig or a dict"),
        ({"city_seed": -1}, r"city_seed"),
    ],
)
def test_config_rejects_bad_values(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        ScenarioConfig(**kwargs)


def test_config_accepts_dicts_and_resolves_centroid() -> None:
    cfg = ScenarioConfig(kinematics={"max_speed_mps": 5.0}, city_config={"n_blocks_x": 3})
    assert cfg.kinematics == KinematicsConfig(max_speed_mps=5.0)
    assert cfg.city_config.n_blocks_x == 3
    assert ScenarioConfig(n_uavs=AUTO_SHARED_MIN_UAVS - 1).centroid_mode == "self"
    assert ScenarioConfig(n_uavs=AUTO_SHARED_MIN_UAVS).centroid_mode == "shared"
    assert ScenarioConfig(n_uavs=3, centroid="shared").centroid_mode == "shared"


# ---- formation, start and goal ----------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 5, 50])
def test_formation_offsets_are_separated_and_inside_the_street(n) -> None:
    off = formation_offsets(n, 5.0, 8.0, 15.0, 6.0, 29.0)
    assert off.shape == (n, 3)
    assert np.all(np.abs(off[:, 1]) <= 8.0)
    assert np.all((off[:, 2] >= 6.0) & (off[:, 2] <= 29.0))
    d = np.linalg.norm(off[:, None] - off[None], axis=2) + np.eye(n) * 1e9
    assert d.min() >= 5.0 - 1e-9


def test_formation_offsets_are_a_fresh_array_each_call() -> None:
    """The lattice is cached per arguments; what a caller gets is its own, writable copy."""
    a = formation_offsets(5, 5.0, 8.0, 15.0, 6.0, 29.0)
    expected = a.copy()
    a[:] = -1.0  # must not reach the cache
    b = formation_offsets(5, 5.0, 8.0, 15.0, 6.0, 29.0)
    assert b.flags.writeable and b is not a
    assert np.array_equal(b, expected)
    assert not np.array_equal(formation_offsets(5, 5.0, 8.0, 20.0, 6.0, 29.0), expected)


@pytest.mark.parametrize(("city", "n"), [("grid", 5), ("grid", 50), ("canyon", 5)])
def test_reset_places_a_valid_formation_and_goal(city, n) -> None:
    cfg = ScenarioConfig(n_uavs=n, city=city)
    world = UrbanWorld(cfg)
    for seed in range(5):
        ep = world.reset(np.random.default_rng(seed))
        pos = ep.pos_enu_m
        x0, x1, y0, y1 = world.city.extent_m
        assert np.all((pos[:, 0] > x0) & (pos[:, 0] < x1) & (pos[:, 1] > y0) & (pos[:, 1] < y1))
        assert not building_collisions(world.city.buildings, pos, 1.0).any()
        assert not separation_violations(pos, cfg.kinematics.min_separation_m).any()
        assert not building_collisions(world.city.buildings, ep.goal_enu_m[None], 1.0).any()
        assert np.linalg.norm(pos[:, :2].mean(0) - ep.goal_enu_m[:2]) >= cfg.goal_distance_min_m
        assert np.all(ep.vel_enu_mps == 0.0)


def test_city_is_drawn_per_episode_unless_seeded() -> None:
    rng = np.random.default_rng(0)
    world = UrbanWorld(ScenarioConfig())
    world.reset(rng)
    a = world.city.buildings.max_m.copy()
    world.reset(rng)
    assert not np.array_equal(a, world.city.buildings.max_m)
    fixed = UrbanWorld(ScenarioConfig(city_seed=11))
    fixed.reset(rng)
    b = fixed.city.buildings.max_m.copy()
    fixed.reset(rng)
    np.testing.assert_array_equal(b, fixed.city.buildings.max_m)


# ---- the epoch pipeline -----------------------------------------------------------------------


def test_frames_match_the_gnss_package() -> None:
    cfg = ScenarioConfig()
    world = UrbanWorld(cfg)
    enu = np.random.default_rng(1).uniform(-300, 300, (7, 3))
    ecef = world.enu_to_ecef(enu)
    np.testing.assert_allclose(ecef, enu_to_ecef(enu, cfg.lat_deg, cfg.lon_deg, cfg.alt_m), 0, 1e-6)
    np.testing.assert_allclose(
        world.ecef_to_enu(ecef), ecef_to_enu(ecef, cfg.lat_deg, cfg.lon_deg, cfg.alt_m), 0, 1e-6
    )


def test_relative_positions_rotate_like_from_enu() -> None:
    from coopnav_env.nav import RelativePositions
    from coopnav_env.sim import RelativeSensingConfig, measure_relative_positions

    cfg = ScenarioConfig()
    world = UrbanWorld(cfg)
    rng = np.random.default_rng(0)
    pos = np.c_[rng.uniform(-100, 100, (6, 2)), rng.uniform(5, 30, 6)]
    rel, cov, avail = measure_relative_positions(rng, pos, RelativeSensingConfig(sigma0_m=0.3))
    var = cov[:, :, 0, 0]
    assert np.array_equal(cov, var[:, :, None, None] * np.eye(3))  # isotropic
    ours = world._relative_ecef(rel, var, avail)
    ref = RelativePositions.from_enu(rel, cov, avail, cfg.lat_deg, cfg.lon_deg)
    np.testing.assert_allclose(ours.rel_ecef_m, ref.rel_ecef_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours.cov_ecef_m2, ref.cov_ecef_m2, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(ours.available, ref.available)
    row = world._relative_ecef(rel, var, avail, row=2)
    np.testing.assert_allclose(row.rel_ecef_m[2], ref.rel_ecef_m[2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(row.cov_ecef_m2[2], ref.cov_ecef_m2[2], rtol=0, atol=1e-14)
    assert row.available.sum() == avail[2].sum() + 6  # row 2 plus the diagonal


def test_same_generator_state_gives_the_same_epochs_bit_for_bit() -> None:
    def run(seed: int):
        world = UrbanWorld(ScenarioConfig(nlos_probability=0.3))
        rng = np.random.default_rng(seed)
        out = [world.reset(rng)]
        cmd_rng = np.random.default_rng(99)
        for _ in range(15):
            out.append(world.step(cmd_rng.uniform(-0.3, 0.3, (5, 3)), rng))
        return out

    a, b = run(4), run(4)
    for ea, eb in zip(a, b):
        for name in ("pos_enu_m", "nav_pos_enu_m", "nav_cov_enu_m2", "rel_enu_m", "received"):
            np.testing.assert_array_equal(getattr(ea, name), getattr(eb, name))
    c = run(5)
    assert not np.array_equal(a[3].nav_pos_enu_m, c[3].nav_pos_enu_m)


def test_world_pickles_mid_episode() -> None:
    world = UrbanWorld(ScenarioConfig())
    rng = np.random.default_rng(2)
    world.reset(rng)
    world.step(np.full((5, 3), 0.1), rng)
    clone, rng2 = pickle.loads(pickle.dumps((world, rng)))
    e1 = world.step(np.full((5, 3), 0.2), rng)
    e2 = clone.step(np.full((5, 3), 0.2), rng2)
    np.testing.assert_array_equal(e1.nav_pos_enu_m, e2.nav_pos_enu_m)


def test_satellites_move_and_solvers_are_warm_started() -> None:
    world = UrbanWorld(ScenarioConfig(city="canyon", t0_s=5000.0))
    rng = np.random.default_rng(0)
    first = world.reset(rng)
    assert first.t_s == 5000.0
    assert first.n_iter_standalone <= 3  # started from the known launch positions
    eps = [world.step(np.zeros((5, 3)), rng) for _ in range(5)]
    assert eps[-1].t_s == 5005.0
    assert not np.allclose(first.sv_el_deg, eps[-1].sv_el_deg)
    # warm start: 2 iterations (one step, one check below 0.1 mm), 3 after a big jump of a
    # poor standalone fix
    iters = np.array([[e.n_iter_standalone, e.n_iter_coop] for e in eps])
    assert iters.max() <= 3 and np.mean(iters <= 2) >= 0.8


def test_visibility_cut_off_channel_limit_and_nlos() -> None:
    city = _canyon_and_field()
    pos = np.c_[np.zeros(5), np.arange(5) * 6.0 - 12, np.full(5, 8.0)]
    world = UrbanWorld(ScenarioConfig(max_sats=6), city=city)
    ep = world.reset(np.random.default_rng(0), start_pos_enu_m=pos + FIELD)
    assert np.all(ep.n_sats <= 6)
    assert np.all(ep.received <= (ep.sv_el_deg > 10.0)[None])
    assert not ep.nlos.any()
    np.testing.assert_array_equal(
        ep.los, city.line_of_sight(pos + FIELD, _dirs(ep)) & (ep.sv_el_deg > 10)[None]
    )
    nlos_world = UrbanWorld(ScenarioConfig(nlos_probability=1.0), city=city)
    ep = nlos_world.reset(np.random.default_rng(0), start_pos_enu_m=pos)
    above = ep.sv_el_deg > 10.0
    np.testing.assert_array_equal(ep.received, np.broadcast_to(above, ep.received.shape))
    np.testing.assert_array_equal(ep.nlos, above[None] & ~ep.los)
    assert ep.nlos.any()


def _dirs(ep) -> np.ndarray:
    az, el = np.radians(ep.sv_az_deg), np.radians(ep.sv_el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)


def test_crash_stops_the_uav_and_fence_clamps() -> None:
    world = UrbanWorld(ScenarioConfig(city="canyon"))
    rng = np.random.default_rng(0)
    ep0 = world.reset(rng)
    cmd = np.zeros((5, 3))
    cmd[:, 0] = 1.0  # east, into the east row of buildings (x >= 10 m)
    crashed = False
    for _ in range(5):
        prev = world.pos_enu_m.copy()
        ep = world.step(cmd, rng)
        if ep.collided.any():
            crashed = True
            np.testing.assert_array_equal(ep.pos_enu_m[ep.collided], prev[ep.collided])
            assert np.all(ep.vel_enu_mps[ep.collided] == 0.0)
            break
    assert crashed
    assert ep0.collided.sum() == 0
    # the fence: fly north for a long time in the canyon, stay inside the extent
    world.reset(rng)
    cmd = np.zeros((5, 3))
    cmd[:, 1] = 1.0
    for _ in range(60):
        ep = world.step(cmd, rng)
    assert np.all(ep.pos_enu_m[:, 1] <= world.city.extent_m[3] - 1.0 + 1e-9)


def test_culled_swept_collisions_equal_the_full_test() -> None:
    rng = np.random.default_rng(3)
    world = UrbanWorld(ScenarioConfig())
    world.reset(rng)
    b = world.city.buildings
    p0 = np.c_[rng.uniform(-250, 250, (400, 2)), rng.uniform(5, 30, 400)]
    p1 = p0 + rng.normal(0, 8, (400, 3))
    hit = _sim_kernels.swept_collisions_culled(b.min_m, b.max_m, p0, p1, 1.0)
    np.testing.assert_array_equal(hit, swept_collisions(b, p0, p1, 1.0))
    np.testing.assert_array_equal(oracles.swept_collisions_culled(b, p0, p1, 1.0), hit)
    assert 0 < hit.sum() < hit.size


# ---- the navigation matters -------------------------------------------------------------------

LINE = np.c_[np.zeros(5), np.arange(5) * 6.0 - 12.0, np.full(5, 8.0)]


@pytest.mark.parametrize("centroid", ["self", "shared"])
def test_deep_canyon_is_worse_than_open_sky(centroid) -> None:
    world = UrbanWorld(ScenarioConfig(centroid=centroid), city=_canyon_and_field())
    canyon = _parked(world, LINE, 20, seed=1)
    field = _parked(world, LINE + FIELD, 20, seed=1)
    assert np.mean([e.n_sats.mean() for e in canyon]) < np.mean([e.n_sats.mean() for e in field])
    err_canyon = np.nanmean([e.coop_error_m for e in canyon])
    err_field = np.nanmean([e.coop_error_m for e in field])
    assert err_canyon > 2.0 * err_field
    # in the canyon the cooperative fix is available more often than the standalone one
    assert np.mean([e.coop_ok.mean() for e in canyon]) > np.mean(
        [e.standalone_ok.mean() for e in canyon]
    )


@pytest.mark.parametrize("centroid", ["self", "shared"])
def test_cooperation_helps_the_masked_uavs(centroid) -> None:
    world = UrbanWorld(ScenarioConfig(centroid=centroid), city=_canyon_and_field())
    mixed = LINE.copy()
    mixed[3:, 0] = 150.0  # two UAVs in the open field, 150 m east of the canyon
    eps = _parked(world, mixed, 30, seed=2)
    masked = slice(0, 3)
    coop = np.array([e.coop_error_m[masked] for e in eps])
    alone = np.array([e.standalone_error_m[masked] for e in eps])
    assert np.all(np.isfinite(coop))  # always a cooperative fix
    assert np.isfinite(alone).mean() < 0.5  # mostly no standalone fix at all
    both = np.isfinite(alone)
    assert coop[both].mean() < 0.5 * alone[both].mean()
    assert all(np.all(e.nav_source[masked] == NavSource.COOPERATIVE) for e in eps)


def test_degenerate_geometry_is_a_status_not_an_exception() -> None:
    world = UrbanWorld(ScenarioConfig(elevation_mask_deg=60.0, city="canyon"))
    rng = np.random.default_rng(0)
    world.reset(rng)
    for _ in range(5):
        ep = world.step(np.zeros((5, 3)), rng)
    assert np.all(ep.standalone_status == NavStatus.TOO_FEW_SATELLITES)
    assert np.all(ep.nav_source == NavSource.DEAD_RECKONING)
    assert np.all(np.isfinite(ep.nav_pos_enu_m)) and np.all(np.isfinite(ep.nav_cov_enu_m2))
    # dead reckoning: the predicted sigma grows
    assert np.all(ep.nav_sigma_enu_m > world.config.start_prior_sigma_m)


def test_uavs_out_of_relative_range_navigate_standalone() -> None:
    cfg = ScenarioConfig(relative_sensing={"max_range_m": 1.0})
    world = UrbanWorld(cfg, city=_canyon_and_field())
    eps = _parked(world, LINE + FIELD, 3, seed=0)
    for ep in eps:
        assert ep.out_of_contact.all()
        assert np.all(ep.coop_status == NavStatus.NO_RELATIVE_POSITION)
        assert np.all(ep.nav_source == NavSource.STANDALONE)
        np.testing.assert_array_equal(ep.nav_pos_enu_m, ep.standalone_pos_enu_m)


def test_shared_centroid_is_the_uav_with_most_satellites() -> None:
    world = UrbanWorld(ScenarioConfig(centroid="shared"), city=_canyon_and_field())
    mixed = LINE.copy()
    mixed[4, 0] = 150.0
    for ep in _parked(world, mixed, 3, seed=0):
        assert ep.centroid_uav == int(np.argmax(ep.n_sats))
        assert ep.n_sats_swarm.max() >= ep.n_sats.max()


def test_fifty_uavs_step() -> None:
    cfg = ScenarioConfig(n_uavs=50, city_config=CityConfig(), city_seed=1)
    world = UrbanWorld(cfg)
    rng = np.random.default_rng(0)
    world.reset(rng)
    for _ in range(3):
        ep = world.step(np.zeros((50, 3)), rng)
    assert ep.centroid_uav >= 0
    assert np.all(np.isfinite(ep.nav_pos_enu_m))
    assert ep.coop_ok.mean() > 0.5


# ---- integrity gate and the spurious root of zero-redundancy fixes --------------------------


def _first_epoch_with_solver_inputs(cfg: ScenarioConfig, seed: int):
    """The first epoch of ``seed`` and the standalone solver's observations (spied on the
    modular path, whose epochs are those of the one-call path bit for bit)."""
    import coopnav_env.sim.scenario as scenario

    calls = {}
    original, fused = scenario.solve_standalone, scenario.UrbanWorld._navigate_fused

    def spy(obs, x0, **kw):
        calls["obs"] = obs
        return original(obs, x0, **kw)

    world = UrbanWorld(cfg)
    scenario.solve_standalone = spy
    scenario.UrbanWorld._navigate_fused = scenario.UrbanWorld._navigate
    try:
        ep = world.reset(np.random.default_rng(seed))
    finally:
        scenario.solve_standalone, scenario.UrbanWorld._navigate_fused = original, fused
    return world, ep, calls["obs"]


def test_zero_redundancy_fix_from_the_earth_centre_finds_the_spurious_root() -> None:
    """Seed 245, UAV 2: 5 satellites of GPS + BDS for 5 unknowns (two exact solutions).

    Started at the Earth's centre (the solvers' default x0) Gauss-Newton converges to the
    second root 48,500 km from the Earth's centre, with a zero residual; the solvers report it
    as IMPLAUSIBLE_POSITION (it was OK before the plausibility check). The world starts from
    the launch positions and gets the near root (a 100-300 m error with a ~500 m predicted
    sigma), which the integrity gate rejects.
    """
    from coopnav_env.nav import RelativePositions, solve_cooperative, solve_standalone

    world, ep, obs = _first_epoch_with_solver_inputs(ScenarioConfig(max_fix_sigma_m=None), 245)
    truth = world.enu_to_ecef(ep.pos_enu_m)
    unchecked = solve_standalone(obs, np.zeros((5, 3)), plausible_radius_m=None)
    assert unchecked.status[2] == NavStatus.OK
    assert np.linalg.norm(unchecked.pos_ecef_m[2] - truth[2]) > 4e7
    assert np.linalg.norm(unchecked.pos_ecef_m[2]) > 4e7
    assert np.sqrt(np.trace(unchecked.cov_ecef_m2[2])) > 1e3  # its sigma: 5 km
    cold = solve_standalone(obs, np.zeros((5, 3)))
    assert cold.status[2] == NavStatus.IMPLAUSIBLE_POSITION and not cold.ok[2]
    np.testing.assert_array_equal(cold.pos_ecef_m[2], unchecked.pos_ecef_m[2])  # kept for diagnosis
    # the cooperative solver, the UAV alone as its own centroid, finds the same far root
    alone = RelativePositions(np.zeros((1, 1, 3)), np.zeros((1, 1, 3, 3)), np.ones((1, 1), bool))
    for transfer in ("sdt", "ddt"):
        co = solve_cooperative(obs.subset_receivers([2]), alone, transfer=transfer)
        assert co.status[0] == NavStatus.IMPLAUSIBLE_POSITION
        co_unchecked = solve_cooperative(
            obs.subset_receivers([2]), alone, transfer=transfer, plausible_radius_m=None
        )
        assert co_unchecked.status[0] == NavStatus.OK
        assert np.linalg.norm(co_unchecked.pos_ecef_m[0]) > 4e7
    # the world's warm start finds the near root: large error, and a sigma that says so
    assert obs.visible[2].sum() == 5 and ep.standalone_status[2] == NavStatus.OK
    assert 50.0 < ep.standalone_error_m[2] < 1e3
    sigma = np.sqrt(np.trace(ep.standalone_cov_enu_m2[2]))
    assert 300.0 < sigma < 1e3
    # with the default gate (30 m) the same fix is rejected and never used
    _, gated, _ = _first_epoch_with_solver_inputs(ScenarioConfig(), 245)
    assert gated.standalone_rejected[2] and not gated.standalone_ok[2]
    assert math.isnan(gated.standalone_error_m[2])
    assert gated.nav_error_m[2] < 50.0


def test_integrity_gate_rejects_only_fixes_with_a_large_predicted_sigma() -> None:
    cfg = ScenarioConfig(max_fix_sigma_m=30.0)
    world = UrbanWorld(cfg)
    rng = np.random.default_rng(3)
    rejected = 0
    for _ in range(3):
        world.reset(rng)
        for _ in range(20):
            ep = world.step(rng.uniform(-0.3, 0.3, (5, 3)), rng)
            for kind in ("coop", "standalone"):
                ok = getattr(ep, f"{kind}_ok")
                cov = getattr(ep, f"{kind}_cov_enu_m2")
                rej = getattr(ep, f"{kind}_rejected")
                assert not np.any(ok & rej)
                sig = np.sqrt(np.einsum("nii->n", cov[ok]))
                assert np.all(sig <= 30.0)
                assert np.all(np.isnan(getattr(ep, f"{kind}_pos_enu_m")[rej]))
                rejected += int(rej.sum())
            # the estimate used is a valid fix or dead reckoning, never a rejected fix
            src = ep.nav_source
            assert np.all(ep.coop_ok[src == NavSource.COOPERATIVE])
            assert np.all(ep.standalone_ok[src == NavSource.STANDALONE])
    assert rejected > 0  # the gate fired (8 of 600 fixes with these seeds)
    with pytest.raises(ValueError, match="max_fix_sigma_m"):
        ScenarioConfig(max_fix_sigma_m=0.0)
    assert ScenarioConfig(max_fix_sigma_m=None).max_fix_sigma_m is None


def test_world_step_rejects_bad_commands() -> None:
    """The motion step refuses a NaN or wrongly shaped command with a clear error."""
    world = UrbanWorld(ScenarioConfig(n_uavs=3))
    world.reset(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    bad = np.zeros((3, 3))
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="finite"):
        world.step(bad, rng)
    with pytest.raises(ValueError, match="shape"):
        world.step(np.zeros((2, 3)), rng)
    world.step(np.zeros((3, 3)), rng)  # still usable
