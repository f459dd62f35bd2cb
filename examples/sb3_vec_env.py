"""Train SB3 PPO with one policy shared by every UAV, on coopnav's seeded vector environment.

``coopnav_env.training.vec_env.urban_canyon_vec_env`` turns ``n_copies`` swarms of
``urban_canyon_v1`` into a Stable-Baselines3 ``VecEnv`` with one slot per UAV (parameter
sharing, as ``coopnav train``).
Unlike PettingZoo's published SuperSuit recipe it works with ``PPO(..., seed=0)`` (the same
seed gives the same episodes and weights) and reports the episode length limit to PPO as
``info["TimeLimit.truncated"]``, so PPO bootstraps the value there instead of treating the
limit as a crash. This script counts those truncations. Torch runs with one thread per
process (much faster on small machines). Run it (the default took about 30 s on a 2-core VM)::

    python examples/sb3_vec_env.py --timesteps 20000 --save runs/sb3_shared.zip

(``examples/sb3_ppo.py`` trains one policy for the whole swarm on the Gymnasium view instead.)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor

from coopnav_env import urban_canyon_v1
from coopnav_env.training.vec_env import VEC_ENV_KINDS, urban_canyon_vec_env


class EpisodeEnds(BaseCallback):
    """Counts swarm episodes ended by the time limit and by a crash or the goal."""

    def __init__(self, n_uavs: int):
        super().__init__()
        self.n_uavs = n_uavs
        self.truncated = 0
        self.ended = 0

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        for first in range(0, len(infos), self.n_uavs):  # slot k * N is UAV 0 of swarm k
            if dones[first]:
                self.ended += 1
                self.truncated += bool(infos[first].get("TimeLimit.truncated", False))
        return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--timesteps", type=int, default=20_000, help="agent-steps (default: %(default)s)"
    )
    parser.add_argument(
        "--n-steps", type=int, default=256, help="PPO rollout per slot (default: %(default)s)"
    )
    parser.add_argument(
        "--n-copies", type=int, default=2, help="swarms stepped together (default: %(default)s)"
    )
    parser.add_argument("--n-uavs", type=int, default=3, help="UAVs (default: %(default)s)")
    parser.add_argument(
        "--max-steps", type=int, default=100, help="steps per episode (default: %(default)s)"
    )
    parser.add_argument(
        "--kind", choices=VEC_ENV_KINDS, default="batched", help="vector env (default: %(default)s)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed (default: %(default)s)")
    parser.add_argument(
        "--save", type=Path, default=None, help="write the model to this .zip (default: no file)"
    )
    args = parser.parse_args(argv)

    torch.set_num_threads(1)  # one thread per process: much faster on small machines
    env_kwargs = {"n_uavs": args.n_uavs, "max_steps": args.max_steps}
    venv = VecMonitor(urban_canyon_vec_env(args.n_copies, kind=args.kind, **env_kwargs))
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=args.n_steps,
        batch_size=64,
        seed=args.seed,  # works: the vector env implements seed()
        device="cpu",
        verbose=0,
    )
    ends = EpisodeEnds(args.n_uavs)
    model.learn(total_timesteps=args.timesteps, callback=ends)
    venv.close()
    print(f"trained {model.num_timesteps} agent-steps ({venv.num_envs} slots)")
    print(
        f"swarm episodes ended: {ends.ended}, {ends.truncated} of them by the time limit "
        "(TimeLimit.truncated)"
    )

    # one evaluation episode of the shared policy on the PettingZoo env, a held-out seed
    env = urban_canyon_v1.parallel_env(**env_kwargs)
    obs, _ = env.reset(seed=1_000_000 + args.seed)
    errors = []
    while env.agents:
        agents = list(env.agents)
        act, _ = model.predict(np.stack([obs[a] for a in agents]), deterministic=True)
        obs, _rewards, _terms, _truncs, infos = env.step(dict(zip(agents, act, strict=True)))
        errors += [infos[a]["nav_error_m"] for a in agents]
    env.close()
    print(f"evaluation episode: mean 3-D navigation error {np.nanmean(errors):.2f} m")

    if args.save is not None:  # write to a temporary name, then rename into place
        args.save.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.save.with_name(f".{args.save.stem}.tmp.zip")
        model.save(tmp)
        os.replace(tmp, args.save)
        print(f"saved {args.save}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
