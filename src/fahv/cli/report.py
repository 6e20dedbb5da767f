"""`fahv report RUN | CAMPAIGN_DIR`: one self-contained HTML page of a run or a campaign."""

from __future__ import annotations

from pathlib import Path


def cmd_report(args) -> int:
    """Write the page of a run (a run folder or .mcap) or a campaign folder; print its path."""
    target = Path(args.target)
    if target.is_dir() and (target / "results").is_dir():
        from fahv.campaign.report_page import write_campaign_page

        path = write_campaign_page(target, args.out)
    else:
        from fahv.runs.report_page import write_run_page

        path = write_run_page(target, args.out)
    print(f"report: {path}")
    return 0


def add_parsers(sub) -> None:
    """Add the `report` parser."""
    p = sub.add_parser(
        "report",
        help="one self-contained HTML page of a run (verdict, coverage, metadata, metrics, "
        "figures) or of a campaign folder (pass rates with bounds, worst runs, figures)",
    )
    p.add_argument("target", help="run folder or .mcap, or a campaign folder")
    p.add_argument("--out", default=None, help="the page (default RUN/report.html or "
                   "DIR/report/report.html)")  # fmt: skip
    p.set_defaults(func=cmd_report)
