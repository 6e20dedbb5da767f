"""Plant integrator, parameter perturbation and fault models."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fahv.errors import ConfigError
from fahv.model.dynamics import cm_rhs
from fahv.model.trim import trim
from fahv.plant.faults import FaultInjector, LossOfEffectiveness, make_fault
from fahv.plant.integrator import Plant, rk4_step
from fahv.plant.uncertainty import PAPER_UNCERTAINTY, perturb


def test_rk4_matches_adaptive_reference(vehicle):
    tp = trim(vehicle, 85500.0, 7900.0)
    x0 = tp.x_r + np.array([0, 0, 1e-3, 0, 2e-3, 0.05, 0, 0.01, 0])
    u = tp.u_r + np.array([0.01, -0.005])
    # 0.2 s with Ts = 0.02 s, 10 RK4 steps per period (dt = 2 ms, omega_2 dt = 0.1)
    x = x0.copy()
    for _ in range(10):
        x = rk4_step(lambda a, b: cm_rhs(a, b, vehicle.params), x, u, 0.02, 10)
    ref = solve_ivp(
        lambda t, y: cm_rhs(y, u, vehicle.params),
        (0, 0.2),
        x0,
        rtol=1e-11,
        atol=1e-12,
        method="DOP853",
    ).y[:, -1]
    err = np.abs(x - ref) / vehicle.state_scale
    # RK4 phase error of mode 2: (omega_2 dt)^4 / 120 * omega_2 t = 8e-6 rad times an
    # eta_2_dot amplitude of ~0.05 -> ~4e-7 (measured 3.4e-7); rigid states ~1e-11
    assert err.max() < 1e-6
    assert err[:4].max() < 1e-9


def test_trim_is_equilibrium_of_plant(vehicle):
    tp = trim(vehicle, 85500.0, 7900.0, "cm")
    p = Plant(vehicle.params, vehicle.limits, tp.x_r, 0.02, 10)
    for _ in range(50):
        p.step(tp.u_r)
    # 1 s; the unstable short period (+1.7 1/s) amplifies rounding only to ~1e-12
    assert np.max(np.abs(p.x - tp.x_r) / vehicle.state_scale) < 1e-8


def test_the_plant_compiles_its_kernels_when_built_and_only_once(vehicle):
    """The plant node's step 1 is timed by its peers' watchdogs: the kernels (ideal and
    servo actuators) are compiled by the constructor, the steps add no specialisation,
    and the zero-length warm-up step leaves the state as given."""
    from fahv.plant import rk4

    tp = trim(vehicle, 85500.0, 7900.0)
    p = Plant(vehicle.params, vehicle.limits, tp.x_r, 0.02, 10, vehicle.actuators["second_order"])
    n_cm, n_act = len(rk4.rk4_cm.signatures), len(rk4.rk4_cm_act.signatures)
    assert n_cm >= 1 and n_act >= 1
    assert np.array_equal(p.x[0], tp.x_r) and p.a is None
    p.step(tp.u_r)
    p.step(tp.u_r, held=[True])
    assert (len(rk4.rk4_cm.signatures), len(rk4.rk4_cm_act.signatures)) == (n_cm, n_act)


def test_plant_saturates_and_rejects_bad_input(vehicle):
    tp = trim(vehicle, 85500.0, 7900.0)
    p = Plant(vehicle.params, vehicle.limits, tp.x_r, 0.02, 10)
    with pytest.raises(ValueError, match="finite"):
        p.step(np.array([np.nan, 0.2]))
    with pytest.raises(ValueError, match="9 finite values"):
        Plant(vehicle.params, vehicle.limits, np.zeros(8), 0.02, 10)


def test_perturb_box(vehicle):
    signs = {k: 1.0 for k in PAPER_UNCERTAINTY}
    vp = perturb(vehicle.params, PAPER_UNCERTAINTY, signs)
    assert vp.m == pytest.approx(330.0, rel=1e-12)
    assert vp.c_e == pytest.approx(-1.2897 * 1.03, rel=1e-12)
    assert vp.beta_2 == vehicle.params.beta_2  # not in the box
    with pytest.raises(ValueError, match="unknown parameter 'mass'"):
        perturb(vehicle.params, {"mass": 0.1}, {})


def test_fault_models():
    u = np.array([[0.3, 0.2]])
    loe = FaultInjector(make_fault("loss_of_effectiveness", 100.0, {"rho_f": 0.9}))
    np.testing.assert_allclose(loe.apply(99.98, u), u)
    np.testing.assert_allclose(loe.apply(100.0, u), [[0.3, 0.18]])  # whole deflection scaled
    stuck = FaultInjector(make_fault("stuck", 1.0, {}))
    stuck.apply(0.5, np.array([[0.3, 0.1]]))
    assert stuck.apply(1.0, np.array([[0.3, 0.25]]))[0, 1] == pytest.approx(0.1)
    assert stuck.apply(2.0, np.array([[0.3, -0.2]]))[0, 1] == pytest.approx(0.1)
    bias = FaultInjector(make_fault("bias", 0.0, {"bias_deg": math.degrees(0.01)}))
    assert bias.apply(0.0, u)[0, 1] == pytest.approx(0.21)
    drop = FaultInjector(make_fault("dropout", 1.0, {}))
    drop.apply(0.9, np.array([[0.3, 0.1]]))
    np.testing.assert_allclose(drop.apply(1.0, np.array([[0.5, 0.3]])), [[0.3, 0.1]])


def test_fault_injector_of_mixed_kinds_acts_per_run():
    faults = [
        make_fault("stuck", 1.0, {}),
        make_fault("loss_of_effectiveness", 0.0, {"rho_f": 0.5}),
        make_fault("none", 0.0, {}),
        make_fault("stuck", 2.0, {}),
    ]
    inj = FaultInjector(faults)
    assert inj.kind == ["stuck", "loss_of_effectiveness", "none", "stuck"]
    u = np.tile([0.3, 0.1], (4, 1))
    np.testing.assert_array_equal(inj.apply(0.5, u)[:, 1], [0.1, 0.05, 0.1, 0.1])
    u[:, 1] = 0.2
    np.testing.assert_array_equal(inj.apply(1.0, u)[:, 1], [0.1, 0.1, 0.2, 0.2])  # run 0 held
    u[:, 1] = 0.3
    np.testing.assert_array_equal(inj.apply(2.0, u)[:, 1], [0.1, 0.15, 0.3, 0.2])  # run 3 too
    np.testing.assert_array_equal(inj.active(1.5), [True, True, False, False])
    np.testing.assert_array_equal(inj.rho_f, [1.0, 0.5, 1.0, 1.0])
    with pytest.raises(ConfigError, match="needs parameter"):
        LossOfEffectiveness(0.0)
    with pytest.raises(ConfigError, match="unknown fault kind 'melted'"):
        make_fault("melted", 0.0, {})


def test_perturbed_records_are_perturb_vectorised_to_the_bit():
    """perturbed_records over the 1024 corners and 300 interior fractions of the sec. 5.1
    box gives exactly the records of perturb (the same arithmetic); a wrong shape, NaN,
    a fraction outside [-1, 1] or an unknown parameter is refused, named."""
    import itertools

    from fahv.model.vehicle import load_vehicle
    from fahv.plant.rk4 import params_records, perturbed_records
    from fahv.plant.uncertainty import PAPER_UNCERTAINTY, perturb

    vp = load_vehicle().params
    names = list(PAPER_UNCERTAINTY)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=len(names))))
    inner = np.random.default_rng(5).uniform(-1.0, 1.0, (300, len(names)))
    signs = np.vstack([corners, inner])
    got = perturbed_records(vp, PAPER_UNCERTAINTY, signs)
    ref = params_records([perturb(vp, PAPER_UNCERTAINTY, dict(zip(names, s, strict=True)))
                          for s in signs])  # fmt: skip
    assert got.shape == (1324,)
    for f in ref.dtype.names:
        assert np.array_equal(got[f], ref[f]), f
    assert got["m"].max() == pytest.approx(vp.m * 1.1, rel=1e-15)
    with pytest.raises(ValueError, match=r"signs must be \(B, 10\)"):
        perturbed_records(vp, PAPER_UNCERTAINTY, signs[:, :9])
    bad = signs[:2].copy()
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        perturbed_records(vp, PAPER_UNCERTAINTY, bad)
    with pytest.raises(ValueError, match=r"\[-1, 1\]"):
        perturbed_records(vp, PAPER_UNCERTAINTY, 1.5 * signs[:2])
    with pytest.raises(ValueError, match="unknown parameter 'mass'"):
        perturbed_records(vp, {"mass": 0.1}, np.zeros((1, 1)))


def test_servo_factors_scale_each_vehicles_servos_and_refuse_what_is_not_physical():
    """Kernel rows [zeta, omega_n, rate_incr, rate_decr, min, max]: omega_n, zeta and both
    rate limits scaled per vehicle, the position limits kept; ones keep every bit."""
    from fahv.plant.integrator import scaled_servos

    base = np.array([[0.7, 50.0, 1.0, 2.0, 0.0, 1.5], [0.6, 150.0, 1.7, 1.7, -0.5, 0.5]])
    out = scaled_servos(base, [[1.0, 1.0, 1.0], [0.5, 2.0, 0.8]])
    assert out.shape == (2, 2, 6) and np.array_equal(out[0], base)
    np.testing.assert_array_equal(out[1, :, 1], base[:, 1] * 0.5)
    np.testing.assert_array_equal(out[1, :, 0], base[:, 0] * 2.0)
    np.testing.assert_array_equal(out[1, :, 2:4], base[:, 2:4] * 0.8)
    np.testing.assert_array_equal(out[1, :, 4:], base[:, 4:])
    for bad in ([0.0, 1.0, 1.0], [1.0, -0.1, 1.0], [1.0, 1.0, 0.0], [1.0, math.nan, 1.0]):
        with pytest.raises(ValueError, match="omega_n and rate_limit must be > 0, zeta >= 0"):
            scaled_servos(base, [bad])
