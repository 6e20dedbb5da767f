"""The exact RPI level of an ellipsoidal tube: the worst one-step level over Z and W.

A tube Z = {e : e' N^-1 e <= 1} is robust positively invariant (RPI) for
e+ = A_cl,i e + w, w in the box W, at every vertex i exactly when

    level = max_i max_{e in Z, w in W} (A_cl,i e + w)' N^-1 (A_cl,i e + w) <= 1.

The level is convex in (e, w), so over the box W its maximum lies at a corner; over the
ellipsoid it is a trust-region subproblem, solved through its dual (`max_on_ball`,
compiled with numba). Whatever found N (an LMI, a scaling, a file), this level is the
certificate: it trusts no solver.
"""

from __future__ import annotations

import itertools

import numpy as np


def max_on_ball(M: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Max over |u| <= 1 of |M u + c_l|^2 per row c_l of c, bounded from above.

    Exact up to rounding, never below the maximum. The trust-region
    subproblem max u'G u + 2 b'u + c'c (G = M'M, b = M'c) has no duality gap (Moré and
    Sorensen 1983): it equals the minimum over lam >= sigma_max^2 of the convex dual
    function lam + b'(lam I - G)^-1 b + c'c, attained where |(lam I - G)^-1 b| = 1 (the
    secular equation), or at lam = sigma_max^2 in the hard case. A safeguarded Newton
    iteration (`fahv.synthesis.rpi_kernels.dual_bound`) brackets that minimiser;
    the dual function at any lam above sigma_max^2 bounds the maximum from above (weak
    duality), with an error of second order in the distance to the minimiser (the
    function's slope vanishes there).
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


def _dual_kernel():
    """The compiled dual bound (`fahv.synthesis.rpi_kernels.dual_bound`).

    Imported at its first use, so that numba is loaded only where a level is computed;
    compiled once and cached on disk. The iteration is up to 200 steps for each of L
    rows: in numpy, its per-call overhead made it 70 % of an onset bound's time
    (benchmarks/bench_certificate.py).
    """
    from fahv.synthesis.rpi_kernels import dual_bound

    return dual_bound


def worst_level(A, B, F, N, w_max, tau: float = 1.0, pulse=None):
    """Exact max of (A_cl,i e + w)' (tau^2 N)^-1 (A_cl,i e + w) over e in tau Z, w in W.

    The level is convex in (e, w), so over the box W its maximum lies at a corner; over
    the ellipsoid the trust-region subproblem of `max_on_ball` is solved by its
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
    """Exact worst one-step level of each closed-loop vertex (`worst_level`).

    Parameters
    ----------
    Acl : (R, n, n) ndarray
        Closed-loop vertices.
    N : (n, n) ndarray
        Shape of the set, {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W (a zero row: no disturbance there).
    pulse : (g, n) ndarray, optional
        Pulse generators, as in `worst_level`.

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
    (`_vertex_kernel`): the same bound as `max_on_ball`, vertex by vertex.
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


def _vertex_kernel():
    """The compiled all-vertex loop (`fahv.synthesis.rpi_kernels.vertex_bounds`)."""
    from fahv.synthesis.rpi_kernels import vertex_bounds

    return vertex_bounds


def rpi_margin(A, B, F, N, w_max, tau: float = 1.0, hi: float = 4.0) -> float:
    """Largest factor g in [0, hi] such that the tube stays RPI for g W.

    Bisection on `worst_level` (30 halvings of [0, hi], or of [0, 1] when the
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
        Adjustable factor (eq. 54), as in `worst_level`.
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
