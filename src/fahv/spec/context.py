"""What a control law's offline part sees when a design or a scenario prepares it."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from fahv.model.vehicle import Vehicle


@dataclass(frozen=True)
class DesignContext:
    """What a control law's offline part (`fahv.control.ControlLaw.design`) sees.

    Attributes
    ----------
    spec : dict
        The validated design data with the `command` the offline part is sized for
        (the design step as a step command, or a scenario's command: a run spec's data).
    vehicle : fahv.model.vehicle.Vehicle
    arrays : dict
        Arrays designed so far (the TP model, W, F, Z, K, Q, trim map ...).
    log : callable
        Receives one line per step.
    previous : Mapping[str, ndarray], optional
        The arrays of an earlier design of the same file, where an offline part's solves
        may start (its stored coordinates): it changes how fast a design runs, not what
        it certifies. None for a scenario's own offline parts and `fahv design --cold`.
    """

    spec: dict
    vehicle: Vehicle
    arrays: dict
    log: Callable[[str], None]
    previous: Mapping | None = None
