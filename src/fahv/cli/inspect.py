"""``fahv inspect``, ``export``, ``compare``, ``plot``: tools on recorded runs."""

from __future__ import annotations

from pathlib import Path

from fahv.cli.common import read_run_warned, to_json
from fahv.errors import FahvError
from fahv.runs.bag import bag_paths, run_result_of
from fahv.runs.plots import GROUPS, plot_group, run_labels
from fahv.runs.tools import (
    compare,
    export_run,
    format_metrics,
    format_summary,
    run_vehicle,
    summarize,
)


def _with_limits(rec):
    """(recording, actuator limits of the vehicle the run was made with)."""
    return rec, run_vehicle(rec).limits


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
    """Paper-style figures of one or several recorded runs, overlaid."""
    recs, results = [], []
    for path in args.runs:
        rec = read_run_warned(path)
        run = run_result_of(rec)
        if run.t.size == 0:
            raise FahvError(f"{path}: no complete step of the loop topics to plot")
        recs.append(rec)
        results.append(run)
    labels = run_labels(args.runs, [r.metadata.get("variant") for r in recs])
    runs = list(zip(labels, results, strict=True))
    out = Path(args.out)
    for group in GROUPS:
        if group == "flexible_rates":
            continue
        print(plot_group(group, runs, out / f"{group}.{args.format}"))
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
    p = sub.add_parser("plot", help="paper-style figures of recorded runs, overlaid")
    p.add_argument("runs", nargs="+", help="run folders or .mcap files")
    p.add_argument("--out", default="figures", help="output folder")
    p.add_argument("--format", choices=("png", "pdf"), default="png")
    p.set_defaults(func=cmd_plot)
