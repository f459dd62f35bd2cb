"""Where the privileged planner's headroom comes from, and whether a policy could copy it.

Flies the privileged planner over a base heuristic (``planner@base='BASE'``) and the base
heuristic alone through the same episodes, keeps every step (the actor's inputs of a residual
policy over the base: observation and base command; the planner's offset to the base
command; the look-ahead cost of the base alone and of the plan applied, and every candidate
scored with its cost; each UAV's fix and the 3-D error of the estimate it used) and reports:

1. **the headroom**: mean ``nav`` error (every UAV-step, as ``coopnav study --score nav``)
   of planner and base, and their paired difference by episode with a 95 % bootstrap interval
   (4000 resamples over episodes, generator seed 0);
2. **where it comes from**: the share of UAV-steps with a cooperative fix, how much of
   the mean error comes from UAV-steps with an error above 5 m and 10 m, split into steps
   with and without a cooperative fix (dead reckoning or a standalone fix), and how many of
   the UAV-steps without a fix fall in steps when no UAV of the swarm has one (an outage of
   the centroid solution, not of one UAV);
3. **whether an on-board policy could copy it**: how much of the planner's per-UAV offset
   a regression on the actor's inputs explains on held-out episodes (R^2 per axis, 5-fold
   cross-validation by episode, ridge regression on standardised inputs), once unweighted and
   once weighted by the planner's gain at that step (base cost minus best cost), which is
   what a distillation that imitates the planner where its choice matters would fit.
4. **around the outages**: per UAV, how many outages of the cooperative fix an episode has, how
   long they last, and the mean error at the last fix before an outage, at its first and last
   step, at the first fix after it, and over every step with a fix (:func:`outage_edges`):
   whether the error of an outage is drift during it or a bad fix it starts from.
5. **the goal rate** of planner and base (episodes that end with every UAV in the goal area
   and no crash, as ``coopnav evaluate`` counts them), so that errors are compared at the
   same goal rate, and the paired difference on the episodes both finish (conditioned on the
   outcome, so only a pointer where the goal rates differ); episode files written before
   this was recorded lack it, and a report from them leaves it out.
6. **whether a learned model could stand in for the look-ahead** (:func:`lookahead_model`):
   how much of the difference between each candidate's look-ahead cost and the base's a
   regression on the actor's inputs and the candidate's offsets explains on held-out
   episodes, and what choosing the candidate it predicts cheapest would cost against the
   base (the look-ahead's own, in-sample choice and a random candidate beside it); episode
   files written before the candidates were recorded lack them, and a report from them
   leaves it out.

The planner is slow (about 11-13 s per episode on one core with its defaults); episodes are
written one file each into ``--out`` (a temporary name, then renamed), so an interrupted run
continues where it stopped, and a folder holds one setting only. The study
(``studies/planner_headroom/README.md``) uses, once as below and once
with ``--planner-set from_estimate=True --out runs/planner_headroom_onboard`` (the on-board
look-ahead from the estimates; add ``sample_belief=True`` to start it from draws of the
receiver's belief instead, the estimate plus its own covariance)::

    python studies/planner_headroom/planner_headroom.py --episodes 200 --first-seed 5000000 \\
        --env-set preset=urban_nlos_3dma dead_reckoning_noise=true nav_reward=error \\
        nav_reward_weight=1.0 collision_penalty=250 nav_team_weight=1.0 \\
        progress_reward_weight=0.2 --base ceiling_column --out runs/planner_headroom
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _save_npz(path: Path, **arrays: Any) -> None:
    from coopnav_env.training.files import atomic_path

    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, **arrays)


def fly_planner(env: Any, planner: Any, seed: int) -> dict[str, np.ndarray]:
    """One episode of ``planner`` from ``reset(seed)``, every step kept (agents in
    ``possible_agents`` order; ``alive`` marks the UAVs still flying at that step).

    Besides the observations, base commands, offsets applied, fixes and errors, every
    candidate the planner scored is kept with its look-ahead cost (``candidates``: ``(steps,
    n_samples * iterations, n_agents, 3)``, the first of each step the base alone;
    ``candidate_costs``: ``(steps, n_samples * iterations)``): the data a learned model of
    the look-ahead would be fitted to."""
    agents = list(env.possible_agents)
    obs, _ = env.reset(seed=seed)
    planner.reset(seed)
    rows: dict[str, list[Any]] = {k: [] for k in ("obs", "base", "offset", "fix", "nav", "alive")}
    costs: list[tuple[float, float]] = []
    cands: list[np.ndarray] = []
    cand_costs: list[np.ndarray] = []
    at_goal, collided = np.zeros(len(agents), dtype=bool), False
    while env.agents:
        live = list(env.agents)
        cmd = planner.act(obs)
        plan = planner.last_plan
        zero3 = np.zeros(3, dtype=np.float32)
        rows["obs"].append(np.stack([obs.get(a, np.zeros_like(obs[live[0]])) for a in agents]))
        rows["base"].append(np.stack([plan["base_command"].get(a, zero3) for a in agents]))
        rows["offset"].append(plan["offsets"].astype(np.float32))
        costs.append((plan["base_cost"], plan["best_cost"]))
        cands.append(np.asarray(plan["candidates"], dtype=np.float32))
        cand_costs.append(np.asarray(plan["costs"], dtype=np.float64))
        obs, _r, _te, _tr, infos = env.step(cmd)
        rows["fix"].append([bool(infos[a]["coop_fix"]) if a in infos else False for a in agents])
        rows["nav"].append(
            [float(infos[a]["nav_error_m"]) if a in infos else np.nan for a in agents]
        )
        rows["alive"].append([a in live for a in agents])
        at_goal = np.array([bool(infos.get(a, {}).get("in_goal", False)) for a in agents])
        collided = collided or any(bool(i.get("collided", False)) for i in infos.values())
    out = {k: np.asarray(v) for k, v in rows.items()}
    # reached the goal: every UAV in the goal area at the last step and no crash (the
    # definition of coopnav_env.training.evaluate's goal rate)
    out["success"] = np.asarray(bool(rows["alive"]) and bool(at_goal.all()) and not collided)
    c = np.asarray(costs, dtype=float).reshape(-1, 2)
    out["cost_base"], out["cost_best"] = c[:, 0], c[:, 1]
    out["candidates"] = np.asarray(cands, dtype=np.float32)
    out["candidate_costs"] = np.asarray(cand_costs, dtype=np.float64)
    return out


def fly_base(env: Any, policy: Any, seed: int) -> dict[str, np.ndarray]:
    """One episode of the base heuristic: per step and UAV the ``nav`` error, the fix flag and
    whether the UAV was still flying (``(steps, n_agents)`` each)."""
    from coopnav_env.training.evaluate import run_episode

    rec = run_episode(env, policy, int(seed))
    nav = np.asarray(rec.nav_error_m, dtype=float)
    coop = np.asarray(rec.coop_error_m, dtype=float)
    return {
        "nav": nav,
        "fix": np.isfinite(coop),
        "alive": np.isfinite(nav),
        "success": np.asarray(bool(rec.success)),
    }


def _worker(
    env_kwargs: dict[str, Any], base: str, seeds: list[int], out: str, planner_set: list[str]
) -> int:
    import torch

    import studies.planner_headroom.planner  # noqa: F401  (registers 'planner')
    from coopnav_env import urban_canyon_v0
    from coopnav_env.agents import make_policy

    torch.set_num_threads(1)
    env = urban_canyon_v0.parallel_env(**env_kwargs)
    planner = make_policy(",".join([f"planner@base={base!r}", *planner_set]), env)
    base_policy = make_policy(base, env)
    for seed in seeds:
        p_file, b_file = Path(out, f"{seed}.npz"), Path(out, f"{seed}_base.npz")
        if not p_file.exists():
            _save_npz(p_file, **fly_planner(env, planner, seed))
        if not b_file.exists():
            _save_npz(b_file, **fly_base(env, base_policy, seed))
    return len(seeds)


def ridge_r2(
    x: np.ndarray,
    y: np.ndarray,
    groups: np.ndarray,
    w: np.ndarray | None = None,
    folds: int = 5,
    lam: float = 10.0,
) -> np.ndarray:
    """Cross-validated R^2 per column of ``y`` of a ridge regression on ``x`` (folds by
    ``groups``, the episode; inputs standardised on the training folds; weighted by ``w``).
    NaN for a column with nothing to explain (no variance, or every weight zero)."""
    w = np.ones(len(x)) if w is None else np.asarray(w, dtype=float)
    return _r2(y, ridge_cv_predict(x, y, groups, w, folds, lam), w)


def _r2(y: np.ndarray, pred: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """R^2 per column of ``pred`` against ``y`` (2-D), weighted by ``w``; NaN for a column
    with nothing to explain (no variance, or every weight zero)."""
    w = np.ones(len(y)) if w is None else np.asarray(w, dtype=float)
    if not w.sum() > 0.0:  # nothing to weigh (e.g. a planner that never left its base)
        return np.full(y.shape[1], np.nan)
    mean = (w[:, None] * y).sum(0) / w.sum()
    ss_res = (w[:, None] * (y - pred) ** 2).sum(0)
    ss_tot = (w[:, None] * (y - mean) ** 2).sum(0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ss_tot > 0.0, 1.0 - ss_res / ss_tot, np.nan)


def ridge_cv_predict(
    x: np.ndarray,
    y: np.ndarray,
    groups: np.ndarray,
    w: np.ndarray | None = None,
    folds: int = 5,
    lam: float = 10.0,
) -> np.ndarray:
    """Held-out predictions of ``y`` (2-D) by the ridge regression of :func:`ridge_r2`: each
    fold (``groups % folds``, the episode) predicted by the fit on the others."""
    w = np.ones(len(x)) if w is None else np.asarray(w, dtype=float)
    pred = np.zeros_like(y, dtype=float)
    for k in range(folds):
        te = groups % folds == k
        tr = ~te
        if not te.any() or not tr.any():
            continue
        mu, sd = x[tr].mean(0), x[tr].std(0) + 1e-6
        a_tr = np.c_[(x[tr] - mu) / sd, np.ones(tr.sum())]
        a_te = np.c_[(x[te] - mu) / sd, np.ones(te.sum())]
        sw = w[tr][:, None]
        coef = np.linalg.solve(
            a_tr.T @ (sw * a_tr) + lam * np.eye(a_tr.shape[1]), a_tr.T @ (sw * y[tr])
        )
        pred[te] = a_te @ coef
    return pred


LOOKAHEAD_CLIP_M = 20.0
"""Cost differences of the look-ahead model are clipped to +/- this [m of look-ahead cost],
so that the rare look-ahead crashes (``crash_cost_m``, 1000) do not dominate the fit."""


def lookahead_model(
    episodes: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
) -> dict[str, float]:
    """Could a model on the actor's inputs stand in for the look-ahead's simulation?

    ``episodes``: per episode ``(obs, base, candidates, candidate_costs)`` as
    :func:`fly_planner` records them. For every step and every candidate but the first (the
    base alone), the difference of its look-ahead cost to the base's (clipped to
    +/-``LOOKAHEAD_CLIP_M``) is regressed on the swarm's observations, base commands and the
    candidate's offsets (ridge, 5-fold cross-validation by episode). Returns the held-out
    R^2, and the mean look-ahead cost against the base per step (clipped) of choosing, at
    every step, the candidate the model predicts cheapest (the base where none is predicted
    below it), of the look-ahead's own choice (the cheapest as simulated: in-sample, so
    optimistic), and of a random candidate other than the base.
    """
    xs, ys, gs, keys = [], [], [], []
    for i, (obs, base, cands, costs) in enumerate(episodes):
        steps, n_c = costs.shape
        for t in range(steps):
            ctx = np.concatenate([obs[t].reshape(-1), base[t].reshape(-1)])
            for c in range(1, n_c):
                xs.append(np.concatenate([ctx, cands[t, c].reshape(-1)]))
                ys.append(costs[t, c] - costs[t, 0])
                gs.append(i)
                keys.append((i, t))
    if len(set(gs)) < 2:
        return {}
    x = np.asarray(xs, dtype=float)
    y = np.clip(np.asarray(ys, dtype=float), -LOOKAHEAD_CLIP_M, LOOKAHEAD_CLIP_M)[:, None]
    g = np.asarray(gs)
    pred2 = ridge_cv_predict(x, y, g)
    r2 = float(_r2(y, pred2)[0])
    pred = pred2[:, 0]
    by_step: dict[tuple[int, int], list[tuple[float, float]]] = {}
    for k, p_, y_ in zip(keys, pred, y[:, 0], strict=True):
        by_step.setdefault(k, []).append((float(p_), float(y_)))
    chosen, best, rand = [], [], []
    for v in by_step.values():
        p_ = np.array([0.0] + [a for a, _ in v])
        y_ = np.array([0.0] + [b for _, b in v])
        chosen.append(y_[int(np.argmin(p_))])
        best.append(y_.min())
        rand.append(y_[1:].mean())
    return {
        "lookahead_model_samples": len(y),
        "lookahead_model_r2": r2,
        "lookahead_model_choice_cost_m": float(np.mean(chosen)),
        "lookahead_own_choice_cost_m": float(np.mean(best)),
        "lookahead_random_choice_cost_m": float(np.mean(rand)),
    }


def _swarm_wide(fix: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Per flying UAV-step: True where no flying UAV of the swarm has a cooperative fix."""
    none = ~(fix & alive).any(axis=1)
    return np.broadcast_to(none[:, None], alive.shape)[alive]


def outage_edges(episodes: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> dict[str, float]:
    """The ``nav`` error around outages of the cooperative fix, per UAV.

    ``episodes`` holds one ``(nav, fix, alive)`` triple per episode (``(steps, n_agents)``
    each). An *outage* is a run of a UAV's steps without a cooperative fix that follows a step
    with one (the start of an episode is not counted). Returned: outages per episode, their
    mean length [steps], and the mean error at the last fix before an outage, at its first and
    its last step, at the first fix after it (outages that end before the UAV stops flying),
    and over every step with a fix, for comparison.
    """
    before, first, last, after, fixed, lengths = [], [], [], [], [], []
    for nav, fix, alive in episodes:
        for u in range(nav.shape[1]):
            flying = np.flatnonzero(alive[:, u])
            n = int(flying[-1]) + 1 if flying.size else 0
            e, f = nav[:n, u], fix[:n, u].astype(bool)
            fixed.extend(e[f].tolist())
            t = 1
            while t < n:
                if f[t - 1] and not f[t]:
                    start = t
                    while t < n and not f[t]:
                        t += 1
                    before.append(e[start - 1])
                    first.append(e[start])
                    last.append(e[t - 1])
                    lengths.append(t - start)
                    if t < n:
                        after.append(e[t])
                t += 1

    def mean(v: list[float]) -> float:
        return float(np.nanmean(v)) if v else float("nan")

    return {
        "outages_per_episode": len(lengths) / max(len(episodes), 1),
        "mean_length_steps": mean(lengths),
        "last_fix_before_m": mean(before),
        "first_outage_step_m": mean(first),
        "last_outage_step_m": mean(last),
        "first_fix_after_m": mean(after),
        "all_fix_steps_m": mean(fixed),
    }


def analyse(folder: str | Path, seeds: list[int]) -> dict[str, Any]:
    """The report's numbers from the episode files of ``seeds`` in ``folder``."""
    from coopnav_env.training.stats import bootstrap_mean_interval

    folder = Path(folder)
    p_nav, b_nav, xs, ys, ws, gs = [], [], [], [], [], []
    p_err, p_fix, b_err, b_fix, p_all, b_all = [], [], [], [], [], []
    p_eps, b_eps = [], []
    p_ok: list[bool] = []
    b_ok: list[bool] = []
    looks: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for i, seed in enumerate(seeds):
        p = np.load(folder / f"{seed}.npz")
        b = np.load(folder / f"{seed}_base.npz")
        if "success" in p.files and "success" in b.files:  # older episode files lack it
            p_ok.append(bool(p["success"]))
            b_ok.append(bool(b["success"]))
        if "candidates" in p.files:  # older episode files lack them
            looks.append((p["obs"], p["base"], p["candidates"], p["candidate_costs"]))
        alive = p["alive"]
        p_eps.append((p["nav"], p["fix"], alive))
        b_eps.append((b["nav"], b["fix"], b["alive"]))
        p_err.append(p["nav"][alive])
        p_fix.append(p["fix"][alive])
        b_err.append(b["nav"][b["alive"]])
        b_fix.append(b["fix"][b["alive"]])
        p_all.append(_swarm_wide(p["fix"], alive))
        b_all.append(_swarm_wide(b["fix"], b["alive"]))
        p_nav.append(float(np.nanmean(p["nav"][alive])))
        b_nav.append(float(np.nanmean(b["nav"][b["alive"]])))
        gain = np.maximum(p["cost_base"] - p["cost_best"], 0.0)
        xs.append(np.concatenate([p["obs"], p["base"]], axis=-1)[alive])
        ys.append(p["offset"][alive])
        ws.append(np.broadcast_to(gain[:, None], alive.shape)[alive])
        gs.append(np.full(int(alive.sum()), i))
    d = np.asarray(p_nav) - np.asarray(b_nav)
    paired = bootstrap_mean_interval(d, 4000, np.random.default_rng(0))

    def tails(
        err: list[np.ndarray], fix: list[np.ndarray], wide: list[np.ndarray]
    ) -> dict[str, float]:
        e, f = np.concatenate(err), np.concatenate(fix).astype(bool)
        w = np.concatenate(wide).astype(bool)
        ok = np.isfinite(e)
        e, f, w = e[ok], f[ok], w[ok]
        out = {
            "fix_share": float(f.mean()),
            "mean_m": float(e.mean()),
            "no_fix_swarm_wide_share": float(w[~f].mean()) if (~f).any() else float("nan"),
        }
        for t in (5, 10):
            big = e > t
            out[f"above_{t}m_share"] = float(big.mean())
            out[f"above_{t}m_with_fix_m"] = float((e * (big & f)).sum() / e.size)
            out[f"above_{t}m_no_fix_m"] = float((e * (big & ~f)).sum() / e.size)
        return out

    x, y, w, g = (np.concatenate(v) for v in (xs, ys, ws, gs))
    goals: dict[str, Any] = {}
    if len(p_ok) == len(seeds):  # every episode file records it (this code wrote them all)
        goals = {"planner_goal_rate": float(np.mean(p_ok)), "base_goal_rate": float(np.mean(b_ok))}
        # the paired difference on the episodes both finish: conditioned on the outcome, so a
        # pointer only, for when the goal rates differ (a crash ends an episode before its
        # dead reckoning drifts further)
        both = np.asarray(p_ok) & np.asarray(b_ok)
        goals["both_finished_episodes"] = int(both.sum())
        if both.sum() >= 2:
            goals["paired_both_finished_m"] = list(
                bootstrap_mean_interval(d[both], 4000, np.random.default_rng(0))
            )
    model = lookahead_model(looks) if len(looks) == len(seeds) else {}
    return {
        **goals,
        **model,
        "episodes": len(seeds),
        "planner_nav_m": float(np.mean(p_nav)),
        "base_nav_m": float(np.mean(b_nav)),
        "paired_m": list(paired),
        "planner_better_share": float((d < 0).mean()),
        "planner": tails(p_err, p_fix, p_all),
        "base": tails(b_err, b_fix, b_all),
        "planner_edges": outage_edges(p_eps),
        "base_edges": outage_edges(b_eps),
        "offset_std": y.std(0).tolist(),
        "r2_unweighted": ridge_r2(x, y, g).tolist(),
        "r2_gain_weighted": ridge_r2(x, y, g, w).tolist(),
        "gain_share_top10pct": float(
            np.sort(w)[-max(1, len(w) // 10) :].sum() / max(w.sum(), 1e-12)
        ),
    }


def report_lines(r: dict[str, Any], base: str) -> list[str]:
    pm, lo, hi = r["paired_m"]
    lines = [
        f"episodes {r['episodes']}: nav error planner {r['planner_nav_m']:.3f} m, {base} "
        f"{r['base_nav_m']:.3f} m, paired {pm:+.3f} m [{lo:+.3f}, {hi:+.3f}] "
        f"(planner lower in {r['planner_better_share']:.0%} of episodes)",
    ]
    if "planner_goal_rate" in r:
        line = f"goal rate: planner {r['planner_goal_rate']:.3f}, {base} {r['base_goal_rate']:.3f}"
        if "paired_both_finished_m" in r:
            bm, blo, bhi = r["paired_both_finished_m"]
            line += (
                f"; on the {r['both_finished_episodes']} episodes both finish, paired "
                f"{bm:+.3f} m [{blo:+.3f}, {bhi:+.3f}] (conditioned on the outcome: a pointer)"
            )
        lines.append(line)
    lines.append(
        "where the error comes from (metres of the mean error; UAV-steps above the threshold):"
    )
    sides = (("planner", "planner"), (base, "base"))  # printed name, key in the report
    for name, key in sides:
        t = r[key]
        lines.append(
            f"  {name:10s} fix share {t['fix_share']:.3f}; above 5 m: "
            f"{t['above_5m_share']:.3f} of steps, {t['above_5m_with_fix_m']:.3f} m with a fix "
            f"+ {t['above_5m_no_fix_m']:.3f} m without; above 10 m: "
            f"{t['above_10m_with_fix_m']:.3f} + {t['above_10m_no_fix_m']:.3f} m; "
            f"{t['no_fix_swarm_wide_share']:.0%} of the UAV-steps without a fix are steps "
            "when no UAV of the swarm has one"
        )
    lines.append("around outages of the cooperative fix (per UAV; mean nav error [m]):")
    for name, key in sides:
        o = r[f"{key}_edges"]
        lines.append(
            f"  {name:10s} {o['outages_per_episode']:.2f} outages per episode, "
            f"{o['mean_length_steps']:.1f} steps long; last fix before "
            f"{o['last_fix_before_m']:.2f}, first / last step without "
            f"{o['first_outage_step_m']:.2f} / {o['last_outage_step_m']:.2f}, first fix after "
            f"{o['first_fix_after_m']:.2f}; every step with a fix {o['all_fix_steps_m']:.2f}"
        )
    fmt = lambda v: "[" + ", ".join(f"{a:+.3f}" for a in v) + "]"  # noqa: E731
    lines += [
        f"planner offsets: std per axis {fmt(r['offset_std'])} (command units)",
        "  explained by the actor's inputs (5-fold CV by episode, ridge): "
        f"R^2 {fmt(r['r2_unweighted'])}, "
        f"weighted by the planner's gain {fmt(r['r2_gain_weighted'])}; "
        f"the top 10 % of UAV-steps carry {r['gain_share_top10pct']:.0%} of the gain",
    ]
    if "lookahead_model_r2" in r:
        lines.append(
            "a model of the look-ahead from the actor's inputs and the candidate (ridge, 5-fold "
            f"CV by episode, {r['lookahead_model_samples']} candidates): R^2 of the cost "
            f"difference to the base {r['lookahead_model_r2']:+.3f}; look-ahead cost against "
            f"the base per step, choosing by it {r['lookahead_model_choice_cost_m']:+.3f}, "
            f"the look-ahead's own choice {r['lookahead_own_choice_cost_m']:+.3f} (in-sample),"
            f" a random candidate {r['lookahead_random_choice_cost_m']:+.3f}"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    from coopnav_env.training.config import apply_overrides
    from coopnav_env.training.files import atomic_write_text

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", default="ceiling_column", help="base heuristic (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=60, help="episodes (default: 60)")
    p.add_argument(
        "--first-seed", type=int, default=5_000_000, help="first reset seed (default: 5000000)"
    )
    p.add_argument("--env-set", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument(
        "--planner-set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="planner options (studies.planner_headroom.planner.PrivilegedPlanner), "
        "e.g. from_estimate=True",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    p.add_argument("--out", required=True, help="folder of the episode files and report.json")
    args = p.parse_args(argv)
    if args.episodes < 2:
        raise SystemExit(f"--episodes must be >= 2, got {args.episodes}")
    if args.jobs < 1:
        raise SystemExit(f"--jobs must be >= 1, got {args.jobs}")
    env_kwargs = apply_overrides({}, args.env_set)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for item in args.planner_set:
        if "=" not in item:
            raise SystemExit(f"--planner-set takes KEY=VALUE, got {item!r}")
    settings = {"env": env_kwargs, "base": args.base, "planner": args.planner_set}
    sfile = out / "settings.json"
    if sfile.exists():
        old = json.loads(sfile.read_text())
        if old != settings:
            raise SystemExit(f"{out} holds episodes of other settings ({old}); use another --out")
    else:
        atomic_write_text(sfile, json.dumps(settings, indent=1, sort_keys=True))
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    chunks = [seeds[i :: args.jobs] for i in range(args.jobs)]
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover
        tqdm = None
    if args.jobs == 1:
        _worker(env_kwargs, args.base, seeds, str(out), args.planner_set)
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futs = [
                pool.submit(_worker, env_kwargs, args.base, c, str(out), args.planner_set)
                for c in chunks
                if c
            ]
            bar = tqdm(total=len(seeds), unit="episode") if tqdm is not None else None
            while not all(f.done() for f in futs):
                time.sleep(2.0)
                if bar is not None:
                    bar.n = sum((out / f"{s}_base.npz").exists() for s in seeds)
                    bar.refresh()
            for f in futs:
                f.result()
            if bar is not None:
                bar.n = len(seeds)
                bar.close()
    r = analyse(out, seeds)
    r["command"] = "python studies/planner_headroom/planner_headroom.py " + " ".join(
        argv or sys.argv[1:]
    )
    atomic_write_text(out / "report.json", json.dumps(r, indent=1))
    print("\n".join(report_lines(r, args.base)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
