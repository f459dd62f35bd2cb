"""The real-city suite: real OpenStreetMap places under a real sky, in one place.

Each :class:`SuiteCity` is a box of a real OpenStreetMap extract shipped with the package
(:data:`~coopnav_env.sim.osm_city.SHIPPED_OSM_PATHS`) and the environment settings that fly
it (:meth:`SuiteCity.env_settings`). :data:`REAL_SUITE` holds three places of different
character:

========================  ==============================================================
``monaco_ville``          a dense old town: Monaco-Ville, the old town on its rock, narrow
                          lanes between four-storey houses (``osm:monaco``)
``monte_carlo``           a high-rise district: Monte Carlo, Monaco, east of the casino,
                          towers of up to 81 m (``osm:monaco``)
``helsinki_centre``       wide avenues: the centre of Helsinki, city blocks along wide
                          streets, the Esplanadi and squares (``osm:helsinki``)
========================  ==============================================================

What every city of the suite shares:

* **Buildings** are the file's buildings whose footprint's vertex mean lies in the box
  (``city_bbox``), repaired as :mod:`coopnav_env.sim.file_city` does by default. Each box
  is about 600 m across, the size of the default grid city (500 m and its margin), so that
  a route fits the task's 200 steps as on a grid.
* **Heights** come from ``height``, else ``building:levels`` x 3 m; a building with neither
  gets ``city_default_height_m``, which is, for each city, the median roof height of the
  buildings in its box that have one, rounded to the metre (halves up).
* **Starts and goals** follow the environment's rules for file cities: drawn on streets in
  the built-up area, at least ``goal_distance_min_m`` apart; routes are A* through its free
  space.
* **The sky** is :data:`SUITE_SKY`, real broadcast GPS ephemerides that hold for any place on
  Earth (``rinex:igs_brdc``, :data:`~coopnav_env.gnss.rinex.SHIPPED_NAV_PATHS`), with
  ``systems=("GPS",)``; each episode starts at a time drawn in the file's usable span.

Everything else is at the environment's defaults. ``coopnav evaluate --suite real`` flies
policies on every city of the suite (:mod:`coopnav_env.training.suite`); the data's sources
and licences are in ``coopnav_env/data/NOTICE-openstreetmap.md`` and
``coopnav_env/data/NOTICE-navigation.md``.

:data:`FAMILY_SUITE` (``coopnav evaluate --suite families``) is its generated counterpart: one
:class:`GeneratedSuiteCity` per family of :mod:`coopnav_env.sim.city_families`, a new city
of the family in every episode (its seed drawn from the episode's reset seed, so held-out
reset seeds fly cities that no training episode had), under the environment's default sky;
:data:`GRID_SUITE` (``--suite grid``) the environment's own random street grids the same way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "FAMILY_SUITE",
    "GRID_SUITE",
    "REAL_SUITE",
    "SUITES",
    "SUITE_SKY",
    "SUITE_SYSTEMS",
    "GeneratedSuiteCity",
    "SuiteCity",
    "suite_cities",
]

SUITE_SKY: str = "rinex:igs_brdc"
"""The sky of every suite city: the shipped IGS merged broadcast GPS file of 2018-08-30."""

SUITE_SYSTEMS: tuple[str, ...] = ("GPS",)
"""The systems of :data:`SUITE_SKY` (a GPS-only file)."""


@dataclass(frozen=True)
class SuiteCity:
    """One place of a suite: a box of a shipped OpenStreetMap extract and how to fly it.

    Attributes
    ----------
    name : str
        Identifier (a folder name of ``coopnav evaluate --suite``'s output).
    place : str
        Where it is, in words.
    character : str
        What kind of place it is (old town, high-rise district, wide avenues).
    osm : str
        The shipped extract, a key of :data:`~coopnav_env.sim.osm_city.SHIPPED_OSM_PATHS`.
    bbox : (float, float, float, float)
        ``(south, west, north, east)`` [deg]: the buildings flown.
    default_height_m : float
        Roof height of a building without ``height`` or ``building:levels`` [m].
    """

    name: str
    place: str
    character: str
    osm: str
    bbox: tuple[float, float, float, float]
    default_height_m: float

    def env_settings(self) -> dict[str, Any]:
        """The environment settings that fly this city under :data:`SUITE_SKY` (keyword
        arguments of ``urban_canyon_v1.parallel_env``; all others at their defaults)."""
        return {
            "city": f"osm:{self.osm}",
            "city_bbox": self.bbox,
            "city_default_height_m": self.default_height_m,
            "constellation": SUITE_SKY,
            "systems": SUITE_SYSTEMS,
        }

    def buildings_flown(self, settings: Mapping[str, Any], seeds: Sequence[int]) -> float:
        """Buildings of the city flown with ``settings`` (the box and the default height may
        be changed there); the same in every episode, whatever the ``seeds``."""
        from coopnav_env.sim.file_city import load_file_city
        from coopnav_env.sim.osm_city import resolve_osm_path

        return float(
            load_file_city(
                f"osm:{resolve_osm_path(self.osm)}",
                bbox=settings.get("city_bbox", self.bbox),
                default_height_m=settings.get("city_default_height_m", self.default_height_m),
                warn=False,
            ).buildings.n
        )


@dataclass(frozen=True)
class GeneratedSuiteCity:
    """Generated cities of one kind in a suite: a new city every episode.

    Attributes
    ----------
    name : str
        Identifier (a folder name of ``coopnav evaluate --suite``'s output).
    city : str
        The environment's ``city`` setting: ``"grid"`` (random street grids) or
        ``"family:NAME"`` (:mod:`coopnav_env.sim.city_families`).
    character : str
        What kind of place it is.
    """

    name: str
    city: str
    character: str

    @property
    def place(self) -> str:
        """Where it is, in words: a generated city of its kind, new every episode."""
        return f"a new generated city (`{self.city}`) every episode"

    def env_settings(self) -> dict[str, Any]:
        """The environment settings that fly these cities under the environment's own sky
        (keyword arguments of ``urban_canyon_v1.parallel_env``; all others at their defaults).
        Each episode draws its city from its reset seed, so that held-out reset seeds fly
        cities no training episode (reset seeds below
        ``coopnav_env.training.envs.EVAL_SEED_START``) had."""
        return {"city": self.city}

    def buildings_flown(self, settings: Mapping[str, Any], seeds: Sequence[int]) -> float:
        """Mean number of buildings of the cities of the episodes ``seeds`` flown with
        ``settings`` (each city built once per process and seed, as the episodes build it)."""
        import coopnav_env.urban_canyon_v1 as v1

        env = v1.parallel_env(**{**self.env_settings(), **settings})
        counts = []
        for seed in seeds:
            env.reset(seed=int(seed))
            counts.append(env.world.city.buildings.n)
        env.close()
        return float(sum(counts) / len(counts))


REAL_SUITE: tuple[SuiteCity, ...] = (
    SuiteCity(
        name="monaco_ville",
        place="Monaco-Ville, Monaco",
        character="dense old town",
        osm="monaco",
        bbox=(43.7290, 7.4180, 43.7330, 7.4260),
        default_height_m=12.0,
    ),
    SuiteCity(
        name="monte_carlo",
        place="Monte Carlo, Monaco",
        character="high-rise district",
        osm="monaco",
        bbox=(43.7395, 7.4265, 43.7450, 7.4340),
        default_height_m=21.0,
    ),
    SuiteCity(
        name="helsinki_centre",
        place="Helsinki centre, Finland",
        character="wide avenues",
        osm="helsinki",
        bbox=(60.1665, 24.9410, 60.1720, 24.9520),
        default_height_m=10.0,
    ),
)
"""The real-city suite (see the module docstring)."""

FAMILY_SUITE: tuple[GeneratedSuiteCity, ...] = (
    GeneratedSuiteCity("irregular", "family:irregular", "irregular blocks, mixed heights"),
    GeneratedSuiteCity("old_town", "family:old_town", "low old town, lanes, small squares"),
    GeneratedSuiteCity("high_rise", "family:high_rise", "high-rise centre, wide streets"),
    GeneratedSuiteCity("avenues", "family:avenues", "wide and diagonal avenues"),
    GeneratedSuiteCity("courtyards", "family:courtyards", "perimeter blocks, inner yards"),
)
"""The generated-city suite: one entry per family of :mod:`coopnav_env.sim.city_families`,
flown under the environment's default sky (GPS and BeiDou)."""

GRID_SUITE: tuple[GeneratedSuiteCity, ...] = (
    GeneratedSuiteCity("grid", "grid", "random street grid, the training city"),
)
"""The environment's own random street grids (the city policies are trained in), under its
default sky, as a suite: held-out grids beside the other suites, with the same references."""

SUITES: dict[str, tuple[SuiteCity | GeneratedSuiteCity, ...]] = {
    "real": REAL_SUITE,
    "families": FAMILY_SUITE,
    "grid": GRID_SUITE,
}
"""Suites by the name ``coopnav evaluate --suite`` takes."""


def suite_cities(name: str) -> tuple[SuiteCity | GeneratedSuiteCity, ...]:
    """The cities of the suite called ``name`` (a key of :data:`SUITES`).

    Raises
    ------
    ValueError
        An unknown name; the message lists the suites.
    """
    try:
        return SUITES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown suite {name!r}; suites: {sorted(SUITES)}") from None
