"""The certificate lines a design prints, each with its margin and verdict: formatting only.

Every function here formats a result computed elsewhere and computes nothing; no
computation imports this module (the design's stages call it, an import-linter contract
holds it). The eight-state tube set: `tube_set_lines` (with `range_line`,
`onset_lines` and the notch loops' lines). The paper's vertex tube checked over its
domain: `vertex_certificate_lines`. The stages' own lines follow. The two lines the
tube's computations print while they run (a closure iteration, a notch loop's verdict)
are `fahv.tube.lines`.
"""

from __future__ import annotations

import numpy as np

from fahv.bounds.domain import SchedulingBox
from fahv.tube.lines import join as _join
from fahv.tube.lines import notch_loop_line
from fahv.tube.tube_set import ASSUMPTIONS, EIGHT_STATES


def range_line(cert: SchedulingBox, nominal: SchedulingBox) -> str:
    """The line of the certified nominal range (`fahv.bounds.domain.certified_range`)."""
    deg = np.degrees
    o = cert.other_half
    return (
        f"the certificate covers a nominal anywhere in the scheduling box less the tube: h "
        f"{cert.lo[0]:.0f}..{cert.hi[0]:.0f} ft, V {cert.lo[1]:.2f}..{cert.hi[1]:.2f} ft/s, "
        f"alpha {deg(cert.lo[2]):+.3f}..{deg(cert.hi[2]):+.3f} deg and theta "
        f"{deg(cert.lo[3]):+.3f}..{deg(cert.hi[3]):+.3f} deg from the trim at its own (h, V), "
        f"applied Phi {cert.lo[4]:+.4f}..{cert.hi[4]:+.4f} and delta_e "
        f"{deg(cert.lo[5]):+.3f}..{deg(cert.hi[5]):+.3f} deg from the trim's, |q| <= "
        f"{deg(o[0]):.3f} deg/s, |eta_1|, |eta_1_dot|, |eta_2|, |eta_2_dot| <= {o[1]:.3f}, "
        f"{o[2]:.3f}, {o[3]:.3f}, {o[4]:.3f} from the trim's (the design's nominal box, "
        f"e.g. alpha +/-{deg(nominal.hi[2]):.3f} deg, is the part the QP's rows keep)"
    )


def tube_set_lines(tube_set, nominal: SchedulingBox, box: SchedulingBox) -> list[str]:
    """The certificate lines of a closed tube set, each with its margin (the design log).

    Parameters
    ----------
    tube_set : fahv.tube.tube_set.TubeSet
    nominal, box : SchedulingBox
        The nominal box and the scheduling box it was closed over.

    Returns
    -------
    list of str
        W_8's bound, the closure, the altitude bound, the box's reach, the certified
        range, Z_8's supports, the assumptions, then the onset lines and the notch loops.
    """
    reach, where = tube_set.reach(nominal, box)
    sz = np.sqrt(np.diag(tube_set.N_8))
    t = tube_set.tightening
    return [
        "W_8 bounds the one-step disturbance over its domain (the nominal box, the product "
        "set |e_h| <= H x Z_8, every corner of the parameter box, rho_f in [rho_min, 1]): "
        f"slack per row (V ... eta_2_dot) {_join(tube_set.slack, '.3f')}, smallest "
        f"{tube_set.slack.min():.3f}  OK",
        f"closed: Z_8 RPI for W_8, exact worst one-step level {tube_set.level:.6f} <= 1 "
        f"(margin {1.0 - tube_set.level:.2e}), lam = {tube_set.lam}  OK",
        f"altitude: |e_h| <= H = {tube_set.H:.3f} ft by the reset every {tube_set.moves} "
        f"steps (step {tube_set.step:.4f} ft, w_h {tube_set.w_h:.4f} ft)",
        f"scheduling box holds the nominal box plus the tube: smallest reach "
        f"{reach:.2f} x the tube's support ({where})  OK",
        range_line(tube_set.certified_range(box), nominal),
        f"Z_8 supports: V {sz[0]:.3f} ft/s, alpha {np.degrees(sz[1]):.4f} deg, theta "
        f"{np.degrees(sz[2]):.4f} deg, q {np.degrees(sz[3]):.4f} deg/s; tightening "
        f"{t[0]:.4f} / {np.degrees(t[1]):.3f} deg",
        "assumed, not certified: " + "; ".join(ASSUMPTIONS),
        *([] if tube_set.onset is None else onset_lines(tube_set.onset)),
        *(notch_loop_line(loop) for loop in tube_set.notch_loops),
    ]


def onset_lines(onset) -> list[str]:
    """The design log's lines of an onset bound (`fahv.onset.bound.OnsetBound`).

    The level bound at the design's loss with its verdict, the largest certified losses,
    the first jump state by state and, with a lower bound, `witness_line`.
    """
    ok = onset.peak <= 1.0
    gains = f"estimate gain {onset.gamma:.3f} per step"
    if onset.gamma_e > 0.0:
        gains += (
            f", {onset.gamma_e:.3f} along the elevator column (the jump's share along it "
            f"{onset.jump_elevator:.3f}, the rest {onset.jump_rest:.3f} x Z_8)"
        )
    share = ", ".join(f"{n} {v:+.3f}" for n, v in zip(EIGHT_STATES, onset.jump_share, strict=True))
    return [
        f"onset of a {100 * onset.loss:.1f} % loss (from the error at its steady level "
        f"{onset.level0:.3f} (c Z_8, c = {onset.steady:.3f}; the ellipsoid RPI for the bound "
        f"itself lies in {onset.steady_shaped:.3f} Z_8), {gains}): first jump "
        f"{onset.jump:.3f} x Z_8 at the scheduling box's worst point (interior samples "
        f"{onset.interior_ratio:.3f} of the corners'), closed-loop contraction "
        f"{onset.contraction:.5f} per step, level bound {onset.peak:.3f} "
        + ("<= 1  OK" if ok else "> 1: NOT certified"),
        f"largest loss whose onset keeps e in Z_8: {100 * onset.certified_loss:.2f} % with "
        f"the design's estimate, {100 * onset.certified_loss_one_step:.2f} % with an estimate "
        "that knows the whole loss one step after it acts (the first step alone, which no "
        "estimate can remove)",
        f"the first jump state by state, x Z_8's support: {share}; its Z_8 norm without the "
        f"bending modes {onset.jump_rigid_q:.3f}, without q and them (V, alpha, theta alone) "
        f"{onset.jump_rigid:.3f}",
    ] + ([] if onset.witness is None else [witness_line(onset)])


def witness_line(onset) -> str:
    """The design log's line of the onset's lower bound (requires `onset.witness`)."""
    w = onset.witness
    refuted = w.level_any_column > 1.0
    return (
        f"onset lower bound (one vertex held, w inside the bound for {w.pre_steps} steps, "
        f"a jump sample, the estimate's most favourable elevator direction; re-simulated): "
        f"level {w.level:.3f} at the {100 * onset.loss:.1f} % loss, {w.step} steps after "
        f"the onset (its onset part {w.pulse:.3f}; whichever column the estimate uses, "
        f"{w.level_any_column:.3f}) "
        + ("> 1: no analysis on the tube set's assumptions certifies this loss; the smallest "
           f"loss so refuted {100 * onset.ceiling:.2f} % (certified "
           f"{100 * onset.certified_loss:.2f} %)" if refuted else
           "<= 1: not refuted")
    )  # fmt: skip


def rpi_check_line(level: float, n_vertices: int, n_corners: int, growth: float,
                   tau: float) -> str:  # fmt: skip
    """The vertex tube's exact RPI check (`fahv.synthesis.rpi_level.worst_level`).

    Parameters
    ----------
    level : float
        The worst one-step level.
    n_vertices, n_corners : int
        Vertices (the gains tau' F included) and corners of W checked.
    growth : float
        The factor W may grow by (`fahv.synthesis.rpi_level.rpi_margin`).
    tau : float
        Adjustable factor (eq. 48).
    """
    gains = f" with the gains tau' F, tau' in [{tau:g}, 1]" if tau < 1 else ""
    return (
        f"RPI check (exact): worst one-step level over {n_vertices} vertices{gains} x "
        f"{n_corners} corners of W and all of Z = {level:.5f} (<= 1 required; margin "
        f"{1 - level:.2e}); the tube stays RPI for W scaled by up to {growth:.3f}x"
        + ("  OK" if level <= 1.0 else ": NOT RPI for its own W")
    )


def adjustable_tube_line(tau: float, level_t: float, w_prime: float) -> str:
    """The adjustable tube tau Z with tau F (eq. 47-48): its level for W and W' = g W."""
    return (
        f"adjustable tube tau Z with tau F (eq. 47-48, tau = {tau:g}): worst one-step "
        f"level for W = {level_t:.5f}; RPI for W' = {w_prime:.3f} W (the incomplete "
        f"disturbance set; >= tau by the LMI's tau vertices"
        + ("  OK)" if w_prime >= tau * (1 - 1e-9) else ": NOT as designed)")
        + ". For the whole W the error stays in Z and the input deviation in tau F Z"
    )


def domain_line(dom, n_schedules: int) -> str:
    """The vertex tube's domain (`fahv.bounds.domain.CertificateDomain`)."""
    return (
        f"certificate domain: {n_schedules} scheduling point(s) over the envelope; x - x_rs "
        f"within nominal + Z = +/-[{_join(dom.x_half, '.3g', ', ')}]; inputs Phi in "
        f"[{dom.u_lo[0]:.3f}, {dom.u_hi[0]:.3f}], delta_e in [{np.degrees(dom.u_lo[1]):.1f}, "
        f"{np.degrees(dom.u_hi[1]):.1f}] deg (tightened set + tau F Z); all "
        f"{2 ** len(dom.uncertainty)} corners of the parameter box; rho_f in {list(dom.rho)}. "
        "Assumed: " + "; ".join(dom.notes)
    )


def domain_bound_line(n_evaluations: int, ratio, slack) -> str:
    """W against the bound over the domain (`fahv.bounds.one_step_bound`)."""
    return (
        "W over the domain (Taylor bound + corner remainder, "
        f"{n_evaluations} plant steps): bound / W per row = "
        + _join(ratio, ".2f", ", ")
        + "; slack (W - bound) / W = "
        + _join(slack, "+.2f", ", ")
    )


def closed_line(closed: bool, ratio, growth: float) -> str:
    """Whether the bound over the domain lies inside W, or by how much it exceeds it."""
    if closed:
        return "certificate closed: the disturbance over the domain lies inside W  OK"
    worst_row = int(np.argmax(ratio))
    return (
        f"certificate NOT closed: the disturbance over the domain exceeds W by up to "
        f"{ratio[worst_row]:.1f}x (row {worst_row}); the tube is RPI only up to "
        f"{growth:.3f} W, so e in Z is NOT guaranteed for this plant (measured, "
        "docs/theory/certificate.md)"
    )


def vertex_onset_line(rho_min: float, delta_e: float, est_tau, level_max: float) -> str:
    """The vertex tube's onset of a loss (`fahv.tube.vertex_tube.onset_levels`)."""
    return (
        f"onset of a {100 * (1 - rho_min):.0f} % loss at delta_e = "
        f"{np.degrees(delta_e):.1f} deg (estimate time constant {est_tau} s): "
        f"level bound from the certificate up to {level_max:.3g} "
        + ("<= 1  OK" if level_max <= 1 else "> 1: the onset is NOT certified")
    )


def vertex_certificate_lines(cert) -> list[str]:
    """The lines of the vertex tube checked over its domain, in the order it was checked.

    Parameters
    ----------
    cert : fahv.tube.vertex_tube.VertexCertificate

    Returns
    -------
    list of str
        The exact RPI check (`rpi_check_line`; `adjustable_tube_line` for
        tau < 1), then the domain (`domain_line`), the bound over it
        (`domain_bound_line`), whether it closes (`closed_line`) and the onset
        (`vertex_onset_line`), or why the domain was not checked.
    """
    r = cert.rpi
    lines = [rpi_check_line(r.level, r.n_vertices, r.n_corners, r.growth, r.tau)]
    if r.tau < 1:
        lines.append(adjustable_tube_line(r.tau, r.level_tau, r.w_prime))
    if cert.skipped is not None:
        return lines + [
            f"certificate domain: {cert.skipped}; the tube certificate is NOT checked over "
            "its domain"
        ]
    return lines + [
        domain_line(cert.domain, cert.n_schedules),
        domain_bound_line(cert.bound.n_evaluations, cert.ratio, cert.slack),
        closed_line(cert.closed, cert.ratio, r.growth),
        vertex_onset_line(cert.rho_min, cert.domain.u_hi[1], cert.est_tau,
                          cert.onset_level_max),  # fmt: skip
    ]


# -- the stages' own lines (fahv.design.stages, fahv.design.tube_forms) -------------------
def tp_model_line(kind: str, n_vertices: int, Ts: float) -> str:
    """The TP model's line: design model, vertex count (eq. 11), control period [s]."""
    return f"TP model: {kind.upper()}, {n_vertices} vertices, Ts = {Ts} s"


def disturbance_line(section: dict, W) -> str:
    """The sampled W's line (eq. 13-19): samples, margin, dominant source per state."""
    return (
        f"W: {section['samples']} samples, margin {section['margin']}, constant part of the "
        f"parameter error {section['constant']}; dominant source per state: "
        + ", ".join(W.dominant())
    )


def tube_lmi_line(n_vertices: int, rho_f: float, tau: float, min_eig: float, lam) -> str:
    """The tube LMI's line (LMI 24 with the S-procedure, eq. 48 for tau < 1)."""
    return (
        f"certificate F, Z (LMI 24 + S-procedure, {n_vertices} vertices incl. rho_f = "
        f"{rho_f}{f' and the gains tau F, tau = {tau:g} (eq. 48)' if tau < 1 else ''}): min "
        f"eigenvalue {min_eig:.3e} >= -1e-12 x the largest entry of each vertex matrix "
        f"(tolerance), lam = {lam}  OK"
    )


def tightening_line(room, tightening, tau: float) -> str:
    """The tightened inputs' line (eq. 30; eq. 53 with tau < 1): room and tau F Z's support."""
    return (
        f"tightened inputs (eq. 30{', 53 with tau = ' + str(tau) if tau < 1 else ''}): "
        f"room {room[0]:.4f} / {np.degrees(room[1]):.3f} deg, tightening "
        f"{tau * tightening[0]:.4f} / {np.degrees(tau * tightening[1]):.3f} deg"
    )


def coverage_line(coverage, rho_f: float) -> str:
    """The loss coverage's line (`fahv.bounds.coverage.LossCoverage`)."""
    c = coverage
    return (
        f"largest elevator loss whose faulty trim fits the tightened inputs for every one of "
        f"the {c.corners} distinct corners of the parameter box (1024 corners; I_yy does "
        f"not enter a trim): {100 * c.loss_path:.1f} % on the design step's path, "
        f"{100 * c.loss:.1f} % over the whole envelope ({c.points} grid points, "
        f"+{np.degrees(c.remainder):.4f} deg of elevator between them; trim elevator "
        f"monotone in h, V: {c.monotone[0]}, {c.monotone[1]}); worst: "
        f"{np.degrees(c.delta_e_max):.3f} deg at h = {c.worst_point[0]:.0f} ft, "
        f"V = {c.worst_point[1]:.1f} ft/s; design rho_f = {rho_f}"
    )


def input_rows_line(offsets, nominal: SchedulingBox, u_box) -> str:
    """The line of the QP's rows on the nominal input (`mpc.u_box`, `fahv.tube.rows`)."""
    off_lo, off_hi = offsets
    deg = np.degrees
    return (
        f"nominal box inputs (applied input minus the nominal trim): the box corners' trims "
        f"lie at Phi {off_lo[0]:+.4f}..{off_hi[0]:+.4f}, delta_e {deg(off_lo[1]):+.3f}"
        f"..{deg(off_hi[1]):+.3f} deg (any loss or bias: the plant applies its own "
        f"trim); the box allows {nominal.lo[4]:+.3f}..{nominal.hi[4]:+.3f} and "
        f"{deg(nominal.lo[5]):+.2f}..{deg(nominal.hi[5]):+.2f} deg, so "
        f"the QP bounds the manoeuvre part K zeta + c of the nominal input to Phi "
        f"{u_box[0, 0]:+.4f}..{u_box[1, 0]:+.4f}, delta_e {deg(u_box[0, 1]):+.3f}.."
        f"{deg(u_box[1, 1]):+.3f} deg (mpc.u_box; a loss scales the applied part "
        "towards 0)"
    )


def nominal_range_line(hv_box) -> str:
    """The line of the nominal's h, V range (`mpc.hv_box`)."""
    return (
        f"nominal range (mpc.hv_box): h {hv_box[0, 0]:.0f}..{hv_box[1, 0]:.0f} ft, V "
        f"{hv_box[0, 1]:.2f}..{hv_box[1, 1]:.2f} ft/s: the QP keeps its set point and its "
        "predicted h, V in it (the tube set's nominal box)"
    )


def state_rows_line(x_box) -> str:
    """The line of the nominal's other states' range (`mpc.x_box`)."""
    xd = np.degrees(x_box[:, :3])
    return (
        f"nominal state range (mpc.x_box): alpha {xd[0, 0]:+.3f}..{xd[1, 0]:+.3f} deg, theta "
        f"{xd[0, 1]:+.3f}..{xd[1, 1]:+.3f} deg, |q| <= {xd[1, 2]:.3f} deg/s, |eta_1|, "
        f"|eta_1_dot|, |eta_2|, |eta_2_dot| <= "
        + ", ".join(f"{v:.3f}" for v in x_box[1, 3:])
        + " from the trim at the nominal's own (h, V): the QP keeps its prediction in it "
        "(the range the certificate covers)"
    )


def nominal_gain_line(cert: dict, s: float) -> str:
    """The nominal gain's line (LMI 33-35'): contraction, input ratio, LMI margin, s."""
    return (
        f"certificate K (LMI 33-35'): contraction {cert['contraction']:.6f} < 1, input "
        f"ratio {cert['input_ratio']:.4f} <= 1, LMI (34') min eigenvalue "
        f"{cert['lmi34_min_eig']:.2e} >= -{cert['lmi34_tol']:.2e} (tolerance: 1e-9 x the "
        f"largest entry of the block), fraction of the design step in E(Q) s = {s:.3f}  OK"
    )


def no_estimate_line(variant: str) -> str:
    """The note for a tube variant without disturbance estimate while W leaves it one."""
    return (
        f"note: variant {variant} has no disturbance estimate; W leaves the constant "
        "part of the parameter error to one, so its tube certificate does not cover it"
    )
