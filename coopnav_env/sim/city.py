"""The urban world: buildings, street grid, line of sight and the analytic canyon mask.

Frames and units
----------------
Everything lives in a local East-North-Up (ENU) frame in metres, relative to a geodetic
origin (by default :data:`coopnav_env.constants.SHANGHAI_LAT_DEG` etc.; the origin matters
only to the GNSS sub-package). ``x`` is East, ``y`` North, ``z`` Up; the ground is ``z = 0``.
Satellites are so far away that, for line-of-sight purposes, a satellite is a direction:
an ``(n_sv, 3)`` array of ENU vectors (normalised internally). Azimuths are measured from
North, clockwise towards East, in degrees: a unit direction is
``(cos(el) sin(az), cos(el) cos(az), sin(el))``.

Buildings are axis-aligned boxes standing on the ground. Two visibility models are offered:

* the 3-D model, :func:`line_of_sight` (ray against every box, slab method) with its
  skyline companion :func:`mask_elevation_deg` (and :func:`wall_distance_m`, the horizontal
  range to the nearest wall, what a navigation agent's range sensor measures);
* the paper's analytic urban-canyon mask (Eq. 25), :class:`CanyonMask`.

:func:`canyon_city` builds the paper's straight canyon as real boxes so that both models can
be compared on the same scenario (``tests/sim`` checks that they agree).

All functions are pure: they never modify their inputs, and randomness comes only from an
explicit :class:`numpy.random.Generator`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.sim import _kernels

__all__ = [
    "DEFAULT_CANYON_GAPS_DEG",
    "Buildings",
    "CanyonMask",
    "City",
    "CityConfig",
    "SkyDirections",
    "canyon_city",
    "draw_nlos",
    "generate_city",
    "is_inside_building",
    "line_of_sight",
    "mask_elevation_deg",
    "ray_directions",
    "sky_and_walls",
    "sky_directions",
    "wall_distance_m",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

CHUNK_ELEMENTS: int = 1 << 20
"""Largest number of elements of one temporary array in the chunked numpy functions (about
8 MB of float64). Bounds the memory of :func:`is_inside_building` and the collision functions
of :mod:`coopnav_env.sim.swarm` whatever the number of receivers and buildings."""

DEFAULT_CANYON_GAPS_DEG: tuple[tuple[float, float], ...] = ((50.0, 70.0), (220.0, 240.0))
"""Default gaps of the analytic canyon mask, absolute azimuth intervals ``(start, end)`` [deg].

Two 20 deg gaps, one on each side of a north-south street, placed asymmetrically. The paper
(Section 4.1, Figure 6) breaks the two building silhouettes with gaps "due to the finite width
of the surrounding buildings" but gives neither their number nor their positions; this choice
keeps the spirit of the figure: each silhouette is broken once, where the mask is high
(azimuths 50-70 deg and 220-240 deg are 50-70 deg and 40-60 deg away from the street axis,
where Eq. 25 with ``h/d = sqrt(3)`` gives a 53-58 deg and 48-56 deg mask), so that a gap really
lets a few extra satellites through."""


# --------------------------------------------------------------------------------------------
# small validation helpers
# --------------------------------------------------------------------------------------------


def _check_real(
    owner: str,
    name: str,
    value: Any,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> float:
    """Return ``value`` as float or raise ``ValueError`` naming the field and the range."""
    lb = "(" if lo_open else "["
    rb = ")" if hi_open else "]"
    allowed = f"{lb}{lo}, {hi}{rb}"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{owner}.{name} must be a real number in {allowed}, got {value!r}")
    v = float(value)
    ok = math.isfinite(v) or (v == hi and math.isinf(hi) and not hi_open)
    ok = ok and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        raise ValueError(f"{owner}.{name} must be in {allowed}, got {value!r}")
    return v


def _check_int(owner: str, name: str, value: Any, lo: int, hi: int) -> int:
    """Return ``value`` as int or raise ``ValueError`` naming the field and the range."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{owner}.{name} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= int(value) <= hi:
        raise ValueError(f"{owner}.{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def _as_points(value: ArrayLike, name: str) -> FloatArray:
    """Return ``value`` as a finite float array of shape ``(n, 3)`` (no copy if possible)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


def _chunk_slices(n: int, elements_per_item: int) -> Iterator[slice]:
    """Slices of ``range(n)`` so that a chunk holds at most :data:`CHUNK_ELEMENTS` elements."""
    step = max(1, CHUNK_ELEMENTS // max(int(elements_per_item), 1))
    for start in range(0, n, step):
        yield slice(start, min(start + step, n))


def _readonly(arr: FloatArray) -> FloatArray:
    arr.setflags(write=False)
    return arr


# --------------------------------------------------------------------------------------------
# buildings
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Buildings:
    """A set of axis-aligned box buildings standing on the ground.

    Parameters
    ----------
    min_m : ndarray, shape (n_b, 3)
        Lower ENU corner ``(x_min, y_min, 0)`` of each box [m]. Every box stands on the
        ground: ``min_m[:, 2] == 0``.
    max_m : ndarray, shape (n_b, 3)
        Upper ENU corner ``(x_max, y_max, height)`` of each box [m]; ``max_m > min_m``.

    Notes
    -----
    The arrays are copied and made read-only on construction. Build instances with
    :meth:`from_boxes`, :meth:`from_footprints` or :meth:`empty`.
    """

    min_m: FloatArray
    max_m: FloatArray

    def __post_init__(self) -> None:
        lo = np.array(self.min_m, dtype=np.float64)
        hi = np.array(self.max_m, dtype=np.float64)
        lo = lo.reshape(0, 3) if lo.size == 0 else lo
        hi = hi.reshape(0, 3) if hi.size == 0 else hi
        if lo.ndim != 2 or lo.shape[1] != 3:
            raise ValueError(f"Buildings.min_m must have shape (n_b, 3), got {lo.shape}")
        if hi.shape != lo.shape:
            raise ValueError(
                f"Buildings.max_m must have the shape of min_m {lo.shape}, got {hi.shape}"
            )
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("Buildings.min_m and Buildings.max_m must be finite")
        if np.any(lo[:, 2] != 0.0):
            bad = lo[lo[:, 2] != 0.0, 2][0]
            raise ValueError(
                f"Buildings.min_m[:, 2] must be 0 (boxes stand on the ground), got {bad}"
            )
        if np.any(hi <= lo):
            i = int(np.nonzero(np.any(hi <= lo, axis=1))[0][0])
            raise ValueError(
                f"Buildings.max_m must be > min_m on every axis; box {i} has "
                f"min {lo[i].tolist()} and max {hi[i].tolist()}"
            )
        object.__setattr__(self, "min_m", _readonly(lo))
        object.__setattr__(self, "max_m", _readonly(hi))

    @classmethod
    def _of_arrays(cls, min_m: FloatArray, max_m: FloatArray) -> Buildings:
        """Buildings of float64 corner arrays ``(n_b, 3)`` that are valid by construction
        (a generator's own output), taken as they are (made read-only), without the checks
        and copies of the constructor."""
        out = object.__new__(cls)
        object.__setattr__(out, "min_m", _readonly(min_m))
        object.__setattr__(out, "max_m", _readonly(max_m))
        return out

    @property
    def n(self) -> int:
        """Number of buildings ``n_b``."""
        return int(self.min_m.shape[0])

    @property
    def heights_m(self) -> FloatArray:
        """Roof heights above the ground, shape ``(n_b,)`` [m]."""
        return self.max_m[:, 2].copy()

    @property
    def footprints_m(self) -> FloatArray:
        """Footprints ``(x_min, y_min, x_max, y_max)``, shape ``(n_b, 4)`` [m]."""
        return np.concatenate([self.min_m[:, :2], self.max_m[:, :2]], axis=1)

    @classmethod
    def empty(cls) -> Buildings:
        """No buildings (open sky everywhere)."""
        return cls(np.zeros((0, 3)), np.zeros((0, 3)))

    @classmethod
    def from_footprints(cls, footprints_m: ArrayLike, heights_m: ArrayLike) -> Buildings:
        """Build from footprints and heights.

        Parameters
        ----------
        footprints_m : array_like, shape (n_b, 4)
            ``(x_min, y_min, x_max, y_max)`` of each building in ENU [m].
        heights_m : array_like, shape (n_b,)
            Roof height of each building above the ground [m].
        """
        fp = np.asarray(footprints_m, dtype=np.float64).reshape(-1, 4)
        h = np.asarray(heights_m, dtype=np.float64).reshape(-1)
        if h.shape[0] != fp.shape[0]:
            raise ValueError(
                f"heights_m must have one value per footprint ({fp.shape[0]}), got {h.shape[0]}"
            )
        zeros = np.zeros_like(h)
        lo = np.stack([fp[:, 0], fp[:, 1], zeros], axis=1)
        hi = np.stack([fp[:, 2], fp[:, 3], h], axis=1)
        return cls(lo, hi)

    @classmethod
    def from_boxes(cls, boxes: Sequence[Sequence[float]]) -> Buildings:
        """Build from a list of ``(x_min, y_min, x_max, y_max, height_m)`` tuples [m]."""
        arr = np.asarray(boxes, dtype=np.float64).reshape(-1, 5)
        return cls.from_footprints(arr[:, :4], arr[:, 4])

    def concatenate(self, other: Buildings) -> Buildings:
        """A new :class:`Buildings` holding the boxes of ``self`` then those of ``other``."""
        return Buildings(
            np.concatenate([self.min_m, other.min_m]), np.concatenate([self.max_m, other.max_m])
        )


def is_inside_building(buildings: Buildings, pos_enu_m: ArrayLike) -> BoolArray:
    """Whether each point lies strictly inside a building.

    Parameters
    ----------
    buildings : Buildings
    pos_enu_m : array_like, shape (n, 3)
        Points in ENU [m].

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the point is in the open interior of at least one box (points on a wall
        or roof are outside).
    """
    pos = _as_points(pos_enu_m, "pos_enu_m")
    if not isinstance(buildings, Buildings):  # extruded polygons (sim.file_city)
        return buildings.is_inside(pos)
    inside = np.zeros(pos.shape[0], dtype=bool)
    for c in _chunk_slices(buildings.n, 3 * max(pos.shape[0], 1)):
        lo = buildings.min_m[None, c, :]
        hi = buildings.max_m[None, c, :]
        p = pos[:, None, :]
        inside |= np.any(np.all((p > lo) & (p < hi), axis=2), axis=1)
    return inside


# --------------------------------------------------------------------------------------------
# ray casting
# --------------------------------------------------------------------------------------------


def _unit_directions(dir_enu: ArrayLike) -> FloatArray:
    d = _as_points(dir_enu, "dir_enu")
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm == 0.0):
        raise ValueError("dir_enu must not contain zero vectors")
    return d / norm[:, None]


def line_of_sight(buildings: Buildings, pos_enu_m: ArrayLike, dir_enu: ArrayLike) -> BoolArray:
    """Line of sight from receivers to satellites through a city of box buildings.

    The ray ``pos + t * dir`` (``t > 0``) from each receiver toward each satellite direction is
    tested against the buildings with the slab method, in one compiled call
    (:func:`coopnav_env.sim._kernels.line_of_sight`; a file city's extruded polygons go
    through their own kernel). Because every box stands on the ground and a ray with positive
    elevation only rises, the 3-D slab test reduces to the 2-D slab test of the horizontal ray
    against the footprint plus a height test: the ray hits the box if and only if it enters the
    footprint, at horizontal distance ``t_in >= 0``, no higher than the roof,
    ``z_rx + t_in * tan(el) <= roof``. ``tests/sim`` checks this against a brute-force 3-D
    ray/face intersection. Receivers are assumed at ``z >= 0``.

    Parameters
    ----------
    buildings : Buildings
        The city's boxes.
    pos_enu_m : array_like, shape (n_rx, 3)
        Receiver positions in ENU [m].
    dir_enu : array_like, shape (n_sv, 3)
        Directions from the receiver to each satellite in ENU (any non-zero length; normalised
        here). Satellites are treated as infinitely far away.

    Returns
    -------
    ndarray of bool, shape (n_rx, n_sv)
        True when the ray hits no building. Directions with elevation <= 0 are never visible;
        a receiver strictly inside a building sees nothing. A ray that only grazes an edge or
        a face counts as blocked.

    Notes
    -----
    (Receiver, building) pairs that cannot block any ray are culled first (buildings not
    taller than the receiver, and buildings whose footprint is farther than
    ``(roof - z_rx) / tan(el_min)``, the horizontal distance at which the lowest ray has
    already risen above the roof); then, per remaining pair, only the satellites low enough to
    pass under the roof at the footprint's nearest point, ``tan(el) < (roof - z_rx) / dist``,
    are tested (typically a tenth of all triples). Memory: two ``(n_rx, n_sv)`` boolean arrays.
    ``tests/sim/oracles.py`` holds a numpy formulation of the same test, which the tests
    compare with the kernel bit for bit.
    """
    pos = _as_points(pos_enu_m, "pos_enu_m")
    return _trace_line_of_sight(buildings, pos, sky_directions(dir_enu))


@dataclass(frozen=True, eq=False)
class SkyDirections:
    """Satellite directions prepared for :func:`line_of_sight` (see :func:`sky_directions`).

    They depend on the satellites only, not on the receivers or the city, so a caller that
    traces the same sky from many positions or cities (the world at one GNSS epoch, copies
    of an environment at the same time) prepares them once.
    """

    n_sv: int
    up: BoolArray  # (n_sv,) elevation > 0
    order: NDArray[np.intp]  # rising satellites by increasing cot(el)
    cot_s: FloatArray  # (n_up,) sorted cot(el): horizontal distance per metre of climb
    h_dir: FloatArray  # (n_up, 2) sorted horizontal unit directions (0 at the zenith)


def sky_directions(dir_enu: ArrayLike) -> SkyDirections:
    """Normalise and sort satellite directions, shape ``(n_sv, 3)``, for :func:`line_of_sight`."""
    u = _unit_directions(dir_enu)
    up = u[:, 2] > 0.0
    # satellites sorted by decreasing elevation (increasing cot(el))
    u_up = u[up]
    cos_el = np.hypot(u_up[:, 0], u_up[:, 1])
    cot_el = cos_el / u_up[:, 2]  # horizontal distance per metre of climb
    order = np.argsort(cot_el, kind="stable")
    with np.errstate(divide="ignore", invalid="ignore"):
        h_dir = np.where(cos_el[:, None] > 0.0, u_up[:, :2] / cos_el[:, None], 0.0)[order]
    for arr in (up, order, h_dir):
        arr.setflags(write=False)
    return SkyDirections(u.shape[0], up, order, _readonly(cot_el[order]), h_dir)


def _trace_line_of_sight(buildings: Buildings, pos: FloatArray, sky: SkyDirections) -> BoolArray:
    """:func:`line_of_sight` from validated receivers and prepared directions: boxes in one
    compiled call (:func:`coopnav_env.sim._kernels.line_of_sight`), a file city's extruded
    polygons through their own kernel."""
    if not isinstance(buildings, Buildings):  # extruded polygons (sim.file_city)
        return buildings.trace_line_of_sight(pos, sky)
    return _kernels.line_of_sight(
        np.ascontiguousarray(pos, dtype=float),
        buildings.min_m,
        buildings.max_m,
        sky.up,
        sky.order,
        sky.cot_s,
        sky.h_dir,
    )


def ray_directions(az_deg: ArrayLike) -> FloatArray:
    """Horizontal unit vectors ``(sin az, cos az)`` (n_az, 2) of azimuths [deg], read-only:
    the rays :func:`sky_and_walls` traces (and the compiled sweeps take).

    Components below 1e-15 are exact zeros, so that the slab test treats the cardinal
    directions exactly. Cached by value (an environment asks for the same azimuths each step).
    A non-finite azimuth or an array that is not one-dimensional raises ``ValueError``.
    """
    az = np.asarray(az_deg, dtype=np.float64)
    key = az.tobytes() if az.ndim == 1 else None
    hit = _RAY_DIRECTIONS.get(key) if key is not None else None
    if hit is not None:
        return hit
    if az.ndim != 1:
        raise ValueError(f"az_deg must have shape (n_az,), got {az.shape}")
    if not np.all(np.isfinite(az)):
        raise ValueError("az_deg must be finite")
    az_rad = np.radians(az)
    dir_xy = np.stack([np.sin(az_rad), np.cos(az_rad)], axis=1)  # (n_az, 2)
    out = np.where(np.abs(dir_xy) < 1e-15, 0.0, dir_xy)
    out.setflags(write=False)
    if len(_RAY_DIRECTIONS) < 64:
        _RAY_DIRECTIONS[key] = out
    return out


_RAY_DIRECTIONS: dict[bytes, FloatArray] = {}


def mask_elevation_deg(buildings: Buildings, pos_enu_m: ArrayLike, az_deg: ArrayLike) -> FloatArray:
    """Elevation of the building skyline seen from each receiver along each azimuth.

    For a horizontal direction of azimuth ``az`` the skyline elevation is the highest angle
    under which a roof edge is seen: ``max_b atan((h_b - z_rx) / t_b)`` over the buildings
    whose footprint the horizontal ray enters, at horizontal distance ``t_b``. Because every
    box stands on the ground and rays only rise, a satellite at ``(az, el)`` is blocked by the
    3-D model (:func:`line_of_sight`) exactly when ``el < mask`` (up to ties on the boundary),
    which makes this the "sky openness" observation of a navigation agent.

    Parameters
    ----------
    buildings : Buildings
    pos_enu_m : array_like, shape (n, 3)
        Receiver positions in ENU [m].
    az_deg : array_like, shape (n_az,)
        Azimuths, clockwise from North [deg].

    Returns
    -------
    ndarray, shape (n, n_az)
        Skyline elevation [deg], in [0, 90]: 0 where no building taller than the receiver lies
        along the azimuth, 90 for a receiver inside a building.
    """
    return sky_and_walls(buildings, pos_enu_m, az_deg)[0]


def sky_and_walls(
    buildings: Buildings, pos_enu_m: ArrayLike, az_deg: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """:func:`mask_elevation_deg` and :func:`wall_distance_m` from one horizontal sweep.

    Both trace the same horizontal rays (receivers x azimuths) through the same footprints:
    one compiled sweep (:func:`coopnav_env.sim._kernels.sky_and_walls`; a file city's
    extruded polygons through their own kernel) returns exactly what the two functions return.
    """
    if not isinstance(buildings, Buildings):  # extruded polygons (sim.file_city)
        return buildings.sky_and_walls(pos_enu_m, az_deg)
    pos = _as_points(pos_enu_m, "pos_enu_m")
    tan_max, dist = _kernels.sky_and_walls(
        np.ascontiguousarray(pos), ray_directions(az_deg), buildings.min_m, buildings.max_m
    )
    return np.degrees(np.arctan(tan_max)), dist


def wall_distance_m(buildings: Buildings, pos_enu_m: ArrayLike, az_deg: ArrayLike) -> FloatArray:
    """Horizontal distance to the nearest building wall along each azimuth (a range sensor).

    The ray starts at the receiver and runs horizontally at its altitude toward azimuth
    ``az``; it hits a building when it enters the building's footprint while the receiver is
    below the roof (``z < roof``: a lower building is overflown, exactly as the collision test
    of :mod:`coopnav_env.sim.swarm` sees it). The distance is measured to the footprint edge.

    Parameters
    ----------
    buildings : Buildings
    pos_enu_m : array_like, shape (n, 3)
        Receiver positions in ENU [m].
    az_deg : array_like, shape (n_az,)
        Azimuths, clockwise from North [deg].

    Returns
    -------
    ndarray, shape (n, n_az)
        Distance [m], >= 0: ``inf`` where the ray meets no building taller than the receiver,
        0 for a receiver inside a building.
    """
    return sky_and_walls(buildings, pos_enu_m, az_deg)[1]


# --------------------------------------------------------------------------------------------
# the paper's analytic canyon mask (Eq. 25)
# --------------------------------------------------------------------------------------------


def _in_intervals_deg(az_deg: FloatArray, intervals: tuple[tuple[float, float], ...]) -> BoolArray:
    """Whether each azimuth lies in one of the clockwise intervals ``(start, end)`` [deg]."""
    az = np.asarray(az_deg, dtype=np.float64)
    if not intervals:
        return np.zeros(az.shape, dtype=bool)
    iv = np.asarray(intervals, dtype=np.float64)  # (n_gap, 2)
    start = iv[:, 0]
    width = np.mod(iv[:, 1] - start, 360.0)
    offset = np.mod(az[..., None] - start, 360.0)
    return np.any(offset <= width, axis=-1)


@dataclass(frozen=True)
class CanyonMask:
    """The paper's analytic urban-canyon elevation mask (Eq. 25) with gaps.

    ``theta_m(phi) = |atan(h/d * sin(phi))|`` (Eq. 25), where ``phi`` is the satellite azimuth
    measured from the street axis, ``h`` the height of the buildings above the receiver and
    ``d`` the horizontal distance to their walls. In absolute azimuth ``az`` (clockwise from
    North) this is ``theta_m(az) = |atan(h/d * sin(az - street_azimuth))|``: 0 along the street,
    ``atan(h/d)`` across it. This is exactly the skyline of two infinitely long walls of height
    ``h`` at distance ``d`` on both sides (a ray of azimuth ``phi`` meets the wall after a
    horizontal distance ``d / |sin(phi)|``).

    Parameters
    ----------
    h_over_d : float, default sqrt(3)
        Ratio ``h / d`` >= 0 (the paper's Figure 6 uses sqrt(3), a 60 deg mask across the
        street).
    street_azimuth_deg : float, default 0.0
        Azimuth of the street axis, clockwise from North, in [0, 360) [deg]. 0 is a
        north-south street.
    gaps_deg : tuple of (float, float), default :data:`DEFAULT_CANYON_GAPS_DEG`
        Absolute azimuth intervals ``(start, end)`` [deg], each bound in [0, 360], read
        clockwise from ``start`` to ``end`` (``(350, 10)`` wraps through North), in which a gap
        between buildings leaves the mask at 0 deg. The paper adds gaps "due to the finite
        width of the surrounding buildings" without saying where; see
        :data:`DEFAULT_CANYON_GAPS_DEG` for the default's rationale. Pass ``()`` for none.
    """

    h_over_d: float = math.sqrt(3.0)
    street_azimuth_deg: float = 0.0
    gaps_deg: tuple[tuple[float, float], ...] = DEFAULT_CANYON_GAPS_DEG

    def __post_init__(self) -> None:
        owner = "CanyonMask"
        object.__setattr__(self, "h_over_d", _check_real(owner, "h_over_d", self.h_over_d, 0.0))
        az = _check_real(
            owner, "street_azimuth_deg", self.street_azimuth_deg, 0.0, 360.0, hi_open=True
        )
        object.__setattr__(self, "street_azimuth_deg", az)
        object.__setattr__(self, "gaps_deg", _validate_gaps(owner, self.gaps_deg))

    def mask_elevation_deg(self, az_deg: ArrayLike) -> FloatArray:
        """Mask elevation for each azimuth.

        Parameters
        ----------
        az_deg : array_like, any shape
            Satellite azimuths, clockwise from North [deg].

        Returns
        -------
        ndarray, same shape as ``az_deg``
            Mask elevation [deg] in ``[0, atan(h/d)]``; 0 inside a gap.
        """
        az = np.asarray(az_deg, dtype=np.float64)
        phi_rad = np.radians(az - self.street_azimuth_deg)
        theta = np.abs(np.degrees(np.arctan(self.h_over_d * np.sin(phi_rad))))
        return np.where(_in_intervals_deg(az, self.gaps_deg), 0.0, theta)

    def in_gap(self, az_deg: ArrayLike) -> BoolArray:
        """Whether each azimuth [deg] falls in one of the gaps; same shape as ``az_deg``."""
        return _in_intervals_deg(np.asarray(az_deg, dtype=np.float64), self.gaps_deg)

    def visible(self, az_deg: ArrayLike, el_deg: ArrayLike) -> BoolArray:
        """Whether a satellite is above the mask.

        Parameters
        ----------
        az_deg, el_deg : array_like, broadcastable
            Satellite azimuth (clockwise from North) and elevation [deg].

        Returns
        -------
        ndarray of bool, the broadcast shape
            True when ``el > mask(az)`` (hence also ``el > 0``).
        """
        el = np.asarray(el_deg, dtype=np.float64)
        return el > self.mask_elevation_deg(az_deg)


def _validate_gaps(owner: str, gaps: Any) -> tuple[tuple[float, float], ...]:
    try:
        items = tuple(tuple(g) for g in gaps)
    except TypeError as exc:
        raise ValueError(
            f"{owner}.gaps_deg must be a tuple of (start, end) azimuth pairs, got {gaps!r}"
        ) from exc
    out = []
    for g in items:
        if len(g) != 2:
            raise ValueError(f"{owner}.gaps_deg entries must be (start, end) pairs, got {g!r}")
        a = _check_real(owner, "gaps_deg", g[0], 0.0, 360.0)
        b = _check_real(owner, "gaps_deg", g[1], 0.0, 360.0)
        if math.isclose(a % 360.0, b % 360.0):
            raise ValueError(f"{owner}.gaps_deg interval {g!r} is empty (start == end)")
        out.append((a, b))
    return tuple(out)


# --------------------------------------------------------------------------------------------
# NLOS reception
# --------------------------------------------------------------------------------------------


def draw_nlos(
    rng: np.random.Generator,
    blocked: ArrayLike,
    probability: float,
    bias_mean_m: float,
    bias_floor_m: float = 1.0,
) -> tuple[BoolArray, FloatArray]:
    """Non-line-of-sight reception of blocked satellites through reflections.

    A blocked satellite is still received, through a reflection, with the given probability;
    its pseudorange then carries a positive bias ``bias_floor_m + Exp(bias_mean_m)`` (the
    reflected path is always longer than the direct one). Line-of-sight satellites are always
    received with zero bias.

    Parameters
    ----------
    rng : numpy.random.Generator
    blocked : array_like of bool, shape (n_rx, n_sv)
        True where the direct path is blocked (e.g. ``~line_of_sight(...)``).
    probability : float
        Probability in [0, 1] that a blocked satellite is received by reflection.
    bias_mean_m : float
        Mean of the exponential part of the NLOS range bias, >= 0 [m].
    bias_floor_m : float, default 1.0
        Smallest NLOS bias, >= 0 [m]; the mean bias is ``bias_floor_m + bias_mean_m``.

    Returns
    -------
    received : ndarray of bool, shape (n_rx, n_sv)
        ``~blocked`` or (``blocked`` and received by reflection).
    bias_m : ndarray, shape (n_rx, n_sv)
        Range bias [m]: 0 for LOS and for satellites not received.

    Notes
    -----
    The uniform and exponential draws are made for the full ``(n_rx, n_sv)`` arrays whatever
    the mask, so that the random stream does not depend on the geometry.
    """
    p = _check_real("draw_nlos", "probability", probability, 0.0, 1.0)
    mean = _check_real("draw_nlos", "bias_mean_m", bias_mean_m, 0.0)
    floor = _check_real("draw_nlos", "bias_floor_m", bias_floor_m, 0.0)
    blk = np.asarray(blocked, dtype=bool)
    if blk.ndim != 2:
        raise ValueError(f"blocked must have shape (n_rx, n_sv), got {blk.shape}")
    u = rng.random(blk.shape)
    e = rng.standard_exponential(blk.shape)
    nlos = blk & (u < p)
    received = ~blk | nlos
    bias_m = np.where(nlos, floor + mean * e, 0.0)
    return received, bias_m


# --------------------------------------------------------------------------------------------
# cities
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CityConfig:
    """A Manhattan-like grid of rectangular blocks separated by streets.

    The city is ``n_blocks_x`` x ``n_blocks_y`` square blocks of side ``block_size_m``,
    separated and surrounded by streets of width ``street_width_m``, centred on the ENU
    origin. A fraction of the blocks is left empty (open squares); every other block is split
    along a random axis into ``buildings_per_block`` buildings of random widths separated by
    ``building_gap_m`` wide alleys.

    Parameters
    ----------
    n_blocks_x, n_blocks_y : int, default 6
        Number of blocks along East and North, in [1, 200].
    block_size_m : float, default 60.0
        Side of a block, in (0, 10000] [m].
    street_width_m : float, default 20.0
        Width of every street (kerb to kerb: buildings stand at the block edge), in
        (0, 1000] [m].
    buildings_per_block : int, default 2
        Buildings per non-empty block, in [1, 50].
    building_gap_m : float, default 4.0
        Width of the alley between two buildings of one block, >= 0 [m]; every building must
        keep at least 1 m of width on average.
    height_mean_m, height_std_m : float, default 45.0, 20.0
        Mean and standard deviation of the normal distribution that roof heights are drawn
        from before truncation to ``[height_min_m, height_max_m]`` [m] (truncated normal by
        rejection; the truncated mean is therefore slightly different). ``height_std_m = 0``
        gives equal heights. The mean must lie in ``[height_min_m, height_max_m]``.
    height_min_m, height_max_m : float, default 10.0, 150.0
        Truncation bounds, ``0 < height_min_m < height_max_m <= 1000`` [m].
    open_square_fraction : float, default 0.1
        Fraction of the blocks left empty, in [0, 1]; the count is rounded to the nearest
        integer and the empty blocks are drawn at random.
    """

    n_blocks_x: int = 6
    n_blocks_y: int = 6
    block_size_m: float = 60.0
    street_width_m: float = 20.0
    buildings_per_block: int = 2
    building_gap_m: float = 4.0
    height_mean_m: float = 45.0
    height_std_m: float = 20.0
    height_min_m: float = 10.0
    height_max_m: float = 150.0
    open_square_fraction: float = 0.1

    def __post_init__(self) -> None:
        o = "CityConfig"
        _check_int(o, "n_blocks_x", self.n_blocks_x, 1, 200)
        _check_int(o, "n_blocks_y", self.n_blocks_y, 1, 200)
        _check_real(o, "block_size_m", self.block_size_m, 0.0, 10_000.0, lo_open=True)
        _check_real(o, "street_width_m", self.street_width_m, 0.0, 1000.0, lo_open=True)
        k = _check_int(o, "buildings_per_block", self.buildings_per_block, 1, 50)
        max_gap = (self.block_size_m - k * 1.0) / (k - 1) if k > 1 else math.inf
        _check_real(o, "building_gap_m", self.building_gap_m, 0.0, max(max_gap, 0.0))
        _check_real(o, "height_min_m", self.height_min_m, 0.0, 1000.0, lo_open=True)
        _check_real(o, "height_max_m", self.height_max_m, self.height_min_m, 1000.0, lo_open=True)
        _check_real(o, "height_mean_m", self.height_mean_m, self.height_min_m, self.height_max_m)
        _check_real(o, "height_std_m", self.height_std_m, 0.0, 1000.0)
        _check_real(o, "open_square_fraction", self.open_square_fraction, 0.0, 1.0)


@dataclass(frozen=True, eq=False)
class City:
    """A city: buildings plus the street layout that navigation tasks need.

    Parameters
    ----------
    buildings : Buildings
    extent_m : tuple of 4 float
        ``(x_min, x_max, y_min, y_max)`` of the city in ENU [m]; every building lies inside.
    street_centres_x_m : ndarray, shape (n_sx,)
        East coordinates of the north-south street centre lines [m]; each runs from
        ``y_min`` to ``y_max``.
    street_centres_y_m : ndarray, shape (n_sy,)
        North coordinates of the east-west street centre lines [m]; each runs from ``x_min``
        to ``x_max``.
    open_squares : ndarray, shape (k, 2)
        East/North centres of the empty blocks (open squares) [m].
    config : CityConfig or None
        The configuration a generated city came from; None for hand-made cities such as
        :func:`canyon_city`.
    street_width_m : float or None
        Width of the streets [m]; taken from ``config`` when None.
    canyon_mask : CanyonMask or None
        For :func:`canyon_city`, the analytic Eq. 25 mask equivalent to the boxes as seen from
        the street centre line at the canyon's reference altitude; None otherwise.
    """

    buildings: Buildings
    extent_m: tuple[float, float, float, float]
    street_centres_x_m: FloatArray
    street_centres_y_m: FloatArray
    open_squares: FloatArray
    config: CityConfig | None = None
    street_width_m: float | None = None
    canyon_mask: CanyonMask | None = None

    def __post_init__(self) -> None:
        ext = tuple(float(v) for v in self.extent_m)
        if len(ext) != 4 or not (ext[0] < ext[1] and ext[2] < ext[3]):
            raise ValueError(
                f"City.extent_m must be (x_min, x_max, y_min, y_max) with x_min < x_max and "
                f"y_min < y_max, got {self.extent_m!r}"
            )
        object.__setattr__(self, "extent_m", ext)
        for name in ("street_centres_x_m", "street_centres_y_m"):
            arr = np.array(getattr(self, name), dtype=np.float64).reshape(-1)
            object.__setattr__(self, name, _readonly(arr))
        sq = np.array(self.open_squares, dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "open_squares", _readonly(sq))
        width = self.street_width_m
        if width is None:
            if self.config is None:
                raise ValueError("City.street_width_m is required when City.config is None")
            width = self.config.street_width_m
        object.__setattr__(
            self,
            "street_width_m",
            _check_real("City", "street_width_m", width, 0.0, math.inf, lo_open=True),
        )

    @classmethod
    def _of_parts(
        cls,
        buildings: Buildings,
        extent_m: tuple[float, float, float, float],
        street_centres_x_m: FloatArray,
        street_centres_y_m: FloatArray,
        open_squares: FloatArray,
        config: CityConfig,
        street_width_m: float,
    ) -> City:
        """A city of parts that are valid by construction (:func:`generate_city`'s: float
        extent, read-only float64 arrays, a checked street width), without the checks and
        copies of the constructor."""
        out = object.__new__(cls)
        for name, value in (
            ("buildings", buildings),
            ("extent_m", tuple(float(v) for v in extent_m)),
            ("street_centres_x_m", _readonly(street_centres_x_m)),
            ("street_centres_y_m", _readonly(street_centres_y_m)),
            ("open_squares", _readonly(open_squares)),
            ("config", config),
            ("street_width_m", float(street_width_m)),
            ("canyon_mask", None),
        ):
            object.__setattr__(out, name, value)
        return out

    def is_inside_building(self, pos_enu_m: ArrayLike) -> BoolArray:
        """Whether each point (shape ``(n, 3)``, ENU [m]) is inside a building; ``(n,)`` bool."""
        return is_inside_building(self.buildings, pos_enu_m)

    def line_of_sight(self, pos_enu_m: ArrayLike, dir_enu: ArrayLike) -> BoolArray:
        """:func:`line_of_sight` against this city's buildings; ``(n_rx, n_sv)`` bool."""
        return line_of_sight(self.buildings, pos_enu_m, dir_enu)

    def mask_elevation_deg(self, pos_enu_m: ArrayLike, az_deg: ArrayLike) -> FloatArray:
        """:func:`mask_elevation_deg` against this city's buildings; ``(n, n_az)`` [deg]."""
        return mask_elevation_deg(self.buildings, pos_enu_m, az_deg)

    def wall_distance_m(self, pos_enu_m: ArrayLike, az_deg: ArrayLike) -> FloatArray:
        """:func:`wall_distance_m` against this city's buildings; ``(n, n_az)`` [m]."""
        return wall_distance_m(self.buildings, pos_enu_m, az_deg)

    def sky_and_walls(
        self, pos_enu_m: ArrayLike, az_deg: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """:func:`sky_and_walls`: skyline [deg] and wall distances [m], each ``(n, n_az)``."""
        return sky_and_walls(self.buildings, pos_enu_m, az_deg)

    def random_street_points(
        self,
        rng: np.random.Generator,
        n: int,
        altitude_m: float = 10.0,
        margin_m: float = 2.0,
    ) -> FloatArray:
        """Uniformly random points on the street network.

        A street is drawn with probability proportional to its length, then a position
        uniformly along it and across it, at least ``margin_m`` from its kerbs and from the
        city's edge. Streets hold no building, so the points are free space.

        Parameters
        ----------
        rng : numpy.random.Generator
        n : int
            Number of points, >= 0.
        altitude_m : float, default 10.0
            Height of the points above the ground [m].
        margin_m : float, default 2.0
            Clearance from the kerbs, in ``[0, street_width_m / 2)`` [m].

        Returns
        -------
        ndarray, shape (n, 3)
            Points in ENU [m].
        """
        n = _check_int("random_street_points", "n", n, 0, 10**9)
        alt = _check_real("random_street_points", "altitude_m", altitude_m, 0.0)
        w_half = float(self.street_width_m) / 2.0
        margin = _check_real(
            "random_street_points", "margin_m", margin_m, 0.0, w_half, hi_open=True
        )
        x0, x1, y0, y1 = self.extent_m
        cx, cy = self.street_centres_x_m, self.street_centres_y_m
        if cx.size + cy.size == 0:
            raise ValueError("City has no streets to sample from")
        lengths = np.r_[np.full(cx.size, y1 - y0), np.full(cy.size, x1 - x0)]
        street = rng.choice(lengths.size, size=n, p=lengths / lengths.sum())
        along01 = rng.random(n)
        across = rng.uniform(-(w_half - margin), w_half - margin, size=n)
        ns = street < cx.size
        centre = np.r_[cx, cy][street]
        y_along = y0 + margin + along01 * (y1 - y0 - 2.0 * margin)
        x_along = x0 + margin + along01 * (x1 - x0 - 2.0 * margin)
        x = np.where(ns, centre + across, x_along)
        y = np.where(ns, y_along, centre + across)
        return np.stack([x, y, np.full(n, alt)], axis=1)

    def random_street_point(
        self, rng: np.random.Generator, altitude_m: float = 10.0, margin_m: float = 2.0
    ) -> FloatArray:
        """One random street point, shape ``(3,)`` ENU [m]; see :meth:`random_street_points`."""
        return self.random_street_points(rng, 1, altitude_m, margin_m)[0]


def _truncated_normal(
    rng: np.random.Generator, n: int, mean: float, std: float, lo: float, hi: float
) -> FloatArray:
    """``n`` draws of N(mean, std^2) truncated to [lo, hi], by rejection (mean in [lo, hi])."""
    if std == 0.0:
        return np.full(n, mean)
    out = np.empty(n)
    todo = np.arange(n)
    for _ in range(64):
        if todo.size == 0:
            return out
        x = rng.normal(mean, std, size=todo.size)
        ok = (x >= lo) & (x <= hi)
        out[todo[ok]] = x[ok]
        todo = todo[~ok]
    # Only reached when std >> hi - lo, where the truncated normal is nearly uniform.
    out[todo] = rng.uniform(lo, hi, size=todo.size)
    return out


@functools.lru_cache(maxsize=64)
def _grid_layout(
    n_blocks_x: int, n_blocks_y: int, block_m: float, street_m: float
) -> tuple[float, float, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """What a grid city's size fixes (:func:`generate_city`): the south-west corner
    ``x0, y0`` [m], the street centre lines ``street_x (n_x + 1,)``, ``street_y (n_y + 1,)``,
    the west and south edges of every block ``blk_x0, blk_y0 (n_x n_y,)`` and their pairs
    ``(n_x n_y, 2)`` [m], all read-only."""
    pitch = block_m + street_m
    size_x = n_blocks_x * block_m + (n_blocks_x + 1) * street_m
    size_y = n_blocks_y * block_m + (n_blocks_y + 1) * street_m
    x0, y0 = -size_x / 2.0, -size_y / 2.0
    street_x = x0 + street_m / 2.0 + pitch * np.arange(n_blocks_x + 1)
    street_y = y0 + street_m / 2.0 + pitch * np.arange(n_blocks_y + 1)
    ix, iy = np.unravel_index(np.arange(n_blocks_x * n_blocks_y), (n_blocks_x, n_blocks_y))
    blk_x0 = x0 + street_m + pitch * ix  # west edge of each block
    blk_y0 = y0 + street_m + pitch * iy  # south edge of each block
    blk_xy = np.stack([blk_x0, blk_y0], axis=1)
    arrays = (street_x, street_y, blk_x0, blk_y0, blk_xy)
    return (x0, y0, *(_readonly(a) for a in arrays))


def generate_city(config: CityConfig, rng: np.random.Generator) -> City:
    """Generate a random grid city.

    Parameters
    ----------
    config : CityConfig
    rng : numpy.random.Generator
        Source of all randomness; the same seed gives the same city.

    Returns
    -------
    City
        Blocks between streets; the street centre lines include the streets around the city,
        so the extent is ``n * block + (n + 1) * street`` on each axis, centred on the origin.
        Buildings stand exactly on the block edges (no setback) and never on a street.
    """
    c = config
    block, k = c.block_size_m, c.buildings_per_block
    x0, y0, street_x, street_y, blk_x0, blk_y0, blk_xy = _grid_layout(
        c.n_blocks_x, c.n_blocks_y, c.block_size_m, c.street_width_m
    )

    n_blocks = c.n_blocks_x * c.n_blocks_y
    n_open = round(c.open_square_fraction * n_blocks)
    open_idx = rng.choice(n_blocks, size=n_open, replace=False)
    built = np.ones(n_blocks, dtype=bool)
    built[open_idx] = False
    open_squares = blk_xy[np.sort(open_idx)] + block / 2.0

    m = n_blocks - n_open
    bx0, by0 = blk_x0[built], blk_y0[built]
    split_along_x = rng.integers(0, 2, size=m).astype(bool)  # strips stacked along East
    weights = rng.uniform(0.6, 1.4, size=(m, k))
    heights = _truncated_normal(
        rng, m * k, c.height_mean_m, c.height_std_m, c.height_min_m, c.height_max_m
    )
    # the boxes' corners (x_min, y_min, 0) and (x_max, y_max, height), building j of block b
    # in row b k + j; valid by construction (positive strips inside the block, heights in the
    # configuration's range), so not checked again
    lo, hi = _kernels.grid_boxes(
        bx0,
        by0,
        split_along_x,
        weights,
        weights.sum(axis=1),
        heights,
        float(block),
        float(block - (k - 1) * c.building_gap_m),
        float(c.building_gap_m),
    )
    return City._of_parts(
        Buildings._of_arrays(lo, hi),
        (x0, -x0, y0, -y0),
        street_x,
        street_y,
        open_squares,
        config,
        float(c.street_width_m),
    )


def _gap_y_interval(az_start: float, az_end: float, d_m: float) -> tuple[float, float]:
    """North interval of a wall at distance ``d_m`` seen from the origin under an azimuth gap."""
    ys = [
        d_m * math.cos(math.radians(a)) / abs(math.sin(math.radians(a))) for a in (az_start, az_end)
    ]
    return min(ys), max(ys)


def canyon_city(
    h_over_d: float = math.sqrt(3.0),
    street_width_m: float = 20.0,
    length_m: float = 400.0,
    gaps_deg: tuple[tuple[float, float], ...] = DEFAULT_CANYON_GAPS_DEG,
    building_depth_m: float = 20.0,
    reference_altitude_m: float = 15.0,
) -> City:
    """The paper's single straight urban canyon (Section 4.1, Eq. 25, Figure 5) as boxes.

    Two rows of buildings line a north-south street centred on ``x = 0`` from
    ``y = -length_m / 2`` to ``length_m / 2``. Their walls face the street at
    ``d = street_width_m / 2`` and their roofs stand ``h = h_over_d * d`` above
    ``reference_altitude_m``, so that a receiver on the street centre line at the reference
    altitude sees the skyline of Eq. 25 with the given ``h/d``. A receiver at altitude ``z``
    on the centre line sees ``h/d = (roof - z) / d`` instead.

    Parameters
    ----------
    h_over_d : float, default sqrt(3)
        Ratio h/d at the reference altitude, in (0, 100].
    street_width_m : float, default 20.0
        Wall-to-wall width of the street, in (0, 1000] [m].
    length_m : float, default 400.0
        Length of the canyon, in (0, 100000] [m].
    gaps_deg : tuple of (float, float), default :data:`DEFAULT_CANYON_GAPS_DEG`
        Gaps between buildings given as absolute azimuth intervals ``(start, end)`` [deg] as
        seen from the origin, exactly as :attr:`CanyonMask.gaps_deg`; each interval must lie
        on one side of the street, ``0 < start < end < 180`` (east row) or
        ``180 < start < end < 360`` (west row). The row is cut where the wall is seen under
        those azimuths, i.e. along ``y = d cos(az) / |sin(az)|``, so the 3-D gaps match the
        analytic ones in azimuth. (Seen through a gap at low elevation, the side walls of the
        neighbouring buildings, ``building_depth_m`` deep, narrow it a little: the 3-D gap is
        the analytic one only for rays that clear those side walls.)
    building_depth_m : float, default 20.0
        Depth of the building rows (across the street), in (0, 1000] [m].
    reference_altitude_m : float, default 15.0
        Altitude at which the canyon has exactly ``h_over_d`` on its centre line, in
        [0, 1000] [m]. The default lies inside the default UAV altitude band (5-30 m) and makes
        the default roofs 32.3 m high, above the band, so that UAVs cannot overfly them.

    Returns
    -------
    City
        With ``config=None``, ``street_centres_x_m=[0]``, no east-west street, no open square
        and ``canyon_mask`` set to the matching :class:`CanyonMask` (street azimuth 0).
    """
    o = "canyon_city"
    h_over_d = _check_real(o, "h_over_d", h_over_d, 0.0, 100.0, lo_open=True)
    w = _check_real(o, "street_width_m", street_width_m, 0.0, 1000.0, lo_open=True)
    length = _check_real(o, "length_m", length_m, 0.0, 100_000.0, lo_open=True)
    depth = _check_real(o, "building_depth_m", building_depth_m, 0.0, 1000.0, lo_open=True)
    ref = _check_real(o, "reference_altitude_m", reference_altitude_m, 0.0, 1000.0)
    gaps = _validate_gaps(o, gaps_deg)
    d = w / 2.0
    roof = ref + h_over_d * d

    cut: dict[str, list[tuple[float, float]]] = {"east": [], "west": []}
    for a, b in gaps:
        if 0.0 < a < b < 180.0:
            cut["east"].append(_gap_y_interval(a, b, d))
        elif 180.0 < a < b < 360.0:
            cut["west"].append(_gap_y_interval(a, b, d))
        else:
            raise ValueError(
                f"{o}.gaps_deg interval {(a, b)!r} must lie on one side of the street: "
                "0 < start < end < 180 or 180 < start < end < 360"
            )

    boxes: list[tuple[float, float, float, float, float]] = []
    for side, (xa, xb) in (("east", (d, d + depth)), ("west", (-d - depth, -d))):
        pieces = [(-length / 2.0, length / 2.0)]
        for g0, g1 in cut[side]:
            nxt = []
            for p0, p1 in pieces:
                if g1 <= p0 or g0 >= p1:
                    nxt.append((p0, p1))
                    continue
                if g0 > p0:
                    nxt.append((p0, g0))
                if g1 < p1:
                    nxt.append((g1, p1))
            pieces = nxt
        boxes.extend((xa, p0, xb, p1, roof) for p0, p1 in pieces if p1 - p0 > 1e-9)

    half_x = d + depth
    return City(
        buildings=Buildings.from_boxes(boxes),
        extent_m=(-half_x, half_x, -length / 2.0, length / 2.0),
        street_centres_x_m=np.array([0.0]),
        street_centres_y_m=np.zeros(0),
        open_squares=np.zeros((0, 2)),
        config=None,
        street_width_m=w,
        canyon_mask=CanyonMask(h_over_d=h_over_d, street_azimuth_deg=0.0, gaps_deg=gaps),
    )
