"""In-process closed loop: the node computations of the SIL graph, called in its order.

One step k (t_k = k Ts), the order of the node graph (docs/architecture.md), each line one
``*Core`` of :mod:`fahv.loop.cores` built from that node's parameters
(:func:`fahv.loop.params.node_parameters`)::

    state_k   = plant.state()                               (plant, + /clock)
    q'_k      = notch.on_state(state_k)                     (notch_filter)
    ref_k     = nominal.on_state(state_k, u_k-1)            (nominal_trajectory)
    u_k, Z_k  = controller.on_inputs(state_k, q'_k, ref_k)  (tube_mpc / rmpc)
    u_f,k, f_k = fault.on_command(u_k)                      (fault_injector)
    plant.advance(u_f,k): integrate [t_k, t_k+1], saturated u_f,k held (ZOH).

The messages of every step can be written to a run file (:class:`fahv.runs.bag.RunWriter`)
with the same topics and types as the SIL recorder, and :func:`run_result` turns the
messages of either kind of run into arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fahv.errors import RunError
from fahv.loop.cores import build_core
from fahv.loop.graph import STATE_FIELDS, TOPICS, clock_msg, n_steps_of
from fahv.loop.params import controller_node, node_parameters

#: Counters of the RMPC's LMI solves in /hsv/tube_status (``lmi_<name>``).
LMI_COUNTS = ("solves", "fallback", "failed")
#: Counters of the nominal MPC's QP in /hsv/nominal (``qp_<name>``).
QP_COUNTS = ("solves", "fallback", "terminal")


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
    qp_counts : (3,) int ndarray
        Nominal MPC QPs accepted, nominal steps on the shifted plan and on the
        terminal law over the run (zeros without the online MPC).
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
    qp_counts: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=int))


def run_result(records: dict, info: dict | None = None) -> RunResult:
    """Arrays of a run from its step-aligned messages.

    Parameters
    ----------
    records : dict[str, list[dict]]
        Per loop topic (:data:`fahv.loop.graph.TOPICS`), the message dicts of steps
        0..N-1 in order (e.g. from :func:`fahv.runs.bag.step_arrays`).
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
        np.array([nom[-1].get(f"qp_{c}", 0) if nom else 0 for c in QP_COUNTS], dtype=int),
    )


def run_parameters(design, variant: str | None, duration, overrides: dict | None) -> dict:
    """Node parameters of one run: the design's, the duration, then the overrides.

    Parameters
    ----------
    design : fahv.design.Design
    variant : str or None
        A variant of the case (its first by default).
    duration : float or None
        Simulated time [s] (the case's by default).
    overrides : dict or None
        ``{node: {name: value}}`` applied last.

    Returns
    -------
    dict
        ``{node: {name: value}}`` (flat, unvalidated: :func:`fahv.loop.cores.build_core`
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
        One of the case's variants (:data:`fahv.control.VARIANTS`); the first by default.
    duration : float, optional
        Simulated time [s]; the case duration by default.
    progress : callable, optional
        Iterable wrapper (tqdm).
    writer : fahv.runs.bag.RunWriter, optional
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
    p = run_parameters(design, variant, duration, overrides)
    ctrl_node = controller_node(p)
    plant, notch, nominal, fault, ctrl = (
        build_core(n, p[n])
        for n in ("plant", "notch_filter", "nominal_trajectory", "fault_injector", ctrl_node)
    )
    Ts = p["plant"]["Ts"]
    records = {t: [] for t in TOPICS}  # the graph order of one step
    n_steps = n_steps_of(p["plant"])
    steps = range(n_steps) if progress is None else progress(range(n_steps))
    cmd = None
    for k in steps:
        state = plant.state()
        qf = notch.on_state(state)
        nom = nominal.on_state(state, cmd)
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
