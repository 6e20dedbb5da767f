"""Actuator faults: the registry of fault kinds and the injector between controller and plant.

A fault kind is one class (subclass of :class:`FaultKind`) registered in
:data:`FAULTS`: its name, the parameters it takes (declared as config fields, so the
case file, the fault-injector node and the docs read them from here), and
:meth:`FaultKind.apply`, the input that reaches the actuators while it is active.
Built-in kinds: ``none``, ``loss_of_effectiveness`` (eq. 15), ``bias``, ``stuck``,
``dropout``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from fahv.config import Field, Registry
from fahv.config.spec import lookup
from fahv.errors import ConfigError
from fahv.model.vehicle import DELTA_E


class FaultKind:
    """A fault of the actuators, active from ``t_onset`` on.

    Subclasses set :attr:`name` and :attr:`parameters` and implement :meth:`apply`.

    Parameters
    ----------
    t_onset : float
        Onset time [s].
    **params
        Values of :attr:`parameters` (validated by the caller).

    Raises
    ------
    ConfigError
        If a parameter of the kind is missing.
    """

    #: Registry name (``fault.kind`` of a case file).
    name: ClassVar[str] = ""
    #: Parameters the kind takes, beyond ``kind`` and ``t_onset``.
    parameters: ClassVar[tuple[Field, ...]] = ()

    def __init__(self, t_onset: float = math.inf, **params) -> None:
        self.t_onset = float(t_onset)
        missing = [f.name for f in self.parameters if f.name not in params]
        if missing:
            raise ConfigError(f"fault kind '{self.name}' needs parameter(s) {missing}")
        self.params = {f.name: params[f.name] for f in self.parameters}

    @property
    def kind(self) -> str:
        """Registry name of the fault."""
        return self.name

    def active(self, t: float) -> bool:
        """True once t >= t_onset [s] (never for ``none``)."""
        return self.name != "none" and t >= self.t_onset - 1e-12

    def design_effectiveness(self) -> float:
        """Elevator effectiveness rho_f the tube design covers (eq. 15-16); 1 if none."""
        return 1.0

    @property
    def rho_f(self) -> float:
        """Elevator effectiveness reported on /hsv/fault_status (1 unless a loss)."""
        return 1.0

    @property
    def bias(self) -> float:
        """Elevator bias reported on /hsv/fault_status [rad] (0 unless a bias)."""
        return 0.0

    def apply(self, u: np.ndarray, held: np.ndarray | None) -> np.ndarray:
        """Input at the actuators while active.

        Parameters
        ----------
        u : (2,) ndarray
            Commanded [Phi, delta_e rad] (a copy the method may change).
        held : (2,) ndarray or None
            Input applied at the previous step (None at step 0).

        Returns
        -------
        (2,) ndarray
        """
        return u


#: Fault kinds by name.
FAULTS: Registry[type[FaultKind]] = Registry("fault kind")


def register_fault(cls: type[FaultKind]) -> type[FaultKind]:
    """Class decorator: register a :class:`FaultKind` under its ``name``."""
    FAULTS.register(cls.name, cls)
    return cls


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
        """rho_f: the tube's fault vertices are B_i with the elevator column times rho_f."""
        return float(self.params["rho_f"])

    @property
    def rho_f(self) -> float:
        """The effectiveness rho_f."""
        return float(self.params["rho_f"])

    def apply(self, u, held):
        """Scale the elevator deflection by rho_f."""
        u[DELTA_E] = self.params["rho_f"] * u[DELTA_E]
        return u


@register_fault
class Bias(FaultKind):
    """delta_e,applied = delta_e + bias."""

    name = "bias"
    parameters = (Field("bias_deg", "float", "elevator bias", unit="deg", lo=-30.0, hi=30.0),)

    @property
    def bias(self) -> float:
        """The bias [rad]."""
        return math.radians(self.params["bias_deg"])

    def apply(self, u, held):
        """Add the bias to the elevator deflection."""
        u[DELTA_E] += self.bias
        return u


@register_fault
class Stuck(FaultKind):
    """delta_e frozen at the value applied just before the onset."""

    name = "stuck"

    def __init__(self, t_onset: float = math.inf, **params) -> None:
        super().__init__(t_onset, **params)
        self._stuck: float | None = None

    def apply(self, u, held):
        """Hold the elevator at its value at onset."""
        if self._stuck is None:
            self._stuck = u[DELTA_E] if held is None else held[DELTA_E]
        u[DELTA_E] = self._stuck
        return u


@register_fault
class Dropout(FaultKind):
    """The command is lost: the previous applied input is held."""

    name = "dropout"

    def apply(self, u, held):
        """The previous applied input (the command itself at step 0)."""
        return u if held is None else held.copy()


def fault_kind_of(root) -> str | None:
    """``kind`` of a case's fault section (``fault.kind``) or of flat node parameters."""
    return lookup(root, "fault.kind") or lookup(root, "kind")


#: Fault kind (case key ``fault.kind``, fault-injector parameter ``kind``).
FAULT_KIND = Field("kind", "str", "actuator fault kind", choices=FAULTS.names)
#: Onset time, used by every kind but ``none``.
T_ONSET = Field(
    "t_onset", "float", "fault onset time", unit="s", lo=0.0, default=math.inf,
    when=lambda r: fault_kind_of(r) not in (None, "none"), when_text="kind is not none",
)  # fmt: skip


def fault_fields() -> list[Field]:
    """Parameters of every registered kind, each used only with its kind (for configs)."""
    return [
        dataclasses.replace(
            f, when=lambda root, name=name: fault_kind_of(root) == name, when_text=f"kind is {name}"
        )
        for name, cls in FAULTS.items()
        for f in cls.parameters
    ]


def make_fault(kind: str, t_onset: float, params: dict) -> FaultKind:
    """The fault of a registered kind with the parameters it takes (others ignored).

    Raises
    ------
    ConfigError
        On an unknown kind or a missing parameter.
    """
    cls = FAULTS[kind]
    return cls(t_onset, **{f.name: params[f.name] for f in cls.parameters if f.name in params})


class FaultInjector:
    """Stateful application of a :class:`FaultKind` to commands u (2,)."""

    def __init__(self, fault: FaultKind) -> None:
        self.fault = fault
        self._held: np.ndarray | None = None

    def apply(self, t: float, u: np.ndarray) -> np.ndarray:
        """Input reaching the actuators at time t [s] for the command u [Phi, delta_e rad]."""
        out = np.array(u, dtype=float)
        if self.fault.active(t):
            out = self.fault.apply(out, self._held)
        self._held = out.copy()
        return out
