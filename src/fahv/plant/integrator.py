"""Plant: the nonlinear CM (eq. 1-3) of B vehicles, ZOH input, saturation, actuators, RK4.

One class serves every path: the plant node (B = 1), `fahv simulate` (B = 1) and a
campaign batch (B runs with their own parameters); the integration is the compiled
kernel `fahv.plant.rk4.rk4_cm` with ideal actuators (the paper's plant: the
saturated command is the position) and `fahv.plant.rk4.rk4_cm_act` with servo
dynamics (`fahv.model.actuators`), both imported when the first plant is built,
so that the other nodes of the graph start without numba.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fahv.model.actuators import kernel_parameters
from fahv.model.vehicle import InputLimits, VehicleParams


def rk4_step(f, x: np.ndarray, u: np.ndarray, Ts: float, n_sub: int) -> np.ndarray:
    """Integrate x_dot = f(x, u) over Ts with n_sub classical RK4 steps, u held (ZOH).

    The generic numpy integrator of the offline design (any model function); the
    closed loop uses the compiled `fahv.plant.rk4.rk4_cm`.

    Parameters
    ----------
    f : callable
        f(x, u) -> x_dot.
    x : (n,) or (n, B) ndarray
    u : (m,) or (m, B) ndarray
    Ts : float
        Interval [s].
    n_sub : int
        Number of RK4 steps (dt = Ts / n_sub).

    Returns
    -------
    ndarray
        Shape of x.
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
    """Clip [Phi, delta_e] ((2,) or (B, 2)) to the actuator limits of sec. 5.1."""
    return np.clip(u, limits.u_min, limits.u_max)


class Plant:
    """B vehicles of the nonlinear CM (eq. 1-3) with ZOH input, saturation, actuators and RK4.

    Parameters
    ----------
    params : VehicleParams or sequence of B VehicleParams
        True (possibly perturbed) parameters of each vehicle.
    limits : InputLimits
        Actuator limits (shared).
    x0 : (9,) or (B, 9) array_like
        Initial states.
    Ts : float
        Control period [s].
    n_sub : int
        RK4 steps per period; dt = Ts / n_sub must resolve the flexible modes
        (omega_2 dt well below 1) and the servos (omega_n dt well below 1).
    actuators : dict, optional
        Servo of each input, `{"Phi": Servo, "delta_e": Servo}`
        (`fahv.model.actuators`); None: ideal actuators (no dynamics). The servos
        start at rest at the first command.
    servo_scale : (B, 3) array_like, optional
        Per vehicle, factors on its servos' natural frequency omega_n, damping ratio
        zeta and rate limits (both servos alike; a campaign's actuator dispersion);
        ones by default (the vehicle file's servos, bit for bit).

    Raises
    ------
    ValueError
        If x0 does not have 9 finite values per vehicle, the counts differ, or a
        servo factor is not positive and finite (zeta: not negative).
    """

    def __init__(
        self, params, limits: InputLimits, x0, Ts: float, n_sub: int, actuators=None,
        servo_scale=None,
    ) -> None:
        from fahv.plant import rk4

        plist = [params] if isinstance(params, VehicleParams) else list(params)
        x = np.array(x0, dtype=float, ndmin=2)
        if x.shape != (len(plist), 9) or not np.all(np.isfinite(x)):
            raise ValueError(
                f"plant initial state must be 9 finite values per vehicle ({len(plist)}), "
                f"got shape {np.shape(x0)}"
            )
        self._kernel = rk4.rk4_cm
        self.records = rk4.params_records(plist)
        self.params: Sequence[VehicleParams] = plist
        self.limits, self.Ts, self.n_sub = limits, float(Ts), int(n_sub)
        self.x = x
        #: Servo data (B, 2, 6) of the kernel, each vehicle's; None for ideal actuators.
        self.servos = None
        if actuators is not None:
            self._kernel_act = rk4.rk4_cm_act
            self.servos = scaled_servos(
                kernel_parameters(actuators, limits.u_min, limits.u_max),
                np.ones((len(plist), 3)) if servo_scale is None else servo_scale,
            )  # fmt: skip
        #: Actuator states (B, 4) [Phi, Phi_dot 1/s, delta_e rad, delta_e_dot rad/s]
        #: (None before the first step; rates zero for ideal actuators).
        self.a: np.ndarray | None = None
        #: Each servo's peak |rate| (B, 2) [1/s, rad/s] within the last period (None
        #: before the first step and for ideal actuators, which have no rate).
        self.rate_peak: np.ndarray | None = None
        rk4.compile_kernels(self.records, self.servos)  # now, not in a timed step

    @property
    def positions(self) -> np.ndarray | None:
        """Actuator positions (B, 2) [Phi, delta_e rad] now (None before the first step)."""
        return None if self.a is None else self.a[:, ::2].copy()

    def step(self, u_applied: np.ndarray, held: np.ndarray | None = None) -> np.ndarray:
        """Advance one period with the inputs u_applied (B, 2), saturated; returns x (B, 9).

        Parameters
        ----------
        u_applied : (B, 2) array_like
            Commands [Phi, delta_e rad] at the actuators, held over the period.
        held : (B,) bool array_like, optional
            Runs whose elevator actuator is held at its position (fault `stuck`;
            used only with servo dynamics: for ideal actuators the held command is
            the position).

        Returns
        -------
        (B, 9) ndarray
            The airframe states at the end of the period.

        Raises
        ------
        ValueError
            If an input is not finite (the state is left unchanged).
        """
        u = saturate(np.asarray(u_applied, float).reshape(-1, 2), self.limits)
        if not np.all(np.isfinite(u)):
            raise ValueError(f"plant input must be finite, got {np.asarray(u_applied)!r}")
        u = np.ascontiguousarray(u)
        if self.servos is None:
            self.x = self._kernel(self.x, u, self.records, self.Ts, self.n_sub)
            self.a = np.zeros((len(u), 4))
            self.a[:, ::2] = u
            return self.x
        if self.a is None:  # the servos start at rest at the first command
            self.a = np.zeros((len(u), 4))
            self.a[:, ::2] = u
        hold = np.zeros(len(u), bool) if held is None else np.asarray(held, bool).reshape(-1)
        self.x, self.a, self.rate_peak = self._kernel_act(
            self.x, self.a, u, self.records, self.servos, np.ascontiguousarray(hold),
            self.Ts, self.n_sub,
        )  # fmt: skip
        return self.x


#: Columns of a servo factor row (`scaled_servos`): what each multiplies.
SERVO_FACTORS = ("omega_n", "zeta", "rate_limit")


def scaled_servos(servos: np.ndarray, factors) -> np.ndarray:
    """Each vehicle's servo data: `servos` with its natural frequency, damping, rates scaled.

    Parameters
    ----------
    servos : (2, 6) ndarray
        Kernel rows of the vehicle file's servos [zeta, omega_n, rate_limit_incr,
        rate_limit_decr, min, max] (`fahv.model.actuators.kernel_parameters`).
    factors : (B, 3) array_like
        Per vehicle, factors on omega_n, zeta and both rate limits (`SERVO_FACTORS`),
        applied to both servos; a factor of 1 keeps the value bit for bit.

    Returns
    -------
    (B, 2, 6) ndarray
        The kernel's servo data of each vehicle (`fahv.plant.rk4.rk4_cm_act`).

    Raises
    ------
    ValueError
        If `factors` is not (B, 3), an omega_n or rate factor is not > 0, a zeta
        factor is negative, or one is not finite.
    """
    f = np.asarray(factors, dtype=float)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"servo factors of shape {f.shape}, expected (B, 3) {SERVO_FACTORS}")
    bad = ~np.isfinite(f) | (f[:, [0, 2]] <= 0.0).any(axis=1)[:, None] | (f[:, [1]] < 0.0)
    if bad.any():
        b = int(np.flatnonzero(bad.any(axis=1))[0])
        given = dict(zip(SERVO_FACTORS, f[b].tolist(), strict=True))
        raise ValueError(f"servo factors {given} of vehicle {b}: omega_n and rate_limit "
                         "must be > 0, zeta >= 0")  # fmt: skip
    out = np.repeat(np.asarray(servos, dtype=np.float64)[None], len(f), axis=0)
    out[:, :, 1] *= f[:, 0:1]
    out[:, :, 0] *= f[:, 1:2]
    out[:, :, 2:4] *= f[:, 2:3, None]
    return np.ascontiguousarray(out)
