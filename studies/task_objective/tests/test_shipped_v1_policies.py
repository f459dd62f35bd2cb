"""The shipped v1 policies give back the committed comparison without training.

``learned_v1_by_backend/report.json`` keeps every policy's per-episode figures; flying the
shipped policies (``agents/pretrained/mappo_v1_s*``, ``ippo_v1_s*`` and the SB3 models under
``policies/``) on the report's first episodes must give the same scores, to the bit.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from studies.task_objective import compare_learned as cl

REPORT = Path(__file__).resolve().parents[1] / "learned_v1_by_backend" / "report.json"
SHIPPED = (
    "mappo:pretrained/v1_s0",
    "mappo:pretrained/v1_s1",
    "mappo:pretrained/v1_s2",
    "ippo:pretrained/v1_s0",
    "ippo:pretrained/v1_s1",
    "ppo:studies/task_objective/policies/sb3_ppo_s0/final_model.zip",
)


@pytest.mark.parametrize("policy", SHIPPED)
def test_a_shipped_policy_flies_the_reports_episodes_again(policy, monkeypatch) -> None:
    if policy.startswith("ppo:"):
        pytest.importorskip("stable_baselines3")
    else:
        pytest.importorskip("torch")
    monkeypatch.chdir(REPORT.parents[3])  # the SB3 model's path is relative to the repository
    report = json.loads(REPORT.read_text())
    stored = report["episodes_per_policy"][policy][:2]
    flown = cl.fly(policy, [e["seed"] for e in stored])
    for got, want in zip(flown, stored):
        assert got == want
