"""The README's results tables: every variant of Cases 1 and 2, metrics and reference.

`fahv results` runs (in process, `fahv.loop.simulate.simulate`) every variant
of each case file on its design (designed first if missing or stale), prints the
results table in the README's layout and can write the metrics as a JSON reference;
`compare_reference` checks a new set of metrics against such a file within
`TOLERANCES` (the CI test `tests/runs/test_results_reference.py` does so for
every variant of Case 1).
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np

from fahv.loop.simulate import simulate
from fahv.runs.metrics import metrics

#: Metrics compared with the reference: key -> (relative, absolute) tolerance. Times
#: may move by one step (Ts = 0.02 s); the rest are continuous in the design's bits.
TOLERANCES = {
    "settling_time_h_s": (0.0, 0.021),
    "settling_time_V_s": (0.0, 0.021),
    "h_err_final_ft": (1e-3, 0.01),
    "V_err_final_fps": (1e-3, 0.01),
    "alpha_err_max_deg": (1e-3, 1e-4),
    "theta_err_max_deg": (1e-3, 1e-4),
    "eta_1_dot_rms_after_fault": (1e-3, 1e-6),
    "eta_2_dot_rms_after_fault": (1e-3, 1e-6),
    "Phi_min": (1e-3, 1e-5),
    "Phi_max": (1e-3, 1e-5),
    "delta_e_min_deg": (1e-3, 1e-3),
    "delta_e_max_deg": (1e-3, 1e-3),
    "input_limit_violations": (0.0, 0.0),
    "tube_fraction_inside": (0.0, 1e-4),
    "tube_level_max": (1e-3, 1e-5),
    "rmpc_lmi_failed": (0.0, 0.0),
    "nominal_qp_solves": (0.0, 0.0),
    "nominal_qp_fallback": (0.0, 0.0),
    "nominal_qp_terminal": (0.0, 0.0),
}


def _num(v) -> float:
    return math.nan if v is None else float(v)


def run_case(design, variants, limits, log=print) -> dict[str, dict]:
    """Metrics of each variant of a designed case (one in-process run each).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variants : sequence of str
        Variants of the case, in order.
    limits : fahv.model.vehicle.InputLimits
    log : callable
        Receives a progress line per variant.

    Returns
    -------
    dict
        variant -> metrics (`fahv.runs.metrics.metrics`) plus `wall_s`.
    """
    out = {}
    for i, v in enumerate(variants, 1):
        log(f"[{i}/{len(variants)}] {design.case['name']} {v}: simulating")
        t0 = time.perf_counter()
        m = metrics(simulate(design, v), limits)
        m["wall_s"] = time.perf_counter() - t0
        log(f"[{i}/{len(variants)}] {design.case['name']} {v}: done in {m['wall_s']:.1f} s")
        out[v] = m
    return out


def compare_reference(new: dict, ref: dict) -> list[str]:
    """Differences of metrics beyond `TOLERANCES` (empty list: within them).

    Parameters
    ----------
    new, ref : dict
        `{case: {variant: metrics}}`; every (case, variant) of `ref` must be in
        `new`. NaN (or null) matches only NaN.

    Returns
    -------
    list of str
        One line per metric outside its tolerance, naming case, variant, key, both
        values and the tolerance.
    """
    bad = []
    for case, variants in ref.items():
        for v, mref in variants.items():
            mnew = new.get(case, {}).get(v)
            if mnew is None:
                bad.append(f"{case} {v}: missing from the new results")
                continue
            for key, (rtol, atol) in TOLERANCES.items():
                if key not in mref and key not in mnew:
                    continue
                a, b = _num(mnew.get(key, 0)), _num(mref.get(key, 0))
                if math.isnan(a) and math.isnan(b):
                    continue
                if not abs(a - b) <= atol + rtol * abs(b):
                    bad.append(
                        f"{case} {v} {key}: {a!r} against the reference {b!r} "
                        f"(tolerance {rtol:g} relative + {atol:g})"
                    )
    return bad


def _f(v, fmt: str) -> str:
    v = _num(v)
    return "never" if math.isnan(v) else fmt.format(v)


def _percent(fraction: float) -> str:
    """A fraction in percent: "100 %" only when it is exactly one (99.98 % is not 100 %)."""
    return "100 %" if fraction == 1.0 else f"{min(100 * fraction, 99.99):.2f} %"


#: Rows of the results table a reference file gives (it holds no wall times): (label,
#: function of a metrics dict -> text).
REFERENCE_ROWS = (
    ("settling time h (10 ft) / V (2 ft/s), from t = 0",
     lambda m: f"{_f(m.get('settling_time_h_s'), '{:.1f} s')} / "
               f"{_f(m.get('settling_time_V_s'), '{:.1f} s')}"),
    ("h / V error at the end", lambda m: f"{m['h_err_final_ft']:+.2f} ft / "
                                         f"{m['V_err_final_fps']:+.2f} ft/s"),
    ("max \\|alpha - alpha_r\\| / \\|theta - theta_r\\| [deg]",
     lambda m: f"{m['alpha_err_max_deg']:.3f} / {m['theta_err_max_deg']:.3f}"),
    ("RMS eta_1_dot / eta_2_dot after fault [1/s]",
     lambda m: f"{m['eta_1_dot_rms_after_fault']:.5f} / {m['eta_2_dot_rms_after_fault']:.5f}"),
    ("Phi range / delta_e range [deg]",
     lambda m: f"{m['Phi_min']:.3f}-{m['Phi_max']:.3f} / "
               f"{m['delta_e_min_deg']:.2f}-{m['delta_e_max_deg']:.2f}"),
    ("steps beyond input limits", lambda m: f"{m['input_limit_violations']}"),
    ("steps with e in Z (max level)",
     lambda m: "no tube" if math.isnan(_num(m.get("tube_fraction_inside")))
     else f"{_percent(m['tube_fraction_inside'])} ({m['tube_level_max']:.3f})"),
    ("RMPC steps outside its largest ellipsoid",
     lambda m: "-" if "rmpc_lmi_failed" not in m and not m.get("_rmpc")
     else f"{m.get('rmpc_lmi_failed', 0)}"),
)  # fmt: skip
#: Rows of the README's results table of fresh runs: the reference's and the wall time.
ROWS = (*REFERENCE_ROWS,
        ("wall time of the run (this machine)", lambda m: f"{m.get('wall_s', math.nan):.1f} s"))


def markdown_table(results: dict, rows=ROWS) -> str:
    """The README's results table: one column per (case, variant), one row per `rows`."""
    cols = [(c, v) for c, vs in results.items() for v in vs]
    lines = [
        "| metric | " + " | ".join(f"{c} `{v}`" for c, v in cols) + " |",
        "|---|" + "---|" * len(cols),
    ]
    for label, fn in rows:
        cells = []
        for c, v in cols:
            m = dict(results[c][v])
            m["_rmpc"] = v.startswith("rmpc")
            cells.append(fn(m))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def reference_table(path: str | Path) -> str:
    """The results table of a reference file (`write_reference`), for the docs.

    Cases in the file's order, each case's Tube-MPC variants first, then the others
    (the RMPC baseline); the rows of `REFERENCE_ROWS` (no wall time: the file holds
    none). The docs' table of Cases 1 and 2 is this table of
    tests/data/results_reference.json, which `fahv results --write-reference` writes
    and tests/runs/test_results_reference.py checks against fresh runs.

    Parameters
    ----------
    path : path
        A reference file (`{case: {variant: metrics}}` JSON).

    Returns
    -------
    str
        The Markdown table, one column per (case, variant).

    Raises
    ------
    OSError, ValueError
        If the file cannot be read or is not JSON.
    """
    ref = read_reference(path)

    def tube_first(v: str) -> tuple:
        return not v.startswith("tube"), v

    ordered = {c: {v: ref[c][v] for v in sorted(ref[c], key=tube_first)} for c in ref}
    return markdown_table(ordered, REFERENCE_ROWS)


def write_reference(results: dict, path: str | Path) -> Path:
    """Write `{case: {variant: metrics}}` as JSON (NaN as null), keys sorted."""

    def clean(v):
        if isinstance(v, dict):
            return {str(k): clean(x) for k, x in v.items() if k != "wall_s"}
        if isinstance(v, float | np.floating):
            return None if not math.isfinite(float(v)) else float(v)
        if isinstance(v, np.integer):
            return int(v)
        return v

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".part")  # a reference is replaced whole or not at all
    tmp.write_text(json.dumps(clean(results), indent=1, sort_keys=True) + "\n")
    os.replace(tmp, p)
    return p


def read_reference(path: str | Path) -> dict:
    """Read a reference written by `write_reference` (null back to NaN)."""

    def back(v):
        if isinstance(v, dict):
            return {k: back(x) for k, x in v.items()}
        return math.nan if v is None else v

    return back(json.loads(Path(path).read_text()))
