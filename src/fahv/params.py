"""Node parameters: what each node of the SIL graph is configured with, and its checks.

The offline design (:mod:`fahv.design`) writes one standard ROS 2 parameter file per
case (``<node>: ros__parameters: {...}``); :func:`node_parameters` produces its
content for any simulation variant. Matrices are flattened row-major with their
shape in ``<name>_shape``. :data:`SPECS` lists, per node, every parameter with its
type, unit/description and admissible range; the ROS nodes declare exactly these
(typed, with descriptions and ranges) and :func:`validate` checks the values they
receive -- the same function the in-process simulator runs on the same dictionaries,
so both build the same objects from the same numbers.

No ROS import here: the nodes in ``ros_ws/`` translate :data:`SPECS` into
``rcl_interfaces`` descriptors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fahv.errors import FahvError
from fahv.plant import PAPER_UNCERTAINTY

#: Fault kinds the fault injector accepts (see :class:`fahv.plant.ElevatorFault`).
FAULT_KINDS = ("none", "loss_of_effectiveness", "stuck", "bias", "dropout")
#: Control laws of the controller node: eq. (36), eq. (54), Kothare RMPC.
LAWS = ("tube_mpc", "adjustable", "rmpc")


class ParameterError(FahvError):
    """A node parameter is missing, of the wrong type or shape, non-finite or out of range."""


@dataclass(frozen=True)
class Param:
    """Specification of one node parameter.

    Attributes
    ----------
    name : str
    kind : {"double", "int", "string", "bool", "matrix"}
        ``matrix``: a double array ``name`` plus an integer array ``name_shape``.
    description : str
        Meaning and unit (shown by ``ros2 param describe``).
    lo, hi : float
        Inclusive range for numbers (matrix entries are only checked to be finite).
    choices : tuple of str
        Admissible values of a string.
    rmpc_only : bool
        Required only when the controller's ``law`` is ``rmpc``.
    """

    name: str
    kind: str
    description: str
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple = ()
    rmpc_only: bool = False


def _common() -> list[Param]:
    return [
        Param("case", "string", "case name of the design (offline_design/<case>.yaml)"),
        Param("design_hash", "string", "content hash of the design artefacts"),
        Param("Ts", "double", "control period Ts [s]", 1e-4, 1.0),
        Param("duration", "double", "simulated duration of the run [s]", 0.0, 1e6),
        Param(
            "watchdog_s",
            "double",
            "wall-clock time without a peer message that is an error [s]",
            0.1,
            3600.0,
        ),
    ]


_COMMAND = [
    Param("command.kind", "string", "command shape", choices=("step", "ramp")),
    Param("command.h0", "double", "initial altitude [ft]", 0.0, 2e5),
    Param("command.V0", "double", "initial velocity [ft/s]", 0.0, 2e4),
    Param("command.h_c", "double", "commanded altitude [ft]", 0.0, 2e5),
    Param("command.V_c", "double", "commanded velocity [ft/s]", 0.0, 2e4),
    Param("command.t_start", "double", "command start time [s]", 0.0, 1e6),
    Param("command.t_ramp", "double", "ramp duration [s] (ramp only)", 0.0, 1e6),
]

#: Parameters per node name.
SPECS: dict[str, list[Param]] = {
    "plant": _common()
    + [
        Param("plant_substeps", "int", "RK4 steps per control period", 1, 10000),
        Param("vehicle_file", "string", "vehicle data file (YAML); empty: the packaged one"),
        Param(
            "x0", "matrix", "initial plant state (9,) [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s]"
        ),
    ]
    + [
        Param(f"params.{k}", "double", f"true (perturbed) value of vehicle parameter {k}")
        for k in PAPER_UNCERTAINTY
    ],
    "fault_injector": _common()
    + [
        Param("kind", "string", "elevator fault kind", choices=FAULT_KINDS),
        Param("t_onset", "double", "fault onset time [s]", 0.0),
        Param(
            "rho_f",
            "double",
            "elevator effectiveness for loss_of_effectiveness (eq. 15)",
            1e-6,
            1.0,
        ),
        Param("bias_deg", "double", "elevator bias for kind bias [deg]", -30.0, 30.0),
    ],
    "notch_filter": _common()
    + [
        Param("enabled", "bool", "false: pass q through (Tube-MPC without notch)"),
        Param("omega_z", "double", "notch zero frequency omega_z (eq. 38) [rad/s]", 1e-3, 1e4),
        Param("eps_z", "double", "notch zero damping eps_z (eq. 38)", 0.0, 10.0),
        Param("omega_p", "double", "notch pole frequency omega_p (eq. 38) [rad/s]", 1e-3, 1e4),
        Param("eps_p", "double", "notch pole damping eps_p (eq. 38)", 1e-6, 10.0),
    ],
    "nominal_trajectory": _common()
    + _COMMAND
    + [
        Param(
            "mode",
            "string",
            "governor: nominal system with reference governor (Tube-MPC); "
            "command: trim of the raw command, x_n = 0 (RMPC)",
            choices=("governor", "command"),
        ),
        Param("level_max", "double", "governor bound on x_n' Q^-1 x_n", 1e-6, 1.0),
        Param("x0", "matrix", "initial measured state (n,) in design-model order"),
        Param("A", "matrix", "nominal discrete LPV vertices A_i (R, n, n)"),
        Param("B", "matrix", "nominal discrete LPV vertices B_i (R, n, 2)"),
        Param("h_grid", "matrix", "TP weight grid in altitude [ft]"),
        Param("V_grid", "matrix", "TP weight grid in velocity [ft/s]"),
        Param("W_h", "matrix", "TP weighting functions of h on h_grid"),
        Param("W_V", "matrix", "TP weighting functions of V on V_grid"),
        Param("K", "matrix", "nominal gain K (2, n) (LMI 32-35)"),
        Param("Q", "matrix", "certified nominal ellipsoid Q (n, n)"),
        Param("trim_h", "matrix", "trim map altitudes [ft]"),
        Param("trim_V", "matrix", "trim map velocities [ft/s]"),
        Param("trim_x", "matrix", "trim states (N_h, N_V, n)"),
        Param("trim_u", "matrix", "trim inputs (N_h, N_V, 2)"),
    ],
    "tube_mpc": _common()
    + [
        Param(
            "law",
            "string",
            "control law: tube_mpc (eq. 36), adjustable (eq. 54), rmpc (Kothare 1996)",
            choices=LAWS,
        ),
        Param("tau", "double", "adjustable factor tau (eq. 54); 1 for eq. 36", 1e-6, 1.0),
        Param("F", "matrix", "robust feedback gain F (2, n) (LMI 24)"),
        Param("N", "matrix", "tube shape Z = {e: e' N^-1 e <= 1} (n, n)"),
        Param("rmpc_A", "matrix", rmpc_only=True, description="RMPC model vertices (R, 9, 9)"),
        Param("rmpc_B", "matrix", rmpc_only=True, description="RMPC model vertices (R, 9, 2)"),
        Param(
            "u_room",
            "matrix",
            rmpc_only=True,
            description="RMPC input room |u - u_r| <= u_room (2,)",
        ),
        Param("psi", "matrix", rmpc_only=True, description="RMPC state weights (9,), scaled units"),
        Param(
            "sigma", "matrix", rmpc_only=True, description="RMPC input weights (2,), scaled units"
        ),
        Param("Dx", "matrix", rmpc_only=True, description="state scales (9,)"),
        Param("Du", "matrix", rmpc_only=True, description="input scales (2,)"),
        Param("resolve_every", "int", "RMPC steps between LMI solves", 1, 10**7, rmpc_only=True),
    ],
}
#: The RMPC executable is the controller node under another name.
SPECS["rmpc"] = SPECS["tube_mpc"]

_PY = {"double": float, "int": int, "string": str, "bool": bool}


def _number(node: str, p: Param, v):
    typ = _PY[p.kind]
    if typ is float and isinstance(v, int) and not isinstance(v, bool):
        v = float(v)
    if not isinstance(v, typ) or (typ is not bool and isinstance(v, bool)):
        raise ParameterError(f"{node}: parameter '{p.name}' must be {p.kind}, got {v!r}")
    if typ in (float, int):
        if not math.isfinite(v):
            raise ParameterError(f"{node}: parameter '{p.name}' must be finite, got {v!r}")
        if not p.lo <= v <= p.hi:
            raise ParameterError(
                f"{node}: parameter '{p.name}' = {v!r} is outside [{p.lo}, {p.hi}]"
            )
    if p.choices and v not in p.choices:
        raise ParameterError(f"{node}: parameter '{p.name}' must be one of {p.choices}, got {v!r}")
    return v


def _matrix(node: str, p: Param, values: dict) -> np.ndarray:
    shape_key = f"{p.name}_shape"
    if values.get(p.name) is None or values.get(shape_key) is None:
        missing = p.name if values.get(p.name) is None else shape_key
        raise ParameterError(f"{node}: parameter '{missing}' is missing")
    shape = values[shape_key]
    if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape):
        raise ParameterError(f"{node}: parameter '{shape_key}' must be non-negative integers")
    try:
        data = np.asarray(values[p.name], dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{node}: parameter '{p.name}' must be an array of doubles") from None
    if data.ndim != 1 or data.size != math.prod(shape):
        raise ParameterError(
            f"{node}: parameter '{p.name}' has {data.size} values, but '{shape_key}' = "
            f"{list(shape)} needs {math.prod(shape)}"
        )
    if not np.all(np.isfinite(data)):
        bad = int(np.flatnonzero(~np.isfinite(data))[0])
        raise ParameterError(f"{node}: parameter '{p.name}' has a non-finite value at index {bad}")
    return data.reshape(tuple(shape))


def _expect(node: str, name: str, arr: np.ndarray, shape: tuple) -> None:
    if arr.shape != shape:
        raise ParameterError(f"{node}: parameter '{name}' has shape {arr.shape}, expected {shape}")


def _check_shapes(node: str, v: dict) -> None:
    """Cross-parameter shape checks of the matrices of one node."""
    if node == "plant":
        _expect(node, "x0", v["x0"], (9,))
    elif node == "nominal_trajectory":
        A = v["A"]
        if A.ndim != 3 or A.shape[1] != A.shape[2]:
            raise ParameterError(f"{node}: parameter 'A' must have shape (R, n, n), got {A.shape}")
        R, n = A.shape[0], A.shape[1]
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
    elif node in ("tube_mpc", "rmpc"):
        F = v["F"]
        if F.ndim != 2 or F.shape[0] != 2:
            raise ParameterError(f"{node}: parameter 'F' must have shape (2, n), got {F.shape}")
        n = F.shape[1]
        _expect(node, "N", v["N"], (n, n))
        if v["law"] == "adjustable" and n != 11:
            raise ParameterError(
                f"{node}: parameter 'law' = adjustable needs the 11-state ECM design "
                f"(F has n = {n})"
            )
        if v["law"] != "rmpc":
            return
        R = v["rmpc_A"].shape[0] if v["rmpc_A"].ndim == 3 else -1
        for name, shape in (
            ("rmpc_A", (R, 9, 9)),
            ("rmpc_B", (R, 9, 2)),
            ("u_room", (2,)),
            ("psi", (9,)),
            ("sigma", (2,)),
            ("Dx", (v["Dx"].size,)),
            ("Du", (2,)),
        ):
            _expect(node, name, v[name], shape)
        if v["Dx"].size < 9:
            raise ParameterError(f"{node}: parameter 'Dx' needs at least 9 scales")


def validate(node: str, values: dict) -> dict:
    """Check every parameter of ``node`` and return them typed.

    Parameters
    ----------
    node : str
        A key of :data:`SPECS`.
    values : dict
        Parameter name -> value as loaded from the parameter file (flat names with
        dots, matrices flattened plus ``<name>_shape``). Unknown names are ignored.

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
    if node not in SPECS:
        raise ParameterError(f"unknown node '{node}', expected one of {sorted(SPECS)}")
    out = {}
    rmpc = values.get("law") == "rmpc"
    for p in SPECS[node]:
        if p.rmpc_only and not rmpc:
            continue
        if p.kind == "matrix":
            out[p.name] = _matrix(node, p, values)
            continue
        if values.get(p.name) is None:
            raise ParameterError(f"{node}: parameter '{p.name}' is missing")
        out[p.name] = _number(node, p, values[p.name])
    _check_shapes(node, out)
    return out


def node_parameters(design, variant: str | None = None, watchdog_s: float = 10.0) -> dict:
    """Parameters of every node of the graph for one variant of a designed case.

    Parameters
    ----------
    design : fahv.design.Design
    variant : str, optional
        One of :data:`fahv.case.VARIANTS` (default: the case's first variant).
        ``tube_mpc_no_notch`` disables the notch, ``tube_mpc_notch2`` centres it on
        flexible mode 2, ``rmpc`` puts the Kothare controller under node name
        ``rmpc`` and the nominal node in command mode; the 11-state design selects
        the adjustable law (eq. 54) when tau < 1.
    watchdog_s : float
        Wall-clock watchdog of every node [s].

    Returns
    -------
    dict
        ``{node: {name: value}}`` with matrices flattened (lists) plus ``<name>_shape``;
        wrap each in ``{"ros__parameters": ...}`` for a ROS 2 parameter file.

    Raises
    ------
    ParameterError
        If the variant is not one of the case's.
    """
    a, c = design.arrays, design.case
    variant = c["variants"][0] if variant is None else variant
    if variant not in c["variants"]:
        raise ParameterError(f"variant '{variant}' is not in the case's variants {c['variants']}")
    n = a["A"].shape[1]

    def mat(name, arr=None):
        arr = np.asarray(a[name] if arr is None else arr, float)
        return {name: arr.ravel().tolist(), f"{name}_shape": list(arr.shape)}

    common = {
        "case": c["name"],
        "design_hash": design.summary["design_hash"],
        "Ts": float(c["Ts"]),
        "duration": float(c["duration"]),
        "watchdog_s": float(watchdog_s),
    }
    cmd, f, nt = c["command"], c["fault"], c["notch"]
    from fahv.trim import TrimMap

    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    x0 = np.asarray(tm(float(cmd["h0"]), float(cmd["V0"]))[0][:9], float)
    notch = {k: float(nt[k]) for k in ("omega_z", "eps_z", "omega_p", "eps_p")}
    enabled = bool(nt["enabled"]) and variant != "tube_mpc_no_notch"
    if variant == "tube_mpc_notch2":
        w2 = float(a["omega_flex"][1])
        notch.update(omega_z=w2, omega_p=w2)
    x0_meas = x0.copy()
    if enabled:
        x0_meas[4] = 0.0  # the filter starts in steady state at q = 0 (trim)
    if n == 11:
        x0_meas = np.concatenate([x0_meas, np.zeros(2)])
    tau = float(c["tube"]["tau"])
    law = "rmpc" if variant == "rmpc" else ("adjustable" if n == 11 and tau < 1.0 else "tube_mpc")
    r = c["rmpc"]
    nodes = {
        "plant": {
            **common,
            "plant_substeps": int(c["plant_substeps"]),
            "vehicle_file": "",
            **mat("x0", x0),
            **{f"params.{k}": float(v) for k, v in design.summary["plant_params"].items()},
        },
        "fault_injector": {
            **common,
            "kind": f["kind"],
            "t_onset": float(f["t_onset"]),
            "rho_f": float(f["rho_f"]),
            "bias_deg": float(f["bias_deg"]),
        },
        "notch_filter": {**common, "enabled": enabled, **notch},
        "nominal_trajectory": {
            **common,
            **{f"command.{k}": (v if k == "kind" else float(v)) for k, v in cmd.items()},
            "mode": "command" if variant == "rmpc" else "governor",
            "level_max": float(c["nominal"]["level_max"]),
            **mat("x0", x0_meas),
            **{
                k: v
                for name in (
                    "A",
                    "B",
                    "h_grid",
                    "V_grid",
                    "W_h",
                    "W_V",
                    "K",
                    "Q",
                    "trim_h",
                    "trim_V",
                    "trim_x",
                    "trim_u",
                )
                for k, v in mat(name).items()
            },
        },
        "rmpc" if law == "rmpc" else "tube_mpc": {
            **common,
            "law": law,
            "tau": tau if law == "adjustable" else 1.0,
            **mat("F"),
            **mat("N"),
        },
    }
    if law == "rmpc":
        nodes["rmpc"].update(
            **mat("rmpc_A"),
            **mat("rmpc_B"),
            **mat("u_room"),
            **mat("psi", np.full(9, float(r["psi"]))),
            **mat("sigma", np.full(2, float(r["sigma"]))),
            **mat("Dx", a["Dx"][:9]),
            **mat("Du"),
            resolve_every=int(r["resolve_every"]),
        )
    return nodes


def parameter_file(nodes: dict) -> dict:
    """``{node: {"ros__parameters": params}}``: the layout of a ROS 2 parameter file."""
    return {k: {"ros__parameters": v} for k, v in nodes.items()}


__all__ = [
    "FAULT_KINDS",
    "LAWS",
    "ParameterError",
    "Param",
    "SPECS",
    "validate",
    "node_parameters",
    "parameter_file",
]
