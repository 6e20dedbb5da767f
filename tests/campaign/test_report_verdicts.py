"""Verdicts of one campaign row: each requirement, and every requirement at once."""

import math

from fahv.campaign.report import REQUIREMENTS, verdicts

REQ = {"attitude_deg": 0.5, "settling_s": 60.0, "h_final_ft": 10.0, "V_final_fps": 2.0}
ROW = {
    "status": "ok", "alpha_err_max_deg": 0.3, "theta_err_max_deg": 0.4,
    "tube_fraction_inside": 1.0, "settling_after_command_s": 42.0,
    "input_limit_violations": 0, "h_err_final_ft": -0.5, "V_err_final_fps": 0.1,
}  # fmt: skip


def test_a_run_meeting_every_requirement_passes_all():
    v = verdicts(ROW, REQ)
    assert set(v) == {k for k, _ in REQUIREMENTS}
    assert all(v.values())


def test_one_miss_fails_all_and_not_applicable_is_not_a_miss():
    slow = verdicts({**ROW, "settling_after_command_s": 60.02}, REQ)
    assert slow["settling"] is False and slow["all"] is False and slow["attitude"] is True
    never = verdicts({**ROW, "settling_after_command_s": math.nan}, REQ)  # never settled
    assert never["settling"] is False and never["all"] is False
    no_tube = verdicts({**ROW, "tube_fraction_inside": math.nan}, REQ)  # RMPC: no tube
    assert no_tube["tube"] is None and no_tube["all"] is True
    gone = verdicts({"status": "failed", "alpha_err_max_deg": None}, REQ)  # no metrics
    assert gone["completes"] is False and gone["all"] is False
