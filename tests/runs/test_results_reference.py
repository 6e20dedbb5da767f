"""The README's results of the paper's Case 1 design are reproduced: every variant of
offline_design/case1_vertex.yaml (the vertex tube, the quick design of CI; the certified
case1.yaml takes minutes to design), designed from scratch (or from a valid saved
design) and simulated in process, against the checked-in reference
tests/data/results_reference.json within the stated tolerances
(fahv.runs.results.TOLERANCES). Regenerate with ``fahv results --write-reference
tests/data/results_reference.json`` (every case of the README's table; this test reads
case1_vertex, ``fahv results --check`` every case)."""

import io
import math
from pathlib import Path

import pytest

from fahv.cli.design import load_or_design
from fahv.runs.results import TOLERANCES, compare_reference, read_reference, run_case

REFERENCE = Path(__file__).parents[1] / "data" / "results_reference.json"


@pytest.fixture(scope="module")
def case1_results():
    case, design, vehicle = load_or_design(
        "offline_design/case1_vertex.yaml", None, None, io.StringIO().write
    )
    return {case.name: run_case(design, case["variants"], vehicle.limits, lambda *_: None)}


def test_every_case1_variant_matches_the_reference(case1_results):
    ref = read_reference(REFERENCE)
    # every variant is checked
    assert set(ref["case1_vertex"]) == set(case1_results["case1_vertex"])
    bad = compare_reference(case1_results, {"case1_vertex": ref["case1_vertex"]})
    assert bad == [], "\n".join(bad)


def test_the_reference_says_what_the_readme_says(case1_results):
    """The headline numbers of the README table, within the same tolerances."""
    ref = read_reference(REFERENCE)["case1_vertex"]
    assert ref["tube_mpc"]["settling_time_h_s"] == pytest.approx(28.76, abs=0.021)  # 28.8 s
    assert ref["rmpc"]["h_err_final_ft"] == pytest.approx(117.95, abs=0.01)
    assert ref["rmpc"].get("rmpc_lmi_failed", 0) == 0  # the step starts inside E_1, stays
    assert math.isnan(ref["rmpc"]["tube_fraction_inside"])


def test_a_change_beyond_the_tolerance_is_reported():
    ref = read_reference(REFERENCE)
    new = {"case1_vertex": {v: dict(m) for v, m in ref["case1_vertex"].items()}}
    new["case1_vertex"]["rmpc"]["h_err_final_ft"] += 1.0
    new["case1_vertex"]["tube_mpc"]["settling_time_h_s"] += 0.02  # one step: within
    bad = compare_reference(new, {"case1_vertex": ref["case1_vertex"]})
    assert len(bad) == 1 and "rmpc h_err_final_ft" in bad[0]
    assert TOLERANCES["h_err_final_ft"] == (1e-3, 0.01)
