"""Sensors in the closed loop (Case 1 design): the plant measures at every step, with the
numbers a record measured afterwards gives, the same in simulate() and the batch engine;
the paper's loop reads the exact state through its full-state sensor, the Kalman loop
reads the sensors, and a sensor fault reaches the controller only through the estimate."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fahv.errors import ParameterError, RunError
from fahv.loop.batch import simulate_batch
from fahv.loop.simulate import simulate
from fahv.model.vehicle import ETA1_DOT, ETA2_DOT, IQ, THETA, H, V
from fahv.sensors.data import load_sensors
from fahv.sensors.measure import measure_history

DURATION = 2.0
ROOT = Path(__file__).resolve().parents[2]
CHANNELS = "h,V,theta,q"


def kalman(measured: str = CHANNELS, **plant) -> dict:
    """Overrides of a run on the Kalman filter of the sensors `measured`."""
    return {"plant": {"measured": measured, **plant},
            "state_estimator": {"estimator": "kalman", "measured": measured}}  # fmt: skip


def test_the_plant_measures_what_the_record_gives_afterwards(design):
    """simulate()'s y (channels h, V, theta, q; seed 0) equals `measure_history` of its
    state history, bit for bit; its error against the true outputs stays within 6 sigma
    of each channel (100 steps); the gyro's q differs from q by the modes' rates."""
    run = simulate(design, "tube_mpc", DURATION, overrides=kalman())
    assert run.info["measured"] == CHANNELS
    data = load_sensors()
    channels = CHANNELS.split(",")
    again = measure_history(data, [0], design.case["Ts"], run.x, channels)
    assert np.array_equal(run.y, again)
    q_gyro = run.x[:, IQ] + data.phi_1 * run.x[:, ETA1_DOT] + data.phi_2 * run.x[:, ETA2_DOT]
    truth = np.stack([run.x[:, H], run.x[:, V], run.x[:, THETA], q_gyro], axis=1)
    sigma = np.array([data.channels[c].stddev for c in channels])
    worst = np.abs(run.y - truth).max(axis=0) / sigma
    assert (worst < 6.0).all() and (worst > 0.5).all(), worst  # noisy, and within 6 sigma
    assert np.abs(q_gyro - run.x[:, IQ]).max() > 0.0
    assert not np.array_equal(run.x_hat, run.x)  # the controller read an estimate


def test_the_paper_loop_reads_the_exact_state_through_its_full_state_sensor(design):
    """By default the plant measures 'state' (y = x, bit for bit) and the estimate is the
    exact state; no measurement or a sensor fault there is refused, naming the key."""
    run = simulate(design, "tube_mpc", DURATION)
    assert run.info["measured"] == "state"
    assert np.array_equal(run.y, run.x) and np.array_equal(run.x_hat, run.x)
    with pytest.raises(RunError, match="state_estimator: the measurement's channels 'h,V'"):
        simulate(design, "tube_mpc", DURATION, overrides={"plant": {"measured": "h,V"}})
    with pytest.raises(ParameterError, match="state_estimator: parameter 'estimator' = 'none'"):
        simulate(design, "tube_mpc", DURATION, overrides=kalman("h,V")
                 | {"state_estimator": {"measured": "h,V"}})
    fault = {"sensor_fault.kind": "stuck", "sensor_fault.channel": "q",
             "sensor_fault.t_onset": 1.0}  # fmt: skip
    with pytest.raises(ParameterError, match="the exact state .* has no sensor to fail"):
        simulate(design, "tube_mpc", DURATION, overrides={"plant": fault})


def test_the_batch_draws_each_runs_own_seed_as_simulate_does(design):
    """Three runs of a batch, sensor seeds 0, 5 and 5 (one with alpha measured: another
    group): each lane equals simulate() with the same parameters; equal seeds give equal y
    as long as the states are equal, other seeds other y."""
    overrides = [kalman(sensor_seed=0), kalman(sensor_seed=5),
                 kalman(CHANNELS + ",alpha", sensor_seed=5)]  # fmt: skip
    batch = simulate_batch(design, "tube_mpc", overrides, DURATION)
    for ov, res in zip(overrides, batch, strict=True):
        one = simulate(design, "tube_mpc", DURATION, overrides=ov)
        assert np.array_equal(res.y, one.y) and np.array_equal(res.x, one.x)
    assert not np.array_equal(batch[0].y, batch[1].y)
    assert np.array_equal(batch[1].y[0], batch[2].y[0, :4])  # step 0: the same true state
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
        simulate(design, "tube_mpc", DURATION, overrides=kalman(measured))
    assert message in str(err.value)


def test_sensor_faults_act_on_the_measurement_and_through_the_estimate(design):
    """On the Kalman loop, a stuck gyro from 1 s holds the sample of the step before; a
    100 ft bias step on h adds exactly 100 ft from step 50; the states equal the healthy
    run's up to the onset and differ after it (the controller reads the estimate); the
    batch gives simulate()'s bits for both faults side by side."""
    stuck = {"sensor_fault.kind": "stuck", "sensor_fault.channel": "q",
             "sensor_fault.t_onset": 1.0}  # fmt: skip
    bias = {"sensor_fault.kind": "bias_step", "sensor_fault.channel": "h",
            "sensor_fault.t_onset": 1.0, "sensor_fault.bias": 100.0}  # fmt: skip
    base = simulate(design, "tube_mpc", DURATION, overrides=kalman())
    runs = [simulate(design, "tube_mpc", DURATION, overrides=kalman(**f)) for f in (stuck, bias)]
    assert np.all(runs[0].y[50:, 3] == runs[0].y[49, 3]) and runs[0].y[48, 3] != runs[0].y[49, 3]
    np.testing.assert_array_equal(runs[0].y[:50], base.y[:50])
    assert np.all(runs[1].y[:50, 0] == base.y[:50, 0])
    assert abs(runs[1].y[50, 0] - base.y[50, 0] - 100.0) < 1e-9  # same state at step 50
    for r in runs:
        assert np.array_equal(r.x[:51], base.x[:51]) and not np.array_equal(r.x, base.x)
    batch = simulate_batch(design, "tube_mpc", [kalman(**stuck), kalman(**bias)], DURATION)
    assert all(np.array_equal(b.y, r.y) for b, r in zip(batch, runs, strict=True))


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        ({"sensor_fault.kind": "stuck", "sensor_fault.channel": "alpha",
          "sensor_fault.t_onset": 1.0},  # fmt: skip
         "sensor_fault.channel: 'alpha' is not a measured channel"),
        ({"sensor_fault.kind": "drift", "sensor_fault.channel": "h", "sensor_fault.t_onset": 1.0},
         "'sensor_fault.rate' is missing"),
    ],
)
def test_a_bad_sensor_fault_is_refused_naming_the_parameter(design, fault, message):
    with pytest.raises(ParameterError, match="plant: parameter") as err:
        simulate(design, "tube_mpc", DURATION, overrides=kalman(**fault))
    assert message in str(err.value)


def test_a_scenario_sets_the_sensor_fault_and_the_estimator(tmp_path):
    """The scenario sections `sensor_fault` and `estimator` reach the run spec (the
    plant's parameters, the channels' default of the Kalman filter, a reason the design
    does not certify it); an unknown kind is refused naming the key."""
    from fahv.errors import ConfigError
    from fahv.spec.scenario import load_scenario
    from fahv.spec.schema import plant_choices, sensor_fault_values

    spec = yaml.safe_load((ROOT / "offline_design/scenarios/case1.yaml").read_text())
    spec["sensor_fault"] = {"kind": "drift", "channel": "theta", "t_onset": 30.0, "rate": 1e-4}
    spec["estimator"] = {"kind": "kalman"}
    path = tmp_path / "drift.yaml"
    path.write_text(yaml.safe_dump(spec))
    run_spec = load_scenario(path).run_spec.data
    assert sensor_fault_values(run_spec) == {
        "sensor_fault.kind": "drift", "sensor_fault.channel": "theta",
        "sensor_fault.t_onset": 30.0, "sensor_fault.rate": 1e-4,
    }  # fmt: skip
    assert plant_choices(run_spec)["measured"] == CHANNELS
    spec["sensor_fault"]["kind"] = "frozen"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(ConfigError, match="sensor_fault.kind"):
        load_scenario(path)
