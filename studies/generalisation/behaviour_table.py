"""Behaviour descriptors per policy and city of the generalisation protocol's suites.

Flies each policy through ``--episodes`` held-out episodes (reset seeds from ``--seed-start``)
of every city of the suites, each trained policy with its run's settings and the suite's city
and sky (as ``coopnav evaluate --suite`` does), and writes the mean of
:func:`coopnav_env.training.behaviour.cruise_behaviour` per policy and city to ``--out``
(markdown).

Usage::

    python studies/generalisation/behaviour_table.py --episodes 5
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

HERE = Path(__file__).resolve().parent
POLICIES = ("high_wide_column", "mappo:pretrained/v1_s0", "mappo:pretrained/route_s0")
KEYS = ("spacing_m", "altitude_m", "lateral_spread_m", "speed_mps")


def main(argv: list[str] | None = None) -> int:
    import coopnav_env.urban_canyon_v1 as v1
    from coopnav_env.agents import make_policy
    from coopnav_env.sim.real_suite import suite_cities
    from coopnav_env.training.evaluate import run_episode
    from coopnav_env.training.files import atomic_write_text
    from coopnav_env.training.run_configs import train_config_of_policies

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policies", nargs="+", default=list(POLICIES))
    ap.add_argument("--suites", nargs="+", default=["grid", "families", "real"])
    ap.add_argument("--episodes", type=int, default=5)
    ap.add_argument("--seed-start", type=int, default=1_000_200)
    ap.add_argument("--out", default=str(HERE / "behaviour.md"))
    args = ap.parse_args(argv)
    lines = [
        "| city | policy | spacing [m] | altitude [m] | spread across route [m] | speed [m/s] |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for suite in args.suites:
        for city in suite_cities(suite):
            for name in args.policies:
                run_env = dict(train_config_of_policies([name]).get("env") or {})
                for key in [k for k in run_env if k.startswith("city_")]:
                    run_env.pop(key)
                for key in ("city", "constellation", "systems"):
                    run_env.pop(key, None)
                env = v1.parallel_env(**{**run_env, **city.env_settings()})
                policy = make_policy(name, env)
                rows = []
                for seed in range(args.seed_start, args.seed_start + args.episodes):
                    rows.append(run_episode(env, policy, seed).behaviour())
                env.close()
                cells = " | ".join(f"{np.nanmean([r[k] for r in rows]):.1f}" for k in KEYS)
                lines.append(f"| {city.name} | `{name}` | {cells} |")
                print(lines[-1], flush=True)
    given = argv if argv is not None else sys.argv[1:]
    command = " ".join(["python studies/generalisation/behaviour_table.py", *given])
    text = (
        "# Behaviour in the cruise, per city and policy\n\n"
        f"Regenerate: `{command}`. Means over {args.episodes} held-out episodes per city "
        f"(reset seeds from {args.seed_start}) of the middle 60 % of each episode's steps.\n\n"
        + "\n".join(lines)
        + "\n"
    )
    atomic_write_text(Path(args.out), text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
