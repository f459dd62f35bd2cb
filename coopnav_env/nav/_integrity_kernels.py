r"""Compiled (numba) kernels of the integrity monitor (:mod:`coopnav_env.nav.integrity`).

Three groups:

* **Distributions** (no scipy at run time): the regularised incomplete gamma function
  (series / Lentz continued fraction), the chi-square upper quantile (Wilson-Hilferty start,
  safeguarded Newton on ``log Q``), the non-central chi-square CDF (Poisson mixture summed
  downward from its upper end, where the recurrence adds positive terms only) and the
  non-centrality whose CDF at a threshold is a given missed-detection probability
  (safeguarded Newton with ``dF/dlambda = (F_{k+2} - F_k) / 2``); the standard normal
  quantile (Acklam's rational start, one Halley step on ``erfc``). The tests compare every
  one with scipy.
* **Statistics of one fix** (:func:`problem_statistics`): the weighted sum of squared
  residuals ``T = a^T R a``, its degrees of freedom, Baarda's normalised residuals
  ``w_i = (R a)_i / sqrt(R_ii)``, and each measurement's position gain ``K_i`` (the shift of
  the fix per metre of bias on it) projected horizontally and vertically per unit
  ``sqrt(R_ii)`` (the RAIM slopes), where ``R = P~ - P~ A (A^T P~ A)^-1 A^T P~`` is the
  residual projector of the GLS with the exact structured covariance ``C*`` (every UAV's
  clocks eliminated; see :mod:`coopnav_env.nav.integrity`). ``C*`` is never formed: the
  elimination is that of ``cooperative._structured_normal`` (per-UAV clocks and rank-3
  relative errors per block, then one ``S' x S'`` solve for the errors common to all UAVs,
  over the ``S'`` satellites the fix uses), kept here per row because the per-row quantities
  need the blocks themselves. A standalone fix (diagonal covariance) has its own ``O(m)``
  path, :func:`standalone_statistics`. Their measurements come as the records
  :class:`FixRows` (:class:`ReceiverRows` for one receiver) and the fix as :class:`FixPoint`.
* **FDE loops** (:func:`standalone_fde`, :func:`cooperative_fde`): test, identify, exclude,
  re-solve with the solvers' own kernels, until the test passes or redundancy runs out.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from coopnav_env.nav._kernels import (
    Measured,
    Problems,
    ProblemSetup,
    Solved,
    Transferred,
    cooperative_finish,
    cooperative_gauss_newton,
    n_nuisance,
    setup_masks,
    standalone_solve,
)

# integrity statuses (coopnav_env.nav.integrity.IntegrityStatus)
INT_OK = 0
INT_EXCLUDED = 1
INT_FAULT_DETECTED = 2
INT_NO_REDUNDANCY = 3
INT_NO_FIX = 4
# NavStatus.OK and NavStatus.FAULT_DETECTED
_NAV_OK = 0
_NAV_FAULT = 6

#: a row whose residual variance ``R_ii`` is below this fraction of its own weight carries no
#: redundancy (a fault on it cannot be seen in the residuals)
UNOBSERVABLE_RII = 1e-9
#: ... and a fault on such a row that moves the fix by less than this [m per m of bias] is
#: harmless (it is absorbed by a clock)
HARMLESS_GAIN = 1e-6
#: normalised residuals equal to this relative tolerance are a tie: structurally
#: indistinguishable rows (e.g. the only two satellites of a constellation at the clock
#: reference: a bias on one and the opposite bias on the other leave the same residuals); the
#: tie goes to the positive residual, the sign of an NLOS bias
TIE_RTOL = 1e-9
#: the figures of a test that could not run (normal matrix not positive definite):
#: ``t_stat, dof, q_star, k_star, w_star, h_slope, v_slope``
_FAILED = (np.nan, 0, -1, -1, np.nan, np.inf, np.inf)


# --------------------------------------------------------------------------------------------
# distributions
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _gamma_p_series(a, x):
    """Lower regularised gamma ``P(a, x)`` by its series (for ``x < a + 1``)."""
    if x <= 0.0:
        return 0.0
    ap = a
    term = 1.0 / a
    total = term
    for _ in range(100000):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * 1e-17:
            break
    return total * math.exp(-x + a * math.log(x) - math.lgamma(a))


@njit(cache=True)
def _gamma_q_fraction(a, x):
    """Upper regularised gamma ``Q(a, x)`` by Lentz's continued fraction (``x >= a + 1``)."""
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        if abs(d) < tiny:
            d = tiny
        c = b + an / c
        if abs(c) < tiny:
            c = tiny
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    return math.exp(-x + a * math.log(x) - math.lgamma(a)) * h


@njit(cache=True)
def gamma_p(a, x):
    """Lower regularised incomplete gamma function ``P(a, x)``, ``a > 0``."""
    if x <= 0.0:
        return 0.0
    if x < a + 1.0:
        return _gamma_p_series(a, x)
    return 1.0 - _gamma_q_fraction(a, x)


@njit(cache=True)
def gamma_q(a, x):
    """Upper regularised incomplete gamma function ``Q(a, x) = 1 - P(a, x)``, ``a > 0``."""
    if x <= 0.0:
        return 1.0
    if x < a + 1.0:
        return 1.0 - _gamma_p_series(a, x)
    return _gamma_q_fraction(a, x)


@njit(cache=True)
def chi2_sf(x, k):
    """Survival function of the chi-square distribution with ``k`` degrees of freedom."""
    return gamma_q(0.5 * k, 0.5 * x)


@njit(cache=True)
def norm_ppf(p):
    """Standard normal quantile, ``0 < p < 1`` (Acklam's approximation + one Halley step)."""
    a1, a2, a3 = -3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02
    a4, a5, a6 = 1.383577518672690e02, -3.066479806614716e01, 2.506628277459239e00
    b1, b2, b3 = -5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02
    b4, b5 = 6.680131188771972e01, -1.328068155288572e01
    c1, c2, c3 = -7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00
    c4, c5, c6 = -2.549732539343734e00, 4.374664141464968e00, 2.938163982698783e00
    d1, d2, d3 = 7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00
    d4 = 3.754408661907416e00
    p_low = 0.02425
    if p < p_low:
        q = math.sqrt(-2.0 * math.log(p))
        x = (((((c1 * q + c2) * q + c3) * q + c4) * q + c5) * q + c6) / (
            (((d1 * q + d2) * q + d3) * q + d4) * q + 1.0
        )
    elif p <= 1.0 - p_low:
        q = p - 0.5
        r = q * q
        x = (
            (((((a1 * r + a2) * r + a3) * r + a4) * r + a5) * r + a6)
            * q
            / (((((b1 * r + b2) * r + b3) * r + b4) * r + b5) * r + 1.0)
        )
    else:
        q = math.sqrt(-2.0 * math.log(1.0 - p))
        x = -(((((c1 * q + c2) * q + c3) * q + c4) * q + c5) * q + c6) / (
            (((d1 * q + d2) * q + d3) * q + d4) * q + 1.0
        )
    # one Halley step on Phi(x) - p, Phi from erfc (accurate in both tails)
    e = 0.5 * math.erfc(-x / math.sqrt(2.0)) - p
    u = e * math.sqrt(2.0 * math.pi) * math.exp(0.5 * x * x)
    return x - u / (1.0 + 0.5 * x * u)


@njit(cache=True)
def chi2_isf(p, k):
    """Upper quantile of the chi-square distribution: ``x`` with ``Q(k/2, x/2) = p``.

    Wilson-Hilferty start, then Newton on ``log Q`` (the density over ``Q`` is its
    derivative), safeguarded by bisection inside a bracket that every step narrows.
    """
    z = -norm_ppf(p)
    h = 2.0 / (9.0 * k)
    x = k * (1.0 - h + z * math.sqrt(h)) ** 3
    if not x > 0.0:
        x = 0.5 * k
    lo, hi = 0.0, math.inf
    a = 0.5 * k
    target = math.log(p)
    for _ in range(200):
        q = chi2_sf(x, k)
        if q > p:
            lo = x
        else:
            hi = x
        if q <= 0.0:  # far in the tail: step back
            x = 0.5 * (lo + x)
            continue
        f = math.log(q) - target
        dens = math.exp((a - 1.0) * math.log(0.5 * x) - 0.5 * x - math.lgamma(a)) * 0.5
        step = f / (dens / q)  # Newton on log Q: f' = -dens / Q
        x_new = x + step
        if not (lo < x_new < hi):
            x_new = 0.5 * (lo + hi) if hi < math.inf else 2.0 * x
        if abs(x_new - x) <= 1e-14 * x:
            return x_new
        x = x_new
    return x


@njit(cache=True)
def ncx2_cdf(x, k, lam):
    """CDF of the non-central chi-square distribution (``k`` degrees of freedom,
    non-centrality ``lam``) at ``x``: the Poisson(``lam / 2``) mixture of central CDFs.

    ``P(a + j, y)`` is computed once at the upper end of the sum by its own series or
    fraction and recurred downward, ``P(a, y) = P(a + 1, y) + y^a e^-y / Gamma(a + 1)``,
    which adds positive terms only (stable even where the CDF is tiny).
    """
    if x <= 0.0:
        return 0.0
    a = 0.5 * k
    y = 0.5 * x
    if lam <= 0.0:
        return gamma_p(a, y)
    h = 0.5 * lam
    j_hi = int(h + 12.0 * math.sqrt(h) + 40.0)
    p_j = gamma_p(a + j_hi, y)
    log_y = math.log(y)
    log_h = math.log(h)
    total = 0.0
    for j in range(j_hi, -1, -1):
        if j < j_hi:
            aj = a + j
            p_j += math.exp(aj * log_y - y - math.lgamma(aj + 1.0))
        total += math.exp(-h + j * log_h - math.lgamma(j + 1.0)) * p_j
    return min(total, 1.0)


@njit(cache=True)
def ncx2_lambda(x, k, p_md):
    """The non-centrality ``lam`` with ``ncx2_cdf(x, k, lam) = p_md`` (0 if already below).

    The CDF falls with ``lam``; Newton on ``log F`` with ``dF/dlam = (F_{k+2} - F_k) / 2``,
    safeguarded by bisection in a bracket found by doubling.
    """
    if ncx2_cdf(x, k, 0.0) <= p_md:
        return 0.0
    lo = 0.0
    hi = max(1.0, (math.sqrt(x) - norm_ppf(p_md)) ** 2)
    while ncx2_cdf(x, k, hi) > p_md:
        lo = hi
        hi *= 2.0
    lam = 0.5 * (lo + hi)
    target = math.log(p_md)
    for _ in range(200):
        f_k = ncx2_cdf(x, k, lam)
        if f_k > p_md:
            lo = lam
        else:
            hi = lam
        if f_k <= 0.0:
            lam_new = 0.5 * (lo + hi)
        else:
            deriv = 0.5 * (ncx2_cdf(x, k + 2.0, lam) - f_k)  # < 0
            g = math.log(f_k) - target
            lam_new = lam - g * f_k / deriv if deriv < 0.0 else 0.5 * (lo + hi)
            if not (lo < lam_new < hi):
                lam_new = 0.5 * (lo + hi)
        if abs(lam_new - lam) <= 1e-13 * max(lam, 1.0) or hi - lo <= 1e-13 * max(hi, 1.0):
            return lam_new
        lam = lam_new
    return lam


@njit(cache=True)
def threshold_tables(p_fa, p_md, dof_max):
    """``thr[d]`` (chi-square threshold for false-alarm ``p_fa``) and ``lam[d]`` (the
    non-centrality detected with probability ``1 - p_md``) for ``d = 0 .. dof_max``
    (entry 0 is NaN: no test)."""
    thr = np.full(dof_max + 1, np.nan)
    lam = np.full(dof_max + 1, np.nan)
    for d in range(1, dof_max + 1):
        thr[d] = chi2_isf(p_fa, float(d))
        lam[d] = ncx2_lambda(thr[d], float(d), p_md)
    return thr, lam


# --------------------------------------------------------------------------------------------
# statistics of one fix
# --------------------------------------------------------------------------------------------
#
# Reference counting. numba counts references to every array a function binds (atomic
# increments and decrements, about as costly as the arithmetic of these small problems) and
# removes the pairs it can prove redundant; it cannot when an array dies in the middle of the
# function (numba releases it after its last use, at a loop exit that LLVM has duplicated) or
# when a path leaves the function early (a ``return`` inside the computation, or an exception:
# Python's float division raises on a zero divisor, and a call to another compiled function
# may raise). The statistics kernels below therefore use ``error_model="numpy"`` (a zero
# divisor gives inf / NaN, for every other divisor the quotient is the same bit for bit),
# call only inlined helpers before their end, return at the end only, and keep their arrays
# alive to the end (:func:`keep_alive`), which lets numba remove every pair.


@njit(cache=True)
def keep_alive(*arrays):
    """Does nothing with ``arrays``: a last use at the end of a kernel, so that numba releases
    them there (see the note above)."""
    return None


@njit(cache=True, inline="always", error_model="numpy")
def cholesky_inverse3(a00, a10, a11, a20, a21, a22):
    """:func:`coopnav_env.nav._kernels._cholesky_inverse_into` of a symmetric 3x3 matrix
    given by its lower triangle, in scalars (no arrays): the same operations in the same
    order, so the same result bit for bit (``tests/nav/test_integrity.py``). Returns ``ok,
    o00, o01, o02, o11, o12, o22`` (the inverse's upper triangle; NaN when not positive
    definite)."""
    nan = np.nan
    s = a00
    if not s > 0.0:
        return False, nan, nan, nan, nan, nan, nan
    d = math.sqrt(s)
    l00 = d
    l10 = a10 / d
    l20 = a20 / d
    s = a11
    s -= l10 * l10
    if not s > 0.0:
        return False, nan, nan, nan, nan, nan, nan
    d = math.sqrt(s)
    l11 = d
    s = a21
    s -= l20 * l10
    l21 = s / d
    s = a22
    s -= l20 * l20
    s -= l21 * l21
    if not s > 0.0:
        return False, nan, nan, nan, nan, nan, nan
    l22 = math.sqrt(s)
    v00 = 1.0 / l00  # inv(L), column by column
    s = 0.0
    s -= l10 * v00
    v10 = s / l11
    s = 0.0
    s -= l20 * v00
    s -= l21 * v10
    v20 = s / l22
    v11 = 1.0 / l11
    s = 0.0
    s -= l21 * v11
    v21 = s / l22
    v22 = 1.0 / l22
    o00 = 0.0  # inv(a)[i, j] = sum_{k >= j} inv(L)[k, i] inv(L)[k, j]
    o00 += v00 * v00
    o00 += v10 * v10
    o00 += v20 * v20
    o01 = 0.0
    o01 += v10 * v11
    o01 += v20 * v21
    o02 = 0.0
    o02 += v20 * v22
    o11 = 0.0
    o11 += v11 * v11
    o11 += v21 * v21
    o12 = 0.0
    o12 += v21 * v22
    o22 = 0.0
    o22 += v22 * v22
    return True, o00, o01, o02, o11, o12, o22


@njit(cache=True, inline="always", error_model="numpy")
def _solve3(inverse, r, apa):
    """``x = info^-1 r`` and the test statistic ``T = a^T P a - r^T x`` (0 where rounding
    makes a (near) zero statistic negative). ``inverse``: ``info^-1`` by its upper triangle
    ``(o00, o01, o02, o11, o12, o22)`` (as :func:`cholesky_inverse3` returns it after
    ``ok``); ``r``: ``(r0, r1, r2)``; ``apa``: ``a^T P a``."""
    o00, o01, o02, o11, o12, o22 = inverse
    r0, r1, r2 = r
    x0 = o00 * r0 + o01 * r1 + o02 * r2
    x1 = o01 * r0 + o11 * r1 + o12 * r2
    x2 = o02 * r0 + o12 * r1 + o22 * r2
    t_stat = apa
    t_stat -= r0 * x0
    t_stat -= r1 * x1
    t_stat -= r2 * x2
    if t_stat < 0.0:
        t_stat = 0.0
    return x0, x1, x2, t_stat


@njit(cache=True, inline="always", error_model="numpy")
def inverse3_sym(a, b, c, d, e, f):
    """:func:`coopnav_env.nav._kernels._inv3` in scalars: the closed-form inverse of the
    symmetric matrix ``[[a, b, c], [b, d, e], [c, e, f]]``, the same operations (bit for
    bit). Returns its upper triangle ``o00, o01, o02, o11, o12, o22``."""
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    return c00 / det, c01 / det, c02 / det, c11 / det, c12 / det, c22 / det


@njit(cache=True)
def workspace(n, s):
    """Scratch arrays of :func:`_statistics` for ``n`` UAVs and ``s`` satellites: views of one
    float and one integer buffer (allocated once per FDE call, reused by every fix it
    tests)."""
    sm = max(s, 3)
    shapes = (
        (n, s, 4),  # a_x: [A | a]
        (n, s, s),  # pq
        (n, s, 4),  # pax
        (n, s, 4),  # ptx
        (n, s, 1),  # ptd
        (s, 3, 1),  # lam
        (s, 3, 1),  # p0l
        (s, 3, 1),  # g3
        (s, 1, 1),  # wrow
        (s, s, 1),  # mg (the compact S' x S' system in its leading block)
        (s, s, 1),  # mgi
        (s, 4, 1),  # u_mat
        (s, 4, 1),  # v_mat
        (s, 4, 1),  # vloc
        (s, s, 1),  # mloc
        (s, s, 1),  # bq
        (sm, sm, 1),  # low (Cholesky scratch)
        (sm, sm, 1),  # linv
        (3, 4, 1),  # t3
        (s, 1, 1),  # ddiag
    )
    total = 0
    for a, b, c in shapes:
        total += a * b * c
    buf = np.empty(total)
    ints = np.empty(s + 1 + n + n * s + s, dtype=np.int64)
    o = np.zeros(len(shapes) + 1, dtype=np.int64)
    for i in range(len(shapes)):
        a, b, c = shapes[i]
        o[i + 1] = o[i] + a * b * c
    return (
        ints[: s + 1],  # gs: a block's constellation row ranges
        ints[s + 1 : s + 1 + n],  # m_q
        ints[s + 1 + n : s + 1 + n + n * s].reshape((n, s)),  # idx
        buf[o[0] : o[1]].reshape((n, s, 4)),
        buf[o[1] : o[2]].reshape((n, s, s)),
        buf[o[2] : o[3]].reshape((n, s, 4)),
        buf[o[3] : o[4]].reshape((n, s, 4)),
        buf[o[4] : o[5]].reshape((n, s)),
        buf[o[5] : o[6]].reshape((s, 3)),
        buf[o[6] : o[7]].reshape((s, 3)),
        buf[o[7] : o[8]].reshape((s, 3)),
        buf[o[8] : o[9]],
        buf[o[9] : o[10]].reshape((s, s)),
        buf[o[10] : o[11]].reshape((s, s)),
        buf[o[11] : o[12]].reshape((s, 4)),
        buf[o[12] : o[13]].reshape((s, 4)),
        buf[o[13] : o[14]].reshape((s, 4)),
        buf[o[14] : o[15]].reshape((s, s)),
        buf[o[15] : o[16]].reshape((s, s)),
        buf[o[16] : o[17]].reshape((sm, sm)),
        buf[o[17] : o[18]].reshape((sm, sm)),
        ints[s + 1 + n + n * s :],  # loc
        buf[o[18] : o[19]].reshape((3, 4)),
        buf[o[19] : o[20]],
    )


class FixRows(NamedTuple):
    """The measurements of a fix under test and their error model (:func:`problem_statistics`)."""

    pr: np.ndarray  # (N, S) pseudoranges [m] (any value where rows is False)
    sv: np.ndarray  # (S, 3) satellite positions, ECEF [m]
    system: np.ndarray  # (S,) int64 constellation index, sorted
    n_sys: int  # constellations (clock states)
    rows: np.ndarray  # (N, S) bool the measurements of the fix
    w: np.ndarray  # (N, S) inverse variance of each row's per-receiver error [1/m^2]
    sig_c: np.ndarray  # (S,) sigma of the errors common to all receivers [m] (all zero: none)


class FixPoint(NamedTuple):
    """Where a fix is linearised: its position and its UAVs' relative positions
    (:func:`problem_statistics`)."""

    pos: np.ndarray  # (3,) the fix (centroid) position, ECEF [m]
    base: np.ndarray  # (N, 3) offsets of the UAVs from pos, ECEF [m]
    froot: np.ndarray  # (N, 3, 3) roots of their relative-position error covariances [m]


@njit(cache=True)
def problem_statistics(fix_rows, point, rot, positive_only):
    """Residual test quantities of one GLS fix (a receiver's or a centroid problem's).

    Model (the undifferenced form of ``cooperative._linearize``): row ``(q, k)`` is UAV
    ``q``'s pseudorange to satellite ``k`` with design ``-u_qk`` (position) at
    ``pos + base[q]`` and the error ``e_c^k + e_u,qk + u_qk . F_q z_q`` (``sig_c``, ``1 / w``,
    ``froot``). Every UAV has one flat-prior clock per constellation it has rows of, all
    eliminated as nuisance parameters. The solvers estimate the clock reference's clocks
    instead (and the others relative to it); the column space is the same, so the residuals,
    the statistic and the position gains are too, and no clock estimate is needed here.

    Parameters
    ----------
    fix_rows : FixRows
        The fix's pseudoranges ``pr``, satellites, rows and weights (or a plain tuple of
        its fields).
    point : FixPoint
        The fix position ``pos`` and the UAVs' offsets ``base`` and relative-error roots
        ``froot`` (or a plain tuple of its fields).
    rot : (3, 3) ECEF -> local ENU rotation (horizontal / vertical split)
    positive_only : identify among positive residuals only (faults known to be positive
        range biases, as NLOS reception)

    Returns
    -------
    ok, t_stat, dof, q_star, k_star, w_star, h_slope, v_slope
        ``ok`` False when the normal matrix is not positive definite. ``q_star, k_star``:
        the row with the largest ``|w_i|`` among the observable ones (with
        ``positive_only``: among those with a positive residual) (-1 if none; an exact tie
        goes to a positive residual, see :data:`TIE_RTOL`), ``w_star`` its ``|w_i|``.
        ``h_slope, v_slope``: the largest horizontal / vertical position gain per unit
        ``sqrt(non-centrality)``, ``|K_i| / sqrt(R_ii)`` (inf when an unobservable row moves
        the fix).
    """
    n, s = fix_rows[4].shape
    return _statistics(workspace(n, s), fix_rows, point, rot, positive_only)


@njit(cache=True, error_model="numpy")
def _statistics(ws, fix_rows, point, rot, positive_only):
    """:func:`problem_statistics` in the scratch arrays ``ws`` (:func:`workspace`).

    Written for the compiler as much as for the reader: no array views, no ``continue`` or
    ``return`` inside a loop (either keeps numba from pruning the reference counting of the
    arrays, which otherwise costs more than the arithmetic on these small problems), and
    every sum accumulated over its index in increasing order, with the loops nested so that
    the innermost one updates independent entries (no serial chain of additions).
    """
    (
        gs,
        m_q,
        idx,
        a_x,
        pq,
        pax,
        ptx,
        ptd,
        lam,
        p0l,
        g3,
        wrow,
        mg,
        mgi,
        u_mat,
        v_mat,
        vloc,
        mloc,
        bq,
        low,
        linv,
        loc,
        t3,
        ddiag,
    ) = ws
    pr, sv, system, n_sys, rows, w, sig_c = fix_rows
    pos, base, froot = point
    n, s = rows.shape
    for q in range(n):
        m_q[q] = 0
        for k in range(s):
            if rows[q, k]:
                idx[q, m_q[q]] = k
                m_q[q] += 1
    common = False
    for k in range(s):
        if sig_c[k] != 0.0:
            common = True
    # a_x: [A | a] per block row; pq: P_q, the block precision with the clocks and the
    # relative-error latent eliminated; pax: P_q [A | a]. A block's rows follow the
    # satellite order, so the rows of one constellation are contiguous: [gs[j], gs[j + 1]).
    n_rows = 0
    n_clocks = 0
    for q in range(n):
        mq = m_q[q]
        n_rows += mq
        i = 0
        for j in range(n_sys + 1):
            while i < mq and system[idx[q, i]] < j:
                i += 1
            gs[j] = i
        for i in range(mq):
            k = idx[q, i]
            d0 = sv[k, 0] - (pos[0] + base[q, 0])
            d1 = sv[k, 1] - (pos[1] + base[q, 1])
            d2 = sv[k, 2] - (pos[2] + base[q, 2])
            rng = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            u0, u1, u2 = d0 / rng, d1 / rng, d2 / rng
            for j in range(3):
                lam[i, j] = u0 * froot[q, 0, j] + u1 * froot[q, 1, j] + u2 * froot[q, 2, j]
            a_x[q, i, 0] = -u0
            a_x[q, i, 1] = -u1
            a_x[q, i, 2] = -u2
            a_x[q, i, 3] = pr[q, k] - rng
            wrow[i] = w[q, k]
            for i2 in range(mq):
                pq[q, i, i2] = 0.0
            pq[q, i, i] = wrow[i]
        # 1. the clocks: P0 = W - W N (N^T W N)^-1 N^T W, one group per constellation
        for j in range(n_sys):
            i0, i1 = gs[j], gs[j + 1]
            if i1 > i0:
                n_clocks += 1
                dsum = 0.0
                amean = 0.0
                for i in range(i0, i1):
                    dsum += wrow[i]
                    amean += wrow[i] * a_x[q, i, 3]
                # remove the group's weighted mean from the residuals (its clock, tens of
                # km): a shift along a clock column leaves R a unchanged, and costs no
                # digits in T
                amean /= dsum
                for i in range(i0, i1):
                    a_x[q, i, 3] -= amean
                # P0 [A | a] = W X - w (w^T X) / d over the group
                acc0 = acc1 = acc2 = acc3 = 0.0
                for i in range(i0, i1):
                    wi = wrow[i]
                    acc0 += wi * a_x[q, i, 0]
                    acc1 += wi * a_x[q, i, 1]
                    acc2 += wi * a_x[q, i, 2]
                    acc3 += wi * a_x[q, i, 3]
                acc0 /= dsum
                acc1 /= dsum
                acc2 /= dsum
                acc3 /= dsum
                for i in range(i0, i1):
                    wi = wrow[i]
                    pax[q, i, 0] = wi * (a_x[q, i, 0] - acc0)
                    pax[q, i, 1] = wi * (a_x[q, i, 1] - acc1)
                    pax[q, i, 2] = wi * (a_x[q, i, 2] - acc2)
                    pax[q, i, 3] = wi * (a_x[q, i, 3] - acc3)
                for i in range(i0, i1):
                    f = wrow[i] / dsum
                    for i2 in range(i0, i1):
                        pq[q, i, i2] -= f * wrow[i2]
        # 2. rank-3 relative-error latent: P_q = P0 - P0 lam (I + lam^T P0 lam)^-1 lam^T P0
        has_rel = False
        for a_ in range(3):
            for c in range(3):
                if froot[q, a_, c] != 0.0:
                    has_rel = True
        if has_rel and mq > 0:
            for j in range(n_sys):  # P0 lam = W lam - w (w^T lam) / d over each group
                i0, i1 = gs[j], gs[j + 1]
                if i1 > i0:
                    dsum = 0.0
                    for i in range(i0, i1):
                        dsum += wrow[i]
                    acc0 = acc1 = acc2 = 0.0
                    for i in range(i0, i1):
                        wi = wrow[i]
                        acc0 += wi * lam[i, 0]
                        acc1 += wi * lam[i, 1]
                        acc2 += wi * lam[i, 2]
                    acc0 /= dsum
                    acc1 /= dsum
                    acc2 /= dsum
                    for i in range(i0, i1):
                        wi = wrow[i]
                        p0l[i, 0] = wi * (lam[i, 0] - acc0)
                        p0l[i, 1] = wi * (lam[i, 1] - acc1)
                        p0l[i, 2] = wi * (lam[i, 2] - acc2)
            # m3 = I + lam^T P0 lam (its upper triangle: what the inverse reads) and
            # t3 = (P0 lam)^T [A | a] (P_q [A | a] = P0 [A | a] - g3 t3, g3 = P0 lam m3^-1)
            m00 = m11 = m22 = 1.0
            m01 = m02 = m12 = 0.0
            for j in range(3):
                for c in range(4):
                    t3[j, c] = 0.0
            for i in range(mq):
                l0, l1, l2 = lam[i, 0], lam[i, 1], lam[i, 2]
                e0, e1, e2 = p0l[i, 0], p0l[i, 1], p0l[i, 2]
                m00 += l0 * e0
                m01 += l0 * e1
                m02 += l0 * e2
                m11 += l1 * e1
                m12 += l1 * e2
                m22 += l2 * e2
                for c in range(4):
                    x = a_x[q, i, c]
                    t3[0, c] += e0 * x
                    t3[1, c] += e1 * x
                    t3[2, c] += e2 * x
            i00, i01, i02, i11, i12, i22 = inverse3_sym(m00, m01, m02, m11, m12, m22)
            for i in range(mq):
                e0, e1, e2 = p0l[i, 0], p0l[i, 1], p0l[i, 2]
                g3[i, 0] = e0 * i00 + e1 * i01 + e2 * i02
                g3[i, 1] = e0 * i01 + e1 * i11 + e2 * i12
                g3[i, 2] = e0 * i02 + e1 * i12 + e2 * i22
            for i in range(mq):
                for c in range(4):
                    pax[q, i, c] -= g3[i, 0] * t3[0, c] + g3[i, 1] * t3[1, c] + g3[i, 2] * t3[2, c]
                for i2 in range(mq):
                    pq[q, i, i2] -= (
                        g3[i, 0] * p0l[i2, 0] + g3[i, 1] * p0l[i2, 1] + g3[i, 2] * p0l[i2, 2]
                    )
    # 3. errors common to all receivers: P~ = Pblk - Pblk E (I + E^T Pblk E)^-1 E^T Pblk;
    # ptx: P~ [A | a] per row, ptd: diag(P~)
    for q in range(n):
        for i in range(m_q[q]):
            ptd[q, i] = pq[q, i, i]
            for c in range(4):
                ptx[q, i, c] = pax[q, i, c]
    ok = True
    if common:
        # the latent common errors of the satellites the fix uses (loc: their index in the
        # compact S' x S' system, the leading block of mg; the other columns of E are zero)
        sl = 0
        for k in range(s):
            loc[k] = -1
        for q in range(n):
            for i in range(m_q[q]):
                k = idx[q, i]
                if loc[k] < 0 and sig_c[k] != 0.0:
                    loc[k] = 0
        for k in range(s):
            if loc[k] == 0:
                loc[k] = sl
                sl += 1
        for k in range(sl):
            for k2 in range(sl):
                mg[k, k2] = 0.0
            mg[k, k] = 1.0
            for c in range(4):
                u_mat[k, c] = 0.0  # u_mat: E^T Pblk [A | a]
        for q in range(n):
            for i in range(m_q[q]):
                k = idx[q, i]
                lk = loc[k]
                if lk >= 0:
                    for i2 in range(m_q[q]):
                        k2 = idx[q, i2]
                        if loc[k2] >= 0:
                            mg[lk, loc[k2]] += sig_c[k] * pq[q, i, i2] * sig_c[k2]
                    for c in range(4):
                        u_mat[lk, c] += sig_c[k] * pax[q, i, c]
        # mgi = mg^-1 by Cholesky: nav._kernels._cholesky_inverse_into's sums in its order
        # (the same result bit for bit), with the loops nested so that the innermost one
        # updates independent entries; written out here because a call in the middle of
        # this kernel would bring back its reference counting (see the note above)
        for j in range(sl):
            s_ = 0.0
            if ok:
                s_ = mg[j, j]
                for k in range(j):
                    s_ -= low[j, k] * low[j, k]
                ok = s_ > 0.0
            if ok:
                d = math.sqrt(s_)
                low[j, j] = d
                for i in range(j + 1, sl):  # (mg[i, j] - sum_k low[i, k] low[j, k]) / d
                    low[i, j] = mg[i, j]
                for k in range(j):
                    f = low[j, k]
                    for i in range(j + 1, sl):
                        low[i, j] -= low[i, k] * f
                for i in range(j + 1, sl):
                    low[i, j] /= d
        if ok:
            # inverse of the factor, column by column (forward substitution):
            # linv[i, j] = (-sum_{k = j .. i-1} low[i, k] linv[k, j]) / low[i, i]
            for j in range(sl):
                linv[j, j] = 1.0 / low[j, j]
                for i in range(j + 1, sl):
                    linv[i, j] = 0.0
                for k in range(j, sl):
                    if k > j:
                        linv[k, j] /= low[k, k]
                    f = linv[k, j]
                    for i in range(k + 1, sl):
                        linv[i, j] -= low[i, k] * f
            # mgi[i, j] = sum_{k = j .. sl-1} linv[k, i] linv[k, j] (j >= i), symmetric
            for i in range(sl):
                for j in range(i, sl):
                    mgi[i, j] = 0.0
                for k in range(i, sl):
                    f = linv[k, i]
                    for j in range(i, k + 1):
                        mgi[i, j] += f * linv[k, j]
                for j in range(i + 1, sl):
                    mgi[j, i] = mgi[i, j]
            for k in range(sl):  # v_mat: (I + E^T Pblk E)^-1 E^T Pblk [A | a]
                for c in range(4):
                    v_mat[k, c] = 0.0
                for k2 in range(sl):
                    f = mgi[k, k2]
                    for c in range(4):
                        v_mat[k, c] += f * u_mat[k2, c]
            # per block, with local (contiguous) copies: Vloc = Sigma V[sats], Mloc = Sigma
            # Mginv[sats, sats] Sigma; P~ [A | a] = P_q [A | a] - P_q Vloc and
            # diag(P~) = diag(P_q) - diag(P_q Mloc P_q)
            for q in range(n):
                mq = m_q[q]
                for i in range(mq):
                    lk = loc[idx[q, i]]
                    if lk < 0:
                        for c in range(4):
                            vloc[i, c] = 0.0
                        for i2 in range(mq):
                            mloc[i, i2] = 0.0
                    else:
                        sk = sig_c[idx[q, i]]
                        for c in range(4):
                            vloc[i, c] = sk * v_mat[lk, c]
                        for i2 in range(mq):
                            lk2 = loc[idx[q, i2]]
                            mloc[i, i2] = 0.0 if lk2 < 0 else sk * mgi[lk, lk2] * sig_c[idx[q, i2]]
                for i2 in range(mq):  # P~ [A | a] = P_q [A | a] - P_q Vloc
                    for i in range(mq):
                        f = pq[q, i, i2]
                        for c in range(4):
                            ptx[q, i, c] -= f * vloc[i2, c]
                for i in range(mq):  # bq = P_q Mloc
                    for i2 in range(mq):
                        bq[i, i2] = 0.0
                    for i3 in range(mq):
                        f = pq[q, i, i3]
                        for i2 in range(mq):
                            bq[i, i2] += f * mloc[i3, i2]
                for i in range(mq):  # diag(P_q Mloc P_q), staged in ddiag
                    ddiag[i] = 0.0
                for i2 in range(mq):
                    for i in range(mq):
                        ddiag[i] += bq[i, i2] * pq[q, i2, i]
                for i in range(mq):
                    ptd[q, i] -= ddiag[i]
    # normal equations (info = A^T P~ A, r = A^T P~ a) and the residual projector
    # R = P~ - P~ A info^-1 A^T P~
    t_stat = np.nan
    state = (0.0, 0.0, -1, -1, 0.0, False)
    if ok:
        f00 = f01 = f02 = f10 = f11 = f12 = f20 = f21 = f22 = 0.0
        r0 = r1 = r2 = 0.0
        apa = 0.0
        for q in range(n):
            for i in range(m_q[q]):
                a0, a1, a2, a3 = a_x[q, i, 0], a_x[q, i, 1], a_x[q, i, 2], a_x[q, i, 3]
                t0, t1, t2, t3_ = ptx[q, i, 0], ptx[q, i, 1], ptx[q, i, 2], ptx[q, i, 3]
                f00 += a0 * t0
                f01 += a0 * t1
                f02 += a0 * t2
                r0 += a0 * t3_
                f10 += a1 * t0
                f11 += a1 * t1
                f12 += a1 * t2
                r1 += a1 * t3_
                f20 += a2 * t0
                f21 += a2 * t1
                f22 += a2 * t2
                r2 += a2 * t3_
                apa += a3 * t3_
        # symmetrise (the two triangles differ by rounding only), invert
        v01 = 0.5 * (f01 + f10)
        v02 = 0.5 * (f02 + f20)
        v12 = 0.5 * (f12 + f21)
        ok, o00, o01, o02, o11, o12, o22 = cholesky_inverse3(f00, v01, f11, v02, v12, f22)
        if ok:
            x0, x1, x2, t_stat = _solve3((o00, o01, o02, o11, o12, o22), (r0, r1, r2), apa)
            for q in range(n):
                for i in range(m_q[q]):
                    t0, t1, t2 = ptx[q, i, 0], ptx[q, i, 1], ptx[q, i, 2]
                    g0 = o00 * t0 + o01 * t1 + o02 * t2  # the row's position gain
                    g1 = o01 * t0 + o11 * t1 + o12 * t2
                    g2 = o02 * t0 + o12 * t1 + o22 * t2
                    r_ii = ptd[q, i] - (t0 * g0 + t1 * g1 + t2 * g2)
                    ra = ptx[q, i, 3] - (t0 * x0 + t1 * x1 + t2 * x2)
                    k = idx[q, i]
                    state = _row(state, q, k, r_ii, ra, (g0, g1, g2), w[q, k], rot, positive_only)
    h_slope, v_slope, q_star, k_star, w_star, _sp = state
    keep_alive(gs, m_q, idx, a_x, pq, pax, ptx, ptd, lam, p0l, g3, wrow, mg, mgi, u_mat, v_mat)
    keep_alive(vloc, mloc, bq, low, linv, loc, t3, ddiag)
    keep_alive(pr, sv, system, rows, w, sig_c, pos, base, froot, rot)
    dof = n_rows - n_clocks - 3
    if not ok:
        t_stat, dof, q_star, k_star, w_star, h_slope, v_slope = _FAILED
    return ok, t_stat, dof, q_star, k_star, w_star, h_slope, v_slope


@njit(cache=True, inline="always", error_model="numpy")
def _row(state, q, k, r_ii, ra, gain, w_qk, rot, positive_only):
    """One row's share of a test: its slopes (the largest so far) and its normalised residual
    (the identified row so far). ``state``: ``(h_slope, v_slope, q_star, k_star, w_star,
    star_positive)``; ``q, k``: the row (UAV, satellite); ``r_ii``, ``ra``: its residual
    variance ``R_ii`` and residual ``(R a)_i``; ``gain``: ``(g0, g1, g2)``, its ECEF position
    gain ``K_i``; ``w_qk``: its weight."""
    h_slope, v_slope, q_star, k_star, w_star, star_positive = state
    g0, g1, g2 = gain
    ke = rot[0, 0] * g0 + rot[0, 1] * g1 + rot[0, 2] * g2
    kn = rot[1, 0] * g0 + rot[1, 1] * g1 + rot[1, 2] * g2
    ku = rot[2, 0] * g0 + rot[2, 1] * g1 + rot[2, 2] * g2
    kh = math.sqrt(ke * ke + kn * kn)
    if r_ii <= UNOBSERVABLE_RII * w_qk:
        if kh > HARMLESS_GAIN:
            h_slope = math.inf
        if abs(ku) > HARMLESS_GAIN:
            v_slope = math.inf
        return h_slope, v_slope, q_star, k_star, w_star, star_positive
    sr = math.sqrt(r_ii)
    h_slope = max(h_slope, kh / sr)
    v_slope = max(v_slope, abs(ku) / sr)
    wi = abs(ra) / sr
    if positive_only and not ra > 0.0:
        return h_slope, v_slope, q_star, k_star, w_star, star_positive
    if (
        q_star < 0
        or wi > w_star * (1.0 + TIE_RTOL)
        or (wi >= w_star * (1.0 - TIE_RTOL) and ra > 0.0 and not star_positive)
    ):
        return h_slope, v_slope, q, k, wi, ra > 0.0
    return h_slope, v_slope, q_star, k_star, w_star, star_positive


class ReceiverRows(NamedTuple):
    """The measurements of one receiver's standalone fix under test and their weights
    (:func:`standalone_statistics`)."""

    pr: np.ndarray  # (S,) pseudoranges [m] (any value where vis is False)
    sv: np.ndarray  # (S, 3) satellite positions, ECEF [m]
    system: np.ndarray  # (S,) int64 constellation index
    n_sys: int  # constellations (clock states)
    vis: np.ndarray  # (S,) bool the measurements of the fix
    w: np.ndarray  # (S,) inverse variance of each row's error (common error included) [1/m^2]


@njit(cache=True)
def standalone_statistics(receiver_rows, pos, rot, positive_only, u):
    """:func:`problem_statistics` of one receiver's standalone fix (diagonal covariance, no
    relative or common-error terms), in ``O(m)``: the clocks are eliminated by weighted mean
    removal per constellation, after which ``P~ = W - w w^T / d`` per group is applied to
    the design in closed form. Takes the record :class:`ReceiverRows` (or a plain tuple of
    its fields), the fix ``pos`` (3,) ECEF [m], ``rot`` and ``positive_only`` as
    :func:`problem_statistics` and the scratch ``u`` (S, 4). The same quantities as
    :func:`problem_statistics` (compared in the tests)."""
    n_sys = receiver_rows[3]
    return _standalone_statistics(receiver_rows, pos, rot, positive_only, u, np.empty((n_sys, 5)))


@njit(cache=True, error_model="numpy")
def _standalone_statistics(receiver_rows, pos, rot, positive_only, u, grp):
    """:func:`standalone_statistics` with the group scratch ``grp`` (n_sys, 5) given (each
    constellation's weighted means of ``[A | a]`` and its weight sum): no allocation."""
    pr, sv, system, n_sys, vis, w = receiver_rows
    s = vis.shape[0]
    n_rows = 0
    n_clocks = 0
    for j in range(n_sys):
        for c in range(5):
            grp[j, c] = 0.0
    for k in range(s):  # [A | a] of the rows, then each group's weighted means removed
        if vis[k]:
            d0 = sv[k, 0] - pos[0]
            d1 = sv[k, 1] - pos[1]
            d2 = sv[k, 2] - pos[2]
            rng = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            u[k, 0] = -d0 / rng
            u[k, 1] = -d1 / rng
            u[k, 2] = -d2 / rng
            u[k, 3] = pr[k] - rng
            grp[system[k], 4] += w[k]
            n_rows += 1
    for j in range(n_sys):
        if grp[j, 4] > 0.0:
            n_clocks += 1
    for k in range(s):
        if vis[k]:
            j = system[k]
            for c in range(4):
                grp[j, c] += w[k] * u[k, c] / grp[j, 4]
    # the normal matrix (its lower triangle: what the factorisation reads), A^T P a, a^T P a
    a00 = a10 = a11 = a20 = a21 = a22 = 0.0
    r0 = r1 = r2 = 0.0
    apa = 0.0
    for k in range(s):
        if vis[k]:
            j = system[k]
            for c in range(4):
                u[k, c] -= grp[j, c]
            wk = w[k]
            u0, u1, u2, u3 = u[k, 0], u[k, 1], u[k, 2], u[k, 3]
            a00 += wk * u0 * u0
            a10 += wk * u1 * u0
            a11 += wk * u1 * u1
            a20 += wk * u2 * u0
            a21 += wk * u2 * u1
            a22 += wk * u2 * u2
            r0 += wk * u0 * u3
            r1 += wk * u1 * u3
            r2 += wk * u2 * u3
            apa += wk * u3 * u3
    ok, o00, o01, o02, o11, o12, o22 = cholesky_inverse3(a00, a10, a11, a20, a21, a22)
    t_stat = np.nan
    state = (0.0, 0.0, -1, -1, 0.0, False)
    if ok:
        x0, x1, x2, t_stat = _solve3((o00, o01, o02, o11, o12, o22), (r0, r1, r2), apa)
        for k in range(s):
            if vis[k]:
                wk = w[k]
                t0, t1, t2 = wk * u[k, 0], wk * u[k, 1], wk * u[k, 2]  # (P~ A)_k
                g0 = o00 * t0 + o01 * t1 + o02 * t2
                g1 = o01 * t0 + o11 * t1 + o12 * t2
                g2 = o02 * t0 + o12 * t1 + o22 * t2
                r_ii = wk - wk * wk / grp[system[k], 4] - (t0 * g0 + t1 * g1 + t2 * g2)
                ra = wk * u[k, 3] - (t0 * x0 + t1 * x1 + t2 * x2)
                state = _row(state, 0, k, r_ii, ra, (g0, g1, g2), wk, rot, positive_only)
    h_slope, v_slope, _q, k_star, w_star, _sp = state
    q_star = 0 if k_star >= 0 else -1
    dof = n_rows - n_clocks - 3
    if not ok:
        t_stat, dof, q_star, k_star, w_star, h_slope, v_slope = _FAILED
    keep_alive(pr, sv, system, vis, w, pos, rot, u, grp)
    return ok, t_stat, dof, q_star, k_star, w_star, h_slope, v_slope


# --------------------------------------------------------------------------------------------
# protection levels
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def protection_level(slope_h, slope_v, sqrt_lam, cov_ecef, rot, k_h, k_v):
    """``(HPL, VPL)`` of one fix: faulted slope bound plus the fault-free bound.

    ``HPL = slope_h sqrt(lam) + k_h sigma_major``, ``VPL = slope_v sqrt(lam) + k_v sigma_u``
    with ``sigma_major`` the semi-major axis of the horizontal error ellipse and ``sigma_u``
    the vertical sigma of ``cov_ecef`` rotated by ``rot`` (see the integrity module's
    docstring for why the sum bounds the misleading-information probability).
    """
    # the entries of rot cov rot^T used (no array: this runs for every fix of every epoch)
    c00 = c01 = c10 = c11 = c22 = 0.0
    for a in range(3):
        for b in range(3):
            cab = cov_ecef[a, b]
            c00 += rot[0, a] * cab * rot[0, b]
            c01 += rot[0, a] * cab * rot[1, b]
            c10 += rot[1, a] * cab * rot[0, b]
            c11 += rot[1, a] * cab * rot[1, b]
            c22 += rot[2, a] * cab * rot[2, b]
    half_tr = 0.5 * (c00 + c11)
    half_diff = 0.5 * (c00 - c11)
    major = half_tr + math.sqrt(half_diff * half_diff + c01 * c10)
    sig_major = math.sqrt(max(major, 0.0))
    sig_u = math.sqrt(max(c22, 0.0))
    return slope_h * sqrt_lam + k_h * sig_major, slope_v * sqrt_lam + k_v * sig_u


# --------------------------------------------------------------------------------------------
# fault detection and exclusion
# --------------------------------------------------------------------------------------------


_EXCLUDE = -1  # a verdict of _record: exclude the identified row and test again


@njit(cache=True)
def _record(f, stats, detected, n_excl, test, figs):
    """The verdict of one test of fix ``f`` of an FDE loop, and its figures stored in ``figs``
    (``t_out, dof_out, h_out, v_out``). ``stats``: :func:`_statistics`' outputs; ``detected``:
    a fault was detected before. Returns ``(verdict, failed)``: the IntegrityStatus to stop
    with, or ``_EXCLUDE``; whether this test failed."""
    ok, t_stat, dof, _q, k_s, _w, h_sl, v_sl = stats
    thr, max_excl, _pos = test
    t_out, dof_out, h_out, v_out = figs
    if not ok:
        return (INT_FAULT_DETECTED if detected else INT_NO_FIX), False
    t_out[f] = t_stat
    dof_out[f] = dof
    if dof < 1:
        return (INT_FAULT_DETECTED if detected else INT_NO_REDUNDANCY), False
    if t_stat <= thr[dof]:
        h_out[f] = h_sl
        v_out[f] = v_sl
        return (INT_EXCLUDED if n_excl > 0 else INT_OK), False
    if dof < 2 or n_excl >= max_excl or k_s < 0:
        return INT_FAULT_DETECTED, True
    return _EXCLUDE, True


@njit(cache=True)
def standalone_fde(obs, solver, fix, rot, test):
    """RAIM FDE of every standalone fix; the solver's outputs are updated in place.

    Per receiver: test (chi-square on ``T``), and while it fails with at least two degrees
    of freedom and exclusions left, exclude the row of the largest normalised residual and
    re-solve with :func:`coopnav_env.nav._kernels.standalone_solve` (warm start at the
    current fix). A fault that cannot be cleared leaves the receiver's original fix with
    ``NavStatus.FAULT_DETECTED``.

    Parameters (grouped)
    --------------------
    obs : ``(vis, pr, sigma_user, sigma_common, sv, system, n_sys, el)``, the observations
        (``el`` is handed to the re-solves, which do not read it)
    solver : ``(max_iter, tol_m, check, r_lo, r_hi)``, the re-solves' settings (the fields
        of :class:`~coopnav_env.nav._kernels.SolverLimits`)
    fix : ``(pos, cov, clock, status, n_used)``, the solver's fixes (R receivers), updated in
        place
    rot : (R, 3, 3) ECEF -> ENU rotations
    test : ``(thr, max_excl, positive_only)``: chi-square thresholds per degree of freedom,
        exclusions allowed per fix (a large number: until redundancy runs out), whether only
        positive residuals are identified

    Returns ``istat, detected, n_excl, excluded (R, S), t_stat, dof, h_slope, v_slope``.
    """
    vis, pr, sigma_user, sigma_common, sv, system, n_sys, el = obs
    pos, cov, clock, status, n_used = fix
    positive_only = test[2]
    n_rx, s = vis.shape
    istat = np.full(n_rx, INT_NO_FIX, dtype=np.int64)
    detected = np.zeros(n_rx, dtype=np.bool_)
    n_excl = np.zeros(n_rx, dtype=np.int64)
    excluded = np.zeros((n_rx, s), dtype=np.bool_)
    t_out = np.full(n_rx, np.nan)
    dof_out = np.zeros(n_rx, dtype=np.int64)
    h_out = np.full(n_rx, np.inf)
    v_out = np.full(n_rx, np.inf)
    figs = (t_out, dof_out, h_out, v_out)
    w = np.zeros(s)
    u = np.empty((s, 4))
    grp = np.empty((n_sys, 5))
    vis_r = np.empty((1, s), dtype=np.bool_)
    pr_r = np.empty((1, s))
    vis1 = vis_r[0]  # the same memory, 1-D
    pr1 = pr_r[0]
    rows1 = ReceiverRows(pr1, sv, system, n_sys, vis1, w)  # (updated in place per receiver)
    # the solver's fix, kept from its first detection on (restored if not cleared)
    keep_pos, keep_cov, keep_clk = np.empty(3), np.empty((3, 3)), np.empty(n_sys)
    for r in range(n_rx):
        vis_r[0] = vis[r]
        pr_r[0] = pr[r]
        su_r = sigma_user[r : r + 1]
        el_r = el[r : r + 1]
        keep_used = n_used[r]
        t_first, dof_first = np.nan, 0
        while True:
            if status[r] != _NAV_OK:
                istat[r] = INT_FAULT_DETECTED if detected[r] else INT_NO_FIX
                break
            for k in range(s):
                w[k] = 0.0
                if vis1[k]:
                    w[k] = 1.0 / (su_r[0, k] ** 2 + sigma_common[k] ** 2)
            stats = _standalone_statistics(rows1, pos[r], rot[r], positive_only, u, grp)
            verdict, failed = _record(r, stats, detected[r], n_excl[r], test, figs)
            if failed and not detected[r]:  # the solver's own fix, kept
                t_first, dof_first = stats[1], stats[2]
                keep_pos[:] = pos[r]
                keep_cov[:, :] = cov[r]
                keep_clk[:] = clock[r]
            detected[r] |= failed
            if verdict != _EXCLUDE:
                istat[r] = verdict
                break
            k_s = stats[4]
            vis_r[0, k_s] = False
            pr_r[0, k_s] = np.nan
            excluded[r, k_s] = True
            n_excl[r] += 1
            p1, c1, k1, st1, nu1, _it = standalone_solve(
                Measured(pr_r, vis_r, sv, system, su_r, sigma_common, el_r, n_sys),
                pos[r : r + 1].copy(),
                solver,
            )
            pos[r] = p1[0]
            cov[r] = c1[0]
            clock[r] = k1[0]
            status[r] = st1[0]
            n_used[r] = nu1[0]
        if istat[r] == INT_FAULT_DETECTED:  # the original fix, flagged
            pos[r], cov[r], clock[r], n_used[r] = keep_pos, keep_cov, keep_clk, keep_used
            status[r] = _NAV_FAULT
            t_out[r], dof_out[r] = t_first, dof_first
            excluded[r, :] = False
            n_excl[r] = 0
    return istat, detected, n_excl, excluded, t_out, dof_out, h_out, v_out


@njit(cache=True)
def cooperative_fde(obs, setup, solver, sol, rot, test):
    """RAIM FDE of every centroid problem; the solver's outputs are updated in place.

    As :func:`standalone_fde`, per centroid problem, on the rows the solver used
    (:func:`~coopnav_env.nav._kernels.setup_masks`, so DDT's pivot rule and SDT's
    availability rule hold after every exclusion), re-solving one problem with the solver's
    kernels (``setup_masks``, ``cooperative_gauss_newton``, ``n_nuisance``,
    ``cooperative_finish``) from its current fix.

    Parameters (grouped)
    --------------------
    obs : ``(vis, pr, sigma_user, sigma_common, sv, system, n_sys, el)``; ``pr`` NaN where not
        received
    setup : ``(base, bcov, froot, bavail, cen, ddt, need_override, with_uavs)``: the masked
        baselines, their covariances and roots (B, N, ...), the links with the centroid UAV's
        own entry True, the centroid UAVs (-1: a virtual point), the transfer, the SDT rule
    solver : as :func:`standalone_fde`
    sol : ``(c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status)``,
        the solver's outputs (those of ``cooperative_finish``; the UAV arrays (B, 0, ...)
        without ``with_uavs``), updated in place
    rot : (B, 3, 3); test : as :func:`standalone_fde`

    Returns ``istat, detected, n_excl, excluded (B, N, S), t_stat, dof, h_slope, v_slope``.
    """
    vis, pr, sigma_user, sig_c, sv, system, n_sys, el = obs
    base, bcov, froot, bavail, cen, ddt, need_override, with_uavs = setup
    max_iter, tol_m, check, lo, hi = solver
    c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status = sol
    positive_only = test[2]
    n_b, n = bavail.shape
    s = vis.shape[1]
    istat = np.full(n_b, INT_NO_FIX, dtype=np.int64)
    detected = np.zeros(n_b, dtype=np.bool_)
    n_excl = np.zeros(n_b, dtype=np.int64)
    excluded = np.zeros((n_b, n, s), dtype=np.bool_)
    t_out = np.full(n_b, np.nan)
    dof_out = np.zeros(n_b, dtype=np.int64)
    h_out = np.full(n_b, np.inf)
    v_out = np.full(n_b, np.inf)
    figs = (t_out, dof_out, h_out, v_out)
    w = np.zeros((n, s))
    for q in range(n):
        for k in range(s):
            if vis[q, k]:
                w[q, k] = 1.0 / (sigma_user[q, k] * sigma_user[q, k])
    m = uav_pos.shape[1]
    ws = workspace(n, s)
    # the solver's own set-up of every problem (as cooperative_isotropic / _setup made it)
    _ref, used_all, _hc, _piv, _tf = setup_masks(
        vis, bavail, cen, system, el, n_sys, ddt, need_override
    )
    # the solver's fix of a problem, kept from its first detection on (restored if the fault
    # cannot be cleared)
    keep_pos, keep_clk, keep_h = np.empty(3), np.empty(n_sys), np.empty((3, 3))
    keep_upos, keep_ucov = np.empty((m, 3)), np.empty((m, 3, 3))
    keep_ustat = np.empty(m, dtype=np.int64)
    for b in range(n_b):
        vis_b = vis
        pr_b = pr
        el_b = el
        copied = False
        keep_n = (c_status[b], n_uavs[b], n_meas[b])
        t_first, dof_first = np.nan, 0
        rows_b = used_all[b]
        while True:
            if c_status[b] != _NAV_OK:
                istat[b] = INT_FAULT_DETECTED if detected[b] else INT_NO_FIX
                break
            stats = _statistics(
                ws,
                # FixRows as a plain tuple: pr_b is the caller's array or its copy, whose
                # layouts (e.g. Fortran and C) a named tuple's type cannot unify
                (pr_b, sv, system, n_sys, rows_b, w, sig_c),
                FixPoint(c_pos[b], base[b], froot[b]),
                rot[b],
                positive_only,
            )
            verdict, failed = _record(b, stats, detected[b], n_excl[b], test, figs)
            if failed and not detected[b]:  # the solver's own fix, kept
                t_first, dof_first = stats[1], stats[2]
                keep_pos[:] = c_pos[b]
                keep_clk[:] = c_clk[b]
                keep_h[:, :] = h_star[b]
                if m > 0:
                    keep_upos[:, :] = uav_pos[b]
                    keep_ucov[:, :, :] = uav_cov[b]
                    keep_ustat[:] = uav_status[b]
            detected[b] |= failed
            if verdict != _EXCLUDE:
                istat[b] = verdict
                break
            q_s, k_s = stats[3], stats[4]
            if not copied:
                vis_b, pr_b, el_b = vis.copy(), pr.copy(), el.copy()
                copied = True
            vis_b[q_s, k_s] = False
            pr_b[q_s, k_s] = np.nan
            el_b[q_s, k_s] = np.nan
            excluded[b, q_s, k_s] = True
            n_excl[b] += 1
            ref, used, has_clock, _piv, too_few = setup_masks(
                vis_b,
                bavail[b : b + 1],
                cen[b : b + 1],
                system,
                el_b,
                n_sys,
                ddt,
                need_override,
            )
            pr0 = np.zeros((1, n, s))
            for q in range(n):
                for k in range(s):
                    if vis_b[q, k]:
                        pr0[0, q, k] = pr_b[q, k]
            usable = np.empty(1, dtype=np.bool_)
            usable[0] = not too_few[0]
            x0 = c_pos[b : b + 1].copy()
            pos1, clk1, inv1, cross1, conv1, sing1, _it = cooperative_gauss_newton(
                Transferred(pr0, sv, vis_b, sigma_user, sig_c, system),
                Problems(used, base[b : b + 1], froot[b : b + 1], ref, has_clock, usable, x0),
                max_iter,
                tol_m,
            )
            rows_b = used[0]
            nn = n_nuisance(used, system, ref, n_sys)
            out = cooperative_finish(
                Solved(pos1, clk1, inv1, cross1, conv1, sing1),
                ProblemSetup(
                    used,
                    nn,
                    too_few,
                    has_clock,
                    base[b : b + 1],
                    bcov[b : b + 1],
                    froot[b : b + 1],
                    bavail[b : b + 1],
                ),
                check,
                lo,
                hi,
                with_uavs,
            )
            c_pos[b] = out[0][0]
            h_star[b] = out[1][0]
            c_clk[b] = out[2][0]
            c_status[b] = out[3][0]
            n_uavs[b] = out[4][0]
            n_meas[b] = out[5][0]
            if m > 0:
                uav_pos[b] = out[6][0]
                uav_cov[b] = out[7][0]
                uav_status[b] = out[8][0]
        if istat[b] == INT_FAULT_DETECTED:  # the original fix, flagged
            c_pos[b], c_clk[b], h_star[b] = keep_pos, keep_clk, keep_h
            c_status[b] = _NAV_FAULT
            t_out[b], dof_out[b] = t_first, dof_first
            n_uavs[b], n_meas[b] = keep_n[1], keep_n[2]
            excluded[b] = False
            n_excl[b] = 0
            if m > 0:
                uav_pos[b], uav_cov[b] = keep_upos, keep_ucov
                for q in range(m):
                    st = keep_ustat[q]
                    uav_status[b, q] = _NAV_FAULT if st == _NAV_OK else st
    return istat, detected, n_excl, excluded, t_out, dof_out, h_out, v_out
