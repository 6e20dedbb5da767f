"""The stages of a design, in the paper's order: each a function of the records before it.

Every stage takes the validated design data (`spec`), the vehicle and the frozen
records of the stages it needs (`fahv.design.results`), and returns its own record
with the certificate lines it prints:

1. `model_stage` (sec. 3.1, eq. 11): the TP model of the design model,
   discretised; the flexible modes at the design point; the trim map;
2. `disturbance_stage` (eq. 13-19): the disturbance set W by sampling;
3. `vertex_tube_stage` (LMI 24-28): F and Z over the healthy and faulty vertices
   (eq. 15) and the adjustable gains (eq. 48);
4. `tube_form_stage`: the tube the law runs on, by `tube.form`
   (`fahv.design.tube_forms.TUBE_FORMS`);
5. `tightening_stage` (eq. 30, 53): the tightened inputs and the elevator loss
   they cover over the parameter box;
6. `nominal_stage` (eq. 32-35): the nominal gain K and ellipsoid E(Q);
7. `certificate_stage`: the form's certificate over its own domain;
8. `laws_stage`: the stored arrays and the offline part of every law a variant
   uses (the nominal MPC's terminal check, the RMPC baseline's ellipsoids).

A law's offline part that reads only the model (the RMPC baseline's) is started by
`early_laws_stage` right after stage 1 on the design's Dask cluster, and collected
by `laws_stage`: it runs on a worker while this process makes the tube.

`fahv.design.pipeline.run_design` calls them top to bottom.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fahv.bounds.coverage import loss_coverage
from fahv.bounds.disturbance import INPUT_DEVIATIONS, sample_disturbance, state_deviations
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
from fahv.cluster import active_client
from fahv.control import LAWS, VARIANTS, variant_notch
from fahv.design.results import (
    DesignModel,
    Disturbance,
    EarlyLaws,
    FormCertificate,
    FormTube,
    Nominal,
    NotchVariants,
    Tightening,
    VertexTube,
)
from fahv.design.tube_forms import TUBE_FORMS
from fahv.errors import DesignError
from fahv.model.linearize import classify_modes, linearize
from fahv.model.notch import NotchFilter
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import IQ, Vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.spec.context import DesignContext
from fahv.synthesis.feedback import design_tube, verify_tube
from fahv.synthesis.nominal import design_nominal, verify_nominal
from fahv.tube.feasibility import input_room

Log = Callable[[str], None]


def step_command(step: dict) -> dict:
    """The design step (`design_step`) as the step command the laws' offline parts see.

    The nominal ellipsoid E(Q) (eq. 33) and the baseline's ellipsoids are sized for this
    step; x0 is the trim at its start.
    """
    return {"kind": "step", "h0": step["h0"], "V0": step["V0"], "h_c": step["h_c"],
            "V_c": step["V_c"], "t_start": 0.0, "t_ramp": 0.0}  # fmt: skip


def design_rho_f(spec) -> float:
    """Smallest elevator effectiveness the tube is designed for (eq. 15): `tube.rho_min`.

    The design covers every loss of effectiveness up to `1 - rho_min`; a scenario's
    fault beyond it is reported by `fahv.spec.scenario.uncertified`.
    """
    return float(spec["tube"]["rho_min"])


def model_stage(spec: dict, vehicle: Vehicle) -> DesignModel:
    """TP model (eq. 11) discretised at Ts, flexible modes at the design point, trim map.

    Raises
    ------
    DesignError
        If the vertices exceed the TP samples or the sampled tensor lacks their rank.
    EnvelopeError
        If the design step leaves the flight envelope.
    """
    kind, n = spec["design_model"], spec["notch"]
    notch = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])
    model_notch = notch if kind == "ecm" else None
    (r_h, r_V), (n_h, n_V) = spec["vertices"], spec["samples"]
    if r_h > n_h or r_V > n_V:
        raise DesignError(f"vertices {spec['vertices']} exceed the TP samples {spec['samples']}")
    tp = build_tp_model(vehicle, kind, r_h, r_V, n_h, n_V, model_notch)
    if tp.n_vertices != r_h * r_V:
        raise DesignError(
            f"the design asks for {r_h * r_V} vertices, the TP model has {tp.n_vertices}: "
            "the sampled tensor does not have that rank"
        )
    disc = tp.discretize(spec["Ts"])
    step = step_command(spec["design_step"])
    lin = linearize(vehicle, step["h0"], step["V0"], "cm")
    p = vehicle.params
    modes = {m.name: m.wn for m in classify_modes(lin.A, p.omega_1, p.omega_2)}
    omega_flex = np.array([modes["flexible 1"], modes["flexible 2"]])
    vehicle.envelope.check(step["h0"], step["V0"])
    vehicle.envelope.check(step["h_c"], step["V_c"])
    tg = spec["trim_grid"]
    tm = trim_map(vehicle, tg[0], tg[1], kind, model_notch)
    x_start, _ = tm(step["h0"], step["V0"])
    x_end, _ = tm(step["h_c"], step["V_c"])
    return DesignModel(notch, model_notch, tp, disc, tp.state_scale, tp.input_scale, step,
                       omega_flex, tm, x_start, x_end,
                       (tp_model_line(kind, tp.n_vertices, spec["Ts"]),))  # fmt: skip


def disturbance_stage(spec: dict, vehicle: Vehicle, model: DesignModel,
                      progress=None) -> Disturbance:  # fmt: skip
    """The disturbance set W by sampling (eq. 13-19) over the parameter box."""
    dx_half = state_deviations(model.model_notch, model.Dx[IQ])
    d = spec["disturbance"]
    unc = {k: v * spec["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    W = sample_disturbance(vehicle, model.tp, spec["Ts"], unc, 1.0, dx_half, INPUT_DEVIATIONS,
                           d["samples"], d["seed"], d["margin"], progress=progress,
                           notch=model.model_notch, constant=d["constant"])  # fmt: skip
    return Disturbance(unc, W, (disturbance_line(d, W),))


def vertex_tube_stage(spec: dict, vehicle: Vehicle, model: DesignModel,
                      dist: Disturbance) -> VertexTube:  # fmt: skip
    """F and Z from LMI 24 over the fault vertices (eq. 15) and the gains tau F (eq. 48).

    Raises
    ------
    DesignError
        If the faulty vehicle's trim input leaves the input limits, or the LMI fails.
    """
    rho_f = design_rho_f(spec)
    Af, Bf = fault_vertices(model.disc.A, model.disc.B, rho_f)
    room = input_room(vehicle)
    # row weights of the tube objective: the room of each row's binding side of the
    # asymmetric input set, with the elevator trim of the faulty vehicle
    room_f = input_room(vehicle, rho_f=rho_f)
    if np.any(room_f <= 0.0):
        raise DesignError(
            f"tube.rho_min: with rho_f = {rho_f} the trim input of the faulty vehicle "
            f"leaves the input limits somewhere in the envelope (room {room_f})"
        )
    tau = spec["tube"]["tau"]
    # the adjustable law (eq. 48) feeds tau F e back: the LMI holds for every gain it uses
    At, Bt = gain_vertices(Af, Bf, tau)
    tube = design_tube(At, Bt, dist.W.w_max, model.Dx, model.Du, room_f,
                       tuple(spec["tube"]["lam"]))  # fmt: skip
    eigs = verify_tube(At, Bt, tube, model.Dx, model.Du)
    line = tube_lmi_line(At.shape[0], rho_f, tau, eigs.min(), tube.lam)
    return VertexTube(rho_f, Af, Bf, room, room_f, tau, tube, eigs, (line,))


def tube_notches(spec: dict, omega_flex) -> dict[str, NotchFilter]:
    """The notch filters the design's tube variants run on the q feedback, by variant name.

    Parameters
    ----------
    spec : dict
        Validated design data (`variants`, `notch`).
    omega_flex : (2,) array_like
        Flexible mode frequencies [rad/s] (`mode2` notches).

    Returns
    -------
    dict
        `{variant: NotchFilter}` for every variant whose law has a tube and whose
        notch is on (`fahv.control.variant_notch`).
    """
    out = {}
    for name in spec["variants"]:
        v = VARIANTS[name]
        nt = variant_notch(spec["notch"], v.notch, omega_flex)
        if LAWS[v.law].has_tube and nt is not None:
            out[name] = NotchFilter(**nt)
    return out


def notch_checks(spec: dict, notches: dict) -> NotchVariants:
    """Split the tube's notch variants into those certified and those checked for stability.

    A law that forms its error's q with the same filter on the nominal's q as on the
    measured one (`LAWS[law].filters_nominal_q` with the design key
    `tube.filter_nominal_q` true) runs the loop `fahv.tube.notch_loop.notch_tube`
    certifies in its own states, [e; chi]. Any other notch variant filters the measured q
    alone: its error also carries (notch - 1)(q_r + q_n), which no certificate covers, so
    only its stability is checked (`fahv.tube.notch_loop.notch_loop`).

    Parameters
    ----------
    spec : dict
        Validated design data (`tube.filter_nominal_q`).
    notches : dict
        `{variant: NotchFilter}` (`tube_notches`).

    Returns
    -------
    NotchVariants
        The two parts of `notches`, in its order.
    """
    filtered = bool(spec["tube"]["filter_nominal_q"])
    certified = {
        v: nf for v, nf in notches.items() if filtered and LAWS[VARIANTS[v].law].filters_nominal_q
    }
    return NotchVariants(certified, {v: nf for v, nf in notches.items() if v not in certified})


def tube_form_stage(spec: dict, vehicle: Vehicle, model: DesignModel, dist: Disturbance,
                    vertex: VertexTube, log: Log, tell: Log,
                    previous=None) -> FormTube:  # fmt: skip
    """The tube the law runs on, made by the design's tube form (`TUBE_FORMS`).

    `log` receives the progress lines of the form's long computations; `tell` is told
    the start of each of its parts (the stage clock); `previous`, the arrays of an
    earlier design of the file, is where the form's LMIs start
    (`fahv.design.tube_forms.TubeForm.design`).
    """
    # ECM: the filter is modelled; otherwise certified (notch_tube) or stability (notch_loop)
    found = tube_notches(spec, model.omega_flex) if spec["design_model"] != "ecm" else {}
    form = TUBE_FORMS[spec["tube"]["form"]]
    return form.design(spec, vehicle, model, dist, vertex, notch_checks(spec, found), log, tell,
                       previous)  # fmt: skip


def tightening_stage(spec: dict, vehicle: Vehicle, model: DesignModel, dist: Disturbance,
                     vertex: VertexTube, tube: FormTube) -> Tightening:  # fmt: skip
    """Tightened inputs (eq. 30; eq. 53 with tau < 1) and the loss they cover over the box.

    Raises
    ------
    DesignError
        If the tightened input set is empty, or the fault range's loss is not covered
        over the parameter box.
    """
    tau, room = vertex.tau, vertex.room
    u_n_max = room - tau * tube.tightening
    if np.any(u_n_max <= 0.0):
        raise DesignError(
            f"tightened input set U minus F Z is empty (eq. 30): room {room}, "
            f"tightening {tau * tube.tightening}"
        )
    u_lo = vehicle.limits.u_min + tau * tube.tightening
    u_hi = vehicle.limits.u_max - tau * tube.tightening
    step = model.step
    path = [(step["h0"], step["V0"]), (step["h_c"], step["V_c"])]
    coverage = loss_coverage(vehicle, dist.uncertainty, model.trim, u_lo, u_hi, path=path)
    why = coverage.failing(vertex.rho_f, u_hi[1])
    if why:
        raise DesignError(f"tube.rho_min = {spec['tube']['rho_min']}: {why}")
    lines = (tightening_line(room, tube.tightening, tau), coverage_line(coverage, vertex.rho_f))
    return Tightening(u_n_max, u_lo, u_hi, coverage, lines)


def nominal_stage(spec: dict, model: DesignModel, tightening: Tightening) -> Nominal:
    """Nominal gain K and ellipsoid E(Q) (LMI 32-35) sized for the design step."""
    dvec = model.x_start - model.x_end
    Dn = model.Dx * np.maximum(1.0, np.abs(dvec) / model.Dx)  # step-sized scaling of the LMI
    u_n_max, disc = tightening.u_n_max, model.disc
    nominal = design_nominal(disc.A, disc.B, dvec, u_n_max, Dn, u_n_max, spec["nominal"]["lam"])
    cert = verify_nominal(disc.A, disc.B, nominal, Dn, u_n_max)
    return Nominal(nominal, cert, (nominal_gain_line(cert, nominal.s),))


def certificate_stage(spec: dict, vehicle: Vehicle, model: DesignModel, vertex: VertexTube,
                      tube: FormTube, tightening: Tightening,
                      progress=None) -> FormCertificate:  # fmt: skip
    """The tube form's certificate over its own domain; notes on variants it leaves out."""
    form = TUBE_FORMS[spec["tube"]["form"]]
    cert = form.certify(spec, vehicle, model, vertex, tube, tightening, progress)
    notes = ()
    if spec["disturbance"]["constant"] == "estimated":
        for v in spec["variants"]:
            law = LAWS[VARIANTS[v].law]
            if law.has_tube and not law.nominal.estimates_disturbance:
                notes += (no_estimate_line(v),)
    return FormCertificate(cert.summary, cert.arrays, cert.lines + notes)


def model_arrays(model: DesignModel, vehicle: Vehicle) -> dict[str, np.ndarray]:
    """The arrays an offline part with `fahv.control.ControlLaw.model_only` reads.

    Returns
    -------
    dict
        `trim_h` (n_h,) [ft], `trim_V` (n_V,) [ft/s], `trim_x` (n_h, n_V, n),
        `trim_u` (n_h, n_V, 2): the trim map; `x0` (9,): the trim at the design
        point; `u_room` (2,): the input room (`fahv.tube.feasibility.input_room`).
    """
    tm = model.trim
    return {"trim_h": tm.h_grid, "trim_V": tm.V_grid, "trim_x": tm.x_r, "trim_u": tm.u_r,
            "x0": np.asarray(model.x_start[:9], float),  # the trim at the design point
            "u_room": input_room(vehicle)}  # fmt: skip


def early_laws_stage(spec: dict, vehicle: Vehicle, model: DesignModel,
                     previous=None) -> EarlyLaws:  # fmt: skip
    """Start the offline parts that read only the model on the design's Dask cluster.

    The offline part of a law with `fahv.control.ControlLaw.model_only` (the
    RMPC baseline's ellipsoids) depends on the model stage alone: with an active Dask
    client (`fahv design` starts one) it is submitted as soon as the model is made
    and runs on a worker while this process makes the tube; `laws_stage` takes
    its result. Without a client nothing starts here and `laws_stage` computes
    every part in order.

    Returns
    -------
    EarlyLaws
        `{law name: distributed.Future of (arrays, lines)}`, empty without a client.
    """
    client = active_client()
    if client is None:
        return EarlyLaws({})
    ctx_spec = {**spec, "command": model.step}
    arrays = model_arrays(model, vehicle)
    names = dict.fromkeys(VARIANTS[v].law for v in spec["variants"])
    return EarlyLaws({
        name: client.submit(offline_part, LAWS[name], ctx_spec, vehicle, arrays, previous,
                            pure=False, key=f"offline-{name}")  # fmt: skip
        for name in names if LAWS[name].model_only
    })  # fmt: skip


def offline_part(part, spec: dict, vehicle: Vehicle, arrays: dict,
                 previous=None) -> tuple[dict, list[str]]:  # fmt: skip
    """An offline part (`fahv.control.ControlLaw.design`) with its log lines.

    Parameters
    ----------
    part : type
        A registered law (`fahv.control.LAWS`) or nominal part class.
    spec : dict
        The validated design data with its `command` (a run spec's data).
    vehicle : Vehicle
    arrays : dict
        The arrays the part reads.
    previous : Mapping[str, ndarray], optional
        An earlier design's arrays, where the part's solves start.

    Returns
    -------
    (dict, list of str)
        The part's arrays and the lines it logged, in order.

    Raises
    ------
    DesignError
        As the law's offline part.
    """
    lines: list[str] = []
    ctx = DesignContext(spec, vehicle, dict(arrays), lines.append, previous)
    return part.design(ctx), lines


def laws_stage(spec: dict, vehicle: Vehicle, model: DesignModel, dist: Disturbance,
               vertex: VertexTube, tube: FormTube, tightening: Tightening, nominal: Nominal,
               cert: FormCertificate, log: Log, previous=None,
               early: EarlyLaws | None = None) -> dict:  # fmt: skip
    """The stored arrays, then the offline part of every law a variant uses.

    Each law's offline part (`fahv.control.ControlLaw.design`) sees the arrays made
    so far, the nominal parts' first, and adds its own; `previous`, the arrays of an
    earlier design of the file, is where its solves may start
    (`fahv.spec.context.DesignContext`). A part started early
    (`early_laws_stage`) is collected here, its lines logged in the same place.

    Returns
    -------
    dict
        `{name: array}`: what `design.npz` stores (`fahv.spec.artefacts.Design`).

    Raises
    ------
    DesignError
        If a law's offline part fails (the message names which).
    """
    tp, t = model.tp, tightening
    arrays = dict(cert.arrays)
    arrays.update({
        "A": model.disc.A, "B": model.disc.B, "h_grid": tp.h_grid, "V_grid": tp.V_grid,
        "W_h": tp.W_h, "W_V": tp.W_V, "Dx": model.Dx, "Du": model.Du, "w_max": dist.W.w_max,
        "F": tube.F, "N": tube.N, "K": nominal.design.K, "Q": nominal.design.Q,
        "u_room": vertex.room, "u_n_max": t.u_n_max,
        "u_lo": t.u_lo, "u_hi": t.u_hi,  # tightened absolute limits (eq. 30, asymmetric)
        "omega_flex": model.omega_flex,
        # largest trim attitude offset of a parameter-box corner from the nominal trim
        "att_trim_offset": np.array(t.coverage.alpha_offset_max),
        **{k: v for k, v in model_arrays(model, vehicle).items() if k != "u_room"},
    })  # fmt: skip
    started = {} if early is None else early.parts
    laws = [LAWS[name] for name in dict.fromkeys(VARIANTS[v].law for v in spec["variants"])]
    for part in (*dict.fromkeys(law.nominal for law in laws), *laws):  # nominal parts first
        if part in laws and part.name in started:
            made, lines = started[part.name].result()
        else:
            made, lines = offline_part(part, {**spec, "command": model.step}, vehicle, arrays,
                                       previous)  # fmt: skip
        for line in lines:
            log(line)
        arrays.update(made)
    return arrays
