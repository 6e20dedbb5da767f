"""In-process closed loop: the node computations of the SIL graph, called in its order.

One step k (t_k = k Ts), the order of the node graph (ARCHITECTURE.md), each line one
``*Core`` of :mod:`fahv.loop` built from that node's parameters
(:func:`fahv.params.node_parameters`)::

    state_k   = plant.state()                               (plant, + /clock)
    q'_k      = notch.on_state(state_k)                     (notch_filter)
    ref_k     = nominal.on_state(state_k)                   (nominal_trajectory)
    u_k, Z_k  = controller.on_inputs(state_k, q'_k, ref_k)  (tube_mpc / rmpc)
    u_f,k, f_k = fault.on_command(u_k)                      (fault_injector)
    plant.advance(u_f,k): integrate [t_k, t_k+1], saturated u_f,k held (ZOH).

The messages of every step can be written to a run file (:class:`fahv.runlog.RunWriter`)
with the same topics and types as the SIL recorder, and :func:`run_result` turns the
messages of either kind of run into arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fahv.errors import RunError
from fahv.loop import (
    STATE_FIELDS,
    ControllerCore,
    FaultCore,
    NominalCore,
    NotchCore,
    PlantCore,
    clock_msg,
    n_steps_of,
)
from fahv.params import node_parameters
from fahv.runlog import TOPICS, Recording, step_arrays
from fahv.vehicle import ALPHA, ETA1, ETA1_DOT, ETA2, ETA2_DOT, THETA, H, V

#: Tracking counts as settled when |h - h_c| <= 10 ft and |V - V_c| <= 2 ft/s.
SETTLE_TOL = {"h": 10.0, "V": 2.0}
#: Counters of the RMPC's LMI solves in /hsv/tube_status (``lmi_<name>``).
LMI_COUNTS = ("solves", "fallback", "failed")
#: Attitude error bound of sec. 5.1 [deg].
ATTITUDE_BOUND_DEG = 0.5


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
        Case command [ft, ft/s]; ``h_g``, ``V_g`` the governed reference.
    tube_level : (N,) ndarray
        e' (tau^2 N)^-1 e (<= 1 inside the tube; NaN for the RMPC).
    fault_active : (N,) bool ndarray
        Fault applied at the step.
    lmi_counts : (3,) int ndarray
        RMPC LMI solves, certified fallbacks and rejected solves over the run
        (zeros for the tube laws).
    info : dict
        Variant, case name, metadata.
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


def run_result(records: dict, info: dict | None = None) -> RunResult:
    """Arrays of a run from its step-aligned messages.

    Parameters
    ----------
    records : dict[str, list[dict]]
        Per loop topic (:data:`fahv.runlog.TOPICS`), the message dicts of steps
        0..N-1 in order (e.g. from :func:`fahv.runlog.step_arrays`).
    info : dict, optional
        Stored as ``RunResult.info``.

    Raises
    ------
    RunError
        If the topics do not hold the same number of steps.
    """
    st, qf, nom = records["/hsv/state"], records["/hsv/q_filtered"], records["/hsv/nominal"]
    cmd, act = records["/hsv/control_command"], records["/hsv/actuator_command"]
    tube, fs = records["/hsv/tube_status"], records["/hsv/fault_status"]
    lens = {len(v) for v in (st, qf, nom, cmd, act, tube, fs)}
    if len(lens) != 1:
        raise RunError(f"run topics hold different numbers of steps: {sorted(lens)}")

    def col(msgs, name):
        return np.array([m[name] for m in msgs], dtype=float)

    def mat(msgs, name, width=None):
        rows = [np.asarray(m[name], float)[:width] for m in msgs]
        return np.array(rows) if rows else np.zeros((0, width or 0))

    return RunResult(
        col(st, "t"),
        np.stack([col(st, f) for f in STATE_FIELDS], axis=1) if st else np.zeros((0, 9)),
        col(qf, "q_f"),
        mat(nom, "x_r", 9),
        mat(nom, "x_n"),
        np.stack([col(cmd, "phi"), col(cmd, "delta_e")], axis=1) if cmd else np.zeros((0, 2)),
        np.stack([col(act, "phi"), col(act, "delta_e")], axis=1) if act else np.zeros((0, 2)),
        col(nom, "h_c"),
        col(nom, "v_c"),
        col(nom, "h_g"),
        col(nom, "v_g"),
        col(tube, "level"),
        np.array([bool(m["active"]) for m in fs], dtype=bool),
        np.array([tube[-1].get(f"lmi_{c}", 0) if tube else 0 for c in LMI_COUNTS], dtype=int),
        dict(info or {}),
    )


def run_result_of(rec: Recording) -> RunResult:
    """:class:`RunResult` of a recorded run (complete steps only)."""
    n, aligned = step_arrays(rec)
    return run_result(aligned, {**rec.metadata, "steps": n})


def simulate(
    design,
    variant: str | None = None,
    duration: float | None = None,
    progress=None,
    writer=None,
    overrides: dict | None = None,
) -> RunResult:
    """Run one variant of a designed case in process.

    Parameters
    ----------
    design : fahv.design.Design
    variant : str, optional
        One of the case's variants (:data:`fahv.case.VARIANTS`); the first by default.
    duration : float, optional
        Simulated time [s]; the case duration by default.
    progress : callable, optional
        Iterable wrapper (tqdm).
    writer : fahv.runlog.RunWriter, optional
        Receives every message of every step (the SIL graph's topics).
    overrides : dict, optional
        Node parameter overrides ``{node: {name: value}}`` applied last (e.g.
        ``{"rmpc": {"resolve_every": 50}}``); validated like every parameter.

    Returns
    -------
    RunResult

    Raises
    ------
    RunError
        On an unknown variant, or if the plant state becomes non-finite (the run
        stops there and the message gives the time).
    ParameterError
        If the design gives a node an invalid parameter.
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
    ctrl_node = "rmpc" if "rmpc" in p else "tube_mpc"
    plant = PlantCore(p["plant"])
    notch = NotchCore(p["notch_filter"])
    nominal = NominalCore(p["nominal_trajectory"])
    ctrl = ControllerCore(p[ctrl_node], ctrl_node)
    fault = FaultCore(p["fault_injector"])
    Ts = p["plant"]["Ts"]
    records = {t: [] for t in TOPICS}  # the graph order of one step
    n_steps = n_steps_of(p["plant"])
    steps = range(n_steps) if progress is None else progress(range(n_steps))
    for k in steps:
        state = plant.state()
        qf = notch.on_state(state)
        nom = nominal.on_state(state)
        cmd, tube = ctrl.on_inputs(state, qf, nom)
        act, fs = fault.on_command(cmd)
        plant.advance(act)
        msgs = (clock_msg(k, Ts), state, qf, nom, cmd, tube, act, fs)
        for topic, msg in zip(records, msgs, strict=True):
            records[topic].append(msg)
            if writer is not None:
                writer.write(topic, k, msg)
    info = {"variant": variant, "case": case["name"], "Ts": Ts, "fault": case["fault"]}
    return run_result(records, info)


def _settling_time(t, err, tol, t_from):
    """First time after t_from from which |err| <= tol until the end (NaN if never)."""
    bad = np.nonzero((np.abs(err) > tol) & (t >= t_from))[0]
    if bad.size == 0:
        return float(t_from)
    if bad[-1] == t.size - 1:
        return math.nan
    return float(t[bad[-1] + 1])


def metrics(run: RunResult, limits, t_fault: float | None = None) -> dict[str, float]:
    """Metrics of a run (the issue's table): tracking, attitude, flexible, inputs, tube.

    Parameters
    ----------
    run : RunResult
    limits : fahv.vehicle.InputLimits
        Actuator limits (sec. 5.1) the commands u (N, 2) are checked against.
    t_fault : float, optional
        Fault onset [s]; by default the first step with the fault active. None (no
        active fault) or beyond the run: the flexible RMS is over the run.

    Returns
    -------
    dict
        Keys and units as in ``fahv simulate`` (ft, ft/s, deg, s; NaN where a value
        does not exist, e.g. a settling time that is never reached).

    Attitude errors are against the trim of the governed reference x_r (the
    equilibrium the vehicle is steered to). Tracking errors are against the case
    command. Flexible RMS values are over t >= t_fault (the whole run without fault).
    """
    t, x = run.t, run.x
    if t.size == 0:
        raise RunError("the run holds no complete step: no metrics")
    if t_fault is None and np.any(run.fault_active):
        t_fault = float(t[np.argmax(run.fault_active)])
    eh, eV = x[:, H] - run.h_c, x[:, V] - run.V_c
    moving = np.nonzero((run.h_c != run.h_c[-1]) | (run.V_c != run.V_c[-1]))[0]
    t_cmd_end = float(t[moving[-1]]) if moving.size else 0.0
    ts_h = _settling_time(t, eh, SETTLE_TOL["h"], t_cmd_end)
    ts_V = _settling_time(t, eV, SETTLE_TOL["V"], t_cmd_end)
    t_settle = max(ts_h, ts_V) if not (math.isnan(ts_h) or math.isnan(ts_V)) else math.nan
    after = t >= (t_settle if not math.isnan(t_settle) else t[-1])
    tf = t_fault if t_fault is not None and t_fault < t[-1] else t[0]
    post = t >= tf
    ea = np.degrees(x[:, ALPHA] - run.x_r[:, ALPHA])
    et = np.degrees(x[:, THETA] - run.x_r[:, THETA])
    u, lo, hi = run.u, limits.u_min, limits.u_max
    viol = np.maximum(np.maximum(lo - u, u - hi), 0.0)
    lvl = run.tube_level
    lmi = {f"rmpc_lmi_{c}": int(v) for c, v in zip(LMI_COUNTS, run.lmi_counts, strict=True)}
    return {
        "settling_time_h_s": ts_h,
        "settling_time_V_s": ts_V,
        "h_err_max_after_settle_ft": float(np.abs(eh[after]).max()),
        "V_err_max_after_settle_fps": float(np.abs(eV[after]).max()),
        "h_err_rms_after_settle_ft": float(np.sqrt(np.mean(eh[after] ** 2))),
        "V_err_rms_after_settle_fps": float(np.sqrt(np.mean(eV[after] ** 2))),
        "h_err_final_ft": float(eh[-1]),
        "V_err_final_fps": float(eV[-1]),
        "alpha_err_max_deg": float(np.abs(ea).max()),
        "theta_err_max_deg": float(np.abs(et).max()),
        "attitude_within_0.5deg": bool(max(np.abs(ea).max(), np.abs(et).max()) <= 0.5),
        "eta_1_dev_peak": float(np.abs(x[:, ETA1] - run.x_r[:, ETA1]).max()),
        "eta_2_dev_peak": float(np.abs(x[:, ETA2] - run.x_r[:, ETA2]).max()),
        "eta_1_dot_rms_after_fault": float(np.sqrt(np.mean(x[post, ETA1_DOT] ** 2))),
        "eta_2_dot_rms_after_fault": float(np.sqrt(np.mean(x[post, ETA2_DOT] ** 2))),
        "Phi_min": float(u[:, 0].min()),
        "Phi_max": float(u[:, 0].max()),
        "delta_e_min_deg": float(np.degrees(u[:, 1].min())),
        "delta_e_max_deg": float(np.degrees(u[:, 1].max())),
        "input_limit_violations": int(np.count_nonzero(viol.max(axis=1) > 0.0)),
        "tube_fraction_inside": float(np.mean(lvl <= 1.0))
        if np.all(np.isfinite(lvl))
        else math.nan,
        "tube_level_max": float(np.nanmax(lvl)) if np.any(np.isfinite(lvl)) else math.nan,
        **(lmi if run.lmi_counts.any() else {}),
    }


__all__ = [
    "SETTLE_TOL",
    "ATTITUDE_BOUND_DEG",
    "RunResult",
    "run_result",
    "run_result_of",
    "simulate",
    "metrics",
]
