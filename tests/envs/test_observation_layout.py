"""The named observation layout (coopnav_env.envs.obs_layout) against the environment."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.envs import UrbanCanyonConfig, obs_layout
from coopnav_env.envs.observation_layout import ObsField, city_scale_m
from coopnav_env.sim.route import remaining_route_m

CONFIGS = [
    {},
    {"obs_sky_azimuths": 12, "obs_neighbours": 2},
    {"obs_neighbours": 0, "obs_sky_azimuths": 1},
    {"city": "canyon", "n_uavs": 3, "obs_neighbours": 6},
    {"n_uavs": 7, "kinematics": {"altitude_min_m": 8.0, "altitude_max_m": 40.0}},
    {"city_config": {"n_blocks_x": 4, "n_blocks_y": 7, "street_width_m": 25.0}},
]


@pytest.mark.parametrize("kwargs", CONFIGS)
def test_layout_covers_every_index_once_and_matches_the_space(kwargs) -> None:
    layout = obs_layout(**kwargs)
    cfg = layout.config
    covered = np.concatenate([np.arange(f.start, f.stop) for f in layout.values()])
    # in index order, no gap, no overlap, and exactly obs_dim = 20 + 2A + 4K entries
    assert covered.tolist() == list(range(cfg.obs_dim))
    assert layout.dim == cfg.obs_dim == 20 + 2 * cfg.obs_sky_azimuths + 4 * cfg.obs_neighbours
    assert len(layout) == 14 + 2 * cfg.obs_neighbours  # 14 fields + two per neighbour slot
    for f in layout.values():
        assert f.size == len(f.components) > 0
        assert f.scale > 0 and f.units in {"m", "m/s", "deg", "steps", "1", "flag"}
    space = urban_canyon_v0.parallel_env(**kwargs).observation_space("uav_0")
    low, high = layout.bounds()
    np.testing.assert_array_equal(low, space.low)
    np.testing.assert_array_equal(high, space.high)


def test_default_layout_matches_the_documented_indices() -> None:
    """The documentation page's "With the defaults" index list, field by field."""
    layout = obs_layout()
    expected = {
        "position_to_goal": (0, 3),
        "velocity": (3, 6),
        "sigma": (6, 9),
        "satellites": (9, 10),
        "swarm_satellites": (10, 11),
        "skyline": (11, 19),
        "neighbour_0": (19, 22),
        "neighbour_0_present": (22, 23),
        "neighbour_3_present": (34, 35),
        "cooperative_fix": (35, 36),
        "fresh_fix": (36, 37),
        "time_left": (37, 38),
        "next_waypoint": (38, 40),
        "next_leg": (40, 42),
        "remaining_route": (42, 43),
        "altitude": (43, 44),
        "wall_distance": (44, 52),
    }
    for name, (start, stop) in expected.items():
        assert layout[name].slice == slice(start, stop), name
    assert layout["next_waypoint"].units == "m" and layout["next_waypoint"].scale == 50.0
    assert (layout["altitude"].offset, layout["altitude"].scale) == (5.0, 25.0)
    assert layout["skyline"].components[2] == "90 deg"
    assert layout.neighbour_present_indices().tolist() == [22, 26, 30, 34]


@pytest.mark.parametrize("kwargs", [CONFIGS[0], CONFIGS[3], CONFIGS[5]])
def test_city_scale_is_the_environments_in_every_episode(kwargs) -> None:
    env = urban_canyon_v0.parallel_env(**kwargs)
    scale = obs_layout(env).city_scale_m
    assert scale == city_scale_m(env.config)
    for seed in range(4):  # a new random city per episode: the extent does not change
        env.reset(seed=seed)
        assert env.unwrapped._city_scale_m == scale


@pytest.mark.parametrize("kwargs", [CONFIGS[0], CONFIGS[1], CONFIGS[4]])
def test_decoded_fields_are_the_physical_quantities(kwargs) -> None:
    """Every field decodes to the quantity it names, within float32 rounding of the entry.

    An entry in [-1, 1] stored as float32 is off by at most 2**-24 relative (6e-8), so its
    decoded value is off by at most 6e-8 * scale (plus float64 rounding); atol = 1e-7 * scale.
    Values outside the entry's bounds decode to the clipped bound.
    """
    from coopnav_env.agents.heuristics import WaypointPolicy

    env = urban_canyon_v0.parallel_env(max_steps=40, **kwargs)
    layout = obs_layout(env)
    cfg = env.config
    policy = WaypointPolicy(env, altitude_m=28.0)  # climbs: the altitude entry changes
    obs, _ = env.reset(seed=11)
    checked = 0
    for _ in range(25):
        ep = env.unwrapped._epoch
        world = env.unwrapped.world
        o = np.stack([obs[a] for a in env.possible_agents])
        d = layout.decode(o)

        def close(name, truth, d=d):
            f = layout[name]
            lo, hi = f.offset + f.low * f.scale, f.offset + f.high * f.scale
            np.testing.assert_allclose(
                d[name], np.clip(truth, lo, hi), rtol=0, atol=1e-7 * f.scale, err_msg=name
            )

        close("position_to_goal", ep.nav_pos_enu_m - ep.goal_enu_m)
        close("velocity", ep.vel_enu_mps)
        close("sigma", ep.nav_sigma_enu_m)
        close("satellites", (ep.n_sats / max(ep.n_above_mask, 1))[:, None])
        close("altitude", ep.nav_pos_enu_m[:, 2:3])
        close("time_left", np.full((cfg.n_uavs, 1), cfg.max_steps - env.unwrapped._steps))
        route, wp = world.route_xy_m, ep.next_waypoint
        close("next_waypoint", route[wp] - ep.nav_pos_enu_m[:, :2])
        close("next_leg", route[np.minimum(wp + 1, len(route) - 1)] - route[wp])
        remaining = remaining_route_m(route, ep.nav_pos_enu_m[:, :2], wp, world.route_tail_m)
        close("remaining_route", remaining[:, None])
        sky, walls = world.city.sky_and_walls(
            ep.pos_enu_m, np.arange(cfg.obs_sky_azimuths) * 360.0 / cfg.obs_sky_azimuths
        )
        close("skyline", sky)
        close("wall_distance", walls)
        # neighbour slots: the k-th nearest measured neighbour, its flag set
        for i in range(cfg.n_uavs):
            avail = ep.rel_available[i]
            rel = ep.rel_enu_m[i][avail]
            rel = rel[np.argsort(np.linalg.norm(rel, axis=1), kind="stable")]
            for k in range(cfg.obs_neighbours):
                present = d[f"neighbour_{k}_present"][i, 0]
                if k < len(rel):
                    assert present == 1.0
                    f = layout[f"neighbour_{k}"]
                    np.testing.assert_allclose(
                        d[f.name][i], np.clip(rel[k], -f.scale, f.scale), atol=1e-7 * f.scale
                    )
                else:
                    assert present == 0.0 and np.all(d[f"neighbour_{k}"][i] == 0.0)
        assert np.all(d["cooperative_fix"][:, 0] == (ep.nav_source == 0))
        assert np.all(d["fresh_fix"][:, 0] == (ep.nav_source != 2))
        checked += 1
        if not env.agents:
            break
        obs, *_ = env.step(policy.act(obs))
    assert checked == 25


def test_decode_keeps_the_hand_written_arithmetic() -> None:
    """decode is ``value * scale`` (no ``+ 0.0``: a -0.0 stays -0.0) and ``offset + value *
    scale`` with an offset, bit for bit."""
    layout = obs_layout()
    o = np.linspace(-1.0, 1.0, 52 * 3).reshape(3, 52).astype(np.float32)
    o[0, 38] = -0.0
    wp = layout["next_waypoint"].decode(o)
    assert np.array_equal(wp, o[:, 38:40].astype(np.float64) * 50.0)
    assert np.signbit(wp[0, 0])
    alt = layout["altitude"].decode(o)[:, 0]
    assert np.array_equal(alt, 5.0 + o[:, 43].astype(np.float64) * 25.0)
    single = layout["altitude"].decode(o[1])
    assert single.shape == (1,) and single[0] == alt[1]


def test_layout_arguments_and_errors() -> None:
    cfg = UrbanCanyonConfig(obs_neighbours=2)
    assert obs_layout(cfg).dim == obs_layout(obs_neighbours=2).dim == 44
    assert obs_layout(cfg, obs_neighbours=3).dim == 48
    assert isinstance(obs_layout()["velocity"], ObsField)
    with pytest.raises(KeyError, match="no observation field 'speed'; fields: position_to_goal"):
        obs_layout()["speed"]
    with pytest.raises(ValueError, match="obs_layout needs an UrbanCanyonConfig"):
        obs_layout("default")
    with pytest.raises(ValueError, match="obs_neighbours must be an integer in"):
        obs_layout(obs_neighbours=-1)
    assert "next_waypoint" in repr(obs_layout())
