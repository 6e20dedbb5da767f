"""Nominal gain K from the LMI problem (33)-(35) (Kothare et al. 1996, ref. [37]).

For the nominal system x_n(k+1) = A(p) x_n + B(p) u_n (eq. 20/46), with Q > 0, Y,
X = diag(X_jj):

    [[1, x_n0'], [x_n0, Q]] >= 0                                            (33)
    [[lam Q, (A_i Q + B_i Y)'], [A_i Q + B_i Y, Q]] >= 0   for every vertex  (34')
    [[X, Y], [Y', Q]] >= 0,  X_jj <= u_n,max,j^2                            (35)

K = Y Q^-1. (34') is the paper's (34) with the cost terms replaced by a decay factor
lam < 1 (its limit gamma_n -> infinity with V+ <= lam V); it makes the invariance of
E(Q) = {x' Q^-1 x <= 1} strict, so the certificate survives the solver tolerance and
leaves room for the reference governor of `fahv.control`.

E(Q) contains x_n0, is invariant for every vertex and keeps |K_j x| <= u_n,max,j inside
it, so a K computed once stays valid along the whole nominal trajectory as long as the
nominal state stays in E(Q) (there is no disturbance on it). On this vehicle no
ellipsoid certified for the tightened bounds contains the whole Case 1 step; the
design maximises the fraction s of the command that fits, and the governor feeds the
rest in gradually (docs/theory/certificate.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fahv.errors import DesignError
from fahv.synthesis.lmi import (
    LMI_MARGIN,
    SDP_OPTIONS,
    SDP_SOLVER,
    psd_tolerance,
    require_psd,
    scale_vertices,
)

if TYPE_CHECKING:  # cvxpy only where a problem is built: the checks load none
    import cvxpy as cp

#: Default decay factor of (34): per-step Lyapunov decrease V+ <= lam V.
DEFAULT_LAM = 0.9995
#: Relative margins kept on (33) and (35) so the certificate is strict after the solve.
_MARGIN = 1e-3


@dataclass(frozen=True)
class NominalDesign:
    """Nominal gain and its invariant ellipsoid (unscaled units).

    Attributes
    ----------
    K : (m, n) ndarray
        Nominal gain, u_n = K x_n.
    Q : (n, n) ndarray
        Ellipsoid E(Q) = {x : x' Q^-1 x <= 1} (eq. 33).
    s : float
        Fraction of the command direction d inside E(Q): x0 = s d.
    u_max : (m,) ndarray
        Nominal input bounds used in (35).
    x0 : (n,) ndarray
        Nominal state the design was made for.
    lam : float
        Decay factor of (34).
    """

    K: np.ndarray
    Q: np.ndarray
    s: float
    u_max: np.ndarray
    x0: np.ndarray
    lam: float

    def level(self, x: np.ndarray) -> float:
        """Level x' Q^-1 x of a nominal state x (n,): <= 1 inside E(Q).

        Parameters
        ----------
        x : (n,) ndarray
            Nominal state deviation (state units).

        Returns
        -------
        float
            The level.

        Examples
        --------
        >>> nd = NominalDesign(K=np.array([[-0.5]]), Q=np.array([[4.0]]), s=1.0,
        ...                    u_max=np.array([1.0]), x0=np.array([2.0]), lam=0.9995)
        >>> nd.level(np.array([1.0])), nd.level(nd.x0)
        (0.25, 1.0)
        """
        return float(x @ np.linalg.solve(self.Q, x))


def _block34(As_i, Bs_i, Qs, Ys, lam):
    AQ = As_i @ Qs + Bs_i @ Ys
    return np.block([[lam * Qs, AQ.T], [AQ, Qs]])


def contraction(A, B, K, Q) -> float:
    """max_i ||L^-1 (A_i + B_i K) L||_2 with Q = L L' (Cholesky).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
    K : (m, n) ndarray
    Q : (n, n) ndarray, positive definite

    Returns
    -------
    float
        The ellipsoid E(Q) is mapped into c E(Q) by every vertex closed loop; c < 1
        means strict invariance and a quadratic Lyapunov function x' Q^-1 x.

    Examples
    --------
    >>> A, B = np.array([[[0.5]], [[1.2]]]), np.array([[[1.0]], [[1.0]]])
    >>> [round(contraction(A[i : i + 1], B[i : i + 1], np.array([[-0.2]]), np.eye(1)), 9)
    ...  for i in range(2)]  # |a_i + b_i K| for one state
    [0.3, 1.0]
    >>> round(contraction(A, B, np.array([[-0.2]]), np.eye(1)), 9)  # the worst vertex
    1.0
    """
    L = np.linalg.cholesky(Q)
    return max(
        float(np.linalg.norm(np.linalg.solve(L, (A[i] + B[i] @ K) @ L), 2))
        for i in range(A.shape[0])
    )


def input_ratio(K, Q, u_max) -> np.ndarray:
    """Largest |K_j x| / u_max,j over E(Q), i.e. sqrt(K_j Q K_j') / u_max,j (LMI 35).

    Parameters
    ----------
    K : (m, n) ndarray
    Q : (n, n) ndarray, positive definite
    u_max : (m,) ndarray
        Input bounds, in the units of K x.

    Returns
    -------
    (m,) ndarray
        <= 1 where the input bound holds on the whole ellipsoid E(Q).

    Examples
    --------
    >>> input_ratio(np.array([[2.0]]), np.array([[4.0]]), [8.0]).tolist()  # 2 sqrt(4) / 8
    [0.5]
    """
    return np.sqrt(np.einsum("ij,jk,ik->i", K, Q, K)) / np.asarray(u_max, float)


def verify_nominal(A, B, nd: NominalDesign, Dx, Du) -> dict[str, float]:
    """Re-check the certificate of (33)-(35) numerically.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete nominal vertices (unscaled).
    nd : NominalDesign
    Dx : (n,) ndarray
    Du : (m,) ndarray
        Scales in which the LMI blocks are checked.

    Returns
    -------
    dict
        `containment` = x0' Q^-1 x0 (<= 1); `contraction` (< 1, see
        `contraction`); `lmi34_min_eig`: smallest eigenvalue of the blocks
        (34') over the vertices with Y = K Q, and `lmi34_tol` the tolerance it was
        checked against (>= -lmi34_tol, `fahv.synthesis.lmi.psd_tolerance` of
        that vertex's block: 1e-9 relative); `input_ratio` =
        max_j sqrt(K_j Q K_j') / u_max,j (<= 1); `spectral_radius` = max_i
        rho(A_i + B_i K) (< 1).

    Raises
    ------
    DesignError
        If any of them does not hold.

    Examples
    --------
    >>> A, B, D = np.array([[[1.1]]]), np.array([[[1.0]]]), np.ones(1)
    >>> nd = design_nominal(A, B, d=[1.0], u_max=[1.0], Dx=D, Du=D)
    >>> checks = verify_nominal(A, B, nd, D, D)
    >>> checks["containment"] <= 1.0, checks["contraction"] < 1.0, checks["input_ratio"] <= 1.0
    (True, True, True)
    """
    As, Bs = scale_vertices(A, B, Dx, Du)
    Qs = nd.Q / np.outer(Dx, Dx)
    Ks = nd.K * Dx[None, :] / Du[:, None]
    Ys = Ks @ Qs
    require_psd(Qs, "nominal ellipsoid Q")
    cont = nd.level(nd.x0)
    if not cont <= 1.0 + 1e-7:
        raise DesignError(f"certificate failed: x_n0 not in the nominal ellipsoid (33): {cont:.6g}")
    c = contraction(As, Bs, Ks, Qs)
    if not c < 1.0:
        raise DesignError(
            f"certificate failed: nominal ellipsoid not invariant (34'), contraction {c:.9f}"
        )
    blocks = [_block34(As[i], Bs[i], Qs, Ys, nd.lam) for i in range(As.shape[0])]
    eigs = [require_psd(M, f"LMI (34') at vertex {i}") for i, M in enumerate(blocks)]
    worst = int(np.argmin(eigs))
    rho = max(max(abs(np.linalg.eigvals(As[i] + Bs[i] @ Ks))) for i in range(As.shape[0]))
    if not rho < 1.0:
        raise DesignError(f"certificate failed: nominal closed loop not stable, rho = {rho:.6g}")
    ratio = float(np.max(input_ratio(nd.K, nd.Q, nd.u_max)))
    if not ratio <= 1.0 + 1e-6:
        raise DesignError(
            f"certificate failed: nominal input bound (35) exceeded, ratio {ratio:.6g}"
        )
    return {
        "containment": cont,
        "contraction": c,
        "lmi34_min_eig": float(min(eigs)),
        "lmi34_tol": psd_tolerance(blocks[worst]),
        "input_ratio": ratio,
        "spectral_radius": float(rho),
    }


def _check_bounds(u_max) -> np.ndarray:
    u_max = np.asarray(u_max, float)
    if np.any(~np.isfinite(u_max)) or np.any(u_max <= 0.0):
        raise DesignError(f"nominal input bounds must be > 0 (U minus F Z empty): {u_max}")
    return u_max


def _invariance_constraints(As, Bs, Q, Y, Xd, ums, lam):
    import cvxpy as cp

    R, n, m = Bs.shape
    cons = [Xd <= ums**2 * (1.0 - _MARGIN)]
    # (34') with the strict margin of every RPI block: the solver's own tolerance (1e-8)
    # then cannot break the re-check, whatever BLAS kernels the machine runs
    for i in range(R):
        AQ = As[i] @ Q + Bs[i] @ Y
        blk = cp.bmat([[lam * Q, AQ.T], [AQ, Q]])
        cons.append(0.5 * (blk + blk.T) >> LMI_MARGIN * np.eye(2 * n))
    blk = cp.bmat([[cp.diag(Xd), Y], [Y.T, Q]])
    cons.append(0.5 * (blk + blk.T) >> 0)
    return cons


def _solve(prob: cp.Problem, what: str) -> None:
    import cvxpy as cp

    try:
        prob.solve(solver=SDP_SOLVER, **SDP_OPTIONS)
    except cp.error.SolverError:
        raise DesignError(
            f"{what}: infeasible or numerically unsolvable (the solver stopped): no "
            "invariant ellipsoid fits within the nominal input bounds"
        ) from None
    if prob.status not in ("optimal", "optimal_inaccurate"):
        raise DesignError(f"{what}: infeasible (solver status '{prob.status}')")


def design_nominal(A, B, d, u_max, Dx, Du, lam: float = DEFAULT_LAM) -> NominalDesign:
    """Nominal gain K from (33)-(35): the largest invariant ellipsoid along the command.

    Maximise s subject to s d in E(Q) (33), (34) in its decay-rate form
    [[lam Q, (A_i Q + B_i Y)'], [A_i Q + B_i Y, Q]] >= 0 for every vertex (the limit
    gamma_n -> infinity of (34) with V+ <= lam V), and (35). K = Y Q^-1.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete nominal vertices (unscaled).
    d : (n,) array_like
        Command direction: the initial nominal state x_r(start) - x_r(command).
    u_max : (m,) array_like
        Nominal input bounds u_n,max (after tightening, eq. 30), unscaled.
    Dx : (n,) ndarray
    Du : (m,) ndarray
        State and input scales of the LMI.
    lam : float
        Decay factor, 0 < lam < 1.

    Returns
    -------
    NominalDesign
        With x0 = s d (s <= 1, shrunk by a relative margin), certified by
        `verify_nominal`.

    Raises
    ------
    DesignError
        If u_max is not positive (U minus F Z empty), the LMI is infeasible or
        numerically unsolvable, or the certificate fails.

    Notes
    -----
    The paper minimises gamma_n of (32) for a given x_n0. On this vehicle that
    problem is numerically ill-posed with the tightened bounds: gamma_n diverges
    while Clarabel iterates and it stops with a numerical error (measured for
    x_n0 = 0.2 d with psi = sigma = I and 1e-2 I, docs/theory/certificate.md).
    Maximising the certified region instead is well posed; the reference governor
    then feeds the command in so that the nominal state stays in it.

    Examples
    --------
    One unstable state, x+ = 1.1 x + u, |u| <= 1: a unit step fits (s at its bound 1,
    less the relative margin) and K stabilises it:

    >>> A, B, D = np.array([[[1.1]]]), np.array([[[1.0]]]), np.ones(1)
    >>> nd = design_nominal(A, B, d=[1.0], u_max=[1.0], Dx=D, Du=D)
    >>> round(nd.s, 6), nd.level(nd.x0) <= 1.0
    (0.999, True)
    >>> bool(abs(1.1 + nd.K[0, 0]) < 1.0), bool(input_ratio(nd.K, nd.Q, nd.u_max)[0] <= 1.0)
    (True, True)
    """
    import cvxpy as cp

    if not 0.0 < lam < 1.0:
        raise DesignError(f"nominal decay factor lam must be in (0, 1), got {lam}")
    u_max = _check_bounds(u_max)
    As, Bs = scale_vertices(np.asarray(A), np.asarray(B), Dx, Du)
    R, n, m = Bs.shape
    d = np.asarray(d, float)
    ds = d / Dx
    Q = cp.Variable((n, n), symmetric=True)
    Y = cp.Variable((m, n))
    Xd = cp.Variable(m)
    s = cp.Variable()
    cons = _invariance_constraints(As, Bs, Q, Y, Xd, u_max / Du, lam)
    cons += [
        cp.bmat([[np.ones((1, 1)), s * ds[None, :]], [s * ds[:, None], Q]]) >> 0,
        s <= 1.0,
    ]
    _solve(cp.Problem(cp.Maximize(s), cons), "nominal LMI (33)-(35)")
    if s.value is None or not s.value > 0.0:
        raise DesignError("nominal LMI (33)-(35): no invariant ellipsoid along the command")
    Qs = 0.5 * (Q.value + Q.value.T)
    Ks = Y.value @ np.linalg.inv(Qs)
    nd = NominalDesign(
        K=Ks * Du[:, None] / Dx[None, :],
        Q=Qs * np.outer(Dx, Dx),
        s=float(s.value) * (1.0 - _MARGIN),
        u_max=u_max,
        x0=float(s.value) * (1.0 - _MARGIN) * d,
        lam=lam,
    )
    verify_nominal(A, B, nd, Dx, Du)
    return nd


def verify_terminal(A, B, K, Q, u_lo, u_hi, u_r_path, lam: float = 1.0) -> dict:
    """Re-check the terminal ingredients of the online nominal MPC numerically.

    E(Q) invariant under u = K x for every vertex: Q^-1/2 (A_i + B_i K) Q^1/2 has
    spectral norm <= lam (<= 1); the inscribed box of the QP lies inside E(Q); and at
    every trim input of `u_r_path` the steady input with the full set
    (u_r +/- sqrt(K_j Q K_j')) fits the tightened limits, or at least the trim does
    (alpha = 0).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
    K : (m, n) ndarray
    Q : (n, n) ndarray
    u_lo, u_hi : (m,) ndarray
        Tightened absolute limits.
    u_r_path : (P, m) ndarray
        Trim inputs along the case's path (start, end, ...).
    lam : float
        Required contraction bound.

    Returns
    -------
    dict
        `invariance` (largest norm over vertices), `alpha_max` (largest alpha
        admissible at every path point, in [0, 1]).

    Raises
    ------
    DesignError
        If E(Q) is not invariant for a vertex, or a trim input of the path lies
        outside the tightened limits (the set point cannot be held).

    Examples
    --------
    One state, x+ = 0.9 x + u with K = -0.4 (a = 0.5), E(Q) = [-1, 1], limits +/-2: the
    whole set fits around the trim 0 (alpha 1), half of it around the trim 1.8:

    >>> A, B, K, Q = np.array([[[0.9]]]), np.array([[[1.0]]]), np.array([[-0.4]]), np.eye(1)
    >>> lo, hi = np.array([-2.0]), np.array([2.0])
    >>> out = verify_terminal(A, B, K, Q, lo, hi, np.array([[0.0]]))
    >>> round(out["invariance"], 9), out["alpha_max"]
    (0.5, 1.0)
    >>> round(verify_terminal(A, B, K, Q, lo, hi, np.array([[1.8]]))["alpha_max"], 9)
    0.5
    """
    L = np.linalg.cholesky(Q)
    L_inv = np.linalg.inv(L)
    norms = np.array([np.linalg.norm(L_inv @ (A[i] + B[i] @ K) @ L, 2) for i in range(len(A))])
    if np.any(norms > lam * (1 + 1e-9)):
        i = int(np.argmax(norms))
        raise DesignError(
            f"certificate failed: terminal set E(Q) is not invariant under K at vertex {i} "
            f"(||Q^-1/2 (A_i + B_i K) Q^1/2|| = {norms[i]:.6f} > {lam})"
        )
    k_max = np.sqrt(np.einsum("ij,jk,ik->i", K, Q, K))
    u = np.atleast_2d(u_r_path)
    if np.any(u < u_lo) or np.any(u > u_hi):
        raise DesignError(
            "certificate failed: a trim input of the case's path lies outside the tightened "
            f"input set [{u_lo}, {u_hi}]: {u.tolist()}"
        )
    room = np.minimum(u - u_lo, u_hi - u).min(axis=0)
    alpha_max = float(np.clip(np.min(room / k_max), 0.0, 1.0))
    return {"invariance": float(norms.max()), "alpha_max": alpha_max}
