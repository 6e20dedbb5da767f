"""The README's results of the paper's Case 1 design are reproduced: every variant of
scenario case1_paper, run in process on its shipped design (offline_design/designs/cm_paper/,
re-checked by fahv verify, never re-designed), against the checked-in reference
tests/data/results_reference.json within the stated tolerances
(fahv.runs.results.TOLERANCES). The shipped design makes the numbers independent of the
machine's floating point in the LMI solves. Regenerate with ``fahv results
--write-reference tests/data/results_reference.json``."""

import io
import math
from pathlib import Path

import pytest

from fahv.certificate.verified import load_or_design
from fahv.runs.results import (
    ROWS,
    TOLERANCES,
    compare_reference,
    read_reference,
    reference_table,
    run_case,
)

REFERENCE = Path(__file__).parents[1] / "data" / "results_reference.json"
CASES_PAGE = Path(__file__).parents[2] / "docs" / "results" / "cases.md"


@pytest.fixture(scope="module")
def case1_results():
    case, design, vehicle = load_or_design(
        "offline_design/scenarios/case1_paper.yaml", None, None, io.StringIO().write
    )
    return {case.name: run_case(design, case["variants"], vehicle.limits, lambda *_: None)}


def test_every_case1_variant_matches_the_reference(case1_results):
    ref = read_reference(REFERENCE)
    # every variant is checked
    assert set(ref["case1_paper"]) == set(case1_results["case1_paper"])
    bad = compare_reference(case1_results, {"case1_paper": ref["case1_paper"]})
    assert bad == [], "\n".join(bad)


def test_the_reference_says_what_the_readme_says(case1_results):
    """The headline numbers of the README table, within the same tolerances."""
    ref = read_reference(REFERENCE)["case1_paper"]
    assert ref["tube_mpc"]["settling_time_h_s"] == pytest.approx(28.76, abs=0.021)  # 28.8 s
    assert ref["rmpc"]["h_err_final_ft"] == pytest.approx(119.13, abs=0.01)
    assert ref["rmpc"].get("rmpc_lmi_failed", 0) == 0  # the step starts inside E_1, stays
    assert math.isnan(ref["rmpc"]["tube_fraction_inside"])


def test_a_change_beyond_the_tolerance_is_reported():
    ref = read_reference(REFERENCE)
    new = {"case1_paper": {v: dict(m) for v, m in ref["case1_paper"].items()}}
    new["case1_paper"]["rmpc"]["h_err_final_ft"] += 1.0
    new["case1_paper"]["tube_mpc"]["settling_time_h_s"] += 0.02  # one step: within
    bad = compare_reference(new, {"case1_paper": ref["case1_paper"]})
    assert len(bad) == 1 and "rmpc h_err_final_ft" in bad[0]
    assert TOLERANCES["h_err_final_ft"] == (1e-3, 0.01)


@pytest.mark.parametrize("marker, reference", [
    ("cases-table", REFERENCE),
    ("case2-cm-table", Path(__file__).parents[2] / "studies/case2_on_cm/results_reference.json"),
])  # fmt: skip
def test_the_docs_tables_of_the_cases_are_their_references(marker, reference):
    """docs/results/cases.md shows the reference files' numbers (docs/hooks/generated.py
    writes them there), column by column in the docs' order, Tube-MPC variants first."""
    page = CASES_PAGE.read_text()
    shown = page.split(f"<!-- {marker} -->\n", 1)[1].split(f"<!-- /{marker} -->")[0]
    assert shown.strip("\n") == reference_table(reference)
    head = shown.splitlines()[0]
    assert head.index("`tube_mpc`") < head.index("`rmpc`")


def test_a_fraction_below_one_is_never_shown_as_100_percent():
    row = dict(ROWS)["steps with e in Z (max level)"]
    assert row({"tube_fraction_inside": 1.0, "tube_level_max": 0.5}) == "100 % (0.500)"
    assert row({"tube_fraction_inside": 0.99999, "tube_level_max": 1.2}) == "99.99 % (1.200)"
    assert row({"tube_fraction_inside": 0.9981, "tube_level_max": 2.5}) == "99.81 % (2.500)"
