"""Study: cooperative navigation under urban NLOS reception: no defence, FDE, map + FDE.

The reception of the ``urban_nlos`` preset (``coopnav_env.envs.PRESETS``: half of the
satellites a building blocks are received through a reflection, with a delay of
3 m + Exp(30 m)) in the default grid city with 5 UAVs, flown by the ``column`` and ``sky_column``
heuristics (``coopnav_env.agents.make_policy``), in three variants:

* ``off``: the navigation as it is (``integrity="off"``);
* ``fde``: the ``urban_nlos`` preset's fault detection and exclusion (``integrity="fde"``,
  ``integrity_fault_sign="positive"``);
* ``map``: the ``urban_nlos_3dma`` preset: the same FDE after 3D-mapping-aided NLOS
  exclusion (``nlos_exclusion="map"``, ``coopnav_env.sim.map_aided``: satellites the city
  model predicts blocked within 2 sigma of the position a UAV believes it is at are not
  used), with the fix gate ``max_fix_sigma_m`` at 15 m instead of 30 m;
* the two controls that separate the map from the gate: ``fde15`` (``urban_nlos`` with the
  15 m gate) and ``map30`` (``urban_nlos_3dma`` with the 30 m gate).

The same episode seeds for every variant (the episodes still differ: the policies fly by
the estimates).

Figures per policy and variant, over every UAV-step of every episode:

* ``coop OK``: share of UAV-steps with a cooperative fix reported valid (solver status OK,
  not rejected by the ``max_fix_sigma_m`` gate; with FDE, not ``FAULT_DETECTED``);
* ``p95 coop``: 95th percentile of the 3-D error of those fixes [m];
* ``OK > 30 m``: share of those fixes off by more than 30 m (reported valid, yet wrong);
* ``> 3 sig``: share of those fixes off by more than 30 m *and* by more than 3 times their
  own predicted 3-D sigma ``sqrt(trace(cov))``: wrong fixes whose covariance does not say so
  (the rest of ``OK > 30 m`` are fixes whose predicted sigma is itself 10-30 m, honest but
  imprecise, let through by the 30 m ``max_fix_sigma_m`` gate);
* ``p95 used``: 95th percentile of the 3-D error of the estimate each UAV uses [m];
* with FDE: ``avail`` (HPL of the estimate used at most the 30 m alert limit), ``MI``
  (horizontal error above the HPL) and ``HMI`` (declared available, horizontal error above
  the alert limit), from ``coopnav_env.nav.integrity_rates``.

Standard errors come from a bootstrap over episodes (steps within an episode are
correlated; episodes are independent): ``--bootstrap`` resamples of the episodes, the SE is
the standard deviation of the statistic over them.

Usage::

    python studies/nlos_defences/nlos_defences.py                      # 200 episodes per variant
    python studies/nlos_defences/nlos_defences.py --episodes 10 --variants fde map --json study.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from coopnav_env import urban_canyon_v0
from coopnav_env.agents import make_policy
from coopnav_env.envs import PRESETS
from coopnav_env.nav import integrity_rates
from coopnav_env.training.files import write_json

ALERT_LIMIT_M = 30.0
RECEPTION = ("nlos_probability", "nlos_bias_mean_m", "nlos_bias_floor_m")
VARIANTS = ("off", "fde", "fde15", "map30", "map")
_PRESET = {
    "fde": "urban_nlos",
    "fde15": "urban_nlos",
    "map30": "urban_nlos_3dma",
    "map": "urban_nlos_3dma",
}
# the controls: each preset with the other one's fix gate (max_fix_sigma_m)
_GATE = {"fde15": {"max_fix_sigma_m": 15.0}, "map30": {"max_fix_sigma_m": 30.0}}


def variant_config(variant: str, n_uavs: int) -> dict:
    """The environment arguments of one variant (:data:`VARIANTS`, see the module
    docstring)."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; variants are {VARIANTS}")
    if variant == "off":
        kw = {k: PRESETS["urban_nlos"][k] for k in RECEPTION}
    else:
        kw = dict(PRESETS[_PRESET[variant]])
        kw["alert_limit_m"] = ALERT_LIMIT_M
    kw["n_uavs"] = n_uavs
    kw.update(_GATE.get(variant, {}))
    return kw


def run_episodes(policy_name: str, variant: str, seeds: list[int], n_uavs: int) -> list[dict]:
    """Per episode, the per-UAV-step arrays the figures need."""
    env = urban_canyon_v0.parallel_env(**variant_config(variant, n_uavs))
    policy = make_policy(policy_name, env)
    out = []
    keys = ("coop_ok", "coop_err", "coop_sig", "nav_err", "h_err", "hpl")
    for seed in seeds:
        obs, _infos = env.reset(seed=seed)
        policy.reset(seed=seed)
        rows: dict[str, list] = {k: [] for k in keys}
        while env.agents:
            obs, _r, _t, _tr, infos = env.step(policy.act(obs))
            for a in env.possible_agents:
                info = infos[a]
                ok = info["coop_status"] == 0 and not info["coop_rejected"]
                rows["coop_ok"].append(ok)
                rows["coop_err"].append(info["coop_error_m"])
                # a valid cooperative fix is the estimate used: its predicted 3-D sigma
                rows["coop_sig"].append(info["sig_3d_m"])
                rows["nav_err"].append(info["nav_error_m"])
                rows["h_err"].append(info.get("nav_h_error_m", np.nan))
                hpl = info.get("hpl_m", -1.0)
                rows["hpl"].append(hpl if hpl >= 0 else np.inf)  # -1: no protection level
        out.append({k: np.asarray(v) for k, v in rows.items()})
    return out


def figures(episodes: list[dict]) -> dict:
    """The figures of a set of episodes (pooled over their UAV-steps)."""
    cat = {k: np.concatenate([e[k] for e in episodes]) for k in episodes[0]}
    ok = cat["coop_ok"]
    err = cat["coop_err"][ok]
    sig = cat["coop_sig"][ok]
    rates = integrity_rates(cat["h_err"], cat["hpl"], ALERT_LIMIT_M)
    return {
        "uav_steps": int(ok.size),
        "coop_fixes": int(ok.sum()),
        "coop_ok": float(ok.mean()),
        "p95_coop_m": float(np.percentile(err, 95)) if err.size else float("nan"),
        "ok_over_30m": float((err > 30.0).mean()) if err.size else float("nan"),
        "ok_over_30m_3sig": (
            float(((err > 30.0) & (err > 3.0 * sig)).mean()) if err.size else float("nan")
        ),
        "p95_used_m": float(np.percentile(cat["nav_err"], 95)),
        "availability": rates.availability,
        "misleading_rate": rates.misleading_rate,
        "hazardous_rate": rates.hazardous_rate,
    }


def bootstrap_se(episodes: list[dict], n_boot: int, seed: int) -> dict:
    """Standard error of every figure by resampling episodes with replacement."""
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(n_boot):
        pick = rng.integers(0, len(episodes), len(episodes))
        draws.append(figures([episodes[i] for i in pick]))
    return {k: float(np.nanstd([d[k] for d in draws], ddof=1)) for k in draws[0]}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--episodes", type=int, default=200, help="episodes per variant (200)")
    ap.add_argument("--first-seed", type=int, default=1000, help="seed of the first episode")
    ap.add_argument("--n-uavs", type=int, default=5, help="swarm size (5)")
    ap.add_argument(
        "--policies",
        nargs="+",
        default=["column", "sky_column"],
        help="policies (default: %(default)s)",
    )
    ap.add_argument(
        "--variants",
        nargs="+",
        default=list(VARIANTS),
        choices=VARIANTS,
        help="variants (off fde fde15 map30 map)",
    )
    ap.add_argument("--bootstrap", type=int, default=400, help="bootstrap resamples (400)")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    if args.episodes < 2 or args.bootstrap < 10 or args.n_uavs < 1:
        ap.error("--episodes must be >= 2, --bootstrap >= 10 and --n-uavs >= 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    out: dict = {"episodes": args.episodes, "seeds": seeds, "results": {}}
    head = f"{'policy':>10} {'def.':>5} | {'UAV-steps':>9} | {'coop OK':>7} | "
    head += f"{'p95 coop [m]':>13} | {'OK > 30 m':>16} | {'> 3 sig':>16} | "
    head += f"{'p95 used [m]':>13} | {'avail':>5} | "
    head += f"{'MI':>7} | {'HMI':>7}"
    print(f"urban NLOS reception, {args.n_uavs} UAVs, {args.episodes} episodes per row (+- SE)")
    print(head)
    for policy in args.policies:
        for variant in args.variants:
            eps = run_episodes(policy, variant, seeds, args.n_uavs)
            fig = figures(eps)
            se = bootstrap_se(eps, args.bootstrap, seed=0)
            out["results"][f"{policy}/{variant}"] = {"figures": fig, "se": se}
            line = f"{policy:>10} {variant:>5} | {fig['uav_steps']:9d} | {fig['coop_ok']:7.3f} | "
            line += f"{fig['p95_coop_m']:5.1f} +- {se['p95_coop_m']:4.1f} | "
            line += f"{fig['ok_over_30m']:6.4f} +- {se['ok_over_30m']:.4f} | "
            line += f"{fig['ok_over_30m_3sig']:6.4f} +- {se['ok_over_30m_3sig']:.4f} | "
            line += f"{fig['p95_used_m']:5.1f} +- {se['p95_used_m']:4.1f} | "
            if variant != "off":
                line += f"{fig['availability']:5.3f} | {fig['misleading_rate']:7.5f} | "
                line += f"{fig['hazardous_rate']:7.5f}"
            else:
                line += f"{'-':>5} | {'-':>7} | {'-':>7}"
            print(line, flush=True)
    if args.json:
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
