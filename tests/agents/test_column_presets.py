"""The column heuristics as one policy with named settings: presets, the earlier names (which
warn), the classes of the earlier names, pickles, and the validation of options."""

from __future__ import annotations

import importlib.util
import pickle

import numpy as np
import pytest

from coopnav_env.agents import COLUMN_PRESET_NAMES, POLICY_NAMES, make_policy
from coopnav_env.agents import heuristics as h

HAS_ENV = importlib.util.find_spec("coopnav_env.urban_canyon_v0") is not None
pytestmark = pytest.mark.skipif(not HAS_ENV, reason="coopnav_env.urban_canyon_v0 not available")

SEED = 1_000_001


@pytest.fixture(scope="module")
def env():
    from coopnav_env import urban_canyon_v0

    e = urban_canyon_v0.parallel_env()
    yield e
    e.close()


def _first_actions(env, policy, steps: int = 3) -> list[dict[str, np.ndarray]]:
    obs, _ = env.reset(seed=SEED)
    policy.reset(seed=SEED)
    out = []
    for _ in range(steps):
        act = policy.act(obs)
        out.append(act)
        obs, *_ = env.step(act)
    return out


def _same(a: list[dict[str, np.ndarray]], b: list[dict[str, np.ndarray]]) -> bool:
    return len(a) == len(b) and all(
        x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)
        for x, y in zip(a, b, strict=True)
    )


def test_every_alias_names_a_preset_and_every_name_is_a_policy_name() -> None:
    assert set(h.COLUMN_ALIASES.values()) == set(h.COLUMN_PRESETS) - {"high_wide_column"}
    assert not set(h.COLUMN_ALIASES) & set(h.COLUMN_PRESETS)
    assert COLUMN_PRESET_NAMES == (*h.COLUMN_PRESETS, *h.COLUMN_ALIASES)
    assert set(COLUMN_PRESET_NAMES) <= set(POLICY_NAMES)
    for settings in h.COLUMN_PRESETS.values():
        assert set(settings) <= set(h.COLUMN_OPTIONS)


@pytest.mark.parametrize(("alias", "preset"), sorted(h.COLUMN_ALIASES.items()))
def test_an_earlier_name_warns_flies_as_its_preset_and_keeps_its_name(env, alias, preset) -> None:
    with pytest.warns(DeprecationWarning, match=rf"'{alias}' is deprecated.*use '{preset}'"):
        by_alias = make_policy(alias, env)
    with pytest.warns(DeprecationWarning, match=rf"'{alias}' is deprecated.*use '{preset}'"):
        assert make_policy(f"{alias}@spacing_m=9", env).spacing_m == 9.0
    by_preset = make_policy(preset, env)
    assert isinstance(by_alias, h.ColumnPolicy) and isinstance(by_preset, h.ColumnPolicy)
    assert (by_alias.name, by_preset.name) == (alias, preset)
    assert _same(_first_actions(env, by_alias), _first_actions(env, by_preset))


def test_presets_differ_in_what_they_say() -> None:
    p = h.COLUMN_PRESETS
    assert p["column"] == {}
    assert p["sky_column"]["hold_contact"] and p["sky_column"]["max_offset_m"] > 0
    assert p["stretched_column"]["spacing_m"] > p["sky_column"].get("spacing_m", 7.0)
    assert p["wide_column"]["spacing_m"] > p["stretched_column"]["spacing_m"]
    assert p["guarded_column"]["wall_margin_m"] > 0
    assert p["ceiling_column"]["ceiling_margin_m"] < 0
    assert p["best_sky_route"] == {**p["ceiling_column"], "route_choice": "pdop_gt3"}
    assert p["high_wide_column"] == {
        **p["wide_column"],
        "spacing_m": 60.0,
        "cruise_speed_mps": 10.0,
        "ceiling_margin_m": -10.0,
    }


def test_high_wide_column_is_the_wide_column_retuned(env) -> None:
    """60 m apart at 10 m/s, altitude target above the band: what its docstring says."""
    pol = make_policy("high_wide_column", env)
    n = len(env.possible_agents)
    assert (pol.spacing_m, pol.cruise_speed_mps, pol.ceiling_margin_m) == (60.0, 10.0, -10.0)
    assert pol.close_distance_m == 240.0 and pol.open_distance_m == (n - 1) * 54.0
    kin = env.unwrapped.config.kinematics
    assert pol._altitude_m() == kin.altitude_max_m + 10.0  # above the band: climbs to its top
    spec = make_policy("wide_column@spacing_m=60,cruise_speed_mps=10,ceiling_margin_m=-10", env)
    assert _same(_first_actions(env, pol, steps=8), _first_actions(env, spec, steps=8))


def test_best_sky_route_chooses_by_pdop_and_the_column_only_between_two_rules(env) -> None:
    assert make_policy("best_sky_route", env).route_choice == "pdop_gt3"
    assert make_policy("best_sky_route@route_choice='first'", env).route_choice == "first"
    assert make_policy("column@route_choice='pdop_gt3'", env).route_choice == "pdop_gt3"
    with pytest.raises(ValueError, match=r"route_choice must be one of \['first', 'pdop_gt3'\]"):
        make_policy("column@route_choice='swarm_mean'", env)
    with pytest.raises(ValueError, match=r"unknown option\(s\) 'route_index'"):
        make_policy("best_sky_route@route_index=1", env)


def test_wide_column_derived_settings_follow_the_given_ones(env) -> None:
    n = len(env.possible_agents)
    pol = make_policy("wide_column@spacing_m=20,goal_spacing_m=8", env)
    assert pol.close_distance_m == 80.0 and pol.open_distance_m == (n - 1) * 12.0
    assert make_policy("wide_column@open_distance_m=None", env).open_distance_m is None
    assert make_policy("wide@close_distance_m=33", env).close_distance_m == 33.0


def test_settings_combine_beyond_the_presets(env) -> None:
    """Any option on any preset: the plain column that seeks the sky and holds the top."""
    pol = make_policy("column@max_offset_m=3,ceiling_margin_m=-10,hold_contact=True", env)
    sky = make_policy("sky_column@ceiling_margin_m=-10,max_offset_m=3", env)
    assert _same(_first_actions(env, pol), _first_actions(env, sky))
    assert not _same(_first_actions(env, pol), _first_actions(env, make_policy("column", env)))


@pytest.mark.parametrize(
    ("old", "alias"),
    [
        ("FormationPolicy", "formation"),
        ("SkySeekingPolicy", "sky"),
        ("SpreadColumnPolicy", "spread"),
        ("WideColumnPolicy", "wide"),
        ("GuardedColumnPolicy", "guarded"),
        ("CeilingColumnPolicy", "ceiling"),
        ("SkyRoutePolicy", "skyroute"),
    ],
)
def test_the_earlier_classes_warn_and_make_the_same_column(env, old, alias) -> None:
    cls = getattr(h, old)
    with pytest.warns(DeprecationWarning, match=old):
        pol = cls(env, cruise_speed_mps=5.0)
    assert isinstance(pol, h.ColumnPolicy) and pol.name == alias
    want = make_policy(f"{h.COLUMN_ALIASES[alias]}@cruise_speed_mps=5.0", env)
    assert _same(_first_actions(env, pol), _first_actions(env, want))
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="unknown option"):
        cls(env, bogus=1)


def test_a_pickled_column_flies_on_identically(env) -> None:
    pol = make_policy("guarded_column", env)
    obs, _ = env.reset(seed=SEED)
    pol.reset(seed=SEED)
    for _ in range(3):
        obs, *_ = env.step(pol.act(obs))
    copy = pickle.loads(pickle.dumps(pol))
    assert copy.name == "guarded_column"
    a, b = pol.act(obs), copy.act(obs)
    assert all(np.array_equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize(
    ("old", "alias"), [("FormationPolicy", "formation"), ("WideColumnPolicy", "wide")]
)
def test_a_column_pickled_before_the_presets_loads(env, old, alias) -> None:
    """A pickle of an earlier class lacks the settings the sky seeker did not have (the plain
    column) or ``hold_contact``: restored, it flies as before."""
    with pytest.warns(DeprecationWarning):
        pol = getattr(h, old)(env)
    state = dict(pol.__dict__)
    for key in ("hold_contact", "smoothing", "_offset") + (
        ("max_offset_m", "ceiling_margin_m") if alias == "formation" else ()
    ):
        state.pop(key)
    restored = object.__new__(getattr(h, old))
    restored.__setstate__(state)
    assert restored.name == alias
    want = make_policy(h.COLUMN_ALIASES[alias], env)
    assert _same(_first_actions(env, restored), _first_actions(env, want))


@pytest.mark.parametrize(
    ("name", "match"),
    [
        ("waypoint@altitude_m=1e6", r"altitude_m must be in \[5, 30\] m.*1000000\.0"),
        ("waypoint@altitude_m=2", r"altitude_m must be in \[5, 30\].*got 2"),
        ("waypoint@cruise_speed_mps=0", r"cruise_speed_mps must be > 0 m/s, got 0"),
        ("waypoint@gain_per_s=-1", r"gain_per_s must be > 0.*got -1"),
        ("waypoint@altitude=28", r"unknown option\(s\) 'altitude'.*altitude_m, gain_per_s"),
        ("column@spacing_m=0", r"spacing_m must be > 0 m, got 0"),
        ("wide_column@spacing_m=-45", r"spacing_m must be > 0 m, got -45"),
        ("stretched_column@goal_spacing_m=0", r"goal_spacing_m must be > 0 m, got 0"),
        ("sky_column@cruise_speed_mps=-3", r"cruise_speed_mps must be > 0 m/s, got -3"),
        ("column@turn_speed_mps=0", r"turn_speed_mps must be > 0"),
        ("column@brake_mps2=0", r"brake_mps2 must be > 0"),
        ("column@max_lag_m=0", r"max_lag_m must be > 0"),
        ("column@close_distance_m=nan", r"close_distance_m must be > 0"),
        ("column@spacing_m='wide'", r"spacing_m must be > 0 m, got 'wide'"),
        ("sky_column@max_offset_m=-1", r"max_offset_m must be in \[0, 50\] m, got -1"),
        ("sky_column@smoothing=1", r"smoothing must be in \[0, 1\), got 1"),
        (
            "ceiling_column@ceiling_margin_m=60",
            r"ceiling_margin_m must be in \[-50, 50\] m, got 60",
        ),
        ("column@route_max_turns=9", r"route_max_turns must be in \[0, 8\], got 9"),
        ("column@hold_contact=1", r"hold_contact must be True or False, got 1"),
        ("column@spacing=7", r"unknown option\(s\) 'spacing' of policy 'column'.*spacing_m"),
        ("wide_column@bogus=1,other=2", r"unknown option\(s\) 'bogus', 'other'"),
    ],
)
def test_bad_options_are_refused_naming_the_value(env, name, match) -> None:
    with pytest.raises(ValueError, match=match):
        make_policy(name, env)


def test_good_options_are_taken(env) -> None:
    pol = make_policy("waypoint@altitude_m=30,cruise_speed_mps=100", env)
    assert pol.altitude_m == 30.0
    assert pol.cruise_speed_mps == env.unwrapped.config.kinematics.max_speed_mps
    assert make_policy("column@goal_spacing_m=None", env).goal_spacing_m == 7.0


def test_an_unknown_preset_is_refused(env) -> None:
    with pytest.raises(ValueError, match=r"unknown column preset 'zigzag'.*best_sky_route"):
        h.column_policy("zigzag", env)
