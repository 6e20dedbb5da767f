"""The `fahv-studies` command line: the studies' commands, apart from the product's `fahv`.

Subcommands:

    fahv-studies estimation   what can be certified about a scenario's state estimate,
                              and what cannot (bounds, output-feedback tube, probabilistic
                              tube of the loop on the estimate)

Errors, interruptions and exit statuses are those of `fahv` (`fahv.cli.run_parsed`).
"""

from __future__ import annotations

import argparse
import sys

from fahv.cli import run_parsed
from fahv_studies.cli import estimation


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of the `fahv-studies` command (every study's subcommand)."""
    ap = argparse.ArgumentParser(prog="fahv-studies", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    estimation.add_parsers(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point of `fahv-studies`; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    return run_parsed(build_parser().parse_args(argv), "fahv-studies")


if __name__ == "__main__":
    sys.exit(main())
