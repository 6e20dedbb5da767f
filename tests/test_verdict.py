"""How a run ends (fahv.verdict): the verdict's text, its metadata and its exception."""

import pytest

from fahv.errors import RunError
from fahv.verdict import METADATA_KEYS, VERDICTS, RunEnded, Verdict, completed


def test_a_verdict_round_trips_through_the_run_metadata_and_a_status():
    v = Verdict("non_finite_state", "plant", 1312, 26.24, "state not finite")
    md = v.metadata()
    assert tuple(md) == METADATA_KEYS
    assert md == {"verdict": "non_finite_state", "verdict_node": "plant", "verdict_step": "1312",
                  "verdict_t": "26.24", "verdict_reason": "state not finite"}  # fmt: skip
    assert Verdict.from_metadata(md) == v == Verdict.from_dict(v.as_dict())
    assert Verdict.from_metadata({"case": "case1"}) is None
    assert v.text() == "non_finite_state at t = 26.24 s (step 1312, plant): state not finite"
    assert v.status == "ended: non_finite_state" and not v.completed
    done = completed(3000, 0.02)
    assert done.completed and done.status == "complete"
    assert done.text() == "completed at t = 60.00 s (3000 steps)"


def test_run_ended_is_a_run_error_naming_verdict_time_step_and_node():
    exc = RunEnded("nominal_out_of_domain", "nominal_trajectory", 275, 5.5, "left the map")
    assert isinstance(exc, RunError) and exc.partial is None
    assert (
        str(exc)
        == "nominal_out_of_domain at t = 5.50 s (step 275, nominal_trajectory): left the map"
    )
    assert RunEnded.of(exc.verdict).verdict == exc.verdict
    with pytest.raises(ValueError, match="verdict must be one of"):
        Verdict("crashed", "plant", 1, 0.02)
    with pytest.raises(ValueError, match="no RunEnded"):
        RunEnded("completed", "-", 10, 0.2, "")
    with pytest.raises(ValueError, match="missing or malformed"):
        Verdict.from_dict({"name": "non_finite_state"})
    assert "completed" in VERDICTS and all(len(v) == 2 for v in VERDICTS.values())
