"""The console script: help works without optional dependencies, the demo runs."""

from __future__ import annotations

import pytest

from coopnav_env.training.cli import build_parser, main
from coopnav_env.training.demo import run_demo


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "demo" in out


def test_every_subcommand_has_help(capsys):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in sub.choices:
        with pytest.raises(SystemExit) as exc:
            main([name, "--help"])
        assert exc.value.code == 0, name
    capsys.readouterr()


def test_demo_cooperative_beats_standalone():
    res = run_demo(n_epochs=30, seed=1, progress=False)
    import numpy as np

    both = np.isfinite(res.standalone_err_m) & np.isfinite(res.coop_err_m)
    assert both.sum() >= 25
    assert np.sqrt(np.mean(res.coop_err_m[both] ** 2)) < np.sqrt(
        np.mean(res.standalone_err_m[both] ** 2)
    )


def test_demo_is_deterministic_and_validates():
    a = run_demo(n_epochs=5, seed=3, progress=False)
    b = run_demo(n_epochs=5, seed=3, progress=False)
    import numpy as np

    assert np.array_equal(a.coop_err_m, b.coop_err_m, equal_nan=True)
    with pytest.raises(ValueError, match=r"n_epochs \(--epochs\) must be an integer >= 1"):
        run_demo(n_epochs=0)


def test_demo_bar_starts_after_the_first_epoch(monkeypatch, capsys):
    """The first epoch (numba compilation) runs before the bar, so its ETA is honest."""
    import numpy as np
    import tqdm

    import coopnav_env.training.demo as demo
    from coopnav_env.training.compile_notice import KERNEL_MODULES

    made = []

    class Bar:
        def __init__(self, iterable, **kw):
            made.append((list(iterable), kw))
            self.items = made[-1][0]

        def __iter__(self):
            return iter(self.items)

    monkeypatch.setattr(tqdm, "tqdm", Bar)
    a = run_demo(n_epochs=4, seed=2, progress=True)
    b = run_demo(n_epochs=4, seed=2, progress=False)
    assert made == [([1, 2, 3], {"desc": "demo epochs", "unit": "epoch", "initial": 1, "total": 4})]
    for field in ("standalone_err_m", "coop_err_m", "coop_sigma_m", "n_sats_canyon"):
        assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=True)
    assert set(demo.DEMO_KERNEL_MODULES) <= set(KERNEL_MODULES)
    capsys.readouterr()


@pytest.mark.parametrize("command", ["demo", "evaluate", "train"])
def test_every_option_shows_its_default(command, capsys):
    """Every option of demo/evaluate/train says its default in --help (issue 16)."""
    import argparse

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    options = [
        a
        for a in sub._actions
        if a.option_strings and not isinstance(a, argparse._HelpAction) and a.dest != "debug"
    ]
    assert len(options) >= 4
    for action in options:
        assert "(default: " in action.help or "; default: " in action.help, action.dest
        value = action.default
        if isinstance(value, list) and value:
            assert f"(default: {' '.join(value)})" in action.help, action.dest
        elif value not in (None, False, []):  # a real value: shown by argparse itself
            assert "%(default)s" in action.help, action.dest
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    shown = {
        "demo": ["(default: 60)", "(default: 60.0)", "(default: 0)"],
        "evaluate": ["(default: 20)", "(default: none, only the table is printed)"],
        "train": ["(default: runs/ppo)"],
    }[command]
    for want in shown:
        assert want in text, (want, text)
