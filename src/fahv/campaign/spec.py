"""Campaign files: a scenario, its dispersions, the variants, the requirements.

Declared once in the configuration language (`fahv.config`), validated once by
`load_campaign`; every error names the file and the dotted key, e.g.
`mc.yaml: key 'dispersions.fault.loss' must be in [0, 1), got 1.2`. A range is a
list `[low, high]` (uniform draw, `low == high` fixes the value); an absent range
leaves the scenario's value. The generated key table is in docs/reference/configuration.md.

Checks beyond the field ranges (made here, with the run spec and the vehicle at hand):
`low <= high`; the variants are among the scenario's; every fault kind drawn has its
size and onset (from the campaign or the scenario); initial trims and commanded points
stay inside the vehicle's flight envelope for every value of their ranges.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fahv.config import Check, Field, Section, validate
from fahv.config.extends import resolve_extends
from fahv.control import VARIANTS
from fahv.errors import CampaignError, SpecError
from fahv.model.actuators import IDEAL
from fahv.model.vehicle import load_vehicle
from fahv.plant.faults import FAULTS
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.sensors.data import EXACT_STATE
from fahv.spec.files import SpecFile, read_yaml_file
from fahv.spec.requirements import REQUIREMENT_FIELDS
from fahv.spec.scenario import load_scenario
from fahv.spec.schema import plant_choices

#: Ways to draw the uncertain parameters of sec. 5.1.
METHODS = ("uniform", "corners", "lhs", "none")


def _range(name: str, description: str, unit: str = "", **kw) -> Field:
    return Field(name, "floats", description, unit=unit, length=2, default=(), **kw)


def _ordered(section: str, key: str) -> Check:
    def ok(root) -> bool:
        v = root["dispersions"][section][key]
        return not v or v[0] <= v[1]

    return Check(key, ok, "must be [low, high] with low <= high")


def _uncertainty_section() -> Section:
    """The campaign file's `dispersions.uncertainty` section."""
    return Section(
        "uncertainty",
        (
            Field("method", "str", "uniform in the box, its corners (index bits), a Latin "
                  "hypercube over the campaign (scipy.stats.qmc), or none (the scenario's draw)",
                  choices=METHODS, default="uniform"),
            Field("scale", "float", "fraction of the sec. 5.1 parameter box", lo=0.0, hi=1.0,
                  default=1.0),
            Field("parameters", "strs", "uncertain parameters drawn (the others nominal)",
                  choices=tuple(PAPER_UNCERTAINTY), default=tuple(PAPER_UNCERTAINTY)),
        ),
        "plant parameters p (1 + s_p scale rel_p), s_p in [-1, 1] (sec. 5.1)",
    )  # fmt: skip


def _fault_section() -> Section:
    """The campaign file's `dispersions.fault` section (kinds from the fault registry)."""
    return Section(
        "fault",
        (
            Field("kinds", "strs", "fault kinds drawn with equal probability (empty: the "
                  "scenario's kind)", choices=FAULTS.names, default=()),
            _range("onset", "fault onset time range", "s", lo=0.0),
            _range("loss", "elevator loss of effectiveness 1 - rho_f range", lo=0.0, hi=1.0,
                   hi_open=True, equation="eq. (15)"),
            _range("bias_deg", "elevator bias range", "deg", lo=-30.0, hi=30.0),
        ),
        "actuator fault of the plant (the design keeps the scenario's fault)",
        checks=(_ordered("fault", "onset"), _ordered("fault", "loss"),
                _ordered("fault", "bias_deg")),
    )  # fmt: skip


def _command_section() -> Section:
    """The campaign file's `dispersions.command` section."""
    return Section(
        "command",
        (
            _range("dh", "altitude step h_c - h0 range (negative: descent)", "ft",
                   lo=-2e5, hi=2e5),
            _range("dV", "velocity step V_c - V0 range (negative: slow down)", "ft/s",
                   lo=-2e4, hi=2e4),
        ),
        "command step sizes and directions (kept inside the envelope)",
        checks=(_ordered("command", "dh"), _ordered("command", "dV")),
    )  # fmt: skip


def _initial_section() -> Section:
    """The campaign file's `dispersions.initial` section."""
    return Section(
        "initial",
        (
            _range("h0", "initial trim altitude range", "ft", lo=0.0, hi=2e5),
            _range("V0", "initial trim velocity range", "ft/s", lo=0.0, hi=2e4),
        ),
        "initial trim point (the plant starts at the trim there)",
        checks=(_ordered("initial", "h0"), _ordered("initial", "V0")),
    )  # fmt: skip


def _actuators_section() -> Section:
    """The campaign file's `dispersions.actuators` section (factors on the vehicle file's)."""
    return Section(
        "actuators",
        (
            _range("omega_n", "factor on the natural frequency omega_n of both servos",
                   lo=0.0, lo_open=True, hi=100.0),
            _range("zeta", "factor on the damping ratio zeta of both servos", lo=0.0, hi=100.0),
            _range("rate_limit", "factor on the rate limits of both servos", lo=0.0,
                   lo_open=True, hi=100.0),
        ),
        "the simulated plant's servos (scenario plant.actuators second_order); the Kalman "
        "filter keeps the vehicle file's",
        checks=tuple(_ordered("actuators", k) for k in ("omega_n", "zeta", "rate_limit")),
    )  # fmt: skip


def _sensors_section() -> Section:
    """The campaign file's `dispersions.sensors` section (factors on the vehicle file's)."""
    return Section(
        "sensors",
        (
            _range("stddev", "factor on every measured channel's white-noise stddev",
                   lo=0.0, hi=100.0),
            _range("bias_stddev", "factor on every measured channel's turn-on bias stddev",
                   lo=0.0, hi=100.0),
            _range("bias_mean", "shift of every measured channel's turn-on bias mean, in its "
                   "white-noise stddevs", lo=-100.0, hi=100.0),
        ),
        "the simulated plant's sensors (a scenario with an estimator); the Kalman filter "
        "keeps the vehicle file's",
        checks=tuple(_ordered("sensors", k) for k in ("stddev", "bias_stddev", "bias_mean")),
    )  # fmt: skip


def _requirements_section() -> Section:
    """The campaign file's `requirements` section: a scenario's limits and a confidence."""
    return Section(
        "requirements",
        (
            *REQUIREMENT_FIELDS,
            Field("confidence", "float", "confidence C of the failure-probability bounds",
                  lo=0.0, hi=1.0, lo_open=True, hi_open=True, default=0.95),
        ),
        "requirement verdicts of the report (fahv.spec.requirements)",
    )  # fmt: skip


def campaign_spec() -> Section:
    """The campaign-file declaration (fault kinds and variants from their registries).

    The schema reads top to bottom as the file does; each dispersion and the
    requirements are sections of their own (`_uncertainty_section` ...).
    """
    return Section(
        "",
        (
            Field("name", "str", "campaign name (default folder campaigns/<name>)"),
            Field("description", "str", "what the campaign is", default=""),
            Field("scenario", "str", "scenario file, relative to the campaign file (or a "
                  "name in offline_design/scenarios/); fahv campaign --scenario overrides it"),
            Field("seed", "int", "campaign seed: run i draws from SeedSequence(seed, "
                  "spawn_key=(i, stream))", lo=0),
            Field("runs", "int", "number of dispersed samples (each run with every variant)",
                  lo=1, hi=1_000_000),
            Field("variants", "strs", "variants run on every sample (among the scenario's)",
                  choices=VARIANTS.names),
            Field("duration", "float", "simulated time of each run (0: the scenario's)", unit="s",
                  lo=0.0, default=0.0),
            Field("batch_size", "int", "runs per Dask task (simulated together)", lo=1,
                  hi=10_000, default=50),
            Section("dispersions", (_uncertainty_section(), _fault_section(),
                                     _command_section(), _initial_section(),
                                     _actuators_section(), _sensors_section()),
                    "what varies from run to run"),
            _requirements_section(),
        ),
        "campaign file",
    )  # fmt: skip


@dataclass(frozen=True)
class Campaign:
    """A validated campaign file.

    Attributes
    ----------
    path : Path
        File it was read from.
    data : dict
        Validated content, defaults filled in (see `campaign_spec`).
    run_spec : fahv.spec.files.SpecFile
        The run spec of the scenario file it names.
    vehicle : fahv.model.vehicle.Vehicle
        The vehicle its envelope and range checks used (`--vehicle`, or the packaged
        one).
    """

    path: Path
    data: dict
    run_spec: SpecFile
    vehicle: Any

    def __getitem__(self, key: str):
        """Top-level entry of the campaign."""
        return self.data[key]

    @property
    def name(self) -> str:
        """Campaign name."""
        return self.data["name"]

    @property
    def duration(self) -> float:
        """Simulated time of each run [s] (the scenario's when the file says 0)."""
        return float(self.data["duration"] or self.run_spec["duration"])

    @property
    def warnings(self) -> list[str]:
        """What the campaign does that its author may not expect (`fahv campaign` prints it).

        Fault onsets drawn (or the scenario's onset) beyond the run's duration: those runs
        end before their fault, i.e. without one.
        """
        out = self._beyond_design()
        f, cf, d = self.data["dispersions"]["fault"], self.run_spec["fault"], self.duration
        kinds = f["kinds"] or [cf["kind"]]
        if all(k == "none" for k in kinds):
            return out
        lo, hi = f["onset"] or (cf["t_onset"], cf["t_onset"])
        if hi >= d:
            share = 1.0 if lo >= d else (hi - d) / (hi - lo)
            where = (
                f"dispersions.fault.onset [{lo:g}, {hi:g}] s"
                if f["onset"]
                else f"the scenario's fault onset {lo:g} s"
            )
            out.append(
                f"{self.path}: {where} reaches beyond the run's duration {d:g} s: "
                f"{100.0 * share:.0f} % of the runs end before their fault (no fault in them)"
            )
        return out

    def _beyond_design(self) -> list[str]:
        """Draws beyond the fault range and nominal range the scenario's design certifies."""
        out = []
        rho_min = float(self.run_spec["tube"]["rho_min"])
        f = self.data["dispersions"]["fault"]
        kinds = f["kinds"] or [self.run_spec["fault"]["kind"]]
        if "loss_of_effectiveness" in kinds and f["loss"]:
            if f["loss"][1] > 1.0 - rho_min + 1e-12:
                out.append(
                    f"{self.path}: dispersions.fault.loss {list(f['loss'])} reaches beyond the "
                    f"design's fault range (losses up to {100 * (1 - rho_min):.0f} %, "
                    f"tube.rho_min {rho_min:g}): those runs are not covered by its certificate"
                )
        if self.run_spec["tube"]["form"] == "eight_state":
            out += self._beyond_nominal_range()
        return out

    def _beyond_nominal_range(self) -> list[str]:
        """Initial points and commands drawn beyond the eight-state tube's nominal range."""
        from fahv.bounds.domain import nominal_box

        nominal, _ = nominal_box(self.run_spec["eight_state"], self.vehicle.envelope)
        lo, hi = nominal.lo[:2], nominal.hi[:2]
        cmd, d = self.run_spec["command"], self.data["dispersions"]
        h0 = d["initial"]["h0"] or [cmd["h0"]] * 2
        V0 = d["initial"]["V0"] or [cmd["V0"]] * 2
        h_c = [h0[0] + d["command"]["dh"][0], h0[1] + d["command"]["dh"][1]] if d["command"][
            "dh"] else [cmd["h_c"]] * 2  # fmt: skip
        V_c = [V0[0] + d["command"]["dV"][0], V0[1] + d["command"]["dV"][1]] if d["command"][
            "dV"] else [cmd["V_c"]] * 2  # fmt: skip
        out = []
        for what, (a, b), i, unit in (("initial h0", h0, 0, "ft"), ("initial V0", V0, 1, "ft/s"),
                                      ("commanded h_c", h_c, 0, "ft"),
                                      ("commanded V_c", V_c, 1, "ft/s")):  # fmt: skip
            if min(a, b) < lo[i] - 1e-9 or max(a, b) > hi[i] + 1e-9:
                out.append(
                    f"{self.path}: the {what} drawn in [{min(a, b):g}, {max(a, b):g}] {unit} "
                    f"reaches beyond the nominal range the design certifies, [{lo[i]:g}, "
                    f"{hi[i]:g}] {unit}: such runs are not covered by its certificate (the QP "
                    "keeps the set point on the range's edge)"
                )
        return out

    def content_hash(self) -> str:
        """sha256 of the campaign and run spec content (defaults included), 16 hex characters."""
        text = json.dumps({"campaign": self.data, "case": self.run_spec.data}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def _fail(source: str, key: str, message: str) -> CampaignError:
    return CampaignError(f"{source}: key '{key}' {message}")


def check_campaign(data: dict, run_spec: SpecFile, source: str, vehicle=None) -> None:
    """Cross-checks of a validated campaign against its run spec and the vehicle.

    Raises
    ------
    CampaignError
        Naming the key: a variant the run spec does not run, a fault kind without size or
        onset, an initial trim or commanded point outside the flight envelope.
    """
    veh = load_vehicle() if vehicle is None else vehicle
    for v in data["variants"]:
        if v not in run_spec["variants"]:
            raise _fail(source, "variants", f"names '{v}', which the scenario {run_spec.name} "
                        f"does not run (its variants: {run_spec['variants']})")  # fmt: skip
    f, cf = data["dispersions"]["fault"], run_spec["fault"]
    kinds = f["kinds"] or [cf["kind"]]
    if any(k != "none" for k in kinds) and not f["onset"] and not math.isfinite(cf["t_onset"]):
        raise _fail(
            source, "dispersions.fault.onset", "is needed: the scenario's fault has no onset"
        )
    for kind, key in (("loss_of_effectiveness", "loss"), ("bias", "bias_deg")):
        if kind in kinds and not f[key] and cf["kind"] != kind:
            msg = f"is needed for fault kind '{kind}' (the scenario's fault is '{cf['kind']}')"
            raise _fail(source, f"dispersions.fault.{key}", msg)
    env, cmd = veh.envelope, run_spec["command"]
    init, dc = data["dispersions"]["initial"], data["dispersions"]["command"]
    h0s = init["h0"] or [cmd["h0"]]
    V0s = init["V0"] or [cmd["V0"]]
    for key, vals, lo, hi in (("initial.h0", h0s, env.h_min, env.h_max),
                              ("initial.V0", V0s, env.V_min, env.V_max)):  # fmt: skip
        if min(vals) < lo or max(vals) > hi:
            raise _fail(source, f"dispersions.{key}", f"must stay inside the flight envelope "
                        f"[{lo}, {hi}], got {vals}")  # fmt: skip
    for key, starts, steps, spec_end, lo, hi in (
        ("dh", h0s, dc["dh"], cmd["h_c"], env.h_min, env.h_max),
        ("dV", V0s, dc["dV"], cmd["V_c"], env.V_min, env.V_max),
    ):
        ends = [s + d for s in starts for d in steps] if steps else [spec_end]
        if min(ends) < lo or max(ends) > hi:
            raise _fail(source, f"dispersions.command.{key}", f"takes the command outside the "
                        f"flight envelope [{lo}, {hi}]: commanded values {min(ends)} to "
                        f"{max(ends)}")  # fmt: skip
    _check_hardware(data["dispersions"], run_spec, source)


def _check_hardware(d: dict, run_spec: SpecFile, source: str) -> None:
    """Servo and sensor dispersions need servos and sensors in the scenario's plant."""
    plant = plant_choices(run_spec.data)
    if any(d["actuators"].values()) and plant["actuators"] == IDEAL:
        key = next(k for k, v in d["actuators"].items() if v)
        raise _fail(source, f"dispersions.actuators.{key}", f"disperses servos, but the "
                    f"scenario {run_spec.name} flies ideal actuators "
                    "(plant.actuators)")  # fmt: skip
    if any(d["sensors"].values()) and plant["measured"] == EXACT_STATE:
        key = next(k for k, v in d["sensors"].items() if v)
        raise _fail(source, f"dispersions.sensors.{key}", f"disperses sensors, but the "
                    f"scenario {run_spec.name} reads the exact state (plant.measured)")  # fmt: skip


def campaign_from_mapping(data, source: str = "<mapping>", run_spec: SpecFile | None = None,
                          base: Path | None = None, vehicle=None) -> Campaign:  # fmt: skip
    """Validate a campaign mapping and load (or take) its scenario's run spec.

    Parameters
    ----------
    data : Mapping
        Parsed campaign file.
    source : str
        Name used in messages.
    run_spec : SpecFile, optional
        The scenario's run spec, when already loaded (otherwise that of the scenario file
        `data['scenario']`, relative to `base`).
    base : Path, optional
        Folder the scenario path is relative to (the campaign file's folder).
    vehicle : fahv.model.vehicle.Vehicle, optional
        For the envelope checks (the packaged vehicle by default).

    Raises
    ------
    CampaignError
        Naming the source and the dotted key (unknown key, out of range, wrong
        type, missing, cross-check); a scenario that does not load is reported under
        the key `scenario`.
    """
    v = validate(campaign_spec(), data, source, CampaignError)
    named = None  # the vehicle file the scenario names
    if run_spec is None:
        path = scenario_path(v.values["scenario"], base)
        try:
            scenario = load_scenario(path)
        except SpecError as exc:
            raise _fail(source, "scenario", f"names a scenario that does not load: {exc}") from None
        run_spec, named = scenario.run_spec, scenario.vehicle_file
    vehicle = load_vehicle(named) if vehicle is None else vehicle
    values = _scenario_limits(v.values, v.defaults_used, run_spec)
    check_campaign(values, run_spec, source, vehicle)
    return Campaign(Path(source), values, run_spec, vehicle)


def _scenario_limits(values: dict, defaults_used: dict, run_spec: SpecFile) -> dict:
    """The campaign's requirements: the limits it sets, the scenario's where it sets none.

    A limit the campaign file leaves out takes its scenario's `requirements` value (the
    paper's when the scenario sets none either), so a scenario's runs are judged alike
    alone and in a campaign.
    """
    own = run_spec.data.get("requirements") or {}
    req = dict(values["requirements"])
    for f in REQUIREMENT_FIELDS:
        if f"requirements.{f.name}" in defaults_used and f.name in own:
            req[f.name] = own[f.name]
    return {**values, "requirements": req}


def scenario_path(name: str, base: Path | None = None) -> Path:
    """A campaign's scenario: a path relative to `base`, or a scenario's name.

    A name (no `.yaml`) is looked up in the `scenarios/` folder beside the campaign's
    folder (`offline_design/campaigns/x.yaml` -> `offline_design/scenarios/<name>.yaml`),
    then in `offline_design/scenarios/` of the working folder, then in the project's own
    (`fahv.sil.workspace.ROOT`): a campaign file that names its scenario runs from
    wherever it is copied, started from wherever.
    """
    from fahv.sil.workspace import ROOT

    p = Path(base or ".") / name
    if p.suffix or p.is_file():
        return p
    tries = [Path(base or ".").parent / "scenarios" / f"{name}.yaml",
             Path("offline_design") / "scenarios" / f"{name}.yaml",
             ROOT / "offline_design" / "scenarios" / f"{name}.yaml"]  # fmt: skip
    return next((t for t in tries if t.is_file()), tries[-1])


def _read(path: Path) -> Any:
    """A campaign file's YAML content (`fahv.spec.files.read_yaml_file`).

    Raises
    ------
    CampaignError
        If the file is missing or not YAML (with the line of the error).
    """
    return read_yaml_file(path, "campaign file", CampaignError)


def _campaign_candidates(name: str, folder: Path) -> list[Path]:
    """Where `extends: <name>` of a campaign file is looked for, from its folder."""
    return [folder / f"{name}.yaml", folder.parent / "campaigns" / f"{name}.yaml",
            Path("offline_design") / "campaigns" / f"{name}.yaml"]  # fmt: skip


def load_campaign(path: str | Path, vehicle=None, scenario: str | None = None,
                  runs: int | None = None, duration: float | None = None) -> Campaign:  # fmt: skip
    """Read and validate a campaign file (and its scenario file).

    `scenario` (a path or a name in offline_design/scenarios/) replaces the file's
    own `scenario`: the same dispersions around another scenario or design. `runs` and
    `duration` [s] replace the file's (`fahv campaign FILE --runs N --duration S`: the
    first N draws of the same campaign, each run S seconds long), validated as the file's.

    Raises
    ------
    CampaignError
        If the file is missing, not YAML, or does not validate (naming the key).
    """
    p = Path(path)
    if not p.is_file():
        raise CampaignError(f"campaign file not found: {p}")
    data = resolve_extends(_read(p), p, _read, _campaign_candidates, CampaignError,
                           path_keys=("scenario",))  # fmt: skip
    if isinstance(data, dict):
        sized = {k: v for k, v in (("runs", runs), ("duration", duration)) if v is not None}
        data = {**data, **sized}
    if scenario is not None and isinstance(data, dict):
        data = {
            **data,
            "scenario": str(Path(scenario).resolve()) if Path(scenario).suffix else scenario,
        }
    return campaign_from_mapping(data, str(p), base=p.parent, vehicle=vehicle)
