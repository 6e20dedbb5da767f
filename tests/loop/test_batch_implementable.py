"""The implementable loop batches: runs with their own sensor seeds, servo and sensor data
and faults share one batch, and every run gets the bits it gets alone and in `simulate`."""

import numpy as np
import pytest

from fahv.certificate.verified import load_or_design
from fahv.loop.batch import shared_signature, simulate_batch
from fahv.loop.simulate import run_parameters, simulate

SCENARIO = "offline_design/scenarios/case1_implementable.yaml"
FIELDS = ("t", "x", "q_f", "x_r", "x_n", "u", "u_applied", "h_c", "V_c", "h_g", "V_g",
          "tube_level", "fault_active", "lmi_counts", "qp_counts", "u_actuator",
          "u_actuator_rate_peak", "y", "x_hat", "x_hat_sigma")  # fmt: skip
#: Long enough for the first re-plans and the faults' onsets, short for CI [s].
DURATION = 2.0


@pytest.fixture(scope="module")
def design():
    _, design, _ = load_or_design(SCENARIO, log=lambda *_: None, allow_uncertified=True,
                                  variants=["tube_mpc"])  # fmt: skip
    return design


def _overrides():
    """Four runs: other noise seeds, servos, sensors, faults, one a sensor fault."""
    faults = [("loss_of_effectiveness", {"rho_f": 0.9}), ("bias", {"bias_deg": 0.5}),
              ("stuck", {}), ("none", {})]  # fmt: skip
    plant = [
        {"sensor_seed": 11, "servo_omega_n_factor": 0.8, "servo_rate_limit_factor": 1.1},
        {"sensor_seed": 12, "servo_zeta_factor": 1.2, "sensor_stddev_factor": 1.25},
        {"sensor_seed": 13, "sensor_bias_mean_shift": 0.5, "stuck": True, "stuck_onset": 1.0},
        {"sensor_seed": 14, "sensor_fault.kind": "bias_step", "sensor_fault.channel": "q",
         "sensor_fault.t_onset": 0.5, "sensor_fault.bias": 0.001},
    ]  # fmt: skip
    return [
        {"plant": p, "fault_injector": {"kind": kind, "t_onset": 0.5 + 0.25 * i, **extra}}
        for i, (p, (kind, extra)) in enumerate(zip(plant, faults, strict=True))
    ]


def _assert_same(a, b):
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f


def test_the_runs_share_one_batch(design):
    sigs = {shared_signature(run_parameters(design, "tube_mpc", DURATION, ov))
            for ov in _overrides()}  # fmt: skip
    assert len(sigs) == 1


def test_the_batch_gives_each_run_its_bits_alone_and_in_simulate(design):
    ovs = _overrides()
    batch = simulate_batch(design, "tube_mpc", ovs, DURATION)
    reversed_batch = simulate_batch(design, "tube_mpc", ovs[::-1], DURATION)[::-1]
    for ov, res, rev in zip(ovs, batch, reversed_batch, strict=True):
        assert not isinstance(res, Exception), res
        _assert_same(res, rev)
        _assert_same(res, simulate(design, "tube_mpc", DURATION, overrides=ov))
    # the runs did differ: their own noise, servos and faults
    assert len({r.y[5, 0] for r in batch}) == 4
    assert len({r.u_actuator[10, 1] for r in batch}) == 4
    # the filter's own standard deviations, positive in every state it estimates
    assert np.all(batch[0].x_hat_sigma[1:] > 0.0) and batch[0].x_hat_sigma.shape[1] == 9


def test_the_servo_data_reach_the_plant(design):
    """A slower elevator servo (omega_n x 0.5) lags its command more at the first steps."""
    base = simulate(design, "tube_mpc", 0.5)
    slow = simulate(design, "tube_mpc", 0.5,
                    overrides={"plant": {"servo_omega_n_factor": 0.5}})  # fmt: skip
    lag = np.abs(base.u_actuator[1:, 1] - base.u_applied[:-1, 1]).max()
    lag_slow = np.abs(slow.u_actuator[1:, 1] - slow.u_applied[:-1, 1]).max()
    assert lag_slow > 1.5 * lag > 0.0
