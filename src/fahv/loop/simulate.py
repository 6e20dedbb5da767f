"""In-process closed loop: the node computations of the SIL graph, called in its order.

One step k (t_k = k Ts), the order of the node graph (docs/reference/architecture.md), each line one
`*Core` of `fahv.loop.cores` built from that node's parameters
(`fahv.loop.params.node_parameters`), for B runs at once:

    state_k   = plant.state(), y_k = plant.measurement()    (plant, + /clock)
    x_k|k     = estimator.on_measurement(y_k, u_k-1)        (state_estimator)
    q'_k      = notch.on_state(x_k|k)                       (notch_filter)
    ref_k     = nominal.on_state(x_k|k, u_k-1)              (nominal_trajectory)
    u_k, Z_k  = controller.on_inputs(x_k|k, q'_k, ref_k)    (tube_mpc / rmpc)
    u_f,k, f_k = fault.on_command(u_k)                      (fault_injector)
    plant.advance(u_f,k): integrate [t_k, t_k+1], saturated u_f,k held (ZOH).

`simulate` runs one run (B = 1) and can write every message to a run file
(`fahv.runs.writer.RunWriter`) with the topics and types of the SIL recorder; the
campaign engine runs batches of runs through the same `Loop`
(`fahv.loop.batch.simulate_batch`). `History` turns the messages of
either kind of run, simulated or recorded, into `RunResult` arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fahv.errors import RunError
from fahv.lanes import Lanes
from fahv.loop.cores import build_core
from fahv.loop.graph import TOPICS, clock_msg
from fahv.loop.params import controller_node, node_parameters
from fahv.msg import (
    ControlCommand,
    FaultStatus,
    FilteredPitchRate,
    Measurement,
    NominalTrajectory,
    StateEstimate,
    TubeStatus,
    VehicleState,
)
from fahv.verdict import RunEnded

#: Counters of /hsv/tube_status (`lmi_<name>`): the off-line RMPC counts its steps
#: outside its largest ellipsoid as `failed`.
LMI_COUNTS = ("failed",)
#: Counters of the nominal MPC's QP in /hsv/nominal (`qp_<name>`).
QP_COUNTS = ("solves", "fallback", "terminal", "recovered")
#: Loop nodes in the order of one step (the controller node is added per run).
LOOP_NODES = ("plant", "state_estimator", "notch_filter", "nominal_trajectory", "fault_injector")


@dataclass
class RunResult:
    """Histories of one closed-loop run, N steps.

    Attributes
    ----------
    t : (N,) ndarray
        Simulated time [s].
    x : (N, 9) ndarray
        Plant state [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s].
    q_f : (N,) ndarray
        Filtered pitch rate q' [rad/s] (q when there is no notch).
    x_r : (N, 9) ndarray
        Trim state of the governed reference (first 9 components).
    x_n : (N, n) ndarray
        Nominal state (deviation).
    u : (N, 2) ndarray
        Controller command [Phi, delta_e rad].
    u_applied : (N, 2) ndarray
        Input after the fault injector (the plant saturates it).
    h_c, V_c : (N,) ndarray
        Case command [ft, ft/s]; `h_g`, `V_g` the governed reference.
    tube_level : (N,) ndarray
        e' N^-1 e (<= 1 inside the tube Z; NaN for the RMPC).
    fault_active : (N,) bool ndarray
        Fault applied at the step.
    lmi_counts : (1,) int ndarray
        (RMPC) steps with the state outside its largest ellipsoid over the run
        (`LMI_COUNTS`; zero for the tube laws).
    info : dict
        Variant, case name, metadata.
    qp_counts : (4,) int ndarray
        Nominal MPC QPs accepted, nominal steps on the shifted plan and on the
        terminal law, re-plans by the recovery QP over the run (zeros without the
        online MPC; `QP_COUNTS`).
    u_actuator : (N, 2) ndarray or None
        Actuator positions [Phi, delta_e rad] at t_k (/hsv/state; NaN at step 0;
        ideal actuators: the applied input of step k - 1); None if not given.
    u_actuator_rate_peak : (N, 2) ndarray or None
        Each servo's peak |rate| [1/s, rad/s] within [t_k-1, t_k] (/hsv/state; NaN at
        step 0 and for ideal actuators, which have no rate); None if not given.
    y : (N, n_y) ndarray or None
        Sensor measurement of each step (/hsv/measurement, channels in
        `info["measured"]`); None if not given.
    x_hat : (N, 9) ndarray or None
        State estimate x_k|k the controller read (/hsv/state_estimate; the exact state
        for the estimator `none`); None if not given.
    x_hat_sigma : (N, 9) ndarray or None
        The estimator's own standard deviation of each state's error (its covariance's
        diagonal, /hsv/state_estimate `sigma`; NaN where it states none: the exact
        state); None if not given.
    """

    t: np.ndarray
    x: np.ndarray
    q_f: np.ndarray
    x_r: np.ndarray
    x_n: np.ndarray
    u: np.ndarray
    u_applied: np.ndarray
    h_c: np.ndarray
    V_c: np.ndarray
    h_g: np.ndarray
    V_g: np.ndarray
    tube_level: np.ndarray
    fault_active: np.ndarray
    lmi_counts: np.ndarray
    info: dict = field(default_factory=dict)
    qp_counts: np.ndarray = field(default_factory=lambda: np.zeros(4, dtype=int))
    u_actuator: np.ndarray | None = None
    u_actuator_rate_peak: np.ndarray | None = None
    y: np.ndarray | None = None
    x_hat: np.ndarray | None = None
    x_hat_sigma: np.ndarray | None = None


class History:
    """The arrays of `RunResult` for B runs, filled one step at a time.

    Parameters
    ----------
    n_steps : int
        Steps N to hold.
    n_runs : int
        Runs B.
    n : int
        Design-model state dimension (length of x_n).
    n_y : int, optional
        Measured channels (0: no measurement is stored).
    """

    def __init__(self, n_steps: int, n_runs: int, n: int, n_y: int = 0) -> None:
        N, B = n_steps, n_runs
        self.N, self.B, self.count = N, B, 0
        self.t = np.empty(N)
        self.a = {
            "x": np.empty((N, B, 9)),
            "q_f": np.empty((N, B)),
            "x_r": np.empty((N, B, 9)),
            "x_n": np.empty((N, B, n)),
            "u": np.empty((N, B, 2)),
            "u_applied": np.empty((N, B, 2)),
            "h_c": np.empty((N, B)),
            "V_c": np.empty((N, B)),
            "h_g": np.empty((N, B)),
            "V_g": np.empty((N, B)),
            "tube_level": np.empty((N, B)),
            "fault_active": np.empty((N, B), dtype=bool),
            "u_actuator": np.empty((N, B, 2)),
            "u_actuator_rate_peak": np.empty((N, B, 2)),
            "x_hat": np.empty((N, B, 9)),
            "x_hat_sigma": np.full((N, B, 9), np.nan),
        }
        if n_y:
            self.a["y"] = np.empty((N, B, n_y))
        self._counters = None  # the last step's (TubeStatus, NominalTrajectory)

    def add(
        self,
        state: VehicleState,
        qf: FilteredPitchRate,
        nom: NominalTrajectory,
        cmd: ControlCommand,
        tube: TubeStatus,
        act: ControlCommand,
        fs: FaultStatus,
        meas: Measurement | None = None,
        est: StateEstimate | None = None,
    ) -> None:
        """Store the messages of the next step (in step order; `meas` if n_y > 0).

        Without `est` (a run recorded before the estimator existed), the estimate is
        the state the controller then read, the exact state.

        Raises
        ------
        RunError
            If more steps arrive than the history holds.
        """
        k = self.count
        if k >= self.N:
            raise RunError(f"run history holds {self.N} steps; step {k} is one too many")
        a = self.a
        self.t[k] = state.t
        a["x"][k] = state.x()
        a["q_f"][k] = qf.q_f
        a["x_r"][k] = nom.x_r[:, :9]
        a["x_n"][k] = nom.x_n
        a["u"][k] = cmd.u()
        a["u_applied"][k] = act.u()
        a["h_c"][k], a["V_c"][k] = nom.h_c, nom.v_c
        a["h_g"][k], a["V_g"][k] = nom.h_g, nom.v_g
        a["tube_level"][k] = tube.level
        a["fault_active"][k] = fs.active
        a["u_actuator"][k] = state.u_a()
        a["u_actuator_rate_peak"][k] = state.rate_peak()
        a["x_hat"][k] = a["x"][k] if est is None else est.x()
        if est is not None and np.shape(est.sigma)[-1:] == (9,):
            a["x_hat_sigma"][k] = est.sigma
        if "y" in a:
            a["y"][k] = meas.y
        self._counters = (tube, nom)  # running totals: the last step's are the run's
        self.count += 1

    def counts(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """LMI (1,) and QP (4,) counters of run `b` at the last stored step (zeros before)."""
        if self._counters is None:
            return np.zeros(len(LMI_COUNTS), dtype=int), np.zeros(4, dtype=int)
        tube, nom = self._counters
        lmi = (tube.lmi_failed,)
        qp = (nom.qp_solves, nom.qp_fallback, nom.qp_terminal, nom.qp_recovered)
        return np.array([c[b] for c in lmi], dtype=int), np.array([c[b] for c in qp], dtype=int)

    def result(self, b: int, info: dict, n: int | None = None) -> RunResult:
        """`RunResult` of run `b` over its first `n` steps (all stored ones)."""
        n = self.count if n is None else min(int(n), self.count)
        col = {k: np.ascontiguousarray(v[:n, b]) for k, v in self.a.items()}
        lmi, qp = self.counts(b)
        return RunResult(t=self.t[:n].copy(), **col, lmi_counts=lmi, info=dict(info), qp_counts=qp)


def run_result(records: dict, info: dict | None = None) -> RunResult:
    """`RunResult` of one recorded run from its step-aligned messages.

    Parameters
    ----------
    records : dict[str, list[dict]]
        Per loop topic (`fahv.loop.graph.TOPICS`), the message fields (lane form,
        `fahv.msg.LoopMessage.lane`) of steps 0..N-1 in order (e.g. from
        `fahv.runs.bag.step_arrays`).
    info : dict, optional
        Stored as `RunResult.info`.

    Raises
    ------
    RunError
        If the topics do not hold the same number of steps.
    """
    classes = (VehicleState, FilteredPitchRate, NominalTrajectory, ControlCommand, TubeStatus,
               ControlCommand, FaultStatus)  # fmt: skip
    topics = ("/hsv/state", "/hsv/q_filtered", "/hsv/nominal", "/hsv/control_command",
              "/hsv/tube_status", "/hsv/actuator_command", "/hsv/fault_status")  # fmt: skip
    meas = records.get("/hsv/measurement")  # absent from runs recorded before it existed
    est = records.get("/hsv/state_estimate")  # ditto
    lens = {len(records[t]) for t in topics} | {len(m) for m in (meas, est) if m is not None}
    if len(lens) != 1:
        raise RunError(f"run topics hold different numbers of steps: {sorted(lens)}")
    N = lens.pop()
    nom = records["/hsv/nominal"]
    n = len(nom[0]["x_n"]) if N else 9
    hist = History(N, 1, n, len(meas[0]["y"]) if meas and N else 0)
    for k in range(N):
        msgs = (cls.from_lanes([records[t][k]]) for cls, t in zip(classes, topics, strict=True))
        hist.add(*msgs, meas=Measurement.from_lanes([meas[k]]) if meas else None,
                 est=StateEstimate.from_lanes([est[k]]) if est else None)
    return hist.result(0, info or {})


def run_parameters(design, variant: str | None, duration, overrides: dict | None) -> dict:
    """Node parameters of one run: the design's, the duration, then the overrides.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant : str or None
        A variant of the case (its first by default).
    duration : float or None
        Simulated time [s] (the case's by default).
    overrides : dict or None
        `{node: {name: value}}` applied last.

    Returns
    -------
    dict
        `{node: {name: value}}` (flat, unvalidated: `fahv.loop.cores.build_core`
        validates them).

    Raises
    ------
    RunError
        On an override for a node that is not in the run, or an unknown variant.
    """
    case = design.case
    variant = case["variants"][0] if variant is None else variant
    if variant not in case["variants"]:
        raise RunError(f"variant '{variant}' is not in the case's variants {case['variants']}")
    p = node_parameters(design, variant)
    if duration is not None:
        for node in p.values():
            node["duration"] = float(duration)
    for node, values in (overrides or {}).items():
        if node not in p:
            raise RunError(f"override for node '{node}', which is not in the run: {sorted(p)}")
        p[node].update(values)
    return p


class Loop:
    """The closed loop of B runs: the six node cores called in the graph's order.

    Parameters
    ----------
    runs : sequence of dict
        Per run, its raw node parameters `{node: {name: value}}` (`run_parameters`);
        the runs share every design value and the controller node.
    lanes : fahv.lanes.Lanes
        The runs' alive flags (strict: a single run that raises).

    Raises
    ------
    ParameterError
        On a bad parameter of a run (names the node and the key).
    """

    def __init__(self, runs, lanes: Lanes) -> None:
        ctrl = controller_node(runs[0])
        self.lanes = lanes
        self.plant, self.estimator, self.notch, self.nominal, self.fault, self.controller = (
            build_core(node, [r[node] for r in runs], lanes)
            for node in (*LOOP_NODES, ctrl)
        )  # fmt: skip
        self.Ts = runs[0]["plant"]["Ts"]
        self.n_steps = self.plant.n_steps
        self.n = self.controller.n
        #: Measured channels of the plant's sensors.
        self.n_y = 0 if self.plant.sensors is None else len(self.plant.sensors.names)
        self.cmd: ControlCommand | None = None

    def step(self, k: int) -> tuple:
        """Messages of step k in topic order (`fahv.loop.graph.TOPICS`)."""
        self.lanes.step = k
        state = self.plant.state()
        meas = self.plant.measurement()
        est = self.estimator.on_measurement(meas, self.cmd)
        qf = self.notch.on_state(est)
        nom = self.nominal.on_state(est, self.cmd)
        cmd, tube = self.controller.on_inputs(est, qf, nom)
        act, fs = self.fault.on_command(cmd)
        self.plant.advance(act)
        self.cmd = cmd
        return clock_msg(k, self.Ts), state, meas, est, qf, nom, cmd, tube, act, fs


def run_info(design, variant: str, Ts: float, plant: dict | None = None) -> dict:
    """`RunResult.info` of a run: variant, case name, Ts and the case's fault.

    With the run's `plant` node parameters also `plant_params` ({name: value} of
    its perturbed parameters) and `vehicle_file`: what the metric of the attitude
    from the dispersed vehicle's own trim needs (`fahv.runs.metrics.metrics`).
    """
    case = design.case
    info = {"variant": variant, "case": case["name"], "Ts": Ts, "fault": case["fault"]}
    if plant is not None:
        info["plant_params"] = {
            k.split(".", 1)[1]: float(v) for k, v in plant.items() if k.startswith("params.")
        }
        info["vehicle_file"] = plant.get("vehicle_file", "") or ""
        info["measured"] = plant.get("measured", "")
    return info


def simulate(
    design,
    variant: str | None = None,
    duration: float | None = None,
    progress=None,
    writer=None,
    overrides: dict | None = None,
) -> RunResult:
    """Run one variant of a designed case in process (one run, B = 1).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant : str, optional
        One of the case's variants (`fahv.control.VARIANTS`); the first by default.
    duration : float, optional
        Simulated time [s]; the case duration by default.
    progress : callable, optional
        Iterable wrapper (tqdm).
    writer : fahv.runs.writer.RunWriter, optional
        Receives every message of every step (the SIL graph's topics): `write(topic,
        k, msg)` with a `fahv.msg.LoopMessage` of one run (the Clock as fields).
    overrides : dict, optional
        Node parameter overrides `{node: {name: value}}` applied last (e.g.
        `{"plant": {"params.m": 1.05 * m}}`); validated like every parameter.

    Returns
    -------
    RunResult

    Raises
    ------
    RunEnded
        If the run ends before its duration with a verdict (`fahv.verdict`: the
        vehicle left the flight envelope, a non-finite state or input, a nominal that
        cannot be scheduled); the message names the verdict, the time, the step and
        the node, `exc.partial` holds the steps flown before (None before step 1).
    RunError
        On an unknown variant.
    ParameterError
        If the design gives a node an invalid parameter.
    """
    variant = design.case["variants"][0] if variant is None else variant
    p = run_parameters(design, variant, duration, overrides)
    return simulate_parameters(
        p, progress, writer, run_info(design, variant, p["plant"]["Ts"], p["plant"])
    )


def simulate_parameters(params: dict, progress=None, writer=None, info: dict | None = None):
    """Run one run in process from its node parameters alone (B = 1).

    The loop of `simulate`, for a run given by its parameter file rather than a
    design (e.g. the one a run file holds: `fahv campaign rerun RUN`).

    Parameters
    ----------
    params : dict
        `{node: {name: value}}` of every loop node and the controller node
        (`run_parameters`; other sections, e.g. the recorder's, are ignored).
    progress, writer
        As `simulate`.
    info : dict, optional
        `RunResult.info`.

    Returns
    -------
    RunResult

    Raises
    ------
    RunEnded
        If the run ends before its duration with a verdict (as `simulate`).
    ParameterError
        On an invalid node parameter (names the node and the key).
    """
    loop = Loop([params], Lanes(1, strict=True))
    hist = History(loop.n_steps, 1, loop.n, loop.n_y)
    steps = range(loop.n_steps) if progress is None else progress(range(loop.n_steps))
    try:
        for k in steps:
            msgs = loop.step(k)
            _, state, meas, est, *rest = msgs
            hist.add(state, *rest, meas=meas, est=est)
            if writer is not None:
                for topic, msg in zip(TOPICS, msgs, strict=True):
                    writer.write(topic, k, msg)
    except RunEnded as exc:  # what the run flew before, as the batch engine keeps it
        exc.partial = hist.result(0, info or {}) if hist.count else None
        raise
    return hist.result(0, info or {})
