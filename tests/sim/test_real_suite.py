"""The real-city suite (``coopnav_env.sim.real_suite``): shipped real data, its attribution,
and the rule that sets each city's default height.

Reading the extracts needs pyosmium (the ``osm`` extra); those tests are skipped without it.
"""

from __future__ import annotations

import fnmatch
import gzip
import hashlib
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from coopnav_env.gnss.rinex import SHIPPED_NAV_PATHS, load_broadcast_constellation
from coopnav_env.sim.file_city import load_file_city
from coopnav_env.sim.osm_city import SHIPPED_OSM_PATHS, resolve_osm_path
from coopnav_env.sim.real_suite import (
    REAL_SUITE,
    SUITE_SKY,
    SUITE_SYSTEMS,
    suite_cities,
)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "coopnav_env" / "data"

try:
    import osmium  # noqa: F401

    HAVE_OSMIUM = True
except ImportError:
    HAVE_OSMIUM = False

needs_osmium = pytest.mark.skipif(not HAVE_OSMIUM, reason="pyosmium (the osm extra) not installed")


def test_the_suite_has_three_places_of_different_character() -> None:
    assert len(REAL_SUITE) >= 3
    assert len({c.name for c in REAL_SUITE}) == len(REAL_SUITE)
    characters = {c.character for c in REAL_SUITE}
    assert {"dense old town", "high-rise district", "wide avenues"} <= characters
    assert suite_cities("real") == REAL_SUITE
    with pytest.raises(
        ValueError, match=r"unknown suite 'unreal'; suites: \['families', 'grid', 'real'\]"
    ):
        suite_cities("unreal")


def test_every_suite_city_flies_a_shipped_extract_under_the_shipped_real_sky() -> None:
    for city in REAL_SUITE:
        env = city.env_settings()
        assert env["city"] == f"osm:{city.osm}"
        assert env["constellation"] == SUITE_SKY and env["systems"] == SUITE_SYSTEMS
        path = resolve_osm_path(city.osm)
        assert path == SHIPPED_OSM_PATHS[city.osm] and path.is_file()
        south, west, north, east = city.bbox
        assert south < north and west < east


def test_shipped_real_files_are_small_attributed_and_packaged() -> None:
    """Each shipped real file is well under 1 MB, named in its NOTICE with the sha256 it
    has, and matched by the package-data patterns (so that a wheel carries it)."""
    osm_notice = (DATA / "NOTICE-openstreetmap.md").read_text()
    nav_notice = (DATA / "NOTICE-navigation.md").read_text()
    assert "© OpenStreetMap contributors, ODbL 1.0" in osm_notice
    assert "MIT License" in nav_notice
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"
    ]["coopnav_env"]
    shipped = [(p, osm_notice) for p in SHIPPED_OSM_PATHS.values()]
    shipped.append((SHIPPED_NAV_PATHS["igs_brdc"], nav_notice))
    for path, notice in shipped:
        assert path.stat().st_size < 800_000, path
        assert f"`{path.name}`" in notice
        assert hashlib.sha256(path.read_bytes()).hexdigest() in notice, path.name
        assert any(fnmatch.fnmatch(f"data/{path.name}", p) for p in patterns), path.name
    for name in ("NOTICE-openstreetmap.md", "NOTICE-navigation.md"):
        assert any(fnmatch.fnmatch(f"data/{name}", p) for p in patterns), name


def test_the_shipped_real_sky_is_every_gps_satellite_over_six_hours() -> None:
    path = SHIPPED_NAV_PATHS["igs_brdc"]
    assert gzip.open(path, "rt").readline().split()[0] == "2.11"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the one unhealthy record is left out with a warning
        sky = load_broadcast_constellation("igs_brdc", SUITE_SYSTEMS)
    assert sky.n_sv >= 30
    lo, hi = sky.coverage_s
    assert hi - lo == pytest.approx(6 * 3600.0)


@needs_osmium
def test_each_default_height_is_the_median_of_the_known_heights_in_its_box() -> None:
    """A building's height is known when it does not change with the default height; the
    suite's default is the median of the known ones, rounded to the metre (halves up)."""
    for city in REAL_SUITE:
        spec = f"osm:{resolve_osm_path(city.osm)}"
        a, b = (
            load_file_city(spec, bbox=city.bbox, default_height_m=h, warn=False).buildings
            for h in (1.0, 2.0)
        )
        known = a.heights_m[a.heights_m == b.heights_m]
        assert a.n >= 100 and known.size >= 30, city.name
        assert city.default_height_m == math.floor(float(np.median(known)) + 0.5), city.name
