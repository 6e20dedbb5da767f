"""Longitudinal models as functions x_dot = f(x, u): CM (eq. 1-3), DM (eq. 4), ECM (eq. 40)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.model.vehicle import (
    ALPHA,
    DELTA_E,
    ETA1,
    ETA1_DOT,
    ETA2,
    ETA2_DOT,
    IQ,
    PHI,
    THETA,
    H,
    V,
    Vehicle,
    VehicleParams,
)


def density(h, vp: VehicleParams):
    """Air density rho(h) [slug/ft^3], eq. (3) with the exponent (h - h_0)/h_s.

    The paper prints `exp(-h-h_s/h_0)`; the exponential model of Parker et al.
    2007 is `rho_0 exp(-(h - h_0)/h_s)` (docs/reference/vehicle_data.md).

    Parameters
    ----------
    h : float or ndarray
        Altitude [ft], real or complex (complex-step differentiation).
    vp : VehicleParams
        Uses `rho_0` [slug/ft^3], `h_0` [ft] and `h_s` [ft].

    Returns
    -------
    float or ndarray
        Density [slug/ft^3], of the shape of `h`.

    Examples
    --------
    >>> from fahv.model.vehicle import load_vehicle
    >>> vp = load_vehicle().params
    >>> round(float(density(vp.h_0, vp) / vp.rho_0), 12)
    1.0
    >>> round(float(density(vp.h_0 + vp.h_s, vp) / vp.rho_0), 6)  # exp(-1)
    0.367879
    """
    return vp.rho_0 * np.exp(-(h - vp.h_0) / vp.h_s)


def forces(x, u, vp: VehicleParams):
    """Lift, drag, thrust, pitching moment and generalized forces, eq. (2)-(3).

    Parameters
    ----------
    x : (>=5,) array_like, real or complex
        State; only h, V, alpha (indices 0-2) are used: in the paper's CM the
        flexible states do not enter L, D, T, M.
    u : (2,) array_like
        [Phi, delta_e] (delta_e in rad).
    vp : VehicleParams

    Returns
    -------
    L, D, T, M, N1, N2
        Forces [lbf/ft], moment [lbf ft/ft], generalized forces.

    Notes
    -----
    M = z_T T + q_bar S c_bar (C_M,alpha(alpha) + c_e delta_e), as in Parker et
    al. 2007 (the paper's eq. (2) drops the factor T after z_T).

    Examples
    --------
    In level flight at trim, lift and the thrust's normal part carry the weight:

    >>> from fahv.model.trim import trim
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> tp = trim(v, 85500.0, 7900.0, "cm")
    >>> L, D, T, M, N1, N2 = forces(tp.x_r, tp.u_r, v.params)
    >>> round(float((L + T * np.sin(tp.alpha)) / (v.params.m * v.params.g)), 9)
    1.0
    """
    h, Vel, alpha = x[H], x[V], x[ALPHA]
    Phi, de = u[PHI], u[DELTA_E]
    qbar = 0.5 * density(h, vp) * Vel * Vel
    C_L = vp.C_L_alpha * alpha + vp.C_L_de * de + vp.C_L_0
    C_D = (
        vp.C_D_alpha2 * alpha * alpha
        + vp.C_D_alpha * alpha
        + vp.C_D_de2 * de * de
        + vp.C_D_de * de
        + vp.C_D_0
    )
    C_M = vp.C_M_alpha2 * alpha * alpha + vp.C_M_alpha * alpha + vp.C_M_0 + vp.c_e * de
    C_T3 = vp.beta_1 * Phi + vp.beta_2
    C_T2 = vp.beta_3 * Phi + vp.beta_4
    C_T1 = vp.beta_5 * Phi + vp.beta_6
    C_T0 = vp.beta_7 * Phi + vp.beta_8
    L = qbar * vp.S * C_L
    D = qbar * vp.S * C_D
    T = ((C_T3 * alpha + C_T2) * alpha + C_T1) * alpha + C_T0
    M = vp.z_T * T + qbar * vp.S * vp.c_bar * C_M
    N1 = vp.N1_alpha2 * alpha * alpha + vp.N1_alpha * alpha + vp.N1_0
    N2 = vp.N2_alpha2 * alpha * alpha + vp.N2_alpha * alpha + vp.N2_de * de + vp.N2_0
    return L, D, T, M, N1, N2


def _rigid_kinematics(x, q, T, D, L, vp: VehicleParams):
    """h_dot, V_dot, alpha_dot, theta_dot of eq. (1)/(4) for a given pitch rate q."""
    Vel, alpha, theta = x[V], x[ALPHA], x[THETA]
    gamma = theta - alpha
    h_dot = Vel * np.sin(gamma)
    V_dot = (T * np.cos(alpha) - D) / vp.m - vp.g * np.sin(gamma)
    alpha_dot = (-T * np.sin(alpha) - L) / (vp.m * Vel) + q + vp.g / Vel * np.cos(gamma)
    return h_dot, V_dot, alpha_dot, q


def cm_rhs(x, u, vp: VehicleParams) -> np.ndarray:
    """Coupling model CM, eq. (1)-(3): x_dot = f(x, u).

    Parameters
    ----------
    x : (9,) array_like
        [h ft, V ft/s, alpha rad, theta rad, q rad/s, eta_1, eta_1_dot, eta_2, eta_2_dot].
    u : (2,) array_like
        [Phi -, delta_e rad].
    vp : VehicleParams

    Returns
    -------
    x_dot : (9,) ndarray
        Same dtype kind as the inputs (complex inputs give a complex result).

    Notes
    -----
    The two coupled flexible equations of eq. (1) are solved exactly as one linear
    system in (eta_1_ddot, eta_2_ddot):

        [k_1             psi_1 psi_2/I] [eta_1_ddot]   [r_1]
        [psi_1 psi_2/I   k_2          ] [eta_2_ddot] = [r_2],
        r_i = -2 zeta_i omega_i eta_i_dot - omega_i^2 eta_i + N_i - psi_i M / I_yy,

    with k_i = 1 + psi_i^2 / I_yy, then q_dot = (M + psi_1 eta_1_ddot +
    psi_2 eta_2_ddot) / I_yy.

    Examples
    --------
    At a trim every derivative vanishes (to the trim's scaled tolerance):

    >>> from fahv.model.trim import trim
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> tp = trim(v, 85500.0, 7900.0, "cm")
    >>> x_dot = cm_rhs(tp.x_r, tp.u_r, v.params)
    >>> x_dot.shape, bool(np.max(np.abs(x_dot / v.state_scale)) < 1e-8)
    ((9,), True)
    """
    L, D, T, M, N1, N2 = forces(x, u, vp)
    h_dot, V_dot, alpha_dot, theta_dot = _rigid_kinematics(x, x[IQ], T, D, L, vp)
    eta_dd1, eta_dd2 = _flexible_accelerations(x, M, N1, N2, vp)
    q_dot = (M + vp.psi_1 * eta_dd1 + vp.psi_2 * eta_dd2) / vp.I_yy
    return np.array(
        [h_dot, V_dot, alpha_dot, theta_dot, q_dot, x[ETA1_DOT], eta_dd1, x[ETA2_DOT], eta_dd2]
    )


def _flexible_accelerations(x, M, N1, N2, vp: VehicleParams):
    """Solve the coupled eta_ddot equations of eq. (1) (2x2 linear system, Cramer)."""
    k1 = 1.0 + vp.psi_1**2 / vp.I_yy
    k2 = 1.0 + vp.psi_2**2 / vp.I_yy
    c = vp.psi_1 * vp.psi_2 / vp.I_yy
    r1 = (
        -2.0 * vp.zeta_1 * vp.omega_1 * x[ETA1_DOT]
        - vp.omega_1**2 * x[ETA1]
        + N1
        - vp.psi_1 * M / vp.I_yy
    )
    r2 = (
        -2.0 * vp.zeta_2 * vp.omega_2 * x[ETA2_DOT]
        - vp.omega_2**2 * x[ETA2]
        + N2
        - vp.psi_2 * M / vp.I_yy
    )
    det = k1 * k2 - c * c
    return (k2 * r1 - c * r2) / det, (k1 * r2 - c * r1) / det


def dm_rhs(x, u, vp: VehicleParams) -> np.ndarray:
    """Decoupled model DM, eq. (4): CM without the inertial coupling psi_i.

    Shapes and units as `cm_rhs`. q_dot = M / I_yy and
    eta_i_ddot = -2 zeta_i omega_i eta_i_dot - omega_i^2 eta_i + N_i.

    Parameters
    ----------
    x : (9,) array_like
        [h ft, V ft/s, alpha rad, theta rad, q rad/s, eta_1, eta_1_dot, eta_2, eta_2_dot].
    u : (2,) array_like
        [Phi -, delta_e rad].
    vp : VehicleParams
        The vehicle's parameters (psi_i unused).

    Returns
    -------
    x_dot : (9,) ndarray
        Same dtype kind as the inputs (complex inputs give a complex result).

    Examples
    --------
    CM and DM share their trim (M = 0 and eta_ddot = 0 there):

    >>> from fahv.model.trim import trim
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> tp = trim(v, 85500.0, 7900.0, "dm")
    >>> bool(np.allclose(dm_rhs(tp.x_r, tp.u_r, v.params), 0.0, atol=1e-9))
    True
    """
    L, D, T, M, N1, N2 = forces(x, u, vp)
    h_dot, V_dot, alpha_dot, theta_dot = _rigid_kinematics(x, x[IQ], T, D, L, vp)
    eta_dd1 = -2.0 * vp.zeta_1 * vp.omega_1 * x[ETA1_DOT] - vp.omega_1**2 * x[ETA1] + N1
    eta_dd2 = -2.0 * vp.zeta_2 * vp.omega_2 * x[ETA2_DOT] - vp.omega_2**2 * x[ETA2] + N2
    return np.array(
        [
            h_dot,
            V_dot,
            alpha_dot,
            theta_dot,
            M / vp.I_yy,
            x[ETA1_DOT],
            eta_dd1,
            x[ETA2_DOT],
            eta_dd2,
        ]
    )


def ecm_rhs(x, u, vp: VehicleParams, A_q, B_q, C_q, D_q) -> np.ndarray:
    """Extended coupling model ECM, eq. (39)-(40): CM in series with the notch filter.

    Parameters
    ----------
    x : (11,) array_like
        [h, V, alpha, theta, q', eta_1, eta_1_dot, eta_2, eta_2_dot, x_q1, x_q2],
        q' the filtered pitch rate [rad/s] (eq. 43).
    u : (2,) array_like
        [Phi, delta_e rad].
    vp : VehicleParams
    A_q : (2, 2) array_like
    B_q : (2,) array_like
    C_q : (2,) array_like
    D_q : float
        Notch filter state space of eq. (39); D_q must be non-zero (it is 1 for
        the notch of eq. (38) with equal leading coefficients).

    Returns
    -------
    x_dot : (11,) ndarray

    Notes
    -----
    Eq. (40) writes alpha_dot and theta_dot with q' in place of q. That changes
    the physics (the body does not rotate at the filtered rate). Here the true
    pitch rate is recovered from the filter output equation (39),
    q = (q' - C_q x_q) / D_q, so that the ECM is exactly the CM in series with
    the filter, which is the system the controller actually acts on. The
    derivative of q' is eq. (40): q'_dot = C_q x_q_dot + D_q q_dot.
    """
    x_q = x[9:11]
    q = (x[IQ] - (C_q[0] * x_q[0] + C_q[1] * x_q[1])) / D_q
    x_cm = np.concatenate([x[:4], [q], x[5:9]])
    f = cm_rhs(x_cm, u, vp)
    xq_dot = np.array(
        [
            A_q[0][0] * x_q[0] + A_q[0][1] * x_q[1] + B_q[0] * q,
            A_q[1][0] * x_q[0] + A_q[1][1] * x_q[1] + B_q[1] * q,
        ]
    )
    qp_dot = C_q[0] * xq_dot[0] + C_q[1] * xq_dot[1] + D_q * f[IQ]
    return np.concatenate([f[:4], [qp_dot], f[5:9], xq_dot])


#: The functions of the CM right-hand side, in call order: compiled for the plant's batch
#: kernel (`fahv.plant.rk4`), so keep them free of Python-only constructs.
JITABLE = (density, forces, _rigid_kinematics, _flexible_accelerations, cm_rhs)

MODEL_KINDS = ("dm", "cm", "ecm")


@dataclass(frozen=True)
class Model:
    """One of the longitudinal models as a function x_dot = f(x, u).

    Attributes
    ----------
    kind : {"dm", "cm", "ecm"}
        Decoupled model (eq. 4), coupling model (eq. 1-3) or extended coupling
        model with notch states (eq. 40).
    params : VehicleParams
    notch_ss : tuple or None
        (A_q (2, 2), B_q (2,), C_q (2,), D_q) of eq. (39); required for "ecm".

    Raises
    ------
    ValueError
        On an unknown kind, or "ecm" without a notch filter or with D_q = 0.
    """

    kind: str
    params: VehicleParams
    notch_ss: tuple | None = None

    def __post_init__(self) -> None:
        if self.kind not in MODEL_KINDS:
            raise ValueError(f"model kind must be one of {MODEL_KINDS}, got {self.kind!r}")
        if self.kind == "ecm":
            if self.notch_ss is None:
                raise ValueError("model kind 'ecm' needs the notch filter state space (eq. 39)")
            if self.notch_ss[3] == 0.0:
                raise ValueError("ECM needs a notch filter with D_q != 0 (q' = C_q x_q + D_q q)")

    @property
    def n_x(self) -> int:
        """Number of states: 9 (DM, CM) or 11 (ECM)."""
        return 11 if self.kind == "ecm" else 9

    def f(self, x, u) -> np.ndarray:
        """Evaluate x_dot = f(x, u); units as the module docstring.

        Parameters
        ----------
        x : (n_x,) array_like
            State (9 for CM and DM, 11 for ECM), real or complex.
        u : (2,) array_like
            Input [Phi -, delta_e rad].

        Returns
        -------
        (n_x,) ndarray
            The state derivative x_dot.
        """
        if self.kind == "cm":
            return cm_rhs(x, u, self.params)
        if self.kind == "dm":
            return dm_rhs(x, u, self.params)
        return ecm_rhs(x, u, self.params, *self.notch_ss)

    def state_scale(self, vehicle: Vehicle, notch=None) -> np.ndarray:
        """Scale vector of the states, shape (n_x,), from the vehicle file (and notch).

        Parameters
        ----------
        vehicle : Vehicle
            Its `state_scale` (9,) [state units].
        notch : NotchFilter, optional
            Required for "ecm": the scales of the filter's two states.

        Returns
        -------
        (n_x,) ndarray
            Typical magnitudes of the states [state units].

        Raises
        ------
        ValueError
            For "ecm" without `notch`.
        """
        if self.kind != "ecm":
            return vehicle.state_scale.copy()
        if notch is None:
            raise ValueError("ECM state scaling needs the NotchFilter")
        return np.concatenate([vehicle.state_scale, notch.state_scale(vehicle.state_scale[IQ])])


def make_model(kind: str, vehicle: Vehicle | VehicleParams, notch=None) -> Model:
    """Build a `Model` of the given kind.

    Parameters
    ----------
    kind : {"dm", "cm", "ecm"}
    vehicle : Vehicle or VehicleParams
    notch : fahv.model.notch.NotchFilter, optional
        Required for "ecm".

    Returns
    -------
    Model
        The model, with the notch's state space of eq. (39) for "ecm".

    Raises
    ------
    ValueError
        On an unknown kind, or "ecm" without a notch filter.

    Examples
    --------
    >>> from fahv.model.notch import NotchFilter
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> make_model("cm", v).n_x, make_model("ecm", v, NotchFilter(19.05, 0.02, 19.05, 0.1)).n_x
    (9, 11)
    >>> make_model("ecm", v)
    Traceback (most recent call last):
        ...
    ValueError: model kind 'ecm' needs the notch filter state space (eq. 39)
    """
    params = vehicle.params if isinstance(vehicle, Vehicle) else vehicle
    return Model(kind, params, notch.ss() if (kind == "ecm" and notch is not None) else None)
