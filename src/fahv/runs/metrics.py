"""Metrics of a run: tracking, attitude, flexible modes, inputs, tube (the metrics table)."""

from __future__ import annotations

import functools
import math

import numpy as np

from fahv.control.base import ATTITUDE_BOUND_DEG as _ATTITUDE_BOUND_DEG
from fahv.errors import RunError
from fahv.loop.simulate import LMI_COUNTS, QP_COUNTS, RunResult
from fahv.model.trim import TRIM_TOL, trim_batch, trim_map
from fahv.model.vehicle import ALPHA, ETA1, ETA1_DOT, ETA2, ETA2_DOT, THETA, H, V, load_vehicle

#: Tracking counts as settled when |h - h_c| <= 10 ft and |V - V_c| <= 2 ft/s.
SETTLE_TOL = {"h": 10.0, "V": 2.0}


#: Attitude error bound of sec. 5.1 [deg] (defined with the control layer, whose nominal MPC
#: derives its attitude rows from it).
ATTITUDE_BOUND_DEG = _ATTITUDE_BOUND_DEG


def _settling_time(t, err, tol, t_from):
    """First time after t_from from which |err| <= tol until the end (NaN if never)."""
    bad = np.nonzero((np.abs(err) > tol) & (t >= t_from))[0]
    if bad.size == 0:
        return float(t_from)
    if bad[-1] == t.size - 1:
        return math.nan
    return float(t[bad[-1] + 1])


#: Time after the start before the estimate's error is measured (the filter's
#: transient) [s].
ESTIMATE_SETTLE_S = 10.0


def estimate_errors(run: RunResult) -> dict:
    """Errors of the state estimate the controller read, against the true state.

    Parameters
    ----------
    run : RunResult
        With `x_hat` (N, 9) [plant units].

    Returns
    -------
    dict
        Empty when the run read the exact state (no `x_hat`, or x_hat equal to x);
        else `estimate_err_h_rms_ft`, `estimate_err_V_rms_fps` (rms) and
        `estimate_err_alpha_max_deg`, `estimate_err_theta_max_deg` (largest |error|),
        over t >= `ESTIMATE_SETTLE_S` (the whole run if shorter); where the run recorded
        the filter's own standard deviations (`x_hat_sigma`), the share of those steps
        whose error of h lies beyond 3 sigma (`estimate_err_h_outside_3sigma_pct`) and
        the largest such share over h, V, alpha, theta and q
        (`estimate_err_outside_3sigma_max_pct`) [%]: about 0.3 % for a filter whose
        covariance accounts for its errors (Gaussian).
    """
    if run.x_hat is None or np.array_equal(run.x_hat, run.x):
        return {}
    keep = run.t >= ESTIMATE_SETTLE_S
    e = (run.x_hat - run.x)[keep if keep.any() else slice(None)]
    return {
        "estimate_err_h_rms_ft": float(np.sqrt(np.mean(e[:, H] ** 2))),
        "estimate_err_V_rms_fps": float(np.sqrt(np.mean(e[:, V] ** 2))),
        "estimate_err_alpha_max_deg": float(np.degrees(np.abs(e[:, ALPHA]).max())),
        "estimate_err_theta_max_deg": float(np.degrees(np.abs(e[:, THETA]).max())),
        **_outside_3sigma(run, keep if keep.any() else slice(None)),
    }


def _outside_3sigma(run: RunResult, keep) -> dict:
    """Shares [%] of the steps `keep` whose estimate error lies beyond the filter's 3 sigma."""
    sigma = getattr(run, "x_hat_sigma", None)
    if sigma is None or not np.isfinite(sigma[keep][:, :5]).all():
        return {}
    out = np.abs((run.x_hat - run.x)[keep][:, :5]) > 3.0 * sigma[keep][:, :5]
    pct = 100.0 * out.mean(axis=0)
    return {"estimate_err_h_outside_3sigma_pct": float(pct[H]),
            "estimate_err_outside_3sigma_max_pct": float(pct.max())}


def settling_times(run: RunResult, t_cmd_end: float | None = None) -> tuple[float, float]:
    """Settling times of the altitude and the velocity [s] (NaN: never settled).

    The first time after the case command stops moving from which |h - h_c| <=
    `SETTLE_TOL["h"]` (resp. |V - V_c| <= `SETTLE_TOL["V"]`) holds to the end of the run.

    Parameters
    ----------
    run : RunResult
        A run of N >= 1 steps.
    t_cmd_end : float, optional
        `command_end(run)` [s] if already known (computed here otherwise).

    Returns
    -------
    (float, float)
        (t_s of h, t_s of V) [s], simulated time.
    """
    t = run.t
    t_cmd_end = command_end(run) if t_cmd_end is None else t_cmd_end
    return (
        _settling_time(t, run.x[:, H] - run.h_c, SETTLE_TOL["h"], t_cmd_end),
        _settling_time(t, run.x[:, V] - run.V_c, SETTLE_TOL["V"], t_cmd_end),
    )


def command_end(run: RunResult) -> float:
    """Time the case command stops moving [s] (0 for a constant command).

    The last step at which h_c or V_c still differs from its final value, one step
    (Ts) before the command holds it: a step at t_start gives t_start - Ts. Settling is
    measured from it (`settling_times`), the requirement's "after the command", so
    the settling counted is at most one step longer than from the step itself.
    """
    moving = np.nonzero((run.h_c != run.h_c[-1]) | (run.V_c != run.V_c[-1]))[0]
    return float(run.t[moving[-1]]) if moving.size else 0.0


def settling_after(ts_h: float, ts_V: float, t_end: float = 0.0) -> float:
    """Settling time of h and V together, counted from `t_end` [s].

    Parameters
    ----------
    ts_h, ts_V : float
        Settling times of h and V [s, simulated time] (`settling_times`; NaN: never).
    t_end : float
        Time to count from [s]: `command_end` for the requirement's "after the
        command", 0 for the run's time.

    Returns
    -------
    float
        max(ts_h, ts_V) - t_end [s]; NaN unless both settle.
    """
    return math.nan if math.isnan(ts_h) or math.isnan(ts_V) else max(ts_h, ts_V) - t_end


def _settling_after_fault(run: RunResult, t_fault: float | None, t_cmd_end: float) -> float:
    """Settling of h and V together counted from the fault's onset [s] (sec. 5.1).

    The later of the first times after the onset from which |h - h_c| and |V - V_c|
    stay within `SETTLE_TOL` to the end, minus the onset (0: the fault never moved them
    out). NaN without a fault in the run, for an onset before the command stops moving
    (the settling after the command holds it), or when they never settle.
    """
    if t_fault is None or t_fault <= t_cmd_end:
        return math.nan
    ts = settling_times(run, t_fault)
    return settling_after(*ts, t_fault)


@functools.lru_cache(maxsize=4)
def _vehicle(path: str):
    return load_vehicle(path or None)


@functools.lru_cache(maxsize=4)
def _trim_map(path: str):
    return trim_map(_vehicle(path))


#: The nominal's states whose deviation from the nominal vehicle's trim at its own (h, V)
#: `nominal_deviation` measures (the eight-state tube's nominal box coordinates).
NOMINAL_STATES = ("alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")

#: Metric keys of the nominal's largest |deviation| per state of `NOMINAL_STATES`.
NOMINAL_KEYS = (
    "nominal_alpha_dev_max_deg", "nominal_theta_dev_max_deg", "nominal_q_dev_max_degps",
    "nominal_eta_1_dev_max", "nominal_eta_1_dot_dev_max", "nominal_eta_2_dev_max",
    "nominal_eta_2_dot_dev_max",
)  # fmt: skip


def nominal_deviation(run: RunResult) -> np.ndarray:
    """The nominal's deviation from the nominal vehicle's trim at its own (h, V) (N, 7).

    The nominal state is x_r + x_n (the reference's trim plus the nominal deviation the
    nominal_trajectory node publishes); the trim is the packaged (or the run's) vehicle
    file's nominal vehicle, trimmed on a 13 x 13 grid over the envelope and interpolated
    (`fahv.model.trim.trim_map`) at the nominal's (h, V), clipped to the envelope.
    Columns `NOMINAL_STATES` [rad, rad, rad/s, -, 1/s, -, 1/s]: the coordinates
    of the eight-state tube's nominal box, whose range the certificate assumes
    (`fahv.bounds.domain.certified_range`).

    Raises
    ------
    RunError
        If the run holds no step.
    """
    if run.t.size == 0:
        raise RunError("the run holds no complete step: no nominal deviation")
    xn = run.x_r[:, :9] + run.x_n[:, :9]
    env = _vehicle(run.info.get("vehicle_file", "")).envelope
    x_t, _ = _trim_map(run.info.get("vehicle_file", "")).at(
        np.clip(xn[:, H], env.h_min, env.h_max), np.clip(xn[:, V], env.V_min, env.V_max)
    )
    return xn[:, ALPHA:] - np.asarray(x_t, float)[:, ALPHA:9]


def own_trim_attitude(run: RunResult) -> np.ndarray | None:
    """Angle of attack and pitch [rad] (N, 2) of the dispersed vehicle's own trim, eq. (5).

    The trim (eq. 5) of the vehicle with the run's perturbed parameters
    (`run.info["plant_params"]`) at each step's governed reference / artificial set
    point (h_g, V_g), clipped to the envelope; one trim per distinct set point
    (vectorised, `fahv.model.trim.trim_batch`). The parameters come from
    `run.info["plant_params"]` (a simulated run) or the `plant_params.<p>` entries of a
    recorded run's metadata; None if the run carries neither (a run recorded before).

    Raises
    ------
    RunError
        If a trim does not converge.
    """
    pp = run.info.get("plant_params") or {
        k.split(".", 1)[1]: float(v)
        for k, v in run.info.items()
        if k.startswith("plant_params.")  # a recorded run's metadata
    }
    if not pp or run.t.size == 0:
        return None
    veh = _vehicle(run.info.get("vehicle_file", ""))
    env = veh.envelope
    hV = np.stack(
        [np.clip(run.h_g, env.h_min, env.h_max), np.clip(run.V_g, env.V_min, env.V_max)], axis=1
    )
    pts, inv = np.unique(hV, axis=0, return_inverse=True)
    vp = veh.params.replace(**pp)
    guess = np.tile(np.array([[0.03], [0.22], [0.27]]), (1, pts.shape[0]))
    z, res = trim_batch(vp, pts[:, 0], pts[:, 1], guess)
    if not np.all(res < TRIM_TOL):
        raise RunError("no trim of the run's dispersed vehicle at its set point")
    alpha = z[0][np.ravel(inv)]
    return np.stack([alpha, alpha], axis=1)  # level flight: theta = alpha


def input_rates(run: RunResult) -> dict[str, float]:
    """The elevator's largest rate: of the command, of the servo's position, of the servo.

    Parameters
    ----------
    run : RunResult
        With `u` (N, 2) and, if recorded, `u_actuator` (N, 2) [Phi, rad] and
        `u_actuator_rate_peak` (N, 2) [1/s, rad/s].

    Returns
    -------
    dict
        `delta_e_rate_max_degps`: max |u_k+1 - u_k| / Ts of the commanded elevator
        [deg/s], what the controller asks of the servo; `delta_e_actuator_rate_max_degps`:
        the same of the actuator's position (what flies; ideal actuators: the applied
        command), left out without `u_actuator`; `delta_e_servo_rate_peak_degps`: the
        servo's largest |rate| within any step (its rate state, which its rate limit
        bounds; above the step-to-step average), left out for a run without servos.
        NaN for a run of fewer than two steps.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> run = SimpleNamespace(t=np.array([0.0, 0.02, 0.04]), u_actuator=None,
    ...                       u=np.array([[0.0, 0.0], [0.0, np.radians(1.0)], [0.0, 0.0]]))
    >>> round(input_rates(run)["delta_e_rate_max_degps"], 6)
    50.0
    """
    if run.t.size < 2:
        return {"delta_e_rate_max_degps": math.nan}
    Ts = float(run.t[1] - run.t[0])

    def rate(u) -> float:
        step = np.abs(np.diff(u[:, 1]))
        step = step[np.isfinite(step)]
        return float(np.degrees(step.max()) / Ts) if step.size else math.nan

    out = {"delta_e_rate_max_degps": rate(run.u)}
    if run.u_actuator is not None:
        out["delta_e_actuator_rate_max_degps"] = rate(run.u_actuator)
    peak = getattr(run, "u_actuator_rate_peak", None)
    if peak is not None and np.isfinite(peak[:, 1]).any():
        out["delta_e_servo_rate_peak_degps"] = float(np.degrees(np.nanmax(peak[:, 1])))
    return out


def has_servos(run: RunResult) -> bool:
    """Whether the run's actuators have dynamics (a servo between command and position).

    Ideal actuators (the paper's plant) put the applied input of step k - 1 at the
    position of step k (`RunResult.u_actuator`); any servo lags it. A run without
    recorded positions has none known (False).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> u = np.array([[0.1, 0.0], [0.2, 0.01]])
    >>> has_servos(SimpleNamespace(u_applied=u, u_actuator=np.vstack([[np.nan] * 2, u[:1]])))
    False
    >>> has_servos(SimpleNamespace(u_applied=u, u_actuator=np.full((2, 2), np.nan)))
    True
    """
    if run.u_actuator is None or len(run.u_actuator) < 2:
        return False
    return not np.array_equal(run.u_actuator[1:], run.u_applied[:-1], equal_nan=True)


def rate_violations(u: np.ndarray, Ts: float, limits) -> int:
    """Steps whose command asks a servo for more than its rate limit.

    Parameters
    ----------
    u : (N, 2) ndarray
        Commands [Phi, delta_e (rad)] at the steps of period Ts.
    Ts : float
        Control period [s].
    limits : fahv.model.vehicle.InputLimits
        Its `rate_incr`, `rate_decr` (2,) [1/s, rad/s] (JSBSim's `rate_limit` of the
        vehicle file's servos; `inf`: none).

    Returns
    -------
    int
        Steps k (of N - 1) with (u_k+1 - u_k) / Ts above `rate_incr` or below
        -`rate_decr` for either input (beyond a relative 1e-9, rounding).

    Examples
    --------
    >>> from fahv.model.vehicle import InputLimits
    >>> lim = InputLimits(0.0, 1.5, -0.5, 0.5, (1.0, 1.0), (1.0, 0.4))
    >>> rate_violations(np.array([[0.0, 0.0], [0.01, -0.01], [0.0, 0.0]]), 0.02, lim)
    1
    """
    du = np.diff(np.asarray(u, float), axis=0) / Ts
    incr = np.asarray(limits.rate_incr, float) * (1.0 + 1e-9)
    decr = np.asarray(limits.rate_decr, float) * (1.0 + 1e-9)
    with np.errstate(invalid="ignore"):
        over = (du > incr) | (-du > decr)
    return int(np.count_nonzero(over.any(axis=1)))


def _own_trim_metrics(run: RunResult) -> dict[str, float]:
    """Largest attitude errors against the dispersed vehicle's own trim [deg] ({} if unknown)."""
    own = own_trim_attitude(run)
    if own is None:
        return {}
    d = np.degrees(np.abs(run.x[:, ALPHA : THETA + 1] - own))
    return {"alpha_err_own_trim_max_deg": float(d[:, 0].max()),
            "theta_err_own_trim_max_deg": float(d[:, 1].max())}  # fmt: skip


def _nominal_range_metrics(run: RunResult) -> dict[str, float]:
    """The nominal's largest deviations (`NOMINAL_KEYS`) and its h, V range (a tube's run)."""
    dev = np.abs(nominal_deviation(run)).max(axis=0)
    dev[:3] = np.degrees(dev[:3])
    out = {k: float(v) for k, v in zip(NOMINAL_KEYS, dev, strict=True)}
    hn, Vn = run.x_r[:, H] + run.x_n[:, H], run.x_r[:, V] + run.x_n[:, V]
    return out | {
        "nominal_h_min_ft": float(hn.min()), "nominal_h_max_ft": float(hn.max()),
        "nominal_V_min_fps": float(Vn.min()), "nominal_V_max_fps": float(Vn.max()),
    }  # fmt: skip


def metrics(run: RunResult, limits, t_fault: float | None = None) -> dict[str, float]:
    """Metrics of a run (the issue's table): tracking, attitude, flexible, inputs, tube.

    Parameters
    ----------
    run : RunResult
    limits : fahv.model.vehicle.InputLimits
        Actuator limits (sec. 5.1) the commands u (N, 2) are checked against, and the
        servos' rate limits: `input_rate_violations` (`rate_violations`) for a run whose
        actuators have dynamics (`has_servos`), NaN for ideal ones, which have no rate
        limit (the paper's plant).
    t_fault : float, optional
        Fault onset [s]; by default the first step with the fault active. None (no
        active fault) or beyond the run: the flexible RMS is over the run.

    Returns
    -------
    dict
        Keys and units as in `fahv simulate` (ft, ft/s, deg, s; NaN where a value
        does not exist, e.g. a settling time that is never reached).

    Attitude errors are against the trim of the governed reference x_r (the
    equilibrium the vehicle is steered to), the nominal vehicle's (the requirement of
    sec. 5.1 as the project measures it); `alpha_err_own_trim_max_deg` and
    `theta_err_own_trim_max_deg` are against the dispersed vehicle's own trim at the
    same point (`own_trim_attitude`; only for runs that carry their parameters).
    For runs with a tube (finite tube level) `NOMINAL_KEYS` (deg, deg, deg/s for
    alpha, theta, q) are the nominal's largest deviations from the nominal vehicle's
    trim at its own (h, V) (`nominal_deviation`) and `nominal_h_min_ft` ...
    `nominal_V_max_fps` its range: what the tube's certificate assumes of the nominal
    (the campaign report checks them against the design's certified range).
    `settling_after_command_s` is the later settling time of h and V counted from
    `t_command_end_s` (`command_end`), the time the requirement's 60 s run from (NaN
    unless both settle); `settling_after_fault_s` the same counted from a fault's onset
    after the command stopped moving (`_settling_after_fault`); `t_final_s` the time of
    the last step (how long after the command or the onset the run was watched). The
    elevator's largest rates are `input_rates`'. Tracking
    errors are against the case command. Flexible RMS values are over t >= t_fault
    (the whole run without fault); `t_fault_s` is the onset within the run (NaN: no
    fault within the run, so the "after fault" values are over the whole run).
    `tube_error_h_max_ft` is the largest altitude part of the tube error,
    |h - h_r - h_n| (with `mpc.h_reset` it returns to 0 at every re-plan; NaN without
    a tube).
    """
    t, x = run.t, run.x
    if t.size == 0:
        raise RunError("the run holds no complete step: no metrics")
    if t_fault is None and np.any(run.fault_active):
        t_fault = float(t[np.argmax(run.fault_active)])
    eh, eV = x[:, H] - run.h_c, x[:, V] - run.V_c
    t_end = command_end(run)
    ts_h, ts_V = settling_times(run, t_end)
    t_settle = settling_after(ts_h, ts_V)
    settled = not math.isnan(t_settle)
    after = t >= (t_settle if settled else t[-1])
    in_run = t_fault is not None and t_fault < t[-1]
    tf = t_fault if in_run else t[0]
    post = t >= tf
    ea = np.degrees(x[:, ALPHA] - run.x_r[:, ALPHA])
    et = np.degrees(x[:, THETA] - run.x_r[:, THETA])
    u, lo, hi = run.u, limits.u_min, limits.u_max
    viol = np.maximum(np.maximum(lo - u, u - hi), 0.0)
    lvl = run.tube_level
    own_m = _own_trim_metrics(run)
    nom_m = _nominal_range_metrics(run) if np.all(np.isfinite(lvl)) else {}
    lmi = {f"rmpc_lmi_{c}": int(v) for c, v in zip(LMI_COUNTS, run.lmi_counts, strict=True)}
    qp = {f"nominal_qp_{c}": int(v) for c, v in zip(QP_COUNTS, run.qp_counts, strict=True)}
    return {
        "settling_time_h_s": ts_h,
        "settling_time_V_s": ts_V,
        "t_command_end_s": t_end,
        "settling_after_command_s": settling_after(ts_h, ts_V, t_end),
        "settling_after_fault_s": _settling_after_fault(run, tf if in_run else None, t_end),
        "t_final_s": float(t[-1]),
        # after settling: only for a run that settled (NaN otherwise)
        "h_err_max_after_settle_ft": float(np.abs(eh[after]).max()) if settled else math.nan,
        "V_err_max_after_settle_fps": float(np.abs(eV[after]).max()) if settled else math.nan,
        "h_err_rms_after_settle_ft": float(np.sqrt(np.mean(eh[after] ** 2)))
        if settled else math.nan,
        "V_err_rms_after_settle_fps": float(np.sqrt(np.mean(eV[after] ** 2)))
        if settled else math.nan,
        "h_err_final_ft": float(eh[-1]),
        "V_err_final_fps": float(eV[-1]),
        "alpha_err_max_deg": float(np.abs(ea).max()),
        "theta_err_max_deg": float(np.abs(et).max()),
        "attitude_within_0.5deg": bool(
            max(np.abs(ea).max(), np.abs(et).max()) <= ATTITUDE_BOUND_DEG
        ),
        **own_m,
        **estimate_errors(run),
        "eta_1_dev_peak": float(np.abs(x[:, ETA1] - run.x_r[:, ETA1]).max()),
        "eta_2_dev_peak": float(np.abs(x[:, ETA2] - run.x_r[:, ETA2]).max()),
        "t_fault_s": float(tf) if in_run else math.nan,
        "eta_1_dot_rms_after_fault": float(np.sqrt(np.mean(x[post, ETA1_DOT] ** 2))),
        "eta_2_dot_rms_after_fault": float(np.sqrt(np.mean(x[post, ETA2_DOT] ** 2))),
        "Phi_min": float(u[:, 0].min()),
        "Phi_max": float(u[:, 0].max()),
        "delta_e_min_deg": float(np.degrees(u[:, 1].min())),
        "delta_e_max_deg": float(np.degrees(u[:, 1].max())),
        "input_limit_violations": int(np.count_nonzero(viol.max(axis=1) > 0.0)),
        "input_rate_violations": rate_violations(u, float(t[1] - t[0]), limits)
        if t.size > 1 and has_servos(run) else math.nan,
        **input_rates(run),
        "tube_fraction_inside": float(np.mean(lvl <= 1.0))
        if np.all(np.isfinite(lvl))
        else math.nan,
        "tube_level_max": float(np.nanmax(lvl)) if np.any(np.isfinite(lvl)) else math.nan,
        "tube_error_h_max_ft": float(np.abs(x[:, H] - run.x_r[:, H] - run.x_n[:, H]).max())
        if np.all(np.isfinite(lvl))
        else math.nan,
        **nom_m,
        **(lmi if run.lmi_counts.any() else {}),
        **(qp if run.qp_counts.any() else {}),
    }
