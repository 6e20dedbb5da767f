"""Closure of the eight-state tube set: W_8 and Z_8 iterated until each holds the other.

Z_8 is designed for W_8 (the tube LMI (24) over the vertices along the nominal), and
W_8 must bound the one-step disturbance over the product set of that Z_8
(`fahv.bounds.one_step_bound.altitude_bound`). `close_tube_set` iterates
W_8 <- max(W_8, grow x bound) with the LMI re-solved until the bound lies inside W_8,
checks that the scheduling box holds the nominal box grown by the product set's supports
(the integral form's segment condition, `fahv.bounds.domain.box_shortfall`), and
re-checks the exact worst one-step level over the vertices and the corners of W_8
(`fahv.synthesis.rpi_level.worst_level`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fahv.bounds.domain import SchedulingBox, box_shortfall, shortfall_fixes
from fahv.bounds.one_step_bound import altitude_bound
from fahv.bounds.vertices import NominalVertices
from fahv.errors import DesignError
from fahv.synthesis.feedback import GENERATION_ADD, ActiveSet, design_tube
from fahv.synthesis.rpi_level import worst_level
from fahv.tube.lines import closure_iteration_line
from fahv.tube.tube_set import TubeSet


def close_tube_set(
    nv: NominalVertices,
    nominal: SchedulingBox,
    W_8,
    state_scale,
    input_scale,
    room,
    lam: float,
    moves: int,
    *,
    grow: float = 1.05,
    iterations: int = 6,
    w_ref=None,
    active: int = GENERATION_ADD,
    state_max=None,
    contain=None,
    warm: ActiveSet | None = None,
    log: Callable[[str], None] = print,
) -> TubeSet:
    """Iterate W_8 and Z_8 to a closed tube set over the vertices `nv` (module docstring).

    Parameters
    ----------
    nv : NominalVertices
        Vertex data over the scheduling box.
    nominal : SchedulingBox
        The nominal's own box, which the scheduling box must hold grown by the tube.
    W_8 : (8,) array_like
        Starting half-widths of W_8 (state units per period).
    state_scale : (9,) array_like
        Design state scaling (Dx); its eight entries after h scale the LMI.
    input_scale : (2,) array_like
        Design input scaling (Du).
    room : (2,) array_like
        Input room of each row (`fahv.tube.feasibility.input_room`).
    lam : float
        Contraction factor of the tube LMI (24).
    moves : int
        Fast steps between the nominal's altitude resets (M of `mpc`).
    grow : float
        W_8 <- max(W_8, grow x bound) between iterations.
    iterations : int
    w_ref : (9,) array_like, optional
        Reference size of W for the LMI's scaling (`fahv.synthesis.feedback.design_tube`);
        its eight entries after h are used.
    active : int
        Vertex blocks and points added per pass of constraint generation
        (`fahv.synthesis.feedback.design_tube`).
    state_max : (8,) array_like, optional
        Largest supports of Z_8 along e_8's axes (V, alpha, theta, ...; unscaled, inf: no
        bound), e.g. 0.5 deg less the QP's attitude rows in alpha and theta, so that the
        attitude requirement follows from the tube set; passed to
        `fahv.synthesis.feedback.design_tube`.
    contain : (S, 8) array_like, optional
        Errors Z_8 must contain (`contain` of `fahv.synthesis.feedback.design_tube`),
        e.g. the onset's jumps over the level they may use.
    warm : ActiveSet, optional
        The vertices and points the constraint generation starts from (the `active_set`
        of an earlier design of this file); it changes how fast the LMI is solved, not
        what is certified.
    log : callable
        Receives one line per iteration.

    Returns
    -------
    TubeSet
        Closed: bound <= W_8 in every row, the box holds nominal + product set, exact
        one-step level <= 1.

    Raises
    ------
    DesignError
        If the tube LMI is infeasible, the tube outgrows the scheduling box (names the
        coordinates), the exact level exceeds 1, or the iterations run out (gives the
        last bound / W_8).
    """
    A, B = nv.vertices()
    A_8, B_8 = A[:, 1:, 1:], B[:, 1:, :]
    W_8 = np.asarray(W_8, float).copy()
    w_ref_8 = None if w_ref is None else np.asarray(w_ref, float)[1:]
    ratio = np.full(8, np.inf)
    for it in range(iterations):
        tube = design_tube(A_8, B_8, W_8, np.asarray(state_scale, float)[1:], input_scale, room,
                           (lam,), state_max=state_max, w_ref=w_ref_8, active=active,
                           contain=contain, warm=warm)  # fmt: skip
        F_8, N_8 = tube.F, tube.N
        ab = altitude_bound(nv, A, B, F_8, N_8, moves)
        ratio = ab.bound / W_8
        short = box_shortfall(nv.box, nominal, F_8, N_8, ab.H)
        log(closure_iteration_line(it, tube.tightening, N_8, ab, ratio))
        if short:
            raise DesignError(
                "eight-state tube: the scheduling box does not hold the nominal box grown by "
                "the tube (short by "
                + ", ".join(f"{n} {v:.3g}" for n, v in short.items())
                + "). In the design file, set "
                + "; ".join(shortfall_fixes(short, nv.box, nominal))
                + ", or shrink the nominal box (eight_state.attitude, Phi, delta_e, other)"
            )
        if np.all(ratio <= 1.0):
            level, _ = worst_level(A_8, B_8, F_8, N_8, W_8)
            if level > 1.0:
                raise DesignError(
                    f"eight-state tube: bound inside W_8 but the exact worst one-step level "
                    f"is {level:.6f} > 1 over {A_8.shape[0]} vertices"
                )
            return TubeSet(F_8, N_8, W_8, ab.H, float(tube.lam), ab.bound, float(level),
                           int(moves), ab.step, ab.w_h, active_set=tube.active_set)  # fmt: skip
        W_8 = np.maximum(W_8, grow * ab.bound)
    raise DesignError(
        f"eight-state tube: not closed in {iterations} iterations (bound / W_8 "
        + " ".join(f"{r:.3f}" for r in ratio)
        + ")"
    )
