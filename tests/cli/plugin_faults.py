"""A fault kind outside the library (a plugin): the elevator's travel limited from onset.

Imported through ``FAHV_PLUGINS=plugin_faults`` (with this folder on ``PYTHONPATH``);
nothing in the library names it. At +/-12.1 deg the travel is just short of Case 1's
trim deflection (12.3 deg at 86 100 ft, 8150 ft/s): the vehicle cannot hold its trim.
"""

import numpy as np

from fahv.config import Field
from fahv.model.vehicle import DELTA_E
from fahv.plant.faults import FaultKind, register_fault


@register_fault
class ElevatorTravel(FaultKind):
    """From onset the elevator deflection is clipped to +/- ``travel_deg`` (a test fault)."""

    name = "elevator_travel"
    parameters = (Field("travel_deg", "float", "elevator travel", unit="deg", lo=0.0, hi=30.0),)

    def apply(self, u, held, lanes):
        """Clip delta_e to the travel."""
        lim = np.radians(self.params["travel_deg"][lanes])
        u[:, DELTA_E] = np.clip(u[:, DELTA_E], -lim, lim)
        return u
