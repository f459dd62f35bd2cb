"""coopnav_env.training.files.claim_run_folder."""

from __future__ import annotations

import json

import pytest

from coopnav_env.training.files import claim_run_folder


def test_claim_run_folder_keeps_a_folder_to_one_run(tmp_path):
    out = tmp_path / "run"
    settings = {"episodes": 3, "env": {"max_fix_sigma_m": 8}}
    assert claim_run_folder(out, settings) is False  # new: claimed, nothing to reuse
    assert json.loads((out / "settings.json").read_text()) == settings
    assert claim_run_folder(out, settings) is False  # same run, no flights yet
    (out / "episodes.npz").write_bytes(b"x")
    assert claim_run_folder(out, settings) is True  # same run: reuse its flights
    with pytest.raises(ValueError, match="belongs to a run with other settings"):
        claim_run_folder(out, {**settings, "episodes": 4})
    assert (out / "episodes.npz").read_bytes() == b"x"  # untouched
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match="holds files of no run"):
        claim_run_folder(other, settings)
    afile = tmp_path / "afile"
    afile.write_text("")
    with pytest.raises(ValueError, match="is a file"):
        claim_run_folder(afile, settings)
