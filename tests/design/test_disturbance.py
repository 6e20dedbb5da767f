"""Disturbance set W (eq. 13-19) on the real model, small seeded sample."""

import numpy as np
import pytest

from fahv.bounds.disturbance import INPUT_DEVIATIONS, STATE_DEVIATIONS, sample_disturbance
from fahv.plant.uncertainty import PAPER_UNCERTAINTY


def _sample(vehicle, tp, margin=1.2):
    return sample_disturbance(
        vehicle,
        tp,
        0.02,
        PAPER_UNCERTAINTY,
        0.9,
        STATE_DEVIATIONS,
        INPUT_DEVIATIONS,
        25,
        seed=0,
        margin=margin,
    )


@pytest.fixture(scope="module")
def wset(vehicle, tp_cm):
    return _sample(vehicle, tp_cm)


def test_w_is_margin_times_total(wset):
    np.testing.assert_allclose(wset.w_max, 1.2 * wset.parts["total"])
    assert np.all(wset.w_max > 0)


def test_fault_dominates_flexible_and_pitch_rows(vehicle, wset):
    dom = wset.dominant()
    # the 10 % elevator loss on a ~12-15 deg deflection drives q and eta_2 through
    # M_delta_e and N2_delta_e; measured: fault 0.065 vs parameters 0.030 (q, scaled)
    assert dom[4] == "fault" and dom[8] == "fault"


def test_cm_design_model_error_is_small(vehicle, wset):
    # CM-based LPV vs nonlinear CM: one-step error in q below 0.01 deg/s (scaled < 0.01)
    assert wset.parts["model"][4] / vehicle.state_scale[4] < 0.01


def test_seeded_and_reproducible(vehicle, tp_cm, wset):
    np.testing.assert_array_equal(_sample(vehicle, tp_cm).w_max, wset.w_max)
    with pytest.raises(ValueError, match="margin"):
        _sample(vehicle, tp_cm, margin=0.5)


def test_deviation_box_appends_the_notch_states_for_the_ecm_only():
    """The CM / DM box is a copy of STATE_DEVIATIONS; the ECM's appends twice the filter's
    steady states for the given q scale; a q scale that is not positive and finite is
    refused naming it."""
    from fahv.bounds.disturbance import state_deviations
    from fahv.model.notch import NotchFilter

    cm = state_deviations()
    np.testing.assert_array_equal(cm, STATE_DEVIATIONS)
    cm[0] = 0.0  # a copy: the module's box is untouched
    assert STATE_DEVIATIONS[0] == 600.0
    nf = NotchFilter(20.0, 0.0, 25.0, 0.5)
    ecm = state_deviations(nf, 0.05)
    assert ecm.shape == (11,)
    np.testing.assert_array_equal(ecm[:9], STATE_DEVIATIONS)
    # twice the filter's steady states for q = 0.05 rad/s: q / omega_p, q / omega_p^2
    np.testing.assert_allclose(ecm[9:], [2 * 0.05 / 25.0, 2 * 0.05 / 625.0], rtol=1e-12)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="q_scale"):
            state_deviations(nf, bad)
