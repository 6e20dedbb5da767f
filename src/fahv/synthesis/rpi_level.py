"""The exact RPI level of an ellipsoidal tube: the worst one-step level over Z and W.

A tube Z = {e : e' N^-1 e <= 1} is robust positively invariant (RPI) for
e+ = A_cl,i e + w, w in the box W, at every vertex i exactly when

    level = max_i max_{e in Z, w in W} (A_cl,i e + w)' N^-1 (A_cl,i e + w) <= 1.

The level is convex in (e, w), so over the box W its maximum lies at a corner; over the
ellipsoid it is a trust-region subproblem, solved through its dual (:func:`max_on_ball`,
compiled with numba). Whatever found N (an LMI, a scaling, a file), this level is the
certificate: it trusts no solver.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np


def max_on_ball(M: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Max over |u| <= 1 of |M u + c_l|^2 per row c_l of c, bounded from above.

    Exact up to rounding, never below the maximum. The trust-region
    subproblem max u'G u + 2 b'u + c'c (G = M'M, b = M'c) has no duality gap (Moré and
    Sorensen 1983): it equals the minimum over lam >= sigma_max^2 of the convex dual
    function lam + b'(lam I - G)^-1 b + c'c, attained where |(lam I - G)^-1 b| = 1 (the
    secular equation), or at lam = sigma_max^2 in the hard case. A safeguarded Newton
    iteration (:func:`_dual_bound`) brackets that minimiser; the dual function at any
    lam above sigma_max^2 bounds the maximum from above (weak duality), with an error of
    second order in the distance to the minimiser (the function's slope vanishes there).
    A primal point of that lam, its norm filled up to 1 along the top eigenvector, is no
    bound: in the nearly hard case the fill leaves the ball and overstates a level (by
    4e-3 on a tube of this vehicle).

    Parameters
    ----------
    M : (n, n) ndarray
        The map on the unit ball.
    c : (L, n) ndarray
        Offsets, one per row.

    Returns
    -------
    (L,) ndarray
        Upper bounds of max_u |M u + c_l|^2.

    Examples
    --------
    On a diagonal map the maximum lies along an axis, here (2 + 0)^2, (2 + 1)^2, (1 + 3)^2:

    >>> M = np.diag([2.0, 1.0])
    >>> c = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 3.0]])
    >>> [round(float(v), 9) for v in max_on_ball(M, c)]
    [4.0, 9.0, 16.0]
    """
    s, V = np.linalg.eigh(M.T @ M)
    b = np.ascontiguousarray((c @ M) @ V)  # (L, n): components of M'c in the eigenbasis
    cc = np.einsum("li,li->l", c, c)
    return _dual_kernel()(s, b, cc, 200)


@functools.cache
def _dual_kernel():
    """:func:`_dual_bound` compiled by numba (cached on disk), built at its first use.

    The iteration is up to 200 steps for each of L rows: in numpy, its per-call overhead
    made it 70 % of an onset bound's time (benchmarks/bench_certificate.py).
    """
    import numba

    return numba.njit(cache=True, error_model="numpy")(_dual_bound)


def _dual_bound(s, b, cc, steps):  # pragma: no cover - compiled
    """The dual bound of :func:`max_on_ball` per row, in the eigenbasis of M'M.

    s (n,) ascending eigenvalues, b (L, n) the rows' M'c in that basis, cc (L,) |c_l|^2,
    ``steps`` iterations at most; returns (L,) upper bounds of the maxima. The minimiser
    lam* > sigma_max^2 of the dual function is where psi(lam) = 1 / |x(lam)| - 1 = 0,
    x(lam) = (lam I - G)^-1 b; psi is nearly linear in lam, so Newton's method on it
    (Moré and Sorensen 1983) reaches lam* in a few steps. Each step is kept inside a
    bracket [lo, hi] of lam* (|x| > 1 at lo, <= 1 at hi) and bisects it where Newton
    would leave it; the iteration stops when the bracket or the step falls below the
    float spacing. The dual function is evaluated at the last hi and the last iterate
    (both above sigma_max^2, so both bound the maximum: weak duality) and the smaller
    is returned; its error is of second order in the distance to lam*.
    """
    n_rows, n = b.shape
    smax = s[n - 1]
    out = np.empty(n_rows)
    for r in range(n_rows):
        bb = 0.0
        for j in range(n):
            bb += b[r, j] * b[r, j]
        lo = smax
        hi = smax + np.sqrt(bb) + 1.0  # |x(hi)| <= |b| / (hi - smax) < 1
        lam = hi
        for _ in range(steps):
            norm2 = 0.0  # |x(lam)|^2, the secular function, and its slope
            slope = 0.0
            for j in range(n):
                d = lam - s[j]
                t = b[r, j] * b[r, j] / (d * d)
                norm2 += t
                slope -= 2.0 * t / d
            if norm2 > 1.0:
                lo = lam
            else:
                hi = lam
            nxt = 0.5 * (lo + hi)
            if norm2 > 0.0 and slope < 0.0:  # Newton on psi = |x|^-1 - 1
                nrm = np.sqrt(norm2)
                step = (1.0 / nrm - 1.0) / (-0.5 * slope / (norm2 * nrm))
                if abs(step) <= 1e-15 * lam:  # converged to the float spacing
                    break
                if lo < lam - step < hi:
                    nxt = lam - step
            if nxt <= lo or nxt >= hi or hi - lo <= 1e-15 * hi:
                break
            lam = nxt
        best = np.inf
        for at in (hi, lam):
            if at > smax:  # >= 0 gaps; 0 only along the top eigenvector, where b_j = 0
                total = cc[r] + at
                for j in range(n):
                    if b[r, j] != 0.0:
                        total += b[r, j] * b[r, j] / (at - s[j])
                best = min(best, total)
        out[r] = best
    return out


def worst_level(A, B, F, N, w_max, tau: float = 1.0, pulse=None):
    """Exact max of (A_cl,i e + w)' (tau^2 N)^-1 (A_cl,i e + w) over e in tau Z, w in W.

    The level is convex in (e, w), so over the box W its maximum lies at a corner; over
    the ellipsoid the trust-region subproblem of :func:`max_on_ball` is solved by its
    dual (an upper bound, exact up to the bisection's rounding). The tube is RPI for W
    if the result is at most 1.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices (the fault vertices included).
    F : (m, n) ndarray
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) ndarray
        Half-widths of W (a zero row: no disturbance there, one corner).
    tau : float
        Adjustable factor (eq. 54): the tube is tau Z, the gain tau F.
    pulse : (g, n) ndarray, optional
        Pulse generators G: w ranges over W + {G' p : |p| <= 1} (the corners of both).

    Returns
    -------
    level : float
        The worst one-step level (1: the boundary of the tube).
    where : tuple
        (vertex index, corner of W (and of p) as signs (n + g,)).

    Examples
    --------
    One state: A_cl = 0.9 - 0.4 = 0.5, Z = [-2, 2] (N = 4), W = [-0.5, 0.5]; the level
    is (|A_cl| sqrt(N) + w)^2 / N = (1 + 0.5)^2 / 4:

    >>> A, B, F, N = np.array([[[0.9]]]), np.array([[[1.0]]]), np.array([[-0.4]]), np.eye(1) * 4
    >>> level, (vertex, corner) = worst_level(A, B, F, N, [0.5])
    >>> round(level, 9), vertex, corner.tolist()
    (0.5625, 0, [-1.0])
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    Acl = A + B @ (tau * np.asarray(F, float))
    lev, corner, signs = _levels(Acl, tau**2 * np.asarray(N, float), w_max, pulse)
    i = int(np.argmax(lev))
    return float(lev[i]), (i, signs[corner[i]])


def vertex_levels(Acl, N, w_max, pulse=None) -> np.ndarray:
    """Exact worst one-step level of each closed-loop vertex (:func:`worst_level`).

    Parameters
    ----------
    Acl : (R, n, n) ndarray
        Closed-loop vertices.
    N : (n, n) ndarray
        Shape of the set, {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W (a zero row: no disturbance there).
    pulse : (g, n) ndarray, optional
        Pulse generators, as in :func:`worst_level`.

    Returns
    -------
    (R,) ndarray
        max over e in the set and w in W of (A_cl,i e + w)' N^-1 (A_cl,i e + w).

    Examples
    --------
    One state, N = 1, w = 0.1: the levels are (|a_i| + 0.1)^2:

    >>> levels = vertex_levels(np.array([[[0.5]], [[-0.9]]]), np.eye(1), [0.1])
    >>> [round(float(v), 9) for v in levels]
    [0.36, 1.0]
    """
    return _levels(np.asarray(Acl, float), np.asarray(N, float), w_max, pulse)[0]


def _levels(Acl, Ns, w_max, pulse):
    """Levels (R,), the worst corner's index (R,) and the corners' signs of every vertex.

    The vertices' maps M_i = L^-1 A_cl,i L (N = L L') and the eigen-decompositions of
    M_i' M_i are batched in numpy; the dual bound of every corner at every vertex runs
    in one compiled loop over the vertices, spread over the cores
    (:func:`_vertex_kernel`): the same bound as :func:`max_on_ball`, vertex by vertex.
    """
    L = np.linalg.cholesky(Ns)
    Linv = np.linalg.inv(L)
    n = Ns.shape[0]
    G = np.zeros((0, n)) if pulse is None else np.atleast_2d(np.asarray(pulse, float))
    w_max = np.asarray(w_max, float)
    free = np.r_[w_max != 0.0, np.ones(len(G), bool)]  # a zero half-width has one corner
    signs = np.ones((2 ** int(free.sum()), n + len(G)))
    signs[:, free] = np.array(list(itertools.product((-1.0, 1.0), repeat=int(free.sum()))))
    C = (signs[:, :n] * w_max[None, :] + signs[:, n:] @ G) @ Linv.T
    M = Linv[None] @ np.asarray(Acl, float) @ L[None]
    s, V = np.linalg.eigh(M.transpose(0, 2, 1) @ M)
    CM = np.ascontiguousarray(M @ V)  # (R, n, n): row l of C @ CM[i] is b_l of vertex i
    cc = np.einsum("li,li->l", C, C)
    lev, corner = _vertex_kernel()(np.ascontiguousarray(s), CM, np.ascontiguousarray(C), cc, 200)
    return lev, corner, signs


@functools.cache
def _vertex_kernel():
    """:func:`_vertex_bounds` compiled by numba with a parallel loop over the vertices."""
    import numba

    dual = numba.njit(cache=True, error_model="numpy")(_dual_bound)
    body = _vertex_bounds_factory(dual)
    return numba.njit(cache=True, parallel=True, error_model="numpy")(body)


def _vertex_bounds_factory(dual):
    """The all-vertex loop around the compiled per-vertex dual bound ``dual``."""
    import numba

    def _vertex_bounds(s, CM, C, cc, steps):  # pragma: no cover - compiled
        """Worst dual bound (R,) and its corner (R,) of every vertex (:func:`_levels`)."""
        R = s.shape[0]
        lev = np.empty(R)
        corner = np.empty(R, np.int64)
        for i in numba.prange(R):
            li = dual(s[i], C @ CM[i], cc, steps)
            k = np.argmax(li)
            corner[i] = k
            lev[i] = li[k]
        return lev, corner

    return _vertex_bounds


def rpi_margin(A, B, F, N, w_max, tau: float = 1.0, hi: float = 4.0) -> float:
    """Largest factor g in [0, hi] such that the tube stays RPI for g W.

    Bisection on :func:`worst_level` (30 halvings of [0, hi], or of [0, 1] when the
    tube is not RPI for W itself).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices (the fault vertices included).
    F : (m, n) ndarray
        Tube gain.
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W (state units).
    tau : float
        Adjustable factor (eq. 54), as in :func:`worst_level`.
    hi : float
        Largest factor searched.

    Returns
    -------
    float
        The factor (to 2^-30 of the interval); 0 if the tube is not invariant even
        without a disturbance (some vertex's closed loop expands Z).

    Examples
    --------
    One state, A_cl = 0.5, Z = [-1, 1], W = [-0.25, 0.25]: RPI while 0.5 + g 0.25 <= 1:

    >>> A, B, F = np.array([[[0.5]]]), np.zeros((1, 1, 1)), np.zeros((1, 1))
    >>> round(rpi_margin(A, B, F, np.eye(1), [0.25]), 6)
    2.0
    >>> rpi_margin(2.0 * A + 0.5, B, F, np.eye(1), [0.25])  # A_cl = 1.5 expands Z
    0.0
    """
    if worst_level(A, B, F, N, 0.0 * np.asarray(w_max, float), tau)[0] > 1.0:
        return 0.0
    lo = 0.0
    if worst_level(A, B, F, N, w_max, tau)[0] > 1.0:
        hi = 1.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if worst_level(A, B, F, N, mid * np.asarray(w_max), tau)[0] <= 1.0:
            lo = mid
        else:
            hi = mid
    return lo
