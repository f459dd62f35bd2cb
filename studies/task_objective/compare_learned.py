"""Learned swarms against the heuristics on the v1 score, with paired intervals.

Flies every policy on the same held-out episodes of ``urban_canyon_v1`` and reports, per
policy and per method (a method = its training seeds, averaged per episode):

* the score (the undiscounted return, mean over UAVs) with its 95 % bootstrap interval, the
  goal and collision rates, the mean navigation error, the steps;
* what was learned: the mean distance of a UAV to its nearest neighbour during the cruise
  (the middle 60 % of the episode's steps, leaving out the start lattice and the closing at
  the goal) and the mean altitude;
* the paired difference in score to the reference heuristic and to the baseline, and the
  share of the gap between the baseline and the reference that the method closes;
* the paired difference in score between every two methods (in the order given).

Example::

    python studies/task_objective/compare_learned.py \\
        --methods mappo=mappo:runs/v1/mappo_bc_s0,mappo:runs/v1/mappo_bc_s1 \\
        --heuristics column wide_column high_wide_column --reference high_wide_column \\
        --episodes 100 --seed-start 1000100 --out studies/task_objective/learned_v1
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

CRUISE = (0.2, 0.8)
"""The share of an episode's steps that counts as the cruise (start and end left out)."""

KEYS = (
    "score",
    "goal",
    "collided",
    "nav_error_m",
    "steps",
    "cruise_spacing_m",
    "cruise_altitude_m",
)
"""What :func:`fly_policy` records per episode, in the reports' column order (score first)."""


SCORE_NEUTRAL_SETTINGS = frozenset(
    {
        "nav_team_weight",
        "obs_agent_index",
        "action_frame",
        "route_offset_max_m",
        "route_turn_brake_mps2",
    }
)
"""Environment settings a training run may change without changing the world its episodes
are flown in or their score (team credit moves reward between UAVs, leaving their mean; the
index only adds observation entries; the action frame says what the policy's action
commands, the route frame's autopilot turning it into the velocity command)."""


def env_settings_of(policy_name: str) -> dict[str, Any]:
    """The ``urban_canyon_v1`` settings ``policy_name`` is flown in: a trained policy's run's
    own (from its ``config.yaml``, by
    :func:`coopnav_env.training.evaluate_cli.train_config_of_policies`), ``action_frame=
    "route"`` for a heuristic that flies in that frame
    (:func:`coopnav_env.agents.action_frame_of`), else the environment's
    defaults (``{}``).

    Raises ``ValueError`` for a run on another environment, or one whose settings differ from
    the defaults in anything but :data:`SCORE_NEUTRAL_SETTINGS` (its episodes would not be
    scored as the others').
    """
    from coopnav_env.agents import action_frame_of
    from coopnav_env.training.evaluate_cli import train_config_of_policies

    if action_frame_of(policy_name) == "route":
        return {"action_frame": "route"}
    run = train_config_of_policies([policy_name])
    if not run:
        return {}
    if run.get("env_id") != "urban_canyon_v1":
        raise ValueError(f"{policy_name} was trained on {run.get('env_id')}, not urban_canyon_v1")
    from coopnav_env.envs.config import V1_DEFAULTS

    env = dict(run.get("env") or {})
    other = sorted(
        k for k, v in env.items() if k not in SCORE_NEUTRAL_SETTINGS and V1_DEFAULTS.get(k) != v
    )
    if other:
        raise ValueError(
            f"{policy_name} was trained with env settings {other} that change the episodes; "
            f"only {sorted(SCORE_NEUTRAL_SETTINGS)} may differ from urban_canyon_v1's defaults"
        )
    return env


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    """Run the body with torch on one intra-op thread (when torch is installed), restoring the
    previous count after: a network's output can differ in the last bits with the thread count,
    and a report's episodes must fly the same on every machine."""
    try:
        import torch
    except ImportError:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@contextlib.contextmanager
def policy_in_its_env(policy_name: str) -> Iterator[tuple[Any, Any]]:
    """``(env, policy)``: an ``urban_canyon_v1`` in :func:`env_settings_of` ``policy_name``
    and the policy acting in it, torch on one thread (:func:`one_torch_thread`) for the body;
    the environment is closed after. The privileged planner of
    :mod:`studies.planner_headroom.planner` is registered (``planner@base=...``)."""
    import studies.planner_headroom.planner  # noqa: F401  (registers 'planner')
    from coopnav_env import urban_canyon_v1
    from coopnav_env.agents import make_policy

    env = urban_canyon_v1.parallel_env(**env_settings_of(policy_name))
    try:
        with one_torch_thread():
            yield env, make_policy(policy_name, env)
    finally:
        env.close()


def fly(policy_name: str, seeds: Sequence[int]) -> list[dict[str, float]]:
    """Per-episode figures of ``policy_name`` on ``urban_canyon_v1``
    (:func:`policy_in_its_env`, :func:`fly_policy`)."""
    with policy_in_its_env(policy_name) as (env, policy):
        return fly_policy(env, policy, seeds)


def report_folder(parser: argparse.ArgumentParser, args: argparse.Namespace) -> Path:
    """``args.out`` as a folder for ``report.json``; ``parser.error`` (exit 2) when it holds
    one already and ``args.overwrite`` is not set."""
    out = Path(args.out)
    if (out / "report.json").exists() and not args.overwrite:
        parser.error(f"{out} already holds a report.json; pass --overwrite to replace it")
    return out


def add_report_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--out`` and ``--overwrite`` options of a study report (:func:`report_folder`)."""
    parser.add_argument("--out", required=True, help="folder for report.json and report.md")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing report")


def write_report(out: Path, title: str, report: Mapping[str, Any], text: str) -> None:
    """Write ``report.json`` and ``report.md`` (``# title`` over ``text``) into ``out``, each
    by temporary name and rename, and print ``text``."""
    from coopnav_env.training.files import atomic_write_text, write_json

    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "report.json", report)
    atomic_write_text(out / "report.md", f"# {title}\n\n" + text)
    print(text)


def fly_policy(env: Any, policy: Any, seeds: Sequence[int]) -> list[dict[str, float]]:
    """Per-episode figures of ``policy`` flown in ``env`` (an ``urban_canyon_v1``) on ``seeds``:
    score, goal, collided, nav_error_m, steps, cruise_spacing_m, cruise_altitude_m."""
    from coopnav_env.training.evaluate import run_episode

    out = []
    for seed in seeds:
        rec = run_episode(env, policy, int(seed))
        pos = np.asarray(rec.pos_enu_m, dtype=float)  # (T + 1, N, 3)
        t0, t1 = (round(f * (len(pos) - 1)) for f in CRUISE)
        cruise = pos[max(t0, 1) : max(t1, t0 + 1) + 1]
        d = np.linalg.norm(cruise[:, :, None, :] - cruise[:, None, :, :], axis=-1)
        n = d.shape[1]
        d[:, np.arange(n), np.arange(n)] = np.inf
        nav = np.asarray(rec.nav_error_m, dtype=float)
        out.append(
            {
                "seed": int(seed),
                "score": float(rec.episode_return),
                "goal": float(rec.success),
                "collided": float(rec.collided),
                "nav_error_m": float(np.nanmean(nav)) if nav.size else float("nan"),
                "steps": float(rec.length),
                "cruise_spacing_m": float(d.min(axis=2).mean()),
                "cruise_altitude_m": float(cruise[:, :, 2].mean()),
            }
        )
    return out


def summarise(
    rows: Sequence[Mapping[str, float]], keys: Sequence[str], reps: int
) -> dict[str, Any]:
    """The mean score of per-episode ``rows`` (:func:`fly_policy`) with its 95 % bootstrap
    interval (``[mean, low, high]``), and the mean of every other entry of ``keys``."""
    out: dict[str, Any] = {"score": _mean_ci(np.array([r["score"] for r in rows]), reps)}
    for k in keys:
        if k != "score":
            out[k] = float(np.mean([r[k] for r in rows]))
    return out


def _mean_ci(x: np.ndarray, reps: int) -> list[float]:
    from coopnav_env.training.stats import bootstrap_mean_interval

    return list(bootstrap_mean_interval(x, reps, np.random.default_rng(0)))


def _paired(a: np.ndarray, b: np.ndarray, reps: int) -> list[float]:
    """Paired difference of two ``(runs, episodes)`` matrices (runs resampled too)."""
    from coopnav_env.training.stats import paired_difference

    iv, _ = paired_difference(a, b, reps=reps, seed=0)
    return [iv.value, iv.low, iv.high]


def _gap_closed(method: np.ndarray, base: np.ndarray, ref: np.ndarray, reps: int) -> list[float]:
    """``(method - base) / (ref - base)`` of the episode means, with a paired bootstrap."""
    rng = np.random.default_rng(0)
    est = float((method.mean() - base.mean()) / (ref.mean() - base.mean()))
    idx = rng.integers(0, len(method), size=(reps, len(method)))
    m, b, r = method[idx].mean(axis=1), base[idx].mean(axis=1), ref[idx].mean(axis=1)
    boots = (m - b) / (r - b)
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return [est, float(lo), float(hi)]


def compare(
    methods: Mapping[str, Sequence[str]],
    heuristics: Sequence[str],
    reference: str,
    baseline: str,
    seeds: Sequence[int],
    reps: int = 2000,
) -> dict[str, Any]:
    """Fly every policy and summarise (see the module docstring)."""
    from tqdm.auto import tqdm

    names = list(dict.fromkeys([*heuristics, reference, baseline]))
    names += [p for ps in methods.values() for p in ps if p not in names]
    flown = {name: fly(name, seeds) for name in tqdm(names, desc="policies")}
    keys = KEYS

    def matrix(per_policy: Sequence[str], key: str) -> np.ndarray:
        return np.array([[e[key] for e in flown[p]] for p in per_policy], dtype=float)

    def arrays(per_policy: Sequence[str]) -> dict[str, np.ndarray]:
        return {k: matrix(per_policy, k).mean(axis=0) for k in keys}

    groups = {name: [name] for name in heuristics} | {m: list(ps) for m, ps in methods.items()}
    groups |= {name: [name] for ps in methods.values() for name in ps}
    ref, base = arrays([reference]), arrays([baseline])
    rows = []
    for name, members in groups.items():
        a = arrays(members)
        row: dict[str, Any] = {"name": name, "policies": members}
        row["score"] = _mean_ci(a["score"], reps)
        for k in keys[1:]:
            row[k] = float(np.mean(a[k]))
        scores = matrix(members, "score")
        row["score_minus_reference"] = _paired(scores, matrix([reference], "score"), reps)
        row["score_minus_baseline"] = _paired(scores, matrix([baseline], "score"), reps)
        row["gap_closed"] = _gap_closed(a["score"], base["score"], ref["score"], reps)
        rows.append(row)
    names_m = list(methods)
    between = [
        {
            "a": a,
            "b": b,
            "score_a_minus_b": _paired(
                matrix(methods[a], "score"), matrix(methods[b], "score"), reps
            ),
        }
        for i, a in enumerate(names_m)
        for b in names_m[i + 1 :]
    ]
    return {
        "environment": "urban_canyon_v1",
        "seeds": [int(seeds[0]), int(seeds[-1])],
        "episodes": len(seeds),
        "reference": reference,
        "baseline": baseline,
        "cruise": list(CRUISE),
        "rows": rows,
        "between_methods": between,
        "episodes_per_policy": flown,
    }


def to_markdown(report: Mapping[str, Any]) -> str:
    """The summary table."""

    def iv(v: Sequence[float], nd: int = 3) -> str:
        return f"{v[0]:+.{nd}f} [{v[1]:+.{nd}f}, {v[2]:+.{nd}f}]"

    lines = [
        f"`urban_canyon_v1`, {report['episodes']} held-out episodes (reset seeds "
        f"{report['seeds'][0]}-{report['seeds'][1]}); a method's seeds are averaged per "
        f"episode. Reference: `{report['reference']}`; baseline: `{report['baseline']}`.",
        "",
        "| policy | score [95 % CI] | goal | collisions | nav error [m] | steps | cruise "
        "spacing [m] | cruise altitude [m] | score - reference | gap closed |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for r in sorted(report["rows"], key=lambda r: -r["score"][0]):
        s = r["score"]
        lines.append(
            f"| `{r['name']}` | {s[0]:.3f} [{s[1]:.3f}, {s[2]:.3f}] | {r['goal']:.2f} | "
            f"{r['collided']:.2f} | {r['nav_error_m']:.2f} | {r['steps']:.1f} | "
            f"{r['cruise_spacing_m']:.1f} | {r['cruise_altitude_m']:.1f} | "
            f"{iv(r['score_minus_reference'])} | {iv(r['gap_closed'], 2)} |"
        )
    if report.get("between_methods"):
        lines += ["", "| method a - method b | paired score difference [95 % CI] |", "|---|---|"]
        for d in report["between_methods"]:
            lines.append(f"| `{d['a']}` - `{d['b']}` | {iv(d['score_a_minus_b'])} |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (``--help``)."""
    from coopnav_env.training.envs import heldout_seeds

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--methods",
        nargs="*",
        default=[],
        metavar="NAME=POLICY[,POLICY...]",
        help="learned methods: a name and its policies, one per training seed",
    )
    p.add_argument("--heuristics", nargs="+", default=["column", "wide_column"])
    p.add_argument("--reference", default="wide_column", help="the heuristic to beat")
    p.add_argument("--baseline", default="column", help="the gap's other end")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed-start", type=int, default=1_000_100)
    p.add_argument("--reps", type=int, default=2000, help="bootstrap replicates")
    add_report_arguments(p)
    args = p.parse_args(argv)
    out = report_folder(p, args)
    methods: dict[str, list[str]] = {}
    for item in args.methods:
        name, eq, policies = item.partition("=")
        if not eq or not name or not policies.strip(","):
            p.error(f"--methods {item!r} must look like NAME=POLICY[,POLICY...]")
        methods[name] = [x for x in policies.split(",") if x]
    seeds = heldout_seeds(args.episodes, args.seed_start)
    report = compare(methods, args.heuristics, args.reference, args.baseline, seeds, args.reps)
    write_report(out, "Learned swarms on v1", report, to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
