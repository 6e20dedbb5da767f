"""Actuator faults: the registry of fault kinds and the injector between controller and plant.

A fault kind is one class (subclass of `FaultKind`) registered in
`FAULTS`: its name, the parameters it takes (declared as config fields, so the
case file, the fault-injector node and the docs read them from here), and
`FaultKind.apply`, the input that reaches the actuators while it is active.
Built-in kinds: `none`, `loss_of_effectiveness` (eq. 15), `bias`, `stuck`,
`dropout`, `hardover`.

The faults act on the elevator command before the actuator: with ideal actuators the
command is the position; with servo dynamics (`fahv.model.actuators`) a
`hardover` command at a position limit drives the servo there at its rate limit, and
`stuck` is also applied by the plant, which holds the servo at its position at the
onset (plant parameter `stuck_onset`).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from fahv.config import Field
from fahv.config.faults import FaultRegistry, LaneFault
from fahv.config.spec import lookup
from fahv.errors import ConfigError
from fahv.model.vehicle import DELTA_E, InputLimits


class FaultKind(LaneFault):
    """An actuator fault of one or more runs (lanes), active from `t_onset` on.

    A fault kind is a subclass that sets `name` and `parameters` and
    implements `apply` over lanes. An instance describes the fault of n >= 1
    runs of that kind: `t_onset` and every parameter are (n,) arrays (a scalar
    makes n = 1); `stack` joins the faults of several runs into one instance. The
    lanes, the parameter checks, `stack` and `active` are those of
    `fahv.config.faults.LaneFault`. The fault injector of a single run (B = 1) and of
    a campaign batch call the same `apply`, so the two paths agree by construction.

    Parameters
    ----------
    t_onset : float or (n,) array_like
        Onset time [s].
    **params
        Values of `parameters` (float or (n,) array_like; validated by the caller).

    Raises
    ------
    ConfigError
        If a parameter of the kind is missing or not a number, or the parameters have
        different lengths.
    """

    what: ClassVar[str] = "fault kind"
    #: The kind needs the actuators' position limits (`bind_limits`).
    needs_limits: ClassVar[bool] = False
    #: Position limits of the actuators, once bound.
    limits: InputLimits | None = None

    def bind_limits(self, limits: InputLimits | None) -> None:
        """Give the fault the actuators' position limits (those of the simulated vehicle).

        Parameters
        ----------
        limits : InputLimits or None
            Position limits of the actuators.

        Raises
        ------
        ConfigError
            If the kind needs them (`needs_limits`) and `limits` is None.
        """
        if self.needs_limits and limits is None:
            raise ConfigError(f"fault kind '{self.name}' needs the actuators' position limits")
        self.limits = limits

    def design_effectiveness(self) -> float:
        """Elevator effectiveness rho_f the tube design covers (eq. 15-16); 1 if none."""
        return 1.0

    @property
    def rho_f(self) -> np.ndarray:
        """(n,) elevator effectiveness reported on /hsv/fault_status (1 unless a loss)."""
        return np.ones(self.lanes)

    @property
    def bias(self) -> np.ndarray:
        """(n,) elevator bias reported on /hsv/fault_status [rad] (0 unless a bias)."""
        return np.zeros(self.lanes)

    def apply(self, u: np.ndarray, held: np.ndarray | None, lanes: np.ndarray) -> np.ndarray:
        """Inputs at the actuators of the active runs `lanes`.

        Parameters
        ----------
        u : (m, 2) ndarray
            Commanded [Phi, delta_e rad] of those runs (a copy the method may change).
        held : (m, 2) ndarray or None
            Inputs applied at the previous step (None at step 0).
        lanes : (m,) int ndarray
            Which of this instance's runs the rows are (for parameters and memory).

        Returns
        -------
        (m, 2) ndarray
        """
        return u


#: Fault kinds by name.
FAULTS: FaultRegistry[FaultKind] = FaultRegistry("fault kind")


#: Class decorator: register a `FaultKind` under its `name` (`FaultRegistry.add`).
register_fault = FAULTS.add


@register_fault
class NoFault(FaultKind):
    """No fault."""

    name = "none"


RHO_F = Field(
    "rho_f",
    "float",
    "elevator effectiveness after the fault",
    lo=0.0,
    hi=1.0,
    lo_open=True,
    equation="eq. (15)",
)


@register_fault
class LossOfEffectiveness(FaultKind):
    """delta_e,applied = rho_f delta_e (eq. 15), on the whole deflection, trim included."""

    name = "loss_of_effectiveness"
    parameters = (RHO_F,)

    def design_effectiveness(self) -> float:
        """rho_f of the first run: the tube's fault vertices scale the elevator column."""
        return float(self.params["rho_f"][0])

    @property
    def rho_f(self) -> np.ndarray:
        """The effectiveness rho_f (n,)."""
        return self.params["rho_f"]

    def apply(self, u, held, lanes):
        """Scale the elevator deflection by rho_f."""
        u[:, DELTA_E] = self.params["rho_f"][lanes] * u[:, DELTA_E]
        return u


@register_fault
class Bias(FaultKind):
    """delta_e,applied = delta_e + bias."""

    name = "bias"
    parameters = (Field("bias_deg", "float", "elevator bias", unit="deg", lo=-30.0, hi=30.0),)

    @property
    def bias(self) -> np.ndarray:
        """The bias (n,) [rad]."""
        return np.array([math.radians(b) for b in self.params["bias_deg"]])

    def apply(self, u, held, lanes):
        """Add the bias to the elevator deflection."""
        u[:, DELTA_E] += self.bias[lanes]
        return u


@register_fault
class Stuck(FaultKind):
    """delta_e frozen at the value applied just before the onset; a servo held where it is.

    With servo dynamics the plant also holds the elevator actuator at its position at
    the onset (plant parameters `stuck`, `stuck_onset`).
    """

    name = "stuck"

    def __init__(self, t_onset=math.inf, **params) -> None:
        super().__init__(t_onset, **params)
        self._stuck = np.full(self.lanes, np.nan)
        self._set = np.zeros(self.lanes, dtype=bool)

    def apply(self, u, held, lanes):
        """Hold the elevator at its value at onset."""
        new = ~self._set[lanes]
        if new.any():
            src = u if held is None else held
            self._stuck[lanes[new]] = src[new, DELTA_E]
            self._set[lanes[new]] = True
        u[:, DELTA_E] = self._stuck[lanes]
        return u


@register_fault
class Dropout(FaultKind):
    """The command is lost: the previous applied input is held."""

    name = "dropout"

    def apply(self, u, held, lanes):
        """The previous applied input (the command itself at step 0)."""
        return u if held is None else held.copy()


SIDE = Field(
    "side", "float", "the position limit a hardover drives the elevator to: +1 the upper "
    "(delta_e max), -1 the lower (delta_e min)", lo=-1.0, hi=1.0,
)  # fmt: skip


@register_fault
class Hardover(FaultKind):
    """delta_e commanded to a position limit (side +1: max, -1: min) from the onset.

    With ideal actuators the elevator jumps to the limit; a servo
    (`fahv.model.actuators`) drives it there at its rate limit.

    Raises
    ------
    ConfigError
        If a `side` is not -1 or +1.
    """

    name = "hardover"
    parameters = (SIDE,)
    needs_limits = True

    def __init__(self, t_onset=math.inf, **params) -> None:
        super().__init__(t_onset, **params)
        self.check("side", np.isin(self.params["side"], (-1.0, 1.0)), "-1 or 1")

    def apply(self, u, held, lanes):
        """The elevator command at the limit of each run's side."""
        if self.limits is None:
            raise ConfigError("fault kind 'hardover' needs the actuators' position limits")
        side = self.params["side"][lanes]
        u[:, DELTA_E] = np.where(side > 0.0, self.limits.delta_e_max, self.limits.delta_e_min)
        return u


def fault_kind_of(root) -> str | None:
    """`kind` of a case's fault section (`fault.kind`) or of flat node parameters."""
    return lookup(root, "fault.kind") or lookup(root, "kind")


#: Fault kind (case key `fault.kind`, fault-injector parameter `kind`).
FAULT_KIND = Field("kind", "str", "actuator fault kind", choices=FAULTS.names)
#: Onset time, used by every kind but `none`.
T_ONSET = Field(
    "t_onset", "float", "fault onset time", unit="s", lo=0.0, default=math.inf,
    when=lambda r: fault_kind_of(r) not in (None, "none"), when_text="kind is not none",
)  # fmt: skip


def fault_fields() -> list[Field]:
    """Parameters of every registered kind, each used only with its kind (for configs).

    Returns
    -------
    list of Field
        With `when` true when the fault section's `kind` is the field's kind.
    """
    return FAULTS.fields(fault_kind_of)


def make_fault(kind: str, t_onset: float, params: dict) -> FaultKind:
    """The fault of one run, of a registered kind, with the parameters it takes.

    Parameters
    ----------
    kind : str
        Registered name (`FAULTS`).
    t_onset : float
        Onset time [s].
    params : dict
        Parameter values; other entries are ignored.

    Returns
    -------
    FaultKind

    Raises
    ------
    ConfigError
        On an unknown kind or a missing parameter.
    """
    return FAULTS.make(kind, t_onset, params)


class FaultInjector:
    """Stateful application of the faults of B runs to their commands u (B, 2).

    Parameters
    ----------
    faults : FaultKind or sequence of FaultKind
        The fault of each run (one-lane instances, any kinds), in run order.
    limits : InputLimits, optional
        Position limits of the actuators (needed by a kind that drives to them,
        `hardover`).

    Raises
    ------
    ConfigError
        If a kind needs the limits and none are given.
    """

    def __init__(self, faults, limits: InputLimits | None = None) -> None:
        faults = [faults] if isinstance(faults, FaultKind) else list(faults)
        self.n = sum(f.lanes for f in faults)
        kinds: dict[type, list] = {}
        lane = 0
        for f in faults:
            kinds.setdefault(type(f), []).append((f, np.arange(lane, lane + f.lanes)))
            lane += f.lanes
        #: (runs (n,) int, fault of those runs) per kind
        self.groups = [
            (np.concatenate([ix for _, ix in fl]), cls.stack([f for f, _ in fl]))
            for cls, fl in kinds.items()
        ]
        self.kind = [""] * self.n
        for _, f in self.groups:
            f.bind_limits(limits)
        for ix, f in self.groups:
            for i in ix:
                self.kind[i] = f.kind
        self._held: np.ndarray | None = None

    def _per_run(self, attr: str) -> np.ndarray:
        out = np.empty(self.n)
        for ix, f in self.groups:
            out[ix] = getattr(f, attr)
        return out

    @property
    def t_onset(self) -> np.ndarray:
        """Onset time of each run (B,) [s]."""
        return self._per_run("t_onset")

    @property
    def rho_f(self) -> np.ndarray:
        """Elevator effectiveness of each run (B,)."""
        return self._per_run("rho_f")

    @property
    def bias(self) -> np.ndarray:
        """Elevator bias of each run (B,) [rad]."""
        return self._per_run("bias")

    def active(self, t: float) -> np.ndarray:
        """(B,) bool: the fault of each run is active at time t [s]."""
        out = np.zeros(self.n, dtype=bool)
        for ix, f in self.groups:
            out[ix] = f.active(t)
        return out

    def apply(self, t: float, u: np.ndarray) -> np.ndarray:
        """Inputs (B, 2) reaching the actuators at time t [s] for the commands u (B, 2)."""
        out = np.array(u, dtype=float).reshape(self.n, 2)
        for ix, f in self.groups:
            act = f.active(t)
            if act.any():
                lanes = np.flatnonzero(act)
                rows = ix[lanes]
                held = None if self._held is None else self._held[rows]
                out[rows] = f.apply(out[rows], held, lanes)
        self._held = out.copy()
        return out
