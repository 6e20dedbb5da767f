"""Tube feasibility on the real vehicle (docs/theory/certificate.md), reduced sample sizes."""

import warnings

import numpy as np
import pytest

from fahv.bounds.disturbance import INPUT_DEVIATIONS, STATE_DEVIATIONS
from fahv.bounds.vertices import fault_vertices
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.feedback import verify_tube
from fahv.tube.feasibility import input_room, tube_feasibility


def _run(vehicle, tp, treatment):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return tube_feasibility(
            vehicle,
            tp,
            0.02,
            PAPER_UNCERTAINTY,
            0.9,
            STATE_DEVIATIONS,
            INPUT_DEVIATIONS,
            60,
            0,
            1.2,
            treatment,
            (0.98, 0.99),
        )


def test_input_room(vehicle):
    room = input_room(vehicle)
    # trim Phi 0.265..0.279 -> room 0.265 (to Phi = 0); trim delta_e <= 13.0 deg -> 17.0 deg
    assert room[0] == pytest.approx(0.2649, abs=1e-3)
    assert np.degrees(room[1]) == pytest.approx(17.03, abs=0.05)


def test_polytopic_fault_gives_certified_nonempty_tube(vehicle, tp_cm):
    res = _run(vehicle, tp_cm, "polytopic")
    assert res.tube is not None
    disc = tp_cm.discretize(0.02)
    A, B = fault_vertices(disc.A, disc.B, 0.9)
    eigs = verify_tube(A, B, res.tube, tp_cm.state_scale, tp_cm.input_scale)
    assert eigs.min() > 0.0  # strictly positive: the LMI margin survives the solver
    assert np.all(res.nominal_room > 0.0)  # U minus F Z non-empty (eq. 30)
    assert not res.box.feasible  # the paper's box tube does not exist here
    assert res.box.spectral_radius_abs.max() > 1.0


def test_fault_in_W_leaves_no_nominal_input(vehicle, tp_cm):
    res = _run(vehicle, tp_cm, "box")
    # the tightening is 0.43 in Phi against 0.265 of room
    assert res.tube is None or np.any(res.nominal_room < 0.0)
