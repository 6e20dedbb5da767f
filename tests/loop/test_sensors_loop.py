"""Sensors in the closed loop (Case 1 design): the plant measures at every step, with the
numbers a record measured afterwards gives, the same in simulate() and the batch engine,
and the measurement leaves the control loop bit for bit (no controller reads it yet)."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fahv.errors import ParameterError
from fahv.loop.batch import simulate_batch
from fahv.loop.simulate import simulate
from fahv.model.vehicle import ETA1_DOT, ETA2_DOT, IQ, THETA, H, V
from fahv.sensors.data import load_sensors
from fahv.sensors.measure import measure_history

DURATION = 2.0
ROOT = Path(__file__).resolve().parents[2]


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


def test_sensor_faults_act_on_the_measurement_and_not_the_loop(design):
    """A stuck gyro from 1 s holds the sample of the step before; a 100 ft bias step on h
    adds exactly 100 ft from step 50; the states equal the healthy run's; the batch gives
    simulate()'s bits for both faults side by side."""
    stuck = {"sensor_fault.kind": "stuck", "sensor_fault.channel": "q",
             "sensor_fault.t_onset": 1.0}  # fmt: skip
    bias = {"sensor_fault.kind": "bias_step", "sensor_fault.channel": "h",
            "sensor_fault.t_onset": 1.0, "sensor_fault.bias": 100.0}  # fmt: skip
    base = simulate(design, "tube_mpc", DURATION)
    runs = [simulate(design, "tube_mpc", DURATION, overrides={"plant": f}) for f in (stuck, bias)]
    assert np.all(runs[0].y[50:, 3] == runs[0].y[49, 3]) and runs[0].y[48, 3] != runs[0].y[49, 3]
    np.testing.assert_array_equal(runs[0].y[:50], base.y[:50])
    shift = runs[1].y[:, 0] - base.y[:, 0]
    assert np.all(shift[:50] == 0.0) and np.allclose(shift[50:], 100.0, rtol=0, atol=1e-9)
    assert all(np.array_equal(r.x, base.x) for r in runs)
    batch = simulate_batch(design, "tube_mpc", [{"plant": stuck}, {"plant": bias}], DURATION)
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
        simulate(design, "tube_mpc", DURATION, overrides={"plant": fault})
    assert message in str(err.value)


def test_a_scenario_sets_the_sensor_fault(tmp_path):
    """The scenario section `sensor_fault` reaches the plant's parameters; an unknown kind
    is refused naming the key."""
    from fahv.errors import ConfigError
    from fahv.spec.scenario import load_scenario
    from fahv.spec.schema import sensor_fault_values

    spec = yaml.safe_load((ROOT / "offline_design/scenarios/case1.yaml").read_text())
    spec["sensor_fault"] = {"kind": "drift", "channel": "theta", "t_onset": 30.0, "rate": 1e-4}
    path = tmp_path / "drift.yaml"
    path.write_text(yaml.safe_dump(spec))
    section = load_scenario(path).data["sensor_fault"]
    assert sensor_fault_values({"sensor_fault": section}) == {
        "sensor_fault.kind": "drift", "sensor_fault.channel": "theta",
        "sensor_fault.t_onset": 30.0, "sensor_fault.rate": 1e-4,
    }  # fmt: skip
    spec["sensor_fault"]["kind"] = "frozen"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(ConfigError, match="sensor_fault.kind"):
        load_scenario(path)
