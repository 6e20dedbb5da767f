"""Online nominal MPC for tracking (a QP) with a state-disturbance estimate, over B runs.

The nominal part of the tube-based MPC of Mayne, Seron and Rakovic (2005), in the
tracking form of Limon et al. (2010, "Robust tube-based MPC for tracking"), on the
nominal LPV model of eq. (12) scheduled at the current operating point:

* **Artificial steady state.** The QP chooses, besides the nominal moves, a step
  delta = (dh_s, dV_s) of the artificial set point theta = (h_s, V_s) along the trim
  map; x_s = G_x delta, u_s = G_u delta (the trim map's Jacobian at the scheduling
  point). An offset cost (theta - c)' T (theta - c) pulls theta to the command c, so a
  large step is fed in as fast as the constraints allow; no reference governor.
* **Pre-stabilised, move-blocked predictions.** u = u_s + K (z - x_s) + c_j with the
  certified nominal gain K of LMIs (33)-(35) at the fast rate Ts, and a move c_j held
  for M steps (nominal rate Ts_n = M Ts), j = 0..N_p-1: zeta = z - x_s obeys
  zeta+ = (A + B K) zeta + B c_j + E delta (E = (A - I) G_x + B G_u, zero on the exact
  linear steady-state manifold). The condensed QP is well conditioned although the
  open-loop model is unstable.
* **Constraints.** The nominal input at each move start lies in the tightened
  *asymmetric* set [u_min + t, u_max - t] (t the support of tau F Z, eq. 30), written
  in absolute inputs: 0 <= Phi <= 1.5 and |delta_e| <= 30 deg minus t. Terminal set:
  zeta_{N_p} in alpha E(Q), with E(Q) the invariant ellipsoid of LMIs (33)-(35) (terminal
  law K), entered as its inscribed box |L^-1 zeta_{N_p}|_inf <= alpha / sqrt(n) (Q = L L'),
  and the steady input u_s with a margin alpha * sqrt(K_j Q K_j') from the tightened
  limits, 0 <= alpha <= 1 (the lambda-scaled terminal set of Limon et al.).
* **Terminal cost.** zeta_{N_p}' P zeta_{N_p} with P the tail cost of the blocked model under K
  (discrete Lyapunov equation), i.e. the exact infinite-horizon cost once c = 0.
* **Recovery and fallback.** If the solver does not return a solution that passes
  the numerical check (constraints and KKT conditions), the recovery QP is solved: the
  same rows without the trust region on the set-point step, so the artificial set
  point may move in one re-plan to wherever on the trim map its steady input fits the
  tightened limits (the trust region only keeps the map's linearisation local). If that
  fails too, the shifted previous plan is used (its tail stays in the invariant E(Q));
  when none is left, the terminal law c = 0. Each is counted.

The state disturbance estimate d (:class:`DisturbanceEstimator`, p states) makes the
tracking offset-free and takes the constant part out of the tube's W: the nominal
model is z+ = A z + B u + d, and its steady state at the set point moves by
(x_d, u_d) = (H_x d, H_u d), the solution of (A - I) x_d + B u_d + d = 0 with
h_d = V_d = 0 (n equations, n unknowns; :meth:`TrackingMPC.schedule`). A loss of
elevator effectiveness rho_f gives u_d = -(rho_f - 1) delta_e,r (exactly, since its
d lies along the elevator column of B); parameter uncertainty shifts the trim.

Batch
    :class:`TrackingMPCNominal` runs B runs at once: the fast step (estimator,
    plan interpolation, nominal model, output) is one numpy computation over the
    batch, whose per-run items are the BLAS calls of one run's computation, so a
    run's numbers do not depend on its batch; the re-plans (one QP per run every M
    steps) are a loop over the runs, each with its own :class:`TrackingMPC`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from fahv.config import Field, Section
from fahv.control.base import ATTITUDE_BOUND_DEG, NominalSource, register_nominal
from fahv.control.command import Command, CommandSchedule
from fahv.control.reference import lpv_of, mv, trim_map_of
from fahv.errors import DesignError, RunError
from fahv.lanes import Lanes
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.vehicle import load_vehicle
from fahv.msg import NominalTrajectory
from fahv.plant.rk4 import params_records, rk4_cm
from fahv.synthesis.qp import NO_BOUND, check_kkt

#: Solver status of a successful DAQP solve.
_DAQP_OPTIMAL = (1, 2)


def _daqp():
    import daqp

    return daqp


#: Case-file section of the nominal tracking MPC (all keys defaulted; docs/control_design.md).
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
          "support of Z in alpha and theta (docs/control_design.md); a value above it is "
          "used but reported as not certified", unit="deg", lo=0.0, hi=10.0, default=0.0),
    Field("est_tau", "float", "time constant of the state-disturbance estimate (0: none)",
          unit="s", lo=0.0, hi=1e3, default=0.5),
    Field("est_tau_elevator", "float", "time constant of the estimate along the elevator "
          "column of the scheduled model's B (the direction a loss of effectiveness or an "
          "elevator bias acts in; Ts: the share of the residual along it is taken in one "
          "step); 0: est_tau in every direction (docs/control_design.md)", unit="s", lo=0.0,
          hi=1e3, default=0.0),
    Field("du_max", "floats", "largest change of the nominal input (Phi, delta_e) at a move "
          "start: between consecutive moves of the plan and, at a re-plan, from the nominal "
          "input applied at the step before (0: no rate rows); bounds how fast the residual "
          "the disturbance estimate filters can move (docs/control_design.md)",
          unit="-, deg", lo=0.0, length=2, default=(0.0, 0.0)),
    Field("nominal_model", "str", "model the nominal state moves by: 'lpv' (the scheduled "
          "LPV model, eq. 12) or 'cm' (the nonlinear CM of the nominal vehicle, eq. 1-3, so "
          "that the tube error is linearised along the nominal, not at the scheduling trim)",
          choices=("lpv", "cm"), default="lpv"),
    Field("h_reset", "bool", "reset the nominal's altitude to the measured one at every "
          "re-plan (before the QP), so that the altitude error e_h = h - h_r - h_n returns to "
          "0 every M steps and the tube need not hold the kinematic integrator h "
          "(docs/control_design.md, 'The altitude reset')", default=False),
)  # fmt: skip


@dataclass(frozen=True)
class MPCSettings:
    """Horizon, rates and weights of the nominal MPC (docs/control_design.md).

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
        fast step of the first ``fine_moves`` moves and at the start of every later one.
    fine_moves : int
        Moves whose attitude and inputs are bounded at every fast step (the move the
        plan applies before the next re-plan, and the one a shifted plan applies).
    nominal_model : str
        'lpv' or 'cm': what the nominal state moves by (:class:`TrackingMPCNominal`).
    du_max : (2,) ndarray
        Largest change of the nominal input at a move start [Phi, delta_e rad]: rows on
        the jump between consecutive moves of the plan and, at a re-plan, on the jump from
        the nominal input applied at the previous fast step (:meth:`TrackingMPC.solve`);
        inf (the default, ``mpc.du_max`` 0): no rate rows.
    h_reset : bool
        Reset the nominal's altitude to the measured one at every re-plan
        (:class:`TrackingMPCNominal`).
    u_box : (2, 2) ndarray or None
        Rows [lo, hi] on the manoeuvre part of the nominal input [Phi, delta_e rad], the
        input minus the steady input of the set point (its trim plus the estimate's
        shift u_d), K zeta + c, at every move start and every fast step of the first
        ``fine_moves`` moves: the eight-state tube's nominal box less the box corners'
        trim offsets (the plant applies its own trim at steady state, whatever its loss
        or bias; :mod:`fahv.design.eight_state`); None (``mpc.u_box`` all 0): no rows.
    hv_box : (2, 2) ndarray or None
        [[h lo, V lo], [h hi, V hi]] [ft, ft/s]: the nominal's altitude and speed range
        the design assumed (the eight-state tube's nominal box, the envelope less
        ``eight_state.h_margin`` / ``V_margin``): the artificial set point stays in it
        (the recovery's too) and rows keep the predicted nominal in it at the attitude
        rows' steps; None (``mpc.hv_box`` all 0): the set point anywhere on the trim map.
    x_box : (2, 7) ndarray or None
        [lo, hi] of the nominal's alpha, theta [rad], q [rad/s], eta_1, eta_1_dot [1/s],
        eta_2, eta_2_dot [1/s] as deviations from the nominal vehicle's trim at the
        nominal's own (h, V): the range the tube's certificate covers
        (:func:`fahv.design.eight_state.certified_range`). Rows keep the predicted nominal
        in it at the attitude rows' steps, with the trim at its own (h, V) linearised at
        the scheduling point (``T = Gx[2:9] Gx[0:2]^-1``), widened only to hold the start;
        None (``mpc.x_box`` all 0): no rows.
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

    @property
    def has_rate_rows(self) -> bool:
        """True if the QP carries the rate rows of ``du_max``."""
        return bool(np.all(np.isfinite(self.du_max)))

    @classmethod
    def of_parameters(cls, p: dict, n: int) -> MPCSettings:
        """Settings of a nominal_trajectory node's ``mpc.*`` parameters (n design states)."""
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
    """A box node parameter ``name`` as (n,) finite floats; None if all are 0 (no rows).

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
    """``mpc.u_box`` (Phi lo, Phi hi, delta_e lo, delta_e hi [deg]; all 0: none) as rows.

    Returns
    -------
    (2, 2) ndarray or None
        [[Phi lo, delta_e lo], [Phi hi, delta_e hi]] [-, rad]; None for all zeros.

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
    """``mpc.hv_box`` (h lo, h hi [ft], V lo, V hi [ft/s]; all 0: none) as bounds.

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


#: States of ``mpc.x_box`` (design order 2..8) and their node-parameter units.
X_BOX_STATES = ("alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")
#: Factor from the node parameter's units (deg, deg, deg/s, -, 1/s, -, 1/s) to the state's.
X_BOX_TO_STATE = np.array([math.radians(1.0)] * 3 + [1.0] * 4)


def state_box(x_box) -> np.ndarray | None:
    """``mpc.x_box`` (7 lows then 7 highs; all 0: none) as the QP's state range rows.

    The values are the nominal's alpha, theta [deg], q [deg/s], eta_1, eta_1_dot [1/s],
    eta_2, eta_2_dot [1/s] as deviations from the nominal vehicle's trim at its own
    (h, V) (:data:`X_BOX_STATES`).

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
    """``mpc.du_max`` (Phi, delta_e deg; 0: none) as the QP's rate bounds (2,) [-, rad].

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


@dataclass(frozen=True)
class AttitudeBounds:
    """Attitude rows of the nominal QP against the requirement (:func:`attitude_bounds`).

    Attributes
    ----------
    support : (2,) ndarray
        Support of the tube Z along alpha and theta, sqrt(N_jj) [rad].
    certified : (2,) ndarray
        Requirement minus support [rad]: the largest nominal deviation for which
        nominal + tube stays within the requirement (may be negative).
    used : (2,) ndarray
        Bounds the QP uses [rad]: ``certified`` by default, or the case's value.
    given : bool
        Whether the case gave the bound (``mpc.att_max`` > 0).
    trim_offset : float
        Largest attitude offset of a parameter-box corner's own trim from the nominal
        trim [rad] (0: not known). The nominal must hold it at steady state; where it
        exceeds the rows, the QP widens them to the plant's own trim (see
        :meth:`TrackingMPCNominal._qp`), beyond what the certificate covers.
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
        The case's ``mpc.att_max`` [deg]; 0 uses the certified bound.
    trim_offset : float
        Largest attitude offset of a box corner's trim from the nominal trim [rad]
        (:attr:`AttitudeBounds.trim_offset`; 0: not checked).

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


@dataclass(frozen=True)
class QPLayout:
    """Named parts of the QP's decision vector y (ny,) = [c_0 .. c_{N_p-1}, delta, alpha].

    Attributes
    ----------
    N_p : int
        Moves in the horizon.
    m : int
        Inputs per move.
    """

    N_p: int
    m: int

    @property
    def moves(self) -> slice:
        """The moves c_0..c_{N_p-1} (scaled by Du), N_p m entries."""
        return slice(0, self.N_p * self.m)

    def move(self, j: int) -> slice:
        """Move c_j (m entries)."""
        return slice(j * self.m, (j + 1) * self.m)

    @property
    def delta(self) -> slice:
        """Set-point step delta = (dh_s, dV_s) per (100 ft, 100 ft/s), 2 entries."""
        return slice(self.N_p * self.m, self.N_p * self.m + 2)

    @property
    def alpha(self) -> int:
        """Index of the terminal-set scaling alpha in [0, 1]."""
        return self.N_p * self.m + 2

    @property
    def ny(self) -> int:
        """Length of y."""
        return self.N_p * self.m + 3


def estimator_gains(Ts: float, est_tau: float, est_tau_elevator: float = 0.0):
    """Gains per step of the disturbance estimate (:class:`DisturbanceEstimator`).

    Parameters
    ----------
    Ts : float
        Control period [s].
    est_tau : float
        Time constant of the estimate [s] (``mpc.est_tau``; 0: no estimate).
    est_tau_elevator : float
        Time constant along the elevator column [s] (``mpc.est_tau_elevator``; 0: none).

    Returns
    -------
    gamma : float
        min(1, Ts / est_tau) (first-order filter, docs/control_design.md); 1 without an
        estimate.
    gamma_e : float or None
        min(1, Ts / est_tau_elevator); None without it or without an estimate.
    """
    if est_tau <= 0.0:
        return 1.0, None
    return min(1.0, Ts / est_tau), (min(1.0, Ts / est_tau_elevator)
                                    if est_tau_elevator > 0.0 else None)  # fmt: skip


def elevator_share(v, b, scale) -> np.ndarray:
    """Coefficient c of the share of v along b in the metric diag(scale)^-2: c b is it.

    c = (b' S v) / (b' S b), S = diag(scale)^-2: the part of a residual (or of a jump of
    it) that lies along the elevator column b of the model's B, the direction a loss of
    effectiveness or a bias acts in (eq. 15-16).

    Parameters
    ----------
    v, b : (..., p) array_like
        Vectors and directions (broadcast against each other), state units.
    scale : (p,) array_like
        Positive state scale of the metric (the design scaling Dx).

    Returns
    -------
    (...,) ndarray
        c per vector (the projection is ``c[..., None] * b``).
    """
    bs, vs = b / scale, v / scale
    return np.einsum("...i,...i->...", bs, vs) / np.einsum("...i,...i->...", bs, bs)


class DisturbanceEstimator:
    """Constant additive state disturbance d (B, p) of the scheduled model, for B runs.

    Each step, the one-step residual of each run's scheduled model,
    r = dx_k - A dx_{k-1} - B du_{k-1} (deviations from the trim at the scheduling
    point), is filtered: d <- d + gamma (r - d) with gamma = Ts / tau_est (first
    order, time constant tau_est). d collects what the nominal model misses at the
    current operating point and that varies slowly: the constant part of the parameter
    uncertainty (sec. 5.1), the trim part (rho_f - 1) delta_e,r of a loss of
    effectiveness (eq. 16), the mean of the modelling error. The nominal model then
    predicts with d, so the tube only has to hold what is left (docs/control_design.md).

    With a gain ``gamma_e`` along the elevator column b of the scheduled model's B, the
    share of r - d along b (the projection in the metric of ``scale``,
    b (b' S r) / (b' S b), S = diag(scale)^-2) is filtered with gamma_e instead: a loss of
    effectiveness or an elevator bias acts along b (eq. 15-16), so with gamma_e = 1 the
    estimate knows it one step after the onset while the other directions keep the slow
    filter (gamma = 1 in every direction made the loop unstable, docs/control_design.md).

    Parameters
    ----------
    n_runs : int
        Runs B.
    p : int
        Measured states (9 for a CM design, 11 for the ECM).
    gamma : float
        Filter gain in (0, 1].
    gamma_e : float, optional
        Filter gain in (0, 1] along the elevator column (None: gamma in every direction).
    scale : (p,) array_like, optional
        State scale of the projection's metric (needed with ``gamma_e``).

    Raises
    ------
    ValueError
        If a gain is not in (0, 1], or ``gamma_e`` comes without a positive ``scale`` of
        length p.
    """

    def __init__(self, n_runs: int, p: int, gamma: float, gamma_e: float | None = None,
                 scale=None) -> None:  # fmt: skip
        if not 0.0 < gamma <= 1.0:
            raise ValueError(f"estimator gain gamma must be in (0, 1], got {gamma}")
        if gamma_e is not None:
            if not 0.0 < gamma_e <= 1.0:
                raise ValueError(f"estimator gain gamma_e must be in (0, 1], got {gamma_e}")
            scale = np.asarray(scale, float) if scale is not None else np.zeros(0)
            if scale.shape != (p,) or not np.all(scale > 0.0):
                raise ValueError(f"estimator scale must be ({p},) and positive, got {scale}")
        self.gamma = float(gamma)
        self.gamma_e = None if gamma_e is None else float(gamma_e)
        self.scale = scale
        self.d = np.zeros((n_runs, p))
        #: False until the first residual: it initialises d (the filter's start).
        self.started = False

    def update(self, A, B, dx_prev, du_prev, dx) -> np.ndarray:
        """Estimates d (B, p) [state units per step Ts] after one measured step.

        Parameters
        ----------
        A : (B, p, p) ndarray
        B : (B, p, m) ndarray
            Each run's scheduled model at the fast rate.
        dx_prev, dx : (B, p) ndarray
            Measured states of steps k - 1 and k minus each run's scheduling trim.
        du_prev : (B, m) ndarray
            Commands of step k - 1 minus the scheduling trim input.
        """
        r = (dx - mv(A, np.ascontiguousarray(dx_prev))) - mv(B, np.ascontiguousarray(du_prev))
        return self.update_residual(r, np.asarray(B)[:, :, 1])

    def update_residual(self, r: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
        """Estimates d (B, p) after one step whose residual r (B, p) is given.

        ``b`` (B, p) is each run's elevator column of the scheduled model, the direction
        filtered with ``gamma_e`` (ignored without it; required with it).

        r is what the nominal model missed in the measured step (for the nonlinear
        nominal, x_k - f_0(x_{k-1}, u_{k-1}) with f_0 one period of the nominal CM).
        The first residual initialises the filter, d = r: the vehicle was flying
        before the run's first step, so its constant model error is known from the
        first measured step; starting from d = 0 instead made every run begin with a
        start-up transient of the estimate (its error 20-48x the tube's W,
        docs/control_design.md) during which the nominal input of the first move
        drifted with it beyond the bounds its QP had enforced.
        """
        if self.started:
            e = r - self.d
            self.d = self.d + self.gamma * e
            if self.gamma_e is not None:
                if b is None:
                    raise ValueError("estimator: gamma_e needs the elevator column b")
                coef = elevator_share(e, b, self.scale)
                self.d = self.d + (self.gamma_e - self.gamma) * coef[:, None] * b
        else:
            self.d = np.array(r, float, copy=True)
            self.started = True
        return self.d


@dataclass
class QPStats:
    """Counters of the nominal QP over a run.

    Attributes
    ----------
    solves : int
        QPs solved and accepted.
    fallback : int
        Nominal steps that used the shifted previous plan (QP rejected).
    terminal : int
        Nominal steps that used the terminal law (no plan left).
    recovered : int
        Re-plans whose QP was infeasible and that the recovery QP (set point free on
        the trim map, then also without the steady-input rows,
        :meth:`TrackingMPC.solve`) planned.
    reschedules : int
        Rebuilds of the QP matrices (scheduling changes).
    """

    solves: int = 0
    fallback: int = 0
    terminal: int = 0
    recovered: int = 0
    reschedules: int = 0


class TrackingMPC:
    """One run's nominal tracking QP on the scheduled LPV model (module docstring).

    Parameters
    ----------
    lpv : fahv.model.lpv.PolytopicLPV
        Nominal discrete LPV model at Ts (design-model order, n states, 2 inputs).
    trim_map : fahv.model.trim.TrimMap
        (h, V) -> (x_r (n,), u_r (2,)); its grid bounds the set point.
    K : (2, n) ndarray
        Terminal (and pre-stabilising) law of LMIs (33)-(35).
    Q : (n, n) ndarray
        Terminal ellipsoid E(Q) = {x' Q^-1 x <= 1}, invariant under K.
    u_lo, u_hi : (2,) ndarray
        Tightened absolute input limits [Phi, delta_e rad] (limits -/+ tightening).
    Dx : (n,) ndarray
    Du : (2,) ndarray
        Scaling of states and inputs.
    settings : MPCSettings

    Raises
    ------
    ValueError
        On inconsistent shapes, a non-positive-definite Q, or u_lo >= u_hi.
    """

    def __init__(self, lpv, trim_map, K, Q, u_lo, u_hi, Dx, Du, settings: MPCSettings):
        self.lpv, self.trim_map, self.s = lpv, trim_map, settings
        self.K, self.Q = np.asarray(K, float), np.asarray(Q, float)
        n = self.K.shape[1]
        self.n, self.m = n, self.K.shape[0]
        self.layout = QPLayout(settings.N_p, self.m)
        if self.Q.shape != (n, n):
            raise ValueError(f"nominal MPC: Q {self.Q.shape} does not match K {self.K.shape}")
        self._u_lo, self._u_hi = np.asarray(u_lo, float), np.asarray(u_hi, float)
        if np.any(self.u_lo >= self.u_hi):
            raise ValueError(
                f"nominal MPC: tightened input set is empty: lo {self.u_lo}, hi {self.u_hi}"
            )
        self.Dx, self.Du = np.asarray(Dx, float), np.asarray(Du, float)
        try:
            self.L = np.linalg.cholesky(self.Q)
        except np.linalg.LinAlgError:
            raise ValueError("nominal MPC: terminal ellipsoid Q is not positive definite") from None
        self.L_inv = np.linalg.inv(self.L)
        #: support of K E(Q) per input: max over E(Q) of |K_j x|
        self.k_max = np.sqrt(np.einsum("ij,jk,ik->i", self.K, self.Q, self.K))
        self.theta_scale = np.array([100.0, 100.0])
        self.stats = QPStats()
        self.theta_s = None
        self.last_y = None
        self._qp = None  # DAQP workspace (daqp.Model) of the current scheduling
        # bounds of the rows that have none on one side (terminal rows, steady input)
        self._no_lo_t, self._no_hi_u = np.full(2 * n, -1e30), np.full(self.m, 1e30)
        self._no_lo_u = np.full(self.m, -1e30)

    @property
    def u_lo(self) -> np.ndarray:
        """Tightened lower input limits (2,) [Phi, delta_e rad]."""
        return self._u_lo

    @u_lo.setter
    def u_lo(self, value) -> None:
        self._u_lo = np.asarray(value, float)

    @property
    def u_hi(self) -> np.ndarray:
        """Tightened upper input limits (2,) [Phi, delta_e rad]."""
        return self._u_hi

    @u_hi.setter
    def u_hi(self, value) -> None:
        self._u_hi = np.asarray(value, float)

    # -- scheduling ----------------------------------------------------------------
    def _trim_and_jacobian(self, h: float, V: float):
        """Trim (x_r, u_r) at (h, V) and its Jacobian per scaled set-point step.

        One evaluation of the trim map at five points: (h, V) and central differences
        of 10 ft and 5 ft/s (one-sided at the grid's edges). Returns x_r (n,), u_r (2,),
        Gx (n, 2), Gu (2, 2).
        """
        dh, dV = 10.0, 5.0
        tm = self.trim_map
        h1, h2 = max(h - dh, tm.h_grid[0]), min(h + dh, tm.h_grid[-1])
        V1, V2 = max(V - dV, tm.V_grid[0]), min(V + dV, tm.V_grid[-1])
        x, u = tm.at(np.array([h, h2, h1, h, h]), np.array([V, V, V, V2, V1]))
        Gx = np.stack([(x[1] - x[2]) / (h2 - h1), (x[3] - x[4]) / (V2 - V1)], axis=1)
        Gu = np.stack([(u[1] - u[2]) / (h2 - h1), (u[3] - u[4]) / (V2 - V1)], axis=1)
        return x[0], u[0], Gx * self.theta_scale, Gu * self.theta_scale

    def schedule(self, h: float, V: float) -> None:
        """Build the condensed QP at the scheduling point (h, V) [ft, ft/s].

        Decision y of :class:`QPLayout`. Also the steady-state shift of a constant
        disturbance, Hx (n, n) and Hu (m, n) (module docstring), and the constraint
        matrix of :meth:`solve` (it does not depend on the state). The horizon's
        products are stacked (one matrix product per block of rows, not one per move):
        scheduling is a large part of a campaign's time (docs/campaigns.md).

        Raises
        ------
        DesignError
            If no steady state holds (h, V) against a constant disturbance (the
            steady-state equations are singular at this point).
        """
        s, n, m, ly = self.s, self.n, self.m, self.layout
        A, B = self.lpv.system(h, V)
        self.A, self.B = A, B
        self.theta_s = np.array([h, V], float)
        self.x_r_s, self.u_r_s, Gx, Gu = self._trim_and_jacobian(h, V)
        self.Gx, self.Gu = Gx, Gu
        AK = A + B @ self.K
        E = (A - np.eye(n)) @ Gx + B @ Gu
        # one move held for M fast steps: after i fast steps (i = 1..M) of a move,
        # zeta = Phi_i zeta_0 + Gam_i c + Psi_i delta
        M = s.M
        Phi_w = np.empty((M, n, n))
        Gam_w = np.empty((M, n, m))
        Psi_w = np.empty((M, n, 2))
        Phi, Gam, Psi = np.eye(n), np.zeros((n, m)), np.zeros((n, 2))
        for i in range(M):
            Gam = AK @ Gam + B
            Psi = AK @ Psi + E
            Phi = AK @ Phi
            Phi_w[i], Gam_w[i], Psi_w[i] = Phi, Gam, Psi
        Gam_w *= self.Du  # per scaled move
        Gam = Gam_w[-1]
        N_p, ny = s.N_p, ly.ny
        mv_cols = np.arange(N_p * m).reshape(N_p, m)  # y columns of move j
        # zeta_j = S[j] zeta_0 + C[j] y, zeta_0 = z0 - Gx delta  (j = 0..N_p):
        # S[j] = Phi^j; the move columns are block Toeplitz, C[j][:, c_i] = Phi^(j-1-i) Gam
        # (i < j); the delta columns -Phi^j Gx + sum_(k<j) Phi^k Psi
        S = np.empty((N_p + 1, n, n))
        S[0] = np.eye(n)
        for j in range(N_p):
            S[j + 1] = Phi @ S[j]
        C = np.zeros((N_p + 1, n, ny))
        SG = S[:N_p] @ Gam  # (N_p, n, m): Phi^k Gam
        for i in range(N_p):
            C[i + 1 :, :, mv_cols[i]] = SG[: N_p - i]
        SP = np.cumsum(S[:N_p] @ Psi_w[-1], axis=0)  # sum_(k<j) Phi^k Psi, j = 1..N_p
        C[:, :, ly.delta] = -(S @ Gx)
        C[1:, :, ly.delta] += SP
        self.S, self.C = S, C
        # cost (scaled): sum_j |zeta_j/Dx|^2_qw M + |c_j|^2_rw + |zeta_N/Dx|^2_P + offset
        wq = s.q_w / self.Dx**2 * s.M  # diagonal of the stage weight
        Phi_s = Phi * self.Dx[None, :] / self.Dx[:, None]  # scaled coordinates
        P_s = scipy.linalg.solve_discrete_lyapunov(Phi_s.T, np.diag(s.q_w) * s.M, "bilinear")
        P = (0.5 * (P_s + P_s.T)) / np.outer(self.Dx, self.Dx)
        Cs, Ss = C[:N_p], S[:N_p]
        WC = Cs * wq[None, :, None]  # Wq C[j], (N_p, n, ny)
        H = Cs.reshape(-1, ny).T @ WC.reshape(-1, ny) + C[N_p].T @ P @ C[N_p]
        Fz = WC.reshape(-1, ny).T @ Ss.reshape(-1, n) + C[N_p].T @ P @ S[N_p]
        R = np.zeros(ny)
        R[ly.moves] = np.tile(s.r_w, N_p)
        H += np.diag(R)
        T = np.zeros((ny, ny))
        T[ly.delta, ly.delta] = np.diag(s.t_w)
        H += T
        # alpha: a small weight keeps H positive definite and its condition number near
        # 1e7; with 1e-6 it was 2e11 and DAQP declared feasible QPs infeasible (measured:
        # the equilibrium y = 0 feasible, DAQP exit flag -1; Clarabel solves them)
        H[ly.alpha, ly.alpha] += 1e-2
        # the cost is y' H y + 2 (Fz z0 + ...)' y; DAQP minimises 1/2 y' H_qp y + f' y,
        # so H_qp = 2 H (symmetrised) and f = 2 (Fz z0 + ...)
        self.H = H + H.T
        self.Fz = Fz
        # input rows: u_j = u_base + Gu delta + K zeta_j + c_j (absolute), (N_p m, ny)
        U_y = self.K @ Cs  # (N_p, m, ny)
        U_y[:, :, ly.delta] += Gu
        jj = np.arange(N_p)
        for r in range(m):
            U_y[jj, r, mv_cols[:, r]] += self.Du[r]
        self.U_y = U_y.reshape(N_p * m, ny)
        self.U_z = (self.K @ Ss).reshape(N_p * m, n)
        # zeta at every fast step i = 1..M-1 inside the first fine_moves moves, in closed
        # form zeta = Phi_i zeta_j + Gam_i c_j + Psi_i delta: (M-1, n, ny) per y and
        # (M-1, n, n) per z0, shared by the attitude and the input rows below
        fine = []
        for j in range(min(s.fine_moves, N_p)):
            Zy = Phi_w[: M - 1] @ C[j]
            Zy[:, :, mv_cols[j]] += Gam_w[: M - 1]
            Zy[:, :, ly.delta] += Psi_w[: M - 1]
            fine.append((Zy, Phi_w[: M - 1] @ S[j]))
        # the input rows inside those moves: between move starts the input of the
        # pre-stabilised model moves with K zeta, and the tube's tightening holds only if
        # it stays in the tightened set at every fast step, not at the move starts alone
        uf_y, uf_z = [], []
        for j, (Zy, Zz) in enumerate(fine):
            Ci = self.K @ Zy  # (M-1, m, ny)
            Ci[:, :, mv_cols[j]] += np.diag(self.Du)[None]
            Ci[:, :, ly.delta] += Gu[None]
            uf_y.append(Ci.reshape(-1, ny))
            uf_z.append((self.K @ Zz).reshape(-1, n))
        self.Uf_y = np.concatenate(uf_y) if uf_y else np.zeros((0, ny))
        self.Uf_z = np.concatenate(uf_z) if uf_z else np.zeros((0, n))
        # attitude rows: alpha (2) and theta (3) of zeta at those fast steps and at the
        # move starts j = 1..N_p
        att_y = [Zy[:, 2:4].reshape(-1, ny) for Zy, _ in fine] + [C[1:, 2:4].reshape(-1, ny)]
        att_z = [Zz[:, 2:4].reshape(-1, n) for _, Zz in fine] + [S[1:, 2:4].reshape(-1, n)]
        self.Att_y = np.concatenate(att_y)
        self.Att_z = np.concatenate(att_z)
        if s.hv_box is not None:  # the same steps' absolute h (0) and V (1), x_r_s + Gx
            # delta + zeta: the nominal box's range
            hv_y = np.concatenate([Zy[:, 0:2] for Zy, _ in fine] + [C[1:, 0:2]])  # (., 2, ny)
            hv_y[:, :, ly.delta] += Gx[0:2]
            self.Hv_y = hv_y.reshape(-1, ny)
            self.Hv_z = np.concatenate(
                [Zz[:, 0:2].reshape(-1, n) for _, Zz in fine] + [S[1:, 0:2].reshape(-1, n)]
            )  # fmt: skip
        if s.x_box is not None:  # the same steps' states 2..8 from the trim at the nominal's
            # own (h, V), linearised: zeta[2:9] - T zeta[0:2] (the set point's delta cancels,
            # Gx[2:9] = T Gx[0:2]); plus the estimate's shift x_d in solve()
            self.T_own = Gx[2:9] @ np.linalg.inv(Gx[0:2])  # (7, 2) trim slope per ft, ft/s
            xb_y = [Zy[:, 2:9] - self.T_own @ Zy[:, 0:2] for Zy, _ in fine]
            xb_z = [Zz[:, 2:9] - self.T_own @ Zz[:, 0:2] for _, Zz in fine]
            xb_y.append(C[1:, 2:9] - self.T_own @ C[1:, 0:2])
            xb_z.append(S[1:, 2:9] - self.T_own @ S[1:, 0:2])
            self.Xb_y = np.concatenate(xb_y).reshape(-1, ny)
            self.Xb_z = np.concatenate(xb_z).reshape(-1, n)
        self.Tb_y = self.L_inv @ C[N_p]  # terminal box rows, (n, ny)
        self.Tb_z = self.L_inv @ S[N_p]
        if s.has_rate_rows:
            self._rate_rows(Phi_w, Gam_w, Psi_w)
        self._constraint_matrix()
        self._qp = None
        # steady-state shift of a constant disturbance d: (A - I) x_d + B u_d + d = 0,
        # h_d = V_d = 0; unknowns (x_d[2:], u_d), solved in scaled coordinates
        Dv = np.concatenate([self.Dx[2:], self.Du])
        M_ss = np.hstack([(A - np.eye(n))[:, 2:], B]) * Dv[None, :] / self.Dx[:, None]
        try:
            H_ss = -np.linalg.solve(M_ss, np.diag(1.0 / self.Dx)) * Dv[:, None]
        except np.linalg.LinAlgError:
            raise DesignError(
                f"nominal MPC: no steady state holds (h, V) = ({h}, {V}) against a constant "
                "disturbance (singular steady-state equations)"
            ) from None
        self.Hx = np.zeros((n, n))
        self.Hx[2:] = H_ss[: n - 2]
        self.Hu = H_ss[n - 2 :]
        self.stats.reschedules += 1

    def _rate_rows(self, Phi_w, Gam_w, Psi_w) -> None:
        """Rows of the jumps of the nominal input at the move starts (``mpc.du_max``).

        At the start of move j = 1..N_p-1 the nominal input changes from the last fast step
        of move j-1 to the first of move j by K (zeta_j - zeta_j-1,M-1) + Du (c_j - c_j-1)
        (zeta is continuous, the move jumps), with zeta_j-1,M-1 = Phi_M-1 zeta_j-1 +
        Gam_M-1 c_j-1 + Psi_M-1 delta in closed form: ``Rate_y`` ((N_p-1) m, ny) and
        ``Rate_z`` ((N_p-1) m, n), per Du. The re-plan's own jump, from the input applied
        at the previous fast step to u_0, narrows the bounds of the first m input rows
        (:meth:`solve`; a second copy of those rows would be a degenerate constraint set
        for the active-set solver).
        Between move starts the input moves with K zeta only (the pre-stabilised model).
        """
        s, n, m, ly, N_p, M = self.s, self.n, self.m, self.layout, self.s.N_p, self.s.M
        C, S = self.C, self.S
        if M >= 2:
            P_l, G_l, Q_l = Phi_w[M - 2], Gam_w[M - 2], Psi_w[M - 2]
        else:  # one fast step per move: the last step of a move is its start
            P_l, G_l, Q_l = np.eye(n), np.zeros((n, m)), np.zeros((n, 2))
        mv_cols = np.arange(N_p * m).reshape(N_p, m)
        last_y = P_l @ C[: N_p - 1]  # zeta at the last fast step of moves 0..N_p-2
        for j in range(N_p - 1):
            last_y[j][:, mv_cols[j]] += G_l
        last_y[:, :, ly.delta] += Q_l
        J_y = self.K @ (C[1:N_p] - last_y)  # (N_p - 1, m, ny)
        J_z = self.K @ (S[1:N_p] - P_l @ S[: N_p - 1])
        for r in range(m):
            J_y[np.arange(N_p - 1), r, mv_cols[1:, r]] += self.Du[r]
            J_y[np.arange(N_p - 1), r, mv_cols[:-1, r]] -= self.Du[r]
        self.Rate_y = (J_y / self.Du[None, :, None]).reshape(-1, ly.ny)
        self.Rate_z = (J_z / self.Du[None, :, None]).reshape(-1, n)
        self._rate_scaled = np.tile(s.du_max / self.Du, N_p - 1)

    def _constraint_matrix(self) -> None:
        """Rows of the QP (state independent): inputs, terminal box, steady input, attitude.

        Input limits (N_p m), terminal box |L^-1 zeta_N| <= alpha / sqrt(n) (two one-sided
        sets of n rows), steady input u_base + Gu delta +/- alpha k_max within the
        tightened limits (2 m), attitude rows, the rate rows (``du_max``), the input
        limits at every fast step inside the first ``fine_moves`` moves
        (fine_moves (M - 1) m rows), and with ``u_box`` the rows on the manoeuvre part of
        the input (minus the set point's steady input) at the same move starts and fast
        steps.
        """
        ly, n, m, N_p = self.layout, self.n, self.m, self.s.N_p
        nb = ly.ny
        sc = np.tile(self.Du, N_p)
        A_u = self.U_y / sc[:, None]
        a_coef = np.zeros((n, nb))
        a_coef[:, ly.alpha] = 1.0 / math.sqrt(n)
        A_t1 = self.Tb_y - a_coef  # L^-1 zeta - alpha/sqrt(n) <= 0
        A_t2 = -self.Tb_y - a_coef  # -L^-1 zeta - alpha/sqrt(n) <= 0
        G = np.zeros((m, nb))
        G[:, ly.delta] = self.Gu
        kcol = np.zeros((m, nb))
        kcol[:, ly.alpha] = self.k_max
        A_s1 = (G + kcol) / self.Du[:, None]
        A_s2 = (G - kcol) / self.Du[:, None]
        rows = [A_u, A_t1, A_t2, A_s1, A_s2, self.Att_y]
        if self.s.hv_box is not None:  # the nominal's h and V inside the design's range
            rows.append(self.Hv_y)
        if self.s.x_box is not None:  # its other states inside the certified range
            rows.append(self.Xb_y)
        if self.s.has_rate_rows:  # the jumps between moves (the re-plan's: the first input rows)
            rows.append(self.Rate_y)
        # inputs at the fast steps inside the first fine_moves moves
        sf = np.tile(self.Du, self.Uf_y.shape[0] // m)[:, None]
        rows.append(self.Uf_y / sf)
        if self.s.u_box is not None:  # the manoeuvre part: the input rows less Gu delta (G)
            rows.append((self.U_y - np.tile(G, (N_p, 1))) / sc[:, None])
            rows.append((self.Uf_y - np.tile(G, (self.Uf_y.shape[0] // m, 1))) / sf)
        self.A_c = np.vstack(rows)
        # simple bounds on y: set point trust region and map bounds (delta), alpha in [0, 1]
        s = self.s
        lo_b = np.full(nb, -1e30)
        hi_b = np.full(nb, 1e30)
        dmax = s.dtheta_max / self.theta_scale
        tm = self.trim_map
        h_lo = (tm.h_grid[0] - self.theta_s[0]) / self.theta_scale[0]
        h_hi = (tm.h_grid[-1] - self.theta_s[0]) / self.theta_scale[0]
        V_lo = (tm.V_grid[0] - self.theta_s[1]) / self.theta_scale[1]
        V_hi = (tm.V_grid[-1] - self.theta_s[1]) / self.theta_scale[1]
        d0, d1 = ly.delta.start, ly.delta.start + 1
        if s.hv_box is not None:  # the set point inside the design's nominal range too
            h_lo = max(h_lo, (s.hv_box[0, 0] - self.theta_s[0]) / self.theta_scale[0])
            h_hi = min(h_hi, (s.hv_box[1, 0] - self.theta_s[0]) / self.theta_scale[0])
            V_lo = max(V_lo, (s.hv_box[0, 1] - self.theta_s[1]) / self.theta_scale[1])
            V_hi = min(V_hi, (s.hv_box[1, 1] - self.theta_s[1]) / self.theta_scale[1])
        lo_b[ly.alpha], hi_b[ly.alpha] = 0.0, 1.0
        # recovery (solve(recover=True)): the set point anywhere on the trim map (inside
        # hv_box, if given)
        self._lo_b_rec, self._hi_b_rec = lo_b.copy(), hi_b.copy()
        self._lo_b_rec[d0], self._hi_b_rec[d0] = h_lo, h_hi
        self._lo_b_rec[d1], self._hi_b_rec[d1] = V_lo, V_hi
        lo_b[d0], hi_b[d0] = max(-dmax[0], h_lo), min(dmax[0], h_hi)
        lo_b[d1], hi_b[d1] = max(-dmax[1], V_lo), min(dmax[1], V_hi)
        self._lo_b, self._hi_b = lo_b, hi_b

    # -- solve -----------------------------------------------------------------------
    def solve(
        self,
        z0: np.ndarray,
        u_base: np.ndarray,
        cmd: np.ndarray,
        x_off=None,
        recover=False,
        u_prev=None,
        relax_steady=False,
    ):
        """QP at nominal deviation z0 (n,) from the scheduling trim.

        Parameters
        ----------
        z0 : (n,) ndarray
            Nominal state minus x_r at the scheduling point.
        u_base : (2,) ndarray
            Steady input at the scheduling point, u_r + u_d (absolute).
        cmd : (2,) ndarray
            Command (h_c, V_c) [ft, ft/s].
        x_off : (n,) ndarray, optional
            Steady-state shift x_d of the disturbance estimate. The attitude rows
            bound zeta + x_d, the deviation from the set point's nominal trim (what the
            requirement measures), widened to contain zeta = 0 when the shift alone
            exceeds the bound (the plant must sit at its own trim).
        recover : bool
            The recovery QP: the same problem without the trust region on the
            set-point step (the set point may move anywhere on the trim map in one
            re-plan). The trust region only keeps the trim map's linearisation local;
            no certificate needs it, while every row the certificate needs (inputs,
            attitude, terminal set, steady input) stays.
        u_prev : (2,) ndarray, optional
            Nominal input applied at the previous fast step (absolute). With rate rows
            (``mpc.du_max``) the first move's input may differ from it by at most du_max;
            None: no such row (the first plan of a run).
        relax_steady : bool
            Drop the steady-input rows (the terminal ingredients' admissibility beyond
            the horizon, which the nominal MPC's recursive feasibility needs and the
            tube's certificate does not): the last recovery, when the estimate's shift
            u_d transiently asks for a steady input outside the tightened set anywhere
            on the trim map. The input rows of every move stay.

        Returns
        -------
        y : (ny,) ndarray or None
            Solution (None if rejected).
        info : str
            "ok" or why it was rejected (solver flag, or the failed check of
            :func:`fahv.synthesis.qp.check_kkt`); a rejected QP raises nothing, the
            caller falls back.
        """
        s, ly, m = self.s, self.layout, self.m
        N_p = s.N_p
        e_theta = (self.theta_s - cmd) / self.theta_scale
        f = 2.0 * (self.Fz @ z0)
        f[ly.delta] += 2.0 * s.t_w * e_theta
        lo_b, hi_b = (self._lo_b_rec, self._hi_b_rec) if recover else (self._lo_b, self._hi_b)
        # per-move rows as (N_p, m) and (n_att, 2) blocks broadcast against their
        # (m,) / (2,) bounds (the same element-wise operations as tiling the bounds)
        u_off = (self.U_z @ z0).reshape(N_p, m) + u_base
        lo_u = ((self._u_lo - u_off) / self.Du).reshape(-1)
        hi_u = ((self._u_hi - u_off) / self.Du).reshape(-1)
        if s.has_rate_rows and u_prev is not None:  # u_0 within du_max of the input before
            c0 = (u_off[0] - np.asarray(u_prev, float)) / self.Du
            du = s.du_max / self.Du
            lo_u[:m] = np.maximum(lo_u[:m], -du - c0)
            hi_u[:m] = np.minimum(hi_u[:m], du - c0)
        tz = self.Tb_z @ z0
        att = (self.Att_z @ z0).reshape(-1, 2)
        a_max = np.minimum(np.broadcast_to(s.att_max, (2,)), 1e3)
        att_lo, att_hi = -a_max, a_max
        if x_off is not None:
            off = np.asarray(x_off, float)[2:4]
            att_lo, att_hi = np.minimum(att_lo - off, 0.0), np.maximum(att_hi - off, 0.0)
        s_hi = self._no_hi_u if relax_steady else (self.u_hi - u_base) / self.Du
        s_lo = self._no_lo_u if relax_steady else (self.u_lo - u_base) / self.Du
        bu = np.concatenate(
            [hi_b, hi_u, -tz, tz, s_hi, self._no_hi_u, (att_hi - att).reshape(-1)]
        )  # fmt: skip
        bl = np.concatenate(
            [lo_b, lo_u, self._no_lo_t, self._no_lo_u, s_lo, (att_lo - att).reshape(-1)]
        )  # fmt: skip
        if s.hv_box is not None:  # widened to hold the start (the reset h may lie outside)
            hv = (self.Hv_z @ z0).reshape(-1, 2) + self.x_r_s[:2]
            h0 = z0[:2] + self.x_r_s[:2]
            hv_lo, hv_hi = np.minimum(s.hv_box[0], h0), np.maximum(s.hv_box[1], h0)
            bu = np.concatenate([bu, (hv_hi - hv).reshape(-1)])
            bl = np.concatenate([bl, (hv_lo - hv).reshape(-1)])
        if s.x_box is not None:  # from the trim at the nominal's own (h, V), with x_d
            xd = np.zeros(7) if x_off is None else np.asarray(x_off, float)[2:9]
            start = z0[2:9] - self.T_own @ z0[0:2] + xd  # widened to hold the start
            xb_lo, xb_hi = np.minimum(s.x_box[0], start), np.maximum(s.x_box[1], start)
            xb = (self.Xb_z @ z0).reshape(-1, 7) + xd
            bu = np.concatenate([bu, (xb_hi - xb).reshape(-1)])
            bl = np.concatenate([bl, (xb_lo - xb).reshape(-1)])
        if s.has_rate_rows:
            rz = self.Rate_z @ z0
            bu = np.concatenate([bu, self._rate_scaled - rz])
            bl = np.concatenate([bl, -self._rate_scaled - rz])
        uf_off = (self.Uf_z @ z0).reshape(-1, m) + u_base
        bu = np.concatenate([bu, ((self._u_hi - uf_off) / self.Du).reshape(-1)])
        bl = np.concatenate([bl, ((self._u_lo - uf_off) / self.Du).reshape(-1)])
        if s.u_box is not None:  # the manoeuvre part K zeta + c = u_off - u_base + Du (row y)
            for off in (u_off - u_base, uf_off - u_base):
                bu = np.concatenate([bu, ((s.u_box[1] - off) / self.Du).reshape(-1)])
                bl = np.concatenate([bl, ((s.u_box[0] - off) / self.Du).reshape(-1)])
        if self._qp is None:  # a new workspace per scheduling: H and A_c fixed until then
            self._qp = _daqp().Model()
            self._qp.settings = {"iter_limit": 2000}
            flag = self._qp.setup(self.H, f, self.A_c, bu, bl, primal_start=self.last_y)[0]
            if flag < 0:
                self._qp = None
                return None, f"solver set-up exit flag {flag}"
        else:  # only f and the bounds move between re-plans; warm start from the last one
            self._qp.update(f=f, bupper=bu, blower=bl)
        y, _, flag, info = self._qp.solve()
        if flag not in _DAQP_OPTIMAL:
            self._qp = None  # start the next solve from a fresh workspace
            return None, f"solver exit flag {flag}"
        y = np.asarray(y, float)
        lam = np.asarray(info["lam"], float)
        why = check_kkt(self.H, f, self.A_c, bl, bu, y, lam)
        if why:
            return None, why
        self.last_y = y
        return y, "ok"


assert NO_BOUND < 1e30  # the QP's "no bound" (1e30) must read as none in check_kkt


def _mpc_uses(root) -> bool:
    from fahv.control.base import LAWS, VARIANTS

    return any(
        LAWS[VARIANTS[v].law].nominal is TrackingMPCNominal
        for v in root.get("variants", ())
        if v in VARIANTS and VARIANTS[v].law in LAWS
    )


@register_nominal
class TrackingMPCNominal(NominalSource):
    """Online nominal tracking MPC with a state-disturbance estimate, for B runs.

    Fast step k of each run: the estimate d (p,) is updated from the measured step
    (d <- d + gamma (r - d), r the one-step residual of the scheduled model,
    gamma = Ts / est_tau; the first residual initialises it), the nominal state z
    (deviation from the scheduling trim) moves by z+ = A z + B (u_d + u_dev) + d with
    u_dev = Gu delta + K (z - Gx delta - x_d) + c_j (the nominal input is
    u_r,s + u_d + u_dev, (x_d, u_d) the estimate's steady-state shift); every M steps
    (the first at step 1, once the estimate has started) each run's QP
    (:class:`TrackingMPC`) chooses the moves and the set-point step delta, with its
    input limits at every fast step of the first two moves. Between re-plans u_d
    follows the estimate, which the QP does not bound: the nominal input stays within
    the tightened limits by the plan only as far as d stays near its re-plan value
    (clipping it there instead made the loop diverge after an early loss, measured). The
    output reference is x_r = trim_x(theta), u_r = trim_u(theta) + u_d at the
    artificial set point theta, x_n = X_n - x_r, u_n = u_nominal - u_r, so that the
    ancillary law u = u_r + u_n + tau F (x - x_r - x_n) (eq. 36/54) is unchanged.

    With ``mpc.nominal_model`` 'cm' (9-state CM designs) the nominal state moves by the
    nonlinear CM of the nominal vehicle instead, z+ = f_0(z, u_nominal) + d (one period
    of the plant's RK4, inputs clipped to the actuator limits as the plant does), and
    the estimate filters the residual of that model, r = x_k - f_0(x_k-1, u_k-1). The
    QP still predicts with the scheduled LPV model, and its steady-state shift (x_d, u_d)
    comes from a second filter of the same gain on the scheduled model's residual (as
    with the LPV nominal): both models then agree that the plant's steady state is one,
    so the loop ends on the command. (With the CM residual in the shift, the QP's
    steady state missed the nominal CM's by the linearisation error, measured: Case 1
    ended 0.16 ft / 0.28 ft/s off the command, 1.6 ft / 2.0 ft/s after a 24 % loss.)
    The tube error x - z is then
    linearised along the nominal rather than at the scheduling trim: what the tube
    must hold no longer grows with the nominal's distance from the trim
    (docs/control_design.md, "The error along the nominal").

    With ``mpc.h_reset`` the nominal's altitude is set to the measured one at every
    re-plan, before the QP: the altitude error e_h returns to 0 every M steps, so that
    |e_h| is bounded by M steps of its increment and the tube can be designed on the
    eight states after h (docs/control_design.md, "The altitude reset"). The QP plans
    from the reset nominal. A reset by Delta h, with the artificial set point moved by the
    same Delta h, moves the QP's rows only by the trim map's slope in h times Delta h
    (below 0.001 deg over the eight-state pair's bound of 2.6 ft): feasibility after the
    reset is argued and measured (every re-plan accepted in the runs measured), not
    certified; an infeasible re-plan takes the recovery like any other.

    For an 11-state (ECM) design the estimate works in ECM coordinates: a replica of
    the notch_filter node's filter on the same q samples gives q' and x_q (eq. 43).

    Parameters
    ----------
    p, runs, lanes
        As :class:`~fahv.control.base.NominalSource`.

    Raises
    ------
    RunError
        For an 11-state design with the notch off (the ECM needs its states).
    DesignError
        If no steady state holds the initial point against a constant disturbance.
    """

    name = "mpc"
    estimates_disturbance = True
    section = Section(
        "mpc",
        MPC_SECTION_FIELDS,
        "online nominal tracking MPC (the nominal part of tube_mpc)",
        when=_mpc_uses,
        when_text="a variant's law uses the nominal MPC",
    )

    def __init__(self, p: dict, runs: Sequence[dict], lanes: Lanes) -> None:
        super().__init__(p, runs, lanes)
        B = len(runs)
        n = p["A"].shape[1]
        self.n, self.Ts = n, p["Ts"]
        st = MPCSettings.of_parameters(p, n)
        lpv, tm = lpv_of(p), trim_map_of(p)
        self.mpcs = [
            TrackingMPC(lpv, tm, p["K"], p["Q"], p["u_lo"], p["u_hi"], p["Dx"], p["Du"], st)
            for _ in range(B)
        ]
        m0 = self.mpcs[0]
        self.M, self.K, self.Du, self.scale = st.M, m0.K, m0.Du, m0.theta_scale
        self.trim_map = tm
        self.L_inv = m0.L_inv
        self.filter = None
        self.p_est = 9
        if n == 11:  # ECM: the estimator works in its coordinates (q', x_q, eq. 43)
            if not p["notch.enabled"]:
                raise RunError("nominal_trajectory: the 11-state (ECM) design needs the notch on")
            nf = NotchFilter(*(p[f"notch.{k}"] for k in ("omega_z", "eps_z", "omega_p", "eps_p")))
            self.filter = DiscreteNotch(nf, p["Ts"], np.zeros(B))
            self.p_est = 11
        est_tau, tau_e = p["mpc.est_tau"], p["mpc.est_tau_elevator"]
        pe = self.p_est
        self.has_est = est_tau > 0.0
        #: step of the first plan: 1 with an estimate (it starts from the first residual)
        self.k_first_plan = 1 if self.has_est else 0
        self.est_args = (*estimator_gains(p["Ts"], est_tau, tau_e), np.asarray(p["Dx"], float)[:pe])
        self.est = DisturbanceEstimator(B, pe, *self.est_args)
        self.command = CommandSchedule([Command.of_parameters(r) for r in runs])
        # per-run state of the fast step (stacked) and of the scheduled models
        self.XRS, self.URS, self.THS = np.empty((B, n)), np.empty((B, 2)), np.empty((B, 2))
        self.GX, self.GU = np.empty((B, n, 2)), np.empty((B, 2, 2))
        self.A, self.Bm = np.empty((B, n, n)), np.empty((B, n, 2))
        self.HX, self.HU = np.empty((B, n, pe)), np.empty((B, 2, pe))
        self.EA, self.EB = np.empty((B, pe, pe)), np.empty((B, pe, 2))
        self.TH = np.stack([self.command.h0, self.command.V0], axis=1)
        self.TRX, self.TRU = np.empty((B, n)), np.empty((B, 2))
        self.PLAN = np.zeros((B, st.N_p, 2))
        self.U_NOM = np.zeros((B, 2))  # nominal input of the last fast step (rate rows)
        self.U_D = np.zeros((B, 2))  # the estimate's steady input u_d in it
        self.moves_left = np.zeros(B, dtype=int)
        self.prev = np.zeros((B, pe))
        self.has_prev = False
        self.status = ["not started"] * B
        for b in range(B):
            try:
                self._schedule(b, self.TH[b])
            except DesignError as exc:
                lanes.fail(b, exc)
                continue
            self.TRX[b], self.TRU[b] = tm(*self.TH[b])
        self.XN = np.stack([np.asarray(r["x0"], float) for r in runs])
        self.nominal_cm = st.nominal_model == "cm"
        self.h_reset = st.h_reset
        #: the estimate the QP's steady-state shift (x_d, u_d) uses: the scheduled model's
        #: residual, also with the nonlinear nominal (then a second filter; class docstring)
        self.est_ss = self.est
        if self.nominal_cm and self.has_est:
            self.est_ss = DisturbanceEstimator(B, pe, *self.est_args)
        if self.nominal_cm:
            if n != 9:
                raise RunError(
                    f"nominal_trajectory: mpc.nominal_model 'cm' needs the 9-state CM design, "
                    f"got {n} states"
                )
            veh = load_vehicle(p["vehicle_file"] or None)
            self.nominal_vehicle = params_records([veh.params] * B)
            self.limits_lo, self.limits_hi = veh.limits.u_min, veh.limits.u_max
            self.n_sub = int(p["plant_substeps"])
        self.k = 0
        self._counts = self._qp_counts()

    def _qp_counts(self) -> tuple[np.ndarray, ...]:
        """Per-run QP counters (solves, fallback, terminal, recovered), each (B,) int64.

        Only a re-plan changes them: :meth:`step` builds them after each re-plan and
        its messages share them until the next (no message array is written in place).
        """
        st = [m.stats for m in self.mpcs]
        return tuple(
            np.array([getattr(s, c) for s in st], dtype=np.int64)
            for c in ("solves", "fallback", "terminal", "recovered")
        )

    # -- per run: scheduling and the QP ------------------------------------------------
    def _schedule(self, b: int, theta) -> None:
        mpc = self.mpcs[b]
        mpc.schedule(float(theta[0]), float(theta[1]))
        pe = self.p_est
        self.XRS[b], self.URS[b], self.THS[b] = mpc.x_r_s, mpc.u_r_s, mpc.theta_s
        self.GX[b], self.GU[b], self.A[b], self.Bm[b] = mpc.Gx, mpc.Gu, mpc.A, mpc.B
        self.HX[b], self.HU[b] = mpc.Hx[:, :pe], mpc.Hu[:, :pe]
        self.EA[b], self.EB[b] = mpc.A[:pe, :pe], mpc.B[:pe]

    def _plan(self, b: int, cmd: np.ndarray) -> bool:
        """Re-plan run b: reschedule if needed, solve its QP, or fall back (counted).

        Returns True when the plan moved the set point ``TH[b]``: its trim ``TRX[b]``,
        ``TRU[b]`` is then due (evaluated for all such runs at once by :meth:`step`).
        """
        mpc, ly = self.mpcs[b], self.mpcs[b].layout
        # schedule at the nominal operating point (h, V of X_n), not at the set point:
        # the set point may sit a steady offset away from the state it holds
        if np.any(np.abs(self.XN[b, :2] - mpc.theta_s) > mpc.s.reschedule):
            self._schedule(b, self.XN[b, :2])
        if self.has_est:
            d = self.est_ss.d[b]
            x_d, u_d = self.HX[b] @ d, self.HU[b] @ d
        else:
            x_d, u_d = np.zeros(self.n), np.zeros(2)
        args = (self.XN[b] - mpc.x_r_s - x_d, mpc.u_r_s + u_d, cmd, x_d)
        # the rate rows' start (mpc.du_max): the input of the last fast step with its
        # estimate part moved to the estimate's new steady input. u_d follows the estimate
        # at every fast step, the rows bound the plan's part: measured from the last
        # input as applied, the first re-plan after a loss's onset had to cancel the
        # estimate's jump (a 10-14 % loss: the plan pitched up and the vehicle rose
        # 15-34 ft; docs/control_design.md, "The re-plan's rate row")
        u_prev = self.U_NOM[b] + (u_d - self.U_D[b]) if self.k > 0 else None
        y, why = mpc.solve(*args, u_prev=u_prev)
        recovered = False
        if y is None:  # recovery: the set point free on the trim map (no trust region)
            y, why_rec = mpc.solve(*args, recover=True, u_prev=u_prev)
            if y is None:  # then without the steady-input rows (solve: relax_steady)
                y, why_st = mpc.solve(*args, recover=True, u_prev=u_prev, relax_steady=True)
                why = f"{why}; steady input relaxed" if y is not None else why
                why_rec = f"{why_rec}; without the steady-input rows: {why_st}"
            recovered = y is not None
            why = why if y is not None else f"{why}; recovery: {why_rec}"
        if y is not None:
            if recovered:
                mpc.stats.recovered += 1
            else:
                mpc.stats.solves += 1
            self.PLAN[b] = y[ly.moves].reshape(ly.N_p, ly.m)
            self.TH[b] = mpc.theta_s + y[ly.delta] * mpc.theta_scale
            self.moves_left[b] = ly.N_p
            self.status[b] = f"recovered ({why})" if recovered else "ok"
            return True
        elif self.moves_left[b] > 1:  # the set point stays where it is
            mpc.stats.fallback += 1
            self.PLAN[b] = np.vstack([self.PLAN[b, 1:], np.zeros((1, ly.m))])
            self.moves_left[b] -= 1
            self.status[b] = f"shifted plan ({why})"
        else:
            mpc.stats.terminal += 1
            self.PLAN[b] = 0.0
            self.moves_left[b] = 0
            self.status[b] = f"terminal law ({why})"
        return False

    # -- the batched fast step ----------------------------------------------------------
    def _measure(self, x: np.ndarray) -> np.ndarray:
        """Measured states in the design model's coordinates (B, p)."""
        if self.filter is None:
            return x[:, : self.p_est]
        q_f = self.filter.step(x[:, 4])
        return np.concatenate([x[:, :4], q_f[:, None], x[:, 5:9], self.filter.x_q], axis=1)

    def _nominal_step(self, X: np.ndarray, U) -> np.ndarray:
        """One period of the nominal vehicle's CM (eq. 1-3) from X (B, 9) under U (B, 2)."""
        U = np.clip(np.asarray(U, float), self.limits_lo, self.limits_hi)
        return rk4_cm(np.ascontiguousarray(X, float), np.ascontiguousarray(U), self.nominal_vehicle,
                      self.Ts, self.n_sub)  # fmt: skip

    def step(self, k, t, x, u_prev) -> NominalTrajectory:
        """Output of step k for the B runs (class docstring), then advance one fast step.

        QP counters and the input-equivalent estimate d_hat = -u_d (for a loss of
        elevator effectiveness alone, (0, (rho_f - 1) delta_e,r)) are in the message.
        """
        B = x.shape[0]
        if self.has_est:
            xm = self._measure(np.asarray(x, float))
            if self.has_prev and u_prev is not None:
                self.est_ss.update(
                    self.EA, self.EB, self.prev - self.XRS[:, : self.p_est],
                    np.asarray(u_prev, float) - self.URS, xm - self.XRS[:, : self.p_est],
                )  # fmt: skip
                if self.nominal_cm:  # the nominal CM's own residual, for its propagation
                    self.est.update_residual(xm - self._nominal_step(self.prev, u_prev),
                                             self.EB[:, :, 1])  # fmt: skip
            self.prev = xm.copy()
            self.has_prev = True
        h_c, V_c = self.command(t)
        # re-plan every M steps (each run's own QP); with an estimate, the first plan
        # waits for step 1, when the first residual has initialised it (step 0 holds
        # the initial trim: no plan yet, u = u_r + K (x_n - x_s))
        k0 = self.k_first_plan
        if self.k == k0 or (self.k > k0 and self.k % self.M == 0):
            if self.h_reset:  # the nominal's altitude to the measured one (e_h = 0)
                alive = self.lanes.alive
                self.XN[alive, 0] = np.asarray(x, float)[alive, 0]
            moved = []
            for b in np.flatnonzero(self.lanes.alive):
                try:
                    if self._plan(int(b), np.array([h_c[b], V_c[b]])):
                        moved.append(b)
                except Exception as exc:  # noqa: BLE001 - the run fails alone
                    self.lanes.fail(int(b), exc)
            if moved:  # the trims of the new set points, in one evaluation of the map
                self.TRX[moved], self.TRU[moved] = self.trim_map.at(*self.TH[moved].T)
            self._counts = self._qp_counts()
        if self.has_est:
            Dc = np.ascontiguousarray(self.est_ss.d)
            x_d, u_d = mv(self.HX, Dc), mv(self.HU, Dc)
        else:  # exact zeros (a product with d = 0 could give -0.0)
            x_d, u_d = np.zeros((B, self.n)), np.zeros((B, 2))
        dth = (self.TH - self.THS) / self.scale
        x_s = mv(self.GX, dth) + x_d
        u_s = mv(self.GU, dth)
        z = self.XN - self.XRS
        zx = np.ascontiguousarray(z - x_s)
        u_dev = (u_s + mv(self.K, zx)) + self.PLAN[:, 0] * self.Du
        u_nom = (self.URS + u_d) + u_dev
        self.U_NOM, self.U_D = u_nom, u_d
        x_r, u_r = self.TRX.copy(), self.TRU + u_d
        w = mv(self.L_inv, zx)  # L^-1 (z - x_s): the level in E(Q) is w'w
        solves, fallback, terminal, recovered = self._counts
        out = NominalTrajectory(
            k, t, h_c, V_c, self.TH[:, 0].copy(), self.TH[:, 1].copy(), x_r, u_r,
            self.XN - x_r, u_nom - u_r, (w[:, None, :] @ w[:, :, None])[:, 0, 0],
            solves, fallback, terminal, -u_d, recovered,
        )  # fmt: skip
        d_n = np.zeros_like(z)
        if self.has_est:
            d_n[:, : self.p_est] = self.est.d
        if self.nominal_cm:  # z+ = f_0(z, u_nominal) + d: the nonlinear nominal
            self.XN = self._nominal_step(self.XN, u_nom) + d_n
        else:  # z+ = A z + B u + d: the scheduled LPV model
            zc = np.ascontiguousarray(z)
            self.XN = (
                (self.XRS + mv(self.A, zc)) + mv(self.Bm, np.ascontiguousarray(u_d + u_dev))
            ) + d_n
        self.k += 1
        return out

    # -- offline ------------------------------------------------------------------------
    @classmethod
    def design(cls, ctx) -> dict[str, np.ndarray]:
        """Re-check the terminal ingredients; the attitude bounds of the QP.

        Returns ``att_max`` (2,) [rad], the bounds of the QP's attitude rows, and
        ``att_support`` (2,) [rad], the support of Z in alpha and theta
        (:func:`attitude_bounds`).

        Raises
        ------
        DesignError
            If the terminal set is not invariant or a trim input of the case's path
            is outside the tightened set.
        """
        from fahv.model.trim import TrimMap
        from fahv.synthesis.nominal import verify_terminal

        a = ctx.arrays
        u_lo, u_hi = a["u_lo"], a["u_hi"]
        cmd = ctx.case["command"]
        mpc = ctx.case.get("mpc") or {f.name: f.default for f in MPC_SECTION_FIELDS}
        offset = float(a["att_trim_offset"]) if "att_trim_offset" in a else 0.0
        att = attitude_bounds(a["N"], mpc["att_max"], offset)
        ctx.log(att.report())
        tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
        path = np.array([tm(cmd["h0"], cmd["V0"])[1], tm(cmd["h_c"], cmd["V_c"])[1]])
        cert = verify_terminal(a["A"], a["B"], a["K"], a["Q"], u_lo, u_hi, path)
        ctx.log(
            f"nominal MPC: tightened inputs Phi in [{u_lo[0]:.4f}, {u_hi[0]:.4f}], delta_e in "
            f"[{np.degrees(u_lo[1]):.2f}, {np.degrees(u_hi[1]):.2f}] deg; terminal set E(Q) "
            f"invariant under K at every vertex (norm {cert['invariance']:.6f} <= 1), "
            f"alpha = 1 admissible along the path: {cert['alpha_max'] >= 1.0}  OK"
        )
        return {"att_max": att.used, "att_support": att.support}

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict:
        """``mpc.*`` node parameters from the case's ``mpc`` section (defaults if absent).

        ``mpc.att_max`` is the design's attitude bounds (:func:`attitude_bounds`).
        """
        mpc = case.get("mpc") or {f.name: f.default for f in MPC_SECTION_FIELDS}
        out = {
            f"mpc.{k}": ([float(x) for x in v] if isinstance(v, tuple | list) else v)
            for k, v in mpc.items()
        }
        out["mpc.att_max"] = [float(v) for v in np.degrees(arrays["att_max"])]
        xb = arrays.get("x_box")  # (2, 7) [lo, hi] of the certified range (states 2..8)
        out["mpc.x_box"] = (
            [0.0] * 14 if xb is None else [float(v) for v in (xb / X_BOX_TO_STATE).reshape(-1)]
        )  # fmt: skip
        hv = arrays.get("hv_box")  # (2, 2) [[h lo, V lo], [h hi, V hi]] of the design
        out["mpc.hv_box"] = (
            [0.0] * 4 if hv is None
            else [float(hv[0, 0]), float(hv[1, 0]), float(hv[0, 1]), float(hv[1, 1])]
        )  # fmt: skip
        box = arrays.get("u_box")  # (2, 2) [[Phi lo, de lo], [Phi hi, de hi]] of the design
        out["mpc.u_box"] = (
            [0.0] * 4 if box is None
            else [float(box[0, 0]), float(box[1, 0]),
                  float(np.degrees(box[0, 1])), float(np.degrees(box[1, 1]))]
        )  # fmt: skip
        return out


#: Node parameter ``mpc.att_max``: the bounds the design chose (alpha, theta).
ATT_MAX_PARAMETER = Field(
    "mpc.att_max", "floats", "bounds on the nominal |alpha - alpha_r| and |theta - theta_r| "
    "(from the nominal trim) of the QP's attitude rows, from the design (the default only "
    "fills the parameter of runs without the nominal MPC)", unit="deg", lo=0.0,
    lo_open=True, hi=10.0, length=2, default=(0.35, 0.35),
)  # fmt: skip

#: Node parameter ``mpc.u_box``: the nominal box's input ranges the design assumed.
U_BOX_PARAMETER = Field(
    "mpc.u_box", "floats", "rows on the manoeuvre part of the nominal input (the input minus "
    "the set point's steady input, trim plus estimate shift): Phi lo, Phi hi, delta_e lo, "
    "delta_e hi (Phi -, delta_e deg), from the design's nominal box less the box corners' "
    "trim offsets (tube.form eight_state); all 0: no rows", lo=-30.0, hi=30.0, length=4,
    default=(0.0, 0.0, 0.0, 0.0),
)  # fmt: skip

#: Node parameter ``mpc.hv_box``: the nominal box's h and V ranges the design assumed.
HV_BOX_PARAMETER = Field(
    "mpc.hv_box", "floats", "the nominal's altitude and speed range: h lo, h hi [ft], V lo, "
    "V hi [ft/s], from the design's nominal box (tube.form eight_state: the envelope less "
    "eight_state.h_margin, V_margin); the set point stays in it and rows keep the predicted "
    "nominal in it; all 0: none", lo=0.0, hi=1e6, length=4, default=(0.0, 0.0, 0.0, 0.0),
)  # fmt: skip

#: Node parameter ``mpc.x_box``: the range of the nominal's other states the certificate covers.
X_BOX_PARAMETER = Field(
    "mpc.x_box", "floats", "the range the tube's certificate covers for the nominal's alpha, "
    "theta [deg], q [deg/s], eta_1, eta_1_dot, eta_2, eta_2_dot (from the nominal vehicle's "
    "trim at the nominal's own h, V): 7 lows then 7 highs, from the design (tube.form "
    "eight_state: the scheduling box less the tube); rows keep the predicted nominal in it; "
    "all 0: none", lo=-1e3, hi=1e3, length=14, default=(0.0,) * 14,
)  # fmt: skip

#: Node parameters of the nominal MPC: its case section's keys under ``mpc.`` (``att_max``
#: as the design's bounds) and the design's ``mpc.u_box``, ``mpc.hv_box`` and ``mpc.x_box``.
TrackingMPCNominal.parameters = (
    *(
        ATT_MAX_PARAMETER if f.name == "att_max" else dataclasses.replace(f, name=f"mpc.{f.name}")
        for f in MPC_SECTION_FIELDS
    ),
    U_BOX_PARAMETER,
    HV_BOX_PARAMETER,
    X_BOX_PARAMETER,
)
