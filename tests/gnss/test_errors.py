"""Tests for coopnav_env.gnss.errors (paper Eq. 1-8)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from coopnav_env.constants import (
    FREQ_BDS_B1I_HZ,
    FREQ_BDS_B3I_HZ,
    FREQ_GAL_E1_HZ,
    FREQ_GAL_E5A_HZ,
    FREQ_GPS_L1_HZ,
    FREQ_GPS_L2_HZ,
    SHANGHAI_ALT_M,
    SHANGHAI_LAT_DEG,
    SHANGHAI_LON_DEG,
)
from coopnav_env.gnss.errors import (
    ErrorModel,
    PseudorangeEpoch,
    draw_clock_biases,
    iono_free_factor,
    sigma_multipath_m,
    sigma_noise_m,
    sigma_tropo_m,
    sigma_ure_m,
    sigma_user_m,
    simulate_pseudoranges,
)
from coopnav_env.gnss.frames import direction_enu, enu_to_ecef, geodetic_to_ecef

ORIGIN = (SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG, SHANGHAI_ALT_M)
SV_RANGE_M = 2.2e7
N_MC = 20_000
Z_TOL = 5.0  # tolerance in standard errors for Monte Carlo checks


def _sats_at(az_deg, el_deg) -> np.ndarray:
    """Satellite ECEF positions at given az/el seen from the Shanghai origin."""
    return enu_to_ecef(direction_enu(az_deg, el_deg) * SV_RANGE_M, *ORIGIN)


def _rx(n_rx: int, spread_m: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray:
    enu = np.zeros((n_rx, 3))
    if spread_m:
        enu = rng.uniform(-spread_m, spread_m, (n_rx, 3))
    return enu_to_ecef(enu, *ORIGIN)


def _assert_std(sample: np.ndarray, sigma: float | np.ndarray, axis: int = 0) -> None:
    """Sample std and mean agree with N(0, sigma^2) to Z_TOL standard errors.

    The standard error of a sample std is sigma / sqrt(2 n), of a sample mean sigma / sqrt(n).
    """
    n = sample.shape[axis]
    sigma = np.asarray(sigma, dtype=float)
    std_err = np.abs(sample.std(axis=axis) - sigma) / (sigma / np.sqrt(2 * n))
    mean_err = np.abs(sample.mean(axis=axis)) / (sigma / np.sqrt(n))
    assert np.all(std_err < Z_TOL), f"sample std off by {std_err} standard errors"
    assert np.all(mean_err < Z_TOL), f"sample mean off by {mean_err} standard errors"


# -------------------------------------------------------------------------------------
# Sigma functions
# -------------------------------------------------------------------------------------


def test_sigma_values_at_zenith_and_5_deg():
    el = np.array([90.0, 5.0])
    sin5 = math.sin(math.radians(5.0))
    np.testing.assert_allclose(sigma_ure_m(el), [1.0, 1.0])
    np.testing.assert_allclose(sigma_ure_m(el, value_m=0.5), [0.5, 0.5])
    np.testing.assert_allclose(
        sigma_tropo_m(el), [0.12, 0.12 * 1.001 / math.sqrt(0.002001 + sin5**2)], rtol=1e-14
    )
    np.testing.assert_allclose(sigma_tropo_m(el), [0.12, 1.2261533299], rtol=1e-9)
    np.testing.assert_allclose(
        sigma_multipath_m(el), [0.13 + 0.53 * math.exp(-9.0), 0.13 + 0.53 * math.exp(-0.5)]
    )
    np.testing.assert_allclose(sigma_multipath_m(el), [0.1300654072, 0.4514612496], rtol=1e-9)
    np.testing.assert_allclose(sigma_noise_m(el), [0.1500009306, 0.3583350347], rtol=1e-9)
    np.testing.assert_allclose(sigma_user_m(el, 1.0), [0.1985378788, 0.5763863782], rtol=1e-9)
    np.testing.assert_allclose(sigma_user_m(el, 2.0), 2.0 * sigma_user_m(el, 1.0))


def test_sigmas_are_elementwise_and_decreasing():
    el = np.linspace(0.0, 90.0, 91).reshape(7, 13)
    for func in (sigma_tropo_m, sigma_multipath_m, sigma_noise_m):
        out = func(el)
        assert out.shape == el.shape
        assert np.all(np.diff(out.ravel()) < 0.0)
    assert np.ndim(sigma_tropo_m(30.0)) == 0


def test_iono_free_factor():
    assert iono_free_factor(FREQ_GPS_L1_HZ, FREQ_GPS_L2_HZ) == pytest.approx(2.978, abs=1e-3)
    assert iono_free_factor(FREQ_GPS_L2_HZ, FREQ_GPS_L1_HZ) == pytest.approx(2.978, abs=1e-3)
    f1, f2 = FREQ_BDS_B1I_HZ, FREQ_BDS_B3I_HZ
    expected = math.sqrt((f1**4 + f2**4) / (f1**2 - f2**2) ** 2)
    assert iono_free_factor(f1, f2) == pytest.approx(expected, rel=1e-12)
    assert iono_free_factor(f1, f2) == pytest.approx(3.527, abs=1e-3)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: sigma_tropo_m(np.nan), "el_deg"),
        (lambda: sigma_multipath_m([10.0, 91.0]), "el_deg"),
        (lambda: sigma_noise_m(-90.5), "el_deg"),
        (lambda: sigma_ure_m(10.0, value_m=-1.0), "value_m"),
        (lambda: sigma_user_m(10.0, -2.0), "factor"),
        (lambda: iono_free_factor(FREQ_GPS_L1_HZ, FREQ_GPS_L1_HZ), "differ"),
        (lambda: iono_free_factor(-1.0, FREQ_GPS_L1_HZ), "f1_hz"),
        (lambda: iono_free_factor(0.0, FREQ_GPS_L1_HZ), "> 0"),
    ],
)
def test_sigma_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# -------------------------------------------------------------------------------------
# ErrorModel
# -------------------------------------------------------------------------------------


def test_error_model_defaults_and_factors():
    model = ErrorModel()
    assert model.sigma_ure_m == 1.0
    assert model.iono_free and model.tropo and not model.differential
    np.testing.assert_allclose(model.iono_factor([0, 1, 0]), [2.97826, 3.52749, 2.97826], atol=1e-5)
    np.testing.assert_allclose(ErrorModel(iono_free=False).iono_factor([0, 1]), [1.0, 1.0])
    paper = ErrorModel.paper()
    np.testing.assert_allclose(paper.iono_factor([0, 1]), 2.97826, atol=1e-5)
    assert ErrorModel.paper(differential=True).differential
    assert ErrorModel(frequency_pairs_hz=[[1.5e9, 1.2e9], [1.5e9, 1.1e9]]).frequency_pairs_hz == (
        (1.5e9, 1.2e9),
        (1.5e9, 1.1e9),
    )


def test_error_model_sigmas():
    el = np.array([[90.0, 5.0, 45.0], [60.0, 30.0, 10.0]])
    system = np.array([0, 1, 0])
    model = ErrorModel()
    expected_common = np.sqrt(1.0 + sigma_tropo_m(el) ** 2)  # Eq. 4 + Eq. 5
    np.testing.assert_allclose(model.sigma_common_m(el), expected_common)
    np.testing.assert_allclose(ErrorModel(tropo=False, sigma_ure_m=0.7).sigma_common_m(el), 0.7)
    np.testing.assert_array_equal(ErrorModel(differential=True).sigma_common_m(el), 0.0)
    factor = np.array([2.9782552, 3.5274865, 2.9782552])
    np.testing.assert_allclose(
        model.sigma_user_m(el, system), factor * sigma_user_m(el, 1.0), rtol=1e-7
    )
    np.testing.assert_allclose(
        ErrorModel(iono_free=False).sigma_user_m(el, system), sigma_user_m(el, 1.0)
    )
    with pytest.raises(ValueError, match="el_deg"):
        model.sigma_user_m(el, np.array([0, 1]))
    # index 2 is Galileo (skies from navigation files): E1/E5a unless a third pair is given
    gal = iono_free_factor(FREQ_GAL_E1_HZ, FREQ_GAL_E5A_HZ)
    assert model.iono_factor([2])[0] == gal
    assert ErrorModel.paper().iono_factor([2])[0] == gal
    third = ErrorModel(frequency_pairs_hz=(*model.frequency_pairs_hz, (1575.42e6, 1207.14e6)))
    assert third.iono_factor([2])[0] == iono_free_factor(1575.42e6, 1207.14e6)
    with pytest.raises(ValueError, match="system"):
        model.iono_factor([0, 3])


def test_error_model_is_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        ErrorModel().sigma_ure_m = 2.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"sigma_ure_m": -0.1}, "sigma_ure_m"),
        ({"sigma_ure_m": float("nan")}, "sigma_ure_m"),
        ({"sigma_ure_m": "1"}, "sigma_ure_m"),
        ({"iono_free": 1}, "iono_free"),
        ({"differential": "yes"}, "differential"),
        ({"tropo": None}, "tropo"),
        ({"frequency_pairs_hz": ((FREQ_GPS_L1_HZ, FREQ_GPS_L2_HZ),)}, "frequency_pairs_hz"),
        ({"frequency_pairs_hz": ((1e9, 1e9), (1e9, 2e9))}, "frequency_pairs_hz"),
        ({"frequency_pairs_hz": ((-1e9, 1e9), (1e9, 2e9))}, "frequency_pairs_hz"),
        ({"frequency_pairs_hz": (1e9, 2e9)}, "frequency_pairs_hz"),
    ],
)
def test_error_model_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ErrorModel(**kwargs)


# -------------------------------------------------------------------------------------
# simulate_pseudoranges
# -------------------------------------------------------------------------------------


def _simple_setup():
    sv = _sats_at(np.array([0.0, 90.0, 200.0, 300.0]), np.array([80.0, 35.0, 12.0, 50.0]))
    system = np.array([0, 1, 0, 1])
    rx = _rx(3, spread_m=20.0, rng=np.random.default_rng(3))
    visible = np.array([[1, 1, 1, 1], [1, 0, 1, 1], [0, 0, 0, 1]], dtype=bool)
    return rx, sv, system, visible


def test_simulate_structure_and_composition():
    rx, sv, system, visible = _simple_setup()
    clock = np.array([[100.0, -50.0], [3e4, 2e4], [0.0, 1.0]])
    extra = np.zeros((3, 4))
    extra[0, 2] = 35.0
    args = (rx, sv, system, visible, ErrorModel())
    copies = [np.copy(a) for a in args[:4]] + [clock.copy(), extra.copy()]
    ep = simulate_pseudoranges(
        np.random.default_rng(1), *args, clock_bias_m=clock, extra_bias_m=extra
    )
    for before, after in zip(copies, [*args[:4], clock, extra]):
        np.testing.assert_array_equal(before, after)  # inputs untouched
    assert isinstance(ep, PseudorangeEpoch)
    assert (ep.n_rx, ep.n_sv) == (3, 4)
    assert ep.pr_m.shape == ep.el_deg.shape == ep.az_deg.shape == ep.sigma_user_m.shape == (3, 4)
    assert ep.sigma_common_m.shape == ep.common_error_m.shape == (4,)
    assert ep.clock_bias_m.shape == (3, 2)
    np.testing.assert_array_equal(np.isnan(ep.pr_m), ~visible)
    np.testing.assert_allclose(ep.el_deg, [[80.0, 35.0, 12.0, 50.0]] * 3, atol=1e-3)
    np.testing.assert_allclose(ep.range_m, np.linalg.norm(sv[None] - rx[:, None], axis=-1))
    model = (
        ep.range_m + clock[:, system] + ep.common_error_m[None, :] + ep.user_error_m + extra
    )  # Eq. 1 after the iono-free combination
    np.testing.assert_allclose(ep.pr_m[visible], model[visible], rtol=0, atol=1e-6)
    np.testing.assert_allclose(
        ep.sigma_common_m, ErrorModel().sigma_common_m(ep.el_deg.mean(axis=0))
    )
    np.testing.assert_allclose(ep.sigma_user_m, ErrorModel().sigma_user_m(ep.el_deg, system))
    with pytest.raises(ValueError):
        ep.pr_m[0, 0] = 0.0  # read-only
    with pytest.raises(dataclasses.FrozenInstanceError):
        ep.pr_m = ep.range_m  # type: ignore[misc]


def test_simulate_defaults_zero_clock_and_el_ref():
    rx, sv, system, visible = _simple_setup()
    el_ref = np.array([5.0, 5.0, 90.0, 90.0])
    ep = simulate_pseudoranges(
        np.random.default_rng(2), rx, sv, system, visible, ErrorModel(), el_ref_deg=el_ref
    )
    np.testing.assert_array_equal(ep.clock_bias_m, 0.0)
    np.testing.assert_allclose(ep.sigma_common_m, ErrorModel().sigma_common_m(el_ref))
    resid = ep.pr_m - ep.range_m - ep.common_error_m - ep.user_error_m
    np.testing.assert_allclose(resid[visible], 0.0, atol=1e-6)


def test_simulate_is_deterministic_and_draw_order_fixed():
    rx, sv, system, visible = _simple_setup()
    model = ErrorModel()
    ep1 = simulate_pseudoranges(np.random.default_rng(7), rx, sv, system, visible, model)
    ep2 = simulate_pseudoranges(np.random.default_rng(7), rx, sv, system, visible, model)
    np.testing.assert_array_equal(ep1.pr_m, ep2.pr_m)
    # Visibility does not change the draws.
    ep3 = simulate_pseudoranges(
        np.random.default_rng(7), rx, sv, system, np.ones_like(visible), model
    )
    np.testing.assert_array_equal(ep3.user_error_m, ep1.user_error_m)
    np.testing.assert_array_equal(ep3.common_error_m, ep1.common_error_m)
    # Fixed order: n_sv common normals first, then (n_rx, n_sv) user normals.
    gen = np.random.default_rng(7)
    z_common = gen.standard_normal(4)
    z_user = gen.standard_normal((3, 4))
    np.testing.assert_allclose(ep1.common_error_m, ep1.sigma_common_m * z_common)
    np.testing.assert_allclose(ep1.user_error_m, ep1.sigma_user_m * z_user)
    # Differential consumes the same draws: user errors unchanged.
    ep4 = simulate_pseudoranges(
        np.random.default_rng(7), rx, sv, system, visible, ErrorModel(differential=True)
    )
    np.testing.assert_array_equal(ep4.user_error_m, ep1.user_error_m)
    ep5 = simulate_pseudoranges(np.random.default_rng(8), rx, sv, system, visible, model)
    assert not np.allclose(ep5.user_error_m, ep1.user_error_m)


def test_differential_removes_common_error():
    rx, sv, system, visible = _simple_setup()
    ep = simulate_pseudoranges(
        np.random.default_rng(4), rx, sv, system, visible, ErrorModel(differential=True)
    )
    np.testing.assert_array_equal(ep.common_error_m, 0.0)
    np.testing.assert_array_equal(ep.sigma_common_m, 0.0)
    np.testing.assert_allclose((ep.pr_m - ep.range_m)[visible], ep.user_error_m[visible], atol=1e-6)


def test_monte_carlo_user_error():
    # Many co-located receivers: each column is N_MC independent user-error draws.
    el_deg = np.array([5.0, 15.0, 40.0, 85.0])
    sv = _sats_at(np.array([10.0, 100.0, 190.0, 280.0]), el_deg)
    system = np.array([0, 1, 0, 1])
    rx = _rx(N_MC)
    model = ErrorModel()
    ep = simulate_pseudoranges(
        np.random.default_rng(11), rx, sv, system, np.ones((N_MC, 4), bool), model
    )
    sigma = model.iono_factor(system) * sigma_user_m(el_deg, 1.0)  # Eq. 8
    np.testing.assert_allclose(ep.sigma_user_m[0], sigma, rtol=1e-6)
    _assert_std(ep.user_error_m, sigma)
    # The common error is shared: pr - range - common is the user error for every receiver.
    _assert_std(ep.pr_m - ep.range_m - ep.common_error_m, sigma)


def test_monte_carlo_common_and_total_error():
    # One receiver, N_MC satellites all at 30 deg elevation: Eq. 3 total variance.
    az = np.linspace(0.0, 360.0, N_MC, endpoint=False)
    sv = _sats_at(az, 30.0)
    system = np.zeros(N_MC, dtype=int)
    model = ErrorModel()
    ep = simulate_pseudoranges(
        np.random.default_rng(12), _rx(1), sv, system, np.ones((1, N_MC), bool), model
    )
    sigma_common = math.sqrt(1.0 + sigma_tropo_m(30.0) ** 2)
    sigma_user = iono_free_factor(FREQ_GPS_L1_HZ, FREQ_GPS_L2_HZ) * sigma_user_m(30.0, 1.0)
    np.testing.assert_allclose(ep.sigma_common_m, sigma_common, rtol=1e-6)
    _assert_std(ep.common_error_m, sigma_common)
    _assert_std((ep.pr_m - ep.range_m)[0], math.hypot(sigma_common, sigma_user))


def test_monte_carlo_cross_receiver_covariance():
    # Eq. 18: same satellite, different receivers -> covariance sigma_URE^2 + sigma_tropo^2.
    az = np.linspace(0.0, 360.0, N_MC, endpoint=False)
    sv = _sats_at(az, 60.0)
    ep = simulate_pseudoranges(
        np.random.default_rng(13),
        _rx(2),
        sv,
        np.ones(N_MC, int),
        np.ones((2, N_MC), bool),
        ErrorModel(),
    )
    resid = ep.pr_m - ep.range_m
    var_c = 1.0 + float(sigma_tropo_m(60.0)) ** 2
    var_u = float(ep.sigma_user_m[0, 0]) ** 2
    cov = np.mean(resid[0] * resid[1])
    se = math.sqrt(((var_c + var_u) ** 2 + var_c**2) / N_MC)
    assert abs(cov - var_c) < Z_TOL * se


def test_draw_clock_biases():
    clk = draw_clock_biases(np.random.default_rng(0), 5, 2)
    assert clk.shape == (5, 2)
    np.testing.assert_array_equal(clk, draw_clock_biases(np.random.default_rng(0), 5, 2))
    big = draw_clock_biases(np.random.default_rng(1), N_MC, 1, sigma_m=10.0)
    _assert_std(big[:, 0], 10.0)
    np.testing.assert_array_equal(
        draw_clock_biases(np.random.default_rng(1), 3, 2, sigma_m=0.0), 0.0
    )
    with pytest.raises(ValueError, match="sigma_m"):
        draw_clock_biases(np.random.default_rng(0), 2, 2, sigma_m=-1.0)
    with pytest.raises(ValueError, match="n_sys"):
        draw_clock_biases(np.random.default_rng(0), 2, 0)
    with pytest.raises(ValueError, match="rng"):
        draw_clock_biases(0, 2, 2)  # type: ignore[arg-type]


def _bad_call(**override):
    rx, sv, system, visible = _simple_setup()
    kwargs = dict(
        rng=np.random.default_rng(0),
        rx_ecef_m=rx,
        sv_ecef_m=sv,
        system=system,
        visible=visible,
        model=ErrorModel(),
    )
    kwargs.update(override)
    return lambda: simulate_pseudoranges(**kwargs)


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"rng": 42}, "rng"),
        ({"model": "paper"}, "model"),
        ({"rx_ecef_m": np.zeros((3, 2))}, "rx_ecef_m"),
        ({"rx_ecef_m": np.zeros((0, 3))}, "rx_ecef_m"),
        ({"sv_ecef_m": np.full((4, 3), np.nan)}, "sv_ecef_m"),
        ({"system": np.array([0, 1, 0, 3])}, "system"),
        ({"system": np.array([0, 1, 0])}, "system"),
        ({"visible": np.ones((3, 3), bool)}, "visible"),
        ({"visible": np.full((3, 4), 0.5)}, "visible"),
        ({"clock_bias_m": np.zeros((3, 1))}, "clock_bias_m"),
        ({"clock_bias_m": np.full((3, 2), np.nan)}, "clock_bias_m"),
        ({"el_ref_deg": np.zeros(3)}, "el_ref_deg"),
        ({"el_ref_deg": np.full(4, 120.0)}, "el_ref_deg"),
        ({"extra_bias_m": np.zeros((3, 3))}, "extra_bias_m"),
    ],
)
def test_simulate_bad_inputs(override, match):
    with pytest.raises(ValueError, match=match):
        _bad_call(**override)()


def test_geodetic_helper_sanity():
    # The test helpers put the receivers at the Shanghai origin.
    np.testing.assert_allclose(_rx(1)[0], geodetic_to_ecef(*ORIGIN), atol=1e-6)
