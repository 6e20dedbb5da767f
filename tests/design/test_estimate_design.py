"""The estimate design cm_implementable: its claims re-checked, its settings flown, a bound
that does not hold refused."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fahv.certificate.verified import load_or_design
from fahv.certificate.verify_estimate import check_estimate
from fahv.loop.params import node_parameters
from fahv.spec.scenario import flies_its_estimate_design, uncertified

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "studies" / "estimate_design" / "scenarios" / "case1_estimate_design.yaml"


@pytest.fixture(scope="module")
def flown():
    """case1_estimate_design's (run spec, design, vehicle) on cm_implementable."""
    return load_or_design(str(SCENARIO), log=lambda *_: None)


def test_the_attitude_claim_holds_and_the_rate_is_reported(flown):
    """Sigma re-checked at the 400 pairs; the attitude rows are 0.5 deg less Z_8's support
    less 5.10 sigma (p = 0.99 for the one claim over 2 x 15 000 samples); the rate claim,
    not made, would fail: the tube's worst case and the noise's part exceed the servo."""
    _, design, vehicle = flown
    res = {r.name: r for r in check_estimate(design, vehicle)}
    assert all(r.ok for r in res.values()), [r.text() for r in res.values()]
    assert 0.0 <= res["estimate bound"].margin < 1e-3
    rows = np.asarray(design.arrays["estimate_att_max_deg"], float)
    assert np.all((rows > 0.25) & (rows < 0.32)), rows
    assert res["estimate attitude"].margin == pytest.approx(rows.min(), abs=1e-9)
    assert "p >= 0.9900 per run (5.10 sigma" in res["estimate attitude"].line
    assert res["estimate elevator rate"].margin < 0.0  # reported: no room, not claimed
    assert "not claimed (it does not hold)" in res["estimate elevator rate"].line


def test_a_covariance_bound_one_percent_smaller_is_refused(flown):
    """The exact re-check has no tolerance: Sigma times 0.99 fails at some pair."""
    _, design, vehicle = flown
    arrays = {**design.arrays, "estimate_Sigma": 0.99 * design.arrays["estimate_Sigma"]}
    bad = {r.name: r for r in check_estimate(dataclasses.replace(design, arrays=arrays),
                                             vehicle)}  # fmt: skip
    assert not bad["estimate bound"].ok and bad["estimate bound"].margin < 0.0


def test_the_run_flies_the_designs_settings_and_is_covered(flown):
    """The nominal node gets the design's tightened rows, its rate rows and the estimate's
    settings; the run spec needs no --allow-uncertified; another tube factor does."""
    spec, design, vehicle = flown
    assert flies_its_estimate_design(spec.data)
    assert uncertified(design, spec.data, vehicle) == []
    nominal = node_parameters(design)["nominal_trajectory"]
    np.testing.assert_allclose(nominal["mpc.att_max"], design.arrays["estimate_att_max_deg"],
                               rtol=0.0, atol=0.0)  # fmt: skip
    assert (nominal["mpc.est_tau"], nominal["mpc.est_tau_elevator"]) == (2.0, 5.0)
    assert nominal["mpc.est_start"] == "zero"
    other = {**spec.data, "estimator": {**spec.data["estimator"], "tube_tau": 0.8}}
    assert not flies_its_estimate_design(other)
    assert any("estimator" in line for line in uncertified(design, other, vehicle))
