"""Tube-MPC control law, eq. (36); adjustable Tube-MPC, eq. (54)."""

from __future__ import annotations

import numpy as np

from fahv.control.base import ControlLaw, Variant, register_law
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


class TubeMPCLaw(ControlLaw):
    """Tube-MPC, eq. (36): u = u_r + u_n + tau F (x - x_r - x_n); eq. (54) when tau < 1.

    The nominal part (x_r, u_r, x_n, u_n) comes from the nominal_trajectory node
    (governor mode); the law adds the ancillary feedback F on the tube error and
    reports the tube level e' (tau^2 N)^-1 e.

    Raises
    ------
    ParameterError
        If tau < 1 (adjustable law) with a design other than the 11-state ECM.
    """

    name = "tube_mpc"

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


register_law(
    TubeMPCLaw,
    (
        Variant("tube_mpc_no_notch", "tube_mpc", "off", "Tube-MPC without the notch filter"),
        Variant("tube_mpc_notch2", "tube_mpc", "mode2", "Tube-MPC, notch on flexible mode 2"),
    ),
)
