"""The domains of the one-step bounds (fahv.bounds.domain)."""

import numpy as np
import pytest
from tube_set_records import load_record

from fahv.bounds.domain import (
    SchedulingBox,
    certified_range,
    joint_shape,
    nominal_box,
    product_supports,
    schedule_points,
)
from fahv.certificate.report import range_line
from fahv.spec.scenario import load_run_spec

CASE = "offline_design/scenarios/case1.yaml"


def test_scheduling_box_rejects_bad_bounds():
    """Wrong shapes, NaN or lo > hi are refused with the box named."""
    ok = np.zeros(6), np.ones(6), np.ones(5)
    SchedulingBox(*ok)
    with pytest.raises(ValueError, match="scheduling box"):
        SchedulingBox(np.zeros(5), np.ones(6), np.ones(5))
    with pytest.raises(ValueError, match="scheduling box"):
        SchedulingBox(np.ones(6), np.zeros(6), np.ones(5))
    with pytest.raises(ValueError, match="scheduling box"):
        SchedulingBox(np.full(6, np.nan), np.ones(6), np.ones(5))


def test_joint_shape_is_the_tube_sets_own_and_checks_its_shapes():
    """[I; F_8] N_8 [I; F_8]': its diagonal gives Z_8's and F_8 Z_8's supports."""
    rng = np.random.default_rng(0)
    G = rng.normal(size=(8, 8))
    N_8, F_8 = G @ G.T + np.eye(8), rng.normal(size=(2, 8))
    C = joint_shape(F_8, N_8)
    np.testing.assert_allclose(C[:8, :8], N_8, rtol=1e-14)
    np.testing.assert_allclose(C[8:, 8:], F_8 @ N_8 @ F_8.T, rtol=1e-12)
    s_lo, s_oth = product_supports(F_8, N_8, 2.5)
    np.testing.assert_allclose(s_lo, np.r_[2.5, np.sqrt(np.diag(C))[[0, 1, 2, 8, 9]]])
    np.testing.assert_allclose(s_oth, np.sqrt(np.diag(N_8))[3:])
    with pytest.raises(ValueError, match="joint_shape"):
        joint_shape(F_8[:, :7], N_8)


def test_schedule_points_are_the_envelope_grid(vehicle):
    """1: the centre; 3: the centre and two opposite corners; 9: the 3 x 3 grid."""
    env = vehicle.envelope
    centre = [0.5 * (env.h_min + env.h_max), 0.5 * (env.V_min + env.V_max)]
    np.testing.assert_allclose(schedule_points(env, 1), [centre])
    corners = [[env.h_min, env.V_min], centre, [env.h_max, env.V_max]]
    np.testing.assert_allclose(schedule_points(env, 3), corners)
    assert schedule_points(env, 9).shape == (9, 2)
    with pytest.raises(ValueError, match="certificate.schedules"):
        schedule_points(env, 2)


def test_case_boxes_are_the_stored_tube_sets_within_rounding(vehicle):
    """The case's nominal box is the k = 5 tube set's (V margin 4.98 for 4.978 ft/s)
    except the lower ends of Phi and delta_e (-0.2 and -3 deg for -0.12 and -1 deg: room
    for decelerations and descents below the corners' trims) and h (the envelope less
    5 ft, the stored set's less 150 ft: h enters only the box's containment check,
    H = 2.6 ft), and its scheduling box holds the stored one, larger by at most 0.3 % of
    a reach except there."""
    d = load_record("closed_tube_h_reset.npz")
    nominal, box = nominal_box(load_run_spec(CASE)["eight_state"], vehicle.envelope)
    env = vehicle.envelope
    np.testing.assert_allclose([nominal.lo[0], nominal.hi[0]], [env.h_min + 5.0, env.h_max - 5.0])
    np.testing.assert_allclose([d["nominal_lo"][0], d["nominal_hi"][0]],
                               [env.h_min + 150.0, env.h_max - 150.0])  # fmt: skip
    np.testing.assert_allclose(nominal.lo[1:4], d["nominal_lo"][1:4], rtol=0, atol=0.0025)
    np.testing.assert_allclose(nominal.lo[4:], [-0.2, np.radians(-3.0)], rtol=1e-12)
    np.testing.assert_allclose(nominal.hi[1:], d["nominal_hi"][1:], rtol=0, atol=0.0025)
    np.testing.assert_allclose(nominal.other_half, d["nominal_other_half"], rtol=1e-9)
    reach_lo, reach_hi = d["nominal_lo"] - d["lo"], d["hi"] - d["nominal_hi"]
    assert np.all(box.lo <= d["lo"]) and np.all(box.hi >= d["hi"])
    assert np.all(box.other_half >= d["other_half"])
    assert np.all(d["lo"][2:4] - box.lo[2:4] <= 0.003 * reach_lo[2:4])  # alpha, theta
    np.testing.assert_allclose(box.lo[4:] - nominal.lo[4:], -reach_lo[4:], rtol=0.003)
    assert np.all(box.hi[2:] - d["hi"][2:] <= 0.003 * reach_hi[2:])
    with pytest.raises(Exception, match="h_margin"):
        nominal_box({**load_run_spec(CASE)["eight_state"], "h_margin": 1e4}, vehicle.envelope)


def test_certified_range_is_the_box_less_the_tube_and_holds_the_nominal_box():
    """certified_range: the scheduling box shrunk by the product set's supports (H in h,
    Z_8's in the states, F_8 Z_8's in the inputs); on the stored k = 5 tube set it holds
    the nominal box in every coordinate (the containment check), alpha by 0.25 deg to
    spare, and the design log's line names it."""
    d = load_record("closed_tube_h_reset.npz")
    box = SchedulingBox(d["lo"], d["hi"], d["other_half"])
    nominal = SchedulingBox(d["nominal_lo"], d["nominal_hi"], d["nominal_other_half"])
    cert = certified_range(box, d["F"], d["N"], float(d["H"]))
    s_lo, s_oth = product_supports(d["F"], d["N"], float(d["H"]))
    np.testing.assert_allclose(cert.hi - cert.lo, box.hi - box.lo - 2.0 * s_lo, rtol=1e-12)
    np.testing.assert_allclose(box.other_half - cert.other_half, s_oth, rtol=1e-12)
    assert np.all(cert.lo <= nominal.lo) and np.all(cert.hi >= nominal.hi)
    assert np.all(cert.other_half >= nominal.other_half)
    assert np.degrees(cert.hi[2] - nominal.hi[2]) == pytest.approx(0.25, abs=0.02)
    assert float(d["H"]) == pytest.approx(box.hi[0] - cert.hi[0], abs=1e-9)
    line = range_line(cert, nominal)
    assert line.startswith("the certificate covers a nominal anywhere in the scheduling box")
    with pytest.raises(ValueError, match="scheduling box"):
        certified_range(box, d["F"], 100.0 * d["N"], float(d["H"]))  # a tube wider than the box


def test_a_box_too_small_for_the_tube_names_the_design_key_and_a_value_that_holds():
    """The shortfall of each coordinate is mapped to the design file's key that gives it
    room (eight_state.reach[i] in its units, h_margin for h), with the room now plus the
    shortfall and 1 % (rounded up to four digits): eta_2 short by 0.00281 with 0.24 of
    reach needs 0.2452; alpha short by 0.001 rad with 0.573 deg needs 0.6366 deg."""
    from fahv.bounds.domain import SchedulingBox, shortfall_fixes

    nominal = SchedulingBox(np.array([85005.0, 7705.0, -0.007, -0.007, -0.2, -0.05]),
                            np.array([86495.0, 8295.0, 0.007, 0.007, 1.1, 0.12]),
                            np.array([0.012, 0.5, 3.5, 0.3, 3.5]))  # fmt: skip
    box = SchedulingBox(np.array([85000.0, 7700.0, -0.017, -0.017, -0.28, -0.13]),
                        np.array([86500.0, 8300.0, 0.017, 0.017, 1.18, 0.2]),
                        np.array([0.03, 1.2, 13.0, 0.54, 9.1]))  # fmt: skip
    fixes = shortfall_fixes({"eta_2": 0.00281, "lo alpha": 0.001, "hi alpha": 0.0005,
                             "hi h": 3.0}, box, nominal)  # fmt: skip
    assert fixes == [
        "eight_state.reach[7] (eta_2) to at least 0.2452 (now 0.24)",
        "eight_state.reach[0] (alpha) to at least 0.6366 (now 0.573)",  # the larger side
        "eight_state.h_margin to at least 8.08 (now 5)",
    ]
    grown = SchedulingBox(box.lo, box.hi, box.other_half + np.r_[0, 0, 0, 0.2452 - 0.24, 0])
    assert grown.margin_to(nominal)[2][3] >= 0.24 + 0.00281  # the value given holds
