"""Sensors in the closed loop (Case 1 design): the plant measures at every step, with the
numbers a record measured afterwards gives, the same in simulate() and the batch engine,
and the measurement leaves the control loop bit for bit (no controller reads it yet)."""

import math

import numpy as np
import pytest

from fahv.errors import ParameterError
from fahv.loop.batch import simulate_batch
from fahv.loop.simulate import simulate
from fahv.model.vehicle import ETA1_DOT, ETA2_DOT, IQ, THETA, H, V
from fahv.sensors.data import load_sensors
from fahv.sensors.measure import measure_history

DURATION = 2.0


def test_the_plant_measures_what_the_record_gives_afterwards(design):
    """simulate()'s y (default channels h, V, theta, q; seed 0) equals `measure_history` of
    its state history, bit for bit; its error against the true outputs stays within 6
    sigma of each channel (100 steps); the gyro's q differs from q by the modes' rates."""
    run = simulate(design, "tube_mpc", DURATION)
    assert run.info["measured"] == "h,V,theta,q"
    data = load_sensors()
    channels = ("h", "V", "theta", "q")
    again = measure_history(data, [0], design.case["Ts"], run.x, channels)
    assert np.array_equal(run.y, again)
    q_gyro = run.x[:, IQ] + data.phi_1 * run.x[:, ETA1_DOT] + data.phi_2 * run.x[:, ETA2_DOT]
    truth = np.stack([run.x[:, H], run.x[:, V], run.x[:, THETA], q_gyro], axis=1)
    sigma = np.array([data.channels[c].stddev for c in channels])
    worst = np.abs(run.y - truth).max(axis=0) / sigma
    assert (worst < 6.0).all() and (worst > 0.5).all(), worst  # noisy, and within 6 sigma
    assert np.abs(q_gyro - run.x[:, IQ]).max() > 0.0


def test_the_measurement_leaves_the_loop_unchanged(design):
    """Another channel set, another seed or no sensors give the same states and inputs."""
    base = simulate(design, "tube_mpc", DURATION)
    for plant in ({"measured": ""}, {"measured": "alpha,q", "sensor_seed": 9}):
        other = simulate(design, "tube_mpc", DURATION, overrides={"plant": plant})
        assert np.array_equal(other.x, base.x) and np.array_equal(other.u, base.u)
    none = simulate(design, "tube_mpc", DURATION, overrides={"plant": {"measured": ""}})
    assert none.y is None


def test_the_batch_draws_each_runs_own_seed_as_simulate_does(design):
    """Three runs of a batch, sensor seeds 0, 5 and 5 (one with alpha measured: another
    group): each lane equals simulate() with the same parameters; equal seeds give equal y,
    other seeds other y."""
    overrides = [
        {"plant": {"sensor_seed": 0}},
        {"plant": {"sensor_seed": 5}},
        {"plant": {"sensor_seed": 5, "measured": "h,V,theta,q,alpha"}},
    ]
    batch = simulate_batch(design, "tube_mpc", overrides, DURATION)
    for ov, res in zip(overrides, batch, strict=True):
        one = simulate(design, "tube_mpc", DURATION, overrides=ov)
        assert np.array_equal(res.y, one.y) and np.array_equal(res.x, one.x)
    assert not np.array_equal(batch[0].y, batch[1].y)
    assert np.array_equal(batch[1].y, batch[2].y[:, :4])
    alpha = batch[2].y[:, 4]
    assert np.abs(alpha - batch[2].x[:, 2]).max() < 6.0 * math.radians(0.057)


@pytest.mark.parametrize(
    ("measured", "message"),
    [
        ("h,V,eta_1", "unknown channel(s) ['eta_1']"),
        ("h,h", "a channel named twice"),
    ],
)
def test_a_bad_channel_list_is_refused_naming_the_parameter(design, measured, message):
    with pytest.raises(ParameterError, match=r"plant: parameter 'measured'") as err:
        simulate(design, "tube_mpc", DURATION, overrides={"plant": {"measured": measured}})
    assert message in str(err.value)
