"""Online parts of the control laws: nominal trajectory, Tube-MPC (eq. 36 / 54), RMPC.

One step of the loop (docs/architecture.md), all in deviation coordinates around the trim
x_r(g), u_r(g) of the governed reference g = (h_g, V_g)::

    NominalTrajectory.step()       -> x_r, u_r, x_n, u_n = K x_n         (eq. 20, 33-35)
    TubeMPC.step(x, ref)           -> u = u_r + u_n + tau F (x - x_r - x_n)   (eq. 36/54)
    RobustMPC.step(k, x, ref)      -> u = u_r + K_k (x - x_r)        (Kothare et al. 1996)

The classes hold only numbers from the offline design (no solver in the Tube-MPC
path), so the simulator and the ROS 2 nodes compute the same values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

COMMAND_KINDS = ("step", "ramp")


@dataclass(frozen=True)
class Command:
    """Altitude and speed command of a case (sec. 5.1).

    Attributes
    ----------
    h0, V0 : float
        Initial trim [ft, ft/s].
    h_c, V_c : float
        Final command [ft, ft/s].
    t_start : float
        Time the command starts to change [s].
    kind : {"step", "ramp"}
        Step at t_start (Case 1) or constant-rate ramp from t_start to
        t_start + t_ramp (Case 2).
    t_ramp : float
        Ramp duration [s] (ignored for a step).

    Raises
    ------
    ValueError
        On an unknown kind, a non-finite value or t_ramp <= 0 for a ramp.
    """

    h0: float
    V0: float
    h_c: float
    V_c: float
    t_start: float = 0.0
    kind: str = "step"
    t_ramp: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in COMMAND_KINDS:
            raise ValueError(f"command kind must be one of {COMMAND_KINDS}, got {self.kind!r}")
        vals = (self.h0, self.V0, self.h_c, self.V_c, self.t_start, self.t_ramp)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"command values must be finite: {self}")
        if self.kind == "ramp" and self.t_ramp <= 0.0:
            raise ValueError(f"ramp command needs t_ramp > 0, got {self.t_ramp}")

    def __call__(self, t: float) -> tuple[float, float]:
        """Commanded (h_c [ft], V_c [ft/s]) at time t [s]."""
        if t < self.t_start:
            f = 0.0
        elif self.kind == "step":
            f = 1.0
        else:
            f = min(1.0, (t - self.t_start) / self.t_ramp)
        return self.h0 + f * (self.h_c - self.h0), self.V0 + f * (self.V_c - self.V0)


@dataclass(frozen=True)
class NominalOutput:
    """Reference and nominal trajectory of one step (the nominal_trajectory message).

    Attributes
    ----------
    h_g, V_g : float
        Governed reference point [ft, ft/s].
    x_r : (n,) ndarray
    u_r : (2,) ndarray
        Trim state and input at (h_g, V_g).
    x_n : (n,) ndarray
        Nominal state, deviation from x_r.
    u_n : (2,) ndarray
        Nominal input K x_n.
    level : float
        x_n' Q^-1 x_n (<= 1 inside the certified ellipsoid).
    """

    h_g: float
    V_g: float
    x_r: np.ndarray
    u_r: np.ndarray
    x_n: np.ndarray
    u_n: np.ndarray
    level: float


class NominalTrajectory:
    """Nominal system (eq. 20 / 46) under u_n = K x_n, with a reference governor.

    The nominal state is X_n = x_r(g) + x_n. Each step it moves by the nominal LPV
    model scheduled at the governed reference g, and g moves toward the command
    c(t) by the largest fraction s in [0, 1] that keeps x_n in the certified
    ellipsoid E(Q) of :func:`fahv.synthesis.nominal.design_nominal` (incremental
    reference governor, Gilbert & Kolmanovsky 2002). Since E(Q) is invariant with
    contraction < 1, s = 0 is always admissible, so x_n stays in E(Q) and
    |u_n,j| <= u_n,max,j at every step, by construction.

    Parameters
    ----------
    lpv : PolytopicLPV
        Nominal (healthy) discrete LPV model.
    trim_map : callable
        (h, V) -> (x_r (n,), u_r (2,)), e.g. :class:`fahv.model.trim.TrimMap`.
    K : (m, n) ndarray
    Q : (n, n) ndarray
        Nominal gain and certified ellipsoid.
    command : Command
    Ts : float
        Sampling period [s].
    level_max : float
        Governor bound on x_n' Q^-1 x_n (<= 1).

    Raises
    ------
    ValueError
        On inconsistent shapes or a non-positive-definite Q.
    """

    def __init__(self, lpv, trim_map, K, Q, command: Command, Ts: float, level_max=0.999):
        n = lpv.A.shape[1]
        K, Q = np.asarray(K, float), np.asarray(Q, float)
        if K.shape != (lpv.B.shape[2], n) or Q.shape != (n, n):
            raise ValueError(f"nominal K {K.shape} / Q {Q.shape} do not match n = {n}")
        try:
            np.linalg.cholesky(Q)
        except np.linalg.LinAlgError:
            raise ValueError("nominal ellipsoid Q must be positive definite") from None
        self.lpv, self.trim_map, self.K, self.command, self.Ts = lpv, trim_map, K, command, Ts
        self.P = np.linalg.inv(Q)
        self.level_max = float(level_max)
        self.k = 0
        self.g = (command.h0, command.V0)
        self.x_n = np.zeros(n)
        self.x_r, self.u_r = trim_map(*self.g)

    def reset(self, x0: np.ndarray) -> None:
        """Start at step 0 with the nominal state on the measured state x0 (n,)."""
        self.k = 0
        self.g = (self.command.h0, self.command.V0)
        self.x_r, self.u_r = self.trim_map(*self.g)
        self.x_n = np.asarray(x0, float) - self.x_r
        if self._level(self.x_n) > self.level_max:
            raise ValueError(
                "initial state is outside the certified nominal ellipsoid: start the "
                "case closer to its initial trim"
            )

    def _level(self, x: np.ndarray) -> float:
        return float(x @ self.P @ x)

    def output(self) -> NominalOutput:
        """Reference and nominal trajectory of the current step."""
        return NominalOutput(
            self.g[0],
            self.g[1],
            self.x_r.copy(),
            self.u_r.copy(),
            self.x_n.copy(),
            self.K @ self.x_n,
            self._level(self.x_n),
        )

    def advance(self) -> None:
        """Propagate the nominal model one step and move the governed reference."""
        A, B = self.lpv.system(*self.g)
        x_pred = A @ self.x_n + B @ (self.K @ self.x_n)
        self.k += 1
        c = self.command(self.k * self.Ts)
        dh, dV = c[0] - self.g[0], c[1] - self.g[1]

        def candidate(s):
            x_r, u_r = self.trim_map(self.g[0] + s * dh, self.g[1] + s * dV)
            return x_r, u_r, x_pred - (x_r - self.x_r)

        best = (0.0, self.x_r, self.u_r, x_pred)
        if dh != 0.0 or dV != 0.0:
            x_r, u_r, x_n = candidate(1.0)
            if self._level(x_n) <= self.level_max:
                best = (1.0, x_r, u_r, x_n)
            else:
                lo, hi = 0.0, 1.0
                for _ in range(30):
                    mid = 0.5 * (lo + hi)
                    x_r, u_r, x_n = candidate(mid)
                    if self._level(x_n) <= self.level_max:
                        lo, best = mid, (mid, x_r, u_r, x_n)
                    else:
                        hi = mid
        s, self.x_r, self.u_r, self.x_n = best
        self.g = (self.g[0] + s * dh, self.g[1] + s * dV)

    def step(self) -> NominalOutput:
        """Output of the current step, then advance: the per-step call of the node."""
        out = self.output()
        self.advance()
        return out


class CommandReference:
    """Reference of the traditional RMPC: trim of the raw command, x_n = 0, no governor.

    Parameters
    ----------
    trim_map : callable
        (h, V) -> (x_r (n,), u_r (2,)).
    command : Command
    n : int
        Design-model state dimension.
    Ts : float
        Sampling period [s].
    """

    def __init__(self, trim_map, command: Command, n: int, Ts: float) -> None:
        self.trim_map, self.command, self.n, self.Ts, self.k = trim_map, command, n, Ts, 0

    def step(self) -> NominalOutput:
        """Reference of the current step (x_n = 0, u_n = 0), then advance one step."""
        h, V = self.command(self.k * self.Ts)
        x_r, u_r = self.trim_map(h, V)
        self.k += 1
        return NominalOutput(h, V, x_r, u_r, np.zeros(self.n), np.zeros(2), math.nan)
