"""coopnav evaluate: availability and misleading-information rate with integrity on."""

from __future__ import annotations

import math

import numpy as np

from coopnav_env.nav import integrity_rates
from coopnav_env.training.evaluate import EVAL_SEED_START, evaluate


def test_integrity_columns_only_with_integrity_and_equal_to_integrity_rates() -> None:
    seeds = [EVAL_SEED_START, EVAL_SEED_START + 1]
    plain = evaluate(["formation"], seeds, {"max_steps": 25}, None)
    assert math.isnan(plain.stats[0].availability)
    assert "availability" not in plain.to_markdown()
    rep = evaluate(
        ["formation", "spread"],
        seeds,
        {"max_steps": 25, "integrity": "fde", "alert_limit_m": 20.0},
        None,
    )
    md = rep.to_markdown()
    assert "availability" in md and "MI rate" in md
    for s in rep.stats:
        eps = rep.episodes[s.policy]
        h = np.concatenate([e.h_error_m.ravel() for e in eps])
        pl = np.concatenate([e.hpl_m.ravel() for e in eps])
        assert np.all(np.isfinite(h)) and np.all(pl > 0)  # -1 of the infos became inf
        r = integrity_rates(h, pl, 20.0)
        assert s.availability == r.availability and s.misleading_rate == r.misleading_rate
        assert 0.0 < s.availability <= 1.0 and s.alert_limit_m == 20.0
    # the error figures do not depend on whether integrity is reported
    assert rep.stats[0].goal_rate >= 0.0
