"""The city from a GeoJSON file: reading, errors, polygon line of sight against independent
computations, sensors, collisions, free space and routes.

Line of sight is checked against two computations that share no code with the kernel of
:mod:`coopnav_env.sim._polygon_kernels` (a 2-D first-entry distance along the ray's ground
track):

* a 3-D brute force in numpy (:func:`_brute_los`): the ray against every wall rectangle
  (edge x [0, roof], solved in its vertical plane) and every roof polygon (the plane
  ``z = roof`` with a winding-number inside test), plus the start-inside case;
* shapely (optional, ``pip install coopnav[geo]``): the intersection of the ray's ground track
  with each footprint, the first point of it (its distance to the receiver) and the ray's
  height there against the roof.

Grazing cases, where the two may disagree and neither is wrong: a ray that only touches a
footprint at a vertex or runs along an edge (the kernel counts a touch as entering, shapely
returns a point or segment there too, the 3-D brute force may miss a touch by rounding), and a
ray whose height at the entry equals the roof to rounding (the kernel's rule: at most
roof-high is blocked). The tests flag a ray as grazing when its margin at the decisive
building, ``|roof - height at entry|``, is below 1e-6 m or its ground track passes within
1e-6 m of a footprint vertex, and require agreement on every other ray.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.sim import file_city as fc
from coopnav_env.sim.city import (
    is_inside_building,
    line_of_sight,
    mask_elevation_deg,
    sky_and_walls,
    wall_distance_m,
)
from coopnav_env.sim.osm_city import helsinki_geojson_path
from tests.sim import oracles

GRAZE_M = 1e-6

# the shipped real city's heights are mostly unknown: its warning is tested where it matters
pytestmark = pytest.mark.filterwarnings("ignore:.*get the default height")


@pytest.fixture(scope="module")
def city() -> fc.FileCity:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fc.load_file_city(fc.sample_city_path())


def _random_rays(city: fc.FileCity, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Receivers in the city's extent at 0.5-80 m (some inside buildings) and directions at
    1-89 deg elevation."""
    rng = np.random.default_rng(seed)
    x0, x1, y0, y1 = city.extent_m
    pos = np.column_stack(
        [rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(0.5, 80.0, n)]
    )
    az = rng.uniform(0.0, 2 * math.pi, n)
    el = np.radians(rng.uniform(1.0, 89.0, n))
    d = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    return pos, d


def _per_ray_los(city: fc.FileCity, pos: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The kernel's verdict for ray i = (pos[i], d[i]), by groups of 50 directions."""
    out = np.empty(pos.shape[0], dtype=bool)
    for s in range(0, pos.shape[0], 50):
        sl = slice(s, s + 50)
        out[sl] = np.diagonal(line_of_sight(city.buildings, pos[sl], d[sl]))
    return out


def _brute_los(b: fc.ExtrudedBuildings, p: np.ndarray, d: np.ndarray) -> tuple[bool, bool]:
    """3-D brute force for one ray: (visible, grazing)."""
    tan_el = d[2] / math.hypot(d[0], d[1])
    u = d / np.linalg.norm(d)
    blocked, graze = False, False
    # only buildings taller than the receiver whose box lies within the ray's reach
    bb = b.bbox_m
    ddx = np.maximum(np.maximum(bb[:, 0] - p[0], 0.0), p[0] - bb[:, 2])
    ddy = np.maximum(np.maximum(bb[:, 1] - p[1], 0.0), p[1] - bb[:, 3])
    near = (b.heights_m > p[2] - 1e-9) & (np.hypot(ddx, ddy) * tan_el <= b.heights_m - p[2] + 1)
    for k in np.flatnonzero(near):
        h = b.heights_m[k]
        e = b.edges_m[b.edge_start[k] : b.edge_start[k + 1]]
        a, c = e[:, :2], e[:, 2:]
        # walls: plane through the edge, vertical; ray p + s u
        ev = c - a
        nrm = np.column_stack([-ev[:, 1], ev[:, 0]])
        den = nrm @ u[:2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.einsum("ij,ij->i", nrm, a - p[:2]) / den
            q = p[:2] + s[:, None] * u[:2]
            w = np.einsum("ij,ij->i", q - a, ev) / np.einsum("ij,ij->i", ev, ev)
        z = p[2] + s * u[2]
        hit = (den != 0) & (s > 0) & (w >= 0) & (w <= 1) & (z <= h)
        # roof: the plane z = h, winding number of the crossing point
        s_r = (h - p[2]) / u[2]
        r = p[:2] + s_r * u[:2]
        ang = np.arctan2(a[:, 1] - r[1], a[:, 0] - r[0])
        ang2 = np.arctan2(c[:, 1] - r[1], c[:, 0] - r[0])
        dang = (ang2 - ang + np.pi) % (2 * np.pi) - np.pi
        # even-odd over rings = winding parity for simple, nested rings
        roof_in = s_r > 0 and round(abs(dang.sum()) / (2 * np.pi)) % 2 == 1
        ang0 = np.arctan2(a[:, 1] - p[1], a[:, 0] - p[0])
        ang1 = np.arctan2(c[:, 1] - p[1], c[:, 0] - p[0])
        d0 = (ang1 - ang0 + np.pi) % (2 * np.pi) - np.pi
        start_in = p[2] <= h and round(abs(d0.sum()) / (2 * np.pi)) % 2 == 1
        if np.any(hit) or roof_in or start_in:
            blocked = True
        # grazing: a vertex near the ground track, or a wall crossing at roof height
        rel = a - p[:2]
        along = rel @ u[:2] / math.hypot(*u[:2])
        perp = np.abs(rel[:, 0] * u[1] - rel[:, 1] * u[0]) / math.hypot(*u[:2])
        if np.any((perp < GRAZE_M) & (along > -GRAZE_M)):
            graze = True
        t_h = np.where(den != 0, s * math.hypot(*u[:2]), np.inf)
        on = (den != 0) & (s > 0) & (w >= -1e-9) & (w <= 1 + 1e-9)
        if np.any(on & (np.abs(p[2] + t_h * tan_el - h) < GRAZE_M)):
            graze = True
    return not blocked, graze


def test_line_of_sight_agrees_with_3d_brute_force(city: fc.FileCity) -> None:
    pos, d = _random_rays(city, 400, seed=1)
    kern = _per_ray_los(city, pos, d)
    bad = []
    n_graze = 0
    for i in range(pos.shape[0]):
        vis, graze = _brute_los(city.buildings, pos[i], d[i])
        n_graze += graze
        if vis != kern[i] and not graze:
            bad.append(i)
    assert not bad, f"{len(bad)} disagreements, first ray {bad[0]}: {pos[bad[0]]}, {d[bad[0]]}"
    assert 0.2 < kern.mean() < 0.9  # the sample really has both outcomes
    assert n_graze <= 2


def _shapely_los(city: fc.FileCity, pos: np.ndarray, d: np.ndarray):
    """Visible and grazing per ray from shapely's track/footprint intersections."""
    shapely = pytest.importorskip("shapely")
    from shapely import STRtree

    b = city.buildings
    polys = [shapely.Polygon(r[0], r[1:]) for r in b.rings_m]
    verts = [np.concatenate(r) for r in b.rings_m]
    tree = STRtree(polys)
    hxy = np.hypot(d[:, 0], d[:, 1])
    u = d[:, :2] / hxy[:, None]
    tan_el = d[:, 2] / hxy
    reach = np.maximum(b.heights_m.max() - pos[:, 2], 0.0) / tan_el + 1.0
    ends = pos[:, :2] + u * reach[:, None]
    lines = shapely.linestrings(np.stack([pos[:, :2], ends], axis=1))
    points = shapely.points(pos[:, :2])
    ray_i, bld = tree.query(lines, predicate="intersects")
    inter = shapely.intersection(np.array(polys, dtype=object)[bld], lines[ray_i])
    t_in = shapely.distance(points[ray_i], inter)
    margin = b.heights_m[bld] - (pos[ray_i, 2] + t_in * tan_el[ray_i])
    blocked = np.zeros(pos.shape[0], dtype=bool)
    np.logical_or.at(blocked, ray_i, margin >= 0.0)
    graze = np.zeros(pos.shape[0], dtype=bool)
    np.logical_or.at(graze, ray_i, np.abs(margin) < GRAZE_M)
    # a footprint vertex within GRAZE_M of the ground track
    vertex_sets = np.array([shapely.multipoints(v) for v in verts], dtype=object)
    near_vertex = shapely.distance(lines[ray_i], vertex_sets[bld]) < GRAZE_M
    np.logical_or.at(graze, ray_i, near_vertex)
    return ~blocked, graze


def _check_against_shapely(city: fc.FileCity, n: int, seed: int) -> None:
    pos, d = _random_rays(city, n, seed)
    vis, graze = _shapely_los(city, pos, d)
    kern = _per_ray_los(city, pos, d)
    bad = np.flatnonzero((vis != kern) & ~graze)
    assert bad.size == 0, (
        f"{bad.size} of {n} rays disagree away from grazing; first: pos {pos[bad[0]]}, "
        f"dir {d[bad[0]]}, kernel visible {kern[bad[0]]}"
    )
    assert graze.sum() <= max(3, n // 10_000)
    assert 0.2 < kern.mean() < 0.9


def test_line_of_sight_agrees_with_shapely_5000_rays(city: fc.FileCity) -> None:
    _check_against_shapely(city, 5_000, seed=2)


@pytest.mark.slow
def test_line_of_sight_agrees_with_shapely_100000_rays(city: fc.FileCity) -> None:
    _check_against_shapely(city, 100_000, seed=3)


def test_skyline_and_walls_match_line_of_sight_and_inside_test(city: fc.FileCity) -> None:
    rng = np.random.default_rng(4)
    pts = city.random_street_points(rng, 60, altitude_m=12.0)
    az = np.arange(0.0, 360.0, 7.5)
    sky, walls = sky_and_walls(city.buildings, pts, az)
    np.testing.assert_array_equal(sky, mask_elevation_deg(city.buildings, pts, az))
    np.testing.assert_array_equal(walls, wall_distance_m(city.buildings, pts, az))
    assert np.all((sky >= 0) & (sky < 90)) and np.any(sky > 20)
    for i in range(pts.shape[0]):
        for j, a in enumerate(az):
            m = sky[i, j]
            if m < 0.05:
                continue
            dirs = []
            for el in (m - 0.01, m + 0.01):
                e, z = math.radians(el), math.radians(a)
                dirs.append([math.cos(e) * math.sin(z), math.cos(e) * math.cos(z), math.sin(e)])
            los = line_of_sight(city.buildings, pts[i : i + 1], np.array(dirs))[0]
            assert not los[0] and los[1], (i, a, m)
            w = walls[i, j]
            if np.isfinite(w):
                u = np.array([math.sin(math.radians(a)), math.cos(math.radians(a)), 0.0])
                before = pts[i] + (w - 1e-6) * u
                after = pts[i] + (w + 1e-6) * u
                inside = is_inside_building(city.buildings, np.stack([before, after]))
                assert not inside[0] and inside[1], (i, a, w)


def test_inside_points_see_nothing_and_read_zero_walls(city: fc.FileCity) -> None:
    b = city.buildings
    k = int(np.argmax(b.heights_m))
    ring = b.rings_m[k][0]
    # the centroid of a triangle fan is inside for the convex sample shapes: find an inside point
    rng = np.random.default_rng(5)
    x0, y0, x1, y1 = b.bbox_m[k]
    cand = np.column_stack(
        [rng.uniform(x0, x1, 200), rng.uniform(y0, y1, 200), np.full(200, b.heights_m[k] / 2)]
    )
    inside = is_inside_building(b, cand)
    assert inside.any() and ring.shape[0] >= 3
    p = cand[inside][:1]
    sky, walls = sky_and_walls(b, p, [0.0, 90.0])
    np.testing.assert_array_equal(sky, 90.0)
    np.testing.assert_array_equal(walls, 0.0)
    assert not line_of_sight(b, p, [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]).any()
    above = p.copy()
    above[0, 2] = b.heights_m[k] + 1.0
    assert not is_inside_building(b, above)[0]


def _prism_dist(b: fc.ExtrudedBuildings, q: np.ndarray) -> float:
    """Smallest distance from points ``q`` (m, 3) to the extruded polygons (a reference:
    horizontal distance to the nearest edge, 0 inside, combined with the height above the
    roof), over the buildings whose box lies within 20 m of the points."""
    lo, hi = q[:, :2].min(axis=0) - 20.0, q[:, :2].max(axis=0) + 20.0
    bb = b.bbox_m
    near = (bb[:, 0] <= hi[0]) & (bb[:, 2] >= lo[0]) & (bb[:, 1] <= hi[1]) & (bb[:, 3] >= lo[1])
    best = math.inf
    for k in np.flatnonzero(near):
        e = b.edges_m[b.edge_start[k] : b.edge_start[k + 1]]
        a, c = e[None, :, :2], e[None, :, 2:]
        ev = c - a
        rel = q[:, None, :2] - a
        w = np.clip(np.sum(rel * ev, axis=2) / np.sum(ev * ev, axis=2), 0, 1)
        dxy = np.min(np.linalg.norm(rel - w[..., None] * ev, axis=2), axis=1)
        inside = np.array(
            [
                fc._pk.inside_footprint(x, y, b.edges_m, b.edge_start[k], b.edge_start[k + 1])
                for x, y in q[:, :2]
            ]
        )
        dz = np.maximum(q[:, 2] - b.heights_m[k], 0.0)
        best = min(best, float(np.min(np.where(inside, dz, np.hypot(dxy, dz)))))
    return best


def test_swept_collisions_match_sampled_distances(city: fc.FileCity) -> None:
    b = city.buildings
    rng = np.random.default_rng(6)
    start = city.random_street_points(rng, 150, altitude_m=20.0)
    start[:, 2] = rng.uniform(5.0, 60.0, 150)
    end = start + rng.normal(0.0, 6.0, (150, 3))
    end[:, 2] = np.clip(end[:, 2], 1.0, 80.0)
    r = 1.0
    hit = b.swept_collisions(start, end, r)
    n_checked = 0
    for i in range(start.shape[0]):
        ts = np.linspace(0.0, 1.0, 401)
        dmin = _prism_dist(b, start[i] + ts[:, None] * (end[i] - start[i]))
        step = np.linalg.norm(end[i] - start[i]) / 400
        if dmin < r - 1e-9:
            assert hit[i], (i, dmin)
            n_checked += 1
        elif dmin > r + step:
            assert not hit[i], (i, dmin)
            n_checked += 1
    assert n_checked >= 140 and 0 < hit.sum() < 150


# ---- reading -----------------------------------------------------------------------------


def test_shipped_sample_is_what_the_generator_writes(tmp_path: Path) -> None:
    out = fc.write_sample_city(tmp_path / "c.geojson")
    assert json.loads(out.read_text()) == json.loads(fc.sample_city_path().read_text())


def test_sample_city_reads_with_heights_and_origin(city: fc.FileCity) -> None:
    b = city.buildings
    assert 200 <= b.n <= 500
    assert np.all(b.heights_m > 0)
    feats = json.loads(fc.sample_city_path().read_text())["features"]
    n_missing = sum(
        "height" not in f["properties"] and "building:levels" not in f["properties"] for f in feats
    )
    assert city.n_default_height == n_missing > 0
    lat0, lon0, _ = city.origin
    assert abs(lat0 - fc.SAMPLE_ORIGIN_LAT_LON[0]) < 1e-3
    assert abs(lon0 - fc.SAMPLE_ORIGIN_LAT_LON[1]) < 1e-3
    # a vertex converts back to its file coordinates (ENU -> geodetic)
    ring = feats[0]["geometry"]["coordinates"][0]
    xy = city.lat_lon_to_xy(ring[0][1], ring[0][0])
    lat, lon = city.xy_to_lat_lon(xy)
    assert abs(lat - ring[0][1]) < 1e-9 and abs(lon - ring[0][0]) < 1e-9


def _write(tmp_path: Path, features: list, name: str = "c.geojson") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return p


def _square(lon: float = 121.5, lat: float = 31.2, s: float = 1e-4) -> list:
    return [[[lon, lat], [lon + s, lat], [lon + s, lat + s], [lon, lat + s], [lon, lat]]]


def _feat(coords: list, props: dict | None = None, fid: str | None = "x1", kind="Polygon"):
    f = {"type": "Feature", "properties": props, "geometry": {"type": kind, "coordinates": coords}}
    if fid is not None:
        f["id"] = fid
    return f


@pytest.mark.parametrize(
    "props, expected",
    [
        ({"height": 12}, 12.0),
        ({"height": "12 m"}, 12.0),
        ({"height": "12.5"}, 12.5),
        ({"height": "100 ft"}, 30.48),
        ({"building:levels": 4}, 12.0),
        ({"building:levels": "5"}, 15.0),
        ({"height": "20 m", "building:levels": 2}, 20.0),
    ],
)
def test_heights(tmp_path: Path, props: dict, expected: float) -> None:
    b, _, n_def = fc.read_geojson_footprints(_write(tmp_path, [_feat(_square(), props)]))
    assert b.heights_m[0] == pytest.approx(expected) and n_def == 0


def test_default_height_is_counted_and_warned(tmp_path: Path) -> None:
    p = _write(tmp_path, [_feat(_square(), {}), _feat(_square(121.501), {"height": 9})])
    b, _, n_def = fc.read_geojson_footprints(p, default_height_m=7.0)
    assert n_def == 1 and list(b.heights_m) == [7.0, 9.0]
    with pytest.warns(UserWarning, match="1 of 2 buildings"):
        fc.load_file_city(p, clearance_m=0.0)


@pytest.mark.parametrize(
    "feature, match",
    [
        (_feat(_square(), {}), r"feature 0 \(id 'x1'\): no height"),
        (_feat(_square(), {"height": "tall"}), "cannot read height 'tall'"),
        (_feat(_square(), {"height": -3}), "must be a finite height > 0"),
        (
            _feat([[[121.5, 31.2], [121.5001, 31.2], [121.5001, 31.2001]]], {"height": 5}),
            "ring 0: open ring",
        ),
        (
            _feat([[[121.5, 31.2], [121.5001, 31.2], [121.5, 31.2]]], {"height": 5}),
            "fewer than 3 distinct vertices",
        ),
        (
            _feat(
                [
                    [
                        [121.5, 31.2],
                        [121.5001, 31.2001],
                        [121.5001, 31.2],
                        [121.5, 31.2001],
                        [121.5, 31.2],
                    ]
                ],
                {"height": 5},
            ),
            "self-intersecting ring",
        ),
        (
            _feat(
                [[[121.5, 31.2], [float("nan"), 31.2], [121.5, 31.3], [121.5, 31.2]]], {"height": 5}
            ),
            "non-finite",
        ),
        (_feat(_square(lat=95.0), {"height": 5}), "out of longitude/latitude range"),
        (_feat([_square()], {"height": 5}, fid=None, kind="MultiPolygon"), None),
    ],
)
def test_bad_features_name_file_feature_and_problem(tmp_path: Path, feature, match) -> None:
    p = _write(tmp_path, [feature])
    if match is None:  # a good MultiPolygon reads
        b, _, _ = fc.read_geojson_footprints(p)
        assert b.n == 1 and b.feature_ids == ("feature 0",)
        return
    with pytest.raises(fc.CityFileError, match=match) as info:
        fc.read_geojson_footprints(p, default_height_m=None, repair=False)
    assert str(p) in str(info.value)


def test_far_point_and_bad_files(tmp_path: Path) -> None:
    p = _write(tmp_path, [_feat(_square(), {"height": 5}), _feat(_square(121.7), {"height": 5})])
    with pytest.raises(
        fc.CityFileError,
        match=r"feature 1 \(id 'x1'\), ring 0: vertex 0 lies .* m from the origin.*beyond the 5000",
    ):
        fc.read_geojson_footprints(p, origin_lat_lon=(31.2, 121.5), max_origin_distance_m=5000.0)
    bad = tmp_path / "bad.geojson"
    bad.write_text("{not json")
    with pytest.raises(fc.CityFileError, match=r"bad\.geojson: not readable GeoJSON"):
        fc.read_geojson_footprints(bad)
    bad.write_text(json.dumps({"type": "Feature"}))
    with pytest.raises(fc.CityFileError, match="expected a GeoJSON FeatureCollection"):
        fc.read_geojson_footprints(bad)
    with pytest.raises(fc.CityFileError, match=r"nowhere\.geojson: no such file"):
        fc.load_file_city(tmp_path / "nowhere.geojson")
    pts = _write(
        tmp_path,
        [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "Point", "coordinates": [0, 0]},
            }
        ],
        "p.geojson",
    )
    with pytest.raises(fc.CityFileError, match="no Polygon or MultiPolygon"):
        fc.read_geojson_footprints(pts)


# ---- free space and routes ---------------------------------------------------------------


def test_free_space_keeps_clearance_and_routes_stay_free(city: fc.FileCity) -> None:
    b = city.buildings
    gx, gy = np.meshgrid(city.grid_x_m, city.grid_y_m)
    cells = np.column_stack([gx[city.free], gy[city.free], np.full(city.free.sum(), 1.0)])
    assert not is_inside_building(b, cells).any()
    walls = wall_distance_m(b, cells[::50], np.arange(0.0, 360.0, 10.0))
    assert walls.min() >= fc.CLEARANCE_M - 1e-9
    rng = np.random.default_rng(8)
    for _ in range(5):
        s, g = city.random_street_points(rng, 2)[:, :2]
        route = city.free_space_route(s, g)
        np.testing.assert_array_equal(route[0], s)
        np.testing.assert_array_equal(route[-1], g)
        for a, c in itertools.pairwise(route):
            t = np.linspace(0.0, 1.0, 200)[:, None]
            assert city.is_free_xy(a + t * (c - a)).all()
        length = np.hypot(*np.diff(route, axis=0).T).sum()
        assert length >= np.hypot(*(g - s)) - 1e-9


def test_largest_component_equals_its_oracle(city: fc.FileCity) -> None:
    # the compiled labelling keeps the piece the numpy oracle keeps, on random grids (many
    # pieces, diagonal contacts that do and do not connect, ties between equal pieces) and on
    # the city's own free space
    rng = np.random.default_rng(3)
    grids = [rng.random((ny, nx)) < p for ny, nx, p in ((1, 1, 0.5), (7, 9, 0.45), (40, 30, 0.55))]
    grids += [rng.random((60, 80)) < 0.5 for _ in range(20)]
    grids += [np.zeros((5, 4), dtype=bool), np.eye(6, dtype=bool), city.free]
    grids.append(np.array([[1, 0, 1], [0, 0, 0], [1, 1, 0]], dtype=bool))  # a tie: the first
    kept = []
    for free in grids:
        got = fc._largest_component(free)
        expected = oracles.largest_component(free)
        assert got.dtype == expected.dtype == bool
        np.testing.assert_array_equal(got, expected)
        kept.append(int(got.sum()))
    assert kept[-1] == 2 and fc._largest_component(grids[-1])[2, 0]
    assert kept[-4] == 0 and kept[-3] == 1  # nothing free; a diagonal without its sides


def test_route_refuses_an_end_inside_a_building(city: fc.FileCity) -> None:
    b = city.buildings
    k = int(np.argmax(b.heights_m))
    x0, y0, x1, y1 = b.bbox_m[k]
    rng = np.random.default_rng(9)
    cand = np.column_stack([rng.uniform(x0, x1, 100), rng.uniform(y0, y1, 100), np.ones(100)])
    inside = cand[is_inside_building(b, cand)][0, :2]
    free = city.random_street_points(rng, 1)[0, :2]
    with pytest.raises(ValueError, match=r"route goal .* not in the reachable free space"):
        city.free_space_route(free, inside)


# ---- real footprints (OpenStreetMap, central Helsinki): repairs, heights, coordinates ------


def _real_doc() -> dict:
    """The shipped real city (183 buildings of central Helsinki, (c) OpenStreetMap
    contributors, ODbL 1.0) as a GeoJSON dict."""
    return json.loads(helsinki_geojson_path().read_text(encoding="utf-8"))


def _write_doc(tmp_path: Path, doc: dict, name: str = "real.geojson") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


def test_real_city_reads_and_warns_that_most_heights_are_defaulted() -> None:
    path = helsinki_geojson_path()
    with pytest.warns(UserWarning, match=r"122 of 183 buildings .*most of the city's heights"):
        b, origin, n_def = fc.read_geojson_footprints(path)
    assert b.n == 183 and n_def == 122
    assert abs(origin[0] - 60.170) < 0.01 and abs(origin[1] - 24.944) < 0.01
    defaulted = b.heights_m == fc.DEFAULT_HEIGHT_M
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        b25, _, _ = fc.read_geojson_footprints(path, default_height_m=25.0, storey_height_m=3.5)
    assert np.all(b25.heights_m[defaulted] == 25.0)
    feats = _real_doc()["features"]
    levels = np.array([f["properties"].get("building:levels", 0.0) for f in feats], dtype=float)
    has_levels = np.array(["height" not in f["properties"] for f in feats]) & (levels > 0)
    assert has_levels.sum() == 58
    assert np.allclose(b25.heights_m[has_levels], 3.5 * levels[has_levels])
    # a few known heights: no warning about the default, and the report says so
    few = fc.load_file_city(path, warn=False).report
    assert (few.n_height, few.n_levels, few.n_default_height) == (3, 58, 122)


@pytest.mark.parametrize(
    "value, expected_m",
    [("5;6", 18.0), ("6;5", 18.0), ("5-6", 18.0), ("5 - 6", 18.0), ("5.5", 16.5), (4, 12.0)],
)
def test_levels_lists_ranges_and_decimals_on_real_footprints(
    tmp_path: Path, value, expected_m: float
) -> None:
    doc = _real_doc()
    doc["features"][0]["properties"] = {"building": "yes", "building:levels": value}
    b, _, _ = fc.read_geojson_footprints(_write_doc(tmp_path, doc), default_height_m=30.0)
    assert b.heights_m[0] == pytest.approx(expected_m)


def test_heights_lists_and_unreadable_values() -> None:
    assert fc._parse_height("12;15 m", "f", "height") == 15.0
    assert fc._parse_height("30-40 ft", "f", "height") == pytest.approx(12.192)
    with pytest.raises(fc.CityFileError, match=r"cannot read height '12;tall'"):
        fc._parse_height("12;tall", "f", "height")


def test_unreadable_heights_are_read_as_missing_with_repair_and_listed_without(
    tmp_path: Path,
) -> None:
    doc = _real_doc()
    doc["features"][0]["properties"] = {"height": "tall", "building:levels": "5"}
    doc["features"][1]["properties"] = {"building:levels": "ground floor"}
    p = _write_doc(tmp_path, doc)
    with pytest.warns(UserWarning, match=r"2 features have an unreadable height.*'tall'"):
        b, _, _ = fc.read_geojson_footprints(p, default_height_m=30.0)
    assert b.heights_m[0] == 15.0 and b.heights_m[1] == 30.0
    with pytest.raises(fc.CityFileError, match=r"2 feature problem\(s\)") as info:
        fc.read_geojson_footprints(p, repair=False)
    msg = str(info.value)
    assert "cannot read height 'tall'" in msg and "cannot read building:levels" in msg


def _damage(doc: dict) -> list[str]:
    """Damage four real footprints the ways OpenStreetMap's validators flag them (a
    self-intersecting way, an unclosed way, a way through one node twice, a way of two nodes);
    returns their ids."""
    shapely = pytest.importorskip("shapely")
    feats = doc["features"]
    picked = []
    for f in feats:  # the first footprints that a swap of two vertices makes self-intersecting
        ring = f["geometry"]["coordinates"][0]
        if len(f["geometry"]["coordinates"]) == 1 and len(ring) >= 6:
            bent = [ring[0], ring[2], ring[1], *ring[3:]]
            if not shapely.Polygon(bent).is_valid:
                picked.append(f)
        if len(picked) == 4:
            break
    a, b, c, d = picked
    ra = a["geometry"]["coordinates"][0]
    a["geometry"]["coordinates"][0] = [ra[0], ra[2], ra[1], *ra[3:]]
    b["geometry"]["coordinates"][0] = b["geometry"]["coordinates"][0][:-1]
    rc = c["geometry"]["coordinates"][0]
    c["geometry"]["coordinates"][0] = [*rc[:3], rc[0], *rc[3:]]
    rd = d["geometry"]["coordinates"][0]
    d["geometry"]["coordinates"][0] = [rd[0], rd[1], rd[0]]
    return [f["id"] for f in picked]


def test_invalid_real_rings_are_repaired_with_one_warning(tmp_path: Path) -> None:
    shapely = pytest.importorskip("shapely")
    doc = _real_doc()
    ids = _damage(doc)
    p = _write_doc(tmp_path, doc)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        city = fc.load_file_city(p)
    about_rings = [w for w in caught if "invalid rings" in str(w.message)]
    assert len(about_rings) == 1
    assert "3 features with invalid rings repaired" in str(about_rings[0].message)
    assert "1 dropped" in str(about_rings[0].message)
    report = city.report
    assert (report.n_repaired, report.n_dropped) == (3, 1)
    b = city.buildings
    assert not any(ids[3] in fid for fid in b.feature_ids)  # the two-node way: nothing to build
    assert b.n >= 182
    for k in range(b.n):  # every footprint kept is a valid polygon
        rings = b.rings_m[k]
        assert shapely.Polygon(rings[0], rings[1:]).is_valid, b.feature_ids[k]
    # the repaired self-intersecting way keeps its area inside its original outline
    orig = next(f for f in _real_doc()["features"] if f["id"] == ids[0])
    ring = np.array(orig["geometry"]["coordinates"][0])
    xy = np.array([city.lat_lon_to_xy(lat, lon) for lon, lat in ring])
    outline = shapely.Polygon(xy).buffer(0.01)
    parts = [k for k in range(b.n) if ids[0] in b.feature_ids[k]]
    assert parts and all(outline.contains(shapely.Polygon(b.rings_m[k][0])) for k in parts)


def test_without_repair_every_bad_real_feature_is_listed_in_one_error(tmp_path: Path) -> None:
    doc = _real_doc()
    ids = _damage(doc)
    p = _write_doc(tmp_path, doc)
    with pytest.raises(fc.CityFileError, match=r"4 feature problem\(s\), every one listed") as e:
        fc.load_file_city(p, repair=False)
    lines = str(e.value).splitlines()[1:]
    assert len(lines) == 4
    for fid, why in zip(
        ids,
        ["self-intersecting ring", "open ring", "self-intersecting ring", "fewer than 3 distinct"],
    ):
        assert any(f"(id '{fid}')" in line and why in line for line in lines), (fid, why)


def test_repair_without_shapely_says_to_install_the_extra(tmp_path: Path, monkeypatch) -> None:
    doc = _real_doc()
    _damage(doc)
    p = _write_doc(tmp_path, doc)
    monkeypatch.setitem(sys.modules, "shapely", None)
    with pytest.raises(fc.CityFileError, match=r"needs shapely: `pip install 'coopnav\[geo\]'`"):
        fc.read_geojson_footprints(p)


def test_swapped_latitude_and_longitude_are_refused(tmp_path: Path) -> None:
    doc = _real_doc()
    for f in doc["features"]:
        f["geometry"]["coordinates"] = [
            [[lat, lon] for lon, lat in ring] for ring in f["geometry"]["coordinates"]
        ]
    with pytest.raises(fc.CityFileError, match=r"latitude and longitude look swapped: \d+%"):
        fc.read_geojson_footprints(_write_doc(tmp_path, doc))
    # a place whose longitude is beyond 90 deg: swapped, it is out of range
    sample = fc.sample_city_geojson(n_blocks=2)
    for f in sample["features"]:
        f["geometry"]["coordinates"] = [
            [[lat, lon] for lon, lat in ring] for ring in f["geometry"]["coordinates"]
        ]
    with pytest.raises(fc.CityFileError, match=r"out of longitude/latitude range; .*swapped"):
        fc.read_geojson_footprints(_write_doc(tmp_path, sample, "s.geojson"))
    # as written, neither file is refused
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert fc.read_geojson_footprints(helsinki_geojson_path())[0].n == 183


def test_projected_coordinates_and_other_crs_are_refused(tmp_path: Path) -> None:
    doc = _real_doc()
    lat0, lon0 = 60.17, 24.944
    for f in doc["features"]:  # metres east and north, offset as a national grid would be
        f["geometry"]["coordinates"] = [
            [
                [385_000.0 + (lon - lon0) * 55_500.0, 6_672_000.0 + (lat - lat0) * 111_400.0]
                for lon, lat in ring
            ]
            for ring in f["geometry"]["coordinates"]
        ]
    with pytest.raises(fc.CityFileError, match=r"look like projected coordinates \(metres"):
        fc.read_geojson_footprints(_write_doc(tmp_path, doc))
    doc = _real_doc()
    doc["crs"] = {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::3067"}}
    with pytest.raises(fc.CityFileError, match=r"declares the coordinate reference system .*3067"):
        fc.read_geojson_footprints(_write_doc(tmp_path, doc))
    doc["crs"] = {"type": "name", "properties": {"name": "urn:ogc:def:crs:OGC:1.3:CRS84"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert fc.read_geojson_footprints(_write_doc(tmp_path, doc))[0].n == 183
    far = [_feat(_square(24.94, 60.17), {"height": 5}), _feat(_square(27.0, 60.17), {"height": 5})]
    with pytest.raises(fc.CityFileError, match=r"span 114 km east-west .* implausible extent"):
        fc.read_geojson_footprints(_write(tmp_path, far))


def test_bounding_box_keeps_the_footprints_inside(tmp_path: Path) -> None:
    box = (60.168, 24.940, 60.171, 24.946)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        city = fc.load_file_city(helsinki_geojson_path(), bbox=box)
    assert 10 < city.buildings.n < 183
    assert city.report.n_outside_bbox + city.buildings.n == 183
    for rings in city.buildings.rings_m:
        lat, lon = city.xy_to_lat_lon(rings[0].mean(axis=0))
        assert box[0] - 1e-4 <= lat <= box[2] + 1e-4 and box[1] - 1e-4 <= lon <= box[3] + 1e-4
    with pytest.raises(fc.CityFileError, match="no Polygon or MultiPolygon feature inside the"):
        fc.read_geojson_footprints(helsinki_geojson_path(), bbox=(10.0, 10.0, 11.0, 11.0))
    with pytest.raises(ValueError, match=r"bbox must be \(south_deg, west_deg, north_deg"):
        fc.load_file_city(helsinki_geojson_path(), bbox=(60.2, 24.9, 60.1, 25.0))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"storey_height_m": 1.0}, r"storey_height_m must be in \[2, 10\] m, got 1.0"),
        ({"default_height_m": 0.5}, r"default_height_m must be None or in \[1, 500\] m"),
        ({"default_height_m": float("nan")}, "default_height_m must be None or in"),
    ],
)
def test_height_settings_are_checked(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fc.load_file_city(helsinki_geojson_path(), **kwargs)


@pytest.mark.parametrize("source", ["sample", "helsinki"])
def test_starts_goals_and_routes_stay_in_the_built_up_area(source: str) -> None:
    path = fc.sample_city_path() if source == "sample" else helsinki_geojson_path()
    city = fc.load_file_city(path, warn=False)
    assert 0 < city.built_up.sum() < city.reachable.sum()
    assert not np.any(city.built_up & ~city.reachable)
    rng = np.random.default_rng(5)
    pts = city.random_street_points(rng, 400, altitude_m=0.5)  # below every roof
    _, wall_m = city.buildings.sky_and_walls(pts, np.arange(0.0, 360.0, 45.0))
    # cell centres qualify; a point half a cell away may see a wall's edge on another side
    near = np.sum(wall_m <= fc.BUILT_UP_RADIUS_M + city.resolution_m, axis=1)
    assert np.mean(near >= fc.BUILT_UP_MIN_DIRECTIONS) > 0.95 and near.min() >= 2
    bb = city.buildings.bbox_m  # never in the open margin around the footprints
    lo, hi = bb[:, :2].min(axis=0), bb[:, 2:].max(axis=0)
    assert np.all((pts[:, :2] >= lo) & (pts[:, :2] <= hi))
    plain = dataclasses.replace(city, built_up=np.zeros_like(city.built_up))

    def inside_share(c: fc.FileCity, a: np.ndarray, b: np.ndarray) -> float:
        route = c.free_space_route(a, b)
        if c is city:  # without the built-up area, a route may run along the map's edge
            assert np.all((route >= lo - c.resolution_m) & (route <= hi + c.resolution_m))
        legs = np.linspace(route[:-1], route[1:], 20).reshape(-1, 2)
        rows = np.round((legs[:, 1] - c.grid_y_m[0]) / c.resolution_m).astype(int)
        cols = np.round((legs[:, 0] - c.grid_x_m[0]) / c.resolution_m).astype(int)
        return float(city.built_up[rows, cols].mean())

    # routes keep inside the footprints' extent, and in the built-up area more than without it
    kept = [inside_share(city, pts[k, :2], pts[k + 1, :2]) for k in range(0, 40, 2)]
    base = [inside_share(plain, pts[k, :2], pts[k + 1, :2]) for k in range(0, 40, 2)]
    assert np.mean(kept) > 0.85 and np.mean(kept) >= np.mean(base)
