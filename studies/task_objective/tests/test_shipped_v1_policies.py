"""The shipped v1 policies give back the committed comparison without training.

The comparison reports of this study (``learned_*/report.json``) keep every policy's
per-episode figures; flying the policies the package ships (``mappo:pretrained/...``) and the
models under ``policies/`` on a report's first episodes must give the same figures, to the
bit. A policy that has moved since its report was written is flown from where it is now and
compared with the figures the report stored under its name of then.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from studies.task_objective import compare_learned as cl

STUDY = Path(__file__).resolve().parents[1]
REPORT = STUDY / "learned_v1_by_backend" / "report.json"
ROUTE_REPORT = STUDY / "learned_route_frame" / "report.json"
BRAKE_REPORT = STUDY / "learned_route_braking" / "report.json"
BRAKE_8M_REPORT = STUDY / "learned_route_braking_8m" / "report.json"
REPEAT_REPORT = STUDY / "learned_route_repeat" / "report.json"
REPEAT_8M_REPORT = STUDY / "learned_route_repeat_8m" / "report.json"
NOISE_HELD_REPORT = STUDY / "learned_route_noise_held" / "report.json"
NOISE_START_REPORT = STUDY / "learned_route_noise_start" / "report.json"
NOISE_START_8M_REPORT = STUDY / "learned_route_noise_start_8m" / "report.json"
NOISE_SPEED_REPORT = STUDY / "learned_route_noise_start_speed" / "report.json"
HOLD_REPORT = STUDY / "learned_route_hold" / "report.json"
HOLD_IPPO_REPORT = STUDY / "learned_route_hold_ippo" / "report.json"
POLICIES = "studies/task_objective/policies"

REL_TOLERANCE = 1e-5
"""Relative difference allowed in a flown episode's real-valued figures. The policies are
float32 torch networks, whose CPU kernels may round differently on another processor (their
vector instructions set the order of summation): an action moves by about 1e-7 and the closed
loop carries that into the figures (seen: 4e-7 relative in the cruise spacing of an 82-step
episode). A policy that flies differently moves them by far more."""
EXACT = ("seed", "goal", "collided", "steps")
"""The figures that must agree exactly."""
SHIPPED = (
    "mappo:pretrained/v1_s0",
    "mappo:pretrained/v1_s1",
    "mappo:pretrained/v1_s2",
    "ippo:pretrained/v1_s0",
    "ippo:pretrained/v1_s1",
    "ppo:studies/task_objective/policies/sb3_ppo_s0/final_model.zip",
)


ROUTE_SHIPPED = ("mappo:studies/task_objective/policies/mappo_route_6m_s0",)

MOVED = {
    f"{kind}:pretrained/v1_route_s{k}": f"{kind}:{POLICIES}/{kind}_v1_route_s{k}"
    for kind, k in (("mappo", 0), ("mappo", 1), ("mappo", 2), ("ippo", 0))
}
"""Policies this study's reports name by their earlier place in the package -> where they are."""

RECIPE = {
    f"mappo:pretrained/route_s{k}": f"mappo:{POLICIES}/mappo_route_hold_unweighted_bc_8m_s{k}"
    for k in range(3)
} | {
    f"mappo:pretrained/route_scratch_s{k}": f"mappo:{POLICIES}/mappo_route_hold_unweighted_8m_s{k}"
    for k in range(3)
}
"""The shipped recipe policies (``coopnav train --config mappo_route``, ``mappo_route_scratch``)
-> the study's runs they are copies of, whose episodes ``learned_route_hold`` stores."""


@pytest.mark.parametrize(
    ("report_path", "policy"),
    [(REPORT, p) for p in SHIPPED]
    + [(ROUTE_REPORT, p) for p in ROUTE_SHIPPED]
    + [(ROUTE_REPORT, (stored, now)) for stored, now in MOVED.items()]
    + [(HOLD_REPORT, (stored, shipped)) for shipped, stored in RECIPE.items()]
    + [(BRAKE_REPORT, "mappo:studies/task_objective/policies/mappo_route_brake_4m_s2")]
    + [(BRAKE_8M_REPORT, "mappo:studies/task_objective/policies/mappo_route_brake_8m_s0")]
    + [(REPEAT_REPORT, "mappo:studies/task_objective/policies/mappo_route_repeat4_bc_4m_s0")]
    + [(REPEAT_8M_REPORT, "mappo:studies/task_objective/policies/mappo_route_repeat4_bc_8m_s1")]
    + [(NOISE_HELD_REPORT, "mappo:studies/task_objective/policies/mappo_route_noise_held_bc_s0")]
    + [(NOISE_START_REPORT, f"mappo:{POLICIES}/mappo_route_noise_start_bc_4m_s1")]
    + [(NOISE_START_8M_REPORT, f"mappo:{POLICIES}/mappo_route_noise_start_8m_s2")]
    + [(NOISE_SPEED_REPORT, f"mappo:{POLICIES}/mappo_route_noise_start_speed_bc_4m_s1")]
    + [(HOLD_REPORT, f"mappo:{POLICIES}/mappo_route_hold_unweighted_bc_8m_s0")]
    + [(HOLD_REPORT, f"mappo:{POLICIES}/mappo_route_hold_importance_bc_4m_s2")]
    + [(HOLD_IPPO_REPORT, f"ippo:{POLICIES}/ippo_route_hold_unweighted_bc_4m_s1")],
    ids=lambda v: v.parent.name if isinstance(v, Path) else v[1] if isinstance(v, tuple) else v,
)
def test_a_shipped_policy_flies_the_reports_episodes_again(
    report_path, policy, monkeypatch
) -> None:
    """``policy``: a name in the report, or (name in the report, name to fly it by now)."""
    stored_name, flown_name = policy if isinstance(policy, tuple) else (policy, policy)
    if flown_name.startswith("ppo:"):
        pytest.importorskip("stable_baselines3")
    else:
        pytest.importorskip("torch")
    monkeypatch.chdir(STUDY.parents[1])  # the models' paths are relative to the repository
    report = json.loads(report_path.read_text())
    stored = report["episodes_per_policy"][stored_name][:2]
    flown = cl.fly(flown_name, [e["seed"] for e in stored])
    assert len(flown) == len(stored)
    for got, want in zip(flown, stored):
        assert set(got) == set(want)
        assert {k: got[k] for k in EXACT if k in got} == {k: want[k] for k in EXACT if k in want}
        assert got == pytest.approx(want, rel=REL_TOLERANCE, abs=1e-9)
