"""Numerical checks of a quadratic program's solution (never trust a solver status)."""

from __future__ import annotations

import functools

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
        Bounds on [y; A_c y]; `|b| >= NO_BOUND` means none.
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

    Examples
    --------
    min 0.5 y^2 - 2 y subject to y <= 1: y = 1 with the multiplier 1 (y - 2 + 1 = 0):

    >>> H, f, A_c = np.eye(1), np.array([-2.0]), np.zeros((0, 1))
    >>> bl, bu = np.array([-1e30]), np.array([1.0])
    >>> check_kkt(H, f, A_c, bl, bu, np.array([1.0]), np.array([1.0]))
    ''
    >>> check_kkt(H, f, A_c, bl, bu, np.array([1.5]), np.array([0.5]))
    'primal infeasible by 5.00e-01'
    >>> check_kkt(H, f, A_c, bl, bu, np.array([1.0]), np.array([0.5]))
    'stationarity residual 5.00e-01'
    """
    r = _kkt_kernel()(
        np.ascontiguousarray(H, dtype=float), np.ascontiguousarray(f, dtype=float),
        np.ascontiguousarray(A_c, dtype=float), np.ascontiguousarray(bl, dtype=float),
        np.ascontiguousarray(bu, dtype=float), np.ascontiguousarray(y, dtype=float),
        np.ascontiguousarray(lam, dtype=float), NO_BOUND, primal_tol, kkt_tol,
    )  # fmt: skip
    viol, ay_max, res, scale, comp_hi, comp_lo = r
    if viol > primal_tol * (1.0 + ay_max):
        return f"primal infeasible by {viol:.2e}"
    if res > kkt_tol * scale:
        return f"stationarity residual {res:.2e}"
    if comp_hi:
        return "complementarity (upper bounds)"
    if comp_lo:
        return "complementarity (lower bounds)"
    return ""


def compile_kernel() -> None:
    """Compile the KKT check now (or load it from numba's disk cache), not at the first QP.

    Every QP check passes C-contiguous float64 arrays, so one call on a 1-variable
    problem builds the only specialisation. A loop node builds its MPC before it
    reports ready: a cold compile (about 6 s of CPU) then falls in its start-up,
    not in a step its peers' watchdogs time. Raises nothing.
    """
    check_kkt(np.eye(1), np.zeros(1), np.zeros((0, 1)), -np.ones(1), np.ones(1),
              np.zeros(1), np.zeros(1))  # fmt: skip


@functools.cache
def _kkt_kernel():
    """`_kkt_measures` compiled by numba (cached on disk), built at its first use.

    A process that never checks a QP (most nodes) does not import numba (0.16 s).
    """
    import numba

    return numba.njit(cache=True)(_kkt_measures)


def _kkt_measures(H, f, A_c, bl, bu, y, lam, big, primal_tol, kkt_tol):  # pragma: no cover
    """The numbers `check_kkt` compares (compiled: a QP per re-plan and run).

    Returns (largest bound violation, max |[y; A_c y]|, largest stationarity residual,
    its scale, an upper-bound complementarity failure, a lower-bound one).
    """
    ny, nc = y.size, A_c.shape[0]
    Ay = np.empty(ny + nc)
    Ay[:ny] = y
    Ay[ny:] = A_c @ y
    # A_c' lam from the rows with a multiplier only (an active-set solver's multipliers
    # are zero off its active set): a second pass over A_c, the QP's largest array and
    # often out of cache in a campaign batch, would cost as much as the first
    glam = lam[:ny].copy()
    for i in range(nc):
        li = lam[ny + i]
        if li != 0.0:
            for j in range(ny):
                glam[j] += A_c[i, j] * li
    viol = 0.0
    ay_max = 0.0
    for i in range(ny + nc):
        ay_max = max(ay_max, abs(Ay[i]))
        if bl[i] > -big:
            viol = max(viol, bl[i] - Ay[i])
        if bu[i] < big:
            viol = max(viol, Ay[i] - bu[i])
    grad = H @ y + f
    res = 0.0
    g_max = 0.0
    l_max = 0.0
    for i in range(ny):
        res = max(res, abs(grad[i] + glam[i]))
        g_max = max(g_max, abs(grad[i]))
        l_max = max(l_max, abs(glam[i]))
    scale = 1.0 + g_max + l_max
    tol = kkt_tol * scale
    comp_hi = False
    comp_lo = False
    for i in range(ny + nc):
        room = primal_tol * (1.0 + abs(Ay[i])) * 10.0
        if lam[i] > tol and bu[i] < big and bu[i] - Ay[i] > room:
            comp_hi = True
        if lam[i] > tol and not bu[i] < big:  # a multiplier on an absent bound
            comp_hi = True
        if lam[i] < -tol and bl[i] > -big and Ay[i] - bl[i] > room:
            comp_lo = True
        if lam[i] < -tol and not bl[i] > -big:
            comp_lo = True
    return viol, ay_max, res, scale, comp_hi, comp_lo
