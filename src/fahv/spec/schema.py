"""Design, scenario and run-spec schemas: what a design certifies and what a scenario flies.

A **design file** (`design_spec`, `offline_design/designs/<name>.yaml`) holds what
`fahv design` synthesises and certifies: design model, parameter box, fault range,
tube, nominal MPC, notch and baseline settings. A **scenario file**
(`scenario_spec`, `offline_design/scenarios/<name>.yaml`) names a design and holds
one thing to fly on it: command, fault instance, simulated vehicle draw, duration,
variants. The **run spec** (`run_spec`) is the two together, what the loop runs on.

Each schema is declared once in the configuration language (`fahv.config`), with
the fault kinds of `fahv.plant.faults.FAULTS` and the sections of the control laws
of `fahv.control.LAWS` (a law's section is required only when a listed variant
uses the law). Numerical knobs (sample counts, seeds, margins, trim grid, LMI factors)
have defaults, and the defaults a design used are reported by it. The node parameters of
the SIL graph reuse the same fields (`fahv.loop.params`), so a range is written once.

Loading (`fahv.spec.files`) fails with `fahv.errors.SpecError` naming the
file and the dotted key.
"""

from __future__ import annotations

import math

from fahv.config import Check, Field, Section
from fahv.config.spec import lookup
from fahv.control import LAWS, NOMINAL_SOURCES, VARIANTS
from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.model.actuators import ACTUATOR_MODELS, IDEAL
from fahv.plant.faults import FAULT_KIND, T_ONSET, fault_fields
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.sensors.data import CHANNELS, DEFAULT_MEASURED, EXACT_STATE
from fahv.sensors.faults import SENSOR_FAULTS, sensor_fault_fields
from fahv.spec.estimator import (  # noqa: F401 - the scenario schema's estimator section
    ESTIMATE_DESIGN,
    ESTIMATOR,
    ESTIMATORS,
    NO_ESTIMATOR,
    estimate_design_section,
    estimator_kind,
    estimator_section,
    estimator_value,
    law_tau,
)
from fahv.spec.plant_dispersion import PLANT_DISPERSION
from fahv.spec.requirements import requirements_section

TS = Field("Ts", "float", "control period Ts", unit="s", lo=0.0, hi=0.1, lo_open=True)
DURATION = Field("duration", "float", "simulated duration of a run", unit="s", lo=0.0, lo_open=True)
PLANT_SUBSTEPS = Field(
    "plant_substeps", "int", "RK4 steps per control period (plant integrator)", lo=1, hi=100,
    default=5,
)  # fmt: skip

NOTCH = (
    Field("enabled", "bool", "notch filter on the q feedback (false: q passes through)"),
    Field("omega_z", "float", "notch zero frequency omega_z", unit="rad/s", lo=0.0,
          lo_open=True, equation="eq. (38)"),
    Field("eps_z", "float", "notch zero damping eps_z", lo=0.0, hi=10.0, equation="eq. (38)"),
    Field("omega_p", "float", "notch pole frequency omega_p", unit="rad/s", lo=0.0,
          lo_open=True, equation="eq. (38)"),
    Field("eps_p", "float", "notch pole damping eps_p", lo=0.0, hi=10.0, lo_open=True,
          equation="eq. (38)"),
)  # fmt: skip

COMMAND = (
    Field("kind", "str", "command shape: step at t_start, or ramp over t_ramp",
          choices=("step", "ramp")),
    Field("h0", "float", "initial trim altitude", unit="ft", lo=0.0, hi=2e5),
    Field("V0", "float", "initial trim velocity", unit="ft/s", lo=0.0, hi=2e4),
    Field("h_c", "float", "commanded altitude", unit="ft", lo=0.0, hi=2e5),
    Field("V_c", "float", "commanded velocity", unit="ft/s", lo=0.0, hi=2e4),
    Field("t_start", "float", "time the command starts to change", unit="s", lo=0.0),
    Field("t_ramp", "float", "ramp duration", unit="s", lo=0.0, default=0.0,
          when=lambda r: lookup(r, "command.kind") == "ramp", when_text="command.kind is ramp"),
)  # fmt: skip

#: Forms of the tube (`tube.form`).
TUBE_FORMS = ("vertices", "eight_state")


def _eight_state(root) -> bool:
    return lookup(root, "tube.form") == "eight_state"


#: The eight-state tube (`fahv.design.tube_set_design`): vertex data, the nominal box
#: (the ranges of the nominal the certificate covers), the scheduling box beyond it and
#: the W_8-Z_8 iteration. Defaults: the tube set of docs/theory/certificate.md.
EIGHT_STATE = (
    Field("k", "int", "parameter directions the vertices carry (64 scheduling-box corners "
          "x 2^k x 2 rho_f vertices)", lo=1, hi=8, default=5),
    Field("lam", "float", "contraction factor of the eight-state tube LMI", lo=0.0, hi=1.0,
          lo_open=True, hi_open=True, default=0.995, equation="LMI (24)"),
    Field("w0", "float", "W_8 the iteration starts from, as a fraction of the sampled W",
          lo=0.0, hi=100.0, lo_open=True, default=0.15, equation="eq. (19)"),
    Field("grow", "float", "W_8 <- max(W_8, grow x bound) between iterations", lo=1.0,
          hi=2.0, default=1.05),
    Field("iterations", "int", "most W_8-Z_8 iterations", lo=1, hi=50, default=6),
    Field("h_margin", "float", "nominal box: the nominal's h range is the envelope's shrunk "
          "by this on each side (the scheduling box spans the envelope; at least the altitude "
          "bound H); the QP keeps its set point and prediction in it (mpc.hv_box) and the "
          "design step must lie in it", unit="ft", lo=0.0, default=5.0),
    Field("V_margin", "float", "nominal box: the nominal's V range is the envelope's shrunk "
          "by this on each side (at least Z_8's V support; mpc.hv_box as h_margin)",
          unit="ft/s", lo=0.0, default=4.98),
    Field("attitude", "float", "nominal box: half-width of the nominal's alpha and theta "
          "deviation from the trim at its own (h, V); at least mpc.att_max", unit="deg",
          lo=0.0, lo_open=True, hi=5.0, default=0.4),
    Field("Phi", "floats", "nominal box: range of the applied Phi minus the nominal trim's "
          "(it must hold every parameter-box corner's trim and the manoeuvres)", lo=-2.0,
          hi=2.0, length=2, default=(-0.2, 1.1)),
    Field("delta_e", "floats", "nominal box: range of the applied delta_e minus the nominal "
          "trim's (it must hold every parameter-box corner's trim and the manoeuvres)",
          unit="deg", lo=-30.0, hi=30.0, length=2, default=(-3.0, 7.0)),
    Field("other", "floats", "nominal box: half-widths of the nominal's q [deg/s] and "
          "eta_1, eta_1_dot, eta_2, eta_2_dot deviations from the trim", lo=0.0,
          lo_open=True, length=5, default=(0.7, 0.5, 3.5, 0.3, 3.5)),
    Field("reach", "floats", "scheduling box beyond the nominal box, each side: alpha, "
          "theta [deg], Phi, delta_e [deg], q [deg/s], eta_1, eta_1_dot, eta_2, eta_2_dot; "
          "must hold the tube's supports (the design refuses it otherwise)", lo=0.0,
          length=9, default=(0.59, 0.554, 0.0772, 4.39, 0.886, 0.716, 9.48, 0.24, 5.655)),
    Field("certify_attitude", "bool", "bound Z_8's supports in alpha and theta in the tube "
          "LMI to the attitude requirement (0.5 deg, sec. 5.1) minus mpc.att_max, so that "
          "the requirement follows from the tube set with the QP's rows", default=False),
    Field("onset_in_tube", "float", "kappa: the tube LMI makes Z_8 hold every first jump "
          "J / rho_min of the design's loss 1 - rho_min over the scheduling box (its 64 x "
          "2^P corners and 1024 interior points) in kappa Z_8, so that the onset bound "
          "starts from room along the elevator's column (docs/theory/certificate.md, 'A tube "
          "shaped for the onset's jump'); 0: not imposed", lo=0.0, default=0.0),
    Field("notch_gain", "str", "gain of the tube variants that run through the certified "
          "notch (tube.filter_nominal_q): the tube set's F_8 ('tube') or a gain designed for the "
          "loop with the filter's states, certified with the tube set's Z_8 and tightening and "
          "W_8 re-bounded over its own set ('designed'; docs/theory/certificate.md)",
          choices=("tube", "designed"), default="tube"),
    Field("notch_continuation", "floats", "notch pole dampings eps_p the designed gain "
          "passes through before notch.eps_p, increasing (the first from F_8's ellipsoid)",
          lo=0.0, hi=1.0, lo_open=True, default=(0.05,)),
)  # fmt: skip

EIGHT_STATE_CHECKS = (
    Check("Phi", lambda r: r["eight_state"]["Phi"][0] < r["eight_state"]["Phi"][1],
          "must be an increasing pair"),
    Check("delta_e", lambda r: r["eight_state"]["delta_e"][0] < r["eight_state"]["delta_e"][1],
          "must be an increasing pair"),
    Check("certify_attitude", lambda r: not r["eight_state"]["certify_attitude"]
          or ("mpc" in r and r["mpc"]["att_max"] < ATTITUDE_BOUND_DEG),
          f"needs mpc.att_max below the requirement {ATTITUDE_BOUND_DEG} deg (the rest is "
          "the tube's support)"),
    Check("notch_continuation", lambda r: r["eight_state"]["notch_gain"] != "designed" or (
          all(b > a for a, b in zip(r["eight_state"]["notch_continuation"],
                                    [*r["eight_state"]["notch_continuation"][1:],
                                     r["notch"]["eps_p"]], strict=True))),
          "must increase to below notch.eps_p"),
    Check("notch_gain", lambda r: r["eight_state"]["notch_gain"] != "designed" or (
          r["notch"]["enabled"] and r["tube"]["filter_nominal_q"]),
          "'designed' needs notch.enabled and tube.filter_nominal_q (the certified loop)"),
    Check("notch_gain", lambda r: r["eight_state"]["notch_gain"] != "designed"
          or r["tube"]["tau"] == 1.0,
          "'designed' needs tube.tau 1 (the designed gain's certificate covers that gain "
          "alone, not the adjustable law's tau' K)"),
)  # fmt: skip


def _eight_state_needs(r) -> bool:
    """True unless the design asks for the eight-state tube without the loop it is closed for.

    That loop: the CM design model, the CM nominal with the altitude reset and a
    disturbance estimate (W_8 bounds what the converged estimate leaves), and attitude
    rows inside the nominal box. Any tau: the vertices cover the adjustable law's gains.
    """
    if r["tube"]["form"] != "eight_state":
        return True
    m = r.get("mpc")
    return bool(
        r["design_model"] == "cm" and m is not None
        and m["nominal_model"] == "cm" and m["h_reset"] and m["est_tau"] > 0.0
        and 0.0 < m["att_max"] <= r["eight_state"]["attitude"]
    )  # fmt: skip


#: The simulated plant's own choices (scenario key `plant`): the actuator model and the
#: sensors (the noise models are the vehicle file's `sensors` section).
PLANT = (
    Field("actuators", "str", "actuator model of the simulated plant: ideal (no dynamics, "
          "the paper's plant) or second_order (servos of the vehicle file's actuators "
          "section, rate and position limited)", choices=ACTUATOR_MODELS, default=IDEAL),
    Field("measured", "str", "sensor channels of /hsv/measurement, comma-separated, from "
          f"{', '.join(CHANNELS)} (q: the gyro, which sees the flexible modes), or "
          f"{EXACT_STATE!r}: every state exactly (the paper's full-state loop); default: "
          f"{EXACT_STATE!r} with estimator none, {','.join(DEFAULT_MEASURED)!r} with kalman",
          default=EXACT_STATE),
    Field("sensor_seed", "int", "seed of the run's sensor noise (with the channel and the "
          "step, it keys every draw)", lo=0, default=0),
    *PLANT_DISPERSION,
)  # fmt: skip


def plant_choices(spec) -> dict:
    """The simulated plant's choices of a run spec or scenario (its `plant` section).

    `actuators`, `measured`, `sensor_seed` and the servo and sensor factors
    (`fahv.spec.plant_dispersion`), each at its default where the section (or the key)
    is absent: ideal actuators; seed 0; the exact state for the estimator `none`, h,
    V, theta and the gyro's q for the Kalman filter; the vehicle file's servos and
    sensors.

    Examples
    --------
    >>> {k: v for k, v in plant_choices({}).items() if k in ("actuators", "measured")}
    {'actuators': 'ideal', 'measured': 'state'}
    >>> plant_choices({})["servo_omega_n_factor"], plant_choices({})["sensor_bias_mean_shift"]
    (1.0, 0.0)
    >>> plant_choices({"estimator": {"kind": "kalman"}})["measured"]
    'h,V,theta,q'
    """
    plant = spec.get("plant") or {}
    out = {f.name: plant.get(f.name, f.default) for f in PLANT}
    if "measured" not in plant and estimator_kind(spec) != NO_ESTIMATOR:
        out["measured"] = ",".join(DEFAULT_MEASURED)
    return out


def plant_section() -> Section:
    """The `plant` section of a scenario and a run spec: optional, left out when absent.

    Absent, it is not filled in (so the run spec, and its hash, of a scenario without it
    is what it was before the section existed); `actuator_model` and `plant_choices`
    read it.
    """
    return Section("plant", PLANT, "the simulated plant: actuator model, sensors",
                   when=lambda r: False, when_text="a scenario sets another actuator model "
                   "or other sensors (optional: absent, the actuators are ideal and the "
                   "sensors measure h, V, theta and q)")


def sensor_fault_section() -> Section:
    """The `sensor_fault` section of a scenario and a run spec: optional, left out when absent.

    Absent, no sensor fault (and the run spec, and its hash, of a scenario without it is
    what it was before the section existed). `fahv.sensors.faults.sensor_fault_fields`
    gives its keys.
    """
    return Section("sensor_fault", sensor_fault_fields(), "a fault of one sensor channel "
                   "(fahv.sensors.faults)", when=lambda r: False,
                   when_text="a scenario fails a sensor (optional: absent, none)")  # fmt: skip


def sensor_fault_used(section: dict) -> dict:
    """The keys of a `sensor_fault` section that its kind uses (the others' defaults out).

    Examples
    --------
    >>> sensor_fault_used({"kind": "none", "channel": "h", "t_onset": 1.0})
    {'kind': 'none'}
    """
    kind = section["kind"]
    used = ("kind", "channel", "t_onset", *(f.name for f in SENSOR_FAULTS[kind].parameters))
    return {k: section[k] for k in used if k in section and (kind != "none" or k == "kind")}


def sensor_fault_values(spec) -> dict:
    """The plant's `sensor_fault.*` node parameters of a run spec or scenario.

    The section's keys that its kind uses, prefixed; `{"sensor_fault.kind": "none"}`
    when the section is absent.

    Examples
    --------
    >>> sensor_fault_values({})
    {'sensor_fault.kind': 'none'}
    >>> sensor_fault_values({"sensor_fault": {"kind": "stuck", "channel": "q", "t_onset": 5.0}})
    {'sensor_fault.kind': 'stuck', 'sensor_fault.channel': 'q', 'sensor_fault.t_onset': 5.0}
    """
    section = spec.get("sensor_fault") or {"kind": "none"}
    return {f"sensor_fault.{k}": v for k, v in sensor_fault_used(section).items()}


def actuator_model(spec) -> str:
    """The actuator model of a run spec or scenario (`plant.actuators`; `ideal` if absent).

    Examples
    --------
    >>> actuator_model({}), actuator_model({"plant": {"actuators": "second_order"}})
    ('ideal', 'second_order')
    """
    return (spec.get("plant") or {}).get("actuators", IDEAL)


#: Uncertain parameters of the sec. 5.1 box (`uncertainty.s` holds one value per each).
N_UNCERTAIN = len(PAPER_UNCERTAINTY)
UNCERTAINTY = (
    Field("seed", "int", "seed of the parameter draw s_p ~ U(-1, 1)", lo=0),
    Field("scale", "float", "fraction of the sec. 5.1 parameter box", lo=0.0, hi=1.0),
    Field("s", "floats", "the vehicle's s_p in [-1, 1] themselves, one per uncertain "
          f"parameter in the order {', '.join(PAPER_UNCERTAINTY)} (empty: drawn from the "
          "seed); a clearance's worst case names its vehicle so", lo=-1.0, hi=1.0,
          default=()),
)


def fault_section() -> Section:
    """The `fault` section: kind (from the fault registry), onset, the kind's parameters."""
    return Section("fault", (FAULT_KIND, T_ONSET, *fault_fields()), "actuator fault (eq. 15 ...)",
                   checks=(Check("side", lambda r: r["fault"]["kind"] != "hardover"
                                 or r["fault"]["side"] in (-1.0, 1.0),
                                 "must be -1 (lower limit) or 1 (upper limit)"),))  # fmt: skip


#: The design step: the design point where the flexible modes are linearised (h0, V0) and
#: the reference step (to h_c, V_c) that sizes the nominal ellipsoid E(Q) (eq. 33) and the
#: baseline's ellipsoids. A scenario may fly any other command inside the certified range.
DESIGN_STEP = (
    Field("h0", "float", "design point altitude (flexible modes linearised here)", unit="ft",
          lo=0.0, hi=2e5),
    Field("V0", "float", "design point velocity", unit="ft/s", lo=0.0, hi=2e4),
    Field("h_c", "float", "altitude of the reference step that sizes E(Q)", unit="ft",
          lo=0.0, hi=2e5, equation="eq. (33)"),
    Field("V_c", "float", "velocity of the reference step that sizes E(Q)", unit="ft/s",
          lo=0.0, hi=2e4, equation="eq. (33)"),
)  # fmt: skip

#: Top-level keys a scenario sets; everything else of a run spec comes from its design.
SCENARIO_KEYS = (
    "name", "description", "command", "fault", "uncertainty", "plant", "sensor_fault",
    "estimator", "duration", "variants",
)
#: Optional scenario sections a run spec holds only when the scenario sets them.
OPTIONAL_SECTIONS = ("plant", "sensor_fault", "estimator", "requirements")


def _law_sections() -> tuple:
    return tuple(
        cls.section
        for _, cls in (*NOMINAL_SOURCES.items(), *LAWS.items())
        if cls.section is not None
    )


def _design_items() -> tuple:
    """Entries of a design that a scenario does not change (validated in both specs)."""
    return (
        Field("design_model", "str", "LPV design model: CM (Case 1) or codesigned ECM "
              "(Case 2)", choices=("cm", "ecm"), equation="eq. (1-3) / (40)"),
        Field("vertices", "ints", "TP vertices of the design model (h, V)", lo=1, length=2,
              equation="eq. (11)"),
        Field("samples", "ints", "TP sampling grid over the envelope (h, V)", lo=4,
              length=2, default=(21, 21), equation="eq. (11)"),
        TS,
        PLANT_SUBSTEPS,
        Field("trim_grid", "ints", "trim map grid (h, V), bicubic interpolation", lo=4,
              length=2, default=(13, 13)),
        Section("notch", NOTCH, "notch filter on q", checks=(
            Check("omega_z", lambda r: r["notch"]["omega_z"] < math.pi / r["Ts"],
                  "must be below the Nyquist frequency pi/Ts"),
            Check("omega_p", lambda r: r["notch"]["omega_p"] < math.pi / r["Ts"],
                  "must be below the Nyquist frequency pi/Ts"),
        )),
        Section("disturbance", (
            Field("samples", "int", "samples bounding W", lo=10, default=300,
                  equation="eq. (13-19)"),
            Field("seed", "int", "seed of the W samples", lo=0, default=0),
            Field("margin", "float", "factor on the sampled W", lo=1.0, default=1.2),
            Field("constant", "str", "constant part of the parameter error: in W "
                  "(bounded, the paper) or left to the online estimate of tube_mpc "
                  "(estimated)", choices=("bounded", "estimated"), default="estimated",
                  equation="eq. (13)"),
        ), "disturbance set W by sampling"),
        Section("tube", (
            Field("lam", "floats", "contraction factors tried in the tube LMI", lo=0.0,
                  hi=1.0, lo_open=True, hi_open=True, default=(0.98, 0.99, 0.995),
                  equation="LMI (24)"),
            Field("tau", "float", "adjustable factor tau (1: eq. 36)", lo=0.0, hi=1.0,
                  lo_open=True, default=1.0, equation="eq. (53-54)"),
            Field("rho_min", "float", "smallest elevator effectiveness the tube covers "
                  "(the fault range of the design: every loss up to 1 - rho_min)", lo=0.0,
                  hi=1.0, lo_open=True, default=1.0, equation="eq. (15)"),
            Field("form", "str", "the tube the law runs on: 'vertices', Z over the TP "
                  "vertices for the sampled W (the paper), or 'eight_state', Z_8 along "
                  "the nominal on the eight states after h with |e_h| bounded by the "
                  "nominal's altitude reset, W_8 bounded over its own domain "
                  "(section eight_state)",
                  choices=TUBE_FORMS, default="vertices", equation="LMI (24)"),
            Field("filter_nominal_q", "bool", "law tube_mpc with the notch on: the "
                  "error's q is q' - notch(q_r + q_n) = notch(q - q_r - q_n), the loop "
                  "the design certifies in its own states (true), or q' - q_r - q_n as "
                  "in the paper (false: only the loop's stability is checked)",
                  default=False, equation="eq. (36), (38)"),
        ), "tube: F and Z"),
        Section("eight_state", EIGHT_STATE, "the eight-state tube along the nominal "
                "(tube.form eight_state): its vertices, nominal box and closure",
                when=_eight_state, when_text="tube.form is eight_state",
                checks=EIGHT_STATE_CHECKS),
        Section("certificate", (
            Field("schedules", "int", "scheduling points of the domain check of W: 0 "
                  "skips it, 1 the envelope centre, 3 centre and two opposite corners, "
                  "9 a 3 x 3 grid", lo=0, hi=9, default=3),
        ), "the tube certificate checked over its own domain",
            checks=(Check("schedules", lambda r: r["certificate"]["schedules"] in (0, 1, 3, 9),
                          "must be 0, 1, 3 or 9"),)),
        Section("nominal", (
            Field("lam", "float", "decay factor of (34')", lo=0.0, hi=1.0, lo_open=True,
                  hi_open=True, default=0.9995, equation="LMI (34)"),
            Field("level_max", "float", "governor bound on x_n' Q^-1 x_n", lo=0.0, hi=1.0,
                  lo_open=True, default=0.999),
        ), "nominal gain K and its ellipsoid"),
        *_law_sections(),
        estimate_design_section(),
    )  # fmt: skip


def _design_checks() -> tuple:
    return (
        Check("notch.enabled", lambda r: r["design_model"] != "ecm" or r["notch"]["enabled"],
              "must be true for design_model ecm"),
        Check("variants", lambda r: r["design_model"] != "ecm"
              or set(r["variants"]) <= {"tube_mpc"}, "an ECM design runs only 'tube_mpc'"),
        Check("tube.form", _eight_state_needs, "eight_state needs design_model cm "
              "and the loop it is closed for: mpc.nominal_model cm, mpc.h_reset "
              "true, mpc.est_tau > 0, 0 < mpc.att_max <= eight_state.attitude"),
    )  # fmt: skip


def _variants(what: str) -> Field:
    return Field("variants", "strs", what, choices=VARIANTS.names)


def _command_section() -> Section:
    return Section("command", COMMAND, "altitude and velocity command (sec. 5.1)", checks=(
        Check("t_ramp", lambda r: r["command"]["kind"] != "ramp"
              or r["command"]["t_ramp"] > 0.0, "must be > 0 for a ramp"),
    ))  # fmt: skip


def run_spec() -> Section:
    """The run spec: a design's entries with one scenario's (what the loop runs on).

    A run spec is never written by hand: `fahv.spec.scenario.load_scenario` forms
    it from a scenario file and the design it names, and validates it against this spec.
    """
    return Section(
        "",
        (
            Field("name", "str", "scenario name (run names)"),
            Field("description", "str", "what the scenario is", default=""),
            *_design_items(),
            DURATION,
            _command_section(),
            fault_section(),
            Section("uncertainty", UNCERTAINTY, "plant parameters p (1 + s_p scale rel_p)"),
            plant_section(),
            sensor_fault_section(),
            estimator_section(),
            requirements_section(),
            _variants("variants to run (law + notch setting)"),
        ),
        "run spec",
        checks=(
            Check("duration", lambda r: r["duration"] >= 10 * r["Ts"], "must be >= 10 Ts"),
            *_design_checks(),
        ),
    )


def design_spec() -> Section:
    """A design file (`offline_design/designs/<name>.yaml`): what `fahv design` certifies.

    The vehicle's envelope and parameter box (`uncertainty.scale`), the fault range
    (`tube.rho_min`), the design model, tube, nominal MPC, notch and baseline settings,
    the design step, and the variants whose offline parts it prepares. Nothing of a
    scenario (command, fault instance, vehicle draw, duration) enters it.
    """
    return Section(
        "",
        (
            Field("name", "str", "design name (its artefact folder)"),
            Field("description", "str", "what the design is and certifies", default=""),
            *_design_items(),
            Section("design_step", DESIGN_STEP, "design point and reference step"),
            Section(
                "uncertainty",
                (UNCERTAINTY[1],),
                "the parameter box the design covers: this fraction of the sec. 5.1 box",
            ),
            _variants("variants whose offline parts the design prepares"),
        ),
        "design file",
        checks=_design_checks(),
    )


def scenario_spec() -> Section:
    """A scenario file (`offline_design/scenarios/<name>.yaml`): one thing to fly on a design."""
    return Section(
        "",
        (
            Field("name", "str", "scenario name (run names)"),
            Field("description", "str", "what the scenario is", default=""),
            Field(
                "design",
                "str",
                "name of the design it runs on (offline_design/designs/<design>.yaml)",
            ),
            Field("vehicle", "str", "vehicle data file (YAML), relative to the scenario file; "
                  "empty: the packaged vehicle (--vehicle on the command line takes "
                  "precedence)", default=""),
            DURATION,
            _command_section(),
            fault_section(),
            Section(
                "uncertainty",
                UNCERTAINTY,
                "the simulated vehicle: plant parameters p (1 + s_p scale rel_p), s_p ~ U(-1, 1)",
                checks=(Check("s", lambda r: len(r["uncertainty"]["s"]) in (0, N_UNCERTAIN),
                              f"must be empty or hold {N_UNCERTAIN} values"),),
            ),
            plant_section(),
            sensor_fault_section(),
            estimator_section(),
            requirements_section(),
            _variants("variants to run (a subset of the design's; empty: the design's)"),
        ),
        "scenario file",
    )
