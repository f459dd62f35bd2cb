"""Policy evaluation: navigation error, goal rate and collisions per policy.

Each policy flies the same held-out episodes (reset seeds ``EVAL_SEED_START + i``, never used
in training: ``coopnav train`` keeps its reset seeds below
:data:`coopnav_env.training.envs.EVAL_SEED_START`) and is scored on every UAV at every step:

* cooperative and standalone 3-D position error (true minus estimated): mean, median, 95th
  percentile over the agent-steps that have a fix, and P(error < 3 m) over all agent-steps
  (a step without a fix counts as a failure), the statistic of the paper's Figure 8; the
  standard error of the cooperative mean treats episodes as independent clusters (steps of one
  episode are correlated), so two policies' means differ clearly when they differ by several
  of their combined SEs;
* the goal rate (episodes in which the swarm reached the goal: every UAV in the goal area at
  once, which ends the episode), the UAV goal rate (UAVs that entered the goal area at some
  step), collisions (episodes ended by a crash), satellites received per UAV and by the UAV
  with its neighbours, the error of the estimate each UAV actually used (cooperative, else
  standalone, else dead reckoning), episode return and length;
* what the swarm flew like, over the middle 60 % of an episode's steps (:data:`CRUISE`,
  leaving out the start lattice and the closing at the goal): the cruise spacing (the mean
  distance of a UAV to its nearest neighbour), altitude, spread across the street route and
  horizontal speed (:mod:`coopnav_env.training.behaviour`).

Several policies can be pooled as one *method* (one policy per training seed): a method's row
summarises all their episodes. Given a baseline and a reference (``gap``), the report also
gives every policy's and method's mean return (in ``urban_canyon_v1`` the score) with its 95 %
bootstrap interval, and the share of the reference's margin over the baseline that it closes
(:func:`coopnav_env.training.stats.gap_closed`), a method's training seeds averaged per
episode.

Outputs in ``--out DIR``: ``report.json``, ``report.csv``, ``report.md`` (the table printed on
the terminal, under a header naming the environment settings and where they came from),
``errors.npz`` (every error sample), ``error_cdf.png`` (empirical CDF of the error per policy)
and ``trajectories_<policy>.png`` (top view and altitude along the route of the first
episode), drawn by :mod:`coopnav_env.training.eval_plots`. Every file is written atomically
(:mod:`coopnav_env.training.files`): a failed write leaves the earlier version. Results are
deterministic for fixed seeds: the env and every stochastic policy are reseeded with the
episode seed.

The command line ``coopnav evaluate`` (flags, and flying a trained policy in the environment
its run's ``config.yaml`` records) is :mod:`coopnav_env.training.evaluate_cli`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.envs.urban_canyon import fix_error_m
from coopnav_env.training.behaviour import CRUISE, cruise_behaviour, cruise_spacing_m
from coopnav_env.training.envs import DEFAULT_ENV_ID, EVAL_SEED_START, make_env_fn
from coopnav_env.training.files import (
    atomic_path,
    atomic_write_text,
    ensure_folder,
    jsonable,
    write_json,
)
from coopnav_env.training.stats import Interval, bootstrap_mean_interval, gap_closed

__all__ = [
    "CRUISE",
    "DEFAULT_EPISODES",
    "EVAL_SEED_START",
    "EpisodeRecord",
    "GapRow",
    "PolicyStats",
    "Report",
    "check_methods_and_gap",
    "clustered_se",
    "cruise_spacing_m",
    "evaluate",
    "run_episode",
    "write_report",
]

DEFAULT_EPISODES: int = 20
"""Episodes per policy when no seeds are given."""

ERROR_THRESHOLD_M: float = 3.0
"""Threshold of the availability statistic P(3-D error < 3 m) (the paper's Figure 8)."""

BOOTSTRAP_REPS: int = 2000
"""Bootstrap replicates of the intervals of the gap table."""


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------


@dataclass
class EpisodeRecord:
    """What one policy did in one episode (arrays over steps ``t`` and agents ``i``).

    Attributes
    ----------
    seed : int
    coop_error_m, standalone_error_m : ndarray, shape (T, N)
        3-D errors of the cooperative and standalone fixes [m]; NaN where there was none.
    n_sats, n_sats_swarm : ndarray, shape (T, N)
    nav_error_m : ndarray, shape (T, N)
        3-D error of the estimate each UAV used [m]; NaN where the env does not report it.
    pos_enu_m : ndarray, shape (T + 1, N, 3) or None
        True positions from the reset on (for the trajectory plot); None if unknown.
    goal_reached : ndarray of bool, shape (N,)
        Whether each UAV was in the goal area at some step.
    success : bool
        Whether the episode ended with every UAV in the goal area (and no collision).
    collided : bool
        Whether the episode ended in a collision.
    episode_return : float
        Sum of the rewards of all UAVs, divided by N: in ``urban_canyon_v1`` the episode's
        score (its page defines it).
    length : int
        Steps.
    h_error_m, hpl_m : ndarray, shape (T, N), or None
        With integrity monitoring on (the env's ``integrity`` setting): the horizontal error of
        the estimate used and its horizontal protection level (inf: none); None otherwise.
    route_xy_m : ndarray, shape (K, 2), or None
        The episode's planned street route (the env's ``world.route_xy_m`` after the reset);
        None where the env has none.
    dt_s : float
        The env's step length [s]; NaN where it does not say.
    """

    seed: int
    coop_error_m: np.ndarray
    standalone_error_m: np.ndarray
    n_sats: np.ndarray
    n_sats_swarm: np.ndarray
    nav_error_m: np.ndarray
    pos_enu_m: np.ndarray | None
    goal_reached: np.ndarray
    success: bool
    collided: bool
    episode_return: float
    length: int
    h_error_m: np.ndarray | None = None
    hpl_m: np.ndarray | None = None
    route_xy_m: np.ndarray | None = None
    dt_s: float = math.nan

    def behaviour(self) -> dict[str, float]:
        """The episode's cruise descriptors
        (:func:`coopnav_env.training.behaviour.cruise_behaviour`)."""
        return cruise_behaviour(self.pos_enu_m, self.route_xy_m, self.dt_s)


@dataclass
class PolicyStats:
    """Summary of one policy over all evaluation episodes (see the module docstring)."""

    policy: str
    episodes: int
    agent_steps: int
    coop_error_mean_m: float
    coop_error_mean_se_m: float
    coop_error_median_m: float
    coop_error_p95_m: float
    p_coop_error_lt_3m: float
    coop_fix_rate: float
    standalone_error_mean_m: float
    standalone_error_median_m: float
    standalone_error_p95_m: float
    p_standalone_error_lt_3m: float
    standalone_fix_rate: float
    nav_error_mean_m: float
    nav_error_median_m: float
    goal_rate: float
    uav_goal_rate: float
    collisions: int
    collision_rate: float
    n_sats_mean: float
    n_sats_swarm_mean: float
    return_mean: float
    length_mean: float
    wall_s: float
    availability: float = math.nan
    misleading_rate: float = math.nan
    alert_limit_m: float = math.nan
    cruise_spacing_m: float = math.nan
    cruise_altitude_m: float = math.nan
    cruise_spread_m: float = math.nan
    cruise_speed_mps: float = math.nan

    @classmethod
    def from_episodes(
        cls,
        policy: str,
        eps: Sequence[EpisodeRecord],
        wall_s: float,
        alert_limit_m: float = 30.0,
    ) -> PolicyStats:
        """Aggregate episode records.

        ``cruise_spacing_m``, ``cruise_altitude_m``, ``cruise_spread_m`` (across the street
        route) and ``cruise_speed_mps`` are the means over episodes of
        :meth:`EpisodeRecord.behaviour` (NaN where an episode has no positions, the spread
        where it has no route and the speed where the step length is unknown). With
        integrity monitoring (records with ``hpl_m``): ``availability`` is the share of
        UAV-steps whose horizontal protection level is within ``alert_limit_m``, and
        ``misleading_rate`` the share whose true horizontal error exceeds the protection
        level (:func:`coopnav_env.nav.integrity_rates`); NaN without integrity.
        """
        coop = np.concatenate([e.coop_error_m.ravel() for e in eps])
        alone = np.concatenate([e.standalone_error_m.ravel() for e in eps])
        sats = np.concatenate([e.n_sats.ravel() for e in eps])
        sats_sw = np.concatenate([e.n_sats_swarm.ravel() for e in eps])
        goals = np.concatenate([e.goal_reached.ravel() for e in eps])
        used = _error_stats(np.concatenate([e.nav_error_m.ravel() for e in eps]))
        collisions = int(sum(e.collided for e in eps))
        c, s = _error_stats(coop), _error_stats(alone)
        moves = [e.behaviour() for e in eps]
        return cls(
            policy=policy,
            episodes=len(eps),
            agent_steps=int(coop.size),
            coop_error_mean_m=c["mean"],
            coop_error_mean_se_m=clustered_se([e.coop_error_m for e in eps]),
            coop_error_median_m=c["median"],
            coop_error_p95_m=c["p95"],
            p_coop_error_lt_3m=c["p_lt"],
            coop_fix_rate=c["fix_rate"],
            standalone_error_mean_m=s["mean"],
            standalone_error_median_m=s["median"],
            standalone_error_p95_m=s["p95"],
            p_standalone_error_lt_3m=s["p_lt"],
            standalone_fix_rate=s["fix_rate"],
            nav_error_mean_m=used["mean"],
            nav_error_median_m=used["median"],
            goal_rate=float(np.mean([e.success for e in eps])),
            uav_goal_rate=float(goals.mean()) if goals.size else math.nan,
            collisions=collisions,
            collision_rate=collisions / len(eps),
            n_sats_mean=_nanmean(sats),
            n_sats_swarm_mean=_nanmean(sats_sw),
            return_mean=float(np.mean([e.episode_return for e in eps])),
            length_mean=float(np.mean([e.length for e in eps])),
            wall_s=round(float(wall_s), 3),
            **_integrity_stats(eps, alert_limit_m),
            cruise_spacing_m=float(np.mean([m["spacing_m"] for m in moves])),
            cruise_altitude_m=float(np.mean([m["altitude_m"] for m in moves])),
            cruise_spread_m=float(np.mean([m["lateral_spread_m"] for m in moves])),
            cruise_speed_mps=float(np.mean([m["speed_mps"] for m in moves])),
        )


def _alert_limit_m(env: Any) -> float:
    """The environment's horizontal alert limit (``alert_limit_m``; 30 m if it has none)."""
    cfg = getattr(getattr(env, "unwrapped", env), "config", None)
    return float(getattr(cfg, "alert_limit_m", 30.0))


def _integrity_stats(eps: Sequence[EpisodeRecord], alert_limit_m: float) -> dict[str, float]:
    """Availability and MI rate of episodes with integrity monitoring (else nothing)."""
    if not eps or any(e.hpl_m is None or e.h_error_m is None for e in eps):
        return {}
    from coopnav_env.nav import integrity_rates

    r = integrity_rates(
        np.concatenate([e.h_error_m.ravel() for e in eps]),
        np.concatenate([e.hpl_m.ravel() for e in eps]),
        alert_limit_m,
    )
    return {
        "availability": r.availability,
        "misleading_rate": r.misleading_rate,
        "alert_limit_m": float(alert_limit_m),
    }


def clustered_se(per_episode: Sequence[np.ndarray]) -> float:
    """Standard error of the pooled mean of the finite samples, episodes as clusters.

    The errors of one episode are strongly correlated (same city, same sky, consecutive
    epochs), the episodes independent, so the usual ``std / sqrt(n_samples)`` would be far too
    small. For the ratio estimator ``mean = sum_e S_e / sum_e n_e`` (``S_e`` the sum and
    ``n_e`` the count of episode ``e``'s finite errors) the cluster-robust standard error is
    ``sqrt(E / (E - 1) * sum_e (S_e - n_e mean)^2) / sum_e n_e`` over ``E`` episodes.
    """
    sums = np.array([float(np.sum(x[np.isfinite(x)])) for x in per_episode])
    counts = np.array([float(np.isfinite(x).sum()) for x in per_episode])
    used = counts > 0
    n_eps, total = int(used.sum()), counts.sum()
    if n_eps < 2:
        return math.nan
    mean = sums.sum() / total
    resid = sums[used] - counts[used] * mean
    return float(np.sqrt(n_eps / (n_eps - 1) * np.sum(resid**2)) / total)


def _finite_mean(x: np.ndarray) -> float:
    fin = np.asarray(x)[np.isfinite(x)]
    return float(fin.mean()) if fin.size else math.nan


def _episode_summary(e: EpisodeRecord) -> dict[str, Any]:
    """Per-episode figures written to ``report.json`` (for paired comparisons)."""
    b = e.behaviour()
    return {
        "seed": e.seed,
        "coop_error_mean_m": _finite_mean(e.coop_error_m),
        "standalone_error_mean_m": _finite_mean(e.standalone_error_m),
        "success": bool(e.success),
        "collided": bool(e.collided),
        "length": int(e.length),
        "return": float(e.episode_return),
        "cruise_spacing_m": b["spacing_m"],
        "cruise_altitude_m": b["altitude_m"],
        "cruise_spread_m": b["lateral_spread_m"],
        "cruise_speed_mps": b["speed_mps"],
    }


def _nanmean(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else math.nan


def _error_stats(err: np.ndarray) -> dict[str, float]:
    """mean/median/p95 over finite errors; P(< 3 m) and fix rate over all samples."""
    fin = err[np.isfinite(err)]
    n = max(err.size, 1)
    return {
        "mean": float(fin.mean()) if fin.size else math.nan,
        "median": float(np.median(fin)) if fin.size else math.nan,
        "p95": float(np.percentile(fin, 95)) if fin.size else math.nan,
        "p_lt": float(np.sum(fin < ERROR_THRESHOLD_M) / n),
        "fix_rate": float(fin.size / n),
    }


#: (column title, PolicyStats field, format) of the Markdown/terminal table
_TABLE: tuple[tuple[str, str, str], ...] = (
    ("policy", "policy", "{}"),
    ("coop mean [m]", "coop_error_mean_m", "{:.2f}"),
    ("± SE [m]", "coop_error_mean_se_m", "{:.2f}"),
    ("coop median [m]", "coop_error_median_m", "{:.2f}"),
    ("coop p95 [m]", "coop_error_p95_m", "{:.2f}"),
    ("P(coop < 3 m)", "p_coop_error_lt_3m", "{:.3f}"),
    ("alone mean [m]", "standalone_error_mean_m", "{:.2f}"),
    ("alone median [m]", "standalone_error_median_m", "{:.2f}"),
    ("alone p95 [m]", "standalone_error_p95_m", "{:.2f}"),
    ("P(alone < 3 m)", "p_standalone_error_lt_3m", "{:.3f}"),
    ("goal rate", "goal_rate", "{:.3f}"),
    ("collisions", "collisions", "{:d}"),
    ("sats/UAV", "n_sats_mean", "{:.1f}"),
    ("return", "return_mean", "{:.3f}"),  # urban_canyon_v1: the task's score
    ("steps", "length_mean", "{:.1f}"),
    ("cruise spacing [m]", "cruise_spacing_m", "{:.1f}"),
    ("altitude [m]", "cruise_altitude_m", "{:.1f}"),
    ("spread across route [m]", "cruise_spread_m", "{:.1f}"),
    ("speed [m/s]", "cruise_speed_mps", "{:.1f}"),
    ("availability", "availability", "{:.3f}"),
    ("MI rate", "misleading_rate", "{:.4f}"),
)
_INTEGRITY_COLUMNS = ("availability", "misleading_rate")
"""Shown only when some policy was evaluated with integrity monitoring on."""


@dataclass
class GapRow:
    """A policy's (or a method's) share of the gap between a baseline and a reference.

    Attributes
    ----------
    name : str
        The policy, or the method (several policies pooled).
    policies : list of str
        The policies whose episodes it averages per episode (the policy itself for one).
    return_mean : Interval
        Mean episode return (in ``urban_canyon_v1``, the score) with its 95 % bootstrap
        interval (:func:`coopnav_env.training.stats.bootstrap_mean_interval`).
    gap_closed : Interval
        Share of the baseline-to-reference gap closed, with its paired 95 % bootstrap
        interval (:func:`coopnav_env.training.stats.gap_closed`).
    """

    name: str
    policies: list[str]
    return_mean: Interval
    gap_closed: Interval

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form."""
        return {
            "name": self.name,
            "policies": list(self.policies),
            "return": self.return_mean.as_dict(),
            "gap_closed": self.gap_closed.as_dict(),
        }


@dataclass
class Report:
    """The evaluation of several policies on the same episodes.

    Attributes
    ----------
    stats : list of PolicyStats
        One per policy, in the order given.
    seeds : list of int
    env_kwargs : dict
    env_id : str
    episodes : dict of str to list of EpisodeRecord
        Raw records per policy (JSON gets a per-episode summary; errors go to ``errors.npz``).
    files : dict of str to Path
        What was written (empty when ``out`` was None).
    env_source : str
        Where the environment settings came from (in words; "" when not said).
    methods : dict of str to list of str
        Methods: a name and the policies pooled under it (empty: none).
    method_stats : list of PolicyStats
        One per method, over all episodes of its policies, in the order of :attr:`methods`.
    gap : (str, str) or None
        The baseline and the reference of :attr:`gap_rows` (None: no gap table).
    gap_rows : list of GapRow
        Every policy, then every method.
    own_frame : dict of str to str
        Heuristics flown in their own action frame instead of ``env_kwargs``' (name -> frame).
    """

    stats: list[PolicyStats]
    seeds: list[int]
    env_kwargs: dict[str, Any]
    env_id: str
    episodes: dict[str, list[EpisodeRecord]] = field(default_factory=dict, repr=False)
    files: dict[str, Path] = field(default_factory=dict)
    env_source: str = ""
    methods: dict[str, list[str]] = field(default_factory=dict)
    method_stats: list[PolicyStats] = field(default_factory=list)
    gap: tuple[str, str] | None = None
    gap_rows: list[GapRow] = field(default_factory=list)
    own_frame: dict[str, str] = field(default_factory=dict)

    def header(self) -> str:
        """The environment and episodes the table was measured on (printed above it).

        Names the environment, the settings given (every other setting at the
        environment's default) and where they came from (:attr:`env_source`, e.g. the
        training run's ``config.yaml``), and the held-out reset seeds.
        """
        seeds = self.seeds
        span = f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
        source = f"; {self.env_source}" if self.env_source else ""
        own = ""
        if self.own_frame:
            flown = ", ".join(f"`{n}` with action_frame={f!r}" for n, f in self.own_frame.items())
            own = f" Heuristics in the frame they command: {flown}."
        return (
            f"Environment `{self.env_id}`, settings `{json.dumps(jsonable(self.env_kwargs))}` "
            f"(all others at their defaults{source}); {len(seeds)} held-out episodes (reset "
            f"seeds {span}).{own}"
        )

    def __getitem__(self, policy: str) -> PolicyStats:
        """The stats of a policy or of a method."""
        for s in [*self.stats, *self.method_stats]:
            if s.policy == policy:
                return s
        raise KeyError(policy)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (NaN written as null)."""
        out = {
            "env_id": self.env_id,
            "env_kwargs": jsonable(self.env_kwargs),
            "env_source": self.env_source,
            "seeds": list(self.seeds),
            "error_threshold_m": ERROR_THRESHOLD_M,
            "policies": [jsonable(asdict(s)) for s in self.stats],
            "episodes": {
                name: [jsonable(_episode_summary(e)) for e in eps]
                for name, eps in self.episodes.items()
            },
        }
        if self.own_frame:
            out["own_frame"] = dict(self.own_frame)
        if self.methods:
            out["methods"] = {
                name: {"policies": list(members), "stats": jsonable(asdict(s))}
                for (name, members), s in zip(self.methods.items(), self.method_stats)
            }
        if self.gap is not None:
            out["gap"] = {
                "baseline": self.gap[0],
                "reference": self.gap[1],
                "rows": [jsonable(r.to_dict()) for r in self.gap_rows],
            }
        return out

    def paired_difference(self, policy: str, reference: str) -> tuple[float, float, int]:
        """Mean cooperative error of ``policy`` minus ``reference``, paired by episode seed.

        Both policies flew the same held-out episodes (same city, sky and noise seeds), so the
        per-episode difference of the mean cooperative 3-D error removes most of the
        episode-to-episode spread that the per-policy standard errors carry.

        Returns
        -------
        (mean difference [m], its standard error [m], episodes used)
            Episodes flown by only one of them or in which either had no fix are skipped; SE
            is NaN below 2 pairs.
        """
        ref = {e.seed: e for e in self.episodes[reference]}
        diffs = []
        for a in self.episodes[policy]:
            b = ref.get(a.seed)
            if b is None:
                continue
            ea, eb = _finite_mean(a.coop_error_m), _finite_mean(b.coop_error_m)
            if np.isfinite(ea) and np.isfinite(eb):
                diffs.append(ea - eb)
        d = np.asarray(diffs)
        if d.size == 0:
            return math.nan, math.nan, 0
        se = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else math.nan
        return float(d.mean()), se, int(d.size)

    def return_is_score(self) -> bool:
        """Whether the episode return is the task's score (``urban_canyon_v1`` with its own
        reward); the table then titles that column "score"."""
        scheme = self.env_kwargs.get("reward_scheme", "navigated_distance")
        return self.env_id == "urban_canyon_v1" and scheme == "navigated_distance"

    def to_markdown(self) -> str:
        """The summary table in GitHub Markdown: a row per policy, then one per method (its
        policies' episodes together, named ``NAME (K policies)``); the return column is titled
        "score" where the return is the score (:meth:`return_is_score`)."""
        every = [*self.stats, *self.method_stats]
        integrity = any(math.isfinite(getattr(s, f)) for s in every for f in _INTEGRITY_COLUMNS)
        table = [c for c in _TABLE if integrity or c[1] not in _INTEGRITY_COLUMNS]
        head = [t for t, _, _ in table]
        if self.return_is_score():
            head = ["score" if t == "return" else t for t in head]
        rows = [[_fmt(getattr(s, f), fmt) for _, f, fmt in table] for s in self.stats]
        for (name, members), s in zip(self.methods.items(), self.method_stats):
            row = [_fmt(getattr(s, f), fmt) for _, f, fmt in table[1:]]
            rows.append([f"{name} ({len(members)} policies)", *row])
        lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(lines)

    def gap_markdown(self) -> str:
        """The gap table in GitHub Markdown ("" without a gap): every policy's and method's
        mean return (titled "score" where it is, :meth:`return_is_score`) with its 95 %
        interval and the share of the gap it closes."""
        if self.gap is None:
            return ""
        base, ref = self.gap

        def iv(x: Interval, fmt: str) -> str:
            return f"{x.value:{fmt}} [{x.low:{fmt}}, {x.high:{fmt}}]"

        lines = [
            f"Share of the gap from `{base}` (0) to `{ref}` (1) closed; a method's policies "
            "averaged per episode; 95 % bootstrap intervals over the episodes, paired.",
            "",
            f"| policy | {'score' if self.return_is_score() else 'return'} [95 % CI] "
            "| gap closed [95 % CI] |",
            "|---|---|---|",
        ]
        for r in self.gap_rows:
            name = f"{r.name} ({len(r.policies)} policies)" if r.name in self.methods else r.name
            lines.append(f"| {name} | {iv(r.return_mean, '.3f')} | {iv(r.gap_closed, '.2f')} |")
        return "\n".join(lines)


def _fmt(value: Any, fmt: str) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return "n/a"
    return fmt.format(value)


def _slug(name: str) -> str:
    """A file-name-safe form of a policy name (``ppo:runs/a/final_model.zip`` -> ...)."""
    name = re.sub(r"\.zip$", "", name)
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "policy"


# --------------------------------------------------------------------------------------------
# running episodes
# --------------------------------------------------------------------------------------------


def _make_env(env_id: str, env_kwargs: Mapping[str, Any]) -> Any:
    return make_env_fn(env_id, env_kwargs)()


def _true_positions(env: Any, infos: Mapping[str, Mapping[str, Any]]) -> np.ndarray | None:
    """True ENU positions of all possible agents, shape (N, 3), or None if unavailable."""
    agents = env.possible_agents
    if all("pos_enu_m" in infos.get(a, {}) for a in agents):
        return np.array([np.asarray(infos[a]["pos_enu_m"], float)[:3] for a in agents])
    base = getattr(env, "unwrapped", env)
    for owner in (getattr(base, "world", None), base):
        val = getattr(owner, "pos_enu_m", None)
        if val is not None:
            arr = np.asarray(val, dtype=float)
            if arr.shape == (len(agents), 3):
                return arr.copy()
    return None


def _route_and_step(env: Any) -> tuple[np.ndarray | None, float]:
    """A copy of the env's planned street route, shape (K, 2) (None if it has none), and its
    step length [s] (NaN if it does not say), read after a reset."""
    base = getattr(env, "unwrapped", env)
    route = getattr(getattr(base, "world", None), "route_xy_m", None)
    if route is not None:
        route = np.array(route, dtype=float).reshape(-1, 2)
        route = route if route.shape[0] >= 2 else None
    dt_s = getattr(getattr(base, "config", None), "dt_s", None)
    return route, float(dt_s) if dt_s is not None else math.nan


def _in_goal(info: Mapping[str, Any]) -> bool:
    """Whether a UAV is in the goal area (``in_goal``; ``goal_reached`` for other envs)."""
    return bool(info.get("in_goal", info.get("goal_reached", False)))


def _info_float(info: Mapping[str, Any], key: str) -> float:
    """``info[key]`` as a float (NaN if absent); a missing fix's error is ``inf``."""
    v = info.get(key)
    try:
        return fix_error_m(info, key) if v is not None else math.nan
    except (TypeError, ValueError):
        return math.nan


def run_episode(
    env: Any,
    policy: Any,
    seed: int,
    max_steps: int | None = None,
    options: dict[str, Any] | None = None,
) -> EpisodeRecord:
    """Fly one episode of ``policy`` in ``env`` from ``reset(seed=seed)``.

    Parameters
    ----------
    env : pettingzoo.ParallelEnv
    policy : Policy
    seed : int
        Reset seed of the env and of the policy.
    max_steps : int or None
        Safety limit on the number of steps (the env's own ``max_steps`` truncates first).
    options : dict, optional
        Reset options (e.g. ``{"noise_stream": 1}``: the same episode under another noise
        realisation, see ``urban_canyon_v0``'s ``reset``); default none.

    Returns
    -------
    EpisodeRecord
    """
    agents = list(env.possible_agents)
    n = len(agents)
    obs, infos = env.reset(seed=int(seed), options=options)
    policy.reset(seed=int(seed))
    rows: dict[str, list[np.ndarray]] = {
        k: []
        for k in ("coop_error_m", "standalone_error_m", "n_sats", "n_sats_swarm", "nav_error_m")
    }
    integrity = bool(infos) and "hpl_m" in next(iter(infos.values()))
    h_rows: list[np.ndarray] = []
    pl_rows: list[np.ndarray] = []
    pos0 = _true_positions(env, infos)
    route, dt_s = _route_and_step(env)
    positions = [pos0] if pos0 is not None else None
    goal = np.zeros(n, dtype=bool)
    at_goal = np.zeros(n, dtype=bool)
    collided = False
    total = 0.0
    steps = 0
    limit = max_steps if max_steps is not None else 1_000_000
    while env.agents and steps < limit:
        actions = policy.act({a: obs[a] for a in env.agents})
        obs, rewards, _terms, _truncs, infos = env.step(actions)
        steps += 1
        total += float(sum(rewards.values()))
        for key, lst in rows.items():
            lst.append(np.array([_info_float(infos.get(a, {}), key) for a in agents]))
        if integrity:
            h_rows.append(
                np.array([_info_float(infos.get(a, {}), "nav_h_error_m") for a in agents])
            )
            pl = np.array([_info_float(infos.get(a, {}), "hpl_m") for a in agents])
            pl_rows.append(np.where(pl >= 0.0, pl, np.inf))  # the infos' -1: none
        at_goal = np.array([_in_goal(infos.get(a, {})) for a in agents])
        goal |= at_goal
        collided |= any(bool(infos.get(a, {}).get("collided", False)) for a in agents)
        if positions is not None:
            p = _true_positions(env, infos)
            if p is None:
                positions = None
            else:
                positions.append(p)
    arr = {k: np.array(v, dtype=float).reshape(-1, n) for k, v in rows.items()}
    success = bool(steps > 0 and at_goal.all() and not collided)
    return EpisodeRecord(
        seed=int(seed),
        coop_error_m=arr["coop_error_m"],
        standalone_error_m=arr["standalone_error_m"],
        n_sats=arr["n_sats"],
        n_sats_swarm=arr["n_sats_swarm"],
        nav_error_m=arr["nav_error_m"],
        pos_enu_m=np.array(positions) if positions is not None else None,
        goal_reached=goal,
        success=success,
        collided=collided,
        episode_return=total / n,
        length=steps,
        h_error_m=np.array(h_rows, dtype=float).reshape(-1, n) if integrity else None,
        hpl_m=np.array(pl_rows, dtype=float).reshape(-1, n) if integrity else None,
        route_xy_m=route,
        dt_s=dt_s,
    )


def evaluate(
    policies: Sequence[str],
    seeds: Sequence[int],
    env_kwargs: Mapping[str, Any] | None = None,
    out: str | Path | None = None,
    *,
    env_id: str = DEFAULT_ENV_ID,
    plots: bool = True,
    verbose: bool = False,
    env_source: str = "",
    methods: Mapping[str, Sequence[str]] | None = None,
    gap: Sequence[str] | None = None,
    bootstrap_reps: int = BOOTSTRAP_REPS,
) -> Report:
    """Evaluate named policies on the same held-out episodes.

    Parameters
    ----------
    policies : sequence of str
        Registry names (:data:`coopnav_env.agents.POLICY_NAMES`), e.g. ``["random",
        "column", "sky_column", "ppo:runs/quick/final_model.zip"]``; all are made (and checkpoints
        checked) before any episode runs.
    seeds : sequence of int
        Reset seeds, one episode each (see :func:`heldout_seeds`).
    env_kwargs : mapping or None
        Environment settings (must match those a PPO policy was trained with).
    out : path or None
        Directory for the report files and plots; None writes nothing.
    env_id : str, default "urban_canyon_v1"
        As in :class:`coopnav_env.training.config.TrainConfig`.
    plots : bool, default True
        Write the CDF and trajectory plots (needs matplotlib).
    verbose : bool, default False
        Print progress per policy.
    env_source : str, default ""
        Where ``env_kwargs`` came from, in words, for the report's header
        (:meth:`Report.header`).
    methods : mapping of str to sequence of str, optional
        Methods: a name and the policies of ``policies`` pooled under it (e.g. one per
        training seed); each gets a row over all their episodes. Default: none.
    gap : (str, str), optional
        A baseline and a reference, each a policy or a method: the report's gap table
        (:meth:`Report.gap_markdown`) gives every policy's and method's share of the gap
        between them. Default: none.
    bootstrap_reps : int, default :data:`BOOTSTRAP_REPS`
        Bootstrap replicates of the gap table's intervals.

    A heuristic that commands another action frame than ``env_kwargs`` sets (the column
    heuristics command velocities, a policy trained in the route frame route set-points) is
    flown with ``action_frame`` set to its own frame (:func:`coopnav_env.agents.action_frame_of`),
    every other setting as given; the report names it (:attr:`Report.own_frame`).

    Returns
    -------
    Report

    Raises
    ------
    ValueError
        No policy, no seed, a duplicated or unknown policy name, bad env settings; a method
        without policies, with a policy not in ``policies`` or named like a policy; a gap
        whose ends are not two different policies or methods.
    FileNotFoundError
        A ``ppo:<path>`` checkpoint does not exist.
    """
    from coopnav_env.agents import make_policy

    policies = list(policies)
    seeds = [int(s) for s in seeds]
    if not policies:
        raise ValueError("give at least one policy to evaluate")
    if not seeds:
        raise ValueError("give at least one evaluation seed")
    if len(set(policies)) != len(policies):
        raise ValueError(f"policy names must be unique, got {policies}")
    groups, gap_ends = check_methods_and_gap(policies, methods, gap)
    env_kwargs = dict(env_kwargs or {})
    if out is not None:
        ensure_folder(out)  # before any episode runs
    own_frame = _own_frames(policies, env_kwargs)
    envs = {
        name: _make_env(env_id, {**env_kwargs, "action_frame": own_frame[name]})
        if name in own_frame
        else _make_env(env_id, env_kwargs)
        for name in policies
    }
    made = {}
    for name in policies:
        try:
            made[name] = make_policy(name, envs[name])
        except (ValueError, FileNotFoundError, ImportError):
            raise
        except Exception as exc:  # a damaged checkpoint: the loader's own error
            raise ValueError(f"policy {name!r} does not load: {type(exc).__name__}: {exc}") from exc

    stats: list[PolicyStats] = []
    records: dict[str, list[EpisodeRecord]] = {}
    for name in policies:
        t0 = time.perf_counter()
        eps = [run_episode(envs[name], made[name], s) for s in seeds]
        wall = time.perf_counter() - t0
        records[name] = eps
        alert = _alert_limit_m(envs[name])
        stats.append(PolicyStats.from_episodes(name, eps, wall, alert))
        if verbose:
            print(f"  {name}: {len(eps)} episodes in {wall:.1f} s", file=sys.stderr)

    method_stats = [
        PolicyStats.from_episodes(
            name,
            [e for p in members for e in records[p]],
            sum(s.wall_s for s in stats if s.policy in members),
            _alert_limit_m(envs[members[0]]),
        )
        for name, members in groups.items()
    ]
    report = Report(
        stats,
        seeds,
        env_kwargs,
        env_id,
        records,
        env_source=env_source,
        methods=groups,
        method_stats=method_stats,
        own_frame=own_frame,
    )
    if gap_ends is not None:
        report.gap = gap_ends
        report.gap_rows = _gap_rows(records, policies, groups, gap_ends, bootstrap_reps)
    if out is not None:
        _write(report, Path(out), envs[policies[0]], plots)
    for env in envs.values():
        env.close()
    return report


def check_methods_and_gap(
    policies: Sequence[str],
    methods: Mapping[str, Sequence[str]] | None,
    gap: Sequence[str] | None,
) -> tuple[dict[str, list[str]], tuple[str, str] | None]:
    """``(methods, gap)`` as :func:`evaluate` takes them, checked against ``policies``.

    Raises
    ------
    ValueError
        As :func:`evaluate` does for a bad method or gap (so that a command line can refuse
        them before any work).
    """
    groups = _check_methods(methods or {}, policies)
    return groups, _check_gap(gap, policies, groups)


def _check_methods(
    methods: Mapping[str, Sequence[str]], policies: Sequence[str]
) -> dict[str, list[str]]:
    """``methods`` as a dict of lists, checked against ``policies`` (``ValueError``)."""
    out: dict[str, list[str]] = {}
    for name, members in methods.items():
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"a method needs a name, got {name!r}")
        if name in policies:
            raise ValueError(
                f"method {name!r} is named like a policy it would be confused with; "
                "give the method another name"
            )
        members = [members] if isinstance(members, str) else list(members)
        if not members:
            raise ValueError(f"method {name!r} has no policies; give at least one")
        missing = [p for p in members if p not in policies]
        if missing:
            raise ValueError(
                f"method {name!r} pools {missing}, which are not among the policies "
                f"evaluated {list(policies)}; evaluate them too"
            )
        if len(set(members)) != len(members):
            raise ValueError(f"method {name!r} names a policy twice: {members}")
        out[name] = members
    return out


def _check_gap(
    gap: Sequence[str] | None, policies: Sequence[str], methods: Mapping[str, Sequence[str]]
) -> tuple[str, str] | None:
    """``gap`` as ``(baseline, reference)``, each a policy or a method (``ValueError``)."""
    if gap is None:
        return None
    ends = [gap] if isinstance(gap, str) else list(gap)
    if len(ends) != 2:
        raise ValueError(f"gap takes a baseline and a reference, two names, got {ends}")
    known = [*policies, *methods]
    for role, name in zip(("baseline", "reference"), ends):
        if name not in known:
            raise ValueError(
                f"the gap's {role} {name!r} is neither a policy evaluated nor a method; "
                f"choose one of {known}"
            )
    if ends[0] == ends[1]:
        raise ValueError(
            f"the gap's baseline and reference are both {ends[0]!r}; give two different ones"
        )
    return ends[0], ends[1]


def _own_frames(policies: Sequence[str], env_kwargs: Mapping[str, Any]) -> dict[str, str]:
    """Heuristics that command another action frame than ``env_kwargs`` sets -> their frame."""
    from coopnav_env.agents import action_frame_of

    frame = env_kwargs.get("action_frame", "velocity")
    out = {}
    for name in policies:
        own = action_frame_of(name)
        if own is not None and own != frame:
            out[name] = own
    return out


def _gap_rows(
    records: Mapping[str, Sequence[EpisodeRecord]],
    policies: Sequence[str],
    methods: Mapping[str, Sequence[str]],
    gap: tuple[str, str],
    reps: int,
) -> list[GapRow]:
    """A :class:`GapRow` for every policy, then every method (their policies averaged per
    episode)."""
    groups = {name: [name] for name in policies} | {m: list(ps) for m, ps in methods.items()}

    def returns(members: Sequence[str]) -> np.ndarray:
        return np.array([[e.episode_return for e in records[p]] for p in members], dtype=float)

    base, ref = returns(groups[gap[0]]), returns(groups[gap[1]])
    rows = []
    for name, members in groups.items():
        scores = returns(members)
        mean = bootstrap_mean_interval(scores.mean(axis=0), reps, np.random.default_rng(0))
        rows.append(
            GapRow(name, list(members), Interval(*mean), gap_closed(scores, base, ref, reps))
        )
    return rows


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------


def _write(report: Report, out: Path, env: Any, plots: bool) -> None:
    out.mkdir(parents=True, exist_ok=True)
    files = report.files
    files["json"] = out / "report.json"
    write_json(files["json"], report.to_dict())
    files["csv"] = out / "report.csv"
    names = [f.name for f in PolicyStats.__dataclass_fields__.values()]
    table = io.StringIO(newline="")
    w = csv.writer(table)
    w.writerow(names)
    for s in [*report.stats, *report.method_stats]:
        w.writerow([_csv_cell(getattr(s, k)) for k in names])
    atomic_write_text(files["csv"], table.getvalue())
    files["md"] = out / "report.md"
    atomic_write_text(files["md"], _markdown_document(report))
    files["npz"] = out / "errors.npz"
    arrays = {}
    for name, eps in report.episodes.items():
        arrays[f"{_slug(name)}__coop_error_m"] = np.concatenate(
            [e.coop_error_m.ravel() for e in eps]
        )
        arrays[f"{_slug(name)}__standalone_error_m"] = np.concatenate(
            [e.standalone_error_m.ravel() for e in eps]
        )
    with atomic_path(files["npz"], suffix=".npz") as tmp:
        np.savez_compressed(tmp, **arrays)
    if plots:
        from coopnav_env.training.eval_plots import plot_error_cdf, plot_trajectories, short_labels

        files["cdf"] = plot_error_cdf(report, out / "error_cdf.png", ERROR_THRESHOLD_M)
        labels = short_labels(list(report.episodes))
        for name, eps in report.episodes.items():
            path = out / f"trajectories_{_slug(name)}.png"
            if plot_trajectories(env, eps[0], path, title=f"{labels[name]}, seed {eps[0].seed}"):
                files[f"trajectories:{name}"] = path


def write_report(report: Report, out: str | Path) -> None:
    """Write ``report``'s files (``report.json``, ``report.csv``, ``report.md``,
    ``errors.npz``; no plots) into the folder ``out``, recording them in ``report.files``."""
    _write(report, Path(out), None, plots=False)


def _csv_cell(v: Any) -> Any:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(round(v, 6))
    return v


def _markdown_document(report: Report) -> str:
    lines = [
        "# Policy evaluation",
        "",
        report.header(),
        "Errors are true-minus-estimated 3-D position errors over all UAV-steps; mean, median"
        " and p95 over steps with a fix, P(< 3 m) over all steps. Goal rate: episodes in which"
        " the whole swarm reached the goal area; collisions: episodes ended by a crash.",
        "",
        report.to_markdown(),
        "",
    ]
    if report.gap is not None:
        lines += [report.gap_markdown(), ""]
    return "\n".join(lines)
