"""Online parts of the control laws: nominal trajectory, Tube-MPC (eq. 36 / 54), RMPC.

One step of the loop (ARCHITECTURE.md), all in deviation coordinates around the trim
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

from fahv.errors import DesignError
from fahv.tp_model import tp_weights
from fahv.tube.lmi import SDP_SOLVER, scale_vertices

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
class PolytopicLPV:
    """Discrete polytopic LPV model, eq. (12), with its TP weighting functions.

    Attributes
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices A_i, B_i (unscaled, deviation coordinates).
    h_grid, V_grid : ndarray
    W_h, W_V : ndarray
        Sampled weighting functions (see :func:`fahv.tp_model.tp_weights`).
    """

    A: np.ndarray
    B: np.ndarray
    h_grid: np.ndarray
    V_grid: np.ndarray
    W_h: np.ndarray
    W_V: np.ndarray

    def __post_init__(self) -> None:
        R, n, _ = self.A.shape
        if self.A.shape != (R, n, n) or self.B.shape[:2] != (R, n):
            raise ValueError(f"LPV vertex shapes do not match: A {self.A.shape}, B {self.B.shape}")
        if self.W_h.shape[1] * self.W_V.shape[1] != R:
            raise ValueError(
                f"LPV weighting functions give {self.W_h.shape[1]} x {self.W_V.shape[1]} "
                f"vertices, but there are {R} vertex systems"
            )

    def system(self, h: float, V: float) -> tuple[np.ndarray, np.ndarray]:
        """(A(p) (n, n), B(p) (n, m)) = sum_i tau_i(p) [A_i, B_i] at p = (h, V)."""
        w = tp_weights(h, V, self.h_grid, self.V_grid, self.W_h, self.W_V)
        return np.tensordot(w, self.A, axes=1), np.tensordot(w, self.B, axes=1)


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
    ellipsoid E(Q) of :func:`fahv.tube.nominal.design_nominal` (incremental
    reference governor, Gilbert & Kolmanovsky 2002). Since E(Q) is invariant with
    contraction < 1, s = 0 is always admissible, so x_n stays in E(Q) and
    |u_n,j| <= u_n,max,j at every step, by construction.

    Parameters
    ----------
    lpv : PolytopicLPV
        Nominal (healthy) discrete LPV model.
    trim_map : callable
        (h, V) -> (x_r (n,), u_r (2,)), e.g. :class:`fahv.trim.TrimMap`.
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


class TubeMPC:
    """Tube-MPC control law, eq. (36); with tau < 1 the adjustable law, eq. (54).

    u = u_r + u_n + tau F (x - x_r - x_n).

    Parameters
    ----------
    F : (m, n) ndarray
        Robust feedback gain (LMI 24).
    N : (n, n) ndarray
        Tube shape Z = {e : e' N^-1 e <= 1}.
    tau : float
        Adjustable factor in (0, 1] (1 for the baseline law); the tube is tau Z.
    """

    def __init__(self, F, N, tau: float = 1.0) -> None:
        self.F, N = np.asarray(F, float), np.asarray(N, float)
        n = self.F.shape[1]
        if N.shape != (n, n):
            raise ValueError(f"tube shape N {N.shape} does not match F {self.F.shape}")
        if not 0.0 < tau <= 1.0:
            raise ValueError(f"adjustable factor tau must be in (0, 1], got {tau}")
        self.N_inv = np.linalg.inv(N)
        self.tau = float(tau)

    def error(self, x: np.ndarray, ref: NominalOutput) -> np.ndarray:
        """Tube error e = x - x_r - x_n (n,)."""
        return np.asarray(x, float) - ref.x_r - ref.x_n

    def tube_level(self, e: np.ndarray) -> float:
        """Tube level e' (tau^2 N)^-1 e: <= 1 when e is inside the tube tau Z."""
        return float(e @ self.N_inv @ e) / self.tau**2

    def step(self, x: np.ndarray, ref: NominalOutput) -> np.ndarray:
        """Command u (2,) [Phi, delta_e rad] for the measured state x (n,).

        Raises
        ------
        ValueError
            If x has the wrong shape or is not finite.
        """
        x = np.asarray(x, float)
        if x.shape != (self.F.shape[1],) or not np.all(np.isfinite(x)):
            raise ValueError(f"controller state must be {self.F.shape[1]} finite values")
        return ref.u_r + ref.u_n + self.tau * self.F @ self.error(x, ref)


class RobustMPC:
    """The "traditional" robust MPC of Kothare, Balakrishnan & Morari (1996), sec. 5.2.

    At every ``resolve_every``-th step, minimise gamma subject to (33)-(35) with the
    current state x(k) - x_r (in place of x_n; x_r the trim of the raw command, no
    governor) and the full input room (no tube), and apply u = u_r + K (x - x_r)
    until the next solve.

    Each solve is certified numerically: contraction of E(Q) < 1 for every vertex,
    the input bound on E(Q), and x(k) - x_r inside E(Q). When the min-gamma solve
    is not certified (large set-point steps put its optimum on the edge of
    feasibility, where gamma ~ 1e6 and interior-point solvers lose accuracy), the
    same LMIs are solved for the largest margin s (s (x - x_r) in E(Q), s <= 1.1)
    and that feasible, certified (Q, Y) is used: it is still a Kothare gain, only
    not cost-optimal (counted in ``n_fallback``). If both fail, the previous gain
    is kept and the failure is counted (``n_failed``).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices of the design model (the DM LPV model in the paper).
    u_room : (m,) ndarray
        Input bounds |u - u_r| <= u_room.
    psi : (n,) ndarray
    sigma : (m,) ndarray
        Diagonal weights of (31), scaled units.
    Dx, Du : ndarray
        State and input scales.
    resolve_every : int
        Steps between LMI solves (>= 1).

    Raises
    ------
    ValueError
        If ``resolve_every`` < 1.
    """

    #: Upper bound on the margin s of the fallback problem (s >= 1 is required).
    S_CAP = 1.1

    def __init__(self, A, B, u_room, psi, sigma, Dx, Du, resolve_every: int) -> None:
        if resolve_every < 1:
            raise ValueError(f"RMPC resolve_every must be >= 1, got {resolve_every}")
        import cvxpy as cp  # imported here: the other controllers start without it

        As, Bs = scale_vertices(np.asarray(A, float), np.asarray(B, float), Dx, Du)
        R, n, m = Bs.shape
        self.Dx, self.Du, self.resolve_every = np.asarray(Dx), np.asarray(Du), resolve_every
        self._As, self._Bs = As, Bs
        self.u_room_s = np.asarray(u_room, float) / self.Du
        self._x0 = cp.Parameter(n)
        Qv = cp.Variable((n, n), symmetric=True)
        Y = cp.Variable((m, n))
        g = cp.Variable()
        Xd = cp.Variable(m)
        s = cp.Variable()
        ps, ss = np.sqrt(np.asarray(psi, float)), np.sqrt(np.asarray(sigma, float))
        lmis = [Xd <= self.u_room_s**2]  # (33)-(35) without the initial-state LMI
        for i in range(R):
            AQ = As[i] @ Qv + Bs[i] @ Y
            blk = cp.bmat(
                [
                    [Qv, AQ.T, Qv @ np.diag(ps), Y.T @ np.diag(ss)],
                    [AQ, Qv, np.zeros((n, n)), np.zeros((n, m))],
                    [np.diag(ps) @ Qv, np.zeros((n, n)), g * np.eye(n), np.zeros((n, m))],
                    [np.diag(ss) @ Y, np.zeros((m, n)), np.zeros((m, n)), g * np.eye(m)],
                ]
            )
            lmis.append(0.5 * (blk + blk.T) >> 0)
        blk = cp.bmat([[cp.diag(Xd), Y], [Y.T, Qv]])
        lmis.append(0.5 * (blk + blk.T) >> 0)

        def contains(x):  # x' Q^-1 x <= 1 as an LMI (33)
            return cp.bmat([[np.ones((1, 1)), x[None, :]], [x[:, None], Qv]]) >> 0

        self._prob = cp.Problem(cp.Minimize(g), [contains(self._x0), *lmis])
        self._prob_margin = cp.Problem(
            cp.Maximize(s), [contains(s * self._x0), s <= self.S_CAP, *lmis]
        )
        self._Q, self._Y = Qv, Y
        self.K = np.zeros((m, n))
        self.Q_s = None  # scaled Q of the gain in use
        self.n_solves = 0
        self.n_fallback = 0
        self.n_failed = 0
        self.have_gain = False

    def _certified_gain(self, prob, x0s: np.ndarray) -> tuple | None:
        """Solve ``prob``; (K, Q) in scaled units if its result is certified, else None."""
        import cvxpy as cp

        from fahv.tube.nominal import contraction, input_ratio

        try:
            prob.solve(solver=SDP_SOLVER)
        except cp.error.SolverError:
            return None
        if prob.status not in ("optimal", "optimal_inaccurate") or self._Q.value is None:
            return None
        Qs = 0.5 * (self._Q.value + self._Q.value.T)
        try:
            Ks = self._Y.value @ np.linalg.inv(Qs)
            c = contraction(self._As, self._Bs, Ks, Qs)
        except np.linalg.LinAlgError:  # Q singular or not positive definite
            return None
        ratio = input_ratio(Ks, Qs, self.u_room_s)
        level = float(x0s @ np.linalg.solve(Qs, x0s))
        if not (c < 1.0 and np.all(ratio <= 1.0 + 1e-6) and level <= 1.0 + 1e-6):
            return None
        return Ks, Qs

    def _solve(self, dx: np.ndarray) -> bool:
        x0s = dx / self.Dx
        self._x0.value = x0s
        self.n_solves += 1
        gain = self._certified_gain(self._prob, x0s)
        if gain is None:
            gain = self._certified_gain(self._prob_margin, x0s)
            if gain is None:
                return False
            self.n_fallback += 1
        Ks, self.Q_s = gain
        self.K = Ks * self.Du[:, None] / self.Dx[None, :]
        return True

    def step(self, k: int, x: np.ndarray, ref: NominalOutput) -> np.ndarray:
        """Command u (2,) at step k for the measured state x (n,) and reference ref.

        Raises
        ------
        DesignError
            If the very first solve fails (there is no gain to fall back on).
        """
        dx = np.asarray(x, float) - ref.x_r
        if k % self.resolve_every == 0:
            if self._solve(dx):
                self.have_gain = True
            else:
                self.n_failed += 1
                if not self.have_gain:
                    raise DesignError(
                        "RMPC: the first LMI solve (33)-(35) failed: no invariant "
                        "ellipsoid contains the initial state within the input room"
                    )
        return ref.u_r + self.K @ dx


__all__ = [
    "Command",
    "PolytopicLPV",
    "NominalOutput",
    "NominalTrajectory",
    "TubeMPC",
    "RobustMPC",
]
