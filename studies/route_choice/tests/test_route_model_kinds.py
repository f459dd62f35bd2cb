"""A column policy refuses a model object of the wrong kind (issue 35, finding 8).

``route_model`` scores routes by their ROUTE_FEATURES, ``route_split_model`` scores splits by
their SPLIT_FEATURES: a model of the other kind would be read on the wrong table and flown
under the wrong label. Paths were checked on load; a ``RouteModel`` passed in code is
checked too, and the error names the kind it got.
"""

from __future__ import annotations

import pytest

from coopnav_env import urban_canyon_v0
from coopnav_env.agents import make_policy
from coopnav_env.agents.heuristics import ColumnPolicy
from studies.route_choice.routes import ROUTE_FEATURES, SPLIT_FEATURES, RouteModel


def _model(kind: str) -> RouteModel:
    features = list((ROUTE_FEATURES if kind == "route" else SPLIT_FEATURES)[:2])
    return RouteModel(
        features=features,
        mean=[0.0, 0.0],
        scale=[1.0, 1.0],
        weights=[1.0, -1.0],
        alpha=1.0,
        base="ceiling_column",
        kind=kind,
    )


@pytest.fixture(scope="module")
def env():
    env = urban_canyon_v0.parallel_env(n_uavs=3)
    env.reset(seed=0)
    return env


def test_a_split_model_as_route_model_is_refused_naming_its_kind(env):
    with pytest.raises(ValueError, match=r"route_model must be a route model") as err:
        make_policy("route_column@preset='ceiling_column'", env, route_model=_model("split"))
    assert "got a RouteModel of kind 'split' (pass it as route_split_model)" in str(err.value)


def test_a_route_model_as_route_split_model_is_refused_naming_its_kind(env):
    with pytest.raises(ValueError, match=r"route_split_model must be a split model") as err:
        make_policy("route_column@preset='ceiling_column'", env, route_split_model=_model("route"))
    assert "got a RouteModel of kind 'route' (pass it as route_model)" in str(err.value)


def test_models_of_the_right_kind_are_taken(env):
    policy = make_policy("route_column@preset='ceiling_column'", env, route_model=_model("route"))
    assert isinstance(policy, ColumnPolicy) and policy.route_model.kind == "route"
    policy = make_policy(
        "route_column@preset='ceiling_column'", env, route_split_model=_model("split")
    )
    assert policy.route_split_model.kind == "split"
    with pytest.raises(ValueError, match=r"route_model must be a route model .*, got 3$"):
        make_policy("route_column@preset='ceiling_column'", env, route_model=3)
