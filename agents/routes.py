"""Route choice: which of the equally short street routes to fly, from the map and the sky.

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
  (:data:`FEATURE_SENSE`), e.g. ``ceiling@route_choice='los_mean'``.
* A *learned* choice (:class:`RouteModel`) predicts each route's error from all features
  with a model fitted to flown episodes (``training/route_learning.py``) and takes the lowest.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coopnav_env.nav import pdop
from coopnav_env.sim.route import Polyline

__all__ = [
    "FEATURE_SENSE",
    "MODEL_KINDS",
    "PRETRAINED_ROUTE_DIR",
    "ROUTE_FEATURES",
    "SPLIT_FEATURES",
    "SPLIT_FEATURE_SENSE",
    "RouteModel",
    "fit_route_model",
    "resolve_route_model",
    "route_features",
    "split_features",
]

PRETRAINED_ROUTE_DIR = Path(__file__).resolve().parent / "pretrained"
"""Where the shipped route models live (``route_s<k>`` folders)."""


def resolve_route_model(text: str, kind: str = "route") -> Path:
    """The file behind a ``route:<text>`` (``split:<text>``) policy name: ``pretrained`` is
    the shipped model of training seed 0 (``agents/pretrained/route_s0``, ``split_s0``),
    ``pretrained/s<k>`` that of seed ``k``; anything else a path (a ``route_model.json`` or
    ``split_model.json`` file, or a folder holding one)."""
    if kind not in ("route", "split"):
        raise ValueError(f"kind must be 'route' or 'split', got {kind!r}")
    if text == "pretrained" or text.startswith("pretrained/"):
        tail = text[len("pretrained") :].lstrip("/") or "s0"
        if not (tail.startswith("s") and tail[1:].isdigit()):
            raise ValueError(f"{kind}:pretrained takes a seed as pretrained/s<k>, got {text!r}")
        return PRETRAINED_ROUTE_DIR / f"{kind}_{tail}"
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
        The column heuristic (a :func:`coopnav_env.agents.make_policy` name) that flies the
        chosen route, and that flew the training episodes.
    info : dict
        What the model was fitted on (environment settings, seeds, sizes, CV scores).
    kind : str
        ``"route"``: scores routes by their :data:`ROUTE_FEATURES` (the ``route_model``
        option of the column heuristics); ``"split"``: scores flying one column against
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
                f"{p} holds a {found} model, not a {kind} model: {kind}:<path> takes a "
                f"{kind}_model.json; give it as {found}:{path}"
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
