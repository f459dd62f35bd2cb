"""A city from a file: building footprints from GeoJSON or OpenStreetMap, extruded to their
roof heights.

What it reads
-------------
A GeoJSON ``FeatureCollection`` (RFC 7946: WGS 84 longitude/latitude in degrees) whose
features are ``Polygon`` or ``MultiPolygon`` building footprints, the form OpenStreetMap
extracts and the open building datasets are shared in. Each polygon of a ``MultiPolygon``
becomes its own building; interior rings (courtyards) are kept. Other geometry types
(points, lines) are skipped and counted. OpenStreetMap ``.osm``/``.osm.pbf`` files
(``osm:PATH``) are read into such features by :mod:`coopnav_env.sim.osm_city` and then
checked here in the same way. A ``bbox`` ``(south, west, north, east)`` [deg] keeps the
features whose footprint's vertex mean lies inside. The roof height of a feature comes from,
in order:

1. ``properties["height"]``: metres, a number or a string such as ``"12"``, ``"12 m"`` or
   ``"40 ft"`` (feet are converted);
2. ``properties["building:levels"]`` times ``storey_height_m`` (default
   :data:`STOREY_HEIGHT_M`, 3.0 m per storey, in :data:`STOREY_HEIGHT_RANGE_M`); ``"5.5"``
   reads as 5.5 storeys;
3. ``default_height_m`` (the environment uses :data:`DEFAULT_HEIGHT_M`, 10 m, in
   :data:`DEFAULT_HEIGHT_RANGE_M`), counted in :attr:`FileCity.n_default_height` and reported
   in one warning (which says so when most buildings got it); with ``default_height_m=None``
   a feature without a height is an error.

A list (``"5;6"``, OpenStreetMap's separator) or a range (``"5-6"``) of heights or levels
reads as its largest value: the tallest part of a building is what blocks a satellite.

Repairs
-------
With ``repair=True`` (the default) what can be repaired is, and one warning counts it
(:class:`CityReport`): an open ring is closed; a ring that crosses or touches itself, or runs
through a vertex twice, is made valid with shapely's ``make_valid`` (the ``geo`` extra; without
shapely such a file raises saying to install it), each polygon of the result becoming a
building; a footprint with nothing left (an exterior of fewer than 3 distinct vertices, no area
after repair) is dropped; an unreadable ``height`` or ``building:levels`` is read as missing.
Repeated consecutive vertices are merged in every case. With ``repair=False`` every bad
feature is listed, with its id and what is wrong, in one error.

Coordinates
-----------
Positions must be WGS 84 longitude/latitude degrees. A declared ``crs`` member (the 2008
GeoJSON draft) other than WGS 84 (``CRS84``, ``EPSG:4326``) is refused; so are positions out of
range (saying whether they look projected, in metres, or swapped), footprints spanning more
than :data:`MAX_SPAN_M`, and footprints whose corners are square only with latitude and
longitude swapped (most buildings are rectangular; swapping the axes scales them unequally by
the cosines of two different latitudes and skews their corners: a file is refused when at least
30 % of its corners are right angles swapped and three times fewer as written).

Frames
------
The footprints are converted to the environment's local East-North-Up frame (metres) at a
stated geodetic origin with :mod:`coopnav_env.gnss.frames` (geodetic -> ECEF -> ENU, the
vertices at the origin's ellipsoidal height). The origin is the centroid of all footprint
vertices (mean latitude and longitude) unless the caller gives one. The ground is the plane
``z = 0`` of that frame; over the :data:`MAX_ORIGIN_DISTANCE_M` a file may span, the Earth's
curvature drops the ground by at most ``d^2 / (2 R)`` (8 m at 10 km, 0.08 m at 1 km), which is
neglected. Every vertex farther than ``max_origin_distance_m`` from the origin is an error.

Errors
------
A bad file raises :class:`CityFileError` (a ``ValueError``) naming the file, and every bad
feature (index and ``id`` when it has one), ring and what is wrong: not JSON, not a
FeatureCollection, non-numeric or non-finite coordinates, coordinates that are not WGS 84
degrees (above), a point beyond ``max_origin_distance_m``, no height (with no default); without
``repair`` also an open ring (first position differs from the last), a ring with fewer than 3
distinct vertices, a self-intersecting ring and an unreadable height.

Geometry
--------
:class:`ExtrudedBuildings` holds the polygons as flat edge arrays and traces them with the
compiled loops of :mod:`coopnav_env.sim._polygon_kernels`: line of sight (the same rule as
the box city: a ray is blocked when it is at most roof-high where it first enters a footprint),
the skyline and wall-distance sensors, the inside test and swept-sphere collisions.
:class:`FileCity` is a :class:`~coopnav_env.sim.city.City` whose ``buildings`` are
:class:`ExtrudedBuildings`; the free functions of :mod:`coopnav_env.sim.city`
(:func:`~coopnav_env.sim.city.line_of_sight`, :func:`~coopnav_env.sim.city.sky_and_walls`, ...)
hand such buildings to these methods, so the world uses a file city wherever it uses a grid
city.

Routes
------
A file city has no street grid. Its free space is a grid of square cells
(``grid_resolution_m``, default 5 m) whose centres lie outside every footprint and at least
``clearance_m`` (default 3 m) from every wall; buildings count as obstacles whatever their
height. Cells are 8-connected (a diagonal step needs both of its orthogonal neighbours free).
Start and goal points are drawn in the largest connected piece of the built-up free space:
on streets between buildings, where walls lie within :data:`BUILT_UP_RADIUS_M` (80 m)
in at least 4 of 8 directions, not in the open margin around the footprints, over water or in
a wide park. A route is the A* cheapest path between the cells of its ends, where a cell
nearer a wall than :data:`PREFERRED_CLEARANCE_M` (10 m) costs more to cross (the route keeps
to the middle of the streets) and a cell outside the built-up area costs 21 times as much as
one in a street's middle (the route keeps inside it where it can), shortened by keeping only
the waypoints it cannot cut (a straight leg crosses reachable cells only, none nearer a wall,
or outside the built-up area, than the path it replaces or 10 m, by an exact grid traversal).
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from coopnav_env.gnss.frames import ecef_to_enu, ecef_to_geodetic, enu_to_ecef, geodetic_to_ecef
from coopnav_env.sim import _polygon_kernels as _pk
from coopnav_env.sim._route_kernels import pull_string
from coopnav_env.sim.city import City, SkyDirections, _as_points, _readonly, ray_directions

__all__ = [
    "CLEARANCE_M",
    "DEFAULT_HEIGHT_M",
    "DEFAULT_HEIGHT_RANGE_M",
    "GEOJSON_PREFIX",
    "GRID_RESOLUTION_M",
    "MAX_ORIGIN_DISTANCE_M",
    "OSM_PREFIX",
    "OSM_SUFFIXES",
    "PREFERRED_CLEARANCE_M",
    "STOREY_HEIGHT_M",
    "STOREY_HEIGHT_RANGE_M",
    "CityFileError",
    "CityReport",
    "ExtrudedBuildings",
    "FileCity",
    "city_from_buildings",
    "load_file_city",
    "read_city_footprints",
    "read_geojson_footprints",
    "sample_city_geojson",
    "sample_city_path",
    "write_sample_city",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

GEOJSON_PREFIX: str = "geojson:"
"""Prefix of the environment's ``city`` setting that names a GeoJSON file."""
OSM_PREFIX: str = "osm:"
"""Prefix of the environment's ``city`` setting that names an OpenStreetMap file."""
OSM_SUFFIXES: tuple[str, ...] = (".osm", ".osm.pbf", ".pbf", ".osm.bz2", ".osm.gz")
"""File names read as OpenStreetMap data (:mod:`coopnav_env.sim.osm_city`)."""
STOREY_HEIGHT_M: float = 3.0
"""Height of one storey [m] for features with ``building:levels`` but no ``height``."""
STOREY_HEIGHT_RANGE_M: tuple[float, float] = (2.0, 10.0)
"""Allowed ``storey_height_m`` [m]."""
DEFAULT_HEIGHT_M: float = 10.0
"""Roof height [m] the environment gives a feature with neither ``height`` nor levels."""
DEFAULT_HEIGHT_RANGE_M: tuple[float, float] = (1.0, 500.0)
"""Allowed ``default_height_m`` [m]."""
MAX_ORIGIN_DISTANCE_M: float = 10_000.0
"""Default farthest a footprint vertex may lie from the origin [m] (the flat-ground limit)."""
MAX_SPAN_M: float = 100_000.0
"""Widest extent a city file's footprints may have [m]: wider means coordinates that are not
degrees (metres, another unit) or footprints of places far apart, and is refused as such."""
GRID_RESOLUTION_M: float = 5.0
"""Default cell size of the free-space grid [m]."""
CLEARANCE_M: float = 3.0
"""Default smallest distance from a free cell's centre to a wall [m]."""
PREFERRED_CLEARANCE_M: float = 10.0
"""Clearance from walls a route keeps where the free space allows [m]: cells nearer a wall cost
more to cross (up to 5 times), and a shortcut may not pass nearer a wall than the path it
replaces or this (so that a column of UAVs a few metres either side of the route clears the
corners)."""
BUILT_UP_RADIUS_M: float = 80.0
"""A free cell is in the built-up area when a wall lies within this distance [m] in at least
:data:`BUILT_UP_MIN_DIRECTIONS` of 8 directions (45 deg apart)."""
BUILT_UP_MIN_DIRECTIONS: int = 4
"""See :data:`BUILT_UP_RADIUS_M`: on a street between buildings walls lie on both sides and on
the diagonals; at the edge of the map, over water or in a wide park, on one side at most."""
EXTENT_MARGIN_M: float = 20.0
"""Open ground around the footprints' bounding box, inside the city's extent [m]."""


class CityFileError(ValueError):
    """A city file that cannot be used; the message names the file, feature and problem."""


# --------------------------------------------------------------------------------------------
# extruded polygons
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ExtrudedBuildings:
    """Buildings that are polygons (with holes) extruded from the ground to a flat roof.

    Build with :meth:`from_rings`. Fields are read-only arrays.

    Attributes
    ----------
    rings_m : tuple of tuple of ndarray
        Per building, its rings (exterior first, then holes), each ``(k, 2)`` East/North
        vertices [m] without the closing repeat.
    heights_m : ndarray, shape (n_b,)
        Roof heights [m], > 0.
    edges_m : ndarray, shape (n_e, 4)
        Every ring edge ``(ax, ay, bx, by)`` [m], building after building.
    edge_start : ndarray of int64, shape (n_b + 1,)
        Building ``b`` owns ``edges_m[edge_start[b]:edge_start[b + 1]]``.
    bbox_m : ndarray, shape (n_b, 4)
        ``(x_min, y_min, x_max, y_max)`` of each footprint [m].
    feature_ids : tuple of str
        Per building, the feature it came from (``"feature 3"``, with ``" (id 'b3')"`` when
        the feature has an ``id``).
    """

    rings_m: tuple[tuple[FloatArray, ...], ...]
    heights_m: FloatArray
    edges_m: FloatArray
    edge_start: NDArray[np.int64]
    bbox_m: FloatArray
    feature_ids: tuple[str, ...] = field(default=())

    @classmethod
    def from_rings(
        cls,
        rings_m: Sequence[Sequence[ArrayLike]],
        heights_m: ArrayLike,
        feature_ids: Sequence[str] | None = None,
    ) -> ExtrudedBuildings:
        """Buildings from their rings (per building: exterior then holes, ``(k, 2)`` [m],
        closed or not) and roof heights ``(n_b,)`` [m]."""
        h = np.array(heights_m, dtype=np.float64).reshape(-1)
        if h.size != len(rings_m):
            raise ValueError(
                f"heights_m must have one value per building ({len(rings_m)}), got {h.size}"
            )
        if not np.all(np.isfinite(h) & (h > 0.0)):
            raise ValueError("heights_m must be finite and > 0")
        all_rings, edges, starts, boxes = [], [], [0], []
        for b, rings in enumerate(rings_m):
            if len(rings) == 0:
                raise ValueError(f"building {b} has no ring")
            kept = []
            for ring in rings:
                r = np.array(ring, dtype=np.float64).reshape(-1, 2)
                if r.shape[0] > 1 and np.array_equal(r[0], r[-1]):
                    r = r[:-1]
                if r.shape[0] < 3 or not np.all(np.isfinite(r)):
                    raise ValueError(f"building {b}: a ring needs >= 3 finite vertices")
                kept.append(_readonly(r))
                edges.append(np.concatenate([r, np.roll(r, -1, axis=0)], axis=1))
            all_rings.append(tuple(kept))
            starts.append(starts[-1] + sum(k.shape[0] for k in kept))
            ext = kept[0]
            boxes.append([*ext.min(axis=0), *ext.max(axis=0)])
        ids = tuple(feature_ids) if feature_ids is not None else ()
        return cls(
            rings_m=tuple(all_rings),
            heights_m=_readonly(h),
            edges_m=_readonly(np.concatenate(edges) if edges else np.zeros((0, 4))),
            edge_start=_readonly(np.array(starts, dtype=np.int64)),
            bbox_m=_readonly(np.array(boxes, dtype=np.float64).reshape(-1, 4)),
            feature_ids=ids,
        )

    @property
    def n(self) -> int:
        """Number of buildings ``n_b``."""
        return int(self.heights_m.shape[0])

    @property
    def footprints_m(self) -> FloatArray:
        """Bounding boxes ``(x_min, y_min, x_max, y_max)`` of the footprints, ``(n_b, 4)`` [m]
        (what a box-city drawing shows; :attr:`rings_m` has the polygons)."""
        return self.bbox_m.copy()

    def _args(self) -> tuple[Any, ...]:
        return self.edges_m, self.edge_start, self.heights_m, self.bbox_m

    def is_inside(self, pos_enu_m: ArrayLike) -> BoolArray:
        """Whether each point ``(n, 3)`` [m] is inside a building (inside a footprint by the
        even-odd rule, ``0 < z < roof``); ``(n,)`` bool. Points on a wall may fall either
        way."""
        pos = np.ascontiguousarray(_as_points(pos_enu_m, "pos_enu_m"))
        return _pk.inside_buildings(pos, *self._args())

    def trace_line_of_sight(self, pos_enu_m: ArrayLike, sky: SkyDirections) -> BoolArray:
        """Line of sight ``(n_rx, n_sv)`` from receivers to prepared satellite directions
        (:func:`~coopnav_env.sim.city.sky_directions`): the rule of
        :func:`~coopnav_env.sim.city.line_of_sight` (directions at elevation <= 0 never
        visible; a ray that grazes an edge or a roof counts as blocked)."""
        pos = np.ascontiguousarray(_as_points(pos_enu_m, "pos_enu_m"))
        return _pk.line_of_sight(pos, *self._args(), sky.up, sky.order, sky.cot_s, sky.h_dir)

    def sky_and_walls(
        self, pos_enu_m: ArrayLike, az_deg: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Skyline elevation [deg] and nearest-wall distance [m] along each azimuth,
        ``(n, n_az)`` each, as :func:`~coopnav_env.sim.city.sky_and_walls` defines them (90 deg
        and 0 m inside a footprint below its roof; 0 deg and ``inf`` where nothing is met)."""
        pos = np.ascontiguousarray(_as_points(pos_enu_m, "pos_enu_m"))
        tan_max, dist = _pk.sky_and_walls(pos, ray_directions(az_deg), *self._args())
        return np.degrees(np.arctan(tan_max)), dist

    def swept_collisions(
        self, start_enu_m: ArrayLike, end_enu_m: ArrayLike, radius_m: float
    ) -> BoolArray:
        """Whether spheres of ``radius_m`` moving along straight segments ``(n, 3)`` [m] touch
        a building (distance <= radius: touching collides); ``(n,)`` bool."""
        p0 = np.ascontiguousarray(_as_points(start_enu_m, "start_enu_m"))
        p1 = np.ascontiguousarray(_as_points(end_enu_m, "end_enu_m"))
        if p0.shape != p1.shape:
            raise ValueError(f"start and end must share one shape, got {p0.shape}, {p1.shape}")
        return _pk.swept_collisions(*self._args(), p0, p1, float(radius_m))


# --------------------------------------------------------------------------------------------
# reading GeoJSON
# --------------------------------------------------------------------------------------------

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_UNIT = r"(m|metres|meters|ft|feet|')?"
_HEIGHT_RE = re.compile(rf"^\s*({_NUMBER})\s*{_UNIT}\s*$")
_RANGE_RE = re.compile(rf"^\s*({_NUMBER})\s*(?:-|–|to)\s*({_NUMBER})\s*{_UNIT}\s*$")

_WGS84_CRS_NAMES = (
    "urn:ogc:def:crs:ogc:1.3:crs84",
    "urn:ogc:def:crs:ogc::crs84",
    "ogc:crs84",
    "crs84",
    "urn:ogc:def:crs:epsg::4326",
    "urn:ogc:def:crs:epsg:4326",
    "epsg:4326",
)
"""Names of a GeoJSON ``crs`` member (the 2008 GeoJSON draft) that mean WGS 84 degrees."""


def _parse_height(value: Any, where: str, key: str) -> float:
    """A positive height in metres (or a number of storeys) from a number or a string.

    Strings read: ``"12"``, ``"12 m"``, ``"40 ft"``, ``"5.5"``; a list ``"5;6"`` or a range
    ``"5-6"`` gives its largest value (the tallest part is what blocks a satellite)."""
    if isinstance(value, bool):
        raise CityFileError(f"{where}: {key} {value!r} is not a height")
    if isinstance(value, (int, float)):
        h = float(value)
    elif isinstance(value, str):
        values = []
        for part in value.split(";"):
            m = _HEIGHT_RE.match(part)
            if m is not None:
                nums, unit = [m.group(1)], m.group(2)
            else:
                m = _RANGE_RE.match(part)
                if m is None:
                    raise CityFileError(
                        f"{where}: cannot read {key} {value!r} (expected e.g. '12 m', '5;6' or "
                        "'5-6')"
                    )
                nums, unit = [m.group(1), m.group(2)], m.group(3)
            scale = 0.3048 if unit in ("ft", "feet", "'") else 1.0
            values += [float(v) * scale for v in nums]
        h = max(values)
    else:
        raise CityFileError(f"{where}: {key} {value!r} is not a number or a string")
    if not (math.isfinite(h) and h > 0.0):
        raise CityFileError(f"{where}: {key} {value!r} must be a finite height > 0 m")
    return h


def _feature_height(
    props: dict[str, Any], where: str, storey_m: float, default_m: float | None, lenient: bool
) -> tuple[float | None, str, list[str]]:
    """Roof height of a feature, where it came from (``"height"``, ``"building:levels"`` or
    ``"default"``) and the unreadable values met on the way. ``lenient``: an unreadable value
    is skipped (the next source is tried); otherwise it raises. The height is None when no
    source gives one and there is no default."""
    unreadable: list[str] = []
    for key in ("height", "building:levels"):
        if props.get(key) is None:
            continue
        try:
            h = _parse_height(props[key], where, key)
        except CityFileError as exc:
            if not lenient:
                raise
            unreadable.append(str(exc)[len(where) + 2 :])
            continue
        return (h if key == "height" else h * storey_m), key, unreadable
    return default_m, "default", unreadable


def _segments_cross(p: FloatArray, q: FloatArray) -> bool:
    """Whether any two non-adjacent edges of the closed ring ``p`` (k, 2) intersect (``q`` is
    ``p`` rolled by one: edge ``i`` runs from ``p[i]`` to ``q[i]``). Pure numpy, O(k^2)."""
    k = p.shape[0]
    a, b = p[:, None, :], q[:, None, :]
    c, d = p[None, :, :], q[None, :, :]

    def orient(u, v, w):
        return (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (
            w[..., 0] - u[..., 0]
        )

    o1, o2 = orient(a, b, c), orient(a, b, d)
    o3, o4 = orient(c, d, a), orient(c, d, b)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)

    def on_seg(u, v, w, o):  # w on segment u v given orient(u, v, w) == o
        return (
            (o == 0)
            & (np.minimum(u[..., 0], v[..., 0]) <= w[..., 0])
            & (w[..., 0] <= np.maximum(u[..., 0], v[..., 0]))
            & (np.minimum(u[..., 1], v[..., 1]) <= w[..., 1])
            & (w[..., 1] <= np.maximum(u[..., 1], v[..., 1]))
        )

    touch = on_seg(a, b, c, o1) | on_seg(a, b, d, o2) | on_seg(c, d, a, o3) | on_seg(c, d, b, o4)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    adjacent = (i == j) | ((i + 1) % k == j) | ((j + 1) % k == i)
    return bool(np.any((proper | touch) & ~adjacent))


@dataclass(frozen=True)
class CityReport:
    """What reading a city file found (:attr:`FileCity.report`, ``coopnav city convert``).

    Attributes
    ----------
    source : str
        The file read.
    n_features : int
        Polygon and MultiPolygon features (OSM: building ways and relations) read.
    n_buildings : int
        Buildings kept (one per polygon; a repaired footprint may give several).
    n_height : int
        Buildings whose roof came from ``height``.
    n_levels : int
        Buildings whose roof came from ``building:levels`` x the storey height.
    n_default_height : int
        Buildings that got the default height (no readable ``height`` or levels).
    n_unreadable_height : int
        Features with a ``height`` or ``building:levels`` that could not be read (skipped,
        with ``repair``).
    n_repaired : int
        Features whose rings were repaired (closed, or made valid by shapely ``make_valid``).
    n_dropped : int
        Features with nothing left to build (a ring of fewer than 3 distinct vertices, or no
        area after repair).
    n_skipped : int
        Features of another geometry type (points, lines).
    n_outside_bbox : int
        Features outside the bounding box.
    n_incomplete : int
        OSM only: ways with nodes missing from the extract and relations that could not be
        assembled into areas (cut by the extract's edge, or broken).
    default_height_m : float or None
        The default roof height used [m].
    unreadable_examples : tuple of str
        Up to 5 unreadable values, naming their features.
    """

    source: str
    n_features: int = 0
    n_buildings: int = 0
    n_height: int = 0
    n_levels: int = 0
    n_default_height: int = 0
    n_unreadable_height: int = 0
    n_repaired: int = 0
    n_dropped: int = 0
    n_skipped: int = 0
    n_outside_bbox: int = 0
    n_incomplete: int = 0
    default_height_m: float | None = DEFAULT_HEIGHT_M
    unreadable_examples: tuple[str, ...] = ()

    def lines(self) -> list[str]:
        """The report as lines of text (what ``coopnav city convert`` prints)."""
        out = [
            f"buildings: {self.n_buildings} (from "
            f"{self.n_features - self.n_outside_bbox - self.n_dropped} footprint features)",
            f"heights known: {self.n_height + self.n_levels} ({self.n_height} from 'height', "
            f"{self.n_levels} from 'building:levels'); defaulted: {self.n_default_height} "
            f"(default height {self.default_height_m} m)",
            f"rings repaired: {self.n_repaired} features; dropped: {self.n_dropped} "
            "(nothing left to build)",
        ]
        if self.n_unreadable_height:
            out.append(
                f"unreadable heights skipped: {self.n_unreadable_height} "
                f"(e.g. {'; '.join(self.unreadable_examples[:2])})"
            )
        if self.n_outside_bbox:
            out.append(f"outside the bounding box: {self.n_outside_bbox} features")
        if self.n_incomplete:
            out.append(
                f"incomplete in the extract: {self.n_incomplete} ways or relations (nodes "
                "missing, or a multipolygon that could not be assembled)"
            )
        if self.n_skipped:
            out.append(f"other geometries skipped: {self.n_skipped}")
        return out

    def warnings(self) -> list[str]:
        """One message per thing a user should know: repairs, drops, unreadable and default
        heights (most buildings defaulted: a stronger message)."""
        name = f"city file {self.source}"
        out = []
        if self.n_repaired or self.n_dropped:
            out.append(
                f"{name}: {self.n_repaired} features with invalid rings repaired (closed, or "
                f"made valid with shapely make_valid), {self.n_dropped} dropped with nothing "
                "left to build; repair=False (city_repair=False) lists them as an error instead"
            )
        if self.n_unreadable_height:
            out.append(
                f"{name}: {self.n_unreadable_height} features have an unreadable height or "
                f"building:levels, read as missing: {'; '.join(self.unreadable_examples)}"
            )
        if self.n_default_height:
            msg = (
                f"{name}: {self.n_default_height} of {self.n_buildings} buildings have neither "
                f"'height' nor 'building:levels'; they get the default height "
                f"{self.default_height_m} m"
            )
            if 2 * self.n_default_height > self.n_buildings:
                msg += (
                    ": most of the city's heights are this default, so its line of sight "
                    "depends on it; set default_height_m (the environment's "
                    "city_default_height_m) to a typical roof height of the place"
                )
            out.append(msg)
        return out


@dataclass(frozen=True)
class _Footprints:
    rings_lonlat: list[list[FloatArray]]  # per building, rings (k, 2) lon/lat, not closed
    heights_m: list[float]
    ids: list[str]
    sources: list[str]  # per building: "height", "building:levels" or "default"
    report: CityReport
    names: list[str]  # per building: the feature's id (or "feature i"), "part k" of a split


def _geojson_features(path: Path) -> list[Any]:
    """The ``features`` of a GeoJSON FeatureCollection in WGS 84 degrees (a declared other
    CRS is refused)."""
    name = str(path)
    if not path.is_file():
        raise CityFileError(f"city file {name}: no such file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CityFileError(f"city file {name}: not readable GeoJSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise CityFileError(f"city file {name}: expected a GeoJSON FeatureCollection")
    crs = doc.get("crs")
    if crs is not None:
        crs_name = crs.get("properties", {}).get("name") if isinstance(crs, dict) else None
        if not (isinstance(crs_name, str) and crs_name.strip().lower() in _WGS84_CRS_NAMES):
            raise CityFileError(
                f"city file {name}: declares the coordinate reference system {crs_name or crs!r}; "
                "a city file must be in WGS 84 longitude/latitude degrees (RFC 7946): reproject "
                "it, e.g. `ogr2ogr -t_srs EPSG:4326 out.geojson in.geojson`"
            )
    feats = doc.get("features")
    if not isinstance(feats, list):
        raise CityFileError(f"city file {name}: 'features' must be a list")
    return feats


def _check_range(name: str, rings: list[FloatArray]) -> None:
    """Refuse positions out of longitude/latitude range, saying whether they look projected
    (metres) or swapped."""
    allv = np.concatenate(rings)
    bad_lon = np.abs(allv[:, 0]) > 180.0
    bad_lat = np.abs(allv[:, 1]) > 90.0
    if np.any(bad_lon | bad_lat):
        x, y = allv[int(np.argmax(bad_lon | bad_lat))]
        if np.all(np.abs(allv) <= 180.0) and np.all(np.abs(allv[:, 0]) <= 90.0):
            why = (
                "latitude and longitude look swapped (a GeoJSON position is [longitude, latitude])"
            )
        else:
            why = (
                "these look like projected coordinates (metres, e.g. UTM or Web Mercator), not "
                "WGS 84 degrees: reproject the file (e.g. `ogr2ogr -t_srs EPSG:4326 out.geojson "
                "in.geojson`)"
            )
        raise CityFileError(
            f"city file {name}: position [{x:.6g}, {y:.6g}] is out of longitude/latitude "
            f"range; {why}"
        )


def _check_place(name: str, rings: list[FloatArray], max_span_m: float) -> None:
    """Refuse coordinates that are not the longitude/latitude degrees of one place: an
    implausible extent, or footprints whose corners are square only when latitude and
    longitude are swapped (:func:`_square_corner_share`)."""
    allv = np.concatenate(rings)
    lat_mid = math.radians(float(allv[:, 1].mean()))
    span_e = float(np.ptp(allv[:, 0])) * 111_320.0 * math.cos(lat_mid)
    span_n = float(np.ptp(allv[:, 1])) * 110_574.0
    if max(span_e, span_n) > max_span_m:
        raise CityFileError(
            f"city file {name}: the footprints span {span_e / 1000:.0f} km east-west and "
            f"{span_n / 1000:.0f} km north-south, an implausible extent for one city (more "
            f"than {max_span_m / 1000:.0f} km): coordinates in metres or another unit instead "
            "of degrees, or footprints of places far apart?"
        )
    as_read, n_corners = _square_corner_share(rings, swap=False)
    swapped, _ = _square_corner_share(rings, swap=True)
    if n_corners >= 20 and swapped >= 0.3 and swapped >= 3.0 * as_read:
        raise CityFileError(
            f"city file {name}: latitude and longitude look swapped: {swapped:.0%} of the "
            f"footprints' corners are right angles with the two swapped, {as_read:.0%} as "
            "written (a GeoJSON position is [longitude, latitude]); swap them"
        )


def _square_corner_share(rings: list[FloatArray], swap: bool) -> tuple[float, int]:
    """Share of ring corners (turns of more than 10 deg) within 2 deg of a right angle, in a
    local equirectangular frame, and the number of corners; ``swap`` reads each position as
    ``[lat, lon]``. Buildings are mostly rectangular; swapping the two axes of a file scales
    them unequally (by the cosines of two different latitudes) and skews their corners."""
    rs = [r[:, ::-1] for r in rings] if swap else rings
    allv = np.concatenate(rs)
    if np.any(np.abs(allv[:, 1]) > 90.0):
        return 0.0, 0
    c = math.cos(math.radians(float(allv[:, 1].mean())))
    n = right = 0
    for r in rs:
        xy = np.column_stack([r[:, 0] * c, r[:, 1]])
        a = np.roll(xy, 1, axis=0) - xy
        b = np.roll(xy, -1, axis=0) - xy
        na, nb = np.hypot(a[:, 0], a[:, 1]), np.hypot(b[:, 0], b[:, 1])
        ok = (na > 0) & (nb > 0)
        cosang = np.sum(a[ok] * b[ok], axis=1) / (na[ok] * nb[ok])
        ang = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
        corner = ang < 170.0
        n += int(corner.sum())
        right += int(np.sum(np.abs(ang[corner] - 90.0) < 2.0))
    return right / max(n, 1), n


def _shapely_for_repair(name: str, n_invalid: int, first: str) -> Any:
    """shapely, or an error saying how to get it (or to list the bad features instead)."""
    try:
        import shapely
    except ImportError:
        raise CityFileError(
            f"city file {name}: {n_invalid} features have invalid rings (the first: {first}); "
            "repairing them needs shapely: `pip install 'coopnav[geo]'` (or pass repair=False, "
            "city_repair=False, to list every one)"
        ) from None
    return shapely


def _repair_polygon(shapely: Any, rings: list[FloatArray]) -> list[list[FloatArray]]:
    """The valid polygons (rings, not closed) of ``make_valid`` of an exterior and its holes
    (in degrees); parts without area (lines, points, slivers under 0.01 m^2) are dropped."""
    poly = shapely.Polygon(rings[0], [h for h in rings[1:]])
    fixed = shapely.make_valid(poly)
    parts, stack = [], [fixed]
    while stack:
        g = stack.pop()
        if g.geom_type == "Polygon":
            parts.append(g)
        elif hasattr(g, "geoms"):
            stack.extend(g.geoms)
    min_area_deg2 = 1e-2 / (111_000.0**2)
    out = []
    for g in sorted(parts, key=lambda g: (g.bounds[0], g.bounds[1])):
        if g.is_empty or g.area < min_area_deg2:
            continue
        out.append(
            [np.asarray(g.exterior.coords)[:-1, :2]]
            + [np.asarray(h.coords)[:-1, :2] for h in g.interiors]
        )
    return out


def _ring_problem(arr: FloatArray) -> str | None:
    """Why a ring (not closed, consecutive repeats removed) is invalid, or None."""
    distinct = np.unique(arr, axis=0).shape[0]
    if distinct < 3:
        return f"fewer than 3 distinct vertices ({distinct})"
    if distinct != arr.shape[0] or _segments_cross(arr, np.roll(arr, -1, axis=0)):
        return "self-intersecting ring"
    return None


def _read_lonlat(
    path: Path,
    storey_m: float,
    default_m: float | None,
    *,
    repair: bool = True,
    bbox: tuple[float, float, float, float] | None = None,
    features: list[Any] | None = None,
    n_incomplete: int = 0,
    max_span_m: float = MAX_SPAN_M,
) -> _Footprints:
    """Parse and check the polygons of a GeoJSON file (or of ``features`` read from it by
    another reader) in lon/lat. Problems that cannot be repaired, or every problem without
    ``repair``, are listed together in one :class:`CityFileError`."""
    name = str(path)
    feats = _geojson_features(path) if features is None else features
    problems: list[str] = []
    # parse every feature: (where, height, source, [polygon: [ring arrays]], open ring seen)
    parsed: list[tuple[str, float | None, str, list[list[FloatArray]], bool]] = []
    feature_names: dict[str, str] = {}  # where -> the feature's own id, or "feature i"
    n_skipped = n_unreadable = n_outside = 0
    unreadable: list[str] = []
    for i, feat in enumerate(feats):
        fid = feat.get("id") if isinstance(feat, dict) else None
        where = f"feature {i}" + (f" (id {fid!r})" if fid is not None else "")
        feature_names[where] = f"feature {i}" if fid is None else str(fid)
        if not isinstance(feat, dict) or feat.get("type") != "Feature":
            problems.append(f"{where}: not a GeoJSON Feature")
            continue
        geom = feat.get("geometry")
        props = feat.get("properties") or {}
        if not isinstance(props, dict):
            problems.append(f"{where}: 'properties' must be an object")
            continue
        gtype = geom.get("type") if isinstance(geom, dict) else None
        if gtype not in ("Polygon", "MultiPolygon"):
            n_skipped += 1
            continue
        coords = geom.get("coordinates")
        polys = [coords] if gtype == "Polygon" else coords
        if not isinstance(polys, list) or not polys:
            problems.append(f"{where}: empty {gtype} coordinates")
            continue
        try:
            height, source, bad = _feature_height(props, where, storey_m, default_m, repair)
        except CityFileError as exc:
            problems.append(str(exc))
            continue
        if bad:
            n_unreadable += 1
            unreadable += [f"{where}: {b}" for b in bad]
        if height is None:
            why = f" ({'; '.join(bad)})" if bad else ""
            problems.append(
                f"{where}: no height (neither 'height' nor 'building:levels' readable{why}) and "
                "no default height"
            )
            continue
        arrays: list[list[FloatArray]] = []
        opened = False
        for pi, poly in enumerate(polys):
            pw = where if gtype == "Polygon" else f"{where}, polygon {pi}"
            if not isinstance(poly, list) or not poly:
                problems.append(f"{pw}: a polygon needs at least an exterior ring")
                break
            rings = []
            for ri, ring in enumerate(poly):
                rw = f"{pw}, ring {ri}"
                try:
                    arr = np.array(ring, dtype=np.float64)
                except (TypeError, ValueError):
                    problems.append(f"{rw}: coordinates are not numbers")
                    break
                if arr.ndim != 2 or arr.shape[0] < 1 or arr.shape[1] < 2:
                    problems.append(f"{rw}: positions must be [lon, lat] pairs")
                    break
                arr = arr[:, :2]
                if not np.all(np.isfinite(arr)):
                    problems.append(f"{rw}: non-finite coordinates")
                    break
                if arr.shape[0] < 2 or not np.array_equal(arr[0], arr[-1]):
                    opened = True
                    if not repair:
                        problems.append(
                            f"{rw}: open ring (the last position must repeat the first)"
                        )
                        break
                else:
                    arr = arr[:-1]
                keep = np.ones(arr.shape[0], dtype=bool)  # consecutive repeats: one vertex
                keep[1:] = np.any(arr[1:] != arr[:-1], axis=1)
                arr = arr[keep]
                if arr.shape[0] > 1 and np.array_equal(arr[0], arr[-1]):
                    arr = arr[:-1]
                rings.append(arr)
            else:
                arrays.append(rings)
                continue
            break
        else:
            parsed.append((where, height, source, arrays, opened))
    if parsed:
        _check_range(name, [r for p in parsed for poly in p[3] for r in poly])
    if bbox is not None:
        south, west, north, east = bbox
        inside = []
        for item in parsed:
            c = np.concatenate([poly[0] for poly in item[3]]).mean(axis=0)
            if west <= c[0] <= east and south <= c[1] <= north:
                inside.append(item)
        n_outside = len(parsed) - len(inside)
        parsed = inside
    if parsed:
        _check_place(name, [r for p in parsed for poly in p[3] for r in poly], max_span_m)
    # ring validity: repair, or list
    invalid: list[tuple[int, int, str]] = []  # (feature item, polygon, why)
    for k, (where, _, _, arrays, _) in enumerate(parsed):
        for pi, rings in enumerate(arrays):
            for ri, arr in enumerate(rings):
                why = _ring_problem(arr)
                if why is not None:
                    poly = "" if len(arrays) == 1 else f", polygon {pi}"
                    invalid.append((k, pi, f"{where}{poly}, ring {ri}: {why}"))
                    break
    if not repair:
        problems += [why for _, _, why in invalid]
    if problems:
        raise CityFileError(
            f"city file {name}: {len(problems)} feature problem(s), every one listed:\n  "
            + "\n  ".join(problems)
        )
    repaired = {k for k, (*_, opened) in enumerate(parsed) if opened}
    fixed: dict[tuple[int, int], list[list[FloatArray]]] = {}
    if invalid:
        shapely = _shapely_for_repair(name, len({k for k, _, _ in invalid}), invalid[0][2])
        for k, pi, _ in invalid:
            rings = parsed[k][3][pi]
            ok = [r for r in rings[1:] if np.unique(r, axis=0).shape[0] >= 3]
            if np.unique(rings[0], axis=0).shape[0] < 3:
                fixed[(k, pi)] = []
            else:
                fixed[(k, pi)] = _repair_polygon(shapely, [rings[0], *ok])
            repaired.add(k)
    out_rings: list[list[FloatArray]] = []
    heights: list[float] = []
    ids: list[str] = []
    sources: list[str] = []
    names: list[str] = []
    n_dropped = 0
    counts = {"height": 0, "building:levels": 0, "default": 0}
    for k, (where, height, source, arrays, _) in enumerate(parsed):
        polys: list[list[FloatArray]] = []
        for pi, rings in enumerate(arrays):
            polys += fixed.get((k, pi), [rings])
        if not polys:
            n_dropped += 1
            repaired.discard(k)
            continue
        for part, rings in enumerate(polys):
            out_rings.append(rings)
            heights.append(float(height))  # type: ignore[arg-type]
            ids.append(where)
            sources.append(source)
            names.append(feature_names[where] + (f" part {part + 1}" if len(polys) > 1 else ""))
            counts[source] += 1
    if not out_rings:
        raise CityFileError(
            f"city file {name}: no Polygon or MultiPolygon feature"
            + (" inside the bounding box" if n_outside else "")
            + (f" left after repair ({n_dropped} dropped)" if n_dropped else "")
        )
    report = CityReport(
        source=name,
        n_features=len(parsed) + n_outside,
        n_buildings=len(out_rings),
        n_height=counts["height"],
        n_levels=counts["building:levels"],
        n_default_height=counts["default"],
        n_unreadable_height=n_unreadable,
        n_repaired=len(repaired),
        n_dropped=n_dropped,
        n_skipped=n_skipped,
        n_outside_bbox=n_outside,
        n_incomplete=n_incomplete,
        default_height_m=default_m,
        unreadable_examples=tuple(unreadable[:5]),
    )
    return _Footprints(out_rings, heights, ids, sources, report, names)


def _check_bbox(bbox: Any) -> tuple[float, float, float, float] | None:
    """``(south, west, north, east)`` [deg] as floats, checked; None passes."""
    if bbox is None:
        return None
    try:
        box = tuple(float(v) for v in bbox)
    except (TypeError, ValueError):
        box = ()
    if not (
        len(box) == 4
        and all(math.isfinite(v) for v in box)
        and -90.0 <= box[0] < box[2] <= 90.0
        and -180.0 <= box[1] < box[3] <= 180.0
    ):
        raise ValueError(
            "bbox must be (south_deg, west_deg, north_deg, east_deg) with south < north in "
            f"[-90, 90] and west < east in [-180, 180], got {bbox!r}"
        )
    return box  # type: ignore[return-value]


def _check_heights(storey_height_m: float, default_height_m: float | None) -> None:
    """Validate the storey and default heights (ValueError naming the bad one)."""
    if not (
        isinstance(storey_height_m, (int, float))
        and math.isfinite(storey_height_m)
        and STOREY_HEIGHT_RANGE_M[0] <= storey_height_m <= STOREY_HEIGHT_RANGE_M[1]
    ):
        raise ValueError(
            f"storey_height_m must be in [{STOREY_HEIGHT_RANGE_M[0]:g}, "
            f"{STOREY_HEIGHT_RANGE_M[1]:g}] m, got {storey_height_m!r}"
        )
    if default_height_m is not None and not (
        isinstance(default_height_m, (int, float))
        and math.isfinite(default_height_m)
        and DEFAULT_HEIGHT_RANGE_M[0] <= default_height_m <= DEFAULT_HEIGHT_RANGE_M[1]
    ):
        raise ValueError(
            f"default_height_m must be None or in [{DEFAULT_HEIGHT_RANGE_M[0]:g}, "
            f"{DEFAULT_HEIGHT_RANGE_M[1]:g}] m, got {default_height_m!r}"
        )


def read_city_footprints(
    path: str | os.PathLike[str],
    *,
    storey_height_m: float = STOREY_HEIGHT_M,
    default_height_m: float | None = DEFAULT_HEIGHT_M,
    repair: bool = True,
    bbox: tuple[float, float, float, float] | None = None,
) -> tuple[list[dict[str, Any]], CityReport]:
    """The checked (and, with ``repair``, repaired) building footprints of a city file as
    GeoJSON features in WGS 84 degrees, and what reading found.

    Parameters
    ----------
    path : path-like
        A GeoJSON file, or an OpenStreetMap file (``.osm``, ``.osm.pbf``; as
        ``osm:PATH`` or by its suffix; needs the ``osm`` extra: :mod:`coopnav_env.sim.osm_city`).
    storey_height_m, default_height_m, repair, bbox
        As for :func:`read_geojson_footprints`.

    Returns
    -------
    features : list of dict
        One ``Polygon`` feature per building, its ``id`` the source feature, its properties
        ``height`` [m] when the source gave one, else ``building:levels`` (the number read),
        else none (the reader of the file gives the default).
    report : CityReport
    """
    fp = _read_source(path, storey_height_m, default_height_m, repair, bbox)
    feats = []
    for rings, h, fid, source in zip(fp.rings_lonlat, fp.heights_m, fp.names, fp.sources):
        props: dict[str, Any] = {"building": "yes"}
        if source == "height":
            props["height"] = _plain_number(h)
        elif source == "building:levels":
            props["building:levels"] = _plain_number(h / storey_height_m)
        coords = [[*np.round(r, 7).tolist(), np.round(r[0], 7).tolist()] for r in rings]
        feats.append(
            {
                "type": "Feature",
                "id": fid,
                "properties": props,
                "geometry": {"type": "Polygon", "coordinates": coords},
            }
        )
    return feats, fp.report


def _plain_number(x: float) -> float | int:
    """``x`` rounded to 3 decimals, an int when whole (``5`` rather than ``5.0``)."""
    r = round(float(x), 3)
    return int(r) if r.is_integer() else r


def _read_source(
    path: str | os.PathLike[str],
    storey_height_m: float,
    default_height_m: float | None,
    repair: bool,
    bbox: Any,
    max_span_m: float = MAX_SPAN_M,
) -> _Footprints:
    """:func:`_read_lonlat` of a GeoJSON or OSM file (by prefix or suffix), settings checked."""
    _check_heights(storey_height_m, default_height_m)
    box = _check_bbox(bbox)
    text = os.fspath(path)
    is_osm = text.startswith(OSM_PREFIX) or text.lower().endswith(OSM_SUFFIXES)
    for prefix in (GEOJSON_PREFIX, OSM_PREFIX):
        if text.startswith(prefix):
            text = text[len(prefix) :]
    p = Path(text).expanduser()
    if not is_osm:
        return _read_lonlat(
            p,
            float(storey_height_m),
            default_height_m,
            repair=repair,
            bbox=box,
            max_span_m=max_span_m,
        )
    from coopnav_env.sim.osm_city import read_osm_buildings

    feats, n_incomplete = read_osm_buildings(p)
    return _read_lonlat(
        p,
        float(storey_height_m),
        default_height_m,
        repair=repair,
        bbox=box,
        features=feats,
        n_incomplete=n_incomplete,
        max_span_m=max_span_m,
    )


def read_geojson_footprints(
    path: str | os.PathLike[str],
    *,
    origin_lat_lon: tuple[float, float] | None = None,
    alt_m: float = 0.0,
    storey_height_m: float = STOREY_HEIGHT_M,
    default_height_m: float | None = DEFAULT_HEIGHT_M,
    max_origin_distance_m: float = MAX_ORIGIN_DISTANCE_M,
    repair: bool = True,
    bbox: tuple[float, float, float, float] | None = None,
) -> tuple[ExtrudedBuildings, tuple[float, float, float], int]:
    """Read building footprints from a city file into the ENU frame of an origin.

    Parameters
    ----------
    path : path-like
        The GeoJSON FeatureCollection (module docstring), or an OpenStreetMap file
        (``osm:PATH`` or a ``.osm``/``.osm.pbf`` suffix: :mod:`coopnav_env.sim.osm_city`).
    origin_lat_lon : (float, float), optional
        Geodetic origin of the ENU frame [deg]; default: the mean latitude and longitude of
        all footprint vertices.
    alt_m : float, default 0.0
        Ellipsoidal height of the origin (the ground) [m].
    storey_height_m : float, default :data:`STOREY_HEIGHT_M`
        Metres per ``building:levels`` storey, in :data:`STOREY_HEIGHT_RANGE_M`.
    default_height_m : float or None, default :data:`DEFAULT_HEIGHT_M`
        Height of a feature without a readable ``height`` or levels [m], in
        :data:`DEFAULT_HEIGHT_RANGE_M`; None: such a feature is an error.
    max_origin_distance_m : float, default :data:`MAX_ORIGIN_DISTANCE_M`
        Farthest a vertex may lie from the origin (horizontally) [m].
    repair : bool, default True
        Repair what can be repaired (module docstring, "Repairs") and warn with the counts;
        False: every bad feature is listed in one :class:`CityFileError`.
    bbox : (float, float, float, float), optional
        ``(south, west, north, east)`` [deg]: only features whose footprint's vertex mean lies
        inside are read.

    Returns
    -------
    buildings : ExtrudedBuildings
    origin : (float, float, float)
        ``(lat_deg, lon_deg, alt_m)`` of the ENU frame.
    n_default_height : int
        Buildings that got ``default_height_m``.

    Raises
    ------
    CityFileError
        Naming the file, the feature and what is wrong.
    """
    buildings, origin, report = _read_buildings(
        path,
        origin_lat_lon=origin_lat_lon,
        alt_m=alt_m,
        storey_height_m=storey_height_m,
        default_height_m=default_height_m,
        max_origin_distance_m=max_origin_distance_m,
        repair=repair,
        bbox=bbox,
    )
    for msg in report.warnings():
        warnings.warn(msg, stacklevel=2)
    return buildings, origin, report.n_default_height


def _read_buildings(
    path: str | os.PathLike[str],
    *,
    origin_lat_lon: tuple[float, float] | None,
    alt_m: float,
    storey_height_m: float,
    default_height_m: float | None,
    max_origin_distance_m: float,
    repair: bool,
    bbox: Any,
) -> tuple[ExtrudedBuildings, tuple[float, float, float], CityReport]:
    """:func:`read_geojson_footprints` without its warnings, with the whole report."""
    fp = _read_source(
        path,
        storey_height_m,
        default_height_m,
        repair,
        bbox,
        max_span_m=max(MAX_SPAN_M, 2.0 * float(max_origin_distance_m)),
    )
    p = fp.report.source
    if origin_lat_lon is None:
        allv = np.concatenate([r for rings in fp.rings_lonlat for r in rings])
        lat0, lon0 = float(allv[:, 1].mean()), float(allv[:, 0].mean())
    else:
        lat0, lon0 = (float(v) for v in origin_lat_lon)
        if not (math.isfinite(lat0) and math.isfinite(lon0) and abs(lat0) <= 85.0):
            raise ValueError(
                f"origin_lat_lon must be finite with |lat| <= 85, got {origin_lat_lon}"
            )
    rings_enu = []
    for k, rings in enumerate(fp.rings_lonlat):
        conv = []
        for ri, r in enumerate(rings):
            ecef = geodetic_to_ecef(r[:, 1], r[:, 0], np.full(r.shape[0], float(alt_m)))
            enu = ecef_to_enu(ecef, lat0, lon0, float(alt_m))[:, :2]
            far = np.hypot(enu[:, 0], enu[:, 1]) > max_origin_distance_m
            if np.any(far):
                j = int(np.argmax(far))
                raise CityFileError(
                    f"city file {p}, {fp.ids[k]}, ring {ri}: vertex {j} lies "
                    f"{float(np.hypot(*enu[j])):.0f} m from the origin ({lat0:.6f}, "
                    f"{lon0:.6f}), beyond the {max_origin_distance_m:.0f} m limit"
                )
            conv.append(enu)
        rings_enu.append(conv)
    buildings = ExtrudedBuildings.from_rings(rings_enu, fp.heights_m, fp.ids)
    return buildings, (lat0, lon0, float(alt_m)), fp.report


# --------------------------------------------------------------------------------------------
# the city
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class FileCity(City):
    """A :class:`~coopnav_env.sim.city.City` read from a file: extruded polygon buildings,
    a free-space grid for start, goal and routes, and the geodetic origin of its frame.

    Build with :func:`load_file_city`. ``street_centres_x_m``/``_y_m`` and ``open_squares``
    are empty; ``street_width_m`` is twice the clearance (the narrowest passage the free
    space keeps); ``buildings`` is an :class:`ExtrudedBuildings`.

    Attributes
    ----------
    grid_x_m, grid_y_m : ndarray
        East/North of the free-space cell centres [m].
    free : ndarray of bool, shape (n_y, n_x)
        Free cells (outside footprints, clearance kept).
    built_up : ndarray of bool, shape (n_y, n_x)
        Reachable cells in the built-up area (:data:`BUILT_UP_RADIUS_M`), its largest
        8-connected piece: where starts and goals are drawn, and where routes keep where
        they can (without any, starts and goals are drawn in every reachable cell).
    reachable : ndarray of bool, shape (n_y, n_x)
        Free cells of the largest 8-connected piece of free space (where starts and goals are
        drawn).
    origin : (float, float, float)
        ``(lat_deg, lon_deg, alt_m)`` of the ENU frame.
    source : str
        The file read.
    n_default_height : int
        Buildings that got the default height.
    report : CityReport or None
        What reading the file found (heights known and defaulted, rings repaired, ...).
    clearance_grid_m : ndarray, shape (n_y, n_x)
        Distance from each cell centre to the nearest wall [m], capped at
        :data:`PREFERRED_CLEARANCE_M` or the clearance, whichever is larger (0 inside a
        footprint).
    """

    grid_x_m: FloatArray = field(default_factory=lambda: np.zeros(0))
    grid_y_m: FloatArray = field(default_factory=lambda: np.zeros(0))
    free: BoolArray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    reachable: BoolArray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: str = ""
    n_default_height: int = 0
    clearance_grid_m: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    report: CityReport | None = None
    built_up: BoolArray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))

    @property
    def resolution_m(self) -> float:
        """Cell size of the free-space grid [m]."""
        return float(self.grid_x_m[1] - self.grid_x_m[0]) if self.grid_x_m.size > 1 else 1.0

    def lat_lon_to_xy(self, lat_deg: float, lon_deg: float) -> FloatArray:
        """East/North [m], shape ``(2,)``, of a point on the ground in this city's frame."""
        lat0, lon0, alt0 = self.origin
        ecef = geodetic_to_ecef(float(lat_deg), float(lon_deg), alt0)
        return ecef_to_enu(ecef, lat0, lon0, alt0)[:2]

    def xy_to_lat_lon(self, xy: ArrayLike) -> tuple[float, float]:
        """Latitude and longitude [deg] of an East/North point [m] on the ground."""
        lat0, lon0, alt0 = self.origin
        p = np.asarray(xy, dtype=float).reshape(2)
        ecef = enu_to_ecef(np.array([p[0], p[1], 0.0]), lat0, lon0, alt0)
        lat, lon, _ = ecef_to_geodetic(ecef)
        return float(lat), float(lon)

    def _cell(self, xy: ArrayLike) -> tuple[int, int]:
        """``(row, col)`` of the cell holding ``xy`` (clipped to the grid)."""
        p = np.asarray(xy, dtype=float).reshape(2)
        res = self.resolution_m
        col = int(
            np.clip(np.floor((p[0] - self.grid_x_m[0]) / res + 0.5), 0, self.grid_x_m.size - 1)
        )
        row = int(
            np.clip(np.floor((p[1] - self.grid_y_m[0]) / res + 0.5), 0, self.grid_y_m.size - 1)
        )
        return row, col

    def is_free_xy(self, xy: ArrayLike) -> BoolArray:
        """Whether each East/North point ``(n, 2)`` [m] lies in a reachable free cell."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        res = self.resolution_m
        col = np.floor((p[:, 0] - self.grid_x_m[0]) / res + 0.5).astype(np.int64)
        row = np.floor((p[:, 1] - self.grid_y_m[0]) / res + 0.5).astype(np.int64)
        ok = (col >= 0) & (col < self.grid_x_m.size) & (row >= 0) & (row < self.grid_y_m.size)
        out = np.zeros(p.shape[0], dtype=bool)
        out[ok] = self.reachable[row[ok], col[ok]]
        return out

    def random_street_points(
        self,
        rng: np.random.Generator,
        n: int,
        altitude_m: float = 10.0,
        margin_m: float = 2.0,
    ) -> FloatArray:
        """Uniformly random points ``(n, 3)`` [m] in the built-up reachable free space (a
        random cell of :attr:`built_up`, then uniformly within ``resolution / 2 - margin`` of
        its centre, at ``altitude_m``). ``margin_m`` is clipped to ``[0, resolution / 2]``."""
        rows, cols = np.nonzero(self.built_up if np.any(self.built_up) else self.reachable)
        k = rng.integers(0, rows.size, size=int(n))
        half = max(self.resolution_m / 2.0 - max(float(margin_m), 0.0), 0.0)
        jitter = rng.uniform(-half, half, size=(int(n), 2))
        x = self.grid_x_m[cols[k]] + jitter[:, 0]
        y = self.grid_y_m[rows[k]] + jitter[:, 1]
        return np.stack([x, y, np.full(int(n), float(altitude_m))], axis=1)

    def nearest_free_xy(self, xy: ArrayLike) -> FloatArray:
        """Centre ``(2,)`` [m] of the reachable cell nearest to ``xy`` (ties: the first in
        row-major order)."""
        p = np.asarray(xy, dtype=float).reshape(2)
        rows, cols = np.nonzero(self.reachable)
        d2 = (self.grid_x_m[cols] - p[0]) ** 2 + (self.grid_y_m[rows] - p[1]) ** 2
        k = int(np.argmin(d2))
        return np.array([self.grid_x_m[cols[k]], self.grid_y_m[rows[k]]])

    def free_space_route(
        self, start_xy: ArrayLike, goal_xy: ArrayLike, *, snap: bool = False
    ) -> FloatArray:
        """The route ``(k, 2)`` [m] from start to goal through the free space (module
        docstring): A* on the reachable cells between the cells of the two ends, shortened.

        Parameters
        ----------
        start_xy, goal_xy : array_like, shape (2,)
            East/North of the ends [m].
        snap : bool, default False
            An end off the reachable free space is refused (False) or planned from the
            nearest reachable cell (True: the route then runs from the end itself to that
            cell first, or from it to the end last).

        Raises
        ------
        ValueError
            Without ``snap``, when an end is not on a reachable free cell.
        """
        s = np.asarray(start_xy, dtype=float).reshape(2)
        g = np.asarray(goal_xy, dtype=float).reshape(2)
        head, tail = [], []
        for name, p in (("start", s), ("goal", g)):
            if self.is_free_xy(p)[0]:
                continue
            if not snap:
                raise ValueError(
                    f"route {name} ({p[0]:.1f}, {p[1]:.1f}) m is not in the reachable free "
                    f"space of {self.source or 'the city'} (inside or within the clearance of "
                    "a building, or cut off from the rest)"
                )
            if name == "start":
                head, s = [s], self.nearest_free_xy(s)
            else:
                tail, g = [g], self.nearest_free_xy(g)
        # outside the built-up area a cell costs 21 times a street's middle (a wall's side: 5)
        # and a shortcut may cross it only where the path does
        grid = cost = self.clearance_grid_m
        if np.any(self.built_up):
            grid = np.where(self.built_up, grid, 0.0)
            cost = np.where(self.built_up, grid, -4.0 * PREFERRED_CLEARANCE_M)
        cells = _astar(self.reachable, cost, self._cell(s), self._cell(g))
        pts = [s] + [np.array([self.grid_x_m[c], self.grid_y_m[r]]) for r, c in cells[1:-1]] + [g]
        clear = np.array([grid[r, c] for r, c in cells])
        kept = pull_string(  # the farthest waypoint reachable in a straight leg, from each
            np.array(pts, dtype=float),
            clear.astype(float),
            (  # the kernel's record (_route_kernels.FreeGrid) as a plain tuple
                self.reachable,
                np.ascontiguousarray(grid, dtype=float),
                float(self.grid_x_m[0]),
                float(self.grid_y_m[0]),
                float(self.resolution_m),
            ),
            PREFERRED_CLEARANCE_M,
        )
        out = [pts[k] for k in kept]
        keep = [out[0]]  # drop waypoints on a straight line (the same path, fewer legs)
        for k in range(1, len(out) - 1):
            u, v = out[k] - keep[-1], out[k + 1] - out[k]
            if abs(u[0] * v[1] - u[1] * v[0]) > 1e-9 * (u @ u + v @ v) or u @ v <= 0.0:
                keep.append(out[k])
        keep.append(out[-1])
        return np.array(head + keep + tail, dtype=float).reshape(-1, 2)


def _astar(
    free: BoolArray, clear: FloatArray, start: tuple[int, int], goal: tuple[int, int]
) -> list[tuple[int, int]]:
    """Cheapest 8-connected path of cells (no corner cutting) on ``free``: a step costs its
    length (1 or sqrt 2 cells) times ``1 + 4 (1 - clear / PREFERRED_CLEARANCE_M)`` of the cell
    entered (``clear`` capped there), so routes keep to the middle of streets; the octile
    distance is the (admissible) heuristic (:func:`coopnav_env.sim._polygon_kernels.astar`)."""
    nx = free.shape[1]
    path = _pk.astar(
        free,
        np.ascontiguousarray(clear, dtype=np.float64),
        float(PREFERRED_CLEARANCE_M),
        start[0] * nx + start[1],
        goal[0] * nx + goal[1],
    )
    if path.size == 0:
        raise ValueError(f"no free-space route between cells {start} and {goal}")
    return [(int(k) // nx, int(k) % nx) for k in path]


def _largest_component(free: BoolArray) -> BoolArray:
    """The largest 8-connected piece of ``free`` (the same moves as :func:`_astar`), by the
    compiled :func:`coopnav_env.sim._polygon_kernels.largest_component`."""
    return _pk.largest_component(np.ascontiguousarray(free, dtype=bool))


def load_file_city(
    spec: str | os.PathLike[str],
    *,
    origin_lat_lon: tuple[float, float] | None = None,
    alt_m: float = 0.0,
    grid_resolution_m: float = GRID_RESOLUTION_M,
    clearance_m: float = CLEARANCE_M,
    default_height_m: float | None = DEFAULT_HEIGHT_M,
    storey_height_m: float = STOREY_HEIGHT_M,
    repair: bool = True,
    bbox: tuple[float, float, float, float] | None = None,
    warn: bool = True,
) -> FileCity:
    """Read a city file into a :class:`FileCity` (cached per file version and arguments).

    Parameters
    ----------
    spec : str or path-like
        The GeoJSON file, with or without the ``geojson:`` prefix, or an OpenStreetMap file
        as ``osm:PATH`` (``.osm``, ``.osm.pbf``; :mod:`coopnav_env.sim.osm_city`, the ``osm``
        extra).
    origin_lat_lon : (float, float), optional
        Origin of the ENU frame [deg]; default: the footprints' centroid.
    alt_m : float, default 0.0
        Ellipsoidal height of the ground at the origin [m].
    grid_resolution_m : float, default :data:`GRID_RESOLUTION_M`
        Free-space cell size, in [0.5, 100] [m].
    clearance_m : float, default :data:`CLEARANCE_M`
        Distance kept from walls by the free space, in [0, 100] [m].
    default_height_m, storey_height_m, repair, bbox
        As for :func:`read_geojson_footprints`.
    warn : bool, default True
        Warn what reading found (repairs, unreadable and default heights; once per file
        version, settings and process).

    Raises
    ------
    CityFileError
        A bad file (naming it, the feature and the problem), or a file without free space.
    """
    text = os.fspath(spec)
    prefix = OSM_PREFIX if text.startswith(OSM_PREFIX) else ""
    for pre in (GEOJSON_PREFIX, OSM_PREFIX):
        if text.startswith(pre):
            text = text[len(pre) :]
    p = Path(text).expanduser().resolve()
    if not p.is_file():
        raise CityFileError(f"city file {text}: no such file")
    if not 0.5 <= float(grid_resolution_m) <= 100.0:
        raise ValueError(f"grid_resolution_m must be in [0.5, 100], got {grid_resolution_m!r}")
    if not 0.0 <= float(clearance_m) <= 100.0:
        raise ValueError(f"clearance_m must be in [0, 100], got {clearance_m!r}")
    _check_heights(storey_height_m, default_height_m)
    box = _check_bbox(bbox)
    st = p.stat()
    origin = None if origin_lat_lon is None else tuple(float(v) for v in origin_lat_lon)
    settings = (default_height_m, float(storey_height_m), bool(repair), box)
    city = _load_cached(
        prefix + str(p),
        st.st_mtime_ns,
        st.st_size,
        origin,
        float(alt_m),
        float(grid_resolution_m),
        float(clearance_m),
        settings,
    )
    key = (str(p), st.st_mtime_ns, settings)
    if warn and key not in _WARNED and city.report is not None:
        _WARNED.add(key)
        for msg in city.report.warnings():
            warnings.warn(msg, stacklevel=2)
    return city


_WARNED: set[tuple[Any, ...]] = set()
"""Files (and reading settings) already reported (one set of warnings per file version)."""


@functools.lru_cache(maxsize=16)
def _load_cached(
    path: str,
    mtime_ns: int,
    size: int,
    origin: tuple[float, float] | None,
    alt_m: float,
    res: float,
    clearance: float,
    settings: tuple[Any, ...],
) -> FileCity:
    default_height_m, storey_height_m, repair, box = settings
    buildings, org, report = _read_buildings(
        path,
        origin_lat_lon=origin,
        alt_m=alt_m,
        storey_height_m=storey_height_m,
        default_height_m=default_height_m,
        max_origin_distance_m=MAX_ORIGIN_DISTANCE_M,
        repair=repair,
        bbox=box,
    )
    return city_from_buildings(
        buildings,
        origin=org,
        grid_resolution_m=res,
        clearance_m=clearance,
        source=path.removeprefix(OSM_PREFIX),
        report=report,
    )


def _walls_within(
    buildings: ExtrudedBuildings, cells: FloatArray, radius_m: float, tile_m: float = 100.0
) -> NDArray[np.int64]:
    """How many of 8 directions (45 deg apart) from each point ``(n, 3)`` meet a wall within
    ``radius_m`` (:meth:`ExtrudedBuildings.sky_and_walls`), ``(n,)``. The points are taken a
    tile of ``tile_m`` at a time, against the buildings whose bounding box comes within
    ``radius_m`` of the tile's points: a wall within the radius belongs to one of them, and the
    distance to it is the same number, so the counts are those of all buildings at once."""
    dirs = ray_directions(np.arange(0.0, 360.0, 45.0))
    out = np.zeros(cells.shape[0], dtype=np.int64)
    bb, es = buildings.bbox_m, buildings.edge_start
    _, tile = np.unique(np.floor(cells[:, :2] / tile_m), axis=0, return_inverse=True)
    tile = tile.reshape(-1)
    for k in range(int(tile.max()) + 1 if tile.size else 0):
        sel = np.nonzero(tile == k)[0]
        pts = np.ascontiguousarray(cells[sel])
        lo, hi = pts[:, :2].min(axis=0) - radius_m, pts[:, :2].max(axis=0) + radius_m
        sub = np.nonzero(
            (bb[:, 2] >= lo[0]) & (bb[:, 0] <= hi[0]) & (bb[:, 3] >= lo[1]) & (bb[:, 1] <= hi[1])
        )[0]
        if sub.size == 0:
            continue
        n_edges = es[sub + 1] - es[sub]
        start = np.r_[0, np.cumsum(n_edges)].astype(np.int64)
        idx = np.repeat(es[sub] - start[:-1], n_edges) + np.arange(start[-1])
        _, dist = _pk.sky_and_walls(
            pts, dirs, buildings.edges_m[idx], start, buildings.heights_m[sub], bb[sub]
        )
        out[sel] = np.sum(dist <= radius_m, axis=1)
    return out


def city_from_buildings(
    buildings: ExtrudedBuildings,
    *,
    origin: tuple[float, float, float],
    grid_resolution_m: float = GRID_RESOLUTION_M,
    clearance_m: float = CLEARANCE_M,
    extent_m: tuple[float, float, float, float] | None = None,
    source: str = "",
    report: CityReport | None = None,
) -> FileCity:
    """A :class:`FileCity` of extruded buildings in a local frame: the free-space grid, the
    reachable and built-up cells (module docstring), as a city file's.

    Parameters
    ----------
    buildings : ExtrudedBuildings
        The buildings, East/North [m] in the frame of ``origin``.
    origin : (float, float, float)
        ``(lat_deg, lon_deg, alt_m)`` of the frame.
    grid_resolution_m, clearance_m : float
        Free-space cell size and the distance kept from walls [m].
    extent_m : (x0, x1, y0, y1), optional
        The city's extent [m]; default: the footprints' bounding box widened by
        :data:`EXTENT_MARGIN_M` on every side.
    source : str
        What the city came from (named in messages).
    report : CityReport, optional
        What reading a file found.

    Raises
    ------
    CityFileError
        No free space between the buildings.
    """
    res, clearance = float(grid_resolution_m), float(clearance_m)
    bb = buildings.bbox_m
    if extent_m is None:
        x0, y0 = bb[:, 0].min() - EXTENT_MARGIN_M, bb[:, 1].min() - EXTENT_MARGIN_M
        x1, y1 = bb[:, 2].max() + EXTENT_MARGIN_M, bb[:, 3].max() + EXTENT_MARGIN_M
    else:
        x0, x1, y0, y1 = (float(v) for v in extent_m)
    xs = x0 + res / 2.0 + res * np.arange(max(int((x1 - x0) // res), 1))
    ys = y0 + res / 2.0 + res * np.arange(max(int((y1 - y0) // res), 1))
    clear = _pk.wall_clearance(
        xs, ys, max(clearance, PREFERRED_CLEARANCE_M), buildings.edges_m, buildings.edge_start, bb
    )
    free = clear >= clearance
    reach = _largest_component(free)
    if not np.any(reach):
        raise CityFileError(f"city file {source}: no free space between the buildings")
    rows, cols = np.nonzero(reach)
    cells = np.column_stack([xs[cols], ys[rows], np.full(rows.size, 0.5)])
    near = _walls_within(buildings, cells, BUILT_UP_RADIUS_M) >= BUILT_UP_MIN_DIRECTIONS
    built = np.zeros_like(reach)
    built[rows[near], cols[near]] = True
    built = _largest_component(built)  # routes between its cells need not leave it
    city = FileCity(
        buildings=buildings,  # type: ignore[arg-type]
        extent_m=(float(x0), float(x1), float(y0), float(y1)),
        street_centres_x_m=np.zeros(0),
        street_centres_y_m=np.zeros(0),
        open_squares=np.zeros((0, 2)),
        config=None,
        street_width_m=max(2.0 * clearance, res),
        grid_x_m=_readonly(xs),
        grid_y_m=_readonly(ys),
        free=_readonly(free),
        reachable=_readonly(reach),
        built_up=_readonly(built),
        origin=origin,
        source=source,
        n_default_height=0 if report is None else report.n_default_height,
        clearance_grid_m=_readonly(clear),
        report=report,
    )
    return city


# --------------------------------------------------------------------------------------------
# the sample city
# --------------------------------------------------------------------------------------------

SAMPLE_ORIGIN_LAT_LON: tuple[float, float] = (31.2330, 121.4950)
"""Where the sample city stands (Shanghai's Huangpu riverside, near the paper's site) [deg]."""


def sample_city_path() -> Path:
    """The sample city shipped with the package (``coopnav_env/data/sample_city.geojson``)."""
    return Path(__file__).resolve().parent.parent / "data" / "sample_city.geojson"


def _shape(rng: np.random.Generator, cx: float, cy: float, w: float, d: float) -> list[FloatArray]:
    """A footprint (rings) of one of five shapes inside a ``w`` x ``d`` lot centred at
    ``(cx, cy)`` [m]: rotated rectangle, L, U, convex polygon, courtyard block."""
    kind = int(rng.integers(0, 5))
    hw, hd = w / 2.0, d / 2.0
    if kind == 0:  # rectangle turned by a small angle
        a = math.radians(float(rng.uniform(-20.0, 20.0)))
        s = 1.0 / (abs(math.cos(a)) + abs(math.sin(a)))
        pts = np.array([[-hw, -hd], [hw, -hd], [hw, hd], [-hw, hd]]) * s
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return [pts @ rot.T + [cx, cy]]
    if kind == 1:  # L
        fx, fy = rng.uniform(0.35, 0.6, size=2)
        pts = np.array(
            [
                [-hw, -hd],
                [hw, -hd],
                [hw, -hd + fy * d],
                [-hw + fx * w, -hd + fy * d],
                [-hw + fx * w, hd],
                [-hw, hd],
            ]
        )
        return [pts + np.array([cx, cy])]
    if kind == 2:  # U
        f = float(rng.uniform(0.25, 0.35))
        pts = np.array(
            [
                [-hw, -hd],
                [hw, -hd],
                [hw, hd],
                [hw - f * w, hd],
                [hw - f * w, -hd + f * d],
                [-hw + f * w, -hd + f * d],
                [-hw + f * w, hd],
                [-hw, hd],
            ]
        )
        return [pts + np.array([cx, cy])]
    if kind == 3:  # convex polygon (5 to 8 vertices on an ellipse)
        k = int(rng.integers(5, 9))
        ang = np.sort(rng.uniform(0.0, 2 * math.pi, size=k))
        ang = np.linspace(0.0, 2 * math.pi, k, endpoint=False) + 0.3 * (ang - ang.mean()) / k
        return [np.stack([cx + hw * np.cos(ang), cy + hd * np.sin(ang)], axis=1)]
    # courtyard block: a rectangle with a rectangular hole
    f = float(rng.uniform(0.25, 0.35))
    outer = np.array([[-hw, -hd], [hw, -hd], [hw, hd], [-hw, hd]]) + np.array([cx, cy])
    inner = np.array([[-hw, -hd], [-hw, hd], [hw, hd], [hw, -hd]]) * (1.0 - 2.0 * f) + np.array(
        [cx, cy]
    )
    return [outer, inner]


def sample_city_geojson(seed: int = 7, n_blocks: int = 8) -> dict[str, Any]:
    """The sample city as a GeoJSON dict: ``n_blocks`` x ``n_blocks`` blocks of 60 m between
    20 m streets, about one block in ten left open and a diagonal avenue (no lot whose centre
    lies within 25 m of ``x = y``); each block split into 2 x 2 or 3 x 3 lots, nine in ten
    built with one footprint of five shapes (:func:`_shape`; roofs log-normal around 30 m, in
    [6, 180] m), its height given as a number, as a ``"NN m"`` string, as
    ``building:levels`` or (one in twenty) not at all. Synthetic: not a real place's
    buildings, placed near :data:`SAMPLE_ORIGIN_LAT_LON`. Deterministic in
    ``seed``; the shipped file is ``sample_city_geojson()``, written by
    ``write_sample_city(sample_city_path())`` (``tests/sim/test_file_city.py`` checks it)."""
    rng = np.random.default_rng(seed)
    block, street = 60.0, 20.0
    pitch = block + street
    size = n_blocks * block + (n_blocks + 1) * street
    lat0, lon0 = SAMPLE_ORIGIN_LAT_LON
    feats = []
    for bx in range(n_blocks):
        for by in range(n_blocks):
            if rng.random() < 0.1:
                continue
            x0 = -size / 2 + street + pitch * bx
            y0 = -size / 2 + street + pitch * by
            split = int(rng.integers(2, 4))
            lot = block / split
            for i in range(split):
                for j in range(split):
                    if rng.random() < 0.1:
                        continue
                    cx, cy = x0 + lot * (i + 0.5), y0 + lot * (j + 0.5)
                    if abs(cx - cy) < 25.0:  # the diagonal avenue
                        continue
                    w, d = lot * rng.uniform(0.7, 0.92, size=2)
                    rings = _shape(rng, cx, cy, w, d)
                    ll = []
                    for r in rings:
                        ecef = enu_to_ecef(
                            np.column_stack([r, np.zeros(r.shape[0])]), lat0, lon0, 0.0
                        )
                        lat, lon, _ = ecef_to_geodetic(ecef)
                        ring = np.round(np.column_stack([lon, lat]), 8).tolist()
                        ll.append([*ring, ring[0]])
                    h = float(np.clip(rng.lognormal(math.log(30.0), 0.6), 6.0, 180.0))
                    style = rng.random()
                    if style < 0.05:
                        props: dict[str, Any] = {"building": "yes"}
                    elif style < 0.35:
                        props = {"building": "yes", "building:levels": max(round(h / 3.0), 2)}
                    elif style < 0.65:
                        props = {"building": "yes", "height": f"{h:.1f} m"}
                    else:
                        props = {"building": "yes", "height": round(h, 1)}
                    feats.append(
                        {
                            "type": "Feature",
                            "id": f"b{len(feats)}",
                            "properties": props,
                            "geometry": {"type": "Polygon", "coordinates": ll},
                        }
                    )
    return {
        "type": "FeatureCollection",
        "name": "coopnav sample city (synthetic footprints, not a real place's buildings)",
        "features": feats,
    }


def write_sample_city(path: str | os.PathLike[str], seed: int = 7) -> Path:
    """Write :func:`sample_city_geojson` to ``path`` (temporary name, then rename)."""
    out = Path(path)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(sample_city_geojson(seed), indent=None) + "\n", encoding="utf-8")
    os.replace(tmp, out)
    return out
