"""Helpers shared by the LMI designs: scaling and numerical certificate checks."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fahv.errors import DesignError

if TYPE_CHECKING:  # cvxpy only where a problem is built: the checks load none
    import cvxpy as cp

#: Solver used for every LMI (interior point, handles SDP cones); see docs/reference/environment.md.
SDP_SOLVER = "CLARABEL"
#: Its options: one thread, so that a solve gives the same numbers on every run (a
#: parallel factorisation may sum in another order) and two design processes on two
#: cores do not contend for four threads (measured: 2 threads took twice one's time then).
SDP_OPTIONS = {"max_threads": 1}

#: Strict margin of the RPI LMI blocks (scaled units), so that the solver's tolerance
#: cannot break the re-check.
LMI_MARGIN = 1e-5


def solve_lmi(prob: cp.Problem) -> bool:
    """Solve an LMI problem with `SDP_SOLVER`.

    "optimal_inaccurate" counts as solved: every caller re-checks its certificate.

    Parameters
    ----------
    prob : cvxpy.Problem

    Returns
    -------
    bool
        False if the solver fails or finds no (near-)optimal point.

    Examples
    --------
    >>> import cvxpy as cp
    >>> x = cp.Variable()
    >>> prob = cp.Problem(cp.Minimize(x), [x >= 1.0, x >= -5.0])
    >>> solve_lmi(prob), round(float(prob.value), 6)
    (True, 1.0)
    """
    import cvxpy as cp

    try:
        prob.solve(solver=SDP_SOLVER, **SDP_OPTIONS)
    except cp.error.SolverError:
        return False
    return prob.status in ("optimal", "optimal_inaccurate")


#: A constraint whose dual is below this share of the largest one is not in the
#: solution's support (`dual_support`): constraint generation releases it.
SUPPORT_RTOL = 1e-6


def dual_support(constraints) -> np.ndarray:
    """Positions of the constraints whose dual carries the solution.

    The activity of a constraint is the trace of its dual (a scalar's dual for a scalar
    constraint); those above `SUPPORT_RTOL` of the largest are the support. Of a
    convex problem in d unknowns, at most d constraints support the optimum; the rest
    can be left out without changing it, which constraint generation uses to keep its
    LMIs small.

    Parameters
    ----------
    constraints : sequence of cvxpy.Constraint
        Constraints of a solved problem.

    Returns
    -------
    (s,) ndarray of int
        Their positions in `constraints` (all of them where no dual is available).

    Examples
    --------
    >>> import cvxpy as cp
    >>> x = cp.Variable()
    >>> constraints = [x >= 1.0, x >= -5.0]
    >>> solve_lmi(cp.Problem(cp.Minimize(x), constraints))
    True
    >>> dual_support(constraints).tolist()  # x >= -5 does not bind
    [0]
    """
    if not constraints:
        return np.zeros(0, int)
    tr = np.array([np.trace(np.atleast_2d(c.dual_value)) if c.dual_value is not None else np.inf
                   for c in constraints])  # fmt: skip
    return np.flatnonzero(~(tr <= SUPPORT_RTOL * np.max(tr[np.isfinite(tr)], initial=0.0)))


def scale_vertices(A: np.ndarray, B: np.ndarray, Dx: np.ndarray, Du: np.ndarray):
    """Scaled vertices A_s = D_x^-1 A D_x (R, n, n), B_s = D_x^-1 B D_u (R, n, m).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices (unscaled).
    Dx : (n,) ndarray
        State scales (state units).
    Du : (m,) ndarray
        Input scales (input units).

    Returns
    -------
    A_s : (R, n, n) ndarray
    B_s : (R, n, m) ndarray
        The vertices in scaled coordinates.

    Examples
    --------
    >>> A, B = np.array([[[1.0, 2.0], [3.0, 4.0]]]), np.array([[[1.0], [1.0]]])
    >>> As, Bs = scale_vertices(A, B, np.array([1.0, 10.0]), np.array([2.0]))
    >>> As.tolist(), Bs.tolist()
    ([[[1.0, 20.0], [0.3, 4.0]]], [[[2.0], [0.2]]])
    """
    return A * Dx[None, None, :] / Dx[None, :, None], B * Du[None, None, :] / Dx[None, :, None]


def min_eig(M: np.ndarray) -> float:
    """Smallest eigenvalue of the symmetric part of M.

    Parameters
    ----------
    M : (k, k) ndarray
        Square matrix.

    Returns
    -------
    float
        The smallest eigenvalue of (M + M') / 2.

    Examples
    --------
    >>> round(min_eig(np.array([[2.0, 1.0], [1.0, 2.0]])), 12)
    1.0
    >>> round(min_eig(np.array([[1.0, 4.0], [0.0, 1.0]])), 12)  # symmetric part [[1, 2], [2, 1]]
    -1.0
    """
    return float(np.linalg.eigvalsh(0.5 * (M + M.T)).min())


def psd_tolerance(M: np.ndarray, rtol: float = 1e-9) -> float:
    """Tolerance of `require_psd`: rtol max(1, max |M_ij|) (>= 0).

    Parameters
    ----------
    M : (k, k) ndarray
        The matrix checked.
    rtol : float
        Relative tolerance.

    Returns
    -------
    float
        The largest negative eigenvalue accepted, in absolute value.

    Examples
    --------
    >>> psd_tolerance(np.eye(2)), round(psd_tolerance(np.array([[1e3]])), 15)
    (1e-09, 1e-06)
    """
    return float(rtol * max(1.0, float(np.abs(M).max())))


def require_psd(M: np.ndarray, what: str, rtol: float = 1e-9) -> float:
    """Check M >= -rtol ||M|| I; return the smallest eigenvalue.

    `||M||` is max(1, max |M_ij|) (`psd_tolerance`): an eigenvalue that is
    negative by less than that tolerance is rounding of the solver and accepted.

    Parameters
    ----------
    M : (k, k) ndarray
        The matrix checked (its symmetric part).
    what : str
        What M is, for the error message.
    rtol : float
        Relative tolerance.

    Returns
    -------
    float
        The smallest eigenvalue of M's symmetric part (>= -tolerance).

    Raises
    ------
    DesignError
        Naming `what`, the eigenvalue found and the tolerance, if the check fails.

    Examples
    --------
    >>> require_psd(np.eye(2), "I"), require_psd(np.diag([1.0, -1e-12]), "nearly PSD")
    (1.0, -1e-12)
    >>> require_psd(np.diag([1.0, -1.0]), "M")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
        ...
    fahv.errors.DesignError: certificate failed: M has eigenvalue -1.000e+00 < -1.00e-09 ...
    """
    e = min_eig(M)
    tol = psd_tolerance(M, rtol)
    if not np.isfinite(e) or e < -tol:
        raise DesignError(
            f"certificate failed: {what} has eigenvalue {e:.3e} < -{tol:.2e} (tolerance)"
        )
    return e


def invariance_blocks(AP, lam, mu, P, E) -> np.ndarray:
    """The S-procedure blocks [[lam P, 0, AP'], [0, diag(mu), E'], [AP, E, P]] of RPI.

    A block is positive semidefinite exactly when (A_cl e + E w)' P^-1 (A_cl e + E w) <=
    lam e' P^-1 e + sum_j mu_j w_j^2 for every e and w (the S-procedure form of LMI (24)).

    Parameters
    ----------
    AP : (R, n, n) ndarray
        A_cl,i P stacked over the vertices.
    lam : float
        Contraction factor.
    mu : (p,) ndarray
        Multipliers of the disturbance's generators.
    P : (n, n) ndarray
        The ellipsoid's shape.
    E : (n, p) ndarray
        Map of the p generators of the disturbance.

    Returns
    -------
    (R, 2n + p, 2n + p) ndarray

    Examples
    --------
    One state, e+ = 0.5 e + w, P = 1, lam = 0.9: the condition holds for mu = 2, not for
    mu = 1 (it needs mu >= 1 + 0.25 / 0.65):

    >>> AP, P, E = np.array([[[0.5]]]), np.eye(1), np.eye(1)
    >>> invariance_blocks(AP, 0.9, np.array([2.0]), P, E).shape
    (1, 3, 3)
    >>> [min_eig(invariance_blocks(AP, 0.9, np.array([mu]), P, E)[0]) >= 0 for mu in (2.0, 1.0)]
    [True, False]
    """
    R, n, _ = AP.shape
    p = E.shape[1]
    blk = np.zeros((R, 2 * n + p, 2 * n + p))
    blk[:, :n, :n] = lam * P
    blk[:, n : n + p, n : n + p] = np.diag(mu)
    blk[:, n : n + p, n + p :] = E.T
    blk[:, n + p :, n : n + p] = E
    blk[:, n + p :, :n] = AP
    blk[:, :n, n + p :] = AP.transpose(0, 2, 1)
    blk[:, n + p :, n + p :] = P
    return blk
