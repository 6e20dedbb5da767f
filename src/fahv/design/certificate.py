"""The tube certificate checked against its own assumptions (issue: a certificate that is true).

The tube Z = {e : e' N^-1 e <= 1} of LMI (24) is robust positively invariant (RPI) for
e+ = (A_i + B_i F) e + w, w in the box W, at every vertex i. That statement is only
as true as W: W must bound the one-step disturbance of the perturbed, faulty nonlinear
plant over every state and input the closed loop can reach. This module

* states that domain explicitly (:class:`CertificateDomain`): scheduling points over
  the envelope, the nominal deviations the nominal MPC allows plus the box of Z, the
  inputs the tightened set plus F Z allows, every corner of the sec. 5.1 parameter
  box, rho_f at the ends of [rho_min, 1];
* bounds the one-step disturbance over it (:func:`bound_disturbance`) by a
  deterministic second-order Taylor model with an absolute-value (interval) bound over
  the box, plus a third-order remainder measured at every corner of the box
  (no random sampling: the result does not depend on a seed);
* computes the exact worst one-step level of the tube over the vertices, the corners
  of W and the whole of Z (:func:`worst_level`, a trust-region subproblem per vertex
  and corner), i.e. the RPI property itself, with its margin;
* certifies the onset of a fault and the start of a run, where the disturbance
  estimate has not converged yet, by the level recursion of the S-procedure
  certificate (:func:`onset_levels`).

The disturbance (in deviation coordinates around the scheduling trim (x_rs, u_rs) of
the nominal MPC, A_s, B_s the scheduled discrete model, P = diag(1, rho_f))::

    Delta(z, p, rho_f) = Phi_p(x_rs + z_x, P (u_rs + z_u)) - x_rs - A_s z_x - B_s P z_u
                         - [Phi_p(x_rs, P u_rs) - x_rs]

is the one-step error of the vertex model with the constant part at the trim (which
the online estimate removes, ``disturbance.constant: estimated``) taken out;
Phi_p is one control period of the plant (RK4, the plant's own sub-steps).
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field, replace

import numpy as np

from fahv.control.nominal_mpc import estimator_gains
from fahv.design.feasibility import gain_vertices
from fahv.errors import DesignError
from fahv.model.notch import DiscreteNotch
from fahv.model.vehicle import DELTA_E
from fahv.plant.rk4 import params_records, perturbed_records, rk4_cm
from fahv.synthesis.feedback import invariant_ellipsoid, output_feedback_step

#: Safety factor on the third-order remainder measured at the corners of the box.
REMAINDER_FACTOR = 2.0


@dataclass(frozen=True)
class CertificateDomain:
    """The set of states, inputs, vehicles and faults the tube certificate assumes.

    Attributes
    ----------
    schedules : (S, 2) ndarray
        Scheduling points (h, V) [ft, ft/s] of the nominal model: the corners and the
        centre of the envelope grid.
    x_half : (9,) ndarray
        Half-widths of x - x_rs: the nominal deviation the nominal MPC allows from its
        scheduling trim plus the box of Z [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s].
    nominal_half : (9,) ndarray
        The nominal part of ``x_half`` (without Z), for the report.
    u_lo, u_hi : (2,) ndarray
        Absolute input range [Phi, delta_e rad]: the tightened nominal set plus the
        support of tau F Z (the actuator limits when the design is consistent).
    uncertainty : dict[str, float]
        Relative bounds of the sec. 5.1 box; every corner is evaluated.
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


def nominal_half_widths(mpc: dict, x_default: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Nominal deviation from the scheduling trim that the nominal MPC allows (9,).

    h and V: the rescheduling threshold plus half a set-point move (the nominal model
    is re-scheduled at a plan when its h, V left the threshold; between plans it moves
    on); alpha, theta: the attitude rows of the QP (``mpc.att_max``, from the nominal
    trim) plus the same margin as h, V of the trim map's slope; q and the flexible
    states: ``x_default`` (no QP row bounds them: stated as an assumption).

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


def _one_step(X, U, P, Ts, n_sub):
    return rk4_cm(np.ascontiguousarray(X), np.ascontiguousarray(U), P, Ts, n_sub)


def _disturbance(Z, x_rs, u_rs, A_s, B_s, rho, recs, Ts, n_sub, lin=None):
    """Delta (module docstring) for L points Z (L, 11) and parameter records (L,).

    ``lin`` (L, 9, 11), optional: a per-point linear term [dA, dB] of the vehicle's
    parameters that the tube's vertices carry (:class:`ParameterDirections`); it is
    removed from Delta as A_s z_x + B_s P z_u is.
    """
    L = Z.shape[0]
    P = np.array([1.0, rho])
    X = x_rs[None, :] + Z[:, :9]
    U = (u_rs[None, :] + Z[:, 9:]) * P[None, :]
    x1 = _one_step(X, U, recs, Ts, n_sub)
    x0 = _one_step(np.tile(x_rs, (L, 1)), np.tile(u_rs * P, (L, 1)), recs, Ts, n_sub)
    out = x1 - x0 - Z[:, :9] @ A_s.T - (Z[:, 9:] * P[None, :]) @ B_s.T
    if lin is not None:
        zp = np.concatenate([Z[:, :9], Z[:, 9:] * P[None, :]], axis=1)
        out -= np.einsum("lij,lj->li", lin, zp)
    return out


def _stencil(a: np.ndarray):
    """Central-difference stencil (K, d) with steps a/2 for value, gradient, Hessian."""
    d = a.size
    h = 0.5 * a
    pts = [np.zeros(d)]
    for i in range(d):
        for s in (1.0, -1.0):
            p = np.zeros(d)
            p[i] = s * h[i]
            pts.append(p)
    for i, k in itertools.combinations(range(d), 2):
        for si, sk in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            p = np.zeros(d)
            p[i], p[k] = si * h[i], sk * h[k]
            pts.append(p)
    return np.array(pts), h


def _taylor(G, h, d):
    """Value g0 (n,), gradient J (n, d), Hessian H (n, d, d) from stencil values G (K, n)."""
    g0 = G[0]
    n = g0.size
    J = np.empty((n, d))
    H = np.zeros((n, d, d))
    for i in range(d):
        gp, gm = G[1 + 2 * i], G[2 + 2 * i]
        J[:, i] = (gp - gm) / (2 * h[i])
        H[:, i, i] = (gp + gm - 2 * g0) / h[i] ** 2
    base = 1 + 2 * d
    for c, (i, k) in enumerate(itertools.combinations(range(d), 2)):
        pp, pm, mp, mm = G[base + 4 * c : base + 4 * c + 4]
        H[:, i, k] = H[:, k, i] = (pp - pm - mp + mm) / (4 * h[i] * h[k])
    return g0, J, H


@dataclass(frozen=True)
class DisturbanceBound:
    """Bound of the one-step disturbance over a :class:`CertificateDomain`.

    Attributes
    ----------
    w_bound : (9,) ndarray
        max |Delta_j| over the domain (Taylor bound + remainder), deviation units.
    quadratic : (9,) ndarray
        The second-order part of the bound alone.
    remainder : (9,) ndarray
        REMAINDER_FACTOR times the largest corner mismatch of the quadratic model.
    corner_max : (9,) ndarray
        Largest |Delta_j| evaluated exactly at the corners of the box (a lower bound).
    worst : list of dict
        Per row: the scheduling point, parameter corner and rho_f of the largest bound.
    n_evaluations : int
        One-step evaluations of the plant made.
    """

    w_bound: np.ndarray
    quadratic: np.ndarray
    remainder: np.ndarray
    corner_max: np.ndarray
    worst: list
    n_evaluations: int


def bound_disturbance(
    domain: CertificateDomain, vehicle, tp, trim_map, progress=None, directions=None
):
    """Bound max |Delta_j| over the whole domain (module docstring), deterministic.

    For every scheduling point, parameter corner (all 2^P) and rho_f of the domain,
    Delta is expanded about the centre c of the (state, input) box B = c + [-a, a]
    (11 dimensions) with central differences of step a/2 (243 plant steps), and
    bounded over the box by |g0| + |J| a + 1/2 a' |H| a (elementwise absolute values:
    an interval bound of the quadratic model). The third-order remainder is measured
    as the largest mismatch between the exact Delta and the quadratic model at all
    2^11 corners of the box, for the parameter corner and rho_f that give the largest
    quadratic bound of each row, and added times :data:`REMAINDER_FACTOR`.

    Parameters
    ----------
    domain : CertificateDomain
    vehicle : fahv.model.vehicle.Vehicle
        Nominal vehicle (parameters perturbed here).
    tp : fahv.model.tp_model.TPModel
        The continuous TP model (discretised at ``domain.Ts``), CM (9 states).
    trim_map : fahv.model.trim.TrimMap
        Scheduling trims (x_rs, u_rs).
    progress : callable, optional
        Iterable wrapper (tqdm).
    directions : ParameterDirections, optional
        When the tube's vertices carry the parameter box along principal directions
        (:func:`parameter_directions`), the linear part they carry is removed from Delta
        corner by corner (it is covered by the vertices, not by W). Its schedules must
        be those of ``domain``.

    Returns
    -------
    DisturbanceBound

    Raises
    ------
    DesignError
        If the design model is not the 9-state CM/DM, or an evaluation is not finite.
    """
    disc = tp.discretize(domain.Ts)
    n = disc.A.shape[1]
    if n != 9:
        raise DesignError(
            f"certificate domain: bound implemented for the 9-state CM/DM design model, got {n}"
        )
    corners = domain.corners()
    recs_all = perturbed_records(vehicle.params, domain.uncertainty, corners)
    quad = np.zeros(n)
    best = [None] * n  # (quadratic bound, schedule index, corner index, rho)
    n_eval = 0
    items = list(itertools.product(range(len(domain.schedules)), domain.rho))
    it = items if progress is None else progress(items)
    cache = {}
    if directions is not None and not np.allclose(directions.schedules, domain.schedules):
        raise DesignError("certificate domain: parameter directions built for other schedules")
    for si, rho in it:
        h_s, V_s = domain.schedules[si]
        lin_c = None if directions is None else directions.corner_linear[si]  # (C, 9, 11)
        x_rs, u_rs = trim_map(h_s, V_s)
        x_rs = np.asarray(x_rs[:9], float)
        A_s, B_s = _scheduled(disc, tp, h_s, V_s)
        u_c = 0.5 * (domain.u_lo + domain.u_hi) - u_rs
        a_u = 0.5 * (domain.u_hi - domain.u_lo)
        center = np.concatenate([np.zeros(9), u_c])
        a = np.concatenate([domain.x_half, a_u])
        S, hstep = _stencil(a)
        K, C = S.shape[0], corners.shape[0]
        Zs = np.tile(center + S, (C, 1))
        recs = np.repeat(recs_all, K)
        lin = None if lin_c is None else np.repeat(lin_c, K, axis=0)
        G = _disturbance(Zs, x_rs, u_rs, A_s, B_s, rho, recs, domain.Ts, domain.n_sub, lin)
        n_eval += 2 * G.shape[0]
        if not np.all(np.isfinite(G)):
            raise DesignError(
                f"certificate domain: non-finite plant step at schedule ({h_s}, {V_s}); the "
                "domain leaves the model's validity"
            )
        G = G.reshape(C, K, n)
        for c in range(C):
            g0, J, H = _taylor(G[c], hstep, a.size)
            qb = np.abs(g0) + np.abs(J) @ a + 0.5 * np.einsum("jik,i,k->j", np.abs(H), a, a)
            cache[(si, rho, c)] = (g0, J, H)
            for j in range(n):
                if qb[j] > quad[j]:
                    quad[j] = qb[j]
                    best[j] = (si, c, rho, center, a, x_rs, u_rs, A_s, B_s, lin_c)
    # third-order remainder at the 2^11 corners of the box, for each row's worst case
    rem = np.zeros(n)
    cmax = np.zeros(n)
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=11)))
    done = {}
    for j in range(n):
        si, c, rho, center, a, x_rs, u_rs, A_s, B_s, lin_c = best[j]
        key = (si, rho, c)
        if key not in done:
            Zc = center + signs * a
            lin = None if lin_c is None else np.repeat(lin_c[c : c + 1], len(Zc), axis=0)
            exact = _disturbance(
                Zc, x_rs, u_rs, A_s, B_s, rho, np.repeat(recs_all[c : c + 1], len(Zc)),
                domain.Ts, domain.n_sub, lin,
            )  # fmt: skip
            n_eval += 2 * len(Zc)
            g0, J, H = cache[key]
            dz = signs * a
            model = g0 + dz @ J.T + 0.5 * np.einsum("li,jik,lk->lj", dz, H, dz)
            done[key] = (np.max(np.abs(exact - model), axis=0), np.max(np.abs(exact), axis=0))
        mis, ex = done[key]
        rem = np.maximum(rem, REMAINDER_FACTOR * mis)
        cmax = np.maximum(cmax, ex)
    worst = [
        {
            "schedule": domain.schedules[b[0]].tolist(),
            "corner": dict(zip(domain.uncertainty, corners[b[1]].tolist(), strict=True)),
            "rho_f": b[2],
        }
        for b in best
    ]
    return DisturbanceBound(quad + rem, quad, rem, cmax, worst, n_eval)


def _scheduled(disc, tp, h, V):
    w = tp.weights(h, V)
    return np.tensordot(w, disc.A, 1), np.tensordot(w, disc.B, 1)


def disturbance_at(
    domain: CertificateDomain, vehicle, tp, trim_map, schedule, Z, signs, rho, directions=None
):
    """Delta (L, 9) at explicit points: an independent evaluation for tests.

    Parameters
    ----------
    domain : CertificateDomain
    vehicle, tp, trim_map
        As :func:`bound_disturbance`.
    schedule : (2,) array_like
        Scheduling point (h, V).
    Z : (L, 11) ndarray
        Deviations (x - x_rs, u - u_rs).
    signs : (L, P) ndarray
        Parameter values as fractions in [-1, 1] of the box, one row per point.
    rho : float
        Elevator effectiveness.
    directions : ParameterDirections, optional
        Remove the linear part the tube's vertices carry (as :func:`bound_disturbance`)
        for every vehicle, corners and interior alike
        (:meth:`ParameterDirections.carried`).

    Raises
    ------
    DesignError
        With ``directions``, if a vehicle's carried coefficient leaves the vertices'
        coefficient box (the vertices would not cover it).
    """
    disc = tp.discretize(domain.Ts)
    x_rs, u_rs = trim_map(*schedule)
    A_s, B_s = _scheduled(disc, tp, *schedule)
    recs = perturbed_records(vehicle.params, domain.uncertainty, signs)
    lin = None
    if directions is not None:
        lin = directions.carried(vehicle, trim_map, schedule, recs, Ts=domain.Ts,
                                 n_sub=domain.n_sub)  # fmt: skip
    return _disturbance(
        np.asarray(Z, float), np.asarray(x_rs[:9], float), u_rs, A_s, B_s, rho, recs,
        domain.Ts, domain.n_sub, lin,
    )  # fmt: skip


# -- the parameter box in the tube's vertices ---------------------------------------------
@dataclass(frozen=True)
class ParameterDirections:
    """The parameter box's first-order effect as principal directions of [dA, dB].

    At a fixed trim, a vehicle of the box differs from the nominal one to first order by
    its Jacobian deviation [dA_p, dB_p] (one control period, discrete). Over the 2^P
    corners these deviations are dominated by a few directions (on this vehicle one:
    I_yy scales the pitch and coupled flexible rows). Along k directions G_l
    (scaled coordinates) with coefficient ranges [c_lo, c_hi] covering every corner at
    every schedule, the vertex set {A_i + sum_l c_l dA_l, B_i + sum_l c_l dB_l} over
    the corners of the coefficient box carries that part in the tube's LMI (24), so W
    need not hold it; the rest of each corner's deviation stays in W
    (:func:`bound_disturbance` with ``directions``).

    Attributes
    ----------
    schedules : (S, 2) ndarray
        Scheduling points (h, V) [ft, ft/s] the Jacobians were taken at.
    dA, dB : (k, 9, 9), (k, 9, 2) ndarray
        Unit directions (unscaled units).
    c_lo, c_hi : (k,) ndarray
        Coefficient range over all corners and schedules.
    corner_linear : (S, C, 9, 11) ndarray
        Per schedule and corner, the projection of [dA_p, dB_p] on the directions.
    singular_values : (r,) ndarray
        RMS singular values of the corners' scaled deviations (all directions), to
        judge what k leaves out.
    row_scale : (9,) ndarray
        Row divisor the directions were chosen with (``Dx`` or the half-widths of W).
    scale : (11,) ndarray
        Column scaling (Dx, Du) of the finite differences and the SVD.
    """

    schedules: np.ndarray
    dA: np.ndarray
    dB: np.ndarray
    c_lo: np.ndarray
    c_hi: np.ndarray
    corner_linear: np.ndarray
    singular_values: np.ndarray
    row_scale: np.ndarray
    scale: np.ndarray

    def carried(self, vehicle, trim_map, schedule, recs, Ts: float, n_sub: int) -> np.ndarray:
        """The part of each vehicle's Jacobian deviation the vertices carry, (L, 9, 11).

        Taken at the nominal trim of ``schedule`` (h, V) [ft, ft/s] for L vehicles
        (``recs``, parameter records), by the same central differences as
        :func:`parameter_directions`, and projected on the directions.

        Raises
        ------
        DesignError
            If a coefficient lies outside [c_lo, c_hi] (beyond 1e-9 of the range).
        """
        h, V = np.asarray(schedule, float)
        sc, rs = self.scale, self.row_scale
        J = _trim_jacobians(trim_map, h, V, np.concatenate([params_records([vehicle.params]),
                            recs]), Ts, n_sub, sc)  # fmt: skip
        dev = (J[1:] - J[0]) / rs[None, :, None] * sc[None, None, :]
        unscale = rs[:, None] / sc[None, :]
        G = np.concatenate([self.dA, self.dB], axis=2) / unscale[None]  # (k, 9, 11) scaled
        coef = np.einsum("lij,kij->lk", dev, G)
        tol = 1e-9 * (self.c_hi - self.c_lo + 1.0)
        out = (coef < self.c_lo - tol) | (coef > self.c_hi + tol)
        if out.any():
            i, j = np.argwhere(out)[0]
            raise DesignError(
                f"parameter directions: vehicle {i} has coefficient {coef[i, j]:.6g} along "
                f"direction {j}, outside the vertices' range [{self.c_lo[j]:.6g}, "
                f"{self.c_hi[j]:.6g}]: the vertices do not cover it"
            )
        return np.einsum("lk,kij->lij", coef, G) * unscale[None]

    def vertices(self, A, B):
        """Vertex set of the tube LMI: every vertex shifted to every corner of the box.

        Parameters
        ----------
        A : (R, 9, 9) ndarray
        B : (R, 9, 2) ndarray
            Vertices of the nominal vehicle (discrete).

        Returns
        -------
        (R 2^k, 9, 9), (R 2^k, 9, 2) ndarray
        """
        As, Bs = [], []
        for c in itertools.product(*zip(self.c_lo, self.c_hi, strict=True)):
            c = np.asarray(c, float)
            As.append(A + np.tensordot(c, self.dA, 1)[None])
            Bs.append(B + np.tensordot(c, self.dB, 1)[None])
        return np.concatenate(As), np.concatenate(Bs)


def parameter_directions(
    vehicle,
    trim_map,
    schedules,
    uncertainty: dict,
    Ts: float,
    n_sub: int,
    Dx,
    Du,
    k: int,
    row_scale=None,
) -> ParameterDirections:
    """Principal directions of the parameter box's Jacobian deviation (one period).

    The discrete Jacobians of one control period of the CM (the plant's RK4) at the
    nominal trim of each scheduling point are taken by central differences (steps 1e-4
    of the scaling) for the nominal vehicle and every corner of the box; the scaled
    deviations (rows / Dx, columns times (Dx, Du)) of all corners and schedules are
    decomposed by an SVD and the first k right singular vectors kept.

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    trim_map : fahv.model.trim.TrimMap
    schedules : (S, 2) array_like
        Scheduling points (h, V) [ft, ft/s].
    uncertainty : dict[str, float]
        Relative bounds of the box (every corner is evaluated).
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period.
    Dx : (9,) ndarray
    Du : (2,) ndarray
        State and input scaling.
    k : int
        Number of directions (0: none, the result carries no vertex shift).
    row_scale : (9,) array_like, optional
        Divisor of each row of the deviations before the SVD (default ``Dx``). With the
        half-widths of W the directions are those that matter most relative to W, row
        by row (a row W bounds tightly gets its share even if its entries are small).

    Returns
    -------
    ParameterDirections

    Raises
    ------
    ValueError
        If k is negative or larger than the number of corners.
    """
    names = list(uncertainty)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=len(names))))
    if not 0 <= k <= len(corners):
        raise ValueError(f"parameter directions: k must be in [0, {len(corners)}], got {k}")
    recs = np.concatenate([params_records([vehicle.params]),
                           perturbed_records(vehicle.params, uncertainty, corners)])  # fmt: skip
    sc = np.concatenate([Dx, Du])
    rs = np.asarray(Dx if row_scale is None else row_scale, float)
    schedules = np.atleast_2d(np.asarray(schedules, float))
    dev = []
    for h, V in schedules:
        J = _trim_jacobians(trim_map, h, V, recs, Ts, n_sub, sc)
        dev.append((J[1:] - J[0]) / rs[None, :, None] * sc[None, None, :])
    dev = np.array(dev)  # (S, C, 9, 11) scaled
    flat = dev.reshape(-1, 99)
    _, s, Vt = np.linalg.svd(flat, full_matrices=False)
    G = Vt[:k]  # (k, 99) orthonormal, scaled
    coef = flat @ G.T
    lo = coef.min(axis=0) if k else np.zeros(0)
    hi = coef.max(axis=0) if k else np.zeros(0)
    unscale = rs[:, None] / sc[None, :]
    dirs = G.reshape(k, 9, 11) * unscale[None]
    proj = (coef @ G).reshape(dev.shape) * unscale[None, None]
    return ParameterDirections(
        schedules,
        dirs[:, :, :9],
        dirs[:, :, 9:],
        lo,
        hi,
        proj,
        s / np.sqrt(len(flat)),
        rs,
        sc,
    )


def _trim_jacobians(trim_map, h, V, recs, Ts, n_sub, sc) -> np.ndarray:
    """One-period Jacobians [A, B] (L, 9, 11) of L vehicles at the nominal trim.

    At (h, V) [ft, ft/s], by central differences with steps 1e-4 of the scaling ``sc`` (11,).
    """
    x, u = trim_map(h, V)
    L = len(recs)
    X = np.tile(np.asarray(x[:9], float), (L, 1))
    return jacobians(X, np.tile(np.asarray(u, float), (L, 1)), recs, Ts, n_sub, sc)


def jacobians(X, U, recs, Ts: float, n_sub: int, scale) -> np.ndarray:
    """One-period Jacobians [A, B] (L, 9, 11) of the CM at L points (central differences).

    X (L, 9) states, U (L, 2) applied inputs, ``recs`` (L,) parameter records, steps
    1e-4 of ``scale`` (11,) (the design scaling Dx, Du).
    """
    z0 = np.concatenate([X, U], axis=1)
    J = np.empty((len(X), 9, 11))
    for i in range(11):
        zp, zm = z0.copy(), z0.copy()
        zp[:, i] += 1e-4 * scale[i]
        zm[:, i] -= 1e-4 * scale[i]
        fp = _one_step(zp[:, :9], zp[:, 9:], recs, Ts, n_sub)
        fm = _one_step(zm[:, :9], zm[:, 9:], recs, Ts, n_sub)
        J[:, :, i] = (fp - fm) / (2e-4 * scale[i])
    return J


# -- the RPI property itself -------------------------------------------------------------
def _max_on_ball(M: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Max over |u| <= 1 of |M u + c_l|^2 per row c_l of c (L, n), bounded from above.

    Exact up to the bisection's rounding, never below the maximum. The trust-region
    subproblem max u'G u + 2 b'u + c'c (G = M'M, b = M'c) has no duality gap (Moré and
    Sorensen 1983): it equals the minimum over lam >= sigma_max^2 of the convex dual
    function lam + b'(lam I - G)^-1 b + c'c, attained where |(lam I - G)^-1 b| = 1 (the
    secular equation), or at lam = sigma_max^2 in the hard case. The bisection keeps an
    upper end lam above that minimiser; the dual function there bounds the maximum from
    above (weak duality), with an error of second order in the bisection's gap (the
    function's slope vanishes at the minimiser). The primal point of that lam, its norm
    filled up to 1 along the top eigenvector, had been used before: in the nearly hard
    case the fill left the ball and overstated a level by 4e-3 (measured).
    """
    s, V = np.linalg.eigh(M.T @ M)
    b = np.ascontiguousarray((c @ M) @ V)  # (L, n): components of M'c in the eigenbasis
    cc = np.einsum("li,li->l", c, c)
    return _dual_kernel()(s, b, cc, 200)


@functools.cache
def _dual_kernel():
    """:func:`_dual_bound` compiled by numba (cached on disk), built at its first use.

    The bisection is up to 200 steps for each of L rows: in numpy, its per-call overhead
    made it 70 % of an onset bound's time (benchmarks/bench_certificate.py).
    """
    import numba

    return numba.njit(cache=True, error_model="numpy")(_dual_bound)


def _dual_bound(s, b, cc, steps):  # pragma: no cover - compiled
    """The dual bound of :func:`_max_on_ball` per row, in the eigenbasis of M'M.

    s (n,) ascending eigenvalues, b (L, n) the rows' M'c in that basis, cc (L,) |c_l|^2,
    ``steps`` bisection halvings at most; returns (L,) upper bounds of the maxima. The
    bisection stops where no float lies between its ends (about 55 halvings): from there
    each further step leaves lo and hi as they are, so the result is that of all
    ``steps`` halvings, bit for bit.
    """
    n_rows, n = b.shape
    smax = s[n - 1]
    out = np.empty(n_rows)
    for r in range(n_rows):
        bb = 0.0
        for j in range(n):
            bb += b[r, j] * b[r, j]
        lo = smax
        hi = smax + np.sqrt(bb) + 1.0
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            norm2 = 0.0  # |(mid I - G)^-1 b|^2, the secular function
            for j in range(n):
                d = mid - s[j]
                norm2 += b[r, j] * b[r, j] / (d * d)
            last = mid == lo or mid == hi  # no float between them: every later step is void
            if norm2 > 1.0:
                lo = mid
            else:
                hi = mid
            if last:
                break
        # >= 0 gaps; 0 only along the top eigenvector in the hard case, where b_j = 0
        total = cc[r] + hi
        for j in range(n):
            if b[r, j] != 0.0:
                total += b[r, j] * b[r, j] / (hi - s[j])
        out[r] = total
    return out


def worst_level(A, B, F, N, w_max, tau: float = 1.0, pulse=None):
    """Exact max of (A_cl,i e + w)' (tau^2 N)^-1 (A_cl,i e + w) over e in tau Z, w in W.

    The level is convex in (e, w), so over the box W its maximum lies at a corner; over
    the ellipsoid the trust-region subproblem of :func:`_max_on_ball` is solved by its
    dual (an upper bound, exact up to the bisection's rounding). The tube is RPI for W
    if the result is at most 1.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices (the fault vertices included).
    F : (m, n) ndarray
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) ndarray
        Half-widths of W (a zero row: no disturbance there, one corner).
    tau : float
        Adjustable factor (eq. 54): the tube is tau Z, the gain tau F.
    pulse : (g, n) ndarray, optional
        Pulse generators G: w ranges over W + {G' p : |p| <= 1} (the corners of both).

    Returns
    -------
    level : float
        The worst one-step level (1: the boundary of the tube).
    where : tuple
        (vertex index, corner of W (and of p) as signs (n + g,)).
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    Acl = A + B @ (tau * np.asarray(F, float))
    lev, corner, signs = _levels(Acl, tau**2 * np.asarray(N, float), w_max, pulse)
    i = int(np.argmax(lev))
    return float(lev[i]), (i, signs[corner[i]])


def vertex_levels(Acl, N, w_max, pulse=None) -> np.ndarray:
    """Exact worst one-step level of each closed-loop vertex (:func:`worst_level`).

    Parameters
    ----------
    Acl : (R, n, n) ndarray
        Closed-loop vertices.
    N : (n, n) ndarray
        Shape of the set, {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W (a zero row: no disturbance there).
    pulse : (g, n) ndarray, optional
        Pulse generators, as in :func:`worst_level`.

    Returns
    -------
    (R,) ndarray
        max over e in the set and w in W of (A_cl,i e + w)' N^-1 (A_cl,i e + w).
    """
    return _levels(np.asarray(Acl, float), np.asarray(N, float), w_max, pulse)[0]


def _levels(Acl, Ns, w_max, pulse):
    L = np.linalg.cholesky(Ns)
    Linv = np.linalg.inv(L)
    n = Ns.shape[0]
    G = np.zeros((0, n)) if pulse is None else np.atleast_2d(np.asarray(pulse, float))
    w_max = np.asarray(w_max, float)
    free = np.r_[w_max != 0.0, np.ones(len(G), bool)]  # a zero half-width has one corner
    signs = np.ones((2 ** int(free.sum()), n + len(G)))
    signs[:, free] = np.array(list(itertools.product((-1.0, 1.0), repeat=int(free.sum()))))
    C = (signs[:, :n] * w_max[None, :] + signs[:, n:] @ G) @ Linv.T
    lev = np.empty(Acl.shape[0])
    corner = np.empty(Acl.shape[0], int)
    for i in range(Acl.shape[0]):
        li = _max_on_ball(Linv @ Acl[i] @ L, C)
        corner[i] = int(np.argmax(li))
        lev[i] = li[corner[i]]
    return lev, corner, signs


def rpi_margin(A, B, F, N, w_max, tau: float = 1.0, hi: float = 4.0) -> float:
    """Largest factor g in [0, hi] such that the tube stays RPI for g W.

    Bisection on :func:`worst_level` (30 halvings of [0, hi], or of [0, 1] when the
    tube is not RPI for W itself). Arguments as :func:`worst_level`.

    Returns
    -------
    float
        The factor (to 2^-30 of the interval); 0 if the tube is not invariant even
        without a disturbance (some vertex's closed loop expands Z).
    """
    if worst_level(A, B, F, N, 0.0 * np.asarray(w_max, float), tau)[0] > 1.0:
        return 0.0
    lo = 0.0
    if worst_level(A, B, F, N, w_max, tau)[0] > 1.0:
        hi = 1.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if worst_level(A, B, F, N, mid * np.asarray(w_max), tau)[0] <= 1.0:
            lo = mid
        else:
            hi = mid
    return lo


# -- the notch filter in the tube's feedback ------------------------------------------
@dataclass(frozen=True)
class NotchLoop:
    """The tube feedback through a variant's notch filter on q, at the design's vertices.

    The RPI certificate (LMI 24, the exact level) is for e+ = (A_i + B_i F) e + w: the
    gain acts on the measured q. A variant with the notch (eq. 38) on the q feedback
    runs u = F e' with q' = notch(q) in e', which adds the filter's two states to the
    loop. Always: the loop's stability at every vertex with the filter in it, a
    *necessary* condition for any tube to hold (:func:`notch_loop`). With
    :func:`notch_tube` (or :func:`notch_certificate`): an RPI certificate of that loop in
    its own states, ``s``, ``level`` and ``supports`` below.

    Attributes
    ----------
    variant : str
    omega, eps_p : float
        Notch centre [rad/s] and pole damping [-].
    rho : float
        Largest spectral radius over the vertices of the loop with the filter.
    rho_q : float
        The same on the measured q (the loop the certificate is for).
    vertex : int
        Vertex of ``rho``.
    s : float or None
        With an RPI certificate of the loop with the filter (:func:`notch_tube`): the
        projection of its invariant ellipsoid on e lies in s Z (None: not sought; inf:
        no ellipsoid found).
    level : float or None
        That ellipsoid's exact worst one-step level over the vertices and the corners
        of W (:func:`worst_level`).
    supports : tuple of float or None
        The input deviation's support over it, per input [-, rad] (through q').
    tightening : tuple of float or None
        The tightening the design applies, F Z's support per input [-, rad].
    designed : bool
        True if the loop runs a gain designed for it (:func:`notch_gain`), not the tube's.
    w_ratio : tuple of float or None
        With a designed gain: the closure of the loop on W's assumptions, every entry
        <= 1 (:func:`fahv.design.eight_state.designed_notch_loop`: the loop's altitude
        bound over the pair's H, then the one-step disturbance bound over the loop's own
        set of (e, u - v) per row of W as a fraction of W); None: not bounded, the tube's
        own closure applies.
    """

    variant: str
    omega: float
    eps_p: float
    rho: float
    rho_q: float
    vertex: int
    s: float | None = None
    level: float | None = None
    supports: tuple[float, ...] | None = None
    tightening: tuple[float, ...] | None = None
    designed: bool = False
    w_ratio: tuple[float, ...] | None = None

    @property
    def stable(self) -> bool:
        """True if the loop with the filter is stable at every vertex."""
        return self.rho < 1.0

    @property
    def certified(self) -> bool:
        """True if the loop with the filter is certified (:func:`notch_tube`).

        An ellipsoid of the loop with the filter is RPI for W (exact level <= 1),
        projects into Z (s <= 1) and keeps the input deviation within the tightening:
        every assumption the tube's W was bounded under then holds with the filter.
        """
        return (
            self.s is not None
            and self.level is not None
            and self.s <= 1.0
            and self.level <= 1.0
            and all(a <= b * (1.0 + 1e-9) for a, b in zip(self.supports, self.tightening,
                                                          strict=True))
            and (self.w_ratio is None or max(self.w_ratio) <= 1.0)
        )  # fmt: skip

    def line(self) -> str:
        """One line for the design log, with its verdict."""
        head = (
            f"variant {self.variant}: tube feedback through the notch on q (omega {self.omega:.2f} "
            f"rad/s, eps_p {self.eps_p:g}): largest spectral radius over the vertices "
            f"{self.rho:.6f} (on the measured q {self.rho_q:.6f})"
        )
        if not self.stable:
            return head + f": UNSTABLE at vertex {self.vertex}: NOT certified with the notch"
        if self.s is None:
            return head + (
                ": stable at every vertex (necessary only); the RPI certificate is for the "
                "feedback on the measured q: NOT certified with the notch"
            )
        if not np.isfinite(self.s):
            return head + (
                "; no ellipsoid of the loop with the filter's states RPI for W with its input "
                "support within the tightening (LMI infeasible): NOT certified with the notch"
            )
        sup = " / ".join(f"{v:.4f}" for v in self.supports)
        tig = " / ".join(f"{v:.4f}" for v in self.tightening)
        closed = ""
        if self.w_ratio is not None:
            closed = (f", over the loop's own set of (e, u - v): H / the pair's "
                      f"{self.w_ratio[0]:.3f}, W's bound / W per row "
                      + " ".join(f"{v:.3f}" for v in self.w_ratio[1:]))  # fmt: skip
        return head + (
            ("; with the gain designed for the loop" if self.designed else "")
            + f"; an ellipsoid of the loop with the filter's states, RPI for W: exact worst "
            f"one-step level {self.level:.6f}, its projection on e inside {self.s:.4f} x Z, "
            f"input support through q' {sup} (tightening {tig}){closed}"
            + (": certified with the notch  OK" if self.certified
               else ": NOT certified with the notch")
        )  # fmt: skip

    def summary(self) -> dict:
        """JSON-ready record: the attributes, ``stable``, ``certified`` and ``ellipsoid``.

        ``ellipsoid`` says whether one was sought and found ("not sought", "infeasible",
        "found"); ``s`` is None unless one was found (strict JSON has no inf).
        """
        found = self.s is not None and np.isfinite(self.s)
        state = "found" if found else ("not sought" if self.s is None else "infeasible")
        return {**self.__dict__, "s": self.s if found else None, "ellipsoid": state,
                "stable": self.stable, "certified": self.certified}  # fmt: skip


def notch_closed_loop(A, B, F, notch, Ts: float, iq: int) -> tuple[np.ndarray, np.ndarray]:
    """The tube loop with the notch filter on q, in the states xi = [e; chi] (:func:`notch_loop`).

    The filter is eq. (38) in the state-space form of eq. (39), discretised as the
    notch_filter node runs it (:class:`fahv.model.notch.DiscreteNotch`), in the
    coordinates chi(k) = x_q(k) - B_d q(k) (a standard state space of the same recursion):
    chi+ = A_d chi + (A_d B_d + B_d) q, q' = C_q chi + (C_q B_d + D_q) q. With u = F e'
    (e' is e with q' for e_q)::

        xi+ = A_xi,i xi + [I; 0] w,   A_xi,i = [[A_i + B_i F S, B_i F_q C_q], [b E_q, A_d]],
        u = K xi,                     K = [F S, F_q C_q],

    with S the identity but (C_q B_d + D_q) at (iq, iq). The notch's effect on the
    nominal's own q is an exogenous signal and enters neither.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube's error dynamics.
    F : (m, n) ndarray
        Tube gain on e.
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.

    Returns
    -------
    A_xi : (R, n + 2, n + 2) ndarray
    K : (m, n + 2) ndarray
        The input deviation the loop applies, u - v = K xi.

    Raises
    ------
    ValueError
        If the shapes disagree or ``iq`` is out of range.
    """
    A, B, F = (np.asarray(v, float) for v in (A, B, F))
    R, n, _ = A.shape
    if B.shape[:2] != (R, n) or F.shape != (B.shape[2], n) or not 0 <= iq < n:
        raise ValueError(f"notch_loop: shapes A {A.shape}, B {B.shape}, F {F.shape}, iq {iq}")
    dn = DiscreteNotch(notch, Ts)
    b = dn.A_d @ dn.B_d + dn.B_d
    S = np.eye(n)
    S[iq, iq] = dn.C_q @ dn.B_d + dn.D_q
    K = np.hstack([F @ S, F[:, iq : iq + 1] * dn.C_q[None, :]])
    Acl = np.zeros((R, n + 2, n + 2))
    Acl[:, :n, :] = np.concatenate([A, np.zeros((R, n, 2))], axis=2) + B @ K
    Acl[:, n:, iq] = b
    Acl[:, n:, n:] = dn.A_d
    return Acl, K


def notch_loop(A, B, F, notch, Ts: float, iq: int, variant: str = "") -> NotchLoop:
    """Stability of the tube loop with the notch filter on q at every vertex (:class:`NotchLoop`).

    The spectral radius of each vertex of :func:`notch_closed_loop`, next to the loop's
    on the measured q (A_i + B_i F).

    Parameters
    ----------
    A, B, F, notch, Ts, iq
        As :func:`notch_closed_loop`.
    variant : str
        Name for the report.

    Returns
    -------
    NotchLoop

    Raises
    ------
    ValueError
        If the shapes disagree or ``iq`` is out of range.
    """
    return _notch_loop(A, B, F, notch, Ts, iq, variant)[0]


def _notch_loop(A, B, F, notch, Ts, iq, variant):
    """:func:`notch_loop` with the loop's A_xi and K of :func:`notch_closed_loop`."""
    Acl, K = notch_closed_loop(A, B, F, notch, Ts, iq)
    A, B, F = (np.asarray(v, float) for v in (A, B, F))
    rho = np.abs(np.linalg.eigvals(Acl)).max(axis=1)
    rho_q = np.abs(np.linalg.eigvals(A + B @ F)).max(axis=1)
    k = int(np.argmax(rho))
    loop = NotchLoop(variant, float(notch.omega_z), float(notch.eps_p), float(rho[k]),
                     float(rho_q.max()), k)  # fmt: skip
    return loop, Acl, K


def notch_loop_scale(N, notch, Ts: float, iq: int) -> np.ndarray:
    """Scaling (n + 2,) of the loop's states xi = [e; chi] for its LMIs (:func:`notch_tube`).

    e by Z's supports sqrt(diag N); the filter's two states chi at their steady size for a
    constant q of Z's q support, |(I - A_d)^-1 (A_d B_d + B_d)| (plus 1e-3, so that
    neither is zero), in the coordinates of :func:`notch_closed_loop`.

    Parameters
    ----------
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.

    Returns
    -------
    (n + 2,) ndarray
        Positive scale, units of e then of the filter's states.
    """
    dn = DiscreteNotch(notch, Ts)
    z = np.sqrt(np.diag(np.asarray(N, float)))
    gain = np.abs(np.linalg.solve(np.eye(2) - dn.A_d, dn.A_d @ dn.B_d + dn.B_d))
    return np.r_[z, (gain + 1e-3) * z[iq]]


def notch_tube(A, B, F, N, w_max, notch, Ts: float, iq: int, lam: float = 0.995,
               variant: str = "", active: int = 40) -> NotchLoop:  # fmt: skip
    """The tube loop with the notch filter on q, certified RPI in its own states.

    The loop of :func:`notch_closed_loop`, xi = [e; chi] with the filter's two states,
    under u = F e' (q' = notch(q) in e'), is checked as it runs: an ellipsoid
    E = {xi' P^-1 xi <= 1} RPI for the box W on e at every vertex is sought with the
    S-procedure (:func:`fahv.synthesis.feedback.invariant_ellipsoid`), its projection on e
    bounded by s Z and its input deviation K xi by F Z's support (the tightening of
    eq. 30) per input. The solver's answer is then re-checked exactly: the worst
    one-step level of E over every vertex and every corner of W (:func:`worst_level`).
    If the level is at most 1, s at most 1 and the supports within the tightening, every
    assumption W was bounded under (e in Z, the applied input within the tightening)
    holds with the filter in the loop (:attr:`NotchLoop.certified`).

    This is the loop the law runs because its error's q is formed with the same filter
    on the nominal's q as well, q' - notch(q_r + q_n) = notch(q - q_r - q_n)
    (:class:`fahv.control.tube_mpc.TubeMPCLaw`); with the measured q filtered alone the
    error would also carry (notch - 1)(q_r + q_n), which this certificate does not cover.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube's error dynamics (unscaled).
    F : (m, n) ndarray
        Tube gain.
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W.
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.
    lam : float
        Contraction factor of the S-procedure certificate.
    variant : str
    active : int
        Vertex blocks per round of constraint generation.

    Returns
    -------
    NotchLoop
        With ``s``, ``level``, ``supports`` and ``tightening`` set when an ellipsoid was
        found (``s`` None if the loop is unstable, inf if the LMI is infeasible).

    Raises
    ------
    ValueError
        On inconsistent shapes.
    DesignError
        If the solver's ellipsoid fails the re-check of its LMI blocks.
    """
    loop, Acl, K = _notch_loop(A, B, F, notch, Ts, iq, variant)
    F, N = np.asarray(F, float), np.asarray(N, float)
    tightening = tuple(np.sqrt(np.einsum("ij,jk,ik->i", F, N, F)).tolist())
    if not loop.stable:
        return replace(loop, tightening=tightening)
    D = notch_loop_scale(N, notch, Ts, iq)
    w_xi = np.r_[np.asarray(w_max, float), 0.0, 0.0]
    ell = invariant_ellipsoid(Acl, w_max, D, N, K, np.asarray(tightening),
                              lambda P: vertex_levels(Acl, P, w_xi), lam, active)  # fmt: skip
    if ell is None:
        return replace(loop, s=float("inf"), tightening=tightening)
    return _recheck(loop, Acl, K, F, N, w_max, ell.P)


def notch_certificate(A, B, F, N, w_max, notch, Ts: float, iq: int, P,
                      variant: str = "", tightening=None) -> NotchLoop:  # fmt: skip
    """Re-check a given ellipsoid of the tube loop with the notch (:func:`notch_tube`).

    Exact, whatever found P: the worst one-step level of E = {xi' P^-1 xi <= 1} over
    every vertex of the loop in [e; chi] and every corner of W (:func:`vertex_levels`),
    the factor s of its projection on e into Z, and its input support through q' against
    F Z's (the tightening). Arguments as :func:`notch_tube`; ``P`` is (n + 2, n + 2) in
    the coordinates of :func:`notch_closed_loop`. ``tightening`` (m,), if given, is the
    tightening the supports are compared with in place of F Z's: for a gain designed
    for the loop (:func:`notch_gain`) it is the pair's, which the nominal QP applies.

    Returns
    -------
    NotchLoop
        ``certified`` if level <= 1, s <= 1 and every support within the tightening.

    Raises
    ------
    ValueError
        On inconsistent shapes (P included).
    """
    loop, Acl, K = _notch_loop(A, B, F, notch, Ts, iq, variant)
    return _recheck(loop, Acl, K, F, N, w_max, P, tightening)


@dataclass(frozen=True)
class NotchGain:
    """A tube gain designed for the loop through the notch and its check (:func:`notch_gain`).

    Attributes
    ----------
    F : (m, n) ndarray
        Gain on e' (e with q' = notch(q) for q) [(-, rad) per state unit].
    P : (n + 2, n + 2) ndarray
        Its ellipsoid in xi = [e; chi] (coordinates of :func:`notch_closed_loop`).
    loop : NotchLoop
        The exact re-check at the case's notch (:func:`notch_certificate` against the
        tightening the design applies), ``designed`` set.
    steps : tuple of (float, float)
        (eps_p, gamma) of every convex step taken, in order.
    """

    F: np.ndarray
    P: np.ndarray
    loop: NotchLoop
    steps: tuple[tuple[float, float], ...]

    def joint(self, notch, Ts: float, iq: int) -> np.ndarray:
        """Shape (n + m, n + m) of (e, u - v) over E(P): [[I, 0], K] P [[I, 0], K]'.

        ``notch``, ``Ts``, ``iq`` as :func:`notch_closed_loop` (the case's notch).
        """
        m, n = self.F.shape
        _, K = notch_closed_loop(np.zeros((1, n, n)), np.zeros((1, n, m)), self.F, notch, Ts, iq)
        J = np.vstack([np.hstack([np.eye(n), np.zeros((n, 2))]), K])
        return J @ self.P @ J.T


def notch_gain(A, B, F, N, w_max, notch, Ts: float, iq: int, lam: float = 0.995,
               continuation=(), rounds: int = 8, variant: str = "", tightening=None,
               log=print) -> NotchGain | None:  # fmt: skip
    """Design the tube gain of the loop through the notch on q together with its certificate.

    :func:`notch_tube` certifies the loop u = F e' for the tube's own F; a gain that
    tolerates the filter's lag less well than the loop needs (the eight-state pair with
    its attitude supports bounded: spectral radius above 1 through deep notches) has no
    such certificate. Every assumption the tube was bounded under holds for any gain
    whose loop has an ellipsoid RPI for W with its projection in Z and its input
    support within the tightening the nominal QP applies: the gain on e' is free. It is
    a static output feedback of the loop in xi = [e; chi], u - v = F T xi, designed by
    convex steps in (F, P) (:func:`fahv.synthesis.feedback.output_feedback_step`: the
    dilated RPI condition, the output structure on the slack, whitened by the last
    ellipsoid), in continuation over the notch's pole damping: from ``F``'s own ellipsoid
    at the first eps_p of ``continuation`` (one is sought with a 100 x looser input
    support bound), each certified gain starts the next, the case's ``notch.eps_p``
    last. Each eps_p is stepped until the exact re-check (:func:`notch_certificate`:
    level over every vertex and corner of W, s, the supports against the tightening)
    certifies it, or gamma gains less than 1e-3 (stalled), or ``rounds`` steps; each
    eps_p before the case's must end certified. A start certified as it is is kept
    (steps that only shrink the ellipsoid were measured not to carry a gain further).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube's error dynamics (unscaled).
    F : (m, n) ndarray
        The gain the continuation starts from (the tube's).
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W.
    notch : fahv.model.notch.NotchFilter
        The case's notch (its eps_p is the last of the continuation).
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.
    lam : float
        Contraction factor of the S-procedure.
    continuation : sequence of float
        Pole dampings eps_p before the case's, increasing, each below it.
    rounds : int
        Most convex steps per eps_p.
    variant : str
    tightening : (m,) array_like, optional
        The tightening the nominal QP applies, which the loop's input supports must keep
        within; default F Z's support (the tube's, when ``F`` is the tube's gain).
    log : callable
        One line per step.

    Returns
    -------
    NotchGain or None
        The last gain reached at the case's eps_p with its re-check (``loop.certified``
        says whether it is certified); None if an earlier eps_p of the continuation was
        not certified or no start ellipsoid exists.

    Raises
    ------
    ValueError
        On inconsistent shapes, or a continuation that is not increasing below the
        case's eps_p.
    DesignError
        If a solve's slack is singular (:func:`output_feedback_step`).
    """
    A, B, F, N = (np.asarray(v, float) for v in (A, B, F, N))
    path = [float(v) for v in continuation] + [float(notch.eps_p)]
    if any(b <= a for a, b in zip(path, path[1:], strict=False)) or path[0] <= 0.0:
        raise ValueError(f"notch_gain: continuation {list(continuation)} must increase "
                         f"from above 0 to below the case's eps_p {notch.eps_p}")  # fmt: skip
    w = np.asarray(w_max, float)
    tight = (
        np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
        if tightening is None
        else np.asarray(tightening, float)
    )
    w_xi = np.r_[w, 0.0, 0.0]
    R, n, m = B.shape
    B0 = np.concatenate([B, np.zeros((R, 2, m))], axis=1)
    steps: list[tuple[float, float]] = []
    loop = None
    for eps_p in path:
        nf = replace(notch, eps_p=eps_p)
        _, T = notch_closed_loop(A[:1], np.zeros((1, n, n)), np.eye(n), nf, Ts, iq)
        A0, _ = notch_closed_loop(A, B, np.zeros_like(F), nf, Ts, iq)
        Acl, K = notch_closed_loop(A, B, F, nf, Ts, iq)
        ell = invariant_ellipsoid(Acl, w, notch_loop_scale(N, nf, Ts, iq), N, K, 100.0 * tight,
                                  lambda P, Acl=Acl: vertex_levels(Acl, P, w_xi), lam)  # fmt: skip
        if ell is None:
            log(f"variant {variant}: notch gain at eps_p {eps_p:g}: no ellipsoid for the start "
                "gain: NOT designed")  # fmt: skip
            return None
        P = ell.P
        loop = replace(notch_certificate(A, B, F, N, w, nf, Ts, iq, P, variant, tight),
                       designed=True)  # fmt: skip
        best = np.inf
        last = eps_p == path[-1]
        for _ in range(rounds):
            if loop.certified:
                break
            got = output_feedback_step(
                A0, B0, T, w, F, P, N, tight,
                lambda Fk, Pk, nf=nf: vertex_levels(notch_closed_loop(A, B, Fk, nf, Ts, iq)[0],
                                                    Pk, w_xi),
                lam,
            )  # fmt: skip
            if got is None:
                log(f"variant {variant}: notch gain at eps_p {eps_p:g}: the step's LMI failed")
                break
            F, P = got.F, got.P
            steps.append((eps_p, got.gamma))
            loop = replace(notch_certificate(A, B, F, N, w, nf, Ts, iq, P, variant, tight),
                           designed=True)  # fmt: skip
            log(f"variant {variant}: notch gain at eps_p {eps_p:g}: step gamma {got.gamma:.4f} "
                f"({got.n_blocks} vertices held): s {loop.s:.4f}, level {loop.level:.6f}, "
                f"supports " + " / ".join(f"{v:.4f}" for v in loop.supports)
                + (" certified" if loop.certified else ""))  # fmt: skip
            if got.gamma > best - 1e-3:
                break  # stalled
            best = got.gamma
        if not loop.certified and not last:
            log(f"variant {variant}: notch gain at eps_p {eps_p:g} NOT certified: the "
                "continuation stops")  # fmt: skip
            return None
    return NotchGain(F, P, loop, tuple(steps))


def _recheck(loop, Acl, K, F, N, w_max, P, tightening=None) -> NotchLoop:
    """The exact re-check of :func:`notch_certificate` on a built loop (A_xi, K)."""
    F, N, P = (np.asarray(v, float) for v in (F, N, P))
    n = N.shape[0]
    if P.shape != (n + 2, n + 2):
        raise ValueError(f"notch_certificate: P has shape {P.shape}, expected {(n + 2, n + 2)}")
    level = float(vertex_levels(Acl, P, np.r_[np.asarray(w_max, float), 0.0, 0.0]).max())
    Li = np.linalg.inv(np.linalg.cholesky(N))
    s = float(np.sqrt(np.linalg.eigvalsh(Li @ P[:n, :n] @ Li.T).max()))
    supports = np.sqrt(np.einsum("ij,jk,ik->i", K, P, K))
    if tightening is None:
        tightening = np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
    tightening = np.asarray(tightening, float)
    if tightening.shape != supports.shape:
        raise ValueError(
            f"notch_certificate: tightening has shape {tightening.shape}, expected {supports.shape}"
        )
    return replace(loop, s=s, level=level, supports=tuple(supports.tolist()),
                   tightening=tuple(tightening.tolist()))  # fmt: skip


# -- onset of a fault and start of a run ----------------------------------------------
def onset_levels(lam, mu, w_base, pulse, gamma, n_steps, level0=1.0) -> np.ndarray:
    """Tube levels after a pulse in the estimate's error, from the S-procedure certificate.

    The certificate of LMI (24) gives, at every vertex and for every e and w,
    (A_cl e + w)' N^-1 (A_cl e + w) <= lam e' N^-1 e + sum_j mu_j w_j^2. With the
    disturbance estimate d <- d + gamma (r - d), the error of the estimate obeys
    eps_k = (1 - gamma) eps_k-1 + (r_k - r_k-1): a jump J of the residual (a fault
    onset, the constant part at the first step) decays as (1 - gamma)^k J on top of
    the steady bound w_base. Hence the level bound

        L_k+1 = lam L_k + sum_j mu_j (w_base,j + (1 - gamma)^k J_j)^2.

    Parameters
    ----------
    lam : float
    mu : (n,) ndarray
        Certificate of the tube (scaled coordinates).
    w_base, pulse : (n,) ndarray
        Steady bound and jump, scaled like ``mu``.
    gamma : float
        Estimator gain Ts / est_tau (1: no estimate memory).
    n_steps : int
    level0 : float
        Level at the jump (1: the error on the boundary of Z).

    Returns
    -------
    (n_steps + 1,) ndarray
        Level bounds L_0 .. L_n.
    """
    L = np.empty(n_steps + 1)
    L[0] = level0
    decay = 1.0
    for k in range(n_steps):
        w = np.asarray(w_base) + decay * np.asarray(pulse)
        L[k + 1] = lam * L[k] + float(np.asarray(mu) @ w**2)
        decay *= 1.0 - gamma
    return L


def fault_jump(vehicle, trim_map, u_hi_abs: float, rho: float, Ts, n_sub) -> np.ndarray:
    """Jump of the one-step residual at the onset of a loss, per state (9,).

    The worst over the trim grid of |Phi(x_r, (Phi_r, rho d)) - Phi(x_r, (Phi_r, d))|
    at d = u_hi_abs (the largest elevator the domain allows), nominal parameters.
    """
    hs, Vs = trim_map.h_grid, trim_map.V_grid
    X, U = [], []
    for h in hs:
        for V in Vs:
            x, u = trim_map(h, V)
            X.append(np.asarray(x[:9], float))
            U.append(np.array([u[0], u_hi_abs]))
    X, U = np.array(X), np.array(U)
    Uf = U.copy()
    Uf[:, DELTA_E] *= rho
    recs = params_records([vehicle.params] * len(X))
    return np.max(np.abs(_one_step(X, Uf, recs, Ts, n_sub) - _one_step(X, U, recs, Ts, n_sub)),
                  axis=0)  # fmt: skip


def schedule_points(envelope, count: int) -> np.ndarray:
    """Scheduling points of the domain (count, 2) [ft, ft/s].

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


def certify_tube(case: dict, vehicle, tp, trim_map, A, B, tube, tau, u_lo, u_hi, rho_min,
                 Dx, x_default, log, progress=None) -> dict:  # fmt: skip
    """Check the tube certificate against its own assumptions and report (no exception).

    Prints, with margins: the stated domain; the bound of the one-step disturbance over
    it per row, as a multiple of W (:func:`bound_disturbance`); the exact worst
    one-step level over the vertices and the corners of W and the factor by which W
    may grow (:func:`worst_level`, :func:`rpi_margin`); whether the certificate is
    closed (the bound inside W); the onset of a loss of 1 - rho_min at the largest
    elevator of the domain (:func:`onset_levels`).

    Parameters
    ----------
    case : dict
        Validated case data (``mpc``, ``certificate``, ``Ts``, ``plant_substeps``).
    vehicle, tp, trim_map
        As :func:`bound_disturbance`.
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube certificate (fault vertices included).
    tube : fahv.synthesis.feedback.TubeDesign
    tau : float
        Adjustable factor (eq. 48). The RPI check covers every gain tau' F, tau' in
        [tau, 1] (:func:`fahv.design.feasibility.gain_vertices`); for tau < 1 it also
        reports the factor g for which eq. (53)'s tau Z is RPI (W' = g W, eq. 47).
    u_lo, u_hi : (2,) ndarray
        Tightened nominal input limits (absolute).
    rho_min : float
    Dx : (n,) ndarray
        State scaling of the tube certificate (mu is in these units).
    x_default : (n,) ndarray
        Assumed nominal deviations of the states no QP row bounds.
    log : callable

    Returns
    -------
    dict
        Summary (JSON-able): ``certified`` (bool), per-row ``w_ratio`` and ``slack``,
        ``rpi_level``, ``rpi_growth``, ``onset_level_max``, the domain; for tau < 1
        ``rpi_level_tau`` (tau Z for W) and ``w_prime`` (g).
    """
    from fahv.plant.uncertainty import PAPER_UNCERTAINTY

    w = tube.w_max
    At, Bt = gain_vertices(A, B, tau)  # every gain tau' F, tau' in [tau, 1] (eq. 48)
    level, (vi, corner) = worst_level(At, Bt, tube.F, tube.N, w)
    growth = rpi_margin(At, Bt, tube.F, tube.N, w)
    gains = f" with the gains tau' F, tau' in [{tau:g}, 1]" if tau < 1 else ""
    log(
        f"RPI check (exact): worst one-step level over {At.shape[0]} vertices{gains} x "
        f"{2**w.size} corners of W and all of Z = {level:.5f} (<= 1 required; margin "
        f"{1 - level:.2e}); the tube stays RPI for W scaled by up to {growth:.3f}x"
        + ("  OK" if level <= 1.0 else ": NOT RPI for its own W")
    )
    out = {"rpi_level": level, "rpi_growth": growth, "certified": False}
    if tau < 1:  # eq. (53)'s smaller tube tau Z: RPI for the incomplete set W' only
        level_t = worst_level(A, B, tube.F, tube.N, w, tau)[0]
        w_prime = rpi_margin(A, B, tube.F, tube.N, w, tau)
        log(
            f"adjustable tube tau Z with tau F (eq. 47-48, tau = {tau:g}): worst one-step "
            f"level for W = {level_t:.5f}; RPI for W' = {w_prime:.3f} W (the incomplete "
            f"disturbance set; >= tau by the LMI's tau vertices"
            + ("  OK)" if w_prime >= tau * (1 - 1e-9) else ": NOT as designed)")
            + ". For the whole W the error stays in Z and the input deviation in tau F Z"
        )
        out.update(rpi_level_tau=level_t, w_prime=w_prime)
    n_s = case["certificate"]["schedules"]
    if n_s == 0 or A.shape[1] != 9:
        why = (
            "skipped (certificate.schedules: 0)"
            if n_s == 0
            else (f"not evaluated for the {A.shape[1]}-state design model (9-state CM/DM only)")
        )
        log(f"certificate domain: {why}; the tube certificate is NOT checked over its domain")
        out["domain"] = why
        return out
    mpc = case.get("mpc") or {}
    if not mpc:
        from fahv.control.nominal_mpc import MPC_SECTION_FIELDS

        mpc = {f.name: f.default for f in MPC_SECTION_FIELDS}
    nominal, notes = nominal_half_widths(mpc, x_default)
    z_box = tube.z_box  # under the whole W the error stays in Z, also for tau < 1
    t = tau * tube.tightening  # the input deviation tau F e, e in Z
    unc = {k: v * case["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    dom = CertificateDomain(
        schedule_points(vehicle.envelope, n_s), nominal + z_box, nominal, u_lo - t, u_hi + t,
        unc, tuple(sorted({rho_min, 1.0})), case["Ts"], case["plant_substeps"], notes,
    )  # fmt: skip
    log(
        f"certificate domain: {n_s} scheduling point(s) over the envelope; x - x_rs within "
        f"nominal + Z = +/-[{', '.join(f'{v:.3g}' for v in dom.x_half)}]; inputs Phi in "
        f"[{dom.u_lo[0]:.3f}, {dom.u_hi[0]:.3f}], delta_e in [{np.degrees(dom.u_lo[1]):.1f}, "
        f"{np.degrees(dom.u_hi[1]):.1f}] deg (tightened set + tau F Z); all "
        f"{2 ** len(unc)} corners of the sec. 5.1 box; rho_f in {list(dom.rho)}. Assumed: "
        + "; ".join(notes)
    )
    bnd = bound_disturbance(dom, vehicle, tp, trim_map, progress)
    ratio = bnd.w_bound / w
    slack = (w - bnd.w_bound) / w
    log(
        "W over the domain (Taylor bound + corner remainder, "
        f"{bnd.n_evaluations} plant steps): bound / W per row = "
        + ", ".join(f"{r:.2f}" for r in ratio)
        + "; slack (W - bound) / W = "
        + ", ".join(f"{s:+.2f}" for s in slack)
    )
    closed = bool(np.all(bnd.w_bound <= w))
    worst_row = int(np.argmax(ratio))
    log(
        "certificate closed: the disturbance over the domain lies inside W  OK" if closed else
         f"certificate NOT closed: the disturbance over the domain exceeds W by up to "
         f"{ratio[worst_row]:.1f}x (row {worst_row}); the tube is RPI only up to "
         f"{growth:.3f} W, so e in Z is NOT guaranteed for this plant (measured, "
         "docs/control_design.md)"
    )  # fmt: skip
    # onset of the design loss at the largest elevator of the domain, estimate's pulse
    gamma, _ = estimator_gains(case["Ts"], mpc.get("est_tau", 0.0))
    J = fault_jump(
        vehicle, trim_map, float(dom.u_hi[1]), rho_min, case["Ts"], case["plant_substeps"]
    )
    Ls = onset_levels(tube.lam, tube.mu, np.minimum(bnd.w_bound, w) / Dx, J / Dx, gamma, 2000)
    log(
        f"onset of a {100 * (1 - rho_min):.0f} % loss at delta_e = "
        f"{np.degrees(dom.u_hi[1]):.1f} deg (estimate time constant {mpc.get('est_tau')} s): "
        f"level bound from the certificate up to {Ls.max():.3g} "
        + ("<= 1  OK" if Ls.max() <= 1 else "> 1: the onset is NOT certified")
    )
    out.update(
        certified=closed and Ls.max() <= 1.0 and level <= 1.0,
        w_bound=bnd.w_bound.tolist(), w_ratio=ratio.tolist(), slack=slack.tolist(),
        corner_max=bnd.corner_max.tolist(), worst=bnd.worst, onset_level_max=float(Ls.max()),
        domain={"schedules": dom.schedules.tolist(), "x_half": dom.x_half.tolist(),
                "nominal_half": nominal.tolist(), "u_lo": dom.u_lo.tolist(),
                "u_hi": dom.u_hi.tolist(), "rho": list(dom.rho), "assumptions": list(notes)},
    )  # fmt: skip
    return out
