"""The servos in the Kalman filter's linear model: the LPV vertices with the actuator states.

Each servo of the vehicle file is delta_ddot = omega_n^2 (u_c - delta) - 2 zeta omega_n
delta_dot (`fahv.model.actuators`), with state s_j = [delta; delta_dot]. Over one step of
a held command u_c the airframe sees the servo's position, not the command; the design's
vertices (eq. 12) are the ZOH model x+ = A_i x + B_i u, so the position is entered as its
average over the step (exact when A_c Ts is small against the servo's own dynamics):

    p_avg = (1 / Ts) int_0^Ts delta(t) dt = P_s s_k + P_u u_c,
    s_k+1 = Phi_s s_k + Gamma_s u_c,

from the matrix exponential of the servo (Van Loan's block form for the integrals). The
filter's state z = [x; d; s] (9 + 2 + 4) then follows

    x+ = A_i x + B_i (P_s s + P_u (u + d)),   d+ = d,   s+ = Phi_s s + Gamma_s (u + d),

the input disturbance d acting on the command before the servo, as a loss of
effectiveness does. The rate and position limits are left to the predictor's nonlinear
kernel (`fahv.plant.rk4.rk4_cm_act`).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

#: Actuator states of the kernel, per input [position, rate]: [Phi, Phi_dot, delta_e,
#: delta_e_dot].
N_SERVO = 4


def servo_step(AP: np.ndarray, Ts: float) -> tuple[np.ndarray, ...]:
    """The servos' discrete model over one held step (module docstring).

    Parameters
    ----------
    AP : (2, 6) ndarray
        Rows [zeta, omega_n rad/s, ...] of the two servos
        (`fahv.model.actuators.kernel_parameters`).
    Ts : float
        Step [s].

    Returns
    -------
    Phi_s : (4, 4) ndarray
    Gamma_s : (4, 2) ndarray
    P_s : (2, 4) ndarray
        The step's average position from the servo states.
    P_u : (2, 2) ndarray
        ... from the command.

    Examples
    --------
    A servo at rest at its command stays there, and its average position is the command:

    >>> AP = np.array([[0.9, 10.0, 0, 0, 0, 0], [0.7, 150.0, 0, 0, 0, 0]])
    >>> Phi, Gam, Ps, Pu = servo_step(AP, 0.02)
    >>> s = np.array([0.3, 0.0, 0.2, 0.0]); u = np.array([0.3, 0.2])
    >>> bool(np.allclose(Phi @ s + Gam @ u, s) and np.allclose(Ps @ s + Pu @ u, u))
    True
    """
    Phi, Gam = np.zeros((N_SERVO, N_SERVO)), np.zeros((N_SERVO, 2))
    Ps, Pu = np.zeros((2, N_SERVO)), np.zeros((2, 2))
    for j in range(2):
        zeta, wn = float(AP[j, 0]), float(AP[j, 1])
        A = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
        b = np.array([0.0, wn * wn])
        # expm([[A, I, 0], [0, 0, I], [0, 0, 0]] Ts): e^{A Ts}, int e^{A r}, int int e^{A r}
        M = np.zeros((6, 6))
        M[:2, :2], M[:2, 2:4], M[2:4, 4:6] = A, np.eye(2), np.eye(2)
        E = scipy.linalg.expm(M * Ts)
        G1, G2 = E[:2, 2:4], E[:2, 4:6]
        rows = slice(2 * j, 2 * j + 2)
        Phi[rows, rows], Gam[rows, j] = E[:2, :2], G1 @ b
        Ps[j, rows], Pu[j, j] = G1[0] / Ts, (G2 @ b)[0] / Ts
    return Phi, Gam, Ps, Pu


def with_servos(A: np.ndarray, B: np.ndarray, AP: np.ndarray, Ts: float) -> np.ndarray:
    """The vertices of z = [x; d; s] (module docstring).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, 2) ndarray
        The design's vertices (ZOH, eq. 12).
    AP : (2, 6) ndarray
        The servos (`servo_step`).
    Ts : float
        Step [s].

    Returns
    -------
    (R, n + 6, n + 6) ndarray
    """
    Phi, Gam, Ps, Pu = servo_step(AP, Ts)
    R, n, m = B.shape
    out = np.zeros((R, n + m + N_SERVO, n + m + N_SERVO))
    out[:, :n, :n] = A
    out[:, :n, n:n + m] = B @ Pu
    out[:, :n, n + m:] = B @ Ps
    out[:, n:n + m, n:n + m] = np.eye(m)
    out[:, n + m:, n:n + m] = Gam
    out[:, n + m:, n + m:] = Phi
    return out


def servo_plants(A, B, servos, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The airframe with its servos at plant points: the state [x; s], the command u.

    x+ = A x + B (P_s s + P_u u), s+ = Phi s + Gamma u
    (`servo_step`: the servos' exact discretisation over the held step, without their
    rate limits).

    Parameters
    ----------
    A : (P, n, n) ndarray
    B : (P, n, m) ndarray
    servos : (2, 6) ndarray
        `fahv.model.actuators.kernel_parameters` of the plant's servos.
    Ts : float
        Control period [s].

    Returns
    -------
    A_p : (P, n + 4, n + 4) ndarray
    B_p : (P, n + 4, m) ndarray
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    Phi, Gam, Ps, Pu = servo_step(servos, Ts)
    P, n, m = B.shape
    A_p = np.zeros((P, n + N_SERVO, n + N_SERVO))
    A_p[:, :n, :n], A_p[:, :n, n:], A_p[:, n:, n:] = A, B @ Ps, Phi
    return A_p, np.concatenate([B @ Pu, np.broadcast_to(Gam, (P,) + Gam.shape)], axis=1)
