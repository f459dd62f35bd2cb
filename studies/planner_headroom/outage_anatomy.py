"""Anatomy of the cooperative fix's outages under a heuristic, and whether map counts steer.

Flies a heuristic (default ``ceiling_column``) through held-out episodes, counts at every step
the satellites each UAV's receiver would use at five candidate positions (:func:`candidate_sky`,
what the environment's former ``obs_candidate_sky`` observed; it does not change how a
heuristic flies) and prints:

1. why UAV-steps have no cooperative fix: the share of each ``coop_status``
   (:class:`coopnav_env.nav.NavStatus`; ``OK`` there means a fix the integrity gate rejected)
   among the UAV-steps without one, and the share of swarm steps when no UAV has one (a
   *swarm-wide outage*);
2. how well counts a receiver can compute predict the onset of a swarm-wide outage: for every
   swarm step with a fix, whether an outage begins within the next ``k`` steps (k = 1, 3, 5),
   ranked by each of three counts (fewer: riskier), as the area under the ROC curve (0.5:
   no better than chance): the satellites the UAVs receive now (``n_sats``, mean over the
   swarm), and from :func:`candidate_sky` the satellites a UAV's receiver would use 10 m
   ahead along its route (mean over the swarm) and the swarm's pooled count there;
3. with ``--steer GAIN:THRESHOLD ...``: the heuristic plus a hand-written use of those counts,
   paired with the heuristic alone on the same episodes. Whenever a UAV's pooled count 10 m
   ahead falls below ``THRESHOLD`` satellites, it is pushed (``GAIN`` of its maximum speed)
   toward the best of the candidates here, left and right (scored by the pooled count plus a
   quarter of its own), when that one beats the point ahead: sideways toward a side
   candidate, back (braking) toward where it is. Mean ``nav`` and ``coop`` errors
   (definitions of ``coopnav study``) and goal rate, and the paired ``nav`` difference with a
   95 % bootstrap interval over episodes (2000 resamples, generator seed 0).

The study (``studies/planner_headroom/README.md``) uses it::

    python studies/planner_headroom/outage_anatomy.py --episodes 200 --first-seed 1000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true --steer 0.15:7 0.3:9

With ``--out FILE`` the figures are also written to a JSON file (a temporary name, then
renamed into place).
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


#: Distance along the route of the near candidates [m], their lateral offset to either side
#: [m], and the distance of the far candidate [m].
CANDIDATE_AHEAD_M = 10.0
CANDIDATE_SIDE_M = 6.0
CANDIDATE_FAR_M = 25.0


def route_points(env: Any, distances_m: tuple[float, ...]) -> np.ndarray:
    """``(D, N, 3)``: each UAV's point ``distances_m[d]`` metres along its route.

    From the UAV's *estimated* position, straight to its next waypoint and on along the
    route's polyline (past its end: on along the last leg's direction; with no leg, the
    position itself), at the estimated altitude clamped to the flight band.
    """
    base = getattr(env, "unwrapped", env)
    ep = base._epoch
    route = np.asarray(base.world.route_xy_m, dtype=float)
    kin = base.config.kinematics
    est = np.asarray(ep.nav_pos_enu_m, dtype=float)
    z = np.clip(est[:, 2], kin.altitude_min_m, kin.altitude_max_m)
    out = np.empty((len(distances_m), est.shape[0], 3))
    for i in range(est.shape[0]):
        pts = np.vstack([est[i, :2], route[int(ep.next_waypoint[i]) :]])
        seg = np.diff(pts, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        cum = np.concatenate([[0.0], np.cumsum(seg_len)])
        for d, dist in enumerate(distances_m):
            if cum[-1] <= 0.0:
                xy = est[i, :2]
            elif dist >= cum[-1]:  # past the end: on along the last non-zero leg
                j = int(np.flatnonzero(seg_len > 0.0)[-1])
                xy = pts[-1] + seg[j] / seg_len[j] * (dist - cum[-1])
            else:
                j = int(np.searchsorted(cum, dist, side="right") - 1)
                xy = pts[j] + seg[j] / seg_len[j] * (dist - cum[j])
            out[d, i] = (xy[0], xy[1], z[i])
    return out


def candidate_points(env: Any) -> np.ndarray:
    """``(5, N, 3)``: the candidates of every UAV, in this order: where it believes it is (its
    estimate, the altitude clamped to the flight band), the point ``CANDIDATE_AHEAD_M`` along
    its route (:func:`route_points`), that point moved ``CANDIDATE_SIDE_M`` to the left and to
    the right of the direction from the estimate to it (East when the two coincide), and the
    point ``CANDIDATE_FAR_M`` along the route."""
    base = getattr(env, "unwrapped", env)
    route = route_points(base, (CANDIDATE_AHEAD_M, CANDIDATE_FAR_M))
    kin = base.config.kinematics
    here = np.array(base._epoch.nav_pos_enu_m, dtype=float, copy=True)
    here[:, 2] = np.clip(here[:, 2], kin.altitude_min_m, kin.altitude_max_m)
    ahead = route[0]
    d = ahead[:, :2] - here[:, :2]
    norm = np.hypot(d[:, 0], d[:, 1])
    u = np.where(norm[:, None] > 0.0, d / np.where(norm > 0.0, norm, 1.0)[:, None], [1.0, 0.0])
    left = np.stack([-u[:, 1], u[:, 0], np.zeros(len(u))], axis=1) * CANDIDATE_SIDE_M
    return np.stack([here, ahead, ahead + left, ahead - left, route[1]])


def candidate_sky(env: Any) -> np.ndarray:
    """``(N, 10)`` float32, every UAV's counts at its :func:`candidate_points`, each divided by
    20 and clipped to [0, 1].

    Columns 0-4: the satellites the UAV's receiver would *use* at each candidate, by the rule
    its 3D-mapping-aided exclusion applies
    (:func:`coopnav_env.sim.map_aided.predicted_line_of_sight` with the UAV's current
    covariance grown by one step of dead reckoning and the configured margin; with
    ``nlos_exclusion="off"`` plain line of sight, margin 0). Columns 5-9: the distinct
    satellites over the swarm if the UAV were at that candidate and every other UAV at its
    own point ``CANDIDATE_AHEAD_M`` along its route. A candidate inside a building counts
    none.
    """
    base = getattr(env, "unwrapped", env)
    cfg = base.config
    pts = candidate_points(base)
    n_c, n = pts.shape[:2]
    if cfg.nlos_exclusion == "map":
        dr_var = (cfg.dead_reckoning_sigma_mps * cfg.dt_s) ** 2
        cov = np.asarray(base.world.nav_cov_enu_m2, dtype=float) + np.eye(3) * dr_var
        margin, cap = cfg.nlos_exclusion_margin_sigma, cfg.nlos_exclusion_max_margin_m
    else:
        cov, margin, cap = np.zeros((n, 3, 3)), 0.0, 0.0
    flat = pts.reshape(-1, 3)
    use = base.world.map_line_of_sight(
        flat, np.tile(cov, (n_c, 1, 1)), margin_sigma=margin, max_margin_m=cap
    )
    use = use.reshape(n_c, n, -1)
    own = use.sum(axis=2).T  # (N, 5)
    ahead = use[1]  # (N, S): every UAV at its near point ahead
    swarm = np.empty((n, n_c))
    for i in range(n):
        others = np.delete(ahead, i, axis=0).any(axis=0)
        swarm[i] = (use[:, i] | others).sum(axis=1)
    cols = np.concatenate([own, swarm], axis=1) / 20.0
    return np.clip(cols, 0.0, 1.0).astype(np.float32)


def candidate_counts(env: Any) -> dict[str, np.ndarray]:
    """Every UAV's :func:`candidate_sky` counts (times 20: satellites), by agent name."""
    base = getattr(env, "unwrapped", env)
    cols = candidate_sky(base)
    return {a: cols[i] * 20.0 for i, a in enumerate(base.possible_agents)}


def _steered(
    env: Any, counts_of: dict[str, np.ndarray], cmd: dict, gain: float, threshold: float
) -> dict:
    """``cmd`` plus the greedy push of the module docstring (item 3); ``counts_of``: each
    UAV's :func:`candidate_counts`."""
    pts = candidate_points(env)
    out = dict(cmd)
    for a in env.agents:
        i = env.possible_agents.index(a)
        counts = np.asarray(counts_of[a], dtype=float)
        own, pooled = counts[:5], counts[5:]
        if pooled[1] >= threshold:
            continue
        score = pooled + 0.25 * own
        k = int(np.argmax(score[:4]))  # here, ahead, left, right
        if score[k] <= score[1]:
            continue
        to = pts[k, i, :2] if k in (2, 3) else pts[0, i, :2]
        d = to - pts[1, i, :2]
        norm = float(np.hypot(d[0], d[1]))
        if norm > 0.0:
            push = np.zeros(3)
            push[:2] = gain * d / norm
            out[a] = np.clip(cmd[a] + push, -1.0, 1.0).astype(np.float32)
    return out


def fly(
    policy: str, env_kwargs: dict[str, Any], seeds: list[int], steer: tuple[float, float] | None
) -> dict[str, Any]:
    """Per-episode errors and goals, and (unsteered) the per-step records of item 1-2."""
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy

    env = urban_canyon_v0.parallel_env(**env_kwargs)
    pol = make_policy(policy, env)
    nav, coop, goal, steps = [], [], [], []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        pol.reset(seed)
        counts = candidate_counts(env)
        agents = list(env.possible_agents)
        nav_sum = nav_n = coop_sum = coop_n = 0.0
        infos: dict = {}
        while env.agents:
            cmd = pol.act(obs)
            if steer is not None:
                cmd = _steered(env, counts, cmd, *steer)
            obs, _r, _te, _tr, infos = env.step(cmd)
            counts = candidate_counts(env)
            live = [a for a in agents if a in infos]
            for a in live:
                nav_sum += infos[a]["nav_error_m"]
                nav_n += 1
                if infos[a]["coop_fix"]:
                    coop_sum += infos[a]["coop_error_m"]
                    coop_n += 1
            if steer is None:
                cand = np.array([counts[a] for a in live if a in obs])
                steps.append(
                    {
                        "episode": seed,
                        "fix": [bool(infos[a]["coop_fix"]) for a in live],
                        "status": [int(infos[a]["coop_status"]) for a in live],
                        "n_sats": float(np.mean([infos[a]["n_sats"] for a in live])),
                        "ahead": float(cand[:, 1].mean()) if len(cand) else np.nan,
                        "pooled": float(cand[:, 6].mean()) if len(cand) else np.nan,
                    }
                )
        nav.append(nav_sum / max(nav_n, 1.0))
        coop.append(coop_sum / coop_n if coop_n else np.nan)
        goal.append(float(bool(infos) and all(i["in_goal"] for i in infos.values())))
    return {"nav": nav, "coop": coop, "goal": goal, "steps": steps, "config": env.config}


def auc(score: np.ndarray, label: np.ndarray) -> float:
    """Area under the ROC curve of ``score`` for the boolean ``label`` (ties: mid-ranks)."""
    from scipy.stats import rankdata

    pos = int(label.sum())
    neg = label.size - pos
    if pos == 0 or neg == 0:
        return float("nan")
    r = rankdata(score)
    return float((r[label].sum() - pos * (pos + 1) / 2) / (pos * neg))


def anatomy(steps: list[dict[str, Any]]) -> dict[str, Any]:
    """Items 1 and 2 of the module docstring from the per-step records."""
    from coopnav_env.nav import NavStatus

    status = np.concatenate([np.asarray(s["status"])[~np.asarray(s["fix"])] for s in steps])
    shares = {NavStatus(int(v)).name: float(np.mean(status == v)) for v in np.unique(status)}
    out: dict[str, Any] = {
        "uav_steps_without_fix": int(status.size),
        "no_fix_status_shares": shares,
        "swarm_wide_outage_share": float(np.mean([not any(s["fix"]) for s in steps])),
        "onset_auc": {},
    }
    eps = np.array([s["episode"] for s in steps])
    outage = np.array([not any(s["fix"]) for s in steps])
    feats = {k: np.array([s[k] for s in steps]) for k in ("n_sats", "ahead", "pooled")}
    for k in (1, 3, 5):
        rows, labels = [], []
        for e in np.unique(eps):
            idx = np.flatnonzero(eps == e)
            for j in range(len(idx) - k):
                if outage[idx[j]]:
                    continue
                rows.append(idx[j])
                labels.append(bool(outage[idx[j + 1 : j + 1 + k]].any()))
        lab = np.array(labels)
        rows_a = np.array(rows, dtype=int)
        out["onset_auc"][f"within_{k}"] = {
            "onset_rate": float(lab.mean()) if lab.size else float("nan"),
            **{name: auc(-f[rows_a], lab) for name, f in feats.items()},
        }
    return out


def _paired(base: list[float], other: list[float], reps: int = 2000) -> tuple[float, ...]:
    from coopnav_env.training.stats import bootstrap_mean_interval

    d = np.asarray(other, dtype=float) - np.asarray(base, dtype=float)
    return bootstrap_mean_interval(d[np.isfinite(d)], reps, np.random.default_rng(0))


def _parse_steer(item: str) -> tuple[float, float]:
    try:
        gain, threshold = (float(x) for x in item.split(":"))
    except ValueError:
        raise SystemExit(f"--steer takes GAIN:THRESHOLD, e.g. 0.15:7, got {item!r}") from None
    if not (0.0 < gain <= 1.0 and 0.0 <= threshold <= 40.0):
        raise SystemExit(f"--steer GAIN must be in (0, 1] and THRESHOLD in [0, 40], got {item!r}")
    return gain, threshold


def main(argv: list[str] | None = None) -> int:
    from coopnav_env.training.config import apply_overrides
    from coopnav_env.training.files import write_json

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--policy", default="ceiling_column", help="the heuristic (default: %(default)s)"
    )
    p.add_argument("--episodes", type=int, default=200, help="episodes (default: 200)")
    p.add_argument(
        "--first-seed", type=int, default=1_000_000, help="first reset seed (default: 1000000)"
    )
    p.add_argument("--env-set", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument(
        "--steer", nargs="*", default=[], metavar="GAIN:THRESHOLD", help="greedy variants"
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    p.add_argument("--out", default=None, help="also write the figures to this JSON file")
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    if args.jobs < 1:
        raise SystemExit(f"--jobs must be >= 1, got {args.jobs}")
    try:
        env_kwargs = apply_overrides({}, list(args.env_set))
    except ValueError as e:
        raise SystemExit(f"--env-set: {e}") from None
    steers = [None, *(_parse_steer(s) for s in args.steer)]
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    n = len(steers)
    if args.jobs == 1:  # in this process
        runs = [fly(args.policy, env_kwargs, seeds, st) for st in steers]
    else:
        with ProcessPoolExecutor(max_workers=min(args.jobs, n)) as pool:
            runs = list(pool.map(fly, [args.policy] * n, [env_kwargs] * n, [seeds] * n, steers))
    report: dict[str, Any] = {
        "policy": args.policy,
        "episodes": args.episodes,
        "first_seed": args.first_seed,
        "env_kwargs": env_kwargs,
        "env_set": args.env_set,
    }
    cfg = runs[0]["config"]
    report.update(
        {"n_uavs": cfg.n_uavs, "nlos_exclusion": cfg.nlos_exclusion, **anatomy(runs[0]["steps"])}
    )
    print(f"{args.policy}: {report['uav_steps_without_fix']} UAV-steps without a cooperative fix")
    for name, share in report["no_fix_status_shares"].items():
        print(f"  {name:22s} {share:6.1%}")
    print(f"  swarm-wide outage in {report['swarm_wide_outage_share']:.1%} of swarm steps")
    print("onset of a swarm-wide outage, AUC (satellites now / own count ahead / pooled ahead):")
    for k, row in report["onset_auc"].items():
        print(
            f"  {k}: onset rate {row['onset_rate']:.4f}, AUC {row['n_sats']:.3f} / "
            f"{row['ahead']:.3f} / {row['pooled']:.3f}"
        )
    base = runs[0]
    report["variants"] = []
    for steer, run in zip(steers, runs):
        name = args.policy if steer is None else f"{args.policy}+steer {steer[0]}:{steer[1]:g}"
        row = {
            "name": name,
            "nav": float(np.nanmean(run["nav"])),
            "coop": float(np.nanmean(run["coop"])),
            "goal": float(np.mean(run["goal"])),
        }
        line = f"{name:24s} nav {row['nav']:.3f} coop {row['coop']:.3f} goal {row['goal']:.3f}"
        if steer is not None:
            row["nav_vs_base"] = _paired(base["nav"], run["nav"])
            m, lo, hi = row["nav_vs_base"]
            line += f"  nav vs {args.policy}: {m:+.3f} [{lo:+.3f},{hi:+.3f}]"
        report["variants"].append(row)
        print(line)
    if args.out:
        write_json(args.out, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
