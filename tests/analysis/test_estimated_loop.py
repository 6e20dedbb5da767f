"""The tube law on the Kalman estimate broken at the elevator (fahv.analysis.estimated_loop):
it closes into the state-feedback loop and the filter's error (the separation principle),
it is the state-feedback loop when the filter passes the state through, and its margins on
cm_certified with the sensors of case1_kalman."""

from __future__ import annotations

import numpy as np
import pytest

from fahv.analysis.estimated_loop import (
    estimated_closed_loop,
    estimated_loop,
    estimated_loop_systems,
    estimated_margins,
    filter_models,
)
from fahv.analysis.margin_study import notch_settings, vertex_plants
from fahv.analysis.margins import closed_loop, loop_systems
from fahv.estimation.kalman import design_filter
from fahv.estimation.servo_model import servo_plants
from fahv.model.actuators import kernel_parameters
from fahv.model.vehicle import load_vehicle
from fahv.sensors.data import load_sensors
from fahv.sil.workspace import ROOT
from fahv.spec.artefacts import load_design

TS = 0.02
MEASURED = ["h", "V", "theta", "q"]


@pytest.fixture(scope="module")
def certified():
    return load_design(ROOT / "offline_design" / "designs" / "cm_certified")


@pytest.fixture(scope="module")
def kalman(certified):
    a = certified.arrays
    return design_filter(a, load_vehicle(), load_sensors(), MEASURED, TS, 2, a["x0"][None])


@pytest.fixture(scope="module")
def kalman_servos(certified):
    a, veh = certified.arrays, load_vehicle()
    return design_filter(a, veh, load_sensors(), MEASURED, TS, 2, a["x0"][None],
                         veh.actuators["second_order"])  # fmt: skip


def _separation(A_p, B_p, F_p, s, A_z, B_z, flt, vertices):
    """The loop's eigenvalues against the state-feedback loop's and the filter error's."""
    C_z = np.hstack([flt.C, np.zeros((len(flt.C), A_z.shape[1] - 9))])
    A_cl = estimated_closed_loop(*estimated_loop(A_p, B_p, s.F, s.notch, TS, A_z, B_z, flt.L,
                                                 flt.C))  # fmt: skip
    for i in vertices:
        got = np.sort_complex(np.linalg.eigvals(A_cl[i]))
        err = A_z[i] @ (np.eye(A_z.shape[1]) - flt.L[i] @ C_z)
        sf = closed_loop(A_p[i : i + 1], B_p[i : i + 1], F_p, s.notch, TS)[0]
        ref = np.sort_complex(np.concatenate([np.linalg.eigvals(sf), np.linalg.eigvals(err)]))
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)


def test_the_loop_closes_into_the_state_feedback_loop_and_the_filter_error(certified, kalman):
    """At each vertex (plant and filter matched) the closed loop's eigenvalues are those of
    the tube loop with the exact state and of the filter's a-priori error A_z (I - L C_z)."""
    v = vertex_plants(certified)
    for s in notch_settings(certified)[:2]:  # the notch at omega_1, and none
        _separation(v.A, v.B, s.F, s, *filter_models(v.A, v.B), kalman, (0, 7, 19))


def test_with_the_servos_in_plant_and_filter_the_separation_holds_too(certified, kalman_servos):
    """The airframe with its servos ([x; s], 13 states) and the filter with their states
    (15): the eigenvalues are those of the state-feedback loop on the servoed airframe (F
    on the airframe's states) and of the filter's error."""
    v = vertex_plants(certified)
    AP = kalman_servos.servos
    np.testing.assert_array_equal(AP, kernel_parameters(load_vehicle().actuators["second_order"],
                                                        *_limits()))  # fmt: skip
    A_p, B_p = servo_plants(v.A, v.B, AP, TS)
    assert A_p.shape[1:] == (13, 13) and B_p.shape[1:] == (13, 2)
    s = notch_settings(certified)[0]
    F_p = np.hstack([s.F, np.zeros((2, 4))])
    _separation(A_p, B_p, F_p, s, *filter_models(v.A, v.B, AP, TS), kalman_servos, (0, 19))


def _limits():
    lim = load_vehicle().limits
    return lim.u_min, lim.u_max


def test_a_filter_that_passes_the_state_through_gives_the_state_feedback_loop(certified):
    """Every state measured and L = [I; 0] (x_hat = x after the correction): the loop at the
    elevator has the frequency response of the state-feedback loop, to 1e-9."""
    v = vertex_plants(certified)
    A, B = v.A[:3], v.B[:3]
    A_z, B_z = filter_models(A, B)
    L = np.broadcast_to(np.vstack([np.eye(9), np.zeros((2, 9))]), (3, 11, 9))
    s = notch_settings(certified)[0]
    est = estimated_loop_systems(*estimated_loop(A, B, s.F, s.notch, TS, A_z, B_z, L,
                                                 np.eye(9)), TS)  # fmt: skip
    sf = loop_systems(v.__class__(v.names[:3], A, B), s.F, s.notch, TS, "delta_e")
    z = np.exp(1j * np.array([0.1, 1.0, 10.0, 19.0, 100.0]) * TS)
    for e, f in zip(est, sf, strict=True):
        np.testing.assert_allclose(np.squeeze(e(z)), np.squeeze(f(z)), rtol=1e-9)
    with pytest.raises(ValueError, match="shapes"):
        estimated_loop(A, B, s.F, s.notch, TS, A_z, B_z, L[:, :, :4], np.eye(9))


def test_the_estimate_costs_the_elevator_loop_its_margins(certified, kalman):
    """cm_certified's law on the estimate of h, V, theta and q (measured): at the design
    point 5.0 dB up and 30.1 deg with the notch, against 7.0 dB and 43.4 deg on the exact
    state; the filter itself rolls the loop off at omega_1 (-6.6 dB without the notch,
    -0.7 on the exact state)."""
    rows = {(r.notch, r.point): r for r in
            estimated_margins(certified, kalman, notch_settings(certified)[:2])}  # fmt: skip
    assert set(rows) == {("omega_1", "design point"), ("omega_1", "worst of 20 vertices"),
                         ("off", "design point"), ("off", "worst of 20 vertices")}
    dp = rows["omega_1", "design point"]
    assert dp.stable and dp.break_at == "delta_e on x_hat"
    assert dp.gm_up_db == pytest.approx(5.0, abs=0.1)
    assert dp.pm_deg == pytest.approx(30.1, abs=0.3)
    assert dp.gain_w1_db == pytest.approx(-13.8, abs=0.2)
    assert rows["off", "design point"].gain_w1_db == pytest.approx(-6.6, abs=0.2)
    assert rows["omega_1", "worst of 20 vertices"].gm_up_db == pytest.approx(3.9, abs=0.1)


def test_the_servos_cost_the_loop_on_the_estimate_another_3_deg(certified, kalman_servos):
    """case1_implementable's loop (servos in the plant and the filter): 4.7 dB and 26.7 deg
    at the design point with the notch, against 5.0 dB and 30.1 deg without the servos."""
    (dp, worst) = estimated_margins(certified, kalman_servos, notch_settings(certified)[:1])
    assert (dp.point, worst.point) == ("design point", "worst of 20 vertices")
    assert dp.gm_up_db == pytest.approx(4.7, abs=0.1)
    assert dp.pm_deg == pytest.approx(26.7, abs=0.3)
    assert worst.pm_deg == pytest.approx(25.9, abs=0.3)
