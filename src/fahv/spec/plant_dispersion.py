"""The simulated plant's servo and sensor data of one run, as factors on the vehicle file's.

A scenario's `plant` section may give them (a clearance case, a sensitivity study), a
campaign draws them per run (`dispersions.actuators`, `dispersions.sensors`); the
plant node takes them as parameters of its own run. They change the simulated plant
only: the Kalman filter's predictor and gains keep the vehicle file's servos and
noise, as a flight computer knows its hardware only from its data sheet.

Factors of 1 and a shift of 0 (the defaults) leave the vehicle file's values bit for
bit. The ranges refuse what is not physical: a natural frequency or a rate limit
that is not positive, a negative damping ratio, a negative noise level.
"""

from __future__ import annotations

from collections.abc import Mapping

from fahv.config import Field

#: Servo fields, in the column order of `fahv.plant.integrator.SERVO_FACTORS`.
SERVO_FIELDS = (
    Field("servo_omega_n_factor", "float", "factor on the natural frequency omega_n of both "
          "servos of the simulated plant", lo=0.0, lo_open=True, hi=100.0, default=1.0),
    Field("servo_zeta_factor", "float", "factor on the damping ratio zeta of both servos of "
          "the simulated plant", lo=0.0, hi=100.0, default=1.0),
    Field("servo_rate_limit_factor", "float", "factor on the rate limits of both servos of "
          "the simulated plant", lo=0.0, lo_open=True, hi=100.0, default=1.0),
)  # fmt: skip

#: Sensor fields, in the column order of `fahv.sensors.measure.SENSOR_DISPERSION`.
SENSOR_FIELDS = (
    Field("sensor_stddev_factor", "float", "factor on the white-noise stddev of every "
          "measured channel", lo=0.0, hi=100.0, default=1.0),
    Field("sensor_bias_stddev_factor", "float", "factor on the turn-on bias stddev of every "
          "measured channel", lo=0.0, hi=100.0, default=1.0),
    Field("sensor_bias_mean_shift", "float", "shift of every measured channel's turn-on bias "
          "mean, in that channel's white-noise stddevs", lo=-100.0, hi=100.0, default=0.0),
)  # fmt: skip

#: Every field of a run's plant dispersion (scenario `plant` keys, plant node parameters).
PLANT_DISPERSION = SERVO_FIELDS + SENSOR_FIELDS


def servo_factors(run) -> list[float]:
    """The servo factors [omega_n, zeta, rate_limit] of one run's plant parameters."""
    return [float(run[f.name]) for f in SERVO_FIELDS]


def sensor_dispersion_of(run) -> list[float]:
    """The sensor dispersion [stddev, bias_stddev, bias_mean] of one run's plant parameters."""
    return [float(run[f.name]) for f in SENSOR_FIELDS]


def rate_limit_factor(run_spec: Mapping, nodes: Mapping | None = None) -> float:
    """The factor on the servos' rate limits a run flies with (1: the vehicle file's).

    Parameters
    ----------
    run_spec : mapping
        The run spec's data (its optional `plant` section).
    nodes : mapping, optional
        The run's node parameters or overrides `{node: {name: value}}` (a campaign run's
        drawn `plant.servo_rate_limit_factor`), or a run's ROS parameter file
        `{node: {"ros__parameters": {...}}}`; they take precedence.

    Returns
    -------
    float
        For `fahv.model.vehicle.InputLimits.with_rate_factor`: a run is judged against
        the rates of its own servos.
    """
    plant = dict((run_spec or {}).get("plant") or {})
    given = (nodes or {}).get("plant") or {}
    plant.update(given.get("ros__parameters", given))
    return float(plant.get("servo_rate_limit_factor", 1.0))
