"""Grid-city generation, the street draws of a reset, its choice of a goal and street routes
equal their numpy oracles (``tests/sim/oracles.py``: the constructors' checked path,
``rng.choice``, ``argmax`` over the distances, the array formulation of the route) bit for
bit, and leave the generator in the same state."""

from __future__ import annotations

import numpy as np
import pytest

from coopnav_env.sim import _kernels as sim_kernels
from coopnav_env.sim import scenario
from coopnav_env.sim.city import CityConfig, generate_city
from tests.sim import oracles

CONFIGS = [
    CityConfig(),
    CityConfig(n_blocks_x=3, n_blocks_y=7, buildings_per_block=1, open_square_fraction=0.0),
    CityConfig(n_blocks_x=9, n_blocks_y=2, buildings_per_block=5, building_gap_m=2.5),
    CityConfig(n_blocks_x=2, n_blocks_y=2, open_square_fraction=1.0),  # no buildings
    CityConfig(block_size_m=37.5, street_width_m=11.25, height_std_m=0.0),
]


def _city_bytes(city) -> list[bytes]:
    b = city.buildings
    arrays = (b.min_m, b.max_m, city.street_centres_x_m, city.street_centres_y_m)
    return [a.tobytes() for a in (*arrays, city.open_squares)] + [
        repr((city.extent_m, city.street_width_m, [a.shape for a in arrays])).encode()
    ]


@pytest.mark.parametrize("config", CONFIGS)
def test_generate_city_matches_oracle(config: CityConfig) -> None:
    for seed in range(20):
        fast_rng, ref_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        fast, ref = generate_city(config, fast_rng), oracles.generate_city(config, ref_rng)
        assert _city_bytes(fast) == _city_bytes(ref)
        assert fast.config is ref.config and fast.canyon_mask is None
        assert not fast.buildings.min_m.flags.writeable
        assert not fast.street_centres_x_m.flags.writeable
        assert fast_rng.random() == ref_rng.random()  # the same draws, no more, no fewer


@pytest.mark.parametrize("config", CONFIGS[:3])
def test_street_frames_match_rng_choice(config: CityConfig) -> None:
    city = generate_city(config, np.random.default_rng(0))
    for seed in range(50):
        a, b = np.random.default_rng(seed), np.random.default_rng(seed)
        xy, ns = scenario._street_frames(city, a, 256, 4.0)
        xy_ref, ns_ref = oracles.street_frames(city, b, 256, 4.0)
        assert xy.tobytes() == xy_ref.tobytes() and ns.tobytes() == ns_ref.tobytes()
        assert a.random() == b.random()
    assert ns.any() and not ns.all()  # both orientations drawn


def test_street_frames_of_cities_with_other_streets_match_rng_choice() -> None:
    # the streets' distribution is remembered per city layout: cities of several layouts,
    # drawn in turn, each get their own streets
    cities = [generate_city(config, np.random.default_rng(3)) for config in CONFIGS[:3]]
    for seed in range(30):
        city = cities[seed % len(cities)]
        a, b = np.random.default_rng(seed), np.random.default_rng(seed)
        xy, ns = scenario._street_frames(city, a, 64, 2.0)
        xy_ref, ns_ref = oracles.street_frames(city, b, 64, 2.0)
        assert xy.tobytes() == xy_ref.tobytes() and ns.tobytes() == ns_ref.tobytes()


def test_far_candidate_is_the_first_far_enough_else_the_first_farthest() -> None:
    # the goal of a reset: numpy's (d >= min).argmax(), and d.argmax() where none is far
    # enough, over distances with ties (repeated candidates)
    rng = np.random.default_rng(5)
    fallbacks = 0
    for _ in range(300):
        cand = rng.uniform(-300.0, 300.0, (int(rng.integers(1, 30)), 2))
        cand = np.concatenate([cand, cand[::2]])  # equal distances, later in the list
        centre = rng.uniform(-50.0, 50.0, 2)
        d = cand - centre
        dist = np.hypot(d[:, 0], d[:, 1])
        min_m = float(rng.choice([0.0, float(np.median(dist)), float(dist.max()) + 1.0]))
        pick = int((dist >= min_m).argmax())
        if not dist[pick] >= min_m:
            pick = int(dist.argmax())
            fallbacks += 1
        assert sim_kernels.far_candidate(cand, centre, min_m) == pick
    assert fallbacks > 50  # the farthest taken where none was far enough


@pytest.mark.parametrize("config", CONFIGS[:3])
def test_street_routes_and_their_lengths_match_the_numpy_definition(config: CityConfig) -> None:
    from coopnav_env.sim.route import route_tail_lengths_m, street_route

    city = generate_city(config, np.random.default_rng(1))
    x0, x1, y0, y1 = city.extent_m
    rng = np.random.default_rng(2)
    ends = [rng.uniform((x0, y0), (x1, y1), size=(2, 2)) for _ in range(300)]
    ends += [np.array([[np.nan, 3.0], [5.0, 6.0]]), np.array([[3.0, np.nan], [5.0, 6.0]])]
    ends += [np.array([[np.inf, 0.0], [1.0, 2.0]]), np.array([[1.0, 2.0], [1.0, 2.0]])]
    ends += [np.array([[np.inf, np.inf], [1.0, 2.0]]), np.array([[1.0, 2.0], [-np.inf, 5.0]])]
    for start, goal in ends:
        route, ref = street_route(city, start, goal), oracles.street_route(city, start, goal)
        assert route.tobytes() == ref.tobytes()
        if np.isfinite(route).all():
            tail = route_tail_lengths_m(route)
            assert tail.tobytes() == oracles.route_tail_lengths_m(route).tobytes()
