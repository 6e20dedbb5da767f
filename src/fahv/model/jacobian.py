"""Numerical Jacobians: complex-step and central differences."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

_CS_STEP = 1e-30


def jacobian_complex_step(fun: Callable[[np.ndarray], np.ndarray], z: np.ndarray) -> np.ndarray:
    """Jacobian d fun / d z by complex step.

    Parameters
    ----------
    fun : callable
        Analytic map (n,) -> (m,) accepting complex arrays.
    z : (n,) array_like
        Point of evaluation (real).

    Returns
    -------
    J : (m, n) ndarray

    Examples
    --------
    >>> def fun(z):
    ...     return np.array([z[0] ** 2 * z[1], np.sin(z[1])])
    >>> jacobian_complex_step(fun, [3.0, 0.0]).tolist()  # exact: no subtraction
    [[0.0, 9.0], [0.0, 1.0]]
    """
    z = np.asarray(z, dtype=float)
    cols = []
    for i in range(z.size):
        zc = z.astype(complex)
        zc[i] += 1j * _CS_STEP
        cols.append(np.imag(np.asarray(fun(zc))) / _CS_STEP)
    return np.stack(cols, axis=1)


def jacobian_central_difference(
    fun: Callable[[np.ndarray], np.ndarray], z: np.ndarray, step: np.ndarray
) -> np.ndarray:
    """Jacobian by central differences with per-coordinate steps `step` (n,).

    Used only to check `jacobian_complex_step`; truncation error O(step^2).

    Parameters
    ----------
    fun : callable
        Map (n,) -> (m,).
    z : (n,) array_like
        Point of evaluation.
    step : (n,) array_like
        Step per coordinate, in the units of `z`.

    Returns
    -------
    J : (m, n) ndarray

    Examples
    --------
    >>> def cube(z):
    ...     return np.array([z[0] ** 3])
    >>> round(float(jacobian_central_difference(cube, [2.0], [1e-3])[0, 0]), 9)  # 12 + step^2
    12.000001
    """
    z = np.asarray(z, dtype=float)
    cols = []
    for i in range(z.size):
        dz = np.zeros_like(z)
        dz[i] = step[i]
        cols.append((np.asarray(fun(z + dz)) - np.asarray(fun(z - dz))) / (2.0 * step[i]))
    return np.stack(cols, axis=1)


def jacobians(f: Callable, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A = df/dx, B = df/du at (x, u), eq. (9).

    Parameters
    ----------
    f : callable
        f(x, u) -> x_dot, analytic in x and u.
    x : (n,) array_like
    u : (m,) array_like

    Returns
    -------
    A : (n, n) ndarray
    B : (n, m) ndarray

    Examples
    --------
    >>> A0, B0 = np.array([[0.0, 1.0], [-2.0, -3.0]]), np.array([[0.0], [1.0]])
    >>> A, B = jacobians(lambda x, u: A0 @ x + B0 @ u, [1.0, 2.0], [0.5])
    >>> A.tolist(), B.tolist()
    ([[0.0, 1.0], [-2.0, -3.0]], [[0.0], [1.0]])
    """
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    A = jacobian_complex_step(lambda xx: f(xx, u.astype(complex)), x)
    B = jacobian_complex_step(lambda uu: f(x.astype(complex), uu), u)
    return A, B
