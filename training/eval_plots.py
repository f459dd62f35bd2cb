"""Plots of ``coopnav evaluate``: error CDF per policy, and each policy's first episode.

* :func:`plot_error_cdf` (``error_cdf.png``): empirical CDF of the cooperative (solid) and
  standalone (dashed) 3-D error per policy over all UAV-steps. A step without a fix has no
  error to plot but counts in the denominator (as in P(< 3 m) of the table), so a curve
  levels off below 1 at the policy's fix rate; the caption says so, and the 3 m line of the
  table's P(< 3 m) is labelled.
* :func:`plot_trajectories` (``trajectories_<policy>.png``): the top view (buildings, planned
  street route, goal, true track of every UAV) above a side view, the altitude along the
  route, which is where the policies differ most (a formation follower, the sky-seeking
  heuristic and a learned policy fly much the same streets at different heights). Start and
  end markers are explained in the legend, which sits below the axes, off the data.
* :func:`trajectory_comparison_figure`: several policies' episodes side by side (a column per
  policy, top view above side view, the side views on one altitude scale), for drawing two
  policies on the same episode.

Policy names are shortened for the plots by :func:`short_labels`: ``waypoint@altitude_m=28``
becomes ``waypoint (tuned)``, ``ppo:runs/quick/final_model.zip`` becomes ``ppo (quick)``.
Every file is written atomically (:func:`coopnav_env.training.files.atomic_path`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any

import numpy as np

from coopnav_env.training.files import atomic_path

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "error_cdf_figure",
    "plot_error_cdf",
    "plot_trajectories",
    "short_label",
    "short_labels",
    "trajectory_comparison_figure",
    "trajectory_figure",
]

#: caption under the CDF: why the curves stop below 1
CDF_CAPTION: str = (
    "Over all UAV-steps of the held-out episodes. A step without a fix counts as a failure "
    "(it has no error to plot),\nso a curve levels off below 1 at that policy's fix rate."
)


def short_label(name: str) -> str:
    """A short plot label of a policy name.

    Heuristic options after ``@`` become ``(tuned)``; a trained policy ``KIND:PATH`` becomes
    ``KIND (RUN)`` with ``RUN`` the run folder's name (for ``RUN/final_model*``, ``RUN/final*``
    or the folder ``RUN`` itself), ``KIND (RUN, CHECKPOINT)`` for ``RUN/checkpoints/
    CHECKPOINT``, else ``KIND (FILE)`` with the file name without its extension.
    """
    base, at, _options = name.partition("@")
    if at:
        return f"{base} (tuned)"
    kind, sep, path = name.partition(":")
    if not sep or not path:
        return name
    p = PurePath(path)
    stem = p.name[: -len(p.suffix)] if p.suffix else p.name
    parts = p.parts
    if "checkpoints" in parts[:-1]:
        i = len(parts) - 1 - parts[::-1].index("checkpoints")
        run = parts[i - 1] if i > 0 else ""
        return f"{kind} ({run}, {stem})" if run else f"{kind} ({stem})"
    if stem.startswith("final") and p.parent.name:
        return f"{kind} ({p.parent.name})"
    return f"{kind} ({stem or path})"


def short_labels(names: Sequence[str]) -> dict[str, str]:
    """:func:`short_label` of each name; names whose short labels coincide keep their own."""
    short = {n: short_label(n) for n in names}
    counts: dict[str, int] = {}
    for label in short.values():
        counts[label] = counts.get(label, 0) + 1
    return {n: (label if counts[label] == 1 else n) for n, label in short.items()}


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Figure, path: str | Path, dpi: int = 120) -> Path:
    """Write ``fig`` to ``path`` (PNG) through a temporary file, and close it."""
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    _pyplot().close(fig)
    return path


# --------------------------------------------------------------------------------------------
# error CDF
# --------------------------------------------------------------------------------------------


def error_cdf_figure(
    episodes: Mapping[str, Sequence[Any]],
    threshold_m: float,
    labels: Mapping[str, str] | None = None,
) -> Figure:
    """The CDF figure of :func:`plot_error_cdf` (not saved), for ``episodes`` per policy."""
    plt = _pyplot()
    labels = dict(labels or short_labels(list(episodes)))
    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (name, eps) in enumerate(episodes.items()):
        c = colors[k % len(colors)]
        for key, style, kind in (
            ("coop_error_m", "-", "cooperative"),
            ("standalone_error_m", "--", "standalone"),
        ):
            err = np.concatenate([getattr(e, key).ravel() for e in eps])
            n = err.size
            fin = np.sort(err[np.isfinite(err)])
            if fin.size == 0:
                continue
            y = np.arange(1, fin.size + 1) / n  # steps without a fix never reach the curve
            ax.step(fin, y, where="post", color=c, ls=style, label=f"{labels[name]} ({kind})")
    ax.axvline(
        threshold_m,
        color="0.4",
        lw=0.9,
        ls=":",
        label=f"{threshold_m:g} m (the table's P(< {threshold_m:g} m))",
    )
    ax.annotate(
        f"{threshold_m:g} m",
        xy=(threshold_m, 1.0),
        xycoords=("data", "axes fraction"),
        xytext=(3, -3),
        textcoords="offset points",
        ha="left",
        va="top",
        fontsize=8,
        color="0.3",
    )
    ax.set_xscale("log")
    ax.set_xlabel("3-D position error [m]")
    ax.set_ylabel("P(error ≤ x)")
    ax.set_ylim(0.0, 1.0)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Navigation error per policy (held-out episodes)")
    fig.legend(loc="outside right upper", fontsize=7)
    fig.text(0.01, -0.01, CDF_CAPTION, fontsize=7.5, ha="left", va="top", color="0.25")
    return fig


def plot_error_cdf(report: Any, path: str | Path, threshold_m: float = 3.0) -> Path:
    """Write the error CDF of a :class:`coopnav_env.training.evaluate.Report` to ``path``
    (PNG), with a labelled line at ``threshold_m``
    (``coopnav_env.training.evaluate.ERROR_THRESHOLD_M``)."""
    return save_figure(error_cdf_figure(report.episodes, threshold_m), path, dpi=120)


# --------------------------------------------------------------------------------------------
# trajectories
# --------------------------------------------------------------------------------------------


def _world(env: Any) -> dict[str, Any]:
    """Building footprints (n_b, 4) and heights, goal (2,), extent and route (n_r, 2) of the
    env's current world (None where the env has none)."""
    base = getattr(env, "unwrapped", env)
    world = getattr(base, "world", base)
    city = getattr(world, "city", None)
    out: dict[str, Any] = {"footprints": None, "heights": None, "extent": None}
    if city is not None:
        out["footprints"] = np.asarray(city.buildings.footprints_m)
        heights = getattr(city.buildings, "heights_m", None)
        out["heights"] = None if heights is None else np.asarray(heights, dtype=float)
        out["extent"] = tuple(city.extent_m)
        out["rings"] = getattr(city.buildings, "rings_m", None)  # a file city's polygons
    goal = getattr(world, "goal_enu_m", None)
    out["goal"] = np.asarray(goal, dtype=float)[:2] if goal is not None else None
    route = getattr(world, "route_xy_m", None)
    route = None if route is None else np.asarray(route, dtype=float).reshape(-1, 2)
    out["route"] = route if route is not None and route.shape[0] >= 2 else None
    return out


def distance_along_route(xy: np.ndarray, route: np.ndarray) -> np.ndarray:
    """Arc length [m] of the point of the polyline ``route`` (n_r, 2) nearest each of ``xy``
    (..., 2): how far along the route a position is (:meth:`Polyline.project` over the
    whole route)."""
    from coopnav_env.sim.route import Polyline

    line = Polyline(np.asarray(route, dtype=float))
    pts = np.asarray(xy, dtype=float)
    flat = pts.reshape(-1, 2)
    n = flat.shape[0]
    return line.project(flat, np.zeros(n), np.full(n, line.length)).reshape(pts.shape[:-1])


def _flown_distance(xy: np.ndarray) -> np.ndarray:
    """Horizontal distance flown [m] at each step of tracks ``xy`` (T, N, 2)."""
    step = np.linalg.norm(np.diff(xy, axis=0), axis=-1)
    return np.concatenate([np.zeros((1, xy.shape[1])), np.cumsum(step, axis=0)])


def _draw_buildings(top: Any, world: Mapping[str, Any]) -> None:
    """The city's footprints on the top view (a file city's holes drawn over in white)."""
    if world.get("rings") is not None:
        from matplotlib.patches import Polygon

        for rings in world["rings"]:
            top.add_patch(Polygon(rings[0], color="0.78", lw=0))
            for hole in rings[1:]:
                top.add_patch(Polygon(hole, color="white", lw=0))
    elif world["footprints"] is not None:
        from matplotlib.patches import Rectangle

        for x0, y0, x1, y1 in world["footprints"]:
            top.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color="0.78", lw=0))


def _draw_episode(top: Any, side: Any, world: Mapping[str, Any], record: Any) -> list[Any]:
    """One episode's world and tracks on a top view and a side view (altitude along the
    route); returns the legend handles of the UAVs' colours."""
    from matplotlib.lines import Line2D

    _draw_buildings(top, world)
    route = world["route"]
    if route is not None:
        top.plot(route[:, 0], route[:, 1], color="0.45", lw=0.9, ls="--")
    pos = np.asarray(record.pos_enu_m, dtype=float)
    if route is not None:
        along = distance_along_route(pos[..., :2], route)
        side.set_xlabel("distance along the planned street route [m]")
    else:
        along = _flown_distance(pos[..., :2])
        side.set_xlabel("horizontal distance flown [m]")
    ends = "x" if record.collided else None
    handles = []
    for i in range(pos.shape[1]):
        (line,) = top.plot(pos[:, i, 0], pos[:, i, 1], lw=1.2)
        c = line.get_color()
        handles.append(Line2D([], [], color=c, lw=1.5, label=f"uav_{i}"))
        end = ends or ("*" if record.goal_reached[i] else "s")
        for ax, x, y in ((top, pos[:, i, 0], pos[:, i, 1]), (side, along[:, i], pos[:, i, 2])):
            if ax is side:
                ax.plot(x, y, color=c, lw=1.2)
            ax.plot(x[0], y[0], "o", color=c, ms=4)
            ax.plot(x[-1], y[-1], end, color=c, ms=7, mew=1.5)
    goal = world["goal"]
    if goal is not None:
        top.plot(goal[0], goal[1], marker="*", color="gold", mec="k", ms=16, ls="")
    if world["extent"] is not None:
        ext = world["extent"]
        top.set_xlim(ext[0], ext[1])
        top.set_ylim(ext[2], ext[3])
    top.set_aspect("equal")
    top.set_xlabel("East [m]")
    top.set_ylabel("North [m]")
    heights = world["heights"]
    if heights is not None and heights.size:
        side.axhline(float(np.median(heights)), color="0.5", lw=0.9, ls="-.")
    side.set_ylabel("altitude [m]")
    side.grid(True, alpha=0.3)
    return handles


def _outcome(record: Any) -> str:
    """How the episode ended, in words."""
    n = int(np.asarray(record.goal_reached).size)
    if record.collided:
        return "ended by a crash"
    return f"{int(np.sum(record.goal_reached))} of {n} UAVs reached the goal area"


def _legend_handles(world: Mapping[str, Any], records: Sequence[Any]) -> list[Any]:
    """Legend entries of the markers and lines that ``records`` drawn in ``world`` show."""
    from matplotlib.lines import Line2D

    def marker(m: str, label: str, **kw: Any) -> Line2D:
        return Line2D([], [], marker=m, color="k", ls="", ms=kw.pop("ms", 6), label=label, **kw)

    handles = [marker("o", "start", ms=4)]
    if any(r.collided for r in records):
        handles.append(marker("x", "end: the episode ended in a crash", mew=1.5))
    flown = [r for r in records if not r.collided]
    if any(np.any(r.goal_reached) for r in flown):
        handles.append(marker("*", "end: reached the goal area", ms=8))
    if any(not np.all(r.goal_reached) for r in flown):
        handles.append(marker("s", "end: did not reach the goal area"))
    if world["goal"] is not None:
        handles.append(marker("*", "goal", ms=12, mfc="gold", mec="k"))
    if world["route"] is not None:
        handles.append(Line2D([], [], color="0.45", lw=0.9, ls="--", label="planned route"))
    heights = world["heights"]
    if heights is not None and heights.size:
        handles.append(Line2D([], [], color="0.5", lw=0.9, ls="-.", label="median building height"))
    return handles


def trajectory_figure(env: Any, record: Any, title: str = "") -> Figure | None:
    """The figure of :func:`plot_trajectories` (not saved); None without true positions."""
    if record.pos_enu_m is None:
        return None
    plt = _pyplot()
    env.reset(seed=record.seed)
    world = _world(env)
    fig, (top, side) = plt.subplots(
        2,
        1,
        figsize=(6.4, 9.0),
        height_ratios=[3.0, 1.3],
        layout="constrained",
    )
    handles = _draw_episode(top, side, world, record)
    top.set_title(f"{title}\n{record.length} steps, {_outcome(record)}", fontsize=9)
    side.set_title("side view: altitude along the route", fontsize=8)
    handles += _legend_handles(world, [record])
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=7, frameon=False)
    return fig


def trajectory_comparison_figure(panels: Sequence[tuple[str, Any, Any]], title: str = "") -> Figure:
    """Several policies' episodes side by side: a column per policy, the top view above the
    side view (altitude along the route), the side views on one altitude scale.

    Parameters
    ----------
    panels : sequence of (label, env, EpisodeRecord)
        Each policy's label, the env it flew in and its episode; every env is reset with its
        record's seed to draw that episode's world (the same world for every panel when the
        records share a seed and the envs a city).
    title : str
        The figure's title, above the panels.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        No panels, or a record without true positions.
    """
    if not panels:
        raise ValueError("panels must name at least one (label, env, record)")
    for label, _env, record in panels:
        if record.pos_enu_m is None:
            raise ValueError(f"the episode of {label!r} has no true positions to draw")
    plt = _pyplot()
    n = len(panels)
    fig, axes = plt.subplots(
        2,
        n,
        figsize=(4.6 * n, 7.0),
        height_ratios=[3.0, 1.3],
        layout="constrained",
        squeeze=False,
    )
    worlds, colours = [], []
    for k, (label, env, record) in enumerate(panels):
        env.reset(seed=record.seed)
        world = _world(env)
        worlds.append(world)
        colours = _draw_episode(axes[0, k], axes[1, k], world, record)
        axes[0, k].set_title(f"{label}\n{record.length} steps, {_outcome(record)}", fontsize=9)
        axes[1, k].set_title("side view: altitude along the route", fontsize=8)
    low = min(ax.get_ylim()[0] for ax in axes[1])
    high = max(ax.get_ylim()[1] for ax in axes[1])
    for ax in axes[1]:
        ax.set_ylim(low, high)
    if title:
        fig.suptitle(title, fontsize=10)
    handles = colours + _legend_handles(worlds[0], [p[2] for p in panels])
    fig.legend(handles=handles, loc="outside lower center", ncol=5, fontsize=7, frameon=False)
    return fig


def plot_trajectories(env: Any, record: Any, path: str | Path, title: str = "") -> bool:
    """Top and side view of one episode (module docstring) written to ``path`` (PNG).

    The env is reset with the record's seed to show the episode's world. Returns False (and
    writes nothing) when the positions are unknown.
    """
    fig = trajectory_figure(env, record, title)
    if fig is None:
        return False
    save_figure(fig, path, dpi=110)
    return True
