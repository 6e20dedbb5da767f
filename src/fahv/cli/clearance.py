"""`fahv clearance`: the worst case of each requirement inside a campaign's dispersions.

    fahv clearance CAMPAIGN.yaml [--requirement R ...] [--budget N] [--monte-carlo]
                   [--certificate] [--noise-seeds K] [--optimizer cma|de] [--population P]
                   [--seed S] [--runs N] [--duration S] [--out DIR] [--scheduler ADDRESS]
                   [--workers N]

With `--certificate` the search stays inside what the design certifies and a miss there
is reported as a certificate failure (exit status 1), with the run that reproduces it.
Prints, per requirement, the smallest margin the search found (limit - value: negative
where the requirement fails), the simulations it spent and, with `--monte-carlo`, the
worst of the campaign's first draws of the same budget; writes the folder that
`fahv.clearance.run` describes. `fahv campaign rerun DIR INDEX [--sil]` flies any of its
runs again (the worst cases' indices are in its `campaign.json`).

    fahv clearance report DIR [--against CAMPAIGN_DIR]

writes the folder's table, `clearance.md` and figures again; `--against` adds the worst
margins of a finished campaign of the same campaign file (e.g. its 1000 runs).

    fahv clearance sweep CAMPAIGN.yaml [--input NAME ...] [--points P] [--requirement R ...]
                         [--against CAMPAIGN_DIR] [--out DIR]

sweeps each dispersed value one at a time over its range, the others at the centre of
theirs (`fahv.clearance.sweep`), and prints per requirement the inputs by the margin's
spread; `--against` sets each beside its PAWN index over a finished campaign, the check
of the campaign report's attribution. `fahv clearance sweep report DIR [--against ...]`
writes its `sweep.md` and figures again.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

from fahv.campaign import store
from fahv.campaign.robustness import SEARCHABLE
from fahv.campaign.spec import load_campaign
from fahv.clearance.report import report, summary_lines
from fahv.clearance.run import clear
from fahv.clearance.sweep import sweep
from fahv.clearance.sweep_report import report as sweep_report
from fahv.errors import CampaignError
from fahv.sil.workspace import ROOT


def cmd_clearance(args) -> int:
    """Run the search of `args.campaign` (or `report DIR`); print its table and the folder."""
    if args.campaign == "report":
        if len(args.rest) != 1:
            raise CampaignError("usage: fahv clearance report DIR [--against CAMPAIGN_DIR]")
        man = report(args.rest[0], args.against)
        print("\n".join(summary_lines(man)))
        print(f"report: {Path(args.rest[0]) / 'clearance.md'}")
        return 0
    if args.campaign == "sweep":
        return _sweep(args)
    if args.rest:
        raise CampaignError(f"unexpected arguments {args.rest} after the campaign file")
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    campaign = load_campaign(args.campaign, runs=args.runs, duration=args.duration)
    requirements = args.requirement or (["tube", "attitude"] if args.certificate
                                        else ["attitude", "settling"])  # fmt: skip
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else ROOT / "campaigns" / f"{campaign.name}_clearance_{stamp}"

    def err(line: str) -> None:
        print(line, file=sys.stderr)

    err(f"clearance of {campaign.name}: {', '.join(requirements)}, {args.budget} runs each "
        f"of {campaign.duration:g} s, into {out}")  # fmt: skip
    clear(campaign, requirements, args.budget, out, args.scheduler, args.workers, args.seed,
          args.noise_seeds, args.monte_carlo, args.optimizer, args.population,
          args.certificate, log=err)  # fmt: skip
    if args.against:
        report(out, args.against)
    print("\n".join(summary_lines(store.read_manifest(out))))
    print(f"clearance folder: {out}")
    failed = any(e.get("certificate", {}).get("failures") for e in
                 store.read_manifest(out)["requirements"])  # fmt: skip
    return 1 if failed else 0


def _sweep(args) -> int:
    """`fahv clearance sweep CAMPAIGN.yaml` (or `sweep report DIR`): run or report a sweep."""
    if args.rest[:1] == ["report"]:
        if len(args.rest) != 2:
            raise CampaignError("usage: fahv clearance sweep report DIR [--against CAMPAIGN_DIR]")
        print("\n".join(sweep_report(args.rest[1], args.against)))
        return 0
    if len(args.rest) != 1:
        raise CampaignError("usage: fahv clearance sweep CAMPAIGN.yaml [--input NAME ...] "
                            "[--points P] [--requirement R ...] [--against CAMPAIGN_DIR]")
    campaign = load_campaign(args.rest[0], duration=args.duration)
    requirements = args.requirement or ["attitude", "settling"]
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else ROOT / "campaigns" / f"{campaign.name}_sweep_{stamp}"
    print(f"one-at-a-time sweeps of {campaign.name}: {', '.join(requirements)}, runs of "
          f"{campaign.duration:g} s, into {out}", file=sys.stderr)  # fmt: skip
    sweep(campaign, requirements, out, args.input, args.points, args.scheduler, args.workers,
          log=lambda line: print(line, file=sys.stderr))  # fmt: skip
    print("\n".join(sweep_report(out, args.against)))
    print(f"sweep folder: {out}")
    return 0


def add_parsers(sub) -> None:
    """Add the `clearance` subcommand."""
    p = sub.add_parser(
        "clearance",
        help="search a campaign's dispersions for each requirement's worst case "
        "(CMA-ES or differential evolution, batches on Dask)",
        description=__doc__.split("\n\n")[0],
    )
    p.add_argument("campaign", help="campaign file (its scenario, dispersions, limits), "
                   "'report' followed by a clearance folder, or 'sweep' followed by a "
                   "campaign file (or by 'report' and a sweep folder)")
    p.add_argument("rest", nargs="*", help="DIR (report); CAMPAIGN.yaml or report DIR (sweep)")
    p.add_argument("--against", help="a finished campaign folder of the same campaign file: "
                   "its worst margins beside the search's")
    p.add_argument("--requirement", action="append", choices=tuple(SEARCHABLE),
                   help="requirement to search (repeat; default attitude and settling)")
    p.add_argument("--budget", type=int, default=200,
                   help="simulations per requirement (default 200)")
    p.add_argument("--monte-carlo", action="store_true",
                   help="also run the campaign's first BUDGET draws and show their worst")
    p.add_argument("--noise-seeds", type=int, default=0,
                   help="search the sensor noise among the campaign's first K runs' seeds "
                   "(default 0: held at run 0's)")
    p.add_argument("--population", type=int,
                   help="points per generation (default: CMA-ES a 40th of the budget, 10-40; "
                   "differential evolution a tenth, 5 to 10 per variable)")
    p.add_argument("--certificate", action="store_true",
                   help="check the design's certificate: search only the runs it certifies "
                   "(losses up to its certified onset loss); a miss there is a certificate "
                   "failure, exit status 1 (default requirements: tube and attitude)")
    p.add_argument("--optimizer", choices=("cma", "de"), default="cma",
                   help="CMA-ES (default) or differential evolution")
    p.add_argument("--seed", type=int, default=0, help="seed of the search (default 0)")
    p.add_argument("--input", action="append",
                   help="sweep: a dispersed value to sweep (repeat; default every one, e.g. "
                   "s.m, fault.loss)")
    p.add_argument("--points", type=int, default=9,
                   help="sweep: values of each input over its range (default 9)")
    p.add_argument("--runs", type=int, help="the campaign's draws (the Monte Carlo's pool)")
    p.add_argument("--duration", type=float, help="simulated time of each run [s]")
    p.add_argument("--out", help="folder (default campaigns/<name>_clearance_<time>)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler")
    p.add_argument("--workers", type=int, help="local Dask workers (default: the cores)")
    p.set_defaults(func=cmd_clearance)
