"""Stored designs: where they live, refusing stale ones, and the design a scenario runs on.

A design made by ``fahv design`` is stored beside its design file
(``offline_design/designs/<name>/``) and committed. :func:`stored_design` loads it and
refuses it when its design file or vehicle changed (naming the command that re-makes
it); :func:`load_or_design` gives a scenario its stored design after the design verified
(:func:`fahv.certificate.verify.verified_design`) and the scenario stayed inside what the
design certifies (:func:`fahv.spec.scenario.uncertified`). Nothing here designs.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from fahv.certificate.verify import verified_design
from fahv.errors import CaseError, DesignError
from fahv.model.vehicle import load_vehicle
from fahv.spec.artefacts import load_design, stale_reason
from fahv.spec.scenario import load_scenario, scenario_design, uncertified
from fahv.spec.schema import load_design_file


def design_dir(design_file: Path, name: str, out=None, vehicle=None) -> Path:
    """Artefact folder of a design: ``<design file's folder>/<name>`` (shipped beside it).

    ``out`` if given. For a vehicle file other than the packaged one,
    ``<name>@<vehicle file stem>-<data hash>``, so designs for several vehicles do not
    overwrite each other.
    """
    if out:
        return Path(out)
    if vehicle is not None and not vehicle.packaged:
        name = f"{name}@{Path(vehicle.source_file).stem}-{vehicle.data_hash[:8]}"
    return Path(design_file).parent / name


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def stored_design(design_file: Path, design_folder=None, vehicle=None):
    """The stored design of a design file, refused if missing or stale.

    Parameters
    ----------
    design_file : Path
        The design file (``offline_design/designs/<name>.yaml``).
    design_folder : Path, optional
        Where the design is stored (default :func:`design_dir`).
    vehicle : fahv.model.vehicle.Vehicle, optional
        The vehicle it was made for (default: the packaged one).

    Returns
    -------
    (Case, Design, Path)
        The validated design file, the stored design and its folder.

    Raises
    ------
    DesignError
        If the folder holds no valid design, or the design file or vehicle changed
        since it was made (the message gives the command that re-makes it).
    """
    vehicle = load_vehicle() if vehicle is None else vehicle
    case = load_design_file(design_file)
    folder = design_dir(case.path, case.name, design_folder, vehicle)
    fix = f"run `fahv design {case.path}`" + (
        "" if vehicle.packaged else f" --vehicle {vehicle.source_file}"
    )
    try:
        design = load_design(folder)
    except DesignError as exc:
        raise DesignError(f"no stored design of {case.path}: {exc}; {fix}") from None
    reason = stale_reason(design, case, vehicle)
    if reason is not None:
        raise DesignError(f"stored design {folder} is stale: {reason}; {fix}")
    return case, design, folder


def load_or_design(
    scenario_path,
    design_folder=None,
    vehicle_file=None,
    log=_stderr,
    allow_uncertified: bool = False,
    variants=None,
):
    """The case of a scenario file and the stored, verified design it runs on.

    The design is never made here: a missing or stale design is refused with the
    command that makes it (:func:`stored_design`); a stored design is verified once per
    content (:func:`fahv.certificate.verify.verified_design`). What the scenario asks beyond
    the design's certified range (:func:`fahv.spec.scenario.uncertified`) is refused,
    or with ``allow_uncertified`` reported as a warning.

    ``variants`` (all of the scenario's by default) are the variants that will run: what
    only another variant needs (the baseline's ellipsoids along a new step) is not made.

    Returns
    -------
    (Case, Design, Vehicle)
        The scenario's case, the design with the scenario's arrays
        (:func:`fahv.spec.scenario.scenario_design`), the vehicle.

    Raises
    ------
    CaseError, DesignError
        Naming the scenario or design file and what is wrong.
    """
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    scenario = load_scenario(scenario_path)
    vehicle = load_vehicle(vehicle_file)
    _, design, folder = stored_design(scenario.design_file, design_folder, vehicle)
    if verified_design(design, vehicle, folder, log) is not None:
        log(f"design {folder.name}: every certificate re-checked (cached for this code)")
    beyond = uncertified(design, scenario.case.data, vehicle)
    if beyond:
        text = f"{scenario.path}: beyond what design {folder.name} certifies: " + "; ".join(beyond)
        if not allow_uncertified:
            raise CaseError(text + " (--allow-uncertified runs it anyway, with this warning)")
        log(f"warning: {text}")
    cache = Path(".cache") / "scenarios" / folder.name
    run = scenario_design(design, scenario.case, vehicle, cache, log, variants)
    return scenario.case, run, vehicle
