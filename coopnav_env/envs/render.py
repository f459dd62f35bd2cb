"""Frames of ``urban_canyon_v1`` (and v0): city map, swarm close-up with error ellipses, sky plot.

matplotlib is imported inside the functions only (an optional dependency, ``coopnav[plot]``).
A frame has four panels:

* **map**: buildings from above, shaded by roof height (colour bar), streets light, the start
  and goal areas, the UAV tracks and their true positions (colour = source of the position
  estimate: cooperative, standalone, dead reckoning);
* **swarm close-up**: true positions (dots), estimates (crosses) and the 2-sigma error ellipse
  of each estimate from the horizontal (E, N) block of its covariance (``H_p`` for a
  cooperative fix, Eq. 19-23);
* **sky plot** of one UAV, like the paper's Figure 6: its skyline (the building mask seen from
  where it is) shaded, satellites in line of sight coloured by constellation, blocked ones
  grey, NLOS receptions ringed;
* **errors**: per-UAV 3-D error of the standalone and cooperative fixes, and each UAV's
  predicted 2-sigma (3-D).
"""

from __future__ import annotations

import datetime
from typing import Any

import numpy as np

from coopnav_env.constants import FILE_SYSTEMS
from coopnav_env.sim.scenario import Epoch, NavSource, UrbanWorld

__all__ = ["close_window", "gnss_time_text", "render_frame", "show_frame"]

SYSTEM_COLOURS = {"GPS": "#1f77b4", "BDS": "#d62728", "GAL": "#6a4c93"}
SOURCE_COLOURS = {
    NavSource.COOPERATIVE: "#2a9d8f",
    NavSource.STANDALONE: "#f4a261",
    NavSource.DEAD_RECKONING: "#9b2226",
}
SOURCE_LABELS = {
    NavSource.COOPERATIVE: "cooperative fix",
    NavSource.STANDALONE: "standalone fix",
    NavSource.DEAD_RECKONING: "dead reckoning",
}
STREET_COLOUR = "#f3efe6"


def _ellipse_2sigma(cov_en: np.ndarray) -> tuple[float, float, float]:
    """Width, height [m] and angle [deg, from East] of the 2-sigma ellipse of a 2x2 covariance."""
    lam, vec = np.linalg.eigh(cov_en)
    lam = np.clip(lam, 0.0, None)
    angle = float(np.degrees(np.arctan2(vec[1, 1], vec[0, 1])))
    return 4.0 * float(np.sqrt(lam[1])), 4.0 * float(np.sqrt(lam[0])), angle


def gnss_time_text(constellation: Any, t_s: float) -> str:
    """The GNSS time of an epoch as the frame's title shows it.

    Parameters
    ----------
    constellation : Constellation or BroadcastConstellation
        The world's satellites. A sky from a navigation file
        (:class:`~coopnav_env.gnss.rinex.BroadcastConstellation`) knows the date: its time is
        shown as the UTC time of day (GPS time less the leap seconds), ``"GNSS 08:00:47 UTC"``.
    t_s : float
        The epoch's GNSS time ``t_s`` [s] (from the start of the file's coverage for a file
        sky; of the nominal constellation's clock otherwise, shown as ``"GNSS t = 115247 s"``).
    """
    reference_gps_s = getattr(constellation, "reference_gps_s", None)
    if reference_gps_s is None:
        return f"GNSS t = {t_s:.0f} s"
    from coopnav_env.gnss.rinex import gps_seconds

    gps_s = float(reference_gps_s) + float(t_s)
    naive = _GPS_EPOCH + datetime.timedelta(seconds=gps_s)  # GPS time read as if it were UTC
    leap_s = gps_seconds(naive) - gps_s  # GPS - UTC at that date
    utc = naive - datetime.timedelta(seconds=leap_s)
    return f"GNSS {utc:%H:%M:%S} UTC"


_GPS_EPOCH = datetime.datetime(1980, 1, 6, tzinfo=datetime.timezone.utc)


def render_frame(
    world: UrbanWorld,
    epoch: Epoch,
    *,
    trail: list[np.ndarray] | None = None,
    sky_uav: int = -1,
    step: int = 0,
    max_steps: int | None = None,
    size_px: tuple[int, int] = (1280, 640),
    env_name: str = "urban_canyon",
) -> np.ndarray:
    """Draw one epoch.

    Parameters
    ----------
    world : UrbanWorld
        The world (city, start, goal) after :meth:`UrbanWorld.reset`.
    epoch : Epoch
        The epoch to draw.
    trail : list of ndarray (N, 3), optional
        Past true positions, oldest first [m].
    sky_uav : int
        UAV of the sky plot; -1: the one that receives the fewest satellites.
    step, max_steps : int
        Shown in the title.
    size_px : (int, int)
        Width and height of the frame [pixel].
    env_name : str
        The environment's id, first in the title (``metadata["name"]``, e.g.
        ``"urban_canyon_v1"``). The title then shows the GNSS time: the UTC time of day for
        a sky from a navigation file (``constellation="rinex:..."``, :func:`gnss_time_text`),
        else the seconds of the nominal constellation's clock.

    Returns
    -------
    ndarray of uint8, shape (height, width, 3)
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width, height = size_px
    fig = Figure(figsize=(width / 100.0, height / 100.0), dpi=100, facecolor="white")
    canvas = FigureCanvasAgg(fig)
    gs = fig.add_gridspec(
        2,
        3,
        width_ratios=[2.0, 1.0, 1.0],
        height_ratios=[1.0, 0.75],
        left=0.045,
        right=0.93,
        top=0.855,
        bottom=0.105,
        wspace=0.3,
        hspace=0.42,
    )
    ax_map = fig.add_subplot(gs[:, 0])
    ax_zoom = fig.add_subplot(gs[0, 1])
    ax_sky = fig.add_subplot(gs[0, 2], projection="polar")
    ax_err = fig.add_subplot(gs[1, 1:])
    n = epoch.n_uavs
    q = int(np.argmin(epoch.n_sats)) if sky_uav < 0 else int(sky_uav)

    _draw_map(fig, ax_map, world, epoch, trail, q)
    _draw_zoom(ax_zoom, world, epoch, q)
    _draw_sky(ax_sky, world, epoch, q)
    _draw_errors(ax_err, epoch)

    coop = epoch.coop_error_m
    sa = epoch.standalone_error_m
    steps = f"step {step}" + (f" / {max_steps}" if max_steps else "")
    city = world.config.city
    n_coop = int(np.sum(epoch.nav_source == NavSource.COOPERATIVE))
    fig.text(
        0.012,
        0.972,
        f"{env_name}  ·  {city} city  ·  {n} UAVs  ·  {steps}  ·  "
        f"{gnss_time_text(world.constellation, epoch.t_s)}",
        fontsize=11,
        weight="bold",
        va="center",
        color="#212529",
    )
    fig.text(
        0.012,
        0.935,
        f"mean 3-D error: cooperative {_nanmean(coop)}, standalone {_nanmean(sa)}  ·  "
        f"{n_coop}/{n} UAVs on a cooperative fix  ·  {epoch.n_above_mask} satellites above the "
        f"{world.config.elevation_mask_deg:g}° cut-off",
        fontsize=9,
        va="center",
        color="#495057",
    )
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    return np.ascontiguousarray(rgba[..., :3])


def _nanmean(x: np.ndarray) -> str:
    ok = np.isfinite(x)
    if not np.any(ok):
        return "n/a"
    text = f"{float(np.mean(x[ok])):.1f} m"
    return text if np.all(ok) else f"{text} ({int(ok.sum())}/{x.size} fixes)"


def _draw_buildings(ax: Any, world: UrbanWorld, norm: Any, cmap: Any) -> Any:
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    b = world.city.buildings
    if hasattr(b, "rings_m"):  # a file city's polygons (holes drawn over in street colour)
        from matplotlib.patches import Polygon

        rects = [Polygon(rings[0], closed=True) for rings in b.rings_m]
        holes = [Polygon(h, closed=True) for rings in b.rings_m for h in rings[1:]]
    else:
        rects = [
            Rectangle((lo[0], lo[1]), hi[0] - lo[0], hi[1] - lo[1])
            for lo, hi in zip(b.min_m, b.max_m)
        ]
        holes = []
    coll = PatchCollection(rects, cmap=cmap, norm=norm, edgecolor="#4a4e69", linewidth=0.4)
    coll.set_array(np.asarray(b.heights_m))
    ax.add_collection(coll)
    if holes:
        ax.add_collection(
            PatchCollection(holes, facecolor=STREET_COLOUR, edgecolor="#4a4e69", linewidth=0.4)
        )
    return coll


def _height_norm(world: UrbanWorld) -> tuple[Any, Any]:
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    h = np.asarray(world.city.buildings.heights_m)
    top = float(h.max()) if h.size else 50.0
    return Normalize(0.0, max(top, 50.0)), colormaps["bone_r"].resampled(256)


def _draw_map(
    fig: Any,
    ax: Any,
    world: UrbanWorld,
    ep: Epoch,
    trail: list[np.ndarray] | None,
    q: int,
) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Rectangle

    x0, x1, y0, y1 = world.city.extent_m
    norm, cmap = _height_norm(world)
    ax.set_facecolor(STREET_COLOUR)
    coll = _draw_buildings(ax, world, norm, cmap)
    cbar = fig.colorbar(coll, ax=ax, fraction=0.035, pad=0.015)
    cbar.set_label("roof height [m]", fontsize=8)
    cbar.ax.tick_params(labelsize=7)
    for sq in world.city.open_squares:
        half = 0.5 * (world.city.config.block_size_m if world.city.config else 0.0)
        ax.add_patch(
            Rectangle((sq[0] - half, sq[1] - half), 2 * half, 2 * half, color="#d8f3dc", zorder=0.5)
        )
    from matplotlib import patheffects

    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    r_goal = world.config.goal_radius_m
    goal = ep.goal_enu_m
    ax.add_patch(
        Circle(goal[:2], r_goal, facecolor="#52b78833", edgecolor="#2d6a4f", lw=1.5, ls="--")
    )
    ax.plot(*goal[:2], marker="*", ms=13, color="#2d6a4f", mec="white", zorder=6)
    ax.annotate(
        "goal",
        goal[:2],
        xytext=(6, 6),
        textcoords="offset points",
        fontsize=8,
        color="#2d6a4f",
        weight="bold",
        path_effects=halo,
    )
    start = world.start_enu_m[:, :2].mean(axis=0)
    ax.plot(*start, marker="s", ms=7, color="#6c757d", mec="white", zorder=5)
    ax.annotate(
        "start",
        start,
        xytext=(6, -11),
        textcoords="offset points",
        fontsize=8,
        color="#495057",
        path_effects=halo,
    )
    if trail and len(trail) > 1:
        tr = np.stack(trail)  # (T, N, 3)
        ax.plot(tr[:, :, 0], tr[:, :, 1], color="#3a86ff", lw=0.8, alpha=0.45, zorder=3)
    colours = [SOURCE_COLOURS[NavSource(s)] for s in ep.nav_source]
    ax.scatter(
        ep.pos_enu_m[:, 0],
        ep.pos_enu_m[:, 1],
        s=24,
        c=colours,
        edgecolors="black",
        linewidths=0.4,
        zorder=7,
    )
    ax.scatter(
        *ep.pos_enu_m[q, :2], s=110, facecolors="none", edgecolors="#7b2cbf", lw=1.4, zorder=8
    )
    crashed = ep.collided
    if np.any(crashed):
        ax.scatter(
            ep.pos_enu_m[crashed, 0],
            ep.pos_enu_m[crashed, 1],
            marker="X",
            s=90,
            color="#d00000",
            zorder=9,
        )
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("East [m]", fontsize=8)
    ax.set_ylabel("North [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title("city map (buildings shaded by roof height)", fontsize=9, pad=12)
    handles = [
        Line2D(
            [],
            [],
            ls="",
            marker="o",
            mfc=SOURCE_COLOURS[s],
            mec="black",
            mew=0.4,
            label=SOURCE_LABELS[s],
        )
        for s in NavSource
    ]
    handles.append(
        Line2D(
            [], [], ls="", marker="o", mfc="none", mec="#7b2cbf", ms=9, label=f"uav_{q} (sky plot)"
        )
    )
    fig.legend(
        handles=handles,
        loc="lower left",
        bbox_to_anchor=(0.01, 0.0),
        ncol=4,
        fontsize=7,
        frameon=False,
        handletextpad=0.3,
        columnspacing=1.0,
    )


def _draw_zoom(ax: Any, world: UrbanWorld, ep: Epoch, q: int) -> None:
    from matplotlib.patches import Ellipse

    norm, cmap = _height_norm(world)
    ax.set_facecolor(STREET_COLOUR)
    _draw_buildings(ax, world, norm, cmap)
    pos = ep.pos_enu_m
    est = ep.nav_pos_enu_m
    cov = ep.nav_cov_enu_m2[:, :2, :2]
    pts = np.vstack([pos[:, :2], est[:, :2]])
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    sig_max = float(np.sqrt(np.clip(np.einsum("nii->n", cov), 0, None)).max())
    half = max(0.5 * float(np.ptp(pts, axis=0).max()) + 6.0, 2.5 * sig_max, 15.0)
    half = min(half, 150.0)
    for i in range(ep.n_uavs):  # drawing only: one artist per UAV
        colour = SOURCE_COLOURS[NavSource(int(ep.nav_source[i]))]
        w, h, ang = _ellipse_2sigma(cov[i])
        ax.add_patch(
            Ellipse(
                est[i, :2],
                w,
                h,
                angle=ang,
                facecolor=colour + "40",
                edgecolor=colour,
                lw=1.0,
                zorder=4,
            )
        )
        ax.plot([pos[i, 0], est[i, 0]], [pos[i, 1], est[i, 1]], color="#6c757d", lw=0.6, zorder=4)
    ax.scatter(pos[:, 0], pos[:, 1], s=14, color="black", zorder=6, label="true position")
    ax.scatter(
        est[:, 0],
        est[:, 1],
        s=26,
        marker="x",
        color="#3a0ca3",
        lw=1.1,
        zorder=6,
        label="estimate (2σ ellipse)",
    )
    ax.scatter(*pos[q, :2], s=90, facecolors="none", edgecolors="#7b2cbf", lw=1.3, zorder=7)
    if ep.n_uavs <= 12:
        for i in range(ep.n_uavs):
            ax.annotate(
                str(i),
                pos[i, :2],
                xytext=(3, 3),
                textcoords="offset points",
                fontsize=7,
                color="#212529",
                zorder=8,
            )
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)
    ax.set_title("swarm close-up", fontsize=9, pad=14)
    ax.set_anchor("N")
    ax.legend(loc="upper left", fontsize=6.5, framealpha=0.85)


def _draw_sky(ax: Any, world: UrbanWorld, ep: Epoch, q: int) -> None:
    az_grid = np.arange(0.0, 360.0 + 2.5, 2.5)
    mask = world.city.mask_elevation_deg(ep.pos_enu_m[q : q + 1], az_grid)[0]
    mask = np.maximum(mask, world.config.elevation_mask_deg)
    theta = np.radians(az_grid)
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.fill_between(theta, 90.0 - mask, 90.0, color="#adb5bd", alpha=0.75, lw=0, zorder=1)
    ax.plot(theta, 90.0 - mask, color="#495057", lw=0.9, zorder=2)
    up = ep.sv_el_deg > 0.0
    th = np.radians(ep.sv_az_deg)
    r = 90.0 - ep.sv_el_deg
    los, rec, nlos = ep.los[q], ep.received[q], ep.nlos[q]
    blocked = up & ~los
    ax.scatter(
        th[blocked], r[blocked], s=34, facecolors="white", edgecolors="#868e96", lw=1.0, zorder=3
    )
    for s, name in enumerate(FILE_SYSTEMS):
        sel = up & los & (ep.system == s)
        if name in world.config.systems:
            ax.scatter(
                th[sel],
                r[sel],
                s=42,
                color=SYSTEM_COLOURS[name],
                edgecolors="white",
                lw=0.6,
                zorder=4,
                label=f"{name} ({int(sel.sum())})",
            )
    if np.any(nlos):
        ax.scatter(
            th[nlos],
            r[nlos],
            s=90,
            facecolors="none",
            edgecolors="#ff7f0e",
            lw=1.3,
            zorder=5,
            label=f"NLOS ({int(nlos.sum())})",
        )
    ax.scatter(
        [],
        [],
        s=34,
        facecolors="white",
        edgecolors="#868e96",
        label=f"blocked ({int(blocked.sum())})",
    )
    ax.set_rlim(0, 90)
    ax.set_yticks([30, 60])
    ax.set_yticklabels(["60°", "30°"], fontsize=6.5, color="#495057")
    ax.set_xticks(np.radians([0, 90, 180, 270]))
    ax.set_xticklabels(["N", "E", "S", "W"], fontsize=8)
    ax.set_title(f"sky of uav_{q}: {int(rec.sum())} satellites received", fontsize=9, pad=14)
    ax.set_anchor("N")
    ax.legend(
        loc="upper left",
        bbox_to_anchor=(0.86, 1.12),
        fontsize=6.5,
        framealpha=0.85,
        borderaxespad=0.0,
    )


def _draw_errors(ax: Any, ep: Epoch) -> None:
    n = ep.n_uavs
    idx = np.arange(n)
    sa = ep.standalone_error_m
    co = ep.coop_error_m
    sig2 = 2.0 * np.sqrt(np.clip(np.trace(ep.nav_cov_enu_m2, axis1=1, axis2=2), 0, None))
    w = 0.4
    ax.bar(idx - w / 2, np.nan_to_num(sa, nan=0.0), w, color="#f4a261", label="standalone")
    ax.bar(idx + w / 2, np.nan_to_num(co, nan=0.0), w, color="#2a9d8f", label="cooperative")
    ax.hlines(
        sig2,
        idx - w,
        idx + w,
        color="#3a0ca3",
        lw=2.0,
        zorder=5,
        label="predicted 2σ of the estimate used",
    )
    top = np.nanmax(np.r_[sa, co, sig2, 1.0][np.isfinite(np.r_[sa, co, sig2, 1.0])])
    no_sa = ~np.isfinite(sa)
    if np.any(no_sa):
        ax.scatter(
            idx[no_sa] - w / 2,
            np.full(no_sa.sum(), 0.04 * top),
            marker="x",
            s=20,
            color="#9b2226",
            zorder=6,
            label="no standalone fix",
        )
    ax.set_ylim(0, min(1.15 * top, 60.0))  # larger errors run off the scale
    ax.set_xlim(-0.7, n - 0.3)
    if n <= 20:
        ax.set_xticks(idx)
        ax.set_xticklabels([str(i) for i in idx], fontsize=7)
    else:
        ax.tick_params(axis="x", labelsize=7)
    ax.set_xlabel("UAV", fontsize=8)
    ax.set_ylabel("3-D position error [m]", fontsize=8)
    ax.tick_params(axis="y", labelsize=7)
    ax.grid(axis="y", color="#dee2e6", lw=0.6)
    ax.set_axisbelow(True)
    ax.legend(
        fontsize=7,
        ncol=4,
        loc="lower center",
        bbox_to_anchor=(0.5, 1.0),
        frameon=False,
        borderaxespad=0.2,
        handlelength=1.5,
        columnspacing=1.0,
    )


def show_frame(frame: np.ndarray, window: Any, fps: float) -> Any:
    """Show ``frame`` in a matplotlib window (created on first use); returns the window."""
    import matplotlib.pyplot as plt

    if window is None:
        h, w = frame.shape[:2]
        fig = plt.figure(figsize=(w / 100.0, h / 100.0), dpi=100)
        ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_axis_off()
        image = ax.imshow(frame)
        plt.show(block=False)
        window = (fig, image)
    else:
        window[1].set_data(frame)
    window[0].canvas.draw_idle()
    plt.pause(1.0 / fps)
    return window


def close_window(window: Any) -> None:
    """Close a window made by :func:`show_frame`."""
    import matplotlib.pyplot as plt

    plt.close(window[0])
