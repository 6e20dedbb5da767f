"""The probabilistic tube of the implementable loop (fahv.stochastic.closed_loop with the
plant's servos, the filter with their states and the scenario's altitude-rate disturbance,
the adjustable law tau F): the joint bound holds at every pair, the nonlinear loop of
case1_implementable deviates as it says, and the command's step it predicts for a whole
run stays within the elevator servo's rate; the figures of docs/theory/estimation.md."""

import numpy as np
import pytest

from fahv.certificate.verified import load_or_design
from fahv.estimation.kalman import design_filter, measurement_covariance
from fahv.sensors.data import DEFAULT_MEASURED, load_sensors
from fahv.stochastic.closed_loop import joint_system, loop_tube, radii
from fahv.stochastic.error_bound import error_system

MEASURED = list(DEFAULT_MEASURED)
SCENARIO = "offline_design/scenarios/case1_implementable.yaml"
#: The pairs (model vertex, gain vertex) that carry the covariance bound: of the 36 its
#: constraint generation from the matched pairs ends with (three solves), the ten of the
#: largest duals (each above 250, the other 26 below 120). Given as its start, the bound
#: takes one solve of ten LMIs instead of three of up to 36: the same Sigma within 5e-5
#: of its largest entry and the same figures to 0.1 % (measured), every pair re-checked
#: exactly either way (a pair the solve left violated would be added), so the start
#: changes the work, not what is certified.
PAIRS = [(8, 4), (8, 8), (9, 8), (4, 8), (8, 9), (4, 4), (8, 3), (9, 9), (4, 9), (4, 18)]
#: The pairs the flight-path filter's bound ends with from the matched pairs (its `pairs`):
#: the same bound in one solve.
FLIGHT_PATH_PAIRS = [(i, i) for i in range(20)] + [
    (8, 4), (4, 8), (4, 5), (4, 18), (8, 14), (18, 4), (8, 1), (5, 4), (14, 8), (1, 8),
    (4, 9), (4, 19), (4, 14), (4, 6), (8, 9), (4, 3), (4, 16)]  # fmt: skip
#: The corners of the sec. 5.1 box the nonlinear loop flies: (s_mass, s_aero).
CORNERS = [(-1, -1), (-1, 1), (1, -1), (1, 1)]


@pytest.fixture(scope="module")
def implementable():
    spec, design, vehicle = load_or_design(SCENARIO, log=lambda *_: None, variants=["tube_mpc"],
                                           allow_uncertified=True)  # fmt: skip
    tau = spec.data["estimator"]["tube_tau"]
    a, data = design.arrays, load_sensors()
    flt = design_filter(a, vehicle, data, MEASURED, 0.02, 5, a["x0"][None],
                        vehicle.actuators["second_order"],
                        spec.data["estimator"]["state_disturbance"])  # fmt: skip
    js, pt = loop_tube(error_system(flt), flt, a, tau, measurement_covariance(MEASURED, data),
                       start=PAIRS)  # fmt: skip
    return design, vehicle, tau, js, pt


@pytest.fixture(scope="module")
def loops(implementable):
    """The nonlinear loop of case1_implementable's tube_mpc, 100 s (before the fault), sensor
    seed 0: {None: the nominal vehicle, (s_mass, s_aero): the vehicle at that corner of the
    sec. 5.1 box (m and I_yy at s_mass, the eight other parameters at s_aero)}, the five
    runs one batch (each run the bits `simulate` gives it alone: tests/loop/test_batch.py)."""
    from fahv.loop.batch import simulate_batch
    from fahv.plant.uncertainty import PAPER_UNCERTAINTY

    design, vehicle, _, _, _ = implementable
    nominal = vehicle.params
    plants = [{"plant": {f"params.{k}": getattr(nominal, k) * (
        1.0 + (s_mass if k in ("m", "I_yy") else s_aero) * rel)
        for k, rel in PAPER_UNCERTAINTY.items()}} for s_mass, s_aero in CORNERS]  # fmt: skip
    runs = simulate_batch(design, "tube_mpc", [None, *plants], duration=100.0)
    for run in runs:
        if isinstance(run, Exception):
            raise run
    return dict(zip([None, *CORNERS], runs, strict=True))


def deviation(run, pt, t_from: float = 40.0):
    """A run's deviation from its nominal against the tube `pt` over t >= t_from, t = x - x_r -
    x_n, as tests/studies/conftest.py's `loop_deviation` measures it of the run it flies:
    (std of t in V, alpha, theta, q over the bound's, std of the elevator command's step
    over the bound's, largest |t| of alpha and theta, their mean, largest |t - mean|, the
    bound's whole-run radius at p = 0.99) [rad]."""
    from fahv.model.vehicle import ALPHA, IQ, THETA, V

    k = run.t >= t_from
    t = (run.x - run.x_r - run.x_n[:, :9])[k]
    att = t[:, [ALPHA, THETA]]
    _, r_run = radii(0.99, len(run.t))
    mean = att.mean(axis=0)
    out = (t[:, [V, ALPHA, THETA, IQ]].std(axis=0) / pt.std_t[:4],
           float(np.diff(run.u[k, 1]).std() / pt.std_step[1]), np.abs(att).max(axis=0), mean,
           np.abs(att - mean).max(axis=0), r_run * pt.std_t[1:3])  # fmt: skip
    print("measured / bound:", np.round(out[0], 3), round(out[1], 3),
          "largest, mean, largest about it, radius [deg]:",
          *(np.round(np.degrees(a), 3) for a in out[2:]))  # fmt: skip
    return out


def test_the_joint_bound_with_the_servos_holds_at_every_pair(implementable, bound_checks):
    """xi = [t (8); the plant's servo states (4); the filter's error (16, d_h its last)] at
    tau = 0.8: Sigma - A_ij Sigma A_ij' - N_j R_v N_j' >= 0 at all 400 pairs (scipy's
    eigvalsh, unscaled, to 1e-12 of Sigma's largest entry). The figures (1 %): 1 sigma of
    t in alpha and theta 0.0222 and 0.0222 deg, of the tube's elevator 0.729 deg, of its
    step 0.356 deg per step (without d_h, 27 states: 0.0221, 0.0222, 0.727 and 0.356)."""
    _, _, tau, js, pt = implementable
    assert tau == 0.8 and js.n_s == 4 and pt.Sigma.shape == (28, 28)
    *_, joint_figures = bound_checks
    joint_figures(js, pt, [0.0222, 0.0222], 0.729, 0.356)


def test_the_command_step_stays_within_the_servo_rate_for_a_run(implementable):
    """With p = 0.99 over a 300 s run the command's step from the noise stays within
    4.97 sigma: 1.77 deg, inside the 2 deg per step of the 100 deg/s servo (with the
    design's F, tau 1, the same bound is 2.27 deg: beyond it, `fahv-studies estimation` of
    case1_implementable_zero_start)."""
    _, vehicle, _, _, pt = implementable
    _, r_run = radii(0.99, 15000)
    step = np.degrees(r_run * pt.std_step[1])
    assert step == pytest.approx(1.77, abs=0.01)
    assert step <= np.degrees(vehicle.limits.rate_decr[1]) * 0.02


def test_the_nonlinear_implementable_loop_deviates_as_the_bound_says(implementable, loops):
    """case1_implementable's tube_mpc, 100 s (before the fault), sensor seed 0: over 40-100 s
    the standard deviation of t = x - x_r - x_n in alpha, theta and q within 15 % of the
    bound's, the elevator command's step within 10 % (measured 0.944, 0.942, 0.891 and
    0.965 of it), and the largest |t| of alpha and theta within the run's radius at
    p = 0.99 (measured 0.059 deg against 0.105). V's is 1.23 of the bound's and held
    below 1.35: the nominal's disturbance estimate at 2 s passes the estimate's noise on
    to the nominal's speed, which the bound leaves out (1.004 at 5 s without the
    altitude-rate disturbance, measured on case1_implementable_slow_estimate)."""
    _, _, _, _, pt = implementable
    ratio, step, largest, _, _, reach = deviation(loops[None], pt)
    assert np.all(np.abs(ratio[1:] - 1.0) < 0.15) and ratio[0] < 1.35, ratio
    assert abs(step - 1.0) < 0.1, step
    assert np.all(largest <= reach)


def test_a_filter_without_the_plants_servos_is_refused(implementable):
    """The error system must be of the plant's actuators: an 11-state filter's with
    servos in the plant is refused by name."""
    design, vehicle, _, js, _ = implementable
    a = design.arrays
    flt = design_filter(a, vehicle, load_sensors(), MEASURED, 0.02, 5, a["x0"][None])
    with pytest.raises(ValueError, match="a filter of 11 states with the servos in the plant"):
        joint_system(error_system(flt), a["A"], a["B"], a["F"], js_servos(vehicle), 0.02)


def js_servos(vehicle):
    """The plant's servo rows (2, 6) of the vehicle file."""
    from fahv.model.actuators import kernel_parameters

    return kernel_parameters(vehicle.actuators["second_order"], vehicle.limits.u_min,
                             vehicle.limits.u_max)  # fmt: skip


@pytest.mark.parametrize("s_mass, s_aero", CORNERS)
def test_the_bound_holds_at_the_corners_of_the_uncertainty_box(implementable, loops, s_mass,
                                                             s_aero):
    """The same nonlinear loop with the simulated vehicle at a corner of the sec. 5.1 box
    (m and I_yy at s_mass, the eight other parameters at s_aero; 100 s, sensor seed 0).
    By linearity t is the noise's part plus the model error's; over 40-100 s:

    - the noise's part, t about its mean: alpha, theta and q's standard deviation and the
      command's step within 15 % of the bound (measured 0.92-1.10), the largest |t - mean|
      of alpha and theta within the run's radius at p = 0.99 (measured up to 0.071 deg
      against 0.105);
    - the model error's part, t's mean: within its frozen worst case `model_t` (0.32 deg
      of alpha, 0.57 of theta). Measured: alpha 0.08-0.10 deg at every corner, the sign
      of the mass's error, held at 0.09 +/- 0.02 (0.04-0.05 without d_h: the filter then
      keeps the offset in h); theta's within 0.001 deg, held within 0.005. The whole |t|
      of alpha reaches 0.17 deg, beyond the noise's radius: the bound of the noise alone
      does not hold a dispersed vehicle's alpha.

    V is not held: a dispersed vehicle's speed drifts from the nominal's by its model
    error, which the noise's bound leaves out."""
    _, _, _, _, pt = implementable
    ratio, step, _, mean, about, reach = deviation(loops[s_mass, s_aero], pt)
    assert np.all(np.abs(ratio[1:] - 1.0) < 0.15) and abs(step - 1.0) < 0.15, (ratio, step)
    assert np.all(about <= reach)
    assert np.all(np.abs(mean) <= pt.model_t[1:3])
    assert s_mass * np.degrees(mean[0]) == pytest.approx(0.09, abs=0.02)
    assert abs(np.degrees(mean[1])) < 0.005


def test_the_flight_path_disturbance_joins_the_error_system(implementable):
    """A filter with the flight-path disturbance (16 states with the servos): its error
    system's covariance bound holds at every pair (the exact re-check), its joint system
    with the servos has 28 states, and d_gamma's error is bounded (1 sigma 2.1e-5 rad/s from
    the sensors' noise, 10 %)."""
    from fahv.stochastic.error_bound import covariance_bound

    design, vehicle, tau, _, _ = implementable
    a = design.arrays
    flt = design_filter(a, vehicle, load_sensors(), MEASURED, 0.02, 5, a["x0"][None],
                        vehicle.actuators["second_order"], "flight_path")  # fmt: skip
    es = error_system(flt)
    cov = covariance_bound(es, measurement_covariance(MEASURED, load_sensors()),
                           start=FLIGHT_PATH_PAIRS)  # fmt: skip
    assert es.M.shape[-1] == 16 and cov.min_eig >= 0.0
    assert np.sqrt(cov.S[-1, -1]) == pytest.approx(2.1e-5, rel=0.1)
    js = joint_system(es, a["A"], a["B"], tau * a["F"], js_servos(vehicle), 0.02)
    assert js.system.M.shape[-1] == 28
