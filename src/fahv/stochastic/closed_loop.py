"""A probabilistic tube of the loop on the estimate: the noise-driven deviation from the nominal.

On the estimate the tube law is u = v + F (x_hat - x_bar) (eq. 36 with the estimate in
place of the state). With t = x - x_bar the true state's deviation from the nominal (the
eight states after h, as in the tube) and e = z - z_hat the filter's a-posteriori error
(`fahv.stochastic.error_bound`), the LPV model (eq. 11-12) at model vertex i and gain
vertex j gives the joint system of xi = [t; e] (8 + 11,)

    t_k+1 = (A_i + B_i F) t_k - B_i F E e_k + w_k,
    e_k+1 = M_ij e_k + G_j g_k + N_j v_k+1,

with E = [0 I_8 0] the rows of z the tube reads. With the plant's servos between the
command and the airframe (the vehicle file's, in the filter's model too) the deviation
gains the servo states' deviation sigma = s - S v from the nominal command's rest
(S puts a constant command at each servo's position, rate 0; `fahv.estimation.
servo_model.servo_step`'s Phi_s, Gamma_s, P_s, P_u):

    t_k+1     = (A_i + B_i P_u F) t_k + B_i P_s sigma_k - B_i P_u F E e_k + w_k,
    sigma_k+1 = Phi_s sigma_k + Gamma_s F t_k - Gamma_s F E e_k + S (v_k - v_k+1),

the nominal command's step v_k+1 - v_k (held within the nominal's rate rows) left with
the model error. With the adjustable law (eq. 53-54) F is tau F. By linearity t is the
sum of three parts:

- the part driven by w under A_i + B_i F: the state-feedback tube, inside Z by the
  design's certificate (eq. 24-28);
- **the part driven by the sensor noise v** through the estimate, a Gaussian sequence:
  `joint_covariance` bounds its covariance at every pair (i, j) with one matrix Sigma
  (the LMI of `fahv.stochastic.error_bound.covariance_bound` on the joint system,
  re-checked exactly), so that at every step each state, input and input step stays
  within r sqrt(Sigma_ss) with the Gaussian probability of r; this is a probabilistic
  reachable set (Hewing and Zeilinger, "Stochastic model predictive control for linear
  systems using probabilistic reachable sets", CDC 2018) of the output-feedback loop;
- the part driven by the model error g through the estimate: `model_part` gives its
  exact worst case at the frozen vertices, a lower bound on any set that holds it.

What it leaves out: the nominal MPC's re-planning from the estimate (its disturbance
estimate moves x_bar by Ts / est_tau of the estimate's deviation per step), the notch,
the h column of A_i (as the tube does), and the nonlinear plant and predictor; the test
compares the bound with the nonlinear loop.
"""

from __future__ import annotations

from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
import scipy.linalg

from fahv.estimation.servo_model import N_SERVO, servo_plants
from fahv.sensors.measure import noise_bound
from fahv.stochastic.error_bound import ErrorSystem, covariance_bound, peak_to_peak

#: Tube states: the eight states after h (V, alpha, theta, q, eta_1, eta_1_dot, eta_2,
#: eta_2_dot), as the tube of the design.
TUBE = slice(1, 9)


@dataclass(frozen=True)
class JointSystem:
    """The joint system of xi = [t; sigma; e] at every pair of model vertex i and gain vertex j.

    n_xi = 8 + n_s + n_z: the tube states t, the plant's servo states sigma (n_s = 4, or
    0 with ideal actuators) and the filter's error e (n_z = 11, or 15 with servos).

    Attributes
    ----------
    system : ErrorSystem
        M: (R, R, n_xi, n_xi) the joint matrices; G: (R, n_xi, n_z) the map of g into e;
        N: (R, n_xi, n_y) the map of v into e; sigma: (n_xi,) the scales (the frozen
        vertices' largest stationary standard deviation of [t; sigma], the filter's of e).
    F8 : (2, 8) ndarray
        The tube gain on the eight states [Phi, rad per unit of each state] (tau F with
        the adjustable law).
    E : (8, n_z) ndarray
        The rows of z the tube reads.
    n_s : int
        Servo states of the plant in xi (0: ideal actuators).
    """

    system: ErrorSystem
    F8: np.ndarray
    E: np.ndarray
    n_s: int = 0

    def input_rows(self) -> np.ndarray:
        """The map of xi to the tube's command u - v = F (t - E e).

        Returns
        -------
        (2, n_xi) ndarray
            [F, 0, -F E], in Phi and rad per unit of each state of xi.
        """
        return np.hstack([self.F8, np.zeros((2, self.n_s)), -self.F8 @ self.E])

    def step_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The maps of (xi_k, v_k+1) to the input's step (u - v)_k+1 - (u - v)_k per pair.

        Returns
        -------
        H : (R, R, 2, n_xi) ndarray
            Rows of xi_k.
        J : (R, 2, n_y) ndarray
            Rows of v_k+1 (gain vertex j).
        """
        Fx = self.input_rows()
        H = np.einsum("ab,ijbc->ijac", Fx, self.system.M) - Fx[None, None]
        return H, np.einsum("ab,jbc->jac", Fx, self.system.N)


def _stationary_std(A: np.ndarray, Bw: np.ndarray) -> np.ndarray:
    """Largest stationary std of x+ = A_i x + Bw_i xi (unit covariance) over vertices (n,)."""
    out = [np.diag(scipy.linalg.solve_discrete_lyapunov(a, b @ b.T, method="bilinear"))
           for a, b in zip(A, Bw, strict=True)]  # fmt: skip
    return np.sqrt(np.max(out, axis=0))


def _deviation_loop(A8, B8, F8, servos, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The closed loop of [t; sigma] and its map of the tube's command (module docstring).

    Returns (R, 8 + n_s, 8 + n_s) A_cl and (R, 8 + n_s, 2) B_c: [t; sigma]+ = A_cl [t;
    sigma] + B_c F (-E e) at the pairs, with the airframe and servos of `servo_plants`;
    n_s = 4 with servos, else 0.
    """
    if servos is None:
        return A8 + B8 @ F8, B8
    A_p, B_p = servo_plants(A8, B8, np.asarray(servos, float), Ts)
    F_p = np.hstack([F8, np.zeros((F8.shape[0], A_p.shape[1] - 8))])  # the tube reads t only
    return A_p + B_p @ F_p, B_p


def joint_system(es: ErrorSystem, A: np.ndarray, B: np.ndarray, F: np.ndarray,
                 servos=None, Ts: float = 0.0) -> JointSystem:  # fmt: skip
    """The joint system of the tube law on a filter's estimate (module docstring).

    Parameters
    ----------
    es : ErrorSystem
        The filter's error system (`fahv.stochastic.error_bound.error_system`), 11 states,
        or 15 with the servos in the filter.
    A : (R, 9, 9) ndarray
        The design's LPV vertices A_i (eq. 12), deviation coordinates.
    B : (R, 9, 2) ndarray
        Their B_i.
    F : (2, 9) ndarray
        The tube gain (LMI 24; its h column is zero), times tau for the adjustable law
        (eq. 53-54).
    servos : (2, 6) ndarray, optional
        The plant's servos (`fahv.model.actuators.kernel_parameters`), the filter's own:
        the command reaches the airframe through them. None: ideal actuators.
    Ts : float
        Control period [s] (with servos).

    Returns
    -------
    JointSystem

    Raises
    ------
    ValueError
        If F reads h, the shapes do not match (the filter's states and the servos
        included), or a frozen vertex's closed loop of [t; sigma] is not stable (no
        stationary covariance).
    """
    A, B, F = (np.asarray(a, float) for a in (A, B, F))
    R, nz = es.n_vertices, es.M.shape[-1]
    n_s = 0 if servos is None else N_SERVO
    if A.shape != (R, 9, 9) or B.shape != (R, 9, 2) or F.shape != (2, 9):
        raise ValueError(f"joint_system: A {A.shape}, B {B.shape}, F {F.shape} do not match "
                         f"{R} vertices of the CM")  # fmt: skip
    if np.any(F[:, 0] != 0.0):
        raise ValueError("joint_system: F reads h; the tube's eight states are after h")
    if nz - n_s not in (11, 12):  # [x; d; s], and d_gamma if the filter has it
        raise ValueError(f"joint_system: a filter of {nz} states with "
                         f"{'the' if n_s else 'no'} servos in the plant; the filter's model "
                         "must have the plant's actuators")  # fmt: skip
    A8, B8, F8 = A[:, TUBE, TUBE], B[:, TUBE], F[:, TUBE]
    E = np.eye(nz)[TUBE]
    Acl, Bc = _deviation_loop(A8, B8, F8, servos, Ts)
    rho = max(np.abs(np.linalg.eigvals(Acl)).max(axis=1))
    if not rho < 1.0:
        raise ValueError(f"joint_system: the loop on the estimate is not stable at a vertex "
                         f"(rho {rho:.6f})")  # fmt: skip
    nt = 8 + n_s
    n = nt + nz
    M = np.zeros((R, R, n, n))
    M[:, :, :nt, :nt] = Acl[:, None]
    M[:, :, :nt, nt:] = -(Bc @ F8 @ E)[:, None]
    M[:, :, nt:, nt:] = es.M
    G = np.concatenate([np.zeros((R, nt, es.G.shape[2])), es.G], axis=1)
    N = np.concatenate([np.zeros((R, nt, es.N.shape[2])), es.N], axis=1)
    # scale of [t; sigma]: the frozen vertices' response to the estimation error at its scale
    scale_t = _stationary_std(Acl, Bc @ F8 @ E * es.sigma[None, None, :])
    return JointSystem(ErrorSystem(M, G, N, np.concatenate([scale_t, es.sigma])), F8, E, n_s)


@dataclass(frozen=True)
class ProbabilisticTube:
    """The noise-driven deviation's bounds (`probabilistic_tube`).

    Attributes
    ----------
    Sigma : (n_xi, n_xi) ndarray
        Common covariance bound of xi = [t; sigma; e] at every vertex pair, re-checked
        exactly (`JointSystem`).
    min_eig : float
        Its exact re-check: the smallest eigenvalue of Sigma - A Sigma A' - N R_v N'
        over the pairs, scaled coordinates (>= 0).
    pairs_held : int
        Pairs the last LMI solve held.
    std_t : (8,) ndarray
        sqrt(diag Sigma) of t [the tube states' units].
    std_u : (2,) ndarray
        Standard deviation bound of the tube's input u - v [Phi, rad].
    std_step : (2,) ndarray
        That of its step from one step to the next [Phi, rad per step].
    model_t : (8,) ndarray
        Frozen-vertex worst case of t by the model error through the estimate (`model_part`).
    pairs : tuple of (int, int)
        The pairs the last solve held (`CovarianceBound.pairs`: a `start` for one solve).
    """

    Sigma: np.ndarray
    min_eig: float
    pairs_held: int
    std_t: np.ndarray
    std_u: np.ndarray
    std_step: np.ndarray
    model_t: np.ndarray
    pairs: tuple = ()


def model_part(js: JointSystem, g_max: np.ndarray) -> np.ndarray:
    """The exact worst case of t at the frozen vertices, g within g_max, v = 0.

    Parameters
    ----------
    js : JointSystem
    g_max : (n_z,) array_like
        Bounds of g = [w (9); w_d (2)] (and zeros for the filter's servo states), in the
        states' units.

    Returns
    -------
    (8,) ndarray
        max over the frozen vertices of the worst |t_s|
        (`fahv.stochastic.error_bound.peak_to_peak`).
    """
    es = js.system
    xi = np.concatenate([np.asarray(g_max, float), np.zeros(es.N.shape[2])])
    return peak_to_peak(es, xi, states=range(8)).max(axis=0)


def probabilistic_tube(js: JointSystem, R_v: np.ndarray, g_max: np.ndarray,
                       start=None) -> ProbabilisticTube:  # fmt: skip
    """Bound the noise-driven deviation of the loop on the estimate (module docstring).

    Parameters
    ----------
    js : JointSystem
    R_v : (n_y, n_y) ndarray
        The sensors' white-noise covariance.
    g_max : (n_z,) array_like
        Bounds of the model error g for `model_part`.
    start : sequence of (int, int), optional
        The covariance bound's first pairs (`covariance_bound`'s `start`).

    Returns
    -------
    ProbabilisticTube

    Raises
    ------
    DesignError
        If the covariance LMI is infeasible or its exact re-check fails.
    ValueError
        If a frozen vertex of the joint system is not stable (`model_part`).

    """
    cov = covariance_bound(js.system, R_v, start=start)
    return ProbabilisticTube(cov.S, cov.min_eig, cov.pairs_held,
                             *standard_deviations(js, cov.S, R_v), model_part(js, g_max),
                             cov.pairs)  # fmt: skip


def standard_deviations(js: JointSystem, S: np.ndarray,
                        R_v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The standard deviation bounds a covariance bound S of xi gives.

    Parameters
    ----------
    js : JointSystem
    S : (n_xi, n_xi) ndarray
        A covariance bound of xi at every pair (`covariance_bound`'s S).
    R_v : (n_y, n_y) ndarray
        The sensors' white-noise covariance.

    Returns
    -------
    std_t : (8,) ndarray
        sqrt(diag S) of t [the tube states' units].
    std_u : (2,) ndarray
        Of the tube's input u - v [Phi, rad].
    std_step : (2,) ndarray
        Of its step from one step to the next, the largest over the pairs [Phi, rad per
        step].
    """
    Fx = js.input_rows()
    H, J = js.step_rows()
    step_var = (np.einsum("ijab,bc,ijac->ija", H, S, H)
                + np.einsum("jab,bc,jac->ja", J, np.asarray(R_v, float), J)[None])  # fmt: skip
    return (np.sqrt(np.diag(S)[:8]), np.sqrt(np.einsum("ab,bc,ac->a", Fx, S, Fx)),
            np.sqrt(step_var.max(axis=(0, 1))))  # fmt: skip


def loop_tube(es: ErrorSystem, flt, arrays, tau: float, R_v: np.ndarray,
              start=None) -> tuple[JointSystem, ProbabilisticTube]:  # fmt: skip
    """The probabilistic tube of a design's tube law tau F on a filter's estimate.

    Parameters
    ----------
    es : ErrorSystem
        The filter's error system (`fahv.stochastic.error_bound.error_system` of `flt`).
    flt : fahv.estimation.kalman.GainScheduledKalman
        The filter; its servos, if any, are the plant's (`joint_system`).
    arrays : mapping
        The design's arrays: `A` (R, 9, 9), `B` (R, 9, 2), `F` (2, 9), `w_max` (9,).
    tau : float
        The adjustable factor the law runs with (eq. 53-54; `fahv.spec.schema.law_tau`).
    R_v : (n_y, n_y) ndarray
        The sensors' white-noise covariance.
    start : sequence of (int, int), optional
        The covariance bound's first pairs (`covariance_bound`'s `start`).

    Returns
    -------
    (JointSystem, ProbabilisticTube)
        The model error's bound g_max is the design's W on the nine states, zero on the
        input disturbance and the servo states.

    Raises
    ------
    ValueError, DesignError
        As `joint_system` and `probabilistic_tube`.
    """
    js = joint_system(es, arrays["A"], arrays["B"], tau * np.asarray(arrays["F"], float),
                      flt.servos, flt.Ts)  # fmt: skip
    g_max = np.zeros(len(es.sigma))
    g_max[:9] = arrays["w_max"]
    return js, probabilistic_tube(js, R_v, g_max, start)


def radii(p: float, steps: int) -> tuple[float, float]:
    """Gaussian radii in standard deviations: one step, and a whole run (union bound).

    Parameters
    ----------
    p : float
        Probability, 0 < p < 1.
    steps : int
        Steps of the run.

    Returns
    -------
    (float, float)
        r with P(|n| <= r sigma) = p for one step, and with P(|n_k| <= r sigma for all
        steps) >= p (`fahv.sensors.measure.noise_bound`).

    Examples
    --------
    >>> [round(r, 3) for r in radii(0.99, 15000)]
    [2.576, 4.971]
    """
    return -NormalDist().inv_cdf((1.0 - p) / 2.0), noise_bound(1.0, steps, p)


def attitude_chance(pt: ProbabilisticTube, rows: np.ndarray, support: np.ndarray,
                    r: float, requirement: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The attitude the loop on the estimate reaches with the noise part at radius r.

    |alpha - alpha_r| <= nominal row + support of Z (the state-feedback tube of W) +
    r std_t (the noise-driven part), and the same for theta (`attitude_bounds` of
    `fahv.control.mpc.attitude` with the noise part added).

    Parameters
    ----------
    pt : ProbabilisticTube
    rows : (2,) array_like
        The nominal QP's attitude rows [rad] (the design's `att_max`).
    support : (2,) array_like
        Support of Z in alpha and theta [rad] (`att_support`).
    r : float
        Radius in standard deviations (`radii`).
    requirement : float
        The attitude requirement [rad].

    Returns
    -------
    reach : (2,) ndarray
        rows + support + r std_t of alpha and theta [rad].
    rows_needed : (2,) ndarray
        The rows with which reach equals the requirement [rad] (<= 0: none).

    Examples
    --------
    >>> pt = ProbabilisticTube(np.eye(19), 0.0, 1, np.full(8, 0.01), np.zeros(2),
    ...                        np.zeros(2), np.zeros(8))
    >>> [np.round(v, 3).tolist() for v in attitude_chance(pt, [0.4, 0.4], [0.1, 0.05], 5.0, 0.5)]
    [[0.55, 0.5], [0.35, 0.4]]
    """
    noise = r * pt.std_t[1:3]
    rows, support = np.asarray(rows, float), np.asarray(support, float)
    return rows + support + noise, requirement - support - noise
