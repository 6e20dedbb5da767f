"""Settings of the nominal tracking MPC: the case file's `mpc` section and its typed form.

`MPC_SECTION_FIELDS` are the keys of the case file's `mpc` section (horizon,
rates, weights, the disturbance estimate's time constants, the nominal model);
`MPCSettings` is what one `fahv.control.mpc.tracking.TrackingMPC` is
built with, read from the nominal_trajectory node's `mpc.*` parameters; the functions
below turn the box and rate parameters (`mpc.u_box`, `mpc.hv_box`, `mpc.x_box`,
`mpc.du_max`) into the QP's bounds, checking them at the boundary.

The horizon is that of the tracking MPC with an artificial steady state of Limon et al.
(2010, "Robust tube-based MPC for tracking"): N_p moves of M fast steps each, an offset
cost on the set point, and a trust region on its step. The input bounds apply to the
tightened set of eq. (30) of Yang et al. (2022); the nominal model is the LPV model of
eq. (12) or the CM of eq. (1)-(3).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from fahv.config import Field

#: Design-file section of the nominal tracking MPC (all keys defaulted; docs/theory/nominal_mpc.md).
MPC_SECTION_FIELDS = (
    Field("M", "int", "fast steps per nominal move: nominal rate Ts_n = M Ts", lo=1,
          hi=1000, default=25),
    Field("N_p", "int", "moves in the prediction horizon (horizon N_p M Ts)", lo=2, hi=200,
          default=30),
    Field("q_w", "floats", "state weights (h, V, alpha, theta, q, eta_1, eta_1_dot, eta_2, "
          "eta_2_dot) per scale unit", lo=0.0, length=9,
          default=(1.0, 1.0, 0.1, 0.1, 0.01, 0.0, 0.0, 0.0, 0.0)),
    Field("r_w", "floats", "move weights (Phi, delta_e) per scale unit", lo=0.0,
          lo_open=True, length=2, default=(1.0, 1.0)),
    Field("t_w", "floats", "offset-cost weights on (h_s - h_c, V_s - V_c) per "
          "(100 ft, 100 ft/s)", lo=0.0, lo_open=True, length=2, default=(1e4, 1e4)),
    Field("dtheta_max", "floats", "largest set-point move per nominal step", unit="ft, ft/s",
          lo=0.0, lo_open=True, length=2, default=(300.0, 150.0)),
    Field("reschedule", "floats", "set-point distance that rebuilds the QP", unit="ft, ft/s",
          lo=0.0, lo_open=True, length=2, default=(100.0, 50.0)),
    Field("att_max", "float", "bound on the nominal |alpha - alpha_r|, |theta - theta_r| "
          "(from the nominal trim) at every fast step of the next two moves and at each later "
          "move; 0: the certified bound, the attitude requirement (0.5 deg) minus the "
          "support of Z in alpha and theta (docs/theory/certificate.md); a value above it is "
          "used but reported as not certified", unit="deg", lo=0.0, hi=10.0, default=0.0),
    Field("est_tau", "float", "time constant of the state-disturbance estimate (0: none)",
          unit="s", lo=0.0, hi=1e3, default=0.5),
    Field("est_tau_elevator", "float", "time constant of the estimate along the elevator "
          "column of the scheduled model's B (the direction a loss of effectiveness or an "
          "elevator bias acts in; Ts: the share of the residual along it is taken in one "
          "step); 0: est_tau in every direction (docs/theory/certificate.md)", unit="s", lo=0.0,
          hi=1e3, default=0.0),
    Field("du_max", "floats", "largest change of the nominal input (Phi, delta_e) at a move "
          "start: between consecutive moves of the plan and, at a re-plan, from the nominal "
          "input applied at the step before (0: no rate rows); bounds how fast the residual "
          "the disturbance estimate filters can move (docs/theory/nominal_mpc.md)",
          unit="-, deg", lo=0.0, length=2, default=(0.0, 0.0)),
    Field("nominal_model", "str", "model the nominal state moves by: 'lpv' (the scheduled "
          "LPV model, eq. 12) or 'cm' (the nonlinear CM of the nominal vehicle, eq. 1-3, so "
          "that the tube error is linearised along the nominal, not at the scheduling trim)",
          choices=("lpv", "cm"), default="lpv"),
    Field("h_reset", "bool", "reset the nominal's altitude to the measured one at every "
          "re-plan (before the QP), so that the altitude error e_h = h - h_r - h_n returns to "
          "0 every M steps and the tube need not hold the kinematic integrator h "
          "(docs/theory/nominal_mpc.md, 'The altitude reset')", default=False),
)  # fmt: skip


@dataclass(frozen=True)
class MPCSettings:
    """Horizon, rates and weights of the nominal MPC (docs/theory/nominal_mpc.md).

    Attributes
    ----------
    M : int
        Fast steps per nominal move (nominal rate Ts_n = M Ts).
    N_p : int
        Moves in the prediction horizon (horizon N_p M Ts seconds).
    q_w : (n,) ndarray
        State weights, per scale unit of the design scaling Dx.
    r_w : (m,) ndarray
        Move weights, per scale unit of Du.
    t_w : (2,) ndarray
        Offset-cost weights on (h_s - h_c, V_s - V_c) per (100 ft, 100 ft/s).
    dtheta_max : (2,) ndarray
        Largest move of the artificial set point per nominal step [ft, ft/s].
    reschedule : (2,) ndarray
        Distance of the nominal (h, V) from the scheduling point that triggers a
        rebuild [ft, ft/s].
    att_max : (2,) ndarray
        Bounds on the nominal |alpha - alpha_s| and |theta - theta_s| [rad] (the
        attitude requirement minus the support of the tube in alpha, theta), at every
        fast step of the first `fine_moves` moves and at the start of every later one.
    fine_moves : int
        Moves whose attitude and inputs are bounded at every fast step (the move the
        plan applies before the next re-plan, and the one a shifted plan applies).
    nominal_model : str
        'lpv' or 'cm': what the nominal state moves by
        (`fahv.control.mpc.nominal_source.TrackingMPCNominal`).
    du_max : (2,) ndarray
        Largest change of the nominal input at a move start [Phi, delta_e rad]: rows on
        the jump between consecutive moves of the plan and, at a re-plan, on the jump from
        the nominal input applied at the previous fast step
        (`fahv.control.mpc.tracking.TrackingMPC.solve`); inf (the default,
        `mpc.du_max` 0): no rate rows.
    h_reset : bool
        Reset the nominal's altitude to the measured one at every re-plan
        (`fahv.control.mpc.nominal_source.TrackingMPCNominal`).
    u_box : (2, 2) ndarray or None
        Rows [lo, hi] on the manoeuvre part of the nominal input [Phi, delta_e rad], the
        input minus the steady input of the set point (its trim plus the estimate's
        shift u_d), K zeta + c, at every move start and every fast step of the first
        `fine_moves` moves: the eight-state tube's nominal box less the box corners'
        trim offsets (the plant applies its own trim at steady state, whatever its loss
        or bias; `fahv.tube.rows`); None (`mpc.u_box` all 0): no rows.
    hv_box : (2, 2) ndarray or None
        `[[h lo, V lo], [h hi, V hi]]` in ft, ft/s: the nominal's altitude and speed range
        the design assumed (the eight-state tube's nominal box, the envelope less
        `eight_state.h_margin` / `V_margin`): the artificial set point stays in it
        (the recovery's too) and rows keep the predicted nominal in it at the attitude
        rows' steps; None (`mpc.hv_box` all 0): the set point anywhere on the trim map.
    x_box : (2, 7) ndarray or None
        [lo, hi] of the nominal's alpha, theta [rad], q [rad/s], eta_1, eta_1_dot [1/s],
        eta_2, eta_2_dot [1/s] as deviations from the nominal vehicle's trim at the
        nominal's own (h, V): the range the tube's certificate covers
        (`fahv.bounds.domain.certified_range`). Rows keep the predicted nominal
        in it at the attitude rows' steps, with the trim at its own (h, V) linearised at
        the scheduling point (`T = Gx[2:9] Gx[0:2]^-1`), widened only to hold the start;
        None (`mpc.x_box` all 0): no rows.
    """

    M: int
    N_p: int
    q_w: np.ndarray
    r_w: np.ndarray
    t_w: np.ndarray
    dtheta_max: np.ndarray
    reschedule: np.ndarray
    att_max: np.ndarray = dataclasses.field(default_factory=lambda: np.full(2, math.inf))
    fine_moves: int = 2
    nominal_model: str = "lpv"
    du_max: np.ndarray = dataclasses.field(default_factory=lambda: np.full(2, math.inf))
    h_reset: bool = False
    u_box: np.ndarray | None = None
    hv_box: np.ndarray | None = None
    x_box: np.ndarray | None = None

    @functools.cached_property
    def has_rate_rows(self) -> bool:
        """True if the QP carries the rate rows of `du_max` (read at every re-plan)."""
        return bool(np.all(np.isfinite(self.du_max)))

    @classmethod
    def of_parameters(cls, p: dict, n: int) -> MPCSettings:
        """Settings of a nominal_trajectory node's `mpc.*` parameters.

        Parameters
        ----------
        p : dict
            Validated node parameters; the keys under `mpc.` are read (`att_max` in
            deg, the boxes and rates as `input_box`, `range_box`,
            `state_box`, `rate_limits`).
        n : int
            Design states (the state weights after the ninth are 0).

        Returns
        -------
        MPCSettings

        Raises
        ------
        ValueError
            If a box or rate parameter is invalid (names the parameter).
        """
        m = {k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("mpc.")}
        q_w = np.concatenate([np.asarray(m["q_w"], float), np.zeros(n - 9)])
        return cls(
            int(m["M"]), int(m["N_p"]), q_w, np.asarray(m["r_w"], float),
            np.asarray(m["t_w"], float), np.asarray(m["dtheta_max"], float),
            np.asarray(m["reschedule"], float),
            np.radians(np.broadcast_to(np.asarray(m["att_max"], float), (2,))).copy(),
            nominal_model=str(m.get("nominal_model", "lpv")),
            du_max=rate_limits(m.get("du_max", (0.0, 0.0))),
            h_reset=bool(m.get("h_reset", False)),
            u_box=input_box(m.get("u_box", (0.0, 0.0, 0.0, 0.0))),
            hv_box=range_box(m.get("hv_box", (0.0, 0.0, 0.0, 0.0))),
            x_box=state_box(m.get("x_box", (0.0,) * 14)),
        )  # fmt: skip


def _box_values(value, n: int, name: str) -> np.ndarray | None:
    """A box node parameter `name` as (n,) finite floats; None if all are 0 (no rows).

    Raises
    ------
    ValueError
        If it is not n finite numbers (names the parameter and the value).
    """
    v = np.asarray(value, float)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be {n} finite numbers, got {value!r}")
    return None if np.all(v == 0.0) else v


def input_box(u_box) -> np.ndarray | None:
    """`mpc.u_box` (Phi lo, Phi hi, delta_e lo, delta_e hi [deg]; all 0: none) as rows.

    Parameters
    ----------
    u_box : (4,) array_like
        The node parameter [-, -, deg, deg].

    Returns
    -------
    (2, 2) ndarray or None
        `[[Phi lo, delta_e lo], [Phi hi, delta_e hi]]` in -, rad; None for all zeros.

    Raises
    ------
    ValueError
        If it is not four finite numbers with lo < 0 < hi for both inputs (the trim
        itself must lie inside).
    """
    v = _box_values(u_box, 4, "mpc.u_box")
    if v is None:
        return None
    if not (v[0] < 0.0 < v[1] and v[2] < 0.0 < v[3]):
        raise ValueError(f"mpc.u_box needs lo < 0 < hi for Phi and delta_e, got {u_box!r}")
    return np.array([[v[0], np.radians(v[2])], [v[1], np.radians(v[3])]])


def range_box(hv_box) -> np.ndarray | None:
    """`mpc.hv_box` (h lo, h hi [ft], V lo, V hi [ft/s]; all 0: none) as bounds.

    Parameters
    ----------
    hv_box : (4,) array_like
        The node parameter [ft, ft, ft/s, ft/s].

    Returns
    -------
    (2, 2) ndarray or None
        [[h lo, V lo], [h hi, V hi]]; None for all zeros.

    Raises
    ------
    ValueError
        If it is not four finite numbers with lo < hi for h and V.
    """
    v = _box_values(hv_box, 4, "mpc.hv_box")
    if v is None:
        return None
    if not (v[0] < v[1] and v[2] < v[3]):
        raise ValueError(f"mpc.hv_box needs h lo < h hi and V lo < V hi, got {hv_box!r}")
    return np.array([[v[0], v[2]], [v[1], v[3]]])


#: States of `mpc.x_box` (design order 2..8) and their node-parameter units.
X_BOX_STATES = ("alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")
#: Factor from the node parameter's units (deg, deg, deg/s, -, 1/s, -, 1/s) to the state's.
X_BOX_TO_STATE = np.array([math.radians(1.0)] * 3 + [1.0] * 4)


def state_box(x_box) -> np.ndarray | None:
    """`mpc.x_box` (7 lows then 7 highs; all 0: none) as the QP's state range rows.

    The values are the nominal's alpha, theta [deg], q [deg/s], eta_1, eta_1_dot [1/s],
    eta_2, eta_2_dot [1/s] as deviations from the nominal vehicle's trim at its own
    (h, V) (`X_BOX_STATES`).

    Parameters
    ----------
    x_box : (14,) array_like
        The node parameter: 7 lows, then 7 highs.

    Returns
    -------
    (2, 7) ndarray or None
        [lo, hi] in the states' units (rad, rad/s, ...); None for all zeros.

    Raises
    ------
    ValueError
        If it is not 14 finite numbers with lo < 0 < hi for every state (the trim
        itself must lie inside).
    """
    v = _box_values(x_box, 14, "mpc.x_box (7 lows, 7 highs)")
    if v is None:
        return None
    box = v.reshape(2, 7)
    if not (np.all(box[0] < 0.0) and np.all(box[1] > 0.0)):
        raise ValueError(
            f"mpc.x_box needs lo < 0 < hi for every state {X_BOX_STATES}, got {x_box!r}"
        )
    return box * X_BOX_TO_STATE


def rate_limits(du_max) -> np.ndarray:
    """`mpc.du_max` (Phi, delta_e deg; 0: none) as the QP's rate bounds (2,) [-, rad].

    Parameters
    ----------
    du_max : (2,) array_like
        The node parameter [-, deg].

    Returns
    -------
    (2,) ndarray
        [Phi, delta_e rad]; inf in both for (0, 0) (no rate rows).

    Raises
    ------
    ValueError
        If it is not two non-negative finite numbers, or only one of them is 0 (a rate
        row on one input only is not a design the certificate can use).
    """
    v = np.asarray(du_max, float)
    if v.shape != (2,) or not np.all(np.isfinite(v)) or np.any(v < 0.0):
        raise ValueError(f"mpc.du_max must be two non-negative numbers (Phi, deg), got {du_max!r}")
    if np.all(v == 0.0):
        return np.full(2, math.inf)
    if np.any(v == 0.0):
        raise ValueError(f"mpc.du_max: give both rates or none (0, 0), got {du_max!r}")
    return np.array([v[0], math.radians(v[1])])
