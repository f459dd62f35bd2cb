"""A privileged planner: the headroom reference of the learning studies, not a baseline.

Importing this module registers it as the policy ``planner``
(:func:`coopnav_env.agents.register_policy`): ``planner@base='ceiling_column',horizon=10``
then names it wherever :func:`coopnav_env.agents.make_policy` is used (options after ``@``
are those of :class:`PrivilegedPlanner`; ``base`` a heuristic's name, default
``wide_column``).

:class:`PrivilegedPlanner` may use everything the simulator knows: the city, the satellites,
the true positions and errors, and the future itself, since it looks ahead in deep copies of
the environment. Each look-ahead draws its own measurement noise (the copy's generator is
reseeded, the same for every candidate of a step), so the planner knows the geometry of the
future exactly but not its noise: it cannot pick a path for a lucky noise draw. It chooses the
swarm's velocity commands by sampling-based model-predictive control: at every step it

1. proposes ``n_samples`` candidate plans: the command of a base heuristic (default the
   :class:`~coopnav_env.agents.heuristics.ColumnPolicy` ``wide_column``, copied with the
   environment so that it keeps planning the route) plus a per-UAV velocity offset held for
   the horizon (one candidate is always the base alone, offset zero);
2. flies each candidate ``horizon`` steps in a deep copy of the environment (with fresh noise) and
   scores it (``objective="error"``, the default) by
   the swarm's mean *true* cooperative 3-D error (the estimate's error where there is no
   cooperative fix) over the horizon, plus ``crash_cost_m`` if any UAV hits a building, minus
   ``progress_weight_m`` times the swarm's mean progress reward (the decrease of the
   remaining route, so that the plan still reaches the goal); with ``objective="return"``,
   by minus the swarm's mean reward over the horizon, plus ``crash_cost_m`` for a crash (on
   ``urban_canyon_v1`` the reward is the task's score, paid with the true error, so the
   planner then maximises the score itself; there the progress reward of the default
   objective is a share of the route, too small beside metres of error to drive the plan);
3. refits the offsets' Gaussian to the best ``n_elite`` candidates (cross-entropy method) for
   ``iterations`` rounds and applies the first command of the best plan found.

It is slow (``n_samples * iterations * horizon`` environment steps and ``n_samples *
iterations`` deep copies per step: about 0.2-0.3 s per step with the defaults on an idle
core), uses information no on-board policy has, and is reported as a reference only: how
much lower the error could be on the same episodes, so that the share of the gap between
``column`` and the best possible that a learned policy closes can be stated. Its result
is what one planner achieves, so the headroom it shows is a lower estimate of the true one
(a better planner could do better still), not a bound.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import numpy as np

from coopnav_env.agents import make_policy, register_policy

__all__ = ["OBJECTIVES", "PrivilegedPlanner", "make_planner"]

OBJECTIVES: tuple[str, ...] = ("error", "return")
"""What the look-ahead can minimise (:class:`PrivilegedPlanner`'s ``objective``)."""


class PrivilegedPlanner:
    """Cross-entropy MPC over offsets to a base heuristic, scored with the truth.

    Parameters
    ----------
    env : urban_canyon_v0 ParallelEnv
        The environment itself (the planner copies it; it must be the object being stepped).
    base : Policy
        The base heuristic, acting in ``env`` (:func:`make_planner` builds ``wide_column``
        unless told otherwise, e.g. ``planner@base='stretched_column'``).
    horizon : int
        Look-ahead steps, >= 1.
    n_samples, n_elite, iterations : int
        Candidates per CEM round, elite size, rounds.
    offset_std : float
        Initial standard deviation of the per-UAV velocity offsets (fraction of max speed).
    crash_cost_m : float
        Cost of a crash in the look-ahead, in the objective's units (metres of error, or
        return with ``objective="return"``).
    progress_weight_m : float
        Metres of error one unit of the progress reward is worth.
    noise_samples : int
        Independent measurement-noise draws each candidate is flown with (the cost is their
        mean; the same draws for every candidate of a step).
    seed : int
        Seed of the planner's own sampling generator (reset per episode with the episode seed).
    from_estimate : bool
        Look ahead from where the swarm *believes* it is: in each copy every UAV's true
        position is replaced by its estimate before the look-ahead (the copy's truth is the
        belief, so its errors start at zero). The planner then no longer knows where the UAVs
        truly are, nor their current errors; it still knows the map, the satellites and the
        simulator's error model. An on-board look-ahead, to tell how much of the headroom
        needs the truth (``studies/planner_headroom``).
        The belief is taken as it is, even where it lies inside a building (the look-ahead
        then starts there).
    sample_belief : bool
        With ``from_estimate``: start each look-ahead not at the estimate itself but at a
        draw from the receiver's own belief, the estimate plus ``N(0, P)`` with ``P`` the
        predicted covariance of the estimate each UAV uses (drawn from the look-ahead's noise
        generator, so the candidates of a step share the draws; ``noise_samples`` draws are
        averaged). Still on-board (it uses only what the receiver believes, its estimate and
        covariance), but it knows that a UAV that has dead-reckoned for a while is far off
        in an unknown direction, which the plain look-ahead from the estimate, whose errors
        start at zero, does not; a draw that falls inside a building is replaced by the
        estimate.
    objective : {"error", "return"}
        What the look-ahead minimises: the swarm's true error less its progress (``"error"``)
        or minus its reward (``"return"``; see the module docstring).
    guard_offsets : bool
        Limit every offset, in the look-ahead and in the command applied, toward walls the
        range sensor sees (:meth:`coopnav_env.agents.heuristics.ColumnPolicy.guard_delta`: nothing
        toward a wall inside the base column's wall margin, toward one beyond it no faster
        than reaches the margin in 2 s; the base must have a wall guard, e.g. ``ceiling_column``).
        Without it an offset can cancel the base's wall guard or outrun it, which is how the
        on-board look-ahead, whose belief of where the UAVs are is metres off, flies them
        into walls (``studies/planner_headroom`` measures how often, with and without it).
        On-board (the range sensor measures true
        distances). In the look-ahead the copy's range sensor is read from where the copy's
        UAVs are (with ``from_estimate``, where they are believed to be).
    """

    name = "planner"

    def __init__(
        self,
        env: Any,
        base: Any,
        horizon: int = 5,
        n_samples: int = 8,
        n_elite: int = 2,
        iterations: int = 2,
        offset_std: float = 0.3,
        crash_cost_m: float = 1000.0,
        progress_weight_m: float = 1.0,
        noise_samples: int = 1,
        seed: int = 0,
        from_estimate: bool = False,
        sample_belief: bool = False,
        guard_offsets: bool = False,
        objective: str = "error",
    ) -> None:
        for name, v, lo in (
            ("horizon", horizon, 1),
            ("n_samples", n_samples, 1),
            ("n_elite", n_elite, 1),
            ("iterations", iterations, 1),
            ("noise_samples", noise_samples, 1),
        ):
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f"planner {name} must be an integer >= {lo}, got {v!r}")
        if n_elite > n_samples:
            raise ValueError(f"planner n_elite ({n_elite}) must be <= n_samples ({n_samples})")
        if not (offset_std >= 0.0 and crash_cost_m >= 0.0 and progress_weight_m >= 0.0):
            raise ValueError("planner offset_std, crash_cost_m, progress_weight_m must be >= 0")
        self.env = env
        self.base = base
        self.horizon = horizon
        self.n_samples = n_samples
        self.n_elite = n_elite
        self.iterations = iterations
        self.offset_std = float(offset_std)
        self.crash_cost_m = float(crash_cost_m)
        self.progress_weight_m = float(progress_weight_m)
        self.noise_samples = noise_samples
        self.seed = int(seed)
        if not isinstance(from_estimate, bool):
            raise ValueError(f"planner from_estimate must be True or False, got {from_estimate!r}")
        self.from_estimate = from_estimate
        if not isinstance(sample_belief, bool):
            raise ValueError(f"planner sample_belief must be True or False, got {sample_belief!r}")
        if sample_belief and not from_estimate:
            raise ValueError("planner sample_belief=True needs from_estimate=True")
        self.sample_belief = sample_belief
        if not isinstance(guard_offsets, bool):
            raise ValueError(f"planner guard_offsets must be True or False, got {guard_offsets!r}")
        if guard_offsets and getattr(base, "wall_margin_m", None) is None:
            raise ValueError(
                "planner guard_offsets=True needs a base with a wall guard (guarded_column, "
                "ceiling_column, "
                f"or a column with wall_margin_m set), got {getattr(base, 'name', base)!r}"
            )
        self.guard_offsets = guard_offsets
        if objective not in OBJECTIVES:
            raise ValueError(
                f"planner objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}"
            )
        self.objective = objective
        self._rng = np.random.default_rng(seed)
        base_env = getattr(env, "unwrapped", env)
        self._agents = list(base_env.possible_agents)
        self.last_plan: dict[str, Any] = {}

    def reset(self, seed: int | None = None) -> None:
        """Reset the base heuristic and the sampling generator."""
        self.base.reset(seed)
        self._rng = np.random.default_rng(self.seed if seed is None else [self.seed, seed])

    def _rollout(
        self, offsets: np.ndarray, first_obs: Mapping[str, np.ndarray], noise_seed: int
    ) -> float:
        """Cost of flying base + ``offsets`` (N, 3) for the horizon in a copy of the world.

        The copy's generator is reseeded with ``noise_seed`` (the same for every candidate of
        a step: common random numbers), so the look-ahead draws measurement noise that is
        independent of the real episode's: the planner chooses by the geometry, not by
        foreseeing the noise.
        """
        env, base = copy.deepcopy((self.env, self.base))
        inner = getattr(env, "unwrapped", env)
        inner._rng = np.random.default_rng(noise_seed)
        if self.from_estimate:
            world = inner.world
            start = np.array(world.nav_pos_enu_m, dtype=float, copy=True)
            if self.sample_belief:
                start = self._belief_draw(start, world, inner._rng)
            world.pos_enu_m = start
        obs = dict(first_obs)
        cost = 0.0
        for _ in range(self.horizon):
            if not env.agents:
                break
            live = [a for a in self._agents if a in env.agents]
            cmd = base.act({a: obs[a] for a in live})
            off = self._applied(base, offsets, obs, live)
            acts = {
                a: np.clip(cmd[a] + off[j], -1.0, 1.0).astype(np.float32)
                for j, a in enumerate(live)
            }
            obs, rewards, _te, _tr, infos = env.step(acts)
            if self.objective == "return":
                cost -= float(np.mean(list(rewards.values())))
            else:
                errs = [
                    i["coop_error_m"] if i["coop_fix"] else i["nav_error_m"] for i in infos.values()
                ]
                cost += float(np.mean(errs))
                cost -= self.progress_weight_m * float(
                    np.mean([i["reward_progress"] for i in infos.values()])
                )
            if any(i["collided"] for i in infos.values()):
                cost += self.crash_cost_m
                break
            if all(i["in_goal"] for i in infos.values()):
                break
        return cost

    def _applied(
        self, base: Any, offsets: np.ndarray, obs: Mapping[str, np.ndarray], live: list[str]
    ) -> np.ndarray:
        """The offsets of the ``live`` agents (rows in their order), wall-guarded with
        ``guard_offsets``."""
        rows = offsets[[self._agents.index(a) for a in live]]
        if not self.guard_offsets or not live:
            return rows
        return base.guard_delta(np.stack([np.asarray(obs[a]) for a in live]), rows)

    @staticmethod
    def _belief_draw(est: np.ndarray, world: Any, rng: np.random.Generator) -> np.ndarray:
        """``est + N(0, P)`` per UAV (``P`` the covariance of the estimate it uses); a draw
        inside a building falls back to the estimate itself."""
        from coopnav_env.sim.city import is_inside_building

        cov = np.asarray(world.nav_cov_enu_m2, dtype=float)
        z = rng.standard_normal(est.shape)
        # eigen-decomposition: a covariance that is only semi-definite still has a square root
        w, v = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, 1, 2)))
        draw = est + np.einsum("nij,nj->ni", v, np.sqrt(np.clip(w, 0.0, None)) * z)
        inside = is_inside_building(world.city.buildings, draw)
        draw[inside] = est[inside]
        return draw

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The first command of the best plan found (see the module docstring).

        Afterwards :attr:`last_plan` describes the choice, for analyses of what the planner
        does (``studies/planner_headroom/planner_headroom.py``): ``base_cost`` (the look-ahead
        cost of the base heuristic alone, offset zero), ``best_cost`` (of the plan applied; at most
        ``base_cost``), ``offsets`` (``(n_agents, 3)``, the per-UAV offset applied, in the
        order of ``possible_agents``, before the wall guard and clipping), ``base_command``
        (the base heuristic's command per agent), and ``candidates`` (``(n_samples * iterations,
        n_agents, 3)``, every offset scored, round by round; the first is the base alone) with
        their look-ahead ``costs`` (the data a learned model of the look-ahead would be
        fitted to).
        """
        live = list(observations)
        if not live:
            return {}
        n = len(self._agents)
        mean = np.zeros((n, 3))
        std = np.full((n, 3), self.offset_std)
        best_cost, best = np.inf, np.zeros((n, 3))
        base_cost = np.inf
        noise_seeds = self._rng.integers(0, 2**63 - 1, self.noise_samples)
        scored, scores = [], []
        for it in range(self.iterations):
            cands = mean + std * self._rng.standard_normal((self.n_samples, n, 3))
            if it == 0:
                cands[0] = 0.0  # the base heuristic itself is always a candidate
            costs = np.array(
                [
                    np.mean([self._rollout(c, observations, int(z)) for z in noise_seeds])
                    for c in cands
                ]
            )
            if it == 0:
                base_cost = costs[0]
            scored.append(cands.copy())
            scores.append(costs)
            order = np.argsort(costs, kind="stable")
            if costs[order[0]] < best_cost:
                best_cost, best = float(costs[order[0]]), cands[order[0]].copy()
            elite = cands[order[: self.n_elite]]
            mean, std = elite.mean(axis=0), elite.std(axis=0) + 1e-3
        live_order = [a for a in self._agents if a in observations]
        cmd = self.base.act({a: observations[a] for a in live_order})  # advances the base
        applied = self._applied(self.base, best, observations, live_order)
        self.last_plan = {
            "base_cost": float(base_cost),
            "best_cost": best_cost,
            "offsets": best.copy(),
            "base_command": {a: np.asarray(cmd[a], dtype=np.float32).copy() for a in cmd},
            "candidates": np.concatenate(scored),
            "costs": np.concatenate(scores),
        }
        return {
            a: np.clip(cmd[a] + applied[j], -1.0, 1.0).astype(np.float32)
            for j, a in enumerate(live_order)
        }


def make_planner(env: Any, base: str = "wide_column", **options: Any) -> PrivilegedPlanner:
    """The :class:`PrivilegedPlanner` over the heuristic named ``base`` (a
    :func:`coopnav_env.agents.make_policy` name) for ``env``; ``options`` are the planner's.
    Registered as the policy ``planner``."""
    return PrivilegedPlanner(env, make_policy(base, env), **options)


register_policy("planner", make_planner)
