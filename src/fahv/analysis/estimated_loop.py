"""The loop margins of the tube law on the Kalman estimate: u = v + F x_hat.

With the state fed back exactly, the tube loop's margins at the elevator are those of a
state-feedback law (`fahv.analysis.margins`). On the loop that can be flown the law acts
on the estimate of the gain-scheduled Kalman filter (`fahv.estimation.kalman`), which
sees the airframe only through the sensors, and a state-feedback law's margins need not
survive an estimator between them and the plant (Doyle 1978, "Guaranteed margins for LQG
regulators", IEEE TAC 23(4): there are none). This module forms that loop at frozen
plant points and breaks it at the elevator input.

Linearised, with the constraints inactive (the nominal part an internal model driven by
the reference, as in `fahv.analysis.margins`), at one point: the plant x+ = A x + B u,
the sensors y = C x; the filter's a-priori state z = [x_hat; d_hat] (11,), corrected by
z_post = z + L (y - C_z z) and predicted by z+ = A_z z_post + B_z u_c with the command
u_c the law computed (the filter does not see what reaches the surface); the notch on the
estimate's q (eq. 38, chi); the law u_c = K [x_hat_post; chi] (`fahv.analysis.margins`'s
gain on [x; chi]). The loop's state is xi = [x; z; chi]. Broken at the elevator input
(the throttle's loop closed), L(z) = -(delta_e the law commands) / (delta_e injected).

A filter with the servos' states (`estimator.actuators: second_order`) flies the
airframe with the same servos, linear (`servo_plants`: their rate limits are not in a
linear loop), and the loop is broken at the elevator servo's command. Leaves out: the
disturbance estimate's path through the nominal MPC, and the scheduling of L on the
estimate (the gains of the point's own vertex, or of the design point's weights).
"""

from __future__ import annotations

import numpy as np

import control
from fahv.analysis.margins import (
    frequency_grid,
    law_gain,
    loop_margins,
    notch_parts,
    spectral_radius,
    worst_case,
)
from fahv.estimation.kalman import filter_model
from fahv.estimation.servo_model import servo_plants, servo_step
from fahv.model.notch import NotchFilter
from fahv.model.vehicle import DELTA_E, IQ, PHI


def estimated_loop(A, B, F, notch: NotchFilter | None, Ts: float, A_z, B_z, L, C,
                   iq: int = IQ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The loop on the estimate broken at the elevator input, at every point.

    Parameters
    ----------
    A : (P, n_p, n_p) ndarray
    B : (P, n_p, m) ndarray
        Plant points (deviation coordinates, one control period): the airframe's n = 9
        states first, then any actuator states (`servo_plants`).
    F : (m, n) ndarray
        Ancillary gain (tau F for the adjustable law) on the airframe's states.
    notch : fahv.model.notch.NotchFilter or None
        Filter on the estimate's q (None: q_hat fed back as estimated).
    Ts : float
        Control period [s].
    A_z : (P, n_z, n_z) ndarray
    B_z : (P, n_z, m) ndarray
        The filter's model at each point, z = [x; d; ...] (`filter_models`).
    L : (P, n_z, n_y) ndarray
        The filter's gain at each point.
    C : (n_y, n) ndarray
        The sensors' output matrix on the airframe's states
        (`fahv.estimation.kalman.output_matrix`).
    iq : int
        Index of q in x.

    Returns
    -------
    A_L : (P, N, N) ndarray
    B_L : (P, N, 1) ndarray
    C_L : (P, 1, N) ndarray
        N = n_p + n_z + k (k = 2 with the notch); negative-feedback convention: w = -y
        closes the loop (`estimated_closed_loop`).

    Raises
    ------
    ValueError
        If the shapes do not agree, or the notch cannot be sampled at Ts.
    """
    A, B, A_z, B_z, L = (np.asarray(v, float) for v in (A, B, A_z, B_z, L))
    C, F = np.asarray(C, float), np.asarray(F, float)
    P, n_p, m = B.shape
    n, n_z = F.shape[1], A_z.shape[1]
    if A.shape != (P, n_p, n_p) or A_z.shape != (P, n_z, n_z) or B_z.shape != (P, n_z, m) \
            or L.shape != (P, n_z, C.shape[0]) or C.shape[1] != n or F.shape[0] != m \
            or n_p < n or n_z < n:
        raise ValueError(f"estimated_loop: shapes A {A.shape}, B {B.shape}, A_z {A_z.shape}, "
                         f"B_z {B_z.shape}, L {L.shape}, C {C.shape}, F {F.shape} disagree")
    K, _ = law_gain(F, notch, Ts, n, iq)
    A_d, b, _, _ = notch_parts(notch, Ts)
    k = len(b)
    C_p = np.hstack([C, np.zeros((len(C), n_p - n))])  # y of the plant's state
    C_z = np.hstack([C, np.zeros((len(C), n_z - n))])  # ... of the filter's
    G = np.eye(n_z)[None] - L @ C_z  # z_post = G z + L C_p x
    LC = L @ C_p
    # the estimate x_hat_post = z_post[:n], and u_c = K_all xi on xi = [x; z; chi]
    Gx, Gz = LC[:, :n], G[:, :n]
    K_all = np.concatenate([K[None, :, :n] @ Gx, K[None, :, :n] @ Gz,
                            np.broadcast_to(K[:, n:], (P, m, k))], axis=2)  # fmt: skip
    N = n_p + n_z + k
    A_L = np.zeros((P, N, N))
    A_L[:, :n_p, :n_p] = A
    A_L[:, :n_p] += B[:, :, PHI : PHI + 1] @ K_all[:, PHI : PHI + 1]  # the throttle's loop
    A_L[:, n_p : n_p + n_z, :n_p] = A_z @ LC
    A_L[:, n_p : n_p + n_z, n_p : n_p + n_z] = A_z @ G
    A_L[:, n_p : n_p + n_z] += B_z @ K_all  # the filter predicts with the commanded input
    A_L[:, n_p + n_z :, :n_p] = b[None, :, None] * Gx[:, None, iq, :]  # chi+ = A_d chi + b q_hat
    A_L[:, n_p + n_z :, n_p : n_p + n_z] = b[None, :, None] * Gz[:, None, iq, :]
    A_L[:, n_p + n_z :, n_p + n_z :] = A_d
    B_L = np.zeros((P, N, 1))
    B_L[:, :n_p, 0] = B[:, :, DELTA_E]
    C_L = -K_all[:, DELTA_E : DELTA_E + 1]
    return A_L, B_L, np.ascontiguousarray(C_L)


def filter_models(A, B, servos=None, Ts: float = 0.0,
                  disturbance=None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The filter's linear model at plant points: (A_z, B_z), z = [x; d] or [x; d; s].

    Parameters
    ----------
    A : (P, n, n) ndarray
    B : (P, n, m) ndarray
        The airframe at each point.
    servos : (2, 6) ndarray, optional
        The filter's servos (`GainScheduledKalman.servos`); None: ideal actuators.
    Ts : float
        Control period [s] (with servos or a state disturbance).
    disturbance : StateDisturbance, optional
        z ends with this state disturbance (`GainScheduledKalman.disturbance`,
        `fahv.estimation.kalman.with_state_disturbance`); None: none.

    Returns
    -------
    A_z : (P, n_z, n_z) ndarray
        `fahv.estimation.kalman.filter_model`.
    B_z : (P, n_z, m) ndarray
        The command's column: [B; 0], or with servos through them ([B P_u; 0; Gamma]);
        0 on d_s.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    P, n, m = B.shape
    if servos is None:
        B_z = np.concatenate([B, np.zeros((P, m, m))], axis=1)
    else:
        _, Gam, _, Pu = servo_step(servos, Ts)
        B_z = np.concatenate([B @ Pu, np.zeros((P, m, m)),
                              np.broadcast_to(Gam, (P,) + Gam.shape)], axis=1)  # fmt: skip
    if disturbance is not None:
        B_z = np.concatenate([B_z, np.zeros((P, 1, m))], axis=1)
    return filter_model(A, B, servos, Ts, disturbance), B_z


def estimated_closed_loop(A_L, B_L, C_L) -> np.ndarray:
    """The closed loop of `estimated_loop`: A_L - B_L C_L (P, N, N).

    Parameters
    ----------
    A_L : (P, N, N) array_like
    B_L : (P, N, 1) array_like
    C_L : (P, 1, N) array_like
        `estimated_loop`'s output (negative-feedback convention).

    Returns
    -------
    (P, N, N) ndarray
        Its eigenvalues are those of the state-feedback loop and of the filter's error at
        a matched point (the separation principle), which the tests check.
    """
    return np.asarray(A_L, float) - np.asarray(B_L, float) @ np.asarray(C_L, float)


def estimated_loop_systems(A_L, B_L, C_L, Ts: float) -> list:
    """python-control state-space loops of `estimated_loop`'s points.

    Parameters
    ----------
    A_L, B_L, C_L : ndarray
        `estimated_loop`'s output, (P, N, N), (P, N, 1), (P, 1, N).
    Ts : float
        Control period [s] (the systems' dt).

    Returns
    -------
    list of control.StateSpace
        P SISO loops, for `fahv.analysis.margins.loop_margins`.
    """
    return [control.ss(a, b, c, 0.0, dt=Ts) for a, b, c in zip(A_L, B_L, C_L, strict=True)]


def estimated_margins(design, flt, settings) -> list:
    """The margins at the elevator of the loop on the estimate, per notch setting.

    At the design point (the LPV model and the filter's gain blended with the weights of
    the design step's (h0, V0)) and worst over the LPV vertices (each vertex with its own
    gain L_i), for each setting of `settings`. A filter with servo states flies the plant
    with the same servos (`servo_plants`), and the loop is broken at the servo's command.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        A nine-state design: `A`, `B`, the TP grids and weights, `omega_flex`.
    flt : fahv.estimation.kalman.GainScheduledKalman
        The scenario's filter (`design_filter`).
    settings : list of fahv.analysis.margin_study.NotchSetting
        The notch settings and gains.

    Returns
    -------
    list of fahv.analysis.margins.LoopMargins
        Two rows per setting, break `delta_e on x_hat`.

    Raises
    ------
    ValueError
        If the shapes disagree (`estimated_loop`).
    """
    a, Ts = design.arrays, float(design.case["Ts"])
    points = _points(design, flt)
    omega = frequency_grid(Ts, a["omega_flex"])
    rows = []
    for s in settings:
        for name, (A_, B_, L_) in points.items():
            systems, rho = _systems(flt, s, A_, B_, L_, Ts)
            got = [loop_margins(sys, r, omega, a["omega_flex"][0],
                                ("delta_e on x_hat", s.label, f"{name} {i}" if len(rho) > 1
                                 else name))
                   for i, (sys, r) in enumerate(zip(systems, rho, strict=True))]  # fmt: skip
            worst = f"worst of {len(got)} vertices"
            rows.append(got[0] if len(got) == 1 else worst_case(got, worst))
    return rows


def _points(design, flt) -> dict[str, tuple]:
    """The plant points of `estimated_margins`: the design point and the LPV vertices.

    Returns {name: (A (P, n, n), B (P, n, m), L (P, n_z, n_y))}: the design step's
    (h0, V0) with the filter's gain blended by its weights (P = 1), and every vertex with
    its own gain.
    """
    a, step = design.arrays, design.case["design_step"]
    w = flt.lpv.weights([step["h0"]], [step["V0"]])[0]
    A_p, B_p = flt.lpv.systems([step["h0"]], [step["V0"]])
    return {
        "design point": (A_p, B_p, np.einsum("r,rab->ab", w, flt.L)[None]),
        "vertex": (np.asarray(a["A"], float), np.asarray(a["B"], float),
                   np.asarray(flt.L, float)),
    }  # fmt: skip


def _systems(flt, setting, A_, B_, L_, Ts: float) -> tuple[list, np.ndarray]:
    """The loop on the estimate at the points (A_, B_, L_) for one notch setting.

    Returns (P SISO `control.StateSpace` loops broken at the elevator, their closed loops'
    spectral radii (P,)).
    """
    plant = (A_, B_) if flt.servos is None else servo_plants(A_, B_, flt.servos, Ts)
    loops = estimated_loop(*plant, setting.F, setting.notch, Ts,
                           *filter_models(A_, B_, flt.servos, Ts, flt.disturbance), L_, flt.C)
    return estimated_loop_systems(*loops, Ts), spectral_radius(estimated_closed_loop(*loops))


def design_point_loops(design, flt, settings) -> list[tuple]:
    """The loop on the estimate at the design point, per notch setting (for its figures).

    Parameters
    ----------
    design, flt, settings
        As `estimated_margins`.

    Returns
    -------
    list of (fahv.analysis.margin_study.NotchSetting, control.StateSpace)
        The SISO loop broken at the elevator (its servo's command with servos) at the
        design point, the one `estimated_margins`' "design point" rows are of.
    """
    A_, B_, L_ = _points(design, flt)["design point"]
    Ts = float(design.case["Ts"])
    return [(s, _systems(flt, s, A_, B_, L_, Ts)[0][0]) for s in settings]
