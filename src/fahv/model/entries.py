"""Entries of the vehicle data file: one number with its unit and its source.

Every number of the vehicle file (`src/fahv/data/vehicle_parker2007.yaml`) is an entry

    m: {value: 300.0, unit: slug/ft, source: "Parker et al. 2007"}

with `representative: true` when the number is not published. `read_entry` reads and
checks one entry (a mapping, a `value` that is a finite number, a `source`, an accepted
unit) for every section that holds them: the `parameters` and `scales` of
`fahv.model.vehicle`, the servos of `fahv.model.actuators` and the noise models of
`fahv.sensors.data`. What the number must be besides (> 0, a whole number of steps) is
checked by the section.

This module imports nothing of `fahv.model`: `fahv.model.vehicle` imports
`fahv.model.actuators`, and both read their entries here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fahv.errors import VehicleDataError

#: Units with other units accepted for them, each with the factor to the unit.
_ALIASES: dict[str, dict[str, float]] = {"rad": {"rad": 1.0, "deg": math.pi / 180.0}}


@dataclass(frozen=True)
class Entry:
    """One entry `{value, unit, source}` of the vehicle file, as `read_entry` returns it.

    Attributes
    ----------
    value : float
        The number, finite, converted to the unit the caller asked for (as written when
        the caller accepts any unit).
    unit : str
        The unit as written in the file ("" when the entry has none).
    source : str
        Where the number comes from ("" when the section needs no source).
    representative : bool
        True if the entry is marked `representative: true` (the number is not published).
    """

    value: float
    unit: str
    source: str
    representative: bool = False


def unit_factors(unit: str) -> dict[str, float]:
    """The units a file may use for a number wanted in `unit`, each with its factor.

    An angle may be given in deg for rad, and the same per second (deg/s for rad/s,
    deg/s/s for rad/s/s); any other unit only as itself. Raises nothing.

    Parameters
    ----------
    unit : str
        The unit wanted (e.g. `rad/s`).

    Returns
    -------
    dict of str to float
        `{accepted unit: factor}`: the value in the accepted unit times the factor is the
        value in `unit`.

    Examples
    --------
    >>> unit_factors("rad/s") == {"rad/s": 1.0, "deg/s": math.pi / 180.0}
    True
    >>> unit_factors("ft")
    {'ft': 1.0}
    """
    if unit in _ALIASES:
        return dict(_ALIASES[unit])
    if unit.endswith("/s"):
        return {u + "/s": f for u, f in unit_factors(unit[:-2]).items()}
    return {unit: 1.0}


def finite_number(value: Any, key: str, path: str) -> float:
    """A number of the vehicle file as a float, checked finite.

    Parameters
    ----------
    value : Any
        The number as parsed from the file; a bool is not a number.
    key : str
        Its full key (e.g. `parameters.m` or `envelope.h.min`), named in errors.
    path : str
        The file, named in errors.

    Returns
    -------
    float
        The value.

    Raises
    ------
    VehicleDataError
        If `value` is not an int or float, or not finite; the message names the file
        and the key.

    Examples
    --------
    >>> finite_number(2, "parameters.m", "veh.yaml")
    2.0
    >>> finite_number(float("nan"), "parameters.m", "veh.yaml")
    Traceback (most recent call last):
        ...
    fahv.errors.VehicleDataError: veh.yaml: 'parameters.m' must be finite, got nan
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise VehicleDataError(f"{path}: '{key}' must be a number, got {value!r}")
    try:
        out = float(value)
    except OverflowError:  # an int beyond the range of a float
        out = math.inf
    if not math.isfinite(out):
        raise VehicleDataError(f"{path}: '{key}' must be finite, got {value!r}")
    return out


def check_section(section: Any, key: str, path: str, allowed=None) -> Mapping[str, Any]:
    """A section of the vehicle file, checked to be a mapping holding only `allowed` keys.

    Parameters
    ----------
    section : Any
        The parsed section.
    key : str
        Its full key (e.g. `sensors.q`), named in errors.
    path : str
        The file, named in errors.
    allowed : collection of str, optional
        The keys the section may hold (None: any).

    Returns
    -------
    mapping
        `section`.

    Raises
    ------
    VehicleDataError
        If `section` is not a mapping or holds a key outside `allowed`; the message
        names the file, the section and the keys expected.

    Examples
    --------
    >>> check_section({"mean": 0, "rate": 1}, "sensors.q", "v.yaml", ["mean"])
    Traceback (most recent call last):
        ...
    fahv.errors.VehicleDataError: v.yaml: unknown key(s) ['rate'] in 'sensors.q'; expected ['mean']
    """
    if not isinstance(section, Mapping):
        raise VehicleDataError(
            f"{path}: '{key}' must be a mapping, got {type(section).__name__}"
        )
    if allowed is not None:
        unknown = sorted(set(section) - set(allowed))
        if unknown:
            raise VehicleDataError(
                f"{path}: unknown key(s) {unknown} in '{key}'; expected {list(allowed)}"
            )
    return section


def read_entry(
    section: Mapping[str, Any],
    key: str,
    path: str,
    prefix: str,
    units: Mapping[str, float] | None = None,
    *,
    sourced: bool = True,
) -> Entry:
    """Read and check the entry `key` of a section of the vehicle file.

    The entry must be a mapping with a `value` that is a finite number (bool is not),
    a non-empty `source` (if `sourced`) and a `unit` among `units` (if given).

    Parameters
    ----------
    section : mapping
        The parsed section holding the entry (e.g. the file's `parameters`).
    key : str
        The entry's key in `section`.
    path : str
        The file, named in errors.
    prefix : str
        The section's full key (e.g. `parameters` or `actuators.second_order.Phi`):
        errors name the entry `prefix.key`.
    units : mapping of str to float, optional
        The accepted units, each with the factor that converts a value in it to the
        unit the caller wants (`unit_factors` gives the usual ones); None accepts any
        unit, or none, and converts nothing.
    sourced : bool, optional
        If False, the entry needs no `source` (design choices such as `scales`).

    Returns
    -------
    Entry
        The value, converted to the unit wanted, with the entry's unit, source and
        `representative` flag.

    Raises
    ------
    VehicleDataError
        If the key is missing, the entry is not a mapping, has no `value` or no
        `source`, its value is not a finite number, or its unit is not accepted; the
        message names the file and the full key.

    Examples
    --------
    >>> q = {"mean": {"value": 0.18, "unit": "deg/s", "source": "Wiese"}}
    >>> e = read_entry(q, "mean", "v.yaml", "sensors.q", unit_factors("rad/s"))
    >>> round(e.value, 8), e.unit, e.source, e.representative
    (0.00314159, 'deg/s', 'Wiese', False)
    >>> read_entry(q, "mean", "v.yaml", "sensors.q", {"ft": 1.0})
    Traceback (most recent call last):
        ...
    fahv.errors.VehicleDataError: v.yaml: 'sensors.q.mean' has unit 'deg/s'; expected one of ['ft']
    """
    full = f"{prefix}.{key}"
    if key not in section:
        raise VehicleDataError(f"{path}: missing key '{full}'")
    entry = section[key]
    if not isinstance(entry, Mapping):
        raise VehicleDataError(
            f"{path}: '{full}' must be a mapping with 'value', 'unit', 'source', "
            f"got {type(entry).__name__}"
        )
    if "value" not in entry:
        raise VehicleDataError(f"{path}: missing key '{full}.value'")
    if sourced and not entry.get("source"):
        raise VehicleDataError(f"{path}: '{full}' has no 'source'")
    value = finite_number(entry["value"], full, path)
    unit = entry.get("unit")
    if units is not None:
        if not isinstance(unit, str) or unit not in units:
            raise VehicleDataError(
                f"{path}: '{full}' has unit {unit!r}; expected one of {sorted(units)}"
            )
        value = value * units[unit]
    return Entry(
        value=value,
        unit="" if unit is None else str(unit),
        source=str(entry.get("source") or ""),
        representative=bool(entry.get("representative", False)),
    )
