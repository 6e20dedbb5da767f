"""The domains a one-step bound is taken over: the states, inputs, vehicles and faults.

W must bound the one-step disturbance over every state and input the closed loop can
reach. Two tube forms state that domain differently:

* the eight-state tube set (`tube.form: eight_state`) is linearised along the nominal
  over a **scheduling box** (`SchedulingBox`): the nominal points the vertices
  cover, s = (h, V, alpha - alpha_r, theta - theta_r, Phi - Phi_r, delta_e - delta_e,r)
  with the trim (x_r, u_r) at (h, V), and half-widths of q and the flexible states. The
  design's **nominal box** is the part the nominal MPC keeps (`nominal_box`); the
  error adds the **product set** {|e_h| <= H} x Z_8 (`product_supports`), so the
  scheduling box must hold the nominal box grown by it (`box_shortfall`); the
  nominal points the certificate covers are the scheduling box less the tube
  (`certified_range`);
* the paper's vertex tube (`tube.form: vertices`) is checked around the scheduling trim
  of the nominal MPC (`CertificateDomain`): scheduling points over the envelope,
  the nominal deviations the QP allows plus Z's supports, the inputs of the tightened set
  plus F Z, every corner of the sec. 5.1 parameter box, rho_f at both ends of
  [rho_min, 1].
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from fahv.errors import DesignError

#: Coordinates of the scheduling box (units: ft, ft/s, rad, rad, -, rad).
BOX_COORDINATES = ("h", "V", "alpha", "theta", "Phi", "delta_e")

#: Names of the scheduling box's half-widths (q [rad/s], then the flexible states).
OTHER_COORDINATES = ("q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")


@dataclass(frozen=True)
class SchedulingBox:
    """Nominal points a certificate along the nominal covers.

    Attributes
    ----------
    lo, hi : (6,) ndarray
        Bounds of s = (h [ft], V [ft/s], alpha - alpha_r [rad], theta - theta_r [rad],
        Phi - Phi_r [-], delta_e - delta_e,r [rad]), the last two of the applied input,
        (x_r, u_r) the nominal vehicle's trim at (h, V).
    other_half : (5,) ndarray
        Half-widths of the nominal's q [rad/s], eta_1, eta_1_dot [1/s], eta_2,
        eta_2_dot [1/s] deviations from the trim (their effect goes into W, linearly).

    Raises
    ------
    ValueError
        If a shape is wrong, a bound is not finite or lo > hi.
    """

    lo: np.ndarray
    hi: np.ndarray
    other_half: np.ndarray

    def __post_init__(self):
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        if lo.shape != (6,) or hi.shape != (6,) or np.asarray(self.other_half).shape != (5,):
            raise ValueError("scheduling box: lo, hi must have shape (6,), other_half (5,)")
        if not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) or np.any(lo > hi):
            raise ValueError(f"scheduling box: need finite lo <= hi, got {lo} and {hi}")

    def margin_to(self, inner: SchedulingBox) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How far this box reaches beyond `inner`, in the coordinates' units.

        Returns the lo side (6,), the hi side (6,) and other_half - inner.other_half (5,);
        negative where `inner` is not inside.
        """
        return (
            np.asarray(inner.lo, float) - np.asarray(self.lo, float),
            np.asarray(self.hi, float) - np.asarray(inner.hi, float),
            np.asarray(self.other_half, float) - np.asarray(inner.other_half, float),
        )

    def corners(self) -> np.ndarray:
        """The 64 corners (64, 6), in `itertools.product` order (lo first)."""
        return np.array(list(itertools.product(*zip(self.lo, self.hi, strict=True))))

    def points(self, trim_map, s) -> tuple[np.ndarray, np.ndarray]:
        """Nominal states (L, 9) and applied inputs (L, 2) of box points s (L, 6)."""
        s = np.atleast_2d(np.asarray(s, float))
        x_r, u_r = trim_map.at(s[:, 0], s[:, 1])
        X = np.array(x_r, float)[:, :9].copy()
        X[:, 2] += s[:, 2]
        X[:, 3] += s[:, 3]
        return X, np.array(u_r, float) + s[:, 4:6]

    def summary(self) -> dict:
        """JSON-ready record: `lo`, `hi`, `other_half` as lists."""
        return {
            "lo": np.asarray(self.lo).tolist(),
            "hi": np.asarray(self.hi).tolist(),
            "other_half": np.asarray(self.other_half).tolist(),
        }


def nominal_box(section: dict, envelope) -> tuple[SchedulingBox, SchedulingBox]:
    """The nominal box and the scheduling box of a design's `eight_state` section.

    Parameters
    ----------
    section : dict
        The validated `eight_state` section (`fahv.spec.schema`).
    envelope : fahv.model.envelope.Envelope
        The flight envelope (h, V ranges).

    Returns
    -------
    nominal, box : SchedulingBox
        The nominal's ranges (h, V: the envelope shrunk by the margins; attitude, input
        deviations from the trim and q, flexible half-widths as given) and the scheduling
        box: the envelope in h, V, the nominal ranges grown by `reach` elsewhere.

    Raises
    ------
    DesignError
        If the margins leave no nominal h or V range inside the envelope.
    """
    deg = np.pi / 180.0
    att = section["attitude"] * deg
    hm, Vm = section["h_margin"], section["V_margin"]
    if hm >= 0.5 * (envelope.h_max - envelope.h_min) or Vm >= 0.5 * (
        envelope.V_max - envelope.V_min
    ):
        raise DesignError(
            f"eight_state.h_margin {hm} / V_margin {Vm} leave no nominal range in the envelope"
        )
    lo = np.array([envelope.h_min + hm, envelope.V_min + Vm, -att, -att,
                   section["Phi"][0], section["delta_e"][0] * deg])  # fmt: skip
    hi = np.array([envelope.h_max - hm, envelope.V_max - Vm, att, att,
                   section["Phi"][1], section["delta_e"][1] * deg])  # fmt: skip
    other = np.asarray(section["other"], float) * np.r_[deg, np.ones(4)]
    nominal = SchedulingBox(lo, hi, other)
    r = np.asarray(section["reach"], float) * np.r_[deg, deg, 1.0, deg, deg, np.ones(4)]
    box = SchedulingBox(
        np.r_[envelope.h_min, envelope.V_min, lo[2:] - r[:4]],
        np.r_[envelope.h_max, envelope.V_max, hi[2:] + r[:4]],
        other + r[4:],
    )
    return nominal, box


def joint_shape(F_8, N_8) -> np.ndarray:
    """Joint shape of (e_8, u - v) over Z_8 under u - v = F_8 e_8: [I; F_8] N_8 [I; F_8]'.

    The set {(e_8, F_8 e_8) : e_8 in Z_8} is the degenerate ellipsoid of this shape: the
    support of r'(e_8, u - v) over it is sqrt(r' C r). A loop whose input deviation is
    not F_8 e_8 (the tube loop through the notch filter, u - v = K xi over an ellipsoid
    E(P) of xi = [e_8; chi]) has its own joint shape, [[I, 0], K] P [[I, 0], K]' (the
    `joint` argument of `product_supports` and of the one-step bounds of
    `fahv.bounds.one_step_bound`).

    Parameters
    ----------
    F_8 : (2, 8) array_like
        Ancillary gain on e_8.
    N_8 : (8, 8) array_like
        Shape of Z_8.

    Returns
    -------
    (10, 10) ndarray
        Rows and columns V ... eta_2_dot, then Phi [-] and delta_e [rad].

    Raises
    ------
    ValueError
        If the shapes are not (2, 8) and (8, 8).
    """
    F_8, N_8 = np.asarray(F_8, float), np.asarray(N_8, float)
    if F_8.shape != (2, 8) or N_8.shape != (8, 8):
        raise ValueError(f"joint_shape: F_8 {F_8.shape}, N_8 {N_8.shape}; expected (2, 8), (8, 8)")
    J = np.vstack([np.eye(8), F_8])
    return J @ N_8 @ J.T


def joint_of(F_8, N_8, joint=None) -> np.ndarray:
    """The joint shape of (e_8, u - v): `joint` checked, or the tube set's own.

    Parameters
    ----------
    F_8 : (2, 8) array_like
    N_8 : (8, 8) array_like
        The tube set (`joint_shape` when `joint` is None).
    joint : (10, 10) array_like, optional
        A loop's own joint shape; symmetrised.

    Returns
    -------
    (10, 10) ndarray

    Raises
    ------
    ValueError
        If `joint` is not a finite (10, 10) matrix, or the tube set is malformed.
    """
    if joint is None:
        return joint_shape(F_8, N_8)
    C = np.asarray(joint, float)
    if C.shape != (10, 10) or not np.all(np.isfinite(C)):
        raise ValueError(f"joint shape must be (10, 10) finite values, got {C.shape}")
    return 0.5 * (C + C.T)


def product_supports(F_8, N_8, H: float, joint=None) -> tuple[np.ndarray, np.ndarray]:
    """Supports of the product set {|e_h| <= H} x Z_8 in the scheduling box's coordinates.

    Parameters
    ----------
    F_8 : (2, 8) array_like
    N_8 : (8, 8) array_like
    H : float
        Altitude error bound [ft].
    joint : (10, 10) array_like, optional
        Joint shape of (e_8, u - v) in place of the tube set's (`joint_shape`).

    Returns
    -------
    s_lo : (6,) ndarray
        h [ft], V [ft/s], alpha, theta [rad], then the input deviation in Phi [-] and
        delta_e [rad] (F_8 Z_8 for the tube set).
    s_oth : (5,) ndarray
        q [rad/s] and the flexible states.

    Raises
    ------
    ValueError
        On a malformed `joint` or tube set.
    """
    s = np.sqrt(np.maximum(np.diag(joint_of(F_8, N_8, joint)), 0.0))
    return np.concatenate([[H], s[:3], s[8:]]), s[3:8]


def box_shortfall(box: SchedulingBox, nominal: SchedulingBox, F_8, N_8, H: float) -> dict:
    """Where the scheduling box does not hold the nominal box grown by the product set.

    The integral form of the one-step bound (`fahv.bounds.one_step_bound`) holds for
    every segment from a nominal point to the plant inside the scheduling box: the box
    must hold the nominal box grown by the supports of {|e_h| <= H} x Z_8 and F_8 Z_8.

    Parameters
    ----------
    box, nominal : SchedulingBox
        The scheduling box and the nominal box.
    F_8, N_8, H
        The tube set and its altitude bound, as in `product_supports`.

    Returns
    -------
    dict
        Coordinate name ("lo alpha", "hi Phi", "q", ...) to how far [coordinate units]
        the box falls short there; empty when it holds it.
    """
    s_lo, s_oth = product_supports(F_8, N_8, H)
    lo, hi, oth = box.margin_to(nominal)
    reach = np.r_[lo - s_lo, hi - s_lo, oth - s_oth]
    names = [f"{side} {c}" for side in ("lo", "hi") for c in BOX_COORDINATES]
    names += list(OTHER_COORDINATES)
    return {n: float(-v) for n, v in zip(names, reach, strict=True) if v < 0}


#: The design-file key that sets each coordinate's room in the scheduling box, and the
#: factor from the coordinate's units to the key's: (key, index or None, factor).
_ROOM_KEYS = {
    "h": ("eight_state.h_margin", None, 1.0), "V": ("eight_state.V_margin", None, 1.0),
    **{c: ("eight_state.reach", i, f) for i, (c, f) in enumerate(zip(
        ("alpha", "theta", "Phi", "delta_e", *OTHER_COORDINATES),
        (180 / np.pi, 180 / np.pi, 1.0, 180 / np.pi, 180 / np.pi, 1.0, 1.0, 1.0, 1.0),
        strict=True))},
}  # fmt: skip


def shortfall_fixes(short: dict, box: SchedulingBox, nominal: SchedulingBox) -> list[str]:
    """For each coordinate `box_shortfall` names, the design-file key and a value that holds.

    A side of h or V is short when the nominal's range comes too near the envelope's edge:
    `eight_state.h_margin` / `V_margin` must grow by the shortfall. Any other coordinate
    is short when the scheduling box reaches too little beyond the nominal box:
    `eight_state.reach[i]` must grow by it (in the key's units: deg for the attitude, the
    elevator and q). The value given is the shortfall added to the box's reach now, 1 %
    more, rounded up at the fourth significant digit.

    Parameters
    ----------
    short : dict
        `box_shortfall`'s {coordinate: shortfall [coordinate units]}.
    box, nominal : SchedulingBox
        The scheduling box and the nominal box the design made.

    Returns
    -------
    list of str
        One sentence per coordinate, e.g. `eight_state.reach[7] (eta_2) to at least 0.2453
        (now 0.24)`; the stronger side where both sides of a coordinate are short.
    """
    lo, hi, oth = box.margin_to(nominal)
    now = {**{f"lo {c}": v for c, v in zip(BOX_COORDINATES, lo, strict=True)},
           **{f"hi {c}": v for c, v in zip(BOX_COORDINATES, hi, strict=True)},
           **dict(zip(OTHER_COORDINATES, oth, strict=True))}  # fmt: skip
    need: dict[str, tuple[float, float, str]] = {}
    for name, gap in short.items():
        coord = name.split()[-1]
        key, i, factor = _ROOM_KEYS[coord]
        value = (now[name] + gap) * factor  # the room on that side grows by the gap
        label = f"{key}[{i}] ({coord})" if i is not None else key
        if label not in need or value > need[label][0]:
            need[label] = (value, now[name] * factor, coord)
    out = []
    for label, (value, have, _) in need.items():
        target = float(np.format_float_positional(value * 1.01, precision=4, unique=False,
                                                  fractional=False, trim="-"))  # fmt: skip
        out.append(f"{label} to at least {target:g} (now {have:.4g})")
    return out


def certified_range(box: SchedulingBox, F_8, N_8, H: float) -> SchedulingBox:
    """The nominal points the tube set's certificate covers: the scheduling box less the tube.

    The vertices and W_8's bound hold for every segment from a nominal point to the plant
    inside the scheduling box (the integral form, `fahv.bounds.one_step_bound`), so
    the certificate needs the nominal inside the box shrunk by the product set's
    supports (H in h, Z_8's in the states, F_8 Z_8's in the inputs); the nominal box of
    the design is a part of it (`box_shortfall` checks that).

    Parameters
    ----------
    box : SchedulingBox
        The scheduling box (coordinates `BOX_COORDINATES`, then q and the
        flexible states as half-widths).
    F_8, N_8, H
        The tube set and its altitude bound, as in `product_supports`.

    Returns
    -------
    SchedulingBox
        The certified nominal range in the same coordinates.

    Raises
    ------
    ValueError
        If the tube does not fit inside the box in some coordinate (an empty range).
    """
    s_lo, s_oth = product_supports(F_8, N_8, H)
    lo, hi, oth = box.lo + s_lo, box.hi - s_lo, box.other_half - s_oth
    if np.any(lo > hi) or np.any(oth < 0.0):
        raise ValueError(
            "certified range: the tube does not fit inside the scheduling box (supports "
            f"{s_lo.tolist()}, {s_oth.tolist()})"
        )
    return SchedulingBox(lo, hi, oth)


@dataclass(frozen=True)
class CertificateDomain:
    """The set of states, inputs, vehicles and faults the vertex tube's certificate assumes.

    Attributes
    ----------
    schedules : (S, 2) ndarray
        Scheduling points (h, V) [ft, ft/s] of the nominal model: the corners and the
        centre of the envelope grid.
    x_half : (9,) ndarray
        Half-widths of x - x_rs: the nominal deviation the nominal MPC allows from its
        scheduling trim plus Z's supports [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s].
    nominal_half : (9,) ndarray
        The nominal part of `x_half` (without Z), for the report.
    u_lo, u_hi : (2,) ndarray
        Absolute input range [Phi, delta_e rad]: the tightened nominal set plus the
        support of tau F Z (the actuator limits when the design is consistent).
    uncertainty : dict[str, float]
        Relative bounds of the parameter box; every corner is evaluated.
    rho : tuple of float
        Elevator effectiveness values evaluated (the ends of [rho_min, 1]).
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period (the plant's).
    notes : tuple of str
        Assumptions stated with the domain (what is assumed, not derived).
    """

    schedules: np.ndarray
    x_half: np.ndarray
    nominal_half: np.ndarray
    u_lo: np.ndarray
    u_hi: np.ndarray
    uncertainty: dict
    rho: tuple
    Ts: float
    n_sub: int
    notes: tuple = field(default=())

    def corners(self) -> np.ndarray:
        """Every corner of the parameter box, (2^P, P) signs in {-1, +1}."""
        return np.array(list(itertools.product((-1.0, 1.0), repeat=len(self.uncertainty))))

    def summary(self) -> dict:
        """JSON-ready record: the schedules, ranges, rho and the assumptions."""
        return {
            "schedules": self.schedules.tolist(),
            "x_half": self.x_half.tolist(),
            "nominal_half": self.nominal_half.tolist(),
            "u_lo": self.u_lo.tolist(),
            "u_hi": self.u_hi.tolist(),
            "rho": list(self.rho),
            "assumptions": list(self.notes),
        }


def nominal_half_widths(mpc: dict, x_default: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Nominal deviation from the scheduling trim that the nominal MPC allows (9,).

    h and V: the rescheduling threshold plus half a set-point move (the nominal model
    is re-scheduled at a plan when its h, V left the threshold; between plans it moves
    on); alpha, theta: the attitude rows of the QP (`mpc.att_max`, from the nominal
    trim) plus the same margin as h, V of the trim map's slope; q and the flexible
    states: `x_default` (no QP row bounds them: stated as an assumption).

    Parameters
    ----------
    mpc : dict
        The design's `mpc` section (`reschedule`, `dtheta_max`, `att_max`).
    x_default : (9,) array_like
        Assumed half-widths of the states no QP row bounds.

    Returns
    -------
    (9,) ndarray, tuple of str
        Half-widths and the assumptions made.
    """
    half = np.array(x_default, float).copy()
    resched = np.asarray(mpc["reschedule"], float)
    dmove = np.asarray(mpc["dtheta_max"], float)
    half[0] = resched[0] + 0.5 * dmove[0]
    half[1] = resched[1] + 0.5 * dmove[1]
    att = np.radians(mpc["att_max"]) + np.radians(0.05)
    half[2] = half[3] = att
    notes = (
        "h, V: rescheduling threshold + half a set-point move",
        "alpha, theta: attitude rows of the QP + 0.05 deg of trim-map slope",
        "q, eta_i, eta_i_dot: nominal deviations assumed within "
        + ", ".join(f"{v:.3g}" for v in half[4:])
        + " (no QP row bounds them)",
    )
    return half, notes


def schedule_points(envelope, count: int) -> np.ndarray:
    """Scheduling points of the vertex tube's domain (count, 2) [ft, ft/s].

    1: the envelope centre; 3: the centre and two opposite corners; 9: the 3 x 3 grid
    of corners, edge midpoints and centre.

    Raises
    ------
    ValueError
        For another count.
    """
    hs = (envelope.h_min, 0.5 * (envelope.h_min + envelope.h_max), envelope.h_max)
    Vs = (envelope.V_min, 0.5 * (envelope.V_min + envelope.V_max), envelope.V_max)
    grid = np.array([[h, V] for h in hs for V in Vs])
    picks = {1: [4], 3: [0, 4, 8], 9: list(range(9))}
    if count not in picks:
        raise ValueError(f"certificate.schedules must be 1, 3 or 9, got {count}")
    return grid[picks[count]]
