"""Plant: fixed-step integration of the nonlinear CM, actuator saturation, fault models.

The same classes are used by the in-process simulator and the plant / fault_injector
nodes, so both produce the same numbers.
"""

from __future__ import annotations

import numpy as np

from fahv.model.dynamics import cm_rhs
from fahv.model.vehicle import InputLimits, VehicleParams


def rk4_step(f, x: np.ndarray, u: np.ndarray, Ts: float, n_sub: int) -> np.ndarray:
    """Integrate x_dot = f(x, u) over Ts with n_sub classical RK4 steps, u held (ZOH).

    Parameters
    ----------
    f : callable
        f(x, u) -> x_dot.
    x : (n,) ndarray
    u : (m,) ndarray
    Ts : float
        Interval [s].
    n_sub : int
        Number of RK4 steps (dt = Ts / n_sub).

    Returns
    -------
    (n,) ndarray
    """
    dt = Ts / n_sub
    for _ in range(n_sub):
        k1 = f(x, u)
        k2 = f(x + 0.5 * dt * k1, u)
        k3 = f(x + 0.5 * dt * k2, u)
        k4 = f(x + dt * k3, u)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def saturate(u: np.ndarray, limits: InputLimits) -> np.ndarray:
    """Clip [Phi, delta_e] to the actuator limits of sec. 5.1."""
    return np.clip(u, limits.u_min, limits.u_max)


class Plant:
    """Nonlinear CM (eq. 1-3) with ZOH input, saturation and fixed-step RK4.

    Parameters
    ----------
    params : VehicleParams
        True (possibly perturbed) parameters.
    limits : InputLimits
    x0 : (9,) array_like
        Initial state.
    Ts : float
        Control period [s].
    n_sub : int
        RK4 steps per period; dt = Ts / n_sub must resolve the flexible modes
        (omega_2 dt well below 1).
    """

    def __init__(
        self, params: VehicleParams, limits: InputLimits, x0, Ts: float, n_sub: int
    ) -> None:
        self.params, self.limits, self.Ts, self.n_sub = params, limits, Ts, n_sub
        self.x = np.asarray(x0, float).copy()
        if self.x.shape != (9,) or not np.all(np.isfinite(self.x)):
            raise ValueError(f"plant initial state must be 9 finite values, got {x0!r}")

    def _f(self, x, u):
        return cm_rhs(x, u, self.params)

    def step(self, u_applied: np.ndarray) -> np.ndarray:
        """Advance one period with the saturated input; returns the new state (9,)."""
        u = saturate(np.asarray(u_applied, float), self.limits)
        if not np.all(np.isfinite(u)):
            raise ValueError(f"plant input must be finite, got {u_applied!r}")
        self.x = rk4_step(self._f, self.x, u, self.Ts, self.n_sub)
        return self.x
