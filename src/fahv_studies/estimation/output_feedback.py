"""Whether an output-feedback tube exists for a filter: the tube of the estimate.

In the output-feedback tube MPC of Mayne, Rakovic, Findeisen and Allgower (Automatica
42(7), 2006) the ancillary law acts on the estimate, u = v + F (x_hat - x_bar), and
the tube is the set Z_hat of the estimate's deviation from the nominal. The estimate
moves by the model and by the filter's correction: with the gain L_j of a vertex,

    x_hat_k+1 = A_i x_hat_k + B_i u_k + L_j (C_z e_k+1|k + v_k+1),

so Z_hat must be robust invariant for the correction iota = L_j (C_z e + v) in place of
the one-step model error W of the state-feedback tube (eq. 13-19). The true state's
error is then x - x_bar in Z_hat + E (E the estimation error's set), and the inputs
are tightened by F Z_hat (eq. 30).

This module bounds iota row by row and asks the tube LMI (24-28) of the design's
synthesis (`fahv.synthesis.feedback.design_tube`, the same objective: each input's
tightening relative to its room) for a tube of that box on the design's LPV vertices,
beside the state-feedback tube of the design's W on the same vertices:

- **the sensor part** |L_j| v_max, v within the bound a whole run stays within with
  probability p: the correction the noise alone makes. The tube LMI is harder for a
  larger box, so a tube that does not fit the inputs' room for this part alone does
  not fit for the whole correction either;
- **the estimation error's part** r ||(L_j C_z A_z,i S^1/2)_s||, the prior error of the
  noise-driven posterior error within its run-long ellipsoid (radius r, covariance bound
  S of `fahv.stochastic.error_bound.covariance_bound`), at every pair of model vertex i
  and gain vertex j: reported beside the sensor part (its size, not a tube).

The statement is the synthesis's (an ellipsoidal tube with one shape over the vertices,
the contraction factors of its grid), as every tube of this project is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.synthesis.feedback import design_tube

#: Contraction factors tried by the tube LMI (the state-feedback tube of the LPV
#: vertices takes 0.98, the estimate's 0.995: measured on cm_certified).
LAM_GRID = (0.95, 0.98, 0.99, 0.995)


def sensor_part(L: np.ndarray, v_max: np.ndarray) -> np.ndarray:
    """Half-widths of the correction L_j v over the gain vertices, |v| <= v_max.

    Parameters
    ----------
    L : (R, n_z, n_y) ndarray
        The filter's vertex gains.
    v_max : (n_y,) array_like
        Noise bound per channel [the channel's unit].

    Returns
    -------
    (n_z,) ndarray
        max_j sum_c |L_j[s, c]| v_max[c] per state s [the state's unit].

    Examples
    --------
    >>> sensor_part(np.array([[[1.0, -2.0]], [[0.5, 3.0]]]), np.array([1.0, 0.1]))
    array([1.2])
    """
    return np.max(np.abs(np.asarray(L, float)) @ np.asarray(v_max, float), axis=0)


def error_part(L: np.ndarray, Cz: np.ndarray, Az: np.ndarray, S: np.ndarray,
               r: float) -> np.ndarray:  # fmt: skip
    """Half-widths of L_j C_z A_z,i e over every pair (i, j), e' S^-1 e <= r^2.

    Parameters
    ----------
    L : (R, n_z, n_y) ndarray
        Gain vertices.
    Cz : (n_y, n_z) ndarray
        Output matrix of z.
    Az : (R, n_z, n_z) ndarray
        Model vertices of z (`GainScheduledKalman.model_vertices`).
    S : (n_z, n_z) ndarray
        Covariance bound of the posterior error.
    r : float
        Radius of its run-long ellipsoid.

    Returns
    -------
    (n_z,) ndarray
        max_ij r sqrt((L_j C_z A_z,i S A_z,i' C_z' L_j')_ss) per state s [the state's
        unit].

    Raises
    ------
    numpy.linalg.LinAlgError
        If S is not positive definite.
    """
    Sh = np.linalg.cholesky(np.asarray(S, float))
    CA = np.einsum("yk,ikl,lm->iym", Cz, Az, Sh)  # (R, n_y, n_z): C_z A_z,i S^1/2
    rows = np.einsum("jsy,iym->ijsm", L, CA)
    return r * np.sqrt((rows**2).sum(axis=-1)).max(axis=(0, 1))


@dataclass(frozen=True)
class TubeFit:
    """The tube LMI's best tube for a box W on the LPV vertices (eight states after h).

    Attributes
    ----------
    w : (8,) ndarray
        Half-widths of W [V ft/s, alpha rad, theta rad, q rad/s, eta_1, eta_1_dot 1/s,
        eta_2, eta_2_dot 1/s].
    lam : float
        Contraction factor of the best tube.
    tightening : (2,) ndarray
        max over Z of |F_j e| [Phi, delta_e rad] (eq. 30).
    room : (2,) ndarray
        The inputs' room [Phi, delta_e rad].
    attitude : (2,) ndarray
        Support of Z in alpha and theta [rad].
    """

    w: np.ndarray
    lam: float
    tightening: np.ndarray
    room: np.ndarray
    attitude: np.ndarray

    @property
    def share(self) -> np.ndarray:
        """The tightening over the room per input (2,): above 1, no room is left for the nominal."""
        return self.tightening / self.room

    @property
    def fits(self) -> bool:
        """Whether the tightening leaves room on both inputs."""
        return bool(np.all(self.share < 1.0))


def tube_fit(arrays, w: np.ndarray) -> TubeFit:
    """The best tube of the design's LPV vertices for the box w (the synthesis of eq. 24-28).

    Parameters
    ----------
    arrays : mapping
        The design's arrays: `A` (R, 9, 9), `B` (R, 9, 2), `Dx` (9,), `Du` (2,),
        `u_room` (2,).
    w : (8,) array_like
        Half-widths of W on the eight states after h.

    Returns
    -------
    TubeFit

    Raises
    ------
    DesignError
        If the LMI has no solution at any contraction factor of `LAM_GRID`, or its
        re-check over the vertices fails.
    """
    A, B = np.asarray(arrays["A"], float), np.asarray(arrays["B"], float)
    room = np.asarray(arrays["u_room"], float)
    td = design_tube(A[:, 1:, 1:], B[:, 1:, :], np.asarray(w, float),
                     np.asarray(arrays["Dx"], float)[1:], np.asarray(arrays["Du"], float),
                     room, lam_grid=LAM_GRID)  # fmt: skip
    return TubeFit(np.asarray(w, float), float(td.lam), td.tightening, room, td.z_box[1:3])


@dataclass(frozen=True)
class OutputFeedbackTube:
    """The estimate's tube beside the state-feedback tube, on the same LPV vertices.

    Attributes
    ----------
    sensor : (11,) ndarray
        Half-widths of the filter's correction by the sensor noise (`sensor_part`).
    error : (11,) ndarray
        Half-widths of its correction by the estimation error (`error_part`).
    state_feedback : TubeFit
        The tube of the design's W (`w_max`).
    estimate : TubeFit
        The tube of the sensor part alone.
    """

    sensor: np.ndarray
    error: np.ndarray
    state_feedback: TubeFit
    estimate: TubeFit


def output_feedback_tube(flt, arrays, S: np.ndarray, r: float,
                         v_max: np.ndarray) -> OutputFeedbackTube:  # fmt: skip
    """Whether a tube of the estimate fits the inputs' room (module docstring).

    Parameters
    ----------
    flt : GainScheduledKalman
        The filter (`fahv.estimation.kalman.design_filter`).
    arrays : mapping
        The design's arrays (`tube_fit`'s and `w_max` (9,)).
    S : (11, 11) ndarray
        Covariance bound of the noise-driven posterior error.
    r : float
        Radius of its run-long ellipsoid.
    v_max : (n_y,) ndarray
        Run-long noise bound per channel.

    Returns
    -------
    OutputFeedbackTube

    Raises
    ------
    DesignError
        If a tube LMI fails (`tube_fit`).
    """
    L = np.asarray(flt.L, float)
    Az = flt.model_vertices()
    Cz = np.hstack([flt.C, np.zeros((len(flt.C), Az.shape[1] - flt.C.shape[1]))])
    sensor = sensor_part(L, v_max)
    return OutputFeedbackTube(
        sensor, error_part(L, Cz, Az, S, r),
        tube_fit(arrays, np.asarray(arrays["w_max"], float)[1:]), tube_fit(arrays, sensor[1:9]),
    )  # fmt: skip
