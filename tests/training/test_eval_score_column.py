"""``coopnav evaluate``'s table titles the return "score" where the return is the score."""

from __future__ import annotations

import warnings

from coopnav_env.training.evaluate import evaluate


def _header(env_id: str, **env_kwargs) -> list[str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # the legacy v0's warning
        report = evaluate(
            ["column"], [1_000_000], {"max_steps": 8, **env_kwargs}, env_id=env_id, plots=False
        )
    return [c.strip() for c in report.to_markdown().splitlines()[0].strip("|").split("|")]


def test_v1_return_is_titled_score_and_v0_return_is_not() -> None:
    v1 = _header("urban_canyon_v1")
    assert "score" in v1 and "return" not in v1
    assert {"goal rate", "collisions", "coop mean [m]", "steps"} <= set(v1)
    per_step = _header("urban_canyon_v1", reward_scheme="per_step", goal_bonus=10.0)
    assert "return" in per_step and "score" not in per_step
    v0 = _header("urban_canyon_v0")
    assert "return" in v0 and "score" not in v0
