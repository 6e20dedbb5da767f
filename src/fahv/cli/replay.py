"""`fahv replay`: republish a recorded run's loop topics, optionally into nodes under test."""

from __future__ import annotations

import sys

from fahv.errors import RunInterrupted
from fahv.runs.bag import stored_metadata
from fahv.runs.replay import run_replay


def cmd_replay(args) -> int:
    """Republish a recorded run (raw CDR), optionally into nodes under test."""
    res = run_replay(
        args.run,
        nodes=args.node or (),
        topics=args.topics,
        capture=args.capture,
        out=args.out,
        rate=0.0 if args.fast else args.rate,
        steps=args.steps,
        watchdog_s=args.watchdog,
        quiet=args.quiet,
        params=args.params,
    )
    if res.interrupted:
        done = stored_metadata(res.out) if res.out is not None else {}
        src = stored_metadata(args.run)
        n = args.steps or int(round(float(src.get("duration", 0)) / float(src.get("Ts", 1))))
        raise RunInterrupted(int(done.get("steps_recorded", 0)), n, res.out)
    if res.returncode != 0:
        print(f"fahv replay: failed (logs in {res.log_dir})", file=sys.stderr)
        return 1
    if res.outputs is not None:  # the runner said where the replayed run was written
        print(res.outputs.summary())
        return 0 if res.outputs.identical else 1
    return 0


def add_parsers(sub) -> None:
    """Add the parser of this command."""
    p = sub.add_parser(
        "replay",
        help="republish a run's loop topics (raw CDR) over DDS, optionally into nodes under test",
    )
    p.add_argument("run", help="run folder or .mcap file")
    p.add_argument("--topics", nargs="+", default=None, help="topics to republish")
    p.add_argument(
        "--node",
        nargs="+",
        default=None,
        help="nodes to test against the replay with the run's parameters (e.g. tube_mpc)",
    )
    p.add_argument(
        "--capture", nargs="+", default=None, help="topics to capture (default: the nodes' outputs)"
    )
    p.add_argument("--out", default=None, help="run folder for the replayed + captured messages")
    p.add_argument("--rate", type=float, default=1.0, help="1: recorded timing, r: r x faster")
    p.add_argument("--fast", action="store_true", help="as fast as possible (lockstep on captures)")
    p.add_argument("--steps", type=int, default=0, help="steps to replay (0: all)")
    p.add_argument("--watchdog", type=float, default=10.0, help="node watchdog [s wall time]")
    p.add_argument(
        "--params",
        metavar="FILE",
        default=None,
        help="parameter file of the nodes under test (default: the one in the run file; "
        "needed only for runs of earlier versions started by hand)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_replay)
