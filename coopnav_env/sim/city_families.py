"""Generated cities of several families, a new one from each random generator.

A family is a way of laying out streets and buildings, with the street widths and roof heights
of a kind of district. Each generator draws, from one ``numpy.random.Generator``, building
footprints (polygon rings in a local East-North frame [m], holes allowed) and roof heights [m]
inside a square of :data:`FAMILY_SIZE_M` centred on the origin, a street of at least
:data:`BORDER_STREET_M` kept free along its edge. :func:`family_city` turns them into a
:class:`~coopnav_env.sim.file_city.FileCity` through
:func:`~coopnav_env.sim.file_city.city_from_buildings`, so that a generated city has the
free-space grid, built-up area, routes, starts and goals of a city read from a file. The
environment flies them as ``city="family:NAME"``
(:class:`~coopnav_env.sim.scenario.ScenarioConfig`).

The families (:data:`FAMILIES`)
-------------------------------
``irregular``
    Voronoi blocks around jittered seeds about 75 m apart; each street (between two
    neighbouring cells) its own width, 10-26 m; blocks cut into lots of 250-900 m^2; roofs
    log-normal around 18 m (6-80 m); one block in twenty left open as a square.
``old_town``
    Voronoi blocks about 42 m across; lanes 6-9 m wide (three in ten; narrower than the
    free space's clearance allows to fly, they open the sky only) and streets 12-16 m;
    lots of 120-400 m^2; roofs of 3-6 storeys (3.2 m each, up to 1.5 m more for the roof); one
    block in fourteen a small square.
``high_rise``
    A street grid turned by a random angle, street centres 70-110 m apart, streets 22-36 m
    wide; one to four towers per block, 2-6 m apart and set back 1-3 m, those under
    150 m^2 left out; roofs heavy-tailed (Pareto, shape 1.5, above 20 m, median near 32 m,
    capped at 300 m); one block in twelve a plaza.
``avenues``
    A turned street grid (street centres 70-105 m apart, streets 14-20 m), every third line
    a boulevard 35-50 m wide, and two diagonal avenues 20-30 m wide through the middle third
    of the square; lots of 300-1000 m^2; roofs normal around 24 m (12-45 m); one block in
    twenty open.
``courtyards``
    Perimeter blocks on a turned grid (street centres 81-119 m apart, streets 16-24 m): each
    block one building with a chamfered outline (corners cut 6-12 m) and an inner yard (a
    hole) 11-16 m behind the street wall; roofs 15-27 m; one block in ten a park.

The geometry is pure numpy: blocks are convex pieces of the square cut by streets (straight
lines with a width, or the bisectors of Voronoi seeds), lots are convex pieces of the blocks,
so footprints never overlap and never leave the square.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from coopnav_env.sim.city import City
from coopnav_env.sim.file_city import (
    CLEARANCE_M,
    GRID_RESOLUTION_M,
    ExtrudedBuildings,
    FileCity,
    city_from_buildings,
)

__all__ = [
    "BORDER_STREET_M",
    "FAMILIES",
    "FAMILY_PREFIX",
    "FAMILY_SIZE_M",
    "MIXED_FAMILY",
    "SEEDED_CACHE_SIZE",
    "CityStatistics",
    "FamilyFootprints",
    "city_statistics",
    "family_city",
    "family_footprints",
    "family_name",
    "family_of_seed",
    "seeded_family_city",
    "statistics_table",
]

FloatArray = NDArray[np.float64]

FAMILY_PREFIX: str = "family:"
"""Prefix of the environment's ``city`` setting that names a city family."""
FAMILY_SIZE_M: float = 500.0
"""Side of the square a generated city fills [m] (the default grid city's size)."""
BORDER_STREET_M: float = 8.0
"""Width of the free strip kept inside the square's edge [m]."""
SEEDED_CACHE_SIZE: int = 256
"""Cities :func:`seeded_family_city` keeps (the latest seeds)."""
_MIN_BUILDING_AREA_M2 = 40.0
_MIN_BLOCK_AREA_M2 = 150.0


# --------------------------------------------------------------------------------------------
# convex polygon operations (vertices counter-clockwise, (k, 2), no closing repeat)
# --------------------------------------------------------------------------------------------


def _clip(poly: FloatArray, n: FloatArray, c: float) -> FloatArray:
    """The part of convex ``poly`` where ``n . p <= c`` (Sutherland-Hodgman, one half-plane:
    each vertex inside is kept, followed by the crossing of its edge where the edge leaves or
    enters). Plain floats: the polygons have a handful of vertices."""
    if poly.shape[0] == 0:
        return poly
    nx, ny = float(n[0]), float(n[1])
    pts = poly.tolist()
    s = [x * nx + y * ny - c for x, y in pts]
    if max(s) <= 0.0:
        return poly
    if min(s) > 0.0:
        return poly[:0]
    out = []
    k = len(pts)
    for i in range(k):
        j = i + 1 if i + 1 < k else 0
        si, sj = s[i], s[j]
        if si <= 0.0:
            out.append(pts[i])
        if (si <= 0.0) != (sj <= 0.0):
            t = si / (si - sj)
            (xi, yi), (xj, yj) = pts[i], pts[j]
            out.append([xi + t * (xj - xi), yi + t * (yj - yi)])
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def _area(poly: FloatArray) -> float:
    """Area of a simple polygon [m^2] (positive when counter-clockwise)."""
    if poly.shape[0] < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * (float(x[:-1] @ y[1:] - x[1:] @ y[:-1]) + float(x[-1] * y[0] - x[0] * y[-1]))


def _split(poly: FloatArray, n: FloatArray, c: float, width: float) -> list[FloatArray]:
    """The pieces of ``poly`` either side of the strip ``|n . p - c| < width / 2``."""
    lo = _clip(poly, n, c - width / 2.0)
    hi = _clip(poly, -n, -(c + width / 2.0))
    return [p for p in (lo, hi) if _area(p) > 1e-6]


def _inset(poly: FloatArray, d: float) -> FloatArray:
    """Convex ``poly`` shrunk by ``d`` [m] (every edge moved inward by ``d``)."""
    out = poly
    for i in range(poly.shape[0]):
        a, b = poly[i], poly[(i + 1) % poly.shape[0]]
        e = b - a
        norm = math.hypot(e[0], e[1])
        if norm < 1e-9:
            continue
        n = np.array([e[1], -e[0]]) / norm  # outward for a counter-clockwise polygon
        out = _clip(out, n, float(n @ a) - d)
        if out.shape[0] == 0:
            break
    return out


def _chamfer(poly: FloatArray, cut_m: float) -> FloatArray:
    """Convex ``poly`` with each corner cut off ``cut_m`` [m] along both of its edges."""
    out = poly
    k = poly.shape[0]
    for i in range(k):
        v, a, b = poly[i], poly[i - 1], poly[(i + 1) % k]
        ua, ub = a - v, b - v
        la, lb = math.hypot(*ua), math.hypot(*ub)
        if la < 3.0 * cut_m or lb < 3.0 * cut_m:
            continue
        p, q = v + ua / la * cut_m, v + ub / lb * cut_m
        e = q - p
        n = np.array([e[1], -e[0]]) / math.hypot(*e)
        if n @ (v - p) < 0.0:
            n = -n
        out = _clip(out, n, float(n @ p))
    return out


def _subdivide(
    poly: FloatArray, rng: np.random.Generator, max_area: float, gap_m: float
) -> list[FloatArray]:
    """Lots of a convex block: halved across its longest side (cut 35-65 % along it, ``gap_m``
    apart) until every lot is at most ``max_area`` [m^2]."""
    todo, lots = [poly], []
    while todo:
        p = todo.pop()
        if _area(p) <= max_area:
            lots.append(p)
            continue
        centred = p - p.mean(axis=0)
        (sxx, sxy), (_, syy) = centred.T @ centred
        theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)  # the vertices' principal axis
        axis = np.array([math.cos(theta), math.sin(theta)])
        s = centred @ axis
        c = float(p.mean(axis=0) @ axis + s.min() + (s.max() - s.min()) * rng.uniform(0.35, 0.65))
        pieces = _split(p, axis, c, gap_m)
        if len(pieces) < 2:
            lots.append(p)
            continue
        todo.extend(pieces)
    return lots


def _area_square() -> FloatArray:
    h = FAMILY_SIZE_M / 2.0 - BORDER_STREET_M
    return np.array([[-h, -h], [h, -h], [h, h], [-h, h]], dtype=np.float64)


def _grid_lines(
    rng: np.random.Generator,
    angle_rad: float,
    pitch_m: tuple[float, float],
    width_m: tuple[float, float],
) -> list[tuple[FloatArray, float, float]]:
    """Two families of parallel streets at right angles, turned by ``angle_rad``: ``(normal,
    offset, width)`` each, blocks ``pitch_m`` apart (uniform) covering the square."""
    reach = FAMILY_SIZE_M / math.sqrt(2.0) + 100.0
    lines = []
    for turn in (0.0, math.pi / 2.0):
        n = np.array([math.cos(angle_rad + turn), math.sin(angle_rad + turn)])
        c = -reach + float(rng.uniform(0.0, pitch_m[1]))
        while c < reach:
            lines.append((n, c, float(rng.uniform(*width_m))))
            c += float(rng.uniform(*pitch_m))
    return lines


def _blocks_from_lines(lines: list[tuple[FloatArray, float, float]]) -> list[FloatArray]:
    """Convex blocks of the square between the streets ``lines``."""
    blocks = [_area_square()]
    for n, c, w in lines:
        nxt = []
        for b in blocks:
            nxt.extend(_split(b, n, c, w))
        blocks = nxt
    return [b for b in blocks if _area(b) >= _MIN_BLOCK_AREA_M2]


def _voronoi_blocks(rng: np.random.Generator, spacing_m: float, width_of: Any) -> list[FloatArray]:
    """Voronoi cells of seeds jittered about a grid ``spacing_m`` apart, each shrunk by half
    the width of the street it shares with each neighbour (``width_of(rng, size)`` draws the
    widths [m], one per pair of seeds)."""
    h = FAMILY_SIZE_M / 2.0
    k = math.ceil(FAMILY_SIZE_M / spacing_m) + 1
    g = -h + spacing_m * (np.arange(k) + 0.5) - (k * spacing_m - FAMILY_SIZE_M) / 2.0
    gx, gy = np.meshgrid(g, g)
    seeds = np.column_stack([gx.ravel(), gy.ravel()])
    seeds = seeds + rng.uniform(-0.4, 0.4, size=seeds.shape) * spacing_m
    m = seeds.shape[0]
    widths = width_of(rng, m * m).reshape(m, m)
    widths = np.triu(widths, 1)
    widths = widths + widths.T
    w_max = float(widths.max())
    square = _area_square()
    blocks = []
    for i in range(m):
        d = seeds - seeds[i]
        dist = np.hypot(d[:, 0], d[:, 1])
        cell = square
        reach = float(np.max(np.hypot(*(cell - seeds[i]).T)))
        for j in np.argsort(dist)[1:]:
            if dist[j] / 2.0 - w_max / 2.0 > reach:  # this and every farther street misses
                break
            n = d[j] / dist[j]
            cut = _clip(cell, n, float(n @ (seeds[i] + seeds[j]) / 2.0) - widths[i, j] / 2.0)
            if cut.shape[0] == 0:
                cell = cut
                break
            if cut is not cell:
                cell = cut
                reach = float(np.max(np.hypot(*(cell - seeds[i]).T)))
        if _area(cell) >= _MIN_BLOCK_AREA_M2:
            blocks.append(cell)
    return blocks


def _lots(
    blocks: list[FloatArray],
    rng: np.random.Generator,
    open_share: float,
    lot_area_m2: tuple[float, float],
    gap_m: float,
    setback_m: tuple[float, float] = (0.0, 0.0),
) -> list[FloatArray]:
    """Building footprints: each block left open with probability ``open_share``, else cut
    into lots of at most a uniform draw in ``lot_area_m2``, each lot shrunk by a setback."""
    out = []
    for b in blocks:
        if rng.random() < open_share:
            continue
        for lot in _subdivide(b, rng, float(rng.uniform(*lot_area_m2)), gap_m):
            back = float(rng.uniform(*setback_m))
            fp = _inset(lot, back) if back > 0.0 else lot
            if _area(fp) >= _MIN_BUILDING_AREA_M2:
                out.append(fp)
    return out


# --------------------------------------------------------------------------------------------
# the families
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FamilyFootprints:
    """What a family generator draws.

    Attributes
    ----------
    rings_m : list of list of ndarray
        Per building, its rings (exterior first, then holes), each ``(k, 2)`` East/North [m].
    heights_m : ndarray, shape (n_b,)
        Roof heights [m].
    family : str
        The family's name.
    """

    rings_m: list[list[FloatArray]]
    heights_m: FloatArray
    family: str


def _irregular(rng: np.random.Generator) -> FamilyFootprints:
    blocks = _voronoi_blocks(rng, 75.0, lambda r, k: r.uniform(10.0, 26.0, size=k))
    fps = _lots(blocks, rng, 0.05, (250.0, 900.0), 1.0)
    h = np.clip(rng.lognormal(math.log(18.0), 0.5, size=len(fps)), 6.0, 80.0)
    return FamilyFootprints([[f] for f in fps], h, "irregular")


def _old_town(rng: np.random.Generator) -> FamilyFootprints:
    def widths(r: np.random.Generator, k: int) -> FloatArray:
        lane = r.random(k) < 0.3
        return np.where(lane, r.uniform(6.0, 9.0, size=k), r.uniform(12.0, 16.0, size=k))

    blocks = _voronoi_blocks(rng, 42.0, widths)
    fps = _lots(blocks, rng, 0.07, (120.0, 400.0), 1.0)
    storeys = rng.integers(3, 7, size=len(fps))
    h = 3.2 * storeys + rng.uniform(0.0, 1.5, size=len(fps))
    return FamilyFootprints([[f] for f in fps], h, "old_town")


def _high_rise(rng: np.random.Generator) -> FamilyFootprints:
    lines = _grid_lines(rng, float(rng.uniform(0.0, math.pi / 2.0)), (70.0, 110.0), (22.0, 36.0))
    blocks = _blocks_from_lines(lines)
    fps = []
    for b in blocks:
        if rng.random() < 0.08:
            continue
        n_towers = int(rng.integers(1, 5))
        for lot in _subdivide(b, rng, _area(b) / n_towers, float(rng.uniform(2.0, 6.0))):
            fp = _inset(lot, float(rng.uniform(1.0, 3.0)))
            if _area(fp) >= 150.0:
                fps.append(fp)
    h = np.minimum(20.0 * rng.uniform(0.0, 1.0, size=len(fps)) ** (-1.0 / 1.5), 300.0)
    return FamilyFootprints([[f] for f in fps], h, "high_rise")


def _avenues(rng: np.random.Generator) -> FamilyFootprints:
    angle = float(rng.uniform(0.0, math.pi / 2.0))
    lines = _grid_lines(rng, angle, (70.0, 105.0), (14.0, 20.0))
    offset = int(rng.integers(0, 3))
    lines = [
        (n, c, float(rng.uniform(35.0, 50.0)) if i % 3 == offset else w)
        for i, (n, c, w) in enumerate(lines)
    ]
    for turn in (math.pi / 4.0, -math.pi / 4.0):  # two diagonals through the middle third
        t = angle + turn + float(rng.uniform(-0.2, 0.2))
        n = np.array([math.cos(t), math.sin(t)])
        c = float(n @ rng.uniform(-FAMILY_SIZE_M / 6.0, FAMILY_SIZE_M / 6.0, size=2))
        lines.append((n, c, float(rng.uniform(20.0, 30.0))))
    fps = _lots(_blocks_from_lines(lines), rng, 0.05, (300.0, 1000.0), 1.0)
    h = np.clip(rng.normal(24.0, 6.0, size=len(fps)), 12.0, 45.0)
    return FamilyFootprints([[f] for f in fps], h, "avenues")


def _courtyards(rng: np.random.Generator) -> FamilyFootprints:
    lines = _grid_lines(rng, float(rng.uniform(0.0, math.pi / 2.0)), (81.0, 119.0), (16.0, 24.0))
    rings: list[list[FloatArray]] = []
    for b in _blocks_from_lines(lines):
        if rng.random() < 0.10:
            continue
        outer = _chamfer(b, float(rng.uniform(6.0, 12.0)))
        yard = _inset(outer, float(rng.uniform(11.0, 16.0)))
        if _area(outer) < _MIN_BUILDING_AREA_M2:
            continue
        rings.append([outer, yard[::-1].copy()] if _area(yard) >= 100.0 else [outer])
    h = rng.uniform(15.0, 27.0, size=len(rings))
    return FamilyFootprints(rings, h, "courtyards")


_GENERATORS = {
    "irregular": _irregular,
    "old_town": _old_town,
    "high_rise": _high_rise,
    "avenues": _avenues,
    "courtyards": _courtyards,
}
FAMILIES: tuple[str, ...] = tuple(_GENERATORS)
"""The city families, in the order the documentation shows them."""
MIXED_FAMILY: str = "mixed"
"""``city="family:mixed"``: every city of a family drawn from its city seed
(:func:`family_of_seed`), each of :data:`FAMILIES` equally often."""


def family_name(spec: str) -> str:
    """The family a ``city`` setting ``"family:NAME"`` (or a bare ``NAME``) names
    (:data:`MIXED_FAMILY` for ``"family:mixed"``).

    Raises
    ------
    ValueError
        An unknown family, listing the known ones.
    """
    name = spec[len(FAMILY_PREFIX) :] if spec.startswith(FAMILY_PREFIX) else spec
    if name not in _GENERATORS and name != MIXED_FAMILY:
        raise ValueError(
            f"unknown city family {name!r}; the families are "
            + ", ".join(f"'{FAMILY_PREFIX}{f}'" for f in (*FAMILIES, MIXED_FAMILY))
        )
    return name


def family_of_seed(name: str, seed: int) -> str:
    """The family of the city of ``seed`` under a ``city`` setting naming ``name``: ``name``
    itself, or for :data:`MIXED_FAMILY` ``FAMILIES[seed % len(FAMILIES)]`` (city seeds are
    drawn uniformly, so each family comes equally often)."""
    name = family_name(name)
    return FAMILIES[int(seed) % len(FAMILIES)] if name == MIXED_FAMILY else name


def family_footprints(name: str, rng: np.random.Generator) -> FamilyFootprints:
    """Draw one city of family ``name`` (:data:`FAMILIES`) from ``rng``: footprints and roofs
    (the same generator state gives the same city)."""
    family = family_name(name)
    if family == MIXED_FAMILY:
        raise ValueError(
            f"{FAMILY_PREFIX}{MIXED_FAMILY} names every family: draw one city of one family "
            "(family_of_seed gives the family of a city seed)"
        )
    return _GENERATORS[family](rng)


def family_city(
    name: str,
    rng: np.random.Generator,
    *,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    grid_resolution_m: float = GRID_RESOLUTION_M,
    clearance_m: float = CLEARANCE_M,
) -> FileCity:
    """A city of family ``name`` drawn from ``rng``, with its free-space grid, built-up area
    and routes (:func:`~coopnav_env.sim.file_city.city_from_buildings`); its extent is the
    square of :data:`FAMILY_SIZE_M` whatever was drawn.

    Parameters
    ----------
    name : str
        One of :data:`FAMILIES` (``"family:"`` prefix allowed).
    rng : numpy.random.Generator
        Source of every draw.
    origin : (float, float, float)
        ``(lat_deg, lon_deg, alt_m)`` of the city's frame.
    grid_resolution_m, clearance_m : float
        As for :func:`~coopnav_env.sim.file_city.load_file_city`.
    """
    fp = family_footprints(name, rng)
    buildings = ExtrudedBuildings.from_rings(
        fp.rings_m, fp.heights_m, [f"building {i}" for i in range(len(fp.rings_m))]
    )
    h = FAMILY_SIZE_M / 2.0
    return city_from_buildings(
        buildings,
        origin=origin,
        grid_resolution_m=grid_resolution_m,
        clearance_m=clearance_m,
        extent_m=(-h, h, -h, h),
        source=FAMILY_PREFIX + fp.family,
    )


@functools.lru_cache(maxsize=SEEDED_CACHE_SIZE)
def seeded_family_city(name: str, seed: int, origin: tuple[float, float, float]) -> FileCity:
    """:func:`family_city` drawn from ``numpy.random.default_rng(seed)``, kept for the
    :data:`SEEDED_CACHE_SIZE` latest seeds and arguments (the environment's city of a
    ``city_seed``, or of the city seed an episode draws)."""
    return family_city(name, np.random.default_rng(seed), origin=origin)


# --------------------------------------------------------------------------------------------
# statistics
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CityStatistics:
    """What a city looks like, measured the same way for generated and real cities.

    Attributes
    ----------
    name : str
    n_buildings : int
    built_share : float
        Footprint area (holes excluded) over the area of the city's extent.
    height_mean_m, height_median_m, height_p90_m : float
        Roof heights over buildings [m].
    street_width_m : float
        Median over sampled built-up free cells of the narrowest wall-to-wall width through
        the cell (the least of ``d(az) + d(az + 180)`` over 8 axes 22.5 deg apart, at
        ground level) [m], each cell weighted by one over its width (so that a street counts
        by its length, not its area).
    h_over_w : float
        Footprint-area-weighted mean roof height over ``street_width_m``.
    open_sky_share : float
        Share of the sampled cells where, at ``altitude_m``, the skyline stays below 45 deg
        elevation in all 16 directions (the zenith cone of 45 deg half-angle is clear).
    mean_skyline_deg : float
        Mean skyline elevation over the sampled cells and 16 directions at ``altitude_m``.
    """

    name: str
    n_buildings: int
    built_share: float
    height_mean_m: float
    height_median_m: float
    height_p90_m: float
    street_width_m: float
    h_over_w: float
    open_sky_share: float
    mean_skyline_deg: float


def _footprint_areas(buildings: ExtrudedBuildings) -> FloatArray:
    return np.array(
        [
            abs(_area(rings[0])) - sum(abs(_area(r)) for r in rings[1:])
            for rings in buildings.rings_m
        ]
    )


def city_statistics(
    city: City,
    name: str = "",
    *,
    n_cells: int = 1500,
    altitude_m: float = 15.0,
    seed: int = 0,
) -> CityStatistics:
    """:class:`CityStatistics` of a city, sampling ``n_cells`` built-up free cells of its
    free-space grid (``seed`` picks them). A box city (``city="grid"``) is measured as the
    polygon city of its boxes (:func:`~coopnav_env.sim.file_city.city_from_buildings` over its
    extent)."""
    if not isinstance(city, FileCity):
        fp = np.asarray(city.buildings.footprints_m)
        rings = [[fp[i, [0, 1, 2, 1, 2, 3, 0, 3]].reshape(4, 2)] for i in range(fp.shape[0])]
        boxes = ExtrudedBuildings.from_rings(rings, city.buildings.heights_m)
        city = city_from_buildings(
            boxes, origin=(0.0, 0.0, 0.0), extent_m=city.extent_m, source=name or "box city"
        )
    b = city.buildings
    rows, cols = np.nonzero(city.built_up if np.any(city.built_up) else city.reachable)
    pick = np.random.default_rng(seed).choice(rows.size, min(n_cells, rows.size), replace=False)
    xy = np.column_stack([city.grid_x_m[cols[pick]], city.grid_y_m[rows[pick]]])
    az = np.arange(0.0, 360.0, 22.5)
    _, wall_m = b.sky_and_walls(np.column_stack([xy, np.full(len(xy), 0.5)]), az)
    width = np.min(wall_m[:, :8] + wall_m[:, 8:], axis=1)
    width = width[np.isfinite(width)]
    order = np.argsort(width)  # median weighted by 1 / width: per street length, not area
    cum = np.cumsum(1.0 / width[order])
    width_m = float(width[order][np.searchsorted(cum, cum[-1] / 2.0)]) if width.size else np.nan
    sky_deg, _ = b.sky_and_walls(np.column_stack([xy, np.full(len(xy), altitude_m)]), az)
    areas = _footprint_areas(b)
    h = np.asarray(b.heights_m)
    x0, x1, y0, y1 = city.extent_m
    h_mean_area = float(np.sum(h * areas) / np.sum(areas))
    return CityStatistics(
        name=name or city.source,
        n_buildings=b.n,
        built_share=float(areas.sum() / ((x1 - x0) * (y1 - y0))),
        height_mean_m=float(h.mean()),
        height_median_m=float(np.median(h)),
        height_p90_m=float(np.percentile(h, 90)),
        street_width_m=width_m,
        h_over_w=h_mean_area / width_m,
        open_sky_share=float(np.mean(np.all(sky_deg < 45.0, axis=1))),
        mean_skyline_deg=float(sky_deg.mean()),
    )


def statistics_table(rows: list[CityStatistics]) -> str:
    """A Markdown table of :class:`CityStatistics`, one row per city."""
    head = (
        "| city | buildings | built share | height mean / median / p90 [m] | street width [m] "
        "| H/W | open sky | mean skyline [deg] |\n|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for s in rows:
        lines.append(
            f"| {s.name} | {s.n_buildings} | {s.built_share:.2f} | {s.height_mean_m:.1f} / "
            f"{s.height_median_m:.1f} / {s.height_p90_m:.1f} | {s.street_width_m:.1f} | "
            f"{s.h_over_w:.2f} | {s.open_sky_share:.2f} | {s.mean_skyline_deg:.1f} |"
        )
    return "\n".join(lines)
