"""Input limits of the vehicle: the positions of sec. 5.1 and the servos' rate limits.

Read from the vehicle file (`fahv.model.vehicle`); a run's limits are the file's with
the rates of its own, possibly dispersed, servos (`InputLimits.with_rate_factor`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class InputLimits:
    """Actuator limits: the positions of sec. 5.1 and the servos' rates.

    Attributes
    ----------
    Phi_min, Phi_max : float
        Fuel-to-air ratio range [-].
    delta_e_min, delta_e_max : float
        Elevator range [rad].
    rate_incr, rate_decr : (2,) tuple of float
        Largest rate of increase and of decrease of (Phi, delta_e) [1/s, rad/s]: the
        rate limits of the vehicle file's physical servos (`actuators.second_order`,
        JSBSim's `rate_limit`), whatever actuator model a run simulates; `inf`: none.

    Examples
    --------
    >>> lim = InputLimits(0.0, 1.5, -0.5, 0.5)
    >>> lim.u_min.tolist(), lim.u_max.tolist(), lim.rate_incr
    ([0.0, -0.5], [1.5, 0.5], (inf, inf))
    """

    Phi_min: float
    Phi_max: float
    delta_e_min: float
    delta_e_max: float
    rate_incr: tuple[float, float] = (math.inf, math.inf)
    rate_decr: tuple[float, float] = (math.inf, math.inf)

    @property
    def u_min(self) -> np.ndarray:
        """Lower input bounds, shape (2,), [-, rad]."""
        return np.array([self.Phi_min, self.delta_e_min])

    @property
    def u_max(self) -> np.ndarray:
        """Upper input bounds, shape (2,), [-, rad]."""
        return np.array([self.Phi_max, self.delta_e_max])

    def with_rate_factor(self, factor: float) -> InputLimits:
        """These limits with both servos' rate limits times `factor` (a dispersed servo).

        The plant's `servo_rate_limit_factor` (`fahv.spec.plant_dispersion`): a run is
        judged against the rates its own servos have.

        Parameters
        ----------
        factor : float
            Factor on `rate_incr` and `rate_decr` of both inputs (an infinite rate stays
            infinite).

        Returns
        -------
        InputLimits
            `self` for a factor of 1, else a copy with the rates scaled.

        Raises
        ------
        ValueError
            If `factor` is not a finite number > 0.
        """
        factor = float(factor)
        if not (0.0 < factor < math.inf):
            raise ValueError(f"servo rate limit factor must be finite and > 0, got {factor}")
        if factor == 1.0:
            return self
        return dataclasses.replace(
            self, rate_incr=tuple(r * factor for r in self.rate_incr),
            rate_decr=tuple(r * factor for r in self.rate_decr),
        )  # fmt: skip
