"""Fault kinds over lanes: the base the actuator and the sensor faults share.

A fault kind is a class with a registry name, its parameters declared as config fields
(`Field`) and an effect its subclass defines. An instance holds the fault of n >= 1 runs
(lanes) of that kind: the onset time and every parameter are (n,) arrays. `LaneFault`
reads and checks them (each `ConfigError` names the kind and the parameter), joins the
runs of several instances (`LaneFault.stack`) and says which runs are active at a time;
`FaultRegistry` registers the kinds, makes the fault of a run and declares every kind's
parameters for a config. The actuator faults (`fahv.plant.faults`) and the sensor faults
(`fahv.sensors.faults`) subclass both; what a fault does to a command or to a channel's
output stays there.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, TypeVar

import numpy as np

from fahv.config.registry import Registry
from fahv.config.spec import Field
from fahv.errors import ConfigError

K = TypeVar("K", bound="LaneFault")


class LaneFault:
    """The fault of n >= 1 runs (lanes) of one kind, active from `t_onset` on.

    A subclass sets `name`, `parameters` and `what`, and adds the effect of the fault.
    A parameter with a default (`Field.default`) may be left out; a scalar (or
    one-element) value is used for every lane.

    Parameters
    ----------
    t_onset : float or (n,) array_like
        Onset time [s] of each run.
    **params
        Values of `parameters` (float or (n,) array_like, in each field's unit); other
        names are not read.

    Raises
    ------
    ConfigError
        If a parameter without a default is missing, a value is not a number, or the
        parameters do not have n lanes; the message names the kind and the parameters.
    """

    #: Registry name (the `kind` of a config section).
    name: ClassVar[str] = ""
    #: Parameters the kind takes, beyond `kind` and `t_onset`.
    parameters: ClassVar[tuple[Field, ...]] = ()
    #: What the kinds are, in messages ("fault kind", "sensor fault kind").
    what: ClassVar[str] = "fault kind"

    def __init__(self, t_onset=math.inf, **params) -> None:
        self.t_onset = self._lanes_of("t_onset", t_onset)
        missing = [f.name for f in self.parameters if f.name not in params and f.required]
        if missing:
            raise ConfigError(f"{self.what} '{self.name}' needs parameter(s) {missing}")
        n = self.t_onset.size
        self.params = {}
        for f in self.parameters:
            v = self._lanes_of(f.name, params.get(f.name, f.default))
            self.params[f.name] = np.broadcast_to(v, (n,)).copy() if v.size == 1 else v
        bad = [k for k, v in self.params.items() if v.size != n]
        if bad:
            raise ConfigError(f"{self.what} '{self.name}': parameters {bad} do not have {n} lanes")

    def _lanes_of(self, param: str, value) -> np.ndarray:
        """`value` as a float array of at least one dimension (lanes)."""
        try:
            return np.atleast_1d(np.asarray(value, dtype=float))
        except (TypeError, ValueError):
            raise ConfigError(
                f"{self.what} '{self.name}': parameter '{param}' must be a number or an "
                f"array of numbers, got {value!r}"
            ) from None

    def check(self, param: str, ok: np.ndarray | bool, must: str) -> None:
        """Refuse the values of a parameter that `ok` marks as wrong.

        Parameters
        ----------
        param : str
            Name of the parameter (`t_onset` or one of `parameters`).
        ok : bool or (n,) bool ndarray
            True where a lane's value is admissible.
        must : str
            What the values must be, e.g. "-1 or 1".

        Raises
        ------
        ConfigError
            "<what> '<name>': parameter '<param>' must be <must>, got [<values>]" unless
            `ok` is True on every lane.
        """
        if not np.all(ok):
            values = self.t_onset if param == "t_onset" else self.params[param]
            raise ConfigError(
                f"{self.what} '{self.name}': parameter '{param}' must be {must}, got "
                f"{values.tolist()}"
            )

    @property
    def lanes(self) -> int:
        """Number of runs n the instance describes."""
        return self.t_onset.size

    @property
    def kind(self) -> str:
        """Registry name of the fault."""
        return self.name

    def shared(self) -> dict[str, Any]:
        """Constructor arguments beyond `t_onset` and `parameters`, common to stacked runs.

        Returns
        -------
        dict
            Keyword arguments (none here; a sensor fault's `channel`).
        """
        return {}

    @classmethod
    def stack(cls: type[K], faults: Sequence[K]) -> K:
        """One instance of the runs of `faults`, in order.

        Parameters
        ----------
        faults : sequence of LaneFault
            Instances of this kind (with the same `shared` arguments, those of the first
            are used).

        Returns
        -------
        LaneFault
            Of `sum(f.lanes)` lanes.
        """
        t_onset = np.concatenate([f.t_onset for f in faults])
        params = {
            p.name: np.concatenate([f.params[p.name] for f in faults]) for p in cls.parameters
        }
        return cls(t_onset, **faults[0].shared(), **params)

    def active(self, t: float) -> np.ndarray:
        """Which runs the fault acts on at time `t`.

        Parameters
        ----------
        t : float
            Time [s].

        Returns
        -------
        (n,) bool ndarray
            True once t >= t_onset (never for the kind `none`).
        """
        if self.name == "none":
            return np.zeros(self.lanes, dtype=bool)
        return t >= self.t_onset - 1e-12


class FaultRegistry(Registry[type[K]]):
    """Fault kinds by name: a `Registry` that also makes faults and declares parameters.

    Parameters
    ----------
    what : str
        What the kinds are ("fault kind", "sensor fault kind"), used in messages.
    """

    def add(self, cls: type[K]) -> type[K]:
        """Register a kind under its `name` (the body of a class decorator).

        Parameters
        ----------
        cls : type
            A subclass of `LaneFault`.

        Returns
        -------
        type
            `cls`.

        Raises
        ------
        ConfigError
            If the name is taken or not an identifier.
        """
        self.register(cls.name, cls)
        return cls

    def make(self, kind: str, t_onset, params: Mapping[str, Any], **shared) -> K:
        """The fault of a registered kind with the parameters it takes.

        Parameters
        ----------
        kind : str
            Registered name.
        t_onset : float or (n,) array_like
            Onset time [s].
        params : mapping
            Parameter values; entries that are not parameters of the kind are ignored.
        **shared
            Further constructor arguments (a sensor fault's `channel`).

        Returns
        -------
        LaneFault

        Raises
        ------
        ConfigError
            On an unknown kind or a missing parameter.
        """
        cls = self[kind]
        taken = {f.name: params[f.name] for f in cls.parameters if f.name in params}
        return cls(t_onset, **shared, **taken)

    def fields(self, kind_of: Callable[[Mapping], str | None]) -> list[Field]:
        """The parameters of every kind, each used only with its kind (for a config).

        Parameters
        ----------
        kind_of : callable
            `kind_of(root)`: the kind a validated document names (None if none).

        Returns
        -------
        list of Field
            Copies of the kinds' fields with `when` true when `kind_of(root)` is the kind.
        """
        return [
            dataclasses.replace(
                f, when=lambda root, name=name: kind_of(root) == name, when_text=f"kind is {name}"
            )
            for name, cls in self.items()
            for f in cls.parameters
        ]
