"""Condensed QP of the tracking MPC: the decision vector's layout, predictions, cost, rows.

The tracking MPC with an artificial steady state of Limon et al. (2010, "Robust
tube-based MPC for tracking") on the nominal LPV model of eq. (12) of Yang et al.
(2022), scheduled at one operating point. Its decision vector y = [c_0 .. c_{N_p-1},
delta, alpha] (`QPLayout`) holds the moves c_j (each held for M fast steps), the
step delta of the artificial set point theta = (h_s, V_s) along the trim map
(x_s = G_x delta, u_s = G_u delta) and the scaling alpha of the terminal set.

Predictions are pre-stabilised by the terminal gain K of LMIs (33)-(35):
u = u_s + K (z - x_s) + c_j, so that zeta = z - x_s obeys
zeta+ = (A + B K) zeta + B c_j + E delta with E = (A - I) G_x + B G_u
(`move_predictions`, `horizon_predictions`). The functions below stack
these predictions into the QP's cost (`tracking_cost`) and the state-independent
parts of its rows: inputs at the move starts and at the fast steps of the first moves
(the tightened set of eq. 30), attitude, the nominal's h, V and other states, and the
jumps of the input between moves. Every row is linear in (y, z0), given as a y part
(rows, ny) and a z0 part (rows, n); the bounds that depend on z0 are set at each solve
(`fahv.control.mpc.tracking.TrackingMPC.solve`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class QPLayout:
    """Named parts of the QP's decision vector y (ny,) = [c_0 .. c_{N_p-1}, delta, alpha].

    Attributes
    ----------
    N_p : int
        Moves in the horizon.
    m : int
        Inputs per move.
    """

    N_p: int
    m: int

    @property
    def moves(self) -> slice:
        """The moves c_0..c_{N_p-1} (scaled by Du), N_p m entries."""
        return slice(0, self.N_p * self.m)

    def move(self, j: int) -> slice:
        """Move c_j (m entries)."""
        return slice(j * self.m, (j + 1) * self.m)

    @property
    def move_columns(self) -> np.ndarray:
        """Columns of y per move, (N_p, m) int: row j holds the columns of c_j."""
        return np.arange(self.N_p * self.m).reshape(self.N_p, self.m)

    @property
    def delta(self) -> slice:
        """Set-point step delta = (dh_s, dV_s) per (100 ft, 100 ft/s), 2 entries."""
        return slice(self.N_p * self.m, self.N_p * self.m + 2)

    @property
    def alpha(self) -> int:
        """Index of the terminal-set scaling alpha in [0, 1]."""
        return self.N_p * self.m + 2

    @property
    def ny(self) -> int:
        """Length of y."""
        return self.N_p * self.m + 3


def move_predictions(A, B, K, Gx, Gu, Du, M: int):
    """Predictions over one move: zeta_i = Phi_i zeta_0 + Gam_i c + Psi_i delta, i = 1..M.

    Parameters
    ----------
    A : (n, n) ndarray
    B : (n, m) ndarray
        Scheduled model at the fast rate Ts.
    K : (m, n) ndarray
        Pre-stabilising (terminal) gain of LMIs (33)-(35).
    Gx : (n, 2) ndarray
    Gu : (m, 2) ndarray
        Trim map's Jacobian per scaled set-point step.
    Du : (m,) ndarray
        Input scaling (the moves c are per Du).
    M : int
        Fast steps per move.

    Returns
    -------
    Phi_w : (M, n, n) ndarray
    Gam_w : (M, n, m) ndarray
    Psi_w : (M, n, 2) ndarray
        Entry i - 1 holds Phi_i, Gam_i (per scaled move), Psi_i, i = 1..M.
    """
    n, m = A.shape[0], B.shape[1]
    AK = A + B @ K
    E = (A - np.eye(n)) @ Gx + B @ Gu
    Phi_w = np.empty((M, n, n))
    Gam_w = np.empty((M, n, m))
    Psi_w = np.empty((M, n, 2))
    Phi, Gam, Psi = np.eye(n), np.zeros((n, m)), np.zeros((n, 2))
    for i in range(M):
        Gam = AK @ Gam + B
        Psi = AK @ Psi + E
        Phi = AK @ Phi
        Phi_w[i], Gam_w[i], Psi_w[i] = Phi, Gam, Psi
    Gam_w *= Du  # per scaled move
    return Phi_w, Gam_w, Psi_w


def horizon_predictions(Phi_w, Gam_w, Psi_w, Gx, layout: QPLayout):
    """Predictions at the move starts: zeta_j = S[j] zeta_0 + C[j] y, zeta_0 = z0 - Gx delta.

    `S[j] = Phi^j`; the move columns are block Toeplitz, `C[j][:, c_i] = Phi^(j-1-i) Gam`
    (i < j); the delta columns -Phi^j Gx + sum_(k<j) Phi^k Psi (Phi, Gam, Psi of a whole
    move, the last entries of `move_predictions`). The horizon's products are
    stacked (one matrix product per block, not one per move).

    Parameters
    ----------
    Phi_w, Gam_w, Psi_w : ndarray
        One move's predictions (`move_predictions`).
    Gx : (n, 2) ndarray
        Trim map's state Jacobian per scaled set-point step.
    layout : QPLayout

    Returns
    -------
    S : (N_p + 1, n, n) ndarray
    C : (N_p + 1, n, ny) ndarray
    """
    n, N_p, ny = Phi_w.shape[1], layout.N_p, layout.ny
    Phi, Gam = Phi_w[-1], Gam_w[-1]
    mv_cols = layout.move_columns
    S = np.empty((N_p + 1, n, n))
    S[0] = np.eye(n)
    for j in range(N_p):
        S[j + 1] = Phi @ S[j]
    C = np.zeros((N_p + 1, n, ny))
    SG = S[:N_p] @ Gam  # (N_p, n, m): Phi^k Gam
    for i in range(N_p):
        C[i + 1 :, :, mv_cols[i]] = SG[: N_p - i]
    SP = np.cumsum(S[:N_p] @ Psi_w[-1], axis=0)  # sum_(k<j) Phi^k Psi, j = 1..N_p
    C[:, :, layout.delta] = -(S @ Gx)
    C[1:, :, layout.delta] += SP
    return S, C


def tracking_cost(C, S, Phi, Dx, settings, layout: QPLayout):
    """Hessian and state term of the QP's cost, in DAQP's form 1/2 y' H y + f' y.

    The cost (scaled) is sum_j M |zeta_j / Dx|^2_(q_w) + |c_j|^2_(r_w) +
    |zeta_N / Dx|^2_P + the offset cost (theta - c)' T (theta - c) of Limon et al. (2010),
    with P the tail cost of the blocked model under K (discrete Lyapunov equation: the
    exact infinite-horizon cost once c = 0). In y' H y + 2 (Fz z0 + ...)' y form, DAQP
    gets H_qp = H + H' and f = 2 (Fz z0 + ...).

    Parameters
    ----------
    C : (N_p + 1, n, ny) ndarray
    S : (N_p + 1, n, n) ndarray
        Move-start predictions (`horizon_predictions`).
    Phi : (n, n) ndarray
        One move's state transition (Phi_M).
    Dx : (n,) ndarray
        State scaling.
    settings : fahv.control.mpc.settings.MPCSettings
        Weights q_w, r_w, t_w and M.
    layout : QPLayout

    Returns
    -------
    H_qp : (ny, ny) ndarray
        Symmetric Hessian.
    Fz : (ny, n) ndarray
        Linear term per z0 (f = 2 Fz z0 + the offset cost's part).
    """
    import scipy.linalg  # here: a node that never builds a QP does not load scipy.linalg

    s, n, N_p, ny = settings, S.shape[1], layout.N_p, layout.ny
    wq = s.q_w / Dx**2 * s.M  # diagonal of the stage weight
    Phi_s = Phi * Dx[None, :] / Dx[:, None]  # scaled coordinates
    P_s = scipy.linalg.solve_discrete_lyapunov(Phi_s.T, np.diag(s.q_w) * s.M, "bilinear")
    P = (0.5 * (P_s + P_s.T)) / np.outer(Dx, Dx)
    Cs, Ss = C[:N_p], S[:N_p]
    WC = Cs * wq[None, :, None]  # Wq C[j], (N_p, n, ny)
    H = Cs.reshape(-1, ny).T @ WC.reshape(-1, ny) + C[N_p].T @ P @ C[N_p]
    Fz = WC.reshape(-1, ny).T @ Ss.reshape(-1, n) + C[N_p].T @ P @ S[N_p]
    R = np.zeros(ny)
    R[layout.moves] = np.tile(s.r_w, N_p)
    H += np.diag(R)
    T = np.zeros((ny, ny))
    T[layout.delta, layout.delta] = np.diag(s.t_w)
    H += T
    # alpha: a small weight keeps H positive definite and its condition number near
    # 1e7; with 1e-6 it was 2e11 and DAQP declared feasible QPs infeasible (measured:
    # the equilibrium y = 0 feasible, DAQP exit flag -1; Clarabel solves them)
    H[layout.alpha, layout.alpha] += 1e-2
    return H + H.T, Fz


def move_input_rows(K, C, S, Gu, Du, layout: QPLayout):
    """Absolute input at each move start, u_j = u_base + Gu delta + K zeta_j + Du c_j.

    Parameters
    ----------
    K : (m, n) ndarray
    C, S : ndarray
        Move-start predictions (`horizon_predictions`).
    Gu : (m, 2) ndarray
        Trim map's input Jacobian per scaled set-point step.
    Du : (m,) ndarray
        Input scaling.
    layout : QPLayout

    Returns
    -------
    U_y : (N_p m, ny) ndarray
    U_z : (N_p m, n) ndarray
        u_j - u_base = U_y y + U_z z0, move by move.
    """
    N_p, m, ny, n = layout.N_p, layout.m, layout.ny, S.shape[1]
    mv_cols = layout.move_columns
    U_y = K @ C[:N_p]  # (N_p, m, ny)
    U_y[:, :, layout.delta] += Gu
    jj = np.arange(N_p)
    for r in range(m):
        U_y[jj, r, mv_cols[:, r]] += Du[r]
    return U_y.reshape(N_p * m, ny), (K @ S[:N_p]).reshape(N_p * m, n)


def fine_step_predictions(Phi_w, Gam_w, Psi_w, C, S, fine_moves: int, layout: QPLayout):
    """Predictions at the fast steps i = 1..M-1 inside the first `fine_moves` moves.

    In closed form zeta = Phi_i zeta_j + Gam_i c_j + Psi_i delta, shared by the attitude,
    range and input rows of those steps.

    Parameters
    ----------
    Phi_w, Gam_w, Psi_w : ndarray
        One move's predictions (`move_predictions`).
    C, S : ndarray
        Move-start predictions (`horizon_predictions`).
    fine_moves : int
        Moves bounded at every fast step.
    layout : QPLayout

    Returns
    -------
    list of (Zy, Zz)
        Per move j < min(fine_moves, N_p): Zy (M-1, n, ny) per y and Zz (M-1, n, n) per z0.
    """
    M, mv_cols = Phi_w.shape[0], layout.move_columns
    fine = []
    for j in range(min(fine_moves, layout.N_p)):
        Zy = Phi_w[: M - 1] @ C[j]
        Zy[:, :, mv_cols[j]] += Gam_w[: M - 1]
        Zy[:, :, layout.delta] += Psi_w[: M - 1]
        fine.append((Zy, Phi_w[: M - 1] @ S[j]))
    return fine


def fine_input_rows(K, fine, Gu, Du, layout: QPLayout, n: int):
    """Absolute input at the fast steps of `fine_step_predictions`, less u_base.

    Between move starts the input of the pre-stabilised model moves with K zeta, and
    the tube's tightening (eq. 30) holds only if it stays in the tightened set at every
    fast step, not at the move starts alone.

    Parameters
    ----------
    K : (m, n) ndarray
    fine : list of (Zy, Zz)
        `fine_step_predictions`.
    Gu : (m, 2) ndarray
    Du : (m,) ndarray
    layout : QPLayout
    n : int
        States.

    Returns
    -------
    Uf_y : (fine_moves (M-1) m, ny) ndarray
    Uf_z : (fine_moves (M-1) m, n) ndarray
    """
    mv_cols, ny = layout.move_columns, layout.ny
    uf_y, uf_z = [], []
    for j, (Zy, Zz) in enumerate(fine):
        Ci = K @ Zy  # (M-1, m, ny)
        Ci[:, :, mv_cols[j]] += np.diag(Du)[None]
        Ci[:, :, layout.delta] += Gu[None]
        uf_y.append(Ci.reshape(-1, ny))
        uf_z.append((K @ Zz).reshape(-1, n))
    Uf_y = np.concatenate(uf_y) if uf_y else np.zeros((0, ny))
    Uf_z = np.concatenate(uf_z) if uf_z else np.zeros((0, n))
    return Uf_y, Uf_z


def attitude_rows(fine, C, S):
    """Rows of alpha (state 2) and theta (3) of zeta at the fine steps and move starts.

    Parameters
    ----------
    fine : list of (Zy, Zz)
        `fine_step_predictions`.
    C, S : ndarray
        Move-start predictions (`horizon_predictions`).

    Returns
    -------
    Att_y : (2 (fine_moves (M-1) + N_p), ny) ndarray
    Att_z : (2 (fine_moves (M-1) + N_p), n) ndarray
        Rows in pairs (alpha, theta), step by step.
    """
    Y, Z = row_steps(fine, C, S)
    return Y[:, 2:4].reshape(-1, Y.shape[2]), Z[:, 2:4].reshape(-1, Z.shape[2])


def row_steps(fine, C, S) -> tuple[np.ndarray, np.ndarray]:
    """The predictions at the steps the state rows constrain: fine steps, then move starts.

    Parameters
    ----------
    fine : list of (Zy, Zz)
        `fine_step_predictions`.
    C, S : ndarray
        Move-start predictions (`horizon_predictions`); their first (the current
        step) is left out.

    Returns
    -------
    Y : (steps, n, ny) ndarray
    Z : (steps, n, n) ndarray
        zeta at each step as a map of the decision vector y and of the current zeta.
    """
    Y = np.concatenate([Zy for Zy, _ in fine] + [C[1:]])
    Z = np.concatenate([Zz for _, Zz in fine] + [S[1:]])
    return Y, Z


def range_rows(fine, C, S, Gx, layout: QPLayout):
    """Absolute h and V of the nominal less x_r_s, at the attitude rows' steps.

    x_r_s + Gx delta + zeta: the rows of `mpc.hv_box` (the nominal box's range).

    Parameters
    ----------
    fine : list of (Zy, Zz)
        `fine_step_predictions`.
    C, S : ndarray
        Move-start predictions (`horizon_predictions`).
    Gx : (n, 2) ndarray
    layout : QPLayout

    Returns
    -------
    Hv_y : (rows, ny) ndarray
    Hv_z : (rows, n) ndarray
        Rows in pairs (h, V), step by step (the steps of `attitude_rows`).
    """
    Y, Z = row_steps(fine, C, S)
    hv_y = Y[:, 0:2].copy()  # (steps, 2, ny)
    hv_y[:, :, layout.delta] += Gx[0:2]
    return hv_y.reshape(-1, layout.ny), Z[:, 0:2].reshape(-1, Z.shape[2])


def own_trim_rows(fine, C, S, Gx):
    """States 2..8 of the nominal from the trim at its own (h, V), at the attitude steps.

    The trim at the nominal's own (h, V), linearised at the scheduling point:
    zeta[2:9] - T zeta[0:2] with T = Gx[2:9] Gx[0:2]^-1 (the set point's delta cancels,
    Gx[2:9] = T Gx[0:2]); the estimate's shift x_d is added at each solve. The rows of
    `mpc.x_box`.

    Parameters
    ----------
    fine : list of (Zy, Zz)
        `fine_step_predictions`.
    C, S : ndarray
        Move-start predictions (`horizon_predictions`).
    Gx : (n, 2) ndarray

    Returns
    -------
    T_own : (7, 2) ndarray
        Trim slope per ft, ft/s.
    Xb_y : (rows, ny) ndarray
    Xb_z : (rows, n) ndarray
        Rows in sevens, step by step (the steps of `attitude_rows`).
    """
    Y, Z = row_steps(fine, C, S)
    T_own = Gx[2:9] @ np.linalg.inv(Gx[0:2])  # (7, 2) trim slope per ft, ft/s
    Xb_y = (Y[:, 2:9] - T_own @ Y[:, 0:2]).reshape(-1, Y.shape[2])
    Xb_z = (Z[:, 2:9] - T_own @ Z[:, 0:2]).reshape(-1, Z.shape[2])
    return T_own, Xb_y, Xb_z


def rate_rows(Phi_w, Gam_w, Psi_w, C, S, K, Du, layout: QPLayout):
    """Jumps of the nominal input at the move starts j = 1..N_p-1, per Du (`mpc.du_max`).

    At the start of move j the nominal input changes from the last fast step of move
    j-1 to the first of move j by K (zeta_j - zeta_j-1,M-1) + Du (c_j - c_j-1) (zeta is
    continuous, the move jumps), with zeta_j-1,M-1 = Phi_M-1 zeta_j-1 + Gam_M-1 c_j-1 +
    Psi_M-1 delta in closed form. Between move starts the input moves with K zeta only
    (the pre-stabilised model).

    Parameters
    ----------
    Phi_w, Gam_w, Psi_w : ndarray
        One move's predictions (`move_predictions`).
    C, S : ndarray
        Move-start predictions (`horizon_predictions`).
    K : (m, n) ndarray
    Du : (m,) ndarray
    layout : QPLayout

    Returns
    -------
    Rate_y : ((N_p-1) m, ny) ndarray
    Rate_z : ((N_p-1) m, n) ndarray
    """
    n, m, N_p, M = S.shape[1], layout.m, layout.N_p, Phi_w.shape[0]
    if M >= 2:
        P_l, G_l, Q_l = Phi_w[M - 2], Gam_w[M - 2], Psi_w[M - 2]
    else:  # one fast step per move: the last step of a move is its start
        P_l, G_l, Q_l = np.eye(n), np.zeros((n, m)), np.zeros((n, 2))
    mv_cols = layout.move_columns
    last_y = P_l @ C[: N_p - 1]  # zeta at the last fast step of moves 0..N_p-2
    for j in range(N_p - 1):
        last_y[j][:, mv_cols[j]] += G_l
    last_y[:, :, layout.delta] += Q_l
    J_y = K @ (C[1:N_p] - last_y)  # (N_p - 1, m, ny)
    J_z = K @ (S[1:N_p] - P_l @ S[: N_p - 1])
    for r in range(m):
        J_y[np.arange(N_p - 1), r, mv_cols[1:, r]] += Du[r]
        J_y[np.arange(N_p - 1), r, mv_cols[:-1, r]] -= Du[r]
    Rate_y = (J_y / Du[None, :, None]).reshape(-1, layout.ny)
    Rate_z = (J_z / Du[None, :, None]).reshape(-1, n)
    return Rate_y, Rate_z
