"""`fahv inspect`, `export`, `compare`, `plot`: tools on recorded runs."""

from __future__ import annotations

from pathlib import Path

from fahv.cli.common import read_run_warned, to_json
from fahv.runs.bag import bag_paths
from fahv.runs.figures import run_figures
from fahv.runs.judged import run_limits
from fahv.runs.plots import save_figure
from fahv.runs.plots_context import clip_runs, plotted_run, run_labels
from fahv.runs.tools import (
    compare,
    export_run,
    format_metrics,
    format_summary,
    summarize,
)


def _with_limits(rec):
    """(recording, actuator limits of the vehicle the run was made with)."""
    return rec, run_limits(rec)


def cmd_inspect(args) -> int:
    """Topics, metadata, step anomalies and metrics of a recorded run."""
    s = summarize(*_with_limits(read_run_warned(args.run)))
    print(to_json(s) if args.json else format_summary(s))
    return 0


def cmd_export(args) -> int:
    """One table per loop topic (CSV or Parquet) with a column dictionary."""
    folder, _ = bag_paths(args.run)
    out = Path(args.out) if args.out else folder / f"export_{args.format}"
    for path in export_run(read_run_warned(args.run), out, args.format):
        print(path)
    return 0


def cmd_compare(args) -> int:
    """Metrics of two runs side by side with their differences."""
    a, b = (summarize(*_with_limits(read_run_warned(r))) for r in (args.a, args.b))
    names = tuple(
        f"{tag}: {s['metadata'].get('variant', bag_paths(r)[0].name)}"
        f" ({s['metadata'].get('source', '?')})"
        for tag, s, r in (("A", a, args.a), ("B", b, args.b))
    )
    c = compare(a, b, names)
    if args.json:
        print(to_json(c))
        return 0
    print(f"A = {a['file']}\nB = {b['file']}")
    for k, (va, vb) in c["metadata"].items():
        print(f"  {k}: A {va!s} | B {vb!s}")
    print(format_metrics(c["table"]))
    return 0


def cmd_plot(args) -> int:
    """Figures of one or several recorded runs, overlaid, over a time window."""
    recs = [read_run_warned(path) for path in args.runs]
    labels = run_labels(args.runs, [r.metadata for r in recs])
    runs = clip_runs([plotted_run(r, lab) for r, lab in zip(recs, labels, strict=True)],
                     args.t0, args.t1)  # fmt: skip
    whole = args.t0 is None and args.t1 is None  # a chosen window is the spectra's
    for name, fig in run_figures(runs, whole):
        print(save_figure(fig, Path(args.out) / f"{name}.{args.format}"))
    return 0


def add_parsers(sub) -> None:
    """Add the parsers of this command group."""
    p = sub.add_parser("inspect", help="topics, metadata, step anomalies and metrics of a run")
    p.add_argument("run", help="run folder or .mcap file")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=cmd_inspect)
    p = sub.add_parser("export", help="one table per topic (CSV or Parquet) with units")
    p.add_argument("run", help="run folder or .mcap file")
    p.add_argument("--format", choices=("csv", "parquet"), default="csv")
    p.add_argument("--out", default=None, help="output folder (default <run>/export_<format>)")
    p.set_defaults(func=cmd_export)
    p = sub.add_parser("compare", help="metrics of two runs side by side, with differences")
    p.add_argument("a", help="run A (folder or .mcap)")
    p.add_argument("b", help="run B (folder or .mcap)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_compare)
    p = sub.add_parser(
        "plot",
        help="figures of recorded runs, overlaid: states, tracking errors with the "
        "requirement bands, inputs with their limits, input rates, tube level, spectra",
        description="Figures of recorded runs, overlaid, written to --out: trajectory, "
        "attitude, flexible (the states); errors (h - h_c, V - V_c, alpha - alpha_r, "
        "theta - theta_r with the requirement bands); inputs (with the actuator and the "
        "tightened limits); input_rates; tube (e' N^-1 e, boundary of Z at 1); spectra "
        "(Welch PSD of q, the notch output q' and eta_1_dot, notch and flexible modes "
        "marked). Legends name each run by scenario / variant from its metadata; a "
        "fault's onset is a vertical line on every figure over time.",
    )
    p.add_argument("runs", nargs="+", help="run folders or .mcap files")
    p.add_argument("--out", default="figures", help="output folder")
    p.add_argument("--format", choices=("png", "pdf"), default="png")
    p.add_argument(
        "--t0",
        type=float,
        default=None,
        help="start of the time window [s] (default: the run's start)",
    )
    p.add_argument("--t1", type=float, default=None,
                   help="end of the time window [s] (default: the run's end); with "
                   "--t0 or --t1 the spectra are over the window, else from the "
                   "step's settling to the end")  # fmt: skip
    p.set_defaults(func=cmd_plot)
