"""The nominal source `mpc`: the online tracking MPC with a disturbance estimate, B runs.

`TrackingMPCNominal` is the nominal part of the law `tube_mpc` (registry entry
`mpc`, case section `mpc`): it runs the nominal of the tube-based MPC of Mayne,
Seron and Rakovic (2005) in the tracking form with an artificial steady state of Limon
et al. (2010), one `fahv.control.mpc.tracking.TrackingMPC` per run, with the
state-disturbance estimate of `fahv.control.mpc.estimator`. Its output is the
reference (x_r, u_r) at the artificial set point and the nominal deviation (x_n, u_n)
that the ancillary law u = u_r + u_n + tau F (x - x_r - x_n) of eq. (36) / (54) of
Yang et al. (2022) acts on. The nominal state moves by the scheduled LPV model of
eq. (12) or by the nonlinear CM of eq. (1)-(3) (`mpc.nominal_model`). Also here: its
node parameters' values (`fahv.control.mpc.parameters`) and
its offline part (the terminal ingredients' re-check and the attitude bounds).

Batch
    `TrackingMPCNominal` runs B runs at once: the fast step (estimator,
    plan interpolation, nominal model, output) is one numpy computation over the
    batch, whose per-run items are the BLAS calls of one run's computation, so a
    run's numbers do not depend on its batch. At a re-plan (every M steps) the QPs'
    linear costs and row bounds of all runs are one computation too
    (`fahv.control.mpc.row_bounds`); the solves are a loop over the runs, each with
    its own `fahv.control.mpc.tracking.TrackingMPC` (its rows, DAQP workspace and
    scheduling).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fahv.config import Section
from fahv.control.base import NominalSource, register_nominal
from fahv.control.command import Command, CommandSchedule
from fahv.control.mpc.attitude import attitude_bounds
from fahv.control.mpc.estimator import DisturbanceEstimator, estimator_gains
from fahv.control.mpc.parameters import MPC_NODE_PARAMETERS, node_values
from fahv.control.mpc.row_bounds import QPVectors, stacked_mv
from fahv.control.mpc.settings import MPC_SECTION_FIELDS, MPCSettings
from fahv.control.mpc.tracking import TRIM_STEP, TrackingMPC
from fahv.control.reference import lpv_of, mv, trim_map_of
from fahv.errors import DesignError, RunError
from fahv.lanes import Lanes
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.vehicle import load_vehicle
from fahv.msg import NominalTrajectory
from fahv.verdict import RunEnded


def _mpc_uses(root) -> bool:
    from fahv.control.base import LAWS, VARIANTS

    return any(
        LAWS[VARIANTS[v].law].nominal is TrackingMPCNominal
        for v in root.get("variants", ())
        if v in VARIANTS and VARIANTS[v].law in LAWS
    )


@register_nominal
class TrackingMPCNominal(NominalSource):
    """Online nominal tracking MPC with a state-disturbance estimate, for B runs.

    Fast step k of each run: the estimate d (p,) is updated from the measured step
    (d <- d + gamma (r - d), r the one-step residual of the scheduled model,
    gamma = Ts / est_tau; the first residual initialises it), the nominal state z
    (deviation from the scheduling trim) moves by z+ = A z + B (u_d + u_dev) + d with
    u_dev = Gu delta + K (z - Gx delta - x_d) + c_j (the nominal input is
    u_r,s + u_d + u_dev, (x_d, u_d) the estimate's steady-state shift); every M steps
    (the first at step 1, once the estimate has started) each run's QP
    (`TrackingMPC`) chooses the moves and the set-point step delta, with its
    input limits at every fast step of the first two moves. Between re-plans u_d
    follows the estimate, which the QP does not bound: the nominal input stays within
    the tightened limits by the plan only as far as d stays near its re-plan value
    (clipping it there instead made the loop diverge after an early loss, measured). The
    output reference is x_r = trim_x(theta), u_r = trim_u(theta) + u_d at the
    artificial set point theta, x_n = X_n - x_r, u_n = u_nominal - u_r, so that the
    ancillary law u = u_r + u_n + tau F (x - x_r - x_n) (eq. 36/54) is unchanged.

    With `mpc.nominal_model` 'cm' (9-state CM designs) the nominal state moves by the
    nonlinear CM of the nominal vehicle instead, z+ = f_0(z, u_nominal) + d (one period
    of the plant's RK4, inputs clipped to the actuator limits as the plant does), and
    the estimate filters the residual of that model, r = x_k - f_0(x_k-1, u_k-1). The
    QP still predicts with the scheduled LPV model, and its steady-state shift (x_d, u_d)
    comes from a second filter of the same gain on the scheduled model's residual (as
    with the LPV nominal): both models then agree that the plant's steady state is one,
    so the loop ends on the command. (With the CM residual in the shift, the QP's
    steady state missed the nominal CM's by the linearisation error, measured: Case 1
    ended 0.16 ft / 0.28 ft/s off the command, 1.6 ft / 2.0 ft/s after a 24 % loss.)
    The tube error x - z is then
    linearised along the nominal rather than at the scheduling trim: what the tube
    must hold no longer grows with the nominal's distance from the trim
    (docs/theory/nominal_mpc.md, "The error along the nominal").

    With `mpc.h_reset` the nominal's altitude is set to the measured one at every
    re-plan, before the QP: the altitude error e_h returns to 0 every M steps, so that
    |e_h| is bounded by M steps of its increment and the tube can be designed on the
    eight states after h (docs/theory/nominal_mpc.md, "The altitude reset"). The QP plans
    from the reset nominal. A reset by Delta h, with the artificial set point moved by the
    same Delta h, moves the QP's rows only by the trim map's slope in h times Delta h
    (below 0.001 deg over the eight-state tube set's bound of 2.6 ft): feasibility after the
    reset is argued and measured (every re-plan accepted in the runs measured), not
    certified; an infeasible re-plan takes the recovery like any other.

    For an 11-state (ECM) design the estimate works in ECM coordinates: a replica of
    the notch_filter node's filter on the same q samples gives q' and x_q (eq. 43).

    Parameters
    ----------
    p, runs, lanes
        As `fahv.control.base.NominalSource`.

    Raises
    ------
    RunError
        For an 11-state design with the notch off (the ECM needs its states).
    DesignError
        If no steady state holds the initial point against a constant disturbance.
    """

    name = "mpc"
    estimates_disturbance = True
    parameters = MPC_NODE_PARAMETERS
    section = Section(
        "mpc",
        MPC_SECTION_FIELDS,
        "online nominal tracking MPC (the nominal part of tube_mpc)",
        when=_mpc_uses,
        when_text="a variant's law uses the nominal MPC",
    )

    def __init__(self, p: dict, runs: Sequence[dict], lanes: Lanes) -> None:
        super().__init__(p, runs, lanes)
        B = len(runs)
        n = p["A"].shape[1]
        self.n, self.Ts = n, p["Ts"]
        st = MPCSettings.of_parameters(p, n)
        lpv, tm = lpv_of(p), trim_map_of(p)
        self.mpcs = [
            TrackingMPC(lpv, tm, p["K"], p["Q"], p["u_lo"], p["u_hi"], p["Dx"], p["Du"], st)
            for _ in range(B)
        ]
        m0 = self.mpcs[0]
        self.M, self.K, self.Du, self.scale = st.M, m0.K, m0.Du, m0.theta_scale
        self.trim_map = tm
        self.L_inv = m0.L_inv
        self._init_estimate(p, B)
        self.command = CommandSchedule([Command.of_parameters(r) for r in runs])
        self._init_batch_state(B, st.N_p)
        #: the runs' QP parts their re-plans read, stacked (filled at each scheduling)
        self.vectors: QPVectors | None = None
        for b in range(B):
            try:
                self._schedule(b, self.TH[b])
            except DesignError as exc:
                lanes.fail(b, exc)
                continue
            self.TRX[b], self.TRU[b] = tm(*self.TH[b])
        self.XN = np.stack([np.asarray(r["x0"], float) for r in runs])
        self.nominal_cm = st.nominal_model == "cm"
        self.h_reset = st.h_reset
        #: the estimate the QP's steady-state shift (x_d, u_d) uses: the scheduled model's
        #: residual, also with the nonlinear nominal (then a second filter; class docstring)
        self.est_ss = self.est
        if self.nominal_cm and self.has_est:
            self.est_ss = DisturbanceEstimator(B, self.p_est, *self.est_args)
        if self.nominal_cm:
            self._init_nominal_cm(p, B)
        self.k = 0
        self._counts = self._qp_counts()

    def _init_estimate(self, p: dict, B: int) -> None:
        """The disturbance estimate of B runs, in ECM coordinates for an 11-state design.

        Raises
        ------
        RunError
            For an 11-state design with the notch off.
        """
        self.filter = None
        self.p_est = 9
        if p["design_model"] == "ecm":  # the estimator works in its coordinates (q', x_q, eq. 43)
            if not p["notch.enabled"]:
                raise RunError("nominal_trajectory: the 11-state (ECM) design needs the notch on")
            nf = NotchFilter(*(p[f"notch.{k}"] for k in ("omega_z", "eps_z", "omega_p", "eps_p")))
            self.filter = DiscreteNotch(nf, p["Ts"], np.zeros(B))
            self.p_est = 11
        est_tau, tau_e = p["mpc.est_tau"], p["mpc.est_tau_elevator"]
        pe = self.p_est
        self.has_est = est_tau > 0.0
        #: step of the first plan: 1 with an estimate (it starts from the first residual)
        self.k_first_plan = 1 if self.has_est else 0
        self.est_args = (*estimator_gains(p["Ts"], est_tau, tau_e), np.asarray(p["Dx"], float)[:pe],
                         p["mpc.est_start"])  # fmt: skip
        self.est = DisturbanceEstimator(B, pe, *self.est_args)

    def _init_batch_state(self, B: int, N_p: int) -> None:
        """Per-run state of the fast step (stacked) and of the scheduled models."""
        n, pe = self.n, self.p_est
        self.XRS, self.URS, self.THS = np.empty((B, n)), np.empty((B, 2)), np.empty((B, 2))
        self.GX, self.GU = np.empty((B, n, 2)), np.empty((B, 2, 2))
        self.A, self.Bm = np.empty((B, n, n)), np.empty((B, n, 2))
        self.HX, self.HU = np.empty((B, n, pe)), np.empty((B, 2, pe))
        self.EA, self.EB = np.empty((B, pe, pe)), np.empty((B, pe, 2))
        self.TH = np.stack([self.command.h0, self.command.V0], axis=1)
        self.TRX, self.TRU = np.empty((B, n)), np.empty((B, 2))
        self.PLAN = np.zeros((B, N_p, 2))
        self.U_NOM = np.zeros((B, 2))  # nominal input of the last fast step (rate rows)
        self.U_D = np.zeros((B, 2))  # the estimate's steady input u_d in it
        self.moves_left = np.zeros(B, dtype=int)
        self.prev = np.zeros((B, pe))
        self.has_prev = False
        self.status = ["not started"] * B

    def _init_nominal_cm(self, p: dict, B: int) -> None:
        """The nominal vehicle's CM for `mpc.nominal_model` 'cm'.

        Raises
        ------
        RunError
            If the design is not the 9-state CM.
        """
        if self.n != 9:
            raise RunError(
                f"nominal_trajectory: mpc.nominal_model 'cm' needs the 9-state CM design, "
                f"got {self.n} states"
            )
        from fahv.plant.rk4 import compile_kernels, params_records, rk4_cm  # numba: this model only

        veh = load_vehicle(p["vehicle_file"] or None)
        self.nominal_vehicle = params_records([veh.params] * B)
        self._rk4_cm = rk4_cm
        self.limits_lo, self.limits_hi = veh.limits.u_min, veh.limits.u_max
        self.n_sub = int(p["plant_substeps"])
        compile_kernels(self.nominal_vehicle)  # now, not in a timed step

    def _qp_counts(self) -> tuple[np.ndarray, ...]:
        """Per-run QP counters (solves, fallback, terminal, recovered), each (B,) int64.

        Only a re-plan changes them: `step` builds them after each re-plan and
        its messages share them until the next (no message array is written in place).
        """
        st = [m.stats for m in self.mpcs]
        return tuple(
            np.array([getattr(s, c) for s in st], dtype=np.int64)
            for c in ("solves", "fallback", "terminal", "recovered")
        )

    # -- per run: scheduling and the QP ------------------------------------------------
    def _schedule(self, b: int, theta) -> None:
        """Schedule run b's QP at theta = (h, V) and copy its model into the batch arrays."""
        mpc = self.mpcs[b]
        mpc.schedule(float(theta[0]), float(theta[1]))
        self._copy_schedule(b)

    def _reschedule(self, b: int, theta) -> None:
        """Schedule run b's QP at the nominal's operating point theta = (h, V) during a run.

        The trim map is the QP's domain: it is clipped to its grid, so at a point more
        than one difference step (`fahv.control.mpc.tracking.TRIM_STEP`) beyond
        the grid its Jacobian has a zero column and the own-trim rows' Gx[0:2] is
        singular. A nominal that left that domain (it follows the disturbance estimate,
        which follows a vehicle that diverges, e.g. under a stuck elevator) ends the run
        with the verdict `nominal_out_of_domain`; singular scheduling equations inside
        it with `nominal_singular` (`fahv.verdict`).

        Raises
        ------
        RunEnded
            With one of those verdicts.
        """
        k, t = self.k, self.k * self.Ts
        tm, (h, V), (dh, dV) = self.trim_map, (float(theta[0]), float(theta[1])), TRIM_STEP
        inside = (tm.h_grid[0] - dh < h < tm.h_grid[-1] + dh
                  and tm.V_grid[0] - dV < V < tm.V_grid[-1] + dV)  # fmt: skip
        if not inside:  # also for a non-finite h or V
            raise RunEnded(
                "nominal_out_of_domain", "nominal_trajectory", k, t,
                f"the nominal's operating point (h, V) = ({h:.1f} ft, {V:.1f} ft/s) left "
                f"the trim map the QP is scheduled on (h in [{tm.h_grid[0]:g}, "
                f"{tm.h_grid[-1]:g}] ft, V in [{tm.V_grid[0]:g}, {tm.V_grid[-1]:g}] ft/s, "
                f"one difference step of {dh:g} ft, {dV:g} ft/s beyond); "
                f"vehicle at {self._vehicle_text(b)}",
            )  # fmt: skip
        try:
            self._schedule(b, theta)
        except (DesignError, np.linalg.LinAlgError) as exc:
            raise RunEnded(
                "nominal_singular", "nominal_trajectory", k, t,
                f"scheduling at (h, V) = ({h:.1f} ft, {V:.1f} ft/s): {exc}",
            ) from None  # fmt: skip

    def _vehicle_text(self, b: int) -> str:
        """Run b's measured altitude, speed and attitude at the current step, as text."""
        x = self._x_now[b]
        return (f"h = {x[0]:.1f} ft, V = {x[1]:.1f} ft/s, alpha = {np.degrees(x[2]):.2f} deg, "
                f"theta = {np.degrees(x[3]):.2f} deg")  # fmt: skip

    def _copy_schedule(self, b: int) -> None:
        """Copy run b's scheduled model and its QP's parts into the batch arrays."""
        mpc = self.mpcs[b]
        if self.vectors is None:
            self.vectors = QPVectors(mpc, len(self.mpcs))
        self.vectors.put(b, mpc)
        pe = self.p_est
        self.XRS[b], self.URS[b], self.THS[b] = mpc.x_r_s, mpc.u_r_s, mpc.theta_s
        self.GX[b], self.GU[b], self.A[b], self.Bm[b] = mpc.Gx, mpc.Gu, mpc.A, mpc.B
        self.HX[b], self.HU[b] = mpc.Hx[:, :pe], mpc.Hu[:, :pe]
        self.EA[b], self.EB[b] = mpc.A[:pe, :pe], mpc.B[:pe]

    def _reschedule_if_due(self, b: int) -> None:
        """Reschedule run b's QP at its nominal operating point if it moved far enough.

        The QP is scheduled at the nominal's (h, V) of X_n, not at the set point: the set
        point may sit a steady offset away from the state it holds.

        Raises
        ------
        RunEnded
            As `_reschedule`.
        """
        mpc = self.mpcs[b]
        if not np.all(np.abs(self.XN[b, :2] - mpc.theta_s) <= mpc.s.reschedule):
            self._reschedule(b, self.XN[b, :2])

    def _qp_arguments(self, cmd: np.ndarray) -> tuple:
        """Every run's QP arguments and its first QP's vectors, in one pass over the batch.

        Returns (z0 (B, n), u_base (B, 2), x_d (B, n), u_prev (B, 2) or None, f, bl, bu)
        (`fahv.control.mpc.row_bounds.QPVectors.compute`). The rate rows' start
        (`mpc.du_max`) is the input of the last fast step with its estimate part moved
        to the estimate's new steady input. u_d follows the estimate at every fast step,
        the rows bound the plan's part: measured from the last input as applied, the first
        re-plan after a loss's onset had to cancel the estimate's jump (a 10-14 % loss:
        the plan pitched up and the vehicle rose 15-34 ft; docs/theory/nominal_mpc.md,
        "The re-plan's rate row").
        """
        B = self.XN.shape[0]
        if self.has_est:
            d = np.ascontiguousarray(self.est_ss.d)
            x_d, u_d = stacked_mv(self.HX, d), stacked_mv(self.HU, d)
        else:
            x_d, u_d = np.zeros((B, self.n)), np.zeros((B, 2))
        z0, u_base = self.XN - self.XRS - x_d, self.URS + u_d
        u_prev = self.U_NOM + (u_d - self.U_D) if self.k > 0 else None
        with np.errstate(all="ignore"):  # a run that has ended may hold NaN
            f, bl, bu = self.vectors.compute(z0, u_base, cmd, x_d, u_prev)
        return z0, u_base, x_d, u_prev, f, bl, bu

    def _plan(self, b: int, cmd: np.ndarray, qp: tuple) -> bool:
        """Re-plan run b: solve its QP (`qp`: `_qp_arguments`), or fall back (counted).

        Returns True when the plan moved the set point `TH[b]`: its trim `TRX[b]`,
        `TRU[b]` is then due (evaluated for all such runs at once by `step`).
        """
        mpc, ly = self.mpcs[b], self.mpcs[b].layout
        z0, u_base, x_d, u_prev, f, bl, bu = qp
        u_prev_b = None if u_prev is None else u_prev[b]
        args = (z0[b], u_base[b], cmd[b], x_d[b])
        y, why = mpc.solve_qp(f[b], bl[b], bu[b])
        recovered = False
        if y is None:
            y, why, recovered = self._recover(mpc, args, u_prev_b, why)
        if y is not None:
            if recovered:
                mpc.stats.recovered += 1
            else:
                mpc.stats.solves += 1
            self.PLAN[b] = y[ly.moves].reshape(ly.N_p, ly.m)
            self.TH[b] = mpc.theta_s + y[ly.delta] * mpc.theta_scale
            self.moves_left[b] = ly.N_p
            self.status[b] = f"recovered ({why})" if recovered else "ok"
            return True
        elif self.moves_left[b] > 1:  # the set point stays where it is
            mpc.stats.fallback += 1
            self.PLAN[b] = np.vstack([self.PLAN[b, 1:], np.zeros((1, ly.m))])
            self.moves_left[b] -= 1
            self.status[b] = f"shifted plan ({why})"
        else:
            mpc.stats.terminal += 1
            self.PLAN[b] = 0.0
            self.moves_left[b] = 0
            self.status[b] = f"terminal law ({why})"
        return False

    @staticmethod
    def _recover(mpc: TrackingMPC, args: tuple, u_prev, why: str):
        """The recovery QPs after a rejected QP: (y or None, why, whether one planned).

        The recovery frees the set point on the trim map (no trust region), then also
        drops the steady-input rows (`TrackingMPC.solve`, `relax_steady`).
        """
        y, why_rec = mpc.solve(*args, recover=True, u_prev=u_prev)
        if y is None:  # then without the steady-input rows (solve: relax_steady)
            y, why_st = mpc.solve(*args, recover=True, u_prev=u_prev, relax_steady=True)
            why = f"{why}; steady input relaxed" if y is not None else why
            why_rec = f"{why_rec}; without the steady-input rows: {why_st}"
        recovered = y is not None
        why = why if y is not None else f"{why}; recovery: {why_rec}"
        return y, why, recovered

    # -- the batched fast step ----------------------------------------------------------
    def _measure(self, x: np.ndarray) -> np.ndarray:
        """Measured states in the design model's coordinates (B, p)."""
        if self.filter is None:
            return x[:, : self.p_est]
        q_f = self.filter.step(x[:, 4])
        return np.concatenate([x[:, :4], q_f[:, None], x[:, 5:9], self.filter.x_q], axis=1)

    def _nominal_step(self, X: np.ndarray, U) -> np.ndarray:
        """One period of the nominal vehicle's CM (eq. 1-3) from X (B, 9) under U (B, 2)."""
        U = np.clip(np.asarray(U, float), self.limits_lo, self.limits_hi)
        return self._rk4_cm(np.ascontiguousarray(X, float), np.ascontiguousarray(U),
                            self.nominal_vehicle, self.Ts, self.n_sub)  # fmt: skip

    def _estimate(self, x: np.ndarray, u_prev) -> None:
        """Update the estimates from the measured states x (B, 9) and the inputs u_prev."""
        xm = self._measure(np.asarray(x, float))
        if self.has_prev and u_prev is not None:
            self.est_ss.update(
                self.EA, self.EB, self.prev - self.XRS[:, : self.p_est],
                np.asarray(u_prev, float) - self.URS, xm - self.XRS[:, : self.p_est],
            )  # fmt: skip
            if self.nominal_cm:  # the nominal CM's own residual, for its propagation
                self.est.update_residual(xm - self._nominal_step(self.prev, u_prev),
                                         self.EB[:, :, 1])  # fmt: skip
        self.prev = xm.copy()
        self.has_prev = True

    def _replan(self, x: np.ndarray, h_c: np.ndarray, V_c: np.ndarray) -> None:
        """Re-plan every live run (each its own QP); a run whose re-plan ends it ends alone."""
        self._x_now = np.asarray(x, float)  # the measured states (B, 9), for a verdict's reason
        if self.h_reset:  # the nominal's altitude to the measured one (e_h = 0)
            alive = self.lanes.alive
            self.XN[alive, 0] = np.asarray(x, float)[alive, 0]
        for b in np.flatnonzero(self.lanes.alive):
            try:
                self._reschedule_if_due(int(b))
            except RunEnded as exc:  # the run ends alone (a batch goes on)
                self.lanes.fail(int(b), exc)
        live = np.flatnonzero(self.lanes.alive)
        moved = []
        if live.size:  # every run's QP vectors at once, then each run's solve
            cmd = np.stack([np.asarray(h_c, float), np.asarray(V_c, float)], axis=1)
            qp = self._qp_arguments(cmd)
            moved = [b for b in live if self._plan(int(b), cmd, qp)]
        if moved:  # the trims of the new set points, in one evaluation of the map
            self.TRX[moved], self.TRU[moved] = self.trim_map.at(*self.TH[moved].T)
        self._counts = self._qp_counts()

    def output(self, k, t, x, u_prev) -> NominalTrajectory:
        """Output of step k for the B runs (class docstring); `advance` follows.

        QP counters and the input-equivalent estimate d_hat = -u_d (for a loss of
        elevator effectiveness alone, (0, (rho_f - 1) delta_e,r)) are in the message.
        """
        B = x.shape[0]
        if self.has_est:
            self._estimate(x, u_prev)
        h_c, V_c = self.command(t)
        # re-plan every M steps (each run's own QP); with an estimate, the first plan
        # waits for step 1, when the first residual has initialised it (step 0 holds
        # the initial trim: no plan yet, u = u_r + K (x_n - x_s))
        k0 = self.k_first_plan
        if self.k == k0 or (self.k > k0 and self.k % self.M == 0):
            self._replan(x, h_c, V_c)
        if self.has_est:
            Dc = np.ascontiguousarray(self.est_ss.d)
            x_d, u_d = mv(self.HX, Dc), mv(self.HU, Dc)
        else:  # exact zeros (a product with d = 0 could give -0.0)
            x_d, u_d = np.zeros((B, self.n)), np.zeros((B, 2))
        dth = (self.TH - self.THS) / self.scale
        x_s = mv(self.GX, dth) + x_d
        u_s = mv(self.GU, dth)
        z = self.XN - self.XRS
        zx = np.ascontiguousarray(z - x_s)
        u_dev = (u_s + mv(self.K, zx)) + self.PLAN[:, 0] * self.Du
        u_nom = (self.URS + u_d) + u_dev
        self.U_NOM, self.U_D = u_nom, u_d
        x_r, u_r = self.TRX.copy(), self.TRU + u_d
        w = mv(self.L_inv, zx)  # L^-1 (z - x_s): the level in E(Q) is w'w
        solves, fallback, terminal, recovered = self._counts
        out = NominalTrajectory(
            k, t, h_c, V_c, self.TH[:, 0].copy(), self.TH[:, 1].copy(), x_r, u_r,
            self.XN - x_r, u_nom - u_r, (w[:, None, :] @ w[:, :, None])[:, 0, 0],
            solves, fallback, terminal, -u_d, recovered,
        )  # fmt: skip
        self._pending = (z, u_nom, u_d, u_dev)
        return out

    def advance(self) -> None:
        """Move the nominal state one fast step by its model (class docstring).

        From the output's z (B, n), the nominal minus the scheduling trim, u_nom (B, 2),
        the nominal input, and u_d + u_dev (B, 2), its deviation from the scheduling
        trim's input.
        """
        z, u_nom, u_d, u_dev = self._pending
        self.k += 1
        d_n = np.zeros_like(z)
        if self.has_est:
            d_n[:, : self.p_est] = self.est.d
        if self.nominal_cm:  # z+ = f_0(z, u_nominal) + d: the nonlinear nominal
            self.XN = self._nominal_step(self.XN, u_nom) + d_n
        else:  # z+ = A z + B u + d: the scheduled LPV model
            zc = np.ascontiguousarray(z)
            self.XN = (
                (self.XRS + mv(self.A, zc)) + mv(self.Bm, np.ascontiguousarray(u_d + u_dev))
            ) + d_n

    # -- offline ------------------------------------------------------------------------
    @classmethod
    def design(cls, ctx) -> dict[str, np.ndarray]:
        """Re-check the terminal ingredients; the attitude bounds of the QP.

        Returns `att_max` (2,) [rad], the bounds of the QP's attitude rows, and
        `att_support` (2,) [rad], the support of Z in alpha and theta
        (`attitude_bounds`).

        Raises
        ------
        DesignError
            If the terminal set is not invariant or a trim input of the case's path
            is outside the tightened set.
        """
        from fahv.model.trim import TrimMap
        from fahv.synthesis.nominal import verify_terminal

        a = ctx.arrays
        u_lo, u_hi = a["u_lo"], a["u_hi"]
        cmd = ctx.spec["command"]
        mpc = ctx.spec.get("mpc") or {f.name: f.default for f in MPC_SECTION_FIELDS}
        offset = float(a["att_trim_offset"]) if "att_trim_offset" in a else 0.0
        att = attitude_bounds(a["N"], mpc["att_max"], offset)
        ctx.log(att.report())
        tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
        path = np.array([tm(cmd["h0"], cmd["V0"])[1], tm(cmd["h_c"], cmd["V_c"])[1]])
        cert = verify_terminal(a["A"], a["B"], a["K"], a["Q"], u_lo, u_hi, path)
        ctx.log(
            f"nominal MPC: tightened inputs Phi in [{u_lo[0]:.4f}, {u_hi[0]:.4f}], delta_e in "
            f"[{np.degrees(u_lo[1]):.2f}, {np.degrees(u_hi[1]):.2f}] deg; terminal set E(Q) "
            f"invariant under K at every vertex (norm {cert['invariance']:.6f} <= 1), "
            f"alpha = 1 admissible along the path: {cert['alpha_max'] >= 1.0}  OK"
        )
        return {"att_max": att.used, "att_support": att.support}

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict:
        """`mpc.*` node parameters from the case's `mpc` section and the design's arrays.

        `fahv.control.mpc.parameters.node_values`.
        """
        return node_values(arrays, case)
