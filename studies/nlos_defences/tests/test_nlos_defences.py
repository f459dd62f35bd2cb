"""nlos_defences.py: the variants' environments, the figures, a tiny run written to JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coopnav_env.envs import PRESETS
from studies.nlos_defences import nlos_defences as study


def test_variants_differ_by_what_they_name():
    off = study.variant_config("off", 3)
    assert off["n_uavs"] == 3 and "integrity" not in off
    assert off["nlos_probability"] == PRESETS["urban_nlos"]["nlos_probability"]
    fde, fde15 = study.variant_config("fde", 3), study.variant_config("fde15", 3)
    assert {k: v for k, v in fde15.items() if k != "max_fix_sigma_m"} == {
        k: v for k, v in fde.items() if k != "max_fix_sigma_m"
    }
    assert fde15["max_fix_sigma_m"] == 15.0
    assert study.variant_config("map30", 3)["max_fix_sigma_m"] == 30.0
    assert study.variant_config("map", 3)["nlos_exclusion"] == "map"
    with pytest.raises(ValueError, match="unknown variant 'gps'"):
        study.variant_config("gps", 3)


def test_figures_pool_uav_steps():
    ep = {
        "coop_ok": np.array([True, True, False, True]),
        "coop_err": np.array([1.0, 40.0, 99.0, 2.0]),
        "coop_sig": np.array([1.0, 1.0, 1.0, 20.0]),
        "nav_err": np.array([1.0, 40.0, 5.0, 2.0]),
        "h_err": np.array([1.0, 40.0, 5.0, 2.0]),
        "hpl": np.array([5.0, 5.0, np.inf, 5.0]),
    }
    f = study.figures([ep, ep])
    assert f["uav_steps"] == 8 and f["coop_fixes"] == 6
    assert f["coop_ok"] == pytest.approx(0.75)
    assert f["ok_over_30m"] == pytest.approx(1 / 3)  # 40 m of the fixes 1, 40, 2 m
    assert f["ok_over_30m_3sig"] == pytest.approx(1 / 3)  # 40 m > 3 x 1 m


def test_a_tiny_run_writes_every_row(tmp_path, capsys):
    out = tmp_path / "nlos.json"
    argv = ["--episodes", "2", "--n-uavs", "2", "--policies", "column"]
    argv += ["--variants", "off", "map", "--bootstrap", "10", "--json", str(out)]
    assert study.main(argv) == 0
    data = json.loads(out.read_text())
    assert set(data["results"]) == {"column/off", "column/map"}
    assert data["results"]["column/map"]["figures"]["uav_steps"] > 0
    assert "column   map" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        study.main(["--episodes", "1"])
