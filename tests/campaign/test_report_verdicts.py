"""Verdicts of one campaign row: each requirement, and every requirement at once."""

import math

import pytest

from fahv.campaign.report import REQUIREMENTS, verdicts
from fahv.spec.requirements import judge, verdict_rows

REQ = {"attitude_deg": 0.5, "settling_s": 60.0, "h_final_ft": 10.0, "V_final_fps": 2.0}
ROW = {
    "status": "ok", "alpha_err_max_deg": 0.3, "theta_err_max_deg": 0.4,
    "tube_fraction_inside": 1.0, "settling_after_command_s": 42.0,
    "input_limit_violations": 0, "input_rate_violations": 0, "h_err_final_ft": -0.5,
    "V_err_final_fps": 0.1,
}  # fmt: skip


def test_a_run_meeting_every_requirement_passes_all():
    v = verdicts(ROW, REQ)
    assert set(v) == {k for k, _ in REQUIREMENTS}
    assert all(x for k, x in v.items() if k not in ("nominal_range", "settling_fault"))
    assert v["settling_fault"] is None  # no fault in the row
    assert v["nominal_range"] is None  # no certified range given


def test_one_miss_fails_all_and_not_applicable_is_not_a_miss():
    slow = verdicts({**ROW, "settling_after_command_s": 60.02}, REQ)
    assert slow["settling"] is False and slow["all"] is False and slow["attitude"] is True
    never = verdicts({**ROW, "settling_after_command_s": math.nan}, REQ)  # never settled
    assert never["settling"] is False and never["all"] is False
    no_tube = verdicts({**ROW, "tube_fraction_inside": math.nan}, REQ)  # RMPC: no tube
    assert no_tube["tube"] is None and no_tube["all"] is True
    gone = verdicts({"status": "failed", "alpha_err_max_deg": None}, REQ)  # no metrics
    assert gone["completes"] is False and gone["all"] is False
    assert gone["input_rates"] is None  # whether it had servos is not known


def test_settling_not_reached_fails_only_a_run_that_went_on_for_the_limit():
    """A run that has not settled fails the settling only if it went on for 60 s after
    the command stopped moving; a shorter one did not measure it (not applicable)."""
    unsettled = {**ROW, "settling_after_command_s": math.nan, "t_command_end_s": 0.0}
    assert verdicts({**unsettled, "t_final_s": 59.9}, REQ)["settling"] is None
    assert verdicts({**unsettled, "t_final_s": 60.0}, REQ)["settling"] is False
    assert verdicts({**unsettled, "t_final_s": 59.9}, REQ)["all"] is True


def test_the_settling_after_a_fault_is_judged_from_its_onset():
    """A fault at t = 100 s after a command that stopped at t = 0: settled 20 s after it
    passes, 70 s fails, never settled fails in a 300 s run and is not measured in a run
    that ends 30 s after the onset; no fault, a fault while the command moves, or a row of
    an earlier version (without the metric): not applicable."""
    fault = {**ROW, "t_command_end_s": 0.0, "t_fault_s": 100.0, "t_final_s": 300.0}
    assert verdicts({**fault, "settling_after_fault_s": 20.0}, REQ)["settling_fault"] is True
    late = verdicts({**fault, "settling_after_fault_s": 70.0}, REQ)
    assert late["settling_fault"] is False and late["all"] is False
    never = {**fault, "settling_after_fault_s": math.nan}
    assert verdicts(never, REQ)["settling_fault"] is False
    assert verdicts({**never, "t_final_s": 130.0}, REQ)["settling_fault"] is None
    assert verdicts({**never, "t_fault_s": math.nan}, REQ)["settling_fault"] is None
    assert verdicts({**never, "t_command_end_s": 120.0}, REQ)["settling_fault"] is None
    assert verdicts({**ROW, "t_fault_s": 100.0}, REQ)["settling_fault"] is None


def test_the_tube_of_a_loop_on_the_estimate_is_reported_not_judged():
    """Outside Z on the exact state fails the tube; on a state estimate (its errors
    measured) the same level is not judged: the certificate assumes the exact state."""
    outside = {**ROW, "tube_fraction_inside": 0.97, "tube_level_max": 1.8}
    assert verdicts(outside, REQ)["tube"] is False
    on_estimate = verdicts({**outside, "estimate_err_h_rms_ft": 1.2}, REQ)
    assert on_estimate["tube"] is None and on_estimate["all"] is True
    rows = {r[0]: r for r in verdict_rows(judge({**outside, "estimate_err_h_rms_ft": 1.2}))}
    assert rows["tube"][2:] == ("1.8", "1", "not judged: on the estimate", "n/a")


def test_a_command_beyond_a_servo_rate_fails_the_rates_and_all():
    """One step beyond the rate limit fails "input_rates" and "all" (the positions still
    pass); a row of an earlier version, without the metric, has it not applicable."""
    fast = verdicts({**ROW, "input_rate_violations": 1}, REQ)
    assert fast["input_rates"] is False and fast["all"] is False
    assert fast["input_limits"] is True
    old = verdicts({k: v for k, v in ROW.items() if k != "input_rate_violations"}, REQ)
    assert old["input_rates"] is None and old["all"] is True


def test_nominal_range_is_checked_against_the_certified_range_and_not_in_all():
    """ "nominal_range": the run's nominal (its h, V range and largest deviations from the
    nominal trim at its own (h, V)) inside the design's certified range; not applicable
    without a range or without the nominal's metrics, and never part of "all"."""
    import numpy as np

    cert = {  # case1.yaml's certified range (the design's summary), rounded
        "lo": [85003.0, 7703.07, np.radians(-0.650), np.radians(-0.635), -0.21, -0.078],
        "hi": [86497.0, 8296.93, np.radians(0.650), np.radians(0.635), 1.11, 0.148],
        "other_half": [np.radians(1.002), 0.766, 6.479, 0.394, 5.080],
    }
    nominal = {  # Case 1's run (main job): alpha 0.416 deg from its own trim
        "nominal_h_min_ft": 85499.98, "nominal_h_max_ft": 86111.80,
        "nominal_V_min_fps": 7900.0, "nominal_V_max_fps": 8150.0,
        "nominal_alpha_dev_max_deg": 0.416, "nominal_theta_dev_max_deg": 0.352,
        "nominal_q_dev_max_degps": 0.140, "nominal_eta_1_dev_max": 0.370,
        "nominal_eta_1_dot_dev_max": 0.232, "nominal_eta_2_dev_max": 0.119,
        "nominal_eta_2_dot_dev_max": 0.165,
    }  # fmt: skip
    row = {**ROW, **nominal}
    assert verdicts(row, REQ, cert)["nominal_range"] is True
    assert verdicts(row, REQ)["nominal_range"] is None  # no certified range: n/a
    assert verdicts(ROW, REQ, cert)["nominal_range"] is None  # no nominal: n/a
    for key, value in (("nominal_alpha_dev_max_deg", 0.651), ("nominal_V_min_fps", 7703.0),
                       ("nominal_q_dev_max_degps", 1.003), ("nominal_eta_2_dev_max", 0.395),
                       ("nominal_h_max_ft", 86497.5)):  # fmt: skip
        v = verdicts({**row, key: value}, REQ, cert)
        assert v["nominal_range"] is False, key
        assert v["all"] is True  # the requirements alone


def test_the_certified_and_the_not_certified_draws_are_counted_apart():
    """Synthetic rows of two variants over five draws: draws 0 and 1 certified, 2 to 4
    not (an onset beyond the certified one, a fault kind outside the design's, an open
    certificate); each group gets its own pass rates and Clopper-Pearson bounds, and the
    reasons are counted with each number (not those in names) as its range over the draws."""
    from fahv.campaign.report import Report, coverage_lines, failure_bound

    onset = "onset loss {} % above the certified 8.07 %"
    stuck = "fault kind stuck outside the design's fault kinds (none, loss_of_effectiveness, bias)"
    paper = "design case1_paper: W is not shown to bound the disturbance over its domain"
    covs = ["certified", "certified", "not certified: " + onset.format(12.5),
            f"not certified: {stuck}; " + onset.format(20), f"not certified: {paper}"]  # fmt: skip
    slow = {"settling_after_command_s": 75.0}
    rows = {
        "a": [{**ROW, "index": i, "variant": "a", "coverage": c} for i, c in enumerate(covs)],
        "b": [{**ROW, **(slow if i >= 1 else {}), "index": i, "variant": "b", "coverage": c}
              for i, c in enumerate(covs)],
    }  # fmt: skip
    data = {"variants": ["a", "b"], "requirements": {**REQ, "confidence": 0.95}}
    table, lines = coverage_lines(data, rows)
    assert set(table) == {"certified", "not certified"}
    assert table["certified"]["a"]["all"] == (2, 2, failure_bound(0, 2, 0.95))
    assert table["certified"]["b"]["all"] == (1, 2, failure_bound(1, 2, 0.95))
    assert table["not certified"]["a"]["all"] == (3, 3, failure_bound(0, 3, 0.95))
    assert table["not certified"]["b"]["settling"] == (0, 3, 1.0)
    assert table["certified"]["b"]["all"][2] == pytest.approx(0.9747, abs=1e-4)
    assert table["not certified"]["a"]["all"][2] == pytest.approx(1 - 0.05 ** (1 / 3))
    text = "\n".join(lines)
    assert "### certified: 2 of 5 draws" in text and "### not certified: 3 of 5 draws" in text
    assert (
        "| settled within 60 s of the command | 2/2 (100.0 %), p_fail < 0.776 | "
        "1/2 (50.0 %), p_fail < 0.975 |" in text
    )
    assert "- 2 x onset loss 12.5 to 20 % above the certified 8.07 %" in text
    assert f"- 1 x {stuck}" in text and f"- 1 x {paper}" in text
    rep = Report("", {v: {k: (0, 0, 0.0) for k, _ in REQUIREMENTS} for v in "ab"}, [], 10, table)
    assert "  all, certified | not certified draws: a 2/2 | 3/3; b 1/2 | 0/3" in rep.summary()
    # a dataset without coverage verdicts (earlier versions) has no such section
    old = {v: [{k: x for k, x in r.items() if k != "coverage"} for r in rs]
           for v, rs in rows.items()}  # fmt: skip
    assert coverage_lines(data, old) == ({}, [])


def test_histograms_of_a_metric_no_run_has_are_drawn_without_warnings(tmp_path, monkeypatch):
    """A baseline that never settles and has no tube (NaN in every row) still gets every
    histogram, the five empty ones marked as such, without matplotlib's empty-legend
    warning."""
    import warnings

    from matplotlib.axes import Axes

    from fahv.campaign.figures import WORST_METRICS, draw_figures

    marks = []
    text = Axes.text
    monkeypatch.setattr(Axes, "text", lambda ax, *a, **k: marks.append(a[2]) or text(ax, *a, **k))
    (tmp_path / "trajectories").mkdir()
    rows = [{**ROW, "index": i, "settling_after_command_s": math.nan,
             "tube_fraction_inside": math.nan, "tube_level_max": math.nan,
             "tube_error_h_max_ft": math.nan} for i in range(3)]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        paths = draw_figures(tmp_path, {"requirements": REQ}, {"rmpc": rows}, cols=[])
    assert {p.name for p in paths} == {f"hist_{k}.png" for k, *_ in WORST_METRICS}
    # settling, tube level and e_h (NaN), eta_1_dot's rms and delta_e (absent): empty
    assert marks == ["no run has a finite value"] * 5
