"""`fahv sil`: a scenario through the ROS 2 node graph in lockstep, recorded to MCAP.

Its coverage line, metrics and verdict table are printed as `fahv simulate` prints them
(`fahv.cli.run`); `--write-params FILE` only writes the run's parameter file and prints
the `ros2 run` commands that start the graph by hand.
"""

from __future__ import annotations

import functools
import sys
import warnings
from pathlib import Path

from fahv.certificate.verified import load_or_design
from fahv.cli.common import add_vehicle_option, to_json
from fahv.cli.run import (
    EXIT_VERDICT,
    add_check_option,
    add_design_options,
    add_live_option,
    exit_status,
    print_coverage,
    print_verdicts,
    verdict_line,
)
from fahv.errors import RunInterrupted
from fahv.loop.graph import COMPOSED, NODES, graph_nodes, loop_nodes
from fahv.loop.params import controller_node
from fahv.runs.bag import read_run, run_result_of
from fahv.runs.judged import run_judgements
from fahv.runs.metrics import metrics
from fahv.runs.tools import format_metrics
from fahv.sil.runner import run_coverage, run_name, run_sil, write_run_params
from fahv.sil.workspace import ROOT
from fahv.spec.plant_dispersion import rate_limit_factor
from fahv.spec.requirements import verdict_record
from fahv.spec.scenario import load_scenario
from fahv.verdict import Verdict


def add_parsers(sub) -> None:
    """Add the parser of `fahv sil`."""
    _add_sil_parser(sub)


def cmd_sil(args) -> int:
    """Run a case through the ROS 2 node graph, recorded to MCAP; metrics of the run."""
    variant = args.variant or load_scenario(args.case).run_spec["variants"][0]
    case, design, vehicle = load_or_design(
        args.case, args.design, args.vehicle, allow_uncertified=args.allow_uncertified,
        variants=[variant],
    )  # fmt: skip
    if args.write_params:
        return _write_params_only(args, design, variant)
    # with --json, stdout holds the JSON only; the status lines go to stderr
    status = functools.partial(print, file=sys.stderr if args.json else sys.stdout)
    res = run_sil(
        design,
        variant,
        args.duration,
        Path(args.out or ROOT / "bags"),
        args.watchdog,
        quiet=args.quiet,
        domain_id=args.domain_id,
        live_port=args.live,
        log=status,
        overrides=_plant_rate(args),
        compose=args.compose,
    )
    n_steps = int(round(res.simulated_s / case["Ts"]))
    if not res.bag.is_dir():
        if res.interrupted:
            raise RunInterrupted(0, n_steps, None)
        print(f"error: the run produced no recording ({res.bag})", file=sys.stderr)
        return 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = read_run(res.bag)
    run = run_result_of(rec)
    if res.interrupted:
        raise RunInterrupted(int(rec.metadata.get("steps_recorded", run.t.size)), n_steps, res.bag)
    ran_s = run.t.size * case["Ts"]  # what the graph simulated, not what was asked for
    rtf = f"{ran_s / res.wall_s:.2f}" if run.t.size and res.wall_s > 0 else "- (no step)"
    status(
        f"run {res.bag.name}: status {rec.metadata.get('status', '?')}, {run.t.size} of "
        f"{n_steps} steps, wall time {res.wall_s:.1f} s, real-time factor {rtf} (simulated "
        f"{ran_s:g} of {res.simulated_s:g} s)"
    )
    if rec.metadata.get("reason"):
        status(f"reason: {rec.metadata['reason']}")
    verdict = Verdict.from_metadata(rec.metadata)
    print_coverage(run_coverage(design, args.duration).describe(), args.json)
    judged = {}
    if run.t.size:
        limits = vehicle.limits.with_rate_factor(rate_limit_factor(design.case, rec.params()))
        table = {variant: metrics(run, limits)}
        judged[variant] = run_judgements(rec.metadata, table[variant])
        if args.json:
            print(to_json({variant: {**table[variant],
                                     "requirements": verdict_record(judged[variant])}}))
        else:
            print(f"case {case.name}, design {design.summary['design_hash']}")
            print(format_metrics(table))
            print_verdicts(case.name, judged)
    if verdict is not None and not verdict.completed:
        print(verdict_line("sil", res.bag.name, verdict), file=sys.stderr)
        return EXIT_VERDICT
    if res.returncode != 0:
        return 1
    return exit_status(args.check, judged)


def _plant_rate(args) -> dict | None:
    """The plant's `rate` override of `fahv sil --rate` (None at 0, the default).

    Raises
    ------
    ValueError
        If the rate is negative or not finite.
    """
    if not 0.0 <= args.rate < float("inf"):
        raise ValueError(f"--rate {args.rate}: must be a finite number >= 0")
    return {"plant": {"rate": args.rate}} if args.rate else None


def _write_params_only(args, design, variant: str) -> int:
    """`fahv sil --write-params FILE`: the run's parameter file and how to start the nodes."""
    from fahv.sil.workspace import ensure_built

    ensure_built()  # the nodes started by hand are those of the current sources
    out = Path(args.out or ROOT / "bags").resolve()
    bag = out / run_name(design.case["name"], variant, "sil")
    path = Path(args.write_params)
    content = write_run_params(design, variant, bag, path, args.duration, args.watchdog,
                               _plant_rate(args))  # fmt: skip
    print(f"parameter file {path} written; the recorder will write {bag}")
    print("start the graph node by node (any order; the plant starts step 0 once all are up):")
    print("  source ros_ws/install/setup.bash")
    print(f"  {export_line(free_domain())}   # a domain no other graph uses now")
    names = graph_nodes(controller_node(content))
    for name in names:
        amp = "" if name == "plant" else " &"
        print(f"  ros2 run {NODES[name].package} {name} --ros-args --params-file {path}{amp}")
    loop = loop_nodes(names)
    print("or the loop nodes composed in one process (after the recorder's line):")
    print(f"  ros2 run hsv_bringup {COMPOSED} {' '.join(loop)} --ros-args --params-file {path}")
    return 0


def free_domain() -> int:
    """A ROS domain ID no other graph of this host holds now (ROS 2's domain_coordinator).

    The ID is released again at once: it is a suggestion for a graph started by hand.
    Without the ROS wheels (no `domain_coordinator`) 42 is suggested.
    """
    try:
        import domain_coordinator
    except ImportError:
        return 42
    with domain_coordinator.domain_id() as domain:
        return int(domain)


def export_line(domain: int) -> str:
    """The shell line that puts a shell into the graph's ROS domain (this host only)."""
    return f"export ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"


def _add_sil_parser(sub) -> None:
    """`fahv sil`: the options read as its usage."""
    p = sub.add_parser(
        "sil", help="the ROS 2 node graph of a scenario in lockstep, recorded to bags/<run>/ (MCAP)"
    )
    p.add_argument(
        "case", metavar="scenario", help="scenario file, e.g. offline_design/scenarios/case1.yaml"
    )
    add_design_options(p)
    p.add_argument("--variant", default=None, help="variant (default: the case's first)")
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument("--out", default=None, help="folder of the recorded runs (default bags/)")
    p.add_argument("--watchdog", type=float, default=10.0, help="node watchdog [s wall time]")
    p.add_argument(
        "--domain-id",
        type=int,
        default=None,
        help="ROS_DOMAIN_ID of the graph (default: a free one from domain_coordinator; "
        "an exported ROS_DOMAIN_ID is not used)",
    )
    p.add_argument(
        "--write-params",
        metavar="FILE",
        default=None,
        help="only write the run's ROS parameter file (every node, the recorder's run folder) "
        "and print the `ros2 run` commands that start the graph by hand",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--compose", action="store_true",
                   help="the loop nodes in one process (ROS 2 composition; about twice as "
                   "fast, the same run step for step) instead of one process each")  # fmt: skip
    p.add_argument("--rate", type=float, default=0.0,
                   help="0: as fast as the graph steps (default); r: at most r x real time "
                   "(1: a live view at the vehicle's own pace)")  # fmt: skip
    add_live_option(p)
    p.add_argument("--json", action="store_true", help="metrics as JSON")
    add_check_option(p)
    add_vehicle_option(p)
    p.set_defaults(func=cmd_sil)
