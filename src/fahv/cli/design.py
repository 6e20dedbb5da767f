"""``fahv design``: a case file to certified artefacts and the ROS 2 parameter file."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import yaml

from fahv.cli.common import add_vehicle_option, artefact_dir, progress, vehicle_of
from fahv.design.artefacts import load_design, save_design, stale_reason
from fahv.design.case import load_case
from fahv.design.pipeline import run_design
from fahv.errors import DesignError
from fahv.loop.params import node_parameters, parameter_file
from fahv.model.vehicle import load_vehicle


def design_case(case, vehicle, out_dir: Path, log=print):
    """Design ``case`` for ``vehicle`` and save it with its ROS 2 parameter file.

    Returns
    -------
    fahv.design.artefacts.Design

    Raises
    ------
    DesignError
        If a certificate fails (nothing is written then).
    """
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")

    def bar(it):
        return progress(it, desc="sample W", leave=False)

    design = run_design(case, vehicle, progress=bar, log=log)
    params = yaml.safe_dump(parameter_file(node_parameters(design)), sort_keys=False, width=120)
    save_design(design, out_dir, {"params.yaml": params})
    return design


def cmd_design(args) -> int:
    """Offline design of a case: print every certificate, write the artefacts."""
    case = load_case(args.case)
    vehicle = vehicle_of(args)
    out = artefact_dir(case, args.out, vehicle)
    design = design_case(case, vehicle, out)
    prov = design.summary["provenance"]
    print(
        f"design hash {design.summary['design_hash']} (case {prov['case_hash']}, vehicle "
        f"{prov['vehicle_file'] or 'packaged'} {prov['vehicle_hash']}, code {prov['code_hash']});"
        f" artefacts written to {out}/"
    )
    return 0


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def load_or_design(case_path, design_dir, vehicle_file=None, log=_stderr):
    """The valid design of a case file for a vehicle, designed first if missing or stale.

    A saved design is reused only if its provenance matches the case content, the
    vehicle file and the design code (:func:`fahv.design.artefacts.stale_reason`).

    The design report goes to ``log`` (stderr by default, so that ``--json`` output
    on stdout stays machine-readable).

    Returns
    -------
    (Case, Design, Vehicle)
    """
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    case = load_case(case_path)
    vehicle = load_vehicle(vehicle_file)
    out = artefact_dir(case, design_dir, vehicle)
    try:
        design = load_design(out)
        reason = stale_reason(design, case, vehicle)
    except DesignError as exc:
        reason = str(exc)
    if reason is not None:
        log(f"no valid design in {out} ({reason}); designing first")
        design = design_case(case, vehicle, out, log=log)
    return case, design, vehicle


def add_parsers(sub) -> None:
    """Add the parsers of this command group."""
    p = sub.add_parser("design", help="offline design of a case: artefacts + ROS parameters")
    p.add_argument("case", help="case file, e.g. offline_design/case1.yaml")
    p.add_argument(
        "--out",
        default=None,
        help="artefact folder (offline_design/artefacts/NAME, NAME@VEHICLE-HASH with --vehicle)",
    )
    add_vehicle_option(p)
    p.set_defaults(func=cmd_design)
