"""One coverage verdict per run: "certified", or "not certified" with its reasons, checked
on the shipped designs (their stored summaries, no verification)."""

import importlib
import json
import sys
from pathlib import Path

import pytest

from fahv.loop.params import case_with
from fahv.model.vehicle import load_vehicle
from fahv.plant.faults import FAULTS
from fahv.spec.coverage import COVERED_KINDS, coverage, is_certified
from fahv.spec.scenario import load_scenario, run_spec_data
from fahv.spec.store import stored_design

ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "offline_design" / "scenarios" / "case1.yaml"
KINDS = ", ".join(COVERED_KINDS)


@pytest.fixture(scope="module")
def certified():
    """The stored design of Case 1 (cm_certified) and the vehicle."""
    vehicle = load_vehicle()
    return stored_design(load_scenario(CASE1).design_file, vehicle=vehicle)[1], vehicle


def test_case1_names_its_onset_beyond_the_certified_onset_loss(certified):
    """Case 1's 10 % loss at 100 s: the onset lines certify 8.07 % (the number stored in
    design.json), and that is the only reason."""
    design, vehicle = certified
    stored = json.loads((ROOT / "offline_design/designs/cm_certified/design.json").read_text())
    onset = stored["summary"]["certificate"]["onset"]["certified_loss"]
    assert round(100 * onset, 2) == 8.07
    cov = coverage(design, run_spec_data(CASE1), vehicle)
    assert cov.text() == "not certified: onset loss 10 % above the certified 8.07 %"
    assert cov.refused == () and not cov.certified  # run, not refused


def test_a_scenario_within_the_design_is_certified(certified):
    design, vehicle = certified
    c = run_spec_data(CASE1)
    c["fault"]["rho_f"] = 0.95  # a 5 % loss: its onset is certified too
    assert coverage(design, c, vehicle).text() == "certified"
    c["fault"] = {"kind": "none", "t_onset": 0.0}
    assert coverage(design, c, vehicle).text() == "certified"
    # Case 1's own fault after the end of the run never acts
    assert coverage(design, run_spec_data(CASE1), vehicle, duration=100.0).text() == "certified"
    assert coverage(design, run_spec_data(CASE1), vehicle, duration=100.02).certified is False


@pytest.mark.parametrize("kind", ["stuck", "dropout"])
def test_stuck_and_dropout_are_not_certified_by_kind(certified, kind):
    design, vehicle = certified
    c = run_spec_data(CASE1)
    c["fault"] = {"kind": kind, "t_onset": 20.0}
    cov = coverage(design, c, vehicle)
    outside = f"fault kind {kind} outside the design's fault kinds ({KINDS})"
    assert cov.text() == f"not certified: {outside}"
    assert cov.refused == ()  # runs without --allow-uncertified, with its verdict


def test_a_plugin_fault_kind_is_not_certified(certified, monkeypatch):
    design, vehicle = certified
    monkeypatch.syspath_prepend(str(ROOT / "tests" / "cli"))
    sys.modules.pop("plugin_faults", None)
    try:
        importlib.import_module("plugin_faults")
        c = run_spec_data(CASE1)
        c["fault"] = {"kind": "elevator_travel", "t_onset": 20.0, "travel_deg": 12.1}
        assert coverage(design, c, vehicle).text() == (
            f"not certified: fault kind elevator_travel outside the design's fault kinds ({KINDS})"
        )
    finally:
        FAULTS.unregister("elevator_travel")


def test_a_loss_beyond_the_fault_range_and_a_command_beyond_the_range_are_refused(certified):
    design, vehicle = certified
    c = run_spec_data(CASE1)
    c["fault"]["rho_f"] = 0.7
    c["command"]["V_c"] = 8298.0
    cov = coverage(design, c, vehicle)
    assert cov.refused == (
        "the command (86100 ft, 8298 ft/s) lies outside the nominal range the tube is certified "
        "for, h 85005..86495 ft, V 7704.98..8295.02 ft/s",
        "loss 30 % above the certified 24 % (elevator effectiveness 0.7 below the design's "
        "fault range rho_f in [0.76, 1])",
    )
    assert cov.run_anyway == ("onset loss 30 % above the certified 8.07 %",)
    assert cov.text() == "not certified: " + "; ".join(cov.refused + cov.run_anyway)


def test_a_bias_onset_and_an_open_certificate_are_named(certified):
    design, vehicle = certified
    c = run_spec_data(CASE1)
    c["fault"] = {"kind": "bias", "t_onset": 20.0, "bias_deg": 2.0}
    assert coverage(design, c, vehicle).text() == (
        "not certified: onset of a 2 deg bias (the onset lines certify losses only)"
    )
    paper = ROOT / "offline_design" / "scenarios" / "case1_paper.yaml"
    design = stored_design(load_scenario(paper).design_file, vehicle=vehicle)[1]
    assert coverage(design, run_spec_data(paper), vehicle).text() == (
        "not certified: design cm_paper: W is not shown to bound the disturbance over its "
        "domain; onset loss 10 % above the certified 0 %"
    )


def test_a_campaign_runs_own_fault_and_command_come_from_its_node_parameters(certified):
    design, vehicle = certified
    c = run_spec_data(CASE1)
    ov = {"fault_injector": {"kind": "loss_of_effectiveness", "t_onset": 30.0, "rho_f": 0.97,
                             "bias_deg": 1.0},
          "nominal_trajectory": {"command.h_c": 86000.0, "command.V_c": 8000.0},
          "plant": {"params.m": 1.0}}  # fmt: skip
    run = case_with(c, ov)
    assert run["fault"] == {"kind": "loss_of_effectiveness", "t_onset": 30.0, "rho_f": 0.97}
    assert run["command"] == {**c["command"], "h_c": 86000.0, "V_c": 8000.0}
    assert c["fault"]["rho_f"] == 0.9  # the run spec itself is unchanged
    assert coverage(design, run, vehicle).text() == "certified"
    assert case_with(c, None) == c


def test_is_certified_reads_a_stored_verdict():
    assert is_certified("certified") is True
    assert is_certified("not certified: onset loss 10 % above the certified 8.07 %") is False
    assert is_certified(None) is None and is_certified("") is None
