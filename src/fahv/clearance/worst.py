"""A clearance's worst case as a scenario file that `fahv simulate` and `fahv sil` fly again.

The file extends the campaign's scenario (`extends:` its path, relative to the file) and
states only what the run's dispersed values change: the vehicle's s_p
(`uncertainty.s`, with the campaign's box fraction), the fault (its kind, onset and the
kind's own parameters), the initial trim and the command, the servo and sensor factors
and the sensor-noise seed (`plant`), the run's duration, variant and requirement limits.
These reach the nodes as the campaign's overrides do, so the run is the searched run,
bit for bit (a test flies one both ways).
"""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from fahv.campaign.draws import HARDWARE, row_values, uncertainty_scale
from fahv.plant.faults import FAULTS
from fahv.plant.uncertainty import PAPER_UNCERTAINTY


def worst_scenario(campaign, row: dict, variant: str, name: str, folder: Path) -> dict:
    """The scenario (a mapping) of the run `row` of a clearance of `campaign`.

    Parameters
    ----------
    campaign : fahv.campaign.spec.Campaign
    row : dict
        The run's row (its dispersed values, `fahv.campaign.draws.row_values`).
    variant : str
    name : str
        The scenario's name.
    folder : Path
        Where the file is written (its `extends:` is relative to it).
    """
    values = row_values(row)
    case = campaign.run_spec.data
    base = os.path.relpath(Path(campaign.run_spec.path).resolve(), Path(folder).resolve())
    out: dict = {"extends": base, "name": name,
                 "description": f"The worst case a clearance of campaign {campaign.name} found "
                 f"(run {row['index']}).", "duration": float(campaign.duration),
                 "variants": [variant]}  # fmt: skip
    if any(k.startswith("s.") for k in values):
        s = [float(values.get(f"s.{p}", 0.0)) for p in PAPER_UNCERTAINTY]
        out["uncertainty"] = {"seed": int(case["uncertainty"]["seed"]),
                              "scale": uncertainty_scale(campaign.data), "s": s}  # fmt: skip
    if "fault.kind" in values:
        kind = values["fault.kind"]
        fault = {"kind": kind, "t_onset": float(values["fault.t_onset"])}
        for p in FAULTS[kind].parameters:
            fault[p.name] = (float(case["fault"].get("side", 1.0)) if p.name == "side"
                             else float(values[f"fault.{p.name}"]))  # fmt: skip
        out["fault"] = fault
    if "initial.h0" in values or "command.h_c" in values:
        cmd = case["command"]
        out["command"] = {k: float(values.get(src, cmd[k])) for k, src in
                          (("h0", "initial.h0"), ("V0", "initial.V0"), ("h_c", "command.h_c"),
                           ("V_c", "command.V_c"))}  # fmt: skip
    plant = {name: float(values[f"{group}.{k}"]) for group, keys in HARDWARE.items()
             for k, name in keys.items() if f"{group}.{k}" in values}  # fmt: skip
    if "sensor_seed" in values:
        plant["sensor_seed"] = int(values["sensor_seed"])
    if plant:
        out["plant"] = plant
    limits = {k: v for k, v in campaign.data["requirements"].items() if k != "confidence"}
    out["requirements"] = limits
    return out


def write_worst_scenario(campaign, row: dict, variant: str, requirement: str,
                         folder: Path) -> Path:  # fmt: skip
    """Write `worst_<requirement>.yaml` (`worst_scenario`) into `folder`; its path."""
    name = f"{campaign.run_spec.data['name']}_worst_{requirement}"
    path = Path(folder) / f"worst_{requirement}.yaml"
    text = yaml.safe_dump(worst_scenario(campaign, row, variant, name, folder), sort_keys=False)
    path.write_text(f"# fahv clearance: the worst {requirement} found (run {row['index']})\n"
                    + text)  # fmt: skip
    return path
