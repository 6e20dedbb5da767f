"""One run's nominal tracking MPC: a QP on the scheduled LPV model, re-planned every M steps.

The nominal part of the tube-based MPC of Mayne, Seron and Rakovic (2005), in the
tracking form of Limon et al. (2010, "Robust tube-based MPC for tracking"), on the
nominal LPV model of eq. (12) of Yang et al. (2022) scheduled at the current operating
point (the condensed QP's layout and rows: `fahv.control.mpc.qp_layout`):

* **Artificial steady state.** The QP chooses, besides the nominal moves, a step
  delta = (dh_s, dV_s) of the artificial set point theta = (h_s, V_s) along the trim
  map; x_s = G_x delta, u_s = G_u delta (the trim map's Jacobian at the scheduling
  point). An offset cost (theta - c)' T (theta - c) pulls theta to the command c, so a
  large step is fed in as fast as the constraints allow; no reference governor.
* **Pre-stabilised, move-blocked predictions.** u = u_s + K (z - x_s) + c_j with the
  certified nominal gain K of LMIs (33)-(35) at the fast rate Ts, and a move c_j held
  for M steps (nominal rate Ts_n = M Ts), j = 0..N_p-1: zeta = z - x_s obeys
  zeta+ = (A + B K) zeta + B c_j + E delta (E = (A - I) G_x + B G_u, zero on the exact
  linear steady-state manifold). The condensed QP is well conditioned although the
  open-loop model is unstable.
* **Constraints.** The nominal input at each move start lies in the tightened
  *asymmetric* set [u_min + t, u_max - t] (t the support of tau F Z, eq. 30), written
  in absolute inputs: 0 <= Phi <= 1.5 and |delta_e| <= 30 deg minus t. Terminal set:
  zeta_{N_p} in alpha E(Q), with E(Q) the invariant ellipsoid of LMIs (33)-(35) (terminal
  law K), entered as its inscribed box |L^-1 zeta_{N_p}|_inf <= alpha / sqrt(n) (Q = L L'),
  and the steady input u_s with a margin alpha * sqrt(K_j Q K_j') from the tightened
  limits, 0 <= alpha <= 1 (the lambda-scaled terminal set of Limon et al.).
* **Terminal cost.** zeta_{N_p}' P zeta_{N_p} with P the tail cost of the blocked model under K
  (discrete Lyapunov equation), i.e. the exact infinite-horizon cost once c = 0.
* **Recovery.** If the solver does not return a solution that passes the numerical
  check (constraints and KKT conditions), the caller solves the recovery QP: the same
  rows without the trust region on the set-point step, so the artificial set point may
  move in one re-plan to wherever on the trim map its steady input fits the tightened
  limits (the trust region only keeps the map's linearisation local), and then without
  the steady-input rows (`TrackingMPC.solve`). What follows when both fail (the
  shifted previous plan, then the terminal law) is the nominal source's
  (`fahv.control.mpc.nominal_source.TrackingMPCNominal`).

The steady state of the set point moves by the disturbance estimate's shift
(x_d, u_d) = (H_x d, H_u d) (`fahv.control.mpc.estimator.steady_state_shift`),
computed at each scheduling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fahv.control.mpc.estimator import steady_state_shift
from fahv.control.mpc.qp_layout import (
    QPLayout,
    attitude_rows,
    fine_input_rows,
    fine_step_predictions,
    horizon_predictions,
    move_input_rows,
    move_predictions,
    own_trim_rows,
    range_rows,
    rate_rows,
    tracking_cost,
)
from fahv.control.mpc.row_bounds import QP_NO_BOUND, QPVectors
from fahv.control.mpc.settings import MPCSettings
from fahv.errors import DesignError
from fahv.synthesis.qp import NO_BOUND, check_kkt, compile_kernel

#: Steps (dh [ft], dV [ft/s]) of the trim map's central differences at a scheduling point.
#: The map clips to its grid: a point farther than one step beyond the grid in h or V
#: gets a zero column of the Jacobian (both points of the difference clip to the edge).
TRIM_STEP = (10.0, 5.0)
#: Solver status of a successful DAQP solve.
DAQP_OPTIMAL = (1, 2)
assert NO_BOUND < QP_NO_BOUND  # the QP's "no bound" must read as none in check_kkt


def daqp_module():
    """The DAQP solver module (`daqp`), imported on the first solve.

    Returns
    -------
    module
        What `TrackingMPC.solve` builds its workspace from (`daqp.Model`).
    """
    import daqp

    return daqp


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
    recovered : int
        Re-plans whose QP was infeasible and that the recovery QP (set point free on
        the trim map, then also without the steady-input rows,
        `TrackingMPC.solve`) planned.
    reschedules : int
        Rebuilds of the QP matrices (scheduling changes).
    """

    solves: int = 0
    fallback: int = 0
    terminal: int = 0
    recovered: int = 0
    reschedules: int = 0


class TrackingMPC:
    """One run's nominal tracking QP on the scheduled LPV model (module docstring).

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
    settings : fahv.control.mpc.settings.MPCSettings

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
        self.layout = QPLayout(settings.N_p, self.m)
        if self.Q.shape != (n, n):
            raise ValueError(f"nominal MPC: Q {self.Q.shape} does not match K {self.K.shape}")
        self._u_lo, self._u_hi = np.asarray(u_lo, float), np.asarray(u_hi, float)
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
        self._qp = None  # DAQP workspace (daqp.Model) of the current scheduling
        compile_kernel()  # at construction: a node's start-up, not its first timed step

    @property
    def u_lo(self) -> np.ndarray:
        """Tightened lower input limits (2,) [Phi, delta_e rad]."""
        return self._u_lo

    @u_lo.setter
    def u_lo(self, value) -> None:
        self._u_lo = np.asarray(value, float)

    @property
    def u_hi(self) -> np.ndarray:
        """Tightened upper input limits (2,) [Phi, delta_e rad]."""
        return self._u_hi

    @u_hi.setter
    def u_hi(self, value) -> None:
        self._u_hi = np.asarray(value, float)

    # -- scheduling ----------------------------------------------------------------
    def _trim_and_jacobian(self, h: float, V: float):
        """Trim (x_r, u_r) at (h, V) and its Jacobian per scaled set-point step.

        One evaluation of the trim map at five points: (h, V) and central differences
        of 10 ft and 5 ft/s (one-sided at the grid's edges). Returns x_r (n,), u_r (2,),
        Gx (n, 2), Gu (2, 2).
        """
        dh, dV = TRIM_STEP
        tm = self.trim_map
        h1, h2 = max(h - dh, tm.h_grid[0]), min(h + dh, tm.h_grid[-1])
        V1, V2 = max(V - dV, tm.V_grid[0]), min(V + dV, tm.V_grid[-1])
        x, u = tm.at(np.array([h, h2, h1, h, h]), np.array([V, V, V, V2, V1]))
        Gx = np.stack([(x[1] - x[2]) / (h2 - h1), (x[3] - x[4]) / (V2 - V1)], axis=1)
        Gu = np.stack([(u[1] - u[2]) / (h2 - h1), (u[3] - u[4]) / (V2 - V1)], axis=1)
        return x[0], u[0], Gx * self.theta_scale, Gu * self.theta_scale

    def schedule(self, h: float, V: float) -> None:
        """Build the condensed QP at the scheduling point (h, V) [ft, ft/s].

        Decision y of `fahv.control.mpc.qp_layout.QPLayout`. Also the
        steady-state shift of a constant disturbance, Hx (n, n) and Hu (m, n)
        (`fahv.control.mpc.estimator.steady_state_shift`), and the constraint
        matrix of `solve` (it does not depend on the state). Scheduling is a large
        part of a campaign's time (docs/guide/campaigns.md): the horizon's products are stacked
        (`fahv.control.mpc.qp_layout`).

        Parameters
        ----------
        h, V : float
            Scheduling point [ft, ft/s]; also the artificial set point's origin.

        Raises
        ------
        DesignError
            If no steady state holds (h, V) against a constant disturbance (the
            steady-state equations are singular at this point).
        """
        A, B = self.lpv.system(h, V)
        self.A, self.B = A, B
        self.theta_s = np.array([h, V], float)
        self.x_r_s, self.u_r_s, Gx, Gu = self._trim_and_jacobian(h, V)
        self.Gx, self.Gu = Gx, Gu
        self._prediction_rows(A, B, Gx, Gu)
        self._constraint_matrix()
        self._qp = None
        try:
            self.Hx, self.Hu = steady_state_shift(A, B, self.Dx, self.Du)
        except np.linalg.LinAlgError:
            raise DesignError(
                f"nominal MPC: no steady state holds (h, V) = ({h}, {V}) against a constant "
                "disturbance (singular steady-state equations)"
            ) from None
        self.stats.reschedules += 1

    def _prediction_rows(self, A, B, Gx, Gu) -> None:
        """Predictions, cost and the state-independent parts of the rows at (A, B, Gx, Gu).

        Sets `S`, `C`, `H`, `Fz`, the input rows `U_y`, `U_z`, `Uf_y`,
        `Uf_z`, the attitude rows `Att_y`, `Att_z`, the terminal box `Tb_y`,
        `Tb_z`, and as the settings ask the range rows `Hv_y`, `Hv_z`, the
        own-trim rows `T_own`, `Xb_y`, `Xb_z` and the rate rows `Rate_y`,
        `Rate_z` (`fahv.control.mpc.qp_layout`).
        """
        s, ly, K, Du = self.s, self.layout, self.K, self.Du
        Phi_w, Gam_w, Psi_w = move_predictions(A, B, K, Gx, Gu, Du, s.M)
        self.S, self.C = S, C = horizon_predictions(Phi_w, Gam_w, Psi_w, Gx, ly)
        self.H, self.Fz = tracking_cost(C, S, Phi_w[-1], self.Dx, s, ly)
        self.U_y, self.U_z = move_input_rows(K, C, S, Gu, Du, ly)
        fine = fine_step_predictions(Phi_w, Gam_w, Psi_w, C, S, s.fine_moves, ly)
        self.Uf_y, self.Uf_z = fine_input_rows(K, fine, Gu, Du, ly, self.n)
        self.Att_y, self.Att_z = attitude_rows(fine, C, S)
        if s.hv_box is not None:
            self.Hv_y, self.Hv_z = range_rows(fine, C, S, Gx, ly)
        if s.x_box is not None:
            self.T_own, self.Xb_y, self.Xb_z = own_trim_rows(fine, C, S, Gx)
        self.Tb_y = self.L_inv @ C[s.N_p]  # terminal box rows, (n, ny)
        self.Tb_z = self.L_inv @ S[s.N_p]
        if s.has_rate_rows:
            # the re-plan's own jump, from the input applied at the previous fast step to
            # u_0, narrows the bounds of the first m input rows instead (solve: a second
            # copy of those rows would be a degenerate set for the active-set solver)
            self.Rate_y, self.Rate_z = rate_rows(Phi_w, Gam_w, Psi_w, C, S, K, Du, ly)

    def _constraint_matrix(self) -> None:
        """Rows of the QP (state independent): inputs, terminal box, steady input, attitude.

        Input limits (N_p m), terminal box |L^-1 zeta_N| <= alpha / sqrt(n) (two one-sided
        sets of n rows), steady input u_base + Gu delta +/- alpha k_max within the
        tightened limits (2 m), attitude rows, the rate rows (`du_max`), the input
        limits at every fast step inside the first `fine_moves` moves
        (fine_moves (M - 1) m rows), and with `u_box` the rows on the manoeuvre part of
        the input (minus the set point's steady input) at the same move starts and fast
        steps. Then the simple bounds on y (`_set_point_bounds`).
        """
        ly, n, m, N_p = self.layout, self.n, self.m, self.s.N_p
        nb = ly.ny
        sc = np.tile(self.Du, N_p)
        A_u = self.U_y / sc[:, None]
        a_coef = np.zeros((n, nb))
        a_coef[:, ly.alpha] = 1.0 / math.sqrt(n)
        A_t1 = self.Tb_y - a_coef  # L^-1 zeta - alpha/sqrt(n) <= 0
        A_t2 = -self.Tb_y - a_coef  # -L^-1 zeta - alpha/sqrt(n) <= 0
        G = np.zeros((m, nb))
        G[:, ly.delta] = self.Gu
        kcol = np.zeros((m, nb))
        kcol[:, ly.alpha] = self.k_max
        A_s1 = (G + kcol) / self.Du[:, None]
        A_s2 = (G - kcol) / self.Du[:, None]
        rows = [A_u, A_t1, A_t2, A_s1, A_s2, self.Att_y]
        if self.s.hv_box is not None:  # the nominal's h and V inside the design's range
            rows.append(self.Hv_y)
        if self.s.x_box is not None:  # its other states inside the certified range
            rows.append(self.Xb_y)
        if self.s.has_rate_rows:  # the jumps between moves (the re-plan's: the first input rows)
            rows.append(self.Rate_y)
        # inputs at the fast steps inside the first fine_moves moves
        sf = np.tile(self.Du, self.Uf_y.shape[0] // m)[:, None]
        rows.append(self.Uf_y / sf)
        if self.s.u_box is not None:  # the manoeuvre part: the input rows less Gu delta (G)
            rows.append((self.U_y - np.tile(G, (N_p, 1))) / sc[:, None])
            rows.append((self.Uf_y - np.tile(G, (self.Uf_y.shape[0] // m, 1))) / sf)
        self.A_c = np.vstack(rows)
        self._set_point_bounds()

    def _set_point_bounds(self) -> None:
        """Simple bounds on y: the set point's trust region and map bounds, alpha in [0, 1].

        The recovery's bounds (`solve(recover=True)`) leave out the trust region: the
        set point anywhere on the trim map (inside `hv_box`, if given).
        """
        s, ly, nb = self.s, self.layout, self.layout.ny
        lo_b = np.full(nb, -QP_NO_BOUND)
        hi_b = np.full(nb, QP_NO_BOUND)
        dmax = s.dtheta_max / self.theta_scale
        tm = self.trim_map
        h_lo = (tm.h_grid[0] - self.theta_s[0]) / self.theta_scale[0]
        h_hi = (tm.h_grid[-1] - self.theta_s[0]) / self.theta_scale[0]
        V_lo = (tm.V_grid[0] - self.theta_s[1]) / self.theta_scale[1]
        V_hi = (tm.V_grid[-1] - self.theta_s[1]) / self.theta_scale[1]
        d0, d1 = ly.delta.start, ly.delta.start + 1
        if s.hv_box is not None:  # the set point inside the design's nominal range too
            h_lo = max(h_lo, (s.hv_box[0, 0] - self.theta_s[0]) / self.theta_scale[0])
            h_hi = min(h_hi, (s.hv_box[1, 0] - self.theta_s[0]) / self.theta_scale[0])
            V_lo = max(V_lo, (s.hv_box[0, 1] - self.theta_s[1]) / self.theta_scale[1])
            V_hi = min(V_hi, (s.hv_box[1, 1] - self.theta_s[1]) / self.theta_scale[1])
        lo_b[ly.alpha], hi_b[ly.alpha] = 0.0, 1.0
        self._lo_b_rec, self._hi_b_rec = lo_b.copy(), hi_b.copy()
        self._lo_b_rec[d0], self._hi_b_rec[d0] = h_lo, h_hi
        self._lo_b_rec[d1], self._hi_b_rec[d1] = V_lo, V_hi
        lo_b[d0], hi_b[d0] = max(-dmax[0], h_lo), min(dmax[0], h_hi)
        lo_b[d1], hi_b[d1] = max(-dmax[1], V_lo), min(dmax[1], V_hi)
        self._lo_b, self._hi_b = lo_b, hi_b

    # -- solve -----------------------------------------------------------------------
    def solve(
        self,
        z0: np.ndarray,
        u_base: np.ndarray,
        cmd: np.ndarray,
        x_off=None,
        recover=False,
        u_prev=None,
        relax_steady=False,
    ):
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
        recover : bool
            The recovery QP: the same problem without the trust region on the
            set-point step (the set point may move anywhere on the trim map in one
            re-plan). The trust region only keeps the trim map's linearisation local;
            no certificate needs it, while every row the certificate needs (inputs,
            attitude, terminal set, steady input) stays.
        u_prev : (2,) ndarray, optional
            Nominal input applied at the previous fast step (absolute). With rate rows
            (`mpc.du_max`) the first move's input may differ from it by at most du_max;
            None: no such row (the first plan of a run).
        relax_steady : bool
            Drop the steady-input rows (the terminal ingredients' admissibility beyond
            the horizon, which the nominal MPC's recursive feasibility needs and the
            tube's certificate does not): the last recovery, when the estimate's shift
            u_d transiently asks for a steady input outside the tightened set anywhere
            on the trim map. The input rows of every move stay.

        Returns
        -------
        y : (ny,) ndarray or None
            Solution (None if rejected).
        info : str
            "ok" or why it was rejected (solver flag, or the failed check of
            `fahv.synthesis.qp.check_kkt`); a rejected QP raises nothing, the
            caller falls back.
        """
        z0 = np.asarray(z0, float)
        x_d = np.zeros(self.n) if x_off is None else np.asarray(x_off, float)
        u_p = None if u_prev is None else np.asarray(u_prev, float)[None]
        f, bl, bu = QPVectors.of(self).compute(
            z0[None], np.asarray(u_base, float)[None], np.asarray(cmd, float)[None], x_d[None],
            u_p, recover, relax_steady,
        )  # fmt: skip
        return self.solve_qp(f[0], bl[0], bu[0])

    def solve_qp(self, f, bl, bu):
        """Solve with DAQP (warm start) and check the solution: (y or None, "ok" or why).

        A new workspace per scheduling (H and `A_c` fixed until then); between re-plans
        only f and the bounds move. A failed solve drops the workspace.

        Parameters
        ----------
        f : (ny,) ndarray
            Linear cost (`fahv.control.mpc.row_bounds.QPVectors.compute`).
        bl, bu : (ny + rows,) ndarray
            Bounds of y and of the rows of `A_c` (scaled units; 1e30: none).

        Returns
        -------
        y : (ny,) ndarray or None
            The solution, None if the solver failed or the solution fails the KKT re-check
            (`fahv.synthesis.qp.check_kkt`); nothing is raised.
        info : str
            "ok" or why it was rejected.
        """
        if self._qp is None:
            self._qp = daqp_module().Model()
            self._qp.settings = {"iter_limit": 2000}
            flag = self._qp.setup(self.H, f, self.A_c, bu, bl, primal_start=self.last_y)[0]
            if flag < 0:
                self._qp = None
                return None, f"solver set-up exit flag {flag}"
        else:
            self._qp.update(f=f, bupper=bu, blower=bl)
        y, _, flag, info = self._qp.solve()
        if flag not in DAQP_OPTIMAL:
            self._qp = None  # start the next solve from a fresh workspace
            return None, f"solver exit flag {flag}"
        y = np.asarray(y, float)
        lam = np.asarray(info["lam"], float)
        why = check_kkt(self.H, f, self.A_c, bl, bu, y, lam)
        if why:
            return None, why
        self.last_y = y
        return y, "ok"
