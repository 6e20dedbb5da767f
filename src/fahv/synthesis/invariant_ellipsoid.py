"""Invariant ellipsoids of a fixed closed loop, and a static output-feedback step.

`invariant_ellipsoid` is the analysis form of the tube LMI (24) for a given loop
xi+ = A_cl,i xi + E w (a tube gain through a notch filter, the disturbance's steady set):
the smallest ellipsoid RPI for the box W whose projection lies in a given one.
`output_feedback_step` designs a gain u = F T xi of such a loop together with its
ellipsoid by one convex step (dilated RPI condition, output structure on the slack).
Every result is re-checked by its exact level (`fahv.synthesis.rpi_level`), which,
not the LMI, is the certificate.
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from fahv.errors import DesignError
from fahv.synthesis.lmi import (
    LMI_MARGIN,
    dual_support,
    invariance_blocks,
    require_psd,
    solve_lmi,
)


@dataclass(frozen=True)
class InvariantEllipsoid:
    """An ellipsoid RPI for a fixed closed loop and its box W (unscaled units), or none.

    Attributes
    ----------
    P : (n, n) ndarray or None
        Shape of E = {xi : xi' P^-1 xi <= 1}; None if the LMI was infeasible (or the
        solver failed) on the vertices held (`found` False).
    s : float
        Smallest factor with the projection of E on the first p states inside
        s {e : e' S^-1 e <= 1} (S the `shape` it was bounded by): the largest eigenvalue
        of S^-1/2 P_ee S^-1/2, square-rooted (inf if none was found).
    supports : (m,) ndarray or None
        max over E of |(K xi)_j| = sqrt(K_j P K_j') (the input deviation's support).
    active : (a,) ndarray of int
        Indices of the vertices whose blocks the last LMI solve held (constraint
        generation): where a later solve of the same problem starts (`start`).
    """

    P: np.ndarray
    s: float
    supports: np.ndarray
    active: np.ndarray

    @property
    def n_blocks(self) -> int:
        """Vertex blocks the last LMI solve held."""
        return int(len(self.active))

    @property
    def found(self) -> bool:
        """True if an ellipsoid was found (its exact level <= 1 at every vertex)."""
        return self.P is not None


#: A held vertex whose exact level lies below this at a solution does not bind it:
#: constraint generation releases it (at most once) for the next pass.
RELEASE_LEVEL = 0.999

#: Share of the budget 1 - lam `invariant_ellipsoid` leaves unused, so that its
#: blocks, solved without a strict margin, leave room for the exact re-check.
BUDGET_MARGIN = 4e-3


def _s_procedure_block(top, AX, E, mu, P):
    """The cvxpy block [[top, 0, AX'], [0, diag(mu), E'], [AX, E, P]], symmetrised.

    The S-procedure form of the RPI condition for a box W (LMI 24 in analysis form):
    `top` is lam P (`invariant_ellipsoid`) or lam (G + G' - P) in the dilated
    form (`output_feedback_step`); AX (n, n) the closed loop times P or G; E (n, p).
    """
    n, p = E.shape
    blk = cp.bmat([[top, np.zeros((n, p)), AX.T],
                   [np.zeros((p, n)), cp.diag(mu), E.T],
                   [AX, E, P]])  # fmt: skip
    return 0.5 * (blk + blk.T)


def _analysis_problem(As, E, Ss, Ks, tmax, lam, s_max=None):
    """The LMI of `invariant_ellipsoid` on the vertices As (scaled): its parts.

    Each vertex's S-procedure block with its middle diag(mu_i) eliminated by a Schur
    complement, mu_i,j = b / r_i,j (b the budget (1 - lam)(1 - BUDGET_MARGIN)):
    [[lam P, (A_i P)'], [A_i P, P - E diag(r_i) E' / b]] >= 0 with sum_j 1 / r_i,j <= 1
    (sum_j mu_i,j <= b): the same condition on blocks of 2n rows instead of 2n + p.
    With `s_max`, a feasibility problem with s^2 <= s_max^2 in place of min s^2.

    Returns (prob, P, r, s2, vertex_constraints).
    """
    R, n, _ = As.shape
    p = E.shape[1]
    b = (1.0 - lam) * (1.0 - BUDGET_MARGIN)
    P = cp.Variable((n, n), symmetric=True)
    r = cp.Variable((R, p), pos=True)
    s2 = cp.Variable()
    cons = [P >> LMI_MARGIN * np.eye(n), cp.sum(cp.inv_pos(r), axis=1) <= 1.0,
            P[:p, :p] << s2 * Ss]  # fmt: skip
    cons += [Ks[j] @ P @ Ks[j] <= tmax[j] ** 2 for j in range(Ks.shape[0])]
    blocks = []
    for i in range(R):
        AP = As[i] @ P
        inner = P - E @ cp.diag(r[i]) @ E.T / b
        blk = cp.bmat([[lam * P, AP.T], [AP, inner]])
        blocks.append(0.5 * (blk + blk.T) >> 0)
    if s_max is not None:
        return cp.Problem(cp.Minimize(0), [*cons, s2 <= s_max**2, *blocks]), P, r, s2, blocks
    return cp.Problem(cp.Minimize(s2), cons + blocks), P, r, s2, blocks


def invariant_ellipsoid(Acl, w_max, D, shape, K, support_max, levels, lam: float,
                        active: int = 24, add: int = 12, start=None,
                        s_max: float | None = None) -> InvariantEllipsoid | None:  # fmt: skip
    """Smallest ellipsoid RPI for a fixed closed loop whose projection lies in a given one.

    The analysis form of the tube LMI (24) for a closed loop xi+ = A_cl,i xi + E w with
    E = [diag(w_max); 0] and w in the unit box (W = {|w_j| <= w_max,j} on the first p
    states), in the shape P of E = {xi' P^-1 xi <= 1}, with S-procedure multipliers mu_i
    per vertex:

        [[lam P, 0, P A_cl,i'], [0, diag(mu_i), E'], [A_cl,i P, E, P]] >= 0,
        sum_j mu_i,j <= (1 - lam) (1 - BUDGET_MARGIN)      every vertex i,
        P_ee <= s^2 S,   K_j P K_j' <= support_max_j^2,

    minimising s^2: E is RPI for W at every vertex, its projection on the first p states
    lies in s {e' S^-1 e <= 1}, and the input deviation K xi stays within support_max.
    With `s_max`, any such E with s <= s_max is sought instead of the smallest (a
    feasibility problem): a certificate with the margin 1 - s_max where the smallest s
    is not needed, found in fewer passes and blocks (the smallest makes the ellipsoid touch
    the invariance condition at many vertices: on cm_certified's notch loop on mode 1,
    64 blocks and 14 s for s <= 0.98 against 154 blocks and 81 s for the smallest, 0.776).
    Linear in (P, mu_i, s^2) for the fixed lam and loop. Solved in the coordinates xi / D
    on a growing subset of the vertices (constraint generation: the `active` vertices
    of largest spectral radius first, then per pass at most `add` of those whose
    exact level `levels(P)` exceeds 1, the worst first, until none does: the result's
    exact level is then at most 1 at every vertex: that exact level, not the LMI, is the
    certificate). Started from the vertices an earlier solve of the same problem held
    (`start`, the result's `active`), the first solve is that solve's last: on the
    same data and machine, the same solution in one pass. The blocks solved are
    re-checked (`fahv.synthesis.lmi.require_psd`) to the
    solver's accuracy, 1e-6 of their largest entry (a strict margin of 1e-5 in the LMI
    made case1.yaml's certified loop infeasible: its multipliers are of order 1e-4).

    Parameters
    ----------
    Acl : (R, n, n) ndarray
        Closed-loop vertices (unscaled).
    w_max : (p,) array_like
        Half-widths of W on the first p states (unscaled), p <= n.
    D : (n,) array_like
        State scaling (positive).
    shape : (p, p) ndarray
        S, the ellipsoid the projection is bounded by (unscaled).
    K : (m, n) ndarray
        Input map of the loop, u - v = K xi.
    support_max : (m,) array_like
        Largest support of K xi per row.
    levels : callable
        `levels(P) -> (R,)`: the exact worst one-step level of each vertex for the
        ellipsoid of shape P (unscaled), e.g.
        `fahv.synthesis.rpi_level.vertex_levels`.
    lam : float
        Contraction factor in (0, 1).
    active : int
        Vertices of the first solve.
    add : int
        Vertices added per pass.
    start : (a,) array_like of int, optional
        Vertices of the first solve in place of the `active` of largest spectral
        radius (an earlier result's `active`). It changes how fast the generation
        ends, not what is accepted.
    s_max : float, optional
        Seek an ellipsoid with s <= s_max, not the smallest s.

    Returns
    -------
    InvariantEllipsoid
        `found` False if the LMI is infeasible (or the solver fails) on the vertices
        held; `active` is then that solve's set, from which a later design finds the
        same answer in one solve.

    Raises
    ------
    DesignError
        If a returned solution fails the re-check of its blocks or budgets.
    ValueError
        On inconsistent shapes, or a `start` index outside the vertices.

    Examples
    --------
    One state, xi+ = 0.5 xi + w, |w| <= 0.25, lam = 0.9: the S-procedure's smallest P is
    lam w^2 / ((lam - 0.5^2)(1 - lam)) = 0.865 (here within its budget margin), inside
    the unit interval and certified by the exact level:

    >>> from fahv.synthesis.rpi_level import vertex_levels
    >>> Acl = np.array([[[0.5]]])
    >>> def levels(P):
    ...     return vertex_levels(Acl, P, [0.25])
    >>> ie = invariant_ellipsoid(Acl, [0.25], [1.0], np.eye(1), np.zeros((1, 1)), [1.0],
    ...                          levels, lam=0.9)
    >>> round(float(ie.P[0, 0]) / (0.9 * 0.25**2 / ((0.9 - 0.25) * 0.1)), 2)
    1.0
    >>> bool(ie.s <= 1.0), bool(levels(ie.P)[0] <= 1.0)
    (True, True)
    """
    Acl = np.asarray(Acl, float)
    R, n, _ = Acl.shape
    ws, D = np.asarray(w_max, float), np.asarray(D, float)
    p = ws.size
    K = np.atleast_2d(np.asarray(K, float))
    if Acl.shape[2] != n or D.shape != (n,) or p > n or np.shape(shape) != (p, p) \
            or K.shape[1] != n or not 0.0 < lam < 1.0:  # fmt: skip
        raise ValueError(
            f"invariant_ellipsoid: shapes Acl {Acl.shape}, w_max {ws.shape}, D {D.shape}, "
            f"shape {np.shape(shape)}, K {K.shape}, lam {lam}"
        )
    As = Acl / D[None, :, None] * D[None, None, :]
    wss = ws / D[:p]
    Ss = np.asarray(shape, float) / np.outer(D[:p], D[:p])
    Ks = K * D[None, :]
    tmax = np.asarray(support_max, float)
    # W as the unit box through E = [diag(w); 0]: multipliers of order 1 - lam (with the
    # identity they were of order (1 - lam) / w^2, and the solves were less accurate)
    E = np.vstack([np.diag(wss), np.zeros((n - p, p))])
    budget = (1.0 - lam) * (1.0 - BUDGET_MARGIN)
    chosen = _first_vertices(As, active, start)
    released = np.zeros(0, int)
    while True:
        prob, P, r, s2, blocks = _analysis_problem(As[chosen], E, Ss, Ks, tmax, lam, s_max)
        if not solve_lmi(prob):
            return InvariantEllipsoid(None, float("inf"), None, chosen)
        Pv = 0.5 * (P.value + P.value.T)
        P_un = Pv * np.outer(D, D)
        lev = np.asarray(levels(P_un), float)
        bad = np.setdiff1d(np.flatnonzero(lev > 1.0), chosen)
        if bad.size == 0:
            break
        # release the blocks outside the solution's support (a zero dual, or an exact
        # level below RELEASE_LEVEL: not binding), each at most once; add the worst
        support = np.union1d(chosen[dual_support(blocks)], chosen[lev[chosen] >= RELEASE_LEVEL])
        drop = np.setdiff1d(np.setdiff1d(chosen, support), released)
        released = np.union1d(released, drop)
        chosen = np.union1d(np.setdiff1d(chosen, drop), bad[np.argsort(-lev[bad])[:add]])
    muv = budget / np.maximum(r.value, 1e-300)
    for r, i in enumerate(chosen):
        blk = invariance_blocks(As[i : i + 1] @ Pv, lam, muv[r], Pv, E)[0]
        require_psd(blk, f"RPI LMI of the fixed loop at vertex {i}", rtol=1e-6)
    if np.any(muv.sum(axis=1) > (1.0 - lam) * (1 + 1e-9)):
        raise DesignError("certificate failed: sum mu of the fixed loop > 1 - lam (W: unit box)")
    L = np.linalg.cholesky(Ss)
    Li = np.linalg.inv(L)
    s = float(np.sqrt(np.linalg.eigvalsh(Li @ Pv[:p, :p] @ Li.T).max()))
    supports = np.sqrt(np.einsum("ij,jk,ik->i", K, P_un, K))
    return InvariantEllipsoid(P_un, s, supports, chosen)


def _first_vertices(As, active: int, start) -> np.ndarray:
    """The sorted vertices of the first solve: `start`, or the `active` of largest rho."""
    R = As.shape[0]
    if start is not None and len(start) > 0:
        chosen = np.unique(np.asarray(start, int))
        if chosen[0] < 0 or chosen[-1] >= R:
            raise ValueError(f"invariant_ellipsoid: start holds vertex indices outside 0..{R - 1}")
        return chosen
    rho = np.abs(np.linalg.eigvals(As)).max(axis=1)
    return np.sort(np.argsort(-rho)[:active])


@dataclass(frozen=True)
class OutputFeedbackStep:
    """One convex step of `output_feedback_step` (unscaled units).

    Attributes
    ----------
    F : (m, p_y) ndarray
        Static output-feedback gain, u - v = F T xi.
    P : (n, n) ndarray
        Ellipsoid E = {xi : xi' P^-1 xi <= 1} RPI for the loop with F at every vertex
        (exact level <= 1, checked by the `levels` callable at every vertex).
    gamma : float
        The step's objective: the projection of E lies in gamma S and the input supports
        within gamma `support_max` (as solved; the caller re-checks both exactly).
    n_blocks : int
        Vertex blocks the last solve held (constraint generation).
    """

    F: np.ndarray
    P: np.ndarray
    gamma: float
    n_blocks: int


def output_feedback_step(A0, B0, T, w_max, F0, P0, shape, support_max, levels, lam: float,
                         active: int = 20, add: int = 40) -> OutputFeedbackStep | None:  # fmt: skip
    """One convex step of a static output-feedback gain and its RPI ellipsoid, together.

    For the loop xi+ = (A0_i + B0_i F T) xi + E w, E = [diag(w_max); 0], w in the unit
    box, the RPI condition of `invariant_ellipsoid` is bilinear in (F, P). This
    step uses its dilated form (de Oliveira, Bernussou & Geromel 1999, discrete time),
    with a slack G in place of P where the loop acts:

        [[lam (G + G' - P), 0, (A0_i G + B0_i Y T)'], [0, diag(mu_i), E'],
         [A0_i G + B0_i Y T, E, P]] >= 0,       sum_j mu_i,j <= (1 - lam)(1 - BUDGET_MARGIN),

    which implies the S-procedure condition of E(P) (G' P^-1 G >= G + G' - P), and the
    output structure on the slack (Crusius & Trofino 1999): T G = M T makes
    F T G = F M T = Y T, so every block is linear in (P, G, M, Y, mu) and F = Y M^-1.
    The input supports are bounded through the same slack,
    [[gamma^2 t_j^2, Y_j T], [T' Y_j', G + G' - P]] >= 0, and the projection on the
    first p states by P_pp <= gamma^2 S; gamma^2 is minimised.

    Solved in the coordinates whitened by the last ellipsoid P0 (xi = L z, P0 = L L'),
    where (G, P, M, Y) = (P0, P0, I, F0) is feasible whenever P0 is RPI for F0: the step
    starts from the last certificate and can only lower gamma (without the whitening
    cond(M) reached 4e6 on the notch loop; without the slack the steps stalled). The
    vertices are held by constraint generation: the `active` worst of the start (by
    spectral radius and by exact level) first, then per pass at most `add` of those
    whose exact level `levels(F, P)` exceeds 1, until none does; that exact level over
    every vertex, not the solver's status, is what the result is accepted on.

    Parameters
    ----------
    A0 : (R, n, n) ndarray
    B0 : (R, n, m) ndarray
        Vertices of the loop without the feedback (unscaled).
    T : (p_y, n) ndarray
        Output map: the gain acts on y = T xi.
    w_max : (p,) array_like
        Half-widths of W on the first p states, p <= n.
    F0 : (m, p_y) ndarray
        The last gain, for which P0 is RPI.
    P0 : (n, n) ndarray
        The last ellipsoid (positive definite).
    shape : (p, p) ndarray
        S, the ellipsoid the projection is bounded by.
    support_max : (m,) array_like
        t_j, the input deviation's support bound per row.
    levels : callable
        `levels(F, P) -> (R,)`: the exact worst one-step level of every vertex of the
        loop with gain F for the ellipsoid of shape P (e.g. built on
        `fahv.synthesis.rpi_level.vertex_levels`).
    lam : float
        Contraction factor in (0, 1).
    active, add : int
        Constraint generation: vertices of the first solve per criterion, and per pass.

    Returns
    -------
    OutputFeedbackStep or None
        None if the LMI is infeasible or the solver fails on the vertices held.

    Raises
    ------
    ValueError
        On inconsistent shapes or lam outside (0, 1).
    DesignError
        If the solved slack's block M is singular (F = Y M^-1 undefined).
    """
    A0, B0, T, F0, P0 = (np.asarray(v, float) for v in (A0, B0, T, F0, P0))
    R, n, _ = A0.shape
    m, py = B0.shape[2], T.shape[0]
    ws = np.asarray(w_max, float)
    p = ws.size
    tmax = np.asarray(support_max, float)
    if (A0.shape[2] != n or B0.shape[:2] != (R, n) or T.shape[1] != n or F0.shape != (m, py)
            or P0.shape != (n, n) or np.shape(shape) != (p, p) or p > n or tmax.shape != (m,)
            or not 0.0 < lam < 1.0):  # fmt: skip
        raise ValueError(
            f"output_feedback_step: shapes A0 {A0.shape}, B0 {B0.shape}, T {T.shape}, F0 "
            f"{F0.shape}, P0 {P0.shape}, w_max {ws.shape}, shape {np.shape(shape)}, "
            f"support_max {tmax.shape}, lam {lam}"
        )
    L = np.linalg.cholesky(0.5 * (P0 + P0.T))
    Li = np.linalg.inv(L)
    Aw, Bw, Tw = Li[None] @ A0 @ L[None], Li[None] @ B0, T @ L
    E = Li @ np.vstack([np.diag(ws), np.zeros((n - p, p))])
    Si = np.linalg.inv(np.linalg.cholesky(np.asarray(shape, float)))
    Acl0 = A0 + B0 @ F0 @ T
    rho = np.abs(np.linalg.eigvals(Acl0)).max(axis=1)
    chosen = np.union1d(np.argsort(-rho)[:active], np.argsort(-np.asarray(levels(F0, P0)))[:active])
    budget = (1.0 - lam) * (1.0 - BUDGET_MARGIN)
    while True:
        P = cp.Variable((n, n), symmetric=True)
        G = cp.Variable((n, n))
        M = cp.Variable((py, py))
        Y = cp.Variable((m, py))
        g2 = cp.Variable()
        mu = cp.Variable((len(chosen), p), nonneg=True)
        GG = G + G.T - P
        proj = Si @ L[:p] @ P @ L[:p].T @ Si.T
        cons = [P >> LMI_MARGIN * np.eye(n), Tw @ G == M @ Tw,
                0.5 * (proj + proj.T) << g2 * np.eye(p), cp.sum(mu, axis=1) <= budget]  # fmt: skip
        for j in range(m):
            row = cp.reshape(Y[j] @ Tw, (1, n), order="C")
            blk = cp.bmat([[cp.reshape(g2 * tmax[j] ** 2, (1, 1), order="C"), row], [row.T, GG]])
            cons.append(0.5 * (blk + blk.T) >> 0)
        cons += [_s_procedure_block(lam * GG, Aw[i] @ G + Bw[i] @ Y @ Tw, E, mu[r], P) >> 0
                 for r, i in enumerate(chosen)]  # fmt: skip
        prob = cp.Problem(cp.Minimize(g2), cons)
        if not solve_lmi(prob):
            return None
        Mv = M.value
        if not np.all(np.isfinite(Mv)) or np.linalg.cond(Mv) > 1e12:
            raise DesignError(
                f"output_feedback_step: the slack's output block M is singular (cond "
                f"{np.linalg.cond(Mv):.2e}): F = Y M^-1 is not defined"
            )
        F = Y.value @ np.linalg.inv(Mv)
        Pn = L @ (0.5 * (P.value + P.value.T)) @ L.T
        lev = np.asarray(levels(F, Pn), float)
        bad = np.setdiff1d(np.flatnonzero(lev > 1.0), chosen)
        if bad.size == 0:
            break
        chosen = np.union1d(chosen, bad[np.argsort(-lev[bad])[:add]])
    return OutputFeedbackStep(F, Pn, float(np.sqrt(max(g2.value, 0.0))), len(chosen))
