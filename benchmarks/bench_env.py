"""Benchmark: urban_canyon_v1 side by side with its peers, in one process.

Every section measures ``urban_canyon_v1``, the environment every default uses (its world,
step and observations are v0's; its reward is the task's score and its episodes start
crash-free for 3 steps, so random actions fly a few steps longer before the first crash).

What it measures (every figure of one run comes from the same process, so that the machine's
load affects the environment and its reference alike; ratios are what to compare across
machines):

1. **Parallel-env steps/s** with uniformly random actions (resetting when an episode ends) of
   ``urban_canyon_v1`` and of PettingZoo MPE ``simple_spread_v3`` (package ``mpe2``,
   ``continuous_actions=True``, N agents and N landmarks, ``max_cycles=25``) at the same N,
   and their ratio; VMAS ``navigation`` (one environment, CPU) beside them when ``vmas`` is
   installed. The two are measured in alternating rounds; the best round of each counts.
2. **Where a step goes**: milliseconds per step inside the navigation of an epoch (the
   "nav solve": pseudoranges, both solvers, the estimate selection and the waypoints, one
   compiled call on the default path; the modular path's solvers and pseudoranges separately
   when it runs), the receiver-satellite geometry, line of sight, the skyline and wall
   sensors, motion (kinematics, collisions) and relative sensing (timer hooks on those
   functions), and the rest (environment adapter, observations, rewards, infos, resets).
3. **Memory per environment**: bytes allocated by building one environment, resetting it
   and stepping it 20 times (``tracemalloc``, what stays allocated), and its pickle size.
3b. **Memory per swarm of the batched environment** (``BatchedUrbanCanyonEnv``, N = 5) at K =
   64, 256, 1,024 and 4,096 swarms, each K in a fresh process: the growth of the resident set
   size per swarm after building, resetting and 20 random steps; what ``tracemalloc`` sees
   still allocated per swarm; the bytes reachable from the copies (and of them numpy array
   data) by part of a copy (its spaces, constellation, city, last epoch, ...) and the batch's
   own buffers; and whether 4,096 swarms of 5 UAVs fit in 2 GiB (measured, or extrapolated
   from the largest K run).
4. **Scaling**: step cost against the swarm size N (2 ... 100, beside MPE) and against the
   size of the grid city (blocks per side), with the growth explained.
5. **Batched**: env-steps/s (swarm steps) of K copies at N = 5 stepped as one SB3 vector
   environment, SuperSuit's adapters vs the batched vector environment
   (``coopnav_env.training.vec_env.make_vec_env(kind=...)``), the batched environment
   itself through its array step (``arrays``: ``BatchedUrbanCanyonEnv.step_arrays``, no
   per-slot info dicts) and VMAS with K batched environments; and the time inside the
   compiled kernels per swarm step (:func:`kernel_timers`), whose inverse times two cores is a
   ceiling for any batching of this simulation, and where an array step's time goes
   (:func:`array_step_timeline`: its three compiled calls, the automatic resets on the
   calling thread beside the navigation kernel, the Python outside them). The array step and
   VMAS also step 4 K copies (``--scale-copies K2``; 0: not) in the same rounds: the cost per
   swarm step at 4 K against K. ``--city`` flies the copies on another city
   (``family:mixed``: a new generated city of extruded polygons every episode; with
   ``--city-pool P``, one of ``P`` cities, all built before timing as in a long training
   run).
6. **PPO training throughput** (agent-steps/s of ``coopnav train``'s own ``train()``, the
   packaged hyperparameters, no behaviour cloning) with each vector environment, and the share
   of the time in SB3's gradient updates (``PPO.train``), whose inverse is a ceiling for the
   speed-up any vector environment can bring.
7. **A city from a file**: parallel-env steps/s at N = 5 on the default grid city and on a
   GeoJSON city of about 500 extruded polygons
   (:func:`coopnav_env.sim.file_city.sample_city_geojson` with 10 x 10 blocks, written to a
   temporary file), hovering (200-step episodes) and with the ``column`` heuristic flying
   its route, in alternating rounds; the ratio is the cost of a file-city step over a
   grid-city step.
8. **Real cities under a real sky**: the same at N = 5 on the default grid city (nominal
   GPS + BeiDou sky) and on real OpenStreetMap cities under the shipped IGS GPS sky
   (``rinex:igs_brdc``): every city of the real-city suite
   (:data:`coopnav_env.sim.real_suite.REAL_SUITE`) and a box of the shipped Monaco extract of
   about 950 buildings; the ratios are the cost of a real-city step over a grid-city step
   measured in the same run, with the grid city's own sky and under the same real sky (the
   grid replays the same epochs every episode, whose sky it caches; a file sky starts each
   episode at a new time). Needs pyosmium (the ``osm`` extra).

Usage::

    python benchmarks/bench_env.py            # everything, about 8-10 minutes on 2 cores
    python benchmarks/bench_env.py --quick    # a smoke run, about 1 minute
    python benchmarks/bench_env.py --sections compare stages --sizes 5 50 --json out.json
    python benchmarks/bench_env.py --sections batch_memory --memory-copies 64 4096
    python benchmarks/bench_env.py --sections batched --city family:mixed --city-pool 200
    python benchmarks/bench_env.py --sections batched --rounds 3   # K = 64, and 256 beside it

Needs the ``benchmark`` extra (``pip install -e ".[benchmark]"``: mpe2, vmas) for the
references; missing ones are reported and skipped. Sections 5-6 need the ``train`` extra.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import gc
import json
import math
import pickle
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from coopnav_env import urban_canyon_v1

SECTIONS = (
    "compare",
    "stages",
    "memory",
    "batch_memory",
    "scaling",
    "batched",
    "train",
    "file_city",
    "real_city",
)

# --------------------------------------------------------------------------------------------
# environments under test
# --------------------------------------------------------------------------------------------


def make_urban(n: int, **kw: Any):
    """The environment under test: ``urban_canyon_v1``'s parallel env of ``n`` UAVs."""
    return urban_canyon_v1.parallel_env(n_uavs=n, **kw)


def make_mpe(n: int):
    from mpe2 import simple_spread_v3

    return simple_spread_v3.parallel_env(N=n, continuous_actions=True, max_cycles=25)


def have(module: str) -> bool:
    try:
        __import__(module)
    except Exception:  # any import failure means "not available"
        return False
    return True


class RandomStepper:
    """Steps a PettingZoo parallel env with uniform random actions, resetting at episode ends.

    Actions are drawn in one numpy call per step (not ``space.sample()`` per agent) so that
    the action source costs both environments the same small amount.
    """

    def __init__(self, env: Any, seed: int = 0):
        self.env = env
        self.rng = np.random.default_rng(seed)
        agent = env.possible_agents[0]
        space = env.action_space(agent)
        self.low, self.high = space.low, space.high
        self.env.reset(seed=seed)
        self.episodes = 1
        self.steps = 0

    def action(self, n_agents: int) -> np.ndarray:
        return self.rng.uniform(self.low, self.high, (n_agents, self.low.size))

    def run(self, steps: int) -> None:
        env = self.env
        for _ in range(steps):
            if not env.agents:
                env.reset()
                self.episodes += 1
            agents = env.agents
            env.step(dict(zip(agents, self.action(len(agents)).astype(np.float32))))
            self.steps += 1


class HoverStepper(RandomStepper):
    """Zero velocity commands: the swarm hovers and every episode runs ``max_steps`` (200)."""

    def action(self, n_agents: int) -> np.ndarray:
        return np.zeros((n_agents, self.low.size))


def timed_rate(step: Callable[[int], None], seconds: float, chunk: int = 1) -> float:
    """Calls of ``step(chunk)`` for about ``seconds``; returns steps per second (wall clock)."""
    step(chunk)  # warm-up
    n = 0
    t0 = time.perf_counter()
    while True:
        step(chunk)
        n += chunk
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def side_by_side(fns: dict[str, Callable[[int], None]], seconds: float, rounds: int):
    """Best steps/s of each stepper over ``rounds`` alternating rounds of ``seconds`` each."""
    best = dict.fromkeys(fns, 0.0)
    for _ in range(rounds):
        for name, fn in fns.items():
            best[name] = max(best[name], timed_rate(fn, seconds))
    return best


# --------------------------------------------------------------------------------------------
# 1. comparison with the peers
# --------------------------------------------------------------------------------------------


def vmas_stepper(n_agents: int, n_envs: int) -> Callable[[int], None]:
    import torch
    import vmas

    # the default spawning square (2 x 2) holds about 4 agents and goals; keep that density
    half = max(1.0, math.sqrt(n_agents / 4.0))
    env = vmas.make_env(
        "navigation",
        num_envs=n_envs,
        device="cpu",
        continuous_actions=True,
        n_agents=n_agents,
        seed=0,
        max_steps=100,
        world_spawning_x=half,
        world_spawning_y=half,
    )
    env.reset()

    def step(k: int) -> None:
        for _ in range(k):
            acts = [env.get_random_action(a) for a in env.agents]
            _obs, _rew, dones, _info = env.step(acts)
            if bool(dones.any()):
                for i in torch.nonzero(dones).flatten().tolist():
                    env.reset_at(i)

    return step


def section_compare(args, out: dict) -> None:
    print("\n== 1. parallel-env steps/s, random actions (best of alternating rounds) ==")
    has_mpe, has_vmas = have("mpe2"), have("vmas")
    if not has_mpe:
        print("   mpe2 not installed (pip install -e '.[benchmark]'): no reference ratio")
    head = f"{'N':>4} | {'urban_canyon_v1':>15} {'mpe2 spread':>12} {'ratio':>7}"
    head += f" | {'urban hover':>11} {'ratio':>7}"
    head += f" | {'VMAS nav':>9}" if has_vmas else ""
    print(head + "   (steps/s; ratio = urban / mpe2)")
    rows = []
    for n in args.sizes:
        fns = {"urban": RandomStepper(make_urban(n)).run}
        if has_mpe:
            fns["mpe2"] = RandomStepper(make_mpe(n)).run
        fns["urban_hover"] = HoverStepper(make_urban(n)).run
        if has_vmas:
            fns["vmas"] = vmas_stepper(n, 1)
        best = side_by_side(fns, args.seconds, args.rounds)
        mpe = best.get("mpe2", math.nan)
        ratio, ratio_h = best["urban"] / mpe, best["urban_hover"] / mpe
        line = f"{n:>4} | {best['urban']:>15.1f} {mpe:>12.1f} {ratio:>6.2f}x"
        line += f" | {best['urban_hover']:>11.1f} {ratio_h:>6.2f}x"
        line += f" | {best['vmas']:>9.1f}" if has_vmas else ""
        print(line)
        rows.append(
            {
                "n": n,
                **{f"{k}_steps_per_s": v for k, v in best.items()},
                "ratio": ratio,
                "ratio_hover": ratio_h,
            }
        )
        rows[-1]["episode_steps"] = fns["urban"].__self__.steps / fns["urban"].__self__.episodes
    lengths = ", ".join(f"{r['episode_steps']:.1f}" for r in rows)
    print(
        f"   (random actions crash soon after the crash-free start: episodes of {lengths} steps,"
        "\n   so a reset -- new city, route, cold solve -- comes that often; 'hover' sends zero"
        "\n   commands: 200-step episodes)"
    )
    out["compare"] = rows


# --------------------------------------------------------------------------------------------
# 2. where a step goes
# --------------------------------------------------------------------------------------------

STAGES: tuple[tuple[str, str, str], ...] = (
    # (label, module, attribute); a method is "Class.method"
    # the fused step (the environment's steps with the default settings, a batch of one):
    # motion, line of sight and relative sensing; the navigation with the reward terms and
    # the skyline and wall sensors; the observations
    ("fused motion+sight", "coopnav_env.envs._batched_kernels", "motion_sight_relative"),
    (
        "fused nav+reward",
        "coopnav_env.envs._batched_kernels",
        "navigation_reward_sensors",
    ),
    ("fused observations", "coopnav_env.envs._batched_kernels", "observations_infos"),
    # the resets' first epoch, and the other settings' steps:
    # the default path: pseudoranges, both solvers, the estimate selection and the waypoints
    # of an epoch in one compiled call (UrbanWorld._navigate_fused)
    ("pseudorange+solvers", "coopnav_env.sim._kernels", "epoch_navigation"),
    ("receiver geometry", "coopnav_env.sim.scenario", "_range_azimuth_elevation"),
    # the modular path (covariance="paper", or satellites not grouped by constellation)
    ("cooperative solver", "coopnav_env.sim.scenario", "UrbanWorld._solve_cooperative"),
    ("standalone solver", "coopnav_env.sim.scenario", "solve_standalone"),
    ("pseudoranges", "coopnav_env.sim.scenario", "_simulate_pseudoranges"),
    ("line of sight", "coopnav_env.sim.scenario", "_trace_line_of_sight"),
    # the environment's sensors call the kernel on the world's own arrays (else the City method)
    ("skyline + walls", "coopnav_env.sim._kernels", "sky_and_walls"),
    ("skyline + walls", "coopnav_env.sim.city", "City.sky_and_walls"),
    ("motion + collisions", "coopnav_env.sim._kernels", "world_motion"),
    ("relative sensing", "coopnav_env.sim.scenario", "_measure_relative"),
    ("relative sensing", "coopnav_env.sim.scenario", "UrbanWorld._relative_ecef"),
)
NAV = (
    "pseudorange+solvers",
    "cooperative solver",
    "standalone solver",
    "fused nav+reward",
)


@contextlib.contextmanager
def timed_attributes(targets: list[tuple[str, Any, str]]) -> Iterator[dict[str, float]]:
    """Replace each ``owner.name`` of ``targets`` (``(label, owner, name)``) by a wrapper
    that adds its wall time to ``acc[label]``; yields ``acc``, then restores the originals.
    A class's attribute is taken from its ``__dict__`` (the plain function, not bound)."""
    acc: dict[str, float] = {}
    undo = []
    for label, owner, name in targets:
        fn = owner.__dict__[name] if isinstance(owner, type) else getattr(owner, name)

        def timed(*a, _fn=fn, _label=label, **k):
            t0 = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                acc[_label] = acc.get(_label, 0.0) + time.perf_counter() - t0

        setattr(owner, name, timed)
        undo.append((owner, name, fn))
    try:
        yield acc
    finally:
        for owner, name, fn in reversed(undo):
            setattr(owner, name, fn)


def stage_timers() -> contextlib.AbstractContextManager[dict[str, float]]:
    """Timers on the functions of :data:`STAGES` (:func:`timed_attributes`): seconds per label."""
    import importlib

    targets = []
    for label, mod_name, attr in STAGES:
        owner: Any = importlib.import_module(mod_name)
        *path, name = attr.split(".")
        for part in path:
            owner = getattr(owner, part)
        if name in (owner.__dict__ if isinstance(owner, type) else dir(owner)):
            targets.append((label, owner, name))
    return timed_attributes(targets)


KERNEL_MODULES = (
    "coopnav_env.sim._kernels",
    "coopnav_env.sim._polygon_kernels",
    "coopnav_env.gnss._kernels",
    "coopnav_env.nav._kernels",
    "coopnav_env.envs._kernels",
    "coopnav_env.envs._batched_kernels",
)


def kernel_timers() -> contextlib.AbstractContextManager[dict[str, float]]:
    """Timers on every compiled kernel the package calls from Python (:func:`timed_attributes`).

    Yields seconds per kernel name, each call counted from Python (the dispatch of its
    arguments and results included; a kernel called from another kernel is part of its
    caller). What the kernels take together is the compiled part of a step: what would be
    left if every line of Python around them cost nothing.
    """
    import importlib

    from numba.core.registry import CPUDispatcher

    targets = []
    for mod_name in KERNEL_MODULES:
        mod = importlib.import_module(mod_name)
        targets += [
            (name, mod, name) for name, fn in vars(mod).items() if isinstance(fn, CPUDispatcher)
        ]
    return timed_attributes(targets)


def array_step_timeline(
    step: Callable[[int], None], seconds: float, min_steps: int = 3
) -> dict[str, float]:
    """Where a step of a batched environment goes, ms per step, over ``seconds`` (at least
    ``min_steps`` steps) of ``step(1)``.

    Keys: each compiled call that runs on every core (``motion_sight_relative``,
    ``navigation_reward_sensors``, ``observations_infos``: the wall time of its window, from
    the call to the last copy done); ``resets``, the automatic resets, which the calling
    thread runs inside the navigation window while the pool's threads run the kernel (their
    first epochs' kernels included); ``python``, the rest of the step: Python outside the
    compiled calls, while the other cores wait; ``step``, the whole step.
    """
    import importlib

    from coopnav_env.envs.batched import BatchedUrbanCanyonEnv

    # the fused step's runner of the compiled calls, wrapped for the run (the package's
    # internals, instrumented as kernel_timers instruments its kernels)
    _fused = importlib.import_module("coopnav_env.envs._fused")
    windows: dict[str, float] = {}
    run_parallel = _fused._run_parallel

    def timed(kernel: Any, n_copies: int, args: tuple, work: Any = None) -> None:
        t0 = time.perf_counter()
        try:
            run_parallel(kernel, n_copies, args, work)
        finally:
            name = kernel.__name__
            windows[name] = windows.get(name, 0.0) + time.perf_counter() - t0

    _fused._run_parallel = timed
    try:
        with timed_attributes([("resets", BatchedUrbanCanyonEnv, "_reset_copies")]) as acc:
            steps, t0 = 0, time.perf_counter()
            while time.perf_counter() - t0 < seconds or steps < min_steps:
                step(1)
                steps += 1
            wall = time.perf_counter() - t0
    finally:
        _fused._run_parallel = run_parallel
    ms = {name: v / steps * 1e3 for name, v in windows.items()}
    ms["resets"] = acc.get("resets", 0.0) / steps * 1e3
    ms["step"] = wall / steps * 1e3
    ms["python"] = ms["step"] - sum(ms[name] for name in windows)
    return ms


def stage_profile(n: int, seconds: float, **env_kw: Any) -> dict[str, Any]:
    """ms per step in total and per stage, for random-action episodes of ``n`` UAVs."""
    stepper = RandomStepper(make_urban(n, **env_kw))
    stepper.run(3)
    with stage_timers() as acc:
        steps = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds or steps < 3:
            stepper.run(1)
            steps += 1
        total = time.perf_counter() - t0
    ms = {k: v / steps * 1e3 for k, v in acc.items()}
    ms["other"] = total / steps * 1e3 - sum(ms.values())
    return {
        "n": n,
        "ms_per_step": total / steps * 1e3,
        "stages_ms": ms,
        "nav_solve_ms": sum(ms.get(k, 0.0) for k in NAV),
        "mean_episode_steps": stepper.steps / stepper.episodes,
    }


def section_stages(args, out: dict) -> None:
    print("\n== 2. where a step of urban_canyon_v1 goes (ms per step, share) ==")
    rows = [stage_profile(n, args.seconds) for n in args.sizes]
    # the stages the runs went through (the default path skips the modular path's functions)
    labels = [
        *(
            label
            for label in dict.fromkeys(label for label, _, _ in STAGES)
            if any(label in r["stages_ms"] for r in rows)
        ),
        "other",
    ]
    print(f"{'':>20}" + "".join(f" | N={r['n']:<13}" for r in rows))
    for label in labels:
        cells = []
        for r in rows:
            v = r["stages_ms"].get(label, 0.0)
            cells.append(f" | {v:6.3f} {100 * v / r['ms_per_step']:5.1f}%")
        print(f"{label:>20}" + "".join(cells))
    print(f"{'total':>20}" + "".join(f" | {r['ms_per_step']:6.3f} 100.0%" for r in rows))
    print(
        f"{'nav solve':>20}"
        + "".join(
            f" | {r['nav_solve_ms']:6.3f} {100 * r['nav_solve_ms'] / r['ms_per_step']:5.1f}%"
            for r in rows
        )
    )
    print(
        "   (random actions: episodes last "
        + ", ".join(f"{r['mean_episode_steps']:.1f}" for r in rows)
        + " steps; the first epoch's solve of each reset is counted in the solver rows)"
    )
    out["stages"] = rows


# --------------------------------------------------------------------------------------------
# 3. memory
# --------------------------------------------------------------------------------------------


def env_memory(make: Callable[[], Any]) -> dict[str, Any]:
    """Bytes still allocated (``tracemalloc``) after building, resetting and stepping one
    environment 20 times, after a first one has loaded the compiled code; its pickle size."""
    RandomStepper(make()).run(3)  # imports, compiled kernels: once per process, not per env
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    env = make()
    stepper = RandomStepper(env)
    stepper.run(20)
    gc.collect()
    held = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    try:
        pickled = len(pickle.dumps(env))
    except Exception:  # an env that does not pickle
        pickled = None
    return {"traced_bytes": held, "pickle_bytes": pickled}


def section_memory(args, out: dict) -> None:
    from coopnav_env.sim import scenario

    print("\n== 3. memory per environment (after construction, reset and 20 steps) ==")
    rows = []
    for n in args.sizes:
        scenario._SKY_CACHE.clear()  # shared by every environment of the process
        row = {"n": n, "urban": env_memory(lambda n=n: make_urban(n))}
        if have("mpe2"):
            row["mpe2"] = env_memory(lambda n=n: make_mpe(n))
        rows.append(row)
        parts = [f"N={n:<3} urban_canyon_v1 {row['urban']['traced_bytes'] / 1e3:8.0f} kB"]
        parts.append(f"(pickle {(row['urban']['pickle_bytes'] or 0) / 1e3:.0f} kB)")
        if "mpe2" in row:
            pk = row["mpe2"]["pickle_bytes"]
            parts.append(f"| mpe2 {row['mpe2']['traced_bytes'] / 1e3:8.0f} kB")
            parts.append(f"(pickle {'n/a' if pk is None else f'{pk / 1e3:.0f} kB'})")
        print("   " + " ".join(parts))
    size = len(scenario._SKY_CACHE._data)
    print(
        f"   plus the process-wide satellite-geometry cache: {size} epochs held (~3 kB each, "
        f"at most {scenario._SKY_CACHE.max_size}), shared by every copy"
    )
    out["memory"] = rows


# --------------------------------------------------------------------------------------------
# 3b. memory per swarm of the batched environment
# --------------------------------------------------------------------------------------------

MEMORY_BUDGET_BYTES = 2 * 1024**3
"""The budget a batch of 4,096 swarms of 5 UAVs must fit in (section 3b)."""


def rss_bytes() -> int:
    """Resident set size of this process now (psutil, else ``/proc/self/statm``; 0 if neither)."""
    try:
        import psutil

        return int(psutil.Process().memory_info().rss)
    except ImportError:
        pass
    try:
        import os

        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def peak_rss_bytes() -> int:
    """Peak resident set size of this process (``resource``; Linux reports kB); 0 if unknown."""
    try:
        import resource
    except ImportError:
        return 0
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


_NOT_FOLLOWED = (type, type(sys), type(len), type(rss_bytes), type(peak_rss_bytes.__code__))


def reachable_bytes(
    root: Any,
    seen: set[int],
    bases: list[Any] | None = None,
    shared: tuple[type, ...] = (),
) -> tuple[int, int]:
    """(bytes, numpy array data bytes) of the objects reachable from ``root`` not in ``seen``.

    Follows ``gc.get_referents``, not into classes, modules, functions or code objects (shared
    by every copy); sizes are ``sys.getsizeof`` (an array that owns its data counts its
    buffer, a view its header; an array a compiled kernel made holds its buffer through
    numba's memory info, and counts it too). The array a view looks into (its ``base``) is
    followed, or, with ``bases`` given, appended to it instead (for the caller to tell a
    copy's own arrays from the batch's buffers that every copy views), as is an object of one
    of the types ``shared`` (what every copy of a batch refers to, such as the arrays of a
    fused step's epochs). Adds what it visits to ``seen``, so that an object reached again
    (from another copy, or another attribute) counts once.
    """
    total = arrays = 0
    stack = [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen or isinstance(obj, _NOT_FOLLOWED):
            continue
        if bases is not None and shared and isinstance(obj, shared):
            bases.append(obj)
            continue
        seen.add(id(obj))
        total += sys.getsizeof(obj)
        if isinstance(obj, np.ndarray):
            if not isinstance(obj.base, np.ndarray):
                # its own buffer (in getsizeof), or one it holds through another object
                # (numba's memory info for an array a compiled kernel made)
                if obj.base is not None:
                    total += obj.nbytes
                arrays += obj.nbytes if obj.flags.owndata or obj.base is not None else 0
            elif bases is None:
                stack.append(obj.base)
            else:
                bases.append(obj.base)
        stack.extend(gc.get_referents(obj))
    return total, arrays


def copy_breakdown(
    envs: list[Any], seen: set[int]
) -> tuple[dict[str, tuple[int, int]], tuple[int, int]]:
    """What ``envs`` (copies of a batch) hold: (bytes, array bytes) summed over them per part
    of a copy (each attribute of its world, ``world.city``, ..., then each other attribute of
    the environment, ``observation_spaces``, ...; an object shared by two parts or copies
    counts in the first), and (bytes, array bytes) of what two or more of the copies share:
    the arrays their views look into and the arrays of the fused step's epochs (the batch's
    buffers, whose size grows with K)."""
    # the object a copy's lazily made epoch reads its fields from (the fused step's arrays,
    # one for all the copies of a step): of the type its pending fields name
    step_arrays = tuple(
        {type(p[0]) for e in envs if (p := vars(e.world.last).get("_pending")) is not None}
    )
    parts: dict[str, list[int]] = {}
    viewed: dict[int, tuple[Any, set[int], str]] = {}
    for c, env in enumerate(envs):
        seen.update({id(env), id(env.__dict__), id(env.world), id(env.world.__dict__)})
        items = [(f"world.{k}", v) for k, v in vars(env.world).items()]
        items += [(k, v) for k, v in vars(env).items() if k != "world"]
        for name, value in items:
            bases: list[Any] = []
            b, a = reachable_bytes(value, seen, bases, step_arrays)
            acc = parts.setdefault(name, [0, 0])
            acc[0] += b
            acc[1] += a
            for base in bases:
                while isinstance(base, np.ndarray) and isinstance(base.base, np.ndarray):
                    base = base.base
                viewed.setdefault(id(base), (base, set(), name))[1].add(c)
    shared = [0, 0]
    for base, copies, name in viewed.values():
        b, a = reachable_bytes(base, seen)
        acc = shared if len(copies) > 1 else parts[name]
        acc[0] += b
        acc[1] += a
    return {k: (v[0], v[1]) for k, v in parts.items()}, (shared[0], shared[1])


def batch_memory_child(k: int, steps: int, trace: bool, sample: int) -> dict[str, Any]:
    """What a batch of ``k`` swarms of 5 UAVs holds (run in a fresh process, see
    :func:`section_batch_memory`): resident memory and time after building the batched
    environment, resetting it and ``steps`` random steps; the bytes reachable from it (the first
    ``sample`` copies broken down by part, the batch's own arrays); with ``trace``, what
    ``tracemalloc`` sees still allocated after the same again."""
    from coopnav_env.envs import BatchedUrbanCanyonEnv

    n = 5
    rng = np.random.default_rng(0)

    def build_and_step() -> tuple[Any, dict[str, float]]:
        t: dict[str, float] = {}
        t0 = time.perf_counter()
        batch = BatchedUrbanCanyonEnv.from_envs([make_urban(n) for _ in range(k)])
        t["build_s"] = time.perf_counter() - t0
        t["rss_built"] = rss_bytes()
        t0 = time.perf_counter()
        batch.reset(seed=0)
        t["reset_s"] = time.perf_counter() - t0
        t["rss_reset"] = rss_bytes()
        t0 = time.perf_counter()
        for _ in range(steps):
            batch.step(rng.uniform(-1.0, 1.0, (k, n, 3)))
        t["steps_s"] = time.perf_counter() - t0
        gc.collect()
        t["rss_stepped"] = rss_bytes()
        return batch, t

    # load the compiled kernels and the process-wide caches before the baseline
    probe = BatchedUrbanCanyonEnv.from_envs([make_urban(n) for _ in range(2)])
    probe.reset(seed=0)
    for _ in range(3):
        probe.step(rng.uniform(-1.0, 1.0, (2, n, 3)))
    del probe
    gc.collect()
    rss0 = rss_bytes()
    batch, t = build_and_step()
    row: dict[str, Any] = {"k": k, "n": n, "steps": steps, "rss_base_bytes": rss0, **t}
    for stage in ("built", "reset", "stepped"):
        row[f"rss_{stage}_per_swarm"] = (row.pop(f"rss_{stage}") - rss0) / k
    row["rss_peak_bytes"] = peak_rss_bytes()
    seen: set[int] = {id(batch), id(batch.__dict__), id(batch.envs)}
    sample = min(sample, k)
    parts, (viewed_b, viewed_a) = copy_breakdown(batch.envs[:sample], seen)
    row["parts_per_swarm"] = {name: (b / sample, a / sample) for name, (b, a) in parts.items()}
    for env in batch.envs[sample:]:  # stop at the other copies: what is left is the batch's
        seen.update({id(env), id(env.__dict__), id(env.world), id(env.world.__dict__)})
    b, a = reachable_bytes(batch, seen)
    # the batch's own state and the buffers the copies' views look into, shared by all K
    row["batch_own_per_swarm"] = ((b + viewed_b) / k, (a + viewed_a) / k)
    del batch
    gc.collect()
    if trace:
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        batch, t = build_and_step()
        gc.collect()
        row["traced_per_swarm"] = (tracemalloc.get_traced_memory()[0] - base) / k
        tracemalloc.stop()
        del batch
    return row


def section_batch_memory(args, out: dict) -> None:
    import subprocess

    steps = args.memory_steps
    print(
        f"\n== 3b. memory per swarm of the batched env (N = 5, after building, resetting and "
        f"{steps} random steps; each K in a fresh process) =="
    )
    print(
        f"{'K':>5} | {'build s':>7} {'reset s':>7} {'steps s':>7} | RSS growth per swarm (kB): "
        f"{'built':>6} {'reset':>6} {'stepped':>7} | {'traced kB':>9} | {'reachable kB':>12} "
        f"{'(arrays)':>8} | {'peak RSS MB':>11}"
    )
    rows = []
    for k in args.memory_copies:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--memory-child", str(k)]
        cmd += ["--memory-steps", str(steps)]
        if k <= args.memory_trace_max:
            cmd.append("--memory-trace")
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            print(f"{k:>5} | failed: {proc.stderr.strip().splitlines()[-1:]}")
            continue
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        reach = sum(b for b, _ in row["parts_per_swarm"].values()) + row["batch_own_per_swarm"][0]
        arrays = sum(a for _, a in row["parts_per_swarm"].values())
        arrays += row["batch_own_per_swarm"][1]
        row["reachable_per_swarm"], row["reachable_arrays_per_swarm"] = reach, arrays
        traced = row.get("traced_per_swarm")
        print(
            f"{k:>5} | {row['build_s']:>7.1f} {row['reset_s']:>7.1f} {row['steps_s']:>7.1f} | "
            f"{'':>26}{row['rss_built_per_swarm'] / 1e3:>6.1f} "
            f"{row['rss_reset_per_swarm'] / 1e3:>6.1f} {row['rss_stepped_per_swarm'] / 1e3:>7.1f}"
            f" | {'-' if traced is None else f'{traced / 1e3:.1f}':>9} | {reach / 1e3:>12.1f} "
            f"{arrays / 1e3:>8.1f} | {row['rss_peak_bytes'] / 2**20:>11.0f}"
        )
        rows.append(row)
    out["batch_memory"] = rows
    if not rows:
        return
    last = rows[-1]
    parts = sorted(last["parts_per_swarm"].items(), key=lambda kv: -kv[1][0])
    print(
        f"   per swarm, by part of a copy (objects reachable from copies 0-{args.memory_sample - 1}"
        f" of K = {last['k']}, kB; of which numpy array data):"
    )
    shown = 0.0
    for name, (b, a) in parts[:10]:
        print(f"   {name:>28}: {b / 1e3:6.1f} ({a / 1e3:5.1f})")
        shown += b
    rest = sum(b for _, (b, _) in parts[10:])
    print(f"   {'other parts':>28}: {rest / 1e3:6.1f}")
    b, a = last["batch_own_per_swarm"]
    print(f"   {'the batch (fused buffers)':>28}: {b / 1e3:6.1f} ({a / 1e3:5.1f})")
    target = 4096
    per_swarm = last["rss_stepped_per_swarm"]
    projected = last["rss_base_bytes"] + target * per_swarm
    how = "measured" if last["k"] == target else f"extrapolated from K = {last['k']}"
    peak = last["rss_peak_bytes"] if last["k"] == target else projected
    verdict = "fits" if peak <= MEMORY_BUDGET_BYTES else "does NOT fit"
    print(
        f"   {target:,} swarms of 5 UAVs ({how}): {per_swarm / 1e3:.0f} kB per swarm of RSS "
        f"growth, peak RSS {peak / 2**20:.0f} MB (the process before the batch: "
        f"{last['rss_base_bytes'] / 2**20:.0f} MB: Python, numpy, the compiled kernels): "
        f"{verdict} in {MEMORY_BUDGET_BYTES / 2**30:.0f} GiB"
    )
    out["batch_memory_verdict"] = {
        "k": target,
        "how": how,
        "peak_rss_bytes": peak,
        "fits_2_gib": bool(peak <= MEMORY_BUDGET_BYTES),
    }


# --------------------------------------------------------------------------------------------
# 4. scaling
# --------------------------------------------------------------------------------------------


def _slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares exponent of ``y ~ x^p`` (log-log slope)."""
    lx, ly = np.log(xs), np.log(ys)
    return float(np.polyfit(lx, ly, 1)[0])


def section_scaling(args, out: dict) -> None:
    print("\n== 4a. step cost vs swarm size N (ms per step) ==")
    has_mpe = have("mpe2")
    print(
        f"{'N':>4} | {'urban ms':>9} {'nav solve':>9} {'LOS+sky':>8} {'other':>7}"
        + (f" | {'mpe2 ms':>9} {'ratio':>7}" if has_mpe else "")
    )
    rows = []
    for n in args.scaling:
        r = stage_profile(n, args.seconds)
        s = r["stages_ms"]
        geo = s.get("line of sight", 0.0) + s.get("skyline + walls", 0.0)
        line = (
            f"{n:>4} | {r['ms_per_step']:>9.2f} {r['nav_solve_ms']:>9.2f} {geo:>8.2f} "
            f"{s['other']:>7.2f}"
        )
        row = {"n": n, **r}
        if has_mpe:
            rate = timed_rate(RandomStepper(make_mpe(n)).run, args.seconds)
            row["mpe2_ms_per_step"] = 1e3 / rate
            line += f" | {1e3 / rate:>9.2f} {row['mpe2_ms_per_step'] / r['ms_per_step']:>6.2f}x"
        print(line)
        rows.append(row)
    big = [r for r in rows if r["n"] >= 10]
    if len(big) >= 2:
        p_urban = _slope([r["n"] for r in big], [r["ms_per_step"] for r in big])
        msg = f"   growth for N >= 10: urban ~ N^{p_urban:.2f}"
        if has_mpe:
            p_mpe = _slope([r["n"] for r in big], [r["mpe2_ms_per_step"] for r in big])
            msg += f", mpe2 ~ N^{p_mpe:.2f}"
        print(msg)
    print(
        "   why: MPE's step is O(N^2) Python (every pair of entities collides in a Python loop);"
        "\n   urban's is numpy over arrays plus compiled loops (solvers, line of sight, sensors):"
        "\n   per-step overhead dominates up to N ~ 10, then the O(N x satellites) measurement"
        "\n   model, the O(N^2) relative sensing (tiny arrays) and the solver (one centroid per"
        "\n   UAV, ~N^2, up to 10 UAVs; one shared centroid, ~N, from 11) grow slowly; the"
        "\n   shared-centroid switch at N = 11 lowers the cost."
    )
    out["scaling_n"] = rows

    print("\n== 4b. step cost vs city size (grid city, N = 5; blocks per side) ==")
    print(f"{'blocks':>6} {'buildings':>9} {'extent m':>8} | {'ms/step':>8} {'LOS':>6} {'sky':>6}")
    crow = []
    for nb in args.blocks:
        from coopnav_env.sim.city import CityConfig, generate_city

        cc = CityConfig(n_blocks_x=nb, n_blocks_y=nb)
        city = generate_city(cc, np.random.default_rng(0))
        x0, x1, _, _ = city.extent_m
        r = stage_profile(5, args.seconds, city_config=cc)
        s = r["stages_ms"]
        print(
            f"{nb:>6} {city.buildings.n:>9} {x1 - x0:>8.0f} | {r['ms_per_step']:>8.2f} "
            f"{s.get('line of sight', 0.0):>6.2f} {s.get('skyline + walls', 0.0):>6.2f}"
        )
        crow.append({"blocks": nb, "buildings": city.buildings.n, "extent_m": x1 - x0, **r})
    print(
        "   why: line of sight culls (UAV, building) pairs in one O(N x buildings) test and"
        "\n   traces only the pairs within reach of the lowest satellite's ray (~(roof - z) /"
        "\n   tan(10 deg), under 1 km) and only the satellites low enough to pass under that"
        "\n   roof; the skyline and wall sensors sweep 8 horizontal rays per UAV over every"
        "\n   building (O(N x 8 x buildings), one compiled loop), which is what grows with the"
        "\n   city; the rest of the step (solvers, measurements) does not depend on it."
    )
    out["scaling_city"] = crow


# --------------------------------------------------------------------------------------------
# 5. batched vector environments
# --------------------------------------------------------------------------------------------


def city_settings(city: str | None, pool: int | None) -> dict[str, Any]:
    """The environment settings of ``--city`` and ``--city-pool`` (none for the defaults)."""
    return ({} if city is None else {"city": city}) | ({} if pool is None else {"city_pool": pool})


def build_city_pool(n: int, city: str, pool: int) -> None:
    """Build the ``pool`` cities of a family city's pool before any timing, as a long training
    run has them (a city is built once per process and seed: ``seeded_family_city``)."""
    from coopnav_env.sim.city_families import family_of_seed, seeded_family_city

    cfg = make_urban(n, city=city, city_pool=pool).config
    origin = (cfg.lat_deg, cfg.lon_deg, cfg.alt_m)
    for seed in range(pool):
        seeded_family_city(family_of_seed(city, seed), seed, origin)


def vec_stepper(
    kind: str, n: int, k: int, city_kw: dict[str, Any] | None = None
) -> tuple[Callable[[int], None], Any]:
    """A stepper of ``k`` copies of ``n`` UAVs as one vector env of ``kind`` with random
    actions (``city_kw``: :func:`city_settings`)."""
    from coopnav_env.training.vec_env import make_vec_env

    venv = make_vec_env(functools.partial(make_urban, n, **(city_kw or {})), k, 1, kind=kind)
    venv.seed(0)
    venv.reset()
    rng = np.random.default_rng(0)

    def step(m: int) -> None:
        for _ in range(m):
            venv.step(rng.uniform(-1.0, 1.0, (venv.num_envs, 3)).astype(np.float32))

    return step, venv


def batch_stepper(
    n: int, k: int, city_kw: dict[str, Any] | None = None
) -> tuple[Callable[[int], None], Any]:
    """A stepper of ``k`` copies of ``n`` UAVs as :class:`~coopnav_env.envs.
    BatchedUrbanCanyonEnv` itself, with random actions through :meth:`step_arrays` (arrays in
    and out, no per-slot dicts: what a trainer that reads arrays pays)."""
    from coopnav_env.envs import BatchedUrbanCanyonEnv

    batch = BatchedUrbanCanyonEnv.from_envs([make_urban(n, **(city_kw or {})) for _ in range(k)])
    batch.reset(seed=0)
    rng = np.random.default_rng(0)

    def step(m: int) -> None:
        for _ in range(m):
            batch.step_arrays(rng.uniform(-1.0, 1.0, (k, n, 3)).astype(np.float32))

    return step, batch


def section_batched(args, out: dict) -> None:
    n, k = 5, args.copies
    city_kw = city_settings(args.city, args.city_pool)
    where = "".join(f" {key}={value}" for key, value in city_kw.items())
    print(
        f"\n== 5. K = {k} copies at N = {n}{where} as one vector env (env-steps/s = swarm steps) =="
    )
    if not (have("stable_baselines3") and have("supersuit")):
        print("   needs the train extra (stable-baselines3, supersuit): skipped")
        return
    if args.city_pool is not None:
        build_city_pool(n, args.city, args.city_pool)
    fns, venvs = {}, []
    for kind in ("supersuit", "batched"):
        fn, venv = vec_stepper(kind, n, k, city_kw)
        fns[kind] = fn
        venvs.append(venv)
    fns["arrays"], batch = batch_stepper(n, k, city_kw)
    venvs.append(batch)
    if have("vmas"):
        fns["vmas"] = vmas_stepper(n, k)
    k2 = args.scale_copies or None
    copies = dict.fromkeys(fns, k)
    if k2 is not None:  # the same steppers at K2, in the same alternating rounds
        fns[f"arrays@{k2}"], big = batch_stepper(n, k2, city_kw)
        venvs.append(big)
        if have("vmas"):
            fns[f"vmas@{k2}"] = vmas_stepper(n, k2)
        copies |= {name: k2 for name in fns if name.endswith(f"@{k2}")}
    seconds = max(args.seconds, 1.0)
    best = side_by_side(fns, seconds, args.rounds)
    row = {kind: rate * copies[kind] for kind, rate in best.items()}
    for kind, rate in row.items():
        print(f"   {kind:>10}: {rate:8.0f} env-steps/s  ({rate * n:8.0f} agent-steps/s)")
    print(f"   batched / supersuit: {row['batched'] / row['supersuit']:.2f}x")
    if "vmas" in row:
        print(f"   batched / vmas: {row['batched'] / row['vmas']:.2f}x")
        print(f"   arrays / vmas: {row['arrays'] / row['vmas']:.2f}x")
    if k2 is not None:
        # cost per swarm step at K2 over that at K: K's env-steps/s over K2's
        print(
            f"   cost per swarm step, K = {k2} against K = {k}: arrays "
            f"{row['arrays'] / row[f'arrays@{k2}']:.2f}x"
            + (f", vmas {row['vmas'] / row[f'vmas@{k2}']:.2f}x" if "vmas" in row else "")
            + " (below 1: cheaper per swarm at the larger batch)"
        )
        if "vmas" in row:
            print(f"   arrays / vmas at K = {k2}: {row[f'arrays@{k2}'] / row[f'vmas@{k2}']:.2f}x")
    # the compiled part of a batched step: a ceiling for any batching of this Python code
    step = fns["batched"]
    with kernel_timers() as acc:
        t0 = time.perf_counter()
        m = 0
        while time.perf_counter() - t0 < seconds or m < 3:
            step(1)
            m += 1
        wall = time.perf_counter() - t0
    per_swarm = {name: v / (m * k) for name, v in acc.items()}
    compiled = sum(per_swarm.values())
    top = max(per_swarm, key=per_swarm.get) if per_swarm else "-"
    cores = 2  # the target machine
    ceiling = cores / compiled if compiled > 0 else float("inf")
    print(
        f"   compiled kernels: {compiled * 1e6:.0f} us of thread time per swarm step "
        f"(summed over the threads: {100 * compiled * m * k / wall:.0f}% of the batched step's "
        f"wall time; the largest, {top}, {per_swarm.get(top, 0.0) * 1e6:.0f} us)"
        f"\n   ceiling with every line of Python free and {cores} cores in perfect parallel: "
        f"{ceiling:,.0f} env-steps/s (= {cores} / compiled time per swarm step)"
    )
    timeline = array_step_timeline(fns["arrays"], seconds)
    print(
        f"   where an array step goes (ms per step of K = {k}): motion "
        f"{timeline.get('motion_sight_relative', 0.0):.2f}, navigation "
        f"{timeline.get('navigation_reward_sensors', 0.0):.2f} (the automatic resets "
        f"{timeline['resets']:.2f} of it, on the calling thread beside the kernel), "
        f"observations {timeline.get('observations_infos', 0.0):.2f}, Python outside the "
        f"compiled calls {timeline['python']:.2f} (the other cores waiting); "
        f"step {timeline['step']:.2f}"
    )
    for venv in venvs:
        venv.close()
    out["batched"] = {
        "n": n,
        "copies": k,
        "scale_copies": k2,
        "city": args.city,
        "city_pool": args.city_pool,
        "env_steps_per_s": row,
        "compiled_s_per_swarm_step": compiled,
        "compiled_by_kernel_s_per_swarm_step": per_swarm,
        "ceiling_env_steps_per_s_2_cores": ceiling,
        "array_step_ms": timeline,
    }


# --------------------------------------------------------------------------------------------
# 6. PPO training throughput
# --------------------------------------------------------------------------------------------


def ppo_update_timer() -> contextlib.AbstractContextManager[dict[str, float]]:
    """Time SB3's ``PPO.train`` (the gradient updates after each rollout): seconds in
    ``acc["update_s"]``."""
    from stable_baselines3 import PPO

    return timed_attributes([("update_s", PPO, "train")])


def train_rate(kind: str, n_envs: int, timesteps: int, n_steps: int) -> tuple[float, float]:
    """(agent-steps/s of ``train()``, share of its learning time in PPO's gradient updates)."""
    from coopnav_env.training.config import TrainConfig, load_config
    from coopnav_env.training.sb3_backend import train

    base = load_config()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = TrainConfig.from_dict(
            {
                **base,
                "out": tmp,
                "timesteps": timesteps,
                "n_envs": n_envs,
                "vec_env": kind,
                "checkpoint_freq": 0,
                "pretrain": None,
                "progress_bar": False,
                "ppo": {
                    **base["ppo"],
                    "n_steps": n_steps,
                    "batch_size": min(int(base["ppo"]["batch_size"]), n_steps * n_envs),
                },
            }
        )
        with ppo_update_timer() as acc:
            train(cfg)
        info = json.loads((Path(tmp) / "run.json").read_text())
    update_share = acc.get("update_s", 0.0) / float(info["session_wall_s"])
    return float(info["agent_steps_per_s"]), update_share


def section_train(args, out: dict) -> None:
    n_uavs = int(urban_canyon_v1.parallel_env().config.n_uavs)
    rollout = args.train_n_steps * args.train_copies * n_uavs
    steps = rollout * args.train_rollouts
    print(
        f"\n== 6. PPO training throughput (coopnav train, packaged hyperparameters, n_envs = "
        f"{args.train_copies}, n_steps = {args.train_n_steps}, {steps} agent-steps each) =="
    )
    if not (have("stable_baselines3") and have("supersuit")):
        print("   needs the train extra: skipped")
        return
    rates: dict[str, list[float]] = {"supersuit": [], "batched": []}
    shares: dict[str, list[float]] = {"supersuit": [], "batched": []}
    for _ in range(args.rounds):
        for kind in rates:
            rate, share = train_rate(kind, args.train_copies, steps, args.train_n_steps)
            rates[kind].append(rate)
            shares[kind].append(share)
    best = {kind: max(v) for kind, v in rates.items()}
    for kind, v in best.items():
        each = ", ".join(f"{x:.0f}" for x in rates[kind])
        share = shares[kind][rates[kind].index(v)]
        print(
            f"   {kind:>9}: {v:8.0f} agent-steps/s  (rounds: {each}; "
            f"{100 * share:.0f}% of the time in PPO's gradient updates)"
        )
    print(f"   batched / supersuit: {best['batched'] / best['supersuit']:.2f}x")
    # PPO's updates cost the same whatever steps the environment: a ceiling for any vector env
    ss_share = shares["supersuit"][rates["supersuit"].index(best["supersuit"])]
    ceiling = 1.0 / ss_share if ss_share > 0 else float("inf")
    print(
        f"   ceiling: a vector env that cost nothing (and a free policy forward pass) would "
        f"leave the updates,\n   so no vector env can train more than 1 / {ss_share:.2f} = "
        f"{ceiling:.2f}x faster than the SuperSuit path with these hyperparameters"
    )
    out["train"] = {
        "n_envs": args.train_copies,
        "n_steps": args.train_n_steps,
        "agent_steps": steps,
        "agent_steps_per_s": best,
        "rounds": rates,
        "update_share_rounds": shares,
        "ceiling_vs_supersuit": ceiling,
    }


# --------------------------------------------------------------------------------------------
# 7. a city from a file
# --------------------------------------------------------------------------------------------


class PolicyStepper(RandomStepper):
    """A named heuristic of :func:`coopnav_env.agents.make_policy` flies the swarm."""

    def __init__(self, env: Any, policy: str, seed: int = 0):
        from coopnav_env.agents import make_policy

        self.policy = make_policy(policy, env)
        super().__init__(env, seed)
        self.obs, _ = env.reset(seed=seed)
        self.policy.reset(seed=seed)

    def run(self, steps: int) -> None:
        env = self.env
        for _ in range(steps):
            if not env.agents:
                self.obs, _ = env.reset()
                self.policy.reset()
                self.episodes += 1
            self.obs = env.step(self.policy.act(self.obs))[0]
            self.steps += 1


def section_file_city(args, out: dict) -> None:
    import warnings

    from coopnav_env.sim.file_city import sample_city_geojson

    print("\n== 7. a city from a GeoJSON file vs the grid city, N = 5 (steps/s) ==")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "city500.geojson"
        path.write_text(json.dumps(sample_city_geojson(seed=11, n_blocks=10)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the buildings without a height
            file_kw = {"city": f"geojson:{path}"}
            n_b = make_urban(5, **file_kw)
            n_b.reset(seed=0)
            n_buildings = n_b.world.city.buildings.n
            rows = []
            for label, stepper in (
                ("hover", lambda **kw: HoverStepper(make_urban(5, **kw)).run),
                ("column", lambda **kw: PolicyStepper(make_urban(5, **kw), "column").run),
            ):
                best = side_by_side(
                    {"grid": stepper(), "file": stepper(**file_kw)}, args.seconds, args.rounds
                )
                ratio = best["grid"] / best["file"]
                print(
                    f"   {label:>9}: grid city {best['grid']:8.1f}, file city ({n_buildings} "
                    f"buildings) {best['file']:8.1f}; a file-city step costs {ratio:.2f}x"
                )
                rows.append({"actions": label, **best, "cost_ratio": ratio})
    out["file_city"] = {"n_buildings": n_buildings, "rows": rows}


# --------------------------------------------------------------------------------------------
# 8. real cities under a real sky
# --------------------------------------------------------------------------------------------

MONACO_LARGE_BBOX: tuple[float, float, float, float] = (43.7280, 7.4150, 43.7460, 7.4350)
"""A box of the shipped Monaco extract with about 950 buildings (section 8)."""


def section_real_city(args, out: dict) -> None:
    import warnings

    from coopnav_env.sim.real_suite import REAL_SUITE, SUITE_SKY, SUITE_SYSTEMS

    print("\n== 8. real cities under a real sky vs the grid city, N = 5 (steps/s) ==")
    if not have("osmium"):
        print("   skipped: needs pyosmium (pip install -e '.[osm]')")
        return
    sky = {"constellation": SUITE_SKY, "systems": SUITE_SYSTEMS}
    cities = [(c.name, c.env_settings()) for c in REAL_SUITE]
    large = {"city": "osm:monaco", "city_bbox": MONACO_LARGE_BBOX, "city_default_height_m": 15.0}
    cities.append(("monaco_large", large | sky))
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the buildings without a height, the sky's records
        for name, kw in cities:
            probe = make_urban(5, **kw)
            probe.reset(seed=0)
            n_buildings = probe.world.city.buildings.n
            for label, stepper in (
                ("hover", lambda **k: HoverStepper(make_urban(5, **k)).run),
                ("column", lambda **k: PolicyStepper(make_urban(5, **k), "column").run),
            ):
                fns = {"grid": stepper(), "grid_sky": stepper(**sky), "real": stepper(**kw)}
                best = side_by_side(fns, args.seconds, args.rounds)
                ratio = best["grid"] / best["real"]
                city_ratio = best["grid_sky"] / best["real"]
                print(
                    f"   {name:>15} ({n_buildings:4d} buildings) {label:>6}: grid city "
                    f"{best['grid']:7.1f}, under the real sky {best['grid_sky']:7.1f}, real city "
                    f"{best['real']:7.1f}; a real-city step costs {ratio:.2f}x a grid-city "
                    f"step, {city_ratio:.2f}x under the same sky"
                )
                rows.append(
                    {"city": name, "buildings": n_buildings, "actions": label, **best}
                    | {"cost_ratio": ratio, "cost_ratio_same_sky": city_ratio}
                )
    out["real_city"] = rows


# --------------------------------------------------------------------------------------------
# main
# --------------------------------------------------------------------------------------------


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="short smoke run (about a minute)")
    ap.add_argument(
        "--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS), help="what to run"
    )
    ap.add_argument("--seconds", type=float, default=None, help="seconds per measurement (3)")
    ap.add_argument("--rounds", type=int, default=None, help="alternating rounds (2)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help="N of 1-3 (5 20 50)")
    ap.add_argument(
        "--scaling", type=int, nargs="+", default=None, help="N of 4a (2 5 10 20 50 100)"
    )
    ap.add_argument("--blocks", type=int, nargs="+", default=None, help="4b (3 6 12 24)")
    ap.add_argument("--copies", type=int, default=64, help="K of section 5 (64)")
    ap.add_argument(
        "--scale-copies",
        type=int,
        default=None,
        metavar="K2",
        help="section 5 also steps K2 copies through the array step, and VMAS with K2, in the "
        "same rounds: the cost per swarm step at K2 against K (default 4 K; 0: not)",
    )
    ap.add_argument(
        "--city",
        default=None,
        help="the environment's city setting for section 5's copies, e.g. family:mixed or "
        "geojson:PATH (default: the environment's grid city)",
    )
    ap.add_argument(
        "--city-pool",
        type=int,
        default=None,
        help="with --city family:NAME, the environment's city_pool; the pool's cities are "
        "built before timing, as in a long training run",
    )
    ap.add_argument("--train-copies", type=int, default=None, help="n_envs of section 6 (8)")
    ap.add_argument("--train-n-steps", type=int, default=None, help="PPO n_steps (256)")
    ap.add_argument("--train-rollouts", type=int, default=None, help="rollouts (2)")
    ap.add_argument(
        "--memory-copies", type=int, nargs="+", default=None, help="K of 3b (64 256 1024 4096)"
    )
    ap.add_argument("--memory-steps", type=int, default=None, help="steps of 3b (20)")
    ap.add_argument(
        "--memory-trace-max", type=int, default=None, help="largest K of 3b traced (1024)"
    )
    ap.add_argument("--memory-sample", type=int, default=256, help="copies broken down in 3b (256)")
    ap.add_argument("--memory-child", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--memory-trace", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--json", default=None, metavar="PATH", help="also write the figures here")
    args = ap.parse_args(argv)
    quick = args.quick
    defaults = {
        "seconds": 0.4 if quick else 3.0,
        "rounds": 1 if quick else 2,
        "sizes": [5, 20] if quick else [5, 20, 50],
        "scaling": [2, 5, 10] if quick else [2, 5, 10, 20, 50, 100],
        "blocks": [3, 6, 12] if quick else [3, 6, 12, 24],
        "train_copies": 2 if quick else 8,
        "train_n_steps": 32 if quick else 256,
        "train_rollouts": 1 if quick else 2,
        "memory_copies": [64, 256] if quick else [64, 256, 1024, 4096],
        "memory_steps": 5 if quick else 20,
        "memory_trace_max": 64 if quick else 1024,
    }
    for name, value in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if quick and args.copies == 64:
        args.copies = 8
    if args.scale_copies is None:
        args.scale_copies = 0 if quick else 4 * args.copies
    if args.scale_copies < 0:
        ap.error(f"--scale-copies must be >= 0, got {args.scale_copies}")
    return args


def check_sources() -> None:
    """Warn when a subpackage of ``coopnav_env`` resolves outside this checkout.

    ``coopnav_env.training`` and ``coopnav_env.agents`` are mapped to this repository's
    ``training/`` and ``agents/`` by the editable install's finder; a ``PYTHONPATH`` entry
    that holds another checkout's editable finder (a site-packages directory used for the
    references) maps them to that checkout's code instead, and the figures would be another
    version's.
    """
    import importlib

    root = Path(__file__).resolve().parents[1]
    for name in ("coopnav_env", "coopnav_env.training", "coopnav_env.agents"):
        try:
            where = Path(importlib.import_module(name).__file__).resolve()
        except ImportError:  # an extra that is not installed: its sections say so
            continue
        if root not in where.parents:
            print(
                f"WARNING: {name} is imported from {where.parent}, not from {root}: the "
                "figures are that code's. Point PYTHONPATH at a folder holding only the "
                "references (vmas, mpe2), not at another checkout's site-packages."
            )


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    check_sources()
    if args.memory_child is not None:  # one K of section 3b, in its own process
        row = batch_memory_child(
            args.memory_child, args.memory_steps, args.memory_trace, args.memory_sample
        )
        print(json.dumps(row, default=float))
        return 0
    try:
        import torch

        torch.set_num_threads(1)  # as coopnav train (torch_threads: 1) and fair to VMAS
    except ImportError:
        pass
    out: dict[str, Any] = {"args": {k: v for k, v in vars(args).items() if k != "json"}}
    print(
        f"bench_env: python {sys.version.split()[0]}, numpy {np.__version__}; "
        f"{args.seconds:g} s per measurement, {args.rounds} round(s)"
    )
    t0 = time.perf_counter()
    runners = {
        "compare": section_compare,
        "stages": section_stages,
        "memory": section_memory,
        "batch_memory": section_batch_memory,
        "scaling": section_scaling,
        "batched": section_batched,
        "train": section_train,
        "file_city": section_file_city,
        "real_city": section_real_city,
    }
    for name in SECTIONS:
        if name in args.sections:
            runners[name](args, out)
    out["wall_s"] = time.perf_counter() - t0
    print(f"\n(total {out['wall_s']:.0f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
