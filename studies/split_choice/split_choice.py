"""Splitting the column over two routes: every split flown, every one-feature rule priced.

The column heuristics can split the swarm over two equally short street routes
(``route_split``, ``route_split_index``: slots 0, 2, 4, ... on the first route, 1, 3, ... on
the second, abreast), so that the cooperative fix pools the sky of two streets. This
benchmark flies, for each held-out episode, the unsplit heuristic (``best_sky_route`` by default,
on its chosen route) and every split of it (its route and each other candidate), each under
``--noise-replicates`` independent noise realisations of the same episode (the environment's
``noise_stream`` reset option). It prices

* every one-feature rule of :data:`studies.route_choice.routes.SPLIT_FEATURES` choosing among
  *all* arms
  (no split, or a split with any other candidate) and among the splits only, as the paired
  difference of the mean error over the replicates to the unsplit heuristic;
* the *expected-error oracle*: per episode, the arm with the lowest mean over R - 1 of the
  replicates, priced on the remaining one (each held out in turn) against the unsplit
  heuristic on that replicate. It does not pick on the noise it is priced on, so it bounds
  what any choice of split, learned or written, could gain (up to the noise of R - 1 flights).

95 % bootstrap intervals over episodes (2000 resamples, generator seed 0).
``studies/choice_headroom`` runs::

    python studies/split_choice/split_choice.py --episodes 1000 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true max_fix_sigma_m=8 \\
        --noise-replicates 3 --out runs/split/explore

about 12 minutes on 2 cores. ``--out`` keeps the flights (``episodes.npz``) and the report
(``report.json``); with an ``episodes.npz`` of the same settings there, nothing is flown again,
and a folder of a run with other settings is refused (it is never overwritten).

``--fit-model PATH`` fits a learned split chooser on the flights (training episodes only:
reset seeds below 1,000,000; :func:`fit_split_model`), the model a
``learned_split@model='PATH'`` policy flies; ``--models`` prices such models on the flights
like the rules. The study's models (``learned_split@model='pretrained'``, ``.../s1``,
``.../s2``) were fitted with::

    python studies/split_choice/split_choice.py --episodes 1000 --first-seed 0 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true max_fix_sigma_m=8 \\
        --noise-replicates 2 --out runs/splits/train1k_s0 \\
        --fit-model studies/split_choice/policies/split_s0

and ``--first-seed 1000`` (``s1``), ``2000`` (``s2``), about 8 minutes each on 2 cores.
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


def _with_option(base: str, option: str) -> str:
    from studies.route_choice.routes import route_column_name

    return route_column_name(base, option)


def collect_episode(env: Any, base: str, seed: int, replicates: int) -> dict[str, np.ndarray]:
    """Fly ``base`` unsplit and split with every other candidate route, ``replicates`` times.

    Returns ``features`` ``(A, len(SPLIT_FEATURES))`` (arm 0 unsplit; NaN for an episode with
    one route, which is flown unsplit once), ``nav`` ``(A, replicates)`` (mean error of the
    estimate each UAV used [m]) and ``goal`` ``(A, replicates)``.
    """
    from coopnav_env.agents import make_policy
    from coopnav_env.training.evaluate import run_episode
    from studies.route_choice.routes import SPLIT_FEATURES

    planner = make_policy(_with_option(base, "route_split='los_mean'"), env)
    obs, _ = env.reset(seed=int(seed))
    planner.reset(int(seed))
    planner.act(obs)
    cands, k = planner.route_candidates, planner.route_chosen
    if len(cands) < 2:
        arms = [base]
        feats = np.full((1, len(SPLIT_FEATURES)), np.nan)
        reps = 1
    else:
        others, feats = planner.split_table(cands, k)
        arms = [base] + [
            _with_option(base, f"route_split_index={i + 1}") for i in range(len(others))
        ]
        reps = replicates
    nav = np.full((len(arms), replicates), math.nan)
    goal = np.zeros((len(arms), replicates), dtype=bool)
    for a, name in enumerate(arms):
        for r in range(reps):
            options = {"noise_stream": r} if r else None
            rec = run_episode(env, make_policy(name, env), int(seed), options=options)
            err = np.asarray(rec.nav_error_m, dtype=float)
            nav[a, r] = float(np.nanmean(err)) if np.isfinite(err).any() else math.nan
            goal[a, r] = bool(rec.success)
    if reps == 1:  # one route: every replicate is the one flight (nothing to choose)
        nav[:, 1:] = nav[:, :1]
        goal[:, 1:] = goal[:, :1]
    return {"features": feats, "nav": nav, "goal": goal}


def _chunk(
    common: tuple[dict[str, Any], str, int], seeds: list[int]
) -> list[dict[str, np.ndarray]]:
    import torch

    from coopnav_env import urban_canyon_v0

    torch.set_num_threads(1)
    env_kwargs, base, replicates = common
    env = urban_canyon_v0.parallel_env(**env_kwargs)
    return [collect_episode(env, base, s, replicates) for s in seeds]


def collect(
    env_kwargs: dict[str, Any],
    base: str,
    seeds: list[int],
    replicates: int,
    jobs: int,
    progress: bool = False,
) -> list[dict[str, np.ndarray]]:
    """:func:`collect_episode` for every seed, in ``jobs`` worker processes (seed order)."""
    from studies.route_choice.parallel import map_seeds

    return map_seeds(
        _chunk, (env_kwargs, base, replicates), seeds, jobs=jobs, desc="splits", progress=progress
    )


def price(
    eps: list[dict[str, np.ndarray]], reps: int = 2000, models: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Rules, learned split ``models`` (name: :class:`studies.route_choice.routes.RouteModel`
    of kind ``"split"``) and the expected-error oracle against the unsplit arm (see the module
    doc)."""
    from coopnav_env.training.stats import bootstrap_mean_interval
    from studies.route_choice.routes import SPLIT_FEATURE_SENSE, SPLIT_FEATURES

    def interval(d: np.ndarray) -> list[float]:
        return [float(v) for v in bootstrap_mean_interval(d, reps, np.random.default_rng(0))]

    mean = [np.nanmean(e["nav"], axis=1) for e in eps]
    unsplit = np.array([m[0] for m in mean])
    multi = [len(m) > 1 for m in mean]
    out: dict[str, Any] = {
        "episodes": len(eps),
        "episodes_with_a_split": int(sum(multi)),
        "unsplit_nav_m": float(unsplit.mean()),
        "unsplit_goal_rate": float(np.mean([e["goal"][0].mean() for e in eps])),
        "rules": {},
    }
    for j, f in enumerate(SPLIT_FEATURES):
        sense = SPLIT_FEATURE_SENSE[f]
        for scope in ("any arm", "splits only"):
            picks = []
            for e, m in zip(eps, mean):
                if len(m) < 2:
                    picks.append(0)
                elif scope == "any arm":
                    picks.append(int(np.argmax(sense * e["features"][:, j])))
                else:
                    picks.append(1 + int(np.argmax(sense * e["features"][1:, j])))
            nav = np.array([m[k] for m, k in zip(mean, picks)])
            goal = np.array([e["goal"][k].mean() for e, k in zip(eps, picks)])
            out["rules"][f"{f} ({scope})"] = {
                "nav_m": float(nav.mean()),
                "goal_rate": float(goal.mean()),
                "vs_unsplit_m": interval(nav - unsplit),
                "split_share": float(np.mean(np.array(picks) > 0)),
            }
    for name, model in (models or {}).items():
        picks = [
            0 if len(m) < 2 else int(np.argmin(model.predict(e["features"])))
            for e, m in zip(eps, mean)
        ]
        nav = np.array([m[k] for m, k in zip(mean, picks)])
        goal = np.array([e["goal"][k].mean() for e, k in zip(eps, picks)])
        out.setdefault("models", {})[name] = {
            "nav_m": float(nav.mean()),
            "goal_rate": float(goal.mean()),
            "vs_unsplit_m": interval(nav - unsplit),
            "split_share": float(np.mean(np.array(picks) > 0)),
        }
    held, diff = [], []
    for e in eps:
        nav = np.asarray(e["nav"], dtype=float)
        n_r = nav.shape[1]
        if nav.shape[0] < 2 or n_r < 2:
            held.append(float(nav[0, 0]))
            diff.append(0.0)
            continue
        v, dv = [], []
        for r in range(n_r):
            k = int(np.nanargmin(np.nanmean(np.delete(nav, r, axis=1), axis=1)))
            v.append(nav[k, r])
            dv.append(nav[k, r] - nav[0, r])
        held.append(float(np.mean(v)))
        diff.append(float(np.mean(dv)))
    out["oracle_expected_nav_m"] = float(np.mean(held))
    out["oracle_expected_vs_unsplit_m"] = interval(np.array(diff))
    return out


def fit_split_model(
    eps: list[dict[str, np.ndarray]], base: str, info: dict[str, Any] | None = None
) -> Any:
    """A learned split chooser: :func:`studies.route_choice.routes.fit_route_model` of kind
    ``"split"`` on the flights ``eps`` (each option's mean error over its replicates; ridge penalty
    by 5-fold cross-validation over episodes). Fit it on training episodes (reset seeds below
    1,000,000), never on the episodes it is to be judged on."""
    from studies.route_choice.routes import fit_route_model

    feats = [np.asarray(e["features"], dtype=float) for e in eps]
    errors = [np.nanmean(np.asarray(e["nav"], dtype=float), axis=1) for e in eps]
    return fit_route_model(feats, errors, base, kind="split", info=info)


def report_lines(rep: dict[str, Any]) -> list[str]:
    """The printed table of :func:`price`."""
    lines = [
        f"{rep['episodes']} episodes, {rep['episodes_with_a_split']} with a split to choose; "
        f"unsplit: nav {rep['unsplit_nav_m']:.3f} m, goal rate {rep['unsplit_goal_rate']:.3f}",
        f"{'rule':28s} {'nav [m]':>8s} {'goal':>6s}  {'vs unsplit [m]':24s} split",
    ]
    for k, c in [
        *rep["rules"].items(),
        *[(f"model {n}", c) for n, c in rep.get("models", {}).items()],
    ]:
        a = c["vs_unsplit_m"]
        lines.append(
            f"{k:28s} {c['nav_m']:8.3f} {c['goal_rate']:6.3f}  "
            f"{a[0]:+.3f} [{a[1]:+.3f}, {a[2]:+.3f}]      {c['split_share']:.2f}"
        )
    o = rep["oracle_expected_vs_unsplit_m"]
    lines.append(
        f"expected-error oracle (chosen on the other noise replicates): nav "
        f"{rep['oracle_expected_nav_m']:.3f} m, vs unsplit {o[0]:+.3f} [{o[1]:+.3f}, {o[2]:+.3f}]"
    )
    return lines


def main(argv: list[str] | None = None) -> int:
    from coopnav_env.training.files import atomic_path, atomic_write_text, claim_run_folder
    from studies.route_choice.route_learning import env_kwargs_from_overrides

    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--episodes", type=int, default=300, help="episodes (default: %(default)s)")
    p.add_argument(
        "--first-seed", type=int, default=1_000_000, help="first reset seed (default: %(default)s)"
    )
    p.add_argument("--env-set", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument(
        "--base", default="best_sky_route", help="column heuristic, unsplit (default: %(default)s)"
    )
    p.add_argument(
        "--noise-replicates",
        type=int,
        default=3,
        help="flights of every arm under independent noise realisations, >= 2 "
        "(default: %(default)s)",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    p.add_argument(
        "--models",
        nargs="*",
        default=[],
        metavar="PATH",
        help="learned split models to price (split_model.json files or folders)",
    )
    p.add_argument(
        "--fit-model",
        default=None,
        metavar="PATH",
        help="fit a split model on these flights and write it to PATH (a .json file, or a "
        "folder for split_model.json); only on training episodes (reset seeds below "
        "1,000,000), and never over an existing model",
    )
    p.add_argument(
        "--out", default=None, help="folder of this run: episodes.npz, settings.json, report.json"
    )
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    if args.noise_replicates < 2:
        raise SystemExit(f"--noise-replicates must be >= 2, got {args.noise_replicates}")
    if args.jobs < 1:
        raise SystemExit(f"--jobs must be >= 1, got {args.jobs}")
    fit_path = None
    if args.fit_model is not None:
        if args.first_seed < 0 or args.first_seed + args.episodes > 1_000_000:
            raise SystemExit(
                "--fit-model fits on training episodes: reset seeds in [0, 1000000) (the "
                f"held-out range starts there), got {args.first_seed}.."
                f"{args.first_seed + args.episodes - 1}"
            )
        fit_path = Path(args.fit_model)
        if fit_path.suffix != ".json":
            fit_path = fit_path / "split_model.json"
        if fit_path.exists():
            raise SystemExit(f"--fit-model: {fit_path} exists; a model is never overwritten")
    from studies.route_choice.routes import RouteModel, resolve_route_model

    models = {
        str(m): RouteModel.load(resolve_route_model(str(m), kind="split")) for m in args.models
    }
    bad = [n for n, m in models.items() if m.kind != "split"]
    if bad:
        raise SystemExit(f"--models takes split models, got route models: {bad}")
    env_kwargs = env_kwargs_from_overrides(args.env_set)
    settings = {
        "env": env_kwargs,
        "base": args.base,
        "first_seed": args.first_seed,
        "episodes": args.episodes,
        "noise_replicates": args.noise_replicates,
    }
    out = Path(args.out) if args.out else None
    eps = None
    if out is not None:
        try:
            reuse = claim_run_folder(out, settings)
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
        if reuse:
            with np.load(out / "episodes.npz") as d:
                eps = [
                    {k: d[f"{k}_{i}"] for k in ("features", "nav", "goal")}
                    for i in range(int(d["count"]))
                ]
            print(f"using the flights of {out}", file=sys.stderr)
    if eps is None:
        seeds = list(range(args.first_seed, args.first_seed + args.episodes))
        eps = collect(env_kwargs, args.base, seeds, args.noise_replicates, args.jobs, progress=True)
        if out is not None:
            arrays: dict[str, np.ndarray] = {"count": np.array(len(eps)), "seed": np.array(seeds)}
            for i, e in enumerate(eps):
                for k, v in e.items():
                    arrays[f"{k}_{i}"] = v
            with atomic_path(out / "episodes.npz") as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, **arrays)
    rep = price(eps, models=models)
    rep["settings"] = settings
    print("\n".join(report_lines(rep)))
    if out is not None:
        atomic_write_text(out / "report.json", json.dumps(rep, indent=1) + "\n")
    if fit_path is not None:
        info = {
            "env": env_kwargs,
            "first_seed": args.first_seed,
            "episodes": args.episodes,
            "noise_replicates": args.noise_replicates,
        }
        model = fit_split_model(eps, args.base, info=info)
        model.save(fit_path)
        cv = model.info["cv_chosen_minus_mean_m"][str(model.alpha)]
        print(
            f"split model: alpha {model.alpha}, cross-validated choice {cv:+.3f} m against the "
            f"mean option; saved {fit_path}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
