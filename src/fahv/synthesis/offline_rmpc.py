"""Off-line robust MPC (Wan & Kothare 2003) on Kothare's LMIs (32)-(35) (ref. [37]).

Kothare, Balakrishnan & Morari (1996) solve, at every state x, the min-gamma problem

    min gamma  s.t.  [[1, x'], [x, Q]] >= 0                                       (33)
        [[Q, (A_i Q + B_i Y)', Q psi^1/2, Y' sigma^1/2],
         [A_i Q + B_i Y, Q, 0, 0], [psi^1/2 Q, 0, gamma I, 0],
         [sigma^1/2 Y, 0, 0, gamma I]] >= 0          for every vertex i           (34)
        [[X, Y], [Y', Q]] >= 0,  X_jj <= u_max,j^2                              (35)

and apply u = Y Q^-1 x. Wan & Kothare (2003, Automatica 39, 837-846) move the solves
off line: for a sequence of states x_1, ..., x_N of decreasing size they solve the
same problem with the extra constraint Q_i < Q_{i-1} (nested ellipsoids E_i =
{x : x' Q_i^-1 x <= 1}, E_i inside E_{i-1}) and store P_i = Q_i^-1 and K_i. On line,
the smallest ellipsoid E_i holding x(k) is found and the gain is interpolated,
u = (a K_i + (1 - a) K_{i+1}) x with x' (a P_i + (1 - a) P_{i+1}) x = 1. Their extra
condition for the interpolation,

    P_i - (A_j + B_j K_{i+1})' P_i (A_j + B_j K_{i+1}) > 0   for every vertex j,    (WK)

(K_{i+1} also keeps E_i invariant) is sufficient for every interpolated ellipsoid
E(a) = {x' (a P_i + (1 - a) P_{i+1}) x <= 1} to be invariant under the interpolated
gain. On this vehicle it does not hold between the outer ellipsoids (the ellipsoid
that holds the Case 1 step is close to the largest admissible one, so only gains very
close to K_1 keep it invariant), and imposing it as an LMI (slack-variable form, K =
Y G^-1) made every ellipsoid collapse onto E_1 (measured, docs/theory/rmpc.md).
So it is measured and reported, and what the law needs is checked directly:
`verify_sequence` requires every interpolated ellipsoid E(a) to be contracted by
the interpolated gain at every vertex and to keep the input bound, on a grid of
101 values of a per pair (numerical evidence between grid points, not a proof).

Numerics (why each solve is certified): the min-gamma optimum of a large set-point
step lies near the edge of feasibility, where gamma ~ 1e5-1e6 while the smallest
axes of Q are O(10) in the design scales; solved as written, an interior-point
solver's tolerance is larger than the Lyapunov decrease it must certify. Each
ellipsoid is therefore solved twice: once in the base scales (states by
`Ds`, inputs by their bounds) with the cost scaled so that gamma ~ 1, and again in
the coordinates of that first solution (z = T^-1 x, Q_est = T T', cost rescaled
by 1 / gamma_est), where Q ~ I and gamma ~ 1, with strict margins on every LMI that
are larger than the solver's tolerance. Every result is re-checked numerically in
the base scales by `verify_sequence`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.errors import DesignError
from fahv.synthesis.lmi import SDP_OPTIONS, SDP_SOLVER, scale_vertices

#: Clarabel settings of every solve (fixed, so designs do not depend on defaults that
#: change between versions): absolute/relative gap and feasibility tolerances.
SOLVER_SETTINGS = {
    "tol_gap_abs": 1e-9,
    "tol_gap_rel": 1e-9,
    "tol_feas": 1e-9,
    "max_iter": 200,
    **SDP_OPTIONS,
}
#: Margin of (34) in the well-scaled coordinates: block >= EPS_34 I (Q ~ I there).
EPS_34 = 1e-6
#: Relative margin of the input bound (35) and the containment (33).
MARGIN = 1e-4
#: Nesting margin: Q_i <= (1 - NEST) Q_{i-1}.
NEST = 1e-3
#: Scaled passes per ellipsoid at most (each rescaled by the previous solution).
REFINE = 3
#: Cost scales 1 / (|z|^2_psi steps) tried in turn by the first, unscaled pass.
FIRST_PASS_STEPS = (1e3, 1e4, 1e2, 1e5)
#: Values of a in [0, 1] at which the interpolated law is re-checked.
ALPHA_GRID = 101


@dataclass(frozen=True)
class EllipsoidSequence:
    """Nested invariant ellipsoids and gains of the off-line RMPC, in scaled units.

    States are scaled by `Ds` (z = x / Ds), inputs by their bounds (v = u / u_max,
    so |v_j| <= 1).

    Attributes
    ----------
    Q : (N, n, n) ndarray
        Ellipsoids E_i = {z : z' Q_i^-1 z <= 1}, E_{i+1} inside E_i.
    P : (N, n, n) ndarray
        Their inverses P_i = Q_i^-1 (the online law uses these).
    K : (N, m, n) ndarray
        Gains K_i = Y_i Q_i^-1, v = K_i z (u - u_r = u_max * v).
    gamma : (N,) ndarray
        Cost bounds of (32) in the units of the scaled cost (psi, sigma).
    z : (N, n) ndarray
        Design states z_i (each on or inside E_i).
    Ds : (n,) ndarray
        State scales.
    u_max : (m,) ndarray
        Input bounds |u - u_r| <= u_max (unscaled); the input scales.
    guess_Q : (N, n, n) ndarray or None
    guess_gamma : (N,) ndarray or None
        The coordinates (an estimate of Q_i and gamma_i) of the pass that certified each
        ellipsoid: where a later design of the same problem starts (`start` of
        `design_sequence`).
    """

    Q: np.ndarray
    P: np.ndarray
    K: np.ndarray
    gamma: np.ndarray
    z: np.ndarray
    Ds: np.ndarray
    u_max: np.ndarray
    guess_Q: np.ndarray | None = None
    guess_gamma: np.ndarray | None = None


def _min_gamma(As, Bs, z, C, S, Q_outer, eps):
    """One min-gamma problem (32)-(35) in given coordinates; (Q, K, gamma) or None.

    Inputs are scaled so that the bounds are 1. `C` and `S` are the factors of the
    state and input cost (cost z' C'C z + v' S'S v). `Q_outer`: the previous
    ellipsoid (nesting Q <= (1 - NEST) Q_outer) or None. K = Y Q^-1.
    """
    import cvxpy as cp

    R, n, m = Bs.shape
    Q = cp.Variable((n, n), symmetric=True)
    Y = cp.Variable((m, n))
    g = cp.Variable()
    Xd = cp.Variable(m)
    cons = [Xd <= 1.0 - MARGIN]
    nc, ns = C.shape[0], S.shape[0]
    size = 2 * n + nc + ns
    for i in range(R):
        AQ = As[i] @ Q + Bs[i] @ Y
        blk = cp.bmat(
            [
                [Q, AQ.T, (C @ Q).T, (S @ Y).T],
                [AQ, Q, np.zeros((n, nc)), np.zeros((n, ns))],
                [C @ Q, np.zeros((nc, n)), g * np.eye(nc), np.zeros((nc, ns))],
                [S @ Y, np.zeros((ns, n)), np.zeros((ns, nc)), g * np.eye(ns)],
            ]
        )
        cons.append(0.5 * (blk + blk.T) - eps * np.eye(size) >> 0)
    blk = cp.bmat([[cp.diag(Xd), Y], [Y.T, Q]])
    cons.append(0.5 * (blk + blk.T) >> 0)
    zz = z * (1.0 + MARGIN)
    cons.append(cp.bmat([[np.ones((1, 1)), zz[None, :]], [zz[:, None], Q]]) >> 0)
    if Q_outer is not None:
        cons.append((1.0 - NEST) * Q_outer - Q >> 0)
    prob = cp.Problem(cp.Minimize(g), cons)
    try:
        prob.solve(solver=SDP_SOLVER, **SOLVER_SETTINGS)
    except cp.error.SolverError:
        return None
    if prob.status not in ("optimal", "optimal_inaccurate") or Q.value is None:
        return None
    Qv = 0.5 * (Q.value + Q.value.T)
    try:
        K = np.linalg.solve(Qv, np.asarray(Y.value).T).T
    except np.linalg.LinAlgError:
        return None
    return Qv, K, float(g.value)


def _solve_point(As, Bs, z, psi, sigma, Q_outer, guess):
    """Min-gamma ellipsoid of state z (scaled), twice-scaled (module notes).

    `guess` = (Q_est, gamma_est) or None. Returns (Q, K, gamma, last guess) in the base
    scales, the last guess being the coordinates of the pass that was certified.
    """
    if guess is None:  # first pass in the base scales, cost scaled so that gamma ~ 1
        for steps in FIRST_PASS_STEPS:  # J ~ |z|^2_psi times the steps it takes to decay
            c = 1.0 / max(1.0, float(np.sum(psi * z**2)) * steps)
            sol = _min_gamma(As, Bs, z, np.diag(np.sqrt(c * psi)),
                             np.diag(np.sqrt(c * sigma)), Q_outer, 0.0)  # fmt: skip
            if sol is not None:
                break
        else:
            return None
        guess = (sol[0], sol[2] / c)
    for _ in range(REFINE):  # rescale with the latest solution until it is certified
        sol = _scaled_pass(As, Bs, z, psi, sigma, Q_outer, guess)
        if sol is None:
            return None
        if _holds(As, Bs, z, psi, sigma, Q_outer, *sol):
            return (*sol, guess)
        guess = (sol[0], sol[2])
    return None


def _holds(As, Bs, z, psi, sigma, Q_outer, Q, K, g) -> bool:
    """The certificates of one ellipsoid (as `verify_sequence` checks them)."""
    try:
        P = np.linalg.inv(Q)
        ok = _contraction(As, Bs, K, Q).max() < 1.0
    except np.linalg.LinAlgError:
        return False
    Acl = As + Bs @ K
    lyap = P[None] - Acl.transpose(0, 2, 1) @ P[None] @ Acl
    lyap -= (np.diag(psi) + K.T @ np.diag(sigma) @ K)[None] / g
    e = np.linalg.eigvalsh(0.5 * (lyap + lyap.transpose(0, 2, 1))).min()
    ok &= e / np.linalg.norm(P, 2) >= -1e-9
    ok &= _input_ratio(K, Q, np.ones(K.shape[0])).max() <= 1.0
    ok &= z @ P @ z <= 1.0
    if Q_outer is not None:
        L = np.linalg.cholesky(Q_outer)
        Li = np.linalg.inv(L)
        ok &= np.linalg.eigvalsh(Li @ Q @ Li.T).max() < 1.0
    return bool(ok)


def _scaled_pass(As, Bs, z, psi, sigma, Q_outer, guess):
    """The min-gamma problem in the coordinates of `guess` = (Q_est, gamma_est)."""
    Q_est, g_est = guess
    T = np.linalg.cholesky(0.5 * (Q_est + Q_est.T))
    Ti = np.linalg.inv(T)
    AT = np.einsum("ij,rjk,kl->ril", Ti, As, T)
    BT = np.einsum("ij,rjk->rik", Ti, Bs)
    c = 1.0 / g_est
    C = np.sqrt(c * psi)[:, None] * T
    S = np.diag(np.sqrt(c * sigma))
    QoT = None if Q_outer is None else Ti @ Q_outer @ Ti.T
    sol = _min_gamma(AT, BT, Ti @ z, C, S, None if QoT is None else 0.5 * (QoT + QoT.T),
                     EPS_34)  # fmt: skip
    if sol is None:
        return None
    QT, KT, gT = sol
    Qs = T @ QT @ T.T
    return 0.5 * (Qs + Qs.T), KT @ Ti, gT / c


def design_sequence(A, B, d, u_max, psi, sigma, Ds, fractions,
                    start=None) -> tuple[EllipsoidSequence, dict]:  # fmt: skip
    """Off-line RMPC of Wan & Kothare (2003): nested ellipsoids along the command step.

    For z_i = f_i d / Ds (`fractions` f_1 > f_2 > ... > 0), solve the min-gamma
    problem (32)-(35) with x_i = z_i and, for i > 1, the nesting Q_i <= (1 - 1e-3)
    Q_{i-1}; K_i = Y_i Q_i^-1. Then `verify_sequence`. Every solve uses
    Clarabel with `SOLVER_SETTINGS` and strict margins (`EPS_34`,
    `MARGIN`, `NEST`), so the result does not depend on solver defaults.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices of the design model (unscaled).
    d : (n,) array_like
        Largest state deviation to hold: x(0) - x_r of the case's set-point change.
    u_max : (m,) array_like
        Input bounds |u - u_r| <= u_max (35), unscaled.
    psi : (n,) array_like
    sigma : (m,) array_like
        Diagonal weights of the cost (31) in the scaled units (z = x / Ds,
        v = (u - u_r) / u_max).
    Ds : (n,) ndarray
        State scales.
    fractions : sequence of float
        f_i, strictly decreasing and positive; f_1 >= 1 puts d inside E_1.
    start : (EllipsoidSequence.guess_Q, EllipsoidSequence.guess_gamma), optional
        The coordinates of the certified pass of every ellipsoid of an earlier design of
        the same problem ((N, n, n), (N,)): each ellipsoid is first solved once in them,
        which on the same data and machine is that design's last pass (the same
        solution); an ellipsoid they do not certify is solved as without them.

    Returns
    -------
    seq : EllipsoidSequence
    certificate : dict
        What `verify_sequence` measured.

    Raises
    ------
    DesignError
        If a solve fails (naming the ellipsoid and the fraction), or a certificate
        does not hold.
    """
    f = np.asarray(fractions, float)
    if f.ndim != 1 or f.size < 1 or np.any(f <= 0.0) or np.any(np.diff(f) >= 0.0):
        raise DesignError(f"rmpc: fractions must be positive and strictly decreasing, got {f}")
    u_max = np.asarray(u_max, float)
    Ds = np.asarray(Ds, float)
    As, Bs = scale_vertices(np.asarray(A, float), np.asarray(B, float), Ds, u_max)
    psi, sigma = np.asarray(psi, float), np.asarray(sigma, float)
    d_s = np.asarray(d, float) / Ds
    Qs, Ks, gs, zs, used = [], [], [], [], []
    guess = None
    for i, fi in enumerate(f):
        z = fi * d_s
        Q_outer = Qs[-1] if Qs else None
        sol = _stored_pass(As, Bs, z, psi, sigma, Q_outer, start, i)
        if sol is None:
            sol = _solve_point(As, Bs, z, psi, sigma, Q_outer, guess)
        if sol is None and guess is not None:  # the guessed scales did not work: rescale
            sol = _solve_point(As, Bs, z, psi, sigma, Q_outer, None)
        if sol is None:
            raise DesignError(
                f"rmpc: ellipsoid {i + 1} of {f.size} (fraction {fi:g} of the step) is "
                "infeasible or numerically unsolvable: no invariant ellipsoid holds that "
                "state within the input bounds"
            )
        Q, K, g, last = sol
        used.append(last)
        Qs.append(Q)
        Ks.append(K)
        gs.append(g)
        zs.append(z)
        if i + 1 < f.size:
            r = f[i + 1] / fi
            guess = (r**2 * Q, r**2 * g)
    Q = np.stack(Qs)
    K = np.stack(Ks)
    P = np.linalg.inv(Q)
    seq = EllipsoidSequence(Q, 0.5 * (P + P.transpose(0, 2, 1)), K, np.asarray(gs),
                            np.stack(zs), Ds, u_max, np.stack([q for q, _ in used]),
                            np.array([g for _, g in used]))  # fmt: skip
    return seq, verify_sequence(A, B, seq, psi, sigma)


def _stored_pass(As, Bs, z, psi, sigma, Q_outer, start, i):
    """Ellipsoid i solved once in the stored coordinates `start` if they certify it.

    Returns (Q, K, gamma, guess) as `_solve_point`, or None (no stored coordinates
    for i, of another shape, or not certified: the caller solves as without them).
    """
    if start is None or i >= len(start[0]) or np.shape(start[0][i]) != As.shape[1:]:
        return None
    guess = (np.asarray(start[0][i], float), float(start[1][i]))
    sol = _scaled_pass(As, Bs, z, psi, sigma, Q_outer, guess)
    if sol is None or not _holds(As, Bs, z, psi, sigma, Q_outer, *sol):
        return None
    return (*sol, guess)


def _contraction(As, Bs, K, Q) -> np.ndarray:
    """||L^-1 (A_r + B_r K) L||_2 (R,) with Q = L L'."""
    L = np.linalg.cholesky(Q)
    M = np.linalg.solve(L[None], (As + Bs @ K) @ L[None])
    return np.linalg.norm(M, 2, axis=(1, 2))


def _input_ratio(K, Q, v_max) -> np.ndarray:
    return np.sqrt(np.einsum("ij,jk,ik->i", K, Q, K)) / v_max


def verify_sequence(A, B, seq: EllipsoidSequence, psi, sigma) -> dict:
    """Re-check every certificate of an off-line RMPC sequence numerically.

    Per ellipsoid i, in the scales of `seq`: Q_i positive definite; contraction
    max_r ||L_i^-1 (A_r + B_r K_i) L_i|| < 1 at every vertex r (invariance, strict);
    the Lyapunov inequality of (34), P_i - (A_r + B_r K_i)' P_i (A_r + B_r K_i) -
    (psi + K_i' sigma K_i) / gamma_i >= 0 at every vertex (the cost bound); the input
    bound sqrt(K_ij Q_i K_ij') <= u_max,j (35); z_i in E_i (33). Per pair (i, i+1):
    nesting, max eig(P_i^1/2 Q_{i+1} P_i^1/2) < 1; and, on a grid of `ALPHA_GRID`
    values of a in [0, 1], the interpolated ellipsoid {z' (a P_i + (1 - a) P_{i+1}) z
    <= 1} is contracted by a K_i + (1 - a) K_{i+1} at every vertex and keeps the input
    bound. The sufficient condition (WK) of Wan & Kothare (K_{i+1} contracts E_i) is
    measured and returned, not required (module notes).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices (unscaled).
    seq : EllipsoidSequence
    psi : (n,) array_like
    sigma : (m,) array_like
        Cost weights (scaled units z, v).

    Returns
    -------
    dict
        `contraction` (N,), `lyapunov_min_eig` (N,) (relative to ||P_i||),
        `input_ratio` (N,), `containment` (N,), `nesting` (N - 1,), `wk` (N - 1,)
        (largest contraction of E_i under K_{i+1}), `interp_contraction` and
        `interp_input_ratio` (largest over the grid, N - 1 each).

    Raises
    ------
    DesignError
        Naming the ellipsoid (or pair), the certificate and the value found.
    """
    As, Bs = scale_vertices(np.asarray(A, float), np.asarray(B, float), seq.Ds, seq.u_max)
    v_max = np.ones(seq.u_max.size)
    psi, sigma = np.diag(np.asarray(psi, float)), np.diag(np.asarray(sigma, float))
    N = seq.Q.shape[0]
    out: dict = {k: [] for k in ("contraction", "lyapunov_min_eig", "input_ratio",
                                 "containment", "nesting", "wk", "interp_contraction",
                                 "interp_input_ratio")}  # fmt: skip

    def fail(what):
        raise DesignError(f"certificate failed: rmpc {what}")

    for i in range(N):
        Q, P, K, g = seq.Q[i], seq.P[i], seq.K[i], seq.gamma[i]
        if np.linalg.eigvalsh(Q).min() <= 0.0:
            fail(f"ellipsoid {i + 1}: Q not positive definite")
        c = float(_contraction(As, Bs, K, Q).max())
        if not c < 1.0:
            fail(f"ellipsoid {i + 1}: not invariant, contraction {c:.9f} >= 1")
        Acl = As + Bs @ K
        lyap = P[None] - Acl.transpose(0, 2, 1) @ P[None] @ Acl - (psi + K.T @ sigma @ K)[None] / g
        e = min(float(np.linalg.eigvalsh(0.5 * (M + M.T)).min()) for M in lyap)
        e /= float(np.linalg.norm(P, 2))
        if not e >= -1e-9:
            fail(f"ellipsoid {i + 1}: Lyapunov inequality of (34) fails, eigenvalue {e:.3e}")
        ratio = float(_input_ratio(K, Q, v_max).max())
        if not ratio <= 1.0:
            fail(f"ellipsoid {i + 1}: input bound (35) exceeded, ratio {ratio:.9f}")
        level = float(seq.z[i] @ P @ seq.z[i])
        if not level <= 1.0:
            fail(f"ellipsoid {i + 1}: design state outside E_i (33), level {level:.9f}")
        out["contraction"].append(c)
        out["lyapunov_min_eig"].append(e)
        out["input_ratio"].append(ratio)
        out["containment"].append(level)
    for i in range(N - 1):
        L = np.linalg.cholesky(seq.Q[i])
        Li = np.linalg.inv(L)
        nest = float(np.linalg.eigvalsh(Li @ seq.Q[i + 1] @ Li.T).max())
        if not nest < 1.0:
            fail(f"ellipsoids {i + 1}, {i + 2}: E_{i + 2} not inside E_{i + 1} ({nest:.9f})")
        # sufficient condition of Wan & Kothare (measured; the grid below is the check)
        wk = float(_contraction(As, Bs, seq.K[i + 1], seq.Q[i]).max())
        ic, ir = 0.0, 0.0
        for a in np.linspace(0.0, 1.0, ALPHA_GRID):
            Pa = a * seq.P[i] + (1.0 - a) * seq.P[i + 1]
            Qa = np.linalg.inv(Pa)
            Qa = 0.5 * (Qa + Qa.T)
            Ka = a * seq.K[i] + (1.0 - a) * seq.K[i + 1]
            ic = max(ic, float(_contraction(As, Bs, Ka, Qa).max()))
            ir = max(ir, float(_input_ratio(Ka, Qa, v_max).max()))
        if not (ic < 1.0 and ir <= 1.0):
            fail(
                f"ellipsoids {i + 1}, {i + 2}: interpolated law not certified on the a grid "
                f"(contraction {ic:.9f}, input ratio {ir:.6f})"
            )
        out["nesting"].append(nest)
        out["wk"].append(wk)
        out["interp_contraction"].append(ic)
        out["interp_input_ratio"].append(ir)
    return {k: np.asarray(v) for k, v in out.items()}
