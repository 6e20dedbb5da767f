"""Scenarios: one thing to fly on a stored design, checked against what the design certifies.

A scenario file (`fahv.spec.schema.scenario_spec`) names a design and gives the
command, the fault instance, the simulated vehicle draw, the duration and the variants.
`load_scenario` reads it, finds its design file, and forms the **run spec** the
loop runs on (the design's entries with the scenario's, `form_run_spec`;
`design_part` goes back); `scenario_design` adds to a stored design what
depends on the scenario, in seconds and without re-designing:

* `x0`, the plant's initial state: the design's trim map at (h0, V0);
* the simulated vehicle's perturbed parameters (`summary['plant_params']`);
* the RMPC baseline's ellipsoids along the scenario's step, when its step differs from
  the design step (Wan & Kothare 2003 re-solved, then cached by content hash).

`certified_range` states what the design certifies (nominal h, V range, fault
range, parameter box) and `uncertified` lists what a scenario asks beyond it (the
reasons a scenario is refused for; the run's whole verdict is
`fahv.spec.coverage.coverage`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fahv.config.extends import resolve_extends
from fahv.control import LAWS, VARIANTS
from fahv.errors import SpecError
from fahv.model.trim import TrimMap
from fahv.plant.faults import make_fault
from fahv.plant.uncertainty import PAPER_UNCERTAINTY, perturb, perturbed_params
from fahv.sensors.data import DEFAULT_MEASURED, measured_channels
from fahv.spec.artefacts import Design, load_arrays, save_arrays
from fahv.spec.context import DesignContext
from fahv.spec.files import SpecFile, load_design_file, read_yaml_file, spec_file
from fahv.spec.schema import (
    NO_ESTIMATOR,
    OPTIONAL_SECTIONS,
    SCENARIO_KEYS,
    actuator_model,
    design_spec,
    estimator_kind,
    estimator_value,
    plant_choices,
    scenario_spec,
    sensor_fault_used,
)

#: Top-level entries of a design file that the run spec does not carry (the scenario's own
#: command and vehicle draw replace them).
DESIGN_ONLY_KEYS = ("design_step", "uncertainty", "name", "description", "variants")


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file and the run spec it forms with its design.

    Attributes
    ----------
    path : Path
        The scenario file.
    data : dict
        Its validated entries (`fahv.spec.schema.scenario_spec`).
    design_file : Path
        The design file it names.
    design : SpecFile
        The validated design file.
    run_spec : SpecFile
        The design's entries with the scenario's (`fahv.spec.schema.run_spec`).
    """

    path: Path
    data: dict
    design_file: Path
    design: SpecFile
    run_spec: SpecFile

    @property
    def vehicle_file(self) -> Path | None:
        """The vehicle data file the scenario names (relative to it), None: the packaged."""
        v = self.data.get("vehicle") or ""
        return (self.path.parent / v) if v else None

    @property
    def name(self) -> str:
        """Scenario name (run names)."""
        return self.data["name"]


def design_file_of(scenario_path: str | Path, design: str) -> Path:
    """The design file a scenario names.

    `design` is a design name, looked up as `designs/<design>.yaml` beside the
    scenario's folder (`offline_design/scenarios/x.yaml` ->
    `offline_design/designs/<design>.yaml`), then under `offline_design/designs/` of
    the working folder; or a path to a `.yaml` file, relative to the scenario file.

    Raises
    ------
    SpecError
        If no such design file exists (naming the scenario and the places looked in).
    """
    p = Path(scenario_path)
    if design.endswith((".yaml", ".yml")):
        tries = [p.parent / design, Path(design)]
    else:
        tries = [p.parent.parent / "designs" / f"{design}.yaml",
                 Path("offline_design") / "designs" / f"{design}.yaml"]  # fmt: skip
    for t in tries:
        if t.is_file():
            return t
    raise SpecError(
        f"{p}: key 'design': no design file {design!r} (looked for "
        + ", ".join(str(t) for t in tries)
        + ")"
    )


def form_run_spec(design: SpecFile, scenario: dict, path: str | Path) -> SpecFile:
    """The run spec of a scenario on a design: the design's entries with the scenario's.

    Parameters
    ----------
    design : SpecFile
        A validated design file (`fahv.spec.files.load_design_file`).
    scenario : dict
        Validated scenario entries (`command`, `fault`, `uncertainty`,
        `duration`, `variants`, `name`, `description`).
    path : str or Path
        Named in errors.

    Raises
    ------
    SpecError
        If a variant is not one the design prepared, or the run spec does not validate.
    """
    variants = list(scenario.get("variants") or design["variants"])
    extra = [v for v in variants if v not in design["variants"]]
    if extra:
        raise SpecError(
            f"{path}: key 'variants': {extra} not prepared by design {design.name!r} "
            f"(its variants: {list(design['variants'])})"
        )
    data = {k: v for k, v in design.data.items() if k not in DESIGN_ONLY_KEYS}
    data.update({k: scenario[k] for k in ("name", "description", "command", "fault",
                                          "uncertainty", "duration")})  # fmt: skip
    for key in OPTIONAL_SECTIONS:  # absent, the run spec is what it was without them
        if key in scenario:
            data[key] = scenario[key]
    if "sensor_fault" in data:  # the keys of its kind (the others' filled defaults out)
        data["sensor_fault"] = sensor_fault_used(data["sensor_fault"])
    data["variants"] = variants
    return spec_file(data, str(path))


def design_part(run_spec: SpecFile) -> SpecFile:
    """The design file of a run spec: its entries less the scenario's, its command as step.

    The inverse of `form_run_spec` for a run spec whose command is the design step.

    Raises
    ------
    SpecError
        If the result does not validate as a design file.
    """
    c = run_spec.data
    data = {k: v for k, v in c.items() if k not in SCENARIO_KEYS}
    data.update(name=c["name"], description=c["description"], variants=list(c["variants"]))
    data["design_step"] = {k: c["command"][k] for k in ("h0", "V0", "h_c", "V_c")}
    data["uncertainty"] = {"scale": c["uncertainty"]["scale"]}
    return spec_file(data, str(run_spec.path), design_spec())


def scenario_from_mapping(data, path: str | Path = "<mapping>") -> Scenario:
    """Validate a scenario mapping, load its design file and form its run spec.

    Raises
    ------
    SpecError
        Naming the file and the key at fault (scenario or design file).
    """
    v = spec_file(data, str(path), scenario_spec())
    dfile = design_file_of(path, v["design"])
    design = load_design_file(dfile)
    return Scenario(Path(path), v.data, dfile, design, form_run_spec(design, v.data, path))


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario file (`offline_design/scenarios/<name>.yaml`).

    Raises
    ------
    SpecError
        If the scenario or its design file is missing, malformed, or names a variant
        the design did not prepare.
    """
    return scenario_from_mapping(read_scenario_file(path), path)


def read_scenario_file(path: str | Path) -> Any:
    """A scenario file's content with its `extends:` chain merged in (`fahv.config.extends`).

    A base given by name is `<name>.yaml` beside the file, in the `scenarios/` folder
    beside the file's folder, then in `offline_design/scenarios/` of the working folder.

    Raises
    ------
    SpecError
        If the file or a base is missing or not YAML, or `extends` makes a cycle.
    """
    def find(name: str, folder: Path) -> list[Path]:
        return [folder / f"{name}.yaml", folder.parent / "scenarios" / f"{name}.yaml",
                Path("offline_design") / "scenarios" / f"{name}.yaml"]  # fmt: skip

    return resolve_extends(read_yaml_file(path, "scenario file"), Path(path),
                           lambda p: read_yaml_file(p, "scenario file"), find, SpecError,
                           path_keys=("design", "vehicle"))  # fmt: skip


def load_run_spec(path: str | Path) -> SpecFile:
    """The run spec of a scenario file: its design's entries with its own.

    Raises
    ------
    SpecError
        If the scenario or its design file is missing or does not validate.
    """
    return load_scenario(path).run_spec


def run_spec_data(path: str | Path) -> dict:
    """The run spec of a scenario file as plain data (lists, not tuples), to modify."""
    return json.loads(json.dumps(load_run_spec(path).data))


def certified_range(design: Design) -> dict:
    """What a stored design certifies for the scenarios flown on it.

    Returns
    -------
    dict
        `hv_box` ((2, 2) `[[h lo, V lo], [h hi, V hi]]` in ft, ft/s, the nominal range of
        the eight-state tube; None for the vertex tube, which covers the envelope),
        `rho_min` (smallest elevator effectiveness of the fault range),
        `uncertainty_scale` (the parameter box's fraction of the sec. 5.1 box), `u_lo`,
        `u_hi` ((2,) tightened input limits, eq. 30).
    """
    hv = design.arrays.get("hv_box")
    return {
        "hv_box": None if hv is None else np.asarray(hv, float),
        "rho_min": float(design.summary["tube"]["rho_f"]),
        "uncertainty_scale": float(design.summary.get("uncertainty_scale", 1.0)),
        "u_lo": np.asarray(design.arrays["u_lo"], float),
        "u_hi": np.asarray(design.arrays["u_hi"], float),
    }


def uncertified(design: Design, spec: dict, vehicle) -> list[str]:
    """What a scenario asks beyond the range its design certifies, one sentence each.

    Checks the initial point and the command against the envelope and the design's
    nominal range (`hv_box`), their trim inputs against the tightened input set
    (eq. 30), the fault's effectiveness against the fault range (`tube.rho_min`),
    the simulated vehicle's draw against the parameter box and the actuator model
    (the design assumes ideal actuators).

    Parameters
    ----------
    design : Design
        The stored design.
    spec : dict
        The run spec's data (`command`, `fault`, `uncertainty`).
    vehicle : fahv.model.vehicle.Vehicle

    Returns
    -------
    list of str
        Empty when the design certifies everything the scenario asks.
    """
    rng = certified_range(design)
    cmd, out = spec["command"], []
    tm = TrimMap(*(design.arrays[k] for k in ("trim_h", "trim_V", "trim_x", "trim_u")))
    for what, h, V in (("initial point", cmd["h0"], cmd["V0"]),
                       ("command", cmd["h_c"], cmd["V_c"])):  # fmt: skip
        if not vehicle.envelope.contains(h, V):
            env = vehicle.envelope
            out.append(f"the {what} ({h:g} ft, {V:g} ft/s) lies outside the flight envelope, "
                       f"h {env.h_min:g}..{env.h_max:g} ft, V {env.V_min:g}..{env.V_max:g} ft/s")
            continue
        hv = rng["hv_box"]
        if hv is not None and not (hv[0, 0] <= h <= hv[1, 0] and hv[0, 1] <= V <= hv[1, 1]):
            out.append(
                f"the {what} ({h:g} ft, {V:g} ft/s) lies outside the nominal range the tube "
                f"is certified for, h {hv[0, 0]:.0f}..{hv[1, 0]:.0f} ft, V "
                f"{hv[0, 1]:.2f}..{hv[1, 1]:.2f} ft/s"
            )
        u = tm(h, V)[1]
        if np.any(u < rng["u_lo"]) or np.any(u > rng["u_hi"]):
            out.append(
                f"the trim input at the {what} (Phi {u[0]:.4f}, delta_e "
                f"{np.degrees(u[1]):.3f} deg) lies outside the tightened input set "
                f"Phi {rng['u_lo'][0]:.4f}..{rng['u_hi'][0]:.4f}, delta_e "
                f"{np.degrees(rng['u_lo'][1]):.3f}..{np.degrees(rng['u_hi'][1]):.3f} deg"
            )
    f = spec["fault"]
    eff = make_fault(f["kind"], f["t_onset"], f).design_effectiveness()
    if eff < rng["rho_min"] - 1e-12:
        out.append(
            f"loss {round(100 * (1 - eff), 2):g} % above the certified "
            f"{round(100 * (1 - rng['rho_min']), 2):g} % (elevator effectiveness {eff:g} below "
            f"the design's fault range rho_f in [{rng['rho_min']:g}, 1])"
        )
    if spec["uncertainty"]["scale"] > rng["uncertainty_scale"] + 1e-12:
        out.append(
            f"the vehicle draw's uncertainty scale {spec['uncertainty']['scale']:g} exceeds the "
            f"design's parameter box ({rng['uncertainty_scale']:g} of the sec. 5.1 box)"
        )
    if flies_its_estimate_design(spec):
        return out  # the estimate design's claims cover the servos and the estimate
    if actuator_model(spec) != "ideal":
        out.append(
            f"the actuator model {actuator_model(spec)!r} (plant.actuators) is not in the "
            "design model: the tube and the nominal ellipsoid are certified for ideal actuators"
        )
    if estimator_kind(spec) != NO_ESTIMATOR:
        out.append(
            f"the estimator {estimator_kind(spec)!r} (estimator.kind): the tube is certified "
            "for a controller that reads the exact state; the estimation error is not in it"
        )
    return out


def flies_its_estimate_design(spec: dict) -> bool:
    """Whether a run spec flies the loop its design's `estimate` section was made for.

    The plant's servos and the filter's are the section's `actuators`, the filter is the
    Kalman filter with its `state_disturbance` on the default sensors, and the scenario
    does not replace the tube law's factor (`estimator.tube_tau`) or widen the nominal's
    attitude rows: the design's probabilistic claims (`fahv.design.estimate`) are then
    about this run.

    Examples
    --------
    >>> est = {"actuators": "second_order", "state_disturbance": "none"}
    >>> run = {"estimate": est, "plant": {"actuators": "second_order"},
    ...        "estimator": {"kind": "kalman", "actuators": "second_order"}}
    >>> flies_its_estimate_design(run), flies_its_estimate_design({**run, "estimate": None})
    (True, False)
    """
    est = spec.get("estimate")
    if not est or estimator_kind(spec) == NO_ESTIMATOR:
        return False
    measured = plant_choices(spec)["measured"]
    return (actuator_model(spec) == est["actuators"]
            and estimator_value(spec, "actuators") == est["actuators"]
            and estimator_value(spec, "state_disturbance") == est["state_disturbance"]
            and float(estimator_value(spec, "tube_tau")) == 0.0
            and measured_channels(measured) == list(DEFAULT_MEASURED)
            and (spec.get("sensor_fault") or {}).get("kind", "none") == "none")


def _steps_equal(spec: dict, design: Design) -> bool:
    step = design.summary.get("design_step")
    cmd = spec["command"]
    return step is not None and all(
        float(cmd[k]) == float(step[k]) for k in ("h0", "V0", "h_c", "V_c")
    )


def scenario_key(design: Design, spec: dict) -> str:
    """Content hash of what a scenario's own arrays depend on (16 hex characters)."""
    text = json.dumps(
        {"design": design.summary["design_hash"], "command": spec["command"],
         "variants": spec["variants"]}, sort_keys=True, default=str,
    )  # fmt: skip
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def scenario_arrays(
    design: Design, spec: dict, vehicle, cache: Path | None, log=print, variants=None
) -> dict:
    """The arrays of a run that depend on its scenario.

    `x0` (9,): the trim at (h0, V0) from the design's trim map. When the scenario runs
    the RMPC baseline on another step than the design step, the baseline's ellipsoids
    (`rmpc_*`) are designed along the scenario's step (its offline LMIs, Wan & Kothare
    2003) and cached in `cache` by `scenario_key`; only when one of `variants`
    (all of the run spec's by default) runs the baseline.

    Raises
    ------
    DesignError
        If the baseline's ellipsoids cannot be designed for the scenario's step.
    """
    a = design.arrays
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    cmd = spec["command"]
    out = {"x0": np.asarray(tm(cmd["h0"], cmd["V0"])[0][:9], float)}
    laws = dict.fromkeys(VARIANTS[v].law for v in (variants or spec["variants"]))
    if "rmpc" not in laws or _steps_equal(spec, design):
        return out
    key = scenario_key(design, spec)
    path = None if cache is None else Path(cache) / f"{key}.npz"
    if path is not None and path.is_file():
        out.update(load_arrays(path))
        return out
    log("baseline rmpc: its ellipsoids along this scenario's step (not the design step)")
    ctx = DesignContext(spec, vehicle, {**a, **out}, log)
    rmpc = LAWS["rmpc"].design(ctx)
    if path is not None:
        save_arrays(rmpc, path)
    out.update(rmpc)
    return out


def scenario_params(vehicle, uncertainty: dict) -> dict[str, float]:
    """The simulated vehicle's uncertain parameters {name: value} of a scenario.

    `uncertainty.s` given: p (1 + s_p scale rel_p) with those s_p (in the order of
    `fahv.plant.uncertainty.PAPER_UNCERTAINTY`); else the seeded draw
    (`fahv.plant.uncertainty.perturbed_params`).
    """
    if not uncertainty.get("s"):
        return perturbed_params(vehicle, uncertainty["seed"], uncertainty["scale"])
    rel = {k: r * float(uncertainty["scale"]) for k, r in PAPER_UNCERTAINTY.items()}
    vp = perturb(vehicle.params, rel, dict(zip(PAPER_UNCERTAINTY, uncertainty["s"], strict=True)))
    return {k: float(getattr(vp, k)) for k in PAPER_UNCERTAINTY}


def scenario_design(
    design: Design,
    run_spec: SpecFile,
    vehicle,
    cache: Path | None = None,
    log=print,
    variants=None,
) -> Design:
    """A stored design with one scenario's run spec and arrays: what a run is given.

    Parameters
    ----------
    design : Design
        The stored, verified design.
    run_spec : SpecFile
        The scenario's run spec (`Scenario.run_spec`).
    vehicle : fahv.model.vehicle.Vehicle
        The nominal vehicle (its parameters are perturbed by the scenario's draw).
    cache : Path, optional
        Folder of the scenario arrays designed earlier (`scenario_arrays`).
    variants : list of str, optional
        The variants that will run (all of the run spec's by default): the baseline's
        ellipsoids along a new step are designed only if one of them runs it.

    Returns
    -------
    Design
        `case`: the run spec's data; `arrays`: the design's with the scenario's;
        `summary`: the design's, with `plant_params` of the vehicle draw,
        `scenario_hash` and `content_hash` (of this run's design, checked by
        `fahv.spec.artefacts.load_design`). `summary['design_hash']` stays the
        stored design's.
    """
    c = run_spec.data
    arrays = {**design.arrays, **scenario_arrays(design, c, vehicle, cache, log, variants)}
    summary = {
        **design.summary,
        "plant_params": scenario_params(vehicle, c["uncertainty"]),
        "scenario_hash": run_spec.content_hash(),
    }
    run = Design(c, arrays, summary)
    run.summary["content_hash"] = run.content_hash()
    return run
