"""The per-step computations of the SIL graph, one class per node, for B runs at once.

Each `*Core` is built from the validated parameters of its node for each of B runs
(`build_core`; the runs of one batch share every design value and differ only in
their own plant parameters, initial state, command and fault) and maps the typed
step-k input messages (`fahv.msg`, fields with a leading axis of B runs) to its
step-k output messages. The ROS nodes in `ros_ws/` call exactly these methods with
B = 1; the in-process simulator (`fahv.loop.simulate`) calls them in the graph's
order with B = 1 (`fahv simulate`) or B runs (a campaign batch). One implementation:

    plant.state(k), plant.measurement() -> estimator.on_measurement -> notch.on_state
        -> nominal.on_state -> controller.on_inputs -> fault.on_command
        -> plant.advance(k, actuator)

A run that fails (non-finite state, an infeasible first solve, ...) is reported to the
`fahv.lanes.Lanes` of the batch: raised at once for a single run, recorded for a
batch, whose other runs go on (the failed run's plant is reset to finite values).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from fahv.control import LAWS, NOMINAL_SOURCES
from fahv.errors import ConfigError, ParameterError, RunError
from fahv.lanes import Lanes
from fahv.loop.graph import CONTROLLER_NODES, n_steps_of
from fahv.loop.params import ESTIMATOR_ARRAYS, validate
from fahv.model.actuators import IDEAL
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.vehicle import DELTA_E, IQ, H, V, load_vehicle
from fahv.msg import (
    ControlCommand,
    FaultStatus,
    FilteredPitchRate,
    LoopMessage,
    Measurement,
    NominalTrajectory,
    StateEstimate,
    TubeStatus,
    VehicleState,
)
from fahv.plant.faults import FAULTS, FaultInjector, make_fault
from fahv.plant.integrator import Plant
from fahv.sensors.data import (
    CHANNELS,
    EXACT_STATE,
    STATE_CHANNELS,
    load_sensors,
    measured_channels,
)
from fahv.sensors.faults import SENSOR_FAULTS, sensor_fault_from_section
from fahv.spec.plant_dispersion import sensor_dispersion_of, servo_factors
from fahv.spec.schema import NO_ESTIMATOR
from fahv.verdict import RunEnded


def servos_of(vehicle, model: str, node: str = "plant"):
    """The servos of actuator model `model` of a vehicle; None for `ideal`.

    Raises
    ------
    ParameterError
        If the vehicle file gives no data for the model (names `node`'s parameter
        `actuators`).
    """
    if model == IDEAL:
        return None
    if model not in vehicle.actuators:
        raise ParameterError(
            f"{node}: parameter 'actuators' = {model!r}: the vehicle file "
            f"{vehicle.source_file} has no 'actuators.{model}' section "
            f"(it gives {sorted(vehicle.actuators) or 'none'})"
        )
    return vehicle.actuators[model]


def sensors_of(p: dict, runs: Sequence[dict], vehicles: dict):
    """The sensors of a batch's plant (parameters `measured`, `vehicle_file`); None: none.

    Each run's seed is its `sensor_seed`, its sensor fault its `sensor_fault.*`, its
    noise levels and biases its `sensor_*` factors (`fahv.spec.plant_dispersion`);
    `measured` = `state` is the exact full-state sensor (`ExactState`).

    Parameters
    ----------
    p : dict
        Validated parameters of node `plant` (the batch's shared values).
    runs : sequence of dict
        Validated parameters of node `plant` of each run.
    vehicles : dict
        Cache of loaded files by name (the sensor data under `("sensors", name)`).

    Raises
    ------
    ParameterError
        On an unknown or repeated channel in `measured`, or a sensor fault on a channel
        that is not measured (names the parameter).
    """
    from fahv.sensors.measure import ExactState, Sensors  # numba: the plant's only

    if p["measured"].strip() == EXACT_STATE:
        if any(r["sensor_fault.kind"] != "none" for r in runs):
            raise ParameterError(f"plant: parameter 'sensor_fault.kind': the exact state "
                                 f"(measured = {EXACT_STATE!r}) has no sensor to fail")  # fmt: skip
        return ExactState(len(runs))
    measured = measured_channels(p["measured"])
    faults = [sensor_fault_of(r, measured) for r in runs]  # a fault names a measured channel
    if not measured:
        return None
    unknown = [c for c in measured if c not in CHANNELS]
    if unknown or len(set(measured)) < len(measured):
        why = f"unknown channel(s) {unknown}" if unknown else "a channel named twice"
        raise ParameterError(f"plant: parameter 'measured' = {p['measured']!r}: {why} "
                             f"(channels: {', '.join(CHANNELS)})")  # fmt: skip
    key = ("sensors", p["vehicle_file"] or "")
    if key not in vehicles:
        vehicles[key] = load_sensors(p["vehicle_file"] or None)
    seeds = [r["sensor_seed"] for r in runs]
    dispersion = [sensor_dispersion_of(r) for r in runs]
    return Sensors(vehicles[key], seeds, p["Ts"], measured, faults, dispersion)


def sensor_fault_of(run: dict, measured: Sequence[str]):
    """The sensor fault of one run's plant parameters `sensor_fault.*`; None for `none`.

    Raises
    ------
    ParameterError
        On a fault whose channel is not measured or a missing parameter of its kind
        (names the parameter).
    """
    values = {k.split(".", 1)[1]: v for k, v in run.items() if k.startswith("sensor_fault.")}
    kind = values.get("kind", "none")
    if kind == "none":
        return None
    used = {"kind", "channel", "t_onset", *(f.name for f in SENSOR_FAULTS[kind].parameters)}
    values = {k: v for k, v in values.items() if k in used}  # the other kinds' defaults out
    try:
        return sensor_fault_from_section(values, measured, key="plant: parameter sensor_fault")
    except ConfigError as exc:
        raise ParameterError(str(exc)) from exc


def check_step(node: str, topic: str, msg: LoopMessage, k: int) -> None:
    """Raise `RunError` unless `msg` is of step `k`."""
    if msg.k != k:
        raise RunError(f"{node}: {topic} of step {msg.k} used at step {k}")


class PlantCore:
    """Plant node: the nonlinear CM of each run with its perturbed parameters (`Plant`).

    The actuator model (parameter `actuators`, shared by the runs of a batch) is
    `ideal` or one of the vehicle file's servo models (`fahv.model.actuators`);
    with servo dynamics, a run's elevator actuator is held at its position from its
    `stuck_onset` on (fault kind `stuck`).

    Parameters
    ----------
    runs : sequence of dict
        Validated parameters of node `plant` of each run.
    lanes : fahv.lanes.Lanes
    vehicles : dict, optional
        Cache of loaded vehicle files by name (shared by the batches of a worker).

    Raises
    ------
    ParameterError
        On a bad parameter (names the key).
    """

    def __init__(self, runs: Sequence[dict], lanes: Lanes, vehicles: dict | None = None) -> None:
        p = runs[0]
        vehicles = {} if vehicles is None else vehicles
        key = p["vehicle_file"] or ""
        if key not in vehicles:
            vehicles[key] = load_vehicle(key or None)
        veh = vehicles[key]
        params = [
            dataclasses.replace(
                veh.params,
                **{k.split(".", 1)[1]: v for k, v in r.items() if k.startswith("params.")},
            )
            for r in runs
        ]
        self.Ts, self.n_steps, self.limits = p["Ts"], n_steps_of(p), veh.limits
        self.envelope = veh.envelope
        # first exit from the flight envelope of each run (reason of a later divergence)
        self.exit_reason: list[str | None] = [None] * len(runs)
        self.x0 = np.stack([np.asarray(r["x0"], float) for r in runs])
        self.stuck_onset = np.array(
            [r["stuck_onset"] if r["stuck"] else np.inf for r in runs], float
        )  # fmt: skip
        self.plant = Plant(params, veh.limits, self.x0, p["Ts"], p["plant_substeps"],
                           servos_of(veh, p["actuators"]),
                           [servo_factors(r) for r in runs])  # fmt: skip
        self.sensors = sensors_of(p, runs, vehicles)
        names = () if self.sensors is None else self.sensors.names
        self._channels = (",".join(names),) * len(runs)
        self.lanes = lanes
        self.k = 0

    def _reset(self, mask: np.ndarray) -> None:
        """Put failed runs back on their initial state (keeps the batch finite)."""
        x = self.plant.x.copy()
        x[mask] = self.x0[mask]
        self.plant.x = x

    def state(self) -> VehicleState:
        """VehicleState of the current step k.

        A run whose state is not finite ends with the verdict `non_finite_state`
        (`fahv.verdict`; the reason names where it left the flight envelope
        before, if it did); the state of an ended run of a batch is put back on its
        initial state, so the batch stays finite.

        Raises
        ------
        RunEnded
            For a single run that ends here (a batch records it).
        """
        t = self.k * self.Ts
        x = self.plant.x
        out = self.envelope.outside(x[:, H], x[:, V])
        if out.any():
            for b in np.flatnonzero(out):
                if self.exit_reason[b] is None:
                    self.exit_reason[b] = self.envelope.describe(t, x[b, H], x[b, V])
        bad = ~np.all(np.isfinite(x), axis=1)
        if bad.any():

            def ended(b: int) -> RunEnded:
                why = self.exit_reason[b]
                after = f" after the vehicle {why}" if why else ""
                return RunEnded("non_finite_state", "plant", self.k, t, f"state not finite{after}")

            self.lanes.fail_mask(bad, ended)
        if not self.lanes.alive.all():
            self._reset(~self.lanes.alive)
        return VehicleState.of(self.k, t, self.plant.x, self.plant.positions, self.plant.rate_peak)

    def measurement(self) -> Measurement:
        """Measurement of the current step k from the true states (after `state`).

        The plant's sensors (`fahv.sensors.measure.Sensors`, parameters `measured` and
        `sensor_seed`); y has no columns when nothing is measured.
        """
        k = self.k
        y = (np.zeros((len(self.x0), 0)) if self.sensors is None
             else self.sensors.measure(k, self.plant.x))  # fmt: skip
        return Measurement(k, k * self.Ts, self._channels, y)

    def advance(self, actuator: ControlCommand) -> None:
        """Integrate [t_k, t_k+1] with the step-k actuator commands (ZOH, saturated).

        Raises
        ------
        RunError
            If the command is not of the current step.
        RunEnded
            For a single run whose input is not finite (verdict `non_finite_input`;
            a batch records it).
        """
        check_step("plant", "actuator_command", actuator, self.k)
        u = actuator.u()
        bad = np.isnan(np.clip(u, self.limits.u_min, self.limits.u_max)).any(axis=1)
        if bad.any():
            t = self.k * self.Ts
            self.lanes.fail_mask(bad, lambda b: RunEnded(
                "non_finite_input", "plant", self.k, t, f"plant input not finite: u = {u[b]!r}"
            ))  # fmt: skip
            u[bad] = self.limits.u_min
        held = actuator.t >= self.stuck_onset - 1e-12
        self.plant.step(u, held if held.any() else None)
        self.k += 1


class EstimatorCore:
    """State-estimator node: the estimate x_k|k of each run from its measurement y_k.

    Parameter `estimator`: `none` passes the exact state of the full-state sensor
    (the plant's `measured` = `state`) through, the paper's loop; `kalman` runs the
    gain-scheduled Kalman filter of `fahv.estimation.kalman` on the measured channels,
    its vertex gains made at start from the design's LPV model of the CM and its
    disturbance bound (`design_filter`; an ECM design's CM part, `fahv.model.cascade`),
    its predictor with the plant's actuator model (parameter `actuators`: the servos'
    states integrated with the airframe). Inputs of step k:
    the Measurement of step k (the trigger) and the controller's command of step k - 1
    (`None` at k = 0), which the filter's prediction takes.

    Raises
    ------
    ParameterError
        If `estimator` and `measured` do not fit (none needs the exact state, kalman
        sensor channels), or no filter exists for the design (names the parameter).
    """

    def __init__(self, runs: Sequence[dict], lanes: Lanes) -> None:
        p = runs[0]
        self.kind, self.lanes, self.k = p["estimator"], lanes, 0
        self.n_runs = len(runs)
        self._names = (self.kind,) * self.n_runs
        exact = p["measured"].strip() == EXACT_STATE
        measured = measured_channels(p["measured"])
        self._channels = ",".join(STATE_CHANNELS if exact else measured)  # what the plant sends
        self._no_sigma = np.zeros((self.n_runs, 0))  # read-only: shared by messages
        self._no_sigma.setflags(write=False)
        self.filter = None
        if self.kind == NO_ESTIMATOR:
            if not exact:
                raise ParameterError(f"state_estimator: parameter 'estimator' = 'none' reads "
                                     f"the exact state, but the plant measures "
                                     f"{p['measured']!r} (measured = '{EXACT_STATE}')")  # fmt: skip
            return
        if exact or not measured:
            raise ParameterError(f"state_estimator: parameter 'estimator' = {self.kind!r} needs "
                                 f"sensor channels, not measured = {p['measured']!r}")  # fmt: skip
        from fahv.estimation.kalman import design_filter  # scipy and numba: the filter's only

        arrays = {name: p[name] for name in ESTIMATOR_ARRAYS}
        self.x0 = x0 = np.stack([np.asarray(r["x0"], float) for r in runs])
        veh = load_vehicle(p["vehicle_file"] or None)
        servos = servos_of(veh, p["actuators"], "state_estimator")
        try:
            self.filter = design_filter(arrays, veh, load_sensors(p["vehicle_file"] or None),
                                        measured, p["Ts"], p["plant_substeps"], x0, servos,
                                        p["state_disturbance"])  # fmt: skip
        except (ValueError, KeyError) as exc:
            raise ParameterError(f"state_estimator: parameter 'estimator' = {self.kind!r}: "
                                 f"{exc}") from exc  # fmt: skip

    def on_measurement(self, meas: Measurement, previous: ControlCommand | None = None):
        """StateEstimate of step k from Measurement k and ControlCommand k - 1.

        A run whose estimate is not finite ends with the verdict `non_finite_estimate`
        (its estimate is put back on finite values, so a batch stays finite).

        Raises
        ------
        RunError
            If a message is not of its step, or y is not of the measured channels.
        RunEnded
            For a single run whose estimate is not finite (a batch records it).
        """
        check_step("state_estimator", "measurement", meas, self.k)
        if self.k == 0 and any(c != self._channels for c in meas.channels):
            raise RunError(f"state_estimator: the measurement's channels {meas.channels[0]!r} "
                           f"are not the estimator's (parameter 'measured': "
                           f"{self._channels!r}): give both the same channels")  # fmt: skip
        if previous is not None:
            check_step("state_estimator", "control_command", previous, self.k - 1)
        y = np.asarray(meas.y, float)
        if self.filter is None:
            x, sigma = y, self._no_sigma
        else:
            if previous is not None:
                self.filter.predict(previous.u())
            try:
                x = self.filter.correct(y)
            except ValueError as exc:
                raise RunError(str(exc)) from exc
            sigma = self.filter.sigma()
        bad = ~np.all(np.isfinite(x), axis=1)
        if bad.any():
            t = meas.t
            self.lanes.fail_mask(bad, lambda b: RunEnded(
                "non_finite_estimate", "state_estimator", self.k, t,
                f"state estimate not finite (measurement {y[b]!r})"))  # fmt: skip
            if self.filter is None:
                x = np.where(bad[:, None], 0.0, x)  # the ended runs' lanes kept finite
            else:  # the ended runs' filters back at their start (the batch stays finite)
                self.filter.restart(bad, self.x0)
                x = np.where(bad[:, None], self.x0, x)
        self.k += 1
        return StateEstimate.of(meas.k, meas.t, x, self._names, sigma)


class NotchCore:
    """Notch filter node on q (eq. 38-39, `fahv.model.notch.DiscreteNotch`)."""

    def __init__(self, runs: Sequence[dict], lanes: Lanes) -> None:
        p = runs[0]
        self.enabled = p["enabled"]
        self.filter = None
        self.n_runs = len(runs)
        if self.enabled:
            nf = NotchFilter(p["omega_z"], p["eps_z"], p["omega_p"], p["eps_p"])
            self.filter = DiscreteNotch(nf, p["Ts"], np.zeros(self.n_runs))
        self.k = 0
        self._enabled = np.full(self.n_runs, self.enabled)  # read-only: shared by messages
        self._enabled.setflags(write=False)

    def on_state(self, state: StateEstimate) -> FilteredPitchRate:
        """FilteredPitchRate of step k from the StateEstimate of step k (its q)."""
        check_step("notch_filter", "state", state, self.k)
        q = np.array(state.q, dtype=float)
        if self.filter is None:
            q_f, x_q = q.copy(), np.zeros((self.n_runs, 0))
        else:
            q_f, x_q = self.filter.step(q), self.filter.x_q.copy()
        self.k += 1
        return FilteredPitchRate(state.k, state.t, q, q_f, self._enabled, x_q)


class NominalCore:
    """Nominal-trajectory node: the law's nominal part (a registered NominalSource).

    Inputs of step k: the StateEstimate of step k (the trigger) and the controller's
    command of step k - 1 (`None` at k = 0).
    """

    def __init__(self, runs: Sequence[dict], lanes: Lanes) -> None:
        p = runs[0]
        self.source = NOMINAL_SOURCES[p["nominal"]](p, runs, lanes)
        self.k = 0

    def on_state(self, state: StateEstimate, previous: ControlCommand | None = None):
        """NominalTrajectory of step k from StateEstimate k and ControlCommand k - 1.

        `output` then `advance` (the node publishes between the two).
        """
        out = self.output(state, previous)
        self.advance()
        return out

    def output(self, state: StateEstimate, previous: ControlCommand | None = None):
        """NominalTrajectory of step k; `advance` must follow before step k + 1."""
        check_step("nominal_trajectory", "state", state, self.k)
        u_prev = None
        if previous is not None:
            check_step("nominal_trajectory", "control_command", previous, self.k - 1)
            u_prev = previous.u()
        return self.source.output(state.k, state.t, state.x(), u_prev)

    def advance(self) -> None:
        """Move the nominal part to step k + 1 (`fahv.control.NominalSource.advance`)."""
        self.source.advance()
        self.k += 1


class ControllerCore:
    """Controller node: the registered control law named by parameter `law`.

    Raises
    ------
    ParameterError
        If the law rejects its parameters (names the key).
    """

    def __init__(self, runs: Sequence[dict], lanes: Lanes) -> None:
        p = runs[0]
        self.n_runs = len(runs)
        self.law = LAWS[p["law"]](p, self.n_runs)
        self.n = p["F"].shape[1]
        self.ecm = p["design_model"] == "ecm"  # its state: the CM's and the notch's (eq. 40)
        self.tau = p["tau"]
        self.lanes = lanes
        self.k = 0
        # the TubeStatus fields that never change (read-only: shared by every message)
        self._law_names = (self.law.name,) * self.n_runs
        self._tau = np.full(self.n_runs, float(self.tau))
        self._tau.setflags(write=False)

    def measured_state(self, state: StateEstimate, qf: FilteredPitchRate) -> np.ndarray:
        """Controller states (B, n): x with q' for q (notch on), plus x_q for the ECM (eq. 43).

        Raises
        ------
        RunError
            If the 11-state controller gets no filter states.
        """
        x = state.x()
        x[:, IQ] = np.where(qf.enabled, qf.q_f, x[:, IQ])
        if self.ecm:
            if qf.x_q.shape[1:] != (2,):
                raise RunError("tube_mpc: the 11-state (ECM) controller needs the notch states")
            x = np.concatenate([x, qf.x_q], axis=1)
        return x

    def on_inputs(
        self, state: StateEstimate, qf: FilteredPitchRate, nominal: NominalTrajectory
    ) -> tuple[ControlCommand, TubeStatus]:
        """ControlCommand and TubeStatus of step k from its three inputs."""
        k = self.k
        for topic, msg in (("state_estimate", state), ("q_filtered", qf), ("nominal", nominal)):
            check_step("tube_mpc", topic, msg, k)
        ls = self.law.step(k, self.measured_state(state, qf), nominal, self.lanes)
        self.k += 1
        t = state.t
        tube = TubeStatus(
            k, t, self._law_names, self._tau, ls.level, ls.level <= 1.0,
            ls.e, ls.lmi_failed, nominal.qp_solves,
            nominal.qp_fallback, nominal.qp_terminal, nominal.qp_recovered,
        )  # fmt: skip
        return ControlCommand.of(k, t, ls.u), tube


class FaultCore:
    """Fault-injector node (`fahv.plant.faults.FaultInjector`), each run its fault."""

    def __init__(self, runs: Sequence[dict], lanes: Lanes) -> None:
        faults = [make_fault(r["kind"], r["t_onset"], r) for r in runs]
        limits = None
        if any(FAULTS[r["kind"]].needs_limits for r in runs):  # e.g. a hardover
            limits = load_vehicle(runs[0]["vehicle_file"] or None).limits
        self.injector = inj = FaultInjector(faults, limits)
        self.k = 0
        # the FaultStatus fields that do not depend on t (read-only: shared by messages)
        self._kind = tuple(inj.kind)
        self._const = [inj.t_onset, inj.rho_f, inj.bias]
        for a in self._const:
            a.setflags(write=False)

    def on_command(self, cmd: ControlCommand) -> tuple[ControlCommand, FaultStatus]:
        """Actuator ControlCommand and FaultStatus of step k from ControlCommand k."""
        check_step("fault_injector", "control_command", cmd, self.k)
        u = cmd.u()
        inj = self.injector
        ua = inj.apply(cmd.t, u)
        self.k += 1
        status = FaultStatus(
            cmd.k, cmd.t, self._kind, inj.active(cmd.t), *self._const,
            u[:, DELTA_E].copy(), ua[:, DELTA_E].copy(),
        )  # fmt: skip
        return ControlCommand.of(cmd.k, cmd.t, ua), status


#: Core class of each loop node.
CORES = {
    "plant": PlantCore,
    "state_estimator": EstimatorCore,
    "notch_filter": NotchCore,
    "nominal_trajectory": NominalCore,
    "fault_injector": FaultCore,
    **dict.fromkeys(CONTROLLER_NODES, ControllerCore),
}


def build_core(node: str, raw, lanes: Lanes | None = None):
    """Validate the raw parameters of `node` (once per run) and build its core.

    Parameters
    ----------
    node : str
        A loop node (key of `CORES`).
    raw : dict or sequence of dict
        Raw parameters of one run, or of each run of a batch.
    lanes : fahv.lanes.Lanes, optional
        The batch's runs (strict single run by default).

    Raises
    ------
    ParameterError
        Naming the node and the key of a bad parameter.
    """
    runs = [raw] if isinstance(raw, dict) else list(raw)
    lanes = Lanes(len(runs)) if lanes is None else lanes
    return CORES[node]([validate(node, r) for r in runs], lanes)
