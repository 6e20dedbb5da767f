"""Actuator dynamics of the plant (fahv.model.actuators, fahv.plant.rk4.rk4_cm_act): the
servo's step response against the analytic one, the rate and position limits, the hold
of a stuck elevator, ideal actuators bit for bit the paper's plant, and the data checks."""

import copy
import math
from importlib import resources

import numpy as np
import pytest

from fahv.config.yamlio import load_yaml
from fahv.errors import ConfigError, ParameterError, SpecError, VehicleDataError
from fahv.loop.cores import servos_of
from fahv.model.actuators import kernel_parameters
from fahv.model.trim import trim
from fahv.model.vehicle import vehicle_from_mapping
from fahv.plant.faults import FaultInjector, make_fault
from fahv.plant.integrator import Plant
from fahv.plant.rk4 import params_records, rk4_cm, rk4_cm_act

#: The plant's RK4 step with the designs' Ts = 0.02 s and 5 sub-steps [s].
DT = 0.004


@pytest.fixture(scope="module")
def setup(vehicle):
    tp = trim(vehicle, 85500.0, 7900.0)
    servos = vehicle.actuators["second_order"]
    ap = kernel_parameters(servos, vehicle.limits.u_min, vehicle.limits.u_max)
    return tp, ap, params_records([vehicle.params])


def servo_run(setup, a0, u, n, held=False):
    """Actuator states (n + 1, 4) of n RK4 steps of DT from a0 (4,) with command u (2,)."""
    tp, ap, rec = setup
    X, A = tp.x_r[None].copy(), np.array([a0], float)
    out = [A[0].copy()]
    for _ in range(n):
        X, A, _ = rk4_cm_act(X, A, np.array([u], float), rec, ap[None], np.array([held]), DT, 1)
        out.append(A[0].copy())
    return np.array(out)


def step_response(t, zeta, omega_n, size):
    """Analytic step response of the second-order servo from rest (0 < zeta < 1)."""
    wd = omega_n * math.sqrt(1.0 - zeta**2)
    decay = np.exp(-zeta * omega_n * t)
    return size * (1.0 - decay * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t)))


def test_servo_step_response_matches_the_analytic_one(vehicle, setup):
    """Steps of 0.05 in Phi and 0.5 deg in delta_e (peak rate 34 deg/s: no limit hit)."""
    tp = setup[0]
    u0, dphi, dde = tp.u_r, 0.05, math.radians(0.5)
    a = servo_run(setup, [u0[0], 0.0, u0[1], 0.0], u0 + [dphi, dde], 150)
    t = DT * np.arange(151)
    so = vehicle.actuators["second_order"]
    for k in (3, 5, 10, 25, 150):  # 12, 20, 40, 100, 600 ms
        # RK4 with omega_n dt = 0.6 (elevator): measured 9.3e-4 of the step; Phi 2e-8
        assert a[k, 2] - u0[1] == pytest.approx(
            step_response(t[k], so["delta_e"].zeta, so["delta_e"].omega_n, dde), abs=2e-3 * dde
        )
        assert a[k, 0] - u0[0] == pytest.approx(
            step_response(t[k], so["Phi"].zeta, so["Phi"].omega_n, dphi), abs=1e-6 * dphi
        )
    assert np.degrees(np.abs(a[:, 3]).max()) < 40.0  # below the 100 deg/s limit


def test_rate_and_position_limits_hold_without_wind_up(vehicle, setup):
    """A 17.6 deg step to the upper limit: the elevator moves at its 100 deg/s rate limit,
    never beyond +30 deg (the unlimited servo overshoots 4.6 %), and comes back off the
    limit at once when the command does (no wind-up)."""
    tp = setup[0]
    rate = vehicle.actuators["second_order"]["delta_e"].rate_limit_incr
    hi = vehicle.limits.delta_e_max
    up = servo_run(setup, [tp.u_r[0], 0.0, tp.u_r[1], 0.0], [tp.u_r[0], hi], 100)
    slope = np.diff(up[:, 2]) / DT
    assert slope.max() <= rate * (1 + 1e-12)  # the position's rate: to rounding
    assert np.abs(up[:, 3]).max() <= rate  # the rate state itself
    assert np.count_nonzero(slope > 0.999 * rate) >= 40  # 0.17 s at the rate limit
    assert up[:, 2].max() <= hi and up[-1, 2] == hi and up[-1, 3] == 0.0
    down = servo_run(setup, up[-1], [tp.u_r[0], hi - math.radians(1.0)], 25)
    assert down[1, 2] < hi and down[-1, 2] == pytest.approx(hi - math.radians(1.0), abs=1e-4)
    lo = servo_run(setup, [tp.u_r[0], 0.0, vehicle.limits.delta_e_min + 1e-3, 0.0],
                   [tp.u_r[0], vehicle.limits.delta_e_min], 50)  # fmt: skip
    assert lo[:, 2].min() >= vehicle.limits.delta_e_min


def test_a_held_elevator_stays_where_it_is(setup):
    tp = setup[0]
    a0 = [tp.u_r[0], 0.0, tp.u_r[1] + 0.01, 0.3]
    a = servo_run(setup, a0, tp.u_r, 20, held=True)
    assert np.all(a[1:, 2] == a0[2]) and np.all(a[1:, 3] == 0.0)
    assert a[-1, 0] == tp.u_r[0]  # Phi at rest at its command


def test_ideal_actuators_are_the_papers_plant_bit_for_bit(vehicle):
    """Plant with ideal actuators == the kernel rk4_cm on the saturated input (the plant
    of every existing result), over 1 s of a Case 1 step's inputs, inputs beyond the
    limits included; the positions reported are the applied inputs."""
    tp = trim(vehicle, 85500.0, 7900.0)
    p = Plant(vehicle.params, vehicle.limits, tp.x_r, 0.02, 5)
    x, rec = tp.x_r[None].copy(), params_records([vehicle.params])
    rng = np.random.default_rng(3)
    for k in range(50):
        u = tp.u_r + [0.05 * rng.standard_normal(), math.radians(1.0) * rng.standard_normal()]
        if k == 20:
            u[1] = 1.0  # beyond +30 deg: saturated
        p.step(u)
        x = rk4_cm(x, np.clip(u, vehicle.limits.u_min, vehicle.limits.u_max)[None], rec, 0.02, 5)
        assert np.array_equal(p.x, x)
        assert np.array_equal(
            p.positions[0], np.clip(u, vehicle.limits.u_min, vehicle.limits.u_max)
        )


def test_actuator_data_and_the_key_are_checked(vehicle, raw):
    from fahv.spec.files import spec_file

    data = load_yaml(resources.files("fahv.data").joinpath("vehicle_parker2007.yaml").read_text())
    bad = copy.deepcopy(data)
    del bad["actuators"]["second_order"]["delta_e"]["omega_n"]["source"]
    with pytest.raises(VehicleDataError, match="'actuators.second_order.delta_e.omega_n' has no"):
        vehicle_from_mapping(bad)
    bad = copy.deepcopy(data)
    bad["actuators"]["second_order"]["delta_e"]["rate_limit_incr"]["unit"] = "rad/s"
    with pytest.raises(VehicleDataError) as err:
        vehicle_from_mapping(bad)
    assert str(err.value) == (
        "<mapping>: 'actuators.second_order.delta_e.rate_limit_incr' has unit 'rad/s'; "
        "expected one of ['1/s', 'deg/s']"
    )
    bad = copy.deepcopy(data)
    bad["actuators"]["third_order"] = bad["actuators"]["second_order"]
    with pytest.raises(VehicleDataError, match="'actuators.third_order': unknown actuator model"):
        vehicle_from_mapping(bad)
    del data["actuators"]
    with pytest.raises(ParameterError, match="parameter 'actuators' = 'second_order'"):
        servos_of(vehicle_from_mapping(data), "second_order")
    assert servos_of(vehicle, "ideal") is None
    with pytest.raises(SpecError, match="key 'plant.actuators' must be one of"):
        spec_file({**raw, "plant": {"actuators": "third_order"}})
    with pytest.raises(SpecError, match="unknown key 'plant.lag'"):
        spec_file({**raw, "plant": {"actuators": "ideal", "lag": 1.0}})
    with pytest.raises(SpecError, match="key 'fault.side' must be -1"):
        spec_file({**raw, "fault": {"kind": "hardover", "t_onset": 1.0, "side": 0.5}})
    assert "plant" not in spec_file(raw).data  # absent: the run spec (and hash) as before


def test_hardover_commands_the_limit_of_its_side(vehicle):
    """With ideal actuators the elevator jumps to the limit at the onset; the kind needs
    the limits and a side of -1 or 1."""
    lim = vehicle.limits
    faults = [make_fault("hardover", 1.0, {"side": s}) for s in (1.0, -1.0)]
    inj = FaultInjector(faults, lim)
    u = np.array([[0.3, 0.2], [0.3, 0.2]])
    np.testing.assert_array_equal(inj.apply(0.98, u), u)
    np.testing.assert_array_equal(inj.apply(1.0, u)[:, 1], [lim.delta_e_max, lim.delta_e_min])
    with pytest.raises(ConfigError, match="needs the actuators' position limits"):
        FaultInjector(make_fault("hardover", 1.0, {"side": 1.0}))
    with pytest.raises(ConfigError, match="parameter 'side' must be -1 or 1"):
        make_fault("hardover", 1.0, {"side": 0.5})


def test_the_servos_rate_limits_reach_the_input_limits_and_not_the_design(vehicle):
    """The vehicle file's elevator servo (100 deg/s each way, Phi without one) gives the
    rate limits a run's commands are checked against (`InputLimits.rate_incr/decr`,
    `fahv.runs.metrics.rate_violations`); they stay out of the vehicle's physics hash,
    so a design is not stale when only the servos change; without servo data no rate
    is limited."""
    from fahv.model.vehicle import physics_hash
    from fahv.runs.metrics import rate_violations

    lim = vehicle.limits
    assert lim.rate_incr == (math.inf, pytest.approx(math.radians(100.0), rel=1e-15))
    assert lim.rate_decr == lim.rate_incr
    data = load_yaml(resources.files("fahv.data").joinpath("vehicle_parker2007.yaml").read_text())
    data["actuators"]["second_order"]["delta_e"]["rate_limit_decr"]["value"] = 50.0
    slower = vehicle_from_mapping(data)
    assert slower.limits.rate_decr[1] == pytest.approx(math.radians(50.0), rel=1e-15)
    assert physics_hash(slower) == physics_hash(vehicle)
    u = np.zeros((4, 2))
    u[1, 1] = -math.radians(1.5)  # -75 deg/s, then +75 deg/s, then +0 (Ts = 0.02 s)
    assert rate_violations(u, 0.02, lim) == 0
    assert rate_violations(u, 0.02, slower.limits) == 1  # the step down only
    del data["actuators"]
    assert vehicle_from_mapping(data).limits.rate_incr == (math.inf, math.inf)


@pytest.mark.parametrize("dde_deg", [0.5, 17.6])
def test_the_peak_rate_within_a_period_is_the_largest_of_its_sub_steps(vehicle, setup, dde_deg):
    """One period of 5 sub-steps returns each servo's peak |rate|: the largest |rate state|
    of the 5 sub-steps one at a time, to the bit, and at least its position's average rate
    over the period (0.5 deg from rest: 1.42 times it); on a 17.6 deg step the elevator's
    peak is its 100 deg/s rate limit."""
    tp, ap, rec = setup
    a0 = [tp.u_r[0], 0.0, tp.u_r[1], 0.0]
    u = tp.u_r + [0.05, math.radians(dde_deg)]
    one_by_one = servo_run(setup, a0, u, 5)
    X, A, peak = rk4_cm_act(tp.x_r[None].copy(), np.array([a0], float), np.array([u], float),
                            rec, ap[None], np.array([False]), 5 * DT, 5)  # fmt: skip
    assert np.array_equal(A[0], one_by_one[-1])
    assert peak[0, 0] == np.abs(one_by_one[1:, 1]).max()
    assert peak[0, 1] == np.abs(one_by_one[1:, 3]).max()
    average = abs(one_by_one[-1, 2] - a0[2]) / (5 * DT)
    assert peak[0, 1] >= average * (1 - 1e-12)
    if dde_deg < 10:
        assert peak[0, 1] == pytest.approx(1.42 * average, rel=0.01)
    else:
        assert peak[0, 1] == vehicle.actuators["second_order"]["delta_e"].rate_limit_incr
