"""The per-step computations of the SIL graph, one class per node, without ROS.

Each ``*Core`` is built from that node's validated parameters
(:func:`fahv.loop.params.validate`, called once by :func:`build_core`) and maps the
step-k input messages to its step-k output messages. Messages are plain dicts with the
field names of the ``hsv_interfaces`` definitions (``src/fahv/msg/*.msg``). The ROS
nodes in ``ros_ws/`` convert ROS messages to these dicts and back and call exactly
these methods; the in-process simulator (:func:`fahv.loop.simulate.simulate`) calls
them in the graph's order.
The lockstep makes both the same computation (docs/architecture.md)::

    plant.state(k) -> notch.on_state -> nominal.on_state -> controller.on_inputs
                   -> fault.on_command -> plant.advance(k, actuator)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fahv.control import LAWS
from fahv.control.nominal_mpc import (
    DisturbanceEstimator,
    MPCSettings,
    TrackingMPC,
    TrackingNominal,
)
from fahv.control.reference import Command, CommandReference, NominalOutput, NominalTrajectory
from fahv.errors import RunError
from fahv.loop.graph import CONTROLLER_NODES, GRAPH, STATE_FIELDS, n_steps_of, state_vector
from fahv.loop.params import validate
from fahv.model.lpv import PolytopicLPV
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.trim import TrimMap
from fahv.model.vehicle import DELTA_E, PHI, Q, load_vehicle
from fahv.plant.faults import FaultInjector, make_fault
from fahv.plant.integrator import Plant

GRAPH["rmpc"] = GRAPH["tube_mpc"]


def _check_step(node: str, topic: str, msg: dict, k: int) -> None:
    if msg["k"] != k:
        raise RunError(f"{node}: {topic} of step {msg['k']} used at step {k}")


class PlantCore:
    """Plant node: nonlinear CM with the perturbed parameters (:class:`fahv.plant.Plant`).

    Parameters
    ----------
    p : dict
        Validated parameters of node ``plant``.

    Raises
    ------
    ParameterError
        On a bad parameter (names the key).
    """

    def __init__(self, p: dict) -> None:
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
    """Notch filter node on q (eq. 38-39, :class:`fahv.model.notch.DiscreteNotch`)."""

    def __init__(self, p: dict) -> None:
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
    """Nominal-trajectory node: tracking MPC, governed nominal system (eq. 20/46) or command.

    Inputs of step k: the VehicleState of step k (the trigger; the MPC's estimator uses
    it) and the controller's command of step k - 1 (``None`` at k = 0).
    """

    def __init__(self, p: dict) -> None:
        c = {k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("command.")}
        self.command = Command(
            c["h0"], c["V0"], c["h_c"], c["V_c"], c["t_start"], c["kind"], c["t_ramp"]
        )
        tm = TrimMap(p["trim_h"], p["trim_V"], p["trim_x"], p["trim_u"])
        n = p["A"].shape[1]
        self.mpc = None
        if p["mode"] == "mpc":
            lpv = PolytopicLPV(p["A"], p["B"], p["h_grid"], p["V_grid"], p["W_h"], p["W_V"])
            m = {k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("mpc.")}
            q_w = np.concatenate([np.asarray(m["q_w"], float), np.zeros(n - 9)])
            st = MPCSettings(
                int(m["M"]), int(m["N"]), q_w, np.asarray(m["r_w"], float),
                np.asarray(m["t_w"], float), np.asarray(m["dtheta_max"], float),
                np.asarray(m["reschedule"], float), float(np.radians(m["att_max"])),
            )  # fmt: skip
            self.mpc = TrackingMPC(
                lpv, tm, p["K"], p["Q"], p["u_lo"], p["u_hi"], p["Dx"], p["Du"], st
            )
            est, measure, n_est = None, None, 9
            if n == 11:  # ECM: the estimator works in its coordinates (q', x_q, eq. 43)
                measure, n_est = self._ecm_measure(p), 11
            if m["est_tau"] > 0.0:
                est = DisturbanceEstimator(p["Dx"][:n_est], min(1.0, p["Ts"] / m["est_tau"]))
            self.source = TrackingNominal(self.mpc, self.command, p["Ts"], est, n_est, measure)
            self.source.reset(p["x0"])
        elif p["mode"] == "governor":
            lpv = PolytopicLPV(p["A"], p["B"], p["h_grid"], p["V_grid"], p["W_h"], p["W_V"])
            self.source = NominalTrajectory(
                lpv, tm, p["K"], p["Q"], self.command, p["Ts"], p["level_max"]
            )
            self.source.reset(p["x0"])
        else:
            self.source = CommandReference(tm, self.command, n, p["Ts"])
        self.k = 0

    @staticmethod
    def _ecm_measure(p: dict):
        """Plant state (9,) -> ECM state (11,) with a replica of the notch node's filter.

        The replica is the same :class:`~fahv.model.notch.DiscreteNotch` on the same q
        samples as the notch_filter node, so q' and x_q are those the controller sees.

        Raises
        ------
        RunError
            If the notch filter is off (the ECM needs its states).
        """
        if not p["notch.enabled"]:
            raise RunError("nominal_trajectory: the 11-state (ECM) design needs the notch on")
        nf = NotchFilter(*(p[f"notch.{k}"] for k in ("omega_z", "eps_z", "omega_p", "eps_p")))
        filt = DiscreteNotch(nf, p["Ts"])

        def measure(x: np.ndarray) -> np.ndarray:
            q_f = filt.step(float(x[Q]))
            return np.concatenate([x[:Q], [q_f], x[Q + 1 : 9], filt.x_q])

        return measure

    def on_state(self, state: dict, previous: dict | None = None) -> dict:
        """NominalTrajectory of step k from VehicleState k and ControlCommand k - 1.

        ``previous`` (the command of step k - 1) is used only by the MPC's estimator.
        """
        _check_step("nominal_trajectory", "state", state, self.k)
        if self.mpc is not None:
            u_prev = None
            if previous is not None:
                _check_step("nominal_trajectory", "control_command", previous, self.k - 1)
                u_prev = np.array([previous["phi"], previous["delta_e"]], float)
            ref = self.source.step(state_vector(state), u_prev)
            st, d = self.mpc.stats, self.source.d
        else:
            ref = self.source.step()
            st, d = None, np.zeros(2)
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
            "qp_solves": st.solves if st else 0,
            "qp_fallback": st.fallback if st else 0,
            "qp_terminal": st.terminal if st else 0,
            "d_hat": d,
        }


class ControllerCore:
    """Controller node: the registered control law named by parameter ``law``.

    Parameters
    ----------
    p : dict
        Validated parameters of the controller node (``tube_mpc`` or ``rmpc``).

    Raises
    ------
    ParameterError
        If the law rejects its parameters (names the key).
    """

    def __init__(self, p: dict) -> None:
        self.law = LAWS[p["law"]](p)
        self.n = p["F"].shape[1]
        self.tau = p["tau"]
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
        u, s = self.law.step(k, x, nominal_output(nominal))
        self.k += 1
        t = state["t"]
        cmd = {"k": k, "t": t, "phi": float(u[PHI]), "delta_e": float(u[DELTA_E])}
        level = s["level"]
        tube = {
            "k": k,
            "t": t,
            "law": s.get("label", self.law.name),
            "tau": self.tau,
            "level": level,
            "inside": bool(level <= 1.0),
            "e": s["e"],
            "lmi_solves": s.get("lmi_solves", 0),
            "lmi_fallback": s.get("lmi_fallback", 0),
            "lmi_failed": s.get("lmi_failed", 0),
            "qp_solves": int(nominal.get("qp_solves", 0)),
            "qp_fallback": int(nominal.get("qp_fallback", 0)),
            "qp_terminal": int(nominal.get("qp_terminal", 0)),
        }
        return cmd, tube


class FaultCore:
    """Fault-injector node (:class:`fahv.plant.FaultInjector`)."""

    def __init__(self, p: dict) -> None:
        self.fault = make_fault(p["kind"], p["t_onset"], p)
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


#: Core class of each loop node.
CORES = {
    "plant": PlantCore,
    "notch_filter": NotchCore,
    "nominal_trajectory": NominalCore,
    "fault_injector": FaultCore,
    **dict.fromkeys(CONTROLLER_NODES, ControllerCore),
}


def build_core(node: str, raw: dict):
    """Validate the raw parameters of ``node`` (once) and build its core.

    Raises
    ------
    ParameterError
        Naming the node and the key of a bad parameter.
    """
    return CORES[node](validate(node, raw))
