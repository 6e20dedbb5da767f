"""Node parameters of the SIL graph: declarations, validation, and their values per run.

Every parameter is a `fahv.config.Field`; the run spec's values reuse the fields
of the design and scenario files (`fahv.spec.schema`: the loop imports the files'
package, no design code), so Ts, the command, the notch and the fault have one range
everywhere. `specs` lists the parameters of each node (the controller's include
every registered law's own parameters, the fault injector's every registered fault
kind's); the ROS nodes generate their descriptors from it
(`hsv_common`) and call `validate` once at start-up, as the in-process
simulator does on the same dictionaries, so both build the same objects from the
same numbers.

A design becomes parameters with `node_parameters`: one standard ROS 2
parameter file (`<node>: ros__parameters: {...}`) per run; matrices are flattened
row-major with their shape in `<name>_shape`. No ROS import here.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from fahv.config import Field
from fahv.config.spec import validate_flat
from fahv.control import LAWS, NOMINAL_SOURCES, VARIANTS, variant_notch
from fahv.errors import ParameterError
from fahv.estimation.state_disturbance import NO_DISTURBANCE, STATE_DISTURBANCE_NAMES
from fahv.loop.estimate_settings import nominal_on_estimate
from fahv.loop.graph import CONTROLLER_NODES
from fahv.model.actuators import ACTUATOR_MODELS, IDEAL
from fahv.model.cascade import AIRFRAME_ARRAYS, airframe_arrays
from fahv.plant.faults import FAULT_KIND, FAULTS, T_ONSET, fault_fields
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.sensors.data import EXACT_STATE
from fahv.sensors.faults import SENSOR_FAULTS, sensor_fault_fields
from fahv.spec.artefacts import variant_gain_key
from fahv.spec.schema import (
    COMMAND,
    DURATION,
    ESTIMATORS,
    NO_ESTIMATOR,
    NOTCH,
    PLANT,
    PLANT_SUBSTEPS,
    TS,
    estimator_kind,
    estimator_value,
    law_tau,
    plant_choices,
    sensor_fault_values,
)

#: The arrays of the CM LPV model the state estimator's Kalman gains are made from
#: (`fahv.estimation.kalman.design_filter`): a CM design's, an ECM design's CM part
#: (`fahv.model.cascade.airframe_arrays`).
ESTIMATOR_ARRAYS = AIRFRAME_ARRAYS

COMMON = (
    Field("case", "str", "name of the run spec the run flies (its scenario's name; the run "
          "files' metadata 'case')"),
    Field("design_hash", "str", "content hash of the design artefacts"),
    TS,
    DURATION,
    Field("watchdog_s", "float", "wall-clock time without a peer message that is an error",
          unit="s", lo=0.1, hi=3600.0, default=10.0),
)  # fmt: skip


#: The design model the node's arrays are of (the design file's `design_model`): the
#: state order and dimension every matrix follows.
DESIGN_MODEL = Field("design_model", "str", "LPV design model the arrays are of: cm (the "
                     "CM's 9 states) or ecm (11: with the notch's 2 states, eq. 40)",
                     choices=("cm", "ecm"))  # fmt: skip
#: State dimension n of each design model.
DESIGN_MODEL_STATES = {"cm": 9, "ecm": 11}


def _matrix(name: str, description: str) -> Field:
    return Field(name, "matrix", description)


def _prefixed(fields, prefix: str) -> list[Field]:
    return [dataclasses.replace(f, name=prefix + f.name) for f in fields]


def _estimator_fields() -> tuple[Field, ...]:
    """Parameters of the state estimator node."""
    return (
        *COMMON,
        PLANT_SUBSTEPS,
        Field("vehicle_file", "str", "vehicle data file (YAML) of the predictor's nominal "
              "vehicle and the sensors' noise; empty: the packaged one", default=""),
        Field("estimator", "str", "state estimator: none (the exact state, measured "
              f"'{EXACT_STATE}') or kalman", choices=ESTIMATORS, default=NO_ESTIMATOR),
        Field("measured", "str", "the plant's measured channels (its parameter measured)",
              default=EXACT_STATE),
        Field("actuators", "str", "actuator model the Kalman filter's predictor integrates "
              "(scenario estimator.actuators): ideal or the vehicle file's second_order "
              "servos", choices=ACTUATOR_MODELS, default=IDEAL),
        Field("state_disturbance", "str", "the Kalman filter's third disturbance "
              "(scenario estimator.state_disturbance): none, flight_path or altitude_rate",
              choices=STATE_DISTURBANCE_NAMES, default=NO_DISTURBANCE),
        _matrix("x0", "initial estimate x_0|-1 (9,) [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s]"),
        *(_matrix(name, f"the filter's CM LPV model: {name} of a CM design, of an ECM "
                  "design's CM part (fahv.model.cascade)")
          for name in ESTIMATOR_ARRAYS),
    )  # fmt: skip


def specs() -> dict[str, tuple[Field, ...]]:
    """Parameters of every loop node, by node name (built from the registries).

    Built once per set of registered laws, nominal sources and fault kinds (a campaign validates
    every node of every run: the declarations are not rebuilt each time); the caller
    gets its own dict.

    Returns
    -------
    dict
        `{node: (Field, ...)}` for plant, fault_injector, notch_filter,
        nominal_trajectory and each controller node name.
    """
    entries = tuple((name, entry) for registry in (LAWS, NOMINAL_SOURCES, FAULTS, SENSOR_FAULTS)
                    for name, entry in registry.items())  # fmt: skip
    return dict(_specs_of(entries))


def _controller_fields() -> tuple[Field, ...]:
    """Parameters of a controller node: the law, its design model, F, N, the notch."""
    return (
        *COMMON,
        Field("law", "str", "control law", choices=LAWS.names),
        DESIGN_MODEL,
        Field("tau", "float", "adjustable factor tau (1 for eq. 36)", lo=0.0, hi=1.0,
              lo_open=True, equation="eq. (54)"),
        _matrix("F", "robust feedback gain F (2, n) (LMI 24)"),
        _matrix("N", "tube shape Z = {e: e' N^-1 e <= 1} (n, n) (eq. 25-28)"),
        *_prefixed(NOTCH, "notch."),  # the notch on q, replicated on the nominal's q
        Field("filter_nominal_q", "bool", "the error's q through the notch: the nominal's q "
              "through a replica of the filter (case key tube.filter_nominal_q)",
              default=False),
        *(f for _, cls in LAWS.items() for f in cls.parameters),
    )  # fmt: skip


def _plant_fields() -> tuple[Field, ...]:
    """Parameters of the plant node: the vehicle, its state, sensors, faults it simulates."""
    return (
        *COMMON,
        PLANT_SUBSTEPS,
        Field("vehicle_file", "str", "vehicle data file (YAML); empty: the packaged one",
              default=""),
        _matrix("x0", "initial plant state (9,) [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s]"),
        *(Field(f"params.{k}", "float", f"true (perturbed) value of vehicle parameter {k}")
          for k in PAPER_UNCERTAINTY),
        *PLANT,
        Field("stuck", "bool", "the run's fault is a stuck elevator (fault kind stuck): "
              "from stuck_onset the elevator actuator is held at its position (with servo "
              "dynamics; an ideal actuator's position is the held command)",
              default=False),
        Field("stuck_onset", "float", "onset of the stuck elevator (fault t_onset)",
              unit="s", lo=0.0, default=0.0),
        Field("rate", "float", "pace of the steps: 0 as fast as the graph steps, r > 0 at "
              "most r times real time (a graph watched live; fahv sil --rate)", lo=0.0,
              default=0.0),
        *_prefixed(sensor_fault_fields(), "sensor_fault."),
    )  # fmt: skip


def _nominal_fields() -> tuple[Field, ...]:
    """Parameters of the nominal-trajectory node: the command, the nominal's model and MPC."""
    return (
        *COMMON,
        PLANT_SUBSTEPS,
        Field("vehicle_file", "str", "vehicle data file (YAML) of the nominal vehicle (the "
              "nonlinear nominal model, mpc.nominal_model 'cm'); empty: the packaged one",
              default=""),
        *_prefixed(COMMAND, "command."),
        DESIGN_MODEL,
        Field("nominal", "str", "nominal part of the law (registered nominal source)",
              choices=NOMINAL_SOURCES.names),
        *(f for _, cls in NOMINAL_SOURCES.items() for f in cls.parameters),
        *_prefixed(NOTCH, "notch."),
        _matrix("u_lo", "tightened lower input limits (2,) [-, rad] (eq. 30)"),
        _matrix("u_hi", "tightened upper input limits (2,) [-, rad] (eq. 30)"),
        _matrix("Dx", "state scales (n,)"),
        _matrix("Du", "input scales (2,)"),
        Field("level_max", "float", "governor bound on x_n' Q^-1 x_n", lo=0.0, hi=1.0,
              lo_open=True),
        _matrix("x0", "initial measured state (n,) in design-model order"),
        _matrix("A", "nominal discrete LPV vertices A_i (R, n, n) (eq. 12)"),
        _matrix("B", "nominal discrete LPV vertices B_i (R, n, 2) (eq. 12)"),
        _matrix("h_grid", "TP weight grid in altitude [ft]"),
        _matrix("V_grid", "TP weight grid in velocity [ft/s]"),
        _matrix("W_h", "TP weighting functions of h on h_grid (eq. 11)"),
        _matrix("W_V", "TP weighting functions of V on V_grid (eq. 11)"),
        _matrix("K", "nominal gain K (2, n) (LMI 32-35)"),
        _matrix("Q", "certified nominal ellipsoid Q (n, n) (LMI 33)"),
        _matrix("trim_h", "trim map altitudes [ft]"),
        _matrix("trim_V", "trim map velocities [ft/s]"),
        _matrix("trim_x", "trim states (N_h, N_V, n)"),
        _matrix("trim_u", "trim inputs (N_h, N_V, 2)"),
    )  # fmt: skip


@functools.lru_cache(maxsize=4)
def _specs_of(entries: tuple) -> dict[str, tuple[Field, ...]]:
    """`specs` for the registered `entries` ((name, entry) pairs of the registries)."""
    controller = _controller_fields()
    out = {
        "plant": _plant_fields(),
        "fault_injector": (
            *COMMON,
            Field("vehicle_file", "str", "vehicle data file (YAML) whose input limits a "
                  "hardover drives to; empty: the packaged one", default=""),
            FAULT_KIND,
            T_ONSET,
            *fault_fields(),
        ),
        "state_estimator": _estimator_fields(),
        "notch_filter": (*COMMON, *NOTCH),
        "nominal_trajectory": _nominal_fields(),
    }
    for name in CONTROLLER_NODES:
        out[name] = controller
    return out


def _expect(node: str, name: str, arr: np.ndarray, shape: tuple) -> None:
    if arr.shape != shape:
        raise ParameterError(f"{node}: parameter '{name}' has shape {arr.shape}, expected {shape}")


def _check_model(node: str, v: dict, name: str, n: int) -> None:
    """The arrays' state dimension n is the one of the node's `design_model`."""
    if n != DESIGN_MODEL_STATES[v["design_model"]]:
        raise ParameterError(f"{node}: parameter '{name}' has {n} states, but design_model "
                             f"'{v['design_model']}' has {DESIGN_MODEL_STATES[v['design_model']]}")


def _check_shapes(node: str, v: dict) -> None:
    """Cross-parameter shape checks of the matrices of one node."""
    if node in ("plant", "state_estimator"):
        _expect(node, "x0", v["x0"], (9,))
    elif node == "nominal_trajectory":
        A = v["A"]
        if A.ndim != 3 or A.shape[1] != A.shape[2]:
            raise ParameterError(f"{node}: parameter 'A' must have shape (R, n, n), got {A.shape}")
        R, n = A.shape[0], A.shape[1]
        _check_model(node, v, "A", n)
        nh, nv = v["W_h"].shape[-1], v["W_V"].shape[-1]
        for name, shape in (
            ("B", (R, n, 2)),
            ("K", (2, n)),
            ("Q", (n, n)),
            ("x0", (n,)),
            ("h_grid", (v["h_grid"].size,)),
            ("V_grid", (v["V_grid"].size,)),
            ("W_h", (v["h_grid"].size, nh)),
            ("W_V", (v["V_grid"].size, nv)),
            ("trim_x", (v["trim_h"].size, v["trim_V"].size, n)),
            ("trim_u", (v["trim_h"].size, v["trim_V"].size, 2)),
        ):
            _expect(node, name, v[name], shape)
        if nh * nv != R:
            raise ParameterError(
                f"{node}: parameter 'A' has {R} vertices but the weights give {nh} x {nv}"
            )
    elif node in CONTROLLER_NODES:
        F = v["F"]
        if F.ndim != 2 or F.shape[0] != 2:
            raise ParameterError(f"{node}: parameter 'F' must have shape (2, n), got {F.shape}")
        _check_model(node, v, "F", F.shape[1])
        _expect(node, "N", v["N"], (F.shape[1], F.shape[1]))


def validate(node: str, values: dict) -> dict:
    """Check every parameter of `node` and return them typed (the one validation).

    Parameters
    ----------
    node : str
        A key of `specs`.
    values : dict
        Parameter name -> value as loaded from the parameter file (flat names with
        dots, matrices flattened plus `<name>_shape`). Unknown names are ignored.

    Returns
    -------
    dict
        Name -> value; matrices as ndarrays of their shape.

    Raises
    ------
    ParameterError
        Naming the node and the key: missing, wrong type, non-finite (NaN/inf in a
        matrix included), out of range, or a shape inconsistent with the others.
    """
    all_specs = specs()
    if node not in all_specs:
        raise ParameterError(f"unknown node '{node}', expected one of {sorted(all_specs)}")
    out = validate_flat(all_specs[node], values, node, ParameterError)
    _check_shapes(node, out)
    return out


def flat_parameter(name: str, value) -> dict:
    """A node parameter as the parameter files hold it: `{name: value}`.

    An array (any shape) becomes `{name: flat list, name_shape: shape}` (how F, N,
    u_lo, ... reach the nodes; e.g. for `simulate(..., overrides=...)`); other values
    are kept as given. Raises nothing.
    """
    if isinstance(value, np.ndarray):
        arr = np.asarray(value, float)
        return {name: arr.ravel().tolist(), f"{name}_shape": list(arr.shape)}
    return {name: value}


def node_parameters(design, variant: str | None = None, watchdog_s: float = 10.0) -> dict:
    """Parameters of every loop node for one variant of a design with its run spec.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant : str, optional
        A variant of the run spec (`fahv.control.VARIANTS`; default: its
        first). The variant gives the law (its controller node, the nominal node's
        mode, the law's own parameters), the notch setting (as in the design, off, or
        centred on flexible mode 2) and the gain F: the design's `F_<variant>` if it
        designed one for the variant's loop through the notch, else `F`.
    watchdog_s : float
        Wall-clock watchdog of every node [s].

    Returns
    -------
    dict
        `{node: {name: value}}` with matrices flattened (lists) plus `<name>_shape`;
        wrap each in `{"ros__parameters": ...}` for a ROS 2 parameter file.

    Raises
    ------
    ParameterError
        If the variant is not one of the run spec's.
    """
    a, c = design.arrays, design.case
    variant = c["variants"][0] if variant is None else variant
    if variant not in c["variants"]:
        raise ParameterError(f"variant '{variant}' is not in the case's variants {c['variants']}")
    v = VARIANTS[variant]
    law = LAWS[v.law]

    def mat(name, arr=None):
        return flat_parameter(name, np.asarray(a[name] if arr is None else arr, float))

    common = {
        "case": c["name"],
        "design_hash": design.summary["design_hash"],
        "Ts": float(c["Ts"]),
        "duration": float(c["duration"]),
        "watchdog_s": float(watchdog_s),
    }
    cmd, f, nt = c["command"], c["fault"], c["notch"]
    x0 = np.asarray(a["x0"], float)
    run_notch = variant_notch(nt, v.notch, a["omega_flex"])
    enabled = run_notch is not None
    notch = run_notch or {k: float(nt[k]) for k in ("omega_z", "eps_z", "omega_p", "eps_p")}
    x0_meas = x0.copy()
    if enabled:
        x0_meas[4] = 0.0  # the filter starts in steady state at q = 0 (trim)
    if c["design_model"] == "ecm":  # the notch's two states start at rest
        x0_meas = np.concatenate([x0_meas, np.zeros(2)])
    tau = law_tau(c) if law.has_tube else 1.0
    vehicle_file = design.summary.get("provenance", {}).get("vehicle_file", "")
    fault = {"kind": f["kind"], "t_onset": float(f["t_onset"]), "vehicle_file": vehicle_file,
             **{p.name: f[p.name] for p in FAULTS[f["kind"]].parameters}}  # fmt: skip
    notch_values = {f"notch.{k}": val for k, val in {"enabled": enabled, **notch}.items()}
    controller = {
        **common,
        "law": law.name,
        "design_model": c["design_model"],
        "tau": tau,
        # the variant's own gain if the design made one for its loop through the notch
        **flat_parameter("F", np.asarray(a.get(variant_gain_key(variant), a["F"]), float)),
        **mat("N"),
        **notch_values,
        "filter_nominal_q": bool(c["tube"]["filter_nominal_q"]),
    }
    for name, value in law.node_values(a, c).items():
        controller.update(flat_parameter(name, value))
    nominal = {k: _plain(v) for k, v in law.nominal.node_values(a, c).items()}
    nominal = nominal_on_estimate(nominal, c, a)
    return {
        **vehicle_parameters(design, common),
        "fault_injector": {**common, **fault},
        "notch_filter": {**common, "enabled": enabled, **notch},
        "nominal_trajectory": {
            **common,
            "plant_substeps": int(c["plant_substeps"]),
            "vehicle_file": vehicle_file,
            **{f"command.{k}": (val if k == "kind" else float(val)) for k, val in cmd.items()},
            "design_model": c["design_model"],
            "nominal": law.nominal.name,
            "level_max": float(c["nominal"]["level_max"]),
            **nominal,
            **notch_values,
            **{k: val for name in ("u_lo", "u_hi", "Dx", "Du") for k, val in mat(name).items()},
            **mat("x0", x0_meas),
            **{
                k: val
                for name in ("A", "B", "h_grid", "V_grid", "W_h", "W_V", "K", "Q")
                + ("trim_h", "trim_V", "trim_x", "trim_u")
                for k, val in mat(name).items()
            },
        },
        law.node: controller,
    }


def vehicle_parameters(design, common: dict) -> dict:
    """The parameters of the plant (its sensors) and the state estimator that reads them.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    common : dict
        The parameters every node shares (`COMMON`).

    Returns
    -------
    dict
        `{"plant": {...}, "state_estimator": {...}}`, matrices flattened.
    """
    a, c = design.arrays, design.case
    f = c["fault"]
    vehicle_file = design.summary.get("provenance", {}).get("vehicle_file", "")
    def x0() -> dict:  # a list of its own per node: a parameter file holds no YAML alias
        return flat_parameter("x0", np.asarray(a["x0"], float)[:9])

    choices = plant_choices(c)
    shared = {**common, "plant_substeps": int(c["plant_substeps"]), "vehicle_file": vehicle_file}
    airframe = airframe_arrays(a, c["design_model"], c["notch"])
    return {
        "plant": {
            **shared, **x0(),
            **{f"params.{k}": float(val) for k, val in design.summary["plant_params"].items()},
            **choices, **stuck_parameters(f["kind"], f["t_onset"]), **sensor_fault_values(c),
        },
        "state_estimator": {
            **shared, **x0(), "estimator": estimator_kind(c), "measured": choices["measured"],
            "actuators": estimator_value(c, "actuators"),
            "state_disturbance": estimator_value(c, "state_disturbance"),
            **{k: val for name in ESTIMATOR_ARRAYS
               for k, val in flat_parameter(name, airframe[name]).items()},
        },
    }  # fmt: skip


def stuck_parameters(kind: str, t_onset: float) -> dict:
    """The plant's parameters `stuck`, `stuck_onset` of a run's fault (kind, onset [s]).

    Examples
    --------
    >>> stuck_parameters("stuck", 100.0), stuck_parameters("bias", 100.0)
    ({'stuck': True, 'stuck_onset': 100.0}, {'stuck': False, 'stuck_onset': 0.0})
    """
    stuck = kind == "stuck"
    return {"stuck": stuck, "stuck_onset": float(t_onset) if stuck else 0.0}


def _plain(v):
    """A run spec value as a ROS parameter value (tuples as lists, ints kept)."""
    if isinstance(v, tuple | list):
        return [float(x) for x in v]
    return v


def controller_node(params: dict) -> str:
    """Name of the controller node among a run's node parameters (keys: node names).

    Raises
    ------
    ParameterError
        If none of `fahv.loop.graph.CONTROLLER_NODES` is among them.
    """
    for name in CONTROLLER_NODES:
        if name in params:
            return name
    raise ParameterError(f"no controller node {CONTROLLER_NODES} among {sorted(params)}")


def parameter_file(nodes: dict) -> dict:
    """`{node: {"ros__parameters": params}}`: the layout of a ROS 2 parameter file."""
    return {k: {"ros__parameters": v} for k, v in nodes.items()}


def case_with(case: dict, nodes: dict | None) -> dict:
    """A run spec's data with the fault and command a run's node parameters give.

    The inverse of `node_parameters` for what a campaign run disperses: the
    `fault_injector`'s fault (`kind`, `t_onset` and the kind's parameters) and the
    `nominal_trajectory`'s `command.*`. Other parameters are left out (the vehicle
    draw stays the run spec's).

    Parameters
    ----------
    case : dict
        The run spec's data (`command`, `fault`, ...).
    nodes : dict or None
        `{node: {name: value}}`, a run's node parameters or only its overrides.

    Returns
    -------
    dict
        A shallow copy of `case` with `fault` and `command` replaced where
        `nodes` gives them.
    """
    nodes = nodes or {}
    out = dict(case)
    fault = nodes.get("fault_injector")
    if fault and "kind" in fault:
        names = ("kind", "t_onset", *(f.name for f in FAULTS[fault["kind"]].parameters))
        out["fault"] = {k: fault[k] for k in names if k in fault}
    cmd = {k.split(".", 1)[1]: v for k, v in (nodes.get("nominal_trajectory") or {}).items()
           if k.startswith("command.")}  # fmt: skip
    if cmd:
        out["command"] = {**case["command"], **cmd}
    return out
