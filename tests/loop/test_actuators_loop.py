"""Actuator models in the closed loop (Case 1 design): ideal actuators are the paper's
plant to the bit; second-order servos run through simulate() and the batch engine alike,
with a stuck elevator held at its position and a hardover driven at the rate limit."""

import dataclasses
import math

import numpy as np
import pytest

from fahv.loop.batch import simulate_batch
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.plant.rk4 import params_records, rk4_cm
from fahv.runs.metrics import input_rates

DURATION = 2.0
SECOND_ORDER = {"actuators": "second_order"}


def test_ideal_actuators_leave_the_loop_bit_for_bit(design):
    """The default and an explicit `ideal` give the same run, and its states are those of
    today's kernel (rk4_cm) fed the applied inputs, saturated: the plant of every result."""
    base = simulate(design, "tube_mpc", DURATION)
    ideal = simulate(design, "tube_mpc", DURATION, overrides={"plant": {"actuators": "ideal"}})
    assert np.array_equal(base.x, ideal.x) and np.array_equal(base.u, ideal.u)
    vp = dataclasses.replace(load_vehicle().params, **design.summary["plant_params"])
    lim = load_vehicle().limits
    rec, Ts, n_sub = params_records([vp]), design.case["Ts"], design.case["plant_substeps"]
    x = base.x[:1].copy()
    for k in range(len(base.t) - 1):
        u = np.clip(base.u_applied[k], lim.u_min, lim.u_max)[None]
        x = rk4_cm(x, np.ascontiguousarray(u), rec, Ts, n_sub)
        assert np.array_equal(x[0], base.x[k + 1]), k
    # the positions on /hsv/state: the input applied over the step before (NaN at k = 0)
    assert np.isnan(base.u_actuator[0]).all()
    assert np.array_equal(base.u_actuator[1:], np.clip(base.u_applied[:-1], lim.u_min, lim.u_max))
    assert np.isnan(base.u_actuator_rate_peak).all()  # ideal actuators have no rate
    assert "delta_e_servo_rate_peak_degps" not in input_rates(base)


def test_second_order_actuators_in_simulate_and_the_batch(design):
    """Three runs with servos (no fault, stuck elevator, hardover to +30 deg at 0.5 s): the
    batch gives simulate()'s bits; the servo lags the command; the stuck elevator stays
    where it was at the onset; the hardover moves at 100 deg/s to the limit, and the run's
    metrics give that rate for the actuator and the command's jump for the command."""
    t_on = 0.5
    ovs = [
        {"plant": SECOND_ORDER, "fault_injector": {"kind": "none"}},
        {"plant": {**SECOND_ORDER, "stuck": True, "stuck_onset": t_on},
         "fault_injector": {"kind": "stuck", "t_onset": t_on}},
        {"plant": SECOND_ORDER, "fault_injector": {"kind": "hardover", "t_onset": t_on,
                                                  "side": 1.0}},
    ]  # fmt: skip
    batch = simulate_batch(design, "tube_mpc", ovs, DURATION)
    for ov, res in zip(ovs, batch, strict=True):
        single = simulate(design, "tube_mpc", DURATION, overrides=ov)
        for f in ("x", "u", "u_applied", "u_actuator", "u_actuator_rate_peak"):
            assert np.array_equal(getattr(single, f), getattr(res, f), equal_nan=True), f
    free, stuck, hard = batch
    lag = free.u_actuator[1:] - free.u_applied[:-1]
    assert 0.0 < np.abs(lag[:, 1]).max() < math.radians(1.0)  # lags: 0.93 deg at the step
    on = int(round(t_on / design.case["Ts"]))
    de = stuck.u_actuator[on + 1 :, 1]
    held_cmd = stuck.u_applied[on + 1 :, 1]
    assert np.all(de == de[0]) and np.all(held_cmd == held_cmd[0])
    assert de[0] != held_cmd[0]  # the servo's position at the onset, not the last command
    de = np.degrees(hard.u_actuator[on + 1 :, 1])
    steps = np.diff(de)
    assert steps.max() <= 100.0 * 0.02 * (1 + 1e-9) and steps[1:5].min() > 1.99
    assert np.nanmax(hard.u_actuator[:, 1]) == load_vehicle().limits.delta_e_max  # reached, clipped
    # the metrics' rates: the command jumps to +30 deg, the servo moves at its 100 deg/s
    rates = input_rates(hard)
    assert 99.9 <= rates["delta_e_actuator_rate_max_degps"] <= 100.0 * (1 + 1e-9)
    assert rates["delta_e_rate_max_degps"] > 1000.0
    assert rates["delta_e_servo_rate_peak_degps"] == pytest.approx(100.0, rel=1e-12)
    # within a step the free servo moves at least as fast as its step-to-step average
    free_rates = input_rates(free)
    assert (free_rates["delta_e_servo_rate_peak_degps"]
            >= free_rates["delta_e_actuator_rate_max_degps"] * (1 - 1e-9))  # fmt: skip
    assert np.isnan(free.u_actuator_rate_peak[0]).all()
