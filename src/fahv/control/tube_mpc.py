"""Tube-MPC control laws: ancillary law eq. (36) / (54) around two kinds of nominal part.

* `tube_mpc` (default): the nominal part is the online tracking MPC of
  `fahv.control.mpc` (a QP in the nominal_trajectory node, on the
  asymmetric tightened input set, with a state-disturbance estimate).
* `tube_mpc_paper`: the paper's law as published, nominal u_n = K x_n with the offline
  K of LMIs (33)-(35) and the incremental reference governor
  (`fahv.control.reference.ReferenceGovernor`).

With tau < 1 (Case 2) either is the adjustable law, eq. (54): the feedback is tau F e,
and the design (`fahv.design.pipeline`) solves the tube LMI over the gains tau' F,
tau' in [tau, 1] (eq. 48), so that Z is RPI for the whole W under it and the input
deviation tau F e stays in tau F Z, the tightening of eq. (53). The tube level is
therefore measured in Z, the set the certificate covers (the paper's smaller tube tau Z
holds only for a part W' of W, eq. 47).
"""

from __future__ import annotations

import numpy as np

from fahv.control.base import ControlLaw, LawStep, Variant, no_lmi_failed, register_law
from fahv.control.mpc.nominal_source import TrackingMPCNominal
from fahv.control.reference import ReferenceGovernor, mv, quad
from fahv.lanes import Lanes
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.vehicle import IQ
from fahv.msg import NominalTrajectory


class TubeMPC:
    """Tube-MPC control law, eq. (36); with tau < 1 the adjustable law, eq. (54).

    u = u_r + u_n + tau F (x - x_r - x_n), for B runs at once.

    Parameters
    ----------
    F : (m, n) ndarray
        Robust feedback gain (LMI 24).
    N : (n, n) ndarray
        Tube shape Z = {e : e' N^-1 e <= 1}.
    tau : float
        Adjustable factor in (0, 1] (1 for the baseline law); the feedback is tau F e.

    Raises
    ------
    ValueError
        On a shape mismatch or tau outside (0, 1].
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
        self.tau_F = self.tau * self.F

    def error(self, x: np.ndarray, ref: NominalTrajectory, q_ref=None) -> np.ndarray:
        """Tube errors e = x - x_r - x_n (B, n) for the states x (B, n).

        With `q_ref` (B,) [rad/s], the reference pitch rate that the error's q is taken
        from in place of q_r + q_n (the filtered nominal q of `TubeMPCLaw`).
        """
        x = np.asarray(x, float)
        e = x - ref.x_r - ref.x_n
        if q_ref is not None:
            e[:, IQ] = x[:, IQ] - q_ref
        return np.ascontiguousarray(e)

    def tube_level(self, e: np.ndarray) -> np.ndarray:
        """Tube levels e' N^-1 e (B,): <= 1 when e is inside Z (also for tau < 1, module doc)."""
        return quad(e, self.N_inv)

    def step(self, x: np.ndarray, ref: NominalTrajectory,
             q_ref=None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """Commands u (B, 2) [Phi, delta_e rad] and errors e (B, n) for the states x (B, n).

        `q_ref` as `error`.

        Raises
        ------
        ValueError
            If x has the wrong shape or is not finite.
        """
        x = np.asarray(x, float)
        if x.ndim != 2 or x.shape[1] != self.F.shape[1] or not np.all(np.isfinite(x)):
            raise ValueError(f"controller states must be (B, {self.F.shape[1]}) finite values")
        e = self.error(x, ref, q_ref)
        return (ref.u_r + ref.u_n) + mv(self.tau_F, e), e


class PaperTubeMPCLaw(ControlLaw):
    """Tube-MPC as published, eq. (36)/(54): nominal u_n = K x_n and the reference governor.

    The nominal part (x_r, u_r, x_n, u_n) comes from the nominal_trajectory node
    (`fahv.control.reference.ReferenceGovernor`); the law adds the ancillary
    feedback tau F on the tube error and reports the tube level e' N^-1 e.
    """

    name = "tube_mpc_paper"
    node = "tube_mpc"
    nominal = ReferenceGovernor

    def __init__(self, p: dict, n_runs: int = 1) -> None:
        super().__init__(p, n_runs)
        self.tube = TubeMPC(p["F"], p["N"], p["tau"])

    def step(self, k: int, x: np.ndarray, ref: NominalTrajectory, lanes: Lanes) -> LawStep:
        """Commands and tube status of step k (see `ControlLaw.step`)."""
        u, e = self.tube.step(x, ref)
        return LawStep(u, e, self.tube.tube_level(e), no_lmi_failed(e.shape[0]))


class TubeMPCLaw(PaperTubeMPCLaw):
    """Tube-MPC with an online nominal tracking MPC (QP), eq. (36)/(54) as ancillary law.

    Same ancillary law u = u_r + u_n + tau F (x - x_r - x_n); the nominal part is
    `fahv.control.mpc.nominal_source.TrackingMPCNominal` (offline it re-checks the
    terminal ingredients against the tightened limits u_lo, u_hi of eq. 30).

    With `filter_nominal_q` (case key `tube.filter_nominal_q`) the error's pitch
    rate is formed through the notch when the notch is on: the q of
    the measured states is q' (the notch_filter node), and the nominal's q (x_r + x_n)
    goes through a replica of the same filter, both from rest, so that

        e'_q = notch(q) - notch(q_r + q_n) = notch(q - q_r - q_n),

    the loop the notch certificate covers (`fahv.tube.notch_loop.notch_tube`,
    xi = [e; chi]). Without the replica, e'_q would also carry (notch - 1)(q_r + q_n), a
    term of the nominal's manoeuvre neither W nor the filter's certificate holds
    (docs/theory/notch.md, "The notch loop certified in its own states"). The 11-state
    ECM design feeds back the filter's states itself and is left as it is.
    """

    name = "tube_mpc"
    nominal = TrackingMPCNominal
    filters_nominal_q = True

    def __init__(self, p: dict, n_runs: int = 1) -> None:
        super().__init__(p, n_runs)
        self.q_filter = None
        if p["filter_nominal_q"] and p["notch.enabled"] and p["design_model"] == "cm":
            nf = NotchFilter(*(p[f"notch.{k}"] for k in ("omega_z", "eps_z", "omega_p", "eps_p")))
            self.q_filter = DiscreteNotch(nf, p["Ts"], np.zeros(n_runs))

    def step(self, k: int, x: np.ndarray, ref: NominalTrajectory, lanes: Lanes) -> LawStep:
        """Commands and tube status of step k (see `ControlLaw.step`).

        With `filter_nominal_q` and the notch on (9-state design), the error's q is q'
        less the filtered nominal q (class docstring).
        """
        q_ref = None
        if self.q_filter is not None:
            q_nom = ref.x_r[:, IQ] + ref.x_n[:, IQ]
            if lanes is not None:  # an ended run of a batch feeds 0, not its last values
                q_nom = np.where(lanes.alive, q_nom, 0.0)
            q_ref = self.q_filter.step(q_nom)
        u, e = self.tube.step(x, ref, q_ref)
        return LawStep(u, e, self.tube.tube_level(e), no_lmi_failed(e.shape[0]))


register_law(PaperTubeMPCLaw)
register_law(
    TubeMPCLaw,
    (
        Variant("tube_mpc_no_notch", "tube_mpc", "off", "Tube-MPC without the notch filter"),
        Variant("tube_mpc_notch2", "tube_mpc", "mode2", "Tube-MPC, notch on flexible mode 2"),
    ),
)
