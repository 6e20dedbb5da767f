"""Campaign report: pass rate per requirement, failure-probability bounds, worst runs, figures.

Requirements (bounds from the campaign file's `requirements`), per variant, on
every run of the dataset:

==============  ===============================================================
completes       the run ends without exception, with a finite state, inside the
                flight envelope (status `ok`)
attitude        max |alpha - alpha_r| and max |theta - theta_r| <= attitude_deg
input_limits    no step with a command beyond the actuator limits (sec. 5.1)
input_rates     no step whose command asks a servo for more than its rate limit
                (the vehicle file's servos; n/a for rows without the metric: ideal
                actuators, a run that raised, datasets of earlier versions)
tube            tube error inside Z (tau Z) at every step (n/a for laws without tube)
settling        |h - h_c| <= 10 ft and |V - V_c| <= 2 ft/s reached within
                settling_s after the command stops moving, and held to the end
final_h         |h - h_c| at the end <= h_final_ft
final_V         |V - V_c| at the end <= V_final_fps
==============  ===============================================================

With two or more variants, each other variant is compared with the first run by run
on the same draws (`fahv.campaign.paired`: paired differences with confidence
intervals, figures). A run without metrics (it raised) fails every requirement but the
tube and the rates (n/a for it). Failure-probability bound: with k failures in n runs,
the one-sided Clopper-Pearson upper bound at confidence C, `beta.ppf(C, k + 1, n - k)`;
for k = 0 it is the zero-failure bound 1 - (1 - C)^(1/n) (n runs without a failure show
p < that bound at confidence C).
"""

from __future__ import annotations

import json
import math
import re
from collections import Counter
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from pathlib import Path

import numpy as np
from scipy.stats import beta

from fahv.campaign import store
from fahv.campaign.attribution import attribute_all, attribution_figure, attribution_lines
from fahv.campaign.draws import scatter_columns
from fahv.campaign.figures import WORST_METRICS, draw_figures, metric
from fahv.campaign.paired import paired_figures, paired_stats, paired_text, table_cell
from fahv.spec.coverage import NOT_CERTIFIED, is_certified
from fahv.spec.requirements import judge, limits_of

#: Requirements in report order: (key, description).
REQUIREMENTS = (
    ("completes", "run completes (no exception, finite state, inside the envelope)"),
    ("attitude", "attitude error within +/- {attitude_deg:g} deg"),
    ("input_limits", "commands within the input limits"),
    ("input_rates", "commands within the servos' rate limits"),
    ("tube", "tube error inside Z at every step"),
    ("settling", "settled within {settling_s:g} s of the command"),
    ("settling_fault", "settled within {settling_s:g} s of a fault after the command"),
    ("final_h", "final |h - h_c| <= {h_final_ft:g} ft"),
    ("final_V", "final |V - V_c| <= {V_final_fps:g} ft/s"),
    ("all", "every requirement at once"),
    (
        "nominal_range",
        "nominal inside the range the tube's certificate covers (its "
        'assumption, not in "every requirement")',
    ),
)

#: The nominal's largest deviations "nominal_range" checks: (metric key, the certified
#: range's field and index, metric in degrees). Attitude against `lo`/`hi` (its
#: smaller side), q and the flexible states against `other_half`.
_NOMINAL_DEV = (
    ("nominal_alpha_dev_max_deg", "lohi", 2, True),
    ("nominal_theta_dev_max_deg", "lohi", 3, True),
    ("nominal_q_dev_max_degps", "other_half", 0, True),
    ("nominal_eta_1_dev_max", "other_half", 1, False),
    ("nominal_eta_1_dot_dev_max", "other_half", 2, False),
    ("nominal_eta_2_dev_max", "other_half", 3, False),
    ("nominal_eta_2_dot_dev_max", "other_half", 4, False),
)


def failure_bound(k: int, n: int, confidence: float) -> float:
    """One-sided upper bound on the failure probability, k failures in n runs.

    Clopper-Pearson at `confidence` C: `beta.ppf(C, k + 1, n - k)`, 1 when k = n,
    NaN when n = 0. For k = 0 this is 1 - (1 - C)^(1/n).
    """
    if n == 0:
        return math.nan
    if k == 0:
        return 1.0 - (1.0 - confidence) ** (1.0 / n)
    if k >= n:
        return 1.0
    return float(beta.ppf(confidence, k + 1, n - k))


def verdicts(row: dict, req: dict, certified: dict | None = None) -> dict[str, bool | None]:
    """Pass (True), fail (False) or not applicable (None) of each requirement for one run.

    `certified` is the design's certified nominal range (`certificate.certified_range`
    of an eight-state design's summary, `fahv.bounds.domain.certified_range`):
    "nominal_range" checks the run's nominal against it (None without it, or for a run
    without a nominal). It is the tube's assumption, not one of the requirements "all"
    combines.
    """
    has = row.get("alpha_err_max_deg") is not None
    if not has:
        not_applicable = ("tube", "input_rates", "settling_fault", "nominal_range")
        return {k: (False if k not in not_applicable else None)
                for k, _ in REQUIREMENTS}  # fmt: skip
    out = _each(row, req)
    out["all"] = all(v for v in out.values() if v is not None)
    out["nominal_range"] = nominal_in_range(row, certified)
    return out


def nominal_in_range(row: dict, certified: dict | None) -> bool | None:
    """The run's nominal inside the certified range (h, V, attitude, q, flexible states).

    Parameters
    ----------
    row : dict
        A dataset row (`fahv.runs.metrics.metrics`' nominal keys).
    certified : dict or None
        `{"lo": (6,), "hi": (6,), "other_half": (5,)}` in the scheduling box's
        coordinates (h ft, V ft/s, alpha, theta rad, Phi, delta_e; q rad/s, flexible).

    Returns
    -------
    bool or None
        None without a range or without the nominal's metrics.
    """
    if certified is None or row.get("nominal_h_min_ft") is None:
        return None
    lo, hi, oth = (np.asarray(certified[k], float) for k in ("lo", "hi", "other_half"))
    ok = lo[0] <= metric(row, "nominal_h_min_ft") and metric(row, "nominal_h_max_ft") <= hi[0]
    ok &= lo[1] <= metric(row, "nominal_V_min_fps") and metric(row, "nominal_V_max_fps") <= hi[1]
    for key, field, i, degrees in _NOMINAL_DEV:
        bound = min(-lo[i], hi[i]) if field == "lohi" else oth[i]
        ok &= bool(metric(row, key) <= (np.degrees(bound) if degrees else bound))
    return bool(ok)


def _each(row: dict, req: dict) -> dict[str, bool | None]:
    """The verdicts of `verdicts` but "all" (`fahv.spec.requirements.judge`)."""
    judged = judge(row, limits_of({"requirements": req}), completed=row["status"] == "ok")
    return {j.requirement.key: j.passed for j in judged}


@dataclass
class Report:
    """A campaign report.

    Attributes
    ----------
    text : str
        Markdown (also written to `DIR/report/report.md`).
    table : dict
        `{variant: {requirement: (passed, applicable, bound)}}`.
    figures : list of Path
    n_runs : int
        Rows in the dataset.
    by_coverage : dict
        `{group: {variant: {requirement: (passed, applicable, bound)}}}` of the
        certified and the not certified draws (`coverage_lines`).
    confidence : float
        Of the failure-probability bounds.
    overview : str
        Markdown of the report's head: the title, the dataset and its parts' wall times,
        and the pass-rate table (what `fahv campaign report DIR --write FILE` writes, the
        evidence a results page shows).
    """

    text: str
    table: dict
    figures: list
    n_runs: int
    by_coverage: dict = dataclass_field(default_factory=dict)
    confidence: float = 0.95
    overview: str = ""

    def summary(self) -> str:
        """A few lines for the terminal: runs, then each requirement's pass count per variant.

        Each count with its pass rate and the upper bound on the failure probability
        (`failure_bound` at the campaign's confidence). The whole report (worst runs,
        figures) is the file `DIR/report/report.md`.
        """
        variants = list(self.table)
        width = max(len(k) for k, _ in REQUIREMENTS)
        lines = [f"{self.n_runs} runs; requirement: runs passing / applicable per variant "
                 f"(pass rate; failure probability below the bound at confidence "
                 f"{self.confidence:g}, Clopper-Pearson)"]  # fmt: skip
        lines.append(f"  {'':<{width}}  " + "  ".join(f"{v:>34}" for v in variants))
        for key, _ in REQUIREMENTS:
            cells = []
            for v in variants:
                ok, n, bound = self.table[v][key]
                cell = "n/a" if n == 0 else (f"{ok}/{n} ({100.0 * ok / n:.1f} %; p_fail < "
                                             f"{100.0 * bound:.2g} %)")  # fmt: skip
                cells.append(f"{cell:>34}")
            lines.append(f"  {key:<{width}}  " + "  ".join(cells))
        if self.by_coverage:  # "every requirement at once" of each group of draws
            c, u = (self.by_coverage[g] for g in COVERAGE_GROUPS)
            lines.append("  all, certified | not certified draws: " + "; ".join(
                f"{v} {c[v]['all'][0]}/{c[v]['all'][1]} | {u[v]['all'][0]}/{u[v]['all'][1]}"
                for v in variants))  # fmt: skip
        return "\n".join(lines)


def _fmt(v) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.4g}"
    return str(v)


def _certified_range(out: Path) -> dict | None:
    """The certified nominal range of the campaign's saved design.

    None if the design is not an eight-state one or the folder holds no saved design.
    """
    try:
        summary = json.loads((out / "design" / "design.json").read_text())["summary"]
    except (OSError, ValueError, KeyError):
        return None
    return (summary.get("certificate") or {}).get("certified_range")


def make_report(out_dir: str | Path, figures: bool = True, worst: int = 3) -> Report:
    """Read a campaign folder's dataset and write its report (`DIR/report/`).

    Parameters
    ----------
    out_dir : path
        Campaign folder.
    figures : bool
        Draw the PNG figures (histograms, scatter plots, worst trajectories).
    worst : int
        Worst runs listed per metric.

    Raises
    ------
    CampaignError
        If the folder is not a campaign folder.
    """
    from fahv.errors import CampaignError

    out = Path(out_dir)
    man = store.read_manifest(out)
    if man is None:
        raise CampaignError(f"{out} is not a campaign folder (no {store.MANIFEST})")
    data = man["campaign"]
    req = data["requirements"]
    rows = store.read_rows(out)
    cols = scatter_columns(data)
    shown = cols + (["fault.kind"] if "fault.kind" in (rows[0] if rows else {}) else [])
    conf = req["confidence"]
    per_variant = {v: [r for r in rows if r["variant"] == v] for v in data["variants"]}
    lines = header_lines(man, rows)
    table, rate_lines = pass_rate_lines(data, per_variant, _certified_range(out))
    lines += rate_lines
    overview = "\n".join(lines) + "\n"
    by_coverage, cov_lines = coverage_lines(data, per_variant, _certified_range(out))
    lines += cov_lines
    reasons = Counter(r["reason"].split(" at t =")[0] for r in rows if r["status"] != "ok")
    if reasons:
        lines += ["", "Failed runs by reason:", ""]
        lines += [f"- {n} x {reason}" for reason, n in reasons.most_common()]
    paired = []
    for b in data["variants"][1:]:  # every other variant against the first, run by run
        a = data["variants"][0]
        res = paired_stats(rows, a, b, conf)
        paired.append((a, b, res))
        lines += [""] + paired_text(res, a, b)
        if res["completion"]["both"] < res["completion"]["n"]:  # also with envelope exits
            lines += [""] + paired_text(paired_stats(rows, a, b, conf, completed=False), a, b)
    lines += worst_lines(data, per_variant, shown, worst)
    drivers = {v: attribute_all(vrows, data) for v, vrows in per_variant.items()}
    for v, found in drivers.items():
        if found:
            lines += attribution_lines(v, found)
    figs: list[Path] = []
    if figures and rows:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        figs = draw_figures(out, data, per_variant, cols)
        for a, b, res in paired:
            figs += paired_figures(res, a, b, out / "report", plt)
        for v, found in drivers.items():
            if found:
                figs.append(attribution_figure(v, found, out / "report" / f"drivers_{v}.png",
                                               plt))  # fmt: skip
        lines += ["## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figs]
    text = "\n".join(lines) + "\n"
    rep = out / "report"
    rep.mkdir(exist_ok=True)
    (rep / "report.md").write_text(text)
    return Report(text, table, figs, len(rows), by_coverage, req["confidence"], overview)


def header_lines(man: dict, rows: list[dict]) -> list[str]:
    """The report's title, dataset line and one line per part of the campaign run."""
    data = man["campaign"]
    conf = data["requirements"]["confidence"]
    return [
        f"# Campaign {man['name']}",
        "",
        f"{len(rows)} of {data['runs'] * len(data['variants'])} runs in the dataset "
        f"({data['runs']} samples x variants {', '.join(data['variants'])}); seed "
        f"{data['seed']}, scenario {man['case']['name']}, {man['duration']:g} s per run, "
        f"design {man['design_hash']}. Wall time summed over the runs (worker time): "
        f"{sum(metric(r, 'wall_s') for r in rows):.0f} s.",
        "",
        *[
            f"Part {x['session']} ({x['engine']}): {x['new']} runs ({x['failed']} failed) "
            f"in {x['wall_s']:.0f} s wall time"
            + (", interrupted" if x["interrupted"] else "")
            + (f", {x['errors']} tasks lost" if x["errors"] else "")
            + "."
            for x in man.get("sessions", [])
        ],
        "",
        f"## Pass rate per requirement (failure-probability bound at C = {conf:g})",
        "",
    ]


def pass_rate_lines(data: dict, per_variant: dict, certified) -> tuple[dict, list[str]]:
    """The pass-rate table per requirement and variant, and the runs stuck off the command.

    Returns
    -------
    table : dict
        `{variant: {requirement: (passed, runs, failure-probability bound)}}`.
    lines : list of str
    """
    req = data["requirements"]
    verd = {v: [verdicts(r, req, certified) for r in rs] for v, rs in per_variant.items()}
    table, lines = rate_table(data, verd)
    for v in data["variants"]:  # a nominal part stuck on its terminal law off the command
        stuck = [
            r["index"] for r, x in zip(per_variant[v], verd[v], strict=True)
            if (r.get("nominal_qp_terminal") or 0) > 0 and not (x["final_h"] and x["final_V"])
        ]  # fmt: skip
        if any(r.get("nominal_qp_terminal") is not None for r in per_variant[v]):
            lines += [
                "",
                f"{v}: {len(stuck)} runs end away from the command (final error beyond its "
                "bound) after nominal steps on the terminal law"
                + (f": runs {', '.join(map(str, stuck[:20]))}" if stuck else "")
                + ".",
            ]
    return table, lines


def rate_table(data: dict, verd: dict) -> tuple[dict, list[str]]:
    """The pass-rate table of runs' verdicts, per requirement and variant.

    Parameters
    ----------
    data : dict
        The validated campaign (`variants`, `requirements`).
    verd : dict
        `{variant: [verdicts of a run, ...]}` (`verdicts`).

    Returns
    -------
    table : dict
        `{variant: {requirement: (passed, runs, failure-probability bound)}}`
        (`failure_bound` at the campaign's confidence).
    lines : list of str
        The Markdown table.
    """
    req = data["requirements"]
    table: dict = {}
    lines = ["| requirement | " + " | ".join(data["variants"]) + " |",
             "|---|" + "---|" * len(data["variants"])]  # fmt: skip
    for key, desc in REQUIREMENTS:
        cells = []
        for v in data["variants"]:
            vals = [x[key] for x in verd[v] if x[key] is not None]
            n, ok = len(vals), sum(vals)
            bound = failure_bound(n - ok, n, req["confidence"])
            table.setdefault(v, {})[key] = (ok, n, bound)
            cells.append(
                "n/a" if n == 0 else f"{ok}/{n} ({100.0 * ok / n:.1f} %), p_fail < {bound:.3g}"
            )
        lines.append(f"| {table_cell(desc.format(**req))} | " + " | ".join(cells) + " |")
    return table, lines


#: The two groups of draws `coverage_lines` reports apart, by their coverage verdict.
COVERAGE_GROUPS = ("certified", "not certified")


def coverage_group(row: dict) -> str | None:
    """`certified` or `not certified` by a row's `coverage`; None without a verdict."""
    ok = is_certified(row.get("coverage"))
    return None if ok is None else COVERAGE_GROUPS[0 if ok else 1]


def coverage_lines(data: dict, per_variant: dict, certified=None) -> tuple[dict, list[str]]:
    """Pass rates of the draws the design certifies and of the others, apart.

    A draw's group is its runs' coverage verdict (column `coverage`,
    `fahv.sil.runner.run_coverage`); a dataset of an earlier version, without the
    column, has no such section.

    Parameters
    ----------
    data : dict
        The validated campaign.
    per_variant : dict
        `{variant: [row, ...]}`.
    certified : dict, optional
        The design's certified nominal range (`verdicts`).

    Returns
    -------
    table : dict
        `{group: {variant: {requirement: (passed, runs, bound)}}}` for the groups of
        `COVERAGE_GROUPS`; empty without coverage verdicts.
    lines : list of str
        The section: per group its draws and its table; the reasons of the draws not
        certified, counted with their numbers as `#`.
    """
    rows = [r for rs in per_variant.values() for r in rs]
    if not any(coverage_group(r) for r in rows):
        return {}, []
    req = data["requirements"]
    draws = {r["index"]: r["coverage"] for r in rows if coverage_group(r)}
    lines = ["", "## Pass rate of the certified and the not certified draws", "",
             "A draw is certified when the design's certificate covers everything it asks "
             "(its coverage verdict); the bounds hold for each group on its own."]  # fmt: skip
    table: dict = {}
    for group in COVERAGE_GROUPS:
        sub = {v: [r for r in rs if coverage_group(r) == group] for v, rs in per_variant.items()}
        n = sum(coverage_group({"coverage": c}) == group for c in draws.values())
        verd = {v: [verdicts(r, req, certified) for r in rs] for v, rs in sub.items()}
        table[group], rate = rate_table(data, verd)
        lines += ["", f"### {group}: {n} of {len(draws)} draws", ""] + rate
    why = reason_counts(
        reason for c in draws.values() if c.startswith(NOT_CERTIFIED)
        for reason in c.removeprefix(NOT_CERTIFIED).split("; ")
    )  # fmt: skip
    if why:
        lines += ["", "Why draws are not certified (draws per reason, the range of each "
                  "number over those draws):", ""]  # fmt: skip
        lines += [f"- {n} x {reason}" for reason, n in why]
    return table, lines


#: A number in a reason (not inside a name such as case1_paper).
_NUMBER = re.compile(r"(?<![A-Za-z_\d.])-?\d+(?:\.\d+)?")


def reason_counts(reasons) -> list[tuple[str, int]]:
    """Reasons of the same wording counted together, each number as its range.

    Parameters
    ----------
    reasons : iterable of str
        One sentence per draw and reason (`fahv.spec.coverage.Coverage.reasons`).

    Returns
    -------
    list of (str, int)
        The reason with each of its numbers written as the range over the draws that give
        it (`onset loss 10.2 to 23.9 % above the certified 8.07 %`, a number the draws
        share once), and the number of draws; most frequent first.

    Examples
    --------
    >>> reason_counts(["onset loss 12 % above 8.07 %", "onset loss 20.5 % above 8.07 %"])
    [('onset loss 12 to 20.5 % above 8.07 %', 2)]
    """
    groups: dict[str, list[list[float]]] = {}
    for reason in reasons:
        key = _NUMBER.sub("\x00", reason)
        groups.setdefault(key, []).append([float(x) for x in _NUMBER.findall(reason)])
    out = []
    for key, numbers in groups.items():
        pieces = key.split("\x00")
        text = pieces[0]
        for column, piece in zip(zip(*numbers, strict=True), pieces[1:], strict=True):
            lo, hi = min(column), max(column)
            text += (f"{lo:g}" if lo == hi else f"{lo:g} to {hi:g}") + piece
        out.append((text, len(numbers)))
    return sorted(out, key=lambda item: -item[1])


def worst_lines(data: dict, per_variant: dict, shown: list[str], worst: int) -> list[str]:
    """The tables of the `worst` runs per metric and variant."""
    lines = ["", f"## Worst {worst} runs per metric", ""]
    for key, label, worse, _ in WORST_METRICS:
        for v in data["variants"]:
            rs = [r for r in per_variant[v] if r.get(key) is not None]
            if not rs:
                continue

            def score(r, key=key, worse=worse):
                x = metric(r, key)
                return math.inf if math.isnan(x) else worse(x)

            top = sorted(rs, key=score, reverse=True)[:worst]
            lines += [f"{label}, {v}:", ""]
            lines.append("| index | value | " + " | ".join(shown) + " |")
            lines.append("|---|---|" + "---|" * len(shown))
            for r in top:
                vals = " | ".join(_fmt(r.get(c)) for c in shown)
                lines.append(f"| {r['index']} | {_fmt(worse(metric(r, key)))} | {vals} |")
            lines.append("")
    return lines
