"""BatchedUrbanCanyonEnv: K copies stepped together equal K separate parallel environments."""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os

import numpy as np
import pytest
from numba import njit

from coopnav_env import urban_canyon_v0, urban_canyon_v1
from coopnav_env.envs import BatchedUrbanCanyonEnv, _batched_kernels, _fused
from coopnav_env.envs._fused import fused_settings
from coopnav_env.sim.scenario import Epoch

SETTINGS = {"n_uavs": 4, "max_steps": 6}


def _same(a, b) -> bool:
    """Equality of nested infos, NaN equal to NaN."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return type(a) is type(b) and a == b


def assert_same_records(fused: list, world: list) -> None:
    """Assert two recordings of one episode sequence equal bit for bit: each entry an
    ``Epoch`` (every field's bytes and dtype), a ``step`` result (observations, rewards, ends,
    infos by value and by bytes) or a reset's observations."""
    assert len(fused) == len(world)
    for a, b in zip(fused, world, strict=True):
        if isinstance(b, Epoch):
            for f in dataclasses.fields(b):
                x, y = getattr(a, f.name), getattr(b, f.name)
                assert np.asarray(x).tobytes() == np.asarray(y).tobytes(), f.name
                assert np.asarray(x).dtype == np.asarray(y).dtype, f.name
        elif isinstance(b, tuple):
            obs_a, rew_a, te_a, tr_a, inf_a = a
            obs_b, rew_b, te_b, tr_b, inf_b = b
            assert all(obs_a[k].tobytes() == obs_b[k].tobytes() for k in obs_b)
            assert rew_a == rew_b and te_a == te_b and tr_a == tr_b
            assert _same(inf_a, inf_b)
            for agent in inf_b:
                for key, v in inf_b[agent].items():
                    w = inf_a[agent][key]
                    assert np.asarray(w).tobytes() == np.asarray(v).tobytes(), key
        else:
            assert all(a[k].tobytes() == b[k].tobytes() for k in b)


def test_copies_equal_separate_environments_across_episode_ends() -> None:
    k_copies, seed = 3, 10
    batch = BatchedUrbanCanyonEnv(k_copies, **SETTINGS)
    single = [urban_canyon_v0.parallel_env(**SETTINGS) for _ in range(k_copies)]
    obs, infos = batch.reset(seed=seed)
    for k, env in enumerate(single):
        o, i = env.reset(seed=seed + k)
        assert np.array_equal(obs[k], np.stack([o[a] for a in env.possible_agents]))
        assert _same(infos[k], i)
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0}
    for _ in range(25):
        # beyond [-1, 1] on purpose: both clip
        act = rng.uniform(-1.3, 1.3, (k_copies, SETTINGS["n_uavs"], 3)).astype(np.float32)
        obs, rew, term, trunc, infos, final = batch.step(act)
        assert obs.dtype == np.float32 and rew.shape == (k_copies, SETTINGS["n_uavs"])
        for k, env in enumerate(single):
            agents = env.possible_agents
            o, r, te, tr, i = env.step({a: act[k, j] for j, a in enumerate(agents)})
            assert np.array_equal(final[k], np.stack([o[a] for a in agents]))
            assert np.array_equal(rew[k], np.array([r[a] for a in agents]))
            assert term[k] == te[agents[0]] and trunc[k] == tr[agents[0]]
            assert _same(infos[k], i)
            if not env.agents:  # episode over: the batch has reset this copy already
                ends["terminated" if term[k] else "truncated"] += 1
                o, _ = env.reset()
            assert np.array_equal(obs[k], np.stack([o[a] for a in agents]))
    assert ends["terminated"] > 0 and ends["truncated"] > 0  # both kinds of end covered


def test_seed_sequences_and_flat_actions() -> None:
    batch = BatchedUrbanCanyonEnv(2, n_uavs=2, max_steps=3)
    obs, _ = batch.reset(seed=[7, None])
    ref = urban_canyon_v0.parallel_env(n_uavs=2, max_steps=3)
    o, _ = ref.reset(seed=7)
    assert np.array_equal(obs[0], np.stack([o[a] for a in ref.possible_agents]))
    batch.step(np.zeros((4, 3)))  # (K * N, 3) is accepted


def test_bad_use_raises() -> None:
    batch = BatchedUrbanCanyonEnv(2, n_uavs=2)
    with pytest.raises(ValueError, match="before reset"):
        batch.step(np.zeros((2, 2, 3)))
    batch.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        batch.step(np.zeros((2, 3, 3)))
    bad = np.zeros((2, 2, 3))
    bad[1, 0, 2] = np.nan
    with pytest.raises(ValueError, match=r"NaN or inf \(copies \[1\]\)"):
        batch.step(bad)
    with pytest.raises(ValueError, match="2 seeds"):
        batch.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="n_copies"):
        BatchedUrbanCanyonEnv(0)
    with pytest.raises(ValueError, match="same configuration"):
        BatchedUrbanCanyonEnv.from_envs(
            [urban_canyon_v0.parallel_env(n_uavs=2), urban_canyon_v0.parallel_env(n_uavs=3)]
        )
    with pytest.raises(ValueError, match="render"):
        BatchedUrbanCanyonEnv(1, render_mode="rgb_array")
    env = urban_canyon_v0.parallel_env(n_uavs=2)
    with pytest.raises(ValueError, match="distinct"):
        BatchedUrbanCanyonEnv.from_envs([env, env])


def _step_alongside(batch, single, steps: int, seed: int, scale: float = 1.0) -> list[int]:
    """Step ``batch`` and the separate environments ``single`` with the same random commands;
    assert every output equal bit for bit (and each copy's ``state()``); return the steps at
    which episodes ended."""
    k_copies, n = batch.n_copies, batch.n_agents
    obs, infos = batch.reset(seed=seed)
    for k, env in enumerate(single):
        o, i = env.reset(seed=seed + k)
        assert obs[k].tobytes() == np.stack([o[a] for a in env.possible_agents]).tobytes()
        assert _same(infos[k], i)
    rng = np.random.default_rng(seed)
    end_steps = []
    for step in range(steps):
        act = rng.uniform(-scale, scale, (k_copies, n, 3))
        obs, rew, term, trunc, infos, final = batch.step(act)
        for k, env in enumerate(single):
            agents = env.possible_agents
            o, r, te, tr, i = env.step({a: act[k, j] for j, a in enumerate(agents)})
            assert final[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
            assert rew[k].tobytes() == np.array([r[a] for a in agents]).tobytes()
            assert term[k] == te[agents[0]] and trunc[k] == tr[agents[0]]
            assert _same(infos[k], i)
            if not env.agents:
                end_steps.append(step)
                o, _ = env.reset()
            assert obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
            assert batch.envs[k].state().tobytes() == env.state().tobytes()
    return end_steps


@pytest.mark.parametrize(
    "settings",
    [
        {"n_uavs": 5, "max_steps": 9},  # one centroid per UAV
        {"n_uavs": 12, "max_steps": 5},  # one shared centroid (centroid="auto", N >= 11)
        {"n_uavs": 1, "max_steps": 4},
    ],
)
def test_fused_step_copies_equal_batch_of_one(settings) -> None:
    # copy k of K = 8 (the fused step: all copies in one set of compiled calls, in threads)
    # equals the parallel environment reset with seed + k, bit for bit, across episodes
    # that end at different steps (crashes of random commands and truncations)
    k_copies = 8
    batch = BatchedUrbanCanyonEnv(k_copies, **settings)
    assert fused_settings(batch.config)
    single = [urban_canyon_v0.parallel_env(**settings) for _ in range(k_copies)]
    end_steps = _step_alongside(batch, single, steps=14, seed=21)
    assert batch._fused_step.state is not None  # the fused step ran
    assert len(set(end_steps)) >= 3  # episodes ended at several different steps
    # a batch of one is the same episode as copy 0 of the batch of eight
    one = BatchedUrbanCanyonEnv(1, **settings)
    assert _step_alongside(one, single[:1], steps=10, seed=21) is not None


def test_settings_outside_the_fused_step_step_copy_by_copy() -> None:
    settings = {"n_uavs": 3, "max_steps": 6, "nlos_probability": 0.3}
    batch = BatchedUrbanCanyonEnv(4, **settings)
    assert not fused_settings(batch.config)
    single = [urban_canyon_v0.parallel_env(**settings) for _ in range(4)]
    assert _step_alongside(batch, single, steps=8, seed=3)
    assert batch._fused_step.state is None


@pytest.mark.parametrize(
    "settings",
    [
        {"n_uavs": 5, "max_steps": 12},
        {"n_uavs": 12, "max_steps": 6},
        {"n_uavs": 4, "max_steps": 10, "nav_reward": "sigma", "nav_team_weight": 0.5},
        {"v1": True, "n_uavs": 5, "max_steps": 12},  # v1's crash-free start
        {"v1": True, "n_uavs": 5, "max_steps": 12, "crash_free_steps": 8},
        # the route frame (its autopilot on the previous estimates) and the agent index
        {
            "v1": True,
            "n_uavs": 5,
            "max_steps": 12,
            "action_frame": "route",
            "obs_agent_index": True,
        },
        {"v1": True, "n_uavs": 3, "max_steps": 9, "action_frame": "route", "crash_free_steps": 0},
    ],
)
def test_fused_step_equals_the_world_step(monkeypatch, settings) -> None:
    # the parallel environment steps as a batch of one (coopnav_env.envs._fused); the same
    # episodes through UrbanWorld.step (the fused step off) are equal bit for bit
    def run(fused: bool) -> list:
        if not fused:
            monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
        fields = dict(settings)
        module = urban_canyon_v1 if fields.pop("v1", False) else urban_canyon_v0
        env = module.parallel_env(**fields)
        obs, _ = env.reset(seed=8)
        rng = np.random.default_rng(4)
        out = [obs]
        for _ in range(30):
            act = {a: rng.uniform(-1.0, 1.0, 3) for a in env.agents}
            out.append(env.step(act))
            out.append(env.world.last)
            if not env.agents:
                out.append(env.reset()[0])
        monkeypatch.undo()
        return out

    fused, world = run(True), run(False)
    assert len(fused) == len(world)
    assert_same_records(fused, world)


def test_copies_epochs_read_late_or_copied_equal_those_read_at_once() -> None:
    # a fused step makes each copy's epoch when one of its fields is first read: read after
    # later steps and automatic resets, pickled or deep-copied, it is the epoch of its step
    import copy
    import pickle

    def run(read_at_once: bool) -> list:
        batch = BatchedUrbanCanyonEnv(3, n_uavs=4)
        batch.reset(seed=5)
        rng = np.random.default_rng(6)
        epochs = []
        for _ in range(12):  # random commands: copies crash and reset along the way
            batch.step(rng.uniform(-1.0, 1.0, (3, 4, 3)))
            for e in batch.envs:
                epochs.append(e.world.last)
                if read_at_once:
                    _ = e.world.last.t_s
        return epochs

    at_once, late = run(True), run(False)
    assert_same_records(late, at_once)
    copies = [pickle.loads(pickle.dumps(ep)) for ep in run(False)]
    copies += [copy.deepcopy(ep) for ep in run(False)]
    assert all(type(c) is Epoch for c in copies)
    assert_same_records(copies, at_once + at_once)


def _step_in_child(batch, queue) -> None:
    obs, *_ = batch.step(np.zeros((batch.n_copies, batch.n_agents, 3)))
    queue.put(obs.copy())


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_fused_step_runs_in_a_forked_child() -> None:
    # the parent's thread pool has no threads in a forked child: the child makes its own
    batch = BatchedUrbanCanyonEnv(16, n_uavs=3)
    batch.reset(seed=2)
    batch.step(np.zeros((16, 3, 3)))
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_step_in_child, args=(batch, queue))
    child.start()
    obs_child = queue.get(timeout=120)
    child.join(timeout=60)
    obs, *_ = batch.step(np.zeros((16, 3, 3)))  # the same step in the parent
    assert child.exitcode == 0
    assert obs_child.tobytes() == obs.tobytes()


@pytest.mark.parametrize(
    "settings",
    [
        {"n_uavs": 5, "max_steps": 7},  # the fused step
        {"n_uavs": 3, "max_steps": 5, "nlos_probability": 0.3},  # copy by copy
        {"n_uavs": 3, "max_steps": 5, "integrity": "fde"},  # more info keys
        {"n_uavs": 4, "max_steps": 6, "action_frame": "route", "obs_agent_index": True},
    ],
)
def test_step_arrays_equals_step(settings) -> None:
    # step_arrays is step with the infos as (K, N) arrays: the same episodes bit for bit,
    # and info[key][k, i] is infos[k][agent_i][key], with the same Python type after tolist()
    k_copies = 6
    by_dicts = BatchedUrbanCanyonEnv(k_copies, **settings)
    by_arrays = BatchedUrbanCanyonEnv(k_copies, **settings)
    by_dicts.reset(seed=5)
    by_arrays.reset(seed=5)
    rng = np.random.default_rng(1)
    ended = 0
    for _ in range(12):
        act = rng.uniform(-1.0, 1.0, (k_copies, by_dicts.n_agents, 3))
        obs, rew, term, trunc, infos, final = by_dicts.step(act)
        out = by_arrays.step_arrays(act)
        assert out.obs.tobytes() == obs.tobytes()
        assert out.final_obs.tobytes() == final.tobytes()
        assert out.rewards.tobytes() == rew.tobytes()
        assert np.array_equal(out.terminated, term) and np.array_equal(out.truncated, trunc)
        ended += int((term | trunc).sum())
        agents = by_dicts.possible_agents
        assert list(out.info) == list(infos[0][agents[0]])  # the same keys, in order
        for key, arr in out.info.items():
            assert arr.shape == (k_copies, by_dicts.n_agents), key
            values = arr.tolist()
            for k in range(k_copies):
                for i, a in enumerate(agents):
                    assert _same(values[k][i], infos[k][a][key]), (key, k, a)
        # the reset infos convert the same way
        assert by_arrays.info_arrays(infos).keys() == out.info.keys()
    assert ended > 0  # automatic resets covered
    with pytest.raises(ValueError, match="needs 6 copies"):
        by_arrays.info_arrays(infos[:2])


def _v1_batch_and_batches_of_one(
    k_copies: int, **settings
) -> tuple[BatchedUrbanCanyonEnv, list[BatchedUrbanCanyonEnv]]:
    """A batch of ``k_copies`` ``urban_canyon_v1`` swarms and as many batches of one."""
    big = BatchedUrbanCanyonEnv.from_envs(
        [urban_canyon_v1.parallel_env(**settings) for _ in range(k_copies)]
    )
    ones = [
        BatchedUrbanCanyonEnv.from_envs([urban_canyon_v1.parallel_env(**settings)])
        for _ in range(k_copies)
    ]
    return big, ones


def _assert_copy_is_the_batch_of_one(out, k: int, ref) -> None:
    """Copy ``k`` of the batched step ``out`` equals the step ``ref`` of a batch of one
    (``step_arrays`` results), bit for bit."""
    assert ref.final_obs.tobytes() == out.final_obs[k : k + 1].tobytes()
    assert ref.obs.tobytes() == out.obs[k : k + 1].tobytes()
    assert ref.rewards.tobytes() == out.rewards[k : k + 1].tobytes()
    assert ref.terminated[0] == out.terminated[k]
    assert ref.truncated[0] == out.truncated[k]
    for key, arr in out.info.items():
        assert ref.info[key].tobytes() == arr[k : k + 1].tobytes(), key


@pytest.mark.parametrize("n_uavs", [5, 1])
def test_v1_copies_of_a_large_batch_equal_batches_of_one(n_uavs) -> None:
    # copy k of a K = 64 batch of urban_canyon_v1 (reward "navigated_distance", computed for
    # all copies at once) is the batch of one reset with seed + k, bit for bit, over episodes
    # that end at different steps
    k_copies, seed, steps = 64, 40, 16
    big, ones = _v1_batch_and_batches_of_one(k_copies, n_uavs=n_uavs, max_steps=10)
    obs, _ = big.reset(seed=seed)
    for k, one in enumerate(ones):
        assert one.reset(seed=seed + k)[0].tobytes() == obs[k].tobytes()
    rng = np.random.default_rng(seed)
    end_steps = set()
    for step in range(steps):
        act = rng.uniform(-1.0, 1.0, (k_copies, n_uavs, 3))
        out = big.step_arrays(act)
        for k, one in enumerate(ones):
            _assert_copy_is_the_batch_of_one(out, k, one.step_arrays(act[k : k + 1]))
        if (out.terminated | out.truncated).any():
            end_steps.add(step)
    assert len(end_steps) >= 3  # episodes ended at several different steps


def test_route_frame_copies_of_a_large_batch_equal_copy_by_copy_environments(monkeypatch) -> None:
    # the settings of the MAPPO recipes (urban_canyon_v1, route frame, agent index): copy k of a
    # K = 64 batch through the fused step equals a separate environment reset with seed + k
    # stepped through UrbanWorld.step (the fused step off), bit for bit, over episodes that
    # end at different steps (crashes at corners without braking, arrivals, truncations)
    k_copies, seed, n = 64, 3, 5
    settings = {
        "n_uavs": n,
        "max_steps": 40,
        "action_frame": "route",
        "route_turn_brake_mps2": 0.0,
        "obs_agent_index": True,
        "crash_free_steps": 0,
    }
    big = BatchedUrbanCanyonEnv.from_envs(
        [urban_canyon_v1.parallel_env(**settings) for _ in range(k_copies)]
    )
    assert fused_settings(big.config)
    single = [urban_canyon_v1.parallel_env(**settings) for _ in range(k_copies)]
    obs, _ = big.reset(seed=seed)
    agents = single[0].possible_agents
    for k, env in enumerate(single):
        o, _ = env.reset(seed=seed + k)
        assert obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
    rng = np.random.default_rng(0)
    end_steps = set()
    for step in range(45):
        act = rng.uniform(-1.2, 1.2, (k_copies, n, 3))
        act[..., 0] = rng.uniform(0.5, 1.2, (k_copies, n))  # fast: corners crash
        out = big.step_arrays(act)
        monkeypatch.setattr(_fused, "fused_settings", lambda cfg: False)
        for k, env in enumerate(single):
            o, r, te, tr, _ = env.step({a: act[k, j] for j, a in enumerate(agents)})
            assert out.final_obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
            assert out.rewards[k].tobytes() == np.array([r[a] for a in agents]).tobytes()
            assert out.terminated[k] == te[agents[0]] and out.truncated[k] == tr[agents[0]]
            if not env.agents:
                o, _ = env.reset()
            assert out.obs[k].tobytes() == np.stack([o[a] for a in agents]).tobytes()
            assert big.envs[k].state().tobytes() == env.state().tobytes()
        monkeypatch.undo()
        if (out.terminated | out.truncated).any():
            end_steps.add(step)
    assert big._fused_step.state is not None  # the batch took the fused step
    assert len(end_steps) >= 10  # episodes ended at many different steps
    assert out.obs.shape == (k_copies, n, big.config.obs_dim)


@pytest.mark.parametrize("threads", [2, 3, 5])
def test_copies_reset_beside_the_navigation_kernel_equal_batches_of_one(
    monkeypatch, threads
) -> None:
    # a step resets the copies it ends (new episode, first epoch) while the navigation kernel
    # runs on the pool's threads, which share the copies with the calling thread: whichever
    # thread takes a copy, each copy has the episodes of a batch of one, bit for bit
    monkeypatch.setattr(_fused, "_threads", lambda: threads)
    k_copies, seed, n = 16, 7, 3
    big, ones = _v1_batch_and_batches_of_one(k_copies, n_uavs=n, max_steps=6)
    big.reset(seed=seed)
    for k, one in enumerate(ones):
        one.reset(seed=seed + k)
    rng = np.random.default_rng(seed)
    resets = 0
    for _ in range(13):
        act = rng.uniform(-1.0, 1.0, (k_copies, n, 3))
        out = big.step_arrays(act)
        for k, one in enumerate(ones):
            _assert_copy_is_the_batch_of_one(out, k, one.step_arrays(act[k : k + 1]))
            assert big.envs[k].state().tobytes() == one.envs[0].state().tobytes()
        resets += int((out.terminated | out.truncated).sum())
    assert resets >= 2 * k_copies  # every copy began new episodes (6-step episodes at most)


@njit(nogil=True)
def _count_claimed(claims, seg, out, spin):
    """A kernel that takes its copies as the fused step's kernels do: ``out[k]`` counts the
    visits of copy ``k``, the order of its last visit in this call and the result of ``spin``
    iterations of busy work (so that threads meet mid-way)."""
    cursor = np.full(1, claims.shape[0] - 1)
    taken = 0
    k = _batched_kernels._claim(claims, seg, cursor)
    while k >= 0:
        x = 0.0
        for j in range(spin):
            x += np.sqrt(j + 1.0)
        out[k, 0] += 1
        out[k, 1] = taken
        out[k, 2] = x
        taken += 1
        k = _batched_kernels._claim(claims, seg, cursor)


@pytest.mark.parametrize("threads", [1, 2, 3, 4])
@pytest.mark.parametrize("n_copies", [1, 8, 37])
@pytest.mark.parametrize("with_work", [False, True])
def test_run_parallel_runs_the_work_once_and_every_copy(
    monkeypatch, threads, n_copies, with_work
) -> None:
    # every copy is computed at least once; only where two threads meet can one take a copy
    # the other has taken too (each segment has one such meeting: at most twice)
    monkeypatch.setattr(_fused, "_threads", lambda: threads)
    out, calls = np.zeros((n_copies, 3)), []
    work = (lambda: calls.append(1)) if with_work else None
    _fused._run_parallel(_count_claimed, n_copies, (out, 20_000), work)
    assert calls == ([1] if with_work else [])
    visits = out[:, 0]
    assert np.all(visits >= 1) and np.all(visits <= 2), visits.tolist()
    assert np.all(out[:, 2] == out[0, 2])  # the same busy work on every thread


def test_claimed_copies_come_from_the_front_of_a_segment_or_the_back_of_all() -> None:
    claims = _batched_kernels.copy_segments(10, 3)
    assert claims.tolist() == [[0, 3], [3, 6], [6, 10]]
    front, back = np.zeros((10, 3)), np.zeros((10, 3))
    _count_claimed(claims, 1, front, 0)  # segment 1, from its front
    _count_claimed(claims, -1, back, 0)  # what is left, from the back of the last segment
    assert np.flatnonzero(front[:, 0]).tolist() == [3, 4, 5]
    assert front[3:6, 1].tolist() == [0, 1, 2]
    assert np.flatnonzero(back[:, 0]).tolist() == [0, 1, 2, 6, 7, 8, 9]
    assert back[[9, 8, 7, 6, 2, 1, 0], 1].tolist() == [0, 1, 2, 3, 4, 5, 6]
    assert claims.tolist() == [[0, 0], [6, 6], [6, 6]]  # nothing left to claim


def test_remaining_routes_of_a_batch_equal_each_copys() -> None:
    # the first epochs' route lengths of the copies reset at a step (padded routes of
    # different lengths) equal remaining_route_m of each copy, bit for bit
    from coopnav_env.sim.route import remaining_route_m, route_tail_lengths_m

    rng = np.random.default_rng(9)
    k_copies, n, r_max = 7, 5, 4
    route, tail = np.zeros((k_copies, r_max, 2)), np.zeros((k_copies, r_max))
    pos = rng.uniform(-200.0, 200.0, (k_copies, n, 3))
    wp = np.empty((k_copies, n), dtype=np.int64)
    routes = []
    for k in range(k_copies):
        r = rng.uniform(-200.0, 200.0, (1 + k % r_max, 2))
        routes.append(r)
        route[k, : len(r)], tail[k, : len(r)] = r, route_tail_lengths_m(r)
        wp[k] = rng.integers(0, len(r), n)
    out = _fused._remaining_routes_m(route, tail, pos, wp)
    for k, r in enumerate(routes):
        ref = remaining_route_m(r, pos[k, :, :2], wp[k], route_tail_lengths_m(r))
        assert out[k].tobytes() == ref.tobytes()


def test_step_infos_from_the_fused_arrays_equal_the_epochs() -> None:
    # the parallel environment's step builds its infos from the fused step's arrays; the
    # infos of the same step built from its epoch are the same numbers of the same types
    from coopnav_env.envs.task import REWARD_TERMS

    env = urban_canyon_v1.parallel_env(n_uavs=4, max_steps=12)
    env.reset(seed=3)
    agents = env.possible_agents
    rng = np.random.default_rng(3)
    missing_fixes = 0
    for _ in range(40):
        act = {a: rng.uniform(-1.0, 1.0, 3) for a in env.agents}
        _, _, _, _, infos = env.step(act)
        terms = {t: np.array([infos[a][f"reward_{t}"] for a in agents]) for t in REWARD_TERMS}
        in_goal = np.array([infos[a]["in_goal"] for a in agents])
        ref = env._infos(terms, in_goal)
        assert list(ref) == list(infos)
        for a in agents:
            assert list(ref[a]) == list(infos[a])
            for key, value in ref[a].items():
                assert type(infos[a][key]) is type(value) and infos[a][key] == value, key
        missing_fixes += sum(
            not infos[a]["coop_fix"] or not infos[a]["standalone_fix"] for a in agents
        )
        if not env.agents:
            env.reset()
    assert missing_fixes > 0  # steps with a missing fix (its error -1, its flag False) too
    assert env._info_parts is None  # read once, by the step that made them
