"""Cities from OpenStreetMap files (:mod:`coopnav_env.sim.osm_city`) on the shipped real
extract of central Helsinki ((c) OpenStreetMap contributors, ODbL 1.0): reading with pyosmium,
the bounding box, conversion to a GeoJSON city and the ``coopnav city convert`` command.

Tests that read OpenStreetMap files need pyosmium (the ``osm`` and ``test`` extras) and are
skipped without it; the error a user gets without it is tested either way."""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.sim import file_city as fc
from coopnav_env.sim.osm_city import (
    HELSINKI_GEOJSON_BBOX,
    OSM_ATTRIBUTION,
    convert_city,
    helsinki_geojson_path,
    helsinki_osm_path,
    read_osm_buildings,
)

try:
    import osmium  # noqa: F401

    HAVE_OSMIUM = True
except ImportError:
    HAVE_OSMIUM = False
needs_osmium = pytest.mark.skipif(not HAVE_OSMIUM, reason="pyosmium (the osm extra) not installed")

pytestmark = pytest.mark.filterwarnings("ignore:.*get the default height")


@needs_osmium
def test_the_extract_reads_ways_and_assembled_relations() -> None:
    feats, n_incomplete = read_osm_buildings(helsinki_osm_path())
    kinds = [f["id"].split("/")[0] for f in feats]
    assert len(feats) == 446
    assert kinds.count("way") == 385 and kinds.count("relation") == 61
    # 48 ways cut by the extract's edge, 6 relations whose members are cut
    assert n_incomplete == 54
    rel = next(f for f in feats if f["id"].startswith("relation/"))
    assert rel["geometry"]["type"] == "MultiPolygon"
    way = next(f for f in feats if f["id"].startswith("way/"))
    ring = way["geometry"]["coordinates"][0]
    assert ring[0] == ring[-1] and all(60.16 < lat < 60.18 for _, lat in ring)
    assert all(f["properties"].get("building", "yes") != "no" for f in feats)


@needs_osmium
def test_osm_city_loads_with_its_report_and_heights() -> None:
    with pytest.warns(UserWarning, match=r"292 of 446 buildings .*most of the city's heights"):
        city = fc.load_file_city(f"osm:{helsinki_osm_path()}")
    r = city.report
    assert (r.n_buildings, r.n_height, r.n_levels, r.n_default_height) == (446, 16, 138, 292)
    assert (r.n_repaired, r.n_dropped, r.n_incomplete) == (0, 0, 54)
    assert city.buildings.n == 446 and np.all(city.buildings.heights_m > 0)
    assert any(
        fid.startswith("feature") and "relation/" in fid for fid in city.buildings.feature_ids
    )
    lat0, lon0, _ = city.origin
    assert 60.16 < lat0 < 60.18 and 24.93 < lon0 < 24.96
    # the suffix alone says it is OpenStreetMap
    assert fc.load_file_city(helsinki_osm_path(), warn=False).buildings.n == 446


@needs_osmium
def test_the_shipped_geojson_city_is_what_convert_writes(tmp_path: Path) -> None:
    out = tmp_path / "h.geojson"
    report = convert_city(helsinki_osm_path(), out, bbox=HELSINKI_GEOJSON_BBOX)
    assert report.n_buildings == 183 and report.n_outside_bbox == 446 - 183
    written = json.loads(out.read_text(encoding="utf-8"))
    assert written == json.loads(helsinki_geojson_path().read_text(encoding="utf-8"))
    assert written["attribution"] == OSM_ATTRIBUTION
    assert not (tmp_path / "h.geojson.tmp").exists()
    # read back, the city has the same buildings and the same unknown heights, nothing repaired
    back = fc.load_file_city(out, warn=False)
    assert back.report.n_default_height == report.n_default_height == 122
    assert back.report.n_repaired == 0 and back.buildings.n == 183


@needs_osmium
def test_osm_xml_reads_as_the_pbf(tmp_path: Path) -> None:
    import osmium

    xml = tmp_path / "helsinki.osm"
    with osmium.SimpleWriter(str(xml)) as writer:
        for obj in osmium.FileProcessor(str(helsinki_osm_path())):
            writer.add(obj)
    assert xml.read_text(encoding="utf-8").lstrip().startswith("<?xml")
    assert read_osm_buildings(xml) == read_osm_buildings(helsinki_osm_path())


@needs_osmium
def test_coopnav_city_convert_prints_the_report(tmp_path: Path, capsys) -> None:
    from coopnav_env.training.cli import main

    out = tmp_path / "c.geojson"
    box = ["60.168", "24.940", "60.171", "24.946"]
    assert (
        main(["city", "convert", str(helsinki_osm_path()), "--out", str(out), "--bbox", *box]) == 0
    )
    text = capsys.readouterr().out
    assert f"wrote {out}" in text
    for part in ("buildings:", "heights known:", "defaulted:", "rings repaired: 0"):
        assert part in text
    n = int(text.split("buildings: ")[1].split()[0])
    assert n == len(json.loads(out.read_text(encoding="utf-8"))["features"]) > 10
    assert main(["city", "convert", str(tmp_path / "x.osm.pbf"), "--out", str(out)]) == 2
    assert "no such file" in capsys.readouterr().err


def test_convert_of_a_damaged_geojson_repairs_and_the_result_reads_clean(tmp_path: Path) -> None:
    pytest.importorskip("shapely")
    doc = json.loads(helsinki_geojson_path().read_text(encoding="utf-8"))
    ring = doc["features"][5]["geometry"]["coordinates"][0]
    doc["features"][5]["geometry"]["coordinates"][0] = ring[:-1]  # an unclosed way
    src = tmp_path / "in.geojson"
    src.write_text(json.dumps(doc))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = convert_city(src, tmp_path / "out.geojson")
    assert report.n_repaired == 1 and report.n_buildings == 183
    assert fc.load_file_city(tmp_path / "out.geojson", warn=False).report.n_repaired == 0
    with pytest.raises(fc.CityFileError, match=r"feature 5 .*open ring"):
        convert_city(src, tmp_path / "strict.geojson", repair=False)
    assert not (tmp_path / "strict.geojson").exists()


def test_without_pyosmium_the_error_says_to_install_the_extra(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "osmium", None)
    with pytest.raises(fc.CityFileError, match=r"needs pyosmium: `pip install 'coopnav\[osm\]'`"):
        read_osm_buildings(helsinki_osm_path())


def test_an_osm_path_needs_an_osm_suffix(tmp_path: Path) -> None:
    p = tmp_path / "city.txt"
    p.write_text("x")
    with pytest.raises(fc.CityFileError, match=r"city\.txt: an OpenStreetMap file must end in"):
        read_osm_buildings(p)
