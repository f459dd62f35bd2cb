"""Urban Canyon v1: a UAV swarm crosses a city on cooperative GNSS navigation, paid its score.

This is the environment every quick start, default and training configuration uses. The
world, the agents, the actions, the observations (tabled with units and bounds), the infos,
the starting state, rendering and seeding are those of the legacy `urban_canyon_v0`, whose
page (the docstring of `coopnav_env.urban_canyon_v0`) tables them. What differs is the
reward: in v1 the undiscounted return of an episode **is the task's score**, the one number
a paper reports for a policy; and the episode starts crash-free (below).

| Import             | `from coopnav_env import urban_canyon_v1`                   |
|--------------------|-------------------------------------------------------------|
| Actions            | Continuous, (3,) in [-1, 1] (float32), as v0                |
| Parallel API       | Yes (`parallel_env`; `env` is the AEC version)              |
| Agents             | `uav_0` ... `uav_{N-1}`, N = `n_uavs` (default 5)           |
| Observation        | as v0: (20 + 2A + 4K,) = (52,) by default                   |
| Reward             | `reward_scheme="navigated_distance"` (below)                |
| Gymnasium          | `gymnasium.make("coopnav/UrbanCanyonSwarm-v1")`, one agent  |

```python
from coopnav_env import urban_canyon_v1

env = urban_canyon_v1.parallel_env(n_uavs=5)
observations, infos = env.reset(seed=42)
score = 0.0
while env.agents:
    actions = {agent: env.action_space(agent).sample() for agent in env.agents}
    observations, rewards, terminations, truncations, infos = env.step(actions)
    score += sum(rewards.values()) / len(rewards)
# `score` is the episode's score: the mean over UAVs of their undiscounted returns
```

## The task and its score

Reach the goal area within the time budget (`max_steps`) with the lowest navigation error
along the way. The score of an episode is the mean over the UAVs of

    score_i = sum over the metres of UAV i's street route it covers of q(e) / L_i
              + goal_bonus        if the swarm arrives
              - collision_penalty if UAV i hits a building

with `q(e) = 1 - min(e, cap) / cap` the quality of navigation at the error `e` [m] of the
estimate the UAV uses when it first covers that metre (`cap = nav_reward_cap_m`, 10 m), `L_i`
its route length at reset (the remaining street route: straight to the next waypoint, then
along the route). On arrival the rest of the route (inside the goal area) is counted at the
error of that step. So:

* a swarm that arrives scores `1 + distance-weighted mean of q along the route` (at most 2
  with the defaults): lower error along the way scores higher;
* the score does not pay for speed: the same path flown faster or slower, with the same error
  per metre, scores the same (each metre counts once, whenever it is flown);
* flying back and forth earns nothing: a metre counts the first time it is covered only
  (progress below the UAV's lowest remaining route so far);
* a swarm that runs out of time keeps what it covered (at most 1) without the bonus, so with
  `goal_bonus = 1` an arriving swarm outscores a non-arriving one unless its navigation was
  nearly useless; a crash forfeits the rest of the route and the bonus and costs 1 more, so
  crashing never pays.

Reports show the score's parts beside it: the mean navigation error, the goal rate, the
number of steps, the collisions (`coopnav evaluate`, `coopnav alignment`). Flying closer than
`min_separation_m` to another UAV is not in the score: it is a safety cost, reported on its
own channel (the infos' `separation_violation` flag, and the separation rate of the reports),
as constrained RL keeps costs apart from the reward (Safety-Gymnasium's convention); a
learner that must respect it can use it as a constraint.

## Rewards

Each step, each UAV gets the sum of the terms below (`infos[agent]["reward_<term>"]` holds
each, as in v0); summed over an episode they give `score_i` exactly (to float rounding;
`tests/envs/test_urban_canyon_v1.py`):

* `progress` = `s_i`, the share of its route the UAV covers for the first time this step
  (its remaining route below its lowest so far, divided by `L_i`; on the arrival step, all
  that is left). Why: the task is to cross the city; paid per metre, not per step, so that
  a slow swarm is not paid more and a fast one is not paid more either.
* `nav` = `-s_i * min(e_i, cap) / cap`. Why: the task is to navigate well on the way; the
  same metre is worth less the larger the error there.
* `collision` = `-collision_penalty` (1) for a UAV that hits a building (the episode ends).
* `goal` = `+goal_bonus` (1) for every UAV when all UAVs are in the goal area.
* `separation` = 0 and `contact` = 0: v0's per-step penalties (separation is the cost
  channel above; losing contact already costs through the cooperative fix's error).

There is no per-step cost: a per-step cost in an episode that ends at the goal pays for a
short trip (the score would then rank a fast clump above the swarm that navigates best, as
v0's return does). v0's per-step weights (`nav_reward_weight`, `progress_reward_weight`,
`separation_penalty`, `contact_penalty`, `integrity_penalty`) are 0 in v1, and giving one of
them a value with `reward_scheme="navigated_distance"` is refused; `nav_reward` must be
`"error"`. `nav_team_weight` (team credit) may be used: it leaves the score, the mean over
UAVs, unchanged.

## Episode end

* Termination (all agents): a UAV hits a building (it is stopped where the step started and
  the episode ends with the collision penalty), or every UAV is in the goal area (the goal
  bonus).
* Truncation (all agents): `max_steps` (200) steps (also accepted as `max_cycles`).
* A crash-free start: in the first `crash_free_steps` (3) steps a UAV whose move would touch a
  building is stopped where it was, with zero velocity, but the episode goes on (no
  `collided` flag, no penalty). So no episode ends before step 4 but by arriving, and
  PettingZoo's `max_cycles_test`, which flies unseeded random actions for `max_cycles=4`,
  passes on this module as it is (random UAVs at full speed can hit a wall within 2 steps).
  A policy that never hits a wall in its first steps flies exactly as without it.

## Discounting

Learners discount. Discounting at `gamma` pays a reward `t` steps ahead `gamma**t` of its
worth, so the goal bonus of a trip 20 steps longer is worth `gamma**20` as much (0.82 at
`gamma = 0.99`): a loss of the size of the differences in navigation quality the score ranks,
which makes a discounted learner prefer a shorter trip again. The training configurations of
v1 (`training/configs/sb3.yaml` and `torchrl.yaml`, sections `urban_canyon_v1`) use the
discount under which `coopnav alignment` finds the discounted return ranking a family of
policies as the score does (`studies/task_objective`).

## Arguments

```python
urban_canyon_v1.parallel_env(render_mode=None, config=None, **fields)
```

As v0, with the defaults of `coopnav_env.envs.config.V1_DEFAULTS` on top of v0's:
`reward_scheme="navigated_distance"`, `goal_bonus=1`, `collision_penalty=1`, the per-step
weights 0 and `crash_free_steps=3`. Keyword fields (and `preset=...`) apply on top of the v1
defaults; a complete `config` is used as it is.

## Version History

* v1: The reward is the task's score (`reward_scheme="navigated_distance"`). v0's return
  paid for a short trip as well as for low error: its navigation term was a cost per step in
  an episode that ends at the goal, so a shorter trip paid less of it, and discounting over
  the 60-80 steps of a trip valued arriving sooner on top; a swarm that navigates worse but
  arrives sooner could earn more than the one that navigates best (`studies/task_objective`
  measures it). The world, observations, actions and infos are v0's; the episode starts
  crash-free (`crash_free_steps=3`). With v0's reward settings (`reward_scheme="per_step"`
  and v0's weights) and `crash_free_steps=0` a v1 environment steps exactly as v0. v0 stays
  importable and unchanged, as a legacy version: its results are reproduced by their commands
  with `urban_canyon_v0`.
* v0: see `coopnav_env.urban_canyon_v0`.
"""

from coopnav_env.envs.urban_canyon import UrbanCanyonV1Env as raw_env
from coopnav_env.envs.urban_canyon import aec_env_v1 as env
from coopnav_env.envs.urban_canyon import parallel_env_v1 as parallel_env

__all__ = ["env", "parallel_env", "raw_env"]
