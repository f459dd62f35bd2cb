"""Route choice: which of the equally short street routes to fly, from the map and the sky.

The study's own policies, built on :class:`coopnav_env.agents.heuristics.ColumnPolicy`;
importing this module registers them (:func:`coopnav_env.agents.register_policy`):

=============================================  ==============================================
name                                           policy
=============================================  ==============================================
``route_column@preset='ceiling_column',...``   a column heuristic (``preset``, a
                                               :data:`~coopnav_env.agents.heuristics.COLUMN_PRESETS`
                                               name) with the route options of
                                               :class:`RouteChoiceColumn` (``route_index``,
                                               ``route_choice`` by any feature,
                                               ``route_split``, ``route_split_index``)
``learned_route@model='PATH'``                 the column that flies the route a learned
                                               route model predicts best (``pretrained``,
                                               ``pretrained/s<k>``: the study's models)
``learned_split@model='PATH'``                 the column split over two streets where a
                                               learned split model predicts it best
=============================================  ==============================================

On the Manhattan street grid of ``urban_canyon_v0`` many routes from the start to the goal
share the shortest length (:func:`coopnav_env.sim.route.street_routes`). The column
heuristics fly the first of them (:func:`~coopnav_env.sim.route.street_route`) unless told
otherwise; the routes differ in the buildings along them, and so in the satellites a receiver
keeps, and so in the swarm's navigation error (``studies/route_choice`` measures by how
much).

Everything here is *on board*: the city map (the same 3-D model the receiver's
mapping-aided NLOS exclusion uses), the satellites' directions at the time of planning (from
the broadcast ephemerides any receiver has) and the swarm's estimated centre. Nothing reads
the UAVs' true positions or errors.

* :func:`route_features` describes a route by the satellites predicted in line of sight along
  it (:data:`ROUTE_FEATURES`).
* A *hand-written* choice takes the route with the best value of one feature
  (:data:`FEATURE_SENSE`), e.g. ``route_column@preset='ceiling_column',route_choice='los_mean'``.
* A *learned* choice (:class:`RouteModel`) predicts each route's error from all features
  with a model fitted to flown episodes and takes the lowest.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.agents import make_policy, register_policy
from coopnav_env.agents.heuristics import (
    COLUMN_ALIASES,
    COLUMN_OPTIONS,
    COLUMN_PRESETS,
    ColumnPolicy,
    street_route,
)
from coopnav_env.nav import pdop
from coopnav_env.sim.route import Polyline, street_routes

__all__ = [
    "FEATURE_SENSE",
    "MODEL_KINDS",
    "PRETRAINED_MODEL_DIRS",
    "ROUTE_FEATURES",
    "SPLIT_FEATURES",
    "SPLIT_FEATURE_SENSE",
    "RouteChoiceColumn",
    "RouteModel",
    "fit_route_model",
    "learned_route",
    "learned_split",
    "resolve_route_model",
    "route_column",
    "route_column_name",
    "route_features",
    "split_features",
]

_STUDIES = Path(__file__).resolve().parents[1]

PRETRAINED_MODEL_DIRS: dict[str, Path] = {
    "route": _STUDIES / "route_choice" / "policies",
    "split": _STUDIES / "split_choice" / "policies",
}
"""Where the studies' fitted models live: ``route_s<k>`` (this study) and ``split_s<k>``
(``studies/split_choice``) folders."""


def resolve_route_model(text: str, kind: str = "route") -> Path:
    """The file behind a ``learned_route@model=<text>`` (``learned_split@model=<text>``)
    policy: ``pretrained`` is the study's model of training seed 0 (``route_s0``,
    ``split_s0`` of :data:`PRETRAINED_MODEL_DIRS`), ``pretrained/s<k>`` that of seed ``k``;
    anything else a path (a ``route_model.json`` or ``split_model.json`` file, or a folder
    holding one)."""
    if kind not in ("route", "split"):
        raise ValueError(f"kind must be 'route' or 'split', got {kind!r}")
    if text == "pretrained" or text.startswith("pretrained/"):
        tail = text[len("pretrained") :].lstrip("/") or "s0"
        if not (tail.startswith("s") and tail[1:].isdigit()):
            raise ValueError(f"model 'pretrained' takes a seed as pretrained/s<k>, got {text!r}")
        return PRETRAINED_MODEL_DIRS[kind] / f"{kind}_{tail}"
    return Path(text)


#: Features of a route (:func:`route_features`), in this order. ``los``: satellites predicted
#: in line of sight at points every ``step_m`` along the route at the flight altitude;
#: ``swarm``: distinct satellites over a column of ``n_uavs`` points ``spacing_m`` apart
#: ending at that point (what the swarm's cooperative fix pools); ``pdop``: the position
#: dilution of precision of the line-of-sight satellites at the point (one receiver clock per
#: constellation; 30 where fewer satellites than unknowns).
ROUTE_FEATURES: tuple[str, ...] = (
    "los_mean",
    "los_min",
    "los_lt5",
    "los_lt6",
    "los_lt7",
    "los_lt8",
    "swarm_mean",
    "swarm_lt8",
    "swarm_lt10",
    "swarm_lt12",
    "pdop_mean",
    "pdop_gt3",
    "pdop_gt6",
    "turns",
)

#: +1 where a larger value of the feature means a better sky (counts), -1 where a smaller one
#: does (shares of points below a count, dilution of precision, turns): the hand-written
#: choice by one feature takes the route with the largest ``sense * value``.
FEATURE_SENSE: dict[str, int] = {
    name: (1 if name in ("los_mean", "los_min", "swarm_mean") else -1) for name in ROUTE_FEATURES
}

PDOP_CAP = 30.0
"""PDOP reported where the line-of-sight satellites cannot fix a position."""


def _pdop(unit_enu: np.ndarray, system: np.ndarray, los: np.ndarray) -> np.ndarray:
    """PDOP (:func:`coopnav_env.nav.pdop`) of the line-of-sight satellites at every point,
    ``(P,)``, capped at PDOP_CAP."""
    return np.array([min(pdop(unit_enu[use], system[use]), PDOP_CAP) for use in los])


def _band_altitude(world: Any, altitude_m: float) -> float:
    kin = world.config.kinematics
    return float(np.clip(altitude_m, float(kin.altitude_min_m), float(kin.altitude_max_m)))


def _as_route(route_xy_m: np.ndarray) -> np.ndarray:
    route = np.asarray(route_xy_m, dtype=float).reshape(-1, 2)
    if route.shape[0] < 2:
        route = np.vstack([route, route + np.array([0.0, 1e-3])])
    return route


def _column_points(
    route: np.ndarray, n: int, spacing_m: float, step_m: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """Arc lengths ``s`` every ``step_m`` along ``route``, and the points ``xy`` at them
    preceded by the points behind the start that a column of ``n`` UAVs ``spacing_m`` apart
    trails over (the route extended backwards on the same step, so that the points on the
    route are exactly those of ``s``); ``first`` is the index of ``s = 0`` in ``xy``."""
    path = Polyline(route)
    s = np.arange(0.0, path.length + 1e-9, step_m)
    tail = (n - 1) * spacing_m
    d0 = route[1] - route[0]
    d0 = d0 / max(float(np.hypot(*d0)), 1e-12)
    back = -np.arange(step_m, tail + step_m - 1e-9, step_m)[::-1] if tail > 0.0 else []
    s_all = np.concatenate([back, s])
    xy = np.where(
        (s_all < 0.0)[:, None], route[0] + d0 * s_all[:, None], path.point(np.maximum(s_all, 0.0))
    )
    return s, xy, len(s_all) - len(s)


def _sky_units(world: Any) -> tuple[np.ndarray, np.ndarray]:
    """Unit line-of-sight vectors (East, North, Up) of the world's satellites at its current
    time, and their constellation indices."""
    sky = world._sky(world.t_s)
    az, el = np.radians(sky.az), np.radians(sky.el)
    unit = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)
    return unit, np.asarray(sky.system)


def route_features(
    world: Any,
    route_xy_m: np.ndarray,
    altitude_m: float,
    *,
    spacing_m: float = 45.0,
    n_uavs: int | None = None,
    step_m: float = 5.0,
) -> np.ndarray:
    """The :data:`ROUTE_FEATURES` of one route, ``(len(ROUTE_FEATURES),)``.

    Parameters
    ----------
    world : coopnav_env.sim.scenario.UrbanWorld
        The world at planning time: its city map, its satellites at ``world.t_s`` and its
        flight band. Only on-board knowledge is read (no true position).
    route_xy_m : ndarray, shape (k, 2)
        The route's waypoints, East/North [m].
    altitude_m : float
        Flight altitude the satellites are predicted at [m] (clamped to the flight band).
    spacing_m : float, default 45.0
        Spacing of the column the ``swarm`` features pool over [m], > 0.
    n_uavs : int, optional
        UAVs of that column; default the world's.
    step_m : float, default 5.0
        Distance between the points sampled along the route [m], > 0.
    """
    if not (math.isfinite(step_m) and step_m > 0.0):
        raise ValueError(f"step_m must be finite and > 0 [m], got {step_m!r}")
    if not (math.isfinite(spacing_m) and spacing_m > 0.0):
        raise ValueError(f"spacing_m must be finite and > 0 [m], got {spacing_m!r}")
    z = _band_altitude(world, altitude_m)
    n = int(world.config.n_uavs if n_uavs is None else n_uavs)
    route = _as_route(route_xy_m)
    s, xy, first = _column_points(route, n, spacing_m, step_m)
    pts = np.column_stack([xy, np.full(len(xy), z)])
    los = world.map_line_of_sight(pts)
    on = np.arange(len(xy)) >= first
    counts = los[on].sum(axis=1).astype(float)
    lag = max(round(spacing_m / step_m), 1)
    swarm = np.empty(len(s))
    for i in range(len(s)):
        j = first + i
        idx = [j - k * lag for k in range(n) if j - k * lag >= 0]
        swarm[i] = los[idx].any(axis=0).sum()
    unit, system = _sky_units(world)
    dop = _pdop(unit, system, los[on])
    turns = max(route.shape[0] - 2, 0)
    return np.array(
        [
            counts.mean(),
            counts.min(),
            (counts < 5).mean(),
            (counts < 6).mean(),
            (counts < 7).mean(),
            (counts < 8).mean(),
            swarm.mean(),
            (swarm < 8).mean(),
            (swarm < 10).mean(),
            (swarm < 12).mean(),
            dop.mean(),
            (dop > 3.0).mean(),
            (dop > 6.0).mean(),
            float(turns),
        ]
    )


#: Features of a *split* swarm (:func:`split_features`): its column's slots alternate
#: between two equally short routes (the leader on the first), or all fly one route.
#: ``swarm``: distinct satellites predicted in line of sight over the column's slots (what
#: the cooperative fix pools), with its minimum and the shares of points below 8, 10 and 12;
#: ``spdop``: the PDOP of those pooled satellites (mean, shares above 2 and 3); ``los_mean``
#: and ``pdop_gt3``: as :data:`ROUTE_FEATURES`, averaged over the routes; ``sep``: the
#: distance between the two routes at the same arc length [m] (mean, max; 0 unsplit);
#: ``turns``: the most turns of a route; ``split``: 1 for two routes, 0 for one.
SPLIT_FEATURES: tuple[str, ...] = (
    "swarm_mean",
    "swarm_min",
    "swarm_lt8",
    "swarm_lt10",
    "swarm_lt12",
    "spdop_mean",
    "spdop_gt2",
    "spdop_gt3",
    "los_mean",
    "pdop_gt3",
    "sep_mean",
    "sep_max",
    "turns",
    "split",
)

#: As :data:`FEATURE_SENSE`, for :data:`SPLIT_FEATURES` (``sep`` and ``split`` count as
#: "larger is better": a rule on them spreads the swarm as far as it can).
SPLIT_FEATURE_SENSE: dict[str, int] = {
    name: (
        1 if name in ("swarm_mean", "swarm_min", "los_mean", "sep_mean", "sep_max", "split") else -1
    )
    for name in SPLIT_FEATURES
}

#: The kinds of :class:`RouteModel` and the feature table each reads.
MODEL_KINDS: dict[str, tuple[str, ...]] = {"route": ROUTE_FEATURES, "split": SPLIT_FEATURES}


def split_features(
    world: Any,
    routes: Sequence[np.ndarray],
    altitude_m: float,
    *,
    spacing_m: float = 45.0,
    n_uavs: int | None = None,
    step_m: float = 5.0,
) -> np.ndarray:
    """The :data:`SPLIT_FEATURES` of a column flown on one route or split over two.

    Slot ``k`` of the column (``k = 0`` leads) flies ``routes[k % len(routes)]`` at the
    same arc length as it would on one route, as the column heuristics fly a split
    (``route_split``); the routes must be equally short (within one ``step_m``). Parameters
    as :func:`route_features`; ``routes`` holds one or two routes.
    """
    if not (math.isfinite(step_m) and step_m > 0.0):
        raise ValueError(f"step_m must be finite and > 0 [m], got {step_m!r}")
    if not (math.isfinite(spacing_m) and spacing_m > 0.0):
        raise ValueError(f"spacing_m must be finite and > 0 [m], got {spacing_m!r}")
    if len(routes) not in (1, 2):
        raise ValueError(f"split_features takes one or two routes, got {len(routes)}")
    z = _band_altitude(world, altitude_m)
    n = int(world.config.n_uavs if n_uavs is None else n_uavs)
    sampled = [_column_points(_as_route(r), n, spacing_m, step_m) for r in routes]
    lengths = [len(p[0]) for p in sampled]
    if max(lengths) - min(lengths) > 1:
        raise ValueError(
            f"split_features needs equally short routes, got {len(routes)} routes of "
            f"{[float(p[0][-1]) for p in sampled]} m"
        )
    m = min(lengths)
    first = sampled[0][2]
    los = [
        world.map_line_of_sight(np.column_stack([xy, np.full(len(xy), z)])) for _, xy, _ in sampled
    ]
    lag = max(round(spacing_m / step_m), 1)
    n_routes = len(routes)
    pooled = np.zeros((m, los[0].shape[1]), dtype=bool)
    for k in range(n):
        j = first + np.arange(m) - k * lag
        ok = j >= 0
        pooled[ok] |= los[k % n_routes][j[ok]]
    swarm = pooled.sum(axis=1).astype(float)
    unit, system = _sky_units(world)
    sdop = _pdop(unit, system, pooled)
    on = [lo[first : first + m] for lo in los]
    counts = np.mean([o.sum(axis=1) for o in on], axis=0)
    dop_gt3 = float(np.mean([(_pdop(unit, system, o) > 3.0).mean() for o in on]))
    if n_routes == 2:
        sep = np.linalg.norm(
            sampled[0][1][first : first + m] - sampled[1][1][first : first + m], axis=1
        )
    else:
        sep = np.zeros(m)
    turns = max(max(_as_route(r).shape[0] - 2, 0) for r in routes)
    return np.array(
        [
            swarm.mean(),
            swarm.min(),
            (swarm < 8).mean(),
            (swarm < 10).mean(),
            (swarm < 12).mean(),
            sdop.mean(),
            (sdop > 2.0).mean(),
            (sdop > 3.0).mean(),
            counts.mean(),
            dop_gt3,
            sep.mean(),
            sep.max(),
            float(turns),
            float(n_routes - 1),
        ]
    )


@dataclass
class RouteModel:
    """A learned route scorer: predicts a route's mean navigation error from its features.

    Linear in the standardised :data:`ROUTE_FEATURES`, fitted by ridge regression on the
    error each route was flown at, relative to the mean over its episode's routes
    (:func:`fit_route_model`); only the differences between the routes of one episode matter,
    so there is no intercept. The route with the lowest prediction is flown.

    Attributes
    ----------
    features : list of str
        Feature names, a subset of :data:`ROUTE_FEATURES` in its order.
    mean, scale : list of float
        Standardisation of each feature.
    weights : list of float
        Ridge weights on the standardised features [m of error per standard deviation].
    alpha : float
        The ridge penalty chosen by cross-validation.
    base : str
        The column heuristic (a :data:`~coopnav_env.agents.heuristics.COLUMN_PRESETS` name,
        or an earlier name of one) that flies the chosen route, and that flew the training
        episodes.
    info : dict
        What the model was fitted on (environment settings, seeds, sizes, CV scores).
    kind : str
        ``"route"``: scores routes by their :data:`ROUTE_FEATURES` (the ``route_model``
        option of :class:`RouteChoiceColumn`); ``"split"``: scores flying one column against
        splitting it onto each other candidate route, by their :data:`SPLIT_FEATURES` (the
        ``route_split_model`` option; the first row of what it scores is the unsplit column).
    """

    features: list[str]
    mean: list[float]
    scale: list[float]
    weights: list[float]
    alpha: float
    base: str
    info: dict[str, Any] = field(default_factory=dict)
    kind: str = "route"

    def __post_init__(self) -> None:
        if self.kind not in MODEL_KINDS:
            raise ValueError(f"model kind must be one of {list(MODEL_KINDS)}, got {self.kind!r}")
        table = self.table
        for name in ("features", "mean", "scale", "weights"):
            value = getattr(self, name)
            if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
                raise ValueError(f"RouteModel {name} must be a list, got {value!r}")
        unknown = [f for f in self.features if f not in table]
        if unknown:
            raise ValueError(f"unknown {self.kind} features {unknown}; known: {list(table)}")
        k = len(self.features)
        if not (len(self.mean) == len(self.scale) == len(self.weights) == k):
            raise ValueError("RouteModel needs one mean, scale and weight per feature")
        # a NaN weight or a zero scale would make every prediction NaN or inf, and the
        # choice among them arbitrary: refused here, where the model is made or loaded
        for name in ("mean", "weights", "scale"):
            value = getattr(self, name)
            ok = all(_is_real(v) and math.isfinite(v) for v in value)
            if name == "scale":
                if not ok or not all(v > 0 for v in value):
                    raise ValueError(f"RouteModel scale must be finite numbers > 0, got {value}")
            elif not ok:
                raise ValueError(f"RouteModel {name} must be finite numbers, got {value}")
        if not _is_real(self.alpha) or not math.isfinite(self.alpha) or self.alpha < 0:
            raise ValueError(f"RouteModel alpha must be a finite number >= 0, got {self.alpha!r}")
        if not isinstance(self.base, str) or not self.base:
            raise ValueError(f"RouteModel base must be a policy name, got {self.base!r}")
        if not isinstance(self.info, dict):
            raise ValueError(f"RouteModel info must be a mapping, got {self.info!r}")
        self._cols = np.array([table.index(f) for f in self.features], dtype=int)

    @property
    def table(self) -> tuple[str, ...]:
        """The feature table the model reads: :data:`ROUTE_FEATURES` or :data:`SPLIT_FEATURES`."""
        return MODEL_KINDS[self.kind]

    def predict(self, feats: np.ndarray) -> np.ndarray:
        """Predicted relative error [m] of the options (routes, or no split and the splits)
        with features ``feats`` ``(R, F)`` of the model's table."""
        x = np.asarray(feats, dtype=float).reshape(-1, len(self.table))[:, self._cols]
        z = (x - np.asarray(self.mean)) / np.asarray(self.scale)
        return z @ np.asarray(self.weights)

    def to_json(self) -> dict[str, Any]:
        out = {
            "format": "coopnav-route-model/1",
            "features": list(self.features),
            "mean": [float(v) for v in self.mean],
            "scale": [float(v) for v in self.scale],
            "weights": [float(v) for v in self.weights],
            "alpha": float(self.alpha),
            "base": self.base,
            "info": self.info,
        }
        if self.kind != "route":  # (route models are written as before)
            out["kind"] = self.kind
        return out

    def save(self, path: str | Path) -> Path:
        """Write the model as JSON (temporary name, then renamed into place)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(self.to_json(), indent=1) + "\n")
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path, kind: str | None = None) -> RouteModel:
        """Read a model written by :meth:`save` (a ``.json`` file, or a folder holding
        ``route_model.json`` or ``split_model.json``).

        With ``kind`` (``"route"`` or ``"split"``), a model of the other kind is refused (a
        folder is searched for that kind's file first). Every refusal is a ``ValueError``
        naming the file: not JSON, not a model, a field missing or of the wrong type, a
        NaN or infinite number, a scale <= 0 (:class:`RouteModel` checks the fields).
        """
        if kind is not None and kind not in MODEL_KINDS:
            raise ValueError(f"kind must be one of {list(MODEL_KINDS)}, got {kind!r}")
        p = Path(path)
        if p.is_dir():
            names = [f"{k}_model.json" for k in ((kind,) if kind else ())]
            names += ["split_model.json", "route_model.json"]
            p = next((p / n for n in names if (p / n).is_file()), p / names[-1])
        if not p.is_file():
            raise FileNotFoundError(f"no route model at {str(path)!r} (looked for {p})")
        try:
            d = json.loads(p.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{p} is not a coopnav route model: not valid JSON ({exc})") from None
        if not isinstance(d, dict) or d.get("format") != "coopnav-route-model/1":
            fmt = d.get("format") if isinstance(d, dict) else type(d).__name__
            raise ValueError(f"{p} is not a coopnav route model (format {fmt!r})")
        missing = [
            k for k in ("features", "mean", "scale", "weights", "alpha", "base") if k not in d
        ]
        if missing:
            raise ValueError(f"{p} is not a complete route model: it lacks {missing}")
        found = d.get("kind", "route")
        if kind is not None and found != kind:
            raise ValueError(
                f"{p} holds a {found} model, not a {kind} model: learned_{kind} takes a "
                f"{kind}_model.json; give it as learned_{found}@model='{path}'"
            )
        try:
            return cls(
                features=d["features"],
                mean=d["mean"],
                scale=d["scale"],
                weights=d["weights"],
                alpha=d["alpha"],
                base=d["base"],
                info=d.get("info", {}),
                kind=found,
            )
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{p}: {exc}") from None


def _is_real(v: Any) -> bool:
    """A real number (int or float, numpy's too), not a bool or a string."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _centred(x: np.ndarray, y: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xc, yc = x.copy(), y.copy()
    for g in np.unique(groups):
        m = groups == g
        xc[m] -= x[m].mean(axis=0)
        yc[m] -= y[m].mean()
    return xc, yc


def fit_route_model(
    feats: Sequence[np.ndarray],
    errors: Sequence[np.ndarray],
    base: str,
    *,
    features: Sequence[str] | None = None,
    alphas: Sequence[float] = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6),
    folds: int = 5,
    info: dict[str, Any] | None = None,
    kind: str = "route",
) -> RouteModel:
    """Fit a :class:`RouteModel` to flown episodes.

    Parameters
    ----------
    feats : sequence of ndarray, each (R_e, len(table))
        Per training episode, the features of its options: its routes (``kind="route"``,
        :data:`ROUTE_FEATURES`), or the unsplit column and each split (``kind="split"``,
        :data:`SPLIT_FEATURES`).
    errors : sequence of ndarray, each (R_e,)
        The mean navigation error each option was flown at [m] (the same episode seed).
    base : str
        The heuristic that flew them.
    features : sequence of str, optional
        The features to use; default: all of the kind's table.
    kind : str
        ``"route"`` or ``"split"`` (see :class:`RouteModel`).
    alphas : sequence of float
        Ridge penalties to choose from, by ``folds``-fold cross-validation over episodes of
        the error of the route each would choose.
    folds : int
        Cross-validation folds, >= 2.

    Episodes with a single route carry no information about the choice and are skipped.
    """
    if len(feats) != len(errors):
        raise ValueError(f"feats and errors differ in length: {len(feats)} and {len(errors)}")
    if folds < 2:
        raise ValueError(f"folds must be >= 2, got {folds}")
    if kind not in MODEL_KINDS:
        raise ValueError(f"model kind must be one of {list(MODEL_KINDS)}, got {kind!r}")
    table = MODEL_KINDS[kind]
    features = list(table if features is None else features)
    unknown = [f for f in features if f not in table]
    if unknown:
        raise ValueError(f"unknown {kind} features {unknown}; known: {list(table)}")
    cols = np.array([table.index(f) for f in features], dtype=int)
    keep = [i for i in range(len(feats)) if len(errors[i]) > 1]
    if len(keep) < folds:
        raise ValueError(
            f"fit_route_model needs at least {folds} episodes with more than one route, got "
            f"{len(keep)}"
        )
    x = np.concatenate([np.asarray(feats[i], dtype=float)[:, cols] for i in keep])
    y = np.concatenate([np.asarray(errors[i], dtype=float) for i in keep])
    g = np.concatenate([np.full(len(errors[i]), k) for k, i in enumerate(keep)])
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("route features and errors must be finite")
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale[scale < 1e-12] = 1.0
    z = (x - mean) / scale
    zc, yc = _centred(z, y, g)
    fold_of = np.arange(len(keep)) % folds

    def ridge(a: float, m: np.ndarray) -> np.ndarray:
        return np.linalg.solve(zc[m].T @ zc[m] + a * np.eye(zc.shape[1]), zc[m].T @ yc[m])

    cv: dict[str, float] = {}
    for a in alphas:
        chosen = []
        for f in range(folds):
            test = fold_of[g] == f
            w = ridge(float(a), ~test)
            for e in np.unique(g[test]):
                m = g == e
                chosen.append(y[m][int(np.argmin(z[m] @ w))] - y[m].mean())
        cv[str(a)] = float(np.mean(chosen))
    best = min(alphas, key=lambda a: cv[str(a)])
    w = ridge(float(best), np.ones(len(y), dtype=bool))
    meta = dict(info or {})
    meta.update({"episodes": len(keep), "routes": len(y), "cv_chosen_minus_mean_m": cv})
    return RouteModel(
        features=list(features),
        mean=mean.tolist(),
        scale=scale.tolist(),
        weights=w.tolist(),
        alpha=float(best),
        base=base,
        info=meta,
        kind=kind,
    )


def _model_kind(model: Any) -> str:
    """How a refused ``route_model`` / ``route_split_model`` value is named in the error."""
    kind = getattr(model, "kind", None)
    if hasattr(model, "predict") and isinstance(kind, str):
        hint = {"split": " (pass it as route_split_model)", "route": " (pass it as route_model)"}
        return f"a {type(model).__name__} of kind {kind!r}{hint.get(kind, '')}"
    return repr(model)


class RouteChoiceColumn(ColumnPolicy):
    """A :class:`~coopnav_env.agents.heuristics.ColumnPolicy` with this study's route options.

    Every option of the column (``column_options``) is taken as it is; these choose among the
    equally short street routes (:func:`coopnav_env.sim.route.street_routes`, planned at the
    first step from the estimated centre of the swarm) and split the column over two of
    them.

    Parameters
    ----------
    route_index : int, default 0
        Fly the candidate route of this index (modulo their number) instead; 0 is
        :func:`~coopnav_env.sim.route.street_route`'s. For flying every route of an episode.
    route_choice : str, default "first"
        ``"first"``, or a feature name of :data:`ROUTE_FEATURES`: the route with the best
        value of that feature (:data:`FEATURE_SENSE`).
    route_model : RouteModel or str, optional
        A learned route model (or the path of one, or ``pretrained``): fly the route it
        predicts the lowest error for. ``route_choice``, ``route_index`` and ``route_model``
        exclude each other.
    route_split : str, default "none"
        Split the column over two equally short routes: a feature name of
        :data:`ROUTE_FEATURES` flies the slots 0, 2, 4, ... (the leader's) on the chosen route
        and the slots 1, 3, ... on the best *other* candidate by that feature, at the same arc
        length, so that the two sub-columns fly abreast through different streets
        (:func:`split_features` predicts what they pool). An episode with one candidate flies
        one column. ``"none"``: no split.
    route_split_index : int, default 0
        Split onto this candidate (counted among the candidates other than the chosen route,
        from 1, modulo their number) instead; 0: no split. Excludes ``route_split``.
    route_split_model : RouteModel or str, optional
        A learned split model (kind ``"split"``, or a path; ``pretrained`` and
        ``pretrained/s<k>`` are the study's): the column splits onto the other candidate route
        the model predicts lowest, or flies unsplit where it predicts that lowest
        (:meth:`split_table` gives what it scores). Excludes ``route_split`` and
        ``route_split_index``.
    **column_options
        Options of :class:`~coopnav_env.agents.heuristics.ColumnPolicy` (its own
        ``route_choice`` is replaced by this one).
    """

    def __init__(
        self,
        env: Any,
        route_index: int = 0,
        route_choice: str = "first",
        route_model: Any = None,
        route_split: str = "none",
        route_split_index: int = 0,
        route_split_model: Any = None,
        **column_options: Any,
    ) -> None:
        super().__init__(env, **column_options)
        if isinstance(route_index, bool) or not isinstance(route_index, (int, np.integer)):
            raise ValueError(f"route_index must be an int >= 0, got {route_index!r}")
        if route_index < 0:
            raise ValueError(f"route_index must be >= 0, got {route_index}")
        self.route_index = int(route_index)
        if route_choice != "first" and route_choice not in ROUTE_FEATURES:
            raise ValueError(
                f"route_choice must be 'first' or a route feature {list(ROUTE_FEATURES)}, got "
                f"{route_choice!r}"
            )
        if sum([route_choice != "first", bool(route_index), route_model is not None]) > 1:
            raise ValueError(
                "route_choice, route_index and route_model exclude each other, got "
                f"route_choice={route_choice!r}, route_index={route_index}, "
                f"route_model={route_model!r}"
            )
        self.route_choice = route_choice
        if route_split != "none" and route_split not in ROUTE_FEATURES:
            raise ValueError(
                f"route_split must be 'none' or a route feature {list(ROUTE_FEATURES)}, got "
                f"{route_split!r}"
            )
        if isinstance(route_split_index, bool) or not isinstance(
            route_split_index, (int, np.integer)
        ):
            raise ValueError(f"route_split_index must be an int >= 0, got {route_split_index!r}")
        if route_split_index < 0:
            raise ValueError(f"route_split_index must be >= 0, got {route_split_index}")
        if route_split != "none" and route_split_index:
            raise ValueError(
                "route_split and route_split_index exclude each other, got "
                f"route_split={route_split!r}, route_split_index={route_split_index}"
            )
        self.route_split = route_split
        self.route_split_index = int(route_split_index)
        if isinstance(route_split_model, (str, Path)):
            route_split_model = RouteModel.load(
                resolve_route_model(str(route_split_model), kind="split"), kind="split"
            )
        if route_split_model is not None and (
            not hasattr(route_split_model, "predict")
            or getattr(route_split_model, "kind", None) != "split"
        ):
            got = _model_kind(route_split_model)
            raise ValueError(
                f"route_split_model must be a split model (RouteModel of kind 'split') or a "
                f"path to one, got {got}"
            )
        if route_split_model is not None and (route_split != "none" or route_split_index):
            raise ValueError(
                "route_split_model excludes route_split and route_split_index, got "
                f"route_split={route_split!r}, route_split_index={route_split_index}"
            )
        self.route_split_model = route_split_model
        self.split_feature_table: np.ndarray | None = None  # no split, then each split
        if isinstance(route_model, (str, Path)):
            route_model = RouteModel.load(resolve_route_model(str(route_model)), kind="route")
        if route_model is not None and (
            not hasattr(route_model, "predict") or getattr(route_model, "kind", "route") != "route"
        ):
            raise ValueError(
                "route_model must be a route model (RouteModel of kind 'route') or a path to "
                f"one, got {_model_kind(route_model)}"
            )
        self.route_model = route_model
        self.route_feature_table: np.ndarray | None = None  # the candidates' features
        self.route_split_chosen: int | None = None  # the second route, when split

    def choose_routes(
        self, city: Any, centre_xy_m: np.ndarray, goal_xy_m: np.ndarray
    ) -> list[np.ndarray]:
        """The route of the episode (candidate ``route_index``, the best by the feature
        ``route_choice``, or the one ``route_model`` predicts lowest), and a second one when
        the column splits (:meth:`_split_route`). Records the candidates, the index flown,
        the second route's index (:attr:`route_split_chosen`) and, when they were scored, the
        candidates' features (:attr:`route_feature_table`)."""
        route = self._choose_route(city, centre_xy_m, goal_xy_m)
        k2 = (
            self._split_route(self.route_candidates, self.route_chosen)
            if len(self.route_candidates) > 1
            else None
        )
        self.route_split_chosen = k2
        return [route] if k2 is None else [route, self.route_candidates[k2]]

    def _choose_route(self, city: Any, centre: np.ndarray, goal_xy: np.ndarray) -> np.ndarray:
        self.route_feature_table = None
        plain = self.route_index == 0 and self.route_choice == "first" and self.route_model is None
        if (
            plain
            and self.route_split == "none"
            and not self.route_split_index
            and self.route_split_model is None
        ):
            self.route_candidates, self.route_chosen = [], 0
            return street_route(city, centre, goal_xy)
        routes = street_routes(city, centre, goal_xy, self.route_max_turns)
        if (
            self.route_choice == "first"
            and self.route_model is None
            and (
                (self.route_split == "none" and self.route_split_model is None) or len(routes) == 1
            )
        ):
            k = self.route_index % len(routes)
        elif len(routes) == 1:
            k = 0
        else:
            feats = np.stack(
                [
                    route_features(
                        self.base.world,
                        r,
                        self._altitude_m(),
                        spacing_m=self.spacing_m,
                        n_uavs=len(self._index),
                    )
                    for r in routes
                ]
            )
            self.route_feature_table = feats
            if self.route_model is not None:
                k = int(np.argmin(self.route_model.predict(feats)))
            elif self.route_choice == "first":
                k = self.route_index % len(routes)
            else:
                j = ROUTE_FEATURES.index(self.route_choice)
                k = int(np.argmax(FEATURE_SENSE[self.route_choice] * feats[:, j]))
        self.route_candidates, self.route_chosen = routes, k
        return routes[k]

    def split_table(self, routes: list[np.ndarray], k: int) -> tuple[list[int], np.ndarray]:
        """The options of splitting the column flown on ``routes[k]``: the indices of the
        other routes, and the :data:`SPLIT_FEATURES` ``(1 + others, F)`` of flying unsplit
        (row 0) and of splitting onto each other route (row ``1 + i``), at the column's
        altitude and spacing; kept as :attr:`split_feature_table`."""
        others = [j for j in range(len(routes)) if j != k]
        world, alt = self.base.world, self._altitude_m()
        feats = np.stack(
            [split_features(world, [routes[k]], alt, spacing_m=self.spacing_m)]
            + [
                split_features(world, [routes[k], routes[j]], alt, spacing_m=self.spacing_m)
                for j in others
            ]
        )
        self.split_feature_table = feats
        return others, feats

    def _split_route(self, routes: list[np.ndarray], k: int) -> int | None:
        """Index of the second route of a split swarm among ``routes`` (``k`` is the first),
        or None to fly one column: candidate ``route_split_index`` counted among the others
        (modulo their number), the one the split model predicts lowest, or the best other one
        by the feature ``route_split``."""
        others = [j for j in range(len(routes)) if j != k]
        if self.route_split_index:
            return others[(self.route_split_index - 1) % len(others)]
        if self.route_split_model is not None:
            _, feats = self.split_table(routes, k)
            c = int(np.argmin(self.route_split_model.predict(feats)))
            return None if c == 0 else others[c - 1]
        if self.route_split == "none":
            return None
        feats = self.route_feature_table
        assert feats is not None
        j = ROUTE_FEATURES.index(self.route_split)
        return others[int(np.argmax(FEATURE_SENSE[self.route_split] * feats[others, j]))]


_ROUTE_OPTIONS = (
    "route_index",
    "route_choice",
    "route_model",
    "route_split",
    "route_split_index",
    "route_split_model",
)


def route_column_name(base: str, options: str = "") -> str:
    """The ``route_column`` policy name that flies the column heuristic ``base`` (a preset
    name, options after ``@`` allowed, or a ``route_column`` name) with ``options``
    (``"key=value,..."``) added: ``route_column_name("ceiling_column@spacing_m=30",
    "route_index=2")`` is ``"route_column@preset='ceiling_column',spacing_m=30,route_index=2"``.
    """
    preset, _, own = base.partition("@")
    if preset == "route_column":
        parts = [own, options]
    else:
        parts = [f"preset={preset!r}", own, options]
    return "route_column@" + ",".join(p for p in parts if p)


def route_column(env: Any, preset: str = "column", **options: Any) -> RouteChoiceColumn:
    """The :class:`RouteChoiceColumn` with the settings of the column preset ``preset`` (a
    :data:`~coopnav_env.agents.heuristics.COLUMN_PRESETS` name, or an earlier name of one)
    and ``options`` on top; registered as the policy ``route_column``.

    A preset that chooses its route (``best_sky_route``: ``route_choice="pdop_gt3"``) flies
    ``route_index`` or ``route_model`` instead where one is given (without a ``route_choice``
    of its own).
    """
    name = COLUMN_ALIASES.get(preset, preset)
    if name not in COLUMN_PRESETS:
        raise ValueError(
            f"unknown column preset {preset!r}; presets are "
            f"{', '.join([*COLUMN_PRESETS, *COLUMN_ALIASES])}"
        )
    unknown = sorted(set(options) - set(COLUMN_OPTIONS) - set(_ROUTE_OPTIONS))
    if unknown:
        raise ValueError(
            f"unknown option(s) {', '.join(map(repr, unknown))} of policy 'route_column'; its "
            f"options are preset, {', '.join([*COLUMN_OPTIONS, *_ROUTE_OPTIONS])}"
        )
    settings = {**COLUMN_PRESETS[name], **options}
    told = options.get("route_index") or options.get("route_model") is not None
    if told and "route_choice" not in options:
        settings["route_choice"] = "first"
    policy = RouteChoiceColumn(env, **settings)
    policy.name = preset
    return policy


def learned_route(env: Any, model: Any = "pretrained", **options: Any) -> RouteChoiceColumn:
    """The column (the model's ``base``, a column heuristic's name with options after ``@``
    allowed) that flies the route a learned route model predicts
    best: ``model`` a :class:`RouteModel`, a path or ``pretrained`` (``pretrained/s<k>``);
    registered as the policy ``learned_route``."""
    if not isinstance(model, RouteModel):
        model = RouteModel.load(resolve_route_model(str(model)), kind="route")
    return make_policy(route_column_name(model.base), env, route_model=model, **options)


def learned_split(env: Any, model: Any = "pretrained", **options: Any) -> RouteChoiceColumn:
    """The column (the model's ``base``) split over two streets where a learned split model
    predicts it best: ``model`` a :class:`RouteModel` of kind ``"split"``, a path or
    ``pretrained`` (``pretrained/s<k>``); registered as the policy ``learned_split``."""
    if not isinstance(model, RouteModel):
        model = RouteModel.load(resolve_route_model(str(model), kind="split"), kind="split")
    if model.kind != "split":
        raise ValueError(f"learned_split needs a split model, got a {model.kind} model")
    return make_policy(route_column_name(model.base), env, route_split_model=model, **options)


register_policy("route_column", route_column)
register_policy("learned_route", learned_route)
register_policy("learned_split", learned_split)
