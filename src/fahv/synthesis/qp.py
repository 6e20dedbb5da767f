"""Numerical checks of a quadratic program's solution (never trust a solver status)."""

from __future__ import annotations

import numpy as np

#: Primal feasibility and KKT tolerances of the solution check (scaled units).
PRIMAL_TOL = 1e-6
KKT_TOL = 1e-5
#: |bound| at or above this is no bound.
NO_BOUND = 1e29


def check_kkt(H, f, A_c, bl, bu, y, lam, primal_tol=PRIMAL_TOL, kkt_tol=KKT_TOL) -> str:
    """Check a QP solution numerically; '' if it passes, else why not (no exception).

    QP: min 0.5 y'Hy + f'y  s.t. bl <= [y; A_c y] <= bu (the first ny bounds are simple
    bounds on y, DAQP's convention). Checks primal feasibility (<= primal_tol),
    stationarity H y + f + [I; A_c]' lam = 0 (relative to the size of the terms,
    <= kkt_tol), dual sign (lam >= 0 on upper, <= 0 on lower active bounds) and
    complementarity.

    Parameters
    ----------
    H : (ny, ny) ndarray
    f : (ny,) ndarray
    A_c : (nc, ny) ndarray
    bl, bu : (ny + nc,) ndarray
        Bounds on [y; A_c y]; ``|b| >= NO_BOUND`` means none.
    y : (ny,) ndarray
        Primal solution.
    lam : (ny + nc,) ndarray
        Multipliers (positive on an active upper bound, negative on a lower one).
    primal_tol, kkt_tol : float
        Tolerances relative to the size of the terms.

    Returns
    -------
    str
        '' when every condition holds, else the first that failed.
    """
    ny = y.size
    Ay = np.concatenate([y, A_c @ y])
    big = NO_BOUND
    viol = np.maximum(np.where(bl > -big, bl - Ay, 0.0), np.where(bu < big, Ay - bu, 0.0))
    if np.max(viol) > primal_tol * (1.0 + np.max(np.abs(Ay))):
        return f"primal infeasible by {np.max(viol):.2e}"
    grad = H @ y + f
    Glam = lam[:ny] + A_c.T @ lam[ny:]
    res = grad + Glam
    scale = 1.0 + np.max(np.abs(grad)) + np.max(np.abs(Glam))
    if np.max(np.abs(res)) > kkt_tol * scale:
        return f"stationarity residual {np.max(np.abs(res)):.2e}"
    slack_hi = np.where(bu < big, bu - Ay, np.inf)
    slack_lo = np.where(bl > -big, Ay - bl, np.inf)
    tol = kkt_tol * scale
    if np.any((lam > tol) & (slack_hi > primal_tol * (1 + np.abs(Ay)) * 10)):
        return "complementarity (upper bounds)"
    if np.any((lam < -tol) & (slack_lo > primal_tol * (1 + np.abs(Ay)) * 10)):
        return "complementarity (lower bounds)"
    return ""
