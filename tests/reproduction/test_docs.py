"""The committed reproduction (``docs/reproduction``) is the default run, and the tables of
its page (``docs/reproduction/README.md``) show its numbers."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from coopnav_env.reproduction import ReproduceConfig

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "reproduction"


@pytest.fixture(scope="module")
def results() -> dict:
    return json.loads((DOCS / "results.json").read_text())


def _section() -> str:
    text = (DOCS / "README.md").read_text()
    assert text.startswith("# Reproducing the paper (Section 4)\n")
    return text


def _row(label: str) -> list[str]:
    """The cells after the first of the page's row that starts with ``| label |``."""
    for line in _section().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == label:
            return cells[1:]
    raise AssertionError(f"no row {label!r} in docs/reproduction/README.md")


def _numbers(cell: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+\.\d+|-?\d+", cell)]


def _sig3d(stats: dict) -> float:
    return math.sqrt(sum(stats[ax]["sig"] ** 2 for ax in "ENU"))


def test_committed_run_is_the_default_configuration(results):
    cfg = json.loads((DOCS / "config.json").read_text())
    assert ReproduceConfig.from_dict(cfg) == ReproduceConfig()
    assert results["config"] == cfg
    report = (DOCS / "report.md").read_text()
    assert report.startswith("# Reproduction of Section 4")
    assert "coopnav reproduce --out DIR --seed 0\n" in report


def test_page_headline_table_is_the_committed_run(results):
    m = results["main"]
    p3, t1 = m["p3m"], m["table1"]
    assert _numbers(_row("P(3-D error < 3 m), standalone")[1]) == [
        round(p3["sdt"]["standalone"], 1)
    ]
    assert _numbers(_row("P(3-D error < 3 m), cooperative SDT / DDT")[1]) == [
        round(p3["sdt"]["cooperative"], 1),
        round(p3["ddt"]["cooperative"], 1),
    ]
    assert _numbers(_row("3-D SIG of the canyon UAV, cooperative")[1]) == [
        round(_sig3d(t1["cooperative"]), 2)
    ]
    assert _numbers(_row("3-D SIG of the canyon UAV, standalone (pooled)")[1]) == [
        round(_sig3d(t1["standalone"]), 2),
        round(m["median_epoch_sig3d_m"]["standalone"], 2),
    ]
    for n in ("2", "5", "50"):
        cells = _row(f"improvement N = {n}, without / with differential")
        pub = [results["published"]["table2"][k][n] for k in ("without", "with")]
        assert _numbers(cells[0]) == pub
        rep = [round(results["swarm"][k][n]["sig"], 1) for k in ("without", "with")]
        assert _numbers(cells[1]) == rep


@pytest.mark.parametrize(
    ("label", "variant"),
    [
        ("published", None),
        ("**default**", "default"),
        ("`iono-free`: Eq. 8 with its iono-free factor", "iono-free"),
        ("`paper-covariance`: the paper's Eq. 18", "paper-covariance"),
        ("`paper-cov-iono-free`: Eq. 18 and the factor", "paper-cov-iono-free"),
        ("`all-fixes`: no PDOP mask", "all-fixes"),
        ("`previous-default`: the factor and no PDOP mask", "previous-default"),
    ],
)
def test_page_table2_rows_are_the_committed_run(results, label, variant):
    if variant is None:
        tab = {
            k: {n: {"sig": v} for n, v in d.items()}
            for k, d in results["published"]["table2"].items()
        }
    elif variant == "default":
        tab = results["swarm"]
    else:
        tab = results["table2_variants"][variant]
    cells = _row(label)
    for cell, key in zip(cells, ("without", "with"), strict=True):
        want = [round(tab[key][n]["sig"], 1) for n in ("2", "5", "10", "20", "50")]
        assert _numbers(cell) == want, (label, key)


def test_page_prose_numbers_are_the_committed_run(results):
    text = " ".join(_section().split())
    dist = results["table2_distance"]["default"]
    assert (
        f"within {dist['without']:.1f} points of the published row without and "
        f"{dist['with']:.1f} points with" in text
    )
    n_claims = len(results["claims"])
    assert sum(c["holds"] for c in results["claims"]) == n_claims == 12
    assert f"All {n_claims} of the paper's qualitative claims we check hold" in text
    sens = {r["name"]: r for r in results["sensitivity"]}
    iono = sens["iono-free"]
    assert f"gives {iono['p3m_standalone']:.0f} % / {iono['p3m_sdt']:.0f} %" in text
    w2 = results["table2_variants"]["paper-covariance"]["with"]["2"]["sig"]
    assert f"({w2:.1f} %)" in text
