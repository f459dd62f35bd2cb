"""studies.route_choice.parallel.map_seeds: per-seed work in worker processes."""

from __future__ import annotations

import pytest

from studies.route_choice.parallel import map_seeds


def _square_block(common: int, seeds: list[int]) -> list[tuple[int, int]]:
    return [(s, s * s + common) for s in seeds]


def _short_block(common: int, seeds: list[int]) -> list[int]:
    return seeds[:-1]


@pytest.mark.parametrize("jobs,block", [(1, 3), (2, 1), (2, 4), (3, 100)])
def test_map_seeds_returns_one_result_per_seed_in_seed_order(jobs, block):
    seeds = [9, 2, 7, 4, 4, 11, 0]
    got = map_seeds(_square_block, 5, seeds, jobs=jobs, block=block, progress=False)
    assert got == [(s, s * s + 5) for s in seeds]


def test_map_seeds_checks_its_arguments_and_the_workers_results():
    assert map_seeds(_square_block, 0, [], jobs=2, progress=False) == []
    with pytest.raises(ValueError, match="jobs must be an int >= 1, got 0"):
        map_seeds(_square_block, 0, [1], jobs=0)
    with pytest.raises(ValueError, match="block must be an int >= 1, got 0"):
        map_seeds(_square_block, 0, [1], block=0)
    with pytest.raises(RuntimeError, match="2 results for a block of 3 seeds"):
        map_seeds(_short_block, 0, [1, 2, 3], jobs=1, block=3, progress=False)
