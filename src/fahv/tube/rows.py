"""Rows of the nominal QP that keep the nominal inside the ranges the tube set assumes.

The eight-state tube set is certified for a nominal inside its certified range
(`fahv.bounds.domain.certified_range`) with its applied input inside the nominal
box. The design turns both into rows of the nominal MPC's QP, so that the assumption
holds by construction: `input_rows` (`mpc.u_box`) and `state_rows`
(`mpc.x_box`).
"""

from __future__ import annotations

import numpy as np

from fahv.bounds.domain import SchedulingBox
from fahv.errors import DesignError


def input_rows(trim_offsets, nominal: SchedulingBox) -> np.ndarray:
    """Rows of the QP on the manoeuvre part of the nominal input (`mpc.u_box`).

    The nominal box bounds the input the plant applies minus the nominal vehicle's trim
    (where the vertices' Jacobians are taken). At steady state the plant applies its own
    trim whatever its loss or bias (eq. 15), so what is left of the box after every box
    corner's trim offset is the room of the manoeuvre part K zeta + c; a loss only scales
    the applied part towards 0.

    Parameters
    ----------
    trim_offsets : tuple of (2,) ndarray
        (lo, hi) of the corners' trim inputs minus the nominal trim [Phi -, delta_e rad]
        (`fahv.bounds.coverage.LossCoverage.trim_offsets`).
    nominal : SchedulingBox
        The nominal box (its Phi and delta_e coordinates).

    Returns
    -------
    (2, 2) ndarray
        `[[Phi lo, delta_e lo], [Phi hi, delta_e hi]]` in -, rad; lo < 0 < hi.

    Raises
    ------
    DesignError
        If the box leaves no room on a side (names the offsets).
    """
    off_lo, off_hi = (np.asarray(v, float) for v in trim_offsets)
    room = np.array([nominal.lo[4:6] - off_lo, nominal.hi[4:6] - off_hi])
    if np.any(room[0] >= 0.0) or np.any(room[1] <= 0.0):
        raise DesignError(
            "eight_state.Phi / delta_e: the nominal box does not hold the trim input of "
            f"every box corner with room to manoeuvre (trims at Phi {off_lo[0]:+.4f}.."
            f"{off_hi[0]:+.4f}, delta_e {np.degrees(off_lo[1]):+.3f}.."
            f"{np.degrees(off_hi[1]):+.3f} deg from the nominal trim): widen the box"
        )
    return room


def state_rows(cert: SchedulingBox) -> np.ndarray:
    """Rows of the QP on the nominal's states besides h, V and the inputs (`mpc.x_box`).

    The certificate covers a nominal inside the certified range
    (`fahv.bounds.domain.certified_range`): its alpha and theta between the range's
    bounds and q and the bending modes within its half-widths, all from the nominal
    vehicle's trim at the nominal's own (h, V). The QP keeps its prediction there
    (`fahv.control.mpc.settings.MPCSettings`, `x_box`), so the assumption holds by
    construction instead of being measured per run.

    Parameters
    ----------
    cert : SchedulingBox
        The certified range.

    Returns
    -------
    (2, 7) ndarray
        [lo, hi] of alpha, theta [rad], q [rad/s], eta_1, eta_1_dot [1/s], eta_2,
        eta_2_dot [1/s].

    Raises
    ------
    DesignError
        If the range does not hold the trim (lo < 0 < hi fails for a state).
    """
    box = np.array([np.r_[cert.lo[2:4], -cert.other_half], np.r_[cert.hi[2:4], cert.other_half]])
    if not (np.all(box[0] < 0.0) and np.all(box[1] > 0.0)):
        raise DesignError(
            f"certified range: it does not hold the trim in every state (lo {box[0].tolist()}, "
            f"hi {box[1].tolist()}): the tube fills the scheduling box"
        )
    return box
