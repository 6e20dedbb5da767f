"""Tube-MPC control laws: ancillary law eq. (36) / (54) around two kinds of nominal part.

* ``tube_mpc`` (default): the nominal part is the online tracking MPC of
  :mod:`fahv.control.nominal_mpc` (a QP in the nominal_trajectory node, on the
  asymmetric tightened input set, with an input-disturbance estimate).
* ``tube_mpc_paper``: the paper's law as published, nominal u_n = K x_n with the offline
  K of LMIs (33)-(35) and the incremental reference governor.
"""

from __future__ import annotations

import numpy as np

from fahv.config import Field, Section
from fahv.control.base import VARIANTS, ControlLaw, Variant, register_law
from fahv.control.nominal_mpc import verify_terminal
from fahv.control.reference import NominalOutput
from fahv.errors import ParameterError


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


def _uses_mpc(root) -> bool:
    return any(VARIANTS[v].law in LAWS_WITH_MPC for v in root.get("variants", ()) if v in VARIANTS)


#: Laws whose nominal part is the online tracking MPC.
LAWS_WITH_MPC = ("tube_mpc",)

#: Case-file section of the nominal tracking MPC (all keys defaulted; docs/control_design.md).
MPC_SECTION = Section(
    "mpc",
    (
        Field("M", "int", "fast steps per nominal move: nominal rate Ts_n = M Ts", lo=1,
              hi=1000, default=25),
        Field("N", "int", "moves in the horizon (horizon N M Ts)", lo=2, hi=200, default=30),
        Field("q_w", "floats", "state weights (h, V, alpha, theta, q, eta_1, eta_1_dot, eta_2, "
              "eta_2_dot) per scale unit", lo=0.0, length=9,
              default=(1.0, 1.0, 0.1, 0.1, 0.01, 0.0, 0.0, 0.0, 0.0)),
        Field("r_w", "floats", "move weights (Phi, delta_e) per scale unit", lo=0.0,
              lo_open=True, length=2, default=(1.0, 1.0)),
        Field("t_w", "floats", "offset-cost weights on (h_s - h_c, V_s - V_c) per "
              "(100 ft, 100 ft/s)", lo=0.0, lo_open=True, length=2, default=(1e4, 1e4)),
        Field("dtheta_max", "floats", "largest set-point move per nominal step", unit="ft, ft/s",
              lo=0.0, lo_open=True, length=2, default=(300.0, 150.0)),
        Field("reschedule", "floats", "set-point distance that rebuilds the QP", unit="ft, ft/s",
              lo=0.0, lo_open=True, length=2, default=(100.0, 50.0)),
        Field("att_max", "float", "bound on the nominal |alpha - alpha_r|, |theta - theta_r| "
              "(from the nominal trim) at each move", unit="deg", lo=0.0, lo_open=True,
              hi=10.0, default=0.35),
        Field("est_tau", "float", "time constant of the state-disturbance estimate (0: none)",
              unit="s", lo=0.0, hi=1e3, default=0.5),
    ),
    "online nominal tracking MPC of the tube_mpc law",
    when=_uses_mpc,
    when_text="a variant uses the law tube_mpc",
)  # fmt: skip


class PaperTubeMPCLaw(ControlLaw):
    """Tube-MPC as published, eq. (36)/(54): nominal u_n = K x_n and the reference governor.

    The nominal part (x_r, u_r, x_n, u_n) comes from the nominal_trajectory node
    (governor mode); the law adds the ancillary feedback F on the tube error and
    reports the tube level e' (tau^2 N)^-1 e.

    Raises
    ------
    ParameterError
        If tau < 1 (adjustable law) with a design other than the 11-state ECM.
    """

    name = "tube_mpc_paper"
    node = "tube_mpc"

    def __init__(self, p: dict) -> None:
        super().__init__(p)
        n = p["F"].shape[1]
        if p["tau"] < 1.0 and n != 11:
            raise ParameterError(
                f"tube_mpc: parameter 'tau' = {p['tau']} (adjustable law, eq. 54) needs the "
                f"11-state ECM design (F has n = {n})"
            )
        self.tube = TubeMPC(p["F"], p["N"], p["tau"])
        self.label = "adjustable" if p["tau"] < 1.0 else self.name

    def step(self, k: int, x: np.ndarray, ref: NominalOutput) -> tuple[np.ndarray, dict]:
        """Command u (2,) and the tube status of step k (see :meth:`ControlLaw.step`)."""
        u = self.tube.step(x, ref)
        e = self.tube.error(x, ref)
        return u, {"e": e, "level": self.tube.tube_level(e), "label": self.label}


class TubeMPCLaw(PaperTubeMPCLaw):
    """Tube-MPC with an online nominal tracking MPC (QP), eq. (36)/(54) as ancillary law.

    Same ancillary law u = u_r + u_n + tau F (x - x_r - x_n); the nominal part comes
    from :class:`fahv.control.nominal_mpc.TrackingNominal` in the nominal_trajectory
    node (mode ``mpc``). Offline it adds the tightened absolute input limits
    ``u_lo``, ``u_hi`` (limits -/+ tau * support of F Z, eq. 30) and re-checks the
    terminal ingredients (:func:`fahv.control.nominal_mpc.verify_terminal`).
    """

    name = "tube_mpc"
    reference = "mpc"
    section = MPC_SECTION

    @classmethod
    def design(cls, ctx) -> dict[str, np.ndarray]:
        """Re-check the terminal ingredients against the tightened limits (no new arrays).

        Raises
        ------
        DesignError
            If the terminal set is not invariant or a trim input of the case's path
            is outside the tightened set.
        """
        a = ctx.arrays
        u_lo, u_hi = a["u_lo"], a["u_hi"]
        cmd = ctx.case["command"]
        from fahv.model.trim import TrimMap

        tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
        path = np.array([tm(cmd["h0"], cmd["V0"])[1], tm(cmd["h_c"], cmd["V_c"])[1]])
        cert = verify_terminal(a["A"], a["B"], a["K"], a["Q"], u_lo, u_hi, path)
        ctx.log(
            f"nominal MPC: tightened inputs Phi in [{u_lo[0]:.4f}, {u_hi[0]:.4f}], delta_e in "
            f"[{np.degrees(u_lo[1]):.2f}, {np.degrees(u_hi[1]):.2f}] deg; terminal set E(Q) "
            f"invariant under K at every vertex (norm {cert['invariance']:.6f} <= 1), "
            f"alpha = 1 admissible along the path: {cert['alpha_max'] >= 1.0}  OK"
        )
        return {}


register_law(PaperTubeMPCLaw)
register_law(
    TubeMPCLaw,
    (
        Variant("tube_mpc_no_notch", "tube_mpc", "off", "Tube-MPC without the notch filter"),
        Variant("tube_mpc_notch2", "tube_mpc", "mode2", "Tube-MPC, notch on flexible mode 2"),
    ),
)
