"""Attitude rows of the nominal QP: the requirement less the tube's support.

The plant's attitude deviation from the set point's trim is the nominal one plus the
tube error, so the nominal QP bounds |alpha_n - alpha_r| and |theta_n - theta_r| by the
attitude requirement of sec. 5.1 of Yang et al. (2022) (0.5 deg) minus the support of
the tube Z (the robust invariant set of eq. 25-26) along alpha and theta.
`attitude_bounds` computes those bounds from the tube shape; `AttitudeBounds`
holds them with the line the design log prints (certified or not, and by how much).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.errors import DesignError


@dataclass(frozen=True)
class AttitudeBounds:
    """Attitude rows of the nominal QP against the requirement (`attitude_bounds`).

    Attributes
    ----------
    support : (2,) ndarray
        Support of the tube Z along alpha and theta, sqrt(N_jj) [rad].
    certified : (2,) ndarray
        Requirement minus support [rad]: the largest nominal deviation for which
        nominal + tube stays within the requirement (may be negative).
    used : (2,) ndarray
        Bounds the QP uses [rad]: `certified` by default, or the case's value.
    given : bool
        Whether the case gave the bound (`mpc.att_max` > 0).
    trim_offset : float
        Largest attitude offset of a parameter-box corner's own trim from the nominal
        trim [rad] (0: not known). The nominal must hold it at steady state; where it
        exceeds the rows, the QP widens them to the plant's own trim
        (`fahv.control.mpc.tracking.TrackingMPC.solve`, `x_off`), beyond what
        the certificate covers.
    """

    support: np.ndarray
    certified: np.ndarray
    used: np.ndarray
    given: bool
    trim_offset: float = 0.0

    @property
    def rows_fit(self) -> bool:
        """True if the rows leave the tube's support inside the requirement."""
        return bool(np.all(self.used <= self.certified + 1e-12))

    @property
    def is_certified(self) -> bool:
        """True if the rows keep nominal + tube within the requirement at every trim.

        The rows must leave the tube's support inside the requirement and hold every box
        corner's own trim (so they are never widened at steady state).
        """
        return self.rows_fit and bool(np.all(self.trim_offset <= self.used + 1e-12))

    def report(self) -> str:
        """One line for the design log: support, certified and used bounds, what is left."""
        sup, cer, use = (np.degrees(v) for v in (self.support, self.certified, self.used))
        trim_offset = self.trim_offset
        left = use - np.degrees(trim_offset)
        head = (
            f"attitude (requirement {ATTITUDE_BOUND_DEG} deg): support of Z "
            f"{sup[0]:.3f} / {sup[1]:.3f} deg (alpha / theta), certified nominal bound "
            f"{cer[0]:.3f} / {cer[1]:.3f} deg; QP rows at {use[0]:.3f} / {use[1]:.3f} deg"
        )
        if trim_offset > 0.0:
            head += (
                f", of which the parameter box's trim offset takes up to "
                f"{np.degrees(trim_offset):.3f} deg (left for manoeuvres {left[0]:.3f} / "
                f"{left[1]:.3f} deg)"
            )
        if self.is_certified:
            return head + ": attitude requirement follows from the certificate  OK"
        if self.rows_fit:
            return (
                head + f": NOT certified (the box's trim offset exceeds the rows, which then "
                f"widen to the plant's own trim; offset + support reaches "
                f"{np.degrees(trim_offset) + sup[0]:.3f} / "
                f"{np.degrees(trim_offset) + sup[1]:.3f} deg)"
            )
        return (
            head + f": NOT certified (the case's mpc.att_max exceeds the certified bound; "
            f"nominal + support reaches {use[0] + sup[0]:.3f} / {use[1] + sup[1]:.3f} deg)"
        )


def attitude_bounds(N, att_max_deg: float = 0.0, trim_offset: float = 0.0) -> AttitudeBounds:
    """Bounds of the nominal QP's attitude rows from the tube and the requirement.

    The plant's attitude deviation from the set point's trim is the nominal one plus
    the tube error: |alpha - alpha_r| <= |alpha_n - alpha_r| + max_{e in Z} |e_alpha|,
    and max_Z |e_j| = sqrt(N_jj) (Z = {e' N^-1 e <= 1}). With the nominal rows at
    ATTITUDE_BOUND_DEG - sqrt(N_jj) the requirement of sec. 5.1 follows from e in Z.
    The adjustable law (tau < 1) changes nothing here: for the whole W its error stays
    in Z (the tube LMI covers every gain tau' F, tau' in [tau, 1]); eq. (53)'s smaller
    tau Z holds only for the incomplete set W' of eq. (47).

    Parameters
    ----------
    N : (n, n) array_like
        Tube shape (state order h, V, alpha, theta, ...; rad).
    att_max_deg : float
        The case's `mpc.att_max` [deg]; 0 uses the certified bound.
    trim_offset : float
        Largest attitude offset of a box corner's trim from the nominal trim [rad]
        (`AttitudeBounds.trim_offset`; 0: not checked).

    Returns
    -------
    AttitudeBounds

    Raises
    ------
    DesignError
        If the bounds used are not positive (the tube's support alone exceeds the
        requirement and the case gives no bound).
    """
    N = np.asarray(N, float)
    support = np.sqrt(np.diag(N)[2:4])
    certified = np.radians(ATTITUDE_BOUND_DEG) - support
    given = att_max_deg > 0.0
    used = np.full(2, np.radians(att_max_deg)) if given else certified.copy()
    if np.any(used <= 0.0):
        raise DesignError(
            f"attitude: the support of Z in alpha / theta, "
            f"{np.degrees(support[0]):.3f} / {np.degrees(support[1]):.3f} deg, leaves no "
            f"nominal bound within the requirement {ATTITUDE_BOUND_DEG} deg; give "
            "mpc.att_max (then reported as not certified) or shrink the tube"
        )
    return AttitudeBounds(support, certified, used, given, float(trim_offset))
