"""The design for the loop on the state estimate: its probabilistic reachable set and claims.

A design file with an `estimate` section (`fahv.spec.estimator.ESTIMATE_DESIGN`) is
made for the loop that can be flown: the vehicle file's servos between the command and
the airframe, its sensors (h, V, theta and the gyro's q) with white noise, and the
gain-scheduled Kalman filter (`fahv.estimation.kalman.design_filter`) whose estimate the
nominal MPC and the tube law read. The tube law runs tau F on the estimate, with the
design's own `tube.tau`, so that the eight-state tube certificate (exact state) covers
the gains tau F .. F (eq. 48, 53-54).

What the noise does to that loop is bounded as a probabilistic reachable set (Hewing
and Zeilinger, CDC 2018): `fahv.stochastic.closed_loop` bounds the covariance of the
joint system of the deviation from the nominal, the servo states and the filter's error
with one matrix Sigma at every pair of model and gain vertex (LMI, re-checked exactly).
The design turns it into the claims per run it makes (`estimate.claims`), each with its
share of 1 - p (a union bound, so they hold at once with probability >= p), each itself
a union bound over the run's steps (and, for the attitude, its two signals); a claim it
does not make is reported with its numbers:

- **attitude**: |alpha - alpha_r|, |theta - theta_r| <= 0.5 deg. The nominal's rows
  are tightened to rows = 0.5 deg - support of Z_8 - r std (r from the union bound),
  at most the design's `mpc.att_max` (`estimate_att_max_deg`);
- **elevator rate**: the command moves by at most the servo's rate limit times Ts per
  step. The tube's worst-case part (`fahv.bounds.input_rate`, as `fahv verify`'s
  `input rate` line) plus the noise part r std of the tube's step leave the nominal's
  delta_e rate rows what is left (`estimate_du_max_elevator`, at most the design's
  `mpc.du_max`).

Assumed, and said in the certificate: the sensors' noise is white and Gaussian at the
vehicle file's sigmas (the turn-on biases are not in it); the vertex sequence does not
depend on the noise (the LPV model's premise); the model error reaches the deviation
through Z_8 as on the exact state, while its part through the estimate is reported as
the exact worst case at a frozen vertex, not bounded; the servos' limits are inactive
(the rate claim is what keeps them so).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.certificate.verify_estimate import rate_parts
from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.stochastic.claims import ASSUMPTIONS, EstimateClaims, claims_at, estimate_bound
from fahv.stochastic.closed_loop import ProbabilisticTube


@dataclass(frozen=True)
class EstimateDesign:
    """The estimate stage's result (`estimate_stage`).

    Attributes
    ----------
    claims : EstimateClaims
        At the design's tube.tau.
    tube : ProbabilisticTube
        Its covariance bound.
    others : tuple of EstimateClaims
        At each of `estimate.tau_candidates` other than the design's, for the designer.
    lines : tuple of str
        The certificate's lines.
    """

    claims: EstimateClaims
    tube: ProbabilisticTube
    others: tuple
    lines: tuple

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays the design stores.

        Returns
        -------
        dict
            `estimate_Sigma` (n_xi, n_xi); the nominal's attitude rows
            `estimate_att_max_deg` (2,) [deg] and its delta_e rate row
            `estimate_du_max_elevator` () [deg]; the warm start `estimate_pairs` (k, 2),
            the pairs the covariance LMI held.
        """
        c = self.claims
        return {"estimate_Sigma": self.tube.Sigma,
                "estimate_att_max_deg": np.degrees(c.rows),
                "estimate_du_max_elevator": np.array(np.degrees(c.du_plan)),
                "estimate_pairs": np.array(self.tube.pairs, dtype=np.int64).reshape(-1, 2)}


def claim_lines(c: EstimateClaims, p: float, pt: ProbabilisticTube, R: int) -> list[str]:
    """The certificate lines of the claims at the design's tau, each with its margin.

    Returns
    -------
    list of str
    """
    deg = np.degrees
    every = (f"estimate: the claims {', '.join(c.claimed)} hold at once with p >= {p:g} per "
             f"run (union bound over {len(c.claimed)}); assumed: {ASSUMPTIONS}")
    return [
        f"estimate: covariance bound of [t; servo states; e] (joint system of the law "
        f"{c.tau:g} F on the estimate and the filter's error) over the {R * R} pairs of model "
        f"and gain vertex, re-checked exactly: smallest eigenvalue {pt.min_eig:.3g} >= 0  OK",
        f"estimate: 1 sigma of alpha {deg(c.std_attitude[0]):.4f} / theta "
        f"{deg(c.std_attitude[1]):.4f} deg, of the tube's delta_e step "
        f"{deg(c.std_step):.4f} deg per step",
        f"estimate attitude (p >= {c.p_claim:.4f} per run, {c.r_attitude:.2f} sigma): rows "
        f"{deg(c.rows[0]):.3f} / {deg(c.rows[1]):.3f} deg (room {deg(c.rows_room[0]):.3f} / "
        f"{deg(c.rows_room[1]):.3f}) + support of Z_8 + noise part <= "
        f"{ATTITUDE_BOUND_DEG} deg: {c.said('attitude')[1]}",
        f"estimate elevator rate (p >= {c.p_claim:.4f} per run, {c.r_rate:.2f} sigma): tube "
        f"{deg(c.rate_tube):.3f} + noise {deg(c.r_rate * c.std_step):.3f} leave "
        f"{deg(c.rate_room):.3f} of the servo's {deg(c.rate_limit):.3f} deg per step for the "
        f"nominal's rate rows ({deg(c.du_plan):.3f}): {c.said('elevator_rate')[1]}",
        every,
    ]


def candidate_line(c: EstimateClaims) -> str:
    """One line of the table of other adjustable factors (the designer's choice).

    Returns
    -------
    str
    """
    deg = np.degrees
    return (f"  tau {c.tau:g}: attitude rows room {deg(c.rows_room[0]):.3f} / "
            f"{deg(c.rows_room[1]):.3f} deg; the servo leaves {deg(c.rate_room):.3f} deg per "
            "step for the nominal's rate rows (the tube's part of this F, whose Z_8 is "
            "certified at the design's tau only)")


def estimate_stage(design, vehicle, previous=None) -> EstimateDesign:
    """The estimate design of a finished exact-state design (module docstring).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        The design so far (its arrays and summary), with an `estimate` section and the
        eight-state tube.
    vehicle : fahv.model.vehicle.Vehicle
    previous : mapping, optional
        An earlier design's warm starts (`estimate_pairs`).

    Returns
    -------
    EstimateDesign

    Raises
    ------
    DesignError
        If the covariance bound fails, or a claim fails at the design's tau (the message
        names the claims and the candidates).
    """
    from fahv.errors import DesignError

    c, a = design.case, design.arrays
    if c["tube"]["form"] != "eight_state":
        raise DesignError("estimate: the estimate design needs the eight-state tube "
                          "(tube.form eight_state)")  # fmt: skip
    start = None if previous is None or "estimate_pairs" not in previous else [
        tuple(p) for p in np.asarray(previous["estimate_pairs"]).tolist()]
    tau = float(c["tube"]["tau"])
    rate_tube, rate_limit = rate_parts(design, vehicle)
    support = np.asarray(a["att_support"], float)
    _, pt = estimate_bound(c, vehicle, a, tau, start)
    claims = claims_at(pt, tau, c, support, rate_tube, rate_limit)
    others = []
    for t in c["estimate"]["tau_candidates"]:
        if abs(float(t) - tau) > 1e-12:
            _, pt_t = estimate_bound(c, vehicle, a, float(t), pt.pairs)
            others.append(claims_at(pt_t, float(t), c, support, rate_tube, rate_limit))
    R = np.asarray(a["A"]).shape[0]
    lines = claim_lines(claims, float(c["estimate"]["probability"]), pt, R)
    if others:
        lines += ["estimate: other adjustable factors (the same F):"] + [
            candidate_line(o) for o in others]
    if not claims.holds:
        raise DesignError("\n".join(["estimate: a claimed claim fails at tube.tau "
                                     f"{tau:g}:", *lines]))  # fmt: skip
    return EstimateDesign(claims, pt, tuple(others), tuple(lines))
