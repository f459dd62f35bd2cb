"""The learning study: learned swarms against every heuristic and a privileged planner.

``python studies/learning_in_default_setting/learning_study.py --help`` (formerly ``coopnav
study``; the learning studies, route choice and split choice use it) writes a study's report
(Markdown, JSON, figures) from training runs into ``--out`` (default ``runs/study``; the
committed ones are under ``studies/``), a folder of its
own that it claims before flying anything
(:func:`coopnav_env.training.files.claim_output_folder`):

1. every policy flies the same held-out episodes (reset seeds from 1,000,000; training uses
   seeds below) in the study's environment; a learned method contributes one row per
   training seed, a heuristic one row; the privileged planner flies a subset (it costs
   about 0.3 s per step);
2. per method: the mean and the interquartile mean of the episode's mean cooperative 3-D
   error and the goal rate, each with a 95 % stratified-bootstrap interval
   (:mod:`coopnav_env.training.stats`, over training seeds within episodes and over episodes);
   paired differences against every heuristic by episode seed;
3. behaviour descriptors per method (what was learned): spacing to the nearest neighbour,
   altitude, the swarm's extent across its direction of travel, the share of UAV-steps
   near an intersection or an open square, the swarm's distinct satellites, the time to the
   goal;
4. figures: learning curves with 95 % bands over seeds, the error per method with its
   interval, and trajectories seen from above and from the side (altitude along the route).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from coopnav_env.training.config import apply_overrides
from coopnav_env.training.envs import EVAL_SEED_START, heldout_seeds
from coopnav_env.training.eval_plots import distance_along_route, save_figure, short_label
from coopnav_env.training.files import atomic_write_text, claim_output_folder, jsonable
from coopnav_env.training.stats import (
    interquartile_mean,
    paired_difference,
    stratified_bootstrap_ci,
)

__all__ = [
    "EpisodeResult",
    "behaviour_descriptors",
    "fly_episodes",
    "main",
    "summarise",
]

NEAR_M = 10.0


@dataclass
class EpisodeResult:
    """One episode of one policy: the figures the study compares."""

    seed: int
    coop_error_mean_m: float  # over UAV-steps with a cooperative fix (NaN if none)
    p_fix: float  # share of UAV-steps with a cooperative fix
    success: bool
    collided: bool
    length: int
    # over every UAV-step: the 3-D error of the estimate each UAV used (its cooperative fix,
    # else its standalone fix, else dead reckoning); NaN where the env does not report it
    nav_error_mean_m: float = math.nan
    descriptors: dict[str, float] = field(default_factory=dict)
    pos_enu_m: np.ndarray | None = None  # (T+1, N, 3) true positions


def _near_features(city: Any, xy: np.ndarray) -> np.ndarray:
    """Whether each point (..., 2) is within NEAR_M of an intersection or an open square.

    An intersection is the square where two streets cross (street width on each side); an
    open square is an empty block. "Within" means inside the area grown by NEAR_M.
    """
    w = float(city.street_width_m) / 2.0 + NEAR_M
    cx = np.asarray(city.street_centres_x_m)
    cy = np.asarray(city.street_centres_y_m)
    near = np.zeros(xy.shape[:-1], dtype=bool)
    if cx.size and cy.size:
        dx = np.min(np.abs(xy[..., 0, None] - cx), axis=-1)
        dy = np.min(np.abs(xy[..., 1, None] - cy), axis=-1)
        near |= (dx <= w) & (dy <= w)
    sq = np.asarray(city.open_squares).reshape(-1, 2)
    if sq.size and city.config is not None:
        half = float(city.config.block_size_m) / 2.0 + NEAR_M
        d = np.abs(xy[..., None, :] - sq)  # (..., k, 2)
        near |= np.any(np.all(d <= half, axis=-1), axis=-1)
    return near


def behaviour_descriptors(env: Any, pos: np.ndarray, n_sats_swarm: np.ndarray) -> dict[str, float]:
    """What a policy does, from an episode's true positions ``(T+1, N, 3)``.

    ``spacing_m``: mean distance of a UAV to its nearest neighbour; ``altitude_m``: mean
    altitude; ``cross_extent_m``: mean extent of the swarm across its direction of travel
    (the smaller of its East and North extents: a column in one street has a small one, a
    swarm that covers two streets or a square a large one); ``near_open_share``: share of
    UAV-steps within 10 m of an intersection or an open square; ``swarm_sats``: mean distinct
    satellites received by the swarm.
    """
    base = getattr(env, "unwrapped", env)
    city = base.world.city
    p = np.asarray(pos, dtype=float)
    out: dict[str, float] = {}
    if p.shape[1] > 1:
        d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)
        d[:, np.arange(p.shape[1]), np.arange(p.shape[1])] = np.inf
        out["spacing_m"] = float(d.min(axis=2).mean())
        ext = p[:, :, :2].max(axis=1) - p[:, :, :2].min(axis=1)
        out["cross_extent_m"] = float(ext.min(axis=1).mean())
    else:
        out["spacing_m"] = math.nan
        out["cross_extent_m"] = 0.0
    out["altitude_m"] = float(p[:, :, 2].mean())
    out["near_open_share"] = float(_near_features(city, p[:, :, :2]).mean())
    out["swarm_sats"] = float(np.mean(n_sats_swarm)) if np.size(n_sats_swarm) else math.nan
    return out


def fly_episodes(
    policy_name: str, env_kwargs: Mapping[str, Any], seeds: Sequence[int], keep_positions: bool
) -> list[EpisodeResult]:
    """Fly ``policy_name`` through ``reset(seed)`` for every seed; one env for all episodes."""
    import studies.planner_headroom.planner  # registers 'planner'
    import studies.route_choice.routes  # noqa: F401  (registers the route policies)
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy
    from coopnav_env.training.evaluate import run_episode

    env = urban_canyon_v0.parallel_env(**dict(env_kwargs))
    policy = make_policy(policy_name, env)
    out = []
    for seed in seeds:
        rec = run_episode(env, policy, int(seed))
        err = rec.coop_error_m
        fix = np.isfinite(err)
        desc = (
            behaviour_descriptors(env, rec.pos_enu_m, rec.n_sats_swarm)
            if rec.pos_enu_m is not None
            else {}
        )
        desc["time_to_goal_s"] = (
            float(rec.length * env.unwrapped.config.dt_s) if rec.success else math.nan
        )
        p_fix = float(fix.mean()) if fix.size else 0.0
        desc["fix_share"] = p_fix
        nav = np.asarray(rec.nav_error_m, dtype=float)
        nav_ok = np.isfinite(nav)
        out.append(
            EpisodeResult(
                seed=int(seed),
                coop_error_mean_m=float(err[fix].mean()) if fix.any() else math.nan,
                p_fix=p_fix,
                success=bool(rec.success),
                collided=bool(rec.collided),
                length=int(rec.length),
                nav_error_mean_m=float(nav[nav_ok].mean()) if nav_ok.any() else math.nan,
                descriptors=desc,
                pos_enu_m=rec.pos_enu_m if keep_positions else None,
            )
        )
    env.close()
    return out


# ---- statistics ---------------------------------------------------------------------------


#: The study's scores (``--score``): what the per-episode error is the mean of.
SCORES = {
    "coop": "the mean cooperative 3-D error over UAV-steps with a cooperative fix",
    "nav": "the mean 3-D error of the estimate each UAV used (its cooperative fix, else its "
    "standalone fix, else dead reckoning) over every UAV-step",
}


def _matrix(runs: Sequence[Sequence[EpisodeResult]], key: str) -> np.ndarray:
    """(runs, episodes) matrix of ``key`` ("coop", "nav", "success" or a descriptor); NaN
    where an episode has no value (e.g. no cooperative fix at all)."""
    rows = []
    for run in runs:
        if key == "coop":
            rows.append([r.coop_error_mean_m for r in run])
        elif key == "nav":
            rows.append([r.nav_error_mean_m for r in run])
        elif key == "success":
            rows.append([float(r.success) for r in run])
        else:
            rows.append([r.descriptors.get(key, math.nan) for r in run])
    return np.array(rows, dtype=float)


def _finite_episodes(*matrices: np.ndarray) -> np.ndarray:
    """Mask of the episodes (columns) where every run of every (runs, episodes) matrix has a
    finite value."""
    return np.logical_and.reduce([np.all(np.isfinite(m), axis=0) for m in matrices])


def summarise(
    results: Mapping[str, Sequence[Sequence[EpisodeResult]]],
    heuristics: Sequence[str],
    reps: int = 2000,
    score: str = "coop",
) -> dict[str, Any]:
    """Per-method statistics and paired differences (see the module docstring).

    ``score`` (a key of :data:`SCORES`) is the error every ``error_*`` figure is of; the other
    score is reported beside it as ``other_error_mean`` and ``other_error_diff_m``.
    """
    if score not in SCORES:
        raise ValueError(f"score must be one of {sorted(SCORES)}, got {score!r}")
    other = next(k for k in SCORES if k != score)
    methods: dict[str, Any] = {}
    for name, runs in results.items():
        err = _matrix(runs, score)
        succ = _matrix(runs, "success")
        e = err[:, _finite_episodes(err)]  # episodes where every run had fixes
        oth = _matrix(runs, other)
        o = oth[:, _finite_episodes(oth)]
        m: dict[str, Any] = {
            "runs": len(runs),
            "episodes": int(err.shape[1]),
            "error_mean": stratified_bootstrap_ci(e, np.mean, reps).as_dict(),
            "error_iqm": stratified_bootstrap_ci(e, interquartile_mean, reps).as_dict(),
            "other_error_mean": (
                stratified_bootstrap_ci(o, np.mean, reps).as_dict() if o.size else None
            ),
            "goal_rate": stratified_bootstrap_ci(succ, np.mean, reps).as_dict(),
            "collision_rate": float(np.mean([[r.collided for r in run] for run in runs])),
            "per_run_error_mean": [float(np.nanmean(row)) for row in err],
            "per_run_goal_rate": [float(np.mean(row)) for row in succ],
        }
        desc: dict[str, float] = {}
        keys = sorted({k for run in runs for r in run for k in r.descriptors})
        for k in keys:
            x = _matrix(runs, k)
            desc[k] = float(np.nanmean(x)) if np.any(np.isfinite(x)) else math.nan
        m["descriptors"] = desc
        methods[name] = m
    paired: dict[str, dict[str, Any]] = {}
    for name, runs in results.items():
        paired[name] = {}
        for h in heuristics:
            if h == name or h not in results:
                continue
            a, b = _matrix(runs, score), _matrix(results[h], score)
            if a.shape[1] != b.shape[1]:
                continue
            ok = _finite_episodes(a, b)
            iv, share = paired_difference(a[:, ok], b[:, ok], reps)
            sa, sb = _matrix(runs, "success"), _matrix(results[h], "success")
            giv, _ = paired_difference(sa, sb, reps)
            oa, ob = _matrix(runs, other), _matrix(results[h], other)
            ook = _finite_episodes(oa, ob)
            oiv = paired_difference(oa[:, ook], ob[:, ook], reps)[0] if ook.any() else None
            paired[name][h] = {
                "error_diff_m": iv.as_dict(),
                "excludes_zero": iv.excludes_zero(),
                "share_episodes_lower": share,
                "goal_rate_diff": giv.as_dict(),
                "other_error_diff_m": oiv.as_dict() if oiv is not None else None,
            }
    return {"methods": methods, "paired": paired, "score": score, "other_score": other}


# ---- figures ------------------------------------------------------------------------------


def _curves(run_dirs: Sequence[Path], key: str) -> tuple[np.ndarray, np.ndarray] | None:
    """(grid, values per run) of ``key`` in each run's logs/progress.csv, on a common grid."""
    import csv

    # SB3 runs log the same figures under their TensorBoard names
    sb3 = {
        "agent_steps": "time/total_timesteps",
        "ep_coop_error_m": "nav/coop_error_mean_m",
        "ep_goal": "nav/goal_rate",
    }
    series = []
    for d in run_dirs:
        f = d / "logs" / "progress.csv"
        if not f.is_file():
            continue
        with f.open() as fh:
            rows = list(csv.DictReader(fh))
        xk, yk = "agent_steps", key
        if rows and xk not in rows[0]:
            xk, yk = sb3["agent_steps"], sb3.get(key, key)
        rows = [r for r in rows if r.get(yk) not in (None, "") and r.get(xk) not in (None, "")]
        if not rows:
            continue
        x = np.array([float(r[xk]) for r in rows])
        y = np.array([float(r[yk]) for r in rows])
        series.append((x, y))
    if not series:
        return None
    hi = min(s[0][-1] for s in series)
    lo = max(s[0][0] for s in series)
    grid = np.linspace(lo, hi, 60)
    vals = np.array([np.interp(grid, x, y) for x, y in series])
    return grid, vals


def plot_learning_curves(
    groups: Mapping[str, Sequence[Path]], path: Path, ref: Mapping[str, float]
) -> Path | None:
    """Training-episode error and goal rate against agent-steps, mean and 95 % band over
    seeds (t interval of the seed mean), one line per method; heuristics as dashed lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    drawn = False
    for name, dirs in groups.items():
        for ax, key, label in (
            (axes[0], "ep_coop_error_m", "training episodes: mean coop error [m]"),
            (axes[1], "ep_goal", "training episodes: goal rate"),
        ):
            c = _curves(dirs, key)
            if c is None:
                continue
            grid, vals = c
            vals = _smooth(vals, 5)  # per-iteration figures are means of few episodes
            mean = vals.mean(axis=0)
            line = ax.plot(grid / 1e6, mean, label=f"{name} ({vals.shape[0]} seeds)")[0]
            if vals.shape[0] > 1:
                half = _t975(vals.shape[0] - 1) * vals.std(axis=0, ddof=1) / np.sqrt(len(vals))
                lo_b, hi_b = (0.0, 1.0) if key == "ep_goal" else (0.0, np.inf)
                ax.fill_between(
                    grid / 1e6,
                    np.clip(mean - half, lo_b, hi_b),
                    np.clip(mean + half, lo_b, hi_b),
                    color=line.get_color(),
                    alpha=0.2,
                )
            ax.set_xlabel("agent-steps [millions]")
            ax.set_ylabel(label)
            drawn = True
    lo, hi = axes[0].get_ylim()
    # points per data unit, so that labels of nearly equal values are stacked upwards
    # (8 points apart) instead of drawn over each other
    ppu = axes[0].bbox.height * 72.0 / fig.dpi / max(hi - lo, 1e-9)
    last_pt = -math.inf
    for h, v in sorted(ref.items(), key=lambda kv: kv[1]):
        y_pt = max(v * ppu, last_pt + 8.0)
        shift, last_pt = y_pt - v * ppu, y_pt
        axes[0].axhline(v, ls="--", lw=0.8, color="grey")
        axes[0].annotate(
            f"{short_label(h)}: {v:.2f}",
            (1.0, v),
            xycoords=("axes fraction", "data"),
            xytext=(3, shift),
            textcoords="offset points",
            fontsize=7,
            va="center",
        )
    axes[0].set_title("dashed: heuristics on the held-out episodes", fontsize=8)
    axes[1].set_ylim(-0.02, 1.02)
    if not drawn:
        plt.close(fig)
        return None
    axes[0].legend(fontsize=8)
    fig.suptitle(
        "Learning curves (training episodes, 5-iteration moving mean): mean and 95 % t-interval "
        "over training seeds",
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def _smooth(vals: np.ndarray, k: int) -> np.ndarray:
    """Moving mean over ``k`` points along the last axis (shorter windows at the ends)."""
    kernel = np.ones(k)
    num = np.apply_along_axis(lambda r: np.convolve(r, kernel, "same"), -1, vals)
    den = np.convolve(np.ones(vals.shape[-1]), kernel, "same")
    return num / den


def _t975(dof: int) -> float:
    """97.5 % quantile of Student's t (table for small dof, normal beyond)."""
    table = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306}
    return table.get(dof, 1.96 if dof > 30 else 2.2)


#: x-axis label of the error figure per score
SCORE_AXIS = {
    "coop": "cooperative 3-D error per episode [m]",
    "nav": "3-D error of the estimate used, per episode [m]",
}


def plot_errors(summary: Mapping[str, Any], path: Path, xlabel: str = SCORE_AXIS["coop"]) -> Path:
    """Mean and IQM of the study's score per method, with 95 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary["methods"])
    fig, ax = plt.subplots(figsize=(8, 0.45 * len(names) + 1.2))
    y = np.arange(len(names))
    for off, key, lab in ((-0.15, "error_mean", "mean"), (0.15, "error_iqm", "IQM")):
        v = np.array([summary["methods"][n][key]["value"] for n in names])
        lo = np.array([summary["methods"][n][key]["low"] for n in names])
        hi = np.array([summary["methods"][n][key]["high"] for n in names])
        ax.errorbar(v, y + off, xerr=[v - lo, hi - v], fmt="o", capsize=3, label=lab)
    ax.set_yticks(y, [short_label(n) for n in names], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel(xlabel, fontsize=9)
    ax.set_title("mean and IQM with 95 % stratified-bootstrap intervals", fontsize=9)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_trajectories(
    env_kwargs: Mapping[str, Any], seed: int, flights: Mapping[str, np.ndarray], path: Path
) -> Path:
    """One episode of several policies: from above (map) and from the side (altitude along
    the route), so that formations that differ in height are told apart."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon, Rectangle

    from coopnav_env import urban_canyon_v0

    env = urban_canyon_v0.parallel_env(**dict(env_kwargs))
    env.reset(seed=seed)
    world = env.unwrapped.world
    b = world.city.buildings
    route_xy = np.asarray(world.route_xy_m)
    names = list(flights)
    fig, axes = plt.subplots(
        2, len(names), figsize=(4.0 * len(names), 5.6), gridspec_kw={"height_ratios": [2, 1.5]}
    )
    axes = np.asarray(axes).reshape(2, len(names))
    for j, name in enumerate(names):
        pos = flights[name]
        ax = axes[0, j]
        if hasattr(b, "rings_m"):  # a file city's footprints (holes in white)
            for rings in b.rings_m:
                ax.add_patch(Polygon(rings[0], closed=True, color="0.75", zorder=0, lw=0))
                for hole in rings[1:]:
                    ax.add_patch(Polygon(hole, closed=True, color="white", zorder=0, lw=0))
        else:
            for lo, hi in zip(b.min_m, b.max_m):
                ax.add_patch(Rectangle(lo[:2], *(hi[:2] - lo[:2]), color="0.75", zorder=0, lw=0))
        xy = np.asarray(world.route_xy_m)
        ax.plot(xy[:, 0], xy[:, 1], "k:", lw=0.8, label="street route")
        for i in range(pos.shape[1]):
            ax.plot(pos[:, i, 0], pos[:, i, 1], lw=1.0)
        ax.plot(*pos[0, :, :2].T, "g^", ms=4, label="start")
        ax.plot(*world.goal_enu_m[:2], "r*", ms=10, label="goal")
        lo_xy = np.minimum(pos[:, :, :2].min(axis=(0, 1)), world.goal_enu_m[:2]) - 40
        hi_xy = np.maximum(pos[:, :, :2].max(axis=(0, 1)), world.goal_enu_m[:2]) + 40
        ax.set_xlim(lo_xy[0], hi_xy[0])
        ax.set_ylim(lo_xy[1], hi_xy[1])
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(short_label(name), fontsize=9)
        ax.set_xlabel("East [m]", fontsize=8)
        if j == 0:
            ax.set_ylabel("North [m]", fontsize=8)
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.3), ncol=3)
        side = axes[1, j]
        t = np.arange(pos.shape[0])
        s = distance_along_route(pos[:, :, :2], route_xy)
        for i in range(pos.shape[1]):
            side.plot(s[:, i], pos[:, i, 2], lw=1.0)
        side.set_ylim(0, 32)
        side.set_xlabel("distance along the route [m]", fontsize=8)
        if j == 0:
            side.set_ylabel("altitude [m]", fontsize=8)
        side.set_title(f"side view ({len(t) - 1} steps)", fontsize=8)
    fig.suptitle(f"Episode seed {seed}: from above and from the side (one line per UAV)")
    fig.tight_layout()
    env.close()
    return save_figure(fig, path, dpi=110)


def _fmt_iv(d: Mapping[str, float], nd: int = 2) -> str:
    return f"{d['value']:.{nd}f} [{d['low']:.{nd}f}, {d['high']:.{nd}f}]"


# ---- command ------------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the script (:func:`main`)."""
    parser.add_argument(
        "--runs",
        nargs="+",
        default=[],
        metavar="NAME=DIR[,DIR...]",
        help="learned methods: a name and its training run folders (one per seed), e.g. "
        "mappo=runs/mappo_s0,runs/mappo_s1. A run folder's model file (final_model.pt, "
        "final_model.zip) is a pickle: loading it runs code from it, so give only runs you "
        "trust (default: none)",
    )
    parser.add_argument(
        "--heuristics",
        nargs="+",
        default=["column", "sky_column", "stretched_column", "wide_column"],
        help="heuristic policies (default: %(default)s)",
    )
    parser.add_argument(
        "--episodes", type=int, default=100, help="held-out episodes (default: %(default)s)"
    )
    parser.add_argument(
        "--first-seed",
        type=int,
        default=EVAL_SEED_START,
        help="reset seed of the first held-out episode, >= %(default)s (training uses the "
        "seeds below); a later start gives a fresh set of episodes, e.g. to confirm on "
        "episodes no design choice has seen what was found on the first ones "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--planner-episodes",
        type=int,
        default=None,
        help="episodes of the privileged planner, the first ones of the set, at most "
        "--episodes; 0 skips it (default: 20, or --episodes if fewer)",
    )
    parser.add_argument(
        "--planner",
        default="planner",
        help="the privileged planner and its options, e.g. "
        "planner@horizon=10,n_samples=16 (default: %(default)s: CEM over offsets to the "
        "'wide_column' column, studies.planner_headroom.planner)",
    )
    parser.add_argument(
        "--env-set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="environment settings of the study (default: the first run's)",
    )
    parser.add_argument(
        "--score",
        choices=sorted(SCORES),
        default="coop",
        help="the per-episode error the study ranks by: coop = "
        + SCORES["coop"]
        + "; nav = "
        + SCORES["nav"]
        + " (use nav where policies differ in how often they have a cooperative fix, e.g. "
        "with fault exclusion); the other is reported beside it (default: %(default)s)",
    )
    parser.add_argument(
        "--out",
        default="runs/study",
        help="output folder, of this study alone: a folder of another command, a study of "
        "other settings or a finished study is refused (default: %(default)s)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of the command (or the earlier study) that --out holds; a "
        "training run is never replaced (default: refuse)",
    )
    parser.add_argument(
        "--reps", type=int, default=2000, help="bootstrap replicates (default: %(default)s)"
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="worker processes flying policies (default: %(default)s)",
    )


PLANNER_EPISODES = 20
"""Episodes of the privileged planner without ``--planner-episodes`` (fewer with fewer
``--episodes``)."""


def parse_named_lists(items: Sequence[str], option: str, form: str) -> dict[str, list[str]]:
    """``NAME=A[,B...]`` items (``--runs``, ``paired_variants.py --groups``) as a mapping.

    A policy's own options stay with it: in ``b=ceiling@gain_per_s=0.3,cruise_speed_mps=10``
    the piece after the comma is a ``key=value`` option of the ``@`` policy before it, not a
    second entry, so that group is one policy.

    Raises ``ValueError`` naming ``option`` and the expected ``form`` for a malformed item
    (an empty list such as ``a=,`` included), and for a name given twice (which would
    otherwise drop the first silently).
    """
    out: dict[str, list[str]] = {}
    for item in items:
        name, eq, values = item.partition("=")
        if not eq or not name or not values:
            raise ValueError(f"{option} entries are {form}, got {item!r}")
        if name in out:
            raise ValueError(f"{option}: the name {name!r} is given twice")
        entries: list[str] = []
        for v in values.split(","):
            if entries and "@" in entries[-1] and re.match(r"[A-Za-z_]\w*=", v):
                entries[-1] += "," + v  # an option of the policy before it
            elif v:
                entries.append(v)
        if not entries:
            raise ValueError(f"{option} {item} names nothing after '='; entries are {form}")
        out[name] = entries
    return out


def parse_runs(items: Sequence[str]) -> dict[str, list[Path]]:
    """``--runs NAME=DIR[,DIR...]`` as a mapping of names to run folders; each folder must
    hold a trained model (one of :data:`_MODEL_FILES`), else ``ValueError`` names it."""
    out = {
        name: [Path(d) for d in dirs]
        for name, dirs in parse_named_lists(items, "--runs", "NAME=DIR[,DIR...]").items()
    }
    for paths in out.values():
        for p in paths:
            if not any((p / f).is_file() for f in _MODEL_FILES):
                raise ValueError(f"run folder {p} has none of {', '.join(_MODEL_FILES)}")
            run_record(p)  # a damaged run.json fails here, before anything is flown
    return out


_MODEL_FILES = ("final_model.pt", "final_model.zip", "route_model.json", "split_model.json")
"""What makes a folder a training run: TorchRL, SB3, ``coopnav train-routes``, or a split
chooser fitted by ``studies/split_choice/split_choice.py --fit-model``."""


def run_policy_name(run: Path) -> str:
    """The :func:`coopnav_env.agents.make_policy` name of a run folder's model (TorchRL, route,
    split or SB3)."""
    if (run / "final_model.pt").is_file():
        return f"torchrl:{run}"
    if (run / "route_model.json").is_file():
        return f"learned_route@model='{run}'"
    if (run / "split_model.json").is_file():
        return f"learned_split@model='{run}'"
    return f"ppo:{run / 'final_model.zip'}"


def _read_record(path: Path) -> dict[str, Any]:
    """The JSON object in ``path`` (a run's ``run.json``, a model file); ``ValueError`` naming
    the file when it is not valid JSON or not an object."""
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise ValueError(f"{path} must hold a JSON object, got a {type(data).__name__}")
    return data


def _env_record(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be a mapping of environment settings, got {value!r}")
    return dict(value)


def run_record(run: Path) -> dict[str, Any] | None:
    """A run folder's ``run.json`` (None without one); ``ValueError`` naming it when it is
    not a JSON object."""
    path = run / "run.json"
    return _read_record(path) if path.is_file() else None


def run_env(run: Path) -> dict[str, Any]:
    """The environment settings a run was trained in (its ``run.json``, a split model's
    own record of them, else its ``config.yaml``)."""
    d = run_record(run)
    if d is not None:
        if "env" in d:
            return _env_record(d["env"], f"{run / 'run.json'}: env")
        settings = d.get("settings")
        if isinstance(settings, dict) and "env" in settings:  # a train-routes run
            return _env_record(settings["env"], f"{run / 'run.json'}: settings.env")
    if (run / "split_model.json").is_file():  # split_choice.py --fit-model records them
        info = _read_record(run / "split_model.json").get("info", {})
        if isinstance(info, dict) and "env" in info:
            return _env_record(info["env"], f"{run / 'split_model.json'}: info.env")
    import yaml

    path = run / "config.yaml"
    try:
        cfg = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ValueError(
            f"run folder {run} records no environment (no env in run.json, no config.yaml)"
        ) from None
    if not isinstance(cfg, dict):
        raise ValueError(f"{path} must be a YAML mapping, got {type(cfg).__name__}")
    return _env_record(cfg.get("env") or {}, f"{path}: env")


def run(args: argparse.Namespace) -> int:
    """Fly, summarise, write ``report.md``, ``report.json`` and figures."""
    t0 = time.perf_counter()
    if args.planner_episodes is None:
        args.planner_episodes = min(PLANNER_EPISODES, args.episodes)
    for option, value, least in (
        ("--reps", args.reps, 1),
        ("--jobs", args.jobs, 1),
        ("--planner-episodes", args.planner_episodes, 0),
    ):
        if value < least:
            raise ValueError(f"{option} must be >= {least}, got {value}")
    if args.planner_episodes > args.episodes:
        raise ValueError(
            f"--planner-episodes {args.planner_episodes} must be <= --episodes "
            f"{args.episodes}: the planner flies the first episodes of the set"
        )
    groups = parse_runs(args.runs)
    env_kwargs: dict[str, Any] = {}
    first = next(iter(groups.values()), [])
    if first:
        env_kwargs = run_env(first[0])
    env_kwargs = apply_overrides(env_kwargs, args.env_set)
    seeds = heldout_seeds(args.episodes, args.first_seed)
    units: list[tuple[str, str, list[int]]] = [(h, h, seeds) for h in args.heuristics]
    for name, dirs in groups.items():
        units += [(name, run_policy_name(d), seeds) for d in dirs]
    if args.planner_episodes > 0:
        if args.planner.split("@")[0] != "planner":
            raise ValueError(f"--planner must name the planner (planner@...), got {args.planner!r}")
        units.append(("planner (privileged)", args.planner, seeds[: args.planner_episodes]))
    settings = {k: getattr(args, k) for k in _SETTINGS}
    settings["env"] = env_kwargs
    out = Path(args.out)
    # --out is claimed (locked, checked, recorded) before any episode is flown
    with claim_output_folder(
        out, STUDY_COMMAND, settings, outputs=STUDY_OUTPUTS, overwrite=args.overwrite
    ) as claim:
        claim.finish(_fly_and_report(args, groups, env_kwargs, seeds, units, out, t0))
    print(f"wrote {out / 'report.md'}", file=sys.stderr)
    return 0


_SETTINGS = (
    "runs",
    "heuristics",
    "episodes",
    "first_seed",
    "planner_episodes",
    "planner",
    "env_set",
    "score",
    "reps",
)
"""The options a study's result depends on (recorded in ``OUT/command.json``)."""

STUDY_OUTPUTS = (
    "report.json",
    "report.md",
    "learning_curves.png",
    "errors.png",
    "trajectories.png",
)
"""The files the study writes into its ``--out``."""

STUDY_COMMAND = "learning_study.py"
"""The command a study's ``--out`` is claimed for
(:func:`coopnav_env.training.files.claim_output_folder`)."""


def _fly_and_report(
    args: argparse.Namespace,
    groups: Mapping[str, Sequence[Path]],
    env_kwargs: dict[str, Any],
    seeds: list[int],
    units: list[tuple[str, str, list[int]]],
    out: Path,
    t0: float,
) -> list[Path]:
    """Fly every unit, summarise, write the report and figures into ``out``; the files."""
    flown = _fly_all(units, env_kwargs, args.jobs)
    results: dict[str, list[list[EpisodeResult]]] = {}
    for (name, _policy, _seeds), episodes in zip(units, flown):
        if name != "planner (privileged)":
            results.setdefault(name, []).append(episodes)
    # every method against every heuristic and every other learned method
    summary = summarise(results, [*args.heuristics, *groups], args.reps, args.score)
    headroom: dict[str, Any] = {}
    if args.planner_episodes > 0:
        plan = flown[-1]
        sub = seeds[: args.planner_episodes]
        sub_results = {n: [run[: len(sub)] for run in r] for n, r in results.items()}
        sub_results["planner (privileged)"] = [plan]
        headroom = summarise(
            sub_results, [*args.heuristics, "planner (privileged)"], args.reps, args.score
        )
        headroom["episodes"] = len(sub)
        headroom["planner_s"] = _timings.get(args.planner, math.nan)
        headroom["planner"] = args.planner
    figs = {}
    ref = {h: summary["methods"][h]["error_mean"]["value"] for h in args.heuristics}
    f = plot_learning_curves(groups, out / "learning_curves.png", ref)
    if f is not None:
        figs["learning_curves"] = f.name
    figs["errors"] = plot_errors(summary, out / "errors.png", SCORE_AXIS[args.score]).name
    # the plain column, the best heuristic (lowest mean score) and the first two learned methods
    best = min(
        (h for h in args.heuristics if h not in ("column", "formation")),
        key=lambda h: summary["methods"][h]["error_mean"]["value"],
        default=None,
    )
    show = [h for h in ("column", "formation", best) if h in results] + list(groups)[:2]
    flights = {
        n: results[n][0][0].pos_enu_m for n in show if results[n][0][0].pos_enu_m is not None
    }
    if flights:
        figs["trajectories"] = plot_trajectories(
            env_kwargs, seeds[0], flights, out / "trajectories.png"
        ).name
    runs_info = {
        name: [run_record(d) or {"dir": str(d)} for d in dirs] for name, dirs in groups.items()
    }
    data = {
        "env": env_kwargs,
        "episodes": len(seeds),
        "seeds": [seeds[0], seeds[-1]],
        "summary": summary,
        "headroom": headroom,
        "runs": runs_info,
        "figures": figs,
        "command": f"python {Path(sys.argv[0]).name} " + " ".join(sys.argv[1:]),
        "wall_s": time.perf_counter() - t0,
    }
    atomic_write_text(out / "report.json", json.dumps(jsonable(data), indent=1, sort_keys=True))
    atomic_write_text(out / "report.md", report_markdown(data))
    return [out / "report.json", out / "report.md", *(out / f for f in figs.values())]


_timings: dict[str, float] = {}


def _fly_unit(unit: tuple[str, str, list[int]], env_kwargs: Mapping[str, Any]) -> tuple:
    _name, policy, seeds = unit
    t0 = time.perf_counter()
    import torch

    torch.set_num_threads(1)
    eps = fly_episodes(policy, env_kwargs, seeds, keep_positions=True)
    return eps, time.perf_counter() - t0


def _fly_all(
    units: Sequence[tuple[str, str, list[int]]], env_kwargs: Mapping[str, Any], jobs: int
) -> list[list[EpisodeResult]]:
    """Fly every (name, policy, seeds) unit, in ``jobs`` worker processes (1: in this one)."""
    out: list[Any] = [None] * len(units)
    if jobs <= 1:
        for i, u in enumerate(units):
            print(f"flying {u[1]} ({len(u[2])} episodes)", file=sys.stderr, flush=True)
            out[i], dt = _fly_unit(u, env_kwargs)
            _timings[u[1]] = dt
        return out
    from concurrent.futures import ProcessPoolExecutor

    # the slowest (the planner, last) first, so that it overlaps the rest
    order = sorted(range(len(units)), key=lambda i: not units[i][1].startswith("planner"))
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {i: pool.submit(_fly_unit, units[i], dict(env_kwargs)) for i in order}
        for i in order:
            out[i], dt = futures[i].result()
            _timings[units[i][1]] = dt
            print(f"flown {units[i][1]} ({dt:.0f} s)", file=sys.stderr, flush=True)
    return out


def report_markdown(data: Mapping[str, Any]) -> str:
    """The study's report as Markdown (tables from ``report.json``'s content)."""
    s = data["summary"]
    score = s.get("score", "coop")
    other = s.get("other_score", "nav")
    lines = [
        "# Learning study: learned swarms against heuristics and a privileged planner",
        "",
        f"Environment settings `{json.dumps(data['env'], sort_keys=True)}`; "
        f"{data['episodes']} held-out episodes (reset seeds {data['seeds'][0]}.."
        f"{data['seeds'][1]}). Regenerate with `{data['command']}`.",
        "",
        f"Per episode, the score (`--score {score}`) is {SCORES[score]}; the "
        f"`{other}` score ({SCORES[other]}) is reported beside it. A learned method has one "
        "run per training seed; intervals are 95 % "
        "stratified-bootstrap intervals (training seeds within episodes, and episodes). "
        "Paired differences use the same episodes for both policies.",
        "",
        f"| method | runs | mean error [m] | IQM error [m] | goal rate | collisions | "
        f"per-seed mean error [m] | mean `{other}` error [m] |",
        "|---|---:|---|---|---|---:|---|---|",
    ]
    for name, m in s["methods"].items():
        oth = m.get("other_error_mean")
        lines.append(
            f"| {name} | {m['runs']} | {_fmt_iv(m['error_mean'])} | {_fmt_iv(m['error_iqm'])} | "
            f"{_fmt_iv(m['goal_rate'])} | {m['collision_rate']:.3f} | "
            + ", ".join(f"{v:.2f}" for v in m["per_run_error_mean"])
            + f" | {_fmt_iv(oth) if oth else 'n/a'} |"
        )
    lines += [
        "",
        "## Paired differences (row minus the method in `vs`, same episodes)",
        "",
        "| method | vs | error difference [m] | CI excludes 0 | episodes lower | "
        f"goal-rate difference | `{other}` error difference [m] |",
        "|---|---|---|---|---:|---|---|",
    ]
    for name, d in s["paired"].items():
        for h, p in d.items():
            od = p.get("other_error_diff_m")
            lines.append(
                f"| {name} | {h} | {_fmt_iv(p['error_diff_m'])} | "
                f"{'yes' if p['excludes_zero'] else 'no'} | {p['share_episodes_lower']:.2f} | "
                f"{_fmt_iv(p['goal_rate_diff'])} | {_fmt_iv(od) if od else 'n/a'} |"
            )
    keys = sorted({k for m in s["methods"].values() for k in m["descriptors"]})
    lines += [
        "",
        "## What each policy does (behaviour descriptors, means over episodes and seeds)",
        "",
        "| method | " + " | ".join(keys) + " |",
        "|---|" + "---:|" * len(keys),
    ]
    for name, m in s["methods"].items():
        lines.append(
            f"| {name} | "
            + " | ".join(f"{m['descriptors'].get(k, math.nan):.2f}" for k in keys)
            + " |"
        )
    lines += [
        "",
        "`spacing_m`: distance to the nearest other UAV; `altitude_m`; `cross_extent_m`: the "
        "swarm's extent across its direction of travel (smaller of East/North extents); "
        "`near_open_share`: share of UAV-steps within 10 m of an intersection or an open "
        "square; `swarm_sats`: distinct satellites received by the swarm; `time_to_goal_s`: "
        "over episodes that reached the goal; `fix_share`: share of UAV-steps with a "
        "cooperative fix.",
    ]
    h = data.get("headroom") or {}
    if h:
        lines += [
            "",
            f"## Headroom ({h['episodes']} episodes, the first of the set; "
            f"`{h.get('planner', 'planner')}` took {h['planner_s']:.0f} s)",
            "",
            "| method | mean error [m] | goal rate |",
            "|---|---|---|",
        ]
        for name, m in h["methods"].items():
            lines.append(f"| {name} | {_fmt_iv(m['error_mean'])} | {_fmt_iv(m['goal_rate'])} |")
        plan = h.get("paired", {}).get("planner (privileged)", {})
        if plan:
            lines += [
                "",
                "The planner against each heuristic on these episodes (paired, planner minus "
                "heuristic): "
                + "; ".join(f"{k}: {_fmt_iv(v['error_diff_m'])} m" for k, v in plan.items())
                + ".",
            ]
    figs = data.get("figures", {})
    for key, title in (
        ("errors", "Error per method"),
        ("learning_curves", "Learning curves"),
        ("trajectories", "Trajectories from above and from the side"),
    ):
        if key in figs:
            lines += ["", f"![{title}]({figs[key]})"]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the arguments (:func:`add_arguments`) and :func:`run`; returns the exit status
    (2, with a one-line message, for a bad setting or output folder)."""
    parser = argparse.ArgumentParser(
        prog="python studies/learning_in_default_setting/learning_study.py",
        description=(__doc__ or "").split("\n")[0],
    )
    add_arguments(parser)
    args = parser.parse_args(argv)
    from coopnav_env.training.cli import usage_errors

    try:
        return int(run(args) or 0)
    except usage_errors() as exc:  # a bad setting or folder: one line, exit status 2
        print(f"learning_study.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
