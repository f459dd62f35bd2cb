"""``coopnav city``: building footprints from OpenStreetMap or GeoJSON into a checked city.

``coopnav city convert IN --out OUT.geojson [--bbox S W N E]`` reads an OpenStreetMap
(``.osm``, ``.osm.pbf``; the ``osm`` extra) or GeoJSON file, repairs and checks its buildings
as the environment does, writes them as a GeoJSON city for ``city="geojson:OUT.geojson"`` and
prints a report (buildings, heights known and defaulted, rings repaired). The work is
:func:`coopnav_env.sim.osm_city.convert_city`; this module is its command line.
"""

from __future__ import annotations

import argparse

from coopnav_env.sim.file_city import DEFAULT_HEIGHT_M, STOREY_HEIGHT_M


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``city`` subcommand's own subcommands (``convert``)."""
    sub = parser.add_subparsers(dest="city_command", metavar="CITY_COMMAND", required=True)
    text = (
        "convert an OpenStreetMap (.osm, .osm.pbf) or GeoJSON file into a checked GeoJSON city "
        "and print a report (buildings, heights known and defaulted, rings repaired)"
    )
    p = sub.add_parser("convert", help=text, description=text)
    p.add_argument("source", metavar="IN", help="the .osm/.osm.pbf or GeoJSON file")
    p.add_argument("--out", required=True, metavar="OUT.geojson", help="the city to write")
    p.add_argument(
        "--bbox",
        nargs=4,
        type=float,
        metavar=("SOUTH", "WEST", "NORTH", "EAST"),
        help="keep only the buildings inside this latitude/longitude box [deg]",
    )
    p.add_argument(
        "--no-repair",
        action="store_true",
        help="list every bad feature in one error instead of repairing invalid rings",
    )
    p.add_argument(
        "--default-height-m",
        type=float,
        default=DEFAULT_HEIGHT_M,
        help=f"roof height of a building without height or levels (default {DEFAULT_HEIGHT_M})",
    )
    p.add_argument(
        "--storey-height-m",
        type=float,
        default=STOREY_HEIGHT_M,
        help=f"metres per building:levels storey (default {STOREY_HEIGHT_M})",
    )


def run(args: argparse.Namespace) -> int:
    """Convert, then print where the city went and the report."""
    from coopnav_env.sim.osm_city import convert_city

    report = convert_city(
        args.source,
        args.out,
        bbox=tuple(args.bbox) if args.bbox else None,
        repair=not args.no_repair,
        default_height_m=args.default_height_m,
        storey_height_m=args.storey_height_m,
    )
    print(f"wrote {args.out} (use it as city='geojson:{args.out}')")
    for line in report.lines():
        print(f"  {line}")
    return 0
