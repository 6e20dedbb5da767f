"""The one configuration language of fahv: declare a value once, validate it once.

A `Field` declares one value: type, unit, range, default (or required),
description and the paper equation it enters. A `Section` groups fields (and
sections) of a YAML mapping, is required always or only when another value asks for
it, and carries cross-field checks. Case files (`fahv.spec.schema`), campaign
files and the node parameters of the SIL graph (`fahv.loop.params`) are declared
this way; the ROS nodes generate their parameter descriptors (type, description,
range) from the same fields, so a range is written in exactly one place.

Validation fails with the caller's error class and a message that names the source
(file or node) and the dotted key, e.g. `case1.yaml: key 'fault.rho_f' must be in
(0, 1], got 1.5`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from fahv.errors import ConfigError


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Default of a value that must be given.
REQUIRED: Any = _Required()

#: Value types: scalars, lists of scalars, and matrices (node parameters only: a flat
#: float array `name` plus its integer shape `name_shape`).
TYPES = ("float", "int", "str", "bool", "floats", "ints", "strs", "matrix")
_SCALAR = {"float": float, "int": int, "str": str, "bool": bool}
_ITEM = {"floats": float, "ints": int, "strs": str}


@dataclass(frozen=True)
class Field:
    """Declaration of one configuration value.

    Parameters
    ----------
    name : str
        Key (a dotted name for flat node parameters, e.g. `command.h0`).
    type : str
        One of `TYPES`.
    description : str
        Meaning, shown in docs and by `ros2 param describe`.
    unit : str
        Physical unit ("" for dimensionless).
    default : object
        Value used when the key is absent; `REQUIRED` if it must be given.
    lo, hi : float, optional
        Range of a number (of every item of a list); inclusive unless `lo_open` /
        `hi_open`.
    choices : tuple or callable, optional
        Admissible strings; a callable returning them (a registry's names).
    length : int, optional
        Exact length of a list.
    equation : str
        Paper equation(s) the value enters, e.g. "eq. (38)".
    when : callable, optional
        `when(root) -> bool` on the validated document: the value is used (and, if
        required, must be given) only when it returns True; `when_text` says when.
    """

    name: str
    type: str
    description: str
    unit: str = ""
    default: Any = REQUIRED
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple | Callable[[], Sequence[str]] | None = None
    length: int | None = None
    equation: str = ""
    when: Callable[[Mapping], bool] | None = None
    when_text: str = ""

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"field {self.name}: type must be one of {TYPES}, got {self.type!r}")

    @property
    def required(self) -> bool:
        """True if the value has no default."""
        return self.default is REQUIRED

    def allowed(self) -> tuple:
        """Admissible strings (empty: any)."""
        if self.choices is None:
            return ()
        return tuple(self.choices() if callable(self.choices) else self.choices)

    def range_text(self) -> str:
        """The range in interval notation, e.g. `(0, 0.1]` ("" if unbounded)."""
        if self.lo is None and self.hi is None:
            return ""
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        left = "(" if self.lo_open or self.lo is None else "["
        right = ")" if self.hi_open or self.hi is None else "]"
        return f"{left}{lo}, {hi}{right}"

    def doc(self) -> str:
        """One line for the docs and the ROS descriptor: description, unit, range, equation."""
        parts = [self.description]
        if self.unit:
            parts.append(f"[{self.unit}]")
        if self.range_text():
            parts.append(f"in {self.range_text()}")
        if self.allowed():
            parts.append(f"one of {', '.join(self.allowed())}")
        if self.equation:
            parts.append(f"({self.equation})")
        if self.when_text:
            parts.append(f"(only when {self.when_text})")
        return " ".join(parts)

    def check(self, value: Any, where: str, error: type[Exception]) -> Any:
        """Return `value` converted to the field's type.

        Raises
        ------
        error
            Naming `where` (source and key): wrong type, non-finite number, out of
            range, not an admissible choice, or a list of the wrong length.
        """
        if self.type == "matrix":
            raise ValueError("matrix fields are checked by check_matrix")
        if self.type in _ITEM:
            if not isinstance(value, list | tuple):
                raise error(f"{where} must be a list of {self.type[:-1]}, got {value!r}")
            if not value and self.default == ():  # the empty default, given (an extension
                return []  # turning off what its base sets)
            if self.length is not None and len(value) != self.length:
                raise error(f"{where} must have {self.length} entries, got {value!r}")
            if not value:
                raise error(f"{where} must not be empty")
            return [self._scalar(_ITEM[self.type], v, where, error) for v in value]
        return self._scalar(_SCALAR[self.type], value, where, error)

    def _scalar(self, typ: type, v: Any, where: str, error: type[Exception]) -> Any:
        if typ is float and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if not isinstance(v, typ) or (typ is not bool and isinstance(v, bool)):
            raise error(f"{where} must be {typ.__name__}, got {v!r}")
        if typ in (float, int):
            if not math.isfinite(v):
                raise error(f"{where} must be finite, got {v!r}")
            lo_bad = self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo)
            hi_bad = self.hi is not None and (v >= self.hi if self.hi_open else v > self.hi)
            if lo_bad or hi_bad:
                unit = f" {self.unit}" if self.unit else ""
                raise error(f"{where} must be in {self.range_text()}{unit}, got {v!r}")
        allowed = self.allowed()
        if allowed and v not in allowed:
            if callable(self.choices):  # a registry's names: plugins may add to them
                raise error(f"{where}: unknown {self.description} {v!r}; must be one of "
                            f"{allowed} (a plugin's are registered by the modules the "
                            "environment variable FAHV_PLUGINS names)")  # fmt: skip
            raise error(f"{where} must be one of {allowed}, got {v!r}")
        return v


@dataclass(frozen=True)
class Check:
    """A cross-field check: `ok(root)` must hold, else the error names `key`."""

    key: str
    ok: Callable[[Mapping], bool]
    message: str


@dataclass(frozen=True)
class Section:
    """A mapping of fields and sections.

    Parameters
    ----------
    name : str
        Key of the section ("" for the document itself).
    entries : tuple of Field or Section
    description : str
    when : callable, optional
        `when(root) -> bool`: the section is required only when it returns True
        (`when_text` says when); absent and not required, it is left out.
    checks : tuple of Check
        Cross-field checks run after every value is validated.
    """

    name: str
    entries: tuple
    description: str = ""
    when: Callable[[Mapping], bool] | None = None
    when_text: str = ""
    checks: tuple[Check, ...] = field(default_factory=tuple)

    def has_required(self) -> bool:
        """True if a value of the section (unconditional, nested included) must be given."""
        return any(
            e.has_required() if isinstance(e, Section) else (e.required and e.when is None)
            for e in self.entries
            if not (isinstance(e, Section) and e.when is not None)
        )

    def fields(self, prefix: str = "") -> list[tuple[str, Field]]:
        """Every field with its dotted key, depth first."""
        out = []
        for e in self.entries:
            if isinstance(e, Section):
                out += e.fields(f"{prefix}{e.name}.")
            else:
                out.append((f"{prefix}{e.name}", e))
        return out


@dataclass
class Validated:
    """Result of `validate`: the typed values and the defaults that were used."""

    values: dict
    defaults_used: dict[str, Any]


def validate(
    spec: Section, data: Any, source: str, error: type[Exception] = ConfigError
) -> Validated:
    """Validate a nested mapping against `spec`.

    Parameters
    ----------
    spec : Section
        The document's declaration.
    data : Mapping
        Parsed YAML.
    source : str
        File name (or other origin) used in every message.
    error : type
        Exception class raised (a `fahv.errors.ConfigError` subclass).

    Returns
    -------
    Validated
        Typed values (defaults filled in) and `{dotted key: default}` of each
        default used.

    Raises
    ------
    error
        Naming the source and the dotted key: unknown key, missing required key or
        section, wrong type, out of range, failed cross-field check, a key its
        condition leaves unused (`fault.rho_f` under `fault.kind: bias`; accepted
        only when it holds its default, which means what its absence means).
    """
    defaults: dict[str, Any] = {}
    pending: list = []
    root = _section(spec, data, source, "", error, defaults, pending)
    for fn in pending:  # conditional entries need the whole document first (the list
        fn(root)  # grows while it runs when a conditional section holds conditional keys
    for sec, prefix in _sections(spec, ""):
        if prefix and lookup(root, prefix.rstrip(".")) is None:
            continue
        for c in sec.checks:
            if not c.ok(root):
                key = prefix + c.key
                raise error(f"{source}: key '{key}' {c.message}, got {lookup(root, key)!r}")
    return Validated(root, defaults)


def _sections(spec: Section, prefix: str):
    yield spec, prefix
    for e in spec.entries:
        if isinstance(e, Section):
            yield from _sections(e, f"{prefix}{e.name}.")


def lookup(root: Mapping, key: str) -> Any:
    """Value of a dotted key in a nested mapping, or of a flat dotted key; None if absent."""
    if key in root:
        return root[key]
    v: Any = root
    for part in key.split("."):
        if not isinstance(v, Mapping) or part not in v:
            return None
        v = v[part]
    return v


def _section(spec, data, source, prefix, error, defaults, pending) -> dict:
    where = prefix.rstrip(".") or "top level"
    if not isinstance(data, Mapping):
        raise error(f"{source}: '{where}' must be a mapping, got {type(data).__name__}")
    names = {e.name for e in spec.entries}
    for e in spec.entries:  # a choice first (a fault kind), then the keys it brings
        if isinstance(e, Field) and e.choices is not None and e.when is None and e.name in data:
            e.check(data[e.name], f"{source}: key '{prefix}{e.name}'", error)
    unknown = sorted(set(data) - names, key=str)
    if unknown:
        raise error(f"{source}: unknown key '{prefix}{unknown[0]}' (known: {sorted(names)})")
    out: dict = {}
    for e in spec.entries:
        key = f"{prefix}{e.name}"
        present = e.name in data
        if e.when is not None:
            pending.append(
                lambda root, e=e, key=key, present=present, out=out: _conditional(
                    e, data, out, root, key, present, source, error, defaults, pending
                )
            )
            continue
        if isinstance(e, Section):
            if not present and e.has_required():
                raise error(f"{source}: missing section '{key}'")
            body = data[e.name] if present else {}
            out[e.name] = _section(e, body, source, key + ".", error, defaults, pending)
        else:
            out[e.name] = _value(e, data, key, source, error, defaults)
    return out


def _conditional(e, data, out, root, key, present, source, error, defaults, pending) -> None:
    used = bool(e.when(root))
    if isinstance(e, Section):
        if used and not present and e.has_required():
            raise error(f"{source}: missing section '{key}' (required when {e.when_text})")
        if present or used:
            body = data[e.name] if present else {}
            out[e.name] = _section(e, body, source, key + ".", error, defaults, pending)
        return
    if not present and not used:
        if not e.required:
            out[e.name] = e.default
        return
    if not present and e.required:
        raise error(f"{source}: missing key '{key}' (required when {e.when_text})")
    if present and not used:
        if not e.required and data[e.name] == e.default:  # means what its absence means
            out[e.name] = e.default
            return
        # a key of another kind would be ignored
        raise error(f"{source}: {_unused_key_message(key, e.when_text, root)}")
    out[e.name] = _value(e, data, key, source, error, defaults)


def _unused_key_message(key: str, when_text: str, root: Mapping) -> str:
    """Why a present key that its condition leaves unused is refused, naming both keys.

    `when_text` names its subject relative to the key's section ("kind is loss" in
    `fault`) or in full ("command.kind is ramp"); the subject's value is quoted.
    """
    parent = key.rpartition(".")[0]
    subject, _, rest = when_text.partition(" is ")
    if parent and rest and "." not in subject:
        subject = f"{parent}.{subject}"
    condition = f"{subject} is {rest}" if rest else when_text
    value = lookup(root, subject) if rest else None
    now = f" ({subject} is {value!r})" if value is not None else ""
    return (f"key '{key}' is used only when {condition}, and here it is not{now}: "
            "remove it (it would be ignored)")


def _value(f: Field, data: Mapping, key: str, source: str, error, defaults) -> Any:
    if f.name not in data:
        if f.required:
            raise error(f"{source}: missing key '{key}' ({f.description})")
        defaults[key] = f.default
        return list(f.default) if isinstance(f.default, tuple) else f.default
    return f.check(data[f.name], f"{source}: key '{key}'", error)


def defaults_text(defaults: Mapping[str, Any]) -> str:
    """`key = value` lines of the defaults used (for design reports)."""
    return "\n".join(f"  {k} = {v!r}" for k, v in sorted(defaults.items()))


def markdown(spec: Section, prefix: str = "") -> str:
    """The declaration as a Markdown table: key, type, unit, range, default, meaning."""
    rows = [
        "| key | type | unit | range / choices | default | meaning |",
        "|---|---|---|---|---|---|",
    ]
    for sec, pre in _sections(spec, prefix):
        if sec.when_text and pre:
            rows.append(f"| `{pre.rstrip('.')}` | section | | | | required when {sec.when_text} |")
        for e in sec.entries:
            if isinstance(e, Section):
                continue
            rng = e.range_text() or ", ".join(str(a) for a in e.allowed())
            default = "required" if e.required else f"`{e.default!r}`"
            if e.when_text:
                default += f" (when {e.when_text})"
            meaning = e.description + (f" ({e.equation})" if e.equation else "")
            rows.append(
                f"| `{pre}{e.name}` | {e.type} | {e.unit} | {rng} | {default} | {meaning} |"
            )
    return "\n".join(rows)


def check_matrix(f: Field, values: Mapping, where: str, error: type[Exception]):
    """A matrix parameter: flat doubles `values[f.name]` reshaped by `values[f.name_shape]`.

    Returns
    -------
    ndarray
        Of the given shape, every entry finite.

    Raises
    ------
    error
        Naming `where` and the key: missing value or shape, wrong count, non-finite.
    """
    import numpy as np

    shape_key = f"{f.name}_shape"
    for key in (f.name, shape_key):
        if values.get(key) is None:
            raise error(f"{where}: parameter '{key}' is missing")
    shape = values[shape_key]
    if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape):
        raise error(f"{where}: parameter '{shape_key}' must be non-negative integers")
    try:
        data = np.asarray(values[f.name], dtype=float)
    except (TypeError, ValueError):
        raise error(f"{where}: parameter '{f.name}' must be an array of doubles") from None
    if data.ndim != 1 or data.size != math.prod(shape):
        raise error(
            f"{where}: parameter '{f.name}' has {data.size} values, but '{shape_key}' = "
            f"{list(shape)} needs {math.prod(shape)}"
        )
    if not np.all(np.isfinite(data)):
        bad = int(np.flatnonzero(~np.isfinite(data))[0])
        raise error(f"{where}: parameter '{f.name}' has a non-finite value at index {bad}")
    return data.reshape(tuple(shape))


def validate_flat(
    fields: Sequence[Field], values: Mapping, where: str, error: type[Exception] = ConfigError
) -> dict:
    """Validate flat parameters (ROS node parameters: dotted names, matrices flattened).

    A value of None counts as absent (a declared ROS parameter that was not set).
    Unknown names are ignored (ROS passes `use_sim_time` and others).

    Returns
    -------
    dict
        Name -> typed value; matrices as ndarrays of their shape.

    Raises
    ------
    error
        Naming `where` (the node) and the parameter.
    """
    out: dict = {}
    for f in fields:
        if f.when is not None and not f.when(values):
            if not f.required:
                out[f.name] = f.default
            continue
        if f.type == "matrix":
            out[f.name] = check_matrix(f, values, where, error)
            continue
        v = values.get(f.name)
        if v is None:
            if f.required:
                raise error(f"{where}: parameter '{f.name}' is missing")
            out[f.name] = f.default
            continue
        out[f.name] = f.check(v, f"{where}: parameter '{f.name}'", error)
    return out
