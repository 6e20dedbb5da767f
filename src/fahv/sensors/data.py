"""Sensor data of the vehicle file: the channels, their noise models and the gyro's mode slopes.

The `sensors` section of the vehicle file (`src/fahv/data/vehicle_parker2007.yaml`)
holds, like its `parameters`, one entry per number with `value`, `unit` and
`source` (`representative: true` when not published):

- `gyro_mode_slopes`: `phi_1`, `phi_2`, the slopes of the mode shapes at the rate
  gyro [rad per unit generalised coordinate];
- one mapping per channel (`h`, `V`, `theta`, `q`, `alpha`) whose keys are the noise
  parameters of `ChannelNoise`; a parameter left out is off (zero; one step for
  `period`).

Angles may be given in deg (deg/s for rates): they are converted to rad.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fahv.errors import VehicleDataError
from fahv.model.entries import check_section, read_entry, unit_factors
from fahv.model.vehicle import parse_vehicle_text, vehicle_file_text

#: Measurable channels, in output order.
CHANNELS: tuple[str, ...] = ("h", "V", "theta", "q", "alpha")
#: Unit of each channel's measurement.
CHANNEL_UNITS: dict[str, str] = {
    "h": "ft",
    "V": "ft/s",
    "theta": "rad",
    "q": "rad/s",
    "alpha": "rad",
}
#: Stable channel ids, the second word of the generator's key (never renumber).
CHANNEL_IDS: dict[str, int] = {"h": 1, "V": 2, "theta": 3, "q": 4, "alpha": 5}
#: Channels measured unless told otherwise (air-data alpha is optional).
DEFAULT_MEASURED: tuple[str, ...] = ("h", "V", "theta", "q")
#: The value of `measured` that reads the whole state exactly: the paper's full-state
#: loop (a sensor of every state, flexible ones included, without error).
EXACT_STATE = "state"
#: The channels of `EXACT_STATE`, the nine CM states in plant order (eq. 7).
STATE_CHANNELS: tuple[str, ...] = (
    "h", "V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot"
)  # fmt: skip


def measured_channels(measured: str) -> list[str]:
    """The channel names of a `measured` parameter (comma-separated, blanks dropped).

    Unchecked: `fahv.loop.cores.sensors_of` names unknown or repeated channels.

    Examples
    --------
    >>> measured_channels(" h, V,theta,q ,"), measured_channels("")
    (['h', 'V', 'theta', 'q'], [])
    """
    return [c.strip() for c in measured.split(",") if c.strip()]


@dataclass(frozen=True)
class ChannelNoise:
    """Noise model of one channel (Gazebo's noise model, JSBSim's sensor component).

    Amplitudes are in the channel's unit u (`CHANNEL_UNITS`).

    Attributes
    ----------
    stddev : float
        Standard deviation of the white Gaussian noise [u].
    mean : float
        Mean of the white noise [u].
    bias_mean, bias_stddev : float
        Turn-on bias of a run: drawn once per run from N(bias_mean, bias_stddev^2) [u].
    dynamic_bias_stddev : float
        Stationary standard deviation of the first-order Gauss-Markov bias [u].
    dynamic_bias_correlation_time : float
        Its correlation time tau [s] (required > 0 when `dynamic_bias_stddev` > 0).
    precision : float
        Quantisation step: the output is rounded to a multiple of it [u]; 0: none.
    lag : float
        JSBSim's lag C_1 of C_1 / (s + C_1) on the true value [1/s]; 0: none.
    drift_rate : float
        Bias growing linearly from t = 0 [u/s].
    bias : float
        Constant bias [u].
    delay : int
        Transport delay [steps of Ts] (JSBSim's frames).
    period : int
        Sensor period [steps of Ts]: a new sample every `period` steps, held between.
    """

    stddev: float = 0.0
    mean: float = 0.0
    bias_mean: float = 0.0
    bias_stddev: float = 0.0
    dynamic_bias_stddev: float = 0.0
    dynamic_bias_correlation_time: float = 0.0
    precision: float = 0.0
    lag: float = 0.0
    drift_rate: float = 0.0
    bias: float = 0.0
    delay: int = 0
    period: int = 1


#: Kind of unit of each parameter: "u" the channel's, "u/s" per second, else literal.
PARAMETER_UNITS: dict[str, str] = {
    "stddev": "u", "mean": "u", "bias_mean": "u", "bias_stddev": "u",
    "dynamic_bias_stddev": "u", "dynamic_bias_correlation_time": "s", "precision": "u",
    "lag": "1/s", "drift_rate": "u/s", "bias": "u", "delay": "steps", "period": "steps",
}  # fmt: skip
_NON_NEGATIVE = ("stddev", "bias_stddev", "dynamic_bias_stddev", "precision", "lag")


@dataclass(frozen=True)
class SensorData:
    """The `sensors` section of a vehicle file.

    Attributes
    ----------
    channels : dict of str to ChannelNoise
        Noise model of every channel of `CHANNELS`.
    phi_1, phi_2 : float
        Mode-shape slopes at the rate gyro [rad per unit generalised coordinate]:
        q_gyro = q + phi_1 eta_1_dot + phi_2 eta_2_dot.
    representative : tuple of str
        Entries (`gyro_mode_slopes.phi_1`, `q.stddev`, ...) marked representative.
    source_file : str
        File the data came from.
    """

    channels: dict[str, ChannelNoise]
    phi_1: float
    phi_2: float
    representative: tuple[str, ...] = ()
    source_file: str = ""


def _channel(section: Any, name: str, path: str) -> tuple[ChannelNoise, list[str]]:
    """The noise model of one channel and its representative entries."""
    check_section(section, f"sensors.{name}", path, PARAMETER_UNITS)
    u = CHANNEL_UNITS[name]
    values: dict[str, Any] = {}
    representative = []
    for key in section:
        unit = (
            PARAMETER_UNITS[key].replace("u", u, 1)
            if PARAMETER_UNITS[key] in ("u", "u/s")
            else PARAMETER_UNITS[key]
        )
        entry = read_entry(section, key, path, f"sensors.{name}", unit_factors(unit))
        v = entry.value
        if key in ("delay", "period"):
            if v != int(v) or v < (1 if key == "period" else 0):
                raise VehicleDataError(
                    f"{path}: 'sensors.{name}.{key}' must be a whole number of steps"
                )
            v = int(v)
        elif key in _NON_NEGATIVE and v < 0.0:
            raise VehicleDataError(f"{path}: 'sensors.{name}.{key}' = {v} must be >= 0")
        values[key] = v
        if entry.representative:
            representative.append(f"{name}.{key}")
    noise = ChannelNoise(**values)
    if noise.dynamic_bias_stddev > 0.0 and noise.dynamic_bias_correlation_time <= 0.0:
        raise VehicleDataError(
            f"{path}: 'sensors.{name}.dynamic_bias_correlation_time' must be > 0 "
            "when dynamic_bias_stddev > 0"
        )
    return noise, representative


def sensors_from_mapping(data: Mapping[str, Any], path: str = "<mapping>") -> SensorData:
    """The `SensorData` of a parsed vehicle file (its `sensors` section).

    Parameters
    ----------
    data : mapping
        The parsed vehicle file.
    path : str
        Name used in error messages.

    Returns
    -------
    SensorData

    Raises
    ------
    VehicleDataError
        On a missing section, channel or slope, an unknown key, an entry without
        `value` or `source`, a wrong unit or a non-physical value; the message names
        the key.

    Examples
    --------
    >>> sensors_from_mapping({"sensors": {}})
    Traceback (most recent call last):
        ...
    fahv.errors.VehicleDataError: <mapping>: missing key 'sensors.gyro_mode_slopes'
    """
    section = data.get("sensors") if isinstance(data, Mapping) else None
    if section is None:
        raise VehicleDataError(f"{path}: missing key 'sensors' (a mapping)")
    check_section(section, "sensors", path, ("gyro_mode_slopes", *CHANNELS))
    for key in ("gyro_mode_slopes", *CHANNELS):
        if key not in section:
            raise VehicleDataError(f"{path}: missing key 'sensors.{key}'")
    slopes = check_section(section["gyro_mode_slopes"], "sensors.gyro_mode_slopes", path)
    representative: list[str] = []
    phi = []
    for key in ("phi_1", "phi_2"):
        entry = read_entry(slopes, key, path, "sensors.gyro_mode_slopes", unit_factors("rad"))
        phi.append(entry.value)
        if entry.representative:
            representative.append(f"gyro_mode_slopes.{key}")
    channels = {}
    for name in CHANNELS:
        channels[name], rep = _channel(section[name], name, path)
        representative += rep
    return SensorData(channels, phi[0], phi[1], tuple(representative), path)


def load_sensors(path: str | Path | None = None) -> SensorData:
    """Load the `sensors` section of a vehicle file.

    Parameters
    ----------
    path : str or Path, optional
        Vehicle file; `None` reads the packaged one.

    Returns
    -------
    SensorData

    Raises
    ------
    VehicleDataError
        If the file cannot be read or its `sensors` section is invalid.

    Examples
    --------
    >>> import math
    >>> s = load_sensors()
    >>> s.channels["V"].stddev, round(math.degrees(s.channels["q"].stddev), 6)
    (1.0, 0.18)
    """
    return _sensors_of_text(*vehicle_file_text(path))


@functools.lru_cache(maxsize=16)
def _sensors_of_text(text: str, name: str) -> SensorData:
    """The validated sensors of a vehicle file's text (once per process and content)."""
    return sensors_from_mapping(parse_vehicle_text(text, name), name)


def replace_channel(data: SensorData, name: str, **changes: Any) -> SensorData:
    """A copy of `data` with parameters of channel `name` changed (tests, studies)."""
    channels = dict(data.channels)
    channels[name] = dataclasses.replace(channels[name], **changes)
    return dataclasses.replace(data, channels=channels)
