"""Vehicle data and the longitudinal models CM (eq. 1-3), DM (eq. 4) and ECM (eq. 40).

State vector of CM and DM (eq. 5, 7), shape (9,), units ft, ft/s, rad, rad/s::

    x = [h, V, alpha, theta, q, eta_1, eta_1_dot, eta_2, eta_2_dot]

Input vector, shape (2,)::

    u = [Phi, delta_e]        (fuel-to-air ratio [-], elevator deflection [rad])

State vector of ECM (eq. 43), shape (11,)::

    x' = [h, V, alpha, theta, q', eta_1, eta_1_dot, eta_2, eta_2_dot, x_q1, x_q2]

where q' is the notch-filtered pitch rate and x_q1, x_q2 the notch states (eq. 39).

All model functions accept real or complex arrays (complex-step differentiation in
:mod:`fahv.linearize` relies on it), and never use ``abs`` or branches on the state.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fahv.errors import EnvelopeError, VehicleDataError
from fahv.yamlio import load_yaml

# Named indices: CM / DM state (eq. 7).
H, V, ALPHA, THETA, Q, ETA1, ETA1_DOT, ETA2, ETA2_DOT = range(9)
# ECM adds the notch states (eq. 43); index Q holds q' in ECM.
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

    Attributes are the paper's symbols: ``m`` [slug/ft], ``I_yy`` [slug ft^2/ft],
    ``S`` [ft^2/ft], ``c_bar`` [ft], ``z_T`` [ft], ``g`` [ft/s^2], ``rho_0``
    [slug/ft^3], ``h_0`` [ft], ``h_s`` [ft], aerodynamic coefficients (per rad),
    thrust coefficients ``beta_1..beta_8`` [lbf/ft per rad^k], and the flexible
    data ``zeta_i``, ``omega_i`` [rad/s], ``psi_i`` and ``N*`` coefficients.
    Use :func:`dataclasses.replace` to perturb a parameter (uncertainty sampling).
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
        """Return a copy with some parameters changed (e.g. ``m=330.0``)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Envelope:
    """Flight envelope Gamma = [h_min, h_max] x [V_min, V_max] (ft, ft/s), sec. 5.1."""

    h_min: float
    h_max: float
    V_min: float
    V_max: float

    def contains(self, h: float, V: float, rtol: float = 1e-12) -> bool:
        """True if (h, V) lies in the closed envelope (relative tolerance ``rtol``)."""
        th = rtol * max(abs(self.h_max), 1.0)
        tv = rtol * max(abs(self.V_max), 1.0)
        return (self.h_min - th <= h <= self.h_max + th) and (
            self.V_min - tv <= V <= self.V_max + tv
        )

    def check(self, h: float, V: float) -> None:
        """Raise :class:`EnvelopeError` naming the envelope if (h, V) lies outside it."""
        if not (np.isfinite(h) and np.isfinite(V)) or not self.contains(h, V):
            raise EnvelopeError(
                f"flight condition h = {h} ft, V = {V} ft/s lies outside the flight envelope "
                f"h in [{self.h_min}, {self.h_max}] ft, V in [{self.V_min}, {self.V_max}] ft/s"
            )


@dataclass(frozen=True)
class InputLimits:
    """Actuator limits of sec. 5.1: Phi in [Phi_min, Phi_max], delta_e in rad."""

    Phi_min: float
    Phi_max: float
    delta_e_min: float
    delta_e_max: float

    @property
    def u_min(self) -> np.ndarray:
        """Lower input bounds, shape (2,), [-, rad]."""
        return np.array([self.Phi_min, self.delta_e_min])

    @property
    def u_max(self) -> np.ndarray:
        """Upper input bounds, shape (2,), [-, rad]."""
        return np.array([self.Phi_max, self.delta_e_max])


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
        Path of the file the data came from.
    """

    params: VehicleParams
    envelope: Envelope
    limits: InputLimits
    state_scale: np.ndarray
    input_scale: np.ndarray
    representative: tuple[str, ...]
    source_file: str
    name: str = ""


def _number(value: Any, key: str, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise VehicleDataError(f"{path}: '{key}' must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise VehicleDataError(f"{path}: '{key}' must be finite, got {value!r}")
    return out


def _entry(section: Mapping[str, Any], key: str, path: str, prefix: str) -> Mapping[str, Any]:
    full = f"{prefix}.{key}"
    if key not in section:
        raise VehicleDataError(f"{path}: missing key '{full}'")
    entry = section[key]
    if not isinstance(entry, Mapping):
        raise VehicleDataError(f"{path}: '{full}' must be a mapping with 'value', 'unit', 'source'")
    return entry


def vehicle_from_mapping(data: Mapping[str, Any], path: str = "<mapping>") -> Vehicle:
    """Build a :class:`Vehicle` from the parsed YAML structure of a vehicle file.

    Parameters
    ----------
    data : mapping
        Parsed file with sections ``parameters``, ``envelope``, ``input_limits``,
        ``scales`` (see ``src/fahv/data/vehicle_parker2007.yaml``).
    path : str
        Name used in error messages.

    Returns
    -------
    Vehicle

    Raises
    ------
    VehicleDataError
        On a missing key, a non-numeric or non-finite value, a parameter entry
        without a ``source``, an unknown parameter, or a non-physical value
        (e.g. ``m <= 0``); the message names the key.
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
        entry = _entry(params_in, key, path, "parameters")
        if "value" not in entry:
            raise VehicleDataError(f"{path}: missing key 'parameters.{key}.value'")
        if not entry.get("source"):
            raise VehicleDataError(f"{path}: 'parameters.{key}' has no 'source'")
        values[key] = _number(entry["value"], f"parameters.{key}", path)
        if entry.get("representative", False):
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

    def bounds(section: str, key: str) -> tuple[float, float]:
        entry = _entry(data[section], key, path, section)
        for b in ("min", "max"):
            if b not in entry:
                raise VehicleDataError(f"{path}: missing key '{section}.{key}.{b}'")
        lo = _number(entry["min"], f"{section}.{key}.min", path)
        hi = _number(entry["max"], f"{section}.{key}.max", path)
        if not lo < hi:
            raise VehicleDataError(f"{path}: '{section}.{key}' needs min < max, got [{lo}, {hi}]")
        return lo, hi

    h_lo, h_hi = bounds("envelope", "h")
    v_lo, v_hi = bounds("envelope", "V")
    if v_lo <= 0.0:
        raise VehicleDataError(f"{path}: 'envelope.V.min' = {v_lo} is not physical (must be > 0)")
    phi_lo, phi_hi = bounds("input_limits", "Phi")
    de_lo, de_hi = bounds("input_limits", "delta_e")

    def scale(key: str) -> float:
        entry = _entry(data["scales"], key, path, "scales")
        if "value" not in entry:
            raise VehicleDataError(f"{path}: missing key 'scales.{key}.value'")
        s = _number(entry["value"], f"scales.{key}", path)
        if s <= 0.0:
            raise VehicleDataError(f"{path}: 'scales.{key}' = {s} must be > 0")
        return s

    return Vehicle(
        params=VehicleParams(**values),
        envelope=Envelope(h_lo, h_hi, v_lo, v_hi),
        limits=InputLimits(phi_lo, phi_hi, math.radians(de_lo), math.radians(de_hi)),
        state_scale=np.array(
            [scale(k) for k in STATE_NAMES[:4]] + [scale("q")] + [scale(k) for k in STATE_NAMES[5:]]
        ),
        input_scale=np.array([scale(k) for k in INPUT_NAMES]),
        representative=tuple(representative),
        source_file=path,
        name=str(data.get("name", "")),
    )


def load_vehicle(path: str | Path | None = None) -> Vehicle:
    """Load and validate a vehicle data file (YAML).

    Parameters
    ----------
    path : str or Path, optional
        Vehicle file; ``None`` loads the packaged Parker et al. 2007 curve fit with
        representative flexible data (``fahv/data/vehicle_parker2007.yaml``).

    Returns
    -------
    Vehicle

    Raises
    ------
    VehicleDataError
        If the file does not exist, is not valid YAML, or any entry is invalid
        (see :func:`vehicle_from_mapping`); the message names the file and key.
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
    try:
        data = load_yaml(text)
    except yaml.YAMLError as exc:
        raise VehicleDataError(f"{name}: not valid YAML: {exc}") from None
    return vehicle_from_mapping(data, name)


# ---------------------------------------------------------------------------------
# Forces and moments, eq. (2)-(3)
# ---------------------------------------------------------------------------------


def density(h, vp: VehicleParams):
    """Air density rho(h) [slug/ft^3], eq. (3) with the exponent (h - h_0)/h_s.

    The paper prints ``exp(-h-h_s/h_0)``; the exponential model of Parker et al.
    2007 is ``rho_0 exp(-(h - h_0)/h_s)`` (MODEL_DATA.md).
    """
    return vp.rho_0 * np.exp(-(h - vp.h_0) / vp.h_s)


def forces(x, u, vp: VehicleParams):
    """Lift, drag, thrust, pitching moment and generalized forces, eq. (2)-(3).

    Parameters
    ----------
    x : (>=5,) array_like, real or complex
        State; only h, V, alpha (indices 0-2) are used: in the paper's CM the
        flexible states do not enter L, D, T, M.
    u : (2,) array_like
        [Phi, delta_e] (delta_e in rad).
    vp : VehicleParams

    Returns
    -------
    L, D, T, M, N1, N2
        Forces [lbf/ft], moment [lbf ft/ft], generalized forces.

    Notes
    -----
    M = z_T T + q_bar S c_bar (C_M,alpha(alpha) + c_e delta_e), as in Parker et
    al. 2007 (the paper's eq. (2) drops the factor T after z_T).
    """
    h, Vel, alpha = x[H], x[V], x[ALPHA]
    Phi, de = u[PHI], u[DELTA_E]
    qbar = 0.5 * density(h, vp) * Vel * Vel
    C_L = vp.C_L_alpha * alpha + vp.C_L_de * de + vp.C_L_0
    C_D = (
        vp.C_D_alpha2 * alpha * alpha
        + vp.C_D_alpha * alpha
        + vp.C_D_de2 * de * de
        + vp.C_D_de * de
        + vp.C_D_0
    )
    C_M = vp.C_M_alpha2 * alpha * alpha + vp.C_M_alpha * alpha + vp.C_M_0 + vp.c_e * de
    C_T3 = vp.beta_1 * Phi + vp.beta_2
    C_T2 = vp.beta_3 * Phi + vp.beta_4
    C_T1 = vp.beta_5 * Phi + vp.beta_6
    C_T0 = vp.beta_7 * Phi + vp.beta_8
    L = qbar * vp.S * C_L
    D = qbar * vp.S * C_D
    T = ((C_T3 * alpha + C_T2) * alpha + C_T1) * alpha + C_T0
    M = vp.z_T * T + qbar * vp.S * vp.c_bar * C_M
    N1 = vp.N1_alpha2 * alpha * alpha + vp.N1_alpha * alpha + vp.N1_0
    N2 = vp.N2_alpha2 * alpha * alpha + vp.N2_alpha * alpha + vp.N2_de * de + vp.N2_0
    return L, D, T, M, N1, N2


def _rigid_kinematics(x, q, T, D, L, vp: VehicleParams):
    """h_dot, V_dot, alpha_dot, theta_dot of eq. (1)/(4) for a given pitch rate q."""
    Vel, alpha, theta = x[V], x[ALPHA], x[THETA]
    gamma = theta - alpha
    h_dot = Vel * np.sin(gamma)
    V_dot = (T * np.cos(alpha) - D) / vp.m - vp.g * np.sin(gamma)
    alpha_dot = (-T * np.sin(alpha) - L) / (vp.m * Vel) + q + vp.g / Vel * np.cos(gamma)
    return h_dot, V_dot, alpha_dot, q


def cm_rhs(x, u, vp: VehicleParams) -> np.ndarray:
    """Coupling model CM, eq. (1)-(3): x_dot = f(x, u).

    Parameters
    ----------
    x : (9,) array_like
        [h ft, V ft/s, alpha rad, theta rad, q rad/s, eta_1, eta_1_dot, eta_2, eta_2_dot].
    u : (2,) array_like
        [Phi -, delta_e rad].
    vp : VehicleParams

    Returns
    -------
    x_dot : (9,) ndarray
        Same dtype kind as the inputs (complex inputs give a complex result).

    Notes
    -----
    The two coupled flexible equations of eq. (1) are solved exactly as one linear
    system in (eta_1_ddot, eta_2_ddot)::

        [k_1             psi_1 psi_2/I] [eta_1_ddot]   [r_1]
        [psi_1 psi_2/I   k_2          ] [eta_2_ddot] = [r_2],
        r_i = -2 zeta_i omega_i eta_i_dot - omega_i^2 eta_i + N_i - psi_i M / I_yy,

    with k_i = 1 + psi_i^2 / I_yy, then q_dot = (M + psi_1 eta_1_ddot +
    psi_2 eta_2_ddot) / I_yy.
    """
    L, D, T, M, N1, N2 = forces(x, u, vp)
    h_dot, V_dot, alpha_dot, theta_dot = _rigid_kinematics(x, x[Q], T, D, L, vp)
    eta_dd1, eta_dd2 = _flexible_accelerations(x, M, N1, N2, vp)
    q_dot = (M + vp.psi_1 * eta_dd1 + vp.psi_2 * eta_dd2) / vp.I_yy
    return np.array(
        [h_dot, V_dot, alpha_dot, theta_dot, q_dot, x[ETA1_DOT], eta_dd1, x[ETA2_DOT], eta_dd2]
    )


def _flexible_accelerations(x, M, N1, N2, vp: VehicleParams):
    """Solve the coupled eta_ddot equations of eq. (1) (2x2 linear system, Cramer)."""
    k1 = 1.0 + vp.psi_1**2 / vp.I_yy
    k2 = 1.0 + vp.psi_2**2 / vp.I_yy
    c = vp.psi_1 * vp.psi_2 / vp.I_yy
    r1 = (
        -2.0 * vp.zeta_1 * vp.omega_1 * x[ETA1_DOT]
        - vp.omega_1**2 * x[ETA1]
        + N1
        - vp.psi_1 * M / vp.I_yy
    )
    r2 = (
        -2.0 * vp.zeta_2 * vp.omega_2 * x[ETA2_DOT]
        - vp.omega_2**2 * x[ETA2]
        + N2
        - vp.psi_2 * M / vp.I_yy
    )
    det = k1 * k2 - c * c
    return (k2 * r1 - c * r2) / det, (k1 * r2 - c * r1) / det


def dm_rhs(x, u, vp: VehicleParams) -> np.ndarray:
    """Decoupled model DM, eq. (4): CM without the inertial coupling psi_i.

    Shapes and units as :func:`cm_rhs`. q_dot = M / I_yy and
    eta_i_ddot = -2 zeta_i omega_i eta_i_dot - omega_i^2 eta_i + N_i.
    """
    L, D, T, M, N1, N2 = forces(x, u, vp)
    h_dot, V_dot, alpha_dot, theta_dot = _rigid_kinematics(x, x[Q], T, D, L, vp)
    eta_dd1 = -2.0 * vp.zeta_1 * vp.omega_1 * x[ETA1_DOT] - vp.omega_1**2 * x[ETA1] + N1
    eta_dd2 = -2.0 * vp.zeta_2 * vp.omega_2 * x[ETA2_DOT] - vp.omega_2**2 * x[ETA2] + N2
    return np.array(
        [
            h_dot,
            V_dot,
            alpha_dot,
            theta_dot,
            M / vp.I_yy,
            x[ETA1_DOT],
            eta_dd1,
            x[ETA2_DOT],
            eta_dd2,
        ]
    )


def ecm_rhs(x, u, vp: VehicleParams, A_q, B_q, C_q, D_q) -> np.ndarray:
    """Extended coupling model ECM, eq. (39)-(40): CM in series with the notch filter.

    Parameters
    ----------
    x : (11,) array_like
        [h, V, alpha, theta, q', eta_1, eta_1_dot, eta_2, eta_2_dot, x_q1, x_q2],
        q' the filtered pitch rate [rad/s] (eq. 43).
    u : (2,) array_like
        [Phi, delta_e rad].
    vp : VehicleParams
    A_q : (2, 2) array_like
    B_q : (2,) array_like
    C_q : (2,) array_like
    D_q : float
        Notch filter state space of eq. (39); D_q must be non-zero (it is 1 for
        the notch of eq. (38) with equal leading coefficients).

    Returns
    -------
    x_dot : (11,) ndarray

    Notes
    -----
    Eq. (40) writes alpha_dot and theta_dot with q' in place of q. That changes
    the physics (the body does not rotate at the filtered rate). Here the true
    pitch rate is recovered from the filter output equation (39),
    q = (q' - C_q x_q) / D_q, so that the ECM is exactly the CM in series with
    the filter, which is the system the controller actually acts on. The
    derivative of q' is eq. (40): q'_dot = C_q x_q_dot + D_q q_dot.
    """
    x_q = x[9:11]
    q = (x[Q] - (C_q[0] * x_q[0] + C_q[1] * x_q[1])) / D_q
    x_cm = np.concatenate([x[:4], [q], x[5:9]])
    f = cm_rhs(x_cm, u, vp)
    xq_dot = np.array(
        [
            A_q[0][0] * x_q[0] + A_q[0][1] * x_q[1] + B_q[0] * q,
            A_q[1][0] * x_q[0] + A_q[1][1] * x_q[1] + B_q[1] * q,
        ]
    )
    qp_dot = C_q[0] * xq_dot[0] + C_q[1] * xq_dot[1] + D_q * f[Q]
    return np.concatenate([f[:4], [qp_dot], f[5:9], xq_dot])


MODEL_KINDS = ("dm", "cm", "ecm")


@dataclass(frozen=True)
class Model:
    """One of the longitudinal models as a function x_dot = f(x, u).

    Attributes
    ----------
    kind : {"dm", "cm", "ecm"}
        Decoupled model (eq. 4), coupling model (eq. 1-3) or extended coupling
        model with notch states (eq. 40).
    params : VehicleParams
    notch_ss : tuple or None
        (A_q (2, 2), B_q (2,), C_q (2,), D_q) of eq. (39); required for "ecm".

    Raises
    ------
    ValueError
        On an unknown kind, or "ecm" without a notch filter or with D_q = 0.
    """

    kind: str
    params: VehicleParams
    notch_ss: tuple | None = None

    def __post_init__(self) -> None:
        if self.kind not in MODEL_KINDS:
            raise ValueError(f"model kind must be one of {MODEL_KINDS}, got {self.kind!r}")
        if self.kind == "ecm":
            if self.notch_ss is None:
                raise ValueError("model kind 'ecm' needs the notch filter state space (eq. 39)")
            if self.notch_ss[3] == 0.0:
                raise ValueError("ECM needs a notch filter with D_q != 0 (q' = C_q x_q + D_q q)")

    @property
    def n_x(self) -> int:
        """Number of states: 9 (DM, CM) or 11 (ECM)."""
        return 11 if self.kind == "ecm" else 9

    @property
    def state_names(self) -> tuple[str, ...]:
        """State names in order (eq. 7 or eq. 43)."""
        return ECM_STATE_NAMES if self.kind == "ecm" else STATE_NAMES

    def f(self, x, u) -> np.ndarray:
        """Evaluate x_dot = f(x, u); x shape (n_x,), u (2,), units as the module docstring."""
        if self.kind == "cm":
            return cm_rhs(x, u, self.params)
        if self.kind == "dm":
            return dm_rhs(x, u, self.params)
        return ecm_rhs(x, u, self.params, *self.notch_ss)

    def state_scale(self, vehicle: Vehicle, notch=None) -> np.ndarray:
        """Scale vector of the states, shape (n_x,), from the vehicle file (and notch)."""
        if self.kind != "ecm":
            return vehicle.state_scale.copy()
        if notch is None:
            raise ValueError("ECM state scaling needs the NotchFilter")
        return np.concatenate([vehicle.state_scale, notch.state_scale(vehicle.state_scale[Q])])


def make_model(kind: str, vehicle: Vehicle | VehicleParams, notch=None) -> Model:
    """Build a :class:`Model` of the given kind.

    Parameters
    ----------
    kind : {"dm", "cm", "ecm"}
    vehicle : Vehicle or VehicleParams
    notch : fahv.notch.NotchFilter, optional
        Required for "ecm".
    """
    params = vehicle.params if isinstance(vehicle, Vehicle) else vehicle
    return Model(kind, params, notch.ss() if (kind == "ecm" and notch is not None) else None)
