"""Offline design: a design file -> certified artefacts with their provenance.

The design is a list of stages (paper sec. 3-4, Algorithm 1), each reading and filling
one :class:`DesignState`:

1. :func:`model_stage`: the TP model of the design model (CM for Case 1, the codesigned
   ECM with the notch's states for Case 2, eq. 11), discretised; the flexible modes at
   the design point; the trim map;
2. :func:`disturbance_stage`: the disturbance set W by sampling (eq. 13-19);
3. :func:`vertex_tube_stage`: F and the invariant tube Z (LMI 24, eq. 25-28) over the
   healthy and faulty vertices (eq. 15) and the adjustable gains (eq. 48);
4. :func:`tube_form_stage`: the tube the law runs on, by ``tube.form``
   (:data:`fahv.design.tube_forms.TUBE_FORMS`);
5. :func:`tightening_stage`: the tightened inputs (eq. 30, eq. 53 with tau < 1) and the
   elevator loss they cover over the uncertainty box;
6. :func:`certificate_stage`: the form's certificate over its own domain;
7. :func:`nominal_stage`: the nominal gain K and ellipsoid E(Q) (LMI 33-35);
8. :func:`laws_stage`: the offline part of every law a variant uses (the nominal MPC's
   terminal check, the RMPC baseline's ellipsoids).

Every certificate is re-checked where it is made and printed with its margin (the lines
are in :mod:`fahv.certificate.report`); nothing is written unless all hold. What depends on a
scenario (its x0, its vehicle draw) is not designed here (:mod:`fahv.spec.scenario`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fahv.bounds.coverage import box_coverage
from fahv.bounds.disturbance import DEFAULT_DU_BOX, deviation_box, sample_disturbance
from fahv.bounds.vertices import fault_vertices, gain_vertices
from fahv.certificate.report import (
    coverage_line,
    disturbance_line,
    no_estimate_line,
    nominal_gain_line,
    tightening_line,
    tp_model_line,
    tube_lmi_line,
)
from fahv.config.spec import defaults_text
from fahv.control import LAWS, VARIANTS, variant_notch
from fahv.design.tube_forms import TUBE_FORMS
from fahv.errors import DesignError
from fahv.model.linearize import classify_modes, linearize
from fahv.model.notch import NotchFilter
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import IQ, Vehicle, load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.spec.artefacts import Design, provenance
from fahv.spec.context import DesignContext
from fahv.spec.schema import Case
from fahv.synthesis.feedback import design_tube, verify_tube
from fahv.synthesis.nominal import design_nominal, verify_nominal
from fahv.tube.feasibility import input_room
from fahv.version import __version__


def tube_notches(c: dict, omega_flex) -> dict[str, NotchFilter]:
    """The notch filters the case's tube variants run on the q feedback, by variant name.

    Parameters
    ----------
    c : dict
        Validated case data (``variants``, ``notch``).
    omega_flex : (2,) array_like
        Flexible mode frequencies [rad/s] (``mode2`` notches).

    Returns
    -------
    dict
        ``{variant: NotchFilter}`` for every variant whose law has a tube and whose
        notch is on (:func:`fahv.control.variant_notch`).
    """
    out = {}
    for name in c["variants"]:
        v = VARIANTS[name]
        nt = variant_notch(c["notch"], v.notch, omega_flex)
        if LAWS[v.law].has_tube and nt is not None:
            out[name] = NotchFilter(**nt)
    return out


def notch_checks(c: dict, notches: dict) -> tuple[dict, dict]:
    """Split the tube's notch variants into those certified and those checked for stability.

    A law that forms its error's q with the same filter on the nominal's q as on the
    measured one (``LAWS[law].filters_nominal_q`` with the case key
    ``tube.filter_nominal_q`` true) runs the loop :func:`fahv.tube.notch_loop.notch_tube`
    certifies in its own states, [e; chi]. Any other notch variant filters the measured q
    alone: its error also carries (notch - 1)(q_r + q_n), which no certificate covers, so
    only its stability is checked (:func:`fahv.tube.notch_loop.notch_loop`).

    Parameters
    ----------
    c : dict
        Validated case data (``tube.filter_nominal_q``).
    notches : dict
        ``{variant: NotchFilter}`` (:func:`tube_notches`).

    Returns
    -------
    certified, stable_only : dict, dict
        The two parts of ``notches``, in its order.
    """
    filtered = bool(c["tube"]["filter_nominal_q"])
    certified = {
        v: nf for v, nf in notches.items() if filtered and LAWS[VARIANTS[v].law].filters_nominal_q
    }
    return certified, {v: nf for v, nf in notches.items() if v not in certified}


def design_rho_f(case) -> float:
    """Smallest elevator effectiveness the tube is designed for (eq. 15): ``tube.rho_min``.

    The design covers every loss of effectiveness up to ``1 - rho_min``; a scenario's
    fault beyond it is reported by :func:`fahv.spec.scenario.uncertified`.
    """
    return float(case["tube"]["rho_min"])


def step_command(step: dict) -> dict:
    """The design step (``design_step``) as the step command the laws' offline parts see.

    The nominal ellipsoid E(Q) (eq. 33) and the baseline's ellipsoids are sized for this
    step; x0 is the trim at its start.
    """
    return {"kind": "step", "h0": step["h0"], "V0": step["V0"], "h_c": step["h_c"],
            "V_c": step["V_c"], "t_start": 0.0, "t_ramp": 0.0}  # fmt: skip


class DesignState:
    """What the stages of one design have made so far (unscaled units).

    Set at the start: ``case`` (the validated design file), ``c`` (its data), ``veh``,
    ``log``, ``progress``, ``clock`` (:meth:`stage`), and the empty ``arrays`` (what is
    stored). Each stage adds its results as attributes, documented in the stage that sets
    them (``tp``, ``disc``, ``W``, ``tube``, ``F``, ``N``, ``tightening``, ``u_lo``,
    ``u_hi``, ``coverage``, ``certificate``, ``nominal`` ...); ``tube_set`` is set by the
    eight-state form only.
    """

    def __init__(
        self, case: Case, veh: Vehicle, log: Callable[[str], None], progress=None, clock=None
    ) -> None:
        self.case, self.c, self.veh, self.log, self.progress = case, case.data, veh, log, progress
        self.clock = clock
        self.arrays: dict = {}
        self.tube_set = None

    def stage(self, name: str) -> None:
        """Tell the clock (if any) that stage ``name`` starts."""
        if self.clock is not None:
            self.clock.stage(name)


def model_stage(st: DesignState) -> None:
    """TP model (eq. 11) discretised at Ts, flexible modes at the design point, trim map."""
    c, veh = st.c, st.veh
    kind = c["design_model"]
    n = c["notch"]
    st.notch = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])
    model_notch = st.notch if kind == "ecm" else None
    (r_h, r_V), (n_h, n_V) = c["vertices"], c["samples"]
    if r_h > n_h or r_V > n_V:
        raise DesignError(f"vertices {c['vertices']} exceed the TP samples {c['samples']}")
    st.tp = build_tp_model(veh, kind, r_h, r_V, n_h, n_V, model_notch)
    if st.tp.n_vertices != r_h * r_V:
        raise DesignError(
            f"the design asks for {r_h * r_V} vertices, the TP model has {st.tp.n_vertices}: "
            "the sampled tensor does not have that rank"
        )
    st.disc = st.tp.discretize(c["Ts"])
    st.Dx, st.Du = st.tp.state_scale, st.tp.input_scale
    st.log(tp_model_line(kind, st.tp.n_vertices, c["Ts"]))
    st.cmd = step_command(c["design_step"])
    lin = linearize(veh, st.cmd["h0"], st.cmd["V0"], "cm")
    modes = {m.name: m.wn for m in classify_modes(lin.A, veh.params.omega_1, veh.params.omega_2)}
    st.omega_flex = np.array([modes["flexible 1"], modes["flexible 2"]])


def disturbance_stage(st: DesignState) -> None:
    """The disturbance set W by sampling (eq. 13-19) over the uncertainty box."""
    c, kind = st.c, st.c["design_model"]
    model_notch = st.notch if kind == "ecm" else None
    dev_box = deviation_box(model_notch, st.Dx[IQ])
    d = c["disturbance"]
    st.unc = {k: v * c["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    st.W = sample_disturbance(st.veh, st.tp, c["Ts"], st.unc, 1.0, dev_box, DEFAULT_DU_BOX,
                              d["samples"], d["seed"], d["margin"], progress=st.progress,
                              notch=model_notch, constant=d["constant"])  # fmt: skip
    st.log(disturbance_line(d, st.W))


def vertex_tube_stage(st: DesignState) -> None:
    """F and Z from LMI 24 over the fault vertices (eq. 15) and the gains tau F (eq. 48)."""
    c, veh = st.c, st.veh
    st.rho_f = design_rho_f(c)
    st.Af, st.Bf = fault_vertices(st.disc.A, st.disc.B, st.rho_f)
    st.room = input_room(veh)
    # row weights of the tube objective: the room of each row's binding side of the
    # asymmetric input set, with the elevator trim of the faulty vehicle
    st.room_f = input_room(veh, rho_f=st.rho_f)
    if np.any(st.room_f <= 0.0):
        raise DesignError(
            f"tube.rho_min: with rho_f = {st.rho_f} the trim input of the faulty vehicle "
            f"leaves the input limits somewhere in the envelope (room {st.room_f})"
        )
    st.tau = c["tube"]["tau"]
    # the adjustable law (eq. 48) feeds tau F e back: the LMI holds for every gain it uses
    At, Bt = gain_vertices(st.Af, st.Bf, st.tau)
    st.tube = design_tube(At, Bt, st.W.w_max, st.Dx, st.Du, st.room_f, tuple(c["tube"]["lam"]))
    st.eigs = verify_tube(At, Bt, st.tube, st.Dx, st.Du)
    st.log(tube_lmi_line(At.shape[0], st.rho_f, st.tau, st.eigs.min(), st.tube.lam))
    cmd = st.cmd
    veh.envelope.check(cmd["h0"], cmd["V0"])
    veh.envelope.check(cmd["h_c"], cmd["V_c"])
    kind, tg = c["design_model"], c["trim_grid"]
    st.tm = trim_map(veh, tg[0], tg[1], kind, st.notch if kind == "ecm" else None)
    st.x_start, _ = st.tm(cmd["h0"], cmd["V0"])
    st.x_end, _ = st.tm(cmd["h_c"], cmd["V_c"])


def tube_form_stage(st: DesignState) -> None:
    """The tube the law runs on, made by the design's tube form (:data:`TUBE_FORMS`)."""
    c = st.c
    # ECM: the filter is modelled; otherwise certified (notch_tube) or stability (notch_loop)
    found = tube_notches(c, st.omega_flex) if c["design_model"] != "ecm" else {}
    st.notches, st.stable_only = notch_checks(c, found)
    TUBE_FORMS[c["tube"]["form"]].design(st)


def tightening_stage(st: DesignState) -> None:
    """Tightened inputs (eq. 30; eq. 53 with tau < 1) and the loss they cover over the box."""
    veh, tau = st.veh, st.tau
    st.u_n_max = st.room - tau * st.tightening
    st.log(tightening_line(st.room, st.tightening, tau))
    if np.any(st.u_n_max <= 0.0):
        raise DesignError(
            f"tightened input set U minus F Z is empty (eq. 30): room {st.room}, "
            f"tightening {tau * st.tightening}"
        )
    st.u_lo = veh.limits.u_min + tau * st.tightening
    st.u_hi = veh.limits.u_max - tau * st.tightening
    cmd = st.cmd
    st.coverage = box_coverage(veh, st.unc, st.tm, st.u_lo, st.u_hi,
                               path=[(cmd["h0"], cmd["V0"]), (cmd["h_c"], cmd["V_c"])])  # fmt: skip
    st.log(coverage_line(st.coverage, st.rho_f))
    why = st.coverage.failing(st.rho_f, st.u_hi[1])
    if why:
        raise DesignError(f"tube.rho_min = {st.c['tube']['rho_min']}: {why}")


def certificate_stage(st: DesignState) -> None:
    """The tube form's certificate over its own domain; notes on variants it leaves out."""
    c = st.c
    st.certificate = TUBE_FORMS[c["tube"]["form"]].certify(st)
    if c["disturbance"]["constant"] == "estimated":
        for v in c["variants"]:
            law = LAWS[VARIANTS[v].law]
            if law.has_tube and not law.nominal.estimates_disturbance:
                st.log(no_estimate_line(v))


def nominal_stage(st: DesignState) -> None:
    """Nominal gain K and ellipsoid E(Q) (LMI 33-35) sized for the design step."""
    dvec = st.x_start - st.x_end
    Dn = st.Dx * np.maximum(1.0, np.abs(dvec) / st.Dx)  # step-sized scaling of the LMI
    st.nominal = design_nominal(st.disc.A, st.disc.B, dvec, st.u_n_max, Dn, st.u_n_max,
                                st.c["nominal"]["lam"])  # fmt: skip
    st.nominal_cert = verify_nominal(st.disc.A, st.disc.B, st.nominal, Dn, st.u_n_max)
    st.log(nominal_gain_line(st.nominal_cert, st.nominal.s))


def laws_stage(st: DesignState) -> None:
    """The stored arrays, then the offline part of every law a variant uses."""
    c, tp, tm = st.c, st.tp, st.tm
    st.arrays.update({
        "A": st.disc.A, "B": st.disc.B, "h_grid": tp.h_grid, "V_grid": tp.V_grid,
        "W_h": tp.W_h, "W_V": tp.W_V, "Dx": st.Dx, "Du": st.Du, "w_max": st.W.w_max,
        "F": st.F, "N": st.N, "K": st.nominal.K, "Q": st.nominal.Q, "u_room": st.room,
        "u_n_max": st.u_n_max,
        "u_lo": st.u_lo, "u_hi": st.u_hi,  # tightened absolute limits (eq. 30, asymmetric)
        "trim_h": tm.h_grid, "trim_V": tm.V_grid, "trim_x": tm.x_r, "trim_u": tm.u_r,
        "omega_flex": st.omega_flex,
        # largest trim attitude offset of a parameter-box corner from the nominal trim
        "att_trim_offset": np.array(st.coverage.alpha_offset_max),
        "x0": np.asarray(st.x_start[:9], float),  # the trim at the design point
    })  # fmt: skip
    ctx = DesignContext({**c, "command": st.cmd}, st.veh, st.arrays, st.log)
    laws = [LAWS[name] for name in dict.fromkeys(VARIANTS[v].law for v in c["variants"])]
    for part in (*dict.fromkeys(law.nominal for law in laws), *laws):  # nominal parts first
        st.arrays.update(part.design(ctx))


#: The stages of a design, in order.
STAGES = (model_stage, disturbance_stage, vertex_tube_stage, tube_form_stage,
          tightening_stage, certificate_stage, nominal_stage, laws_stage)  # fmt: skip


def summary_of(st: DesignState) -> dict:
    """The stored scalars of a finished design: provenance, W, tube, certificates."""
    case, c, tau = st.case, st.c, st.tau
    tube_set = st.tube_set
    return {
        "code_version": __version__,
        "provenance": provenance(case, st.veh),
        "defaults_used": {
            k: list(v) if isinstance(v, tuple) else v for k, v in case.defaults_used.items()
        },
        "n_vertices": int(st.tp.n_vertices),
        "W_parts": {k: v.tolist() for k, v in st.W.parts.items()},
        "W_dominant": st.W.dominant(),
        "tube": {
            "form": c["tube"]["form"],
            "lam": st.tube.lam if tube_set is None else tube_set.lam,
            "min_eig": float(st.eigs.min()),
            "tightening": (tau * st.tightening).tolist(),
            "z_box": np.sqrt(np.diag(st.N)).tolist(),
            "rho_f": st.rho_f,
            "row_room": st.room_f.tolist(),
            "loss_covered": st.coverage.summary(),
            "notch_in_loop": [loop.summary() for loop in st.notch_loops],
        },
        "certificate": st.certificate,
        "nominal": {**st.nominal_cert, "s": st.nominal.s, "lam": st.nominal.lam},
        "design_name": case.name,
        "design_step": dict(c["design_step"]),
        "uncertainty_scale": float(c["uncertainty"]["scale"]),
    }


def run_design(case: Case, vehicle=None, progress=None, log=print, clock=None) -> Design:
    """Run every stage of :data:`STAGES` on a design file; the certified design.

    Parameters
    ----------
    case : Case
        A validated design file (:func:`fahv.spec.schema.load_design_file`), or a whole
        case (a design's entries with a scenario's, :func:`fahv.spec.schema.case_spec`).
    vehicle : fahv.model.vehicle.Vehicle, optional
        The vehicle to design for; the packaged vehicle file by default.
    progress : callable, optional
        Iterable wrapper for long loops (tqdm).
    log : callable
        Receives one line per step and per certificate.
    clock : fahv.design.stage_clock.StageClock, optional
        Told the start of every stage (and of the tube form's parts): the progress
        lines and the stage times.

    Returns
    -------
    Design
        For a design file, its stored form (``case``: the design data). For a whole case,
        its design part (:func:`design_part`) designed with the case's command as design
        step, carrying the case and its scenario arrays
        (:func:`fahv.spec.scenario.scenario_design`), ready to run.

    Raises
    ------
    DesignError
        If an LMI is infeasible or a certificate fails (the message names which).
    """
    veh = load_vehicle() if vehicle is None else vehicle
    if "command" in case.data:  # a whole case: its design part, then its scenario
        from fahv.spec.scenario import scenario_design

        design = run_design(design_part(case), veh, progress, log, clock)
        return scenario_design(design, case, veh, None, log)
    if case.defaults_used:
        log("defaults used by the design file:\n" + defaults_text(case.defaults_used))
    st = DesignState(case, veh, log, progress, clock)
    for stage in STAGES:
        st.stage(stage.__name__.removesuffix("_stage").replace("_", " "))
        stage(st)
    design = Design(case.data, st.arrays, summary_of(st))
    design.summary["design_hash"] = design.content_hash()
    return design


def design_part(case: Case) -> Case:
    """The design file of a whole case: its entries less the scenario's, its command as step.

    Raises
    ------
    CaseError
        If the result does not validate as a design file.
    """
    from fahv.spec.schema import SCENARIO_KEYS, case_from_mapping, design_spec

    c = case.data
    data = {k: v for k, v in c.items() if k not in SCENARIO_KEYS}
    data.update(name=c["name"], description=c["description"], variants=list(c["variants"]))
    data["design_step"] = {k: c["command"][k] for k in ("h0", "V0", "h_c", "V_c")}
    data["uncertainty"] = {"scale": c["uncertainty"]["scale"]}
    return case_from_mapping(data, str(case.path), design_spec())
