"""``route_learning.py`` (formerly ``coopnav train-routes``) refuses damaged run folders with one
line and exit status 2, before flying anything."""

from __future__ import annotations

import json

import numpy as np
import pytest

from studies.route_choice import route_learning


def _collecting(folder, settings) -> None:
    folder.mkdir()
    (folder / "run.json").write_text(json.dumps({"settings": settings, "status": "collecting"}))


@pytest.fixture
def settings():
    """The settings ``--episodes 5`` records (the default seed's episodes)."""
    from studies.route_choice.routes import ROUTE_FEATURES

    return {
        "env": {},
        "base": "ceiling_column",
        "first_seed": 500_000,
        "episodes": 5,
        "max_turns": 3,
        "features": list(ROUTE_FEATURES),
    }


def test_damaged_run_folders_are_refused_with_one_line(tmp_path, capsys, settings) -> None:
    listed = tmp_path / "routes_list"
    listed.mkdir()
    (listed / "run.json").write_text("[1, 2]\n")
    _collecting(tmp_path / "routes_npz_bad", settings)
    (tmp_path / "routes_npz_bad" / "episodes.npz").write_bytes(b"PK\x03\x04 truncated")
    _collecting(tmp_path / "routes_npz_keys", settings)
    with open(tmp_path / "routes_npz_keys" / "episodes.npz", "wb") as fh:
        np.savez(fh, seed=np.arange(3))
    for name, message in (
        ("routes_list", "routes_list/run.json must hold a JSON object, got a list"),
        ("routes_npz_bad", "routes_npz_bad/episodes.npz does not load"),
        ("routes_npz_keys", "routes_npz_keys/episodes.npz lacks 'route', 'features'"),
    ):
        argv = ["--episodes", "5", "--jobs", "1", "--out", str(tmp_path / name)]
        assert route_learning.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("route_learning.py: error: ") and message in err, err
        assert err.count("\n") == 1  # one line, no traceback


def test_a_file_city_is_refused_before_collecting(tmp_path, capsys) -> None:
    """A city read from a file has one route: nothing to choose, said before any episode."""
    argv = ["--episodes", "5", "--jobs", "1", "--out", str(tmp_path / "routes")]
    argv += ["--env-set", "city=geojson:sample"]
    assert route_learning.main(argv) == 2
    err = capsys.readouterr().err
    assert "city=geojson:sample: a city read from a file has one route" in err, err
    assert not (tmp_path / "routes" / "episodes.npz").exists()


def test_the_script_has_help(capsys) -> None:
    with pytest.raises(SystemExit) as info:
        route_learning.main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "route_learning.py" in out and "--noise-replicates" in out
