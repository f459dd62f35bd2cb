r"""The simulation scenario of the paper's Section 4.1, as a reusable, validated builder.

A swarm of UAVs in a fixed formation near Shanghai (the authors' site) sees the nominal GPS and
BeiDou-3 constellations (:func:`coopnav_env.gnss.default_constellation`). One UAV, the *canyon
UAV*, flies in an urban street canyon modelled by the analytic elevation mask of Eq. 25 with gaps
between buildings (Figure 6); the others fly in open sky and track at most ``max_sats``
satellites ("the maximum number of available satellites equals to 10"). Pseudoranges follow
Eq. 1-8 (:class:`coopnav_env.gnss.ErrorModel`), relative positions Eq. 9 with an independent
``N(0, sigma_rel^2)`` error per ENU axis and per pair of UAVs.

Everything the paper leaves open is a field of :class:`PaperScenario` with a default and the
reason for it in the field's description. :meth:`PaperScenario.epoch` builds one epoch (true
geometry, visibility, error standard deviations) and :meth:`PaperEpoch.draw` draws any number
of noise realisations of it at once, for Monte Carlo studies with
:func:`coopnav_env.nav.solve_cooperative_samples`.

Frames: ENU is the local frame at the formation origin (``lat_deg, lon_deg, alt_m``); azimuths
are clockwise from North, elevations above the horizon, both in degrees.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.constants import SHANGHAI_LAT_DEG, SHANGHAI_LON_DEG
from coopnav_env.gnss import (
    Constellation,
    ErrorModel,
    azimuth_elevation,
    default_constellation,
    enu_rotation,
    enu_to_ecef,
    geodetic_to_ecef,
    select_highest,
    simulate_pseudoranges,
)
from coopnav_env.nav import GnssObservations, RelativePositions

__all__ = [
    "DEFAULT_GAPS_DEG",
    "PaperEpoch",
    "PaperScenario",
    "Samples",
    "canyon_mask_elevation_deg",
    "formation_enu",
    "in_azimuth_intervals",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

DEFAULT_GAPS_DEG: tuple[tuple[float, float], ...] = ((50.0, 70.0), (220.0, 240.0))
"""Default gaps of the canyon mask: clockwise azimuth intervals ``(start, end)`` [deg].

One 20 deg gap in each building silhouette of a north-south street, placed asymmetrically where
the mask is high (Eq. 25 with ``h/d = sqrt(3)`` gives 53-58 deg and 48-56 deg there), so that a
gap really lets satellites through. Figure 6 shows gaps but not where; this is the same layout
as ``coopnav_env.sim.city.DEFAULT_CANYON_GAPS_DEG``."""

SIGMA_CLOCK_M: float = 3.0e4
"""Standard deviation of the simulated receiver clock biases [m] (about 100 us)."""


# --------------------------------------------------------------------------------------------
# The analytic canyon mask (Eq. 25) and the formation
# --------------------------------------------------------------------------------------------


def in_azimuth_intervals(
    az_deg: ArrayLike, intervals_deg: tuple[tuple[float, float], ...]
) -> BoolArray:
    """Whether each azimuth lies in one of the clockwise intervals.

    Parameters
    ----------
    az_deg : array_like, any shape
        Azimuths, clockwise from North [deg].
    intervals_deg : tuple of (float, float)
        Intervals ``(start, end)`` [deg] read clockwise from ``start`` to ``end`` (``(350, 10)``
        wraps through North), bounds included.

    Returns
    -------
    ndarray of bool, same shape as ``az_deg``
    """
    az = np.asarray(az_deg, dtype=np.float64)
    if not intervals_deg:
        return np.zeros(az.shape, dtype=bool)
    iv = np.asarray(intervals_deg, dtype=np.float64)
    width = np.mod(iv[:, 1] - iv[:, 0], 360.0)
    offset = np.mod(az[..., None] - iv[:, 0], 360.0)
    return np.any(offset <= width, axis=-1)


def canyon_mask_elevation_deg(
    az_deg: ArrayLike,
    h_over_d: float = math.sqrt(3.0),
    street_azimuth_deg: float = 0.0,
    gaps_deg: tuple[tuple[float, float], ...] = DEFAULT_GAPS_DEG,
) -> FloatArray:
    """Elevation mask of a street canyon, paper Eq. 25, with gaps between buildings.

    ``theta_m = |atan(h/d * sin(az - street_azimuth))|``: 0 along the street, ``atan(h/d)``
    across it (the skyline of two infinitely long walls of height ``h`` at distance ``d``), and
    0 inside a gap.

    Parameters
    ----------
    az_deg : array_like, any shape
        Satellite azimuth, clockwise from North [deg].
    h_over_d : float
        Building height above the UAV over the distance to the buildings [-], >= 0.
    street_azimuth_deg : float
        Azimuth of the street axis, clockwise from North [deg].
    gaps_deg : tuple of (float, float)
        Clockwise azimuth intervals [deg] where a gap between buildings leaves the sky open.

    Returns
    -------
    ndarray, same shape as ``az_deg``
        Mask elevation [deg], in ``[0, atan(h/d)]``.
    """
    az = np.asarray(az_deg, dtype=np.float64)
    phi = np.radians(az - street_azimuth_deg)
    theta = np.abs(np.degrees(np.arctan(h_over_d * np.sin(phi))))
    return np.where(in_azimuth_intervals(az, gaps_deg), 0.0, theta)


def formation_enu(n_uavs: int, spacing_m: float) -> FloatArray:
    """A fixed formation: the ``n_uavs`` points of a square lattice nearest its centre.

    UAV 0 is the centre; the others follow by distance, then by azimuth clockwise from North.
    Five UAVs form a cross (plus sign) ``2 * spacing_m`` across, our reading of Figure 4; the
    same rule grows the swarm compactly for the swarm-size study (50 UAVs fill about a 7 x 7
    square).

    Parameters
    ----------
    n_uavs : int
        Number of UAVs, >= 1.
    spacing_m : float
        Lattice spacing [m], > 0.

    Returns
    -------
    ndarray, shape (n_uavs, 3)
        ENU positions relative to the formation origin [m]; all at the origin's height.
    """
    half = math.ceil(math.sqrt(n_uavs)) + 1
    ij = np.stack(np.meshgrid(np.arange(-half, half + 1), np.arange(-half, half + 1)), -1)
    ij = ij.reshape(-1, 2).astype(float)
    dist = np.hypot(ij[:, 0], ij[:, 1])
    az = np.mod(np.degrees(np.arctan2(ij[:, 0], ij[:, 1])), 360.0)
    order = np.lexsort((az, dist))[:n_uavs]
    out = np.zeros((n_uavs, 3))
    out[:, :2] = ij[order] * spacing_m
    return out


# --------------------------------------------------------------------------------------------
# Validation helpers: a bad value raises ValueError naming the field and the allowed range
# --------------------------------------------------------------------------------------------


def check_real(
    owner: str, name: str, value: Any, lo: float, hi: float, *, lo_open: bool = False
) -> float:
    """``value`` as a float in ``[lo, hi]`` (``(lo, hi]`` if ``lo_open``) or ``ValueError``."""
    allowed = f"{'(' if lo_open else '['}{lo}, {hi}]"
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{owner}.{name} must be a real number in {allowed}, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi):
        raise ValueError(f"{owner}.{name} must be in {allowed}, got {value!r}")
    return v


def check_int(owner: str, name: str, value: Any, lo: int, hi: int) -> int:
    """``value`` as an int in ``[lo, hi]`` or ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{owner}.{name} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= int(value) <= hi:
        raise ValueError(f"{owner}.{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def check_choice(owner: str, name: str, value: Any, allowed: tuple[Any, ...]) -> Any:
    """``value`` if it is one of ``allowed`` or ``ValueError``."""
    if isinstance(value, bool) != isinstance(allowed[0], bool) or value not in allowed:
        raise ValueError(f"{owner}.{name} must be one of {allowed}, got {value!r}")
    return value


def check_intervals(owner: str, name: str, value: Any) -> tuple[tuple[float, float], ...]:
    """A tuple of ``(start, end)`` azimuth pairs in ``[0, 360]`` [deg] or ``ValueError``."""
    try:
        pairs = tuple((a, b) for a, b in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{owner}.{name} must be a sequence of (start, end) azimuth pairs in [0, 360] deg, "
            f"got {value!r}"
        ) from exc
    return tuple(
        (
            check_real(owner, f"{name} start", a, 0.0, 360.0),
            check_real(owner, f"{name} end", b, 0.0, 360.0),
        )
        for a, b in pairs
    )


# --------------------------------------------------------------------------------------------
# The scenario
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Samples:
    """``K`` noise realisations of one epoch.

    Attributes
    ----------
    pr_m : ndarray, shape (K, n_uavs, n_sv)
        Pseudoranges [m]; NaN where not received.
    rel_from_canyon_ecef_m : ndarray, shape (K, n_uavs, 3)
        Measured position of every UAV relative to the canyon UAV (``p_q - p_c + eps_cq``) [m]
        in ECEF; zero for the canyon UAV itself.
    eps_enu_m : ndarray, shape (K, n_uavs, 3)
        The relative-position errors ``eps_cq`` in ENU [m]. The pair (c, q) has one measurement:
        the position of ``c`` relative to ``q`` is ``p_c - p_q - eps_cq``.
    """

    pr_m: FloatArray
    rel_from_canyon_ecef_m: FloatArray
    eps_enu_m: FloatArray


@dataclass(frozen=True, eq=False)
class PaperEpoch:
    """True geometry and error model of one epoch (satellites seen by no UAV dropped).

    Attributes
    ----------
    t_s : float
        Time since the constellation's reference epoch [s].
    pos_ecef_m : ndarray, shape (n_uavs, 3)
        True UAV positions [m].
    canyon_uav : int
        Index of the UAV in the canyon.
    rot_enu : ndarray, shape (3, 3)
        ECEF-to-ENU rotation at the formation origin (``d_enu = rot_enu @ d_ecef``).
    origin_ecef_m : ndarray, shape (3,)
        Formation origin [m] (the solvers' initial guess).
    sv_ecef_m : ndarray, shape (n_sv, 3)
    prn : tuple of str, length n_sv
    system : ndarray of int, shape (n_sv,)
    visible : ndarray of bool, shape (n_uavs, n_sv)
        Satellites tracked by each UAV.
    el_deg, az_deg : ndarray, shape (n_uavs, n_sv)
        Elevation and azimuth of every satellite at every UAV [deg].
    range_m : ndarray, shape (n_uavs, n_sv)
        True geometric ranges [m].
    clock_bias_m : ndarray, shape (n_uavs, n_systems)
        Receiver clock bias per constellation [m].
    sigma_user_m : ndarray, shape (n_uavs, n_sv)
        Multipath + noise standard deviation after the iono-free combination (Eq. 6-8) [m].
    sigma_common_m : ndarray, shape (n_sv,)
        Standard deviation of the errors shared by the swarm (Eq. 4-5; 0 with differential
        correction) [m].
    sigma_rel_m : float
        Relative-position error standard deviation per ENU axis [m].
    """

    t_s: float
    pos_ecef_m: FloatArray
    canyon_uav: int
    rot_enu: FloatArray
    origin_ecef_m: FloatArray
    sv_ecef_m: FloatArray
    prn: tuple[str, ...]
    system: NDArray[np.intp]
    visible: BoolArray
    el_deg: FloatArray
    az_deg: FloatArray
    range_m: FloatArray
    clock_bias_m: FloatArray
    sigma_user_m: FloatArray
    sigma_common_m: FloatArray
    sigma_rel_m: float

    @property
    def n_uavs(self) -> int:
        """Number of UAVs."""
        return int(self.pos_ecef_m.shape[0])

    @property
    def n_sv(self) -> int:
        """Number of satellites kept (seen by at least one UAV)."""
        return int(self.sv_ecef_m.shape[0])

    @property
    def n_los(self) -> int:
        """Number of satellites tracked by the canyon UAV."""
        return int(self.visible[self.canyon_uav].sum())

    def observations(self, pr_m: ArrayLike | None = None) -> GnssObservations:
        """The epoch as solver input.

        Parameters
        ----------
        pr_m : array_like, shape (n_uavs, n_sv), optional
            Pseudoranges [m]; default the noise-free ones (range plus clock).
        """
        if pr_m is None:
            pr = self.range_m + self.clock_bias_m[:, self.system]
            pr_m = np.where(self.visible, pr, np.nan)
        return GnssObservations(
            pr_m=pr_m,
            sv_ecef_m=self.sv_ecef_m,
            system=self.system,
            sigma_user_m=self.sigma_user_m,
            sigma_common_m=self.sigma_common_m,
            el_deg=self.el_deg,
        )

    def relative_positions(self) -> RelativePositions:
        """Error-free pairwise relative positions with the covariance ``sigma_rel^2 I`` (ENU)."""
        n = self.n_uavs
        cov_enu = np.broadcast_to(self.sigma_rel_m**2 * np.eye(3), (n, n, 3, 3)).copy()
        cov_enu[np.arange(n), np.arange(n)] = 0.0
        rot = self.rot_enu
        return RelativePositions(
            rel_ecef_m=self.pos_ecef_m[None, :, :] - self.pos_ecef_m[:, None, :],
            cov_ecef_m2=np.einsum("ji,abjk,kl->abil", rot, cov_enu, rot),
            available=np.ones((n, n), dtype=bool),
        )

    def draw(self, rng: np.random.Generator, n_samples: int) -> Samples:
        """Draw ``n_samples`` independent noise realisations (Eq. 1-9), vectorised.

        Same model as :func:`coopnav_env.gnss.simulate_pseudoranges`: a common error per
        satellite shared by the swarm, an independent user error per UAV and satellite; plus an
        independent relative-position error per pair. Draw order (fixed, whatever the
        visibility): common ``(K, n_sv)``, user ``(K, n_uavs, n_sv)``, relative
        ``(K, n_uavs, 3)``.

        Parameters
        ----------
        rng : numpy.random.Generator
        n_samples : int
            ``K`` >= 1.

        Returns
        -------
        Samples
        """
        k, n, s = int(n_samples), self.n_uavs, self.n_sv
        z_common = rng.standard_normal((k, s))
        z_user = rng.standard_normal((k, n, s))
        eps = self.sigma_rel_m * rng.standard_normal((k, n, 3))
        eps[:, self.canyon_uav] = 0.0
        pr = (
            (self.range_m + self.clock_bias_m[:, self.system])[None]
            + (self.sigma_common_m * z_common)[:, None, :]
            + self.sigma_user_m[None] * z_user
        )
        pr = np.where(self.visible[None], pr, np.nan)
        base = self.pos_ecef_m - self.pos_ecef_m[self.canyon_uav]
        rel = base[None] + eps @ self.rot_enu  # ENU -> ECEF: d_ecef = R^T d_enu
        return Samples(pr_m=pr, rel_from_canyon_ecef_m=rel, eps_enu_m=eps)


OpenSkySelection = Literal["highest", "random"]
Frequencies = Literal["per-system", "paper"]


@dataclass(frozen=True)
class PaperScenario:
    """Configuration of the Section 4.1 scenario (frozen, validated on construction).

    Parameters
    ----------
    n_uavs : int
        Swarm size, in [2, 200]; the paper's default is 5.
    canyon_uav : int
        Index of the UAV in the canyon, in [0, n_uavs - 1]; 0 is the centre of the formation.
    spacing_m : float
        Lattice spacing of the formation (:func:`formation_enu`) [m], in (0, 1000]; 20 m makes
        the 5-UAV cross 40 m across (Figure 4 gives no scale).
    lat_deg, lon_deg : float
        Formation origin [deg]; default Shanghai Jiao Tong University (the authors' site).
    alt_m : float
        Height of the formation above the ellipsoid [m], in [-500, 10000].
    h_over_d : float
        Building height over street half-width seen from the canyon UAV (Eq. 25), in [0, 1000];
        the paper's Figure 6 uses sqrt(3) (a 60 deg mask across the street).
    street_azimuth_deg : float
        Street axis, clockwise from North [deg], in [0, 180]; 0 (north-south) matches Table 1's
        larger East than North error.
    gaps_deg : tuple of (float, float)
        Clockwise azimuth intervals of the gaps between buildings [deg]; see
        :data:`DEFAULT_GAPS_DEG`. ``()`` for an unbroken canyon.
    elevation_cutoff_deg : float
        Elevation mask of every receiver [deg], in [0, 45]. Not given in the paper; 10 deg is a
        common receiver default.
    max_sats : int
        Channel limit per UAV, in [1, 100]: "the maximum number of available satellites equals
        to 10" in open sky.
    open_sky_selection : {"highest", "random"}
        Which satellites an open-sky UAV keeps under the channel limit: the ``max_sats``
        highest (:func:`coopnav_env.gnss.select_highest`, default) or a random subset drawn per
        epoch and UAV.
    canyon_channel_limit : bool
        Apply the channel limit to the canyon UAV too (default True, so that with ``h/d = 0`` it
        sees exactly what an open-sky UAV sees).
    sigma_rel_m : float
        Relative-position error standard deviation per ENU axis [m], in [0, 100]; the paper's
        0.5 m.
    frequencies : {"per-system", "paper"}
        Iono-free pair of Eq. 8: ``"per-system"`` is GPS L1/L2 and BDS B1I/B3I
        (``ErrorModel()``, factors 2.98 and 3.53); ``"paper"`` applies L1/L2 to both systems
        (``ErrorModel.paper()``, Eq. 8 names only ``f_L1, f_L2``).
    iono_free : bool
        Amplify the multipath and noise error by the iono-free factor of Eq. 8 (``True``, as
        Eq. 8 is printed: x 2.98 for GPS L1/L2, x 3.53 for BDS B1I/B3I). Default ``False``:
        the factor is dropped (``ErrorModel(iono_free=False)``, user error
        ``sqrt(sigma_MP^2 + sigma_Noise^2)``), which reproduces the paper's results and
        the printed equation does not: with differential correction only the user error is
        left, and only when it is this small does one partner's 0.5 m relative error outweigh
        the gain, so that Table 2's improvement at N = 2 is lower with correction (33 %) than
        without (56 %), and master-slave loses its gain beyond 0.5 m (Figure 12b). Our reading:
        the authors' simulation applied Eq. 6-7 without the factor. The ionospheric delay
        itself is not simulated either way. ``docs/reproduction/report.md`` shows both.
    differential : bool
        Differential corrections remove the common (URE + troposphere) errors (Eq. 4-5).
    bds_geo_igso : bool
        Add the BeiDou-3 GEO and IGSO satellites (visible from Shanghai; the paper does not say
        whether it used them). Default False: the MEO constellation of ``default_constellation()``.
    """

    n_uavs: int = 5
    canyon_uav: int = 0
    spacing_m: float = 20.0
    lat_deg: float = SHANGHAI_LAT_DEG
    lon_deg: float = SHANGHAI_LON_DEG
    alt_m: float = 60.0
    h_over_d: float = math.sqrt(3.0)
    street_azimuth_deg: float = 0.0
    gaps_deg: tuple[tuple[float, float], ...] = DEFAULT_GAPS_DEG
    elevation_cutoff_deg: float = 10.0
    max_sats: int = 10
    open_sky_selection: OpenSkySelection = "highest"
    canyon_channel_limit: bool = True
    sigma_rel_m: float = 0.5
    frequencies: Frequencies = "per-system"
    iono_free: bool = False
    differential: bool = False
    bds_geo_igso: bool = False

    def __post_init__(self) -> None:
        o = "PaperScenario"
        setv = object.__setattr__
        setv(self, "n_uavs", check_int(o, "n_uavs", self.n_uavs, 2, 200))
        setv(self, "canyon_uav", check_int(o, "canyon_uav", self.canyon_uav, 0, self.n_uavs - 1))
        setv(
            self, "spacing_m", check_real(o, "spacing_m", self.spacing_m, 0.0, 1000.0, lo_open=True)
        )
        setv(self, "lat_deg", check_real(o, "lat_deg", self.lat_deg, -85.0, 85.0))
        setv(self, "lon_deg", check_real(o, "lon_deg", self.lon_deg, -180.0, 360.0))
        setv(self, "alt_m", check_real(o, "alt_m", self.alt_m, -500.0, 10000.0))
        setv(self, "h_over_d", check_real(o, "h_over_d", self.h_over_d, 0.0, 1000.0))
        setv(
            self,
            "street_azimuth_deg",
            check_real(o, "street_azimuth_deg", self.street_azimuth_deg, 0.0, 180.0),
        )
        setv(self, "gaps_deg", check_intervals(o, "gaps_deg", self.gaps_deg))
        setv(
            self,
            "elevation_cutoff_deg",
            check_real(o, "elevation_cutoff_deg", self.elevation_cutoff_deg, 0.0, 45.0),
        )
        setv(self, "max_sats", check_int(o, "max_sats", self.max_sats, 1, 100))
        check_choice(o, "open_sky_selection", self.open_sky_selection, ("highest", "random"))
        check_choice(o, "canyon_channel_limit", self.canyon_channel_limit, (True, False))
        setv(self, "sigma_rel_m", check_real(o, "sigma_rel_m", self.sigma_rel_m, 0.0, 100.0))
        check_choice(o, "frequencies", self.frequencies, ("per-system", "paper"))
        check_choice(o, "iono_free", self.iono_free, (True, False))
        check_choice(o, "differential", self.differential, (True, False))
        check_choice(o, "bds_geo_igso", self.bds_geo_igso, (True, False))

    def to_dict(self) -> dict[str, Any]:
        """The configuration as plain JSON-able values."""
        out = {}
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            out[name] = [list(v) for v in value] if name == "gaps_deg" else value
        return out

    # ----------------------------------------------------------------------------------------

    @cached_property
    def constellation(self) -> Constellation:
        """GPS + BeiDou-3 nominal constellation."""
        return default_constellation(("GPS", "BDS"), bds_geo_igso=self.bds_geo_igso)

    @cached_property
    def error_model(self) -> ErrorModel:
        """The error budget of Eq. 3-8 for the chosen frequencies, iono-free factor and
        differential mode."""
        if self.frequencies == "paper":
            model = ErrorModel.paper(differential=self.differential)
        else:
            model = ErrorModel(differential=self.differential)
        return model if self.iono_free else dataclasses.replace(model, iono_free=False)

    @cached_property
    def positions_enu_m(self) -> FloatArray:
        """UAV positions in the ENU frame of the formation origin [m], shape (n_uavs, 3)."""
        return formation_enu(self.n_uavs, self.spacing_m)

    @cached_property
    def positions_ecef_m(self) -> FloatArray:
        """UAV positions in ECEF [m], shape (n_uavs, 3)."""
        return enu_to_ecef(self.positions_enu_m, self.lat_deg, self.lon_deg, self.alt_m)

    def canyon_mask_deg(self, az_deg: ArrayLike) -> FloatArray:
        """Eq. 25 mask of this scenario's canyon at the given azimuths [deg]."""
        return canyon_mask_elevation_deg(
            az_deg, self.h_over_d, self.street_azimuth_deg, self.gaps_deg
        )

    def epoch(
        self, t_s: float, rng: np.random.Generator, *, n_los: int | None = None
    ) -> PaperEpoch:
        """Geometry, visibility and error model at one time.

        Parameters
        ----------
        t_s : float
            Time since the constellation reference epoch [s].
        rng : numpy.random.Generator
            Used for the receiver clocks and, with ``open_sky_selection="random"`` or
            ``n_los``, for the random satellite subsets.
        n_los : int, optional
            If given, the canyon UAV's satellites are not set by the mask but are a random
            subset of ``n_los`` of its open-sky satellites ("thinning", for the study against the
            number of LOS satellites); ``None`` (default) applies the canyon mask.

        Returns
        -------
        PaperEpoch
        """
        pos = self.positions_ecef_m
        con = self.constellation
        sv = con.positions_ecef(float(t_s))
        az, el = azimuth_elevation(pos, sv)
        above = el > self.elevation_cutoff_deg
        if self.open_sky_selection == "highest":
            vis = select_highest(el, above, self.max_sats)
        else:
            key = np.where(above, rng.random(above.shape), np.inf)
            rank = np.argsort(np.argsort(key, axis=1, kind="stable"), axis=1)
            vis = above & (rank < self.max_sats)
        c = self.canyon_uav
        if n_los is None:
            in_canyon = above[c] & (el[c] > self.canyon_mask_deg(az[c]))
            if self.canyon_channel_limit:
                in_canyon = select_highest(el[c][None], in_canyon[None], self.max_sats)[0]
        else:
            pool = np.flatnonzero(vis[c])
            pick = rng.permutation(pool)[: min(int(n_los), pool.size)]
            in_canyon = np.zeros(sv.shape[0], dtype=bool)
            in_canyon[pick] = True
        vis[c] = in_canyon
        keep = vis.any(axis=0)
        clock = SIGMA_CLOCK_M * rng.standard_normal((pos.shape[0], 2))
        # simulate_pseudoranges defines the error model (its sigmas); its own noise draw is not
        # used: samples are drawn in bulk by PaperEpoch.draw.
        ep = simulate_pseudoranges(
            np.random.default_rng(0),
            pos,
            sv[keep],
            con.system[keep],
            vis[:, keep],
            self.error_model,
            clock_bias_m=clock,
        )
        origin = geodetic_to_ecef(self.lat_deg, self.lon_deg, self.alt_m)
        return PaperEpoch(
            t_s=float(t_s),
            pos_ecef_m=pos,
            canyon_uav=c,
            rot_enu=enu_rotation(self.lat_deg, self.lon_deg),
            origin_ecef_m=origin,
            sv_ecef_m=np.asarray(ep.sv_ecef_m),
            prn=tuple(np.asarray(con.prn, dtype=object)[keep].tolist()),
            system=np.asarray(ep.system),
            visible=np.asarray(ep.visible),
            el_deg=np.asarray(ep.el_deg),
            az_deg=np.asarray(ep.az_deg),
            range_m=np.asarray(ep.range_m),
            clock_bias_m=clock,
            sigma_user_m=np.asarray(ep.sigma_user_m),
            sigma_common_m=np.asarray(ep.sigma_common_m),
            sigma_rel_m=self.sigma_rel_m,
        )

    def sky(self, t_s: float) -> tuple[FloatArray, FloatArray, NDArray[np.intp], BoolArray]:
        """Azimuth, elevation, system and canyon visibility of every satellite at the canyon UAV.

        For the sky plot (Figure 6). Returns ``az_deg, el_deg, system, visible``, each of shape
        (n_sv_total,); ``visible`` ignores the channel limit.
        """
        pos = self.positions_ecef_m[self.canyon_uav][None]
        sv = self.constellation.positions_ecef(float(t_s))
        az, el = azimuth_elevation(pos, sv)
        vis = (el[0] > self.elevation_cutoff_deg) & (el[0] > self.canyon_mask_deg(az[0]))
        return az[0], el[0], np.asarray(self.constellation.system), vis
