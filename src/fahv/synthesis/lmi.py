"""Helpers shared by the LMI designs: scaling and numerical certificate checks."""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from fahv.errors import DesignError

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
    """Solve an LMI problem with :data:`SDP_SOLVER`.

    "optimal_inaccurate" counts as solved: every caller re-checks its certificate.

    Parameters
    ----------
    prob : cvxpy.Problem

    Returns
    -------
    bool
        False if the solver fails or finds no (near-)optimal point.
    """
    try:
        prob.solve(solver=SDP_SOLVER, **SDP_OPTIONS)
    except cp.error.SolverError:
        return False
    return prob.status in ("optimal", "optimal_inaccurate")


#: A constraint whose dual is below this share of the largest one is not in the
#: solution's support (:func:`dual_support`): constraint generation releases it.
SUPPORT_RTOL = 1e-6


def dual_support(constraints) -> np.ndarray:
    """Positions of the constraints whose dual carries the solution.

    The activity of a constraint is the trace of its dual (a scalar's dual for a scalar
    constraint); those above :data:`SUPPORT_RTOL` of the largest are the support. Of a
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
        Their positions in ``constraints`` (all of them where no dual is available).
    """
    if not constraints:
        return np.zeros(0, int)
    tr = np.array([np.trace(np.atleast_2d(c.dual_value)) if c.dual_value is not None else np.inf
                   for c in constraints])  # fmt: skip
    return np.flatnonzero(~(tr <= SUPPORT_RTOL * np.max(tr[np.isfinite(tr)], initial=0.0)))


def scale_vertices(A: np.ndarray, B: np.ndarray, Dx: np.ndarray, Du: np.ndarray):
    """Scaled vertices A_s = D_x^-1 A D_x (R, n, n), B_s = D_x^-1 B D_u (R, n, m)."""
    return A * Dx[None, None, :] / Dx[None, :, None], B * Du[None, None, :] / Dx[None, :, None]


def min_eig(M: np.ndarray) -> float:
    """Smallest eigenvalue of the symmetric part of M."""
    return float(np.linalg.eigvalsh(0.5 * (M + M.T)).min())


def psd_tolerance(M: np.ndarray, rtol: float = 1e-9) -> float:
    """Tolerance of :func:`require_psd`: rtol max(1, max |M_ij|) (>= 0)."""
    return float(rtol * max(1.0, float(np.abs(M).max())))


def require_psd(M: np.ndarray, what: str, rtol: float = 1e-9) -> float:
    """Check M >= -rtol ||M|| I; return the smallest eigenvalue.

    ``||M||`` is max(1, max |M_ij|) (:func:`psd_tolerance`): an eigenvalue that is
    negative by less than that tolerance is rounding of the solver and accepted.

    Raises
    ------
    DesignError
        Naming ``what``, the eigenvalue found and the tolerance, if the check fails.
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
