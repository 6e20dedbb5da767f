"""What drives a requirement (fahv.campaign.attribution) on runs whose driver is known."""

import math

import numpy as np
import pytest

from fahv.campaign.attribution import attribute, attribute_all, attribution_lines

PARAMS = ["m", "I_yy", "c_e", "beta_1"]
DATA = {"dispersions": {
    "uncertainty": {"method": "uniform", "scale": 1.0, "parameters": PARAMS},
    "fault": {"kinds": [], "onset": [0.0, 250.0], "loss": [0.0, 0.08], "bias_deg": []},
    "command": {"dh": [], "dV": []}, "initial": {"h0": [], "V0": []},
    "actuators": {"omega_n": [], "zeta": [], "rate_limit": []},
    "sensors": {"stddev": [], "bias_stddev": [], "bias_mean": []}},
    "requirements": {"attitude_deg": 0.5}}  # fmt: skip


def _rows(n=1000, seed=4):
    """Runs whose attitude error grows with s_m alone: 0.3 + 0.3 s_m deg, failing (above
    0.5 deg) where s_m > 2/3; one run ended early."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n):
        s = rng.uniform(-1, 1, len(PARAMS))
        att = 0.3 + 0.3 * s[0] + 0.002 * rng.normal()
        rows.append({"status": "ok", **{f"s.{p}": float(v) for p, v in zip(PARAMS, s, strict=True)},
                     "fault.t_onset": float(rng.uniform(0, 250)),
                     "fault.loss": float(rng.uniform(0, 0.08)),
                     "alpha_err_max_deg": att, "theta_err_max_deg": 0.1,
                     "estimate_err_h_rms_ft": math.nan})  # fmt: skip
    rows[7]["status"] = "failed"
    return rows


def test_the_one_driver_is_found_with_where_its_failures_sit():
    """s_m comes first, its PAWN index over three times the noise level; the failing runs
    (s_m > 2/3, and the run that ended early) differ from the passing ones in s_m alone
    (KS p < 1e-10; the others p > 1e-3), and their m lies 6.7-10 % above nominal."""
    a = attribute(_rows(), DATA, "attitude")
    assert (a.runs, a.failed) == (1000, sum(r["alpha_err_max_deg"] > 0.5 for r in _rows()) + 1)
    top = a.drivers[0]
    assert top.column == "s.m" and top.label == "m from its nominal [%]"
    assert top.pawn > 3 * a.dummy and top.p_value < 1e-10
    assert all(d.p_value > 1e-3 for d in a.drivers[1:])
    assert top.fail_range[1] == pytest.approx(10.0, abs=0.05)
    assert 6.6 <= sorted(r["s.m"] * 10 for r in _rows() if r["alpha_err_max_deg"] > 0.5)[0]
    text = "\n".join(attribution_lines("tube_mpc", [a]))
    assert "| m from its nominal [%] | " in text and "noise level" in text


def test_values_of_no_influence_are_rarely_above_the_noise():
    """Five values of no influence (I_yy, c_e, beta_1, the onset, the loss) over ten
    campaigns of 1000 runs: each exceeds the largest of the 99 dummies' PAWN indices with
    probability 1 %, so about 0.5 of the 50 are flagged (with five dummies it was one in
    six: about 8); the driver is flagged in every campaign."""
    flagged, driver = 0, 0
    for seed in range(10):
        a = attribute(_rows(seed=seed), DATA, "attitude", seed=seed)
        names = [d.column for d in a.influential()]
        driver += "s.m" in names
        flagged += len([n for n in names if n != "s.m"])
    assert driver == 10 and flagged <= 3, flagged


def test_requirements_that_do_not_apply_are_left_out():
    """No settling metric, no tube error on a loop on the estimate: only the attitude and
    the final errors that the rows measure are attributed; fewer than 20 runs: none."""
    rows = [{**r, "estimate_err_h_rms_ft": 1.0, "tube_level_max": 2.0} for r in _rows()]
    found = {a.requirement for a in attribute_all(rows, DATA)}
    assert "attitude" in found and "tube" not in found and "settling" not in found
    assert attribute(_rows(19), DATA, "attitude") is None
