"""Offline design of a case: case file -> certified artefacts with their provenance.

Steps (paper sec. 3-4, Algorithm 1): notch filter; TP model of the design model (CM
for Case 1, codesigned ECM for Case 2); disturbance set W (eq. 13-19); F and the
invariant tube Z (LMI 24, eq. 25-28) over the healthy and faulty vertices; tightened
inputs (eq. 30, with Z' = tau Z for the adjustable law, eq. 53); trim map; nominal
gain K (LMI 33-35); the offline part of every law a variant uses (e.g. the DM LPV model of the RMPC
baseline); the perturbed plant
parameters. Every certificate is re-checked; nothing is written unless all hold, and
the artefacts are written to a temporary folder renamed into place at the end.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fahv.config.spec import defaults_text
from fahv.control import LAWS, VARIANTS, variant_notch
from fahv.control.nominal_mpc import attitude_bounds, estimator_gains
from fahv.design.artefacts import Design, provenance, variant_gain_key
from fahv.design.case import Case
from fahv.design.certificate import certify_tube, notch_loop, notch_tube
from fahv.design.disturbance import (
    DEFAULT_DEV_BOX,
    DEFAULT_DU_BOX,
    deviation_box,
    sample_disturbance,
)
from fahv.design.eight_state import (
    certified_range,
    design_pair,
    input_rows,
    nominal_box,
    pair_report,
    state_rows,
)
from fahv.design.feasibility import box_coverage, fault_vertices, gain_vertices, input_room
from fahv.errors import DesignError
from fahv.model.linearize import classify_modes, linearize
from fahv.model.notch import NotchFilter
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import IQ, Vehicle, load_vehicle
from fahv.plant.faults import make_fault
from fahv.plant.uncertainty import PAPER_UNCERTAINTY, perturbed_params
from fahv.synthesis.feedback import design_tube, verify_tube
from fahv.synthesis.nominal import design_nominal, verify_nominal
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
    ``tube.filter_nominal_q`` true) runs the loop :func:`fahv.design.certificate.notch_tube`
    certifies in its own states, [e; chi]. Any other notch variant filters the measured q
    alone: its error also carries (notch - 1)(q_r + q_n), which no certificate covers, so
    only its stability is checked (:func:`fahv.design.certificate.notch_loop`).

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


def _notch(case: Case) -> NotchFilter:
    n = case["notch"]
    return NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])


@dataclass(frozen=True)
class DesignContext:
    """What a control law's offline part (:meth:`fahv.control.ControlLaw.design`) sees.

    Attributes
    ----------
    case : dict
        Validated case data.
    vehicle : fahv.model.vehicle.Vehicle
    arrays : dict
        Arrays designed so far (the TP model, W, F, Z, K, Q, trim map ...).
    log : callable
        Receives one line per step.
    """

    case: dict
    vehicle: Vehicle
    arrays: dict
    log: Callable[[str], None]


def design_rho_f(case) -> float:
    """Elevator effectiveness the tube of a case is designed for (eq. 15 with the fault).

    The smaller of the case fault's design effectiveness
    (:meth:`fahv.plant.faults.FaultKind.design_effectiveness`) and ``tube.rho_min``.
    """
    f = case["fault"]
    fault = make_fault(f["kind"], f["t_onset"], f)
    return float(min(fault.design_effectiveness(), case["tube"]["rho_min"]))


def run_design(case: Case, vehicle=None, progress=None, log=print) -> Design:
    """Compute and verify every artefact of ``case``.

    Parameters
    ----------
    case : Case
    vehicle : fahv.model.vehicle.Vehicle, optional
        The vehicle to design for; the packaged vehicle file by default.
    progress : callable, optional
        Iterable wrapper for long loops (tqdm).
    log : callable
        Receives one line per step and per certificate.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        If an LMI is infeasible or a certificate fails (the message names which).
    """
    veh = load_vehicle() if vehicle is None else vehicle
    if case.defaults_used:
        log("defaults used by the case file:\n" + defaults_text(case.defaults_used))
    c = case.data
    kind, Ts = c["design_model"], c["Ts"]
    notch = _notch(case)
    r_h, r_V = c["vertices"]
    n_h, n_V = c["samples"]
    if r_h > n_h or r_V > n_V:
        raise DesignError(f"vertices {c['vertices']} exceed the TP samples {c['samples']}")
    tp = build_tp_model(veh, kind, r_h, r_V, n_h, n_V, notch if kind == "ecm" else None)
    if tp.n_vertices != r_h * r_V:
        raise DesignError(
            f"case asks for {r_h * r_V} vertices, the TP model has {tp.n_vertices}: the "
            "sampled tensor does not have that rank"
        )
    disc = tp.discretize(Ts)
    Dx, Du = tp.state_scale, tp.input_scale
    log(f"TP model: {kind.upper()}, {tp.n_vertices} vertices, Ts = {Ts} s")
    lin = linearize(veh, c["command"]["h0"], c["command"]["V0"], "cm")
    modes = {m.name: m.wn for m in classify_modes(lin.A, veh.params.omega_1, veh.params.omega_2)}
    omega_flex = np.array([modes["flexible 1"], modes["flexible 2"]])
    dev_box = deviation_box(notch if kind == "ecm" else None, Dx[IQ])
    d = c["disturbance"]
    unc = {k: v * c["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    W = sample_disturbance(
        veh,
        tp,
        Ts,
        unc,
        1.0,
        dev_box,
        DEFAULT_DU_BOX,
        d["samples"],
        d["seed"],
        d["margin"],
        progress=progress,
        notch=notch if kind == "ecm" else None,
        constant=d["constant"],
    )
    log(
        f"W: {d['samples']} samples, margin {d['margin']}, constant part of the parameter "
        f"error {d['constant']}; dominant source per state: " + ", ".join(W.dominant())
    )
    rho_f = design_rho_f(c)
    Af, Bf = fault_vertices(disc.A, disc.B, rho_f)
    room = input_room(veh)
    # row weights of the tube objective: the room of each row's binding side of the
    # asymmetric input set, with the elevator trim of the faulty vehicle (docs)
    room_f = input_room(veh, rho_f=rho_f)
    if np.any(room_f <= 0.0):
        raise DesignError(
            f"tube.rho_min / fault: with rho_f = {rho_f} the trim input of the faulty vehicle "
            f"leaves the input limits somewhere in the envelope (room {room_f})"
        )
    tau = c["tube"]["tau"]
    # the adjustable law (eq. 48) feeds tau F e back: the LMI holds for every gain it uses
    At, Bt = gain_vertices(Af, Bf, tau)
    tube = design_tube(At, Bt, W.w_max, Dx, Du, room_f, tuple(c["tube"]["lam"]))
    eigs = verify_tube(At, Bt, tube, Dx, Du)
    log(
        f"certificate F, Z (LMI 24 + S-procedure, {At.shape[0]} vertices incl. rho_f = "
        f"{rho_f}{f' and the gains tau F, tau = {tau:g} (eq. 48)' if tau < 1 else ''}): min "
        f"eigenvalue {eigs.min():.3e} >= -1e-12 x the largest entry of each vertex matrix "
        f"(tolerance), lam = {tube.lam}  OK"
    )
    cmd = c["command"]
    veh.envelope.check(cmd["h0"], cmd["V0"])
    veh.envelope.check(cmd["h_c"], cmd["V_c"])
    tg = c["trim_grid"]
    tm = trim_map(veh, tg[0], tg[1], kind, notch if kind == "ecm" else None)
    x_start, _ = tm(cmd["h0"], cmd["V0"])
    x_end, _ = tm(cmd["h_c"], cmd["V_c"])
    F, N, tightening, pair = tube.F, tube.N, tube.tightening, None
    # ECM: the filter is modelled; otherwise certified (notch_tube) or stability (notch_loop)
    notches, stable_only = notch_checks(c, tube_notches(c, omega_flex) if kind != "ecm" else {})
    notch_loops = []
    if c["tube"]["form"] == "eight_state":  # the law runs on the eight-state tube
        cols = np.concatenate([tube.z_box, tube.tightening])  # the directions' column scale
        # the case check asks for an estimate; its gain along the elevator column, if any
        gamma, gamma_e = estimator_gains(Ts, c["mpc"]["est_tau"], c["mpc"]["est_tau_elevator"])
        estimate = (
            {}
            if gamma_e is None
            else {"gamma_e": gamma_e, "directions": disc.B[:, :, 1], "projection_scale": Dx}
        )
        hv_box = command_range(c, veh.envelope)  # before the design: a clear error first
        pair, es_nominal, es_box = design_pair(
            c, veh, tm, np.concatenate([Dx, Du]), W.w_max, cols, rho_f, room_f, log,
            gamma=gamma, notches=notches, stable_only=stable_only, **estimate,
        )  # fmt: skip
        for line in pair_report(pair, es_nominal, es_box):
            log(line)
        F, N, tightening = pair.F, pair.N, pair.tightening
    else:
        notch_loops = [notch_loop(Af, Bf, tau * F, nf, Ts, IQ, v) for v, nf in stable_only.items()]
        notch_loops += [notch_tube(Af, Bf, tau * F, tau**2 * N, W.w_max, nf, Ts, IQ, tube.lam, v)
                        for v, nf in notches.items()]  # fmt: skip
        for loop in notch_loops:
            log(loop.line())
    u_n_max = room - tau * tightening
    log(
        f"tightened inputs (eq. 30{', 53 with tau = ' + str(tau) if tau < 1 else ''}): "
        f"room {room[0]:.4f} / {np.degrees(room[1]):.3f} deg, tightening "
        f"{tau * tightening[0]:.4f} / {np.degrees(tau * tightening[1]):.3f} deg"
    )
    if np.any(u_n_max <= 0.0):
        raise DesignError(
            f"tightened input set U minus F Z is empty (eq. 30): room {room}, "
            f"tightening {tau * tightening}"
        )
    u_lo = veh.limits.u_min + tau * tightening
    u_hi = veh.limits.u_max - tau * tightening
    coverage = box_coverage(
        veh, unc, tm, u_lo, u_hi, path=[(cmd["h0"], cmd["V0"]), (cmd["h_c"], cmd["V_c"])]
    )
    log(
        f"largest elevator loss whose faulty trim fits the tightened inputs for every one of "
        f"the {coverage.corners} distinct corners of the parameter box (1024 corners; I_yy does "
        f"not enter a trim): {100 * coverage.loss_path:.1f} % on the case's path, "
        f"{100 * coverage.loss:.1f} % over the whole envelope ({coverage.points} grid points, "
        f"+{np.degrees(coverage.remainder):.4f} deg of elevator between them; trim elevator "
        f"monotone in h, V: {coverage.monotone[0]}, {coverage.monotone[1]}); worst: "
        f"{np.degrees(coverage.delta_e_max):.3f} deg at h = {coverage.worst_point[0]:.0f} ft, "
        f"V = {coverage.worst_point[1]:.1f} ft/s; design rho_f = {rho_f}"
    )
    why = coverage.failing(rho_f, u_hi[1])
    if why:
        raise DesignError(f"tube.rho_min = {c['tube']['rho_min']} / fault: {why}")
    if pair is not None:  # the nominal box less every corner's trim offset: the QP's rows
        off_lo, off_hi = coverage.trim_offsets()
        u_box = input_rows((off_lo, off_hi), es_nominal)
        log(
            f"nominal box inputs (applied input minus the nominal trim): the box corners' trims "
            f"lie at Phi {off_lo[0]:+.4f}..{off_hi[0]:+.4f}, delta_e {np.degrees(off_lo[1]):+.3f}"
            f"..{np.degrees(off_hi[1]):+.3f} deg (any loss or bias: the plant applies its own "
            f"trim); the box allows {es_nominal.lo[4]:+.3f}..{es_nominal.hi[4]:+.3f} and "
            f"{np.degrees(es_nominal.lo[5]):+.2f}..{np.degrees(es_nominal.hi[5]):+.2f} deg, so "
            f"the QP bounds the manoeuvre part K zeta + c of the nominal input to Phi "
            f"{u_box[0, 0]:+.4f}..{u_box[1, 0]:+.4f}, delta_e {np.degrees(u_box[0, 1]):+.3f}.."
            f"{np.degrees(u_box[1, 1]):+.3f} deg (mpc.u_box; a loss scales the applied part "
            "towards 0)"
        )
        log(
            f"nominal range (mpc.hv_box): h {hv_box[0, 0]:.0f}..{hv_box[1, 0]:.0f} ft, V "
            f"{hv_box[0, 1]:.2f}..{hv_box[1, 1]:.2f} ft/s: the QP keeps its set point and its "
            "predicted h, V in it (the pair's nominal box)"
        )
        x_box = state_rows(certified_range(es_box, pair.F8, pair.N8, pair.H))
        xd = np.degrees(x_box[:, :3])
        log(
            f"nominal state range (mpc.x_box): alpha {xd[0, 0]:+.3f}..{xd[1, 0]:+.3f} deg, theta "
            f"{xd[0, 1]:+.3f}..{xd[1, 1]:+.3f} deg, |q| <= {xd[1, 2]:.3f} deg/s, |eta_1|, "
            f"|eta_1_dot|, |eta_2|, |eta_2_dot| <= "
            + ", ".join(f"{v:.3f}" for v in x_box[1, 3:])
            + " from the trim at the nominal's own (h, V): the QP keeps its prediction in it "
            "(the range the certificate covers)"
        )
        certificate = pair.summary(es_nominal, es_box)  # W_8 over the pair's own domain
        # the parameter directions' column scale: with the summary, the pair's vertex data
        # can be rebuilt and its certificate re-checked independently (scripts/export_pair.py)
        certificate["col_scale"] = cols.tolist()
    else:
        cert_case = c
        if "mpc" in c:  # the domain of the certificate: the attitude rows the QP will use
            att = attitude_bounds(tube.N, c["mpc"]["att_max"])
            cert_case = {**c, "mpc": {**c["mpc"], "att_max": float(np.degrees(att.used.max()))}}
        certificate = certify_tube(
            cert_case,
            veh,
            tp,
            tm,
            Af,
            Bf,
            tube,
            tau,
            u_lo,
            u_hi,
            rho_f,
            Dx,
            DEFAULT_DEV_BOX,
            log,
            progress,
        )
    if d["constant"] == "estimated":
        for v in c["variants"]:
            law = LAWS[VARIANTS[v].law]
            if law.has_tube and not law.nominal.estimates_disturbance:
                log(
                    f"note: variant {v} has no disturbance estimate; W leaves the constant "
                    "part of the parameter error to one, so its tube certificate does not "
                    "cover it"
                )
    dvec = x_start - x_end
    Dn = Dx * np.maximum(1.0, np.abs(dvec) / Dx)  # command-sized scaling of the nominal LMI
    nominal = design_nominal(disc.A, disc.B, dvec, u_n_max, Dn, u_n_max, c["nominal"]["lam"])
    cert = verify_nominal(disc.A, disc.B, nominal, Dn, u_n_max)
    log(
        f"certificate K (LMI 33-35'): contraction {cert['contraction']:.6f} < 1, input "
        f"ratio {cert['input_ratio']:.4f} <= 1, LMI (34') min eigenvalue "
        f"{cert['lmi34_min_eig']:.2e} >= -{cert['lmi34_tol']:.2e} (tolerance: 1e-9 x the "
        f"largest entry of the block), fraction of the command in E(Q) s = {nominal.s:.3f}  OK"
    )
    arrays = {
        "A": disc.A,
        "B": disc.B,
        "h_grid": tp.h_grid,
        "V_grid": tp.V_grid,
        "W_h": tp.W_h,
        "W_V": tp.W_V,
        "Dx": Dx,
        "Du": Du,
        "w_max": W.w_max,
        "F": F,
        "N": N,
        "K": nominal.K,
        "Q": nominal.Q,
        "u_room": room,
        "u_n_max": u_n_max,
        # tightened absolute limits of the nominal input (eq. 30, asymmetric)
        "u_lo": u_lo,
        "u_hi": u_hi,
        "trim_h": tm.h_grid,
        "trim_V": tm.V_grid,
        "trim_x": tm.x_r,
        "trim_u": tm.u_r,
        "omega_flex": omega_flex,
    }
    if pair is not None:  # the QP's rows on the manoeuvre part of the input (mpc.u_box)
        arrays["u_box"] = u_box
        arrays["hv_box"] = hv_box
        arrays["x_box"] = x_box
        for v, F8v in pair.notch_gains.items():  # a gain designed for a variant's notch loop
            arrays[variant_gain_key(v)] = np.hstack([np.zeros((2, 1)), F8v])
    # largest trim attitude offset of a parameter-box corner from the nominal trim
    arrays["att_trim_offset"] = np.array(coverage.alpha_offset_max)
    arrays["x0"] = np.asarray(x_start[:9], float)  # plant initial state: trim at (h0, V0)
    ctx = DesignContext(c, veh, arrays, log)
    laws = [LAWS[name] for name in dict.fromkeys(VARIANTS[v].law for v in c["variants"])]
    for part in (*dict.fromkeys(law.nominal for law in laws), *laws):  # nominal parts first
        arrays.update(part.design(ctx))
    summary = {
        "code_version": __version__,
        "provenance": provenance(case, veh),
        "defaults_used": {
            k: list(v) if isinstance(v, tuple) else v for k, v in case.defaults_used.items()
        },
        "n_vertices": int(tp.n_vertices),
        "W_parts": {k: v.tolist() for k, v in W.parts.items()},
        "W_dominant": W.dominant(),
        "tube": {
            "form": c["tube"]["form"],
            "lam": tube.lam if pair is None else pair.lam,
            "min_eig": float(eigs.min()),
            "tightening": (tau * tightening).tolist(),
            "z_box": np.sqrt(np.diag(N)).tolist(),
            "rho_f": rho_f,
            "row_room": room_f.tolist(),
            "loss_covered": coverage.summary(),
            "notch_in_loop": [loop.summary() for loop in notch_loops],
        },
        "certificate": certificate,
        "nominal": {**cert, "s": nominal.s, "lam": nominal.lam},
        "plant_params": perturbed_params(veh, c["uncertainty"]["seed"], c["uncertainty"]["scale"]),
    }
    design = Design(c, arrays, summary)
    design.summary["design_hash"] = design.content_hash()
    return design


def command_range(case: dict, envelope) -> np.ndarray:
    """The eight-state tube's nominal h, V range, checked against the case's command.

    The pair is certified for a nominal inside its nominal box (the envelope less
    ``eight_state.h_margin`` / ``V_margin``, :func:`fahv.design.eight_state.nominal_box`);
    the QP keeps its set point and prediction in that range (``mpc.hv_box``).

    Parameters
    ----------
    case : dict
        The validated case (its ``eight_state`` and ``command`` sections).
    envelope : fahv.model.vehicle.Envelope

    Returns
    -------
    (2, 2) ndarray
        [[h lo, V lo], [h hi, V hi]] [ft, ft/s].

    Raises
    ------
    DesignError
        If the initial point or the command lies outside it (names which and the range).
    """
    nominal, _ = nominal_box(case["eight_state"], envelope)
    hv_box = np.array([nominal.lo[:2], nominal.hi[:2]])
    cmd = case["command"]
    for what, h, V in (("initial point", cmd["h0"], cmd["V0"]),
                       ("command", cmd["h_c"], cmd["V_c"])):  # fmt: skip
        if not (hv_box[0, 0] <= h <= hv_box[1, 0] and hv_box[0, 1] <= V <= hv_box[1, 1]):
            raise DesignError(
                f"command: the {what} ({h} ft, {V} ft/s) lies outside the nominal range the "
                f"tube is certified for, h {hv_box[0, 0]:.0f}..{hv_box[1, 0]:.0f} ft, V "
                f"{hv_box[0, 1]:.2f}..{hv_box[1, 1]:.2f} ft/s (the envelope less "
                "eight_state.h_margin / V_margin)"
            )
    return hv_box
