"""Top views and statistics of the generated city families, beside the grid and Helsinki.

Writes, into ``--out`` (default: this study's ``results/``), one top view per family
(``family_NAME.png``: roofs shaded by height, the built-up free space where starts and goals
are drawn in pale blue), ``statistics.md`` (the table of
:func:`coopnav_env.sim.city_families.city_statistics`, each family averaged over
``--seeds`` cities, the grid city over as many, Helsinki's shipped extract once) and
``generation_cost.md`` (the time to draw a city and build its free-space grid, median over
the seeds) and ``episode_cost.md`` (``column`` flying ``--episodes`` episodes of
``urban_canyon_v1`` per city: a reset that builds a new city, the same reset again with the
city of its seed kept, and a step), timed on the machine that runs it. Every file is written to
a temporary name and renamed.

    python studies/city_families/make_figures.py --seeds 10 --episodes 5
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from coopnav_env.sim.city import CityConfig, generate_city
from coopnav_env.sim.city_families import (
    FAMILIES,
    CityStatistics,
    city_statistics,
    family_city,
    statistics_table,
)
from coopnav_env.sim.file_city import load_file_city

HERE = Path(__file__).resolve().parent


def _write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _mean(rows: list[CityStatistics], name: str) -> CityStatistics:
    values = {
        f.name: float(np.mean([getattr(r, f.name) for r in rows]))
        for f in fields(CityStatistics)
        if f.name != "name"
    }
    values["n_buildings"] = round(values["n_buildings"])
    return CityStatistics(name=name, **values)


def top_view(city, title: str, path: Path) -> None:
    """A top view PNG of a polygon city (roofs shaded by height, built-up free space blue)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    fig, ax = plt.subplots(figsize=(3.6, 3.9), dpi=90)
    x0, x1, y0, y1 = city.extent_m
    res = city.resolution_m
    ax.imshow(
        np.where(city.built_up, 1.0, np.nan),
        extent=(x0, x1, y0, y1),
        origin="lower",
        cmap="Blues",
        vmin=0.0,
        vmax=6.0,
        interpolation="nearest",
    )
    norm = Normalize(0.0, 120.0)
    cmap = plt.get_cmap("magma_r")
    b = city.buildings
    outer = [rings[0] for rings in b.rings_m]
    holes = [r for rings in b.rings_m for r in rings[1:]]
    ax.add_collection(PolyCollection(outer, facecolors=cmap(norm(b.heights_m)), edgecolors="none"))
    if holes:
        ax.add_collection(PolyCollection(holes, facecolors="white", edgecolors="none"))
    ax.set_xlim(x0 - res, x1 + res)
    ax.set_ylim(y0 - res, y1 + res)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.tick_params(labelsize=7)
    fig.colorbar(
        plt.cm.ScalarMappable(norm=norm, cmap=cmap),
        ax=ax,
        orientation="horizontal",
        fraction=0.05,
        pad=0.08,
        label="roof [m] (120 m and above: darkest)",
    ).ax.tick_params(labelsize=7)
    fig.tight_layout()
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    os.replace(tmp, path)


def episode_cost(city: str, episodes: int) -> str:
    """A row of ``episode_cost.md``: resets and steps of ``column`` on ``city`` [ms]."""
    from coopnav_env import urban_canyon_v1
    from coopnav_env.agents import make_policy

    env = urban_canyon_v1.parallel_env(city=city)
    policy = make_policy("column", env)
    env.reset(seed=10_000)  # compile first
    fresh, again, step_s, n_steps = [], [], 0.0, 0
    for ep in range(episodes):
        t = time.perf_counter()
        env.reset(seed=20_000 + ep)
        fresh.append(1e3 * (time.perf_counter() - t))
        t = time.perf_counter()
        obs, _ = env.reset(seed=20_000 + ep)
        again.append(1e3 * (time.perf_counter() - t))
        policy.reset(seed=ep)
        t = time.perf_counter()
        while env.agents:
            obs, *_ = env.step(policy.act(obs))
            n_steps += 1
        step_s += time.perf_counter() - t
    step_ms = 1e3 * step_s / n_steps
    return (
        f"| {city} | {np.median(fresh):.0f} | {np.median(again):.1f} | {step_ms:.2f} | "
        f"{80 * step_ms:.0f} | {np.median(fresh) / (80 * step_ms):.1f} |"
    )


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="cities per family (seeds 0..N-1)")
    ap.add_argument("--episodes", type=int, default=5, help="timed episodes per city")
    ap.add_argument("--out", type=Path, default=HERE / "results")
    ap.add_argument("--helsinki", default="osm", choices=("osm", "geojson"))
    args = ap.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    family_city(FAMILIES[0], np.random.default_rng(0))  # compile the kernels first
    rows, cost = (
        [],
        ["| family | buildings | draw + grid [ms], median | max [ms] |", "|---|---|---|---|"],
    )
    for name in FAMILIES:
        stats, times = [], []
        for seed in range(args.seeds):
            t = time.perf_counter()
            city = family_city(name, np.random.default_rng(seed))
            times.append(1e3 * (time.perf_counter() - t))
            stats.append(city_statistics(city, name))
            if seed == 0:
                top_view(city, f"family:{name} (seed 0)", out / f"family_{name}.png")
        rows.append(_mean(stats, f"family:{name}"))
        cost.append(
            f"| {name} | {rows[-1].n_buildings} | {np.median(times):.0f} | {max(times):.0f} |"
        )
        print(cost[-1], flush=True)
    grid = [
        city_statistics(generate_city(CityConfig(), np.random.default_rng(s)), "grid")
        for s in range(args.seeds)
    ]
    rows.append(_mean(grid, "grid"))
    if args.helsinki == "osm":
        from coopnav_env.sim.osm_city import helsinki_osm_path

        hel = load_file_city("osm:" + str(helsinki_osm_path()), warn=False)
    else:
        from coopnav_env.sim.osm_city import helsinki_geojson_path

        hel = load_file_city(helsinki_geojson_path(), warn=False)
    rows.append(city_statistics(hel, f"{args.helsinki}:helsinki"))
    table = statistics_table(rows)
    print(table)
    _write(out / "statistics.md", table + "\n")
    _write(out / "generation_cost.md", "\n".join(cost) + "\n")
    ep_rows = [
        "| city | reset, new city [ms] | reset, kept city [ms] | step [ms] | 80 steps [ms] "
        "| new-city reset / 80 steps |",
        "|---|---|---|---|---|---|",
    ]
    for city in ["grid", *(f"family:{f}" for f in FAMILIES)]:
        ep_rows.append(episode_cost(city, args.episodes))
        print(ep_rows[-1], flush=True)
    _write(out / "episode_cost.md", "\n".join(ep_rows) + "\n")
    return out


if __name__ == "__main__":
    main()
