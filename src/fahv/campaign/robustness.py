"""The margin a clearance search minimises: one continuous robustness value per requirement.

The run verdicts judge a requirement by its margin, the limit minus the value
(`fahv.spec.requirements.Judgement.margin`: positive met with room to spare, negative
missed by that much). A search needs that margin wherever the verdict has one, and a
value that keeps falling past the failure where the verdict has none (a falsification
tool's robustness, e.g. ARCH-COMP's falsification category):

==============  =========================================================================
attitude        limit - max(|alpha - alpha_r|, |theta - theta_r|) over the run [deg]
settling        limit - the settling time after the command stops moving [s]; a run that
                never settles: limit - the time watched - limit (e - 1), e the final
                error in bands (max(|h - h_c| / 10 ft, |V - V_c| / 2 ft/s) >= 1), which
                meets the settled value where the run settles at its last step (n/a:
                a run that ends unsettled before the limit, as its verdict)
settling_fault  the same from a fault's onset after the command (n/a: no such fault)
final_h         limit - |h - h_c| at the last step [ft]
final_V         limit - |V - V_c| at the last step [ft/s]
tube            1 - max e' N^-1 e over the run [-] (n/a: a law without a tube)
input_rates     the elevator servo's rate limit (times the run's factor) - the largest
                step-to-step rate of the command [deg/s] (n/a: ideal actuators)
==============  =========================================================================

A run that ended early (a non-finite state, an exit from the flight envelope, an error)
has margin -inf on every requirement: the worst there is, reported with its reason.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from fahv.runs.metrics import SETTLE_TOL
from fahv.spec.requirements import PAPER_LIMITS

#: Requirements a clearance searches, with the unit of their margin.
SEARCHABLE = {"attitude": "deg", "settling": "s", "settling_fault": "s", "final_h": "ft",
              "final_V": "ft/s", "tube": "-", "input_rates": "deg/s"}  # fmt: skip


def _metric(row: Mapping, key: str) -> float:
    v = row.get(key)
    return math.nan if v is None else float(v)


def _settling(row: Mapping, settled: float, start: float, limit: float) -> float:
    """Settling margin [s] from the settling time `settled` after `start` (NaN: never)."""
    if not math.isnan(settled):
        return limit - settled
    watched = _metric(row, "t_final_s") - start
    if watched < limit:  # the run ended before the limit: not measured (as its verdict)
        return math.nan
    e = max(abs(_metric(row, "h_err_final_ft")) / SETTLE_TOL["h"],
            abs(_metric(row, "V_err_final_fps")) / SETTLE_TOL["V"])  # fmt: skip
    return limit - watched - limit * (max(e, 1.0) - 1.0)


def robustness(row: Mapping, requirement: str, limits: Mapping | None = None,
               rate_limit_degps: float = math.nan) -> float:  # fmt: skip
    """The margin of `requirement` on one run (see the module notes for each).

    Parameters
    ----------
    row : mapping
        The run's campaign row: `status` and the metrics (`fahv.runs.metrics.metrics`),
        `actuators.rate_limit` where the servos are dispersed.
    requirement : str
        One of `SEARCHABLE`.
    limits : mapping, optional
        Requirement limits (`fahv.spec.requirements.limits_of`); the paper's by default.
    rate_limit_degps : float
        The vehicle file's elevator servo rate limit [deg/s] (`input_rates`; NaN: ideal
        actuators, where it does not apply).

    Returns
    -------
    float
        The margin in the requirement's unit (`SEARCHABLE`); -inf for a run that ended
        early; NaN where the requirement does not apply to the run.

    Raises
    ------
    ValueError
        If `requirement` is not searchable, naming those that are.
    """
    if requirement not in SEARCHABLE:
        raise ValueError(f"requirement '{requirement}' is not one a clearance searches: "
                         f"{', '.join(SEARCHABLE)}")  # fmt: skip
    if row.get("status", "ok") != "ok":
        return -math.inf
    lim = {**PAPER_LIMITS, **(limits or {})}
    if requirement == "attitude":
        worst = max(abs(_metric(row, "alpha_err_max_deg")), abs(_metric(row, "theta_err_max_deg")))
        return lim["attitude_deg"] - worst
    if requirement == "final_h":
        return lim["h_final_ft"] - abs(_metric(row, "h_err_final_ft"))
    if requirement == "final_V":
        return lim["V_final_fps"] - abs(_metric(row, "V_err_final_fps"))
    if requirement == "tube":
        return 1.0 - _metric(row, "tube_level_max")
    if requirement == "input_rates":
        factor = row.get("actuators.rate_limit", 1.0)
        return rate_limit_degps * float(factor) - _metric(row, "delta_e_rate_max_degps")
    end = _metric(row, "t_command_end_s")
    if requirement == "settling":
        return _settling(row, _metric(row, "settling_after_command_s"), end, lim["settling_s"])
    onset = _metric(row, "t_fault_s")
    if not onset > end:  # no fault after the command (NaN onset: none in the run)
        return math.nan
    return _settling(row, _metric(row, "settling_after_fault_s"), onset, lim["settling_s"])
