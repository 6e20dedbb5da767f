"""Notch filter on the pitch-rate channel, eq. (37)-(39) of Yang et al. 2022.

Continuous transfer function (eq. 38)::

    H(s) = (s^2/omega_z^2 + 2 eps_z s/omega_z + 1) / (s^2/omega_p^2 + 2 eps_p s/omega_p + 1)

Transfer function, state space (eq. 39), discretisation and frequency responses
come from python-control; the only code here is the parameter handling and the
per-sample state update used by the simulator and the notch_filter node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np


@dataclass(frozen=True)
class NotchFilter:
    """Notch filter parameters of eq. (38).

    Attributes
    ----------
    omega_z : float
        Notch (numerator) frequency [rad/s]; centre of the notch.
    eps_z : float
        Numerator damping ratio [-]; depth: |H(j omega_z)| = eps_z / eps_p when
        omega_z = omega_p.
    omega_p : float
        Denominator frequency [rad/s].
    eps_p : float
        Denominator damping ratio [-]; width of the notch.

    Raises
    ------
    ValueError
        If a frequency is not positive and finite or a damping ratio is negative.
    """

    omega_z: float
    eps_z: float
    omega_p: float
    eps_p: float

    def __post_init__(self) -> None:
        for name in ("omega_z", "omega_p"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"notch filter '{name}' must be > 0 and finite, got {v}")
        for name in ("eps_z", "eps_p"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"notch filter '{name}' must be >= 0 and finite, got {v}")
        if self.eps_p <= 0.0:
            raise ValueError("notch filter 'eps_p' must be > 0 for a stable filter")

    def tf(self) -> control.TransferFunction:
        """Continuous transfer function H(s) of eq. (38) (python-control)."""
        num = [1.0 / self.omega_z**2, 2.0 * self.eps_z / self.omega_z, 1.0]
        den = [1.0 / self.omega_p**2, 2.0 * self.eps_p / self.omega_p, 1.0]
        return control.tf(num, den)

    def ss(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """State-space form of eq. (39): A_q (2, 2), B_q (2,), C_q (2,), D_q scalar.

        Controllable canonical realisation from ``control.tf2ss``; with
        ``omega_z = omega_p`` D_q = 1.
        """
        sys = control.tf2ss(self.tf())
        return (
            np.asarray(sys.A, dtype=float),
            np.asarray(sys.B, dtype=float).ravel(),
            np.asarray(sys.C, dtype=float).ravel(),
            float(np.asarray(sys.D).item()),
        )

    def state_scale(self, q_scale: float) -> np.ndarray:
        """Typical magnitudes of (x_q1, x_q2) for a pitch-rate magnitude ``q_scale``.

        In the controllable canonical form of :meth:`ss` x_q2 is q filtered by
        1/(s^2 + 2 eps_p omega_p s + omega_p^2) and x_q1 its derivative, so
        x_q1 ~ q/omega_p and x_q2 ~ q/omega_p^2; used to scale the ECM.
        """
        return np.array([q_scale / self.omega_p, q_scale / self.omega_p**2])

    def discretize(self, Ts: float) -> control.StateSpace:
        """Discrete filter at sampling period Ts [s]: Tustin, prewarped at omega_z.

        Prewarping keeps the notch centre exactly at omega_z after discretisation.

        Raises
        ------
        ValueError
            If Ts <= 0 or omega_z is not below the Nyquist frequency pi/Ts.
        """
        if not (math.isfinite(Ts) and Ts > 0.0):
            raise ValueError(f"sampling period Ts must be > 0, got {Ts}")
        if self.omega_z >= math.pi / Ts:
            raise ValueError(
                f"notch frequency omega_z = {self.omega_z} rad/s is not below the Nyquist "
                f"frequency pi/Ts = {math.pi / Ts:.3f} rad/s"
            )
        return control.c2d(
            control.ss(self.tf()), Ts, method="tustin", prewarp_frequency=self.omega_z
        )

    def magnitude(self, omega) -> np.ndarray:
        """|H(j omega)| for frequencies ``omega`` [rad/s] (array_like) -> ndarray."""
        resp = control.frequency_response(self.tf(), np.atleast_1d(np.asarray(omega, float)))
        return np.abs(np.asarray(resp.complex)).ravel()


class DiscreteNotch:
    """Per-sample notch filter q -> q' used by the simulator and the notch_filter node.

    Parameters
    ----------
    notch : NotchFilter
    Ts : float
        Sampling period [s].
    q0 : float
        Pitch rate [rad/s] at which the filter starts in steady state (0 at trim).

    Notes
    -----
    x_q(k+1) = A_d x_q(k) + B_d q(k), q'(k) = C_d x_q(k) + D_d q(k), with
    (A_d, B_d, C_d, D_d) from :meth:`NotchFilter.discretize` (python-control).
    """

    def __init__(self, notch: NotchFilter, Ts: float, q0: float = 0.0) -> None:
        sys = notch.discretize(Ts)
        self.A_d = np.asarray(sys.A, float)
        self.B_d = np.asarray(sys.B, float).ravel()
        self.C_d = np.asarray(sys.C, float).ravel()
        self.D_d = float(np.asarray(sys.D).item())
        self.Ts = Ts
        # steady state for constant input q0: x = (I - A_d)^-1 B_d q0
        self.x_q = np.linalg.solve(np.eye(2) - self.A_d, self.B_d * q0)

    def step(self, q: float) -> float:
        """Filter one sample of the pitch rate q [rad/s]; returns q' [rad/s]."""
        if not math.isfinite(q):
            raise ValueError(f"notch filter input q must be finite, got {q}")
        y = float(self.C_d @ self.x_q + self.D_d * q)
        self.x_q = self.A_d @ self.x_q + self.B_d * q
        return y
