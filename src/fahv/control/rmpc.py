"""Robust MPC baseline of sec. 5.2 (Kothare et al. 1996, ref. [37]) in its off-line form.

The paper compares its Tube-MPC with the "traditional" robust MPC of Kothare,
Balakrishnan & Morari (1996) on the DM LPV model: at each step, the min-gamma problem
(32)-(35) with the current state. This law is the off-line formulation of that
controller by Wan & Kothare (2003): `fahv design` solves the same problem for a
sequence of states along the case's set-point change, with nested ellipsoids, and
re-checks every certificate (`fahv.synthesis.offline_rmpc`); on line the law
finds the smallest stored ellipsoid that holds the state deviation and interpolates
the gain in closed form (no solver, a few stacked products per step, for B runs).
"""

from __future__ import annotations

import math

import numpy as np

from fahv.config import Field, Section
from fahv.control.base import VARIANTS, ControlLaw, LawStep, register_law
from fahv.control.reference import CommandReference
from fahv.errors import DesignError, ParameterError
from fahv.lanes import Lanes
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import TrimMap
from fahv.msg import NominalTrajectory

#: Plant states the baseline feeds back (the 9 states of the DM).
NX = 9


class OfflineRMPC:
    """On-line part of the off-line RMPC (Wan & Kothare 2003) for B runs at once.

    For each run, z = (x - x_r) / Ds and the levels l_i = z' P_i z of the N nested
    ellipsoids (l_1 <= l_2 <= ... since E_{i+1} lies inside E_i). With i the smallest
    ellipsoid holding z (l_i <= 1 < l_{i+1}), a = (l_{i+1} - 1) / (l_{i+1} - l_i)
    solves z' (a P_i + (1 - a) P_{i+1}) z = 1, and

        u = u_r + u_max * ((a K_i + (1 - a) K_{i+1}) z);

    inside the smallest ellipsoid u = u_r + u_max * K_N z. A state outside the largest
    ellipsoid E_1 gets K_1 (no certificate holds there) and is counted.

    Parameters
    ----------
    P : (N, n, n) ndarray
        Inverses of the ellipsoids, scaled units
        (`fahv.synthesis.offline_rmpc.EllipsoidSequence`).
    K : (N, m, n) ndarray
        Gains, scaled units (v = K z, u - u_r = u_max v).
    Ds : (n,) ndarray
        State scales.
    u_max : (m,) ndarray
        Input bounds of the design (input scales).

    Raises
    ------
    ValueError
        On inconsistent shapes or non-finite values.
    """

    def __init__(self, P, K, Ds, u_max) -> None:
        P, K = np.asarray(P, float), np.asarray(K, float)
        Ds, u_max = np.asarray(Ds, float), np.asarray(u_max, float)
        N, n = P.shape[0], Ds.size
        if P.shape != (N, n, n) or K.shape != (N, u_max.size, n) or N < 1:
            raise ValueError(f"offline RMPC: P {P.shape}, K {K.shape}, Ds {Ds.shape} do not match")
        if not all(np.all(np.isfinite(a)) for a in (P, K, Ds, u_max)):
            raise ValueError("offline RMPC: P, K, Ds and u_max must be finite")
        self.P, self.K, self.Ds, self.u_max, self.N = P, K, Ds, u_max, N

    def levels(self, z: np.ndarray) -> np.ndarray:
        """Levels z_b' P_i z_b (B, N) of scaled deviations z (B, n) (stacked products)."""
        Pz = np.matmul(self.P[None], z[:, None, :, None])  # (B, N, n, 1)
        return np.matmul(z[:, None, None, :], Pz)[..., 0, 0]

    def control(self, dx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Input deviations u - u_r (B, m) for state deviations dx (B, n).

        Returns
        -------
        du : (B, m) ndarray
        index : (B,) int ndarray
            Number of ellipsoids holding the state (0: outside E_1, N: inside E_N).
        alpha : (B,) ndarray
            Interpolation weight of the smaller-index gain K_i.
        """
        z = dx / self.Ds
        lv = self.levels(z)
        c = np.count_nonzero(lv <= 1.0, axis=1)
        i = np.maximum(c - 1, 0)
        j = np.minimum(c, self.N - 1)
        rows = np.arange(z.shape[0])
        li, lj = lv[rows, i], lv[rows, j]
        between = (c >= 1) & (c < self.N)
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.where(between, (lj - 1.0) / (lj - li), 1.0)
        vi = np.matmul(self.K[i], z[:, :, None])[..., 0]
        vj = np.matmul(self.K[j], z[:, :, None])[..., 0]
        v = a[:, None] * vi + (1.0 - a[:, None]) * vj
        return v * self.u_max, c, a


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


def fractions(case_rmpc: dict) -> np.ndarray:
    """Fractions f_i = margin * ratio^(i - 1), i = 1..ellipsoids, of the case's step."""
    r = case_rmpc
    return float(r["margin"]) * float(r["ratio"]) ** np.arange(int(r["ellipsoids"]))


class RMPCLaw(ControlLaw):
    """Kothare robust MPC (1996), the paper's baseline, off-line form (Wan & Kothare 2003).

    Offline (`fahv design`): the DM polytopic LPV model (the model of the baseline in
    the paper, `rmpc.vertices`), and N nested invariant ellipsoids with their gains
    from the min-gamma LMIs (32)-(35) at N states along the case's set-point change
    (`fahv.synthesis.offline_rmpc.design_sequence`, every certificate re-checked).
    Online: u = u_r + K(x) (x - x_r), K(x) interpolated between the two ellipsoids
    around x (`OfflineRMPC`); x_r, u_r the trim of the raw command (no governor,
    no tube).
    """

    name = "rmpc"
    node = "rmpc"
    nominal = CommandReference
    has_tube = False
    model_only = True  # the DM model, the trim map and the input room
    section = Section(
        "rmpc",
        (
            Field("vertices", "ints", "TP vertices of the DM model (h, V)", lo=1, length=2,
                  default=(4, 5), equation="eq. (11)"),
            Field("psi", "floats", "diagonal state weights of the cost (31) (h, V, alpha, "
                  "theta, q, eta_1, eta_1_dot, eta_2, eta_2_dot) on z = (x - x_r) / Ds",
                  lo=0.0, lo_open=True, length=NX, equation="eq. (31)"),
            Field("sigma", "float", "input weight of the cost (31), on (u - u_r) / u_room",
                  lo=0.0, lo_open=True, equation="eq. (31)"),
            Field("ellipsoids", "int", "number N of nested ellipsoids (Wan & Kothare 2003)",
                  lo=1, hi=200, default=9),
            Field("ratio", "float", "size ratio of consecutive design states x_{i+1} / x_i",
                  lo=0.0, hi=1.0, lo_open=True, hi_open=True, default=0.6),
            Field("margin", "float", "design state of E_1 as a multiple of the case's step "
                  "x(0) - x_r (>= 1: the step starts inside E_1)", lo=0.0, lo_open=True,
                  default=1.05),
        ),
        "Kothare robust MPC baseline (off-line form, Wan & Kothare 2003)",
        when=_uses_rmpc,
        when_text="a variant uses the law rmpc",
    )  # fmt: skip
    parameters = (
        _matrix("rmpc_P", "inverses P_i of the nested ellipsoids (N, 9, 9), scaled units"),
        _matrix("rmpc_K", "gains K_i (N, 2, 9), scaled units: (u - u_r) / u_room = K_i z"),
        _matrix("rmpc_Ds", "state scales of the ellipsoids (9,): z = (x - x_r) / Ds"),
        _matrix("u_room", "RMPC input room |u - u_r| <= u_room (2,) [-, rad]"),
    )

    def __init__(self, p: dict, n_runs: int = 1) -> None:
        super().__init__(p, n_runs)
        N = p["rmpc_P"].shape[0] if p["rmpc_P"].ndim == 3 else -1
        for name, shape in (
            ("rmpc_P", (N, NX, NX)),
            ("rmpc_K", (N, 2, NX)),
            ("rmpc_Ds", (NX,)),
            ("u_room", (2,)),
        ):
            if p[name].shape != shape:
                raise ParameterError(
                    f"rmpc: parameter '{name}' has shape {p[name].shape}, expected {shape}"
                )
        try:
            self.kernel = OfflineRMPC(p["rmpc_P"], p["rmpc_K"], p["rmpc_Ds"], p["u_room"])
        except ValueError as exc:
            raise ParameterError(f"rmpc: {exc}") from None
        self.outside = np.zeros(n_runs, dtype=np.int64)

    @classmethod
    def design(cls, ctx) -> dict[str, np.ndarray]:
        """DM vertices and the certified ellipsoid sequence of the baseline.

        Raises
        ------
        DesignError
            If an ellipsoid cannot be solved or a certificate fails
            (`fahv.synthesis.offline_rmpc.design_sequence`).
        """
        # offline only: the nodes and the campaign workers never import cvxpy (0.6 s each)
        from fahv.synthesis.offline_rmpc import design_sequence

        r = ctx.spec["rmpc"]
        rv = r["vertices"]
        dm = build_tp_model(ctx.vehicle, "dm", rv[0], rv[1], *ctx.spec["samples"])
        dmd = dm.discretize(ctx.spec["Ts"])
        a = ctx.arrays
        tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
        cmd = ctx.spec["command"]
        x_r = np.asarray(tm(cmd["h_c"], cmd["V_c"])[0][:NX], float)
        d = np.asarray(a["x0"][:NX], float) - x_r
        Dx = np.asarray(dm.state_scale, float)[:NX]
        Ds = Dx * np.maximum(1.0, np.abs(d) / Dx)  # command-sized scales
        f = fractions(r)
        prev = ctx.previous or {}
        start = (prev["rmpc_guess_Q"], prev["rmpc_guess_gamma"]) \
            if "rmpc_guess_Q" in prev and "rmpc_guess_gamma" in prev else None  # fmt: skip
        seq, cert = design_sequence(
            dmd.A, dmd.B, d, a["u_room"], np.asarray(r["psi"], float),
            np.full(2, float(r["sigma"])), Ds, f, start,
        )  # fmt: skip
        level0 = float((d / Ds) @ seq.P[0] @ (d / Ds))
        if not level0 <= 1.0:
            raise DesignError(f"rmpc: the case's step lies outside E_1 (level {level0:.6f})")
        ctx.log(
            f"certificate RMPC (Wan & Kothare 2003, {f.size} ellipsoids on the "
            f"{dmd.A.shape[0]}-vertex DM, fractions {f[0]:.3g}..{f[-1]:.3g} of the step): "
            f"contraction <= {cert['contraction'].max():.7f}, input ratio <= "
            f"{cert['input_ratio'].max():.4f}, nesting <= {cert['nesting'].max(initial=0):.4f}, "
            f"interpolation (WK) <= {cert['wk'].max(initial=0):.7f}, interpolated law on "
            f"the a grid: contraction <= {cert['interp_contraction'].max(initial=0):.7f}, "
            f"input ratio <= {cert['interp_input_ratio'].max(initial=0):.4f}; the step's "
            f"level in E_1 {level0:.4f}  OK"
        )
        return {
            "rmpc_A": dmd.A,
            "rmpc_B": dmd.B,
            "rmpc_P": seq.P,
            "rmpc_Q": seq.Q,
            "rmpc_K": seq.K,
            "rmpc_gamma": seq.gamma,
            "rmpc_Ds": Ds,
            "rmpc_d": d,
            "rmpc_z": seq.z,
            # where a later design of the file starts each ellipsoid's solve
            "rmpc_guess_Q": seq.guess_Q,
            "rmpc_guess_gamma": seq.guess_gamma,
        }

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict:
        """The ellipsoids, gains and scales of the baseline."""
        return {
            "rmpc_P": arrays["rmpc_P"],
            "rmpc_K": arrays["rmpc_K"],
            "rmpc_Ds": arrays["rmpc_Ds"],
            "u_room": arrays["u_room"],
        }

    def step(self, k: int, x: np.ndarray, ref: NominalTrajectory, lanes: Lanes) -> LawStep:
        """Commands of step k for B runs (closed form, no solver; no tube).

        `LawStep.lmi_failed` holds the steps so far with the state outside E_1.
        """
        x = np.asarray(x, float)
        dx = x[:, :NX] - ref.x_r[:, :NX]
        du, c, _ = self.kernel.control(dx)
        self.outside += (c == 0) & lanes.alive
        B = x.shape[0]
        outside = np.asarray(self.outside, dtype=np.int64).copy()
        return LawStep(ref.u_r + du, x - ref.x_r, np.full(B, math.nan), outside)


register_law(RMPCLaw)
