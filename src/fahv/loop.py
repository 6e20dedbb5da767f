"""The per-step computations of the SIL graph, one class per node, without ROS.

Each ``*Core`` is built from that node's validated parameters
(:func:`fahv.params.validate`) and maps the step-k input messages to its step-k
output messages. Messages are plain dicts with the field names of the
``hsv_interfaces`` definitions (``src/fahv/msg/*.msg``). The ROS nodes in ``ros_ws/``
convert ROS messages to these dicts and back and call exactly these methods; the
in-process simulator (:func:`fahv.sim.simulate`) calls them in the graph's order.
The lockstep makes both the same computation (ARCHITECTURE.md)::

    plant.state(k) -> notch.on_state -> nominal.on_state -> controller.on_inputs
                   -> fault.on_command -> plant.advance(k, actuator)
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fahv.controllers import (
    Command,
    NominalOutput,
    NominalTrajectory,
    PolytopicLPV,
    RobustMPC,
    TubeMPC,
)
from fahv.errors import RunError
from fahv.notch import DiscreteNotch, NotchFilter
from fahv.params import validate
from fahv.plant import ElevatorFault, FaultInjector, Plant
from fahv.runlog import TOPICS
from fahv.trim import TrimMap
from fahv.vehicle import DELTA_E, PHI, Q, load_vehicle

#: node -> (input topics, output topics) of one control step (ARCHITECTURE.md).
#: ``replay`` (hsv_bringup) may publish and capture any loop topic.
GRAPH = {
    "plant": (("/hsv/actuator_command",), ("/clock", "/hsv/state")),
    "notch_filter": (("/hsv/state",), ("/hsv/q_filtered",)),
    "nominal_trajectory": (("/hsv/state",), ("/hsv/nominal",)),
    "tube_mpc": (
        ("/hsv/state", "/hsv/q_filtered", "/hsv/nominal"),
        ("/hsv/control_command", "/hsv/tube_status"),
    ),
    "fault_injector": (
        ("/hsv/control_command",),
        ("/hsv/actuator_command", "/hsv/fault_status"),
    ),
    "recorder": (tuple(TOPICS), ()),
    "replay": (tuple(TOPICS), tuple(TOPICS)),
}
GRAPH["rmpc"] = GRAPH["tube_mpc"]
#: Nodes of the full graph in start order, the default of parameter ``graph_nodes``.
DEFAULT_GRAPH = [
    "recorder",
    "notch_filter",
    "nominal_trajectory",
    "tube_mpc",
    "fault_injector",
    "plant",
]


def graph_nodes(controller: str = "tube_mpc") -> list[str]:
    """Nodes of a full run with the given controller node (``tube_mpc`` or ``rmpc``)."""
    return [controller if n == "tube_mpc" else n for n in DEFAULT_GRAPH]


def replay_topics(nodes) -> tuple[list[str], list[str]]:
    """(inputs to replay, outputs to capture) for testing ``nodes`` against a run.

    The inputs are the loop topics the nodes consume and do not produce themselves;
    the outputs are what they produce.

    Raises
    ------
    RunError
        On a node that is not in :data:`GRAPH`.
    """
    unknown = [n for n in nodes if n not in GRAPH or n in ("recorder", "replay")]
    if unknown:
        raise RunError(
            f"cannot replay into {unknown}: nodes are {sorted(set(GRAPH) - {'recorder', 'replay'})}"
        )
    produced = [t for n in nodes for t in GRAPH[n][1]]
    consumed = [t for n in nodes for t in GRAPH[n][0]]
    inputs = [t for t in TOPICS if t in consumed and t not in produced]
    return inputs, [t for t in TOPICS if t in produced]


#: Field names of VehicleState after k, t, in plant state order (eq. 1-3).
STATE_FIELDS = ("h", "v", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")


def n_steps_of(p: dict) -> int:
    """Number of control steps of a run: round(duration / Ts)."""
    return int(round(p["duration"] / p["Ts"]))


def clock_msg(k: int, Ts: float) -> dict:
    """rosgraph_msgs/Clock of step k: t_k = k Ts in whole nanoseconds."""
    ns = k * int(round(Ts * 1e9))
    return {"clock": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}}


def state_vector(msg: dict) -> np.ndarray:
    """Plant state x (9,) from a VehicleState dict."""
    return np.array([msg[f] for f in STATE_FIELDS], dtype=float)


def _check_step(node: str, topic: str, msg: dict, k: int) -> None:
    if msg["k"] != k:
        raise RunError(f"{node}: {topic} of step {msg['k']} used at step {k}")


class PlantCore:
    """Plant node: nonlinear CM with the perturbed parameters (:class:`fahv.plant.Plant`).

    Parameters
    ----------
    p : dict
        Parameters of node ``plant`` (validated here).

    Raises
    ------
    ParameterError
        On a bad parameter (names the key).
    """

    def __init__(self, p: dict) -> None:
        p = validate("plant", p)
        veh = load_vehicle(p["vehicle_file"] or None)
        params = dataclasses.replace(
            veh.params, **{k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("params.")}
        )
        self.Ts, self.n_steps, self.limits = p["Ts"], n_steps_of(p), veh.limits
        self.plant = Plant(params, veh.limits, p["x0"], p["Ts"], p["plant_substeps"])
        self.k = 0

    def state(self) -> dict:
        """VehicleState of the current step k.

        Raises
        ------
        RunError
            If the state is no longer finite.
        """
        x = self.plant.x
        if not np.all(np.isfinite(x)):
            raise RunError(f"plant: state not finite at t = {self.k * self.Ts:.2f} s")
        fields = dict(zip(STATE_FIELDS, map(float, x), strict=True))
        return {"k": self.k, "t": self.k * self.Ts, **fields}

    def advance(self, actuator: dict) -> None:
        """Integrate [t_k, t_k+1] with the step-k actuator command (ZOH, saturated).

        Raises
        ------
        RunError
            If the command is not of the current step.
        """
        _check_step("plant", "actuator_command", actuator, self.k)
        self.plant.step(np.array([actuator["phi"], actuator["delta_e"]]))
        self.k += 1


class NotchCore:
    """Notch filter node on q (eq. 38-39, :class:`fahv.notch.DiscreteNotch`)."""

    def __init__(self, p: dict) -> None:
        p = validate("notch_filter", p)
        self.enabled = p["enabled"]
        self.filter = None
        if self.enabled:
            nf = NotchFilter(p["omega_z"], p["eps_z"], p["omega_p"], p["eps_p"])
            self.filter = DiscreteNotch(nf, p["Ts"])
        self.k = 0

    def on_state(self, state: dict) -> dict:
        """FilteredPitchRate of step k from VehicleState k."""
        _check_step("notch_filter", "state", state, self.k)
        q = float(state["q"])
        if self.filter is None:
            q_f, x_q = q, np.zeros(0)
        else:
            q_f, x_q = self.filter.step(q), self.filter.x_q.copy()
        self.k += 1
        return {
            "k": state["k"],
            "t": state["t"],
            "q": q,
            "q_f": q_f,
            "enabled": self.enabled,
            "x_q": x_q,
        }


class _CommandReference:
    """Reference of the traditional RMPC: trim of the raw command, x_n = 0, no governor."""

    def __init__(self, trim_map, command: Command, n: int, Ts: float) -> None:
        self.trim_map, self.command, self.n, self.Ts, self.k = trim_map, command, n, Ts, 0

    def step(self) -> NominalOutput:
        h, V = self.command(self.k * self.Ts)
        x_r, u_r = self.trim_map(h, V)
        self.k += 1
        return NominalOutput(h, V, x_r, u_r, np.zeros(self.n), np.zeros(2), math.nan)


def nominal_output(msg: dict) -> NominalOutput:
    """:class:`NominalOutput` from a NominalTrajectory dict."""
    return NominalOutput(
        msg["h_g"],
        msg["v_g"],
        np.asarray(msg["x_r"], float),
        np.asarray(msg["u_r"], float),
        np.asarray(msg["x_n"], float),
        np.asarray(msg["u_n"], float),
        msg["level"],
    )


class NominalCore:
    """Nominal-trajectory node: governed nominal system (eq. 20/46) or the raw command."""

    def __init__(self, p: dict) -> None:
        p = validate("nominal_trajectory", p)
        c = {k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("command.")}
        self.command = Command(
            c["h0"], c["V0"], c["h_c"], c["V_c"], c["t_start"], c["kind"], c["t_ramp"]
        )
        tm = TrimMap(p["trim_h"], p["trim_V"], p["trim_x"], p["trim_u"])
        n = p["A"].shape[1]
        if p["mode"] == "governor":
            lpv = PolytopicLPV(p["A"], p["B"], p["h_grid"], p["V_grid"], p["W_h"], p["W_V"])
            self.source = NominalTrajectory(
                lpv, tm, p["K"], p["Q"], self.command, p["Ts"], p["level_max"]
            )
            self.source.reset(p["x0"])
        else:
            self.source = _CommandReference(tm, self.command, n, p["Ts"])
        self.k = 0

    def on_state(self, state: dict) -> dict:
        """NominalTrajectory of step k (VehicleState k is the step trigger)."""
        _check_step("nominal_trajectory", "state", state, self.k)
        ref = self.source.step()
        h_c, V_c = self.command(state["t"])
        self.k += 1
        return {
            "k": state["k"],
            "t": state["t"],
            "h_c": h_c,
            "v_c": V_c,
            "h_g": ref.h_g,
            "v_g": ref.V_g,
            "x_r": ref.x_r,
            "u_r": ref.u_r,
            "x_n": ref.x_n,
            "u_n": ref.u_n,
            "level": ref.level,
        }


class ControllerCore:
    """Controller node: Tube-MPC (eq. 36), adjustable Tube-MPC (eq. 54) or the RMPC.

    Parameters
    ----------
    p : dict
        Parameters of node ``tube_mpc`` (or ``rmpc``).
    node : str
        Node name the parameters are validated under.
    """

    def __init__(self, p: dict, node: str = "tube_mpc") -> None:
        p = validate(node, p)
        self.law, self.n = p["law"], p["F"].shape[1]
        self.tube = TubeMPC(p["F"], p["N"], p["tau"])
        self.rmpc = None
        if self.law == "rmpc":
            self.rmpc = RobustMPC(
                p["rmpc_A"],
                p["rmpc_B"],
                p["u_room"],
                p["psi"],
                p["sigma"],
                p["Dx"][:9],
                p["Du"],
                p["resolve_every"],
            )
        self.k = 0

    def measured_state(self, state: dict, qf: dict) -> np.ndarray:
        """Controller state (n,): x with q' for q (notch on), plus x_q for the ECM (eq. 43).

        Raises
        ------
        RunError
            If the 11-state controller gets no filter states.
        """
        x = state_vector(state)
        if qf["enabled"]:
            x[Q] = qf["q_f"]
        if self.n == 11:
            x_q = np.asarray(qf["x_q"], float)
            if x_q.shape != (2,):
                raise RunError("tube_mpc: the 11-state (ECM) controller needs the notch states")
            x = np.concatenate([x, x_q])
        return x

    def on_inputs(self, state: dict, qf: dict, nominal: dict) -> tuple[dict, dict]:
        """ControlCommand and TubeStatus of step k from its three inputs."""
        k = self.k
        for topic, msg in (("state", state), ("q_filtered", qf), ("nominal", nominal)):
            _check_step("tube_mpc", topic, msg, k)
        x = self.measured_state(state, qf)
        ref = nominal_output(nominal)
        if self.rmpc is not None:
            u = self.rmpc.step(k, x[:9], ref)
            e, level = x - ref.x_r, math.nan
        else:
            u = self.tube.step(x, ref)
            e = self.tube.error(x, ref)
            level = self.tube.tube_level(e)
        self.k += 1
        t = state["t"]
        cmd = {"k": k, "t": t, "phi": float(u[PHI]), "delta_e": float(u[DELTA_E])}
        tube = {
            "k": k,
            "t": t,
            "law": self.law,
            "tau": self.tube.tau,
            "level": level,
            "inside": bool(level <= 1.0),
            "e": e,
            "lmi_solves": 0 if self.rmpc is None else self.rmpc.n_solves,
            "lmi_fallback": 0 if self.rmpc is None else self.rmpc.n_fallback,
            "lmi_failed": 0 if self.rmpc is None else self.rmpc.n_failed,
        }
        return cmd, tube


class FaultCore:
    """Fault-injector node (:class:`fahv.plant.FaultInjector`)."""

    def __init__(self, p: dict) -> None:
        p = validate("fault_injector", p)
        self.fault = ElevatorFault(p["kind"], p["t_onset"], p["rho_f"], math.radians(p["bias_deg"]))
        self.injector = FaultInjector(self.fault)
        self.k = 0

    def on_command(self, cmd: dict) -> tuple[dict, dict]:
        """Actuator ControlCommand and FaultStatus of step k from ControlCommand k."""
        _check_step("fault_injector", "control_command", cmd, self.k)
        u = np.array([cmd["phi"], cmd["delta_e"]])
        ua = self.injector.apply(cmd["t"], u)
        self.k += 1
        f = self.fault
        act = {"k": cmd["k"], "t": cmd["t"], "phi": float(ua[PHI]), "delta_e": float(ua[DELTA_E])}
        status = {
            "k": cmd["k"],
            "t": cmd["t"],
            "kind": f.kind,
            "active": f.active(cmd["t"]),
            "t_onset": f.t_onset,
            "rho_f": f.rho_f,
            "bias": f.bias,
            "delta_e_in": float(u[DELTA_E]),
            "delta_e_out": float(ua[DELTA_E]),
        }
        return act, status


__all__ = [
    "STATE_FIELDS",
    "n_steps_of",
    "clock_msg",
    "state_vector",
    "nominal_output",
    "PlantCore",
    "NotchCore",
    "NominalCore",
    "ControllerCore",
    "FaultCore",
]
