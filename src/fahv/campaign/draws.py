"""The dispersed values of run i, a function of (campaign seed, i) only, and their overrides.

Random streams: run `i` draws each group of values from its own generator
`numpy.random.default_rng(SeedSequence(seed, spawn_key=(i, stream)))` (stream 0:
uncertainty, 1: fault, 2: command, 3: initial trim), i.e. the `i`-th child of the
campaign's seed sequence (`numpy.random.SeedSequence.spawn` gives the same
children), split once more by group. So a run's values do not depend on which other
runs exist, in which order or on which worker they run, and adding a dispersion group
to a campaign file does not change the values of the others.

Uncertainty (sec. 5.1): p = p_nominal (1 + s_p scale rel_p) for each drawn parameter
p (`fahv.plant.uncertainty.PAPER_UNCERTAINTY`), with s_p

- `uniform`: s_p ~ U(-1, 1), independent;
- `corners`: s_p = +1 if bit j of (i mod 2^d) is set, else -1 (parameter j of the
  list, d parameters): runs 0 .. 2^d - 1 visit every corner of the box once;
- `lhs`: row i of a scrambled Latin hypercube of `runs` points in d dimensions
  (`scipy.stats.qmc.LatinHypercube`, generator `SeedSequence(seed,
  spawn_key=(2^32 - 1,))`), mapped to [-1, 1]; a run's values depend on the
  campaign's `runs` as well, as every stratified design does.

Fault, command and initial trim: each range is drawn uniformly (one uniform number
each, always drawn, so that the stream does not depend on the fault kind drawn); the
fault kind with equal probability among `kinds`.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.stats import qmc

from fahv.loop.params import node_parameters, stuck_parameters
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY, perturb
from fahv.sensors.data import EXACT_STATE
from fahv.spec.schema import plant_choices

#: Random stream of each group of dispersed values.
STREAMS = {"uncertainty": 0, "fault": 1, "command": 2, "initial": 3, "actuators": 4,
           "sensors": 5}
#: Plant parameter (`fahv.spec.plant_dispersion`) of each actuator and sensor dispersion.
HARDWARE = {
    "actuators": {"omega_n": "servo_omega_n_factor", "zeta": "servo_zeta_factor",
                  "rate_limit": "servo_rate_limit_factor"},
    "sensors": {"stddev": "sensor_stddev_factor", "bias_stddev": "sensor_bias_stddev_factor",
                "bias_mean": "sensor_bias_mean_shift"},
}  # fmt: skip
#: spawn_key of the campaign-wide Latin hypercube.
LHS_KEY = 2**32 - 1


def run_rng(seed: int, index: int, stream: str) -> np.random.Generator:
    """Generator of one group of values of run `index` (see the module notes)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, STREAMS[stream])))


def run_seed(seed: int, index: int) -> int:
    """First 32-bit word of run `index`'s seed sequence (recorded, for reference)."""
    ss = np.random.SeedSequence(seed, spawn_key=(index,))
    return int(ss.generate_state(1, np.uint32)[0])


@functools.lru_cache(maxsize=8)
def _lhs(seed: int, runs: int, d: int) -> np.ndarray:
    """The campaign's Latin hypercube in [-1, 1]^d, (runs, d)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(LHS_KEY,)))
    return 2.0 * qmc.LatinHypercube(d, rng=rng).random(runs) - 1.0


def dispersed_groups(data: dict) -> list[str]:
    """Groups a campaign disperses, in stream order (uncertainty, ..., actuators, sensors)."""
    d = data["dispersions"]
    out = []
    if d["uncertainty"]["method"] != "none":
        out.append("uncertainty")
    if any(d["fault"][k] for k in ("kinds", "onset", "loss", "bias_deg")):
        out.append("fault")
    if d["command"]["dh"] or d["command"]["dV"]:
        out.append("command")
    if d["initial"]["h0"] or d["initial"]["V0"]:
        out.append("initial")
    out += [group for group in HARDWARE if any(d[group].values())]
    return out


def _uniform(rng: np.random.Generator, rng_range, default: float) -> float:
    """Value lo + (hi - lo) u, u ~ U[0, 1) (always drawn); `default` if the range is empty."""
    u = float(rng.random())
    if not rng_range:
        return float(default)
    lo, hi = rng_range
    return float(lo + (hi - lo) * u)


def draw(data: dict, case: dict, index: int) -> dict:
    """The dispersed values of run `index` (columns of the results table).

    Parameters
    ----------
    data : dict
        Validated campaign (`fahv.campaign.spec.campaign_spec`).
    case : dict
        Validated data of its case.
    index : int
        Run index in [0, runs).

    Returns
    -------
    dict
        Per dispersed group: `s.<p>` (s_p in [-1, 1]) of the drawn uncertain
        parameters; `fault.kind`, `fault.t_onset` [s], `fault.loss`,
        `fault.rho_f`, `fault.bias_deg` [deg]; `command.dh` [ft], `command.dV`
        [ft/s], `command.h_c`, `command.V_c`; `initial.h0` [ft], `initial.V0`
        [ft/s]; `actuators.omega_n`, `actuators.zeta`, `actuators.rate_limit`
        (factors on the servos'), `sensors.stddev`, `sensors.bias_stddev` (factors on
        the sensors'), `sensors.bias_mean` [stddevs]; `sensor_seed` (the run's seed of
        the sensors' noise, `run_seed`)
        when the case's plant measures through noisy sensors (an estimator reads
        them), so that every run draws its own noise.

    Raises
    ------
    ValueError
        If `index` is outside [0, runs).
    """
    if not 0 <= index < data["runs"]:
        raise ValueError(f"run index must be in [0, {data['runs']}), got {index}")
    seed, d = data["seed"], data["dispersions"]
    groups = dispersed_groups(data)
    point: dict = {}
    if "uncertainty" in groups:
        u = d["uncertainty"]
        names = list(u["parameters"])
        if u["method"] == "uniform":
            s = run_rng(seed, index, "uncertainty").uniform(-1.0, 1.0, len(names))
        elif u["method"] == "corners":
            corner = index % (2 ** len(names))
            s = np.array([1.0 if (corner >> j) & 1 else -1.0 for j in range(len(names))])
        else:
            s = _lhs(seed, data["runs"], len(names))[index]
        point.update({f"s.{k}": float(v) for k, v in zip(names, s, strict=True)})
    defaults = point_defaults(data, case)
    if "fault" in groups:
        f = d["fault"]
        rng = run_rng(seed, index, "fault")
        kinds = fault_kinds(data, case)
        point["fault.kind"] = kinds[int(rng.integers(len(kinds)))]
        for key, name in (("onset", "fault.t_onset"), ("loss", "fault.loss"),
                          ("bias_deg", "fault.bias_deg")):  # fmt: skip
            point[name] = _uniform(rng, f[key], defaults[name])
    for group, keys in (("initial", ("h0", "V0")), ("command", ("dh", "dV"))):
        if group in groups:
            rng = run_rng(seed, index, group)
            point.update({f"{group}.{k}": _uniform(rng, d[group][k], defaults[f"{group}.{k}"])
                          for k in keys})  # fmt: skip
    for group, keys in HARDWARE.items():
        if group in groups:  # every factor drawn, the absent ones at the scenario's value
            rng = run_rng(seed, index, group)
            point.update({f"{group}.{k}": _uniform(rng, d[group][k], defaults[f"{group}.{k}"])
                          for k in keys})  # fmt: skip
    if plant_choices(case)["measured"] != EXACT_STATE:
        point["sensor_seed"] = run_seed(seed, index)
    return values_at(data, case, point)


def fault_kinds(data: dict, case: dict) -> list[str]:
    """The fault kinds a campaign disperses (the scenario's kind when it names none)."""
    return list(data["dispersions"]["fault"]["kinds"] or [case["fault"]["kind"]])


def point_defaults(data: dict, case: dict) -> dict:
    """The scenario's value of every dispersible value of a point (`values_at`).

    `fault.t_onset` [s], `fault.loss`, `fault.bias_deg` [deg], `initial.h0` [ft],
    `initial.V0` [ft/s], `command.dh` [ft], `command.dV` [ft/s], and the factors and
    shift of `HARDWARE` (`<group>.<key>`), from the campaign's scenario data `case`.
    """
    cmd, cf, plant = case["command"], case["fault"], plant_choices(case)
    out = {"fault.t_onset": cf["t_onset"], "fault.loss": 1.0 - cf.get("rho_f", 1.0),
           "fault.bias_deg": cf.get("bias_deg", 0.0), "initial.h0": cmd["h0"],
           "initial.V0": cmd["V0"], "command.dh": cmd["h_c"] - cmd["h0"],
           "command.dV": cmd["V_c"] - cmd["V0"]}  # fmt: skip
    for group, keys in HARDWARE.items():
        out.update({f"{group}.{k}": plant[name] for k, name in keys.items()})
    return out


def values_at(data: dict, case: dict, point: dict) -> dict:
    """The dispersed values of a run (`draw`'s form) at a point of the dispersion space.

    Parameters
    ----------
    data : dict
        Validated campaign.
    case : dict
        Validated data of its scenario.
    point : dict
        `s.<p>` of the dispersed parameters; `fault.kind`, `fault.t_onset`,
        `fault.loss`, `fault.bias_deg` when faults are dispersed; `initial.h0`,
        `initial.V0`, `command.dh`, `command.dV` and the `HARDWARE` values of the
        groups dispersed (`dispersed_groups`); `sensor_seed` where the scenario
        measures through sensors. A value the group disperses must be given; the
        ones the campaign does not range keep the scenario's (`point_defaults`).

    Returns
    -------
    dict
        The values `draw` returns, with the derived `fault.rho_f`, `command.h_c`,
        `command.V_c` (a command without a dispersed step keeps the scenario's).

    Raises
    ------
    KeyError
        Naming a value of a dispersed group that `point` lacks.
    """
    d, cmd = data["dispersions"], case["command"]
    groups = dispersed_groups(data)
    out = {k: float(v) for k, v in point.items() if k.startswith("s.")}
    if "fault" in groups:
        loss = float(point["fault.loss"])
        out.update({"fault.kind": point["fault.kind"], "fault.t_onset": point["fault.t_onset"],
                    "fault.loss": loss, "fault.rho_f": 1.0 - loss,
                    "fault.bias_deg": point["fault.bias_deg"]})  # fmt: skip
    h0, V0 = cmd["h0"], cmd["V0"]
    if "initial" in groups:
        h0, V0 = point["initial.h0"], point["initial.V0"]
        out.update({"initial.h0": h0, "initial.V0": V0})
    if "command" in groups:
        h_c = h0 + point["command.dh"] if d["command"]["dh"] else cmd["h_c"]
        V_c = V0 + point["command.dV"] if d["command"]["dV"] else cmd["V_c"]
        out.update({"command.dh": h_c - h0, "command.dV": V_c - V0, "command.h_c": h_c,
                    "command.V_c": V_c})  # fmt: skip
    for group, keys in HARDWARE.items():
        if group in groups:
            out.update({f"{group}.{k}": point[f"{group}.{k}"] for k in keys})
    if "sensor_seed" in point:
        out["sensor_seed"] = point["sensor_seed"]
    return out


#: Prefixes of the dispersed values in a run's row (`draw`'s keys).
VALUE_PREFIXES = ("s.", "fault.", "initial.", "command.", "actuators.", "sensors.",
                  "sensor_seed")  # fmt: skip


def row_values(row: dict) -> dict:
    """The dispersed values of a run (`draw`'s form) read back from its results row."""
    return {k: v for k, v in row.items() if k.startswith(VALUE_PREFIXES)}


@functools.lru_cache(maxsize=4)
def _vehicle(path: str):
    return load_vehicle(path or None)


def uncertainty_scale(data: dict) -> float:
    """The fraction of the sec. 5.1 box a campaign's s_p span (`dispersions.uncertainty`)."""
    return float(data["dispersions"]["uncertainty"]["scale"])


def overrides(values: dict, design, variant: str, scale: float = 1.0) -> dict:
    """Node parameter overrides `{node: {name: value}}` of one run's dispersed values.

    Parameters
    ----------
    values : dict
        From `draw`.
    design : fahv.spec.artefacts.Design
        The case's design (its trim map gives the initial trim state; its vehicle
        file the nominal parameters).
    variant : str
        The run's variant (notch setting and state dimension of the nominal x0).
    scale : float
        The campaign's fraction of the parameter box (`uncertainty_scale`): each drawn
        parameter is p (1 + s_p scale rel_p).

    Returns
    -------
    dict
        `plant`: `params.<p>` of all ten uncertain parameters (the drawn ones
        perturbed, the others nominal) and `x0` of the initial trim;
        `fault_injector`: kind, onset and size; `nominal_trajectory`: the command
        and its initial state. Groups that are not dispersed are left out, so the
        run keeps the scenario's values (its seeded parameter draw, fault, command,
        start); `plant.sensor_seed` and the servo and sensor factors when drawn
        (`HARDWARE`), and the initial trim also as the
        `state_estimator`'s initial estimate.
    """
    ov: dict = {}
    if "sensor_seed" in values:
        ov["plant"] = {"sensor_seed": int(values["sensor_seed"])}
    for group, keys in HARDWARE.items():
        drawn = {name: float(values[f"{group}.{k}"]) for k, name in keys.items()
                 if f"{group}.{k}" in values}  # fmt: skip
        if drawn:
            ov.setdefault("plant", {}).update(drawn)
    s = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("s.")}
    if s:
        veh = _vehicle(design.summary.get("provenance", {}).get("vehicle_file", ""))
        rel = {k: r * float(scale) for k, r in PAPER_UNCERTAINTY.items()}
        vp = perturb(veh.params, rel, s)
        ov.setdefault("plant", {}).update(
            {f"params.{k}": float(getattr(vp, k)) for k in PAPER_UNCERTAINTY})
    if "fault.kind" in values:
        ov["fault_injector"] = {
            "kind": values["fault.kind"],
            "t_onset": values["fault.t_onset"],
            "rho_f": values["fault.rho_f"],
            "bias_deg": values["fault.bias_deg"],
            # a drawn hardover goes to the scenario's side (the upper limit if it has none)
            "side": float(design.case["fault"].get("side", 1.0)),
        }
        ov["plant"] = {**ov.get("plant", {}),
                       **stuck_parameters(values["fault.kind"], values["fault.t_onset"])}
    cmd = design.case["command"]
    h0, V0 = values.get("initial.h0", cmd["h0"]), values.get("initial.V0", cmd["V0"])
    if "initial.h0" in values or "command.h_c" in values:
        ov["nominal_trajectory"] = {
            "command.h0": float(h0),
            "command.V0": float(V0),
            "command.h_c": float(values.get("command.h_c", cmd["h_c"])),
            "command.V_c": float(values.get("command.V_c", cmd["V_c"])),
        }
    if "initial.h0" in values:
        a = design.arrays
        tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
        x0 = np.asarray(tm(h0, V0)[0][:9], float)
        p = node_parameters(design, variant)
        x0_meas = x0.copy()
        if p["notch_filter"]["enabled"]:
            x0_meas[4] = 0.0  # as node_parameters: the filter starts in steady state at q = 0
        n = p["nominal_trajectory"]["x0_shape"][0]
        if design.case["design_model"] == "ecm":  # the notch's two states start at rest
            x0_meas = np.concatenate([x0_meas, np.zeros(2)])
        ov.setdefault("plant", {}).update({"x0": x0.tolist(), "x0_shape": [9]})
        ov["state_estimator"] = {"x0": x0.tolist(), "x0_shape": [9]}
        ov["nominal_trajectory"].update({"x0": x0_meas.tolist(), "x0_shape": [n]})
    return ov


def scatter_columns(data: dict) -> list[str]:
    """Numeric dispersed columns a campaign varies (the x axes of the report's scatter plots)."""
    d = data["dispersions"]
    out = []
    if d["uncertainty"]["method"] != "none":
        out += [f"s.{k}" for k in d["uncertainty"]["parameters"]]
    f = d["fault"]
    out += [c for c, key in (("fault.t_onset", "onset"), ("fault.loss", "loss"),
                             ("fault.bias_deg", "bias_deg")) if f[key]]  # fmt: skip
    out += [f"command.{k}" for k in ("dh", "dV") if d["command"][k]]
    out += [f"initial.{k}" for k in ("h0", "V0") if d["initial"][k]]
    out += [f"{group}.{k}" for group, keys in HARDWARE.items() for k in keys if d[group][k]]
    return out
