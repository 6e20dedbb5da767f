"""The stored design a scenario runs on: verified, inside its certified range, with its arrays.

`load_or_design` never designs: it takes the stored design of the scenario's design
file (refused when missing or stale, `fahv.spec.store.stored_design`), re-checks
its certificate once per content (`fahv.certificate.verify.verified_design`),
refuses what the scenario asks beyond the design's certified ranges (the refused reasons
of its coverage verdict, `fahv.spec.coverage.coverage`) and adds the scenario's own
arrays (`fahv.spec.scenario.scenario_design`). What the certificate does not claim
(a fault kind it does not name, the onset of a loss above the certified onset loss) is
not refused: the run's coverage verdict says it.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from fahv.certificate.verify import verified_design
from fahv.errors import SpecError
from fahv.model.vehicle import load_vehicle
from fahv.spec.coverage import coverage
from fahv.spec.scenario import load_scenario, scenario_design
from fahv.spec.store import stored_design


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def load_or_design(
    scenario_path,
    design_folder=None,
    vehicle_file=None,
    log=_stderr,
    allow_uncertified: bool = False,
    variants=None,
):
    """The run spec of a scenario file and the stored, verified design it runs on.

    The design is never made here: a missing or stale design is refused with the
    command that makes it (`fahv.spec.store.stored_design`); a stored design is
    verified once per content (`fahv.certificate.verify.verified_design`). What the
    scenario asks beyond the design's certified ranges
    (`fahv.spec.coverage.Coverage.refused`) is refused, or with `allow_uncertified`
    reported as a warning; the rest of its coverage verdict does not stop it.

    `variants` (all of the scenario's by default) are the variants that will run: what
    only another variant needs (the baseline's ellipsoids along a new step) is not made.

    Returns
    -------
    (SpecFile, Design, Vehicle)
        The scenario's run spec, the design with the scenario's arrays
        (`fahv.spec.scenario.scenario_design`), the vehicle.

    Raises
    ------
    SpecError, DesignError
        Naming the scenario or design file and what is wrong.
    """
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    scenario = load_scenario(scenario_path)
    vehicle = load_vehicle(vehicle_file or scenario.vehicle_file)  # --vehicle first
    _, design, folder = stored_design(scenario.design_file, design_folder, vehicle)
    if verified_design(design, vehicle, folder, log) is not None:
        log(f"design {folder.name}: every certificate re-checked (cached for this code)")
    beyond = coverage(design, scenario.run_spec.data, vehicle).refused
    if beyond:
        text = f"{scenario.path}: beyond what design {folder.name} certifies: " + "; ".join(beyond)
        if not allow_uncertified:
            raise SpecError(text + " (--allow-uncertified runs it anyway, with this warning)")
        log(f"warning: {text}")
    cache = Path(".cache") / "scenarios" / folder.name
    run = scenario_design(design, scenario.run_spec, vehicle, cache, log, variants)
    return scenario.run_spec, run, vehicle
