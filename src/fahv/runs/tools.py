"""Inspect, export and compare recorded runs (`fahv inspect`, `export`, `compare`).

Works on every run file with our loop topics (`fahv.loop.graph.TOPICS`): runs of
the SIL node graph and of the in-process simulator alike. Topics of other programs
are listed, never decoded; a truncated run is used up to its last complete chunk.

Column names and units of the exported tables come from the message definitions
(`src/fahv/msg/*.msg`: `type name  # description [unit]`); array fields are
split into one column per component named after the state or input
(`x_r.alpha`, `u_n.delta_e`).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from fahv.errors import RunError
from fahv.loop.graph import TOPICS
from fahv.msg import MSG_DIR
from fahv.runs.bag import Recording, step_anomalies
from fahv.runs.judged import run_judgements, run_metrics
from fahv.runs.latency import TIMESTAMPS_FILE, format_latencies, run_latencies
from fahv.spec.requirements import (
    verdict_record,
    verdict_table,
)
from fahv.verdict import METADATA_KEYS, Verdict

#: Rows of the metrics table: (key of `fahv.runs.metrics.metrics`, label, format).
METRIC_ROWS = (
    ("settling_time_h_s", "settling time h (10 ft) [s]", "{:.1f}"),
    ("settling_time_V_s", "settling time V (2 ft/s) [s]", "{:.1f}"),
    ("settling_after_command_s", "settling of h and V after the command [s]", "{:.1f}"),
    ("settling_after_fault_s", "settling of h and V after the fault's onset [s]", "{:.1f}"),
    ("h_err_final_ft", "h error at the end [ft]", "{:.2f}"),
    ("V_err_final_fps", "V error at the end [ft/s]", "{:.2f}"),
    ("h_err_rms_after_settle_ft", "h RMS error after settling [ft]", "{:.2f}"),
    ("V_err_rms_after_settle_fps", "V RMS error after settling [ft/s]", "{:.2f}"),
    ("alpha_err_max_deg", "max |alpha - alpha_r| [deg]", "{:.3f}"),
    ("theta_err_max_deg", "max |theta - theta_r| [deg]", "{:.3f}"),
    (
        "alpha_err_own_trim_max_deg",
        "max |alpha - own trim alpha_r,p| [deg]",
        "{:.3f}",
    ),
    (
        "theta_err_own_trim_max_deg",
        "max |theta - own trim theta_r,p| [deg]",
        "{:.3f}",
    ),
    ("estimate_err_h_rms_ft", "state estimate: RMS error of h, t >= 10 s [ft]", "{:.2f}"),
    ("estimate_err_V_rms_fps", "state estimate: RMS error of V, t >= 10 s [ft/s]", "{:.3f}"),
    ("estimate_err_alpha_max_deg", "state estimate: max |alpha error|, t >= 10 s [deg]",
     "{:.4f}"),
    ("estimate_err_theta_max_deg", "state estimate: max |theta error|, t >= 10 s [deg]",
     "{:.4f}"),
    ("estimate_err_h_outside_3sigma_pct", "state estimate: steps with |h error| beyond the "
     "filter's 3 sigma, t >= 10 s [%]", "{:.2f}"),
    ("estimate_err_outside_3sigma_max_pct", "state estimate: the same, largest over h, V, "
     "alpha, theta, q [%]", "{:.2f}"),
    ("eta_1_dev_peak", "peak |eta_1 - eta_1,r|", "{:.4f}"),
    ("eta_2_dev_peak", "peak |eta_2 - eta_2,r|", "{:.4f}"),
    ("t_fault_s", "fault onset [s]", "{:.2f}"),
    ("eta_1_dot_rms_after_fault", "RMS eta_1_dot after fault [1/s]", "{:.5f}"),
    ("eta_2_dot_rms_after_fault", "RMS eta_2_dot after fault [1/s]", "{:.5f}"),
    ("Phi_min", "Phi min", "{:.4f}"),
    ("Phi_max", "Phi max", "{:.4f}"),
    ("delta_e_min_deg", "delta_e min [deg]", "{:.3f}"),
    ("delta_e_max_deg", "delta_e max [deg]", "{:.3f}"),
    ("input_limit_violations", "steps with a command (before the fault injector) beyond limits",
     "{}"),
    ("input_rate_violations", "steps with a command beyond the servos' rate limits", "{}"),
    ("delta_e_rate_max_degps", "max |d delta_e / dt| of the command (before the fault "
     "injector), step to step [deg/s]", "{:.1f}"),
    ("delta_e_actuator_rate_max_degps", "max |d delta_e / dt| of the actuator position, "
     "step to step [deg/s]", "{:.1f}"),
    ("delta_e_servo_rate_peak_degps", "max |d delta_e / dt| of the servo within a step "
     "(its rate state, which its rate limit bounds) [deg/s]", "{:.1f}"),
    ("tube_fraction_inside", "fraction of steps with e in Z", "{:.4f}"),
    ("tube_level_max", "max e' N^-1 e", "{:.4f}"),
    ("tube_error_h_max_ft", "max |e_h| (altitude part of the tube error) [ft]", "{:.3f}"),
    ("rmpc_lmi_failed", "RMPC steps outside its largest ellipsoid", "{}"),
    ("nominal_alpha_dev_max_deg", "max nominal |alpha - trim at its (h, V)| [deg]", "{:.3f}"),
    ("nominal_theta_dev_max_deg", "max nominal |theta - trim at its (h, V)| [deg]", "{:.3f}"),
    ("nominal_q_dev_max_degps", "max nominal |q| [deg/s]", "{:.3f}"),
    ("nominal_eta_1_dev_max", "max nominal |eta_1 - trim at its (h, V)|", "{:.4f}"),
    ("nominal_eta_2_dev_max", "max nominal |eta_2 - trim at its (h, V)|", "{:.4f}"),
    ("nominal_h_min_ft", "nominal h min [ft]", "{:.1f}"),
    ("nominal_h_max_ft", "nominal h max [ft]", "{:.1f}"),
    ("nominal_V_min_fps", "nominal V min [ft/s]", "{:.2f}"),
    ("nominal_V_max_fps", "nominal V max [ft/s]", "{:.2f}"),
    ("nominal_qp_solves", "nominal MPC QPs accepted", "{}"),
    ("nominal_qp_fallback", "nominal steps on the shifted plan (QP rejected)", "{}"),
    ("nominal_qp_terminal", "nominal steps on the terminal law", "{}"),
    ("nominal_qp_recovered", "nominal re-plans by the recovery QP", "{}"),
)

#: Component names and units of the state vectors (design-model order, ECM last).
STATE_COMPONENTS = (
    ("h", "ft"),
    ("V", "ft/s"),
    ("alpha", "rad"),
    ("theta", "rad"),
    ("q", "rad/s"),
    ("eta_1", "-"),
    ("eta_1_dot", "1/s"),
    ("eta_2", "-"),
    ("eta_2_dot", "1/s"),
    ("x_q1", "-"),
    ("x_q2", "-"),
)
INPUT_COMPONENTS = (("Phi", "-"), ("delta_e", "rad"))
#: Components of each array field of the loop messages.
ARRAY_COMPONENTS = {
    "x_r": STATE_COMPONENTS,
    "x_n": STATE_COMPONENTS,
    "e": STATE_COMPONENTS,
    "u_r": INPUT_COMPONENTS,
    "u_n": INPUT_COMPONENTS,
    "x_q": (("x_q1", "-"), ("x_q2", "-")),
    "sigma": STATE_COMPONENTS[:9],
}

_FIELD = re.compile(r"^\s*([\w/]+(?:\[\])?)\s+(\w+)\s*(?:#\s*(.*))?$")
_UNIT = re.compile(r"\[([^\]]+)\]\s*(?:\(.*\))?\s*$")


#: Rows whose values are over the whole run when the run holds no fault.
AFTER_FAULT = ("eta_1_dot_rms_after_fault", "eta_2_dot_rms_after_fault")


def _no_fault(m: dict) -> bool:
    """The run's metrics say it holds no fault (`t_fault_s` NaN; unknown: False)."""
    v = m.get("t_fault_s")
    return isinstance(v, float) and math.isnan(v)


#: What a NaN of a row means, in the words of the README's results table.
NAN_WORDS = {
    "t_fault_s": "none in the run",
    "settling_time_h_s": "never",
    "settling_time_V_s": "never",
    "settling_after_command_s": "never",
    "settling_after_fault_s": "never, or no fault after the command",
    "h_err_rms_after_settle_ft": "never settled",
    "V_err_rms_after_settle_fps": "never settled",
    "tube_fraction_inside": "no tube",
    "tube_level_max": "no tube",
    "tube_error_h_max_ft": "no tube",
    "input_rate_violations": "no servos",
}


def format_metrics(table: dict[str, dict]) -> str:
    """Metrics of several runs as a text table, one column per run.

    Parameters
    ----------
    table : dict[str, dict]
        Column name -> metrics dict (`fahv.runs.metrics.metrics`); a missing key or
        None prints as `-`.

    Notes
    -----
    The "after fault" rows of a run without a fault within it are over the whole run:
    their label says so when no column has a fault, a `*` marks such a cell
    otherwise. A NaN prints as what it means (`NAN_WORDS`: a settling time as
    `never`, a tube row as `no tube`, a fault onset as `none in the run`).
    """
    names = list(table)
    none = [n for n in names if _no_fault(table[n])]
    rows = []
    for key, label, fmt in METRIC_ROWS:
        if all(table[n].get(key) is None for n in names):
            continue
        if key in AFTER_FAULT and len(none) == len(names):
            label = label.replace("after fault", "over the run (no fault in it)")
        cells = []
        for n in names:
            v = table[n].get(key)
            if isinstance(v, float) and math.isnan(v) and key in NAN_WORDS:
                cells.append(NAN_WORDS[key])
            elif v is None:
                cells.append("-")
            else:
                star = "*" if key in AFTER_FAULT and n in none and len(none) < len(names) else ""
                cells.append(fmt.format(v) + star)
        rows.append((label, cells))
    lw = max([len("metric")] + [len(label) for label, _ in rows])
    width = max(12, *(len(n) for n in names), *(len(c) for _, cs in rows for c in cs))
    lines = [f"{'metric':<{lw}} " + " ".join(f"{n:>{width}}" for n in names)]
    lines += [f"{label:<{lw}} " + " ".join(f"{c:>{width}}" for c in cells) for label, cells in rows]
    if 0 < len(none) < len(names):
        lines.append("* no fault within this run: over the whole run")
    return "\n".join(lines)


def field_units(msgtype: str) -> dict[str, tuple[str, str]]:
    """Field -> (unit, description) of a loop message type, from its .msg comments.

    Parameters
    ----------
    msgtype : str
        `hsv_interfaces/msg/<Name>` or `rosgraph_msgs/msg/Clock`.

    Raises
    ------
    RunError
        If the definition file of an `hsv_interfaces` type is missing.
    """
    if msgtype == "rosgraph_msgs/msg/Clock":
        return {"t": ("s", "simulated time t_k")}
    path = MSG_DIR / f"{msgtype.rsplit('/', 1)[1]}.msg"
    try:
        text = path.read_text()
    except OSError as exc:
        raise RunError(f"message definition {path} is unreadable: {exc}") from None
    out = {}
    for line in text.splitlines():
        m = _FIELD.match(line)
        if not m or line.lstrip().startswith("#"):
            continue
        desc = (m.group(3) or "").strip()
        u = _UNIT.search(desc)
        out[m.group(2)] = (u.group(1) if u else "-", desc)
    return out


def topic_table(rec: Recording, topic: str) -> tuple[dict, dict]:
    """Columns of one loop topic of a run, one row per message in file order.

    Returns
    -------
    columns : dict[str, ndarray or list]
        Column name -> values (float64/int64/bool arrays, lists of str).
    meta : dict[str, tuple[str, str]]
        Column name -> (unit, description).

    Raises
    ------
    RunError
        If `topic` is not a loop topic.
    """
    if topic not in TOPICS:
        raise RunError(f"{topic} is not a loop topic: {list(TOPICS)}")
    msgs = rec.records.get(topic, [])
    units = field_units(TOPICS[topic])
    if topic == "/clock":
        t = np.array([m["clock"]["sec"] + 1e-9 * m["clock"]["nanosec"] for m in msgs], float)
        return {"t": t}, {"t": units["t"]}
    names = list(msgs[0]) if msgs else list(units)
    cols, meta = {}, {}
    for name in names:
        unit, desc = units.get(name, ("", ""))
        values = [m.get(name) for m in msgs]
        if name in ARRAY_COMPONENTS or (values and isinstance(values[0], np.ndarray)):
            comps = ARRAY_COMPONENTS.get(name, ())
            width = max((len(v) for v in values), default=0)
            for i in range(width):
                cname, cunit = comps[i] if i < len(comps) else (str(i), unit)
                col = np.full(len(values), math.nan)
                for j, v in enumerate(values):
                    if i < len(v):
                        col[j] = v[i]
                cols[f"{name}.{cname}"] = col
                meta[f"{name}.{cname}"] = (cunit, desc)
            continue
        if values and isinstance(values[0], str):
            cols[name] = [str(v) for v in values]
        elif values and isinstance(values[0], bool | np.bool_):
            cols[name] = np.array(values, dtype=bool)
        elif values and isinstance(values[0], int | np.integer):
            cols[name] = np.array(values, dtype=np.int64)
        else:
            cols[name] = np.array(values, dtype=float)
        meta[name] = (unit, desc)
    return cols, meta


def table_name(topic: str) -> str:
    """File stem of a topic's table: `/hsv/state` -> `hsv_state`."""
    return topic.strip("/").replace("/", "_")


def export_run(rec: Recording, out_dir: str | Path, fmt: str = "csv") -> list[Path]:
    """Write one table per loop topic, a column dictionary and the run metadata.

    Parameters
    ----------
    rec : fahv.runs.bag.Recording
    out_dir : path
        Folder to write (created).
    fmt : {"csv", "parquet"}
        CSV (header row of column names) or Parquet (each field carries its unit
        and description as field metadata).

    Returns
    -------
    list of Path
        Files written: `<topic>.csv|parquet` per loop topic present,
        `columns.csv` (topic, column, unit, description) and `run.json`
        (metadata, topics, schemas).

    Raises
    ------
    RunError
        On an unknown format or when the run holds no loop-topic message.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    if fmt not in ("csv", "parquet"):
        raise RunError(f"unknown export format '{fmt}': csv or parquet")
    present = [t for t in TOPICS if rec.records.get(t)]
    if not present:
        raise RunError(
            f"{rec.path}: no message on any loop topic {list(TOPICS)}: nothing to export"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written, rows = [], []
    for topic in present:
        cols, meta = topic_table(rec, topic)
        fields, arrays = [], []
        for name, values in cols.items():
            arr = pa.array(values)
            unit, desc = meta[name]
            fields.append(pa.field(name, arr.type, metadata={"unit": unit, "description": desc}))
            arrays.append(arr)
            rows.append({"topic": topic, "column": name, "unit": unit, "description": desc})
        table = pa.Table.from_arrays(
            arrays, schema=pa.schema(fields, metadata={"topic": topic, "type": TOPICS[topic]})
        )
        path = out / f"{table_name(topic)}.{fmt}"
        if fmt == "parquet":
            pq.write_table(table, path)
        else:
            pacsv.write_csv(table, path)
        written.append(path)
    dictionary = out / "columns.csv"
    pacsv.write_csv(pa.Table.from_pylist(rows), dictionary)
    info = out / "run.json"
    info.write_text(
        json.dumps(
            {
                "source": str(rec.path),
                "truncated": rec.truncated,
                "metadata": rec.metadata,
                "topics": rec.topics,
                "schemas": rec.schemas,
            },
            indent=1,
        )
    )
    return [*written, dictionary, info]


def summarize(rec: Recording, limits) -> dict:
    """Everything `fahv inspect` reports about a run, as plain JSON-able data.

    Returns
    -------
    dict
        `file`, `size_bytes`, `complete` (footer read), `metadata`,
        `topics` (type, count, first_s, last_s, rate_hz in simulated time,
        `loop` whether it is one of ours), `sim_time_s` [first, last],
        `recorder_anomalies` (out-of-order arrivals counted by the SIL recorder),
        `step_anomalies` (duplicate / out-of-order / missing step indices per
        loop topic, from the messages), `metrics` (or None) and `metrics_note`,
        `latency` (per-hop wall-clock latency of a SIL run,
        `fahv.runs.latency.hop_latencies`; None without recorded timestamps).
    """
    topics = {}
    for name, t in rec.topics.items():
        first = None if t["first_ns"] is None else t["first_ns"] * 1e-9
        last = None if t["last_ns"] is None else t["last_ns"] * 1e-9
        rate = (t["count"] - 1) / (last - first) if t["count"] > 1 and last > first else None
        topics[name] = {
            "type": t["type"],
            "count": t["count"],
            "first_s": first,
            "last_s": last,
            "rate_hz": rate,
            "loop": name in TOPICS and t["type"] == TOPICS[name],
        }
    span = rec.sim_span
    m, note = run_metrics(rec, limits)
    judged = run_judgements(rec.metadata, m)
    recorder = {
        k.removeprefix("anomalies").replace(".", "/"): int(v)
        for k, v in rec.metadata.items()
        if k.startswith("anomalies") and v.lstrip("-").isdigit()
    }
    return {
        "file": str(rec.path),
        "size_bytes": rec.path.stat().st_size,
        "complete": not rec.truncated,
        "metadata": dict(rec.metadata),
        "topics": topics,
        "sim_time_s": None if math.isnan(span[0]) else [span[0], span[1]],
        "recorder_anomalies": recorder,
        "step_anomalies": {t: v for t, v in step_anomalies(rec).items() if rec.topics.get(t)},
        "metrics": m,
        "metrics_note": note,
        "requirements": None if judged is None else verdict_record(judged),
        "latency": run_latencies(rec.attachment(TIMESTAMPS_FILE), rec.params()),
    }


#: Metadata keys `fahv inspect` prints on their own line.
SUMMARY_KEYS = ("case", "variant", "source", "status", "coverage", "design_hash", "code_version",
                "fault")  # fmt: skip


def _fmt(v, spec: str = "{:g}") -> str:
    return "-" if v is None else spec.format(v)


def format_summary(s: dict, column: str | None = None) -> str:
    """Text report of `summarize` (the metrics table as `fahv sil` prints it).

    `column`: header of the metrics column (default: the run's variant).
    """
    md = s["metadata"]
    lines = [
        f"run           {s['file']} ({s['size_bytes'] / 1e6:.2f} MB, "
        f"{'complete' if s['complete'] else 'TRUNCATED: read up to the last complete chunk'})",
    ]
    for key in SUMMARY_KEYS:
        if key in md:
            lines.append(f"{key:<13} {md[key]}")
    verdict = Verdict.from_metadata(md)
    if verdict is not None:  # name, time, step, node and reason on one line
        lines.append(f"{'verdict':<13} {verdict.text()}")
    shown = (*SUMMARY_KEYS, *METADATA_KEYS)
    extra = sorted(k for k in md if k not in shown and not k.startswith("anomalies"))
    if extra:
        lines.append("metadata      " + ", ".join(f"{k}={md[k]}" for k in extra))
    span = s["sim_time_s"]
    lines.append(
        "sim time      " + ("no messages" if span is None else f"{span[0]:g} .. {span[1]:g} s")
    )
    lines.append("")
    width = max([len(t) for t in s["topics"]] + [5])
    lines.append(f"{'topic':<{width}}  {'type':<38} {'count':>7} {'rate [Hz]':>10}  loop")
    for name, t in s["topics"].items():
        lines.append(
            f"{name:<{width}}  {t['type']:<38} {t['count']:>7} "
            f"{_fmt(t['rate_hz'], '{:.2f}'):>10}  {'yes' if t['loop'] else 'no (not decoded)'}"
        )
    lines.append("")
    bad = {t: {k: n for k, n in v.items() if n} for t, v in s["step_anomalies"].items()}
    for t, n in s["recorder_anomalies"].items():
        bad.setdefault(t, {})["recorder out-of-order"] = n
    bad = {t: v for t, v in bad.items() if any(v.values())}
    if bad:
        lines.append("step anomalies:")
        lines += [
            f"  {t}: " + ", ".join(f"{k} {n}" for k, n in v.items() if n) for t, v in bad.items()
        ]
    else:
        lines.append("step anomalies: none (no duplicate, out-of-order or missing step)")
    lines.append("")
    if s["metrics"] is None:
        lines.append(f"metrics: {s['metrics_note']}")
    else:
        lines.append(f"metrics ({s['metrics_note']}):")
        lines.append(format_metrics({column or md.get("variant", "run"): s["metrics"]}))
        lines += ["", "requirements (limits recorded with the run):",
                  verdict_table(run_judgements(md, s["metrics"]))]
    if s.get("latency"):
        lines += ["", format_latencies(s["latency"])]
    return "\n".join(lines)


def compare(a: dict, b: dict, names: tuple[str, str]) -> dict:
    """Metric differences of two runs.

    Parameters
    ----------
    a, b : dict
        `summarize` of each run (metrics must exist).
    names : (str, str)
        Column names of the runs.

    Returns
    -------
    dict
        `table`: {name_a: metrics, name_b: metrics, "B - A": differences of the
        numeric metrics}; `metadata`: keys whose values differ, as (a, b).

    Raises
    ------
    RunError
        If a run has no metrics.
    """
    for s, n in ((a, names[0]), (b, names[1])):
        if s["metrics"] is None:
            raise RunError(f"{n}: {s['metrics_note']}")
    ma, mb = a["metrics"], b["metrics"]
    diff = {}
    for k in ma.keys() | mb.keys():
        va, vb = ma.get(k), mb.get(k)
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (va, vb))
        diff[k] = vb - va if numeric else None
        if k == "t_fault_s" and diff[k] is not None and math.isnan(diff[k]):
            diff[k] = None  # a run without fault: no difference of onsets
    keys = sorted(
        k
        for k in a["metadata"].keys() | b["metadata"].keys()
        if a["metadata"].get(k) != b["metadata"].get(k)
    )
    return {
        "table": {names[0]: ma, names[1]: mb, "B - A": diff},
        "metadata": {k: (a["metadata"].get(k), b["metadata"].get(k)) for k in keys},
    }
