"""Your own policy under a name: coopnav_env.agents.register_policy, make_policy and evaluation."""

from __future__ import annotations

import numpy as np
import pytest

import coopnav_env.agents
from coopnav_env import urban_canyon_v0
from coopnav_env.agents import make_policy, register_policy


class _Hover:
    """Every UAV holds still (a Policy)."""

    name = "hover"

    def __init__(self, env, up: float = 0.0):
        self.up = float(up)
        self.resets: list = []

    def reset(self, seed=None) -> None:
        self.resets.append(seed)

    def act(self, observations):
        return {a: np.array([0.0, 0.0, self.up], np.float32) for a in observations}


@pytest.fixture(autouse=True)
def _empty_registry(monkeypatch):
    monkeypatch.setattr(coopnav_env.agents, "_REGISTERED", {})


def test_registered_policy_is_made_with_options() -> None:
    env = urban_canyon_v0.parallel_env()
    register_policy("hover", _Hover)
    assert isinstance(make_policy("hover", env), _Hover)
    p = make_policy("hover@up=0.5", env)
    assert p.up == 0.5 and p.act({"uav_0": None})["uav_0"].tolist() == [0.0, 0.0, 0.5]
    register_policy("hover", _Hover)  # the same factory again: fine
    with pytest.raises(ValueError, match="registered already; pass overwrite=True"):
        register_policy("hover", lambda env: _Hover(env))
    register_policy("hover", lambda env: _Hover(env, up=1.0), overwrite=True)
    assert make_policy("hover", env).up == 1.0
    with pytest.raises(ValueError, match=r"unknown policy 'hoover'; valid policies: .*, hover"):
        make_policy("hoover", env)


@pytest.mark.parametrize("name", ["formation", "ppo", "my policy", "", 3])
def test_bad_names_are_refused(name) -> None:
    with pytest.raises(ValueError, match="policy name must be a Python identifier"):
        register_policy(name, _Hover)


def test_factory_must_return_a_policy() -> None:
    with pytest.raises(ValueError, match="must be callable"):
        register_policy("x", 3)
    register_policy("x", lambda env: object())
    with pytest.raises(ValueError, match="returned object, which lacks the Policy protocol"):
        make_policy("x", urban_canyon_v0.parallel_env())


def test_evaluate_flies_a_registered_policy() -> None:
    from coopnav_env.training.evaluate import evaluate

    register_policy("hover", _Hover)
    report = evaluate(["hover", "formation"], [1_000_000], {"max_steps": 5}, plots=False)
    hover = report["hover"]
    assert hover.episodes == 1 and hover.length_mean == 5.0 and hover.collisions == 0
    assert report["formation"].length_mean == 5.0
