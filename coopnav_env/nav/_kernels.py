r"""Compiled (numba) Gauss-Newton loops of the standalone and the cooperative WLS solvers.

The public solvers (:func:`~coopnav_env.nav.solve_standalone`,
:func:`~coopnav_env.nav.solve_cooperative`) validate their inputs, prepare the problem with
numpy and hand the iteration to these kernels: one compiled loop per receiver (standalone) or
per centroid problem (cooperative), in which a numpy implementation would spend its time in the
call overhead of a few hundred small array operations per iteration.

The algebra is exactly that of the numpy formulation (see the docstring of
``coopnav_env.nav.cooperative._structured_normal`` for the elimination order); only the order
of the floating-point sums differs, so results agree with it to about 1e-12 relative (the tests
compare both, and the dense literal solve). Two further differences, both below 1e-9 m:

* each problem stops iterating as soon as its own update is below ``tol_m`` (the numpy loop
  iterates all problems until the last one has converged);
* the small dense solves are hand-written (Cholesky for symmetric positive definite matrices,
  cyclic Jacobi for the eigenvalues of the conditioning check when the bound
  ``||A||_F ||A^-1||_F`` does not already settle it), so the kernels need no LAPACK.

Around the two loops, the rest of a solve is compiled too: :func:`standalone_solve` (the
whole standalone solver after its argument checks), :func:`setup_masks` (clock references,
used rows, DDT pivots and availability of the centroid problems), :func:`cooperative_finish`
(statuses, centroid outputs and every UAV's position and covariance, Eq. 19-22),
:func:`fix_status`, :func:`n_nuisance` and :func:`sqrtm_diagonal`. Each has its numpy
formulation as a test oracle (``tests/nav/oracles.py``), compared in
``tests/nav/test_kernels.py``.

The cooperative Gauss-Newton loop is compiled three times from one source: for one and for
two constellations, whose problem sizes are then compile-time constants, and for any number
(:func:`cooperative_gauss_newton` picks one; all three give the same bits).

The kernels are compiled on first use and cached on disk beside this file (numba
``cache=True``); the first call of a fresh installation compiles them (``docs/performance.md``
says how long this takes for all kernels of the package on a 2-core machine).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

# exported as coopnav_env.nav.wls.COND_LIMIT (one value for both implementations)
COND_LIMIT = 1e10


# Views of one buffer: a kernel takes its arrays from one allocation per dtype (numba's
# allocation and release of an array cost about as much as a few hundred flops of these
# small problems). ``_take*(buf, off, shape...)`` returns the view at ``off`` and the next
# offset; the buffer holds zeros, as ``numpy.zeros`` would.


@njit(cache=True, inline="always")
def _take1(buf, off, a):
    """``buf[off:off + a]`` and ``off + a``."""
    return buf[off : off + a], off + a


@njit(cache=True, inline="always")
def _take2(buf, off, a, b):
    """``buf[off:off + a b]`` as ``(a, b)`` and the next offset."""
    return buf[off : off + a * b].reshape((a, b)), off + a * b


@njit(cache=True, inline="always")
def _take3(buf, off, a, b, c):
    """``buf[off:off + a b c]`` as ``(a, b, c)`` and the next offset."""
    return buf[off : off + a * b * c].reshape((a, b, c)), off + a * b * c


@njit(cache=True, inline="always")
def _take4(buf, off, a, b, c, d):
    """``buf[off:off + a b c d]`` as ``(a, b, c, d)`` and the next offset."""
    n = a * b * c * d
    return buf[off : off + n].reshape((a, b, c, d)), off + n


@njit(cache=True)
def _cholesky_inverse(a: np.ndarray, out: np.ndarray) -> bool:
    """Inverse of the symmetric positive definite ``a`` into ``out``; False if not SPD."""
    n = a.shape[0]
    return _cholesky_inverse_into(a, out, np.zeros((n, n)), np.zeros((n, n)))


@njit(cache=True)
def _cholesky_inverse_into(
    a: np.ndarray, out: np.ndarray, low: np.ndarray, linv: np.ndarray
) -> bool:
    """:func:`_cholesky_inverse` in the scratch matrices ``low`` and ``linv`` (at least the
    size of ``a``; only the lower triangles the factorisation writes are read)."""
    return _cholesky_inverse_leading(a, a.shape[0], out, low, linv)


@njit(cache=True)
def _cholesky_inverse_leading(
    a: np.ndarray, n: int, out: np.ndarray, low: np.ndarray, linv: np.ndarray
) -> bool:
    """:func:`_cholesky_inverse_into` of the leading ``n x n`` block of ``a`` (into the
    leading blocks of ``out``, ``low`` and ``linv``), so that callers can keep one buffer for
    problems of several sizes."""
    for j in range(n):
        s = a[j, j]
        for k in range(j):
            s -= low[j, k] * low[j, k]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        low[j, j] = d
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s -= low[i, k] * low[j, k]
            low[i, j] = s / d
    # inverse of the triangular factor, then inv(a) = inv(L)^T inv(L)
    for j in range(n):
        linv[j, j] = 1.0 / low[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= low[i, k] * linv[k, j]
            linv[i, j] = s / low[i, i]
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(j, n):
                s += linv[k, i] * linv[k, j]
            out[i, j] = s
            out[j, i] = s
    return True


@njit(cache=True)
def _eig_extremes_sym(a: np.ndarray) -> tuple[float, float]:
    """Smallest and largest eigenvalue of a small symmetric matrix (cyclic Jacobi)."""
    n = a.shape[0]
    m = a.copy()
    for _sweep in range(60):
        off = 0.0
        for i in range(n):
            for j in range(i + 1, n):
                off += m[i, j] * m[i, j]
        diag = 0.0
        for i in range(n):
            diag += m[i, i] * m[i, i]
        if off <= 1e-30 * diag or off == 0.0:
            break
        for p in range(n):
            for q in range(p + 1, n):
                apq = m[p, q]
                if apq == 0.0:
                    continue
                theta = (m[q, q] - m[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):
                    mkp = m[k, p]
                    mkq = m[k, q]
                    m[k, p] = c * mkp - s * mkq
                    m[k, q] = s * mkp + c * mkq
                for k in range(n):
                    mpk = m[p, k]
                    mqk = m[q, k]
                    m[p, k] = c * mpk - s * mqk
                    m[q, k] = s * mpk + c * mqk
    lo = m[0, 0]
    hi = m[0, 0]
    for i in range(1, n):
        lo = min(lo, m[i, i])
        hi = max(hi, m[i, i])
    return lo, hi


class InverseScratch(NamedTuple):
    """The scratch arrays of :func:`_safe_inverse_into` for a (P, P) matrix (allocated once
    by the caller instead of at every Gauss-Newton update)."""

    d: np.ndarray  # (P,) square roots of the diagonal (the scaling)
    scaled: np.ndarray  # (P, P) the matrix scaled to unit diagonal
    low: np.ndarray  # (P, P) its Cholesky factor (_cholesky_inverse_into)
    linv: np.ndarray  # (P, P) the factor's inverse


@njit(cache=True, inline="always")
def _inverse_scratch(p: int) -> InverseScratch:
    """New :class:`InverseScratch` for a (``p``, ``p``) matrix (the factors start at zero)."""
    return InverseScratch(np.empty(p), np.empty((p, p)), np.zeros((p, p)), np.zeros((p, p)))


@njit(cache=True)
def _safe_inverse_one(info: np.ndarray, usable: bool, out: np.ndarray) -> bool:
    """One matrix of ``coopnav_env.nav.wls._safe_inverse``: inverse into ``out``; singular?

    The matrix is scaled to unit diagonal; it is singular when its smallest eigenvalue is not
    positive or its condition number exceeds ``COND_LIMIT``. A singular or unusable matrix
    gets the (scaled-back) identity.

    The Cholesky factorisation runs first: when it fails the matrix is not numerically
    positive definite (singular, as the eigenvalue test would also end). When it succeeds and
    ``||A||_F ||A^-1||_F <= COND_LIMIT``, the condition number (at most that product, since
    ``||.||_2 <= ||.||_F``) is within the limit and the Jacobi eigenvalues are not needed;
    otherwise they decide, as before. Same decisions and the same inverse, without an
    eigen-decomposition per Gauss-Newton iteration of a well-conditioned problem.
    """
    return _safe_inverse_into(info, usable, out, _inverse_scratch(info.shape[0]))


@njit(cache=True, inline="always")
def _safe_inverse_into(
    info: np.ndarray,
    usable: bool,
    out: np.ndarray,
    scratch: InverseScratch,
) -> bool:
    """:func:`_safe_inverse_one` in the scratch arrays ``scratch`` (:class:`InverseScratch`,
    or a plain tuple of its fields)."""
    d, scaled, low, linv = scratch
    p = info.shape[0]
    for i in range(p):
        d[i] = np.sqrt(max(info[i, i], 1e-300))
    for i in range(p):
        for j in range(p):
            scaled[i, j] = info[i, j] / d[i] / d[j]
    singular = False
    good = usable
    if usable:
        if not _cholesky_inverse_into(scaled, out, low, linv):  # not numerically SPD
            singular = True
        else:
            norm_a = 0.0
            norm_inv = 0.0
            for i in range(p):
                for j in range(p):
                    norm_a += scaled[i, j] * scaled[i, j]
                    norm_inv += out[i, j] * out[i, j]
            if not np.sqrt(norm_a) * np.sqrt(norm_inv) <= COND_LIMIT:
                lo, hi = _eig_extremes_sym(scaled)
                singular = (lo <= 0.0) or (hi > COND_LIMIT * lo)
        good = not singular
    if not good:
        for i in range(p):
            for j in range(p):
                out[i, j] = 0.0
            out[i, i] = 1.0
    for i in range(p):
        for j in range(p):
            out[i, j] = out[i, j] / d[i] / d[j]
    return singular


@njit(cache=True)
def _unit(a: np.ndarray) -> None:
    """Set the square matrix ``a`` to the identity in place."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            a[i, j] = 1.0 if i == j else 0.0


@njit(cache=True)
def _gauss_newton_update(
    info: np.ndarray,
    rhs: np.ndarray,
    usable: bool,
    inv_out: np.ndarray,
    pos: np.ndarray,
    clock: np.ndarray,
    tol_m: float,
) -> tuple[bool, bool]:
    """One update ``dx = info^-1 rhs`` of a Gauss-Newton problem, applied in place.

    ``inv_out`` receives the inverse (:func:`_safe_inverse_one`), ``pos`` (3,) and ``clock``
    (n_sys,) the update. Returns ``(singular, done)``: ``done`` when the problem is unusable
    or singular (no update; the status says why) or the position update is below ``tol_m``.
    """
    return _gauss_newton_update_into(
        info, rhs, usable, inv_out, pos, clock, tol_m, _inverse_scratch(info.shape[0])
    )


@njit(cache=True, inline="always")
def _gauss_newton_update_into(
    info: np.ndarray,
    rhs: np.ndarray,
    usable: bool,
    inv_out: np.ndarray,
    pos: np.ndarray,
    clock: np.ndarray,
    tol_m: float,
    scratch: InverseScratch,
) -> tuple[bool, bool]:
    """:func:`_gauss_newton_update` in the scratch arrays ``scratch`` of
    :func:`_safe_inverse_into` (:class:`InverseScratch`, or a plain tuple of its fields)."""
    p_dim = info.shape[0]
    singular = _safe_inverse_into(info, usable, inv_out, scratch)
    if not usable or singular:
        return singular, True
    step2 = 0.0
    for i in range(p_dim):
        d = 0.0
        for j in range(p_dim):
            d += inv_out[i, j] * rhs[j]
        if i < 3:
            pos[i] += d
            step2 += d * d
        else:
            clock[i - 3] += d
    return False, np.sqrt(step2) < tol_m


@njit(cache=True)
def standalone_gauss_newton(
    pr: np.ndarray,  # (R, S) pseudoranges, 0 where not received
    sv: np.ndarray,  # (S, 3)
    w: np.ndarray,  # (R, S) weights, 0 where not received
    system: np.ndarray,  # (S,) constellation index
    seen: np.ndarray,  # (R, n_sys) bool
    usable: np.ndarray,  # (R,) bool
    x0: np.ndarray,  # (R, 3)
    max_iter: int,
    tol_m: float,
):
    """Gauss-Newton of Eq. 14-17 per receiver.

    Returns ``pos (R, 3), clock (R, n_sys), inv (R, P, P), converged (R,), singular (R,),
    n_iter (R,)`` with ``inv`` the inverse normal matrix at the last linearisation.
    """
    n_rx, n_sv = pr.shape
    n_sys = seen.shape[1]
    p_dim = 3 + n_sys
    pos = x0.copy()
    clock = np.zeros((n_rx, n_sys))
    inv = np.zeros((n_rx, p_dim, p_dim))
    converged = np.zeros(n_rx, dtype=np.bool_)
    singular = np.zeros(n_rx, dtype=np.bool_)
    n_iter = np.zeros(n_rx, dtype=np.int64)
    info = np.empty((p_dim, p_dim))
    rhs = np.empty(p_dim)
    g = np.empty(p_dim)
    scratch = _inverse_scratch(p_dim)  # of the updates (_safe_inverse_into)
    for r in range(n_rx):
        for it in range(1, max_iter + 1):
            n_iter[r] = it
            info[:, :] = 0.0
            rhs[:] = 0.0
            at_sat = False
            for k in range(n_sv):
                wk = w[r, k]
                if wk == 0.0:
                    continue
                dx0 = sv[k, 0] - pos[r, 0]
                dx1 = sv[k, 1] - pos[r, 1]
                dx2 = sv[k, 2] - pos[r, 2]
                rng = np.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2)
                if rng == 0.0:  # a satellite at the iterate: no line of sight (singular)
                    at_sat = True
                    break
                sk = system[k]
                g[:] = 0.0
                g[0] = -dx0 / rng
                g[1] = -dx1 / rng
                g[2] = -dx2 / rng
                g[3 + sk] = 1.0
                res = pr[r, k] - rng - clock[r, sk]
                for i in range(p_dim):
                    wg = wk * g[i]
                    rhs[i] += wg * res
                    for j in range(p_dim):
                        info[i, j] += wg * g[j]
            if at_sat and usable[r]:
                _unit(inv[r])
                singular[r] = True
                converged[r] = True
                break
            for s in range(n_sys):
                if not seen[r, s]:
                    info[3 + s, 3 + s] += 1.0
            singular[r], converged[r] = _gauss_newton_update_into(
                info, rhs, usable[r], inv[r], pos[r], clock[r], tol_m, scratch
            )
            if converged[r]:
                break
    return pos, clock, inv, converged, singular, n_iter


@njit(cache=True)
def _inv3(m: np.ndarray, out: np.ndarray) -> None:
    """Closed-form inverse of a symmetric 3x3 matrix (as ``cooperative._inv_sym3``)."""
    a, b, c = m[0, 0], m[0, 1], m[0, 2]
    d, e, f = m[1, 1], m[1, 2], m[2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    out[0, 0] = c00 / det
    out[0, 1] = c01 / det
    out[0, 2] = c02 / det
    out[1, 0] = c01 / det
    out[1, 1] = c11 / det
    out[1, 2] = c12 / det
    out[2, 0] = c02 / det
    out[2, 1] = c12 / det
    out[2, 2] = c22 / det


class Transferred(NamedTuple):
    """The pseudoranges the centroid problems transfer and their error model
    (:func:`cooperative_gauss_newton`)."""

    pr: np.ndarray  # (B or 1, N, S) pseudoranges [m], 0 where not received
    sv: np.ndarray  # (S, 3) satellite positions, ECEF [m]
    vis: np.ndarray  # (N, S) bool received
    sigma_user: np.ndarray  # (N, S) receiver-error sigma (any value where not received)
    sig_c: np.ndarray  # (S,) common-error sigma
    system: np.ndarray  # (S,) constellation index, sorted


class Problems(NamedTuple):
    """The centroid problems: rows, baselines, clocks and starts
    (:func:`cooperative_gauss_newton`)."""

    rows: np.ndarray  # (B, N, S) bool measurement used
    base: np.ndarray  # (B, N, 3) baseline of each UAV from the centroid
    froot: np.ndarray  # (B, N, 3, 3) square root of its covariance
    ref: np.ndarray  # (B,) clock reference UAV (carries no nuisance clocks), -1: none
    has_clock: np.ndarray  # (B, n_sys) bool centroid clock estimable
    usable: np.ndarray  # (B,) bool
    x0: np.ndarray  # (B, 3) ECEF starts


class Solved(NamedTuple):
    """What :func:`cooperative_gauss_newton` leaves for :func:`cooperative_finish`."""

    pos: np.ndarray  # (B, 3)
    clk: np.ndarray  # (B, n_sys)
    inv: np.ndarray  # (B, P, P) inverse normal matrix at the last update
    cross: np.ndarray  # (B, N, P, 3)
    converged: np.ndarray  # (B,) bool
    singular: np.ndarray  # (B,) bool


class ProblemSetup(NamedTuple):
    """The set-up of the centroid problems that :func:`cooperative_finish` reads."""

    rows: np.ndarray  # (B, N, S) bool measurement used
    n_nuis: np.ndarray  # (B,) nuisance clocks the rows carry
    too_few: np.ndarray  # (B,) bool: too few measurements at the set-up
    has_clock: np.ndarray  # (B, n_sys) bool
    base: np.ndarray  # (B, N, 3) baselines
    bcov: np.ndarray  # (B, N, 3, 3) their covariances
    froot: np.ndarray  # (B, N, 3, 3) and square roots
    avail: np.ndarray  # (B, N) bool


def _cooperative_gauss_newton_for(fixed_n_sys: int):
    """The kernel of :func:`cooperative_gauss_newton` compiled for ``fixed_n_sys``
    constellations (0: as many as ``has_clock`` has columns).

    With the number of constellations a compile-time constant, the sizes of the unknowns
    (``P = 3 + n_sys``) and of every row's columns are constants too: the compiler unrolls the
    small loops over them and keeps their indices out of the loads. The arithmetic, and its
    order, is the same for every ``fixed_n_sys``, so the results are the same bit for bit.
    """

    def gauss_newton(transferred, problems, max_iter, tol_m):
        pr, sv, vis, sigma_user, sig_c, system = transferred
        rows, base, froot, ref, has_clock, usable, x0 = problems
        n_b, n, n_sv = rows.shape
        n_sys = has_clock.shape[1] if fixed_n_sys == 0 else fixed_n_sys
        p_dim = 3 + n_sys
        n_x = 3 + p_dim + 1  # columns [lam | A | a]
        fbuf = np.zeros(
            n * n_sv  # w_user
            + n_b * (3 + n_sys + p_dim * p_dim + n * p_dim * 3)  # pos, clk, inv, cross
            + n_sv * (2 * n_x + (p_dim + 1))  # x, p0x, px
            + n * n_sv * (3 + p_dim)  # g3, a_all
            + n_sv * (p_dim + 1)  # pa_sum, pr_sum
            + (p_dim + 3) * (p_dim + 1)  # atpx, t3
            + 18  # m3, m3inv
            + n_x  # grp_sum
            + 2 * p_dim * n_sv  # ape, gmat
            + 4 * p_dim * p_dim
            + 2 * p_dim  # info, rhs, d_ws, scaled_ws, low_ws, linv_ws
            + 5 * n_sv * n_sv  # sum_p, mg, mg_inv, mg_low, mg_linv
        )
        ibuf = np.zeros(2 * n_sv + n_sys + 1 + n_b, dtype=np.int64)
        bbuf = np.zeros(2 * n_b, dtype=np.bool_)
        o = 0
        w_user, o = _take2(fbuf, o, n, n_sv)  # 1 / sigma_user^2 of the received pseudoranges
        for q in range(n):
            for k in range(n_sv):
                if vis[q, k]:
                    w_user[q, k] = 1.0 / (sigma_user[q, k] * sigma_user[q, k])
        pos, o = _take2(fbuf, o, n_b, 3)
        for b in range(n_b):
            for a in range(3):
                pos[b, a] = x0[b, a]
        clk, o = _take2(fbuf, o, n_b, n_sys)
        inv, o = _take3(fbuf, o, n_b, p_dim, p_dim)
        cross, o = _take4(fbuf, o, n_b, n, p_dim, 3)
        converged, ob = _take1(bbuf, 0, n_b)
        singular, ob = _take1(bbuf, ob, n_b)
        n_iter, oi = _take1(ibuf, 0, n_b)

        x, o = _take2(fbuf, o, n_sv, n_x)  # one block's rows
        p0x, o = _take2(fbuf, o, n_sv, n_x)
        px, o = _take2(fbuf, o, n_sv, p_dim + 1)
        g3, o = _take3(fbuf, o, n, n_sv, 3)  # P0 lam M3^-1 of every block (for the cross terms)
        a_all, o = _take3(fbuf, o, n, n_sv, p_dim)
        sum_p, o = _take2(fbuf, o, n_sv, n_sv)
        pa_sum, o = _take2(fbuf, o, n_sv, p_dim)
        pr_sum, o = _take1(fbuf, o, n_sv)
        atpx, o = _take2(fbuf, o, p_dim, p_dim + 1)
        m3, o = _take2(fbuf, o, 3, 3)
        m3inv, o = _take2(fbuf, o, 3, 3)
        t3, o = _take2(fbuf, o, 3, p_dim + 1)
        grp_sum, o = _take1(fbuf, o, n_x)
        mg, o = _take2(fbuf, o, n_sv, n_sv)
        mg_inv, o = _take2(fbuf, o, n_sv, n_sv)
        ape, o = _take2(fbuf, o, p_dim, n_sv)
        gmat, o = _take2(fbuf, o, p_dim, n_sv)
        info, o = _take2(fbuf, o, p_dim, p_dim)
        rhs, o = _take1(fbuf, o, p_dim)
        mg_low, o = _take2(fbuf, o, n_sv, n_sv)  # scratch of the Cholesky inverse of mg
        mg_linv, o = _take2(fbuf, o, n_sv, n_sv)
        d_ws, o = _take1(fbuf, o, p_dim)  # scratch of the updates (_safe_inverse_into)
        scaled_ws, o = _take2(fbuf, o, p_dim, p_dim)
        low_ws, o = _take2(fbuf, o, p_dim, p_dim)
        linv_ws, o = _take2(fbuf, o, p_dim, p_dim)
        scratch = InverseScratch(d_ws, scaled_ws, low_ws, linv_ws)
        idx, oi = _take1(ibuf, oi, n_sv)
        cols, oi = _take1(ibuf, oi, n_sv)  # the satellites of the common-error block
        # contiguous satellite range of each constellation (system is sorted)
        start, oi = _take1(ibuf, oi, n_sys + 1)
        assert o == fbuf.shape[0] and oi == ibuf.shape[0]  # every view taken, none overlaps
        for s in range(n_sys + 1):
            c = 0
            for k in range(n_sv):
                if system[k] < s:
                    c += 1
            start[s] = c

        for b in range(n_b):
            pb = b if pr.shape[0] > 1 else 0
            # The common-error block over the satellites some UAV uses. A satellite no UAV uses
            # has zero rows and columns in sum_p, pa_sum and pr_sum (+0.0 exactly), so its row
            # of mg is that of the identity, its Cholesky factor and inverse rows are unit rows,
            # and every term it adds below is +0.0 (x - (+0.0) and a sum begun at +0.0 plus
            # +0.0 are exact): leaving it out changes no bit. Only a non-finite common sigma of
            # such a satellite would make those terms NaN; then every satellite stays in.
            n_c = 0
            all_cols = False
            for k in range(n_sv):
                in_use = False
                for q in range(n):
                    if rows[b, q, k]:
                        in_use = True
                        break
                if in_use:
                    cols[n_c] = k
                    n_c += 1
                elif not np.isfinite(sig_c[k]):
                    all_cols = True
            if all_cols:
                n_c = n_sv
                for k in range(n_sv):
                    cols[k] = k
            # g3 is zero outside the rows the problem uses, which every iteration writes again;
            # a_all is read only where g3 is not zero
            g3[:, :, :] = 0.0
            for it in range(1, max_iter + 1):
                n_iter[b] = it
                sum_p[:, :] = 0.0
                pa_sum[:, :] = 0.0
                pr_sum[:] = 0.0
                atpx[:, :] = 0.0
                at_sat = False
                for q in range(n):
                    # the block's rows, in satellite order
                    m = 0
                    for k in range(n_sv):
                        if rows[b, q, k]:
                            idx[m] = k
                            m += 1
                    if m == 0:
                        continue
                    pq0 = pos[b, 0] + base[b, q, 0]
                    pq1 = pos[b, 1] + base[b, q, 1]
                    pq2 = pos[b, 2] + base[b, q, 2]
                    for i in range(m):
                        k = idx[i]
                        d0 = sv[k, 0] - pq0
                        d1 = sv[k, 1] - pq1
                        d2 = sv[k, 2] - pq2
                        rng = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                        if rng == 0.0:  # a satellite at the UAV's iterate: no line of sight
                            at_sat = True
                            break
                        u0, u1, u2 = d0 / rng, d1 / rng, d2 / rng
                        for j in range(3):  # lam = u F_q
                            x[i, j] = (
                                u0 * froot[b, q, 0, j]
                                + u1 * froot[b, q, 1, j]
                                + (u2 * froot[b, q, 2, j])
                            )
                        x[i, 3] = -u0
                        x[i, 4] = -u1
                        x[i, 5] = -u2
                        for s in range(n_sys):
                            x[i, 6 + s] = 0.0
                        sk = system[k]
                        res = pr[pb, q, k] - rng
                        if has_clock[b, sk]:
                            x[i, 6 + sk] = 1.0
                            res -= clk[b, sk]
                        x[i, n_x - 1] = res
                        wk = w_user[q, k]
                        for j in range(n_x):
                            p0x[i, j] = wk * x[i, j]
                        for j in range(p_dim):
                            a_all[q, k, j] = x[i, 3 + j]
                    if at_sat:
                        break
                    # 1. nuisance clocks of a UAV other than the reference: weighted mean removal
                    if q != ref[b]:
                        # the rows of constellation s are rows r0:r1 (satellite order, system
                        # sorted): those of satellites start[s] <= k < start[s + 1]
                        r1 = 0
                        for s in range(n_sys):
                            r0 = r1
                            while r1 < m and idx[r1] < start[s + 1]:
                                r1 += 1
                            dsum = 0.0
                            grp_sum[:] = 0.0
                            for i in range(r0, r1):
                                dsum += w_user[q, idx[i]]
                                for j in range(n_x):
                                    grp_sum[j] += p0x[i, j]
                            if dsum > 0.0:
                                coef = 1.0 / dsum
                                for i in range(r0, r1):
                                    f = w_user[q, idx[i]] * coef
                                    for j in range(n_x):
                                        p0x[i, j] -= f * grp_sum[j]
                                # - sum over the group's pairs of w_s w_t / d
                                for i in range(r0, r1):
                                    ki = idx[i]
                                    f = w_user[q, ki] * coef
                                    for i2 in range(r0, r1):
                                        k2 = idx[i2]
                                        sum_p[ki, k2] -= f * w_user[q, k2]
                    # 2. the rank-3 relative-error latent (Woodbury); each sum of m3 and t3 over
                    # the rows in order, the rows the outer loop
                    for i1 in range(3):
                        for i2 in range(3):
                            m3[i1, i2] = 1.0 if i1 == i2 else 0.0
                        for j in range(p_dim + 1):
                            t3[i1, j] = 0.0
                    for i in range(m):
                        for i1 in range(3):
                            xi = x[i, i1]
                            pi = p0x[i, i1]
                            for i2 in range(3):
                                m3[i1, i2] += xi * p0x[i, i2]
                            for j in range(p_dim + 1):
                                t3[i1, j] += pi * x[i, 3 + j]
                    _inv3(m3, m3inv)
                    for i in range(m):
                        k = idx[i]
                        p0, p1, p2 = p0x[i, 0], p0x[i, 1], p0x[i, 2]
                        g0 = p0 * m3inv[0, 0] + p1 * m3inv[1, 0] + p2 * m3inv[2, 0]
                        g1 = p0 * m3inv[0, 1] + p1 * m3inv[1, 1] + p2 * m3inv[2, 1]
                        g2 = p0 * m3inv[0, 2] + p1 * m3inv[1, 2] + p2 * m3inv[2, 2]
                        g3[q, k, 0] = g0
                        g3[q, k, 1] = g1
                        g3[q, k, 2] = g2
                        for j in range(p_dim + 1):
                            px[i, j] = p0x[i, 3 + j] - (
                                g0 * t3[0, j] + g1 * t3[1, j] + g2 * t3[2, j]
                            )
                    # accumulate A^T P [A, a], sum_n P_n, sum_n P_n A and P_n a
                    for i in range(m):
                        k = idx[i]
                        for p in range(p_dim):
                            ap = x[i, 3 + p]
                            if ap != 0.0:
                                for j in range(p_dim + 1):
                                    atpx[p, j] += ap * px[i, j]
                        for p in range(p_dim):
                            pa_sum[k, p] += px[i, p]
                        pr_sum[k] += px[i, p_dim]
                        sum_p[k, k] += w_user[q, k]
                        g0, g1, g2 = g3[q, k, 0], g3[q, k, 1], g3[q, k, 2]
                        for i2 in range(m):
                            k2 = idx[i2]
                            sum_p[k, k2] -= g0 * p0x[i2, 0] + g1 * p0x[i2, 1] + g2 * p0x[i2, 2]
                if at_sat and usable[b]:  # reported singular, as the numpy formulation does
                    _unit(inv[b])
                    singular[b] = True
                    converged[b] = True
                    break
                # 3. the errors common to all UAVs (indices c of cols, satellites k = cols[c])
                for c in range(n_c):
                    k = cols[c]
                    for c2 in range(n_c):
                        mg[c, c2] = sig_c[k] * sum_p[k, cols[c2]] * sig_c[cols[c2]]
                    mg[c, c] += 1.0
                # I + E^T P E is SPD unless inputs are broken
                if not _cholesky_inverse_leading(mg, n_c, mg_inv, mg_low, mg_linv):
                    for i in range(p_dim):
                        for j in range(p_dim):
                            inv[b, i, j] = 1.0 if i == j else 0.0
                    singular[b] = True
                    converged[b] = True
                    break
                for p in range(p_dim):
                    for c in range(n_c):
                        k = cols[c]
                        ape[p, c] = pa_sum[k, p] * sig_c[k]
                # gmat = ape mg^-1, rhs and info: each sum over c2 (c) in order, from its first
                # term; c2 (c) the outer loop
                for p in range(p_dim):
                    for c in range(n_c):
                        gmat[p, c] = 0.0
                    for c2 in range(n_c):
                        a = ape[p, c2]
                        for c in range(n_c):
                            gmat[p, c] += a * mg_inv[c2, c]
                for p in range(p_dim):
                    rhs[p] = atpx[p, p_dim]
                    for p2 in range(p_dim):
                        info[p, p2] = atpx[p, p2]
                    for c in range(n_c):
                        k = cols[c]
                        g = gmat[p, c]
                        rhs[p] -= g * sig_c[k] * pr_sum[k]
                        for p2 in range(p_dim):
                            info[p, p2] -= g * ape[p2, c]
                for s in range(n_sys):  # unit diagonal for the clocks of constellations not seen
                    if not has_clock[b, s]:
                        info[3 + s, 3 + s] += 1.0
                singular[b], converged[b] = _gauss_newton_update_into(
                    info, rhs, usable[b], inv[b], pos[b], clk[b], tol_m, scratch
                )
                if converged[b] or it == max_iter:
                    # cross terms A^T P~ eps_q = A^T P_q eps_q - G (sig_c P_q eps_q), P_q eps_q =
                    # g3_q, of the iteration that ends (earlier iterations' are never read); each
                    # sum over the satellites c in order, c the outer loop
                    cross[b, :, :, :] = 0.0
                    for q in range(n):
                        for c in range(n_c):
                            k = cols[c]
                            for j in range(3):
                                gk = g3[q, k, j]
                                if gk != 0.0:
                                    for p in range(p_dim):
                                        e = a_all[q, k, p] - gmat[p, c] * sig_c[k]
                                        cross[b, q, p, j] += e * gk
                if converged[b]:
                    break
        return pos, clk, inv, cross, converged, singular, n_iter

    return njit(cache=True)(gauss_newton)


_gauss_newton_1 = _cooperative_gauss_newton_for(1)
_gauss_newton_2 = _cooperative_gauss_newton_for(2)
_gauss_newton_any = _cooperative_gauss_newton_for(0)


@njit(cache=True)
def cooperative_gauss_newton(transferred, problems, max_iter, tol_m):
    """Gauss-Newton of the centroid WLS with the exact structured covariance ``C*``.

    Takes the records :class:`Transferred` and :class:`Problems` (each may come as a plain
    tuple of its fields), the iteration limit and the position update below which a problem
    has converged [m].

    The model of ``cooperative._linearize`` (undifferenced form, one nuisance clock per UAV
    other than the reference and constellation) and the elimination of
    ``cooperative._structured_normal`` with ``eps_load = lam = 1 F_q`` (the exact model).

    Returns ``pos (B, 3), clk (B, n_sys), inv (B, P, P), cross (B, N, P, 3), converged (B,),
    singular (B,), n_iter (B,)``; ``cross`` is that of the last update (it is formed only
    there), undefined for a problem that ends singular before one (its fix fails).

    The sums of the small dense products run in a fixed order, the same for every problem;
    where several sums are formed together, the summation index is the outer loop, so that
    they advance side by side instead of one after another (the same numbers, computed with
    more independent work per step of the processor).

    Runs the kernel compiled for the problems' number of constellations (one or two; any
    other number, a kernel that reads it from ``has_clock``).
    """
    n_sys = problems[4].shape[1]  # has_clock
    if n_sys == 2:
        return _gauss_newton_2(transferred, problems, max_iter, tol_m)
    if n_sys == 1:
        return _gauss_newton_1(transferred, problems, max_iter, tol_m)
    return _gauss_newton_any(transferred, problems, max_iter, tol_m)


@njit(cache=True)
def fix_status(pos, converged, singular, too_few, check_radius, r_lo, r_hi):
    """Status of each fix and whether it failed (no position), as the solvers define them.

    In increasing precedence: OK (0), NOT_CONVERGED (3), IMPLAUSIBLE_POSITION (5, a converged
    fix whose geocentric distance is outside ``[r_lo, r_hi]``, when ``check_radius``),
    SINGULAR_GEOMETRY (2), TOO_FEW_SATELLITES (1). Failed: singular or too few satellites.
    The distance is ``sqrt(x*x + y*y + z*z)``, as ``numpy.linalg.norm`` sums three terms.
    """
    n = pos.shape[0]
    status = np.zeros(n, dtype=np.int64)
    failed = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        if too_few[i]:
            status[i] = 1
            failed[i] = True
        elif singular[i]:
            status[i] = 2
            failed[i] = True
        elif not converged[i]:
            status[i] = 3
        elif check_radius:
            r = np.sqrt(pos[i, 0] * pos[i, 0] + pos[i, 1] * pos[i, 1] + pos[i, 2] * pos[i, 2])
            if np.isfinite(r) and (r < r_lo or r > r_hi):
                status[i] = 5
    return status, failed


@njit(cache=True)
def n_nuisance(used, system, ref, n_sys):
    """Nuisance clocks per centroid problem: (UAV other than the reference, constellation)
    pairs with at least one used row. ``used`` (B, N, S), ``system`` (S,), ``ref`` (B,)."""
    n_b, n, s = used.shape
    out = np.zeros(n_b, dtype=np.int64)
    seen = np.zeros(n_sys, dtype=np.bool_)
    for b in range(n_b):
        for q in range(n):
            if q == ref[b]:
                continue
            seen[:] = False
            for k in range(s):
                if used[b, q, k]:
                    seen[system[k]] = True
            for j in range(n_sys):
                if seen[j]:
                    out[b] += 1
    return out


@njit(cache=True)
def setup_masks(vis, bavail, cen, system, el, n_sys, ddt, need_override):
    """The masks of ``cooperative._setup`` for ``B`` centroid problems (numpy formulation there).

    ``vis`` (N, S), ``bavail`` (B, N), ``cen`` (B,) centroid UAV or -1 for a virtual point,
    ``system`` (S,), ``el`` (N, S) [deg], ``ddt`` the transfer, ``need_override`` the SDT
    availability rule (-1: ``3 + clocks``). Returns ``ref (B,), used (B, N, S),
    has_clock (B, n_sys), pivot (B, N, n_sys), too_few (B,)``.
    """
    n_b, n = bavail.shape
    s = vis.shape[1]
    ref = cen.copy()
    used = np.zeros((n_b, n, s), dtype=np.bool_)
    has_clock = np.zeros((n_b, n_sys), dtype=np.bool_)
    pivot = np.full((n_b, n, n_sys), -1, dtype=np.int64)
    too_few = np.zeros(n_b, dtype=np.bool_)
    ref_vis = np.zeros(s, dtype=np.bool_)
    best_el = np.empty(n_sys)
    nan_seen = np.zeros(n_sys, dtype=np.bool_)
    for b in range(n_b):
        if cen[b] < 0:
            # clock reference of a virtual point: the available UAV seeing most satellites
            best, best_n = 0, -1
            for q in range(n):
                cnt = 0
                if bavail[b, q]:
                    for k in range(s):
                        if vis[q, k]:
                            cnt += 1
                if cnt > best_n:
                    best, best_n = q, cnt
            ref[b] = best if best_n > 0 else -1
        r = ref[b]
        n_ref = 0
        for k in range(s):
            ref_vis[k] = r >= 0 and vis[r, k] and bavail[b, r]
            if ref_vis[k]:
                n_ref += 1
                has_clock[b, system[k]] = True
        for q in range(n):
            if not bavail[b, q]:
                continue
            # DDT pivots: highest elevation at the reference among the satellites of the
            # constellation seen by both (first index on ties, as numpy.argmax)
            for j in range(n_sys):
                best_el[j] = -np.inf
                nan_seen[j] = False
            for k in range(s):
                if vis[q, k] and ref_vis[k]:
                    j = system[k]
                    e = el[r, k]
                    if e != e:
                        nan_seen[j] = True
                    elif pivot[b, q, j] < 0 or e > best_el[j]:
                        best_el[j] = e
                        pivot[b, q, j] = k
            for j in range(n_sys):
                if nan_seen[j] or best_el[j] == -np.inf:
                    pivot[b, q, j] = -1
            for k in range(s):
                if vis[q, k]:
                    used[b, q, k] = (not ddt) or pivot[b, q, system[k]] >= 0
        if ddt:
            too_few[b] = n_ref < 1
        elif cen[b] >= 0:
            need = need_override
            if need < 0:
                need = 3
                for j in range(n_sys):
                    if has_clock[b, j]:
                        need += 1
            too_few[b] = n_ref < need
        else:
            too_few[b] = r < 0
    return ref, used, has_clock, pivot, too_few


class Measured(NamedTuple):
    """The swarm's pseudoranges and their error model (:func:`standalone_solve`,
    :func:`cooperative_isotropic`)."""

    pr: np.ndarray  # (N, S) pseudoranges [m], NaN where not received
    vis: np.ndarray  # (N, S) bool received
    sv: np.ndarray  # (S, 3) satellite positions, ECEF [m]
    system: np.ndarray  # (S,) constellation index (sorted, for the cooperative solve)
    sigma_user: np.ndarray  # (N, S) receiver-error sigma [m]
    sig_c: np.ndarray  # (S,) common-error sigma [m]
    el: np.ndarray  # (N, S) elevations [deg] (the cooperative set-up's DDT pivots)
    n_sys: int  # clock states


class SolverLimits(NamedTuple):
    """When a Gauss-Newton solve stops and which fixes are plausible."""

    max_iter: int
    tol_m: float  # stop when the position update is below this
    check: bool  # check the geocentric distance against [lo, hi]
    lo: float
    hi: float


@njit(cache=True)
def standalone_solve(measured, x0, limits):
    """``wls.solve_standalone`` after its argument checks, in one compiled call.

    Takes the records :class:`Measured` (its elevations ``el`` are not read) and
    :class:`SolverLimits` (each may come as a plain tuple of its fields) and the starts
    ``x0`` (N, 3) ECEF [m].

    Weights ``1 / (sigma_user^2 + sigma_common^2)`` of the received pseudoranges, the
    constellations each receiver sees and the counting rule, :func:`standalone_gauss_newton`,
    :func:`fix_status`, then NaN positions/covariances of failed fixes and NaN clocks of
    constellations not seen. Returns ``pos, cov, clock, status, n_used, n_iter``.
    """
    pr_m, vis, sv, system, sigma_user, sigma_common, _el, n_sys = measured
    max_iter, tol_m, check, lo, hi = limits
    n, s = vis.shape
    w = np.zeros((n, s))
    pr = np.zeros((n, s))
    seen = np.zeros((n, n_sys), dtype=np.bool_)
    n_used = np.zeros(n, dtype=np.int64)
    too_few = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        for k in range(s):
            if vis[r, k]:
                su = sigma_user[r, k]
                sc = sigma_common[k]
                w[r, k] = 1.0 / (su * su + sc * sc)
                pr[r, k] = pr_m[r, k]
                seen[r, system[k]] = True
                n_used[r] += 1
        n_seen = 0
        for j in range(n_sys):
            if seen[r, j]:
                n_seen += 1
        too_few[r] = n_used[r] < 3 + n_seen
    pos, clock, inv, converged, singular, iters = standalone_gauss_newton(
        pr, sv, w, system, seen, ~too_few, x0, max_iter, tol_m
    )
    status, failed = fix_status(pos, converged, singular, too_few, check, lo, hi)
    cov = np.empty((n, 3, 3))
    for r in range(n):
        for a in range(3):
            for b in range(3):
                cov[r, a, b] = np.nan if failed[r] else inv[r, a, b]
            if failed[r]:
                pos[r, a] = np.nan
        for j in range(n_sys):
            if failed[r] or not seen[r, j]:
                clock[r, j] = np.nan
    n_iter = 0
    for r in range(n):
        n_iter = max(n_iter, iters[r])
    return pos, cov, clock, status, n_used, n_iter


@njit(cache=True)
def cooperative_finish(solved, setup, check, lo, hi, with_uavs):
    """``cooperative._finish``: statuses, centroid outputs and (``with_uavs``) every UAV's
    position, covariance and status from each centroid (Eq. 19-22, Appendix B):
    ``p_q = p* + x_q``, ``H_q = H* + C_d,q + Y + Y^T``, ``Y = [H A^T C~^-1 (1 F_q)]_pos F_q^T``
    (``inv[:3] @ cross @ froot^T`` summed in loops here).

    Takes the records :class:`Solved` and :class:`ProblemSetup` (each may come as a plain
    tuple of its fields) and the plausibility check of the fixes' geocentric distance
    (``check``, ``[lo, hi]``).

    Returns ``c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status``
    (the UAV arrays empty with ``with_uavs`` False).
    """
    pos, clk, inv, cross, converged, singular = solved
    rows, n_nuis, too_few_setup, has_clock, base, bcov, froot, avail = setup
    n_b, n, s = rows.shape
    n_sys = has_clock.shape[1]
    p_dim = inv.shape[1]
    n_meas = np.zeros(n_b, dtype=np.int64)
    n_uavs = np.zeros(n_b, dtype=np.int64)
    too_few = too_few_setup.copy()
    for b in range(n_b):
        for q in range(n):
            cnt = 0
            for k in range(s):
                if rows[b, q, k]:
                    cnt += 1
            n_meas[b] += cnt
            if cnt > 0:
                n_uavs[b] += 1
        n_clk = 0
        for j in range(n_sys):
            if has_clock[b, j]:
                n_clk += 1
        # counting rule: measurements minus per-UAV nuisance clocks must cover the unknowns
        if n_meas[b] - n_nuis[b] < 3 + n_clk:
            too_few[b] = True
    c_status, failed = fix_status(pos, converged, singular, too_few, check, lo, hi)
    c_pos = pos.copy()
    h_star = np.empty((n_b, 3, 3))
    c_clk = np.empty((n_b, n_sys))
    for b in range(n_b):
        for a in range(3):
            if failed[b]:
                c_pos[b, a] = np.nan
            for c in range(3):
                h_star[b, a, c] = np.nan if failed[b] else inv[b, a, c]
        for j in range(n_sys):
            c_clk[b, j] = clk[b, j] if has_clock[b, j] and not failed[b] else np.nan
    m = n if with_uavs else 0
    uav_pos = np.empty((n_b, m, 3))
    uav_cov = np.empty((n_b, m, 3, 3))
    uav_status = np.empty((n_b, m), dtype=np.int64)
    t = np.empty((3, 3))
    for b in range(n_b):
        for q in range(m):
            if not avail[b, q]:
                for a in range(3):
                    uav_pos[b, q, a] = np.nan
                    for c in range(3):
                        uav_cov[b, q, a, c] = np.nan
                uav_status[b, q] = 4 if c_status[b] == 0 else c_status[b]
                continue
            uav_status[b, q] = c_status[b]
            for a in range(3):
                uav_pos[b, q, a] = c_pos[b, a] + base[b, q, a]
            # t = inv[:3] @ cross[b, q] (3 x 3), y = t @ froot[b, q]^T
            for a in range(3):
                for c in range(3):
                    acc = 0.0
                    for pp in range(p_dim):
                        acc += inv[b, a, pp] * cross[b, q, pp, c]
                    t[a, c] = acc
            for a in range(3):
                for c in range(3):
                    y_ac = 0.0
                    y_ca = 0.0
                    for l in range(3):
                        y_ac += t[a, l] * froot[b, q, c, l]
                        y_ca += t[c, l] * froot[b, q, a, l]
                    uav_cov[b, q, a, c] = h_star[b, a, c] + bcov[b, q, a, c] + y_ac + y_ca
    return c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status


@njit(cache=True)
def sqrtm_diagonal(cov):
    """Square roots of diagonal ``(M, 3, 3)`` covariances: ``(root, True)``, or
    ``(undefined, False)`` as soon as one matrix has a non-zero (or NaN) off-diagonal entry.

    ``root = sqrt(clip(diag, 0)) * I`` elementwise, as ``cooperative._sqrtm_psd``'s numpy
    shortcut computes it (a negative zero clips to +0, NaN stays NaN).
    """
    m = cov.shape[0]
    out = np.empty((m, 3, 3))
    for i in range(m):
        for a in range(3):
            for b in range(3):
                if a != b and cov[i, a, b] != 0.0:
                    return out, False
        for a in range(3):
            d = cov[i, a, a]
            if not (d > 0.0 or d != d):
                d = 0.0
            r = np.sqrt(d)
            for b in range(3):
                out[i, a, b] = r * (1.0 if a == b else 0.0)
    return out, True


@njit(cache=True)
def isotropic_setup(rel, var, avail, cen):
    """The relative-position arrays of ``cooperative._setup`` for isotropic covariances.

    ``rel`` (B, N, 3), ``var`` and ``avail`` (B, N), ``cen`` (B,). Returns ``bavail`` (the
    centroid UAV's own entry set: a UAV always "sees" itself, as ``RelativePositions`` marks
    the diagonal), the baselines and covariances ``var * I`` masked to the available UAVs, and
    their square roots (:func:`sqrtm_diagonal`).
    """
    n_b, n = avail.shape
    bavail = avail.copy()
    for b in range(n_b):
        bavail[b, cen[b]] = True
    base = np.zeros((n_b, n, 3))
    bcov = np.zeros((n_b, n, 3, 3))
    for b in range(n_b):
        for q in range(n):
            if bavail[b, q]:
                v = var[b, q]
                for a in range(3):
                    base[b, q, a] = rel[b, q, a]
                    for c in range(3):
                        bcov[b, q, a, c] = v * (1.0 if a == c else 0.0)
    froot = sqrtm_diagonal(bcov.reshape((n_b * n, 3, 3)))[0].reshape((n_b, n, 3, 3))
    return bavail, base, bcov, froot


class CentroidProblems(NamedTuple):
    """One cooperative problem per centroid UAV, with isotropic relative positions
    (:func:`cooperative_isotropic`)."""

    rel: np.ndarray  # (B, N, 3) position of each UAV relative to centroid UAV cen[b], ECEF
    var: np.ndarray  # (B, N) per-axis variance of each (covariance var * I)
    avail: np.ndarray  # (B, N) bool (the centroid UAV's own entry is taken as True)
    cen: np.ndarray  # (B,) centroid UAV of each problem
    x0: np.ndarray  # (B, 3) ECEF starts
    ddt: bool  # the transfer: DDT (else SDT)
    need_override: int  # the SDT availability rule (-1: 3 + clocks)


@njit(cache=True)
def cooperative_isotropic(measured, problems, limits, with_uavs):
    """A whole ``solve_cooperative`` (exact covariance, UAV centroids) in one compiled call.

    Takes the records :class:`Measured`, :class:`CentroidProblems` and :class:`SolverLimits`
    (each may come as a plain tuple of its fields) and ``with_uavs``: every UAV's position
    and covariance from each centroid as well.

    For relative positions with isotropic covariances ``var * I`` (the simulator's relative
    sensing), the same kernels with the same arguments as the Python path of
    ``cooperative.solve_cooperative`` (``_setup``, ``_gauss_newton``, ``_finish``): the
    baselines and covariances masked to the available UAVs, :func:`setup_masks`,
    :func:`sqrtm_diagonal`, :func:`cooperative_gauss_newton`, :func:`n_nuisance`,
    :func:`cooperative_finish`; so the results are those of that path, bit for bit
    (``tests/nav/test_kernels.py``), without its Python calls between the kernels.

    Returns ``c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status,
    n_iter`` as :func:`cooperative_finish` plus the largest iteration count.
    """
    pr, vis, sv, system, sigma_user, sig_c, el, n_sys = measured
    rel, var, avail, cen, x0, ddt, need_override = problems
    max_iter, tol_m, check, lo, hi = limits
    n_b, n = avail.shape
    s = vis.shape[1]
    bavail, base, bcov, froot = isotropic_setup(rel, var, avail, cen)
    ref, used, has_clock, _pivot, too_few = setup_masks(
        vis, bavail, cen, system, el, n_sys, ddt, need_override
    )
    pr0 = np.zeros((1, n, s))
    for q in range(n):
        for k in range(s):
            if vis[q, k]:
                pr0[0, q, k] = pr[q, k]
    usable = np.empty(n_b, dtype=np.bool_)
    for b in range(n_b):
        usable[b] = not too_few[b]
    pos, clk, inv, cross, converged, singular, iters = cooperative_gauss_newton(
        Transferred(pr0, sv, vis, sigma_user, sig_c, system),
        Problems(used, base, froot, ref, has_clock, usable, x0),
        max_iter,
        tol_m,
    )
    n_iter = 0
    for b in range(n_b):
        n_iter = max(n_iter, iters[b])
    n_nuis = n_nuisance(used, system, ref, n_sys)
    c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status = (
        cooperative_finish(
            Solved(pos, clk, inv, cross, converged, singular),
            ProblemSetup(used, n_nuis, too_few, has_clock, base, bcov, froot, bavail),
            check,
            lo,
            hi,
            with_uavs,
        )
    )
    return c_pos, h_star, c_clk, c_status, n_uavs, n_meas, uav_pos, uav_cov, uav_status, n_iter
