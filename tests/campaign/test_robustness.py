"""The margins a clearance minimises (fahv.campaign.robustness) agree with the run verdicts
(fahv.spec.requirements.judge) and continue past a failure."""

import math

import pytest

from fahv.campaign.robustness import SEARCHABLE, robustness
from fahv.spec.requirements import judge

#: A run of 300 s: the command ends at 30 s, a fault at 150 s; settled 34 s after the
#: command and 20 s after the fault.
ROW = {"status": "ok", "alpha_err_max_deg": 0.31, "theta_err_max_deg": -0.42,
       "t_command_end_s": 30.0, "t_fault_s": 150.0, "t_final_s": 300.0,
       "settling_after_command_s": 34.0, "settling_after_fault_s": 20.0,
       "h_err_final_ft": 1.5, "V_err_final_fps": -0.2, "tube_level_max": 0.8,
       "tube_fraction_inside": 1.0, "delta_e_rate_max_degps": 62.0,
       "input_rate_violations": 0, "input_limit_violations": 0}  # fmt: skip


def test_each_margin_is_the_verdicts_limit_minus_value():
    """Where the verdict measures a value, the margin is its `Judgement.margin`."""
    judged = {j.requirement.key: j for j in judge(ROW)}
    for key in ("attitude", "settling", "settling_fault", "final_h", "final_V", "tube"):
        assert robustness(ROW, key) == pytest.approx(judged[key].margin, abs=1e-12), key
    assert robustness(ROW, "attitude") == pytest.approx(0.08)
    assert robustness(ROW, "input_rates", rate_limit_degps=100.0) == pytest.approx(38.0)
    assert robustness({**ROW, "actuators.rate_limit": 0.5}, "input_rates",
                      rate_limit_degps=100.0) == pytest.approx(-12.0)  # fmt: skip
    assert math.isnan(robustness(ROW, "input_rates"))  # ideal actuators: no rate limit


def test_settling_continues_past_a_run_that_never_settles():
    """Never settled, 270 s watched after the command: 60 - 270 - 60 (e - 1) with e the
    final error in bands; it meets the settled margin (60 - 270) at e = 1 and falls with
    the error, so a search is led towards worse runs; the verdict fails both."""
    never = {**ROW, "settling_after_command_s": math.nan}
    at_band = {**never, "h_err_final_ft": 10.0}
    assert robustness(at_band, "settling") == pytest.approx(60.0 - 270.0)
    far = {**never, "h_err_final_ft": 30.0}  # e = 3
    assert robustness(far, "settling") == pytest.approx(60.0 - 270.0 - 120.0)
    slow = {**ROW, "settling_after_command_s": 270.0}  # settled at the last step
    assert robustness(slow, "settling") == pytest.approx(robustness(at_band, "settling"))
    assert {j.requirement.key: j.passed for j in judge(far)}["settling"] is False


def test_margins_that_do_not_apply_and_runs_that_ended_early():
    """No fault after the command, or a run that ends unsettled before the limit: NaN
    (the verdict's n/a); a run that ended early: -inf on every requirement."""
    early_fault = {**ROW, "t_fault_s": 10.0}
    assert math.isnan(robustness(early_fault, "settling_fault"))
    short = {**ROW, "t_final_s": 60.0, "settling_after_command_s": math.nan}
    assert math.isnan(robustness(short, "settling"))
    assert {j.requirement.key: j.passed for j in judge(short)}["settling"] is None
    ended = {**ROW, "status": "failed"}
    assert all(robustness(ended, k, rate_limit_degps=100.0) == -math.inf for k in SEARCHABLE)
    with pytest.raises(ValueError, match="not one a clearance searches: attitude"):
        robustness(ROW, "completes")
