"""Misuse of ``urban_canyon_v0`` is a clear ``ValueError`` at the call that misuses it
(issue 15): settings that would divide by zero at reset or step fail at construction; string,
complex and boolean-seed inputs are refused instead of being cast silently."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import BatchedUrbanCanyonEnv


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (
            {"formation_spacing_m": 0.0, "kinematics": {"min_separation_m": 0.0}},
            r"formation_spacing_m must be > 0, got 0\.0",
        ),
        (
            {"kinematics": {"max_speed_mps": 1e-300, "dt_s": 1e-300}},
            r"max_speed_mps \* dt_s .* must be >= 1e-06 m",
        ),
        ({"kinematics": {"max_speed_mps": 1e-320}}, r"max_speed_mps \* dt_s"),
    ],
)
def test_settings_that_would_divide_by_zero_fail_at_construction(kw, match):
    with pytest.raises(ValueError, match=match):
        urban_canyon_v0.parallel_env(n_uavs=2, **kw)


def test_the_smallest_step_still_works():
    env = urban_canyon_v0.parallel_env(n_uavs=2, kinematics={"max_speed_mps": 1e-3, "dt_s": 1e-3})
    env.reset(seed=0)
    _, rewards, *_ = env.step({a: np.zeros(3, np.float32) for a in env.agents})
    assert all(np.isfinite(r) for r in rewards.values())


@pytest.mark.parametrize(
    "action",
    [
        "abc",
        np.array(["0.1", "0.2", "0.3"]),  # numpy would cast these strings to floats
        ["0.1", "0.2", "0.3"],
        np.array([0.1 + 1j, 0.0, 0.0]),  # numpy would drop the imaginary part (a warning)
    ],
    ids=["str", "str-array", "str-list", "complex"],
)
def test_string_and_complex_actions_are_refused(action):
    env = urban_canyon_v0.parallel_env(n_uavs=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="every action must be a real numeric array"):
        env.step({a: action for a in env.agents})
    batched = BatchedUrbanCanyonEnv(2, n_uavs=2)
    batched.reset(seed=0)
    bad = np.broadcast_to(np.asarray(action), (2, 2, 3)) if np.ndim(action) else action
    with pytest.raises(ValueError, match="actions must be a real numeric array"):
        batched.step(bad)


def test_numeric_actions_of_any_real_dtype_are_the_same():
    a = urban_canyon_v0.parallel_env(n_uavs=2)
    b = urban_canyon_v0.parallel_env(n_uavs=2)
    a.reset(seed=3)
    b.reset(seed=3)
    ra = a.step({ag: np.array([1, 0, 0]) for ag in a.agents})[1]  # int
    rb = b.step({ag: np.array([1.0, 0.0, 0.0], np.float32) for ag in b.agents})[1]
    assert ra == rb


@pytest.mark.parametrize("seed", [True, False, 1.5, -1, "3", [1, 2]])
def test_bad_reset_seeds_are_refused(seed):
    env = urban_canyon_v0.parallel_env(n_uavs=2)
    with pytest.raises(ValueError, match="seed must be None or an integer >= 0"):
        env.reset(seed=seed)


@pytest.mark.parametrize("seed", [True, 1.5, "3", [True, 1], [0, -1]])
def test_bad_batched_seeds_are_refused(seed):
    env = BatchedUrbanCanyonEnv(2, n_uavs=2)
    with pytest.raises(ValueError, match="seed must be"):
        env.reset(seed=seed)


def test_numpy_integer_seeds_are_accepted():
    a = urban_canyon_v0.parallel_env(n_uavs=2)
    b = urban_canyon_v0.parallel_env(n_uavs=2)
    oa, _ = a.reset(seed=np.int64(7))
    ob, _ = b.reset(seed=7)
    for k in oa:
        np.testing.assert_array_equal(oa[k], ob[k])


@pytest.mark.parametrize("options", [5, "noise_stream", ["noise_stream"], 1.5])
def test_reset_options_that_are_not_a_mapping_are_refused(options):
    """``reset(options=...)`` takes a mapping (issue 35, finding 10): anything else is a
    ValueError naming ``options`` and the key it may hold, not a raw TypeError."""
    env = urban_canyon_v0.parallel_env(n_uavs=2)
    with pytest.raises(ValueError, match=r"reset options must be a dict.*'noise_stream'.*got"):
        env.reset(seed=0, options=options)
    env.reset(seed=0, options={})  # empty and None stay fine
    env.reset(seed=0, options=None)


def test_batched_step_refuses_a_transposed_action_array():
    """A ``(N, K, 3)`` array has the K * N * 3 entries of ``(K, N, 3)`` but drives the wrong
    UAVs when reshaped (issue 35, finding 11): only ``(K, N, 3)`` and ``(K * N, 3)`` pass."""
    batched = BatchedUrbanCanyonEnv(2, n_uavs=3)
    batched.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 3, 3\) or \(6, 3\), got \(3, 2, 3\)"):
        batched.step(np.zeros((3, 2, 3)))
    with pytest.raises(ValueError, match=r"got \(18,\)"):
        batched.step(np.zeros(18))
    with pytest.raises(ValueError, match=r"got \(2, 9\)"):
        batched.step(np.zeros((2, 9)))
    batched.step(np.zeros((2, 3, 3)))
    batched.step(np.zeros((6, 3)))  # the documented flat form (copy-major)


def test_integrity_off_is_said_to_test_no_residuals():
    """Issue 35, finding 12: with no integrity monitor a 1 km outlier gives a fix of status
    OK with an error of hundreds of metres, because nothing tests the residuals; FDE removes
    it. Where a user reads the status and the setting, the documentation says so."""
    from coopnav_env.nav import IntegrityStatus, NavStatus, fde_standalone, solve_standalone
    from coopnav_env.sim.scenario import ScenarioConfig
    from tests.nav.test_integrity import paper_swarm, with_bias

    sc = paper_swarm(0.0)
    obs = sc.observations(np.random.default_rng(0))
    q = 1  # an open-sky UAV: 15 satellites, plenty of redundancy
    bad = with_bias(obs, q, int(np.flatnonzero(sc.visible[q])[0]), 1000.0)
    sol = solve_standalone(bad)
    err_m = np.linalg.norm(sol.pos_ecef_m[q] - sc.pos_ecef[q])
    assert sol.status[q] == NavStatus.OK and err_m > 100.0  # OK, and far off
    fixed, checked = fde_standalone(bad, enu_rotation=sc.rot)
    assert checked.status[q] == IntegrityStatus.EXCLUDED
    assert np.linalg.norm(fixed.pos_ecef_m[q] - sc.pos_ecef[q]) < 10.0

    import coopnav_env.urban_canyon_v0 as page

    def text(doc):
        return " ".join((doc or "").split())

    assert "with `integrity` off no residual test runs" in text(page.__doc__)
    assert "unless an integrity monitor tested" in text(NavStatus.__doc__)
    assert '``"off"`` (default) runs no residual test' in text(ScenarioConfig.__doc__)
    # and a program can tell: the integrity figures are in the infos only when it ran
    env = urban_canyon_v0.parallel_env(n_uavs=2)
    _, infos = env.reset(seed=0)
    assert "integrity_status" not in infos["uav_0"]
