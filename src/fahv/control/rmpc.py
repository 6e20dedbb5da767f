"""Robust MPC of Kothare, Balakrishnan and Morari (1996): the baseline of sec. 5.2."""

from __future__ import annotations

import math

import numpy as np

from fahv.config import Field, Section
from fahv.control.base import VARIANTS, ControlLaw, LawStep, register_law
from fahv.control.reference import CommandReference
from fahv.errors import DesignError, ParameterError
from fahv.lanes import Lanes
from fahv.model.tp_model import build_tp_model
from fahv.msg import NominalTrajectory
from fahv.synthesis.lmi import SDP_SOLVER, scale_vertices


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

        from fahv.synthesis.nominal import contraction, input_ratio

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

    def step(self, k: int, x: np.ndarray, x_r: np.ndarray, u_r: np.ndarray) -> np.ndarray:
        """Command u (2,) at step k for the measured state x (n,) and the trim x_r, u_r.

        Raises
        ------
        DesignError
            If the very first solve fails (there is no gain to fall back on).
        """
        dx = np.asarray(x, float) - x_r
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
        return u_r + self.K @ dx


def _uses_rmpc(root) -> bool:
    return any(VARIANTS[v].law == "rmpc" for v in root.get("variants", ()) if v in VARIANTS)


def _matrix(name: str, description: str) -> Field:
    return Field(
        name,
        "matrix",
        description,
        when=lambda p: p.get("law") == "rmpc",
        when_text="law is rmpc",
    )


class RMPCLaw(ControlLaw):
    """Kothare robust MPC (1996), the paper's baseline: u = u_r + K_k (x - x_r).

    Offline it builds the DM polytopic LPV model (the model of the baseline in the
    paper) with ``rmpc.vertices``; online :class:`RobustMPC` solves the LMIs
    (33)-(35) every ``resolve_every`` steps, certified after each solve.
    """

    name = "rmpc"
    node = "rmpc"
    nominal = CommandReference
    has_tube = False
    section = Section(
        "rmpc",
        (
            Field("vertices", "ints", "TP vertices of the DM model (h, V)", lo=1, length=2,
                  default=(4, 5), equation="eq. (11)"),
            Field("resolve_every", "int", "steps between LMI solves", lo=1, default=250),
            Field("psi", "float", "state weight of the cost (31), scaled units", lo=0.0,
                  lo_open=True, equation="eq. (31)"),
            Field("sigma", "float", "input weight of the cost (31), scaled units", lo=0.0,
                  lo_open=True, equation="eq. (31)"),
        ),
        "Kothare robust MPC baseline",
        when=_uses_rmpc,
        when_text="a variant uses the law rmpc",
    )  # fmt: skip
    parameters = (
        _matrix("rmpc_A", "RMPC model vertices A_i (R, 9, 9)"),
        _matrix("rmpc_B", "RMPC model vertices B_i (R, 9, 2)"),
        _matrix("u_room", "RMPC input room |u - u_r| <= u_room (2,) [-, rad]"),
        _matrix("psi", "RMPC state weights (9,), scaled units"),
        _matrix("sigma", "RMPC input weights (2,), scaled units"),
        _matrix("Dx", "state scales (9,)"),
        _matrix("Du", "input scales (2,)"),
        Field("resolve_every", "int", "RMPC steps between LMI solves", lo=1, hi=10**7,
              when=lambda p: p.get("law") == "rmpc", when_text="law is rmpc"),
    )  # fmt: skip

    def __init__(self, p: dict, n_runs: int = 1) -> None:
        super().__init__(p, n_runs)
        R = p["rmpc_A"].shape[0] if p["rmpc_A"].ndim == 3 else -1
        for name, shape in (
            ("rmpc_A", (R, 9, 9)),
            ("rmpc_B", (R, 9, 2)),
            ("u_room", (2,)),
            ("psi", (9,)),
            ("sigma", (2,)),
            ("Du", (2,)),
        ):
            if p[name].shape != shape:
                raise ParameterError(
                    f"rmpc: parameter '{name}' has shape {p[name].shape}, expected {shape}"
                )
        if p["Dx"].ndim != 1 or p["Dx"].size < 9:
            raise ParameterError("rmpc: parameter 'Dx' needs at least 9 scales")
        #: one online problem per run (each run re-solves at its own state)
        self.rmpc = [
            RobustMPC(
                p["rmpc_A"], p["rmpc_B"], p["u_room"], p["psi"], p["sigma"], p["Dx"][:9],
                p["Du"], p["resolve_every"],
            )
            for _ in range(n_runs)
        ]  # fmt: skip

    @classmethod
    def design(cls, ctx) -> dict[str, np.ndarray]:
        """DM vertices of the baseline (``rmpc_A``, ``rmpc_B``), discretised at Ts."""
        rv = ctx.case["rmpc"]["vertices"]
        dm = build_tp_model(ctx.vehicle, "dm", rv[0], rv[1], *ctx.case["samples"])
        dmd = dm.discretize(ctx.case["Ts"])
        return {"rmpc_A": dmd.A, "rmpc_B": dmd.B}

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict:
        """The RMPC's arrays, weights and scales."""
        r = case["rmpc"]
        return {
            "rmpc_A": arrays["rmpc_A"],
            "rmpc_B": arrays["rmpc_B"],
            "u_room": arrays["u_room"],
            "psi": np.full(9, float(r["psi"])),
            "sigma": np.full(2, float(r["sigma"])),
            "Dx": arrays["Dx"][:9],
            "Du": arrays["Du"],
            "resolve_every": int(r["resolve_every"]),
        }

    def step(self, k: int, x: np.ndarray, ref: NominalTrajectory, lanes: Lanes) -> LawStep:
        """Commands of step k for B runs, each with its own online LMI problem (no tube).

        A run whose first solve fails fails alone (:class:`~fahv.errors.DesignError`).
        """
        B = x.shape[0]
        u = np.zeros((B, 2))
        lmi = np.zeros((B, 3), dtype=np.int64)
        for b in range(B):
            if not lanes.alive[b]:
                continue
            r = self.rmpc[b]
            try:
                u[b] = r.step(k, x[b, :9], ref.x_r[b, :9], ref.u_r[b])
            except DesignError as exc:
                lanes.fail(b, exc)
            lmi[b] = (r.n_solves, r.n_fallback, r.n_failed)
        return LawStep(u, np.asarray(x, float) - ref.x_r, np.full(B, math.nan), lmi)


register_law(RMPCLaw)
