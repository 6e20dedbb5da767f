"""Nominal gain K from the min-max LMI problem (32)-(35) (Kothare et al. 1996, ref. [37]).

For the nominal system x_n(k+1) = A(p) x_n + B(p) u_n (eq. 20/46), minimise gamma_n
subject to, with Q > 0, Y, X = diag(X_jj)::

    [[1, x_n0'], [x_n0, Q]] >= 0                                            (33)
    [[Q, (A_i Q + B_i Y)', Q psi^1/2, Y' sigma^1/2],
     [A_i Q + B_i Y, Q, 0, 0], [psi^1/2 Q, 0, gamma I, 0],
     [sigma^1/2 Y, 0, 0, gamma I]] >= 0       for every vertex i            (34)
    [[X, Y], [Y', Q]] >= 0,  X_jj <= u_n,max,j^2                            (35)

K = Y Q^-1. The ellipsoid {x' Q^-1 x <= 1} contains x_n0, is invariant for every vertex
and keeps |K_j x| <= u_n,max,j inside it, so a K computed once for the initial nominal
state stays valid along the whole nominal trajectory (there is no disturbance on it).
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from fahv.errors import DesignError
from fahv.tube.lmi import SDP_SOLVER, require_psd, scale_vertices


@dataclass(frozen=True)
class NominalDesign:
    """Nominal gain and its invariant ellipsoid (unscaled units).

    Attributes
    ----------
    K : (m, n) ndarray
        Nominal gain, u_n = K x_n.
    Q : (n, n) ndarray
        Ellipsoid {x : x' Q^-1 x <= 1} (eq. 33).
    gamma : float
        Upper bound gamma_n of the infinite-horizon cost (eq. 31-32), scaled units.
    u_max : (m,) ndarray
        Nominal input bounds used in (35).
    x0 : (n,) ndarray
        Nominal state the design was made for.
    """

    K: np.ndarray
    Q: np.ndarray
    gamma: float
    u_max: np.ndarray
    x0: np.ndarray


def _block34(As_i, Bs_i, Qs, Ys, gamma, ps, ss):
    n, m = Qs.shape[0], Ys.shape[0]
    AQ = As_i @ Qs + Bs_i @ Ys
    return np.block(
        [
            [Qs, AQ.T, Qs @ np.diag(ps), Ys.T @ np.diag(ss)],
            [AQ, Qs, np.zeros((n, n)), np.zeros((n, m))],
            [np.diag(ps) @ Qs, np.zeros((n, n)), gamma * np.eye(n), np.zeros((n, m))],
            [np.diag(ss) @ Ys, np.zeros((m, n)), np.zeros((m, n)), gamma * np.eye(m)],
        ]
    )


def verify_nominal(A, B, nd: NominalDesign, psi, sigma, Dx, Du) -> dict[str, float]:
    """Re-check the certificate of (33)-(35) numerically, on the LMI blocks themselves.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete nominal vertices (unscaled).
    nd : NominalDesign
    psi : (n,) ndarray
    sigma : (m,) ndarray
        Diagonal weights of (31) in scaled units.
    Dx : (n,) ndarray
    Du : (m,) ndarray

    Returns
    -------
    dict
        ``containment`` = x0' Q^-1 x0 (<= 1); ``lmi34_min_eig``: smallest eigenvalue
        of the block (34) over the vertices with Y = K Q (>= 0; by the Schur complement
        this is the Lyapunov decrease A_cl' P A_cl - P + (psi + K' sigma K)/gamma <= 0,
        P = Q^-1); ``input_ratio`` = max_j sqrt(K_j Q K_j') / u_max,j (<= 1);
        ``spectral_radius`` = max_i rho(A_i + B_i K) (< 1).

    Raises
    ------
    DesignError
        If any of them does not hold.
    """
    As, Bs = scale_vertices(A, B, Dx, Du)
    Qs = nd.Q / np.outer(Dx, Dx)
    Ks = nd.K * Dx[None, :] / Du[:, None]
    Ys = Ks @ Qs
    require_psd(Qs, "nominal ellipsoid Q")
    x0s = nd.x0 / Dx
    cont = float(x0s @ np.linalg.solve(Qs, x0s))
    if cont > 1.0 + 1e-7:
        raise DesignError(f"certificate failed: x_n0 not in the nominal ellipsoid (33): {cont:.6g}")
    ps, ss = np.sqrt(np.asarray(psi, float)), np.sqrt(np.asarray(sigma, float))
    eigs = [
        require_psd(
            _block34(As[i], Bs[i], Qs, Ys, nd.gamma, ps, ss), f"LMI (34) at vertex {i}", rtol=1e-12
        )
        for i in range(As.shape[0])
    ]
    rho = max(max(abs(np.linalg.eigvals(As[i] + Bs[i] @ Ks))) for i in range(As.shape[0]))
    if rho >= 1.0:
        raise DesignError(f"certificate failed: nominal closed loop not stable, rho = {rho:.6g}")
    ratio = float(np.max(np.sqrt(np.einsum("ij,jk,ik->i", nd.K, nd.Q, nd.K)) / nd.u_max))
    if ratio > 1.0 + 1e-6:
        raise DesignError(
            f"certificate failed: nominal input bound (35) exceeded, ratio {ratio:.6g}"
        )
    return {
        "containment": cont,
        "lmi34_min_eig": float(min(eigs)),
        "input_ratio": ratio,
        "spectral_radius": float(rho),
    }


def design_nominal(A, B, x0, u_max, psi, sigma, Dx, Du) -> NominalDesign:
    """Solve (32)-(35) for the nominal gain K in scaled coordinates.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete nominal vertices (unscaled).
    x0 : (n,) array_like
        Initial nominal state (deviation from the commanded trim).
    u_max : (m,) array_like
        Nominal input bounds u_n,max (after tightening, eq. 30), unscaled.
    psi : (n,) array_like
    sigma : (m,) array_like
        Diagonal state and input weights of (31) in scaled units.
    Dx : (n,) ndarray
    Du : (m,) ndarray

    Returns
    -------
    NominalDesign
        Certified by :func:`verify_nominal`.

    Raises
    ------
    DesignError
        If u_max is not positive (U minus F Z empty), the LMI is infeasible, or the
        certificate fails.
    """
    u_max = np.asarray(u_max, float)
    if np.any(~np.isfinite(u_max)) or np.any(u_max <= 0.0):
        raise DesignError(f"nominal input bounds must be > 0 (U minus F Z empty): {u_max}")
    As, Bs = scale_vertices(np.asarray(A), np.asarray(B), Dx, Du)
    R, n, m = Bs.shape
    x0s = np.asarray(x0, float) / Dx
    ums = u_max / Du
    ps, ss = np.sqrt(np.asarray(psi, float)), np.sqrt(np.asarray(sigma, float))
    Q = cp.Variable((n, n), symmetric=True)
    Y = cp.Variable((m, n))
    g = cp.Variable()
    Xd = cp.Variable(m)
    eps = 1e-4  # above Clarabel's ~1e-5 accuracy on this problem (measured)
    # margins keep the certificate strict after the solver's tolerance
    cons = [
        cp.bmat([[np.ones((1, 1)) * (1.0 - 1e-4), x0s[None, :]], [x0s[:, None], Q]]) >> 0,
        Xd <= ums**2 * (1.0 - 1e-4),
        Q >> eps * np.eye(n),
    ]
    for i in range(R):
        AQ = As[i] @ Q + Bs[i] @ Y
        blk = cp.bmat(
            [
                [Q, AQ.T, Q @ np.diag(ps), Y.T @ np.diag(ss)],
                [AQ, Q, np.zeros((n, n)), np.zeros((n, m))],
                [np.diag(ps) @ Q, np.zeros((n, n)), g * np.eye(n), np.zeros((n, m))],
                [np.diag(ss) @ Y, np.zeros((m, n)), np.zeros((m, n)), g * np.eye(m)],
            ]
        )
        cons.append(0.5 * (blk + blk.T) >> eps * np.eye(3 * n + m))
    blk = cp.bmat([[cp.diag(Xd), Y], [Y.T, Q]])
    cons.append(0.5 * (blk + blk.T) >> 0)
    prob = cp.Problem(cp.Minimize(g), cons)
    try:
        prob.solve(solver=SDP_SOLVER)
    except cp.error.SolverError:
        # Clarabel stops with a numerical error when gamma_n diverges, i.e. when the
        # problem is (nearly) infeasible; the certificate check below is the judge.
        raise DesignError(
            "nominal LMI (32)-(35) infeasible or numerically unsolvable "
            "(gamma_n diverged): no invariant ellipsoid contains x_n0 within the "
            "nominal input bounds"
        ) from None
    if prob.status not in ("optimal", "optimal_inaccurate") or Q.value is None:
        raise DesignError(
            f"nominal LMI (32)-(35) infeasible (status '{prob.status}'): no "
            "invariant ellipsoid contains x_n0 within the nominal input bounds"
        )
    Qs = 0.5 * (Q.value + Q.value.T)
    Ks = Y.value @ np.linalg.inv(Qs)
    nd = NominalDesign(
        K=Ks * Du[:, None] / Dx[None, :],
        Q=Qs * np.outer(Dx, Dx),
        gamma=float(g.value),
        u_max=u_max,
        x0=np.asarray(x0, float),
    )
    verify_nominal(A, B, nd, psi, sigma, Dx, Du)
    return nd
