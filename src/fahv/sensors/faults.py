"""Sensor faults: the registry of sensor fault kinds, on the base of the actuator faults.

A sensor fault kind is a subclass of `SensorFaultKind` registered in
`SENSOR_FAULTS`: its name, its parameters (config fields, amplitudes in the unit of
the faulty channel) and `SensorFaultKind.apply`, the output of the channel while the
fault is active. Built-in kinds: `none`, `bias_step`, `drift`, `stuck`, `dropout`.
The onset and parameters per lane and the registry are those of `fahv.config.faults`,
shared with the actuator faults (`fahv.plant.faults`).

A scenario's optional section (`sensor_fault_fields`; the plant node's parameters
`sensor_fault.*`):

    sensor_fault:
      channel: q          # one of the measured channels
      kind: bias_step     # a name of SENSOR_FAULTS
      t_onset: 20.0       # [s]
      bias: 0.001         # the kind's parameters (here [rad/s])

`sensor_fault_from_section` validates such a mapping and builds the fault.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from fahv.config import Field
from fahv.config.faults import FaultRegistry, LaneFault
from fahv.config.spec import lookup
from fahv.errors import ConfigError
from fahv.sensors.data import CHANNELS


class SensorFaultKind(LaneFault):
    """A fault of one channel of n >= 1 runs (lanes), active from `t_onset` on.

    The lanes, the parameter checks, `stack` and `active` are those of
    `fahv.config.faults.LaneFault`; a parameter with a default may be left out and a
    scalar is used for every lane.

    Parameters
    ----------
    t_onset : float or (n,) array_like
        Onset time [s].
    channel : str
        The faulty channel (one of `CHANNELS`).
    **params
        Values of `parameters` (float or (n,) array_like), in the channel's unit.

    Raises
    ------
    ConfigError
        If a parameter is missing or not a number, the channel unknown, or the lengths
        differ.
    """

    what: ClassVar[str] = "sensor fault kind"

    def __init__(self, t_onset=math.inf, channel: str = "q", **params) -> None:
        if channel not in CHANNELS:
            raise ConfigError(
                f"sensor fault channel must be one of {list(CHANNELS)}, got {channel!r}"
            )
        self.channel = channel
        super().__init__(t_onset, **params)
        #: Value held by `stuck` (NaN until the onset).
        self.held = np.full(self.t_onset.size, np.nan)

    def shared(self) -> dict[str, Any]:
        """The channel, common to the runs `stack` joins.

        Returns
        -------
        dict
            `{"channel": channel}`.
        """
        return {"channel": self.channel}

    def apply(self, y: np.ndarray, last: np.ndarray, t: float, lanes: np.ndarray) -> np.ndarray:
        """Output of the channel for the active runs `lanes`.

        Parameters
        ----------
        y : (m,) ndarray
            The healthy sample of those runs at time t [unit of the channel].
        last : (m,) ndarray
            The output of the previous step (the healthy sample at step 0).
        t : float
            Time [s].
        lanes : (m,) int ndarray
            Which of this instance's runs the entries are.

        Returns
        -------
        (m,) ndarray
        """
        return y


#: Sensor fault kinds by name.
SENSOR_FAULTS: FaultRegistry[SensorFaultKind] = FaultRegistry("sensor fault kind")


#: Class decorator: register a `SensorFaultKind` under its `name` (`FaultRegistry.add`).
register_sensor_fault = SENSOR_FAULTS.add


@register_sensor_fault
class NoSensorFault(SensorFaultKind):
    """No fault."""

    name = "none"


@register_sensor_fault
class BiasStep(SensorFaultKind):
    """y = y_healthy + bias from the onset on."""

    name = "bias_step"
    parameters = (Field("bias", "float", "bias added from the onset", unit="unit of the channel"),)

    def apply(self, y, last, t, lanes):
        """Add the bias."""
        return y + self.params["bias"][lanes]


@register_sensor_fault
class Drift(SensorFaultKind):
    """y = y_healthy + rate (t - t_onset): a ramp from the onset."""

    name = "drift"
    parameters = (
        Field("rate", "float", "drift rate from the onset", unit="unit of the channel/s"),
    )

    def apply(self, y, last, t, lanes):
        """Add the ramp."""
        return y + self.params["rate"][lanes] * (t - self.t_onset[lanes])


@register_sensor_fault
class StuckSensor(SensorFaultKind):
    """The output frozen at its value at the onset (the last output before it)."""

    name = "stuck"

    def apply(self, y, last, t, lanes):
        """Hold the output of the step before the onset."""
        new = np.isnan(self.held[lanes])
        self.held[lanes[new]] = last[new]
        return self.held[lanes].copy()


@register_sensor_fault
class DropoutSensor(SensorFaultKind):
    """No new sample: the last output is held while the fault lasts (`duration`)."""

    name = "dropout"
    parameters = (
        Field("duration", "float", "length of the dropout (inf: to the end of the run)",
              unit="s", lo=0.0, lo_open=True, default=math.inf),
    )  # fmt: skip

    def active(self, t: float) -> np.ndarray:
        """(n,) bool: t_onset <= t < t_onset + duration [s]."""
        return super().active(t) & (t < self.t_onset + self.params["duration"] - 1e-12)

    def apply(self, y, last, t, lanes):
        """The previous output."""
        return last.copy()


def sensor_fault_kind_of(root) -> str | None:
    """`kind` of a scenario's `sensor_fault` section, or of the flat node parameters."""
    return lookup(root, "sensor_fault.kind") or lookup(root, "kind")


def sensor_fault_fields() -> tuple[Field, ...]:
    """The keys of a `sensor_fault` section: kind, channel, onset, the kind's parameters.

    Returns
    -------
    tuple of Field
        `kind` (default `none`), `channel` (default `q`), `t_onset` [s] (used by every
        kind but `none`), then every kind's parameters, each used only with its kind.
    """
    return (
        Field("kind", "str", "sensor fault kind", choices=SENSOR_FAULTS.names, default="none"),
        Field("channel", "str", "the faulty channel (a measured one)", choices=CHANNELS,
              default="q"),
        Field("t_onset", "float", "sensor fault onset time", unit="s", lo=0.0,
              default=math.inf, when=lambda r: sensor_fault_kind_of(r) not in (None, "none"),
              when_text="kind is not none"),
        *SENSOR_FAULTS.fields(sensor_fault_kind_of),
    )  # fmt: skip


def sensor_fault_from_section(
    section: Mapping[str, Any], measured: Sequence[str] = CHANNELS, key: str = "sensor_fault"
) -> SensorFaultKind:
    """The one-run sensor fault of a scenario's `sensor_fault` section.

    Parameters
    ----------
    section : mapping
        `channel`, `kind`, `t_onset` [s] and the kind's parameters.
    measured : sequence of str
        Channels the run measures (the fault's channel must be one).
    key : str
        Name of the section in messages.

    Returns
    -------
    SensorFaultKind

    Raises
    ------
    ConfigError
        On a missing or unknown key, an unknown kind or channel, or a value that is
        not a number; the message names the key.

    Examples
    --------
    >>> f = sensor_fault_from_section({"channel": "q", "kind": "stuck", "t_onset": 5.0})
    >>> f.name, f.channel, float(f.t_onset[0])
    ('stuck', 'q', 5.0)
    >>> sensor_fault_from_section({"channel": "q", "kind": "drift", "t_onset": 5.0})
    Traceback (most recent call last):
        ...
    fahv.errors.ConfigError: sensor_fault.rate: missing (sensor fault kind 'drift' needs it)
    """
    if not isinstance(section, Mapping):
        raise ConfigError(f"{key}: must be a mapping with channel, kind, t_onset")
    for k in ("channel", "kind"):
        if k not in section:
            raise ConfigError(f"{key}.{k}: missing")
    kind = section["kind"]
    if kind not in SENSOR_FAULTS.names():
        raise ConfigError(
            f"{key}.kind: unknown sensor fault kind {kind!r}; one of {SENSOR_FAULTS.names()}"
        )
    cls = SENSOR_FAULTS[kind]
    if section["channel"] not in measured:
        raise ConfigError(
            f"{key}.channel: {section['channel']!r} is not a measured channel {list(measured)}"
        )
    allowed = {"channel", "kind", "t_onset"} | {f.name for f in cls.parameters}
    unknown = sorted(set(section) - allowed)
    if unknown:
        raise ConfigError(
            f"{key}: unknown key(s) {unknown} for kind '{kind}'; expected {sorted(allowed)}"
        )
    values = {}
    optional = {f.name for f in cls.parameters if not f.required}
    for name in ["t_onset", *(f.name for f in cls.parameters)]:
        if name not in section:
            if (name == "t_onset" and kind == "none") or name in optional:
                continue
            raise ConfigError(f"{key}.{name}: missing (sensor fault kind '{kind}' needs it)")
        v = section[name]
        infinite_ok = name == "duration" and v == math.inf
        if (
            isinstance(v, bool)
            or not isinstance(v, int | float)
            or not (math.isfinite(v) or infinite_ok)
        ):
            raise ConfigError(f"{key}.{name}: must be a finite number, got {v!r}")
        if (name == "t_onset" and v < 0.0) or (name == "duration" and v <= 0.0):
            raise ConfigError(
                f"{key}.{name}: must be {'>= 0' if name == 't_onset' else '> 0'}, got {v}"
            )
        values[name] = float(v)
    t_onset = values.pop("t_onset", math.inf)
    return SENSOR_FAULTS.make(kind, t_onset, values, channel=section["channel"])
