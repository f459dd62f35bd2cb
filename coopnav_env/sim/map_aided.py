r"""3D-mapping-aided NLOS exclusion: satellites the city model predicts blocked are not used.

In a street canyon many satellites are received only by reflection (NLOS), each with a
positive range bias of metres to hundreds of metres, and in the ``urban_nlos`` preset about
40 % of the pseudoranges are such reflections. A residual test (RAIM, FDE:
:mod:`coopnav_env.nav.integrity`) assumes that faults are rare: with several biased rows at
once the least-squares fix is pulled toward them, the residuals of the faulty rows shrink
and those of good rows grow (masking), and one-at-a-time exclusion by the largest normalised
residual can stop with a wrong fix that the test accepts. The field's standard answer in
urban canyons is 3D-mapping-aided (3DMA) GNSS (Groves, J. Navigation 2011, shadow
matching; Hsu, Gu and Kamijo, GPS Solutions 2016; Groves and Adjrad, GPS Solutions 2017; the
NLOS exclusion step of 3DMA ranging): the receiver knows the buildings around it and its
approximate position, predicts from them which satellites are in line of sight, and does not
use the ones predicted blocked.
This module is that step; the environment applies it with ``nlos_exclusion="map"``
(:class:`~coopnav_env.sim.scenario.ScenarioConfig`) before the solvers and before the
residual test, which then deals with the NLOS rows the prediction lets through.

Prediction with position uncertainty
------------------------------------
The prediction is made where the UAV *thinks* it is: its previous estimate moved by its
velocity (the solvers' warm start), with the covariance of that estimate grown by the
dead-reckoning noise of one step. A satellite is *predicted line of sight* only when it is
in line of sight from every candidate position the UAV could be at: the predicted position
and the points ``m`` sigma from it along both horizontal principal axes of the covariance and
along the vertical (``m = margin_sigma``, each displacement capped at ``max_margin_m``),
leaving out candidates inside a building (the UAV cannot be there) and clamping the altitude
to the flight band. A satellite blocked from any candidate is not used. The rule is
conservative on purpose: a satellite in doubt costs one measurement of redundancy, an NLOS
row let through can cost the fix (the residual test is what remains against it). When every
candidate is inside a building (the estimate is badly off) the map says nothing and every
satellite is kept.

Why this design
---------------
The single-fault FDE of :mod:`coopnav_env.nav.integrity` (Baarda's largest normalised
residual, repeated) and the public designs it was compared with share one limit here.
RTKLIB's ``raim_fde`` (``pntpos.c``) excludes at most one satellite; gnss_lib_py's residual
FDE tests single-satellite subsets and its greedy EDM FDE (Knowles and Gao) removes one
measurement per round: each round assumes that the remaining set is mostly clean, which
40 % of reflected rows denies. The cooperative problem adds a blind spot of its own: every
UAV has its own clocks, so NLOS delays of similar size on one UAV's satellites look like a
clock offset and leave no residual at all. Against that no residual test helps; knowing
*which* rows may be reflected does. Tried during the design (prototype runs of the study,
``column`` and ``sky_column``, 10-100 episodes each; not kept): the prediction at the believed
position alone (margin 0) did no better than FDE alone, because that position is off by
metres and the prediction errs both ways; candidates without the vertical pair let several
times more NLOS rows through (the vertical sigma of a GNSS fix is its largest); wider margins
(3 sigma, 15 m) removed more good satellites and left more fixes with a large, honest sigma;
using the doubtful satellites as suspects, excluded only when the residual test fails and
kept while it passes, did worse than excluding them outright: the test passes with a UAV's
similar delays absorbed by its clock, and going back to the full set when the suspect-free
set cannot be cleared brings the masking back. Dropping the candidates that contradict the
reception (a satellite in line of sight from there that is not received), as shadow matching
would, restored satellites but multiplied the wrong fixes several times, and so did turning
the map off for a UAV that had dead-reckoned for 10-20 epochs (a way back for a UAV whose
believed position is wrong, below). What is kept: exclude every satellite blocked from any
candidate, then FDE (one-sided) on what is left; the ``urban_nlos_3dma`` preset also
tightens the fix gate (``max_fix_sigma_m`` 15 m), because the fewer satellites make weak
geometries common, and a fix whose own sigma is 15-30 m is often tens of metres off and
moves the position the next prediction is made at.

What it costs: fewer satellites per fix, so fewer valid cooperative fixes and a lower
availability of protection levels within the alert limit (the UAVs dead-reckon more), for
far fewer wrong ones; ``studies/nlos_defences/nlos_defences.py`` measures both sides, and
``benchmarks/bench_integrity.py`` the step time (the prediction traces seven candidates per
UAV). Dead reckoning is cheap in this simulation by default (it moves the estimate by the
true velocity, so its error does not grow), which flatters any design that rejects fixes;
``dead_reckoning_noise=True`` (:class:`~coopnav_env.sim.scenario.ScenarioConfig`) makes it
drift as its covariance says.

A limitation: the prediction trusts the believed position. When that is off by more than
the margin (an unlucky fix, tens of metres), the map at the wrong place excludes the
satellites the UAV could use and keeps some reflected ones; typically no fix passes again
and the UAV dead-reckons with the error it had (a few episodes in a hundred of the study).
A way back would need the measurements to relocate the UAV (shadow matching over a grid of
candidate positions, Groves 2011); that is not implemented.

Honesty about the map
---------------------
The simulated reception is computed from the same box city the prediction uses, so the map
here is perfect: at the true position it would name every NLOS row exactly, and what is left
comes only from the position uncertainty. A real UAV's 3-D city model has errors of metres
(building outlines, heights, missing structures, trees), and real reception near a building
edge is not binary (diffraction); a real 3DMA receiver widens its margins accordingly. A UAV
carrying a city model is plausible, but the figures measured with this option are an upper
bound on what a real map gives.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from coopnav_env.sim import _kernels
from coopnav_env.sim.city import (
    Buildings,
    SkyDirections,
    _trace_line_of_sight,
    is_inside_building,
)

__all__ = ["N_CANDIDATES", "candidate_positions", "predicted_line_of_sight"]

#: Candidate positions per UAV: the prediction, +-margin along both horizontal principal axes
#: and along the vertical.
N_CANDIDATES = 7


def candidate_positions(
    pos_enu_m: np.ndarray,
    cov_enu_m2: np.ndarray,
    margin_sigma: float,
    max_margin_m: float,
    altitude_band_m: tuple[float, float],
) -> np.ndarray:
    """The positions each UAV could be at, shape ``(N, 7, 3)``.

    Row 0 is the predicted position; rows 1-2 are ``+-margin_sigma`` sigma along the major
    axis of the horizontal covariance, rows 3-4 along its minor axis, rows 5-6
    ``+-margin_sigma`` vertical sigma; each displacement is capped at ``max_margin_m`` (a
    covariance that is not finite gives the cap along East, North and Up), and every altitude
    is clamped to ``altitude_band_m``.
    """
    pos = np.asarray(pos_enu_m, dtype=float)
    cov = np.asarray(cov_enu_m2, dtype=float)
    n = pos.shape[0]
    out = np.repeat(pos[:, None, :], N_CANDIDATES, axis=1)
    h = cov[:, :2, :2]
    finite = np.all(np.isfinite(h.reshape(n, 4)), axis=1) & np.isfinite(cov[:, 2, 2])
    sym = 0.5 * (h + np.swapaxes(h, 1, 2))
    evals, evecs = np.linalg.eigh(np.where(finite[:, None, None], sym, np.eye(2)))
    for j, axis in enumerate((1, 0)):  # major (largest eigenvalue), then minor
        sig = np.sqrt(np.clip(evals[:, axis], 0.0, None))
        d = np.where(finite, np.minimum(margin_sigma * sig, max_margin_m), max_margin_m)
        vec = np.where(finite[:, None], evecs[:, :, axis], np.eye(2)[1 - j])  # else N, E
        out[:, 1 + 2 * j, :2] += vec * d[:, None]
        out[:, 2 + 2 * j, :2] -= vec * d[:, None]
    sig_u = np.sqrt(np.clip(np.where(finite, cov[:, 2, 2], 0.0), 0.0, None))
    d_u = np.where(finite, np.minimum(margin_sigma * sig_u, max_margin_m), max_margin_m)
    out[:, 5, 2] += d_u
    out[:, 6, 2] -= d_u
    lo, hi = altitude_band_m
    np.clip(out[:, :, 2], lo, hi, out=out[:, :, 2])
    return out


def predicted_line_of_sight(
    buildings: Buildings,
    sky: SkyDirections,
    pos_enu_m: np.ndarray,
    cov_enu_m2: np.ndarray,
    *,
    margin_sigma: float,
    max_margin_m: float,
    altitude_band_m: tuple[float, float],
) -> np.ndarray:
    """Satellites predicted in line of sight from every candidate position, ``(N, S)`` bool.

    Parameters
    ----------
    buildings : Buildings
        The city model.
    sky : SkyDirections
        The satellites' directions (:func:`~coopnav_env.sim.city.sky_directions`).
    pos_enu_m : ndarray, shape (N, 3)
        Predicted positions [m].
    cov_enu_m2 : ndarray, shape (N, 3, 3)
        Their covariances [m^2].
    margin_sigma : float
        Candidates this many sigma from the prediction, >= 0 (0: the prediction only).
    max_margin_m : float
        Cap on each candidate's displacement [m], >= 0.
    altitude_band_m : (float, float)
        The flight band the altitudes are clamped to [m], low <= high.

    Returns
    -------
    ndarray of bool, shape (N, S)
        True where the satellite is above the horizon and no building blocks it from any
        candidate (:func:`candidate_positions`) outside the buildings; all True for a UAV
        whose candidates are all inside buildings (the map says nothing).

    Notes
    -----
    Box buildings (:class:`~coopnav_env.sim.city.Buildings`) are predicted in one compiled
    call (:func:`_predict_kernel`); a file city's extruded polygons, which that kernel does not
    take, by :func:`_predict_from_candidates`, the same rule written with
    :func:`candidate_positions`, :func:`~coopnav_env.sim.city.is_inside_building` and the
    line of sight. The tests check that the two agree on box cities.
    """
    if not (math.isfinite(margin_sigma) and margin_sigma >= 0.0):
        raise ValueError(f"margin_sigma must be finite and >= 0, got {margin_sigma!r}")
    if not (math.isfinite(max_margin_m) and max_margin_m >= 0.0):
        raise ValueError(f"max_margin_m must be finite and >= 0, got {max_margin_m!r}")
    lo, hi = (float(v) for v in altitude_band_m)
    if not lo <= hi:
        raise ValueError(
            f"altitude_band_m must be (low, high) with low <= high, got {altitude_band_m!r}"
        )
    pos = np.ascontiguousarray(pos_enu_m, dtype=float)
    cov = np.ascontiguousarray(cov_enu_m2, dtype=float)
    n = pos.shape[0]
    if pos.shape != (n, 3) or cov.shape != (n, 3, 3):
        raise ValueError(
            f"pos_enu_m must be (N, 3) and cov_enu_m2 (N, 3, 3), got {pos.shape} and {cov.shape}"
        )
    if not isinstance(buildings, Buildings):  # extruded polygons (sim.file_city)
        return _predict_from_candidates(
            buildings, sky, pos, cov, margin_sigma, max_margin_m, lo, hi
        )
    # the kernel's records (CandidateMargins, SortedSky) as plain tuples
    return _predict_kernel(
        pos,
        cov,
        (float(margin_sigma), float(max_margin_m), lo, hi),
        (buildings.min_m, buildings.max_m),
        (sky.up, sky.order, sky.cot_s, sky.h_dir),
    )


def _predict_from_candidates(
    buildings: Buildings,
    sky: SkyDirections,
    pos: np.ndarray,
    cov: np.ndarray,
    margin_sigma: float,
    max_margin_m: float,
    z_lo: float,
    z_hi: float,
) -> np.ndarray:
    """:func:`predicted_line_of_sight` of validated arguments through
    :func:`candidate_positions`, :func:`~coopnav_env.sim.city.is_inside_building` and the
    line of sight, for any buildings (the path of a file city's extruded polygons, which
    :func:`_predict_kernel` does not take)."""
    n = pos.shape[0]
    cand = candidate_positions(pos, cov, margin_sigma, max_margin_m, (z_lo, z_hi))
    flat = np.ascontiguousarray(cand.reshape(-1, 3))
    possible = ~is_inside_building(buildings, flat).reshape(n, N_CANDIDATES)
    vis = _trace_line_of_sight(buildings, flat, sky).reshape(n, N_CANDIDATES, -1)
    pred = np.all(vis | ~possible[:, :, None], axis=1)
    pred[~possible.any(axis=1)] = True  # the map says nothing
    return pred


class CandidateMargins(NamedTuple):
    """How far the candidates lie from a prediction (:func:`_predict_kernel`)."""

    margin: float  # candidates this many sigma from the prediction (0: the prediction only)
    cap: float  # cap on each candidate's displacement [m]
    z_lo: float  # the flight band the altitudes are clamped to [m]
    z_hi: float


class SortedSky(NamedTuple):
    """The arrays of a :class:`~coopnav_env.sim.city.SkyDirections` (:func:`_predict_kernel`)."""

    up: np.ndarray  # (S,) bool elevation > 0
    order: np.ndarray  # (n_up,) int64 rising satellites by increasing cot(el)
    cot_s: np.ndarray  # (n_up,) sorted cot(el): horizontal distance per metre of climb
    h_dir: np.ndarray  # (n_up, 2) sorted horizontal unit directions (0 at the zenith)


@njit(cache=True)
def _predict_kernel(pos, cov, margins, boxes, sky):
    """:func:`predicted_line_of_sight` in one compiled call: the candidates of
    :func:`candidate_positions` (the 2 x 2 eigen-decomposition in closed form), the inside
    test of :func:`~coopnav_env.sim.city.is_inside_building` and
    :func:`coopnav_env.sim._kernels.line_of_sight` from the candidates.

    Takes the predicted positions ``pos`` (N, 3) ENU [m] and their covariances ``cov`` (N,
    3, 3) [m^2], the record :class:`CandidateMargins`, the box buildings ``(b_lo, b_hi)``
    (each (B, 3) ENU [m]) and the record :class:`SortedSky` (each record may come as a plain
    tuple of its fields)."""
    margin, cap, z_lo, z_hi = margins
    b_lo, b_hi = boxes
    up, order, cot_s, h_dir = sky
    n = pos.shape[0]
    nc = N_CANDIDATES
    cand = np.empty((n * nc, 3))
    for q in range(n):
        a, b, c, v = cov[q, 0, 0], cov[q, 0, 1], cov[q, 1, 1], cov[q, 2, 2]
        b = 0.5 * (b + cov[q, 1, 0])
        finite = math.isfinite(a) and math.isfinite(b) and math.isfinite(c) and math.isfinite(v)
        # major / minor axis (unit vectors) and their displacements
        if finite:
            half_tr = 0.5 * (a + c)
            rad = math.sqrt(0.25 * (a - c) * (a - c) + b * b)
            l_major, l_minor = half_tr + rad, half_tr - rad
            if b != 0.0:
                ex, ey = l_major - c, b
                nrm = math.sqrt(ex * ex + ey * ey)
                ex, ey = ex / nrm, ey / nrm
            elif a >= c:
                ex, ey = 1.0, 0.0
            else:
                ex, ey = 0.0, 1.0
            d_major = min(margin * math.sqrt(max(l_major, 0.0)), cap)
            d_minor = min(margin * math.sqrt(max(l_minor, 0.0)), cap)
            d_up = min(margin * math.sqrt(max(v, 0.0)), cap)
        else:
            ex, ey = 0.0, 1.0  # as candidate_positions: North, then East
            d_major = d_minor = d_up = cap
        base = q * nc
        for j in range(nc):
            cand[base + j, 0] = pos[q, 0]
            cand[base + j, 1] = pos[q, 1]
            cand[base + j, 2] = pos[q, 2]
        # minor axis: the major one turned by 90 degrees
        mx, my = (-ey, ex) if finite else (1.0, 0.0)
        cand[base + 1, 0] += ex * d_major
        cand[base + 1, 1] += ey * d_major
        cand[base + 2, 0] -= ex * d_major
        cand[base + 2, 1] -= ey * d_major
        cand[base + 3, 0] += mx * d_minor
        cand[base + 3, 1] += my * d_minor
        cand[base + 4, 0] -= mx * d_minor
        cand[base + 4, 1] -= my * d_minor
        cand[base + 5, 2] += d_up
        cand[base + 6, 2] -= d_up
        for j in range(nc):
            cand[base + j, 2] = min(max(cand[base + j, 2], z_lo), z_hi)
    s = up.shape[0]
    pred = np.ones((n, s), dtype=np.bool_)
    sub_lo, sub_hi = np.empty_like(b_lo), np.empty_like(b_hi)
    for q in range(n):
        c = cand[q * nc : (q + 1) * nc]
        m = _near_buildings(c, b_lo, b_hi, cot_s, sub_lo, sub_hi)
        vis = _kernels.line_of_sight(c, sub_lo[:m], sub_hi[:m], up, order, cot_s, h_dir)
        any_possible = False
        for j in range(nc):
            inside = False
            for b in range(m):
                if (
                    sub_lo[b, 0] < c[j, 0] < sub_hi[b, 0]
                    and sub_lo[b, 1] < c[j, 1] < sub_hi[b, 1]
                    and sub_lo[b, 2] < c[j, 2] < sub_hi[b, 2]
                ):
                    inside = True
                    break
            if inside:
                continue
            any_possible = True
            for k in range(s):
                if not vis[j, k]:
                    pred[q, k] = False
        if not any_possible:  # the map says nothing
            for k in range(s):
                pred[q, k] = True
    return pred


@njit(cache=True, error_model="numpy")
def _near_buildings(cand, b_lo, b_hi, cot_s, sub_lo, sub_hi):
    """Copies into ``sub_lo, sub_hi`` the buildings that may matter to one UAV's candidates
    ``cand`` (k, 3) and returns their number: every building except those that
    :func:`coopnav_env.sim._kernels.blocked_sorted` skips for every candidate (no roof above
    it, or its footprint beyond the reach of the lowest rising ray: the skip tested on the
    candidates' bounding box, which bounds each candidate's test, as rounding is monotone and
    ``hypot(x, y) >= max(x, y)``), and those contain no candidate either. So the line of sight
    and the inside test on the subset are those on all buildings, at a fraction of the cost
    (the candidates lie within ``2 max_margin_m`` of each other). With no rising satellite
    (or a negative cotangent) or a candidate that is not finite, all buildings."""
    m = b_lo.shape[0]
    x_lo = y_lo = z_lo = np.inf
    x_hi = y_hi = -np.inf
    finite = True
    for j in range(cand.shape[0]):
        x, y, z = cand[j, 0], cand[j, 1], cand[j, 2]
        finite = finite and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
        x_lo, x_hi = min(x_lo, x), max(x_hi, x)
        y_lo, y_hi = min(y_lo, y), max(y_hi, y)
        z_lo = min(z_lo, z)
    n_up = cot_s.shape[0]
    cot_max = cot_s[n_up - 1] if n_up > 0 else 0.0
    cull = finite and n_up > 0 and cot_max >= 0.0
    k = 0
    for b in range(m):
        if cull:
            climb = b_hi[b, 2] - z_lo  # >= each candidate's climb
            if not climb > 0.0:
                continue
            # <= each candidate's horizontal distance to the footprint (_fmax as numpy's)
            ddx = max(max(b_lo[b, 0] - x_hi, 0.0), x_lo - b_hi[b, 0])
            ddy = max(max(b_lo[b, 1] - y_hi, 0.0), y_lo - b_hi[b, 1])
            if max(ddx, ddy) > climb * cot_max:
                continue
        for a in range(3):
            sub_lo[k, a] = b_lo[b, a]
            sub_hi[k, a] = b_hi[b, a]
        k += 1
    return k
