"""Per-seed work in worker processes, in seed order, with a progress bar.

The data-collection scripts of the studies (``route_learning.py`` and ``route_choice.py`` here,
``studies/split_choice/split_choice.py``, ``studies/choice_headroom/arm_choice.py``) fly
thousands of episodes, one independent job per reset seed. :func:`map_seeds` hands the seeds
to ``jobs`` worker processes in small blocks (one environment per block), shows a progress
bar over the episodes and returns the results in the order of the seeds. The result of a seed
never depends on the block it was flown in or on the number of workers: every episode is fixed
by its reset seed (and reset options), so ``jobs=1`` and ``jobs=2`` give the same results,
bit for bit.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, TypeVar

__all__ = ["map_seeds"]

T = TypeVar("T")


def _bar(total: int, desc: str | None, progress: bool) -> Any:
    if not progress or total < 1:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm comes with the train extra
        return None
    return tqdm(total=total, unit="episode", desc=desc, file=sys.stderr)


def map_seeds(
    worker: Callable[[Any, list[int]], list[T]],
    common: Any,
    seeds: Sequence[int],
    *,
    jobs: int = 2,
    block: int = 8,
    desc: str | None = None,
    progress: bool = True,
) -> list[T]:
    """``worker(common, block_of_seeds)`` for every block of ``seeds``; one result per seed.

    ``worker`` must be a module-level function (it is pickled to the workers) that returns a
    list with one result per seed of its block, in order. ``jobs`` worker processes (1: in
    this process), blocks of ``block`` seeds, a progress bar on stderr unless ``progress`` is
    False. The results come back in the order of ``seeds``.
    """
    seeds = [int(s) for s in seeds]
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be an int >= 1, got {jobs!r}")
    if isinstance(block, bool) or not isinstance(block, int) or block < 1:
        raise ValueError(f"block must be an int >= 1, got {block!r}")
    blocks = [seeds[i : i + block] for i in range(0, len(seeds), block)]
    bar = _bar(len(seeds), desc, progress)
    results: list[list[T] | None] = [None] * len(blocks)
    try:
        if jobs == 1 or len(blocks) < 2:
            for i, b in enumerate(blocks):
                results[i] = _checked(worker(common, b), b)
                if bar is not None:
                    bar.update(len(b))
        else:
            with ProcessPoolExecutor(min(jobs, len(blocks))) as ex:
                futs = {ex.submit(worker, common, b): i for i, b in enumerate(blocks)}
                pending = set(futs)
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for f in done:
                        i = futs[f]
                        results[i] = _checked(f.result(), blocks[i])
                        if bar is not None:
                            bar.update(len(blocks[i]))
    finally:
        if bar is not None:
            bar.close()
    return [r for part in results if part is not None for r in part]


def _checked(part: list[T], block: list[int]) -> list[T]:
    if len(part) != len(block):
        raise RuntimeError(
            f"a worker returned {len(part)} results for a block of {len(block)} seeds"
        )
    return part
