"""Nominal parts of the paper's law and of the RMPC baseline, over B runs at once.

* `ReferenceGovernor` (`governor`): the nominal system of eq. (20)/(46) under
  u_n = K x_n (K of LMIs 33-35) with an incremental reference governor; the nominal
  part of the paper's Tube-MPC (`tube_mpc_paper`).
* `CommandReference` (`command`): the trim of the raw command, x_n = 0; the
  reference of the traditional robust MPC of sec. 5.2.

Both are `fahv.control.base.NominalSource` s: the nominal_trajectory node (B = 1),
`fahv simulate` (B = 1) and a campaign batch call the same `step`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fahv.control.base import NominalSource, register_nominal
from fahv.control.command import Command, CommandSchedule
from fahv.lanes import Lanes
from fahv.model.lpv import PolytopicLPV
from fahv.model.trim import TrimMap
from fahv.msg import NominalTrajectory


def lpv_of(p: dict) -> PolytopicLPV:
    """The nominal LPV model (eq. 12) of a nominal_trajectory node's parameters."""
    return PolytopicLPV(p["A"], p["B"], p["h_grid"], p["V_grid"], p["W_h"], p["W_V"])


def trim_map_of(p: dict) -> TrimMap:
    """The trim map of a nominal_trajectory node's parameters."""
    return TrimMap(p["trim_h"], p["trim_V"], p["trim_x"], p["trim_u"])


def quad(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """x_b' M x_b (B,) for x (B, n): each run's `x @ M @ x` (the same BLAS calls)."""
    return (np.matmul(x[:, None, :], M) @ x[:, :, None])[:, 0, 0]


def mv(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """M @ x_b (B, m) for x (B, n): each run's `M @ x` (a stacked matrix-vector product)."""
    return np.matmul(M, x[:, :, None])[..., 0]


def counters(n: int) -> np.ndarray:
    """Zero QP counters of n runs (nominal parts without an online QP)."""
    return np.zeros(n, dtype=np.int64)


@register_nominal
class ReferenceGovernor(NominalSource):
    """Nominal system (eq. 20 / 46) under u_n = K x_n, with a reference governor.

    The nominal state is X_n = x_r(g) + x_n. Each step it moves by the nominal LPV
    model scheduled at the governed reference g, and g moves toward the command
    c(t) by the largest fraction s in [0, 1] that keeps x_n in the certified
    ellipsoid E(Q) of `fahv.synthesis.nominal.design_nominal` (incremental
    reference governor, Gilbert & Kolmanovsky 2002: the full step if admissible,
    else a 30-halving bisection on s). Since E(Q) is invariant with contraction
    < 1, s = 0 is always admissible, so x_n stays in E(Q) and |u_n,j| <= u_n,max,j at
    every step, by construction.

    Parameters
    ----------
    p, runs, lanes
        As `fahv.control.base.NominalSource`; uses `A`, `B`, the TP weights,
        `K`, `Q`, `level_max`, the trim map, each run's command and `x0`.

    Raises
    ------
    ValueError
        On a non-positive-definite Q, or a run whose initial state lies outside the
        certified ellipsoid (start the case closer to its initial trim).
    """

    name = "governor"

    def __init__(self, p: dict, runs: Sequence[dict], lanes: Lanes) -> None:
        super().__init__(p, runs, lanes)
        self.lpv, self.trim_map = lpv_of(p), trim_map_of(p)
        self.K = np.asarray(p["K"], float)
        try:
            np.linalg.cholesky(p["Q"])
        except np.linalg.LinAlgError:
            raise ValueError("nominal ellipsoid Q must be positive definite") from None
        self.P = np.linalg.inv(p["Q"])
        self.level_max = float(p["level_max"])
        self.command = CommandSchedule([Command.of_parameters(r) for r in runs])
        self.g = np.stack([self.command.h0, self.command.V0], axis=1)  # (B, 2)
        self.x_r, self.u_r = self.trim_map.at(self.g[:, 0], self.g[:, 1])
        self.x_n = np.stack([np.asarray(r["x0"], float) for r in runs]) - self.x_r
        outside = quad(self.x_n, self.P) > self.level_max
        for b in np.flatnonzero(outside):
            lanes.fail(int(b), ValueError(
                "initial state is outside the certified nominal ellipsoid: start the case "
                "closer to its initial trim"
            ))  # fmt: skip

    def _govern(self, dh, dV, x_pred):
        """Largest admissible fraction s (B,) of the command move, and its x_r, u_r, x_n."""
        G0, G1 = self.g[:, 0], self.g[:, 1]
        s_best = np.zeros(G0.size)
        xr_b, ur_b, xn_b = self.x_r.copy(), self.u_r.copy(), x_pred.copy()

        def candidate(s, rows):
            xr, ur = self.trim_map.at(G0[rows] + s * dh[rows], G1[rows] + s * dV[rows])
            xn = x_pred[rows] - (xr - self.x_r[rows])
            return xr, ur, xn, quad(np.ascontiguousarray(xn), self.P) <= self.level_max

        rows = np.flatnonzero((dh != 0.0) | (dV != 0.0))
        if rows.size:
            xr, ur, xn, ok = candidate(1.0, rows)
            acc = rows[ok]
            s_best[acc], xr_b[acc], ur_b[acc], xn_b[acc] = 1.0, xr[ok], ur[ok], xn[ok]
            rows = rows[~ok]
        if rows.size:
            lo, hi = np.zeros(rows.size), np.ones(rows.size)
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                xr, ur, xn, ok = candidate(mid, rows)
                acc = rows[ok]
                s_best[acc], xr_b[acc], ur_b[acc], xn_b[acc] = mid[ok], xr[ok], ur[ok], xn[ok]
                lo = np.where(ok, mid, lo)
                hi = np.where(ok, hi, mid)
        return s_best, xr_b, ur_b, xn_b

    def output(self, k, t, x, u_prev) -> NominalTrajectory:
        """Output of step k (module docstring)."""
        B = self.g.shape[0]
        h_c, V_c = self.command(t)
        u_n = mv(self.K, self.x_n)
        out = NominalTrajectory(
            k, t, h_c, V_c, self.g[:, 0].copy(), self.g[:, 1].copy(), self.x_r.copy(),
            self.u_r.copy(), self.x_n.copy(), u_n, quad(self.x_n, self.P), counters(B),
            counters(B), counters(B), np.zeros((B, 2)), counters(B),
        )  # fmt: skip
        self._k = k
        return out

    def advance(self) -> None:
        """Advance the nominal model and the governed reference g to step k + 1."""
        k = self._k
        A, Bm = self.lpv.systems(self.g[:, 0], self.g[:, 1])
        x_pred = (
            np.matmul(A, self.x_n[:, :, None])[..., 0]
            + np.matmul(Bm, mv(self.K, self.x_n)[:, :, None])[..., 0]
        )
        ch, cV = self.command((k + 1) * self.p["Ts"])
        dh, dV = ch - self.g[:, 0], cV - self.g[:, 1]
        s, self.x_r, self.u_r, self.x_n = self._govern(dh, dV, x_pred)
        self.g = np.stack([self.g[:, 0] + s * dh, self.g[:, 1] + s * dV], axis=1)


@register_nominal
class CommandReference(NominalSource):
    """Reference of the traditional RMPC: trim of the raw command, x_n = 0, no governor.

    Parameters
    ----------
    p, runs, lanes
        As `fahv.control.base.NominalSource`; uses the trim map and each run's
        command.
    """

    name = "command"

    def __init__(self, p: dict, runs: Sequence[dict], lanes: Lanes) -> None:
        super().__init__(p, runs, lanes)
        self.trim_map = trim_map_of(p)
        self.command = CommandSchedule([Command.of_parameters(r) for r in runs])
        self.n = p["A"].shape[1]

    def output(self, k, t, x, u_prev) -> NominalTrajectory:
        """Reference of step k (x_n = 0, u_n = 0, level NaN)."""
        h, V = self.command(t)
        x_r, u_r = self.trim_map.at(h, V)
        B = h.size
        return NominalTrajectory(
            k, t, h, V, h.copy(), V.copy(), x_r, u_r, np.zeros((B, self.n)), np.zeros((B, 2)),
            np.full(B, math.nan), counters(B), counters(B), counters(B), np.zeros((B, 2)),
            counters(B),
        )  # fmt: skip
