"""Plant: fixed-step integration of the nonlinear CM, actuator saturation, fault models.

The same classes are used by the in-process simulator and the plant / fault_injector
nodes, so both produce the same numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fahv.vehicle import DELTA_E, InputLimits, VehicleParams, cm_rhs

#: Parameters of the uncertainty box of sec. 5.1 and their relative bounds.
PAPER_UNCERTAINTY = {
    "m": 0.10,
    "I_yy": 0.10,
    "S": 0.01,
    "z_T": 0.01,
    "c_bar": 0.01,
    "c_e": 0.03,
    "beta_1": 0.03,
    "beta_3": 0.03,
    "beta_5": 0.03,
    "beta_7": 0.03,
}


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


def perturb(vp: VehicleParams, rel: dict[str, float], signs: dict[str, float]) -> VehicleParams:
    """Parameters with p -> p (1 + s_p rel_p) for s_p in [-1, 1] (uncertainty box, sec. 5.1).

    Raises
    ------
    ValueError
        If a name is not a parameter or |s_p| > 1.
    """
    changes = {}
    for name, r in rel.items():
        if not hasattr(vp, name):
            raise ValueError(f"uncertainty: unknown parameter '{name}'")
        s = float(signs.get(name, 0.0))
        if abs(s) > 1.0:
            raise ValueError(f"uncertainty: sign/fraction for '{name}' must be in [-1, 1]")
        changes[name] = getattr(vp, name) * (1.0 + s * r)
    return vp.replace(**changes)


def saturate(u: np.ndarray, limits: InputLimits) -> np.ndarray:
    """Clip [Phi, delta_e] to the actuator limits of sec. 5.1."""
    return np.clip(u, limits.u_min, limits.u_max)


@dataclass(frozen=True)
class ElevatorFault:
    """Actuator fault applied to the commanded input.

    Attributes
    ----------
    kind : {"none", "loss_of_effectiveness", "stuck", "bias", "dropout"}
        Loss of effectiveness: delta_e,applied = rho_f delta_e (eq. 15, applied to
        the whole deflection, trim included, MODEL_DATA.md); stuck: delta_e frozen at
        its value at onset; bias: delta_e + bias; dropout: the command is lost and the
        previous applied input is held.
    t_onset : float
        Onset time [s].
    rho_f : float
        Effectiveness in (0, 1] for loss of effectiveness.
    bias : float
        Elevator bias [rad].
    """

    kind: str = "none"
    t_onset: float = math.inf
    rho_f: float = 1.0
    bias: float = 0.0

    def __post_init__(self) -> None:
        kinds = ("none", "loss_of_effectiveness", "stuck", "bias", "dropout")
        if self.kind not in kinds:
            raise ValueError(f"fault kind must be one of {kinds}, got {self.kind!r}")
        if not 0.0 < self.rho_f <= 1.0:
            raise ValueError(f"fault rho_f must be in (0, 1], got {self.rho_f}")

    def active(self, t: float) -> bool:
        """True once t >= t_onset for a fault other than "none"."""
        return self.kind != "none" and t >= self.t_onset - 1e-12


class FaultInjector:
    """Stateful application of an :class:`ElevatorFault` to commands u (2,)."""

    def __init__(self, fault: ElevatorFault) -> None:
        self.fault = fault
        self._held: np.ndarray | None = None
        self._stuck: float | None = None

    def apply(self, t: float, u: np.ndarray) -> np.ndarray:
        """Input reaching the actuators at time t [s] for the command u [Phi, delta_e rad]."""
        f = self.fault
        out = np.array(u, dtype=float)
        if f.active(t):
            if f.kind == "loss_of_effectiveness":
                out[DELTA_E] = f.rho_f * out[DELTA_E]
            elif f.kind == "bias":
                out[DELTA_E] += f.bias
            elif f.kind == "stuck":
                if self._stuck is None:
                    self._stuck = out[DELTA_E] if self._held is None else self._held[DELTA_E]
                out[DELTA_E] = self._stuck
            elif f.kind == "dropout" and self._held is not None:
                out = self._held.copy()
        self._held = out.copy()
        return out


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


__all__ = [
    "PAPER_UNCERTAINTY",
    "rk4_step",
    "perturb",
    "saturate",
    "ElevatorFault",
    "FaultInjector",
    "Plant",
]
