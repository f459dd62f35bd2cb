"""The world's fast paths return exactly what the checked public functions return.

Shared skyline/wall sweep, cached satellite geometry, unchecked pseudorange simulation and
solver inputs built without re-validation (see docs/performance.md); the end-to-end check is
tests/envs/test_golden.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.gnss import ErrorModel, default_constellation, simulate_pseudoranges
from coopnav_env.gnss.errors import _simulate_pseudoranges
from coopnav_env.nav import GnssObservations, RelativePositions
from coopnav_env.sim import city as C
from coopnav_env.sim import scenario as S
from coopnav_env.sim.city import CityConfig, canyon_city, generate_city
from coopnav_env.sim.swarm import RelativeSensingConfig, measure_relative_positions
from tests.sim import oracles


def _dense_reference(buildings, pos, az_deg):
    """The skyline and wall sweeps as they were written before they shared one pass."""
    az = np.radians(np.asarray(az_deg, dtype=float))
    d = np.stack([np.sin(az), np.cos(az)], axis=1)
    d = np.where(np.abs(d) < 1e-15, 0.0, d)
    tall = np.flatnonzero(buildings.max_m[:, 2] > pos[:, 2].min())
    lo, hi = buildings.min_m[tall][None, None], buildings.max_m[tall][None, None]
    t_near, t_far = oracles.slab_interval(
        [pos[:, None, None, k] for k in range(2)],
        [d[None, :, None, k] for k in range(2)],
        [lo[..., k] for k in range(2)],
        [hi[..., k] for k in range(2)],
    )
    rel_h = hi[..., 2] - pos[:, None, None, 2]
    hit = (t_far > 0.0) & (t_near <= t_far) & (rel_h > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        tan_el = rel_h / np.maximum(t_near, 0.0)
    sky = np.degrees(np.arctan(np.maximum(0.0, np.where(hit, tan_el, 0.0).max(axis=2))))
    z = pos[:, None, None, 2]
    hit = (t_far >= 0.0) & (t_near <= t_far) & (z < hi[..., 2]) & (z >= lo[..., 2])
    walls = np.where(hit, np.maximum(t_near, 0.0), np.inf).min(axis=2)
    return sky, walls


@pytest.mark.parametrize("seed", range(6))
def test_shared_sweep_equals_separate_and_reference_sweeps(seed: int) -> None:
    rng = np.random.default_rng(seed)
    city = canyon_city() if seed == 0 else generate_city(CityConfig(), rng)
    b = city.buildings
    x0, x1, y0, y1 = city.extent_m
    pos = np.c_[rng.uniform(x0, x1, 40), rng.uniform(y0, y1, 40), rng.uniform(0.0, 60.0, 40)]
    m = min(4, b.n)  # receivers on corners, on walls and inside footprints
    pos[:m, :2] = b.min_m[:m, :2]
    pos[5 : 5 + m, 0], pos[5 : 5 + m, 1] = b.max_m[:m, 0], b.min_m[:m, 1] + 3.0
    pos[10 : 10 + m, :2] = (b.min_m[:m, :2] + b.max_m[:m, :2]) / 2.0
    for az in (np.arange(8) * 45.0, np.arange(72) * 5.0, rng.uniform(0.0, 360.0, 7)):
        sky, walls = city.sky_and_walls(pos, az)
        ref_sky, ref_walls = _dense_reference(b, pos, az)
        np.testing.assert_array_equal(sky, ref_sky)
        np.testing.assert_array_equal(walls, ref_walls)
        np.testing.assert_array_equal(sky, city.mask_elevation_deg(pos, az))
        np.testing.assert_array_equal(walls, city.wall_distance_m(pos, az))


def test_sky_cache_returns_the_uncached_geometry_read_only() -> None:
    con = default_constellation(("GPS", "BDS"))
    origin = np.array([-2.85e6, 4.66e6, 3.27e6])
    cache = S._SkyCache(max_size=2)
    for t in (0.0, 1.0, 2.0, 1.0):
        hit = cache.get((10.0, t), con, origin)  # the key ends with (mask, time)
        fresh = S._sky_epoch(con, origin, 10.0, t)
        for name in ("sv_index", "sv_ecef", "system", "system_idx", "az", "el"):
            np.testing.assert_array_equal(getattr(hit, name), getattr(fresh, name))
            assert not getattr(hit, name).flags.writeable
        np.testing.assert_array_equal(hit.directions.cot_s, fresh.directions.cot_s)
    assert len(cache._data) == 2  # bounded
    cache.clear()
    assert not cache._data


def test_unchecked_pseudoranges_and_solver_inputs_equal_the_checked_ones() -> None:
    con = default_constellation(("GPS", "BDS"))
    sv = con.positions_ecef(1234.0)[:14]
    system = np.asarray(con.system)[:14]
    rng = np.random.default_rng(0)
    rx = np.array([-2.85e6, 4.66e6, 3.27e6]) + rng.normal(0.0, 100.0, (4, 3))
    vis = rng.random((4, 14)) < 0.7
    clock = rng.normal(0.0, 1e4, (4, 2))
    extra = np.where(vis, rng.exponential(5.0, (4, 14)), 0.0)
    for model in (ErrorModel(), ErrorModel(differential=True), ErrorModel(iono_free=False)):
        for bias in (None, extra):
            a = simulate_pseudoranges(
                np.random.default_rng(5), rx, sv, system, vis, model, clock, extra_bias_m=bias
            )
            b = _simulate_pseudoranges(
                np.random.default_rng(5), rx, sv, system.astype(np.intp), vis, model, clock, bias
            )
            for name in a.__dataclass_fields__:
                np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
            checked, fast = GnssObservations.from_epoch(a), GnssObservations._trusted_from_epoch(a)
            for name in checked.__dataclass_fields__:
                x, y = getattr(checked, name), getattr(fast, name)
                assert np.asarray(x).dtype == np.asarray(y).dtype, name
                np.testing.assert_array_equal(x, y, err_msg=name)
    pos = rng.normal(0.0, 60.0, (6, 3))
    rel, cov, avail = measure_relative_positions(rng, pos, RelativeSensingConfig(max_range_m=90))
    checked = RelativePositions(rel, cov, avail)
    fast = RelativePositions._trusted(rel, cov, avail)
    for name in ("rel_ecef_m", "cov_ecef_m2", "available"):
        np.testing.assert_array_equal(getattr(checked, name), getattr(fast, name))
    assert not avail.diagonal().any()  # the caller's array is not modified


def test_a_replaced_constellation_bypasses_the_sky_cache() -> None:
    world = S.UrbanWorld(S.ScenarioConfig(n_uavs=3))
    both = world.reset(np.random.default_rng(0))
    world.constellation = default_constellation(("GPS",))
    gps = world.reset(np.random.default_rng(0))
    assert set(gps.system.tolist()) == {0} and gps.sv_index.size < both.sv_index.size


def _tricky_positions(city, rng, n=60):
    """Receivers anywhere, on footprint corners and walls, inside footprints, on the ground."""
    b = city.buildings
    x0, x1, y0, y1 = city.extent_m
    pos = np.c_[rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(0.0, 60.0, n)]
    m = min(4, b.n)
    pos[:m, :2] = b.min_m[:m, :2]
    pos[5 : 5 + m, 0], pos[5 : 5 + m, 1] = b.max_m[:m, 0], b.min_m[:m, 1] + 3.0
    pos[10 : 10 + m, :2] = (b.min_m[:m, :2] + b.max_m[:m, :2]) / 2.0
    pos[15:20, 2] = 0.0
    return pos


@pytest.mark.parametrize("seed", range(5))
def test_compiled_line_of_sight_and_sweeps_equal_the_numpy_ones(seed) -> None:
    """The numba loops (coopnav_env.sim._kernels) give the results of their numpy oracles
    (tests/sim/oracles.py) bit for bit."""
    rng = np.random.default_rng(100 + seed)
    city = canyon_city() if seed == 0 else generate_city(CityConfig(), rng)
    pos = _tricky_positions(city, rng)
    az = rng.uniform(0.0, 360.0, 24)
    el = rng.uniform(-5.0, 90.0, 24)
    el[:3] = (90.0, 0.0, 10.0)  # zenith, horizon, the lowest ray
    az[3:7] = (0.0, 90.0, 180.0, 270.0)  # cardinal directions: zero components
    dirs = np.c_[
        np.cos(np.radians(el)) * np.sin(np.radians(az)),
        np.cos(np.radians(el)) * np.cos(np.radians(az)),
        np.sin(np.radians(el)),
    ]
    dirs = np.where(np.abs(dirs) < 1e-15, 0.0, dirs)
    sweep_az = np.r_[np.arange(8) * 45.0, rng.uniform(0.0, 360.0, 5)]
    fast_los = city.line_of_sight(pos, dirs)
    fast_sky, fast_walls = city.sky_and_walls(pos, sweep_az)
    ref_los = oracles.trace_line_of_sight(city.buildings, pos, C.sky_directions(dirs))
    ref_sky, ref_walls = oracles.sky_and_walls(city.buildings, pos, sweep_az)
    assert ref_los.sum() > 0 and (~ref_los).sum() > 0  # both outcomes occur
    np.testing.assert_array_equal(fast_los, ref_los)
    np.testing.assert_array_equal(fast_sky, ref_sky)
    np.testing.assert_array_equal(fast_walls, ref_walls)
    assert np.array_equal(np.signbit(fast_sky), np.signbit(ref_sky))
    # the separate sweeps of the skyline and the walls
    ref_mask = oracles.mask_elevation_deg(city.buildings, pos, sweep_az)
    assert city.mask_elevation_deg(pos, sweep_az).tobytes() == ref_mask.tobytes()
    ref_dist = oracles.wall_distance_m(city.buildings, pos, sweep_az)
    assert city.wall_distance_m(pos, sweep_az).tobytes() == ref_dist.tobytes()
    # the kernel of the blocked pairs alone, against its oracle
    sky = C.sky_directions(dirs)
    b = city.buildings
    fast_blocked = C._kernels.blocked_sorted(pos, b.min_m, b.max_m, sky.cot_s, sky.h_dir)
    ref_blocked = oracles.blocked_sorted(pos, b.min_m, b.max_m, sky.cot_s, sky.h_dir)
    np.testing.assert_array_equal(fast_blocked, ref_blocked)


@pytest.mark.parametrize("n", [1, 2, 7, 40])
def test_relative_sensing_kernel_equals_numpy_bit_for_bit(n: int) -> None:
    """The compiled relative measurements equal the numpy formulation exactly (same draws)."""
    from coopnav_env.sim import swarm

    cfg = RelativeSensingConfig(max_range_m=150.0, sigma0_m=0.2, sigma_per_m=0.003)
    for seed in range(20):
        rng = np.random.default_rng(seed)
        pos = rng.uniform(-200.0, 200.0, (n, 3)) * rng.choice([1e-3, 1.0, 10.0])
        if n > 2:
            pos[2] = pos[1]  # coincident UAVs: zero range, unavailable
        z = np.random.default_rng(seed).standard_normal((n * (n - 1) // 2, 3))
        fast = swarm._kernels.relative_measurements(pos, z, 0.2, 0.003, 150.0)
        ref = oracles.relative_measurements(pos, z, cfg)
        for name, a, b in zip(("rel", "var", "available"), fast, ref, strict=True):
            assert a.dtype == b.dtype, name
            assert a.tobytes() == b.tobytes(), name
        rel, cov, avail = measure_relative_positions(np.random.default_rng(seed), pos, cfg)
        assert rel.tobytes() == fast[0].tobytes() and np.array_equal(avail, fast[2])
        np.testing.assert_array_equal(cov, fast[1][:, :, None, None] * np.eye(3))


def test_waypoint_advance_kernel_equals_numpy() -> None:
    """Random routes (with a repeated waypoint: a zero-length leg), points on and off them."""
    from coopnav_env.sim import route

    for seed in range(600):
        rng = np.random.default_rng(seed)
        k = int(rng.integers(1, 8))
        pts = np.round(rng.uniform(-100.0, 100.0, (k, 2)) / 10.0) * 10.0
        if k > 2 and seed % 3 == 0:
            pts[2] = pts[1]
        n = int(rng.integers(1, 10))
        if seed % 2:
            xy = np.round(rng.uniform(-120.0, 120.0, (n, 2)))
        else:  # on, near and exactly at the edge of the reach square of waypoints
            xy = pts[rng.integers(0, k, n)] + rng.choice([0.0, 0.5, -3.0, 5.0], (n, 2))
        wp = rng.integers(0, k, n)
        reach = float(rng.choice([0.0, 5.0, 10.0]))
        fast = route.advance_waypoints(pts, xy, wp, reach)
        ref = oracles.advance_waypoints(pts, xy, wp, reach)
        np.testing.assert_array_equal(fast, ref)
        assert fast.dtype == ref.dtype == np.int64


@pytest.mark.parametrize("gate", [None, 3.0])
def test_navigation_selection_kernel_matches_numpy(gate) -> None:
    """Cooperative, else standalone, else dead reckoning, with failed, unlinked and gated fixes."""
    from types import SimpleNamespace

    world = S.UrbanWorld(S.ScenarioConfig(n_uavs=8, max_fix_sigma_m=gate))
    world.reset(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    n = 8
    rejected = 0
    for trial in range(30):

        def fix(rng=rng):
            pos = world.enu_to_ecef(rng.normal(0.0, 50.0, (n, 3)))
            a = rng.normal(0.0, 1.5, (n, 3, 3))
            cov = a @ np.swapaxes(a, 1, 2)
            status = rng.choice([0, 0, 0, 1, 2, 3, 5], n)
            failed = (status == 1) | (status == 2)
            pos[failed] = np.nan
            cov[failed] = np.nan
            return SimpleNamespace(status=status, pos_ecef_m=pos, cov_ecef_m2=cov)

        sa, co = fix(), fix()
        linked = rng.random(n) > 0.2
        pred = rng.normal(0.0, 50.0, (n, 3))
        world.nav_cov_enu_m2 = np.broadcast_to(np.eye(3) * rng.uniform(1, 4), (n, 3, 3)).copy()
        dr_var = float(trial % 2) * 0.25
        fast = S._select_navigation(world, sa, co, linked, pred, dr_var)
        ref = oracles.select_navigation(world, sa, co, linked, pred, dr_var)
        for k, (a, b) in enumerate(zip(fast, ref, strict=True)):
            assert a.shape == b.shape and a.dtype == b.dtype, k
            assert np.array_equal(np.isnan(a), np.isnan(b)) if a.dtype.kind == "f" else True
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-9, err_msg=str(k))
        rejected += int(fast[8].sum() + fast[9].sum())
    assert (rejected > 0) == (gate is not None)  # the gate was exercised


def test_swept_collision_kernel_equals_numpy() -> None:
    """UAVs anywhere, on footprint corners and at roof height, moving or not, radius 0 too."""
    hits = total = 0
    for seed in range(150):
        rng = np.random.default_rng(seed)
        city = generate_city(CityConfig(), rng) if seed % 3 else canyon_city()
        b = city.buildings
        n = int(rng.integers(1, 30))
        x0, x1, y0, y1 = city.extent_m
        p0 = np.c_[rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(0.0, 60.0, n)]
        step = rng.normal(0.0, 8.0, (n, 3)) * rng.choice([0.0, 1.0], (n, 1))
        m = min(3, n, b.n)
        if seed % 5 == 0:
            p0[:m, :2] = b.min_m[:m, :2]
        if seed % 7 == 0:
            p0[:m, 2] = b.max_m[:m, 2]
            step[:m, 2] = 0.0
        p1 = p0 + step
        radius = float(rng.choice([0.0, 1.0, 2.5]))
        fast = S._sim_kernels.swept_collisions_culled(b.min_m, b.max_m, p0, p1, radius)
        ref = oracles.swept_collisions_culled(b, p0, p1, radius)
        np.testing.assert_array_equal(fast, ref)
        hits += int(ref.sum())
        total += n
    assert 0 < hits < total  # both outcomes exercised


def test_separation_kernel_equals_numpy() -> None:
    from coopnav_env.sim import swarm

    for seed in range(200):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(1, 40))
        pos = rng.uniform(-30.0, 30.0, (n, 3))
        if n > 3:
            pos[1] = pos[0] + [3.0, 0.0, 0.0]  # exactly at the limit: not a violation
            pos[3] = pos[2]  # coincident
        sep = float(rng.choice([0.0, 3.0, 8.0]))
        fast = swarm.separation_violations(pos, sep)
        ref = oracles.separation_violations(pos, sep)
        np.testing.assert_array_equal(fast, ref)


def test_world_motion_kernel_equals_numpy(monkeypatch) -> None:
    """Kinematics, fence, collisions and separation of UrbanWorld.step: identical states."""
    cfg = S.ScenarioConfig(n_uavs=12)
    rng = np.random.default_rng(4)
    fast_w, ref_w = S.UrbanWorld(cfg), S.UrbanWorld(cfg)
    fast_w.reset(np.random.default_rng(1))
    ref_w.reset(np.random.default_rng(1))
    g_fast, g_ref = np.random.default_rng(2), np.random.default_rng(2)
    hits = seps = 0
    for step in range(80):
        cmd = rng.uniform(-1.6, 1.6, (12, 3))
        cmd[: step % 4] = 0.0
        a = fast_w.step(cmd, g_fast)
        with monkeypatch.context() as m:
            m.setattr(S, "_world_motion", oracles.world_motion)
            b = ref_w.step(cmd, g_ref)
        for name in ("pos_enu_m", "vel_enu_mps", "collided", "separation_violation"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.tobytes() == y.tobytes(), (step, name)
        hits += int(a.collided.sum())
        seps += int(a.separation_violation.sum())
    assert hits > 0 and seps > 0  # both were exercised


def count_fused_calls(monkeypatch) -> dict[str, int]:
    """Count the calls of ``UrbanWorld._navigate_fused`` (in ``calls["fused"]``)."""
    calls = {"fused": 0}
    fused = S.UrbanWorld._navigate_fused

    def counted(self, *a):
        calls["fused"] += 1
        return fused(self, *a)

    monkeypatch.setattr(S.UrbanWorld, "_navigate_fused", counted)
    return calls


def _world_epochs(kw: dict, steps: int = 40) -> list:
    """A reset and ``steps`` steps of moderately random commands (collisions included)."""
    cfg = S.ScenarioConfig(**kw)
    world = S.UrbanWorld(cfg)
    rng = np.random.default_rng(7)
    cmd_rng = np.random.default_rng(8)
    epochs = [world.reset(rng)]
    for _ in range(steps):
        epochs.append(world.step(cmd_rng.uniform(-0.7, 0.7, (cfg.n_uavs, 3)), rng))
    return epochs


def _assert_epochs_identical(a: list, b: list) -> None:
    from dataclasses import fields

    assert len(a) == len(b)
    for ea, eb in zip(a, b):
        for f in fields(ea):
            x, y = getattr(ea, f.name), getattr(eb, f.name)
            if isinstance(x, np.ndarray):
                assert x.dtype == y.dtype and x.shape == y.shape, f.name
                assert np.array_equal(x, y, equal_nan=True), f.name
                assert x.tobytes() == y.tobytes(), f.name  # signed zeros too
            else:
                assert x == y, f.name


@pytest.mark.parametrize(
    "kw",
    [
        {"n_uavs": 1},
        {"n_uavs": 5, "centroid": "shared"},
        {"n_uavs": 12, "centroid": "self"},
        {"n_uavs": 5, "systems": ("GPS",)},
        {"n_uavs": 4, "error_model": ErrorModel(differential=True, tropo=False)},
        {"n_uavs": 6, "max_fix_sigma_m": None, "transfer": "sdt"},
        {"n_uavs": 5, "max_fix_sigma_m": 2.0},  # the integrity gate rejects fixes
        {"n_uavs": 5, "nlos_probability": 0.4, "max_sats": 8},
        {"n_uavs": 3, "relative_sensing": RelativeSensingConfig(max_range_m=6.0)},  # few links
    ],
)
def test_fused_epoch_navigation_equals_the_modular_path(monkeypatch, kw) -> None:
    """Every field of every epoch, bit for bit: ``UrbanWorld._navigate_fused`` (one compiled
    call) against ``_navigate`` (the same kernels called one by one)."""
    calls = count_fused_calls(monkeypatch)
    fast = _world_epochs(kw)
    assert calls["fused"] == len(fast)
    oracles.navigate_function_by_function(monkeypatch)
    calls["fused"] = 0
    ref = _world_epochs(kw)
    assert calls["fused"] == 0
    _assert_epochs_identical(fast, ref)


def test_paper_covariance_takes_the_modular_path(monkeypatch) -> None:
    """The one-call path serves the exact covariance only; Eq. 18 as printed runs the numpy
    formulation of the cooperative solver."""

    def refuse(self, *a):
        raise AssertionError("the fused path must not run for covariance='paper'")

    monkeypatch.setattr(S.UrbanWorld, "_navigate_fused", refuse)
    epochs = _world_epochs({"n_uavs": 4, "covariance": "paper"}, steps=5)
    assert np.isfinite(epochs[-1].nav_pos_enu_m).all()
