"""Vehicle data and the longitudinal models CM (eq. 1-3), DM (eq. 4) and ECM (eq. 40).

State vector of CM and DM (eq. 5, 7), shape (9,), units ft, ft/s, rad, rad/s:

    x = [h, V, alpha, theta, q, eta_1, eta_1_dot, eta_2, eta_2_dot]

Input vector, shape (2,):

    u = [Phi, delta_e]        (fuel-to-air ratio [-], elevator deflection [rad])

State vector of ECM (eq. 43), shape (11,):

    x' = [h, V, alpha, theta, q', eta_1, eta_1_dot, eta_2, eta_2_dot, x_q1, x_q2]

where q' is the notch-filtered pitch rate and x_q1, x_q2 the notch states (eq. 39).

All model functions accept real or complex arrays (complex-step differentiation in
`fahv.model.linearize` relies on it), and never use `abs` or branches on the state.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fahv.config.yamlio import load_yaml
from fahv.errors import VehicleDataError
from fahv.model.actuators import Servo, actuators_from_mapping
from fahv.model.entries import finite_number, read_entry
from fahv.model.envelope import Envelope
from fahv.model.limits import InputLimits

# Named indices: CM / DM state (eq. 7).
H, V, ALPHA, THETA, IQ, ETA1, ETA1_DOT, ETA2, ETA2_DOT = range(9)
# ECM adds the notch states (eq. 43); index IQ holds q' in ECM. (IQ, not Q: Q is the
# terminal ellipsoid's matrix of LMI 32-35.)
X_Q1, X_Q2 = 9, 10
# Inputs.
PHI, DELTA_E = 0, 1

STATE_NAMES: tuple[str, ...] = (
    "h",
    "V",
    "alpha",
    "theta",
    "q",
    "eta_1",
    "eta_1_dot",
    "eta_2",
    "eta_2_dot",
)
STATE_UNITS: tuple[str, ...] = ("ft", "ft/s", "rad", "rad", "rad/s", "-", "1/s", "-", "1/s")
ECM_STATE_NAMES: tuple[str, ...] = (
    "h",
    "V",
    "alpha",
    "theta",
    "q_prime",
    "eta_1",
    "eta_1_dot",
    "eta_2",
    "eta_2_dot",
    "x_q1",
    "x_q2",
)
INPUT_NAMES: tuple[str, ...] = ("Phi", "delta_e")
INPUT_UNITS: tuple[str, ...] = ("-", "rad")

DEFAULT_VEHICLE_FILE = "vehicle_parker2007.yaml"

#: Parameters that must be strictly positive for the model to be physical.
_POSITIVE = ("m", "I_yy", "S", "c_bar", "g", "rho_0", "h_s", "omega_1", "omega_2")
#: Parameters that must be non-negative.
_NON_NEGATIVE = ("zeta_1", "zeta_2", "h_0")


@dataclass(frozen=True)
class VehicleParams:
    """Physical parameters of eq. (1)-(3), English units per unit width.

    The attributes are the paper's symbols (docs/reference/vehicle_data.md gives every
    value and its source). Use `dataclasses.replace` or `replace` to perturb
    a parameter (uncertainty sampling).

    Attributes
    ----------
    m : float
        Mass [slug/ft].
    I_yy : float
        Pitch moment of inertia [slug ft^2/ft].
    S : float
        Reference area [ft^2/ft].
    c_bar : float
        Mean aerodynamic chord [ft].
    z_T : float
        Thrust moment arm [ft].
    g : float
        Gravitational acceleration [ft/s^2].
    rho_0, h_0, h_s : float
        Density rho_0 [slug/ft^3] at the altitude h_0 [ft], and the scale height h_s [ft]
        of rho = rho_0 exp(-(h - h_0) / h_s), eq. (3).
    C_L_alpha, C_L_de, C_L_0 : float
        Lift coefficient C_L = C_L_alpha alpha + C_L_de delta_e + C_L_0 [1/rad, 1/rad, -].
    C_D_alpha2, C_D_alpha, C_D_de2, C_D_de, C_D_0 : float
        Drag coefficient, quadratic in alpha and in delta_e [1/rad^2, 1/rad, 1/rad^2,
        1/rad, -].
    C_M_alpha2, C_M_alpha, C_M_0 : float
        Pitching-moment coefficient C_M,alpha(alpha), quadratic in alpha [1/rad^2, 1/rad,
        -].
    c_e : float
        Elevator's pitching-moment coefficient [1/rad].
    beta_1, beta_2, beta_3, beta_4, beta_5, beta_6, beta_7, beta_8 : float
        Thrust T = (beta_1 Phi + beta_2) alpha^3 + (beta_3 Phi + beta_4) alpha^2 +
        (beta_5 Phi + beta_6) alpha + beta_7 Phi + beta_8 [lbf/ft per rad^k].
    zeta_1, omega_1, psi_1 : float
        First flexible mode: damping ratio [-], natural frequency [rad/s] and inertial
        coupling [slug^0.5 ft/ft].
    zeta_2, omega_2, psi_2 : float
        Second flexible mode, as the first.
    N1_alpha2, N1_alpha, N1_0 : float
        Generalised force of mode 1, N_1 = N1_alpha2 alpha^2 + N1_alpha alpha + N1_0
        [generalised force per rad^k].
    N2_alpha2, N2_alpha, N2_de, N2_0 : float
        Generalised force of mode 2, N_2 = N2_alpha2 alpha^2 + N2_alpha alpha +
        N2_de delta_e + N2_0 [generalised force per rad^k].
    """

    m: float
    I_yy: float
    S: float
    c_bar: float
    z_T: float
    g: float
    rho_0: float
    h_0: float
    h_s: float
    C_L_alpha: float
    C_L_de: float
    C_L_0: float
    C_D_alpha2: float
    C_D_alpha: float
    C_D_de2: float
    C_D_de: float
    C_D_0: float
    C_M_alpha2: float
    C_M_alpha: float
    C_M_0: float
    c_e: float
    beta_1: float
    beta_2: float
    beta_3: float
    beta_4: float
    beta_5: float
    beta_6: float
    beta_7: float
    beta_8: float
    zeta_1: float
    omega_1: float
    psi_1: float
    zeta_2: float
    omega_2: float
    psi_2: float
    N1_alpha2: float
    N1_alpha: float
    N1_0: float
    N2_alpha2: float
    N2_alpha: float
    N2_de: float
    N2_0: float

    def replace(self, **changes: float) -> VehicleParams:
        """Return a copy with some parameters changed (e.g. `m=330.0`).

        Parameters
        ----------
        **changes : float
            New values by parameter name, in the units of the attributes.

        Returns
        -------
        VehicleParams
            The copy.

        Examples
        --------
        >>> vp = load_vehicle().params
        >>> heavy = vp.replace(m=1.1 * vp.m)
        >>> round(heavy.m, 6), vp.m
        (330.0, 300.0)
        """
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Vehicle:
    """Everything loaded from one vehicle data file.

    Attributes
    ----------
    params : VehicleParams
        Model parameters of eq. (1)-(3).
    envelope : Envelope
        Flight envelope (sec. 5.1).
    limits : InputLimits
        Actuator limits (sec. 5.1).
    state_scale : (9,) ndarray
        Typical deviation magnitudes of x, used to scale before SVD/LMI work.
    input_scale : (2,) ndarray
        Typical deviation magnitudes of u.
    representative : tuple of str
        Names of parameters that are representative, not published.
    source_file : str
        Path of the file the data came from (`<packaged>/...` for the packaged one).
    name : str
        Vehicle name from the file.
    data_hash : str
        sha256 of the vehicle's numbers (`physics_hash`; "" when built from a
        mapping).
    actuators : dict
        Actuator models of the file's `actuators` section, `{model: {channel:
        Servo}}` (`fahv.model.actuators`; `ideal` needs no data). They do not
        enter `data_hash`: the design does not model the actuators.
    """

    params: VehicleParams
    envelope: Envelope
    limits: InputLimits
    state_scale: np.ndarray
    input_scale: np.ndarray
    representative: tuple[str, ...]
    source_file: str
    name: str = ""
    data_hash: str = ""
    actuators: Mapping[str, Mapping[str, Servo]] = dataclasses.field(default_factory=dict)

    @property
    def packaged(self) -> bool:
        """True for the vehicle file shipped with fahv."""
        return self.source_file.startswith("<packaged>")


def _bounds(section: Mapping[str, Any], key: str, path: str, prefix: str) -> tuple[float, float]:
    """The range `{min, max, unit, source}` of `prefix.key`, checked min < max."""
    full = f"{prefix}.{key}"
    if key not in section:
        raise VehicleDataError(f"{path}: missing key '{full}'")
    entry = section[key]
    if not isinstance(entry, Mapping):
        raise VehicleDataError(f"{path}: '{full}' must be a mapping with 'min', 'max', 'unit'")
    for b in ("min", "max"):
        if b not in entry:
            raise VehicleDataError(f"{path}: missing key '{full}.{b}'")
    lo = finite_number(entry["min"], f"{full}.min", path)
    hi = finite_number(entry["max"], f"{full}.max", path)
    if not lo < hi:
        raise VehicleDataError(f"{path}: '{full}' needs min < max, got [{lo}, {hi}]")
    return lo, hi


def vehicle_from_mapping(data: Mapping[str, Any], path: str = "<mapping>") -> Vehicle:
    """Build a `Vehicle` from the parsed YAML structure of a vehicle file.

    Parameters
    ----------
    data : mapping
        Parsed file with sections `parameters`, `envelope`, `input_limits`,
        `scales` and optionally `actuators` (see
        `src/fahv/data/vehicle_parker2007.yaml`).
    path : str
        Name used in error messages.

    Returns
    -------
    Vehicle

    Raises
    ------
    VehicleDataError
        On a missing key, a non-numeric or non-finite value, a parameter entry
        without a `source`, an unknown parameter, or a non-physical value
        (e.g. `m <= 0`); the message names the key.

    Examples
    --------
    >>> vehicle_from_mapping({"parameters": {}})
    Traceback (most recent call last):
        ...
    fahv.errors.VehicleDataError: <mapping>: missing key 'envelope'
    """
    if not isinstance(data, Mapping):
        raise VehicleDataError(f"{path}: top level must be a mapping, got {type(data).__name__}")
    for section in ("parameters", "envelope", "input_limits", "scales"):
        if section not in data:
            raise VehicleDataError(f"{path}: missing key '{section}'")
        if not isinstance(data[section], Mapping):
            raise VehicleDataError(f"{path}: '{section}' must be a mapping")
    params_in = data["parameters"]
    fields = [f.name for f in dataclasses.fields(VehicleParams)]
    unknown = sorted(set(params_in) - set(fields))
    if unknown:
        raise VehicleDataError(f"{path}: unknown parameter(s) {unknown}; expected {fields}")
    values: dict[str, float] = {}
    representative: list[str] = []
    for key in fields:
        entry = read_entry(params_in, key, path, "parameters")
        values[key] = entry.value
        if entry.representative:
            representative.append(key)
    for key in _POSITIVE:
        if values[key] <= 0.0:
            raise VehicleDataError(
                f"{path}: 'parameters.{key}' = {values[key]} is not physical (must be > 0)"
            )
    for key in _NON_NEGATIVE:
        if values[key] < 0.0:
            raise VehicleDataError(
                f"{path}: 'parameters.{key}' = {values[key]} is not physical (must be >= 0)"
            )

    h_lo, h_hi = _bounds(data["envelope"], "h", path, "envelope")
    v_lo, v_hi = _bounds(data["envelope"], "V", path, "envelope")
    if v_lo <= 0.0:
        raise VehicleDataError(f"{path}: 'envelope.V.min' = {v_lo} is not physical (must be > 0)")
    phi_lo, phi_hi = _bounds(data["input_limits"], "Phi", path, "input_limits")
    de_lo, de_hi = _bounds(data["input_limits"], "delta_e", path, "input_limits")

    def scale(key: str) -> float:
        s = read_entry(data["scales"], key, path, "scales", sourced=False).value
        if s <= 0.0:
            raise VehicleDataError(f"{path}: 'scales.{key}' = {s} must be > 0")
        return s

    actuators = actuators_from_mapping(data.get("actuators"), path)
    servos = actuators.get("second_order", {})
    rates = [tuple(getattr(servos[c], f"rate_limit_{d}") if c in servos else math.inf
                   for c in ("Phi", "delta_e")) for d in ("incr", "decr")]  # fmt: skip
    return Vehicle(
        params=VehicleParams(**values),
        envelope=Envelope(h_lo, h_hi, v_lo, v_hi),
        limits=InputLimits(phi_lo, phi_hi, math.radians(de_lo), math.radians(de_hi), *rates),
        state_scale=np.array(
            [scale(k) for k in STATE_NAMES[:4]] + [scale("q")] + [scale(k) for k in STATE_NAMES[5:]]
        ),
        input_scale=np.array([scale(k) for k in INPUT_NAMES]),
        representative=tuple(representative),
        source_file=path,
        name=str(data.get("name", "")),
        actuators=actuators,
    )


def load_vehicle(path: str | Path | None = None) -> Vehicle:
    """Load and validate a vehicle data file (YAML).

    Parameters
    ----------
    path : str or Path, optional
        Vehicle file; `None` loads the packaged Parker et al. 2007 curve fit with
        representative flexible data (`fahv/data/vehicle_parker2007.yaml`).

    Returns
    -------
    Vehicle

    Raises
    ------
    VehicleDataError
        If the file does not exist, is not valid YAML, or any entry is invalid
        (see `vehicle_from_mapping`); the message names the file and key.

    Examples
    --------
    >>> v = load_vehicle()
    >>> v.name, v.packaged, v.params.m
    ('parker2007-curve-fit', True, 300.0)
    >>> v.envelope
    Envelope(h_min=85000.0, h_max=86500.0, V_min=7700.0, V_max=8300.0)
    >>> round(math.degrees(v.limits.delta_e_max), 6)
    30.0
    >>> load_vehicle("no/such/vehicle.yaml")
    Traceback (most recent call last):
        ...
    fahv.errors.VehicleDataError: vehicle file not found: no/such/vehicle.yaml
    """
    return _vehicle_of_text(*vehicle_file_text(path))


@functools.lru_cache(maxsize=16)
def _vehicle_of_text(text: str, name: str) -> Vehicle:
    """The validated vehicle of a file's text (parsed once per process and content).

    Every caller shares it: its arrays are read-only, so that no caller changes another's
    vehicle (a change raises where it is made).
    """
    vehicle = vehicle_from_mapping(parse_vehicle_text(text, name), name)
    for array in (vehicle.state_scale, vehicle.input_scale):
        array.setflags(write=False)
    return dataclasses.replace(vehicle, data_hash=physics_hash(vehicle))


def read_vehicle_file(path: str | Path | None = None) -> tuple[Any, str]:
    """The parsed YAML of a vehicle file and the name its errors give it.

    The file is read at each call and parsed once per process and content
    (`parse_vehicle_text`): a campaign's runs read it, they do not parse it again.

    Parameters
    ----------
    path : str or Path, optional
        Vehicle file; `None` reads the packaged one (`DEFAULT_VEHICLE_FILE`).

    Returns
    -------
    data : Any
        The parsed document (its sections are checked by their readers).
    name : str
        The file's path, or `<packaged>/vehicle_parker2007.yaml`.

    Raises
    ------
    VehicleDataError
        If the file does not exist, cannot be read or is not valid YAML.
    """
    text, name = vehicle_file_text(path)
    return parse_vehicle_text(text, name), name


def vehicle_file_text(path: str | Path | None = None) -> tuple[str, str]:
    """The text of a vehicle file and the name its errors give it.

    Parameters
    ----------
    path : str or Path, optional
        Vehicle file; `None` reads the packaged one (`DEFAULT_VEHICLE_FILE`).

    Returns
    -------
    text : str
        The file's content.
    name : str
        The file's path, or `<packaged>/vehicle_parker2007.yaml`.

    Raises
    ------
    VehicleDataError
        If the file does not exist or cannot be read.
    """
    if path is None:
        ref = resources.files("fahv.data").joinpath(DEFAULT_VEHICLE_FILE)
        text, name = ref.read_text(), f"<packaged>/{DEFAULT_VEHICLE_FILE}"
    else:
        p = Path(path)
        name = str(p)
        try:
            text = p.read_text()
        except FileNotFoundError:
            raise VehicleDataError(f"vehicle file not found: {name}") from None
        except OSError as exc:
            raise VehicleDataError(f"cannot read vehicle file {name}: {exc}") from None
    return text, name


def parse_vehicle_text(text: str, name: str) -> Any:
    """The parsed YAML document of a vehicle file's text (a fresh copy at each call).

    Parsed once per process and content (PyYAML's pure-Python loader takes about
    0.1 s for the packaged file); each caller gets its own copy of the document.

    Parameters
    ----------
    text : str
        The file's content (`vehicle_file_text`).
    name : str
        The name its errors give the file.

    Returns
    -------
    Any
        The parsed document (its sections are checked by their readers).

    Raises
    ------
    VehicleDataError
        If the text is not valid YAML (names the file `name`).
    """
    return copy.deepcopy(_parsed(text, name))


@functools.lru_cache(maxsize=16)
def _parsed(text: str, name: str) -> Any:
    try:
        return load_yaml(text)
    except yaml.YAMLError as exc:
        raise VehicleDataError(f"{name}: not valid YAML: {exc}") from None


def physics_hash(vehicle: Vehicle) -> str:
    """sha256 of the numbers that define a vehicle (16 hex characters).

    Its parameters, envelope, input position limits and scales, rounded to nothing: every bit of
    every value. Comments, provenance notes and layout of the file do not enter, so a
    design stays valid when only the file's notes change. Raises nothing.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle hashed.

    Returns
    -------
    str
        The first 16 hexadecimal characters of the sha256.

    Examples
    --------
    >>> v = load_vehicle()
    >>> digest = physics_hash(v)
    >>> len(digest), digest == v.data_hash
    (16, True)
    >>> physics_hash(dataclasses.replace(v, params=v.params.replace(m=301.0))) == digest
    False
    """
    numbers = {
        "params": dataclasses.asdict(vehicle.params),
        "envelope": dataclasses.asdict(vehicle.envelope),
        # the position limits (the servos' rates are actuator data, outside the design)
        "limits": {k: v for k, v in dataclasses.asdict(vehicle.limits).items()
                   if not k.startswith("rate_")},  # fmt: skip
        "state_scale": [float(v).hex() for v in vehicle.state_scale],
        "input_scale": [float(v).hex() for v in vehicle.input_scale],
    }
    text = json.dumps(numbers, sort_keys=True, default=lambda v: float(v).hex())
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# ---------------------------------------------------------------------------------
# Forces and moments, eq. (2)-(3)
# ---------------------------------------------------------------------------------
