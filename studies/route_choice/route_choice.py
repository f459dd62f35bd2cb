"""Route choice on held-out episodes: every route flown, every one-feature rule and model priced.

Flies *every* equally short street route of each episode with a column heuristic
(``ceiling_column`` by default; :func:`studies.route_choice.route_learning.collect`, the same
collection ``route_learning.py`` uses, here on held-out reset seeds), then prices choosing by
each one-feature rule of :data:`studies.route_choice.routes.ROUTE_FEATURES` (the route with the
best value of the feature) and by each learned route model given with ``--models``: per choice,
the mean ``nav`` error, the goal rate, and the paired difference to the first route (what the
heuristic flies without a choice) and to the best rule, with 95 % bootstrap intervals over
episodes (2000 resamples, generator seed 0). A choice's flight is the flight of the route it
picks, so one collection prices every rule and model exactly as if each had flown (the
heuristics are deterministic given the reset seed). Also printed: the *noise-selected* oracle,
the lowest of each episode's flown routes, an optimistic bound (it picks on the noise too).

With ``--noise-replicates R`` (R >= 2) every route is flown R times under independent noise
realisations of the same episode (the environment's ``noise_stream`` reset option): rules and
models are priced on the mean of the R flights (their *expected* error, with less noise), and
the *expected-error oracle* is printed too: per episode, the route with the lowest mean over
R - 1 of the flights, priced on the remaining one (each flight held out in turn). Unlike the
noise-selected oracle it does not pick on the noise it is priced on, so it measures how much
a choice from the map could gain over the best rule at most (up to the noise of R - 1
flights), i.e. what a learned route model could find.

The study (``studies/route_choice/README.md``) runs::

    python studies/route_choice/route_choice.py --episodes 1000 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true max_fix_sigma_m=8 \\
        --models runs/routes/g8_s0 runs/routes/g8_s1 runs/routes/g8_s2 \\
        --out runs/routes/explore

``--within-turns K`` (with replicates) also prices what routes with more turns add: the best
rule and the expected-error oracle choosing among all the routes (up to ``--max-turns``)
against the same rule among the routes of at most K turns (by their ``turns`` feature, the
route's waypoints less two), paired by episode. Routes with
more turns are what a swarm that re-plans at intersections could fly. ``studies/choice_headroom``
runs::

    python studies/route_choice/route_choice.py --episodes 500 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true max_fix_sigma_m=8 \\
        --noise-replicates 3 --max-turns 6 --within-turns 3 --out runs/routes/explore_t6_r3

``--out`` keeps the collection (``episodes.npz``, as ``route_learning.py`` writes it) and
the printed report (``report.json``); with an existing ``episodes.npz`` of the same settings
the routes are not flown again, and a folder of a run with other settings is refused (it is
never overwritten).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _oracle_expected(
    eps: list[dict[str, np.ndarray]], ref_picks: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Per episode: the expected-error oracle's held-out error, and its paired difference to
    the route ``ref_picks`` picks (see the module doc)."""
    held, diff = [], []
    for e, kb in zip(eps, ref_picks):
        reps_e = np.asarray(e["nav_reps"], dtype=float)
        n_r = reps_e.shape[1]
        if len(e["nav"]) < 2 or n_r < 2:
            held.append(float(np.nanmean(reps_e[kb])))
            diff.append(0.0)
            continue
        v, dv = [], []
        for r in range(n_r):
            k = int(np.nanargmin(np.nanmean(np.delete(reps_e, r, axis=1), axis=1)))
            v.append(reps_e[k, r])
            dv.append(reps_e[k, r] - reps_e[kb, r])
        held.append(float(np.mean(v)))
        diff.append(float(np.mean(dv)))
    return np.array(held), np.array(diff)


def _rule_picks(eps: list[dict[str, np.ndarray]], feature: str) -> list[int]:
    from studies.route_choice.routes import FEATURE_SENSE, ROUTE_FEATURES

    j = ROUTE_FEATURES.index(feature)
    return [
        0 if len(e["nav"]) < 2 else int(np.argmax(FEATURE_SENSE[feature] * e["features"][:, j]))
        for e in eps
    ]


def within_turns(eps: list[dict[str, np.ndarray]], max_turns: int) -> list[dict[str, np.ndarray]]:
    """``eps`` with only the routes of at most ``max_turns`` turns (the ``turns`` feature),
    in their order; an episode with one route keeps it."""
    from studies.route_choice.routes import ROUTE_FEATURES

    j = ROUTE_FEATURES.index("turns")
    out = []
    for e in eps:
        if len(e["nav"]) < 2:
            out.append(e)
            continue
        keep = np.flatnonzero(e["features"][:, j] <= max_turns)
        if keep.size == 0:  # (the first route has the fewest turns; kept whatever they are)
            keep = np.array([0])
        out.append({k: np.asarray(v)[keep] for k, v in e.items()})
    return out


def compare_within_turns(
    eps: list[dict[str, np.ndarray]], rule: str, max_turns: int, reps: int = 2000
) -> dict[str, Any]:
    """The rule ``rule`` (a :data:`~studies.route_choice.routes.ROUTE_FEATURES` name) and the
    expected-error oracle choosing among all the routes of ``eps``, against the same rule choosing
    among the routes of at most ``max_turns`` turns only, paired by episode (means over the noise
    replicates; 95 % bootstrap intervals): what routes with more turns, such as a swarm that
    re-plans at intersections could fly, add to a choice."""
    from coopnav_env.training.stats import bootstrap_mean_interval

    if not all("nav_reps" in e for e in eps):
        raise ValueError("compare_within_turns needs noise replicates (--noise-replicates >= 2)")
    sub = within_turns(eps, max_turns)
    ref = np.array([e["nav"][k] for e, k in zip(sub, _rule_picks(sub, rule))])
    full = np.array([e["nav"][k] for e, k in zip(eps, _rule_picks(eps, rule))])
    sub_oracle, _ = _oracle_expected(sub, _rule_picks(sub, rule))
    full_oracle, _ = _oracle_expected(eps, _rule_picks(eps, rule))

    def interval(d: np.ndarray) -> list[float]:
        return [float(v) for v in bootstrap_mean_interval(d, reps, np.random.default_rng(0))]

    multi = [len(e["nav"]) > 1 for e in eps]
    return {
        "max_turns": int(max_turns),
        "rule": rule,
        "routes_per_episode_within": float(
            np.mean([len(e["nav"]) for e, m in zip(sub, multi) if m])
        )
        if any(multi)
        else 1.0,
        "routes_per_episode_all": float(np.mean([len(e["nav"]) for e, m in zip(eps, multi) if m]))
        if any(multi)
        else 1.0,
        "rule_within_nav_m": float(ref.mean()),
        "rule_all_nav_m": float(full.mean()),
        "oracle_within_nav_m": float(sub_oracle.mean()),
        "oracle_all_nav_m": float(full_oracle.mean()),
        "rule_all_vs_rule_within_m": interval(full - ref),
        "oracle_within_vs_rule_within_m": interval(sub_oracle - ref),
        "oracle_all_vs_rule_within_m": interval(full_oracle - ref),
        "oracle_all_vs_oracle_within_m": interval(full_oracle - sub_oracle),
    }


def price_choices(
    eps: list[dict[str, np.ndarray]], models: dict[str, Any], reps: int = 2000
) -> dict[str, Any]:
    """Mean error, goal rate and paired differences of every rule and model on ``eps``."""
    from coopnav_env.training.stats import bootstrap_mean_interval
    from studies.route_choice.routes import FEATURE_SENSE, ROUTE_FEATURES

    first = np.array([e["nav"][0] for e in eps])
    picks: dict[str, list[int]] = {}
    for j, f in enumerate(ROUTE_FEATURES):
        picks[f"rule {f}"] = [
            0 if len(e["nav"]) < 2 else int(np.argmax(FEATURE_SENSE[f] * e["features"][:, j]))
            for e in eps
        ]
    for name, m in models.items():
        picks[f"model {name}"] = [
            0 if len(e["nav"]) < 2 else int(np.argmin(m.predict(e["features"]))) for e in eps
        ]
    nav = {k: np.array([e["nav"][i] for e, i in zip(eps, p)]) for k, p in picks.items()}
    goal = {k: np.array([e["goal"][i] for e, i in zip(eps, p)]) for k, p in picks.items()}
    rules = [k for k in nav if k.startswith("rule ")]
    best = min(rules, key=lambda k: float(nav[k].mean()))
    out: dict[str, Any] = {"episodes": len(eps), "best_rule": best, "choices": {}}
    out["first_route"] = {
        "nav_m": float(first.mean()),
        "goal_rate": float(np.mean([e["goal"][0] for e in eps])),
    }
    out["episodes_with_a_choice"] = int(sum(len(e["nav"]) > 1 for e in eps))
    out["oracle_noise_selected_nav_m"] = float(np.mean([np.nanmin(e["nav"]) for e in eps]))
    if all("nav_reps" in e for e in eps):
        held, diff = _oracle_expected(eps, picks[best])
        rng = np.random.default_rng(0)
        out["oracle_expected_nav_m"] = float(np.mean(held))
        out["oracle_expected_vs_best_rule_m"] = [
            float(v) for v in bootstrap_mean_interval(np.array(diff), reps, rng)
        ]
    for k in nav:
        rng = np.random.default_rng(0)
        d0 = bootstrap_mean_interval(nav[k] - first, reps, rng)
        rng = np.random.default_rng(0)
        d1 = bootstrap_mean_interval(nav[k] - nav[best], reps, rng)
        out["choices"][k] = {
            "nav_m": float(nav[k].mean()),
            "goal_rate": float(goal[k].mean()),
            "vs_first_route_m": [float(v) for v in d0],
            "vs_best_rule_m": [float(v) for v in d1],
            "differs_from_first": float(np.mean(np.array(picks[k]) != 0)),
        }
    return out


def report_lines(rep: dict[str, Any]) -> list[str]:
    """The printed table of :func:`price_choices`."""
    fr = rep["first_route"]
    lines = [
        f"{rep['episodes']} episodes, {rep['episodes_with_a_choice']} with more than one route; "
        f"first route: nav {fr['nav_m']:.3f} m, goal rate {fr['goal_rate']:.3f}; "
        f"noise-selected oracle {rep['oracle_noise_selected_nav_m']:.3f} m",
        f"{'choice':24s} {'nav [m]':>8s} {'goal':>6s}  {'vs first route [m]':24s} "
        f"{'vs best rule [m]':24s} changed",
    ]
    for k, c in rep["choices"].items():
        a, b = c["vs_first_route_m"], c["vs_best_rule_m"]
        lines.append(
            f"{k:24s} {c['nav_m']:8.3f} {c['goal_rate']:6.3f}  "
            f"{a[0]:+.3f} [{a[1]:+.3f}, {a[2]:+.3f}]      {b[0]:+.3f} [{b[1]:+.3f}, {b[2]:+.3f}]"
            f"      {c['differs_from_first']:.2f}"
        )
    lines.append(f"best rule: {rep['best_rule']}")
    if "oracle_expected_nav_m" in rep:
        o = rep["oracle_expected_vs_best_rule_m"]
        lines.append(
            f"expected-error oracle (chosen on the other noise replicates): nav "
            f"{rep['oracle_expected_nav_m']:.3f} m, vs the best rule {o[0]:+.3f} "
            f"[{o[1]:+.3f}, {o[2]:+.3f}]"
        )
    if "within_turns" in rep:
        w = rep["within_turns"]

        def ci(key: str) -> str:
            a = w[key]
            return f"{a[0]:+.3f} [{a[1]:+.3f}, {a[2]:+.3f}]"

        lines += [
            f"routes of at most {w['max_turns']} turns only ({w['routes_per_episode_within']:.1f} "
            f"per episode with a choice, against {w['routes_per_episode_all']:.1f}): "
            f"rule {w['rule']} {w['rule_within_nav_m']:.3f} m, oracle "
            f"{w['oracle_within_nav_m']:.3f} m",
            f"  against rule {w['rule']} within {w['max_turns']} turns: the same rule on all "
            f"routes {ci('rule_all_vs_rule_within_m')}; oracle within "
            f"{ci('oracle_within_vs_rule_within_m')}; oracle on all routes "
            f"{ci('oracle_all_vs_rule_within_m')}",
            f"  oracle on all routes - oracle within {w['max_turns']} turns: "
            f"{ci('oracle_all_vs_oracle_within_m')}",
        ]
    return lines


def main(argv: list[str] | None = None) -> int:
    from coopnav_env.training.files import atomic_path, atomic_write_text, claim_run_folder
    from studies.route_choice.route_learning import (
        arrays_to_episodes,
        collect,
        env_kwargs_from_overrides,
        episodes_to_arrays,
    )
    from studies.route_choice.routes import RouteModel

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
        "--base", default="ceiling_column", help="column heuristic (default: %(default)s)"
    )
    p.add_argument("--max-turns", type=int, default=3, help="most turns (default: %(default)s)")
    p.add_argument("--models", nargs="*", default=[], help="route models (run folders or files)")
    p.add_argument(
        "--noise-replicates",
        type=int,
        default=1,
        help="flights of every route under independent noise realisations (default: %(default)s)",
    )
    p.add_argument(
        "--within-turns",
        type=int,
        default=None,
        metavar="K",
        help="also compare the best rule and the expected-error oracle on all routes with the "
        "same rule on the routes whose turns feature is at most K (< --max-turns; needs "
        "--noise-replicates)",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    p.add_argument(
        "--out", default=None, help="folder of this run: episodes.npz, settings.json, report.json"
    )
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    if args.noise_replicates < 1:
        raise SystemExit(f"--noise-replicates must be >= 1, got {args.noise_replicates}")
    if args.within_turns is not None:
        if not 0 <= args.within_turns < args.max_turns:
            raise SystemExit(
                f"--within-turns must be in [0, --max-turns - 1] = [0, {args.max_turns - 1}], "
                f"got {args.within_turns}"
            )
        if args.noise_replicates < 2:
            raise SystemExit("--within-turns needs --noise-replicates >= 2")
    env_kwargs = env_kwargs_from_overrides(args.env_set)
    settings = {
        "env": env_kwargs,
        "base": args.base,
        "first_seed": args.first_seed,
        "episodes": args.episodes,
        "max_turns": args.max_turns,
    }
    if args.noise_replicates != 1:  # (absent from the settings of earlier collections)
        settings["noise_replicates"] = args.noise_replicates
    out = Path(args.out) if args.out else None
    eps = None
    if out is not None:
        try:
            reuse = claim_run_folder(out, settings)
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
        if reuse:
            with np.load(out / "episodes.npz") as d:
                _, eps = arrays_to_episodes(dict(d))
            print(f"using the routes flown before in {out}", file=sys.stderr)
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    if eps is None:
        eps = collect(
            env_kwargs,
            args.base,
            seeds,
            max_turns=args.max_turns,
            jobs=args.jobs,
            replicates=args.noise_replicates,
            progress=True,
        )
        if out is not None:
            with atomic_path(out / "episodes.npz") as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, **episodes_to_arrays(seeds, eps))
    models = {str(m): RouteModel.load(m) for m in args.models}
    rep = price_choices(eps, models)
    if args.within_turns is not None:
        rule = rep["best_rule"].removeprefix("rule ")
        rep["within_turns"] = compare_within_turns(eps, rule, args.within_turns)
    rep["settings"] = settings
    print("\n".join(report_lines(rep)))
    if out is not None:
        atomic_write_text(out / "report.json", json.dumps(rep, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
