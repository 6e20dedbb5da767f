"""`fahv campaign`: Monte Carlo campaigns on Dask, their report, and reruns of one run.

    fahv campaign CAMPAIGN.yaml [--scenario S] [--runs N] [--duration S] [--out DIR]
                  [--scheduler ADDRESS] [--workers N] [--resume] [--dashboard [ADDRESS]]
    fahv campaign report DIR [--no-figures] [--write FILE]
    fahv campaign compare DIR_A DIR_B [--variant V] [--variant-b W] [--write FILE]
    fahv campaign rerun DIR INDEX [--variant V] [--sil] [--out BAGS]
    fahv campaign rerun RUN [--sil] [--out BAGS]

`rerun RUN` reruns any recorded run (folder or .mcap) from the parameter file its
run file holds, and compares the metrics with the recorded run's.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from fahv.campaign.compare import compare_campaigns
from fahv.campaign.engine import run_campaign
from fahv.campaign.report import make_report
from fahv.campaign.rerun import rerun, rerun_file
from fahv.campaign.spec import load_campaign
from fahv.errors import CampaignError
from fahv.sil.workspace import ROOT

#: Exit status of an interrupted campaign (as a shell reports SIGINT).
INTERRUPTED = 130


def _err(line: str) -> None:
    print(line, file=sys.stderr)


def cmd_run(args) -> int:
    """Run (or `--resume`) a campaign file; print the report's summary and path at the end."""
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    campaign = load_campaign(args.target, scenario=args.scenario, runs=args.runs,
                             duration=args.duration)  # fmt: skip
    for line in campaign.warnings:
        _err(f"warning: {line}")
    out = Path(args.out) if args.out else ROOT / "campaigns" / _folder_name(campaign, args)
    _err(f"campaign {campaign.name}: {campaign.data['runs']} draws x "
         f"{len(campaign.data['variants'])} variant(s), runs of {_run_seconds(campaign):g} s, "
         f"into {out}")  # fmt: skip
    res = run_campaign(
        campaign,
        out,
        scheduler=args.scheduler,
        workers=args.workers,
        resume=args.resume,
        progress=not args.quiet,
        log=_err,
        dashboard=args.dashboard,
    )
    _err(
        f"campaign {campaign.name}: {res.new} runs this session ({res.failed} failed), "
        f"{res.before} before, {res.missing} missing; wall time {res.wall_s:.1f} s; "
        f"results in {out}/results"
    )
    if res.errors:
        lost = sum("scheduler-connection-lost" in e for e in res.errors)
        if lost:
            _err(f"lost the Dask scheduler: {lost} batches did not finish")
        _err(f"{len(res.errors)} tasks failed, their runs stay missing; first: {res.errors[0]}")
        _err(f"complete it later with\n  fahv campaign {args.target} --out {out} --resume")
    if res.interrupted:
        _err(f"interrupted: every finished batch is kept; complete it with\n"
             f"  fahv campaign {args.target} --out {out} --resume")  # fmt: skip
        return INTERRUPTED
    if not args.no_report:
        rep = make_report(out, figures=not args.no_figures)
        print(rep.summary())
        print(f"report: {out / 'report' / 'report.md'} ({_contents(args)})")
    return 0 if res.missing == 0 else 1


def _contents(args) -> str:
    """What the written report holds (its figures unless --no-figures)."""
    return "pass rates, worst runs" + ("" if args.no_figures else ", figures")


def _folder_name(campaign, args) -> str:
    """The campaign's default folder: its name, with the size when --runs/--duration set it."""
    size = []
    if args.runs is not None:
        size.append(f"{args.runs}runs")
    if args.duration is not None:
        size.append(f"{args.duration:g}s")
    return "-".join([campaign.name, *size])


def _run_seconds(campaign) -> float:
    """Simulated time of each run [s]: the campaign's, or its scenario's (duration 0)."""
    return campaign.data["duration"] or campaign.run_spec["duration"]


def cmd_report(args) -> int:
    """Report of a campaign folder written (tables, figures); its summary printed."""
    rep = make_report(args.dir, figures=not args.no_figures)
    print(rep.summary())
    print(f"report: {Path(args.dir) / 'report' / 'report.md'} ({_contents(args)})")
    if args.write:  # its head, the evidence a results page shows
        Path(args.write).parent.mkdir(parents=True, exist_ok=True)
        Path(args.write).write_text(rep.overview)
        print(f"overview written to {args.write}")
    return 0


def cmd_compare(args) -> int:
    """Two campaign folders of the same draws compared run by run (B - A), printed."""
    lines, _ = compare_campaigns(args.dir_a, args.dir_b, args.variant, args.variant_b)
    text = "\n".join(lines)
    print(text)
    if args.write:  # evidence a results page shows (docs/hooks/generated.py, `evidence:`)
        Path(args.write).parent.mkdir(parents=True, exist_ok=True)
        Path(args.write).write_text(text + "\n")
        print(f"comparison written to {args.write}")
    return 0


def cmd_rerun(args) -> int:
    """One run of a campaign (or any recorded run) again, recorded (MCAP); compares metrics."""
    bags = args.out or ROOT / "bags"
    if args.index is None:
        r = rerun_file(args.dir, sil=args.sil, bags=bags, quiet=args.quiet)
        what = "the recorded run's"
    else:
        r = rerun(args.dir, args.index, args.variant, sil=args.sil, bags=bags, quiet=args.quiet)
        what = "the campaign's row"
    if r.bag is not None and not args.sil:  # the SIL runner says where it wrote the run
        print(f"run written to {r.bag}")
    if r.error:
        print(f"the run failed: {r.error}")
    if r.recorded is None:
        print("the campaign's dataset does not hold this run (yet): nothing to compare")
        return 0
    if r.identical:
        print(f"metrics identical to {what} ({len(r.metrics)} metrics)")
        return 0
    print(f"metrics differ from {what}:")
    for k, (a, b) in r.differences.items():
        print(f"  {k}: campaign {a!r}, rerun {b!r}")
    return 1


def _dispatch(args) -> int:
    """`campaign FILE` / `report DIR` / `compare DIR_A DIR_B` / `rerun DIR INDEX`."""
    rest = args.rest
    if args.target == "report":
        if len(rest) != 1:
            raise CampaignError("usage: fahv campaign report DIR")
        args.dir = rest[0]
        return cmd_report(args)
    if args.target == "compare":
        if len(rest) != 2:
            raise CampaignError("usage: fahv campaign compare DIR_A DIR_B")
        args.dir_a, args.dir_b = rest
        return cmd_compare(args)
    if args.target == "rerun":
        if len(rest) == 1:
            args.dir, args.index = rest[0], None
            return cmd_rerun(args)
        if len(rest) != 2 or not rest[1].isdigit():
            raise CampaignError(
                "usage: fahv campaign rerun DIR INDEX (a run index), or fahv campaign rerun RUN"
            )
        args.dir, args.index = rest[0], int(rest[1])
        return cmd_rerun(args)
    if rest:
        raise CampaignError(f"unexpected arguments {rest} after the campaign file")
    return cmd_run(args)


def add_parsers(sub) -> None:
    """Add the `campaign` parser."""
    p = sub.add_parser(
        "campaign",
        help="Monte Carlo campaign on Dask (campaign FILE | report DIR | compare DIR_A DIR_B | "
        "rerun DIR INDEX)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=__doc__,
    )
    p.add_argument("target", help="campaign file, or 'report' / 'compare' / 'rerun'")
    p.add_argument("rest", nargs="*", help="DIR (report), DIR_A DIR_B (compare), DIR INDEX or "
                   "RUN (rerun)")  # fmt: skip
    p.add_argument(
        "--out",
        default=None,
        help="campaign folder (default campaigns/NAME); for rerun: bags folder",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        help="address of an existing Dask scheduler (default: a LocalCluster)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="LocalCluster worker processes (default: the cores)",
    )
    p.add_argument(
        "--scenario",
        default=None,
        help="run the campaign's dispersions around this scenario (file or name) "
        "instead of the one the campaign file names",
    )
    p.add_argument("--runs", type=int, default=None, help="run only the first N draws "
                   "(default: the file's runs; the default folder gets the size)")
    p.add_argument("--duration", type=float, default=None, help="simulated time of each "
                   "run [s] (default: the file's)")
    p.add_argument("--resume", action="store_true", help="complete the missing runs of DIR")
    p.add_argument(
        "--dashboard",
        nargs="?",
        const=":8787",
        default=None,
        metavar="ADDRESS",
        help="serve the LocalCluster's Dask dashboard (default address :8787)",
    )
    p.add_argument("--no-report", action="store_true", help="no report at the end")
    p.add_argument("--no-figures", action="store_true", help="report: tables only")
    p.add_argument("--variant", default=None, help="rerun, compare: variant (default the "
                   "first)")  # fmt: skip
    p.add_argument("--variant-b", default=None, help="compare: the variant of DIR_B, when "
                   "another than --variant's")  # fmt: skip
    p.add_argument("--write", default=None, metavar="FILE", help="report: also write the "
                   "report's head (dataset, wall times, pass rates) to FILE; compare: the "
                   "comparison; Markdown, e.g. the evidence a results page shows")
    p.add_argument("--sil", action="store_true", help="rerun through the ROS 2 node graph")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_dispatch)  # fmt: skip
