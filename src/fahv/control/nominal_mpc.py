"""Online nominal MPC for tracking (a QP), with an input-disturbance estimate.

The nominal part of the tube-based MPC of Mayne, Seron and Rakovic (2005), in the
tracking form of Limon et al. (2010, "Robust tube-based MPC for tracking"), on the
nominal LPV model of eq. (12) scheduled at the current operating point:

* **Artificial steady state.** The QP chooses, besides the nominal moves, a step
  delta = (dh_s, dV_s) of the artificial set point theta = (h_s, V_s) along the trim
  map; x_s = G_x delta, u_s = G_u delta (the trim map's Jacobian at the scheduling
  point). An offset cost (theta - c)' T (theta - c) pulls theta to the command c, so a
  large step is fed in as fast as the constraints allow; no reference governor.
* **Pre-stabilised, move-blocked predictions.** u = u_s + K (z - x_s) + c_j with the
  certified nominal gain K of LMIs (33)-(35) at the fast rate Ts, and a move c_j held
  for M steps (nominal rate Ts_n = M Ts), j = 0..N-1: zeta = z - x_s obeys
  zeta+ = (A + B K) zeta + B c_j + E delta (E = (A - I) G_x + B G_u, zero on the exact
  linear steady-state manifold). The condensed QP is well conditioned although the
  open-loop model is unstable.
* **Constraints.** The nominal input at each move start lies in the tightened
  *asymmetric* set [u_min + t, u_max - t] (t the support of tau F Z, eq. 30), written
  in absolute inputs: 0 <= Phi <= 1.5 and |delta_e| <= 30 deg minus t. Terminal set:
  zeta_N in alpha E(Q), with E(Q) the invariant ellipsoid of LMIs (33)-(35) (terminal
  law K), entered as its inscribed box |L^-1 zeta_N|_inf <= alpha / sqrt(n) (Q = L L'),
  and the steady input u_s with a margin alpha * sqrt(K_j Q K_j') from the tightened
  limits, 0 <= alpha <= 1 (the lambda-scaled terminal set of Limon et al.).
* **Terminal cost.** zeta_N' P zeta_N with P the tail cost of the blocked model under K
  (discrete Lyapunov equation), i.e. the exact infinite-horizon cost once c = 0.
* **Fallback.** If the solver does not return a solution that passes the numerical
  check (constraints and KKT conditions), the shifted previous plan is used (its tail
  stays in the invariant E(Q)); when none is left, the terminal law c = 0. Each is
  counted.

The state disturbance estimate d (:class:`DisturbanceEstimator`, p states) makes the
tracking offset-free and takes the constant part out of the tube's W: the nominal
model is z+ = A z + B u + d, and its steady state at the set point moves by
(x_d, u_d) = (H_x d, H_u d), the solution of (A - I) x_d + B u_d + d = 0 with
h_d = V_d = 0 (n equations, n unknowns; :meth:`TrackingMPC.schedule`). A loss of
elevator effectiveness rho_f gives u_d = -(rho_f - 1) delta_e,r (exactly, since its
d lies along the elevator column of B); parameter uncertainty shifts the trim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from fahv.control.reference import Command, NominalOutput
from fahv.errors import DesignError

#: Solver status of a successful DAQP solve.
_DAQP_OPTIMAL = (1, 2)
#: Primal feasibility and KKT tolerances of the solution check (scaled units).
PRIMAL_TOL = 1e-6
KKT_TOL = 1e-5


def _daqp():
    import daqp

    return daqp


@dataclass(frozen=True)
class MPCSettings:
    """Horizon, rates and weights of the nominal MPC (docs/control_design.md).

    Attributes
    ----------
    M : int
        Fast steps per nominal move (nominal rate Ts_n = M Ts).
    N : int
        Moves in the horizon (horizon N M Ts seconds).
    q_w : (n,) ndarray
        State weights, per scale unit of the design scaling Dx.
    r_w : (m,) ndarray
        Move weights, per scale unit of Du.
    t_w : (2,) ndarray
        Offset-cost weights on (h_s - h_c, V_s - V_c) per (100 ft, 100 ft/s).
    dtheta_max : (2,) ndarray
        Largest move of the artificial set point per nominal step [ft, ft/s].
    reschedule : (2,) ndarray
        Distance of the nominal (h, V) from the scheduling point that triggers a
        rebuild [ft, ft/s].
    att_max : float
        Bound on the nominal |alpha - alpha_s| and |theta - theta_s| at each move start
        [rad] (the attitude requirement minus the tube's extent in alpha, theta).
    """

    M: int
    N: int
    q_w: np.ndarray
    r_w: np.ndarray
    t_w: np.ndarray
    dtheta_max: np.ndarray
    reschedule: np.ndarray
    att_max: float = math.inf


class DisturbanceEstimator:
    """Constant additive state disturbance d (p,) of the scheduled model.

    Each step, the one-step residual of the scheduled model,
    r = dx_k - A dx_{k-1} - B du_{k-1} (deviations from the trim at the scheduling
    point), is filtered: d <- d + gamma (r - d) with gamma = Ts / tau_est (first
    order, time constant tau_est). d collects what the nominal model misses at the
    current operating point and that varies slowly: the constant part of the parameter
    uncertainty (sec. 5.1), the trim part (rho_f - 1) delta_e,r of a loss of
    effectiveness (eq. 16), the mean of the modelling error. The nominal model then
    predicts with d, so the tube only has to hold what is left (docs/control_design.md).

    Parameters
    ----------
    Dx : (p,) ndarray
        State scaling of the measured plant state (p = 9).
    gamma : float
        Filter gain in (0, 1].

    Raises
    ------
    ValueError
        If gamma is not in (0, 1].
    """

    def __init__(self, Dx: np.ndarray, gamma: float) -> None:
        if not 0.0 < gamma <= 1.0:
            raise ValueError(f"estimator gain gamma must be in (0, 1], got {gamma}")
        self.Dx = np.asarray(Dx, float)
        self.gamma = float(gamma)
        self.d = np.zeros(self.Dx.size)
        self._AB = None

    def schedule(self, A: np.ndarray, B: np.ndarray) -> None:
        """Model (A (p, p), B (p, m)) at the fast rate for the next updates."""
        self._AB = (A, B)

    def update(self, dx_prev: np.ndarray, du_prev: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """Filtered estimate d (p,) [state units per step Ts] after one measured step.

        Parameters
        ----------
        dx_prev, dx : (p,) ndarray
            Measured plant state of steps k - 1 and k minus the scheduling trim.
        du_prev : (m,) ndarray
            Command of step k - 1 minus the scheduling trim input.

        Raises
        ------
        TypeError
            If :meth:`schedule` was not called first.
        """
        A, B = self._AB
        r = dx - A @ dx_prev - B @ du_prev
        self.d = self.d + self.gamma * (r - self.d)
        return self.d


@dataclass
class QPStats:
    """Counters of the nominal QP over a run.

    Attributes
    ----------
    solves : int
        QPs solved and accepted.
    fallback : int
        Nominal steps that used the shifted previous plan (QP rejected).
    terminal : int
        Nominal steps that used the terminal law (no plan left).
    reschedules : int
        Rebuilds of the QP matrices (scheduling changes).
    """

    solves: int = 0
    fallback: int = 0
    terminal: int = 0
    reschedules: int = 0


class TrackingMPC:
    """Nominal tracking MPC on the scheduled LPV model (module docstring).

    Parameters
    ----------
    lpv : fahv.model.lpv.PolytopicLPV
        Nominal discrete LPV model at Ts (design-model order, n states, 2 inputs).
    trim_map : fahv.model.trim.TrimMap
        (h, V) -> (x_r (n,), u_r (2,)); its grid bounds the set point.
    K : (2, n) ndarray
        Terminal (and pre-stabilising) law of LMIs (33)-(35).
    Q : (n, n) ndarray
        Terminal ellipsoid E(Q) = {x' Q^-1 x <= 1}, invariant under K.
    u_lo, u_hi : (2,) ndarray
        Tightened absolute input limits [Phi, delta_e rad] (limits -/+ tightening).
    Dx : (n,) ndarray
    Du : (2,) ndarray
        Scaling of states and inputs.
    settings : MPCSettings

    Raises
    ------
    ValueError
        On inconsistent shapes, a non-positive-definite Q, or u_lo >= u_hi.
    """

    def __init__(self, lpv, trim_map, K, Q, u_lo, u_hi, Dx, Du, settings: MPCSettings):
        self.lpv, self.trim_map, self.s = lpv, trim_map, settings
        self.K, self.Q = np.asarray(K, float), np.asarray(Q, float)
        n = self.K.shape[1]
        self.n, self.m = n, self.K.shape[0]
        if self.Q.shape != (n, n):
            raise ValueError(f"nominal MPC: Q {self.Q.shape} does not match K {self.K.shape}")
        self.u_lo, self.u_hi = np.asarray(u_lo, float), np.asarray(u_hi, float)
        if np.any(self.u_lo >= self.u_hi):
            raise ValueError(
                f"nominal MPC: tightened input set is empty: lo {self.u_lo}, hi {self.u_hi}"
            )
        self.Dx, self.Du = np.asarray(Dx, float), np.asarray(Du, float)
        try:
            self.L = np.linalg.cholesky(self.Q)
        except np.linalg.LinAlgError:
            raise ValueError("nominal MPC: terminal ellipsoid Q is not positive definite") from None
        self.L_inv = np.linalg.inv(self.L)
        #: support of K E(Q) per input: max over E(Q) of |K_j x|
        self.k_max = np.sqrt(np.einsum("ij,jk,ik->i", self.K, self.Q, self.K))
        self.theta_scale = np.array([100.0, 100.0])
        self.stats = QPStats()
        self.theta_s = None
        self.last_y = None

    # -- scheduling ----------------------------------------------------------------
    def _trim_jacobian(self, h: float, V: float):
        dh, dV = 10.0, 5.0
        tm = self.trim_map
        h_lo, h_hi = tm.h_grid[0], tm.h_grid[-1]
        V_lo, V_hi = tm.V_grid[0], tm.V_grid[-1]
        h1, h2 = max(h - dh, h_lo), min(h + dh, h_hi)
        V1, V2 = max(V - dV, V_lo), min(V + dV, V_hi)
        xa, ua = tm(h2, V)
        xb, ub = tm(h1, V)
        xc, uc = tm(h, V2)
        xd, ud = tm(h, V1)
        Gx = np.stack([(xa - xb) / (h2 - h1), (xc - xd) / (V2 - V1)], axis=1)
        Gu = np.stack([(ua - ub) / (h2 - h1), (uc - ud) / (V2 - V1)], axis=1)
        return Gx * self.theta_scale, Gu * self.theta_scale  # per scaled delta

    def schedule(self, h: float, V: float) -> None:
        """Build the condensed QP at the scheduling point (h, V) [ft, ft/s].

        Decision y = [c_0..c_{N-1} (scaled by Du), delta (per 100 ft, 100 ft/s), alpha]
        (ny = N m + 3). Also the steady-state shift of a constant disturbance,
        Hx (n, n) and Hu (m, n) (module docstring).

        Raises
        ------
        DesignError
            If no steady state holds (h, V) against a constant disturbance (the
            steady-state equations are singular at this point).
        """
        s, n, m = self.s, self.n, self.m
        A, B = self.lpv.system(h, V)
        self.A, self.B = A, B
        self.theta_s = np.array([h, V], float)
        self.x_r_s, self.u_r_s = self.trim_map(h, V)
        Gx, Gu = self._trim_jacobian(h, V)
        self.Gx, self.Gu = Gx, Gu
        AK = A + B @ self.K
        E = (A - np.eye(n)) @ Gx + B @ Gu
        # one move held for M fast steps
        Phi, Gam, Psi = np.eye(n), np.zeros((n, m)), np.zeros((n, 2))
        for _ in range(s.M):
            Gam = AK @ Gam + B
            Psi = AK @ Psi + E
            Phi = AK @ Phi
        Gam = Gam * self.Du[None, :]  # per scaled move
        N = s.N
        ny = N * m + 2 + 1
        self.ny = ny
        # zeta_j = S[j] zeta_0 + C[j] y, zeta_0 = z0 - Gx delta  (j = 0..N)
        S = np.zeros((N + 1, n, n))
        C = np.zeros((N + 1, n, ny))
        S[0] = np.eye(n)
        C[0, :, N * m : N * m + 2] = -Gx
        for j in range(N):
            S[j + 1] = Phi @ S[j]
            C[j + 1] = Phi @ C[j]
            C[j + 1, :, j * m : (j + 1) * m] += Gam
            C[j + 1, :, N * m : N * m + 2] += Psi
        self.S, self.C = S, C
        # cost (scaled): sum_j |zeta_j/Dx|^2_qw M + |c_j|^2_rw + |zeta_N/Dx|^2_P + offset
        Wq = np.diag(s.q_w / self.Dx**2) * s.M
        Phi_s = Phi * self.Dx[None, :] / self.Dx[:, None]  # scaled coordinates
        P_s = scipy.linalg.solve_discrete_lyapunov(Phi_s.T, np.diag(s.q_w) * s.M, "bilinear")
        P = (0.5 * (P_s + P_s.T)) / np.outer(self.Dx, self.Dx)
        H = np.zeros((ny, ny))
        Fz = np.zeros((ny, n))
        for j in range(N + 1):
            Wj = P if j == N else Wq
            H += C[j].T @ Wj @ C[j]
            Fz += C[j].T @ Wj @ S[j]
        R = np.zeros(ny)
        R[: N * m] = np.tile(s.r_w, N)
        H += np.diag(R)
        T = np.zeros((ny, ny))
        T[N * m : N * m + 2, N * m : N * m + 2] = np.diag(s.t_w)
        H += T
        H[-1, -1] += 1e-6  # alpha: tiny weight keeps H positive definite
        # the cost is y' H y + 2 (Fz z0 + ...)' y; DAQP minimises 1/2 y' H_qp y + f' y,
        # so H_qp = 2 H (symmetrised) and f = 2 (Fz z0 + ...)
        self.H = H + H.T
        self.Fz = Fz
        # constraints: rows as A_c y in [lo + a z0 ..., hi ...] built at solve time
        rows = []  # (matrix (k, ny), z0 matrix (k, n))
        for j in range(N):
            # u_j = u_base + Gu delta + K zeta_j + c_j  (absolute)
            Uy = self.K @ C[j]
            Uy[:, N * m : N * m + 2] += Gu
            Uy[:, j * m : (j + 1) * m] += np.diag(self.Du)
            rows.append((Uy, self.K @ S[j]))
        self.U_y = np.concatenate([r[0] for r in rows])  # (N m, ny)
        self.U_z = np.concatenate([r[1] for r in rows])  # (N m, n)
        # attitude rows: alpha (2) and theta (3) of zeta_j, j = 1..N
        self.Att_y = np.concatenate([C[j][2:4] for j in range(1, N + 1)])
        self.Att_z = np.concatenate([S[j][2:4] for j in range(1, N + 1)])
        self.Tb_y = self.L_inv @ C[N]  # terminal box rows, (n, ny)
        self.Tb_z = self.L_inv @ S[N]
        # steady-state shift of a constant disturbance d: (A - I) x_d + B u_d + d = 0,
        # h_d = V_d = 0; unknowns (x_d[2:], u_d), solved in scaled coordinates
        Dv = np.concatenate([self.Dx[2:], self.Du])
        M_ss = np.hstack([(A - np.eye(n))[:, 2:], B]) * Dv[None, :] / self.Dx[:, None]
        try:
            H_ss = -np.linalg.solve(M_ss, np.diag(1.0 / self.Dx)) * Dv[:, None]
        except np.linalg.LinAlgError:
            raise DesignError(
                f"nominal MPC: no steady state holds (h, V) = ({h}, {V}) against a constant "
                "disturbance (singular steady-state equations)"
            ) from None
        self.Hx = np.zeros((n, n))
        self.Hx[2:] = H_ss[: n - 2]
        self.Hu = H_ss[n - 2 :]
        self.stats.reschedules += 1

    # -- solve -----------------------------------------------------------------------
    def solve(self, z0: np.ndarray, u_base: np.ndarray, cmd: np.ndarray, x_off=None):
        """QP at nominal deviation z0 (n,) from the scheduling trim.

        Parameters
        ----------
        z0 : (n,) ndarray
            Nominal state minus x_r at the scheduling point.
        u_base : (2,) ndarray
            Steady input at the scheduling point, u_r + u_d (absolute).
        cmd : (2,) ndarray
            Command (h_c, V_c) [ft, ft/s].
        x_off : (n,) ndarray, optional
            Steady-state shift x_d of the disturbance estimate. The attitude rows
            bound zeta + x_d, the deviation from the set point's nominal trim (what the
            requirement measures), widened to contain zeta = 0 when the shift alone
            exceeds the bound (the plant must sit at its own trim).

        Returns
        -------
        y : (ny,) ndarray or None
            Solution (None if rejected).
        info : str
            "ok" or why it was rejected (solver flag, or the failed check of
            :func:`check_kkt`); a rejected QP raises nothing, the caller falls back.
        """
        s, N, m, n = self.s, self.s.N, self.m, self.n
        e_theta = (self.theta_s - cmd) / self.theta_scale
        f = 2.0 * (self.Fz @ z0)
        f[N * m : N * m + 2] += 2.0 * s.t_w * e_theta
        # rows: input limits (N m), terminal box (n, two-sided), steady input (2 m, alpha),
        # set point trust region and map bounds (as bounds on delta), alpha in [0, 1]
        nb = self.ny
        lo_b = np.full(nb, -1e30)
        hi_b = np.full(nb, 1e30)
        dmax = s.dtheta_max / self.theta_scale
        tm = self.trim_map
        h_lo = (tm.h_grid[0] - self.theta_s[0]) / self.theta_scale[0]
        h_hi = (tm.h_grid[-1] - self.theta_s[0]) / self.theta_scale[0]
        V_lo = (tm.V_grid[0] - self.theta_s[1]) / self.theta_scale[1]
        V_hi = (tm.V_grid[-1] - self.theta_s[1]) / self.theta_scale[1]
        lo_b[N * m], hi_b[N * m] = max(-dmax[0], h_lo), min(dmax[0], h_hi)
        lo_b[N * m + 1], hi_b[N * m + 1] = max(-dmax[1], V_lo), min(dmax[1], V_hi)
        lo_b[-1], hi_b[-1] = 0.0, 1.0
        u_off = self.U_z @ z0 + np.tile(u_base, N)
        sc = np.tile(self.Du, N)
        A_u = self.U_y / sc[:, None]
        lo_u = (np.tile(self.u_lo, N) - u_off) / sc
        hi_u = (np.tile(self.u_hi, N) - u_off) / sc
        # terminal box: |L^-1 zeta_N| <= alpha / sqrt(n)  ->  two one-sided rows
        tb = self.Tb_y.copy()
        tz = self.Tb_z @ z0
        a_coef = np.zeros((n, nb))
        a_coef[:, -1] = 1.0 / math.sqrt(n)
        A_t1 = tb - a_coef  # L^-1 zeta - alpha/sqrt(n) <= 0
        A_t2 = -tb - a_coef  # -L^-1 zeta - alpha/sqrt(n) <= 0
        # steady input: u_base + Gu delta +/- alpha k_max within the tightened limits
        G = np.zeros((m, nb))
        G[:, N * m : N * m + 2] = self.Gu
        kcol = np.zeros((m, nb))
        kcol[:, -1] = self.k_max
        A_s1 = (G + kcol) / self.Du[:, None]
        A_s2 = (G - kcol) / self.Du[:, None]
        att = self.Att_z @ z0
        a_max = min(s.att_max, 1e3)
        att_lo, att_hi = np.full(att.size, -a_max), np.full(att.size, a_max)
        if x_off is not None:
            off = np.tile(np.asarray(x_off, float)[2:4], N)
            att_lo, att_hi = np.minimum(att_lo - off, 0.0), np.maximum(att_hi - off, 0.0)
        A_c = np.vstack([A_u, A_t1, A_t2, A_s1, A_s2, self.Att_y])
        hi_c = np.concatenate(
            [hi_u, -tz, tz, (self.u_hi - u_base) / self.Du, np.full(m, 1e30), att_hi - att]
        )
        lo_c = np.concatenate(
            [lo_u, np.full(2 * n, -1e30), np.full(m, -1e30), (self.u_lo - u_base) / self.Du,
             att_lo - att]
        )  # fmt: skip
        bu = np.concatenate([hi_b, hi_c])
        bl = np.concatenate([lo_b, lo_c])
        daqp = _daqp()
        start = self.last_y
        y, _, flag, info = daqp.solve(self.H, f, A_c, bu, bl, primal_start=start, iter_limit=2000)
        if flag not in _DAQP_OPTIMAL:
            return None, f"solver exit flag {flag}"
        y = np.asarray(y, float)
        lam = np.asarray(info["lam"], float)
        why = check_kkt(self.H, f, A_c, bl, bu, y, lam)
        if why:
            return None, why
        self.last_y = y
        return y, "ok"


def check_kkt(H, f, A_c, bl, bu, y, lam, primal_tol=PRIMAL_TOL, kkt_tol=KKT_TOL) -> str:
    """Check a QP solution numerically; '' if it passes, else why not (no exception).

    Parameters
    ----------
    H : (ny, ny) ndarray
    f : (ny,) ndarray
    A_c : (nc, ny) ndarray
    bl, bu : (ny + nc,) ndarray
        Bounds on [y; A_c y]; |b| >= 1e29 means none.
    y : (ny,) ndarray
        Primal solution.
    lam : (ny + nc,) ndarray
        Multipliers (positive on an active upper bound, negative on a lower one).
    primal_tol, kkt_tol : float
        Tolerances relative to the size of the terms.

    QP: min 0.5 y'Hy + f'y  s.t. bl <= [y; A_c y] <= bu (the first ny bounds are simple
    bounds on y, DAQP's convention). Checks primal feasibility (<= primal_tol),
    stationarity H y + f + [I; A_c]' lam = 0 (relative to the size of the terms,
    <= kkt_tol), dual sign (lam >= 0 on upper, <= 0 on lower active bounds) and
    complementarity.
    """
    ny = y.size
    Ay = np.concatenate([y, A_c @ y])
    big = 1e29
    viol = np.maximum(np.where(bl > -big, bl - Ay, 0.0), np.where(bu < big, Ay - bu, 0.0))
    if np.max(viol) > primal_tol * (1.0 + np.max(np.abs(Ay))):
        return f"primal infeasible by {np.max(viol):.2e}"
    G = np.vstack([np.eye(ny), A_c])
    grad = H @ y + f
    res = grad + G.T @ lam
    scale = 1.0 + np.max(np.abs(grad)) + np.max(np.abs(G.T @ lam))
    if np.max(np.abs(res)) > kkt_tol * scale:
        return f"stationarity residual {np.max(np.abs(res)):.2e}"
    slack_hi = np.where(bu < big, bu - Ay, np.inf)
    slack_lo = np.where(bl > -big, Ay - bl, np.inf)
    tol = kkt_tol * scale
    if np.any((lam > tol) & (slack_hi > primal_tol * (1 + np.abs(Ay)) * 10)):
        return "complementarity (upper bounds)"
    if np.any((lam < -tol) & (slack_lo > primal_tol * (1 + np.abs(Ay)) * 10)):
        return "complementarity (lower bounds)"
    return ""


class TrackingNominal:
    """The nominal_trajectory node's object in ``mpc`` mode: MPC plan and estimator.

    Fast step k: the nominal state z (deviation from the scheduling trim) moves by
    z+ = A z + B (u_d + u_dev) + d with u_dev = Gu delta + K (z - Gx delta - x_d) + c_j
    (the nominal input is u_r,s + u_d + u_dev);
    every M steps the QP chooses the moves and the set-point step delta. The output
    reference is x_r = trim_x(theta), u_r = trim_u(theta) + u_d at the artificial set
    point theta (u_d the steady input shift of the estimated disturbance, module
    docstring), x_n = X_n - x_r, u_n = u_nominal - u_r, so that the ancillary law
    u = u_r + u_n + tau F (x - x_r - x_n) (eq. 36/54) is unchanged.

    Parameters
    ----------
    mpc : TrackingMPC
    command : Command
    Ts : float
        Fast sampling period [s].
    estimator : DisturbanceEstimator or None
        None: no disturbance estimate (d = 0).
    n_plant : int
        States the estimator uses (the first n_plant of the model): 9 for a CM design,
        11 for the ECM (with ``measure``).
    measure : callable, optional
        Plant state (9,) -> the design model's coordinates (n_plant,), called once per
        step; for the ECM, the notch filter replayed on q gives q' and x_q (eq. 43).

    Raises
    ------
    DesignError
        If the initial QP is infeasible (the case starts outside the tightened set).
    """

    def __init__(self, mpc: TrackingMPC, command: Command, Ts: float, estimator=None,
                 n_plant: int = 9, measure=None) -> None:  # fmt: skip
        self.mpc, self.command, self.Ts, self.est, self.n_plant = (
            mpc, command, Ts, estimator, n_plant)  # fmt: skip
        self.measure = measure
        self.k = 0
        self.theta = np.array([command.h0, command.V0], float)
        self._schedule(self.theta)
        #: trim (x_r (n,), u_r (2,)) at the set point theta, evaluated when theta moves
        self.trim_theta = self.mpc.trim_map(*self.theta)
        self.X_n = self.mpc.x_r_s.copy()
        self.plan = np.zeros((mpc.s.N, mpc.m))
        self.moves_left = 0
        self.status = "not started"
        self.u_nom = self.mpc.u_r_s.copy()
        self.prev = None

    def _schedule(self, theta) -> None:
        self.mpc.schedule(float(theta[0]), float(theta[1]))
        p = self.n_plant
        self.Hx_p = np.ascontiguousarray(self.mpc.Hx[:, :p])
        self.Hu_p = np.ascontiguousarray(self.mpc.Hu[:, :p])
        if self.est is not None:
            self.est.schedule(self.mpc.A[:p, :p], self.mpc.B[:p])

    @property
    def d(self) -> np.ndarray:
        """Input-equivalent disturbance estimate -u_d (2,) [Phi, delta_e rad].

        The steady input correction of the estimate with its sign flipped: for a loss
        of elevator effectiveness alone, (0, (rho_f - 1) delta_e,r).
        """
        return -self._offset()[1]

    def _offset(self):
        """Steady-state shift (x_d (n,), u_d (2,)) of the estimated disturbance."""
        if self.est is None:
            return np.zeros(self.mpc.n), np.zeros(self.mpc.m)
        return self.Hx_p @ self.est.d, self.Hu_p @ self.est.d

    def reset(self, x0: np.ndarray) -> None:
        """Nominal state on the measured state x0 (n,) at step 0."""
        self.X_n = np.asarray(x0, float).copy()

    def _estimate(self, x_meas, u_prev) -> None:
        if self.est is None or x_meas is None:
            return
        p = self.n_plant
        x = np.asarray(x_meas, float)
        x = x[:p] if self.measure is None else self.measure(x)
        dx = x - self.mpc.x_r_s[:p]
        if self.prev is not None and u_prev is not None:
            dx_prev = self.prev - self.mpc.x_r_s[:p]
            du_prev = np.asarray(u_prev, float) - self.mpc.u_r_s
            self.est.update(dx_prev, du_prev, dx)
        self.prev = x.copy()

    def _plan(self) -> None:
        mpc, N, m = self.mpc, self.mpc.s.N, self.mpc.m
        cmd = np.array(self.command(self.k * self.Ts), float)
        # schedule at the nominal operating point (h, V of X_n), not at the set point:
        # the set point may sit a steady offset away from the state it holds
        if np.any(np.abs(self.X_n[:2] - mpc.theta_s) > mpc.s.reschedule):
            self._schedule(self.X_n[:2])
        x_d, u_d = self._offset()
        y, why = mpc.solve(self.X_n - mpc.x_r_s - x_d, mpc.u_r_s + u_d, cmd, x_d)
        if y is not None:
            mpc.stats.solves += 1
            self.plan = y[: N * m].reshape(N, m)
            self.theta = mpc.theta_s + y[N * m : N * m + 2] * mpc.theta_scale
            self.trim_theta = mpc.trim_map(*self.theta)
            self.moves_left = N
            self.status = "ok"
        elif self.moves_left > 1:  # the set point stays where it is
            mpc.stats.fallback += 1
            self.plan = np.vstack([self.plan[1:], np.zeros((1, m))])
            self.moves_left -= 1
            self.status = f"shifted plan ({why})"
        else:
            mpc.stats.terminal += 1
            self.plan = np.zeros((N, m))
            self.moves_left = 0
            self.status = f"terminal law ({why})"

    def step(self, x_meas=None, u_prev=None) -> NominalOutput:
        """Output of step k, then advance one fast step.

        Parameters
        ----------
        x_meas : (p,) ndarray, optional
            Measured plant state of step k (for the estimator).
        u_prev : (2,) ndarray, optional
            Command of step k - 1 [Phi, delta_e rad] (for the estimator).

        Returns
        -------
        NominalOutput
            Set point (h_g, V_g) = theta, x_r (n,), u_r (2,) = trim input plus u_d,
            x_n (n,), u_n (2,), level = (z - x_s)' Q^-1 (z - x_s).
        """
        mpc = self.mpc
        self._estimate(x_meas, u_prev)
        if self.k % mpc.s.M == 0:
            self._plan()
        x_d, u_d = self._offset()
        # set point and steady state of the current plan (linear in delta from theta_s)
        dth = (self.theta - mpc.theta_s) / mpc.theta_scale
        x_s = mpc.Gx @ dth + x_d
        u_s = mpc.Gu @ dth
        z = self.X_n - mpc.x_r_s
        u_dev = u_s + mpc.K @ (z - x_s) + self.plan[0] * mpc.Du
        self.u_nom = mpc.u_r_s + u_d + u_dev
        x_r, u_r = self.trim_theta[0].copy(), self.trim_theta[1] + u_d
        Q_inv_z = np.linalg.solve(mpc.L, z - x_s)
        out = NominalOutput(
            float(self.theta[0]),
            float(self.theta[1]),
            x_r,
            u_r,
            self.X_n - x_r,
            self.u_nom - u_r,
            float(Q_inv_z @ Q_inv_z),
        )
        # advance the nominal model at the fast rate, with the estimated disturbance
        d_n = np.zeros(mpc.n)
        if self.est is not None:
            d_n[: self.n_plant] = self.est.d
        self.X_n = mpc.x_r_s + mpc.A @ z + mpc.B @ (u_d + u_dev) + d_n
        self.k += 1
        return out


def verify_terminal(A, B, K, Q, u_lo, u_hi, u_r_path, lam: float = 1.0) -> dict:
    """Re-check the terminal ingredients of the nominal MPC numerically.

    E(Q) invariant under u = K x for every vertex: Q^-1/2 (A_i + B_i K) Q^1/2 has
    spectral norm <= lam (<= 1); the inscribed box of the QP lies inside E(Q); and at
    every trim input of ``u_r_path`` the steady input with the full set
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
        ``invariance`` (largest norm over vertices), ``alpha_max`` (largest alpha
        admissible at every path point, in [0, 1]).

    Raises
    ------
    DesignError
        If E(Q) is not invariant for a vertex, or a trim input of the path lies
        outside the tightened limits (the set point cannot be held).
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
