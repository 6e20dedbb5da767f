"""The estimate design's claims from a probabilistic reachable set (fahv.stochastic.claims)."""

import numpy as np
import pytest

from fahv.errors import DesignError
from fahv.stochastic.claims import CLAIMS, claims_at, run_radius
from fahv.stochastic.closed_loop import ProbabilisticTube

CASE = {"Ts": 0.02, "mpc": {"att_max": 0.4, "du_max": [0.02, 0.2]},
        "estimate": {"probability": 0.99, "duration": 300.0}}


def tube(std_alpha_deg: float, std_step_deg: float) -> ProbabilisticTube:
    std_t = np.zeros(8)
    std_t[1:3] = np.radians(std_alpha_deg)
    return ProbabilisticTube(np.eye(3), 0.0, 1, std_t, np.zeros(2),
                             np.array([0.0, np.radians(std_step_deg)]), np.zeros(8))


def test_the_union_bound_radius_is_the_gaussian_quantile_of_its_share():
    """r = Phi^-1(1 - (1 - p) / (2 n)): one sample at p = 0.95 is the 1.96 of a two-sided
    95 % interval; 30 000 samples at 0.995 (the attitude's two signals over 300 s) 5.233."""
    assert run_radius(0.95, 1) == pytest.approx(1.959964, abs=1e-6)
    assert run_radius(0.995, 30000) == pytest.approx(5.2331, abs=1e-4)


def test_rows_are_the_requirement_less_the_support_and_the_noise_at_the_run_radius():
    """Each claim gets half of 1 - p; the rows are 0.5 deg - support - r std, capped by the
    design's; the rate rows what the servo leaves after the tube's and the noise's parts."""
    c = claims_at(tube(0.02, 0.2), 1.0, CASE, np.radians([0.1, 0.08]), np.radians(0.5),
                  np.radians(2.0))  # fmt: skip
    assert c.claimed == CLAIMS and c.p_claim == pytest.approx(0.995, abs=1e-15)
    r_att, r_rate = run_radius(0.995, 30000), run_radius(0.995, 15000)
    assert (c.r_attitude, c.r_rate) == (r_att, r_rate)
    np.testing.assert_allclose(np.degrees(c.rows_room), [0.4 - 0.02 * r_att,
                                                         0.42 - 0.02 * r_att], atol=1e-12)
    np.testing.assert_allclose(np.degrees(c.rows), np.degrees(c.rows_room), atol=1e-12)
    assert np.degrees(c.du_plan) == pytest.approx(0.2, abs=1e-12)  # the design's rows fit
    tight = claims_at(tube(0.02, 0.2), 1.0, CASE, np.radians([0.1, 0.08]), np.radians(0.5),
                      np.radians(1.6))  # fmt: skip
    assert np.degrees(tight.du_plan) == pytest.approx(1.1 - 0.2 * r_rate, abs=1e-12)
    assert c.holds and tight.holds
    noisy = claims_at(tube(0.02, 0.5), 1.0, CASE, np.radians([0.1, 0.08]), np.radians(0.5),
                      np.radians(2.0))  # fmt: skip
    assert noisy.du_plan < 0.0 and not noisy.holds and noisy.attitude_holds
    only = claims_at(tube(0.02, 0.5), 1.0, {**CASE, "estimate": {**CASE["estimate"],
                     "claims": ["attitude"]}}, np.radians([0.1, 0.08]), np.radians(0.5),
                     np.radians(2.0))  # fmt: skip
    # one claim gets all of 1 - p; the rate, not claimed, keeps the design's rows
    assert only.p_claim == pytest.approx(0.99, abs=1e-15) and only.holds
    assert np.degrees(only.du_plan) == pytest.approx(0.2, abs=1e-12) and not only.rate_holds
    assert only.r_attitude == run_radius(0.99, 30000) < r_att


def test_the_estimate_stage_needs_the_eight_state_tube():
    """A design on the vertex tube has no eight-state domain to bound the rate over."""
    from fahv.design.estimate import estimate_stage
    from fahv.spec.artefacts import Design

    with pytest.raises(DesignError, match="eight-state tube"):
        estimate_stage(Design({"tube": {"form": "vertices", "tau": 1.0}}, {}, {}, {}), None)
