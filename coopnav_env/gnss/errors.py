"""GNSS pseudorange error models (paper Eq. 1-8) and pseudorange simulation.

The measurement model is paper Eq. 1 after the ionosphere-free combination,

    pr[r, k] = d[r, k] + b[r, sys(k)] + e_common[k] + e_user[r, k] + e_extra[r, k],

with ``d`` the geometric range (Eq. 2), ``b`` the receiver clock bias of receiver
``r`` for the constellation of satellite ``k`` (in metres, ``c * dt_r``), and the
zero-mean Gaussian errors of Eq. 3:

* ``e_common`` - satellite clock/ephemeris (``sigma_URE``, Eq. 4) plus residual
  troposphere (``sigma_tropo``, Eq. 5). The UAVs of a swarm are close together,
  so these are drawn once per satellite and shared by every receiver.
* ``e_user`` - multipath (Eq. 6) and receiver noise (Eq. 7), scaled by the
  ionosphere-free noise amplification factor (Eq. 8); independent per receiver
  and satellite.
* ``e_extra`` - optional caller-supplied bias (e.g. NLOS reflection delay) that
  the navigation filter does not model.

The ionospheric delay itself is not simulated: the paper assumes the dual-
frequency iono-free combination removes it and only keeps its noise
amplification (Eq. 8). Satellite clock offsets are part of ``e_common``.
Elevations are in degrees throughout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.constants import (
    FILE_SYSTEMS,
    FREQ_BDS_B1I_HZ,
    FREQ_BDS_B3I_HZ,
    FREQ_GAL_E1_HZ,
    FREQ_GAL_E5A_HZ,
    FREQ_GPS_L1_HZ,
    FREQ_GPS_L2_HZ,
    SYSTEMS,
    WGS84_A_M,
    WGS84_B_M,
    WGS84_E2,
    WGS84_F,
)
from coopnav_env.gnss import _kernels
from coopnav_env.gnss._validate import (
    as_bool_matrix,
    as_count,
    as_elevation_deg,
    as_float_array,
    as_index_array,
    as_nonnegative_scalar,
    as_point_list,
    readonly,
)
from coopnav_env.gnss.frames import _EP2, _N_BOWRING_ITER

__all__ = [
    "ErrorModel",
    "PseudorangeEpoch",
    "draw_clock_biases",
    "iono_free_factor",
    "sigma_multipath_m",
    "sigma_noise_m",
    "sigma_tropo_m",
    "sigma_ure_m",
    "sigma_user_m",
    "simulate_pseudoranges",
]

DEFAULT_CLOCK_SIGMA_M: float = 3.0e4
"""Default standard deviation of a receiver clock bias [m] (about 100 us)."""


# --------------------------------------------------------------------------------------------
# Elevation-dependent sigmas (paper Eq. 4-8)
# --------------------------------------------------------------------------------------------


def sigma_ure_m(el_deg: ArrayLike, value_m: float = 1.0) -> NDArray[np.float64]:
    """Clock and ephemeris (user range error) standard deviation, paper Eq. 4.

    Parameters
    ----------
    el_deg : array_like, shape (...)
        Elevation [deg], in ``[-90, 90]`` (only the shape is used).
    value_m : float, optional
        ``sigma_URE`` [m], >= 0; the paper uses 1 m.

    Returns
    -------
    ndarray, shape (...)
        ``value_m`` everywhere [m].
    """
    el = as_elevation_deg(el_deg, "el_deg")
    value = as_nonnegative_scalar(value_m, "value_m")
    return np.full(el.shape, value)


def sigma_tropo_m(el_deg: ArrayLike) -> NDArray[np.float64]:
    """Residual tropospheric delay standard deviation, paper Eq. 5.

    ``sigma_tropo = 0.12 * 1.001 / sqrt(0.002001 + sin^2(pi el / 180))``.

    Parameters
    ----------
    el_deg : array_like, shape (...)
        Elevation [deg], in ``[-90, 90]``.

    Returns
    -------
    ndarray, shape (...)
        Standard deviation [m]: 0.12 m at zenith, about 1.1 m at 5 deg.
    """
    return _sigma_tropo(as_elevation_deg(el_deg, "el_deg"))


def _sigma_tropo(el: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.12 * 1.001 / np.sqrt(0.002001 + np.sin(np.pi * el / 180.0) ** 2)


def sigma_multipath_m(el_deg: ArrayLike) -> NDArray[np.float64]:
    """Multipath standard deviation, paper Eq. 6: ``0.13 + 0.53 exp(-el / 10)``.

    Parameters
    ----------
    el_deg : array_like, shape (...)
        Elevation [deg], in ``[-90, 90]``.

    Returns
    -------
    ndarray, shape (...)
        Standard deviation [m].
    """
    return _sigma_multipath(as_elevation_deg(el_deg, "el_deg"))


def _sigma_multipath(el: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.13 + 0.53 * np.exp(-el / 10.0)


def sigma_noise_m(el_deg: ArrayLike) -> NDArray[np.float64]:
    """Receiver thermal-noise standard deviation, paper Eq. 7: ``0.15 + 0.43 exp(-el / 6.9)``.

    Parameters
    ----------
    el_deg : array_like, shape (...)
        Elevation [deg], in ``[-90, 90]``.

    Returns
    -------
    ndarray, shape (...)
        Standard deviation [m].
    """
    return _sigma_noise(as_elevation_deg(el_deg, "el_deg"))


def _sigma_noise(el: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.15 + 0.43 * np.exp(-el / 6.9)


def iono_free_factor(f1_hz: float, f2_hz: float) -> float:
    """Noise amplification of the ionosphere-free combination, paper Eq. 8.

    ``sqrt((f1^4 + f2^4) / (f1^2 - f2^2)^2)``; about 2.98 for GPS L1/L2 and
    about 3.53 for BDS B1I/B3I.

    Parameters
    ----------
    f1_hz, f2_hz : float
        Carrier frequencies [Hz], positive and different.

    Returns
    -------
    float
        Factor [-] multiplying the single-frequency user error sigma.
    """
    f1 = as_nonnegative_scalar(f1_hz, "f1_hz")
    f2 = as_nonnegative_scalar(f2_hz, "f2_hz")
    if f1 <= 0.0 or f2 <= 0.0:
        raise ValueError(f"frequencies must be > 0 Hz, got f1_hz={f1_hz!r}, f2_hz={f2_hz!r}")
    if f1 == f2:
        raise ValueError(f"f1_hz and f2_hz must differ, both are {f1_hz!r}")
    # Work in GHz to keep the fourth powers well scaled.
    g1, g2 = f1 * 1e-9, f2 * 1e-9
    return float(np.sqrt((g1**4 + g2**4) / (g1**2 - g2**2) ** 2))


def sigma_user_m(el_deg: ArrayLike, factor: ArrayLike) -> NDArray[np.float64]:
    """Receiver-related error standard deviation, paper Eq. 8.

    ``sigma_user = factor * sqrt(sigma_MP^2 + sigma_noise^2)``.

    Parameters
    ----------
    el_deg : array_like, shape (...)
        Elevation [deg], in ``[-90, 90]``.
    factor : float or array_like broadcastable to (...)
        Iono-free amplification (``iono_free_factor``), or 1 for single frequency; >= 0.

    Returns
    -------
    ndarray, shape (...)
        Standard deviation [m].
    """
    fac = as_float_array(factor, "factor")
    if np.any(fac < 0.0):
        raise ValueError(f"factor must be >= 0, got {fac}")
    return _sigma_user(as_elevation_deg(el_deg, "el_deg"), fac)


def _sigma_user(el: NDArray[np.float64], factor: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`sigma_user_m` of validated elevations and factors."""
    return factor * np.hypot(_sigma_multipath(el), _sigma_noise(el))


# --------------------------------------------------------------------------------------------
# Error model configuration
# --------------------------------------------------------------------------------------------

_DEFAULT_PAIRS: tuple[tuple[float, float], ...] = (
    (FREQ_GPS_L1_HZ, FREQ_GPS_L2_HZ),
    (FREQ_BDS_B1I_HZ, FREQ_BDS_B3I_HZ),
)
_GALILEO_PAIR: tuple[float, float] = (FREQ_GAL_E1_HZ, FREQ_GAL_E5A_HZ)


@dataclass(frozen=True)
class ErrorModel:
    """Configuration of the pseudorange error budget (paper Eq. 3-8).

    Parameters
    ----------
    sigma_ure_m : float, optional
        Satellite clock/ephemeris error sigma [m], >= 0 (paper Eq. 4: 1 m).
    iono_free : bool, optional
        If true, the user error is amplified by the iono-free factor of the
        system's frequency pair (Eq. 8). If false the factor is 1 (single-
        frequency user error); the ionospheric delay is then NOT simulated either
        - the model still assumes it removed, as the paper does.
    frequency_pairs_hz : tuple of (float, float), optional
        One (f1, f2) pair [Hz] per system index of ``SYSTEMS``; default GPS
        L1/L2 and BDS B1I/B3I. A third pair is Galileo's (``FILE_SYSTEMS``); without
        it, Galileo satellites (skies from navigation files) use E1/E5a.
    differential : bool, optional
        Differential corrections remove the common (clock/ephemeris and
        troposphere) errors and their variances: ``sigma_common_m`` is 0.
    tropo : bool, optional
        Include the residual troposphere term (Eq. 5) in the common error.
    """

    sigma_ure_m: float = 1.0
    iono_free: bool = True
    frequency_pairs_hz: tuple[tuple[float, float], ...] = _DEFAULT_PAIRS
    differential: bool = False
    tropo: bool = True

    def __post_init__(self) -> None:
        ure = self.sigma_ure_m
        if isinstance(ure, bool) or not isinstance(ure, (int, float, np.floating, np.integer)):
            raise ValueError(f"sigma_ure_m must be a finite float >= 0, got {ure!r}")
        if not np.isfinite(ure) or ure < 0.0:
            raise ValueError(f"sigma_ure_m must be a finite float >= 0, got {ure!r}")
        object.__setattr__(self, "sigma_ure_m", float(ure))
        for name in ("iono_free", "differential", "tropo"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"{name} must be a bool (True/False), got {value!r}")
            object.__setattr__(self, name, bool(value))
        pairs = self.frequency_pairs_hz
        try:
            pairs = tuple((float(f1), float(f2)) for f1, f2 in pairs)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"frequency_pairs_hz must be a tuple of (f1_hz, f2_hz) pairs, got {pairs!r}"
            ) from exc
        if len(pairs) not in (len(SYSTEMS), len(FILE_SYSTEMS)):
            raise ValueError(
                f"frequency_pairs_hz must hold {len(SYSTEMS)} pairs, one per system {SYSTEMS} "
                f"(or {len(FILE_SYSTEMS)} with Galileo's), got {len(pairs)}"
            )
        for f1, f2 in pairs:
            if not (np.isfinite(f1) and np.isfinite(f2) and f1 > 0.0 and f2 > 0.0 and f1 != f2):
                raise ValueError(
                    "frequency_pairs_hz entries must be finite, > 0 Hz and distinct within a "
                    f"pair, got ({f1!r}, {f2!r})"
                )
        object.__setattr__(self, "frequency_pairs_hz", pairs)

    @classmethod
    def paper(cls, differential: bool = False) -> ErrorModel:
        """The paper's configuration: sigma_URE = 1 m, troposphere on, iono-free on.

        Eq. 8 names ``f_L1`` and ``f_L2`` only, so the GPS L1/L2 pair (factor
        about 2.98) is used for BOTH systems, BDS included.
        """
        pair = (FREQ_GPS_L1_HZ, FREQ_GPS_L2_HZ)
        return cls(frequency_pairs_hz=(pair,) * len(SYSTEMS), differential=differential)

    def iono_factor(self, system: ArrayLike) -> NDArray[np.float64]:
        """User-error amplification factor per satellite (Eq. 8, or 1 if not ``iono_free``).

        Parameters
        ----------
        system : array_like of int, shape (n_sv,)
            System index of each satellite into ``FILE_SYSTEMS``.

        Returns
        -------
        ndarray, shape (n_sv,)
            Factor [-].
        """
        sys_idx = as_index_array(system, "system", len(FILE_SYSTEMS))
        if not self.iono_free:
            return np.ones(sys_idx.shape)
        pairs = self.frequency_pairs_hz
        if len(pairs) == len(SYSTEMS):
            pairs = (*pairs, _GALILEO_PAIR)
        factors = np.array([iono_free_factor(f1, f2) for f1, f2 in pairs])
        return factors[sys_idx]

    def sigma_common_m(self, el_deg: ArrayLike) -> NDArray[np.float64]:
        """Standard deviation of the error shared by all receivers (Eq. 4-5).

        Parameters
        ----------
        el_deg : array_like, shape (..., n_sv)
            Elevation [deg].

        Returns
        -------
        ndarray, same shape as ``el_deg``
            ``sqrt(sigma_URE^2 + sigma_tropo^2)`` [m], without the troposphere if
            ``tropo`` is false, and 0 if ``differential``.
        """
        return self._sigma_common(as_elevation_deg(el_deg, "el_deg"))

    def _sigma_common(self, el: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`sigma_common_m` of validated elevations."""
        if self.differential:
            return np.zeros(el.shape)
        tropo = _sigma_tropo(el) if self.tropo else np.zeros(el.shape)
        return np.hypot(np.full(el.shape, self.sigma_ure_m), tropo)

    def sigma_user_m(self, el_deg: ArrayLike, system: ArrayLike) -> NDArray[np.float64]:
        """Standard deviation of the receiver-related error (Eq. 6-8).

        Parameters
        ----------
        el_deg : array_like, shape (n_rx, n_sv) (any shape (..., n_sv))
            Elevation [deg].
        system : array_like of int, shape (n_sv,)
            System index of each satellite.

        Returns
        -------
        ndarray, shape (n_rx, n_sv)
            ``factor[system] * sqrt(sigma_MP^2 + sigma_noise^2)`` [m].
        """
        el = as_elevation_deg(el_deg, "el_deg")
        factor = self.iono_factor(system)
        if el.ndim < 1 or el.shape[-1] != factor.shape[0]:
            raise ValueError(
                f"el_deg must have shape (..., {factor.shape[0]}) to match system, "
                f"got shape {el.shape}"
            )
        return _sigma_user(el, factor)


# --------------------------------------------------------------------------------------------
# Simulation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PseudorangeEpoch:
    """Simulated pseudoranges of all receivers at one epoch, with their ground truth.

    Array fields are read-only. Entries for satellites a receiver does not see are
    still filled (the error model is evaluated at the true elevation) except
    ``pr_m``, which is NaN there.

    Attributes
    ----------
    pr_m : ndarray, shape (n_rx, n_sv)
        Pseudorange [m]; NaN where ``visible`` is false.
    visible : ndarray of bool, shape (n_rx, n_sv)
        Which satellites each receiver tracks.
    sv_ecef_m : ndarray, shape (n_sv, 3)
        Satellite ECEF positions [m].
    system : ndarray of int, shape (n_sv,)
        System index into ``SYSTEMS``.
    el_deg, az_deg : ndarray, shape (n_rx, n_sv)
        True elevation and azimuth of each satellite from each receiver [deg].
    sigma_user_m : ndarray, shape (n_rx, n_sv)
        Receiver-related error sigma [m] (Eq. 8).
    sigma_common_m : ndarray, shape (n_sv,)
        Common (URE + troposphere) error sigma [m] at the reference elevation.
    range_m : ndarray, shape (n_rx, n_sv)
        True geometric range [m] (Eq. 2).
    common_error_m : ndarray, shape (n_sv,)
        Drawn common error [m].
    user_error_m : ndarray, shape (n_rx, n_sv)
        Drawn receiver-related error [m].
    clock_bias_m : ndarray, shape (n_rx, n_sys)
        Receiver clock bias per constellation [m].
    """

    pr_m: NDArray[np.float64]
    visible: NDArray[np.bool_]
    sv_ecef_m: NDArray[np.float64]
    system: NDArray[np.intp]
    el_deg: NDArray[np.float64]
    az_deg: NDArray[np.float64]
    sigma_user_m: NDArray[np.float64]
    sigma_common_m: NDArray[np.float64]
    range_m: NDArray[np.float64]
    common_error_m: NDArray[np.float64]
    user_error_m: NDArray[np.float64]
    clock_bias_m: NDArray[np.float64]

    def __post_init__(self) -> None:
        pr = np.asarray(self.pr_m)
        if pr.ndim != 2:
            raise ValueError(f"pr_m must have shape (n_rx, n_sv), got shape {pr.shape}")
        n_rx, n_sv = pr.shape
        expected = {
            "visible": (n_rx, n_sv),
            "sv_ecef_m": (n_sv, 3),
            "system": (n_sv,),
            "el_deg": (n_rx, n_sv),
            "az_deg": (n_rx, n_sv),
            "sigma_user_m": (n_rx, n_sv),
            "sigma_common_m": (n_sv,),
            "range_m": (n_rx, n_sv),
            "common_error_m": (n_sv,),
            "user_error_m": (n_rx, n_sv),
        }
        for name, shape in expected.items():
            got = np.shape(getattr(self, name))
            if got != shape:
                raise ValueError(f"{name} must have shape {shape}, got shape {got}")
        clock = np.asarray(self.clock_bias_m)
        if clock.ndim != 2 or clock.shape[0] != n_rx:
            raise ValueError(f"clock_bias_m must have shape ({n_rx}, n_sys), got {clock.shape}")
        for name in ("pr_m", *expected, "clock_bias_m"):
            object.__setattr__(self, name, readonly(np.asarray(getattr(self, name))))

    @classmethod
    def _trusted(cls, **fields: NDArray) -> PseudorangeEpoch:
        """An epoch of arrays the simulator just made (shapes right by construction): no
        checks and no copies; the arrays are made read-only in place."""
        out = object.__new__(cls)
        for name, value in fields.items():
            value.setflags(write=False)
            object.__setattr__(out, name, value)
        return out

    @property
    def n_rx(self) -> int:
        """Number of receivers."""
        return int(self.pr_m.shape[0])

    @property
    def n_sv(self) -> int:
        """Number of satellites."""
        return int(self.pr_m.shape[1])


def _check_rng(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    return rng


def draw_clock_biases(
    rng: np.random.Generator, n_rx: int, n_sys: int, sigma_m: float = DEFAULT_CLOCK_SIGMA_M
) -> NDArray[np.float64]:
    """Draw receiver clock biases, one per receiver and constellation.

    The navigation state of a receiver is position plus one clock term per
    constellation (length ``3 + N_const``), which absorbs the inter-system bias.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness.
    n_rx : int
        Number of receivers, >= 0.
    n_sys : int
        Number of constellations (columns, indexed by system), >= 1.
    sigma_m : float, optional
        Standard deviation [m] of the zero-mean Gaussian draw, >= 0.

    Returns
    -------
    ndarray, shape (n_rx, n_sys)
        Clock biases ``c * dt_r`` [m].
    """
    gen = _check_rng(rng)
    n_r = as_count(n_rx, "n_rx", 0)
    n_s = as_count(n_sys, "n_sys", 1)
    sigma = as_nonnegative_scalar(sigma_m, "sigma_m")
    return sigma * gen.standard_normal((n_r, n_s))


def simulate_pseudoranges(
    rng: np.random.Generator,
    rx_ecef_m: ArrayLike,
    sv_ecef_m: ArrayLike,
    system: ArrayLike,
    visible: ArrayLike,
    model: ErrorModel,
    clock_bias_m: ArrayLike | None = None,
    el_ref_deg: ArrayLike | None = None,
    extra_bias_m: ArrayLike | None = None,
) -> PseudorangeEpoch:
    """Simulate iono-free pseudoranges for several receivers at one epoch (paper Eq. 1-8).

    ``pr = range + clock_bias[rx, system[sv]] + common_error[sv] + user_error[rx, sv]
    + extra_bias[rx, sv]`` where visible, NaN elsewhere.

    * ``common_error`` (clock/ephemeris + troposphere, Eq. 4-5) is drawn ONCE per
      satellite with ``model.sigma_common_m(el_ref_deg)``: receivers of a swarm are
      close together and share it.
    * ``user_error`` (multipath + noise times the iono-free factor, Eq. 6-8) is
      drawn independently per receiver and satellite at that receiver's elevation.

    Random draws are made in a fixed order and size regardless of visibility or
    of ``model``: first ``standard_normal(n_sv)`` (common), then
    ``standard_normal((n_rx, n_sv))`` (user). The same generator state therefore
    gives the same numbers, and changing ``visible`` changes nothing else.

    Geometric ranges are instantaneous ECEF distances at the epoch (Eq. 2): no
    signal travel time or Sagnac correction. The navigation solver uses the same
    geometry, so both effects would cancel anyway.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness (advanced by n_sv + n_rx * n_sv normal draws).
    rx_ecef_m : array_like, shape (n_rx, 3)
        True receiver ECEF positions [m], n_rx >= 1.
    sv_ecef_m : array_like, shape (n_sv, 3)
        Satellite ECEF positions [m].
    system : array_like of int, shape (n_sv,)
        System index of each satellite into ``FILE_SYSTEMS`` (Galileo: 2).
    visible : array_like of bool, shape (n_rx, n_sv)
        Satellites tracked by each receiver.
    model : ErrorModel
        Error configuration.
    clock_bias_m : array_like, shape (n_rx, n_sys), optional
        Receiver clock bias per constellation [m], ``n_sys > max(system)``. Zero if None.
    el_ref_deg : array_like, shape (n_sv,), optional
        Elevation [deg] at which the common sigma is evaluated. Default: the mean
        elevation of each satellite over the receivers.
    extra_bias_m : array_like, shape (n_rx, n_sv), optional
        Additional unmodelled bias [m] (e.g. NLOS excess path), finite. Zero if None.

    Returns
    -------
    PseudorangeEpoch
    """
    gen = _check_rng(rng)
    if not isinstance(model, ErrorModel):
        raise ValueError(f"model must be an ErrorModel, got {type(model).__name__}")
    rx = as_point_list(rx_ecef_m, "rx_ecef_m")
    sv = as_point_list(sv_ecef_m, "sv_ecef_m")
    n_rx, n_sv = rx.shape[0], sv.shape[0]
    if n_rx < 1:
        raise ValueError("rx_ecef_m must hold at least one receiver, got shape (0, 3)")
    sys_idx = as_index_array(system, "system", len(FILE_SYSTEMS))
    if sys_idx.shape != (n_sv,):
        raise ValueError(f"system must have shape ({n_sv},), got shape {sys_idx.shape}")
    vis = as_bool_matrix(visible, "visible", (n_rx, n_sv))

    if clock_bias_m is None:
        clock = np.zeros((n_rx, len(FILE_SYSTEMS)))
    else:
        clock = as_float_array(clock_bias_m, "clock_bias_m")
        n_need = int(sys_idx.max()) + 1 if n_sv else 1
        if clock.ndim != 2 or clock.shape[0] != n_rx or clock.shape[1] < n_need:
            raise ValueError(
                f"clock_bias_m must have shape ({n_rx}, n_sys) with n_sys >= {n_need}, "
                f"got shape {clock.shape}"
            )
    if extra_bias_m is None:
        extra = np.zeros((n_rx, n_sv))
    else:
        extra = as_float_array(extra_bias_m, "extra_bias_m")
        if extra.shape != (n_rx, n_sv):
            raise ValueError(
                f"extra_bias_m must have shape ({n_rx}, {n_sv}), got shape {extra.shape}"
            )

    el_ref = None
    if el_ref_deg is not None:
        el_ref = as_elevation_deg(el_ref_deg, "el_ref_deg")
        if el_ref.shape != (n_sv,):
            raise ValueError(f"el_ref_deg must have shape ({n_sv},), got shape {el_ref.shape}")
    return _simulate_pseudoranges(gen, rx, sv, sys_idx, vis, model, clock, extra, el_ref)


def _iono_factors(model: ErrorModel) -> NDArray[np.float64]:
    """``model.iono_factor`` of every system index (cached per model: it is frozen)."""
    cached = _IONO_FACTORS.get(model)
    if cached is None:
        cached = model.iono_factor(np.arange(len(FILE_SYSTEMS)))
        cached.setflags(write=False)
        if len(_IONO_FACTORS) < 64:
            _IONO_FACTORS[model] = cached
    return cached


_IONO_FACTORS: dict[ErrorModel, NDArray[np.float64]] = {}


def _range_azimuth_elevation(
    rx: NDArray[np.float64], sv: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Range, azimuth and elevation of every (receiver, satellite) pair (validated arrays).

    :func:`~coopnav_env.gnss.frames.line_of_sight` and
    :func:`~coopnav_env.gnss.frames.azimuth_elevation` in one compiled pass
    (:func:`coopnav_env.gnss._kernels.range_azimuth_elevation`); they agree to a few units in
    the last place (libm's transcendental functions there, numpy's here).
    """
    range_m, az_deg, el_deg, at_centre, zero_range = _kernels.range_azimuth_elevation(
        np.ascontiguousarray(rx, dtype=np.float64),
        np.ascontiguousarray(sv, dtype=np.float64),
        WGS84_A_M,
        WGS84_B_M,
        WGS84_F,
        WGS84_E2,
        _EP2,
        _N_BOWRING_ITER,
    )
    if at_centre:
        raise ValueError("pos_ecef_m contains the Earth's centre [0, 0, 0], which has no latitude")
    if zero_range:
        raise ValueError("line_of_sight: a receiver coincides with a satellite (zero range)")
    return range_m, az_deg, el_deg


def _pseudorange_model(
    z_common: NDArray[np.float64],
    z_user: NDArray[np.float64],
    range_m: NDArray[np.float64],
    el_deg: NDArray[np.float64],
    sys_idx: NDArray[np.intp],
    vis: NDArray[np.bool_],
    model: ErrorModel,
    clock: NDArray[np.float64],
    extra: NDArray[np.float64],
    el_ref: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], ...]:
    """Sigmas, errors and pseudoranges of one epoch from its standard normal draws (Eq. 1-8).

    Returns ``sigma_common (n_sv,), sigma_user (n_rx, n_sv), common_error (n_sv,),
    user_error (n_rx, n_sv), pr (n_rx, n_sv)`` (NaN where not visible), computed by the
    compiled :func:`coopnav_env.gnss._kernels.pseudorange_model`. ``el_ref`` None: the common
    error's elevation is the mean over the receivers.
    """
    n_sv = range_m.shape[1]
    # the kernel's records (_kernels.ErrorDraws, ErrorBudget) as plain tuples, which numba
    # types faster
    return _kernels.pseudorange_model(
        range_m,
        el_deg,
        np.ascontiguousarray(sys_idx, dtype=np.int64),
        np.ascontiguousarray(vis, dtype=bool),
        (
            np.ascontiguousarray(clock, dtype=np.float64),
            z_common,
            z_user,
            np.ascontiguousarray(extra, dtype=float),
        ),
        (
            _iono_factors(model),
            np.full(n_sv, np.nan) if el_ref is None else np.ascontiguousarray(el_ref, dtype=float),
            float(model.sigma_ure_m),
            bool(model.tropo),
            bool(model.differential),
        ),
    )


def _simulate_pseudoranges(
    gen: np.random.Generator,
    rx: NDArray[np.float64],
    sv: NDArray[np.float64],
    sys_idx: NDArray[np.intp],
    vis: NDArray[np.bool_],
    model: ErrorModel,
    clock: NDArray[np.float64],
    extra: NDArray[np.float64] | None,
    el_ref: NDArray[np.float64] | None = None,
) -> PseudorangeEpoch:
    """:func:`simulate_pseudoranges` of validated arrays (``extra`` None: no extra bias).

    The same arithmetic in the same order as the public function, without re-checking its
    inputs (the environment calls this once per step with arrays it built itself).
    """
    n_rx, n_sv = rx.shape[0], sv.shape[0]
    range_m, az_deg, el_deg = _range_azimuth_elevation(rx, sv)
    z_common = gen.standard_normal(n_sv)  # always first, always full size
    z_user = gen.standard_normal((n_rx, n_sv))
    if extra is None:
        extra = np.zeros((n_rx, n_sv))
    sigma_common, sigma_user, common_error, user_error, pr = _pseudorange_model(
        z_common, z_user, range_m, el_deg, sys_idx, vis, model, clock, extra, el_ref
    )
    return PseudorangeEpoch._trusted(
        pr_m=pr,
        visible=readonly(vis),  # the caller's arrays are copied, the fresh ones are not
        sv_ecef_m=readonly(sv),
        system=readonly(sys_idx),
        el_deg=el_deg,
        az_deg=az_deg,
        sigma_user_m=sigma_user,
        sigma_common_m=sigma_common,
        range_m=range_m,
        common_error_m=common_error,
        user_error_m=user_error,
        clock_bias_m=readonly(clock),
    )
