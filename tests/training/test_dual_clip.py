"""Dual-clip PPO (``torchrl.dual_clip``) and the refusal of a loss that is not finite."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("torchrl")
torch = pytest.importorskip("torch")

from coopnav_env.agents.marl_nets import MARLSettings  # noqa: E402
from coopnav_env.training.torchrl_backend import (  # noqa: E402
    MARLTrainer,
    TrainingDivergedError,
)

ENV = {"n_uavs": 3, "max_steps": 6, "action_frame": "route"}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize("value", [1.0, 1.2, 0.5, True, "3", -3.0])
def test_a_dual_clip_at_or_below_the_clip_range_is_refused_by_name(value) -> None:
    with pytest.raises(ValueError, match=r"torchrl\.dual_clip must be null or a number above"):
        MARLSettings(dual_clip=value)
    assert MARLSettings(dual_clip=3.0).dual_clip == 3.0
    assert MARLSettings().dual_clip is None


def _runaway_batch(tr: MARLTrainer):
    """One rollout with the advantages filled in, in which every sample's logged
    log-probability is 50 below the actor's (ratio e^50) and its advantage negative."""
    data = tr.collect()
    with torch.no_grad():
        tr.loss.value_estimator(
            data,
            params=tr.loss.critic_network_params,
            target_params=tr.loss.target_critic_network_params,
        )
    flat = data.reshape(-1)
    flat["agents", "action_log_prob"] = flat["agents", "action_log_prob"] - 50.0
    adv = flat["agents", "advantage"]
    flat["agents", "advantage"] = -(adv.abs() + 1.0)
    return flat


def _objective_and_grad(tr: MARLTrainer, batch) -> tuple[float, float]:
    tr.loss.normalize_advantage = False  # the hand-set advantages as they are
    out = tr.loss(batch)
    tr.optim.zero_grad()
    out["loss_objective"].backward()
    grad = sum(float(p.grad.abs().sum()) for p in tr.actor.parameters() if p.grad is not None)
    return float(out["loss_objective"]), grad


def test_dual_clip_bounds_a_runaway_ratio_with_a_negative_advantage() -> None:
    plain = MARLTrainer(MARLSettings(n_copies=2, rollout_steps=4), ENV, seed=3)
    batch_p = _runaway_batch(plain)
    dual = MARLTrainer(MARLSettings(n_copies=2, rollout_steps=4, dual_clip=3.0), ENV, seed=3)
    batch_d = _runaway_batch(dual)
    # the same seed: the same rollout and actor
    np.testing.assert_array_equal(
        batch_p["agents", "action"].numpy(), batch_d["agents", "action"].numpy()
    )
    adv = batch_d["agents", "advantage"].numpy()
    obj_p, grad_p = _objective_and_grad(plain, batch_p)
    obj_d, grad_d = _objective_and_grad(dual, batch_d)
    # plain PPO: -ratio * advantage with ratio e^50; dual clip: -3 * advantage, no gradient
    assert obj_p > 1e20
    assert obj_d == pytest.approx(float(-(3.0 * adv).mean()), rel=1e-5)
    assert grad_p > 0.0
    assert grad_d == 0.0
    assert math.isfinite(obj_d)


def test_dual_clip_changes_nothing_while_the_ratios_stay_below_it() -> None:
    """Two updates of one rollout from the same seed: the parameters with and without the cap
    are identical, bit for bit (no ratio of a first update reaches 3)."""
    trained = []
    for cap in (None, 3.0):  # each trainer seeds torch: build, collect and update in turn
        tr = MARLTrainer(
            MARLSettings(n_copies=2, rollout_steps=4, epochs=2, dual_clip=cap), ENV, seed=7
        )
        tr.update(tr.collect())
        trained.append(tr)
    a, b = trained
    for pa, pb in zip(a.loss.parameters(), b.loss.parameters(), strict=True):
        assert torch.equal(pa, pb)


def test_a_loss_that_is_not_finite_stops_training_before_any_update() -> None:
    tr = MARLTrainer(MARLSettings(n_copies=2, rollout_steps=4), ENV, seed=1)
    data = tr.collect()
    data["agents", "action_log_prob"] = data["agents", "action_log_prob"] - 1e6  # ratio inf
    before = [p.detach().clone() for p in tr.loss.parameters()]
    with pytest.raises(
        TrainingDivergedError, match=r"not finite at iteration 1.*not applied.*dual_clip=3"
    ):
        tr.update(data)
    for p, q in zip(tr.loss.parameters(), before, strict=True):
        assert torch.equal(p, q)
