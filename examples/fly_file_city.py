"""Fly the column heuristics over a city read from a GeoJSON file and render the last frame.

The city is a GeoJSON FeatureCollection of building footprints (``height``, else
``building:levels`` x 3 m, else 10 m); by default the sample city shipped with the package
(``geojson:sample``). Start and goal are drawn in the free space between the buildings per
episode, or given as latitude/longitude. Run it::

    python examples/fly_file_city.py --out frames
    python examples/fly_file_city.py --city my_streets.geojson --start 31.2335,121.4921 \\
        --goal 31.2301,121.4982 --out frames

The two lines that fly your own city with the command line tool::

    coopnav evaluate --policies column wide_column --episodes 5 --env-set city=geojson:my.geojson \\
        --out eval_my_city
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from coopnav_env import urban_canyon_v1
from coopnav_env.agents import make_policy


def _lat_lon(text: str) -> tuple[float, float]:
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON in degrees, got {text!r}") from None
    return lat, lon


def _save_png(frame: np.ndarray, path: Path) -> None:
    """Write an RGB frame to ``path`` (temporary name in the same folder, then rename)."""
    import matplotlib.pyplot as plt

    tmp = path.with_name(path.name + ".tmp.png")
    plt.imsave(tmp, frame)
    os.replace(tmp, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--city", default="sample", help="GeoJSON file of footprints (default: the sample city)"
    )
    parser.add_argument("--start", type=_lat_lon, default=None, help="start LAT,LON [deg]")
    parser.add_argument("--goal", type=_lat_lon, default=None, help="goal LAT,LON [deg]")
    parser.add_argument(
        "--policies", nargs="+", default=["column", "wide_column"], help="heuristics to fly"
    )
    parser.add_argument("--episodes", type=int, default=1, help="episodes per policy")
    parser.add_argument("--max-steps", type=int, default=200, help="steps per episode")
    parser.add_argument("--seed", type=int, default=0, help="first reset seed")
    parser.add_argument("--out", type=Path, default=None, help="folder for the rendered frames")
    args = parser.parse_args(argv)

    settings = {
        "city": f"geojson:{args.city}",
        "max_steps": args.max_steps,
        "city_start_lat_lon": args.start,
        "city_goal_lat_lon": args.goal,
        "render_mode": "rgb_array" if args.out is not None else None,
    }
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    for name in args.policies:
        env = urban_canyon_v1.parallel_env(**settings)
        if name == args.policies[0]:
            print(f"city {args.city}: origin {env.config.lat_deg:.6f}, {env.config.lon_deg:.6f}")
        policy = make_policy(name, env)
        for k in range(args.episodes):
            seed = args.seed + k
            obs, _ = env.reset(seed=seed)
            policy.reset(seed=seed)
            city = env.world.city
            errors, steps, reached, crashed = [], 0, False, False
            while env.agents:
                obs, _, _, _, infos = env.step(policy.act(obs))
                steps += 1
                ep = env.world.last
                errors.append(np.linalg.norm(ep.nav_pos_enu_m - ep.pos_enu_m, axis=1).mean())
                crashed |= bool(ep.collided.any())
                reached |= bool(infos) and all(info["in_goal"] for info in infos.values())
            print(
                f"{name} episode {k} ({city.buildings.n} buildings): {steps} steps, "
                f"{'goal reached' if reached else 'crashed' if crashed else 'goal not reached'}, "
                f"mean 3-D navigation error {np.mean(errors):.1f} m"
            )
            if args.out is not None:
                path = args.out / f"{name}_episode{k}.png"
                _save_png(env.render(), path)
                print(f"frame written to {path}")
        env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
