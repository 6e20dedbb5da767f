"""The ECM's airframe part: the CM recovered from the ECM by a change of coordinates.

The ECM (eq. 39-43, `fahv.model.dynamics.ecm_rhs`) is the CM in series with the notch:
its state x' = [h, V, alpha, theta, q', eta_1, eta_1_dot, eta_2, eta_2_dot, x_q1, x_q2]
holds the filtered rate q' = C_q x_q + D_q q in place of q. In the coordinates
z = [x_CM; x_q] = T^-1 x', with T the identity but for the row of q',

    T[IQ, IQ] = D_q,   T[IQ, 9:] = C_q,

a linearisation of the ECM is block lower triangular: the filter's states do not act on
the airframe. A discretisation keeps that form (the matrix exponential of a block
triangular matrix is block triangular), so the first nine rows and columns of
T^-1 A_i T and of T^-1 B_i are the CM's own vertices. This is how a filter of the
airframe (`fahv.estimation.kalman`) runs on a design of the ECM.
"""

from __future__ import annotations

import numpy as np

from fahv.model.notch import NotchFilter
from fahv.model.vehicle import IQ

#: The ECM's coupling of the filter's states into the airframe, in cascade coordinates,
#: that is still read as zero: this fraction of the largest entry of A_i.
CASCADE_RTOL = 1e-9

N_CM = 9

#: The arrays of a design's airframe model (`airframe_arrays`).
AIRFRAME_ARRAYS = ("A", "B", "h_grid", "V_grid", "W_h", "W_V", "w_max", "Dx", "Du")


def cascade_transform(notch: NotchFilter) -> np.ndarray:
    """T with x' = T z: ECM state from the CM's and the notch's, eq. (39), (43).

    Parameters
    ----------
    notch : NotchFilter
        The notch of the ECM (its realisation `NotchFilter.ss`).

    Returns
    -------
    (11, 11) ndarray
        The identity but for row IQ: q' = D_q q + C_q x_q.

    Examples
    --------
    >>> T = cascade_transform(NotchFilter(19.05, 0.02, 19.05, 0.1))
    >>> float(T[4, 4]), np.round(T[4, 9:], 3).tolist()
    (1.0, [-3.048, 0.0])
    """
    _, _, C_q, D_q = notch.ss()
    T = np.eye(N_CM + 2)
    T[IQ, IQ] = D_q
    T[IQ, N_CM:] = C_q
    return T


def cm_vertices(A: np.ndarray, B: np.ndarray, notch: NotchFilter) -> tuple[np.ndarray, np.ndarray]:
    """The CM's vertices held in the ECM's: (T^-1 A_i T)[:9, :9] and (T^-1 B_i)[:9].

    Parameters
    ----------
    A : (R, 11, 11) ndarray
        ECM vertices A_i (eq. 12 on the ECM), continuous or discrete.
    B : (R, 11, 2) ndarray
        ECM vertices B_i.
    notch : NotchFilter
        The notch the ECM was built with.

    Returns
    -------
    A_cm : (R, 9, 9) ndarray
    B_cm : (R, 9, 2) ndarray

    Raises
    ------
    ValueError
        If the shapes are not the ECM's, or a vertex is not a cascade: its filter states
        act on the airframe by more than `CASCADE_RTOL` of its largest entry (a model
        built with another notch, or not of the ECM).
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    n = N_CM + 2
    if A.ndim != 3 or A.shape[1:] != (n, n) or B.shape != (A.shape[0], n, 2):
        raise ValueError(f"ECM vertices must be A (R, {n}, {n}) and B (R, {n}, 2), got "
                         f"{A.shape} and {B.shape}")  # fmt: skip
    T = cascade_transform(notch)
    T_inv = np.linalg.inv(T)
    A_z, B_z = T_inv @ A @ T, T_inv @ B
    coupling = np.abs(A_z[:, :N_CM, N_CM:]).max(axis=(1, 2))
    size = np.abs(A).max(axis=(1, 2))
    bad = np.flatnonzero(coupling > CASCADE_RTOL * size)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"vertex {i} of the ECM is not the CM in series with the notch "
                         f"(omega_z {notch.omega_z:g}, eps_p {notch.eps_p:g}): its filter "
                         f"states act on the airframe by {coupling[i]:.3g} "
                         f"(> {CASCADE_RTOL:g} x {size[i]:.3g})")  # fmt: skip
    return A_z[:, :N_CM, :N_CM].copy(), B_z[:, :N_CM].copy()


def cm_bound(w: np.ndarray, notch: NotchFilter) -> np.ndarray:
    """A bound on the CM's rows from one on the ECM's: |z| <= |T^-1| |x'| row by row.

    Parameters
    ----------
    w : (11,) array_like
        Non-negative bound on each ECM state (e.g. the design's w_max, eq. 13-19).
    notch : NotchFilter

    Returns
    -------
    (9,) ndarray
        The CM's: equal but for q, bounded by (|w_q'| + |C_q| |w_xq|) / |D_q|.

    Raises
    ------
    ValueError
        If w is not (11,) or is negative or not finite.

    Examples
    --------
    >>> w = np.zeros(11); w[4], w[9] = 1.0, 0.5
    >>> cm_bound(w, NotchFilter(19.05, 0.02, 19.05, 0.1))[4].round(3)
    np.float64(2.524)
    """
    w = np.asarray(w, float)
    if w.shape != (N_CM + 2,) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"an ECM bound must be (11,) finite and non-negative, got {w!r}")
    return (np.abs(np.linalg.inv(cascade_transform(notch))) @ w)[:N_CM]


def airframe_arrays(arrays, design_model: str, notch) -> dict:
    """The CM LPV model of a design, the model a filter of the airframe runs on.

    Parameters
    ----------
    arrays : mapping
        The design's arrays: `A`, `B` (R, n, n), (R, n, 2), `w_max`, `Dx` (n,), and the
        TP grid `h_grid`, `V_grid`, `W_h`, `W_V` and `Du`, passed on as they are.
    design_model : {"cm", "ecm"}
        The design's model (design key `design_model`).
    notch : mapping
        The design's `notch` section (`omega_z`, `eps_z`, `omega_p`, `eps_p`): the ECM's
        filter.

    Returns
    -------
    dict
        `A` (R, 9, 9), `B` (R, 9, 2), `w_max` (9,), `Dx` (9,), `Du` (2,) and the TP grid.
        A CM design's own; an ECM design's CM part (`cm_vertices`, `cm_bound`; Dx of q'
        for q).

    Raises
    ------
    ValueError
        If `design_model` is neither, or the ECM's vertices are not a cascade.
    """
    out = {k: np.asarray(arrays[k], float) for k in AIRFRAME_ARRAYS}
    if design_model == "cm":
        return out
    if design_model != "ecm":
        raise ValueError(f"design_model {design_model!r} is neither 'cm' nor 'ecm'")
    nf = NotchFilter(*(float(notch[k]) for k in ("omega_z", "eps_z", "omega_p", "eps_p")))
    out["A"], out["B"] = cm_vertices(out["A"], out["B"], nf)
    out["w_max"] = cm_bound(out["w_max"], nf)
    out["Dx"] = out["Dx"][:N_CM]
    return out
