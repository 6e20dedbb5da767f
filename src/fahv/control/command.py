"""Altitude and speed command of a case (sec. 5.1), for one run or a batch of runs."""

from __future__ import annotations

import math
from collections.abc import Sequence
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

    @classmethod
    def of_parameters(cls, p: dict) -> Command:
        """The command of a nominal_trajectory node's parameters (`command.*`)."""
        c = {k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("command.")}
        return cls(c["h0"], c["V0"], c["h_c"], c["V_c"], c["t_start"], c["kind"], c["t_ramp"])

    def __call__(self, t: float) -> tuple[float, float]:
        """Commanded (h_c [ft], V_c [ft/s]) at time t [s]."""
        h, V = CommandSchedule([self])(t)
        return float(h[0]), float(V[0])


class CommandSchedule:
    """The commands of B runs, evaluated together (the one formula of `Command`).

    Parameters
    ----------
    commands : sequence of Command
        One per run.
    """

    def __init__(self, commands: Sequence[Command]) -> None:
        self.commands = list(commands)

        def col(name):
            return np.array([getattr(c, name) for c in self.commands], dtype=float)

        self.h0, self.V0, self.h_c, self.V_c = col("h0"), col("V0"), col("h_c"), col("V_c")
        self.t_start, self.t_ramp = col("t_start"), col("t_ramp")
        self.is_step = np.array([c.kind == "step" for c in self.commands])
        # per-call constants: the changes, and t_ramp with 1 on step lanes (whose ramp
        # fraction is never used) so that no division by 0 needs an errstate per call
        self._dh, self._dV = self.h_c - self.h0, self.V_c - self.V0
        self._t_ramp = np.where(self.is_step, 1.0, self.t_ramp)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded (h_c (B,) [ft], V_c (B,) [ft/s]) at time t [s].

        The fraction of the change made by t: 0 before t_start, 1 after a step,
        min(1, (t - t_start) / t_ramp) on a ramp.
        """
        ramp = np.minimum(1.0, (t - self.t_start) / self._t_ramp)
        f = np.where(t < self.t_start, 0.0, np.where(self.is_step, 1.0, ramp))
        return self.h0 + f * self._dh, self.V0 + f * self._dV
