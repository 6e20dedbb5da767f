"""Case files (``offline_design/*.yaml``): every choice of a simulation case, validated.

A case file is a YAML mapping with exactly the keys of :data:`SCHEMA`; every leaf is
required. Loading fails with :class:`fahv.errors.CaseError` naming the file and the
key on an unknown key, a missing key, a wrong type or an out-of-range value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fahv.errors import CaseError
from fahv.yamlio import load_yaml

#: Leaf types of a case file; nested dicts are sections.
SCHEMA: dict[str, Any] = {
    "name": str,
    "description": str,
    "design_model": str,
    "vertices": list,
    "samples": list,
    "Ts": float,
    "duration": float,
    "plant_substeps": int,
    "trim_grid": list,
    "notch": {"enabled": bool, "omega_z": float, "eps_z": float, "omega_p": float, "eps_p": float},
    "command": {
        "kind": str,
        "h0": float,
        "V0": float,
        "h_c": float,
        "V_c": float,
        "t_start": float,
        "t_ramp": float,
    },
    "fault": {"kind": str, "t_onset": float, "rho_f": float, "bias_deg": float},
    "uncertainty": {"seed": int, "scale": float},
    "disturbance": {"samples": int, "seed": int, "margin": float},
    "tube": {"lam": list, "tau": float},
    "nominal": {"lam": float, "level_max": float},
    "rmpc": {"vertices": list, "resolve_every": int, "psi": float, "sigma": float},
    "variants": list,
}

#: Simulation variants a case may ask for.
VARIANTS = ("tube_mpc", "tube_mpc_no_notch", "tube_mpc_notch2", "rmpc")


def _check(data: Any, schema: dict, path: str, prefix: str) -> dict:
    if not isinstance(data, dict):
        raise CaseError(f"{path}: '{prefix or 'top level'}' must be a mapping")
    unknown = sorted(set(data) - set(schema))
    if unknown:
        raise CaseError(f"{path}: unknown key '{prefix}{unknown[0]}'")
    out = {}
    for key, typ in schema.items():
        name = f"{prefix}{key}"
        if key not in data:
            raise CaseError(f"{path}: missing key '{name}'")
        val = data[key]
        if isinstance(typ, dict):
            out[key] = _check(val, typ, path, name + ".")
            continue
        if typ is float and isinstance(val, int) and not isinstance(val, bool):
            val = float(val)
        if not isinstance(val, typ) or (typ is int and isinstance(val, bool)):
            raise CaseError(f"{path}: key '{name}' must be {typ.__name__}, got {val!r}")
        if typ is float and not math.isfinite(val):
            raise CaseError(f"{path}: key '{name}' must be finite, got {val!r}")
        out[key] = val
    return out


@dataclass(frozen=True)
class Case:
    """A validated case file.

    Attributes
    ----------
    path : Path
        File it was read from.
    data : dict
        Validated content (see :data:`SCHEMA`).
    """

    path: Path
    data: dict

    def __getitem__(self, key: str) -> Any:
        """Top-level entry of the case."""
        return self.data[key]

    @property
    def name(self) -> str:
        """Case name (used for artefact folders and run files)."""
        return self.data["name"]


def _pair(val, path, key, lo=1):
    if not (isinstance(val, list) and len(val) == 2 and all(isinstance(v, int) for v in val)):
        raise CaseError(f"{path}: key '{key}' must be a list of two integers, got {val!r}")
    if min(val) < lo:
        raise CaseError(f"{path}: key '{key}' entries must be >= {lo}, got {val!r}")
    return tuple(val)


def _require(d: dict, path: str, key: str, ok, what: str) -> None:
    """Raise CaseError naming ``key`` (dotted) and its value unless ok(value)."""
    val = d
    for part in key.split("."):
        val = val[part]
    if not ok(val):
        raise CaseError(f"{path}: key '{key}' {what}, got {val!r}")


def case_from_mapping(data: Any, path: str = "<mapping>") -> Case:
    """Validate a case mapping (see :data:`SCHEMA`) and return a :class:`Case`.

    Raises
    ------
    CaseError
        Naming the key at fault and its value.
    """
    d = _check(data, SCHEMA, path, "")
    fault_kinds = ("none", "loss_of_effectiveness", "stuck", "bias", "dropout")
    Ts = d["Ts"]
    _require(d, path, "design_model", lambda v: v in ("cm", "ecm"), "must be cm or ecm")
    d["vertices"] = _pair(d["vertices"], path, "vertices")
    d["samples"] = _pair(d["samples"], path, "samples", lo=4)
    d["trim_grid"] = _pair(d["trim_grid"], path, "trim_grid", lo=4)
    d["rmpc"]["vertices"] = _pair(d["rmpc"]["vertices"], path, "rmpc.vertices")
    for key, ok, what in (
        ("Ts", lambda v: 0.0 < v <= 0.1, "must be in (0, 0.1] s"),
        ("duration", lambda v: v >= 10 * Ts, "must be >= 10 Ts"),
        ("plant_substeps", lambda v: 1 <= v <= 100, "must be 1..100"),
        ("command.kind", lambda v: v in ("step", "ramp"), "must be step or ramp"),
        ("fault.kind", lambda v: v in fault_kinds, f"must be one of {fault_kinds}"),
        ("fault.rho_f", lambda v: 0.0 < v <= 1.0, "must be in (0, 1]"),
        ("uncertainty.scale", lambda v: 0.0 <= v <= 1.0, "must be in [0, 1]"),
        ("disturbance.samples", lambda v: v >= 10, "must be >= 10"),
        ("disturbance.margin", lambda v: v >= 1.0, "must be >= 1"),
        (
            "tube.lam",
            lambda v: bool(v) and all(isinstance(x, float) and 0.0 < x < 1.0 for x in v),
            "must be a non-empty list of floats in (0, 1)",
        ),
        ("tube.tau", lambda v: 0.0 < v <= 1.0, "must be in (0, 1]"),
        ("nominal.lam", lambda v: 0.0 < v < 1.0, "must be in (0, 1)"),
        ("nominal.level_max", lambda v: 0.0 < v <= 1.0, "must be in (0, 1]"),
        ("rmpc.resolve_every", lambda v: v >= 1, "must be >= 1"),
        (
            "variants",
            lambda v: bool(v) and all(x in VARIANTS for x in v),
            f"must be a non-empty list from {VARIANTS}",
        ),
        ("notch.omega_z", lambda v: 0.0 < v < math.pi / Ts, "must be in (0, pi/Ts)"),
        ("notch.omega_p", lambda v: 0.0 < v < math.pi / Ts, "must be in (0, pi/Ts)"),
    ):
        _require(d, path, key, ok, what)
    if d["design_model"] == "ecm" and not d["notch"]["enabled"]:
        raise CaseError(f"{path}: key 'notch.enabled' must be true for design_model ecm")
    if d["design_model"] == "ecm" and set(d["variants"]) - {"tube_mpc"}:
        raise CaseError(f"{path}: key 'variants': an ECM case runs only 'tube_mpc'")
    return Case(Path(path), d)


def load_case(path: str | Path) -> Case:
    """Read and validate a case file.

    Raises
    ------
    CaseError
        If the file is missing, is not YAML, or does not validate (naming the key).
    """
    p = Path(path)
    if not p.is_file():
        raise CaseError(f"case file not found: {p}")
    try:
        data = load_yaml(p.read_text())
    except Exception as exc:  # yaml errors carry the line number
        raise CaseError(f"{p}: not a valid YAML file: {exc}") from None
    return case_from_mapping(data, str(p))


__all__ = ["SCHEMA", "VARIANTS", "Case", "case_from_mapping", "load_case"]
