"""Notch filter on the pitch-rate channel, eq. (37)-(39) of Yang et al. 2022.

Continuous transfer function (eq. 38):

    H(s) = (s^2/omega_z^2 + 2 eps_z s/omega_z + 1) / (s^2/omega_p^2 + 2 eps_p s/omega_p + 1)

The transfer function, the discretisation and the frequency responses come from
python-control. The state-space form of eq. (39) is the controllable canonical
realisation, written out (equal bit for bit to `control.tf2ss`, tested) together with
the per-sample update used by the simulator, the batch and the nodes: a node builds its
filter without python-control, whose import (with scipy.signal and matplotlib) took
0.9 s of each filtering node's start-up (docs/guide/sil.md). python-control is imported
where it is used, not with this module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import control


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

    Examples
    --------
    The notch of `cm_certified`: at its centre the gain is eps_z / eps_p, at 0 it is 1.

    >>> nf = NotchFilter(omega_z=19.05, eps_z=0.02, omega_p=19.05, eps_p=0.1)
    >>> num, den = nf.coefficients()
    >>> def gain(w):
    ...     return float(abs(np.polyval(num, 1j * w) / np.polyval(den, 1j * w)))
    >>> round(gain(19.05), 12), round(gain(0.0), 12)
    (0.2, 1.0)
    >>> NotchFilter(19.05, 0.02, 19.05, 0.0)
    Traceback (most recent call last):
        ...
    ValueError: notch filter 'eps_p' must be > 0 for a stable filter
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
        """Continuous transfer function H(s) of eq. (38) (python-control).

        Returns
        -------
        control.TransferFunction
            H(s), s in rad/s.
        """
        import control

        num, den = self.coefficients()
        return control.tf(num, den)

    def coefficients(self) -> tuple[np.ndarray, np.ndarray]:
        """Numerator and denominator of eq. (38), each (3,), highest power of s first.

        Returns
        -------
        num : (3,) ndarray
            (1 / omega_z^2, 2 eps_z / omega_z, 1) [s^2, s, -].
        den : (3,) ndarray
            (1 / omega_p^2, 2 eps_p / omega_p, 1) [s^2, s, -].
        """
        num = np.array([1.0 / self.omega_z**2, 2.0 * self.eps_z / self.omega_z, 1.0])
        den = np.array([1.0 / self.omega_p**2, 2.0 * self.eps_p / self.omega_p, 1.0])
        return num, den

    def ss(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """State-space form of eq. (39): A_q (2, 2), B_q (2,), C_q (2,), D_q scalar.

        The controllable canonical realisation of eq. (38) (the one of
        `control.tf2ss` and `scipy.signal.tf2ss`, equal to them bit for bit, tested),
        written out so that a node builds its filter without importing python-control:
        with n(s) = n_0 s^2 + n_1 s + n_2 and d(s) = d_0 s^2 + d_1 s + d_2 divided by d_0,
        A_q = [[-d_1, -d_2], [1, 0]], B_q = (1, 0), C_q = (n_1 - n_0 d_1, n_2 - n_0 d_2),
        D_q = n_0; with `omega_z = omega_p` D_q = 1.

        Returns
        -------
        A_q : (2, 2) ndarray
        B_q : (2,) ndarray
        C_q : (2,) ndarray
        D_q : float
            The realisation x_q_dot = A_q x_q + B_q q, q' = C_q x_q + D_q q (q in rad/s).

        Examples
        --------
        >>> A_q, B_q, C_q, D_q = NotchFilter(19.05, 0.02, 19.05, 0.1).ss()
        >>> np.round(A_q, 6).tolist()  # [[-2 eps_p omega_p, -omega_p^2], [1, 0]]
        [[-3.81, -362.9025], [1.0, 0.0]]
        >>> B_q.tolist(), np.round(C_q, 6).tolist(), D_q  # C_q = (2 (eps_z - eps_p) omega, 0)
        ([1.0, 0.0], [-3.048, 0.0], 1.0)
        """
        num, den = self.coefficients()
        n, d = num / den[0], den / den[0]
        A = np.array([[-d[1], -d[2]], [1.0, 0.0]])
        return A, np.array([1.0, 0.0]), n[1:] - n[0] * d[1:], float(n[0])

    def state_scale(self, q_scale: float) -> np.ndarray:
        """Typical magnitudes of (x_q1, x_q2) for a pitch-rate magnitude `q_scale`.

        In the controllable canonical form of `ss` x_q2 is q filtered by
        1/(s^2 + 2 eps_p omega_p s + omega_p^2) and x_q1 its derivative, so
        x_q1 ~ q/omega_p and x_q2 ~ q/omega_p^2; used to scale the ECM.

        Parameters
        ----------
        q_scale : float
            Typical pitch-rate magnitude [rad/s].

        Returns
        -------
        (2,) ndarray
            Typical magnitudes of x_q1 [rad] and x_q2 [rad s].

        Examples
        --------
        >>> NotchFilter(20.0, 0.02, 20.0, 0.1).state_scale(1.0).tolist()
        [0.05, 0.0025]
        """
        return np.array([q_scale / self.omega_p, q_scale / self.omega_p**2])

    def discretize(self, Ts: float) -> control.StateSpace:
        """Discrete filter at sampling period Ts [s]: Tustin, prewarped at omega_z.

        Prewarping keeps the notch centre exactly at omega_z after discretisation.

        Parameters
        ----------
        Ts : float
            Sampling period [s].

        Returns
        -------
        control.StateSpace
            The discrete filter, sampling period Ts.

        Raises
        ------
        ValueError
            If Ts <= 0 or omega_z is not below the Nyquist frequency pi/Ts.
        """
        self.check_sampling(Ts)
        import control

        return control.c2d(
            control.ss(self.tf()), Ts, method="tustin", prewarp_frequency=self.omega_z
        )

    def check_sampling(self, Ts: float) -> None:
        """Check that the filter can be sampled at Ts [s].

        Parameters
        ----------
        Ts : float
            Sampling period [s].

        Raises
        ------
        ValueError
            If Ts <= 0 or omega_z is not below the Nyquist frequency pi/Ts.

        Examples
        --------
        >>> nf = NotchFilter(19.05, 0.02, 19.05, 0.1)
        >>> nf.check_sampling(0.02)
        >>> nf.check_sampling(0.2)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
            ...
        ValueError: notch frequency omega_z = 19.05 rad/s is not below the Nyquist frequency ...
        """
        if not (math.isfinite(Ts) and Ts > 0.0):
            raise ValueError(f"sampling period Ts must be > 0, got {Ts}")
        if self.omega_z >= math.pi / Ts:
            raise ValueError(
                f"notch frequency omega_z = {self.omega_z} rad/s is not below the Nyquist "
                f"frequency pi/Ts = {math.pi / Ts:.3f} rad/s"
            )

    def magnitude(self, omega) -> np.ndarray:
        """|H(j omega)| of the continuous filter at the frequencies `omega`.

        Parameters
        ----------
        omega : float or (k,) array_like
            Frequencies [rad/s].

        Returns
        -------
        (k,) ndarray
            The gains [-].
        """
        import control

        resp = control.frequency_response(self.tf(), np.atleast_1d(np.asarray(omega, float)))
        return np.abs(np.asarray(resp.complex)).ravel()


class DiscreteNotch:
    """Per-sample notch filter q -> q' of B runs at once (simulator, batch and node).

    Parameters
    ----------
    notch : NotchFilter
    Ts : float
        Sampling period [s].
    q0 : float or (B,) array_like
        Pitch rate [rad/s] at which each filter starts in steady state (0 at trim);
        its length gives the number of runs B (a float: B = 1).

    Raises
    ------
    ValueError
        If Ts is invalid for the notch frequency or q0 is not finite.

    Notes
    -----
    Tustin (bilinear) discretisation prewarped at omega_z, written as the trapezoidal
    rule on the continuous state of eq. (39) with alpha = tan(omega_z Ts / 2) / omega_z:

        x_q(k) = (I - alpha A_q)^-1 [(I + alpha A_q) x_q(k-1) + alpha B_q (q(k-1) + q(k))]
        q'(k)  = C_q x_q(k) + D_q q(k)

    Its transfer function is that of `NotchFilter.discretize` (python-control's
    `c2d(..., "tustin", prewarp_frequency=omega_z)`, checked in the tests), and its
    state `x_q` (B, 2) is in the coordinates of the continuous filter, i.e. the
    x_q1, x_q2 of the ECM state (eq. 43) that the adjustable Tube-MPC feeds back.
    Each run's products are the BLAS calls of one (2, 2) @ (2,) product, so a run's
    output does not depend on B.

    Examples
    --------
    From steady state a constant rate passes unchanged; the prewarped discretisation
    keeps the continuous depth eps_z / eps_p at omega_z exactly:

    >>> nf = NotchFilter(19.05, 0.02, 19.05, 0.1)
    >>> f = DiscreteNotch(nf, Ts=0.02, q0=0.5)
    >>> [round(float(q), 12) for q in f.step([0.5])]
    [0.5]
    >>> z = np.exp(1j * nf.omega_z * f.Ts)  # transfer function of the recursion at omega_z
    >>> H = f.C_q @ np.linalg.solve(z * np.eye(2) - f.A_d, f.B_d) * (z + 1.0) + f.D_q
    >>> round(float(abs(H)), 9)
    0.2
    """

    def __init__(self, notch: NotchFilter, Ts: float, q0=0.0) -> None:
        notch.check_sampling(Ts)
        A, B, C, D = notch.ss()
        A, B, C = np.asarray(A, float), np.asarray(B, float).ravel(), np.asarray(C, float)
        alpha = math.tan(notch.omega_z * Ts / 2.0) / notch.omega_z
        M = np.linalg.inv(np.eye(2) - alpha * A)
        self.A_d = M @ (np.eye(2) + alpha * A)
        self.B_d = alpha * M @ B
        self.C_q, self.D_q, self.Ts = C.ravel(), float(D), Ts
        q0 = np.atleast_1d(np.asarray(q0, dtype=float))
        if not np.all(np.isfinite(q0)):
            raise ValueError(f"notch filter initial pitch rate q0 must be finite, got {q0}")
        # steady state of eq. (39) for q = q0, per run
        self.x_q = np.stack([-np.linalg.solve(A, B * q) for q in q0])
        self.q_prev = q0.copy()

    def step(self, q) -> np.ndarray:
        """Filter one sample of the pitch rates q (B,) [rad/s]; returns q' (B,) [rad/s].

        Parameters
        ----------
        q : float or (B,) array_like
            The pitch rate of each run at this sample [rad/s].

        Returns
        -------
        (B,) ndarray
            The filtered pitch rates q' [rad/s].

        Raises
        ------
        ValueError
            If a q is not finite (the filter state is left unchanged).
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        if not np.all(np.isfinite(q)):
            raise ValueError(f"notch filter input q must be finite, got {q}")
        self.x_q = (
            np.matmul(self.A_d, self.x_q[:, :, None])[..., 0]
            + self.B_d[None, :] * (self.q_prev + q)[:, None]
        )
        self.q_prev = q.copy()
        return np.matmul(self.x_q[:, None, :], self.C_q)[:, 0] + self.D_q * q
