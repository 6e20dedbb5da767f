"""One control period of the perturbed plant, and its one-period Jacobians.

Every bound of the design is a bound of this map: x+ = Phi_p(x, u), one control period
Ts of the CM (eq. 1-3) for the vehicle of parameter record p, integrated by the plant's
own RK4 with its sub-steps (`fahv.plant.rk4.rk4_cm`), batched over points.
"""

from __future__ import annotations

import numpy as np

from fahv.plant.rk4 import rk4_cm

#: Safety factor on a remainder of the one-step map measured at sample points (the
#: Taylor model's at the corners of a box, the multilinear interpolation's along the
#: edges of the scheduling box): what lies between the points evaluated.
REMAINDER_FACTOR = 2.0


def plant_step(X, U, recs, Ts: float, n_sub: int) -> np.ndarray:
    """One control period of the CM at L points: Phi_p(x, u).

    Parameters
    ----------
    X : (L, 9) array_like
        States (h ft, V ft/s, alpha rad, theta rad, q rad/s, eta_1, eta_1_dot, eta_2,
        eta_2_dot).
    U : (L, 2) array_like
        Applied inputs (Phi -, delta_e rad).
    recs : (L,) ndarray
        Parameter records of the vehicles (`fahv.plant.rk4.params_records`).
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period.

    Returns
    -------
    (L, 9) ndarray
        The states one period later.
    """
    return rk4_cm(np.ascontiguousarray(X), np.ascontiguousarray(U), recs, Ts, n_sub)


def jacobians(X, U, recs, Ts: float, n_sub: int, scale) -> np.ndarray:
    """One-period Jacobians [A, B] of the CM at L points, by central differences.

    Parameters
    ----------
    X : (L, 9) ndarray
        States.
    U : (L, 2) ndarray
        Applied inputs.
    recs : (L,) ndarray
        Parameter records.
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period.
    scale : (11,) array_like
        The design scaling (Dx, Du); the steps are 1e-4 of it.

    Returns
    -------
    (L, 9, 11) ndarray
        d Phi_p / d(x, u) at each point.
    """
    z0 = np.concatenate([X, U], axis=1)
    J = np.empty((len(X), 9, 11))
    for i in range(11):
        zp, zm = z0.copy(), z0.copy()
        zp[:, i] += 1e-4 * scale[i]
        zm[:, i] -= 1e-4 * scale[i]
        fp = plant_step(zp[:, :9], zp[:, 9:], recs, Ts, n_sub)
        fm = plant_step(zm[:, :9], zm[:, 9:], recs, Ts, n_sub)
        J[:, :, i] = (fp - fm) / (2e-4 * scale[i])
    return J
