"""Urban Canyon v0 (legacy): kept for the studies that used it; use `coopnav_env.urban_canyon_v1`.

This version stays importable and unchanged so that the studies run on it still reproduce;
its return pays for a short trip as well as for low error, so new work uses
`coopnav_env.urban_canyon_v1`, whose return is the task's score (same world, observations,
actions and infos). Making a v0 environment through this module (`parallel_env`, `env`) or
the Gymnasium id `coopnav/UrbanCanyonSwarm-v0` warns once per process (`FutureWarning`).
This page documents the world, the spaces and the infos that v1 shares.

A UAV swarm crosses a city on cooperative GNSS navigation (PettingZoo env).
A swarm of UAVs crosses a city from a start area to a goal area. Tall buildings block the
GNSS satellites, so a UAV in a street canyon sees few of them and its standalone position fix
degrades or fails; the swarm navigates cooperatively instead, transferring every UAV's
pseudoranges to a virtual centroid with the measured relative positions (SDT/DDT, paper
Sections 2-3). The policy decides where each UAV flies: toward the goal, but also where the sky
is open enough for the swarm to know where it is.

| Import             | `from coopnav_env import urban_canyon_v0`                   |
|--------------------|-------------------------------------------------------------|
| Actions            | Continuous                                                  |
| Parallel API       | Yes (`parallel_env`; `env` is the AEC version)              |
| Manual Control     | No                                                          |
| Agents             | `uav_0` ... `uav_{N-1}`, N = `n_uavs` (default 5; 50 works) |
| Action Shape       | (3,)                                                        |
| Action Values      | [-1, 1] (float32)                                           |
| Observation Shape  | (20 + 2A + 4K,) = (52,) by default                          |
| Observation Values | each entry in [-1, 1] or [0, 1] (float32), see the table    |
| State Shape        | (13 N + 4,) = (69,) for 5 UAVs                              |
| Gymnasium          | `gymnasium.make("coopnav/UrbanCanyonSwarm-v0")`, one agent  |

```python
from coopnav_env import urban_canyon_v0

env = urban_canyon_v0.parallel_env(n_uavs=5, render_mode="rgb_array")
observations, infos = env.reset(seed=42)
while env.agents:
    actions = {agent: env.action_space(agent).sample() for agent in env.agents}
    observations, rewards, terminations, truncations, infos = env.step(actions)
frame = env.render()  # (640, 1280, 3) uint8
env.close()
```

## Description

The world (`coopnav_env.sim.scenario.UrbanWorld`) is a random street grid with open squares
(`city="grid"`, a new city every episode unless `city_seed` is set) or the paper's single
straight canyon (`city="canyon"`), in a local East-North-Up frame at a geodetic origin near the
paper's Shanghai site. At reset the swarm stands in a compact lattice formation on a random
street (the start area) and the goal is a random street point at least `goal_distance_min_m`
away. Each step is one GNSS epoch of `dt_s` (1 s): the UAVs move (kinematic point masses with
speed and acceleration limits, altitude band 5-30 m below most roofs), the nominal GPS and
BeiDou-3 satellites move, each UAV receives the satellites in line of sight (ray-box test against
the buildings, 10 deg cut-off; optional NLOS reflections with an unknown bias), measures
pseudoranges (paper Eq. 1-8) and the relative positions of the UAVs within 200 m (Eq. 9), and
navigates: standalone WLS and the cooperative virtual-centroid solution (DDT by default, exact
covariance; one centroid per UAV up to 10 UAVs, one shared centroid at the UAV with the most
satellites from 11 on). A UAV uses its cooperative fix, else its standalone fix, else dead
reckoning; a fix counts only when its predicted 3-D sigma is at most `max_fix_sigma_m` (30 m,
an integrity gate). At reset the world also plans the shortest street route from the start to
the goal, which the observation and the progress reward follow.

## Action Space

`Box(-1, 1, (3,), float32)` per agent: the desired velocity East, North, Up as a fraction of
`kinematics.max_speed_mps` (10 m/s). The horizontal command is further limited to that speed in
norm, and the velocity moves toward it by at most `max_accel_mps2 * dt_s`. Values outside
[-1, 1] are clipped. A missing or unknown agent, a shape other than (3,), or a NaN/inf entry
raises `ValueError`.

With `action_frame="route"` the same three numbers are set-points in the frame of the street
route instead, which the UAV's autopilot tracks from its *estimated* position: the speed along
the route (`-1` holds its place, `+1` is `max_speed_mps`), the offset across the street from
the route's centre line (`+-route_offset_max_m`, 4 m, positive to the left of travel), and
the altitude (`-1` the bottom of the band, `+1` its top). The autopilot is the `waypoint`
follower's (`coopnav_env.envs.autopilot.pursuit_velocity`: toward the next waypoint, moved by
the offset, slowing before it; the altitude held with a gain of 0.6 per second), and its
output is the velocity command above. The frame
flies a learner along its street route, so that what it learns is how fast, how far apart
and how high its UAVs fly; a constant action flies every UAV along the route together. The
column and waypoint heuristics command velocities and refuse it; `setpoints` gives fixed
set-points (`coopnav evaluate` flies it in this frame by itself;
`coopnav_env.agents.action_frame_of` names each heuristic's frame).

## Observation Space

One float32 vector per agent, containing only what a UAV can know on board (never its true
position). Every entry is clipped to its bounds, so observations always lie in
`observation_space(agent)`. `A = obs_sky_azimuths` (8), `K = obs_neighbours` (4), `L` the
larger side of the city [m].

| Index             | Meaning                                          | Units / scale   | Bounds  |
|-------------------|--------------------------------------------------|-----------------|---------|
| 0-2               | estimated position minus goal centre, E N U      | m / L           | [-1, 1] |
| 3-5               | velocity E N U                                   | m/s / v_max     | [-1, 1] |
| 6-8               | predicted sigma E N U of the estimate (H_p)      | m / sigma_max   | [0, 1]  |
| 9                 | satellites received / above the cut-off          | count ratio     | [0, 1]  |
| 10                | distinct satellites of it + UAVs in range        | count ratio     | [0, 1]  |
| 11..10+A          | skyline elevation at azimuth 360 i / A           | deg / 90        | [0, 1]  |
| 11+A+4k..13+A+4k  | neighbour k (nearest first): relative E N U      | m / range_max   | [-1, 1] |
| 14+A+4k           | neighbour k present (1) or empty slot (0)        | flag            | {0, 1}  |
| 11+A+4K           | the estimate is a cooperative fix                | flag            | {0, 1}  |
| 12+A+4K           | the estimate is a fresh fix (not dead reckoning) | flag            | {0, 1}  |
| 13+A+4K           | steps left / max_steps                           | ratio           | [0, 1]  |
| 14+A+4K..15+A+4K  | next route waypoint minus the estimate, E N      | m / route_scale | [-1, 1] |
| 16+A+4K..17+A+4K  | the leg after that waypoint, E N (0: none)       | m / route_scale | [-1, 1] |
| 18+A+4K           | remaining route length from the estimate         | m / 2L          | [0, 1]  |
| 19+A+4K           | estimated altitude within the altitude band      | m / band        | [0, 1]  |
| 20+A+4K..19+2A+4K | nearest-wall distance at azimuth 360 i / A       | m / wall_scale  | [0, 1]  |

`L`: the larger side of the city extent [m]; `v_max`: `kinematics.max_speed_mps`;
`sigma_max`: `obs_sigma_max_m`; `range_max`: `relative_sensing.max_range_m`;
`route_scale`: `obs_route_scale_m`; `wall_scale`: `obs_wall_scale_m`; `band`: the altitude
band `altitude_max_m - altitude_min_m` above `altitude_min_m`. Azimuths are clockwise from
North; the sigma is from the covariance of the estimate the UAV uses (`H_p` of Eq. 19-23 for a
cooperative fix).

The route: at reset the world plans the shortest route along the street centre lines from the
start formation to the goal (at most two turns on the grid; `env.unwrapped.world.route_xy_m`).
Each UAV tracks its own next waypoint, which advances when the UAV's *estimated* position is
within `route_reach_m` (5 m) of it along East and North, or past it along the leg arriving at
it; the goal is the last waypoint. The skyline and the wall distances are what an on-board
camera and range sensor measure around the UAV (like the relative positions of the
neighbours, from its true position); the wall distance is horizontal, at the UAV's altitude,
to the nearest building taller than the UAV (1 when none is within `wall_scale`). Together
with the waypoint vector at a 50 m scale they resolve the position in the street: 10 m off the
centre line changes the waypoint vector by 0.2 and the wall distances by 0.2, where it changes
the position-to-goal entries (scale `L` = 500 m) by 0.02.

With the defaults: 0-2 position, 3-5 velocity, 6-8 sigma, 9-10 satellite counts, 11-18 sky,
19-34 four neighbour slots, 35-37 flags and time, 38-39 next waypoint, 40-41 the leg after it,
42 remaining route, 43 altitude, 44-51 wall distances.

The same table for code: `coopnav_env.envs.obs_layout(config)` maps a name to its slice,
units, scale (and offset), bounds and description, for any configuration, e.g.
`obs_layout(env.config)["next_waypoint"].slice` (`slice(38, 40)` by default) or
`obs_layout()["altitude"].decode(obs)` (metres). Names: `position_to_goal`, `velocity`,
`sigma`, `satellites`, `swarm_satellites`, `skyline`, `neighbour_k` and
`neighbour_k_present` (k = 0..K-1), `cooperative_fix`, `fresh_fix`, `time_left`,
`next_waypoint`, `next_leg`, `remaining_route`, `altitude`, `wall_distance`.

With `obs_protection_level=True` (needs `integrity` on) two entries follow the table:
`min(HPL / (2 alert_limit_m), 1)` and `min(VPL / (2 alert_limit_m), 1)` of the estimate used
(0.5 at the alert limit, 1 without protection), `obs_dim + 2` in all (54 by default).

With `obs_satellite_sectors=True`, `2 A` entries follow last (after the protection levels when
those are on): `satellites_received_sector`, per azimuth sector of the skyline (sector `i`
centred on azimuth `360 i / A`, clockwise from North, `360 / A` wide), the number of
satellites the UAV tracks there (its pseudoranges, NLOS reflections included, before any map
exclusion) / 4, and `satellites_blocked_sector`, the number above the cut-off it does not
track there / 4, each clipped to [0, 1] (68 entries by default). What a real receiver knows
from its almanac and tracking loops: not only how many satellites it misses, but where.

With `obs_true_error=True` (**privileged: a diagnostic, not an on-board observation**), 3
entries follow last: `true_error`, the true error of the estimate the UAV uses (East, North,
Up) / `obs_sigma_max_m`, clipped to [-1, 1]. No receiver knows it; it exists to tell whether
a learned policy falls short of the privileged planner for want of information or of
learning (`studies/planner_headroom`), and a policy trained with it must not be reported as an
on-board one.

With `obs_agent_index=True`, `n_uavs` entries follow last: `agent_index`, the UAV's one-hot
index in `possible_agents`. A UAV knows which one it is; with one network shared by every UAV,
this lets the UAVs of a tight group, whose observations are otherwise nearly equal, act
differently (agent indication, Terry et al. 2020).

`state()` returns the global state for centralised critics (truth included), float32 in
`state_space`: `(pos - goal) / L` (3N), `velocity / max_speed` (3N), `(goal - city centre) / (L/2)`
(3), `(estimate - pos) / nav_reward_cap_m` (3N), `sigma / obs_sigma_max_m` (3N),
`satellites received / above cut-off` (N), `steps left / max_steps` (1); each clipped to
[-1, 1] or [0, 1].

## Rewards

Per agent, the sum of six terms, each also reported in `infos[agent]["reward_<term>"]`:

* `nav` = `-nav_reward_weight * min(e, nav_reward_cap_m) / nav_reward_scale_m` (defaults 0.1,
  10 m, 10 m), where `e` is the true 3-D error of the estimate the UAV uses
  (`nav_reward="error"`, default) or its predicted 3-D sigma `sqrt(trace H_p)`
  (`nav_reward="sigma"`): -0.03 per step at a 3 m error, at worst -0.1; with team credit
  `nav_team_weight = w` (default 0) each UAV gets `(1 - w) nav_i + w mean_j(nav_j)`, so that a
  UAV that keeps its neighbours' fixes good (holding an open square, spreading the swarm over
  more sky) is paid for it;
* `progress` = `progress_reward_weight * (d_prev - d_now) / (max_speed_mps * dt_s)` (weight 1),
  `d` the remaining length of the street route from the UAV's true position: the straight
  distance to its next waypoint plus the route after that waypoint, both ends of the step
  measured to the waypoint that was next at the start of the step (switching waypoints earns
  nothing). At most 1 in magnitude per step; summed over an episode, about the route length
  covered / 10 m (a 300 m route: about +30);
* `collision` = `-collision_penalty` (40) for a UAV that hits a building;
* `separation` = `-separation_penalty` (0.05) for a UAV closer than `min_separation_m` (3 m)
  to another;
* `contact` = `-contact_penalty` (0.02) for a UAV with no other UAV in relative-sensing range;
* `goal` = `+goal_bonus` (10) for every UAV when all UAVs are in the goal area (not on a step
  where a UAV crashes).

With `integrity` on, a seventh term: `integrity` = `-integrity_penalty` (default 0) for a UAV
whose estimate is not available (horizontal protection level above `alert_limit_m`, dead
reckoning included) or misleading (true horizontal error above the HPL).

Crashing never pays: a crash costs `collision_penalty` = 40, more than the worst a whole
episode can lose to the per-step penalties without one, `max_steps * (0.1 * 10 / 10 + 0.05 +
0.02)` = 200 x 0.17 = 34 (`UrbanCanyonConfig.worst_episode_penalty`; a 200-step episode at a
typical 3 m error loses about 200 x 0.03 = 6 to the navigation term). The progress term is
no penalty to escape: it only pays for route actually covered, which a crash stops. The
penalty is not larger than that on purpose: a crash must also not be so costly that hovering
in place beats flying the route while the policy is still learning to steer (with a 100
penalty PPO learned exactly that). Before coopnav 0.1.0 was released the defaults were 1,
50 m, 10 m, collision 10, separation 1, contact 0.5: the navigation term alone cost about 0.3
per UAV and step, 60 per 200-step episode, so ending the episode in a wall at once (-10) was
the best a policy could do.

## Infos

`infos[agent]` is flat and holds python numbers only, with the same keys (in the same order,
`coopnav_env.envs.urban_canyon.INFO_KEYS`) at `reset()` and at every step, so that libraries
that build their specs from the reset (TorchRL's `PettingZooWrapper`, BenchMARL) and loggers
that average every key work as they are: `nav_error_m`, `coop_error_m`, `standalone_error_m`
(true 3-D errors [m]), `coop_fix`, `standalone_fix` (whether that fix exists: where it does
not, its error is reported as -1, `NO_FIX_ERROR_M`, never `inf` or NaN; mask by the flag
before averaging, or read it with `coopnav_env.envs.urban_canyon.fix_error_m(info, key)`,
which returns `inf` for a missing fix), `sig_e_m`, `sig_n_m`, `sig_u_m`, `sig_3d_m` (predicted
sigma of the estimate used [m]), `n_sats`, `n_sats_swarm`, `n_sats_open_sky`, `coop_status` and
`standalone_status` (`coopnav_env.nav.NavStatus`: 0 OK, 1 too few satellites, 2 singular, 3
not converged, 4 no relative position, 5 implausible position: the spurious far root; OK
means the solver converged on enough measurements, and with `integrity` off no residual test
runs, so a fix built on a faulty pseudorange, such as a 1 km NLOS outlier, is OK too, its
error far beyond `sig_3d_m`: the integrity figures below appear only when a test ran),
`nav_source` (`coopnav_env.sim.NavSource`: 0 cooperative, 1 standalone, 2 dead reckoning),
`goal_distance_m`, `next_waypoint` (index into `world.route_xy_m`), `coop_rejected` and
`standalone_rejected` (the solver's fix was OK but the integrity gate `max_fix_sigma_m`
rejected it: the fix counts as missing), `in_goal`, `collided`, `separation_violation`,
`out_of_contact`, the reward terms `reward_nav`, `reward_progress`, `reward_collision`,
`reward_separation`, `reward_contact`, `reward_goal` (0 at reset; their sum is the reward),
and `step` (0 at reset). With `integrity` on, `reward_integrity` follows `reward_goal`,
and after `step` (in this order): `hpl_m`,
`vpl_m` (protection levels of the estimate used [m]; -1 where none is available,
`integrity_status` says why), `nav_h_error_m`, `nav_v_error_m` (its true horizontal and
vertical errors [m]), `integrity_status` (`coopnav_env.nav.IntegrityStatus`: 0 OK, 1
excluded, 2 fault detected, 3 no redundancy, 4 no fix), `fault_detected` (the UAV's
cooperative or standalone test failed this step) and `fde_excluded` (pseudoranges excluded
from the fix used); a fix whose fault could not be cleared has status 6 (`FAULT_DETECTED`)
and is not used. `coopnav_env.nav.integrity_rates` turns arrays of errors and protection
levels into availability and misleading-information rates.

The reset infos describe the first epoch of the new episode. SuperSuit's own automatic reset
(`pettingzoo_env_to_vec_env_v1`) merges them over the terminal step's infos
(`{**step_info, **reset_info}`), so with that recipe the terminal step's figures are lost;
coopnav's vector environments (`coopnav_env.training.vec_env.make_vec_env`, the batched
`BatchedUrbanCanyonEnv`) keep the terminal step's infos and drop the reset's.

## Starting State

A lattice formation (spacing `formation_spacing_m`, 5 m) centred on a random street point at
`start_altitude_m` (15 m), laid along the street, at rest. The first epoch's solvers start
from the known launch positions; later ones are warm-started from the previous estimates moved
by the velocity.

## Episode End

* Termination (all agents): a UAV hits a building (swept-sphere test). The crashed UAV is
  stopped where the step started. Ending the episode for everyone keeps every agent alive
  until the end, which SuperSuit's vector wrappers (`pettingzoo_env_to_vec_env_v1`) require;
  no black-death wrapper is needed.
* Termination (all agents): every UAV is within `goal_radius_m` (25 m) of the goal centre
  horizontally; every UAV gets `goal_bonus`.
* Truncation (all agents): `max_steps` (200) steps (also accepted as `max_cycles`).

`crash_free_steps` (0 in v0, 3 in v1): a crash-free start. In the first `crash_free_steps`
steps a UAV whose move would touch a building is stopped where the step started, as on a
crash, but the episode goes on (no `collided` flag, no collision penalty), so no episode ends
before step `crash_free_steps + 1` but by arriving. With v0's 0, PettingZoo's
`max_cycles_test` (unseeded random actions, `max_cycles=4`) fails whenever random UAVs hit a
wall in their first 3 steps; it passes with slow UAVs (`kinematics={"max_speed_mps": 0.5}`),
and on `urban_canyon_v1` as it is.

UAVs cannot leave the city extent (a virtual fence clamps them) nor the altitude band.

## Arguments

```python
urban_canyon_v0.parallel_env(render_mode=None, config=None, **fields)
```

`config` is an `coopnav_env.envs.UrbanCanyonConfig`; every keyword is one of its fields and
overrides it. An unknown keyword raises `ValueError` listing the valid ones; a bad value raises
`ValueError` naming the field, the value and the allowed range. Sub-configurations
(`city_config`, `kinematics`, `relative_sensing`, `error_model`) accept the dataclass or a dict.
`env(...)` and `raw_env(...)` take the same arguments: `raw_env` is the `ParallelEnv` class
itself, `env(...)` is `pettingzoo.utils.parallel_to_aec(parallel_env(...))` (AEC, with
`OrderEnforcingWrapper`; no out-of-bounds action wrapper, the environment clips itself).

`render_mode` (None): `"rgb_array"` or `"human"`.

`n_uavs` (5): number of UAVs, in [1, 256].

`city` (`"grid"`): `"grid"`, a random street grid, `"canyon"`, the paper's canyon,
`"geojson:PATH"`, building footprints from a file (section "A city from a GeoJSON file"),
`"osm:PATH"`, an OpenStreetMap extract (`docs/cities.md`), or `"family:NAME"`, a city
generated per episode of a family (`docs/city_families.md`; `"family:mixed"`: of every
family).

`city_origin`, `city_start_lat_lon`, `city_goal_lat_lon` (`"file"`, None, None): the file
city's geodetic origin and fixed start and goal (same section).

`city_bbox`, `city_repair`, `city_default_height_m`, `city_storey_height_m` (None, True, 10,
3): how a file city is read: only the buildings inside a `(south, west, north, east)`
box; invalid footprints repaired with a warning (False: listed in one error); the roof height
of a building without `height` or `building:levels`; metres per storey (`docs/cities.md`).

`city_config` (`CityConfig()`): the grid: 6 x 6 blocks of 60 m, 20 m streets, roofs 10-150 m
(mean 45 m), 10 % of the blocks open squares; 500 m x 500 m.

`city_seed` (None): None draws a new city every episode; an int keeps one city.

`city_pool` (None): family cities only: each episode's city seed drawn from `0 .. city_pool - 1`
(a fixed set of training cities; exclusive with `city_seed`).

`canyon_h_over_d`, `canyon_street_width_m`, `canyon_length_m` (sqrt(3), 20, 400): the canyon;
`h/d` holds at 15 m altitude (Eq. 25), so the roofs are 32.3 m high.

`lat_deg`, `lon_deg`, `alt_m` (31.0252, 121.4337, 10): geodetic origin, the paper's site.

`t0_s`, `t0_random_s` (0, 0): GNSS time of the first epoch and its random spread [s].

`systems` (`("GPS", "BDS")`): constellations.

`constellation`, `constellation_start` (`"nominal"`, None): where the satellites come from
(section "A sky from a RINEX file").

`elevation_mask_deg` (10): elevation cut-off [deg].

`max_sats` (None): receiver channel limit (the highest satellites are kept).

`error_model` (`ErrorModel()`): pseudorange errors, paper Eq. 3-8.

`clock_sigma_m` (3e4): sigma of the receiver clock biases drawn at reset [m].

`nlos_probability`, `nlos_bias_mean_m`, `nlos_bias_floor_m` (0, 15, 1): reception of blocked
satellites through reflections, with a bias `floor + Exp(mean)` [m].

`kinematics` (`KinematicsConfig()`): 1 s step, 10 m/s, 4 m/s^2, altitude 5-30 m, radius 1 m,
minimum separation 3 m.

`relative_sensing` (`RelativeSensingConfig()`): 200 m range, sigma 0.1 m + 0.002 m/m per axis.

`transfer` (`"ddt"`): `"ddt"` or `"sdt"` measurement transfer.

`centroid` (`"auto"`): `"self"` (one centroid per UAV, the paper's choice, cost ~N^2),
`"shared"` (one centroid at the UAV with the most satellites, cost ~N) or `"auto"` (`"self"`
up to 10 UAVs, `"shared"` from 11).

`covariance` (`"exact"`): `"exact"` or `"paper"` (Eq. 18-19 as printed).

`nav_max_iter` (10): Gauss-Newton iteration limit.

`dead_reckoning_sigma_mps` (1): sigma growth while dead reckoning [m/s].

`dead_reckoning_noise` (False): the previous estimate is carried forward with the true
velocity (off: dead reckoning never drifts, which flatters a design that rejects fixes) or,
on, with the true velocity plus `N(0, dead_reckoning_sigma_mps^2)` per axis drawn every step,
a random walk that matches the covariance. Turn it on where fixes are often rejected.

`start_prior_sigma_m` (10): sigma of the launch position if the first epoch has no fix [m].

`formation_spacing_m`, `start_altitude_m` (5, 15): start formation [m].

`goal_distance_min_m`, `goal_radius_m` (200, 25): goal placement and size [m].

`route_reach_m` (5): a UAV's next route waypoint is reached when its estimated position is
within this distance of it along East and North (or past it along the route) [m].

`max_fix_sigma_m` (30): integrity gate. A cooperative or standalone fix whose predicted 3-D
sigma `sqrt(trace(cov))` exceeds this is rejected (`coop_rejected`, `standalone_rejected`) and
the UAV falls back to the next source (standalone, then dead reckoning); None disables it. In
street canyons some fixes come from barely enough satellites (4-5 measurements for 4-5
unknowns) in a narrow strip of sky; they are valid least-squares solutions, but off by tens to
hundreds of metres, and their covariance says so.

`integrity` (`"off"`): integrity monitoring of every fix (`coopnav_env.nav.integrity`):
`"raim"` tests each standalone and cooperative fix's residuals (chi-square with the exact
covariance) and computes protection levels, and a fix that fails is not used; `"fde"` also
excludes the measurement the test identifies and re-solves until the test passes. Needs
`covariance="exact"`. `integrity_p_fa` (1e-3): false-alarm probability per test;
`integrity_risk` (1e-7): integrity risk of a fix (protection levels);
`integrity_fault_sign` (`"any"`): `"positive"` excludes only measurements with a positive
residual (NLOS delays are positive). `alert_limit_m` (30):
horizontal alert limit [m] (availability, the reward term and the observation scale).
`integrity_penalty` (0), `obs_protection_level` (False), `obs_satellite_sectors` (False),
`obs_true_error` (False) and `obs_agent_index` (False): above. (`obs_lookahead` and
`obs_candidate_sky` were removed: an environment given either refuses it, saying so.)
`action_frame` (`"velocity"`), `route_offset_max_m` (4): above (Action Space).
`route_turn_brake_mps2` (0): with `action_frame="route"` and a value `b > 0`, the autopilot
also limits the speed to `1 + sqrt(2 b (d - 3))` m/s at `d` m before a turn of the route, so
that a UAV at full speed can brake for it.
With `"off"` every episode is exactly as before. The preset
`coopnav_env.envs.preset_config("urban_nlos", **fields)` turns on realistic urban reception:
half of the blocked satellites received through reflections with a bias of 3 m + Exp(30 m),
and `integrity="fde"` with `integrity_fault_sign="positive"`.

`nlos_exclusion` (`"off"`): `"map"` is 3D-mapping-aided NLOS exclusion
(`coopnav_env.sim.map_aided`): a UAV does not use the satellites that the city model predicts
blocked from the position it believes it is at or from the candidates
`nlos_exclusion_margin_sigma` (2) sigma around it, each displacement capped at
`nlos_exclusion_max_margin_m` (10 m); `n_sats` and the observation count the satellites used,
and the infos end with `n_map_excluded` (satellites received but not used). The simulated map
is perfect, a real one is not. The preset `preset_config("urban_nlos_3dma")` is `urban_nlos`
with it on and the fix gate `max_fix_sigma_m` at 15 m (fewer satellites, weaker geometry).
A preset can also be named as an argument, `parallel_env(preset="urban_nlos_3dma", **fields)`
(the fields go on top), and so from a training config or `--env-set preset=urban_nlos_3dma`.

`max_steps` (200): truncation. `max_cycles`, the name PettingZoo's own environments and
BenchMARL use, is accepted as an alias (giving both with different values raises
`ValueError`); `config.max_cycles` reads it.

`obs_neighbours`, `obs_sky_azimuths`, `obs_sigma_max_m` (4, 8, 20): observation layout.

`obs_route_scale_m`, `obs_wall_scale_m` (50, 50): scales of the route and wall-distance
observations [m].

`reward_scheme` (`"per_step"`, the rewards above; `"navigated_distance"` is the reward of
`urban_canyon_v1`, whose page defines it: there the undiscounted return is the task's score).

`nav_reward` (`"error"`), `nav_reward_weight`, `nav_reward_scale_m`, `nav_reward_cap_m`
(0.1, 10, 10), `nav_team_weight` (0: own error; 1: the swarm mean),
`progress_reward_weight` (1), `collision_penalty` (40), `separation_penalty`
(0.05), `contact_penalty` (0.02), `goal_bonus` (10): rewards, above.

`render_sky_uav` (-1): the UAV of the sky plot; -1 picks the one with the fewest satellites.

`render_width_px`, `render_height_px` (1280, 640): frame size [pixel].

## A sky from a RINEX file

`constellation="rinex:PATH"` flies the satellites of a RINEX navigation file (RINEX 3 mixed,
GPS or BeiDou, or RINEX 2 GPS; plain or gzip-compressed: GPS LNAV and BeiDou D1/D2, GEO and
IGSO included; those of `systems`) instead of the nominal constellations, propagated as
IS-GPS-200 and the BeiDou B1I ICD specify (`coopnav_env.gnss.rinex`); `"rinex:sample"` is a
one-day GPS + BeiDou file shipped with the package (made from the nominal orbits).
`constellation_start` sets the first epoch: a UTC ISO time (`"2026-12-03T06:00:00Z"`) or GPS
seconds, plus `U(0, t0_random_s)`; None draws it per episode, from the episode's generator,
among the times at which the whole episode lies in the file's usable spans at the origin
(every system with a valid ephemeris, at least 4 satellites above the cut-off; a given start
whose episode leaves them gives a `RinexWarning`). `t0_s` must
be 0 (`t_s` counts from the start of the coverage). Each ephemeris is used within its fit
interval (GPS: the record's, at least 4 h; BeiDou: 1 h either side of `toe`), the one with
the nearest `toe`. The file is read and checked when the environment is made: unhealthy or
implausible records are left out with one `RinexWarning` counting them by system and reason;
a malformed file (the message names the file and line), or a start outside the ephemerides'
validity, raises `ValueError`. A station's file holds the satellites that station tracked:
flown far from it, the origin sees few of them, and a `RinexWarning` says so (fly at the
station's `lat_deg`, `lon_deg`, or use a merged broadcast file). On the command line:
`coopnav evaluate ... --env-set constellation=rinex:my_nav.rnx.gz --env-set
constellation_start=2026-12-03T06:00:00Z`. With a file sky, `systems` may add `"GAL"`:
Galileo's I/NAV records, propagated as the Galileo OS SIS ICD specifies (valid 4 h either side
of `toe`), with a receiver clock of its own (drawn after the others, so GPS and BeiDou
episodes are unchanged) and the E1/E5a iono-free factor; the error model is otherwise the
same for every system.

## A city from a GeoJSON file

`city="geojson:PATH"` flies over the building footprints of a GeoJSON FeatureCollection
(`Polygon`/`MultiPolygon` features in WGS 84 longitude/latitude, courtyards kept), extruded to
their roofs: `height` (metres; `"12 m"` and feet read too), else `building:levels` x 3 m, else
10 m (counted in one warning). `"geojson:sample"` is a synthetic city of 335 buildings shipped
with the package (`coopnav_env/data/sample_city.geojson`). The city is the same every episode;
line of sight, skyline, wall distances and collisions use the polygons
(`coopnav_env.sim.file_city`). With `city_origin="file"` the ENU origin is the footprints'
centroid and `lat_deg`/`lon_deg` are set to it (the satellites are seen from the city);
`"config"` keeps `lat_deg`, `lon_deg`, `alt_m`. Start and goal are drawn per episode in the free
space between the buildings (cells of 5 m at least 3 m from every wall, the largest connected
piece), or given as `city_start_lat_lon` / `city_goal_lat_lon` = `(lat, lon)`; the route is an
A* path through the free space, kept away from walls. The file is read and checked when the
environment is made: a missing file, bad JSON, an open, self-intersecting or degenerate ring,
an unreadable height, a point beyond 10 km of the origin, or a start or goal inside a building
raises `ValueError` naming the file, the feature and the problem. On the command line:
`coopnav evaluate --policies column wide_column --env-set city=geojson:my_city.geojson`;
`examples/fly_file_city.py` flies and renders it.

## Gymnasium (one agent commands the swarm)

`import coopnav_env` registers `"coopnav/UrbanCanyonSwarm-v0"`
(`coopnav_env.envs.UrbanCanyonSwarmEnv`): `gymnasium.make("coopnav/UrbanCanyonSwarm-v0",
reward="mean", **fields)` takes the same keywords and steps the same episodes. The observation
is every UAV's observation stacked (`Box((N * obs_dim,), float32)`, `uav_0` first), the action
every UAV's command (`Box(-1, 1, (3 N,), float32)`), the reward the swarm's mean (`reward=
"mean"`) or summed (`"sum"`) reward; the episode terminates or is truncated when the swarm's
does, and `info` holds the per-agent infos and rewards. It passes Gymnasium's and
Stable-Baselines3's environment checkers; `examples/` trains SB3 PPO on it.

## Rendering

`render_mode="rgb_array"`: `render()` returns an (H, W, 3) uint8 frame: the city map with
buildings shaded by roof height, the start and goal areas and the UAV tracks; a close-up of the
swarm with each estimate's 2-sigma error ellipse (horizontal block of its covariance); a sky
plot of one UAV (skyline, satellites by constellation, blocked ones grey, NLOS ringed), like the
paper's Figure 6; and the per-UAV standalone and cooperative errors (`docs/render_example.png`
is a frame of a default episode half-way). `render_mode="human"` shows the same frame in a
matplotlib window. matplotlib is imported only when rendering (about 1 s per frame).

## Experimental settings

`obs_true_error` (and, for training, some settings of the `torchrl:` section) is
experimental: kept for the studies that used them, off by default,
and liable to change or go without notice. `coopnav_env.envs.config.EXPERIMENTAL_SETTINGS`
lists them, each with one line on what it does.

## Seeding, determinism and pickling

The environment owns one `numpy.random.Generator`, reseeded only by `reset(seed=...)`; the same
seed gives the same episode bit for bit. `reset()` without a seed continues the stream (a new
episode). `reset(seed=s, options={"noise_stream": k})` (k >= 1) gives the episode of seed `s`
(city, satellites, start, goal, first epoch) under another noise realisation: every later draw
comes from a generator seeded with `(s, k)`, so the same episode can be flown several times with
independent noise (variance reduction, e.g. `coopnav train-routes --noise-replicates`); `k = 0`
is the plain episode; other option keys are ignored. The environment pickles
(EzPickle with every argument, plus the generator and the world state): a restored copy
continues exactly like the original.

## Version History

* v1 (`coopnav_env.urban_canyon_v1`): the same world with a reward whose return is the
  task's score, and a crash-free start of 3 steps; v0 is unchanged and stays importable,
  as a legacy version for its studies (making it warns once per process).
* v0: Initial release (coopnav 0.1.0). Before the release the observation gained the route
  (next waypoint, the leg after it, remaining route), the altitude in the band and the wall
  distances (38 -> 52 entries by default), the progress reward moved from the straight-line
  distance to the goal to the remaining street route, the reward defaults changed so that a
  crash never pays (above), and the integrity gate `max_fix_sigma_m` was added.
* v0, unreleased changes that keep the version: the infos became flat and numeric with the
  same keys at reset and at every step (`reward_<term>` instead of the nested `reward_terms`,
  no `"initial"` nesting at reset, a missing fix reported as -1 with `coop_fix` /
  `standalone_fix` instead of `inf`), so that TorchRL's `PettingZooWrapper` and BenchMARL
  accept the environment; and the option `nav_team_weight` (team credit, default 0). With the
  defaults every observation, reward, termination, truncation and state is bit for bit what
  it was (`tests/envs/test_golden.py` converts the new infos back to the old layout and
  checks the recorded digests), so learning results do not change and the version is not
  bumped (PettingZoo bumps it for changes that can change learning results); code that read
  `infos[agent]["initial"]` or `infos[agent]["reward_terms"]` must read the flat keys.
  Optional integrity monitoring (`integrity`, off by default: episodes unchanged) was added
  with them. Also off by default, with the defaults' episodes unchanged: the observation
  options `obs_protection_level`, `obs_satellite_sectors`, `obs_lookahead`,
  `obs_candidate_sky` (both since removed) and `obs_true_error` (privileged, a diagnostic),
  and the world options
  `dead_reckoning_noise` and `preset`; and the reset option `noise_stream` (without it, reset
  is as before).
"""

from __future__ import annotations

import warnings
from typing import Any

from pettingzoo import AECEnv

from coopnav_env.envs.config import UrbanCanyonConfig
from coopnav_env.envs.urban_canyon import UrbanCanyonEnv as raw_env
from coopnav_env.envs.urban_canyon import aec_env as _aec_env
from coopnav_env.envs.urban_canyon import parallel_env as _parallel_env

__all__ = ["env", "parallel_env", "raw_env"]

LEGACY_WARNING = (
    "urban_canyon_v0 is a legacy version kept for the studies that used it: its return pays "
    "for a short trip as well as for low error. New work uses urban_canyon_v1 "
    "(from coopnav_env import urban_canyon_v1; coopnav train --env-id urban_canyon_v1), "
    "whose return is the task's score."
)
"""The text of the once-per-process warning of :func:`warn_legacy`."""

_warned = False


def warn_legacy() -> None:
    """Warn (``FutureWarning``) that v0 is legacy, the first time in this process only."""
    global _warned
    if not _warned:
        _warned = True
        warnings.warn(LEGACY_WARNING, FutureWarning, stacklevel=3)


def parallel_env(
    render_mode: str | None = None, config: UrbanCanyonConfig | None = None, **fields: Any
) -> raw_env:
    """The parallel environment ``urban_canyon_v0`` (legacy: warns once per process); every
    keyword is an :class:`~coopnav_env.envs.config.UrbanCanyonConfig` field."""
    warn_legacy()
    return _parallel_env(render_mode=render_mode, config=config, **fields)


def env(
    render_mode: str | None = None, config: UrbanCanyonConfig | None = None, **fields: Any
) -> AECEnv:
    """The AEC version of ``urban_canyon_v0`` (legacy: warns once per process)."""
    warn_legacy()
    return _aec_env(render_mode=render_mode, config=config, **fields)
