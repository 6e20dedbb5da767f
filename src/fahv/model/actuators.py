"""Actuator data of the vehicle file: servo models of Phi and delta_e, after JSBSim's FGActuator.

Each actuator of a model is a second-order servo from the command u_c to the position
delta, with the position delta and its rate delta_dot as states:

    delta_ddot = omega_n^2 (u_c - delta) - 2 zeta omega_n delta_dot

limited as JSBSim's `FGActuator` (names and meaning of its elements): `rate_limit`
per direction (`incr`, `decr`) on the rate and `clipto` (position limits, here
the vehicle's own input limits of sec. 5.1). The model `ideal` has no dynamics:
the position is the saturated command, as the paper's plant. The limit logic of the
integration is `fahv.plant.rk4.rk4_cm_act`.

Vehicle file section (every number with `value`, `unit` and `source`):

    actuators:
      second_order:
        Phi:     {zeta: ..., omega_n: ...}
        delta_e: {zeta: ..., omega_n: ..., rate_limit_incr: ..., rate_limit_decr: ...}

A rate limit that is absent is none (infinite).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fahv.errors import VehicleDataError
from fahv.model.entries import check_section, read_entry

#: The actuator model without dynamics (the paper's plant, the default of every scenario).
IDEAL = "ideal"
#: Actuator models a scenario may select (`plant.actuators`).
ACTUATOR_MODELS: tuple[str, ...] = (IDEAL, "second_order")
#: Actuators of a model, in input order (u = [Phi, delta_e]).
CHANNELS: tuple[str, ...] = ("Phi", "delta_e")
#: Units accepted for the entries of one actuator, with the factor to the unit of `Servo`
#: (rates in the input's unit per second; delta_e rate limits in deg/s in the file,
#: rad/s in `Servo`).
_RATE_UNITS = {"1/s": 1.0, "deg/s": math.pi / 180.0}
_UNITS = {"zeta": {"-": 1.0}, "omega_n": {"rad/s": 1.0},
          "rate_limit_incr": _RATE_UNITS, "rate_limit_decr": _RATE_UNITS}  # fmt: skip


@dataclass(frozen=True)
class Servo:
    """One second-order servo (JSBSim `FGActuator` with a second-order lag).

    Attributes
    ----------
    zeta : float
        Damping ratio [-].
    omega_n : float
        Natural frequency [rad/s].
    rate_limit_incr, rate_limit_decr : float
        Largest rate of increase and of decrease of the position, both > 0, in the
        input's unit per second ([1/s] for Phi, [rad/s] for delta_e); `inf`: none.
    """

    zeta: float
    omega_n: float
    rate_limit_incr: float = math.inf
    rate_limit_decr: float = math.inf


def kernel_parameters(servos: Mapping[str, Servo], u_min, u_max) -> np.ndarray:
    """Parameters (2, 6) of the compiled kernel, one row per input (Phi, delta_e).

    Parameters
    ----------
    servos : mapping
        `Servo` by channel name (`CHANNELS`).
    u_min, u_max : (2,) array_like
        Position limits (`clipto`) [-, rad].

    Returns
    -------
    (2, 6) float64 ndarray
        Rows [zeta, omega_n, rate_limit_incr, rate_limit_decr, min, max].

    Raises
    ------
    KeyError
        If a channel has no servo.
    """
    return np.array(
        [[servos[c].zeta, servos[c].omega_n, servos[c].rate_limit_incr,
          servos[c].rate_limit_decr, float(lo), float(hi)]
         for c, lo, hi in zip(CHANNELS, u_min, u_max, strict=True)],
        dtype=np.float64,
    )  # fmt: skip


def _servo(data: Any, key: str, path: str) -> Servo:
    check_section(data, key, path, _UNITS)
    out = {}
    for name, units in _UNITS.items():
        if name.startswith("rate_limit") and name not in data:
            continue  # none
        out[name] = read_entry(data, name, path, key, units).value
        if not out[name] > 0.0:
            written = data[name]["value"]  # named as the file gives it, in the file's unit
            raise VehicleDataError(
                f"{path}: '{key}.{name}' = {written} is not physical (must be > 0)"
            )
    return Servo(**out)


def actuators_from_mapping(data: Any, path: str = "<mapping>") -> dict[str, dict[str, Servo]]:
    """The actuator models of a vehicle file's `actuators` section.

    Parameters
    ----------
    data : mapping or None
        The section: `{model: {channel: {entry: {value, unit, source}}}}`; None (no
        section) gives no model but `ideal`.
    path : str
        Named in errors.

    Returns
    -------
    dict
        `{model: {channel: Servo}}` (`ideal` is not listed: it needs no data).

    Raises
    ------
    VehicleDataError
        On an unknown model or channel, a missing entry, an entry without a source,
        a wrong unit, or a value that is not a positive finite number (names the key).

    Examples
    --------
    >>> e = {"value": 150.0, "unit": "rad/s", "source": "s"}
    >>> z = {"value": 0.7, "unit": "-", "source": "s"}
    >>> m = actuators_from_mapping({"second_order": {"Phi": {"zeta": z, "omega_n": e},
    ...                                              "delta_e": {"zeta": z, "omega_n": e}}})
    >>> m["second_order"]["delta_e"].omega_n, m["second_order"]["Phi"].rate_limit_incr
    (150.0, inf)
    """
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise VehicleDataError(f"{path}: 'actuators' must be a mapping")
    out = {}
    for model, channels in data.items():
        if model not in ACTUATOR_MODELS or model == IDEAL:
            raise VehicleDataError(
                f"{path}: 'actuators.{model}': unknown actuator model; expected "
                f"{[m for m in ACTUATOR_MODELS if m != IDEAL]} (ideal needs no data)"
            )
        if not isinstance(channels, Mapping) or set(channels) != set(CHANNELS):
            raise VehicleDataError(
                f"{path}: 'actuators.{model}' must give exactly {list(CHANNELS)}"
            )
        out[model] = {c: _servo(channels[c], f"actuators.{model}.{c}", path) for c in CHANNELS}
    return out
