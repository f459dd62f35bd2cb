"""What a per-episode choice among policies could gain: every arm flown under noise replicates.

Flies every policy given with ``--arms`` (:func:`coopnav_env.agents.make_policy` names, with the
route policies of :mod:`studies.route_choice.routes` registered, e.g. ``best_sky_route
best_sky_route@spacing_m=30``) through every held-out episode, ``--noise-replicates`` times
under independent noise realisations of the same episode (the environment's ``noise_stream``
reset option), and prints each arm's mean ``nav`` error (the 3-D error of the estimate each UAV
used, averaged over UAV-steps, episodes and replicates) and goal rate, the best *fixed* arm, and
the *expected-error oracle*: per episode, the arm with the lowest mean over R - 1 of the
replicates, priced on the remaining one (each held out in turn), as a paired difference to the
best fixed arm on that replicate. The oracle does not pick on the noise it is priced on, so it
bounds what any per-episode choice among the arms, learned (a contextual bandit) or written,
could gain over always flying the best one, up to the noise of R - 1 flights. 95 % bootstrap
intervals over episodes (2000 resamples, generator seed 0).

The study (``studies/choice_headroom/README.md``) runs::

    python studies/choice_headroom/arm_choice.py --episodes 500 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true max_fix_sigma_m=8 \\
        --noise-replicates 3 --arms best_sky_route best_sky_route@spacing_m=30 \\
        best_sky_route@spacing_m=60 best_sky_route@cruise_speed_mps=10 --out runs/arms/spacing

about 6 minutes on 2 cores. ``--compare REF GROUP`` also prints the paired difference of a
group of arms (comma-separated, e.g. the training seeds of one learned method; their mean per
episode) to the arm ``REF``, with its 95 % interval over episodes: with replicates, a
comparison with less of one flight's noise. ``--out`` keeps the flights (``episodes.npz``)
and the report (``report.json``); with an ``episodes.npz`` of the same settings there,
nothing is flown again, and a folder of a run with other settings is refused (it is never
overwritten). ``--reuse FOLDER ...`` takes the flights of arms already flown by other runs of
this benchmark on the same episodes (same environment, seeds and replicates; on the same code
their flights are what flying them again gives, bit for bit) and flies only the arms none of
them holds, e.g. to add a rule to a finished comparison without flying its arms again.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _chunk(common: tuple[dict[str, Any], list[str], int], seeds: list[int]) -> list[np.ndarray]:
    import torch

    import studies.route_choice.routes  # noqa: F401  (registers the route policies)
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy
    from coopnav_env.training.evaluate import run_episode

    torch.set_num_threads(1)
    env_kwargs, arms, replicates = common
    env = urban_canyon_v0.parallel_env(**env_kwargs)
    out = []
    for seed in seeds:
        rows = np.full((len(arms), replicates, 2), math.nan)  # nav, goal
        for a, name in enumerate(arms):
            for r in range(replicates):
                options = {"noise_stream": r} if r else None
                rec = run_episode(env, make_policy(name, env), int(seed), options=options)
                err = np.asarray(rec.nav_error_m, dtype=float)
                rows[a, r, 0] = float(np.nanmean(err)) if np.isfinite(err).any() else math.nan
                rows[a, r, 1] = float(rec.success)
        out.append(rows)
    return out


def collect(
    env_kwargs: dict[str, Any],
    arms: list[str],
    seeds: list[int],
    replicates: int,
    jobs: int,
    progress: bool = False,
) -> np.ndarray:
    """``(episodes, arms, replicates, 2)``: each flight's mean ``nav`` error and goal (0/1)."""
    from studies.route_choice.parallel import map_seeds

    return np.stack(
        map_seeds(
            _chunk, (env_kwargs, arms, replicates), seeds, jobs=jobs, desc="arms", progress=progress
        )
    )


def price(flights: np.ndarray, arms: list[str], reps: int = 2000) -> dict[str, Any]:
    """Each arm's mean, the best fixed arm and the expected-error oracle (see the module doc)."""
    from coopnav_env.training.stats import bootstrap_mean_interval

    nav, goal = flights[..., 0], flights[..., 1]
    n_ep, _, n_r = nav.shape
    mean = np.nanmean(nav, axis=(0, 2))
    best = int(np.nanargmin(mean))
    out: dict[str, Any] = {"episodes": n_ep, "replicates": n_r, "arms": {}}
    for a, name in enumerate(arms):
        d = np.nanmean(nav[:, a] - nav[:, best], axis=1)
        out["arms"][name] = {
            "nav_m": float(mean[a]),
            "goal_rate": float(goal[:, a].mean()),
            "vs_best_fixed_m": [
                float(v) for v in bootstrap_mean_interval(d, reps, np.random.default_rng(0))
            ],
        }
    out["best_fixed"] = arms[best]
    diff, held, goals = [], [], []
    for e in range(n_ep):
        dv, v, g = [], [], []
        for r in range(n_r):
            k = int(np.nanargmin(np.nanmean(np.delete(nav[e], r, axis=1), axis=1)))
            dv.append(nav[e, k, r] - nav[e, best, r])
            v.append(nav[e, k, r])
            g.append(goal[e, k, r])
        diff.append(float(np.mean(dv)))
        held.append(float(np.mean(v)))
        goals.append(float(np.mean(g)))
    out["oracle_expected_nav_m"] = float(np.mean(held))
    out["oracle_expected_goal_rate"] = float(np.mean(goals))
    out["oracle_expected_vs_best_fixed_m"] = [
        float(v) for v in bootstrap_mean_interval(np.array(diff), reps, np.random.default_rng(0))
    ]
    return out


def reused_flights(folders: list[str], settings: dict[str, Any]) -> dict[str, np.ndarray]:
    """The flights ``(episodes, replicates, 2)`` of every arm in the ``--out`` folders of
    earlier runs with the same environment, seeds and replicates as ``settings`` (the first
    folder holding an arm wins). A folder of other episodes, or without finished flights, is
    refused with a :class:`ValueError` that names it."""
    same = ("env", "first_seed", "episodes", "noise_replicates")
    wanted = json.loads(json.dumps({k: settings[k] for k in same}))
    out: dict[str, np.ndarray] = {}
    for folder in folders:
        f = Path(folder)
        sfile, data = f / "settings.json", f / "episodes.npz"
        if not (sfile.is_file() and data.is_file()):
            raise ValueError(f"--reuse {f}: no finished run of this benchmark there")
        old = json.loads(sfile.read_text())
        theirs = {k: old.get(k) for k in same}
        if theirs != wanted:
            raise ValueError(f"--reuse {f}: flown on other episodes ({theirs}), not {wanted}")
        with np.load(data) as d:
            flights = np.asarray(d["flights"])
        for a, name in enumerate(old["arms"]):
            out.setdefault(name, flights[:, a])
    return out


def compare(
    flights: np.ndarray, arms: list[str], ref: str, group: list[str], reps: int = 2000
) -> dict[str, Any]:
    """Paired difference of the mean of ``group``'s arms to arm ``ref`` per episode (means
    over the replicates), with a 95 % bootstrap interval over episodes, and goal rates."""
    from coopnav_env.training.stats import bootstrap_mean_interval

    missing = [a for a in [ref, *group] if a not in arms]
    if missing:
        raise ValueError(f"--compare names arms that were not flown: {missing}; arms: {arms}")
    nav, goal = flights[..., 0], flights[..., 1]
    r = arms.index(ref)
    g = [arms.index(a) for a in group]
    d = np.nanmean(nav[:, g], axis=(1, 2)) - np.nanmean(nav[:, r], axis=1)
    return {
        "ref": ref,
        "group": list(group),
        "group_nav_m": float(np.nanmean(nav[:, g])),
        "ref_nav_m": float(np.nanmean(nav[:, r])),
        "group_goal_rate": float(goal[:, g].mean()),
        "ref_goal_rate": float(goal[:, r].mean()),
        "difference_m": [
            float(v) for v in bootstrap_mean_interval(d, reps, np.random.default_rng(0))
        ],
    }


def report_lines(rep: dict[str, Any]) -> list[str]:
    """The printed table of :func:`price`."""
    lines = [
        f"{rep['episodes']} episodes x {rep['replicates']} noise replicates",
        f"{'arm':40s} {'nav [m]':>8s} {'goal':>6s}  vs best fixed [m]",
    ]
    for k, c in rep["arms"].items():
        a = c["vs_best_fixed_m"]
        lines.append(
            f"{k:40s} {c['nav_m']:8.3f} {c['goal_rate']:6.3f}  "
            f"{a[0]:+.3f} [{a[1]:+.3f}, {a[2]:+.3f}]"
        )
    o = rep["oracle_expected_vs_best_fixed_m"]
    lines.append(
        f"expected-error oracle (chosen on the other noise replicates): nav "
        f"{rep['oracle_expected_nav_m']:.3f} m, goal rate {rep['oracle_expected_goal_rate']:.3f}, "
        f"vs the best fixed arm ({rep['best_fixed']}) {o[0]:+.3f} [{o[1]:+.3f}, {o[2]:+.3f}]"
    )
    if "compare" in rep:
        c = rep["compare"]
        d = c["difference_m"]
        lines.append(
            f"{' + '.join(c['group'])} (mean, nav {c['group_nav_m']:.3f} m, goal rate "
            f"{c['group_goal_rate']:.3f}) - {c['ref']} (nav {c['ref_nav_m']:.3f} m, goal rate "
            f"{c['ref_goal_rate']:.3f}): {d[0]:+.3f} [{d[1]:+.3f}, {d[2]:+.3f}]"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    import studies.route_choice.routes  # noqa: F401  (registers the route policies)
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy
    from coopnav_env.training.files import atomic_path, atomic_write_text, claim_run_folder
    from studies.route_choice.route_learning import env_kwargs_from_overrides

    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--arms", nargs="+", required=True, help="policies to choose among (>= 2)")
    p.add_argument("--episodes", type=int, default=300, help="episodes (default: %(default)s)")
    p.add_argument(
        "--first-seed", type=int, default=1_000_000, help="first reset seed (default: %(default)s)"
    )
    p.add_argument("--env-set", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument(
        "--noise-replicates",
        type=int,
        default=3,
        help="flights of every arm under independent noise realisations, >= 2 "
        "(default: %(default)s)",
    )
    p.add_argument(
        "--compare",
        nargs=2,
        metavar=("REF", "GROUP"),
        default=None,
        help="also print the paired difference of the arms GROUP (comma-separated, their "
        "mean) to the arm REF",
    )
    p.add_argument(
        "--reuse",
        nargs="+",
        default=[],
        metavar="FOLDER",
        help="--out folders of earlier runs on the same episodes: their arms' flights are "
        "taken, not flown again",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    p.add_argument(
        "--out", default=None, help="folder of this run: episodes.npz, settings.json, report.json"
    )
    args = p.parse_args(argv)
    if len(args.arms) < 2:
        raise SystemExit(f"--arms needs at least 2 policies, got {args.arms}")
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    if args.noise_replicates < 2:
        raise SystemExit(f"--noise-replicates must be >= 2, got {args.noise_replicates}")
    if args.jobs < 1:
        raise SystemExit(f"--jobs must be >= 1, got {args.jobs}")
    group = args.compare[1].split(",") if args.compare else []
    if args.compare:
        missing = [a for a in [args.compare[0], *group] if a not in args.arms]
        if missing:
            raise SystemExit(f"--compare names arms not in --arms: {missing}")
    env_kwargs = env_kwargs_from_overrides(args.env_set)
    probe = urban_canyon_v0.parallel_env(**env_kwargs)
    for name in args.arms:  # a bad policy name fails before anything is flown
        make_policy(name, probe)
    settings = {
        "env": env_kwargs,
        "arms": list(args.arms),
        "first_seed": args.first_seed,
        "episodes": args.episodes,
        "noise_replicates": args.noise_replicates,
    }
    try:  # a bad --reuse folder is refused before --out is claimed
        known = reused_flights(args.reuse, settings)
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    out = Path(args.out) if args.out else None
    flights = None
    if out is not None:
        try:
            reuse = claim_run_folder(out, settings)
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
        if reuse:
            with np.load(out / "episodes.npz") as d:
                flights = np.asarray(d["flights"])
            print(f"using the flights of {out}", file=sys.stderr)
    if flights is None:
        seeds = list(range(args.first_seed, args.first_seed + args.episodes))
        todo = [a for a in args.arms if a not in known]
        flown = (
            collect(env_kwargs, todo, seeds, args.noise_replicates, args.jobs, progress=True)
            if todo
            else None
        )
        if known:
            print(f"reused the flights of {sorted(set(args.arms) - set(todo))}", file=sys.stderr)
        flights = np.stack(
            [known[a] if a in known else flown[:, todo.index(a)] for a in args.arms], axis=1
        )
        if out is not None:
            with atomic_path(out / "episodes.npz") as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, seed=np.array(seeds), flights=flights)
    rep = price(flights, list(args.arms))
    if args.compare:
        rep["compare"] = compare(flights, list(args.arms), args.compare[0], group)
    rep["settings"] = settings
    print("\n".join(report_lines(rep)))
    if out is not None:
        atomic_write_text(out / "report.json", json.dumps(rep, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
