"""Does a reward rank policies as the task's score does? ``coopnav alignment``.

A reward is *aligned* with the task when the return an agent maximises ranks policies the way
the score we report for them does. This module flies a family of policies on the same
held-out episodes under each reward setting given, and compares, per policy:

* the **score**: the mean over episodes of the undiscounted return of ``urban_canyon_v1``
  (``reward_scheme="navigated_distance"``, the task's score: the route's distance-weighted
  navigation quality, plus the goal bonus, minus collisions; see the environment's page);
* for each reward setting, the mean **return** and the mean **discounted return** at each
  discount ``gamma`` (every UAV's rewards summed over the episode with weight ``gamma**t``,
  averaged over the UAVs), which is what a learner with that discount maximises from the
  start state;
* the score's parts: mean navigation error, steps, goal rate, collisions.

The rank correlation (Spearman's, ties averaged) between each column and the score, over the
family, says whether a learner paid that way is pushed toward what the score rewards. The
reward does not change the flight (the same seed gives the same trajectory under every
reward setting), so every setting sees the same episodes; :func:`fly` checks it.
"""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.training.envs import heldout_seeds, make_env_fn

__all__ = [
    "DEFAULT_FAMILY",
    "DEFAULT_GAMMAS",
    "REWARD_SETTINGS",
    "AlignmentReport",
    "FlownEpisode",
    "add_arguments",
    "alignment",
    "discounted_return",
    "fly",
    "run",
    "spearman",
]

DEFAULT_FAMILY: tuple[str, ...] = (
    "column",
    "column@cruise_speed_mps=10,spacing_m=3",
    "sky_column",
    "stretched_column",
    "wide_column",
    "wide_column@spacing_m=30",
    "wide_column@cruise_speed_mps=5",
    "wide_column@cruise_speed_mps=10",
    "waypoint",
    "waypoint@altitude_m=28",
)
"""The policies of ``coopnav alignment`` by default: the column heuristics at several spacings
and speeds, the obs-only waypoint follower, and a fast tight clump
(``column@cruise_speed_mps=10,spacing_m=3``)."""

DEFAULT_GAMMAS: tuple[float, ...] = (0.99, 0.995, 0.999, 1.0)
"""The discounts compared by default."""

OUTPUTS: tuple[str, ...] = ("report.json", "report.md")
"""The files ``coopnav alignment --out`` writes."""

REWARD_SETTINGS: dict[str, str] = {"v0": "urban_canyon_v0", "v1": "urban_canyon_v1"}
"""Named reward settings: the environment whose default reward each names."""

WORLD_SETTINGS_OF_V1: tuple[str, ...] = ("crash_free_steps",)
"""Fields of :data:`coopnav_env.envs.config.V1_DEFAULTS` that set the world, not the reward:
every reward setting is flown with v1's values of them (unless ``env_kwargs`` gives its own),
so that the settings compared differ in their reward only."""


def discounted_return(rewards: Sequence[float] | np.ndarray, gamma: float) -> float:
    """``sum_t gamma**t * rewards[t]`` (``t`` from 0)."""
    r = np.asarray(rewards, dtype=float)
    return float(np.sum(r * gamma ** np.arange(r.size)))


def spearman(x: Sequence[float], y: Sequence[float]) -> float:
    """Spearman's rank correlation of ``x`` and ``y`` (ties get their mean rank).

    Raises
    ------
    ValueError
        Different lengths, fewer than 3 values, or a constant sequence (no ranking).
    """
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if a.shape != b.shape or a.ndim != 1 or a.size < 3:
        raise ValueError(
            f"spearman needs two sequences of the same length >= 3, got {a.shape}, {b.shape}"
        )

    def ranks(v: np.ndarray) -> np.ndarray:
        order = np.argsort(v, kind="stable")
        r = np.empty(v.size)
        r[order] = np.arange(v.size, dtype=float)
        for value in np.unique(v):  # ties: their mean rank
            tie = v == value
            r[tie] = r[tie].mean()
        return r

    ra, rb = ranks(a), ranks(b)
    if np.ptp(ra) == 0.0 or np.ptp(rb) == 0.0:
        raise ValueError("spearman: a constant sequence has no ranking")
    return float(np.corrcoef(ra, rb)[0, 1])


@dataclass(frozen=True)
class FlownEpisode:
    """One episode of one policy under one reward setting.

    ``step_rewards``: the reward of each step averaged over the UAVs, ``(T,)``; ``nav_error_m``:
    the mean over UAVs and steps of the error of the estimate used; ``goal``: the swarm
    arrived; ``collided``: a UAV hit a building.
    """

    seed: int
    step_rewards: np.ndarray
    nav_error_m: float
    steps: int
    goal: bool
    collided: bool
    error_trace: np.ndarray = field(repr=False)

    @property
    def episode_return(self) -> float:
        """The undiscounted return, averaged over the UAVs."""
        return float(np.sum(self.step_rewards))


def fly(
    policy_name: str, env_id: str, seeds: Sequence[int], env_kwargs: Mapping[str, Any] | None = None
) -> list[FlownEpisode]:
    """Fly ``policy_name`` (a :func:`coopnav_env.agents.make_policy` name) on ``seeds``."""
    from coopnav_env.agents import make_policy

    env = make_env_fn(env_id, dict(env_kwargs or {}))()
    policy = make_policy(policy_name, env)
    out = []
    for seed in seeds:
        obs, _ = env.reset(seed=int(seed))
        policy.reset(seed=int(seed))
        rewards: list[float] = []
        errors: list[float] = []
        collided = goal = False
        while env.agents:
            obs, rew, _, _, infos = env.step(policy.act(obs))
            rewards.append(float(np.mean(list(rew.values()))))
            errors.append(float(np.mean([i["nav_error_m"] for i in infos.values()])))
            collided |= any(bool(i["collided"]) for i in infos.values())
            goal = all(bool(i["in_goal"]) for i in infos.values()) and not collided
        out.append(
            FlownEpisode(
                seed=int(seed),
                step_rewards=np.array(rewards),
                nav_error_m=float(np.mean(errors)) if errors else math.nan,
                steps=len(rewards),
                goal=bool(goal),
                collided=bool(collided),
                error_trace=np.array(errors),
            )
        )
    env.close()
    return out


@dataclass
class AlignmentReport:
    """Per policy: the score, its parts, and per reward setting the return and discounted
    returns; over the family: each column's rank correlation with the score."""

    policies: list[str]
    settings: list[str]
    gammas: list[float]
    seeds: list[int]
    rows: list[dict[str, Any]]
    correlations: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return {
            "policies": self.policies,
            "settings": self.settings,
            "gammas": self.gammas,
            "seeds": [self.seeds[0], self.seeds[-1]],
            "episodes": len(self.seeds),
            "rows": self.rows,
            "rank_correlation_with_score": self.correlations,
        }

    def to_markdown(self) -> str:
        """The table and the correlations as Markdown."""
        cols = ["score", "nav_error_m", "steps", "goal_rate", "collision_rate"]
        for s in self.settings:
            cols.append(f"{s}:return")
            cols += [f"{s}:disc@{g:g}" for g in self.gammas]
        head = "| policy | " + " | ".join(cols) + " |"
        lines = [head, "|---|" + "---:|" * len(cols)]
        for row in sorted(self.rows, key=lambda r: -r["score"]):
            cells = [f"{row[c]:.3f}" if isinstance(row[c], float) else str(row[c]) for c in cols]
            lines.append(f"| {row['policy']} | " + " | ".join(cells) + " |")
        corr = [f"| {c} | {v:+.3f} |" for c, v in self.correlations.items()]
        return (
            f"{len(self.seeds)} held-out episodes (reset seeds {self.seeds[0]}-{self.seeds[-1]}) "
            f"per policy; rows by score.\n\n"
            + "\n".join(lines)
            + "\n\nSpearman rank correlation with the score over the family:\n\n"
            "| column | rho |\n|---|---:|\n" + "\n".join(corr) + "\n"
        )


def alignment(
    policies: Sequence[str],
    seeds: Sequence[int],
    settings: Sequence[str] = ("v1",),
    gammas: Sequence[float] = DEFAULT_GAMMAS,
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = False,
) -> AlignmentReport:
    """Fly ``policies`` on ``seeds`` under each reward setting and compare with the score.

    Parameters
    ----------
    policies : sequence of str
        :func:`coopnav_env.agents.make_policy` names (at least 3: a ranking).
    seeds : sequence of int
        Reset seeds (the same episodes for every policy and setting).
    settings : sequence of str
        Keys of :data:`REWARD_SETTINGS`; ``"v1"`` (the score) is always flown.
    gammas : sequence of float
        Discounts, each in (0, 1].
    env_kwargs : mapping, optional
        Environment settings applied under every reward setting (world, not reward: e.g.
        ``preset``); a reward field here would change what the settings mean and is refused.
    progress : bool
        Show a progress bar.

    Raises
    ------
    ValueError
        Fewer than 3 policies, an unknown setting, a discount outside (0, 1], a reward field
        in ``env_kwargs``, or flights that differ between settings.
    """
    from coopnav_env.envs.config import V1_DEFAULTS

    policies, seeds = list(policies), [int(s) for s in seeds]
    for option, given in (("--policies", policies), ("--settings", list(settings))):
        twice = sorted({x for x in given if given.count(x) > 1})
        if twice:
            raise ValueError(f"{option}: {', '.join(map(repr, twice))} given twice; name each once")
    if len(policies) < 3:
        raise ValueError(f"alignment needs at least 3 policies to rank, got {policies}")
    unknown = [s for s in settings if s not in REWARD_SETTINGS]
    if unknown:
        raise ValueError(
            f"unknown reward setting(s) {unknown}; settings are {list(REWARD_SETTINGS)}"
        )
    bad = [g for g in gammas if not (0.0 < float(g) <= 1.0)]
    if bad:
        raise ValueError(f"discounts must be in (0, 1], got {bad}")
    reward = set(V1_DEFAULTS).difference(WORLD_SETTINGS_OF_V1) | {"nav_reward_cap_m"}
    reward_fields = sorted(set(env_kwargs or {}) & reward)
    if reward_fields:
        raise ValueError(
            f"env settings {reward_fields} change the reward; the settings compared are "
            f"{list(REWARD_SETTINGS)} (env_kwargs are for the world only)"
        )
    settings = list(dict.fromkeys(["v1", *settings]))
    world = {f: V1_DEFAULTS[f] for f in WORLD_SETTINGS_OF_V1} | dict(env_kwargs or {})
    gammas = [float(g) for g in gammas]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(policies) * len(settings), desc="alignment", unit="flight")
    rows = []
    for name in policies:
        flown = {}
        for s in settings:
            flown[s] = fly(name, REWARD_SETTINGS[s], seeds, world)
            if bar is not None:
                bar.update()
        ref = flown["v1"]
        for s, eps in flown.items():
            if any(not np.array_equal(a.error_trace, b.error_trace) for a, b in zip(eps, ref)):
                raise ValueError(f"{name}: the flights under {s!r} and 'v1' differ")
        row: dict[str, Any] = {
            "policy": name,
            "score": float(np.mean([e.episode_return for e in ref])),
            "nav_error_m": float(np.mean([e.nav_error_m for e in ref])),
            "steps": float(np.mean([e.steps for e in ref])),
            "goal_rate": float(np.mean([e.goal for e in ref])),
            "collision_rate": float(np.mean([e.collided for e in ref])),
        }
        for s, eps in flown.items():
            row[f"{s}:return"] = float(np.mean([e.episode_return for e in eps]))
            for g in gammas:
                row[f"{s}:disc@{g:g}"] = float(
                    np.mean([discounted_return(e.step_rewards, g) for e in eps])
                )
        rows.append(row)
    if bar is not None:
        bar.close()
    score = [r["score"] for r in rows]
    corr = {}
    for col in [c for c in rows[0] if ":" in c] + ["nav_error_m", "steps"]:
        try:
            corr[col] = spearman([r[col] for r in rows], score)
        except ValueError:
            corr[col] = math.nan
    return AlignmentReport(policies, settings, gammas, seeds, rows, corr)


# ---- command line -----------------------------------------------------------------------------


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``coopnav alignment``."""
    p.add_argument(
        "--policies",
        nargs="+",
        default=list(DEFAULT_FAMILY),
        help="the family to rank (policy names of coopnav evaluate; default: the column "
        "heuristics at several spacings and speeds, the waypoint follower and a fast clump)",
    )
    p.add_argument("--episodes", type=int, default=40, help="held-out episodes (default 40)")
    p.add_argument(
        "--seed-start", type=int, default=None, help="first held-out reset seed (default 1000000)"
    )
    p.add_argument(
        "--gammas",
        nargs="+",
        type=float,
        default=list(DEFAULT_GAMMAS),
        help="discounts to compare (default 0.99 0.995 0.999 1)",
    )
    p.add_argument(
        "--settings",
        nargs="+",
        default=["v1"],
        help="reward settings: v1 (urban_canyon_v1, the score; default), v0 (the legacy "
        "urban_canyon_v0's per-step reward)",
    )
    p.add_argument(
        "--env-set",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="world settings applied under every reward setting (e.g. preset=urban_nlos)",
    )
    p.add_argument(
        "--out",
        default=None,
        help="write report.json and report.md here, a folder of this command alone: a folder of "
        "another command, of other settings or holding this finished report is refused",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of the command (or the earlier report) that --out holds",
    )


def run(args: argparse.Namespace) -> int:
    """``coopnav alignment``: print the table (and write it to ``--out``)."""
    from coopnav_env.training.config import apply_overrides
    from coopnav_env.training.envs import EVAL_SEED_START
    from coopnav_env.training.files import atomic_write_text, claim_output_folder, write_json

    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    seeds = heldout_seeds(args.episodes, args.seed_start or EVAL_SEED_START)
    env_kwargs = apply_overrides({}, args.env_set)
    claim = contextlib.nullcontext(None)
    if args.out is not None:  # claimed (locked, checked, recorded) before any flight
        settings = {"policies": args.policies, "seeds": seeds, "gammas": args.gammas}
        settings |= {"settings": args.settings, "env": env_kwargs}
        claim = claim_output_folder(
            args.out, "coopnav alignment", settings, outputs=OUTPUTS, overwrite=args.overwrite
        )
    with claim as folder:
        report = alignment(
            args.policies, seeds, args.settings, args.gammas, env_kwargs, progress=True
        )
        text = report.to_markdown()
        if folder is not None:
            out = Path(args.out)
            files = [
                write_json(out / "report.json", report.to_json()),
                atomic_write_text(out / "report.md", "# Reward alignment\n\n" + text),
            ]
            folder.finish(files)
    print(text)
    return 0
