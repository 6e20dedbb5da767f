"""Verification of an estimate design's probabilistic claims, from its stored arrays.

`fahv design` makes, for a design with an `estimate` section, a covariance bound Sigma of
the loop on the estimate and the nominal's rows tightened by it
(`fahv.design.estimate`). `check_estimate` re-checks them without a solver: the filter
and the joint system rebuilt from the design's arrays and the vehicle file, Sigma's
exact margin at every pair of model and gain vertex, and each claim recomputed from
Sigma with its probability; the stored rows must be the recomputed ones.
"""

from __future__ import annotations

import numpy as np

from fahv.certificate.check_result import CheckResult
from fahv.stochastic.claims import ASSUMPTIONS, claims_at, estimate_filter
from fahv.stochastic.closed_loop import ProbabilisticTube, joint_system, standard_deviations
from fahv.stochastic.error_bound import error_system, exact_margin

#: Tolerance of the stored rows against the recomputed ones [deg] (the same expression).
ROWS_ATOL_DEG = 1e-9


def rate_parts(design, vehicle, vertices=None) -> tuple[float, float]:
    """The tube's worst-case part of the delta_e step and the servo's step [rad per step].

    The law runs tau F (the design's `tube.tau`, eq. 53-54), whose part of the command
    moves by tau F (A_i + tau B_i F - I) e + tau F w along the tube:
    `fahv.bounds.input_rate.law_rate` over the eight-state tube's vertices, Z_8 and W_8:
    `fahv verify`'s `input rate` line without the nominal's rows.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        An eight-state design.
    vehicle : fahv.model.vehicle.Vehicle
    vertices : callable, optional
        Returns the design's eight-state vertices as
        `fahv.certificate.eight_state.eight_state_vertices` does (`fahv verify` builds them
        once for all its checks); default: that function on `design` and `vehicle`.

    Returns
    -------
    (float, float)
        The tube's part and the elevator servo's rate limit times Ts (inf: no servo).
    """
    from fahv.bounds.input_rate import law_rate
    from fahv.certificate.eight_state import eight_state_vertices, elevator_rate_step

    a, c = design.arrays, design.case
    _, A, B = vertices() if vertices is not None else eight_state_vertices(design, vehicle)
    W_8 = np.asarray(design.summary["certificate"]["W_8"], float)
    r = law_rate(A[:, 1:, 1:], B[:, 1:, :], np.asarray(a["F"], float)[:, 1:],
                 np.asarray(a["N"], float)[1:, 1:], W_8, float(c["tube"]["tau"]))  # fmt: skip
    return float(r.per_step[1]), elevator_rate_step(vehicle, float(c["Ts"]))


def check_estimate(design, vehicle, vertices=None) -> list[CheckResult]:
    """The estimate design's covariance bound and claims, re-checked (module docstring).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        A design with an `estimate` section and its stored `estimate_*` arrays.
    vehicle : fahv.model.vehicle.Vehicle
    vertices : callable, optional
        The design's eight-state vertices (`rate_parts`).

    Returns
    -------
    list of CheckResult
        `estimate bound` (Sigma's smallest eigenvalue over the pairs), `estimate
        attitude` and `estimate elevator rate` (each claim's margin, its probability in
        the line).
    """
    c, a = design.case, design.arrays
    tau = float(c["tube"]["tau"])
    flt, R_v = estimate_filter(c, vehicle, a)
    js = joint_system(error_system(flt), a["A"], a["B"], tau * np.asarray(a["F"], float),
                      flt.servos, flt.Ts)  # fmt: skip
    S = np.asarray(a["estimate_Sigma"], float)
    margin = exact_margin(js.system, S, R_v)
    R = np.asarray(a["A"]).shape[0]
    bound = CheckResult(
        "estimate bound", margin >= 0.0, margin,
        f"covariance bound Sigma of [t; servo states; e] under {tau:g} F on the estimate, "
        f"{R * R} pairs of model and gain vertex: smallest eigenvalue of Sigma - M Sigma M' - "
        f"N R_v N' {margin:.3g} >= 0 (scaled coordinates)",
    )
    pt = ProbabilisticTube(S, margin, 0, *standard_deviations(js, S, R_v), np.zeros(8))
    claims = claims_at(pt, tau, c, np.asarray(a["att_support"], float), *rate_parts(design,
                                                                                  vehicle,
                                                                                  vertices))
    rows_deg = np.degrees(claims.rows)
    same = np.allclose(rows_deg, a["estimate_att_max_deg"], rtol=0.0, atol=ROWS_ATOL_DEG)
    du_deg = float(np.degrees(claims.du_plan))
    same_du = abs(du_deg - float(a["estimate_du_max_elevator"])) <= ROWS_ATOL_DEG
    deg = np.degrees
    made = claims.claimed
    att_ok, att_said = claims.said("attitude")
    rate_ok, rate_said = claims.said("elevator_rate")
    rate_margin = (claims.rate_room / claims.rate_limit if np.isfinite(claims.rate_limit)
                   else 1.0)  # fmt: skip
    attitude = CheckResult(
        "estimate attitude", bool(same and att_ok),
        float(deg(claims.rows_room.min())),
        f"p >= {claims.p_claim:.4f} per run ({claims.r_attitude:.2f} sigma of alpha "
        f"{deg(claims.std_attitude[0]):.4f}, theta {deg(claims.std_attitude[1]):.4f} deg): "
        f"nominal rows {rows_deg[0]:.3f} / {rows_deg[1]:.3f} deg + support of Z_8 + noise "
        f"part <= 0.5 deg; {att_said}"
        + ("" if same else "; the stored rows differ from the recomputed"),
    )
    rate = CheckResult(
        "estimate elevator rate",
        bool(same_du and rate_ok), float(rate_margin),
        f"p >= {claims.p_claim:.4f} per run ({claims.r_rate:.2f} sigma of the tube's step "
        f"{deg(claims.std_step):.4f} deg): tube {deg(claims.rate_tube):.3f} + noise "
        f"{deg(claims.r_rate * claims.std_step):.3f} leave {deg(claims.rate_room):.3f} of the "
        f"servo's {deg(claims.rate_limit):.3f} deg per step for the nominal's rate rows "
        f"({du_deg:.3f}); {rate_said}"
        + ("" if same_du else "; the stored rate rows differ from the recomputed"),
    )
    p = float(c["estimate"]["probability"])
    joint = CheckResult("estimate, every claim", attitude.ok and rate.ok, 1.0 - p,
                        f"{', '.join(made)} at once with p >= {p:g} per run (union bound); "
                        f"assumed: {ASSUMPTIONS}")
    return [bound, attitude, rate, joint]
