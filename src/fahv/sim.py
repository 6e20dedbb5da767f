"""In-process closed loop: the same plant, filter, controller and fault classes as the nodes.

One step k (t_k = k Ts), the order of the node graph (ARCHITECTURE.md)::

    x_k  = plant state                      (plant)
    q'_k = notch(q_k)                       (notch_filter)
    ref_k = nominal.step()                  (nominal_trajectory)
    u_k  = controller(x_meas_k, ref_k)      (tube_mpc / rmpc)
    u_f,k = fault(t_k, u_k)                 (fault_injector)
    plant integrates [t_k, t_k+1] with saturated u_f,k held (ZOH).

The measured state is the plant state with q replaced by q' when the notch is in the
loop (eq. 38, Case 1) or the 11-state ECM vector [.., q', .., x_q] (eq. 43, Case 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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
from fahv.plant import ElevatorFault, FaultInjector, Plant, saturate
from fahv.trim import TrimMap
from fahv.vehicle import ALPHA, ETA1, ETA1_DOT, ETA2, ETA2_DOT, THETA, H, Q, V, load_vehicle

#: Tracking counts as settled when |h - h_c| <= 10 ft and |V - V_c| <= 2 ft/s.
SETTLE_TOL = {"h": 10.0, "V": 2.0}
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
        Plant state.
    q_f : (N,) ndarray
        Filtered pitch rate q' (q when there is no notch).
    x_r : (N, 9) ndarray
        Trim state of the governed reference (first 9 components).
    x_n : (N, n) ndarray
        Nominal state (deviation).
    u : (N, 2) ndarray
        Controller command.
    u_applied : (N, 2) ndarray
        Input after the fault and the saturation.
    h_c, V_c : (N,) ndarray
        Case command; ``h_g``, ``V_g`` the governed reference.
    tube_level : (N,) ndarray
        e' (tau^2 N)^-1 e (<= 1 inside the tube; NaN for the RMPC).
    info : dict
        Variant, case name, fault, counters.
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
    info: dict = field(default_factory=dict)


def trim_map_of(design) -> TrimMap:
    """The :class:`TrimMap` stored in a design."""
    a = design.arrays
    return TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])


def lpv_of(design) -> PolytopicLPV:
    """The nominal discrete :class:`PolytopicLPV` stored in a design."""
    a = design.arrays
    return PolytopicLPV(a["A"], a["B"], a["h_grid"], a["V_grid"], a["W_h"], a["W_V"])


def command_of(case: dict) -> Command:
    """The :class:`Command` of a case."""
    c = case["command"]
    return Command(c["h0"], c["V0"], c["h_c"], c["V_c"], c["t_start"], c["kind"], c["t_ramp"])


def fault_of(case: dict) -> ElevatorFault:
    """The :class:`ElevatorFault` of a case."""
    f = case["fault"]
    return ElevatorFault(f["kind"], f["t_onset"], f["rho_f"], math.radians(f["bias_deg"]))


def notch_of(case: dict, variant: str, omega_flex) -> NotchFilter | None:
    """Notch in the q feedback for a variant: the case's, the mode-2 one, or None."""
    n = case["notch"]
    if variant == "tube_mpc_no_notch" or not n["enabled"]:
        return None
    if variant == "tube_mpc_notch2":
        w = float(omega_flex[1])
        return NotchFilter(w, n["eps_z"], w, n["eps_p"])
    return NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])


def measured_state(x: np.ndarray, q_f: float, notch: DiscreteNotch | None, n: int) -> np.ndarray:
    """Controller state (n,) from the plant state x (9,) and the filter.

    n = 9: x with q replaced by q' (when a notch is used); n = 11: the ECM vector
    [h, V, alpha, theta, q', eta.., x_q1, x_q2] of eq. (43).
    """
    xm = np.array(x, dtype=float)
    if notch is not None:
        xm[Q] = q_f
    if n == 11:
        if notch is None:
            raise RunError("the 11-state (ECM) controller needs the notch filter states")
        xm = np.concatenate([xm, notch.x_q])
    return xm


def simulate(design, variant: str, duration: float | None = None, progress=None) -> RunResult:
    """Run one variant of a designed case in process.

    Parameters
    ----------
    design : fahv.design.Design
    variant : str
        One of :data:`fahv.case.VARIANTS` listed in the case.
    duration : float, optional
        Simulated time [s]; the case duration by default.
    progress : callable, optional
        Iterable wrapper (tqdm).

    Returns
    -------
    RunResult

    Raises
    ------
    RunError
        On an unknown variant, or if the plant state becomes non-finite (the run
        stops there and the message gives the time).
    """
    case = design.case
    if variant not in case["variants"]:
        raise RunError(f"variant '{variant}' is not in the case's variants {case['variants']}")
    Ts = case["Ts"]
    T = case["duration"] if duration is None else duration
    n_steps = int(round(T / Ts))
    veh = load_vehicle()
    a = design.arrays
    tm = trim_map_of(design)
    n = design.n_x
    cmd = command_of(case)
    x0 = tm(cmd.h0, cmd.V0)[0][:9]
    plant = Plant(design.plant_params(veh), veh.limits, x0, Ts, case["plant_substeps"])
    nf = notch_of(case, variant, a["omega_flex"])
    notch = DiscreteNotch(nf, Ts) if nf is not None else None
    fault = FaultInjector(fault_of(case))
    tube = TubeMPC(a["F"], a["N"], case["tube"]["tau"])
    rmpc = nominal = None
    if variant != "rmpc":
        nominal = NominalTrajectory(
            lpv_of(design), tm, a["K"], a["Q"], cmd, Ts, case["nominal"]["level_max"]
        )
        nominal.reset(measured_state(x0, 0.0, notch, n))
    else:
        r = case["rmpc"]
        rmpc = RobustMPC(
            a["rmpc_A"],
            a["rmpc_B"],
            a["u_room"],
            np.full(9, r["psi"]),
            np.full(2, r["sigma"]),
            a["Dx"][:9],
            a["Du"],
            r["resolve_every"],
        )
    rec = {k: [] for k in ("x", "q_f", "x_r", "x_n", "u", "ua", "hc", "Vc", "hg", "Vg", "lvl")}
    steps = range(n_steps) if progress is None else progress(range(n_steps))
    for k in steps:
        t = k * Ts
        x = plant.x.copy()
        if not np.all(np.isfinite(x)):
            raise RunError(f"{variant}: plant state not finite at t = {t:.2f} s")
        q_f = notch.step(float(x[Q])) if notch is not None else float(x[Q])
        xm = measured_state(x, q_f, notch, n)
        if rmpc is None:
            ref = nominal.step()
        else:  # the traditional RMPC tracks the raw command, without governor
            x_c, u_c = tm(*cmd(t))
            ref = NominalOutput(*cmd(t), x_c, u_c, np.zeros(n), np.zeros(2), math.nan)
        if rmpc is not None:
            u = rmpc.step(k, xm[:9], ref)
            lvl = math.nan
        else:
            u = tube.step(xm, ref)
            lvl = tube.tube_level(tube.error(xm, ref))
        ua = fault.apply(t, u)
        plant.step(ua)
        hc, Vc = cmd(t)
        for key, val in (
            ("x", x),
            ("q_f", q_f),
            ("x_r", ref.x_r[:9]),
            ("x_n", ref.x_n),
            ("u", u),
            ("ua", saturate(ua, veh.limits)),
            ("hc", hc),
            ("Vc", Vc),
            ("hg", ref.h_g),
            ("Vg", ref.V_g),
            ("lvl", lvl),
        ):
            rec[key].append(val)
    info = {"variant": variant, "case": case["name"], "Ts": Ts, "fault": case["fault"]}
    if rmpc is not None:
        info.update(rmpc_solves=rmpc.n_solves, rmpc_failed=rmpc.n_failed)
    r = {k: np.array(v) for k, v in rec.items()}
    return RunResult(
        np.arange(n_steps) * Ts,
        r["x"],
        r["q_f"],
        r["x_r"],
        r["x_n"],
        r["u"],
        r["ua"],
        r["hc"],
        r["Vc"],
        r["hg"],
        r["Vg"],
        r["lvl"],
        info,
    )


def _settling_time(t, err, tol, t_from):
    """First time after t_from from which |err| <= tol until the end (NaN if never)."""
    bad = np.nonzero((np.abs(err) > tol) & (t >= t_from))[0]
    if bad.size == 0:
        return float(t_from)
    if bad[-1] == t.size - 1:
        return math.nan
    return float(t[bad[-1] + 1])


def metrics(run: RunResult, limits, t_fault: float | None) -> dict[str, float]:
    """Metrics of a run (the issue's table): tracking, attitude, flexible, inputs, tube.

    Parameters
    ----------
    run : RunResult
    limits : fahv.vehicle.InputLimits
        Actuator limits (sec. 5.1) the commands u (N, 2) are checked against.
    t_fault : float or None
        Fault onset [s]; None or beyond the run: the flexible RMS is over the run.

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
    }


__all__ = [
    "SETTLE_TOL",
    "ATTITUDE_BOUND_DEG",
    "RunResult",
    "trim_map_of",
    "lpv_of",
    "command_of",
    "fault_of",
    "notch_of",
    "measured_state",
    "simulate",
    "metrics",
]
