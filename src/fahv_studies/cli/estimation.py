"""`fahv-studies estimation`: what can be certified about a scenario's state estimate.

And what cannot: the filter's error bounds, the output-feedback tube, the probabilistic
tube of the loop on the estimate (`fahv_studies.estimation`).
"""

from __future__ import annotations

import time

import numpy as np

from fahv.certificate.verified import load_or_design
from fahv.cli.common import add_vehicle_option
from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.errors import DesignError, SpecError
from fahv.estimation.kalman import W_SIGMAS, design_filter, measurement_covariance
from fahv.loop.cores import servos_of
from fahv.loop.params import node_parameters
from fahv.model.vehicle import STATE_NAMES, STATE_UNITS
from fahv.sensors.data import CHANNEL_UNITS, load_sensors, measured_channels, replace_channel
from fahv.spec.schema import (
    NO_ESTIMATOR,
    estimator_kind,
    estimator_value,
    law_tau,
    plant_choices,
)

#: Names and units of the filter's state z = [x; d] (`fahv.estimation.kalman`).
Z_NAMES = (*STATE_NAMES, "d_Phi", "d_delta_e")
Z_UNITS = (*STATE_UNITS, "-", "rad")


def named_values(names, units, v) -> str:
    """`h 16.75 ft, theta 0.298 deg`: values with their names, angles in deg, no unit for "-".

    Examples
    --------
    >>> named_values(["h", "q", "eta_1"], ["ft", "rad/s", "-"], [16.75, np.radians(1.0), 0.5])
    'h 16.75 ft, q 1 deg/s, eta_1 0.5'
    """
    out = []
    for name, unit, x in zip(names, units, v, strict=True):
        if unit.startswith("rad"):
            x, unit = np.degrees(x), unit.replace("rad", "deg")
        out.append(f"{name} {x:.4g} {'' if unit == '-' else unit}".rstrip())
    return ", ".join(out)


def state_values(v, states=range(11)) -> str:
    """`h 0.39 ft, V 0.20 ft/s, ...` of states of an (11,) vector of z (`named_values`)."""
    return named_values([Z_NAMES[i] for i in states], [Z_UNITS[i] for i in states],
                        [v[i] for i in states])  # fmt: skip


def channel_values(measured, v) -> str:
    """`h 16.75 ft, theta 0.298 deg` of values per measured channel (`named_values`)."""
    return named_values(measured, [CHANNEL_UNITS[c] for c in measured], v)


def study_lines(study, measured, design_name: str) -> list[str]:
    """The lines `fahv-studies estimation` prints of an `EstimateStudy`.

    `fahv_studies.estimation.study.EstimateStudy`.
    """
    cov, R = study.covariance, study.system.n_vertices
    att = np.degrees(study.noise_worst[2:4]).max()
    verdict = (f"above the attitude requirement ({ATTITUDE_BOUND_DEG} deg) from the estimate "
               "alone: no worst-case (set) certificate of the attitude exists with these "
               "sensors and this filter" if att > ATTITUDE_BOUND_DEG else
               f"within the attitude requirement ({ATTITUDE_BOUND_DEG} deg)")  # fmt: skip
    share = "certified" if study.tube_certified else "NOT certified"
    servos = ", the servos' included (not shown)" if len(cov.std) > len(Z_NAMES) else ""
    return [
        f"estimator: gain-scheduled Kalman filter on {', '.join(measured)} of design "
        f"{design_name} ({R} LPV vertices: {R * R} pairs of model and gain vertex), "
        f"run of {study.steps} steps, probability p = {study.p}",
        f"noise as a random sequence (white, the sensors' stddev): common covariance bound "
        f"over the {R * R} pairs, re-checked exactly (smallest eigenvalue {cov.min_eig:.3g} "
        f">= 0; the LMI held {cov.pairs_held} pairs)",
        f"  1 sigma: {state_values(cov.std)}",
        f"  whole run with p >= {study.p} ({study.r_state:.2f} sigma, union bound over the "
        f"steps and the {len(cov.std)} states{servos}): {state_values(study.run_bound)}",
        f"noise as a bounded sequence (|v| <= {channel_values(measured, study.v_max)}: "
        f"the bound a whole run stays within with p >= {study.p}): worst case at a frozen "
        f"vertex (exact, reached): {state_values(study.noise_worst, range(5))}: {verdict}",
        f"model error as a bounded sequence (the design's W and {W_SIGMAS:g} sigma of the "
        f"input disturbance's step): worst case at a frozen vertex (exact): "
        f"{state_values(study.model_worst, range(5))}",
        f"tube on the estimate (u = v + F (x_hat - x_bar)): the noise-driven error (p >= "
        f"{study.p}, radius {study.r_joint:.2f}) moves the tube error by up to "
        f"{study.tube_share:.3g} of Z per step, against the room {study.tube_room:.3g} of its "
        f"certified level: {share}" + ("" if study.tube_certified else
                                        f" ({study.tube_share / study.tube_room:.0f}x the room)"),
    ]  # fmt: skip


def scaled_noise(data, measured, scale: float):
    """The sensor data with the white-noise stddev of each measured channel times `scale`.

    Raises
    ------
    SpecError
        If `scale` is not a positive finite number.
    """
    if not (np.isfinite(scale) and scale > 0.0):
        raise SpecError(f"--noise-scale must be a positive number, got {scale}")
    for c in measured:
        data = replace_channel(data, c, stddev=data.channels[c].stddev * scale)
    return data


def tube_lines(of) -> list[str]:
    """The lines `fahv-studies estimation` prints of an `OutputFeedbackTube`.

    `of` is a `fahv_studies.estimation.output_feedback.OutputFeedbackTube`.
    """

    def fit(t) -> str:
        return (f"tightening {t.share[0]:.3g} and {t.share[1]:.3g} of the room of Phi and "
                f"delta_e, support of Z in alpha {np.degrees(t.attitude[0]):.3g} deg and theta "
                f"{np.degrees(t.attitude[1]):.3g} deg (lam {t.lam:g})")  # fmt: skip

    est = of.estimate
    verdict = ("it fits" if est.fits else "no room is left for the nominal: no output-feedback "
               "tube of this synthesis exists for these sensors")  # fmt: skip
    return [
        "output-feedback tube (the tube of the estimate, Mayne et al. 2006): the filter's "
        "correction L(p) (C e + v) moves the estimate by up to",
        f"  from the sensor noise (|v| within its run-long bound): "
        f"{state_values(of.sensor, range(1, 9))}",
        f"  from the estimation error (its run-long ellipsoid): "
        f"{state_values(of.error, range(1, 9))}",
        f"  tube LMI (24-28) on the design's LPV vertices (the eight states after h), state "
        f"feedback for the design's W: {fit(of.state_feedback)}",
        f"  the estimate's tube for the sensor noise alone: {fit(est)}: {verdict}",
    ]


def chance_lines(pt, arrays, p: float, steps: int, R: int, tau: float = 1.0,
                 rate_step: float = np.inf, rows=None) -> list[str]:  # fmt: skip
    """The lines `fahv-studies estimation` prints of a `ProbabilisticTube`.

    `fahv.stochastic.closed_loop.ProbabilisticTube`.

    `tau` is the adjustable law's factor (eq. 53-54), `rate_step` the elevator servo's
    rate limit times Ts [rad per step] (inf: none), which the command's step is held
    against; `rows` (2,) the nominal's attitude rows the loop flies [rad] (None: the
    design's `att_max`; a scenario's `estimator.nominal_att_max` sets them lower).
    """
    from fahv.stochastic.closed_loop import attitude_chance, radii

    r_step, r_run = radii(p, steps)
    req = np.radians(ATTITUDE_BOUND_DEG)
    rows = np.asarray(arrays["att_max"] if rows is None else rows, float)
    reach, need = attitude_chance(pt, rows, arrays["att_support"], r_run, req)
    ok = bool(np.all(reach <= req))
    deg = np.degrees
    verdict = ("certified with probability >= p" if ok else
               f"NOT certified; nominal rows of {deg(need[0]):.3f} / {deg(need[1]):.3f} deg "
               "would be")  # fmt: skip
    law = "F" if tau == 1.0 else f"{tau:g} F"
    xi = "[t; e]" if len(pt.Sigma) == 8 + len(Z_NAMES) else "[t; servo states; e]"
    run_step = r_run * pt.std_step[1]
    rate = ("" if not np.isfinite(rate_step) else
            f" ({'within' if run_step <= rate_step else 'BEYOND'} the servo's "
            f"{deg(rate_step):.3f} deg per step)")  # fmt: skip
    return [
        f"probabilistic tube of the loop on the estimate (u = v + {law} (x_hat - x_bar); t = "
        f"x - x_bar, the eight states after h): covariance bound of {xi} driven by the "
        f"sensor noise over the {R * R} pairs, re-checked exactly (smallest eigenvalue "
        f"{pt.min_eig:.3g} >= 0; the LMI held {pt.pairs_held} pairs)",
        f"  1 sigma of t: {state_values(np.r_[0.0, pt.std_t], range(1, 5))}; of the tube's "
        f"input u - v: Phi {pt.std_u[0]:.3g}, delta_e {deg(pt.std_u[1]):.3g} deg; of its step: "
        f"Phi {pt.std_step[0]:.3g}, delta_e {deg(pt.std_step[1]):.3g} deg per step",
        f"  p = {p} at one step ({r_step:.2f} sigma): alpha {deg(r_step * pt.std_t[1]):.4f}, "
        f"theta {deg(r_step * pt.std_t[2]):.4f} deg, delta_e step "
        f"{deg(r_step * pt.std_step[1]):.3f} deg; whole run ({r_run:.2f} sigma): alpha "
        f"{deg(r_run * pt.std_t[1]):.4f}, theta {deg(r_run * pt.std_t[2]):.4f} deg, delta_e "
        f"step {deg(run_step):.3f} deg{rate}",
        f"  attitude (whole run, p >= {p}): nominal rows {deg(rows[0]):.3f} + "
        f"support of Z {deg(arrays['att_support'][0]):.3f} / {deg(arrays['att_support'][1]):.3f}"
        f" + noise part reach {deg(reach[0]):.3f} / {deg(reach[1]):.3f} deg (requirement "
        f"{ATTITUDE_BOUND_DEG} deg): {verdict}",
        f"  model error through the estimate (w within the design's W; exact worst case at a "
        f"frozen vertex, a lower bound on any set that holds it, not in the above): "
        f"{state_values(np.r_[0.0, pt.model_t], range(1, 5))}",
    ]


def cmd_estimation(args) -> int:
    """Print the bounds of a scenario's Kalman filter and the tube's room for them."""
    # cvxpy and scipy.stats: here only
    from fahv.stochastic.closed_loop import loop_tube
    from fahv_studies.estimation.output_feedback import output_feedback_tube
    from fahv_studies.estimation.study import estimate_study

    t0 = time.monotonic()
    spec, design, vehicle = load_or_design(args.scenario, args.design_dir, args.vehicle,
                                           allow_uncertified=True)  # fmt: skip
    c = spec.data
    if estimator_kind(c) == NO_ESTIMATOR:
        raise SpecError(f"{args.scenario}: estimator.kind is {NO_ESTIMATOR!r} (the controller "
                        "reads the exact state): there is no estimate to bound")  # fmt: skip
    if c["design_model"] != "cm":
        raise SpecError(f"{args.scenario}: design {design.summary.get('design_name', '')!r} is "
                        f"of the "
                        f"{c['design_model'].upper()}: the bounds are those of the tube law "
                        "of a CM design (its eight-state tube) on the estimate")  # fmt: skip
    # the rows the scenario's nominal flies (estimator.nominal_att_max); a bad value fails here
    rows = np.radians(node_parameters(design)["nominal_trajectory"]["mpc.att_max"])
    measured = measured_channels(plant_choices(c)["measured"])
    data = scaled_noise(load_sensors(args.vehicle), measured, args.noise_scale)
    a = design.arrays
    actuators = plant_choices(c)["actuators"]
    in_filter = estimator_value(c, "actuators") != "ideal"
    servos = servos_of(vehicle, estimator_value(c, "actuators"), "state_estimator")
    flt = design_filter(a, vehicle, data, measured, c["Ts"], c["plant_substeps"], a["x0"][None],
                        servos, estimator_value(c, "state_disturbance"))  # fmt: skip
    cert = design.summary["certificate"]
    level = cert["level"] if "level" in cert else cert["rpi_level"]
    study = estimate_study(flt, a, data, measured, c["Ts"], round(c["duration"] / c["Ts"]),
                           level, args.probability)  # fmt: skip
    name = design.summary.get("design_name", c.get("design", ""))
    if args.noise_scale != 1.0:
        print(f"sensors: every measured channel's noise stddev times {args.noise_scale:g} "
              "(the filter designed for it)")  # fmt: skip
    for line in study_lines(study, measured, name):
        print(line)
    of = output_feedback_tube(flt, a, study.covariance.S, study.r_joint, study.v_max)
    for line in tube_lines(of):
        print(line)
    tau = law_tau(c)
    rate_step = (min(vehicle.limits.rate_incr[1], vehicle.limits.rate_decr[1]) * c["Ts"]
                 if actuators != "ideal" else np.inf)  # fmt: skip
    try:
        _, pt = loop_tube(study.system, flt, a, tau, measurement_covariance(measured, data))
    except DesignError as exc:  # a verdict, after the bounds above
        pt = None
        print(f"probabilistic tube of the loop: not computed ({exc})")
    for line in () if pt is None else chance_lines(pt, a, study.p, study.steps,
                                                    study.system.n_vertices, tau, rate_step,
                                                    rows):  # fmt: skip
        print(line)
    fault = (c.get("sensor_fault") or {}).get("kind", "none")
    if fault != "none":
        print(f"note: the scenario's sensor fault ({fault}) is not in these bounds: they are "
              "the healthy sensors'")  # fmt: skip
    if actuators != "ideal" and not in_filter:
        print(f"note: the scenario's actuators ({actuators}) are not in the filter's model "
              "(estimator.actuators ideal), so not in these bounds: they are of the loop "
              "whose LPV model takes the command as the applied input")  # fmt: skip
    elif in_filter and actuators == "ideal":
        print("note: the filter models servos (estimator.actuators) the plant does not have "
              "(plant.actuators ideal): these bounds are of a plant with them")  # fmt: skip
    print(f"estimation: {time.monotonic() - t0:.1f} s")
    return 0 if pt is not None else 1


def add_parsers(sub) -> None:
    """Add the parser of this command."""
    p = sub.add_parser(
        "estimation",
        help="bounds of a scenario's state estimate and the tube's room for them",
        description="What can be certified about the estimation error of a scenario's Kalman "
        "filter (estimator.kind kalman): a covariance bound of the noise-driven error over "
        "every pair of model and gain vertex (LMI, re-checked exactly) with the radius a "
        "whole run stays within with probability p; the exact worst cases at the frozen "
        "vertices of the noise and the model error taken as bounded sequences (a lower "
        "bound on any set-based certificate); and what the estimate's error adds to the "
        "tube's one-step level when the tube law feeds it back; whether a tube of the "
        "estimate (output-feedback tube MPC) fits the inputs' room; and the probabilistic "
        "tube of the loop on the estimate (a covariance bound of its deviation from the "
        "nominal, LMI re-checked exactly) with the attitude it reaches with probability p.",
    )
    p.add_argument("scenario", help="scenario file with estimator.kind kalman, e.g. "
                   "studies/kalman_exact_design/scenarios/case1_kalman.yaml")  # fmt: skip
    p.add_argument("--design-dir", default=None, help="artefact folder of the stored design")
    p.add_argument("--probability", type=float, default=0.99,
                   help="probability of the run-long statements (default 0.99)")  # fmt: skip
    p.add_argument("--noise-scale", type=float, default=1.0,
                   help="scale every measured channel's noise stddev by this factor (the "
                        "filter re-designed for it): what sensor quality a certificate "
                        "needs (default 1)")  # fmt: skip
    add_vehicle_option(p)
    p.set_defaults(func=cmd_estimation)
