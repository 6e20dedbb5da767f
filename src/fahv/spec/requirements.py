"""Requirements of a run and its verdict: each requirement's value, limit, margin, PASS/FAIL.

The paper's performance requirements (sec. 5.1: attitude errors within 0.5 deg, the
altitude and velocity steps settled within 60 s, the inputs within their limits) and the
ones a loop with servos and a tube adds, as data: a scenario's optional `requirements`
section (`REQUIREMENT_FIELDS`, defaults the paper's) sets their limits, a campaign file's
its own. Every run is judged against them alike: `fahv simulate`, `sil`, `inspect` and
`replay` print the verdict table (`verdict_table`), a campaign's report counts each row's
(`fahv.campaign.report.verdicts`), one function (`judge`) for both.

Each requirement reads the run's metrics (`fahv.runs.metrics.metrics`), whose names carry
their window and signal, and has a margin in its own unit: the limit minus the value for
an upper bound (positive: met with room to spare, negative: missed by that much).

==============  =======================================================================
completes       the run ends as planned (no early end: `fahv.verdict`)
attitude        max |alpha - alpha_r| and max |theta - theta_r| over the run <= limit
input_limits    steps whose command (the controller's, before the fault injector) lies
                beyond the input limits: 0
input_rates     steps whose command asks a servo for more than its rate limit: 0 (n/a:
                ideal actuators, which have no rate)
tube            max e' N^-1 e (the tube error's level in Z) over the run <= 1 (n/a: a
                law without a tube; not judged on a loop on a state estimate, which the
                tube's certificate does not cover: its level is reported)
settling        |h - h_c| <= 10 ft and |V - V_c| <= 2 ft/s reached within the limit
                after the command stops moving and held to the end (n/a: a run that
                ends before the limit without settling)
settling_fault  the same within the limit after a fault's onset that comes after the
                command stops moving (n/a: no such fault, or a run that ends first)
final_h         |h - h_c| at the run's last step <= limit
final_V         |V - V_c| at the run's last step <= limit
==============  =======================================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from fahv.config import Field, Section

#: The limits a scenario or a campaign may set (defaults: the paper's sec. 5.1).
REQUIREMENT_FIELDS = (
    Field("attitude_deg", "float", "bound on the attitude errors alpha - alpha_r and "
          "theta - theta_r (absolute, over the run)", unit="deg", lo=0.0, lo_open=True,
          default=0.5),
    Field("settling_s", "float", "settling (h within 10 ft of h_c and V within 2 ft/s "
          "of V_c, held to the end) within this time after the command stops moving",
          unit="s", lo=0.0, lo_open=True, default=60.0),
    Field("h_final_ft", "float", "bound on the final altitude error h - h_c (absolute)",
          unit="ft", lo=0.0, lo_open=True, default=10.0),
    Field("V_final_fps", "float", "bound on the final velocity error V - V_c (absolute)",
          unit="ft/s", lo=0.0, lo_open=True, default=2.0),
)  # fmt: skip

#: The paper's limits (the fields' defaults).
PAPER_LIMITS = {f.name: f.default for f in REQUIREMENT_FIELDS}


def requirements_section() -> Section:
    """A scenario's optional `requirements` section (absent: the paper's limits).

    Absent, it is left out of the run spec, so a scenario without it keeps its hash.
    """
    return Section("requirements", REQUIREMENT_FIELDS, "the limits every run of the "
                   "scenario is judged against (fahv.spec.requirements)",
                   when=lambda r: False, when_text="a scenario judges its runs against "
                   "other limits (optional: absent, the paper's sec. 5.1)")  # fmt: skip


def limits_of(spec: Mapping | None) -> dict:
    """The requirement limits of a run spec, scenario or campaign mapping.

    Its `requirements` section's values over the paper's (`PAPER_LIMITS`); other keys of
    the section (a campaign's `confidence`) are left out.
    """
    given = (spec or {}).get("requirements") or {}
    return {k: float(given.get(k, v)) for k, v in PAPER_LIMITS.items()}


@dataclass(frozen=True)
class Requirement:
    """One requirement: what it measures, on which metric, against which limit.

    Attributes
    ----------
    key : str
        Its name (`REQUIREMENTS` order): the campaign report's column.
    signal : str
        What is measured, on which signal and over which window.
    unit : str
        Unit of the value, the limit and the margin.
    value : callable
        `value(metrics) -> float`: the run's value (NaN: not measured).
    limit : callable
        `limit(limits) -> float`: the upper bound the value must not exceed.
    nan : str
        What a NaN value means: `"n/a"` (the requirement does not apply to the run) or a
        word of a failure (`"never"`: a run that never settled fails).
    verdict : callable, optional
        `verdict(metrics) -> bool | None` where the verdict is read from another metric
        than the value (the tube: every step inside Z, a row of any version); by default
        value <= limit.
    start : callable, optional
        `start(metrics) -> float` [s]: when the time the value measures starts (the
        command stops moving, the fault's onset). A value never reached is then a
        failure only if the run went on for the limit after the start; a shorter run did
        not measure it.
    absent : str
        Where a NaN start means the requirement does not apply, why (e.g. no fault in
        the run); empty: a NaN start (a row without the metrics) is a failure.
    """

    key: str
    signal: str
    unit: str
    value: Callable[[Mapping], float]
    limit: Callable[[Mapping], float]
    nan: str = "n/a"
    verdict: Callable[[Mapping], bool | None] | None = None
    start: Callable[[Mapping], float] | None = None
    absent: str = ""


def _metric(name: str) -> Callable[[Mapping], float]:
    """The run's metric `name` as a float (NaN when absent or None)."""

    def value(m: Mapping) -> float:
        v = m.get(name)
        return math.nan if v is None else float(v)

    return value


def _largest(*names: str) -> Callable[[Mapping], float]:
    """The largest absolute value of the metrics `names` (NaN if any is NaN or absent)."""

    def value(m: Mapping) -> float:
        vs = [_metric(n)(m) for n in names]
        return math.nan if any(math.isnan(v) for v in vs) else max(abs(v) for v in vs)

    return value


def _zero(_: Mapping) -> float:
    return 0.0


def _tube_level(m: Mapping) -> float:
    """The tube level's maximum, NaN where the run has no tube error at every step."""
    return math.nan if math.isnan(_metric("tube_fraction_inside")(m)) else _metric(
        "tube_level_max")(m)


def on_estimate(m: Mapping) -> bool:
    """The loop read a state estimate (its errors measured), not the exact state."""
    return not math.isnan(_metric("estimate_err_h_rms_ft")(m))


def _inside_z(m: Mapping) -> bool | None:
    """Every step's tube error inside Z.

    None where the tube is not judged: no tube error at every step, or a loop on a state
    estimate (the tube's certificate assumes the exact state; its level is reported).
    """
    fraction = _metric("tube_fraction_inside")(m)
    return None if math.isnan(fraction) or on_estimate(m) else bool(fraction == 1.0)


def _command_end(m: Mapping) -> float:
    """When the command stops moving [s] (the settling requirement's start)."""
    return _metric("t_command_end_s")(m)


def _fault_onset(m: Mapping) -> float:
    """The fault's onset [s] when it comes after the command stops moving, else NaN.

    NaN too for a row without `settling_after_fault_s` (written before it was measured).
    """
    if "settling_after_fault_s" not in m:
        return math.nan
    onset, end = _metric("t_fault_s")(m), _command_end(m)
    return onset if onset > end else math.nan


#: Every requirement in report order.
REQUIREMENTS = (
    Requirement("attitude", "max |alpha - alpha_r|, |theta - theta_r| over the run", "deg",
                _largest("alpha_err_max_deg", "theta_err_max_deg"),
                lambda lim: lim["attitude_deg"], nan="never measured"),
    Requirement("input_limits", "steps whose command (before the fault injector) is "
                "beyond the input limits", "steps", _metric("input_limit_violations"), _zero,
                nan="never measured"),
    Requirement("input_rates", "steps whose command asks a servo beyond its rate limit",
                "steps", _metric("input_rate_violations"), _zero),
    Requirement("tube", "max tube level e' N^-1 e over the run (inside Z: <= 1)", "-",
                _tube_level, lambda lim: 1.0, verdict=_inside_z),
    Requirement("settling", "settling of h (10 ft) and V (2 ft/s) after the command stops "
                "moving, held to the end", "s", _metric("settling_after_command_s"),
                lambda lim: lim["settling_s"], nan="never", start=_command_end),
    Requirement("settling_fault", "settling of h (10 ft) and V (2 ft/s) after a fault's "
                "onset (after the command), held to the end", "s",
                _metric("settling_after_fault_s"), lambda lim: lim["settling_s"],
                nan="never", start=_fault_onset, absent="no fault after the command"),
    Requirement("final_h", "|h - h_c| at the last step", "ft", _largest("h_err_final_ft"),
                lambda lim: lim["h_final_ft"], nan="never measured"),
    Requirement("final_V", "|V - V_c| at the last step", "ft/s", _largest("V_err_final_fps"),
                lambda lim: lim["V_final_fps"], nan="never measured"),
)  # fmt: skip


@dataclass(frozen=True)
class Judgement:
    """One requirement judged on one run.

    Attributes
    ----------
    requirement : Requirement
    value : float
        The run's value (NaN: not measured; `requirement.nan` says what that means).
    limit : float
        Its upper bound [the requirement's unit].
    passed : bool or None
        Met (True), missed (False), does not apply to this run (None).
    note : str
        Why a requirement was not judged where its value alone does not say it (a run
        too short to measure it, no fault after the command, a loop on the estimate).
    """

    requirement: Requirement
    value: float
    limit: float
    passed: bool | None
    note: str = ""

    @property
    def margin(self) -> float:
        """Limit - value [the requirement's unit]; NaN when the value is not measured."""
        return self.limit - self.value

    @property
    def word(self) -> str:
        """PASS, FAIL or n/a."""
        return {True: "PASS", False: "FAIL", None: "n/a"}[self.passed]


def judge(metrics: Mapping, limits: Mapping | None = None, completed: bool = True
          ) -> list[Judgement]:  # fmt: skip
    """Judge one run against every requirement (`REQUIREMENTS`).

    Parameters
    ----------
    metrics : mapping
        The run's metrics (`fahv.runs.metrics.metrics`, or a campaign row); absent or
        None entries are not measured.
    limits : mapping, optional
        Requirement limits (`limits_of`); the paper's by default.
    completed : bool
        Whether the run ended as planned (`fahv.verdict.Verdict.completed`, a campaign
        row's status `ok`).

    Returns
    -------
    list of Judgement
        `completes` first, then `REQUIREMENTS` in order. A value that is NaN passes only
        where it means the requirement does not apply (`Requirement.nan` "n/a").
    """
    lim = {**PAPER_LIMITS, **(limits or {})}
    out = [Judgement(COMPLETES, 0.0 if completed else 1.0, 0.0, bool(completed))]
    for r in REQUIREMENTS:
        v, bound = r.value(metrics), float(r.limit(lim))
        if r.verdict is not None:
            passed = r.verdict(metrics)
            note = "not judged: on the estimate" if passed is None and on_estimate(metrics) else ""
            out.append(Judgement(r, v, bound, passed, note))
        elif math.isnan(v):
            out.append(_not_reached(r, metrics, bound))
        else:
            out.append(Judgement(r, v, bound, bool(v <= bound)))
    return out


def _not_reached(r: Requirement, metrics: Mapping, bound: float) -> Judgement:
    """The judgement of a value that was not measured or never reached (NaN).

    A failure where it means one (`Requirement.nan` other than "n/a") and the run went on
    for the limit after the requirement's start; else not applicable, with the reason.
    """
    if r.nan == "n/a":
        return Judgement(r, math.nan, bound, None)
    if r.start is None:
        return Judgement(r, math.nan, bound, False)
    t0 = r.start(metrics)
    if math.isnan(t0):
        return Judgement(r, math.nan, bound, None, r.absent) if r.absent else Judgement(
            r, math.nan, bound, False)
    watched = _metric("t_final_s")(metrics) - t0
    if watched < bound:  # the run ended before the limit: not measured
        return Judgement(r, math.nan, bound, None, f"not measured: run ends {watched:.4g} s after")
    return Judgement(r, math.nan, bound, False)


#: The run ended as planned (its value 0, or 1 when it ended early).
COMPLETES = Requirement("completes", "the run ends as planned (no early end, fahv.verdict)",
                        "-", _zero, _zero)


def overall(judgements: list[Judgement]) -> bool:
    """Every applicable requirement met (the run's verdict)."""
    return all(j.passed is not False for j in judgements)


def _number(v: float, unit: str) -> str:
    if unit == "steps":
        return f"{v:.0f}"
    return f"{v:.4g}" if abs(v) < 1000 else f"{v:.0f}"


def verdict_rows(judgements: list[Judgement]) -> list[tuple[str, ...]]:
    """The cells of the verdict table: requirement, measured, value, limit, margin, verdict.

    Values, limits and margins with their unit (counts as integers, else four significant
    digits); a value not measured as what its NaN means (`Requirement.nan`), with no
    margin; `completes` as yes / ended early. The terminal (`verdict_table`) and the
    report page (`fahv.runs.report_page`) print these same cells.
    """
    rows = []
    for j in judgements:
        r = j.requirement
        unit = "" if r.unit == "-" else f" {r.unit}"
        if r is COMPLETES:
            value, limit, margin = ("yes" if j.passed else "ended early"), "", ""
        elif math.isnan(j.value):
            value, limit, margin = j.note or r.nan, f"{_number(j.limit, r.unit)}{unit}", ""
        else:
            value = f"{_number(j.value, r.unit)}{unit}"
            limit = f"{_number(j.limit, r.unit)}{unit}"
            margin = j.note or f"{_number(j.margin, r.unit)}{unit}"
        rows.append((r.key, r.signal, value, limit, margin, j.word))
    return rows


def verdict_table(judgements: list[Judgement], name: str = "") -> str:
    """The verdict table of one run: requirement, value, limit, margin, verdict; then overall.

    Parameters
    ----------
    judgements : list of Judgement
        From `judge`.
    name : str
        The run (its folder or `<scenario> <variant>`), named in the overall line.

    Returns
    -------
    str
        One row per requirement (`verdict_rows`), then `verdict: PASS` or `verdict:
        FAIL (<missed requirements>)`.
    """
    rows = [("requirement", "measured", "value", "limit", "margin", "verdict"),
            *verdict_rows(judgements)]  # fmt: skip
    widths = [max(len(row[i]) for row in rows) for i in range(6)]
    lines = ["  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in
                       enumerate(zip(row, widths, strict=True))).rstrip() for row in rows]
    lines.append(overall_line(judgements, name))
    return "\n".join(lines)


def overall_line(judgements: list[Judgement], name: str = "") -> str:
    """`verdict of <name>: PASS (every applicable requirement met)` or `...: FAIL (<missed>)`."""
    missed = [j.requirement.key for j in judgements if j.passed is False]
    who = f" of {name}" if name else ""
    if not missed:
        return f"verdict{who}: PASS (every applicable requirement met)"
    return f"verdict{who}: FAIL ({', '.join(missed)})"


def verdict_record(judgements: list[Judgement]) -> dict:
    """The verdict as plain data (for a run file's metadata or JSON output).

    Returns
    -------
    dict
        `{"requirements": {key: {"value", "limit", "margin", "unit", "verdict"}},
        "verdict": "PASS" | "FAIL"}`; NaN values as None.
    """

    def num(v: float):
        return None if math.isnan(v) else float(v)

    return {
        "requirements": {
            j.requirement.key: {"value": num(j.value), "limit": num(j.limit),
                                "margin": num(j.margin), "unit": j.requirement.unit,
                                "verdict": j.word}
            for j in judgements
        },
        "verdict": "PASS" if overall(judgements) else "FAIL",
    }  # fmt: skip
