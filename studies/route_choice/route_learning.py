"""Learn which route to fly from flown episodes: the route models of this study.

``python studies/route_choice/route_learning.py --help`` (formerly ``coopnav train-routes``).

A learned *route model* (:class:`studies.route_choice.routes.RouteModel`) scores the equally short
street routes of an episode by the satellites the city map predicts along them and picks the one it
predicts the lowest navigation error for; a column heuristic (``ceiling_column`` by default) flies
it. This command teaches it by experience:

1. **Collect.** For every training episode (reset seeds below the held-out range, see
   ``--first-seed``) the heuristic flies *every* candidate route (the same reset seed, so the
   same city, satellites and start), and each flight's mean ``nav`` error is recorded beside
   the route's features, as planned on board at the first step. This is a contextual bandit
   with full feedback: the outcome of every arm is observed. With ``--noise-replicates R``
   every route is flown R times under independent noise realisations of the same episode
   (the environment's ``noise_stream`` reset option) and the model learns from their mean,
   the route's expected error with less of one flight's noise.
2. **Fit.** Ridge regression of each route's error, relative to the mean of its episode's
   routes, on the standardised features; the penalty is chosen by 5-fold cross-validation
   over episodes of the error of the route each penalty's model would choose.

The run folder holds ``run.json`` (settings, sizes, timings, cross-validation),
``episodes.npz`` (every flown route: seed, index, features, errors, goal) and
``route_model.json``; fly the model as the policy ``learned_route@model='RUN_DIR'`` (registered
by ``studies.route_choice.routes``).
Collection is saved every ``--block`` episodes, and a run started again with the same
``--out`` and settings continues where it stopped; a finished run (``route_model.json``
present) is never overwritten.

Example (the study's training set of seed 0, about 6 minutes on 2 cores)::

    python studies/route_choice/route_learning.py --seed 0 --episodes 1000 \\
        --env-set preset=urban_nlos_3dma \\
        dead_reckoning_noise=true max_fix_sigma_m=8 --out runs/routes/s0
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# run as a script: the repository root on the path, for the `studies` package
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

TRAIN_SEED_BASE = 500_000
"""Reset seed of the first training episode of ``--seed 0``; seed ``k`` starts
``TRAIN_SEED_STRIDE * k`` later. Below the held-out range (reset seeds from 1,000,000)."""
TRAIN_SEED_STRIDE = 100_000


def _with_option(base: str, option: str) -> str:
    """``base`` (a column heuristic's name, options after ``@``) as a ``route_column`` policy
    name with ``option`` added."""
    from studies.route_choice.routes import route_column_name

    return route_column_name(base, option)


def collect_episode(
    env: Any, base: str, seed: int, max_turns: int = 3, replicates: int = 1
) -> dict[str, np.ndarray]:
    """Fly every shortest route of episode ``seed`` with heuristic ``base``.

    Returns ``features`` ``(R, F)`` (:func:`studies.route_choice.routes.route_features`, as the
    heuristic plans them at the first step) and, per route, ``nav`` (mean error of the estimate each
    UAV used [m]), ``coop`` (mean cooperative-fix error [m], NaN without a fix) and ``goal``.
    An episode with one route is flown once (its features are NaN: nothing to choose).

    With ``replicates`` > 1 every route is flown that many times, under independent noise
    realisations of the same episode (the ``noise_stream`` reset option; the first is the
    plain episode): ``nav`` and ``coop`` are then the means over the flights, ``goal`` whether
    every flight reached the goal, and ``nav_reps`` ``(R, replicates)`` keeps each flight's
    error. The route's *expected* error is what the choice is about; the noise of one flight
    is most of a single flight's difference between two routes.
    """
    if isinstance(replicates, bool) or not isinstance(replicates, (int, np.integer)):
        raise ValueError(f"replicates must be an int >= 1, got {replicates!r}")
    if replicates < 1:
        raise ValueError(f"replicates must be >= 1, got {replicates}")
    from coopnav_env.agents import make_policy
    from coopnav_env.training.evaluate import run_episode

    planner = make_policy(
        _with_option(base, f"route_choice='los_mean',route_max_turns={int(max_turns)}"), env
    )
    obs, _ = env.reset(seed=int(seed))
    planner.reset(int(seed))
    planner.act(obs)  # plans the route: candidates and their features
    feats = planner.route_feature_table
    n_routes = len(planner.route_candidates)
    if feats is None or n_routes < 2:
        from studies.route_choice.routes import ROUTE_FEATURES

        n_routes = 1
        feats = np.full((1, len(ROUTE_FEATURES)), np.nan)
    nav = np.full((n_routes, replicates), math.nan)
    coop = np.full((n_routes, replicates), math.nan)
    goal = np.zeros((n_routes, replicates), dtype=bool)
    for k in range(n_routes):
        opt = f"route_max_turns={int(max_turns)}" + (f",route_index={k}" if k else "")
        for r in range(replicates):
            options = {"noise_stream": r} if r else None
            rec = run_episode(
                env, make_policy(_with_option(base, opt), env), int(seed), options=options
            )
            err = np.asarray(rec.nav_error_m, dtype=float)
            c = np.asarray(rec.coop_error_m, dtype=float)
            nav[k, r] = float(np.nanmean(err)) if np.isfinite(err).any() else math.nan
            coop[k, r] = float(np.nanmean(c)) if np.isfinite(c).any() else math.nan
            goal[k, r] = bool(rec.success)
    out = {
        "features": np.asarray(feats, dtype=float),
        "nav": nav.mean(axis=1),
        "coop": coop.mean(axis=1),
        "goal": goal.all(axis=1),
    }
    if replicates > 1:
        out["nav_reps"] = nav
    return out


def _collect_chunk(common: tuple[dict[str, Any], str, int, int], seeds: list[int]) -> list[dict]:
    import torch

    from coopnav_env import urban_canyon_v0

    torch.set_num_threads(1)
    env_kwargs, base, max_turns, replicates = common
    env = urban_canyon_v0.parallel_env(**dict(env_kwargs))
    return [collect_episode(env, base, s, max_turns, replicates) for s in seeds]


def collect(
    env_kwargs: Mapping[str, Any],
    base: str,
    seeds: Sequence[int],
    *,
    max_turns: int = 3,
    jobs: int = 2,
    replicates: int = 1,
    progress: bool = False,
) -> list[dict[str, np.ndarray]]:
    """:func:`collect_episode` for every seed, in ``jobs`` worker processes (seed order;
    :func:`studies.route_choice.parallel.map_seeds`, with a progress bar when ``progress``)."""
    from studies.route_choice.parallel import map_seeds

    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    return map_seeds(
        _collect_chunk,
        (dict(env_kwargs), base, int(max_turns), replicates),
        [int(s) for s in seeds],
        jobs=int(jobs),
        desc="routes",
        progress=progress,
    )


def episodes_to_arrays(seeds: Sequence[int], eps: Sequence[Mapping[str, np.ndarray]]) -> dict:
    """Flatten collected episodes to one row per flown route (what ``episodes.npz`` holds)."""
    rows: dict[str, list[Any]] = {k: [] for k in ("seed", "route", "nav", "coop", "goal")}
    feats = []
    reps = []
    for s, e in zip(seeds, eps):
        r = len(e["nav"])
        rows["seed"] += [int(s)] * r
        rows["route"] += list(range(r))
        rows["nav"] += list(e["nav"])
        rows["coop"] += list(e["coop"])
        rows["goal"] += list(e["goal"])
        feats.append(np.asarray(e["features"], dtype=float).reshape(r, -1))
        if "nav_reps" in e:
            reps.append(np.asarray(e["nav_reps"], dtype=float).reshape(r, -1))
    out = {k: np.asarray(v) for k, v in rows.items()}
    out["features"] = np.concatenate(feats) if feats else np.zeros((0, 0))
    if reps:
        out["nav_reps"] = np.concatenate(reps)
    return out


def arrays_to_episodes(d: Mapping[str, np.ndarray]) -> tuple[list[int], list[dict]]:
    """The inverse of :func:`episodes_to_arrays`: seeds in order, and per episode its routes."""
    seeds: list[int] = []
    eps: list[dict] = []
    seed_col = np.asarray(d["seed"])
    for s in dict.fromkeys(seed_col.tolist()):
        m = seed_col == s
        seeds.append(int(s))
        keys = ("features", "nav", "coop", "goal") + (("nav_reps",) if "nav_reps" in d else ())
        eps.append({k: np.asarray(d[k])[m] for k in keys})
    return seeds, eps


_EPISODE_KEYS = ("seed", "route", "features", "nav", "coop", "goal")
"""The arrays every ``episodes.npz`` holds (``nav_reps`` too with ``--noise-replicates``)."""


def load_episodes(path: Path) -> tuple[list[int], list[dict]]:
    """The episodes collected in ``path`` (an ``episodes.npz``), by
    :func:`arrays_to_episodes`; ``ValueError`` naming the file when it does not load, lacks
    an array, or its arrays do not have one row per flown route."""
    try:
        with np.load(path, allow_pickle=False) as d:
            arrays = dict(d)
    except Exception as exc:  # a damaged zip, a truncated array: numpy's own errors vary
        raise ValueError(
            f"{path} does not load ({type(exc).__name__}: {exc}); remove it to collect "
            "again, or use another --out"
        ) from exc
    missing = [k for k in _EPISODE_KEYS if k not in arrays]
    if missing:
        raise ValueError(
            f"{path} lacks {', '.join(map(repr, missing))} (it holds {sorted(arrays)}); remove "
            "it to collect again, or use another --out"
        )
    rows = {k: len(np.asarray(v)) for k, v in arrays.items()}
    if len(set(rows.values())) != 1 or np.ndim(arrays["features"]) != 2:
        raise ValueError(f"{path} has arrays of different lengths ({rows}); it is damaged")
    return arrays_to_episodes(arrays)


def _read_run_json(path: Path) -> dict[str, Any]:
    """A ``run.json`` as a dict; ``ValueError`` naming it when it is no JSON object."""
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON ({exc}); use another --out") from exc
    if not isinstance(data, dict):
        raise ValueError(
            f"{path} must hold a JSON object, got a {type(data).__name__}; this is not a "
            "train-routes run folder: use another --out"
        )
    return data


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the script (:func:`main`)."""
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = __doc__.split("\n\n", 1)[1] if __doc__ else None
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="training seed: picks the training episodes (reset seeds from "
        f"{TRAIN_SEED_BASE:,} + {TRAIN_SEED_STRIDE:,} x SEED) (default: %(default)s)",
    )
    parser.add_argument(
        "--episodes", type=int, default=1000, help="training episodes (default: %(default)s)"
    )
    parser.add_argument(
        "--first-seed",
        type=int,
        default=None,
        help="reset seed of the first training episode, below 1,000,000 (the held-out "
        "range); default from --seed",
    )
    parser.add_argument(
        "--env-set",
        nargs="*",
        action="extend",
        default=[],
        metavar="KEY=VALUE",
        help="environment settings (as coopnav train), e.g. preset=urban_nlos_3dma (default: none)",
    )
    parser.add_argument(
        "--base",
        default="ceiling_column",
        help="the column heuristic that flies the routes (default: %(default)s)",
    )
    parser.add_argument(
        "--max-turns", type=int, default=3, help="most turns of a route (default: %(default)s)"
    )
    parser.add_argument(
        "--noise-replicates",
        type=int,
        default=1,
        help="flights of every route under independent noise realisations of the same "
        "episode; the model learns from their mean error (default: %(default)s)",
    )
    parser.add_argument(
        "--block", type=int, default=100, help="episodes per saved block (default: %(default)s)"
    )
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    parser.add_argument("--out", required=True, help="run folder (one run per folder)")


def env_kwargs_from_overrides(items: Sequence[str]) -> dict[str, Any]:
    """Environment keyword arguments from ``KEY=VALUE`` items (values parsed as YAML),
    checked by building the config, so that a bad setting fails before anything is flown."""
    from coopnav_env.envs.config import make_config
    from coopnav_env.training.config import apply_overrides

    kwargs = apply_overrides({}, list(items))
    make_config(**kwargs)  # fails early, naming the bad setting
    return kwargs


def run(args: argparse.Namespace) -> int:
    """Collect (resumably), fit and save; prints the cross-validated choice."""
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy
    from coopnav_env.sim.file_city import FileCity
    from coopnav_env.training.files import ensure_folder, folder_lock
    from studies.route_choice.routes import ROUTE_FEATURES

    if args.episodes < 5:
        raise ValueError(f"--episodes must be >= 5 (5-fold cross-validation), got {args.episodes}")
    if args.block < 1 or args.jobs < 1:
        raise ValueError(f"--block and --jobs must be >= 1, got {args.block} and {args.jobs}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.noise_replicates < 1:
        raise ValueError(f"--noise-replicates must be >= 1, got {args.noise_replicates}")
    first = (
        TRAIN_SEED_BASE + TRAIN_SEED_STRIDE * args.seed
        if args.first_seed is None
        else args.first_seed
    )
    if not 0 <= first or first + args.episodes > 1_000_000:
        raise ValueError(
            f"training episodes must have reset seeds in [0, 1000000) (the held-out range starts "
            f"there), got {first}..{first + args.episodes - 1}"
        )
    env_kwargs = env_kwargs_from_overrides(args.env_set)
    # a column heuristic that can choose routes, with a valid --max-turns (fails early)
    probe = _with_option(args.base, f"route_choice='los_mean',route_max_turns={args.max_turns}")
    env = urban_canyon_v0.parallel_env(**env_kwargs)
    make_policy(probe, env)
    env.reset(seed=first)
    if isinstance(env.unwrapped.world.city, FileCity):  # before any episode is collected
        raise ValueError(
            f"--env-set city={env_kwargs.get('city')}: a city read from a file has one route "
            "from start to goal (through its free space), so there is no route to choose "
            "between; route learning needs a grid city (leave city out, or give a grid city)"
        )
    out = Path(args.out)
    settings = {
        "env": env_kwargs,
        "base": args.base,
        "first_seed": first,
        "episodes": args.episodes,
        "max_turns": args.max_turns,
        "features": list(ROUTE_FEATURES),
    }
    if args.noise_replicates != 1:  # (absent from the settings of earlier runs)
        settings["noise_replicates"] = args.noise_replicates
    ensure_folder(out)
    with folder_lock(out):  # one command at a time in a folder (a second fails at once)
        return _collect_and_fit(args, out, settings, env_kwargs, first)


def _collect_and_fit(
    args: argparse.Namespace,
    out: Path,
    settings: dict[str, Any],
    env_kwargs: dict[str, Any],
    first: int,
) -> int:
    """The locked part of :func:`run`: check the folder, collect what is missing, fit, save."""
    from coopnav_env.training.files import atomic_path, write_json
    from studies.route_choice.routes import fit_route_model

    model_path = out / "route_model.json"
    if model_path.exists():
        raise ValueError(f"{out} holds a finished run (route_model.json); use another --out")
    run_json = out / "run.json"
    data_path = out / "episodes.npz"
    seeds: list[int] = []
    eps: list[dict] = []
    from coopnav_env.training.runs import claiming_command, recorded_backend

    # another command's folder: a report's claim, or a coopnav train run (its run.json too)
    owner = claiming_command(out) or ("coopnav train" if recorded_backend(out) else None)
    if owner is not None:
        raise ValueError(
            f"--out {out} exists and is not a train-routes run folder: it holds the outputs of "
            f"`{owner}`; use another --out"
        )
    if run_json.exists():
        old = _read_run_json(run_json)
        if old.get("settings") != json.loads(json.dumps(settings)):
            raise ValueError(
                f"{out} belongs to a run with other settings ({old.get('settings')}); use "
                "another --out"
            )
        if data_path.exists():
            seeds, eps = load_episodes(data_path)
            if seeds != list(range(first, first + len(seeds))) or len(seeds) > args.episodes:
                raise ValueError(
                    f"{data_path} holds episodes of other reset seeds than this run's "
                    f"({first}..{first + args.episodes - 1}); remove it to collect again, or "
                    "use another --out"
                )
            print(f"resuming {out}: {len(seeds)} of {args.episodes} episodes collected")
    elif out.exists() and any(not p.name.startswith(".") for p in out.iterdir()):
        raise ValueError(f"--out {out} exists and is not a train-routes run folder")
    out.mkdir(parents=True, exist_ok=True)
    started = time.time()
    write_json(run_json, {"settings": settings, "status": "collecting"})
    all_seeds = list(range(first, first + args.episodes))
    todo = all_seeds[len(seeds) :]
    bar = None
    try:
        from tqdm import tqdm

        bar = tqdm(total=args.episodes, initial=len(seeds), unit="episode", desc="routes")
    except ImportError:  # pragma: no cover - tqdm comes with the train extra
        pass
    for i in range(0, len(todo), args.block):
        block = todo[i : i + args.block]
        eps += collect(
            env_kwargs,
            args.base,
            block,
            max_turns=args.max_turns,
            jobs=args.jobs,
            replicates=args.noise_replicates,
        )
        seeds += block
        arrays = episodes_to_arrays(seeds, eps)
        with atomic_path(data_path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        if bar is not None:
            bar.update(len(block))
    if bar is not None:
        bar.close()
    collect_s = time.time() - started
    feats = [e["features"] for e in eps]
    errors = [e["nav"] for e in eps]
    model = fit_route_model(
        feats,
        errors,
        args.base,
        info={
            "env": env_kwargs,
            "first_seed": first,
            "training_seed": args.seed,
            "noise_replicates": args.noise_replicates,
        },
    )
    model.save(model_path)
    n_multi = sum(len(e) > 1 for e in errors)
    summary = {
        "settings": settings,
        "status": "finished",
        "episodes_with_a_choice": n_multi,
        "routes_flown": int(sum(len(e) for e in errors)),
        "collect_s": round(collect_s, 1),
        "alpha": model.alpha,
        "cv_chosen_minus_mean_m": model.info["cv_chosen_minus_mean_m"],
    }
    write_json(run_json, summary)
    cv = model.info["cv_chosen_minus_mean_m"][str(model.alpha)]
    print(
        f"route model: {n_multi} of {len(errors)} episodes with a choice, alpha {model.alpha}, "
        f"cross-validated choice {cv:+.3f} m against the mean route; saved {model_path}"
    )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the arguments (:func:`add_arguments`) and :func:`run`; returns the exit status
    (2, with a one-line message, for a bad setting or output folder)."""
    parser = argparse.ArgumentParser(
        prog="python studies/route_choice/route_learning.py",
        description=(__doc__ or "").split("\n\n")[0],
    )
    add_arguments(parser)
    args = parser.parse_args(argv)
    from coopnav_env.training.cli import usage_errors

    try:
        return int(run(args) or 0)
    except usage_errors() as exc:  # a bad setting or folder: one line, exit status 2
        print(f"route_learning.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
