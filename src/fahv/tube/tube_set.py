"""The eight-state tube set (W_8, Z_8): the tube on the states after h, h held by a reset.

Along the nominal, the W-Z iteration at the size the onset of a loss needs diverges in
the h row: the kinematic integrator h_dot = V sin(theta - alpha) is held by the tube only
through theta and q, and its disturbance grows with the box. The tube set takes h out of
the tube's RPI condition. The tube (F_8, Z_8 = {e_8' N_8^-1 e_8 <= 1}) is designed on the
other eight states e_8 = (V, alpha, theta, q, eta_1, eta_1_dot, eta_2, eta_2_dot) with
the ancillary gain blind to e_h, and the altitude error is bounded by the nominal MPC's
reset of its h to the measured altitude at every re-plan (`mpc.h_reset`, M fast steps
apart): |e_h| <= H (`fahv.bounds.one_step_bound.altitude_bound`, eq. (1) there).

W_8 bounds the one-step disturbance over the product set {|e_h| <= H} x Z_8 in the
integral form (`fahv.bounds.one_step_bound`); the closure iterates W_8 and Z_8 until
the bound lies inside W_8 (`fahv.tube.closure`). What the tube set assumes besides
the vertices' own assumptions is `ASSUMPTIONS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from fahv.bounds.domain import (
    BOX_COORDINATES,
    OTHER_COORDINATES,
    SchedulingBox,
    certified_range,
    product_supports,
)

if TYPE_CHECKING:
    from fahv.synthesis.feedback import ActiveSet
    from fahv.tube.notch_loop import NotchLoop

#: The states of the tube, after h (the design's state order without its first entry).
EIGHT_STATES = ("V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")

#: What a tube set assumes beyond the vertices' own assumptions.
ASSUMPTIONS = (
    "the nominal resets its altitude to the measured one every `moves` fast steps "
    "(mpc.h_reset, M = moves), so |e_h| <= H between resets",
    "the ancillary gain is blind to e_h: u = v + F_8 e_8",
    "the nominal stays inside the certified range (the scheduling box less the tube: "
    "certified_range); the QP's rows keep its h, V, attitude (from the set point's trim) and "
    "inputs in the nominal box, and its alpha, theta, q and flexible states in the certified "
    "range from the trim at its own (h, V) (mpc.x_box; the trim's slope linearised at the "
    "scheduling point, the remainder measured per run: metrics nominal_*, the campaign "
    "report's range line)",
    "the disturbance estimate has converged: the onset of a loss and the estimate's lag "
    "are not in W_8 (bounded separately as a transient of the tube set: the onset lines)",
)


@dataclass(frozen=True)
class TubeSet:
    """A closed eight-state tube set (W_8, Z_8) and its altitude bound.

    Attributes
    ----------
    F_8 : (2, 8) ndarray
        Ancillary gain on e_8 [(-, rad) per state unit].
    N_8 : (8, 8) ndarray
        Shape of Z_8 = {e_8' N_8^-1 e_8 <= 1} (state units squared).
    W_8 : (8,) ndarray
        Half-widths of W_8 (state units per period Ts).
    H : float
        Altitude error bound [ft] (`fahv.bounds.one_step_bound.altitude_bound`).
    lam : float
        Contraction factor of the tube LMI (24).
    bound : (8,) ndarray
        The disturbance bound over the product set, per row (<= W_8 when closed).
    level : float
        Exact worst one-step level over the vertices and the corners of W_8 (<= 1).
    moves : int
        Fast steps between the nominal's altitude resets (M).
    step : float
        Largest one-step change of e_h by the tube's own dynamics [ft].
    w_h : float
        The h row's disturbance over the product set [ft].
    onset : fahv.onset.bound.OnsetBound, optional
        The onset of a loss as a transient of the tube set
        (`fahv.onset.bound.onset_bound`, which takes a closed tube set: the onset
        package sits above this one, so the type is not imported here).
    notch_loops : tuple of NotchLoop
        The tube variants that feed q through a notch, their loops certified in their
        own states at the tube set's vertices (`fahv.tube.notch_loop.notch_tube`).
    notch_gains : dict
        `{variant: (2, 8) ndarray}`: the gains designed for those loops and certified
        (`eight_state.notch_gain: designed`, `fahv.tube.notch_gain.notch_gain`);
        such a variant runs its own gain in place of F_8.
    active_set : fahv.synthesis.feedback.ActiveSet, optional
        The vertices and contained points the closure's last LMI solve held: where a
        later design of the same file starts its constraint generation.
    ellipsoid_vertices : dict
        `{name: (a,) ndarray of int}`: the vertices the last LMI solve of each
        invariant ellipsoid checked with the tube set held (the onset's steady sets, the
        notch loops; `fahv.design.tube_set_design.steady_key`, `notch_key`):
        where a later design starts theirs.
    """

    F_8: np.ndarray
    N_8: np.ndarray
    W_8: np.ndarray
    H: float
    lam: float
    bound: np.ndarray
    level: float
    moves: int
    step: float
    w_h: float
    onset: Any = None
    notch_loops: tuple[NotchLoop, ...] = ()
    notch_gains: dict = field(default_factory=dict)
    active_set: ActiveSet | None = None
    ellipsoid_vertices: dict = field(default_factory=dict)

    @property
    def F(self) -> np.ndarray:
        """(2, 9) ancillary gain on the nine states, zero on e_h."""
        return np.hstack([np.zeros((2, 1)), self.F_8])

    @property
    def N(self) -> np.ndarray:
        """(9, 9) diag(H^2, N_8), the tube shape the nodes take.

        Its ellipsoid holds the product set's e_8 part and its h support is H; the
        node's tube level with it is a bound, not the product set's level.
        """
        N = np.zeros((9, 9))
        N[0, 0], N[1:, 1:] = self.H**2, self.N_8
        return N

    @property
    def tightening(self) -> np.ndarray:
        """(2,) support of F_8 Z_8 per input [-, rad]: the tightening of eq. (30)."""
        return np.sqrt(np.einsum("ij,jk,ik->i", self.F_8, self.N_8, self.F_8))

    @property
    def slack(self) -> np.ndarray:
        """(8,) 1 - bound / W_8 per row (>= 0 when closed)."""
        return 1.0 - self.bound / self.W_8

    def certified_range(self, box: SchedulingBox) -> SchedulingBox:
        """The nominal points the certificate covers: `box` less the tube.

        `fahv.bounds.domain.certified_range` of this tube set.
        """
        return certified_range(box, self.F_8, self.N_8, self.H)

    def reach(self, nominal: SchedulingBox, box: SchedulingBox) -> tuple[float, str]:
        """How far the scheduling box reaches beyond the nominal box, in tube supports.

        The smallest over the coordinates after h of the box's margin beyond the nominal
        box (its nearer side) over the product set's support there
        (`fahv.bounds.domain.product_supports`), and that coordinate's name; at
        least 1 when the box holds the nominal box grown by the tube.
        """
        s_lo, s_oth = product_supports(self.F_8, self.N_8, self.H)
        lo, hi, oth = box.margin_to(nominal)
        room = np.r_[np.minimum(lo, hi)[1:] / s_lo[1:], oth / s_oth]
        names = [*BOX_COORDINATES[1:], *OTHER_COORDINATES]
        worst = int(np.argmin(room))
        return float(room[worst]), names[worst]

    def summary(self, nominal: SchedulingBox, box: SchedulingBox) -> dict:
        """JSON-ready record of the tube set for the design summary (`certificate`).

        Units as the attributes; the boxes in their coordinates
        (`fahv.bounds.domain.BOX_COORDINATES`); `certified_range` is
        `certified_range` of the scheduling box.
        """
        return {
            "form": "eight_state",
            "states": list(EIGHT_STATES),
            "W_8": self.W_8.tolist(),
            "bound": self.bound.tolist(),
            "slack": self.slack.tolist(),
            "level": self.level,
            "level_margin": 1.0 - self.level,
            "lam": self.lam,
            "H_ft": self.H,
            "moves": self.moves,
            "h_step_ft": self.step,
            "w_h_ft": self.w_h,
            "tightening": self.tightening.tolist(),
            "nominal_box": nominal.summary(),
            "scheduling_box": box.summary(),
            "certified_range": self.certified_range(box).summary(),
            "assumptions": list(ASSUMPTIONS),
            "onset": None if self.onset is None else self.onset.summary(),
            "notch_in_loop": [loop.summary() for loop in self.notch_loops],
        }
