"""The scenario's `estimator` section: the flight computer's state estimator and its settings.

A scenario without the section flies the paper's loop (the controller reads the exact
state); with `kind: kalman` the gain-scheduled Kalman filter (`fahv.estimation.kalman`)
estimates the state from the sensors, and the section's other keys adapt the nominal MPC
and the tube law to a loop on the estimate. Part of the scenario schema
(`fahv.spec.schema`), which re-exports every name here.
"""

from __future__ import annotations

from fahv.config import Field, Section
from fahv.control.mpc.estimator import EST_STARTS
from fahv.estimation.state_disturbance import NO_DISTURBANCE, STATE_DISTURBANCE_NAMES
from fahv.model.actuators import ACTUATOR_MODELS, IDEAL

#: The flight computer's estimators: `none` passes the exact state of a full-state
#: sensor through; `kalman` is the gain-scheduled Kalman filter (`fahv.estimation`).
NO_ESTIMATOR = "none"
ESTIMATORS = (NO_ESTIMATOR, "kalman")
#: The estimator's keys (scenario section `estimator`).
ESTIMATOR = (
    Field("kind", "str", "state estimator of the flight computer: none (the exact state of "
          "a full-state sensor, the paper's loop) or kalman (a gain-scheduled Kalman filter "
          "on the measured channels)", choices=ESTIMATORS, default=NO_ESTIMATOR),
    Field("nominal_est_tau", "float", "time constant of the nominal MPC's state-disturbance "
          "estimate on the estimate (replaces the design's mpc.est_tau in the run: the estimate "
          "is noisier than the exact state it was designed for, and the filter estimates an "
          "input disturbance itself); 0: the design's", unit="s", lo=0.0, hi=1e3, default=0.0),
    Field("nominal_est_tau_elevator", "float", "the same for the nominal MPC's estimate "
          "along the elevator column (the design's mpc.est_tau_elevator, Ts in "
          "cm_certified: it takes the estimate's discrepancy wholesale every step); 0: the "
          "design's", unit="s", lo=0.0, hi=1e3, default=0.0),
    Field("nominal_est_start", "str", "start of the nominal MPC's state-disturbance estimate "
          "on the estimate: first (its first residual, as on the exact state), mean (the mean "
          "of the residuals until its gain takes over: one residual of a noisy estimate is "
          "mostly the filter's correction) or zero (d = 0, its own gain from the first "
          "residual)", choices=EST_STARTS, default=EST_STARTS[0]),
    Field("nominal_att_max", "float", "the nominal MPC's attitude rows on the estimate (replaces "
          "the design's mpc.att_max in the run, at most it: room within the attitude requirement "
          "for the estimate's noise); 0: the design's", unit="deg", lo=0.0, hi=5.0, default=0.0),
    Field("tube_tau", "float", "adjustable factor tau of the tube law on the estimate, u = v + "
          "tau F (x_hat - x_bar) (replaces the design's tube.tau in the run: a lower gain passes "
          "less of the estimate's noise to the servos); 0: the design's", lo=0.0, hi=1.0,
          default=0.0, equation="eq. (53-54)"),
    Field("actuators", "str", "actuator model of the Kalman filter's predictor and gains: "
          "ideal (the command acts at once) or second_order (the vehicle file's servos, as "
          "the plant's: four more filter states)", choices=ACTUATOR_MODELS, default=IDEAL),
    Field("state_disturbance", "str", "the Kalman filter's third disturbance, a random walk on "
          "a state's rate: none, flight_path (d_gamma) or altitude_rate (d_h); without one a "
          "vehicle of another mass keeps an offset in its altitude estimate",
          choices=STATE_DISTURBANCE_NAMES, default=NO_DISTURBANCE),
)  # fmt: skip

#: The claims an estimate design can make (`fahv.stochastic.claims`).
ESTIMATE_CLAIMS = ("attitude", "elevator_rate")
#: The keys of a design's `estimate` section (`estimate_design_section`): the loop on the
#: estimate the design states a probability for (`fahv.design.estimate`).
ESTIMATE_DESIGN = (
    Field("probability", "float", "probability, per run, that every claim of the estimate "
          "design holds at once (each claim given its share of 1 - p: a union bound)",
          lo=0.5, hi=1.0, hi_open=True, default=0.99),
    Field("claims", "strs", "what the design claims with the probability: the attitude "
          "requirement (the nominal's rows tightened), the elevator servo's rate (its rate "
          "rows tightened); a claim not made is reported with its numbers",
          choices=ESTIMATE_CLAIMS, default=ESTIMATE_CLAIMS),
    Field("duration", "float", "length of the run the probability is stated for (the union "
          "bound over its steps)", unit="s", lo=1.0, hi=1e4, default=300.0),
    Field("actuators", "str", "actuator model of the plant and of the filter's predictor "
          "and gains", choices=ACTUATOR_MODELS, default="second_order"),
    Field("state_disturbance", "str", "the filter's third disturbance (as the scenario's "
          "estimator.state_disturbance)", choices=STATE_DISTURBANCE_NAMES,
          default=NO_DISTURBANCE),
    Field("nominal_est_tau", "float", "time constant of the nominal MPC's state-disturbance "
          "estimate on the estimate (the design's mpc.est_tau is for the exact state)",
          unit="s", lo=0.0, hi=1e3, lo_open=True, default=2.0),
    Field("nominal_est_tau_elevator", "float", "the same along the elevator column",
          unit="s", lo=0.0, hi=1e3, lo_open=True, default=5.0),
    Field("nominal_est_start", "str", "start of the nominal MPC's state-disturbance estimate "
          "on the estimate", choices=EST_STARTS, default="zero"),
    Field("tau_candidates", "floats", "adjustable factors whose claims the design reports "
          "beside its own tube.tau, for the designer's choice (the F of this design)",
          lo=0.0, hi=1.0, lo_open=True, default=(), equation="eq. (53-54)"),
)  # fmt: skip


def estimate_design_section() -> Section:
    """The `estimate` section of a design file: a design for the loop on the estimate.

    Optional: absent, the design is for the exact state (the paper's loop). Present, `fahv
    design` adds the probabilistic reachable set of the loop on the estimate and the
    nominal's rows tightened by it (`fahv.design.estimate`), and the runs on the design
    fly with its settings (`fahv.loop.params`).
    """
    return Section("estimate", ESTIMATE_DESIGN, "the loop on the state estimate the design "
                   "is made for (sensors, servos and the Kalman filter of the vehicle file)",
                   when=lambda r: False, when_text="a design for the loop on the estimate "
                   "(optional: absent, the design is for the exact state)")  # fmt: skip



def estimator_section() -> Section:
    """The `estimator` section of a scenario and a run spec: optional, left out when absent.

    Absent, the estimator is `none` (and the run spec, and its hash, of a scenario
    without it is what it was before the section existed).
    """
    return Section("estimator", ESTIMATOR, "the flight computer's state estimator",
                   when=lambda r: False, when_text="a scenario estimates the state "
                   "(optional: absent, none: the controller reads the exact state)")  # fmt: skip


def estimator_value(spec, key: str):
    """A key of a run spec's or scenario's `estimator` section; its default if absent.

    Parameters
    ----------
    spec : mapping
        The run spec or scenario data.
    key : str
        A key of `ESTIMATOR`.

    Returns
    -------
    The value, or the `ESTIMATOR` field's default.

    Raises
    ------
    StopIteration
        If `key` is not a key of the section.

    Examples
    --------
    >>> estimator_value({}, "actuators"), estimator_value({"estimator": {"kind": "kalman"}}, "kind")
    ('ideal', 'kalman')
    """
    default = next(f.default for f in ESTIMATOR if f.name == key)
    return (spec.get("estimator") or {}).get(key, default)


def estimator_kind(spec) -> str:
    """The estimator of a run spec or scenario (`estimator.kind`; `none` if absent).

    Examples
    --------
    >>> estimator_kind({}), estimator_kind({"estimator": {"kind": "kalman"}})
    ('none', 'kalman')
    """
    return estimator_value(spec, "kind")


def law_tau(spec) -> float:
    """The adjustable factor tau the tube law of a run spec runs with (eq. 53-54).

    The scenario's `estimator.tube_tau` for a loop on the estimate (when set, > 0), the
    design's `tube.tau` otherwise.

    Examples
    --------
    >>> law_tau({"tube": {"tau": 1.0}, "estimator": {"kind": "kalman", "tube_tau": 0.8}})
    0.8
    >>> law_tau({"tube": {"tau": 1.0}, "estimator": {"kind": "none", "tube_tau": 0.8}})
    1.0
    """
    tau_est = float(estimator_value(spec, "tube_tau"))
    if estimator_kind(spec) != NO_ESTIMATOR and tau_est > 0.0:
        return tau_est
    return float(spec["tube"]["tau"])
