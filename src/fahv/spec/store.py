"""Stored designs: where they live, and refusing stale ones.

A design made by `fahv design` is stored beside its design file
(`offline_design/designs/<name>/`) and committed. `stored_design` loads it and
refuses it when its design file or vehicle changed (naming the command that re-makes
it). Nothing here designs or verifies; a scenario is given its stored design after the
design verified by `fahv.certificate.verified.load_or_design`.
"""

from __future__ import annotations

from pathlib import Path

from fahv.errors import DesignError
from fahv.model.vehicle import load_vehicle
from fahv.spec.artefacts import load_design, stale_reason
from fahv.spec.files import load_design_file


def design_dir(design_file: Path, name: str, out=None, vehicle=None) -> Path:
    """Artefact folder of a design: `<design file's folder>/<name>` (shipped beside it).

    `out` if given. For a vehicle file other than the packaged one,
    `<name>@<vehicle file stem>-<data hash>`, so designs for several vehicles do not
    overwrite each other.
    """
    if out:
        return Path(out)
    if vehicle is not None and not vehicle.packaged:
        name = f"{name}@{Path(vehicle.source_file).stem}-{vehicle.data_hash[:8]}"
    return Path(design_file).parent / name


def stored_design(design_file: Path, design_folder=None, vehicle=None):
    """The stored design of a design file, refused if missing or stale.

    Parameters
    ----------
    design_file : Path
        The design file (`offline_design/designs/<name>.yaml`).
    design_folder : Path, optional
        Where the design is stored (default `design_dir`).
    vehicle : fahv.model.vehicle.Vehicle, optional
        The vehicle it was made for (default: the packaged one).

    Returns
    -------
    (SpecFile, Design, Path)
        The validated design file, the stored design and its folder.

    Raises
    ------
    DesignError
        If the folder holds no valid design, or the design file or vehicle changed
        since it was made (the message gives the command that re-makes it).
    """
    vehicle = load_vehicle() if vehicle is None else vehicle
    spec = load_design_file(design_file)
    folder = design_dir(spec.path, spec.name, design_folder, vehicle)
    command = f"fahv design {spec.path}" + (
        "" if vehicle.packaged else f" --vehicle {vehicle.source_file}"
    )
    fix = f"run `{command}`"  # the whole command between the backticks, to paste
    try:
        design = load_design(folder)
    except DesignError as exc:
        raise DesignError(f"no stored design of {spec.path}: {exc}; {fix}") from None
    reason = stale_reason(design, spec, vehicle)
    if reason is not None:
        raise DesignError(f"stored design {folder} is stale: {reason}; {fix}")
    return spec, design, folder
