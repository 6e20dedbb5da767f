"""Feasibility of the tube (eq. 19-30) on the vehicle: which W, which Z, how much room.

Two ways of treating the elevator loss of effectiveness are compared:

* `"box"` -- the paper's eq. (16)-(19): the fault is part of the box W.
* `"polytopic"` -- the deviation part of the fault, B (P - I) u of eq. (16), is
  exact polytopic uncertainty in B (vertices with rho_f and with 1), and W bounds
  only modelling error and parameter uncertainty. The trim part of the fault,
  (rho_f - 1) delta_e,r, is then NOT covered by W (it is a constant offset).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.bounds.disturbance import DisturbanceSet, sample_disturbance
from fahv.bounds.vertices import fault_vertices
from fahv.errors import DesignError
from fahv.model.trim import trim_grid
from fahv.model.vehicle import DELTA_E
from fahv.synthesis.box_tube import BoxTubeResult, box_tube
from fahv.synthesis.feedback import TubeDesign, design_tube


def input_room(vehicle, n: int = 5, rho_f: float = 1.0) -> np.ndarray:
    """Smallest distance (2,) from the trim input to the input limits over the envelope.

    The deviation bound |u_j - u_r,j| <= room_j used by eq. (29)-(30) and (35), on an
    n x n trim grid. With rho_f < 1 the elevator trim is the one of the faulty vehicle,
    delta_e,r / rho_f (eq. 15): the room the binding side of each row of the
    asymmetric input set keeps after the fault.

    Raises
    ------
    ValueError
        If rho_f is not in (0, 1].
    """
    if not 0.0 < rho_f <= 1.0:
        raise ValueError(f"elevator effectiveness rho_f must be in (0, 1], got {rho_f}")
    env, lim = vehicle.envelope, vehicle.limits
    rows = trim_grid(
        vehicle, np.linspace(env.h_min, env.h_max, n), np.linspace(env.V_min, env.V_max, n)
    )
    u_r = np.array([tp.u_r for row in rows for tp in row])
    u_r[:, DELTA_E] /= rho_f
    return np.minimum((u_r - lim.u_min).min(axis=0), (lim.u_max - u_r).min(axis=0))


@dataclass(frozen=True)
class FeasibilityResult:
    """Outcome of `tube_feasibility` for one fault treatment.

    Attributes
    ----------
    treatment : str
        "box" or "polytopic".
    W : DisturbanceSet
    tube : TubeDesign or None
        None if the LMI was infeasible.
    box : BoxTubeResult or None
        The paper's box tube (eq. 25-28) for the same F.
    room : (2,) ndarray
        Input room around trim.
    error : str
        Why the design failed, if it did.
    """

    treatment: str
    W: DisturbanceSet
    tube: TubeDesign | None
    box: BoxTubeResult | None
    room: np.ndarray
    error: str = ""

    @property
    def nominal_room(self) -> np.ndarray:
        """Input room left to the nominal input, room - tightening (2,), eq. (30)."""
        if self.tube is None:
            return np.full(2, -np.inf)
        return self.room - self.tube.tightening


def tube_feasibility(
    vehicle,
    tp,
    Ts,
    uncertainty,
    rho_f,
    dx_half,
    du_half,
    n_samples,
    seed,
    margin,
    treatment,
    lam_grid,
    progress=None,
) -> FeasibilityResult:
    """Sample W, design F and Z, try the box tube, report the input room left.

    Parameters are those of `fahv.bounds.disturbance.sample_disturbance` and
    `fahv.synthesis.feedback.design_tube`; `treatment` is "box" or "polytopic".
    """
    if treatment not in ("box", "polytopic"):
        raise ValueError(f"fault treatment must be 'box' or 'polytopic', got {treatment!r}")
    room = input_room(vehicle)
    W = sample_disturbance(
        vehicle,
        tp,
        Ts,
        uncertainty,
        rho_f if treatment == "box" else 1.0,
        dx_half,
        du_half,
        n_samples,
        seed,
        margin,
        progress=progress,
    )
    disc = tp.discretize(Ts)
    A, B = (disc.A, disc.B) if treatment == "box" else fault_vertices(disc.A, disc.B, rho_f)
    Dx, Du = tp.state_scale, tp.input_scale
    try:
        tube = design_tube(A, B, W.w_max, Dx, Du, room, lam_grid)
    except DesignError as exc:
        return FeasibilityResult(treatment, W, None, None, room, str(exc))
    return FeasibilityResult(treatment, W, tube, box_tube(A, B, tube.F, W.w_max, Dx, Du), room)
