"""`fahv simulate`, `paper-figures`, `results`: runs of the closed loop in process.

Also what every run command prints about its runs (`fahv.cli.sil` uses it too): the
coverage line, the verdict table against the requirements, the exit status.
"""

from __future__ import annotations

import sys
from pathlib import Path

from fahv.certificate.verified import load_or_design
from fahv.cli.common import add_vehicle_option, progress, read_run_warned, to_json
from fahv.errors import FahvError, RunInterrupted
from fahv.loop.graph import TOPICS
from fahv.loop.simulate import simulate
from fahv.runs.bag import run_result_of
from fahv.runs.metrics import metrics
from fahv.runs.tools import format_metrics
from fahv.runs.writer import RunWriter
from fahv.sil.runner import (
    recorder_metadata,
    run_coverage,
    run_name,
    run_parameter_file,
)
from fahv.sil.wire import encode
from fahv.sil.workspace import ROOT
from fahv.spec.plant_dispersion import rate_limit_factor
from fahv.spec.requirements import judge, limits_of, overall, verdict_record, verdict_table
from fahv.spec.scenario import load_scenario
from fahv.verdict import RunEnded, completed

#: Exit status of a run command (`simulate`, `sil`) when a run ended with a verdict
#: other than `completed` (`fahv.verdict`); 1 is a failure, 2 bad input.
EXIT_VERDICT = 3
#: Exit status of a run command with `--check` when a run that completed missed a
#: requirement (`fahv.spec.requirements`).
EXIT_REQUIREMENTS = 4


class StepProgress:
    """Progress of an in-process run: a tqdm bar of steps with rate and ETA.

    Passed to `fahv.loop.simulate.simulate` as its `writer`: it sees every
    message of every step, forwards it to the run writer (if any), advances the bar
    once per step. On a terminal the bar
    updates in place; in a log it writes a line every 10 s.

    Parameters
    ----------
    desc : str
        Label of the bar.
    n_steps : int
        Steps of the run.
    writer : fahv.runs.writer.RunWriter, optional
        Receives every message.
    live : fahv.runs.live.LiveView, optional
        Serves every message (the same CDR bytes) to Foxglove.
    """

    #: The last topic of a step (`fahv.loop.graph.TOPICS` order).
    LAST_TOPIC = list(TOPICS)[-1]

    def __init__(self, desc: str, n_steps: int, writer=None, live=None) -> None:
        self.bar = progress(total=n_steps, desc=desc, unit="step", leave=False)
        self.writer = writer
        self.live = live
        self.k = 0

    def write(self, topic: str, k: int, msg) -> None:
        """Forward one message of step k; count the step after its last topic."""
        if self.live is not None:  # serialised once, the same bytes to both
            data = encode(topic, msg)
            self.live.log(topic, k, data)
            if self.writer is not None:
                self.writer.write_raw(topic, k, data)
        elif self.writer is not None:
            self.writer.write(topic, k, msg)
        if topic == self.LAST_TOPIC:
            self.k = k + 1
            self.bar.update(1)

    def close(self) -> None:
        """Remove the bar."""
        self.bar.close()


#: Cases of `fahv results` and `fahv paper-figures`: Case 1 (certified), the paper's
#: vertex design of Case 1 (the paper's law), Case 2.
DEFAULT_CASES = (
    "offline_design/scenarios/case1.yaml",
    "offline_design/scenarios/case1_paper.yaml",
    "offline_design/scenarios/case2.yaml",
)


def _simulate_recorded(design, variant: str, duration, out_dir, live=None):
    """simulate() with a progress bar, recorded to `out_dir/<run>/` unless it is None.

    The run file also holds the run's ROS parameter file (the one a SIL run's nodes
    get), so `fahv replay --node ...` can start nodes against it.

    Returns
    -------
    (RunResult or None, Verdict, Path or None)
        What the run flew (None when it ended before its first step), its verdict
        (`fahv.verdict`; stored in the run file's metadata), the run folder.

    Raises
    ------
    RunInterrupted
        On Ctrl-C / SIGTERM, after the run file was finalised (status interrupted).
    """
    case = design.case
    desc = f"{case['name']} {variant}"
    d = case["duration"] if duration is None else duration
    n_steps = int(round(d / case["Ts"]))
    bag = None if out_dir is None else Path(out_dir) / run_name(case["name"], variant, "sim")
    progress = StepProgress(desc, n_steps, live=live)
    verdict = completed(n_steps, case["Ts"])
    try:
        if bag is None:
            run = simulate(design, variant, duration, writer=progress)
        else:
            content = run_parameter_file(design, variant, bag, duration, 10.0, source="simulate")
            meta = recorder_metadata(content)
            with RunWriter(bag, meta, case["Ts"], params=content) as writer:
                progress.writer = writer
                run = simulate(design, variant, duration, writer=progress)
    except KeyboardInterrupt:
        # The finalised file's count, not the bar's: a stop deferred to the end of a
        # write is raised after the file counted that step but before the bar did.
        w = progress.writer
        k = progress.k if w is None else int(w.metadata.get("steps_recorded", progress.k))
        raise RunInterrupted(k, n_steps, bag) from None
    except RunEnded as exc:  # the writer recorded the verdict and closed the file
        run, verdict = exc.partial, exc.verdict
    finally:
        progress.close()
    if bag is not None:
        print(f"{desc}: run written to {bag}")
    return run, verdict, bag


def verdict_line(command: str, run: str, verdict) -> str:
    """The line `fahv` prints for a run that ended with a verdict other than completed.

    Parameters
    ----------
    command : str
        Subcommand (`simulate`, `sil`).
    run : str
        The run: its folder name, or `<case> <variant>` when it was not recorded.
    verdict : fahv.verdict.Verdict

    Returns
    -------
    str
        `fahv <command>: run <run> ended: <verdict>` (`fahv.verdict.Verdict.text`:
        name, simulated time, step, node and reason).
    """
    return f"fahv {command}: run {run} ended: {verdict.text()}"


def selected_variants(case, requested: list[str] | None) -> list[str]:
    """Variants a command runs: the case's default (its first) unless `requested`.

    `requested` lists variant names of the case, or is `["all"]` for every variant
    of the case in its order.

    Raises
    ------
    FahvError
        On a variant the case does not list (naming the case's variants).
    """
    listed = list(case["variants"])
    if not requested:
        return listed[:1]
    if requested == ["all"]:
        return listed
    unknown = [v for v in requested if v not in listed]
    if unknown:
        raise FahvError(
            f"{case.name}: variant(s) {', '.join(unknown)} not in the case's variants "
            f"{listed} (or use --variant all)"
        )
    return list(dict.fromkeys(requested))


def cmd_simulate(args) -> int:
    """In-process closed loop of a case; records each variant to bags/, prints metrics."""
    import time

    variants = selected_variants(load_scenario(args.case).run_spec, args.variant)
    case, design, vehicle = load_or_design(
        args.case, args.design, args.vehicle, allow_uncertified=args.allow_uncertified,
        variants=variants,
    )  # fmt: skip
    limits = vehicle.limits.with_rate_factor(rate_limit_factor(design.case))
    table, judged = {}, {}
    ended = []
    live = _live_view(args.live, case["Ts"])
    try:
        for i, v in enumerate(variants, 1):
            out = None if args.no_record else Path(args.out or ROOT / "bags")
            n = len(variants)
            print(f"[{i}/{n}] {case.name} {v}: simulating", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            run, verdict, bag = _simulate_recorded(design, v, args.duration, out, live)
            if run is not None:  # the metrics of what it flew, also when it ended early
                table[v] = metrics(run, limits)
                judged[v] = judge(table[v], limits_of(design.case), verdict.completed)
            if not verdict.completed:
                ended.append(verdict_line("simulate", bag.name if bag else f"{case.name} {v}",
                                          verdict))  # fmt: skip
            how = "done" if verdict.completed else f"ended ({verdict.name})"
            print(f"[{i}/{n}] {case.name} {v}: {how} in {time.perf_counter() - t0:.1f} s",
                  file=sys.stderr, flush=True)  # fmt: skip
    finally:
        if live is not None:
            live.close()
    print_coverage(run_coverage(design, args.duration).describe(), args.json)
    if args.json:
        print(to_json({v: {**m, "requirements": verdict_record(judged[v])}
                       for v, m in table.items()}))  # fmt: skip
    elif table:
        print(f"case {case.name}, design {design.summary['design_hash']}")
        print(format_metrics(table))
        print_verdicts(case.name, judged)
    for line in ended:
        print(line, file=sys.stderr)
    if ended:
        return EXIT_VERDICT
    return exit_status(args.check, judged)


def print_verdicts(scenario: str, judged: dict[str, list]) -> None:
    """Print each run's verdict table (`fahv.spec.requirements.verdict_table`)."""
    for v, js in judged.items():
        print(f"\nrequirements of {scenario} {v}:")
        print(verdict_table(js, f"{scenario} {v}"))


def docs_verdict_table() -> str:
    """The verdict table `fahv simulate offline_design/scenarios/case1.yaml --no-record` prints.

    For the docs build's hook (`docs/hooks/generated.py`, marker `case1-verdict`): the
    command run in process on the repository's scenario (`fahv.sil.workspace.ROOT`),
    its table as an indented block.

    Returns
    -------
    str
        The lines after `requirements of case1 tube_mpc:`, each indented by four spaces.

    Raises
    ------
    FahvError
        If the command fails or prints no verdict table.
    """
    import contextlib
    import io

    from fahv.cli import main

    out = io.StringIO()
    scenario = ROOT / "offline_design" / "scenarios" / "case1.yaml"
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        rc = main(["simulate", str(scenario), "--no-record"])
    text = out.getvalue()
    if rc != 0 or "\nrequirements of " not in text:
        raise FahvError(f"fahv simulate {scenario} exited {rc} without a verdict table")
    table = text.split("\nrequirements of ", 1)[1].split("\n", 1)[1]
    return "\n".join(f"    {line}" for line in table.rstrip("\n").splitlines())


def exit_status(check: bool, judged: dict[str, list]) -> int:
    """0, or with `--check` `EXIT_REQUIREMENTS` when a run missed a requirement."""
    if check and not all(overall(js) for js in judged.values()):
        return EXIT_REQUIREMENTS
    return 0


def print_coverage(text: str, json_out: bool = False) -> None:
    """Print a run's coverage verdict, `coverage: certified` or `coverage: not certified: ...`.

    On stdout before the metrics, on stderr when stdout holds JSON (`json_out`).
    """
    print(f"coverage: {text}", file=sys.stderr if json_out else sys.stdout)


def _live_view(port: int | None, Ts: float):
    """The in-process live view of `fahv simulate --live` (None without `--live`)."""
    if port is None:
        return None
    from fahv.runs.live import LiveView, live_hint

    live = LiveView(port, Ts)
    print(f"live view on {live.url} ({live_hint()})", flush=True)
    return live


def cmd_paper_figures(args) -> int:
    """Simulate every variant of Cases 1 and 2 (recorded) and write Fig. 9-17."""
    from fahv.runs.plots import paper_figures  # matplotlib: this command's only

    runs = {}
    for path in args.runs or []:  # recorded runs (simulated or SIL) instead of new ones
        rec = read_run_warned(path)
        key = (rec.metadata.get("case"), rec.metadata.get("variant"))
        if None in key:
            raise FahvError(f"{path}: no case/variant in the run metadata")
        runs[key] = run_result_of(rec)
        print(f"{key[0]} {key[1]}: {path} ({rec.metadata.get('source', '?')})")
    for case_path in [] if args.runs else args.cases:
        case, design, _ = load_or_design(case_path, None, args.vehicle)
        for v in case["variants"]:
            run, verdict, bag = _simulate_recorded(design, v, args.duration, ROOT / "bags")
            if not verdict.completed:  # the figures show whole runs only
                print(verdict_line("paper-figures", bag.name, verdict), file=sys.stderr)
                return EXIT_VERDICT
            runs[(case.name, v)] = run
    for path in paper_figures(runs, args.out):
        print(path)
    return 0


def add_design_options(p) -> None:
    """`--design DIR` and `--allow-uncertified` of a run command."""
    p.add_argument(
        "--design",
        default=None,
        help="artefact folder of the stored design (default: beside its design file)",
    )
    p.add_argument(
        "--allow-uncertified",
        action="store_true",
        help="run a scenario beyond the design's certified ranges (command, trim, loss, "
        "vehicle draw), with a warning",
    )


def add_live_option(p) -> None:
    """`--live [PORT]`: the run served to Foxglove while it flies."""
    from fahv.runs.live import DEFAULT_PORT

    p.add_argument(
        "--live",
        type=int,
        nargs="?",
        const=DEFAULT_PORT,
        default=None,
        metavar="PORT",
        help=f"serve the loop topics live to Foxglove on ws://localhost:PORT (default "
        f"{DEFAULT_PORT}; 0: any free port)",
    )


def cmd_results(args) -> int:
    """Every variant of each case: the README's results table; reference JSON write/check."""
    from fahv.runs.results import (
        compare_reference,
        markdown_table,
        read_reference,
        run_case,
        write_reference,
    )

    results = {}
    for path in args.cases:
        case, design, vehicle = load_or_design(
            path, None, args.vehicle, allow_uncertified=args.allow_uncertified
        )
        print(f"{case.name}: design {design.summary['design_hash']}", file=sys.stderr)
        log = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
        results[case.name] = run_case(design, case["variants"], vehicle.limits, log)
    print(markdown_table(results))
    if args.write_reference:
        # the cases run replace theirs; the reference's other cases are kept
        out = Path(args.write_reference)
        old = read_reference(out) if out.exists() else {}
        kept = sorted(set(old) - set(results))
        print(f"reference written to {write_reference({**old, **results}, out)}"
              + (f" (kept from it, not run: {', '.join(kept)})" if kept else ""))  # fmt: skip
    if args.check:
        ref = read_reference(args.check)
        checked = {c: v for c, v in ref.items() if c in results}
        for c in sorted(set(results) - set(ref)):
            print(f"note: {c} is not in {args.check}; not checked")
        not_run = sorted(set(ref) - set(results))
        if not_run:
            print(f"note: not run, not checked: {', '.join(not_run)}")
        if not checked:
            print(f"{args.check}: none of the cases run is in the reference", file=sys.stderr)
            return 1
        bad = compare_reference(results, checked)
        for line in bad:
            print(f"differs: {line}")
        print(f"{args.check}: {'within' if not bad else 'OUTSIDE'} the tolerances "
              f"({', '.join(sorted(checked))})")  # fmt: skip
        return 1 if bad else 0
    return 0


def add_parsers(sub) -> None:
    """Add the parsers of this command group: simulate, paper-figures, results."""
    _add_simulate_parser(sub)
    _add_results_parsers(sub)


def _add_simulate_parser(sub) -> None:
    """`fahv simulate`: the options read as its usage."""
    p = sub.add_parser("simulate", help="in-process closed loop of a scenario, metrics table")
    p.add_argument(
        "case", metavar="scenario", help="scenario file, e.g. offline_design/scenarios/case1.yaml"
    )
    add_design_options(p)
    p.add_argument(
        "--variant",
        nargs="+",
        default=None,
        help="variants to run (default: the case's first, its default variant; 'all': every "
        "variant of the case, with a progress line per variant)",
    )
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument("--out", default=None, help="folder of the recorded runs (default bags/)")
    p.add_argument("--no-record", action="store_true", help="do not write the runs to MCAP")
    add_live_option(p)
    p.add_argument("--json", action="store_true")
    add_check_option(p)
    add_vehicle_option(p)
    p.set_defaults(func=cmd_simulate)


def add_check_option(p) -> None:
    """`--check`: the exit status follows the runs' requirement verdicts."""
    p.add_argument("--check", action="store_true",
                   help=f"exit with status {EXIT_REQUIREMENTS} when a run misses a "
                   "requirement (the verdict table; for regression pipelines)")  # fmt: skip


def _add_results_parsers(sub) -> None:
    """`fahv paper-figures` and `fahv results`: the paper's cases, all variants."""
    p = sub.add_parser(
        "paper-figures",
        help="simulate Cases 1 and 2 (all variants, recorded; the paper's law on "
        "case1_paper) and write Fig. 9-17",
    )
    p.add_argument(
        "--cases",
        nargs="+",
        default=list(DEFAULT_CASES),
    )
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument(
        "--runs", nargs="+", default=None, help="use these recorded runs instead of simulating"
    )
    p.add_argument("--out", default="docs/figures")
    add_vehicle_option(p)
    p.set_defaults(func=cmd_paper_figures)
    p = sub.add_parser(
        "results",
        help="every variant of Case 1 (certified and the paper's vertex design) and Case 2 "
        "in process: the README's results tables; write or check a metrics reference "
        "(tests/data/results_reference.json)",
    )
    p.add_argument(
        "--cases",
        nargs="+",
        default=list(DEFAULT_CASES),
    )
    p.add_argument("--write-reference", metavar="FILE", default=None,
                   help="write the metrics of every case and variant as JSON")  # fmt: skip
    p.add_argument("--check", metavar="FILE", default=None,
                   help="compare with a reference JSON; exit 1 outside the tolerances")  # fmt: skip
    p.add_argument("--allow-uncertified", action="store_true",
                   help="run scenarios whose loop the design does not certify (e.g. on "
                   "servos and sensors)")  # fmt: skip
    add_vehicle_option(p)
    p.set_defaults(func=cmd_results)
