"""The eight-state tube's domain rebuilt for a re-check: its vertices and the servo's rate.

`fahv verify` re-checks the eight-state tube over the vertices along the nominal that
the design file's `eight_state` section defines (`eight_state_vertices`), and the
elevator command's rate against the servo's (`elevator_rate_step`); the estimate
design's rate claim (`fahv.certificate.verify_estimate`) uses both.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fahv.spec.artefacts import Design


def eight_state_vertices(design: Design, vehicle):
    """The eight-state tube's vertices along the nominal, rebuilt from the design file.

    Parameters
    ----------
    design : Design
        An eight-state design (its `eight_state` section, the stored `certificate`).
    vehicle : fahv.model.vehicle.Vehicle

    Returns
    -------
    (NominalVertices, (R, 9, 9) ndarray, (R, 9, 2) ndarray)
        The vertices' record and its A, B (with the gains tau F's vertices for tau < 1,
        eq. 48).
    """
    from fahv.bounds.domain import nominal_box
    from fahv.bounds.vertices import nominal_vertices
    from fahv.model.trim import TrimMap
    from fahv.plant.uncertainty import PAPER_UNCERTAINTY

    a, c, s = design.arrays, design.case, design.summary
    cert = s["certificate"]
    _, box = nominal_box(c["eight_state"], vehicle.envelope)
    unc = {k: v * c["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    scale = np.concatenate([a["Dx"], a["Du"]])
    nv = nominal_vertices(box, vehicle, tm, unc, float(s["tube"]["rho_f"]), c["Ts"],
                          c["plant_substeps"], scale, c["eight_state"]["k"], a["w_max"],
                          np.asarray(cert["col_scale"], float))  # fmt: skip
    tau = float(c["tube"]["tau"])
    if tau < 1.0:
        nv = dataclasses.replace(nv, tau=tau)
    A, B = nv.vertices()
    return nv, A, B


def elevator_rate_step(vehicle, Ts: float) -> float:
    """The elevator servo's rate limit times Ts [rad per step]; inf without servos.

    The smaller of the vehicle file's `actuators.second_order.delta_e` rate limits up and
    down (the servos the loop that can be flown has).

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    Ts : float
        Control period [s].

    Returns
    -------
    float
        [rad per step].
    """
    servo = (vehicle.actuators.get("second_order") or {}).get("delta_e")
    rate = np.inf if servo is None else min(servo.rate_limit_incr, servo.rate_limit_decr)
    return float(rate) * Ts
