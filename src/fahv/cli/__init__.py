"""The `fahv` command line.

Subcommands:

    fahv trim      trim table at a point or over a grid of the envelope
    fahv tp        TP model transformation report (singular values, error)
    fahv figures   modelling figures (paper Fig. 2, 3, 4, 5, 8) as PNG
    fahv tube      tube feasibility study (W by source, F, Z, input room)
    fahv design    offline synthesis of a design file: certified artefacts
    fahv verify    re-check every certificate of a stored design (no solver)
    fahv margins   gain, phase, delay and disk margins of the tube loop, with and without the notch
    fahv simulate  in-process closed loop of a scenario: metrics table per variant
    fahv sil       the ROS 2 node graph of a scenario in lockstep, recorded to MCAP
    fahv plot      paper-style figures of recorded runs, overlaid
    fahv paper-figures   Fig. 9-17 of the paper from Cases 1 and 2
    fahv results   every variant of Cases 1 and 2: the README's results table, reference
    fahv inspect   topics, metadata, step anomalies and metrics of a run
    fahv export    one CSV / Parquet table per topic, with units
    fahv compare   metrics of two runs side by side
    fahv report    one HTML page of a run or a campaign: verdict, coverage, metrics, figures
    fahv replay    republish a run over DDS, e.g. into a fresh tube_mpc node
    fahv campaign  Monte Carlo campaign on Dask; campaign report DIR; campaign rerun DIR INDEX
    fahv index     index of offline_design/ from the files' descriptions

Every command that uses the vehicle takes `--vehicle FILE`. Errors name the
input at fault and exit with status 2 (bad input) or 1 (failure). A run that ends with
a verdict other than `completed` (`fahv.verdict`) is named with its verdict, step,
time and node, and the command exits with status 3. Ctrl-C or SIGTERM
stops a command cleanly: a run in progress is finalised (status `interrupted`), the
command prints `interrupted at step k of n; run written to DIR` and exits with 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from fahv.cli.common import stop_signals
from fahv.errors import FahvError, RunInterrupted

#: Exit status after SIGINT / SIGTERM (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130
#: The module of `fahv.cli` that defines each subcommand, in the order of `--help`. A
#: command imports only its own module: `fahv inspect` does not load the design
#: pipeline, Dask or the campaign statistics (a test checks the table is complete).
COMMANDS = {
    "trim": "modelling", "tp": "modelling", "figures": "modelling", "tube": "modelling",
    "design": "design", "verify": "design", "margins": "margins",
    "simulate": "run", "sil": "sil", "replay": "replay", "paper-figures": "run",
    "results": "run", "inspect": "inspect", "export": "inspect", "compare": "inspect",
    "plot": "inspect", "report": "report", "campaign": "campaign",
    "clearance": "clearance", "index": "index",
}  # fmt: skip


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Argument parser of the `fahv` command.

    Parameters
    ----------
    command : str, optional
        A subcommand (a key of `COMMANDS`): only its module is imported and its
        parsers added. None or an unknown word: every subcommand (for `--help` and the
        error that lists them).
    """
    ap = argparse.ArgumentParser(prog="fahv", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    modules = [COMMANDS[command]] if command in COMMANDS else dict.fromkeys(COMMANDS.values())
    for name in modules:
        importlib.import_module(f"fahv.cli.{name}").add_parsers(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point of `fahv`; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    return run_parsed(build_parser(command).parse_args(argv), "fahv")


def run_parsed(args: argparse.Namespace, prog: str) -> int:
    """Run a parsed subcommand (`args.func`) and return its exit status.

    Ctrl-C and SIGTERM stop it cleanly (`EXIT_INTERRUPTED`); bad input (`FahvError`,
    `ValueError`, `OSError`) prints `<prog> <command>: error: ...` and returns 2. Also the
    entry point of the studies' command (`fahv_studies.cli`).
    """
    with stop_signals():
        try:
            return args.func(args)
        except RunInterrupted as exc:
            print(f"{prog} {args.command}: {exc}", file=sys.stderr)
            return EXIT_INTERRUPTED
        except KeyboardInterrupt:
            print(f"{prog} {args.command}: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except (FahvError, ValueError, OSError) as exc:
            print(f"{prog} {args.command}: error: {exc}", file=sys.stderr)
            return 2


if __name__ == "__main__":
    sys.exit(main())
