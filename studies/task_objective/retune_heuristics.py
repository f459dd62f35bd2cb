"""The heuristics on ``urban_canyon_v1``: scored, the best column re-tuned, and confirmed.

Flies the named heuristics (the column presets ``column``, ``sky_column``, ``stretched_column``,
``wide_column``, ``guarded_column``, ``ceiling_column``, ``best_sky_route``, and the waypoint
follower, plain and at 28 m) on held-out episodes of ``urban_canyon_v1``, whose undiscounted
return is the task's score (:func:`coopnav_env.training.alignment.fly`). The column preset with
the highest mean score is then re-tuned on that score over a grid of spacing (``spacing_m``),
cruise speed (``cruise_speed_mps``) and altitude (``ceiling_margin_m``: how far below the top of
the altitude band the column flies; a negative margin puts the target above the band, so that
the column climbs and holds the band's top whatever its estimated altitude reads), on the same
episodes.

Choosing the best of many settings on the episodes that score them flatters the winner, so
the chosen setting is confirmed on as many *fresh* episodes (the next reset seeds): a second
table flies it beside ``wide_column``, the best named column and ``column``.

Each table gives per policy the mean score with its 95 % bootstrap interval over episodes
(:func:`coopnav_env.training.stats.bootstrap_mean_interval`, 2000 resamples), the score's
parts (mean navigation error, goal rate, collision rate, mean steps) and the paired
difference in score against the table's reference (the best policy of the tuning table, the
chosen setting in the confirmation table) with its 95 % paired bootstrap interval
(:func:`coopnav_env.training.stats.paired_difference`). ``report.json`` also keeps every
policy's per-episode scores and errors, for paired comparisons with other policies on the
same seeds. The study (``studies/task_objective``) runs::

    python studies/task_objective/retune_heuristics.py --episodes 100
"""

from __future__ import annotations

import argparse
import inspect
import itertools
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

ENV_ID = "urban_canyon_v1"

NAMED_POLICIES: tuple[str, ...] = (
    "column",
    "sky_column",
    "stretched_column",
    "wide_column",
    "guarded_column",
    "ceiling_column",
    "best_sky_route",
    "waypoint",
    "waypoint@altitude_m=28",
)
"""The heuristics scored by default."""

DEFAULT_SPACINGS_M: tuple[float, ...] = (30.0, 45.0, 60.0)
DEFAULT_SPEEDS_MPS: tuple[float, ...] = (5.0, 7.0, 10.0)
DEFAULT_CEILING_MARGINS_M: tuple[float, ...] = (0.5, -10.0)
"""Altitudes of the grid: 0.5 m below the band's top on the estimated altitude (``wide_column``'s),
and a target 10 m above the band (``ceiling_column``'s: the column holds the top)."""

BOOTSTRAP_REPS = 2000
CHUNK = 10
"""Episodes flown per :func:`fly` call (one environment each; the progress bar's step)."""

TUNED = ("spacing_m", "cruise_speed_mps", "ceiling_margin_m")


def column_preset(name: str) -> str | None:
    """The :data:`COLUMN_PRESETS` key of a column policy name (preset or alias, options after
    ``@`` ignored); None for a policy that is not a column."""
    from coopnav_env.agents.heuristics import COLUMN_ALIASES, COLUMN_PRESETS

    base = name.split("@", 1)[0]
    preset = COLUMN_ALIASES.get(base, base)
    return preset if preset in COLUMN_PRESETS else None


def effective_setting(name: str) -> tuple[str, float, float, float] | None:
    """``(preset, spacing_m, cruise_speed_mps, ceiling_margin_m)`` that the column policy
    ``name`` flies (a ``None`` margin, the start altitude, as NaN); None for a non-column.

    Two names with the same setting fly the same episodes (every other option is the
    preset's), so a grid point equal to a named preset reuses its flights.
    """
    from coopnav_env.agents import parse_policy_name
    from coopnav_env.agents.heuristics import COLUMN_PRESETS, ColumnPolicy

    preset = column_preset(name)
    if preset is None:
        return None
    options = parse_policy_name(name)[1]
    if set(options) - set(TUNED):
        return None  # other options: never the same as a grid point
    defaults = {
        k: p.default for k, p in inspect.signature(ColumnPolicy.__init__).parameters.items()
    }
    values = {**defaults, **COLUMN_PRESETS[preset], **options}
    margin = values["ceiling_margin_m"]
    return (
        preset,
        float(values["spacing_m"]),
        float(values["cruise_speed_mps"]),
        math.nan if margin is None else float(margin),
    )


def grid_names(
    base: str,
    spacings_m: Sequence[float],
    speeds_mps: Sequence[float],
    ceiling_margins_m: Sequence[float],
) -> list[str]:
    """The policy names of the grid over ``base`` (a column preset name), in grid order."""
    if not (spacings_m and speeds_mps and ceiling_margins_m):
        raise ValueError("the grid needs at least one spacing, one speed and one margin")
    return [
        f"{base}@spacing_m={s:g},cruise_speed_mps={v:g},ceiling_margin_m={m:g}"
        for s, v, m in itertools.product(spacings_m, speeds_mps, ceiling_margins_m)
    ]


def fly_scores(
    name: str, seeds: Sequence[int], advance: Callable[[int], None] | None = None
) -> dict[str, np.ndarray]:
    """Fly ``name`` on ``seeds`` of ``urban_canyon_v1``: per episode ``score`` (the
    undiscounted return), ``nav_error_m``, ``steps``, ``goal``, ``collided``."""
    from coopnav_env.training.alignment import fly

    records = []
    for i in range(0, len(seeds), CHUNK):
        chunk = list(seeds[i : i + CHUNK])
        records += fly(name, ENV_ID, chunk)
        if advance is not None:
            advance(len(chunk))
    return {
        "score": np.array([r.episode_return for r in records]),
        "nav_error_m": np.array([r.nav_error_m for r in records]),
        "steps": np.array([r.steps for r in records], dtype=float),
        "goal": np.array([r.goal for r in records], dtype=float),
        "collided": np.array([r.collided for r in records], dtype=float),
    }


def table(flights: dict[str, dict[str, np.ndarray]], reference: str) -> list[dict[str, Any]]:
    """One row per policy, sorted by mean score (highest first): the score with its 95 %
    bootstrap interval, its parts, and the paired difference to ``reference``."""
    from coopnav_env.training.stats import bootstrap_mean_interval, paired_difference

    ref = flights[reference]["score"]
    rows = []
    for name, f in flights.items():
        score, lo, hi = bootstrap_mean_interval(
            f["score"], BOOTSTRAP_REPS, np.random.default_rng(0)
        )
        diff, share_lower = paired_difference(
            f["score"][None, :], ref[None, :], reps=BOOTSTRAP_REPS, seed=0
        )
        rows.append(
            {
                "policy": name,
                "score": score,
                "score_ci95": [lo, hi],
                "nav_error_m": float(np.nanmean(f["nav_error_m"])),
                "goal_rate": float(f["goal"].mean()),
                "collision_rate": float(f["collided"].mean()),
                "steps": float(f["steps"].mean()),
                "vs_reference": diff.as_dict(),
                "share_of_episodes_below_reference": share_lower,
            }
        )
    return sorted(rows, key=lambda r: -r["score"])


def table_lines(rows: Sequence[dict[str, Any]], reference: str) -> list[str]:
    """A Markdown table of :func:`table`'s rows."""
    lines = [
        f"| policy | score [95 % CI] | nav error [m] | goal rate | collision rate | steps "
        f"| score - {reference} [95 % paired CI] |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        d = r["vs_reference"]
        lines.append(
            f"| {r['policy']} | {r['score']:.3f} [{r['score_ci95'][0]:.3f}, "
            f"{r['score_ci95'][1]:.3f}] | {r['nav_error_m']:.2f} | {r['goal_rate']:.2f} "
            f"| {r['collision_rate']:.2f} | {r['steps']:.1f} | {d['value']:+.3f} "
            f"[{d['low']:+.3f}, {d['high']:+.3f}] |"
        )
    return lines


def retune(
    episodes: int,
    seed_start: int,
    policies: Sequence[str] = NAMED_POLICIES,
    spacings_m: Sequence[float] = DEFAULT_SPACINGS_M,
    speeds_mps: Sequence[float] = DEFAULT_SPEEDS_MPS,
    ceiling_margins_m: Sequence[float] = DEFAULT_CEILING_MARGINS_M,
    progress: bool = True,
) -> dict[str, Any]:
    """Score ``policies``, re-tune the best column over the grid, confirm on fresh episodes.

    Tuning episodes: reset seeds ``seed_start .. seed_start + episodes - 1``; confirmation:
    the next ``episodes`` seeds. Returns the report (see the module doc).

    Raises
    ------
    ValueError
        ``episodes < 2``, no column among ``policies``, or an empty grid.
    """
    if episodes < 2:
        raise ValueError(f"episodes must be >= 2, got {episodes}")
    columns = [p for p in policies if column_preset(p) is not None]
    if not columns:
        raise ValueError(f"no column heuristic among the policies {list(policies)}")
    if "wide_column" not in policies:
        raise ValueError(
            f"the policies must include 'wide_column' (the confirmation's), got {policies}"
        )
    tune_seeds = list(range(seed_start, seed_start + episodes))
    confirm_seeds = list(range(seed_start + episodes, seed_start + 2 * episodes))
    n_grid = len(spacings_m) * len(speeds_mps) * len(ceiling_margins_m)
    total = episodes * (len(policies) + n_grid + 4)  # an upper bound: reuse flies less
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="episode", desc="retune", file=sys.stderr)
    advance = bar.update if bar is not None else None
    t0 = time.perf_counter()

    tuning: dict[str, dict[str, np.ndarray]] = {}
    for name in policies:
        tuning[name] = fly_scores(name, tune_seeds, advance)
    best_column = max(columns, key=lambda p: tuning[p]["score"].mean())
    base = best_column.split("@", 1)[0]
    named_settings = {effective_setting(p): p for p in columns if effective_setting(p)}
    grid: list[dict[str, Any]] = []
    for name in grid_names(base, spacings_m, speeds_mps, ceiling_margins_m):
        same_as = named_settings.get(effective_setting(name))
        flights = tuning[same_as] if same_as else fly_scores(name, tune_seeds, advance)
        if not same_as:
            tuning[name] = flights
        grid.append({"policy": name, "same_as": same_as, "score": float(flights["score"].mean())})
    best_grid = max(grid, key=lambda g: g["score"])
    chosen = best_grid["same_as"] or best_grid["policy"]
    top = max(tuning, key=lambda p: tuning[p]["score"].mean())
    tuning_rows = table(tuning, top)

    confirm_names = list(dict.fromkeys([chosen, "wide_column", best_column, "column"]))
    confirm_names = [p for p in confirm_names if p in tuning]  # formation may be left out
    confirmation = {p: fly_scores(p, confirm_seeds, advance) for p in confirm_names}
    confirm_rows = table(confirmation, chosen)
    if bar is not None:
        bar.total = bar.n
        bar.close()

    def per_episode(flights: dict[str, dict[str, np.ndarray]]) -> dict[str, Any]:
        return {
            p: {
                "score": np.round(f["score"], 6).tolist(),
                "nav_error_m": np.round(f["nav_error_m"], 4).tolist(),
            }
            for p, f in flights.items()
        }

    return {
        "env_id": ENV_ID,
        "episodes": episodes,
        "tuning_seeds": [tune_seeds[0], tune_seeds[-1]],
        "confirmation_seeds": [confirm_seeds[0], confirm_seeds[-1]],
        "policies": list(policies),
        "best_named_column": best_column,
        "grid": {
            "base": base,
            "spacing_m": [float(s) for s in spacings_m],
            "cruise_speed_mps": [float(v) for v in speeds_mps],
            "ceiling_margin_m": [float(m) for m in ceiling_margins_m],
            "settings": sorted(grid, key=lambda g: -g["score"]),
        },
        "best_retuned": chosen,
        "best_on_tuning": top,
        "tuning": tuning_rows,
        "confirmation": confirm_rows,
        "bootstrap": {"reps": BOOTSTRAP_REPS, "generator_seed": 0, "confidence": 0.95},
        "per_episode": {"tuning": per_episode(tuning), "confirmation": per_episode(confirmation)},
        "wall_s": time.perf_counter() - t0,
    }


def report_markdown(report: dict[str, Any]) -> str:
    """The report as Markdown: the tuning table, the grid, the confirmation table."""
    e = report["episodes"]
    t0, t1 = report["tuning_seeds"]
    c0, c1 = report["confirmation_seeds"]
    g = report["grid"]
    lines = [
        f"# Heuristics on {report['env_id']}, re-tuned on its score",
        "",
        f"Command: `{report.get('command', '')}` ({report['wall_s'] / 60:.1f} min).",
        "",
        f"## Tuning: {e} held-out episodes (reset seeds {t0:,}-{t1:,})",
        "",
        f"Named heuristics, and the best named column (`{report['best_named_column']}`) over "
        f"spacing_m {g['spacing_m']} x cruise_speed_mps {g['cruise_speed_mps']} x "
        f"ceiling_margin_m {g['ceiling_margin_m']} (ceiling_margin_m: how far below the top of "
        "the altitude band the column flies, on its estimated altitude; a negative margin holds "
        "the band's top; a grid point equal to a named preset is listed under its name). "
        "Score: the undiscounted return, the mean over UAVs (at most "
        "2: 1 for the route at perfect navigation, 1 for arriving). Sorted by score; the last "
        f"column is the paired difference to the best, `{report['best_on_tuning']}`.",
        "",
        *table_lines(report["tuning"], report["best_on_tuning"]),
        "",
        "Grid (mean score on the tuning episodes; per-episode scores and errors of every "
        "policy are in report.json):",
        "",
        "| setting | score |",
        "|---|---:|",
        *[
            f"| {s['policy']}{' (= ' + s['same_as'] + ')' if s['same_as'] else ''} "
            f"| {s['score']:.3f} |"
            for s in g["settings"]
        ],
        "",
        f"**Best heuristic re-tuned on v1: `{report['best_retuned']}`.**",
        "",
        f"## Confirmation: {e} fresh episodes (reset seeds {c0:,}-{c1:,})",
        "",
        "The chosen setting was picked as the best of the grid on the tuning episodes, which "
        "flatters it; here it flies fresh episodes beside the named columns. The last column "
        f"is the paired difference to `{report['best_retuned']}`.",
        "",
        *table_lines(report["confirmation"], report["best_retuned"]),
        "",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    from coopnav_env.training.envs import EVAL_SEED_START
    from coopnav_env.training.files import atomic_write_text, jsonable, write_json

    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="Writes report.json and report.md to --out.",
    )
    p.add_argument("--episodes", type=int, default=100, help="episodes per table (default: 100)")
    p.add_argument(
        "--seed-start",
        type=int,
        default=EVAL_SEED_START,
        help=f"first reset seed of the tuning episodes; the confirmation flies the next "
        f"--episodes seeds (default: {EVAL_SEED_START}, the held-out range)",
    )
    p.add_argument(
        "--out",
        default="studies/task_objective/heuristics_v1",
        help="folder of report.json and report.md (default: studies/task_objective/heuristics_v1)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing report.json")
    p.add_argument(
        "--policies",
        nargs="+",
        default=list(NAMED_POLICIES),
        help="heuristics to score; must include wide (default: " + " ".join(NAMED_POLICIES) + ")",
    )
    p.add_argument("--spacings", type=float, nargs="+", default=list(DEFAULT_SPACINGS_M))
    p.add_argument("--speeds", type=float, nargs="+", default=list(DEFAULT_SPEEDS_MPS))
    p.add_argument(
        "--ceiling-margins",
        type=float,
        nargs="+",
        default=list(DEFAULT_CEILING_MARGINS_M),
        help="ceiling_margin_m values of the grid [m] (default: 0.5 -10)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    if args.episodes < 2:
        p.error(f"--episodes must be >= 2, got {args.episodes}")
    out = Path(args.out)
    if (out / "report.json").exists() and not args.overwrite:
        p.error(f"{out / 'report.json'} exists; pass --overwrite to replace it")
    try:
        report = retune(
            args.episodes,
            args.seed_start,
            policies=args.policies,
            spacings_m=args.spacings,
            speeds_mps=args.speeds,
            ceiling_margins_m=args.ceiling_margins,
            progress=not args.no_progress,
        )
    except ValueError as exc:
        p.error(str(exc))
    report["command"] = " ".join(
        [
            "python studies/task_objective/retune_heuristics.py",
            *(sys.argv[1:] if argv is None else argv),
        ]
    )
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "report.json", jsonable(report))
    text = report_markdown(report)
    atomic_write_text(out / "report.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
