"""A recorded run judged: its metrics and its verdict against the requirements it was flown with.

The input limits a run is measured against are its vehicle file's with the rates of its
own servos (`run_limits`: the plant's `servo_rate_limit_factor` from the run's parameter
file); the requirement limits are those its metadata records (`recorded_limits`, the
paper's for runs recorded before it held them). `fahv inspect`, `compare` and
`campaign rerun` read runs through these.
"""

from __future__ import annotations

import json

from fahv.errors import RunError
from fahv.model.vehicle import load_vehicle
from fahv.runs.bag import Recording, run_result_of
from fahv.runs.metrics import metrics
from fahv.spec.plant_dispersion import rate_limit_factor
from fahv.spec.requirements import PAPER_LIMITS, Judgement, judge, limits_of
from fahv.verdict import Verdict


def run_metrics(rec: Recording, limits) -> tuple[dict | None, str]:
    """Metrics of a run, or None and the reason when it holds no complete step.

    Parameters
    ----------
    rec : fahv.runs.bag.Recording
    limits : fahv.model.vehicle.InputLimits
    """
    run = run_result_of(rec)
    if run.t.size == 0:
        return None, "no complete step on every loop topic: no metrics"
    return metrics(run, limits), f"{run.t.size} complete steps"


def recorded_limits(metadata: dict) -> dict:
    """The requirement limits a run was recorded with (its metadata `requirements`).

    Runs recorded before the metadata held them are judged against the paper's limits.

    Raises
    ------
    RunError
        If the metadata's `requirements` is not a JSON mapping of numbers.
    """
    text = metadata.get("requirements")
    if not text:
        return dict(PAPER_LIMITS)
    try:
        given = json.loads(text)
        return limits_of({"requirements": {k: float(v) for k, v in given.items()}})
    except (ValueError, TypeError, AttributeError) as exc:
        raise RunError(f"run metadata 'requirements' is not a mapping of limits: {text!r} "
                       f"({exc})") from None  # fmt: skip


def run_judgements(metadata: dict, m: dict | None) -> list[Judgement] | None:
    """A recorded run judged against its recorded requirements (None without metrics).

    The run completed unless its metadata holds an early end (`fahv.verdict`) or a status
    other than `complete`.
    """
    if m is None:
        return None
    verdict = Verdict.from_metadata(metadata)
    completed = metadata.get("status", "complete") == "complete" and (
        verdict is None or verdict.completed)
    return judge(m, recorded_limits(metadata), completed)


def run_vehicle(rec: Recording):
    """The vehicle a recorded run was made with (metadata `vehicle_file`; packaged if "").

    Raises
    ------
    VehicleDataError
        If the recorded vehicle file is gone or invalid (the message names it).
    """
    return load_vehicle(rec.metadata.get("vehicle_file") or None)


def run_limits(rec: Recording):
    """The input limits a recorded run is judged against: its vehicle's, its servos' rates.

    The rate limits times the run's `servo_rate_limit_factor` (its parameter file's
    plant node; 1 without one).

    Raises
    ------
    VehicleDataError
        As `run_vehicle`.
    RunError
        If the stored parameter file is not a YAML mapping.
    """
    return run_vehicle(rec).limits.with_rate_factor(rate_limit_factor({}, rec.params()))
