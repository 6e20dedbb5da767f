"""A gain-scheduled Kalman filter of the CM state from the sensors' measurement.

The flight computer measures y_k = C x_k + v_k (`fahv.sensors`: h, V, theta and the
gyro's q by default; the gyro sees the flexible modes through the mode slopes, row
`fahv.sensors.measure.output_matrix`), and must estimate the whole state x_k of the CM, eq. (1)-(3),
flexible states included, to run the tube law on it. The filter here:

- estimates with the state an input disturbance d (2,), a random walk added to the
  command (the offset-free disturbance model of Pannocchia and Rawlings 2003): an
  actuator fault or a model error then moves d, not a bias of x;
- optionally (`design_filter`'s `disturbance`) a third disturbance d_s, a random walk
  added to the rate of one state (`fahv.estimation.state_disturbance`: the flight-path
  angle's, d_gamma, or the altitude's, d_h), which takes up a lift or mass error of the
  flown vehicle that neither input's column carries;
- predicts with the nominal nonlinear CM (`fahv.plant.rk4.rk4_cm`, the plant's own
  kernel with the vehicle file's nominal parameters) under the command the controller
  sent plus d (the flight computer does not know the actuator fault);
- corrects with the a-posteriori (current-estimate) Kalman gain
  L(p) = sum_i tau_i(p) L_i, scheduled on the estimate's (h, V) by the TP weights of the
  design's LPV model, eq. (11)-(12);
- L_i is the steady-state gain of vertex i (`kalman_gains`: the discrete algebraic
  Riccati equation of the augmented ([A_i B_i; 0 I], [C 0]) with the process covariance
  diag(Q_w, Q_d) and the sensors' covariance R_v, scaled by the design's state and
  input scales first).

With the plant's servos (`design_filter`'s `servos`) the predictor integrates the
actuator states with the airframe by the plant's kernel (`fahv.plant.rk4.rk4_cm_act`),
from rest at the first command as the plant's servos start; they are not measured, so
the correction leaves them to the model (the gains are the airframe's: with them this
predictor destabilises Case 1's bending mode, so the loop's default is the ideal one).

It models no sensor delay, lag or sample-and-hold (the vehicle file's defaults have
none). What its error certifies is in `fahv.stochastic.error_bound` and
`fahv.stochastic.closed_loop`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from fahv.estimation.servo_model import N_SERVO, with_servos
from fahv.estimation.state_disturbance import StateDisturbance, state_disturbance
from fahv.model.actuators import kernel_parameters
from fahv.model.lpv import PolytopicLPV
from fahv.model.vehicle import H, V
from fahv.plant.rk4 import compile_kernels, params_records, rk4_cm, rk4_cm_act, servo_lanes
from fahv.sensors.data import SensorData
from fahv.sensors.measure import output_matrix


def measurement_covariance(measured: Sequence[str], data: SensorData) -> np.ndarray:
    """R_v: the white noise variance of each channel on the diagonal.

    Parameters
    ----------
    measured : sequence of str
        Channels in output order.
    data : SensorData
        Their noise models (`stddev`).

    Returns
    -------
    (n_y, n_y) ndarray
        diag(stddev^2) [unit^2 of each channel].
    """
    return np.diag([data.channels[c].stddev ** 2 for c in measured])


def kalman_gains(A: np.ndarray, C: np.ndarray, Q_w: np.ndarray, R_v: np.ndarray,
                 scale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Steady-state a-posteriori Kalman gains L_i of every vertex (A_i, C), and covariances.

    P_i solves the filter's discrete algebraic Riccati equation
    P = A P A' - A P C' (C P C' + R)^-1 C P A' + Q (`scipy.linalg.solve_discrete_are`
    on the dual pair (A', C')), and L_i = P_i C' (C P_i C' + R)^-1, the gain of the
    correction x_k|k = x_k|k-1 + L (y_k - C x_k|k-1).

    Parameters
    ----------
    A : (R, n, n) ndarray
        Discrete vertex matrices A_i (deviation coordinates, unscaled).
    C : (n_y, n) ndarray
        Output matrix.
    Q_w : (n, n) ndarray
        Process noise covariance (unscaled units^2).
    R_v : (n_y, n_y) ndarray
        Measurement noise covariance.
    scale : (n,) ndarray, optional
        State scales D (the design's Dx): the equation is solved for D^-1 x, where its
        entries are of one size.

    Returns
    -------
    L : (R, n, n_y) ndarray
        L_i in unscaled units.
    P : (R, n, n) ndarray
        The a-posteriori error covariance (I - L_i C) P_i of each vertex, unscaled.

    Raises
    ------
    ValueError
        If a vertex is not detectable from C (no stabilising solution; names it), or a
        gain is not finite.
    """
    R_, n, _ = A.shape
    D = np.ones(n) if scale is None else np.asarray(scale, float)
    Cs, Qs = C * D[None, :], Q_w / np.outer(D, D)
    out = np.empty((R_, n, C.shape[0]))
    cov = np.empty((R_, n, n))
    for i in range(R_):
        As = A[i] / D[:, None] * D[None, :]
        try:
            P = scipy.linalg.solve_discrete_are(As.T, Cs.T, Qs, R_v)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ValueError(f"Kalman gain of vertex {i}: no stabilising solution ({exc})") from exc
        Ls = P @ Cs.T @ np.linalg.inv(Cs @ P @ Cs.T + R_v)
        out[i] = D[:, None] * Ls
        cov[i] = np.outer(D, D) * ((np.eye(n) - Ls @ Cs) @ P)
    if not np.all(np.isfinite(out)):
        raise ValueError("Kalman gains: a gain is not finite")
    return out, cov


#: The design's one-step bound w_max read as this many standard deviations of the
#: process noise (Q_w = diag((w_max / W_SIGMAS)^2)).
W_SIGMAS = 3.0
#: Random-walk intensity of the input disturbance d per sqrt(s) [Phi, delta_e rad]:
#: 0.02 and 0.5 deg/sqrt(s) (a 10 % loss of a 13 deg elevator, 1.3 deg, is followed in
#: seconds; the noise it lets into d stays small against the inputs' ranges).
D_INTENSITY = np.array([0.02, np.radians(0.5)])
#: Process noise of the servo states per step, as a share of their scales (position: the
#: input's scale, rate: it times omega_n): their model is exact, this keeps the Riccati
#: equation regular.
SERVO_NOISE = 1e-3


def with_state_disturbance(Az: np.ndarray, Ts: float, dist: StateDisturbance) -> np.ndarray:
    """The vertices of z with a state disturbance d_s appended as its last state.

    d_s+ = d_s, and x[dist.row]+ gains dist.sign Ts d_s
    (`fahv.estimation.state_disturbance`): the column the predictor applies after each
    step.

    Parameters
    ----------
    Az : (R, n_z, n_z) ndarray
        Vertices of z whose first nine states are the CM's (`augmented`, `with_servos`).
    Ts : float
        Step [s].
    dist : StateDisturbance
        The disturbance.

    Returns
    -------
    (R, n_z + 1, n_z + 1) ndarray
    """
    R_, n, _ = Az.shape
    out = np.zeros((R_, n + 1, n + 1))
    out[:, :n, :n] = Az
    out[:, dist.row, n] = dist.sign * Ts
    out[:, n, n] = 1.0
    return out


def augmented(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The vertices of the state with the input disturbance: [[A_i, B_i], [0, I]].

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray

    Returns
    -------
    (R, n + m, n + m) ndarray
        The model of z = [x; d] with x+ = A x + B (u + d), d+ = d.
    """
    R_, n, m = B.shape
    out = np.zeros((R_, n + m, n + m))
    out[:, :n, :n], out[:, :n, n:] = A, B
    out[:, n:, n:] = np.eye(m)
    return out


def filter_model(A: np.ndarray, B: np.ndarray, servos=None, Ts: float = 0.0,
                 disturbance: StateDisturbance | None = None) -> np.ndarray:  # fmt: skip
    """The linear model of the filter's state z at given airframe points.

    z = [x; d] (`augmented`), [x; d; s] with servos
    (`fahv.estimation.servo_model.with_servos`), then d_s if `disturbance`
    (`with_state_disturbance`): the one layout the filter, its error system and the margin
    analysis share.

    Parameters
    ----------
    A : (R, 9, 9) ndarray
    B : (R, 9, 2) ndarray
        The airframe at R points (the LPV vertices, eq. 12, or plant points).
    servos : (2, 6) ndarray, optional
        The filter's servos (`fahv.model.actuators.kernel_parameters`); None: ideal.
    Ts : float
        Step [s] (with servos or a state disturbance).
    disturbance : StateDisturbance, optional
        Append it (`fahv.estimation.state_disturbance`); None: none.

    Returns
    -------
    (R, n_z, n_z) ndarray
        n_z = 11, 15 with servos, one more with `disturbance`.
    """
    Az = augmented(A, B) if servos is None else with_servos(A, B, servos, Ts)
    return Az if disturbance is None else with_state_disturbance(Az, Ts, disturbance)


class GainScheduledKalman:
    """The filter of B runs: `correct` with y_k, then `predict` with the command u_k.

    Its state z = [x; d] is the CM state (9,) and the input disturbance (2,), then the
    servos' four states and the state disturbance d_s, each if the filter has them.

    Parameters
    ----------
    lpv : PolytopicLPV
        The design's LPV model (its weights schedule the gains).
    L : (R, n_z, n_y) ndarray
        Vertex gains of z (`kalman_gains` on `augmented`; n_z = 11, or 15 with servos:
        `fahv.estimation.servo_model.with_servos`; one more with `disturbance`).
    C : (n_y, 9) ndarray
        Output matrix of x (`output_matrix`).
    params : VehicleParams
        The nominal vehicle of the predictor.
    limits : InputLimits
        The plant's input limits (the predictor saturates the command as the plant does).
    Ts : float
        Step [s].
    n_sub : int
        RK4 steps per step.
    x0 : (B, 9) ndarray
        Initial estimate x_0|-1 (e.g. the trim the run starts from).
    P : (R, n_z, n_z) ndarray, optional
        Steady-state a-posteriori covariances of the vertices (`kalman_gains`), for
        `sigma`.
    servos : (2, 6) ndarray, optional
        The plant's servos (`fahv.model.actuators.kernel_parameters`): z then ends with
        the four actuator states `a`, which the predictor integrates with the airframe by
        the plant's own kernel (`fahv.plant.rk4.rk4_cm_act`) and the correction moves
        by their rows of L. None: ideal actuators.
    disturbance : str, optional
        A name of `fahv.estimation.state_disturbance.STATE_DISTURBANCE_NAMES`: z ends with
        that disturbance d_s (`with_state_disturbance`); `none` (the default): it does not.

    Raises
    ------
    ValueError
        If L is not of z's rows (11, 15 with servos, one more with `disturbance`) and
        C's outputs, servos is not (2, 6), or the disturbance is unknown.
    """

    def __init__(self, lpv: PolytopicLPV, L, C, params, limits, Ts: float, n_sub: int, x0,
                 P=None, servos=None, disturbance: str = "none") -> None:  # fmt: skip
        self.lpv, self.L, self.C = lpv, np.asarray(L, float), np.asarray(C, float)
        self.servos = None if servos is None else np.ascontiguousarray(servos, float)
        if self.servos is not None and self.servos.shape != (2, 6):
            raise ValueError(f"estimator: servo data of shape {self.servos.shape}, expected (2, 6)")
        self.disturbance = state_disturbance(disturbance)
        self.n_s = 0 if self.servos is None else N_SERVO
        n_z = 11 + self.n_s + (self.disturbance is not None)
        if self.L.shape[1:] != (n_z, self.C.shape[0]):
            raise ValueError(f"estimator: gains of shape {self.L.shape[1:]}, expected "
                             f"{(n_z, self.C.shape[0])}")  # fmt: skip
        self.P = None if P is None else np.asarray(P, float)
        x0 = np.atleast_2d(np.asarray(x0, float))
        self.z = np.empty((len(x0), n_z))
        self.restart(np.ones(len(x0), dtype=bool), x0)
        self.rec = params_records([params] * len(x0))
        self.limits, self.Ts, self.n_sub = limits, float(Ts), int(n_sub)
        #: The servos once per run, as the kernel takes them (B, 2, 6).
        self._servo_lanes = (np.zeros((0, 2, 6)) if self.servos is None
                             else servo_lanes(self.servos, len(x0)))  # fmt: skip
        compile_kernels(self.rec, self.servos)  # the predictor's kernel now, not in a timed step

    def restart(self, runs: np.ndarray, x0: np.ndarray) -> None:
        """Put the filters of `runs` back at their start: x = x0, d = 0.

        Parameters
        ----------
        runs : (B,) bool ndarray
            The runs to restart.
        x0 : (B, 9) ndarray
            Initial estimates of every run (those of `runs` are taken).
        """
        self.z[runs, :9] = np.asarray(x0, float)[runs]
        self.z[runs, 9:11] = 0.0
        self.z[runs, 11 : 11 + self.n_s] = np.nan  # the servos: at rest at the first command
        self.z[runs, 11 + self.n_s :] = 0.0  # d_s

    @property
    def x(self) -> np.ndarray:
        """The state estimates (B, 9) (a view of z)."""
        return self.z[:, :9]

    @property
    def d(self) -> np.ndarray:
        """The input disturbance estimates (B, 2) [Phi, delta_e rad] (a view of z)."""
        return self.z[:, 9:11]

    @property
    def a(self) -> np.ndarray:
        """The actuator states (B, 4) of z (a view; (B, 0) without servos).

        [Phi, Phi_dot 1/s, delta_e rad, delta_e_dot rad/s]; NaN before a run's first
        prediction, which starts them at rest at its input.
        """
        return self.z[:, 11 : 11 + self.n_s]

    def sigma(self) -> np.ndarray:
        """Standard deviation of each state's error at the current estimates' (h, V).

        The square roots of the diagonal of sum_i tau_i(p) P_i, the vertices'
        steady-state a-posteriori covariances weighted as the gains are: the filter's
        own statement of its accuracy, not a propagated covariance nor a bound.

        Returns
        -------
        (B, 9) ndarray
            [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s]; (B, 0) without P.
        """
        if self.P is None:
            return np.zeros((len(self.x), 0))
        w = self.lpv.weights(self.x[:, H], self.x[:, V])
        return np.sqrt(np.einsum("br,rii->bi", w, self.P[:, :9, :9]))

    def model_vertices(self) -> np.ndarray:
        """The linear model of z at the LPV vertices, the one the gains were designed on.

        Returns
        -------
        (R, n_z, n_z) ndarray
            `filter_model` at the vertices.
        """
        A, B = np.asarray(self.lpv.A, float), np.asarray(self.lpv.B, float)
        return filter_model(A, B, self.servos, self.Ts, self.disturbance)

    def gains(self) -> np.ndarray:
        """The scheduled gains at the current estimates' (h, V).

        Returns
        -------
        (B, n_z, n_y) ndarray
            L(p) = sum_i tau_i(p) L_i of each run.
        """
        w = self.lpv.weights(self.x[:, H], self.x[:, V])  # (B, R)
        return np.einsum("br,rij->bij", w, self.L)

    def correct(self, y: np.ndarray) -> np.ndarray:
        """The corrected estimate x_k|k from the measurement y_k.

        Parameters
        ----------
        y : (B, n_y) ndarray
            Measurement of step k, in the order of the rows of C.

        Returns
        -------
        (B, 9) ndarray
            x_k|k [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s] (a copy).

        Raises
        ------
        ValueError
            If y does not have one column per row of C.
        """
        y = np.atleast_2d(np.asarray(y, float))
        if y.shape != (len(self.x), self.C.shape[0]):
            raise ValueError(f"estimator: y has shape {y.shape}, expected "
                             f"{(len(self.x), self.C.shape[0])}")  # fmt: skip
        # each run's (1, 9) @ (9, n_y) product, as a run alone computes it: a (B, 9) @
        # (9, n_y) product is one BLAS call whose bits depend on B
        innovation = y - np.matmul(self.x[:, None, :], self.C.T)[:, 0, :]
        self.z = self.z + np.einsum("bij,bj->bi", self.gains(), innovation)
        return self.x.copy()

    def predict(self, u: np.ndarray) -> None:
        """Predict z_k+1|k from z_k|k under the command of step k (d and d_s held).

        Parameters
        ----------
        u : (B, 2) ndarray
            Command u_k [Phi, delta_e rad]; u + d is saturated to the plant's limits.
        """
        u = np.atleast_2d(np.asarray(u, float)) + self.d
        u = np.ascontiguousarray(np.clip(u, self.limits.u_min, self.limits.u_max))
        x = np.ascontiguousarray(self.x)
        a = self.a.copy()
        if self.servos is None:
            x = rk4_cm(x, u, self.rec, self.Ts, self.n_sub)
        else:
            new = np.isnan(a[:, 0])
            a[new] = 0.0
            a[new, ::2] = u[new]
            if self._servo_lanes.shape[0] != len(u):
                self._servo_lanes = servo_lanes(self.servos, len(u))
            x, a, _ = rk4_cm_act(x, np.ascontiguousarray(a), u, self.rec, self._servo_lanes,
                              np.zeros(len(u), bool), self.Ts, self.n_sub)  # fmt: skip
        rest = self.z[:, 11 + self.n_s :]  # d_s (or nothing)
        if self.disturbance is not None:
            x[:, self.disturbance.row] += self.disturbance.sign * self.Ts * rest[:, 0]
        self.z = np.concatenate([x, self.d, a, rest], axis=1)


def estimate_history(estimator: GainScheduledKalman, y: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The filter over one recorded run, step by step: correct with y_k, predict with u_k.

    Parameters
    ----------
    estimator : GainScheduledKalman
        A filter of one run (B = 1), at its initial estimate.
    y : (N, n_y) ndarray
        Measurements of the run.
    u : (N, 2) ndarray
        Commands of the run [Phi, delta_e rad].

    Returns
    -------
    (N, 9) ndarray
        x_k|k of every step.
    """
    out = np.empty((len(y), 9))
    for k in range(len(y)):
        out[k] = estimator.correct(y[k][None])[0]
        estimator.predict(u[k][None])
    return out


def design_filter(arrays, vehicle, data: SensorData, measured: Sequence[str], Ts: float,
                  n_sub: int, x0, servos=None, disturbance: str = "none"
                  ) -> GainScheduledKalman:  # fmt: skip
    """The filter of a design: its LPV model, gains with Q_w from its bound w_max.

    Q_w = diag((w_max / 3)^2): the design's one-step disturbance bound (eq. 13-19) read
    as three standard deviations of a white process noise; Q_d = diag(D_INTENSITY^2 Ts)
    the input disturbance's random walk; R_v the sensors' white noise.

    Parameters
    ----------
    arrays : mapping
        The design's arrays: `A`, `B`, `h_grid`, `V_grid`, `W_h`, `W_V`, `w_max`, `Dx`,
        `Du` of the CM, n = 9 (a CM design's; an ECM design's CM part,
        `fahv.model.cascade.airframe_arrays`).
    vehicle : Vehicle
        Nominal parameters and input limits of the predictor.
    data : SensorData
        The sensors' noise and mode slopes.
    measured : sequence of str
        Channels of y, in order.
    Ts, n_sub : float, int
        Step [s] and RK4 steps per step.
    x0 : (B, 9) ndarray
        Initial estimates.
    servos : mapping, optional
        The plant's servo models by channel (`fahv.model.actuators.Servo`, the vehicle
        file's `actuators.second_order`): the predictor integrates them (the gains stay
        those of the airframe, whose ZOH model takes the servo's lag as process noise).
        None: ideal actuators.
    disturbance : str, optional
        Estimate this state disturbance d_s too (a name of
        `fahv.estimation.state_disturbance.STATE_DISTURBANCE_NAMES`; process noise its
        intensity^2 Ts); `none` (the default): no.

    Returns
    -------
    GainScheduledKalman
        The filter of B runs at x0.

    Raises
    ------
    ValueError
        If the design is not of the nine CM states, a vertex gain does not exist, or the
        disturbance is unknown.
    """
    A = np.asarray(arrays["A"], float)
    if A.shape[1:] != (9, 9):
        raise ValueError(f"estimator: the design's A_i are {A.shape[1:]}, not the CM's (9, 9)")
    lpv = PolytopicLPV(A, np.asarray(arrays["B"], float), *(np.asarray(arrays[k], float)
                       for k in ("h_grid", "V_grid", "W_h", "W_V")))  # fmt: skip
    B = np.asarray(arrays["B"], float)
    C = output_matrix(measured, data)
    Du = np.asarray(arrays["Du"], float)
    q = [(np.asarray(arrays["w_max"], float) / W_SIGMAS) ** 2, D_INTENSITY**2 * Ts]
    scale = [np.asarray(arrays["Dx"], float), Du]
    AP = None if servos is None else kernel_parameters(servos, vehicle.limits.u_min,
                                                       vehicle.limits.u_max)  # fmt: skip
    dist = state_disturbance(disturbance)
    Az = filter_model(A, B, AP, Ts, dist)
    if AP is not None:  # the servos' states: the model is exact, their noise only regularises
        s_scale = np.column_stack([Du, Du * AP[:, 1]]).ravel()  # [Phi, Phi_dot, de, de_dot]
        q.append((SERVO_NOISE * s_scale) ** 2)
        scale.append(s_scale)
    if dist is not None:
        q.append(np.array([dist.intensity**2 * Ts]))
        scale.append(np.array([dist.scale]))
    Cz = np.hstack([C, np.zeros((len(C), Az.shape[1] - 9))])
    L, P = kalman_gains(Az, Cz, np.diag(np.concatenate(q)),
                        measurement_covariance(measured, data), np.concatenate(scale))  # fmt: skip
    return GainScheduledKalman(lpv, L, C, vehicle.params, vehicle.limits, Ts, n_sub, x0, P, AP,
                               disturbance)  # fmt: skip
