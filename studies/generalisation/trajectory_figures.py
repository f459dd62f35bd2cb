"""Top and side trajectory figures: the learned swarm beside the grid-tuned rule, per city.

For every city of the generalisation protocol's suites (held-out street grids, each generated
family, each real city under its real sky), flies ``--learned`` and ``--rule`` through the
same held-out episode (the same reset seed, a city never trained on) and draws both side by
side (:func:`coopnav_env.training.eval_plots.trajectory_comparison_figure`): the top view with
the city's footprints, the planned street route and every UAV's true track, above the side
view, the altitude along the route. Each policy flies with the settings of its training run
and the suite's city and sky, as ``coopnav evaluate --suite`` flies it.

The episode is reset seed ``--seed-start`` in every city but the ones named in ``--scan``:
there the script flies the held-out seeds from ``--seed-start`` on and draws the first
episode in which the rule misses the goal and the learned swarm reaches it (the first seed if
none of ``--scan-episodes`` does). The figure's title names the seed and how it was chosen.

Writes ``trajectories_<city>.png`` per city and ``episodes.md`` (each drawn episode's score,
outcome and cruise descriptors, :mod:`coopnav_env.training.behaviour`) into ``--out``, every
file through a temporary name.

Usage::

    python studies/generalisation/trajectory_figures.py --out studies/generalisation/figures
"""

from __future__ import annotations

import argparse
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from coopnav_env.training.envs import EVAL_SEED_START

HERE = Path(__file__).resolve().parent
LEARNED = "mappo:pretrained/families_scratch_s0"
RULE = "high_wide_column"
SUITES = ("grid", "families", "real")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description="Draw the learned swarm beside the grid-tuned rule on the same held-out "
        "episode of every protocol city (top and side views).",
    )
    ap.add_argument("--learned", default=LEARNED, help=f"the learned policy ({LEARNED})")
    ap.add_argument("--rule", default=RULE, help=f"the rule drawn beside it ({RULE})")
    ap.add_argument(
        "--cities",
        nargs="+",
        default=None,
        help="suite city names to draw (default: every city of the grid, families and real suites)",
    )
    ap.add_argument(
        "--seed-start",
        type=int,
        default=EVAL_SEED_START + 200,
        help=f"the held-out reset seed drawn, >= {EVAL_SEED_START} ({EVAL_SEED_START + 200})",
    )
    ap.add_argument(
        "--scan",
        nargs="*",
        default=["old_town"],
        help="cities where the first episode with the rule missing the goal and the learned "
        "swarm reaching it is drawn (old_town)",
    )
    ap.add_argument(
        "--scan-episodes", type=int, default=50, help="held-out seeds scanned at most (50)"
    )
    ap.add_argument("--dpi", type=int, default=90, help="PNG resolution (90)")
    ap.add_argument(
        "--out", default=str(HERE / "figures"), help="output folder (figures/ beside this script)"
    )
    args = ap.parse_args(argv)
    if args.seed_start < EVAL_SEED_START:
        ap.error(
            f"--seed-start must be >= {EVAL_SEED_START} (lower seeds may have been trained "
            f"or tuned on), got {args.seed_start}"
        )
    if args.scan_episodes < 1:
        ap.error(f"--scan-episodes must be >= 1, got {args.scan_episodes}")
    if not 30 <= args.dpi <= 300:
        ap.error(f"--dpi must be in 30..300, got {args.dpi}")
    return args


def policy_env(name: str, city: Any) -> Any:
    """The env ``name`` flies ``city`` in: its run's settings (none for a rule) under the
    suite city's city and sky, as ``coopnav evaluate --suite`` builds it."""
    import coopnav_env.urban_canyon_v1 as v1
    from coopnav_env.training.run_configs import train_config_of_policies

    run_env = dict(train_config_of_policies([name]).get("env") or {})
    for key in [k for k in run_env if k.startswith("city_")] + ["city", "constellation"]:
        run_env.pop(key, None)
    run_env.pop("systems", None)
    return v1.parallel_env(**{**run_env, **city.env_settings()})


def save_small_png(fig: Any, path: Path, dpi: int, colours: int = 128) -> Path:
    """Write ``fig`` to ``path`` as a PNG of at most ``colours`` palette colours (a few
    times smaller than matplotlib's full-colour PNG of a city's footprints), through a
    temporary name, and close it."""
    import io

    import matplotlib.pyplot as plt
    from PIL import Image

    from coopnav_env.training.files import atomic_path

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    buf.seek(0)
    image = Image.open(buf).convert("RGB").quantize(colors=colours)
    with atomic_path(path, suffix=".png") as tmp:
        image.save(tmp, format="PNG", optimize=True)
    return path


def cruise_altitude_per_uav_m(pos_enu_m: Any) -> list[float]:
    """Each UAV's mean altitude over the cruise
    (:data:`coopnav_env.training.behaviour.CRUISE`, the steps ``cruise_behaviour`` averages)."""
    import numpy as np

    from coopnav_env.training.behaviour import CRUISE

    pos = np.asarray(pos_enu_m, dtype=float)
    t0, t1 = (round(f * (len(pos) - 1)) for f in CRUISE)
    part = pos[max(t0, 1) : max(t1, t0 + 1) + 1]
    return [float(z) for z in part[:, :, 2].mean(axis=0)]


def _describe(rec: Any) -> str:
    if rec.collided:
        return "crash"
    return "goal" if rec.success else "goal missed"


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from coopnav_env.agents import make_policy
    from coopnav_env.sim.real_suite import suite_cities
    from coopnav_env.training.eval_plots import trajectory_comparison_figure
    from coopnav_env.training.evaluate import run_episode
    from coopnav_env.training.files import atomic_write_text, ensure_folder

    cities = [c for s in SUITES for c in suite_cities(s)]
    known = [c.name for c in cities]
    wanted = args.cities or known
    unknown = [c for c in [*wanted, *args.scan] if c not in known]
    if unknown:
        print(f"unknown cities {unknown}; the suites' cities are {known}", file=sys.stderr)
        return 2
    out = Path(args.out)
    ensure_folder(out)
    rows = [
        "| city | reset seed | policy | score | outcome | steps | spacing [m] | altitude [m] "
        "| spread across route [m] | speed [m/s] | altitude per UAV [m] |",
        "|---|---:|---|---:|---|---:|---:|---:|---:|---:|---|",
    ]
    t_all = time.perf_counter()
    for city in [c for c in cities if c.name in wanted]:
        t0 = time.perf_counter()
        flown = {}
        for name in (args.rule, args.learned):
            env = policy_env(name, city)
            flown[name] = (env, make_policy(name, env))
        seed, how = args.seed_start, "the first held-out seed"
        records = {}
        if city.name in args.scan:
            how = (
                f"no seed of {args.seed_start}..{args.seed_start + args.scan_episodes - 1} "
                f"has the rule missing the goal and the learned swarm reaching it"
            )
            for s in range(args.seed_start, args.seed_start + args.scan_episodes):
                rule_rec = run_episode(*flown[args.rule], s)
                if rule_rec.success:
                    continue
                learned_rec = run_episode(*flown[args.learned], s)
                print(
                    f"  {city.name} seed {s}: rule {_describe(rule_rec)}, learned "
                    f"{_describe(learned_rec)}",
                    file=sys.stderr,
                    flush=True,
                )
                if learned_rec.success:
                    seed = s
                    how = (
                        f"the first held-out seed from {args.seed_start} where the rule "
                        "misses the goal and the learned swarm reaches it"
                    )
                    records = {args.rule: rule_rec, args.learned: learned_rec}
                    break
        for name in (args.rule, args.learned):
            if name not in records:
                records[name] = run_episode(*flown[name], seed)
        panels = [
            (f"{label} `{name}`", flown[name][0], records[name])
            for label, name in (("rule", args.rule), ("learned", args.learned))
        ]
        where = f"`{city.city}`" if hasattr(city, "city") else city.place
        title = textwrap.fill(f"{city.name} ({where}): reset seed {seed}, {how}", 90)
        fig = trajectory_comparison_figure(panels, title)
        path = save_small_png(fig, out / f"trajectories_{city.name}.png", dpi=args.dpi)
        for name, rec in records.items():
            b = rec.behaviour()
            cells = " | ".join(
                f"{b[k]:.1f}" for k in ("spacing_m", "altitude_m", "lateral_spread_m", "speed_mps")
            )
            per_uav = ", ".join(f"{z:.1f}" for z in cruise_altitude_per_uav_m(rec.pos_enu_m))
            rows.append(
                f"| {city.name} | {seed} | `{name}` | {rec.episode_return:.3f} | "
                f"{_describe(rec)} | {rec.length} | {cells} | {per_uav} |"
            )
        for env, _policy in flown.values():
            env.close()
        print(
            f"{path} ({path.stat().st_size / 1024:.0f} kB, seed {seed}, "
            f"{time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    given = argv if argv is not None else sys.argv[1:]
    command = " ".join(["python studies/generalisation/trajectory_figures.py", *given])
    text = (
        "# The drawn episodes\n\n"
        f"Regenerate: `{command}` ({(time.perf_counter() - t_all) / 60:.1f} min). One held-out "
        "episode per city and policy, the same reset seed for both; descriptors over the "
        "cruise (the middle 60 % of the steps, `coopnav_env.training.behaviour`); altitude "
        "per UAV: `uav_0`, `uav_1`, ... in order.\n\n" + "\n".join(rows) + "\n"
    )
    atomic_write_text(out / "episodes.md", text)
    print(f"{out / 'episodes.md'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
