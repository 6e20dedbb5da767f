"""`fahv-studies estimation`: the bounds of a scenario's Kalman filter as a user reads them."""

import re

import pytest

from fahv_studies.cli import main

#: The loop on the Kalman estimate without servos (a study scenario).
KALMAN = "studies/kalman_exact_design/scenarios/case1_kalman.yaml"


def test_estimation_prints_each_bound_and_the_tubes_verdict(capsys):
    assert main(["estimation", KALMAN]) == 0
    out = capsys.readouterr().out
    assert "gain-scheduled Kalman filter on h, V, theta, q of design cm_certified (20 LPV " \
           "vertices: 400 pairs" in out  # fmt: skip
    m = re.search(r"re-checked exactly \(smallest eigenvalue (\S+) >= 0", out)
    assert m and float(m.group(1)) >= 0.0
    assert re.search(r"  1 sigma: h 0\.39\d* ft, V 0\.19\d* ft/s, alpha 0\.01[34]\d* deg", out)
    assert re.search(r"whole run with p >= 0\.99 \(5\.4\d sigma", out)
    assert re.search(r"\|v\| <= h 16\.7\d ft, V 5\.23\d ft/s, theta 0\.298\d* deg", out)
    assert re.search(r"worst case at a frozen vertex \(exact, reached\): h 36\.\d+ ft, V 8\.9\d* "
                     r"ft/s, alpha 0\.678\d* deg.*: above the attitude requirement", out)
    assert re.search(r"of its certified level: NOT certified \(\d+x the room\)", out)
    # the tube of the estimate: the sensor noise alone needs 13.7 and 9.95 times the room
    # (measured), the state-feedback tube of the same vertices about half of it
    assert re.search(r"from the sensor noise \(.*\): V 0\.327\d* ft/s, alpha 0\.034\d* deg", out)
    m = re.search(r"state feedback for the design's W: tightening (\S+) and (\S+) of the room",
                  out)  # fmt: skip
    assert m and 0.4 < float(m.group(1)) < 0.6 and 0.4 < float(m.group(2)) < 0.6
    m = re.search(r"the estimate's tube for the sensor noise alone: tightening (\S+) and (\S+) "
                  r"of the room .*: no room is left for the nominal: no output-feedback tube of "
                  r"this synthesis exists for these sensors", out)  # fmt: skip
    assert m and float(m.group(1)) == pytest.approx(13.7, rel=0.05)
    assert float(m.group(2)) == pytest.approx(9.95, rel=0.05)
    # the probabilistic tube of the loop on the estimate: its re-check, 1 sigma of t, and
    # the attitude it reaches with the design's rows (0.602 / 0.589 deg, measured)
    m = re.search(r"covariance bound of \[t; e\] .* re-checked exactly \(smallest eigenvalue "
                  r"(\S+) >= 0", out)  # fmt: skip
    assert m and float(m.group(1)) >= 0.0
    assert re.search(r"1 sigma of t: V 0\.107\d* ft/s, alpha 0\.0204\d* deg", out)
    assert re.search(r"noise part reach 0\.60\d / 0\.589 deg \(requirement 0\.5 deg\): NOT "
                     r"certified; nominal rows of 0\.29\d / 0\.31\d deg would be", out)  # fmt: skip


def test_estimation_of_a_scenario_without_an_estimator_is_refused(capsys):
    assert main(["estimation", "offline_design/scenarios/case1.yaml"]) == 2
    err = capsys.readouterr().err
    assert "estimator.kind is 'none' (the controller reads the exact state): there is no " \
           "estimate to bound" in err  # fmt: skip


def test_estimation_of_an_ecm_design_is_refused(capsys):
    """Case 2 flies on the estimate, but these bounds are of a CM design's tube law."""
    assert main(["estimation", "studies/case2_on_cm/scenarios/case2_implementable.yaml"]) == 2
    assert "design 'ecm_paper' is of the ECM: the bounds are those of the tube law of a CM " \
           "design" in capsys.readouterr().err  # fmt: skip


def test_estimation_names_what_its_bounds_leave_out_and_scales_the_noise(tmp_path, capsys):
    """A scenario on servos its filter does not model, with a sensor fault: the bounds are
    printed, and two notes say that neither the fault nor the servos are in them. With
    sensors a hundred times quieter the tube of the estimate fits (0.86 and 0.63 of the
    room, measured). The attitude's reach starts from the rows the scenario's nominal
    flies (estimator.nominal_att_max 0.37 deg, the design's 0.40)."""
    import yaml

    d = yaml.safe_load(open(KALMAN))
    d["name"] = "kalman_servo"
    d.setdefault("plant", {})["actuators"] = "second_order"
    d["sensor_fault"] = {"kind": "stuck", "channel": "h", "t_onset": 50.0}
    d["estimator"]["nominal_att_max"] = 0.37
    path = tmp_path / "kalman_servo.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    assert main(["estimation", str(path), "--noise-scale", "0.01"]) == 0
    out = capsys.readouterr().out
    assert "sensors: every measured channel's noise stddev times 0.01" in out
    m = re.search(r"the estimate's tube for the sensor noise alone: tightening (\S+) and (\S+) "
                  r"of the room .*: it fits", out)  # fmt: skip
    assert m and float(m.group(1)) == pytest.approx(0.855, rel=0.05)
    assert float(m.group(2)) == pytest.approx(0.63, rel=0.05)
    assert "note: the scenario's sensor fault (stuck) is not in these bounds" in out
    assert "attitude (whole run, p >= 0.99): nominal rows 0.370 + support of Z 0.100" in out
    assert "note: the scenario's actuators (second_order) are not in the filter's model " \
           "(estimator.actuators ideal), so not in these bounds" in out  # fmt: skip


@pytest.mark.parametrize("scale", ["0", "nan", "-1"])
def test_a_noise_scale_that_is_not_positive_is_refused(scale, capsys):
    assert main(["estimation", KALMAN, "--noise-scale", scale]) == 2
    assert "--noise-scale must be a positive number" in capsys.readouterr().err


def test_rows_wider_than_the_designs_are_refused_before_any_bound(tmp_path, capsys):
    """estimator.nominal_att_max above the design's 0.40 deg: exit status 2 and an error
    naming the key, before the bounds' work (as a run refuses it)."""
    import yaml

    d = yaml.safe_load(open("offline_design/scenarios/case1_implementable.yaml"))
    d["estimator"]["nominal_att_max"] = 0.45
    path = tmp_path / "wide_rows.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    assert main(["estimation", str(path)]) == 2
    captured = capsys.readouterr()
    assert "estimator.nominal_att_max = 0.45 deg exceeds the design's attitude rows" in captured.err
    assert "probabilistic tube" not in captured.out
