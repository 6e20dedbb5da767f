"""The loop messages, written once: typed, batch-first, and the source of the `.msg` files.

Every message of the SIL loop is one dataclass here. Its fields are the fields of the
ROS 2 message of the same name (package `hsv_interfaces`), in order, each declared
with its ROS type and comment; the `*.msg` files beside this module are generated
from these classes (`msg_text`, checked by a test), and they are the sources
the colcon package builds.

Batch axis
    A message holds one step k of B runs at once: `k` and `t` are shared; every
    other field has a leading axis of B lanes (`float64` -> (B,) float, `float64[]`
    -> (B, n) float, `bool` -> (B,) bool, `int64` -> (B,) int, `string` -> tuple
    of B str). The nodes of the graph and the in-process simulator use B = 1, a
    campaign batch B = 50-100; the same classes serve all of them.

Lane form
    `LoopMessage.lane` gives one run's fields as plain values (the form the ROS
    codec, the MCAP writer and the Foxglove server serialise), and
    `LoopMessage.from_lanes` is its inverse, so no code builds a message by hand.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

#: Folder of the generated `*.msg` files (also the hsv_interfaces sources).
MSG_DIR = Path(__file__).resolve().parent
#: ROS 2 package of the loop messages.
PKG = "hsv_interfaces"
#: Fields shared by every lane of a message (the step).
STEP_FIELDS = ("k", "t")


def _f(ros: str, doc: str) -> Any:
    """A message field: its ROS 2 type and its comment in the `.msg` file."""
    return field(metadata={"ros": ros, "doc": doc})


_STEP_K = "step index"
_STEP_T = "simulated time t_k [s]"


class LoopMessage:
    """Base of the loop messages (see the module notes for shapes).

    Subclasses are frozen dataclasses whose fields carry `metadata["ros"]` (ROS 2
    type) and `metadata["doc"]` (comment), and set `HEADER` (the comment
    lines that open the `.msg` file).
    """

    HEADER: ClassVar[tuple[str, ...]] = ()
    #: Fields added after runs were recorded without them: `from_lanes` reads them as
    #: NaN when a run's lanes lack them (a float64 field each).
    OPTIONAL: ClassVar[tuple[str, ...]] = ()

    @classmethod
    @functools.cache  # every codec call asks: built once per class (the classes are frozen)
    def ros_fields(cls) -> tuple[tuple[str, str, str], ...]:
        """(name, ROS type, comment) of every field, in message order (cached per class)."""
        return tuple(
            (f.name, f.metadata["ros"], f.metadata["doc"]) for f in dataclasses.fields(cls)
        )

    @classmethod
    def ros_type(cls) -> str:
        """Full ROS 2 type name, e.g. `hsv_interfaces/msg/VehicleState`."""
        return f"{PKG}/msg/{cls.__name__}"

    @property
    def lanes(self) -> int:
        """Number of runs B the message holds."""
        for name, _, _ in self.ros_fields():
            if name not in STEP_FIELDS:
                return len(getattr(self, name))
        return 1

    def lane(self, b: int = 0) -> dict:
        """Fields of run `b` as plain values: int, float, bool, str, or a (n,) ndarray.

        Raises
        ------
        IndexError
            If `b` is not a lane of the message.
        """
        out = {}
        for name, ros, _ in self.ros_fields():
            v = getattr(self, name)
            if name in STEP_FIELDS:
                out[name] = v
            elif ros == "float64":
                out[name] = float(v[b])
            elif ros == "int64":
                out[name] = int(v[b])
            elif ros == "bool":
                out[name] = bool(v[b])
            elif ros == "string":
                out[name] = str(v[b])
            else:  # float64[]
                out[name] = np.asarray(v[b], dtype=float)
        return out

    @classmethod
    def from_lanes(cls, lanes: list[dict]):
        """Message of B = len(lanes) runs from their lane forms (`lane`).

        `k` and `t` are taken from the first lane. Variable-length arrays must have
        the same length in every lane.

        Raises
        ------
        KeyError
            Naming a missing field (not one of `OPTIONAL`).
        ValueError
            If `lanes` is empty or an array field has different lengths.
        """
        if not lanes:
            raise ValueError(f"{cls.__name__}: a message needs at least one lane")
        values = {}
        for name, ros, _ in cls.ros_fields():
            if name in cls.OPTIONAL and name not in lanes[0]:
                col = [math.nan] * len(lanes)
            else:
                col = [d[name] for d in lanes]
            if name in STEP_FIELDS:
                values[name] = col[0]
            elif ros == "float64":
                values[name] = np.array(col, dtype=float)
            elif ros == "int64":
                values[name] = np.array(col, dtype=np.int64)
            elif ros == "bool":
                values[name] = np.array(col, dtype=bool)
            elif ros == "string":
                values[name] = tuple(str(s) for s in col)
            elif len(col) == 1:  # one run (every node of the graph): no stacking
                values[name] = np.array(col[0], dtype=float)[None, :]
            else:
                rows = [np.asarray(c, dtype=float) for c in col]
                if len({r.shape for r in rows}) != 1:
                    raise ValueError(f"{cls.__name__}.{name}: lanes of different lengths")
                values[name] = np.stack(rows)
        return cls(**values)


@dataclass(frozen=True)
class StateColumns(LoopMessage):
    """The step and the nine CM state fields (B,) a plant state and an estimate share.

    Not a message of its own: `VehicleState` and `StateEstimate` add their fields.
    """

    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    h: np.ndarray = _f("float64", "altitude [ft]")
    v: np.ndarray = _f("float64", "velocity V [ft/s]")
    alpha: np.ndarray = _f("float64", "angle of attack [rad]")
    theta: np.ndarray = _f("float64", "pitch angle [rad]")
    q: np.ndarray = _f("float64", "pitch rate [rad/s]")
    eta_1: np.ndarray = _f("float64", "first generalised flexible coordinate")
    eta_1_dot: np.ndarray = _f("float64", "its rate [1/s]")
    eta_2: np.ndarray = _f("float64", "second generalised flexible coordinate")
    eta_2_dot: np.ndarray = _f("float64", "its rate [1/s]")

    #: State fields in plant state order (eq. 7).
    STATE: ClassVar[tuple[str, ...]] = (
        "h", "v", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot"
    )  # fmt: skip

    def x(self) -> np.ndarray:
        """States (B, 9) [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s]."""
        out = np.empty(np.shape(self.h) + (9,))  # filled column by column: cheaper than np.stack
        for i, f in enumerate(self.STATE):
            out[..., i] = getattr(self, f)
        return out


@dataclass(frozen=True)
class VehicleState(StateColumns):
    """Plant state x_k (9 fields of (B,)) of the CM, eq. (1)-(3)."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Plant state x_k of the coupling model CM (Yang et al. 2022, eq. 1-3) at step k.",
        "Published by the plant at t_k = k * Ts, before it integrates [t_k, t_k+1],",
        "with the actuator positions at t_k (ideal actuators: the command held over",
        "[t_k-1, t_k]) and each servo's peak rate within [t_k-1, t_k].",
    )
    phi_a: np.ndarray = _f(
        "float64", "actuator position: Phi at the engine [-] (NaN before the first command)"
    )
    delta_e_a: np.ndarray = _f(
        "float64", "actuator position: elevator deflection [rad] (NaN before the first command)"
    )
    phi_a_rate_peak: np.ndarray = _f(
        "float64", "Phi servo: peak |rate| within [t_k-1, t_k] [1/s] (NaN: no servo, or step 0)"
    )
    delta_e_a_rate_peak: np.ndarray = _f(
        "float64",
        "elevator servo: peak |rate| within [t_k-1, t_k] [rad/s] (NaN: no servo, or step 0)",
    )

    OPTIONAL: ClassVar[tuple[str, ...]] = ("phi_a_rate_peak", "delta_e_a_rate_peak")

    @classmethod
    def of(
        cls, k: int, t: float, x: np.ndarray, u_a: np.ndarray | None = None,
        rate_peak: np.ndarray | None = None,
    ) -> VehicleState:
        """Message of step k: plant states, actuator positions, the servos' peak rates.

        x (B, 9) are the states, u_a (B, 2) [Phi, rad] the actuator positions and
        rate_peak (B, 2) [1/s, rad/s] the servos' peak |rate| within the period before
        (`fahv.plant.rk4.rk4_cm_act`). The columns are copied; `u_a` None (before the
        first command) and `rate_peak` None (ideal actuators, or before the first
        command) give NaN.
        """
        x = np.array(x, dtype=float)
        nan = np.full((len(x), 2), np.nan)
        u_a = nan if u_a is None else np.array(u_a, dtype=float)
        peak = nan if rate_peak is None else np.array(rate_peak, dtype=float)
        return cls(k, t, *(x[:, i] for i in range(9)), u_a[:, 0], u_a[:, 1], peak[:, 0],
                   peak[:, 1])  # fmt: skip

    def u_a(self) -> np.ndarray:
        """Actuator positions (B, 2) [Phi, delta_e rad] (NaN before the first command)."""
        return np.stack([np.asarray(self.phi_a, float), np.asarray(self.delta_e_a, float)], axis=1)

    def rate_peak(self) -> np.ndarray:
        """Servos' peak |rate| (B, 2) [1/s, rad/s] within the period before t_k (NaN: none)."""
        return np.stack(
            [np.asarray(self.phi_a_rate_peak, float), np.asarray(self.delta_e_a_rate_peak, float)],
            axis=1,
        )


@dataclass(frozen=True)
class StateEstimate(StateColumns):
    """Estimate x_k|k of the CM state (9 fields of (B,)) from the measurement of step k."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Estimate x_k|k of the coupling model's state (Yang et al. 2022, eq. 1-3) at step k,",
        "from the measurement y_k and the commands before it (fahv.estimation). The notch,",
        "the nominal trajectory and the controller read it; no controller node reads",
        "/hsv/state. Estimator none: the exact state of a full-state sensor (the paper's",
        "loop).",
    )
    estimator: tuple = _f("string", "estimator of the run: none (exact state) or kalman")
    sigma: np.ndarray = _f(
        "float64[]", "standard deviation of each state's error, state order (empty: none)"
    )

    @classmethod
    def of(cls, k: int, t: float, x: np.ndarray, estimator: tuple, sigma: np.ndarray):
        """Message of step k from estimates x (B, 9), names (B,) and sigma (B, 9 or 0)."""
        x = np.array(x, dtype=float)
        return cls(k, t, *(x[:, i] for i in range(9)), estimator, np.array(sigma, dtype=float))


@dataclass(frozen=True)
class Measurement(LoopMessage):
    """Sensor measurement y_k of step k: the measured channels of the true state."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Sensor measurement y_k at step k: the measured channels of the true state x_k with",
        "each sensor's delay, lag, sample-and-hold, biases, noise, fault and quantisation",
        "(fahv.sensors). Published by the plant with /hsv/state: the sensors are part of the",
        "simulated vehicle. The flexible states are never measured; the gyro's q sees them",
        "through the mode slopes.",
    )
    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    channels: tuple = _f("string", "measured channels, comma-separated (e.g. h,V,theta,q)")
    y: np.ndarray = _f(
        "float64[]", "measured values in channel order [ft, ft/s, rad, rad/s, rad]; empty: none"
    )


@dataclass(frozen=True)
class FilteredPitchRate(LoopMessage):
    """Pitch rate through the notch filter (eq. 38-39) of step k."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Pitch rate through the notch filter (eq. 38-39) at step k.",
    )
    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    q: np.ndarray = _f("float64", "pitch rate at the filter input [rad/s]")
    q_f: np.ndarray = _f(
        "float64", "filtered pitch rate q' [rad/s] (= q when the filter is disabled)"
    )
    enabled: np.ndarray = _f("bool", "false: pass-through (Tube-MPC without notch)")
    x_q: np.ndarray = _f(
        "float64[]", "filter states x_q1, x_q2 of the ECM (eq. 40-43); empty when disabled"
    )


@dataclass(frozen=True)
class NominalTrajectory(LoopMessage):
    """Reference (x_r, u_r) and nominal trajectory (x_n, u_n) of step k."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Reference and nominal trajectory of step k: online tracking MPC, or eq. 20 / 46 "
        "(u_n = K x_n).",
    )
    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    h_c: np.ndarray = _f("float64", "commanded altitude [ft]")
    v_c: np.ndarray = _f("float64", "commanded velocity [ft/s]")
    h_g: np.ndarray = _f("float64", "governed reference (MPC: artificial set point) altitude [ft]")
    v_g: np.ndarray = _f(
        "float64", "governed reference (MPC: artificial set point) velocity [ft/s]"
    )
    x_r: np.ndarray = _f(
        "float64[]", "trim state at (h_g, v_g), 9 or 11 values (design-model order)"
    )
    u_r: np.ndarray = _f("float64[]", "trim input [Phi, delta_e rad]")
    x_n: np.ndarray = _f("float64[]", "nominal state deviation, same length as x_r")
    u_n: np.ndarray = _f("float64[]", "nominal input K x_n [Phi, delta_e rad]")
    level: np.ndarray = _f(
        "float64", "x_n' Q^-1 x_n (<= 1 inside the certified ellipsoid; NaN without governor)"
    )
    qp_solves: np.ndarray = _f(
        "int64", "nominal MPC: QPs solved and accepted so far (0 without MPC)"
    )
    qp_fallback: np.ndarray = _f(
        "int64", "nominal MPC: nominal steps on the shifted previous plan (QP rejected)"
    )
    qp_terminal: np.ndarray = _f(
        "int64", "nominal MPC: nominal steps on the terminal law (no plan left)"
    )
    d_hat: np.ndarray = _f(
        "float64[]", "input disturbance estimate [Phi, delta_e rad] (zeros without MPC)"
    )
    qp_recovered: np.ndarray = _f(
        "int64", "nominal MPC: re-plans by the recovery QP (set point free; QP infeasible)"
    )


@dataclass(frozen=True)
class ControlCommand(LoopMessage):
    """Actuator inputs of step k (controller command or input after the fault injector)."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Actuator inputs of step k: the controller command (/hsv/control_command) or the",
        "input after the fault injector (/hsv/actuator_command). The plant saturates it to",
        "0 <= phi <= 1.5 and |delta_e| <= 30 deg (sec. 5.1).",
    )
    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    phi: np.ndarray = _f("float64", "fuel-to-air ratio Phi [-]")
    delta_e: np.ndarray = _f("float64", "elevator deflection [rad]")

    @classmethod
    def of(cls, k: int, t: float, u: np.ndarray) -> ControlCommand:
        """Message of step k from inputs u (B, 2) [Phi, delta_e rad] (columns copied)."""
        u = np.array(u, dtype=float)
        return cls(k, t, u[:, 0], u[:, 1])

    def u(self) -> np.ndarray:
        """Inputs (B, 2) [Phi, delta_e rad]."""
        out = np.empty(np.shape(self.phi) + (2,))
        out[..., 0], out[..., 1] = self.phi, self.delta_e
        return out


@dataclass(frozen=True)
class TubeStatus(LoopMessage):
    """Tube error e = x - x_r - x_n of step k against the invariant set Z."""

    HEADER: ClassVar[tuple[str, ...]] = (
        "Tube of step k: error e = x - x_r - x_n against the invariant set Z (eq. 25-28, 53).",
    )
    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    law: tuple = _f("string", "control law of the run (registry name, e.g. tube_mpc, rmpc)")
    tau: np.ndarray = _f("float64", "adjustable factor (1 for eq. 36, < 1 for eq. 54)")
    level: np.ndarray = _f("float64", "e' N^-1 e, <= 1 inside the tube Z; NaN for rmpc")
    inside: np.ndarray = _f("bool", "level <= 1")
    e: np.ndarray = _f("float64[]", "tube error, design-model order")
    lmi_failed: np.ndarray = _f(
        "int64", "rmpc: steps so far with the state outside its largest ellipsoid E_1"
    )
    qp_solves: np.ndarray = _f(
        "int64", "nominal MPC QPs accepted so far (copied from /hsv/nominal)"
    )
    qp_fallback: np.ndarray = _f("int64", "nominal MPC steps on the shifted plan (QP rejected)")
    qp_terminal: np.ndarray = _f("int64", "nominal MPC steps on the terminal law")
    qp_recovered: np.ndarray = _f(
        "int64", "nominal MPC re-plans by the recovery QP (copied from /hsv/nominal)"
    )


@dataclass(frozen=True)
class FaultStatus(LoopMessage):
    """Fault applied at step k by the fault injector."""

    HEADER: ClassVar[tuple[str, ...]] = ("Fault applied at step k by the fault injector.",)
    k: int = _f("int64", _STEP_K)
    t: float = _f("float64", _STEP_T)
    kind: tuple = _f("string", "none, loss_of_effectiveness, stuck, bias, dropout, hardover")
    active: np.ndarray = _f("bool", "true once t >= t_onset")
    t_onset: np.ndarray = _f("float64", "onset time [s]")
    rho_f: np.ndarray = _f("float64", "elevator effectiveness (eq. 15), 1 = healthy")
    bias: np.ndarray = _f("float64", "elevator bias [rad] (kind bias)")
    delta_e_in: np.ndarray = _f("float64", "commanded elevator [rad]")
    delta_e_out: np.ndarray = _f("float64", "elevator after the fault [rad]")


#: Every loop message class, by ROS 2 type name (`hsv_interfaces/msg/...`).
MESSAGES: dict[str, type[LoopMessage]] = {
    c.ros_type(): c
    for c in (VehicleState, Measurement, StateEstimate, FilteredPitchRate, NominalTrajectory,
              ControlCommand, TubeStatus, FaultStatus)
}  # fmt: skip


def msg_text(cls: type[LoopMessage]) -> str:
    """The `.msg` file of a message class (header comments, fields with comments)."""
    lines = [f"# {h}" for h in cls.HEADER]
    for name, ros, doc in cls.ros_fields():
        lines.append(f"{f'{ros} {name}':<21} # {doc}")
    return "\n".join(lines) + "\n"


def write_msg_files(folder: Path = MSG_DIR) -> list[Path]:
    """Write every `<Name>.msg` into `folder`; returns the paths written."""
    out = []
    for cls in MESSAGES.values():
        path = Path(folder) / f"{cls.__name__}.msg"
        path.write_text(msg_text(cls))
        out.append(path)
    return out
