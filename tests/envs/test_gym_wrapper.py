"""The Gymnasium single-agent view of urban_canyon_v1 (coopnav/UrbanCanyonSwarm-v1, the default
id) and of the legacy urban_canyon_v0 (coopnav/UrbanCanyonSwarm-v0)."""

from __future__ import annotations

import pickle
import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

from coopnav_env import GYM_ENV_ID, GYM_ENV_ID_V0, GYM_ENV_ID_V1, urban_canyon_v1
from coopnav_env.envs.gym_wrapper import UrbanCanyonSwarmEnv, UrbanCanyonSwarmV1Env
from coopnav_env.urban_canyon_v0 import LEGACY_WARNING


def _episode(env, seed: int, action_seed: int, steps: int = 400) -> list:
    """Reset with ``seed``, then seeded random actions until the episode ends."""
    rng = np.random.default_rng(action_seed)
    obs, info = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(
            0.3 * rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        )
        out.append((obs, reward, terminated, truncated, info["agent_rewards"]))
        if terminated or truncated:
            break
    return out


def test_registered_on_import_without_heavy_imports() -> None:
    code = (
        "import sys, gymnasium, coopnav_env\n"
        "assert coopnav_env.GYM_ENV_ID == 'coopnav/UrbanCanyonSwarm-v1'\n"
        "assert coopnav_env.GYM_ENV_ID in gymnasium.registry\n"
        "spec = gymnasium.spec(coopnav_env.GYM_ENV_ID)\n"
        "assert spec.entry_point == 'coopnav_env.envs.gym_wrapper:UrbanCanyonSwarmV1Env'\n"
        "legacy = gymnasium.spec(coopnav_env.GYM_ENV_ID_V0)\n"
        "assert legacy.entry_point == 'coopnav_env.envs.gym_wrapper:UrbanCanyonSwarmEnv'\n"
        "assert spec.max_episode_steps is None\n"  # the env truncates itself
        "heavy = [m for m in ('numba', 'pettingzoo', 'coopnav_env.envs') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "import importlib; importlib.reload(coopnav_env)\n"  # a second registration is skipped
    )
    res = subprocess.run(
        [sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr


def test_import_does_not_load_gymnasium_and_registers_when_it_loads() -> None:
    """``import coopnav_env`` leaves Gymnasium unloaded; importing it afterwards (directly or
    through PettingZoo) registers both ids, and the v1 id makes an environment."""
    code = (
        "import sys, coopnav_env\n"
        "assert 'gymnasium' not in sys.modules\n"
        "import pettingzoo.utils\n"  # loads gymnasium on the way
        "import gymnasium\n"
        "assert coopnav_env.GYM_ENV_ID in gymnasium.registry\n"
        "assert coopnav_env.GYM_ENV_ID_V0 in gymnasium.registry\n"
        "env = gymnasium.make(coopnav_env.GYM_ENV_ID, n_uavs=2)\n"
        "assert env.reset(seed=0)[0].shape == (2 * 52,)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr


def test_gymnasium_env_checker_passes() -> None:
    env = gymnasium.make(GYM_ENV_ID)
    assert isinstance(env.unwrapped, UrbanCanyonSwarmV1Env)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(env)
        gym_check_env(env.unwrapped)
    messages = [str(w.message) for w in caught]
    # the only warning: gymnasium.make's own wrappers (PassiveEnvChecker, OrderEnforcing)
    assert all("is different from the unwrapped version" in m for m in messages), messages
    assert len(messages) == 1


@pytest.mark.parametrize("env_id", [GYM_ENV_ID_V0, GYM_ENV_ID_V1])
def test_stable_baselines3_env_checker_passes(env_id: str) -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(gymnasium.make(env_id, n_uavs=3), warn=True)
    # (the legacy warning of v0 comes once per process: whether here depends on test order)
    messages = [str(w.message) for w in caught if str(w.message) != LEGACY_WARNING]
    if env_id == GYM_ENV_ID_V0:  # Gymnasium's own note that v1 supersedes v0, and nothing else
        assert len(messages) == 1 and "out of date" in messages[0] and "v1" in messages[0]
    else:
        assert messages == []


def test_spaces_and_kwargs_are_forwarded() -> None:
    env = gymnasium.make(GYM_ENV_ID, n_uavs=3, city="canyon", max_cycles=6, obs_neighbours=2)
    inner = env.unwrapped
    cfg = inner.config
    assert (cfg.n_uavs, cfg.city, cfg.max_steps, cfg.obs_neighbours) == (3, "canyon", 6, 2)
    d = cfg.obs_dim
    assert env.observation_space.shape == (3 * d,) and env.observation_space.dtype == np.float32
    assert env.action_space.shape == (9,)
    assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    space = inner.par_env.observation_space("uav_0")
    np.testing.assert_array_equal(env.observation_space.low.reshape(3, d)[2], space.low)
    assert inner.layout.dim == d
    # the episode is truncated (not terminated) after max_cycles steps, hovering in place
    env.reset(seed=0)
    for step in range(1, 7):
        _, _, terminated, truncated, info = env.step(np.zeros(9, dtype=np.float32))
        assert not terminated and truncated == (step == 6)
    assert not info["active"].any()
    with pytest.raises(ValueError, match="unknown urban_canyon argument"):
        gymnasium.make(GYM_ENV_ID, n_drones=3)
    with pytest.raises(ValueError, match=r"reward must be one of \('mean', 'sum'\)"):
        gymnasium.make(GYM_ENV_ID, reward="max")


def test_same_seed_same_episode_and_equal_to_the_pettingzoo_episode() -> None:
    a = gymnasium.make(GYM_ENV_ID, max_steps=60)
    b = gymnasium.make(GYM_ENV_ID, max_steps=60)
    ep_a = _episode(a, seed=7, action_seed=1)
    assert pickle.dumps(ep_a) == pickle.dumps(_episode(b, seed=7, action_seed=1))
    assert pickle.dumps(ep_a[0]) != pickle.dumps(_episode(b, seed=8, action_seed=1)[0])

    # the same episode through the PettingZoo API: stacked observations, mean reward
    par = urban_canyon_v1.parallel_env(max_steps=60)
    rng = np.random.default_rng(1)
    obs, _ = par.reset(seed=7)
    agents = par.possible_agents
    assert np.array_equal(ep_a[0], np.concatenate([obs[x] for x in agents]))
    for obs_g, reward_g, term_g, trunc_g, per_agent in ep_a[1:]:
        act = (0.3 * rng.uniform(-1, 1, 3 * len(agents)).astype(np.float32)).reshape(-1, 3)
        obs, rewards, terms, truncs, _ = par.step({x: act[i] for i, x in enumerate(agents)})
        assert np.array_equal(obs_g, np.concatenate([obs[x] for x in agents]))
        assert np.array_equal(per_agent, [rewards[x] for x in agents])
        assert reward_g == pytest.approx(np.mean(per_agent), rel=1e-12)
        assert (term_g, trunc_g) == (any(terms.values()), any(truncs.values()))
    assert not par.agents and len(ep_a) > 10  # ended by a crash (terminated)


def test_sum_reward_and_infos() -> None:
    env = gymnasium.make(GYM_ENV_ID, reward="sum", n_uavs=4)
    _, info = env.reset(seed=3)
    assert set(info) == {"agent_infos", "agent_rewards", "active"}
    assert list(info["agent_infos"]) == [f"uav_{i}" for i in range(4)] and info["active"].all()
    _, reward, *_, info = env.step(np.full(12, 0.3, dtype=np.float32))
    assert reward == pytest.approx(info["agent_rewards"].sum(), rel=1e-12)
    assert info["agent_rewards"].shape == (4,) and np.any(info["agent_rewards"] != 0)
    with pytest.raises(ValueError, match=r"action must have shape \(12,\).*got shape \(4, 3\)"):
        env.step(np.zeros((4, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.full(12, np.nan, dtype=np.float32))


class _DepartingStub:
    """A PettingZoo-style parallel env in which ``uav_1`` leaves after the first step while the
    others fly on (urban_canyon_v1 never does this; PettingZoo allows it)."""

    def __init__(self) -> None:
        self.possible_agents = ["uav_0", "uav_1", "uav_2"]
        self.agents: list[str] = []
        self.t = 0
        self.seen: list[set] = []

    def reset(self, seed=None, options=None):
        self.agents, self.t = self.possible_agents[:], 0
        return {a: np.full(2, 0.5 + i, np.float32) for i, a in enumerate(self.agents)}, {}

    def step(self, actions):
        self.seen.append(set(actions))
        self.t += 1
        live = self.agents
        obs = {a: np.full(2, self.t, np.float32) for a in live}
        rewards = {a: float(i + 1) for i, a in enumerate(live)}
        terms = {a: a == "uav_1" for a in live}
        truncs = {a: self.t == 3 for a in live}
        self.agents = [a for a in live if not terms[a] and not truncs[a]]
        return obs, rewards, terms, truncs, {a: {} for a in live}


def test_departed_agents_keep_the_stack_size_with_zeros() -> None:
    env = UrbanCanyonSwarmEnv(n_uavs=3)
    env.par_env = stub = _DepartingStub()
    env._d = 2
    obs, info = env.reset(seed=0)
    assert obs.tolist() == [0.5, 0.5, 1.5, 1.5, 2.5, 2.5]
    # step 1: uav_1 terminates; its final observation is still in the stack
    obs, reward, terminated, truncated, info = env.step(np.zeros(9, np.float32))
    assert obs.tolist() == [1, 1, 1, 1, 1, 1] and reward == pytest.approx(2.0)
    assert not terminated and not truncated and info["active"].tolist() == [True, False, True]
    # step 2: uav_1 gets no action, its row is zeros, the mean is over the two still flying
    obs, reward, terminated, truncated, info = env.step(np.zeros(9, np.float32))
    assert stub.seen[-1] == {"uav_0", "uav_2"}
    assert obs.tolist() == [2, 2, 0, 0, 2, 2] and reward == pytest.approx(1.5)
    assert info["agent_rewards"].tolist() == [1.0, 0.0, 2.0]
    # step 3: the others are truncated; the swarm episode ends truncated, not terminated
    obs, reward, terminated, truncated, info = env.step(np.zeros(9, np.float32))
    assert (terminated, truncated) == (False, True) and not info["active"].any()
    assert obs.tolist() == [3, 3, 0, 0, 3, 3]


def test_rgb_array_render_is_the_pettingzoo_frame() -> None:
    env = gymnasium.make(GYM_ENV_ID, render_mode="rgb_array", n_uavs=2)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (640, 1280, 3) and frame.dtype == np.uint8
    env.close()


def test_the_legacy_v0_id_warns_once_per_process() -> None:
    """Making ``coopnav/UrbanCanyonSwarm-v0`` warns (FutureWarning) the first time only; v1
    never does."""
    code = (
        "import warnings, gymnasium, coopnav_env\n"
        "from coopnav_env.urban_canyon_v0 import LEGACY_WARNING\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    gymnasium.make(coopnav_env.GYM_ENV_ID, n_uavs=2)\n"
        "    assert not [w for w in caught if w.category is FutureWarning], caught\n"
        "    gymnasium.make(coopnav_env.GYM_ENV_ID_V0, n_uavs=2)\n"
        "    gymnasium.make(coopnav_env.GYM_ENV_ID_V0, n_uavs=2)\n"
        "legacy = [w for w in caught if str(w.message) == LEGACY_WARNING]\n"
        "assert len(legacy) == 1 and legacy[0].category is FutureWarning, caught\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
