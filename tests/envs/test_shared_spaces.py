"""The spaces of one configuration share their bound arrays, never their random generators."""

from __future__ import annotations

import numpy as np

from coopnav_env import urban_canyon_v1


def test_spaces_share_bounds_across_agents_and_copies() -> None:
    a, b = urban_canyon_v1.parallel_env(n_uavs=3), urban_canyon_v1.parallel_env(n_uavs=3)
    boxes = [env.observation_space(agent) for env in (a, b) for agent in env.possible_agents]
    assert len({id(box) for box in boxes}) == len(boxes)  # one object per agent and copy
    assert all(box.low is boxes[0].low and box.high is boxes[0].high for box in boxes)
    assert all(box == boxes[0] for box in boxes)
    acts = [env.action_space(agent) for env in (a, b) for agent in env.possible_agents]
    assert len({id(box) for box in acts}) == len(acts)
    assert all(box.low is acts[0].low for box in acts)
    assert a.state_space is not b.state_space and a.state_space.low is b.state_space.low
    # another configuration: other bounds
    c = urban_canyon_v1.parallel_env(n_uavs=3, obs_neighbours=2)
    assert c.observation_space("uav_0").shape != boxes[0].shape


def test_seeding_one_space_leaves_the_others_alone() -> None:
    a, b = urban_canyon_v1.parallel_env(n_uavs=2), urban_canyon_v1.parallel_env(n_uavs=2)
    for env in (a, b):
        for i, agent in enumerate(env.possible_agents):
            env.action_space(agent).seed(10 + i)
    first = [a.action_space(agent).sample() for agent in a.possible_agents]
    again = [b.action_space(agent).sample() for agent in b.possible_agents]
    for x, y in zip(first, again, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(first[0], first[1])  # each agent its own generator
    a.observation_space("uav_0").seed(3)
    b.observation_space("uav_0").seed(3)
    a.observation_space("uav_1").sample()  # draws from uav_1's generator only
    np.testing.assert_array_equal(
        a.observation_space("uav_0").sample(), b.observation_space("uav_0").sample()
    )
