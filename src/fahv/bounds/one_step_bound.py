"""Bounds of the one-step disturbance W over a domain, deterministic (no sampling).

Two forms, one per tube form (`fahv.bounds.domain` states their domains):

**Taylor form** (the paper's vertex tube around the scheduling trim,
`bound_disturbance`). In deviation coordinates around the scheduling trim
(x_rs, u_rs) of the nominal MPC, with A_s, B_s the scheduled discrete model and
P = diag(1, rho_f):

    Delta(z, p, rho_f) = Phi_p(x_rs + z_x, P (u_rs + z_u)) - x_rs - A_s z_x - B_s P z_u
                         - [Phi_p(x_rs, P u_rs) - x_rs]

is the one-step error of the vertex model with the constant part at the trim (which
the online estimate removes, `disturbance.constant: estimated`) taken out; Phi_p is
one control period of the plant (`fahv.bounds.plant_step.plant_step`). It is
bounded over the domain by a second-order Taylor model with an interval bound over the
box, plus a third-order remainder measured at every corner of the box.

**Integral form** (the eight-state tube set along the nominal, `product_bound`,
`altitude_bound`). The error along the nominal is exactly a vertex combination of
the one-period Jacobians averaged along the segment from the nominal to the plant
(`fahv.bounds.vertices` (1)), up to what the vertices leave: each vehicle's
parameter residual and the interpolation remainder. Both are first order in the tube,
and their supports are exact over the product set {|e_h| <= H} x Z_8. The altitude error
is held by the nominal's reset of its h to the measured one every M fast steps
(`mpc.h_reset`), which makes e_h = 0 there:

    |e_h| <= H = M (step + w_h),                                                 (1)
    step = max over the vertices of max over Z_8 of |a_h,8 e_8 + b_h F_8 e_8|,

with w_h the h row's own disturbance over the product set (solved to its fixed point:
w_h grows with H, weakly). The altitude error then enters the other rows as a
disturbance, max over the vertices of |A_8h| H, added to their bound.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from fahv.bounds.domain import CertificateDomain, joint_of, product_supports
from fahv.bounds.plant_step import REMAINDER_FACTOR, plant_step
from fahv.bounds.vertices import NominalVertices
from fahv.errors import DesignError
from fahv.plant.rk4 import perturbed_records


@dataclass(frozen=True)
class DisturbanceBound:
    """Bound of the one-step disturbance over a `fahv.bounds.domain.CertificateDomain`.

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


def _disturbance(Z, x_rs, u_rs, A_s, B_s, rho, recs, Ts, n_sub):
    """Delta (module docstring) for L points Z (L, 11) and parameter records (L,)."""
    L = Z.shape[0]
    P = np.array([1.0, rho])
    X = x_rs[None, :] + Z[:, :9]
    U = (u_rs[None, :] + Z[:, 9:]) * P[None, :]
    x1 = plant_step(X, U, recs, Ts, n_sub)
    x0 = plant_step(np.tile(x_rs, (L, 1)), np.tile(u_rs * P, (L, 1)), recs, Ts, n_sub)
    return x1 - x0 - Z[:, :9] @ A_s.T - (Z[:, 9:] * P[None, :]) @ B_s.T


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


def _scheduled(disc, tp, h, V):
    """The scheduled discrete model (A_s, B_s) of the TP model at (h, V)."""
    w = tp.weights(h, V)
    return np.tensordot(w, disc.A, 1), np.tensordot(w, disc.B, 1)


def _quadratic_bounds(domain, disc, tp, trim_map, recs_all, progress):
    """The quadratic part of `bound_disturbance`: per row the largest Taylor bound.

    Returns the bound (9,), per row the data of its schedule, corner and rho_f, the
    Taylor models by (schedule, rho_f, corner) and the plant steps made.
    """
    n = 9
    quad = np.zeros(n)
    best = [None] * n  # (schedule index, corner index, rho, center, a, x_rs, u_rs, A_s, B_s)
    n_eval = 0
    cache = {}
    items = list(itertools.product(range(len(domain.schedules)), domain.rho))
    for si, rho in items if progress is None else progress(items):
        h_s, V_s = domain.schedules[si]
        x_rs, u_rs = trim_map(h_s, V_s)
        x_rs = np.asarray(x_rs[:9], float)
        A_s, B_s = _scheduled(disc, tp, h_s, V_s)
        center = np.concatenate([np.zeros(9), 0.5 * (domain.u_lo + domain.u_hi) - u_rs])
        a = np.concatenate([domain.x_half, 0.5 * (domain.u_hi - domain.u_lo)])
        S, hstep = _stencil(a)
        K, C = S.shape[0], len(recs_all)
        G = _disturbance(np.tile(center + S, (C, 1)), x_rs, u_rs, A_s, B_s, rho,
                         np.repeat(recs_all, K), domain.Ts, domain.n_sub)  # fmt: skip
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
                    best[j] = (si, c, rho, center, a, x_rs, u_rs, A_s, B_s)
    return quad, best, cache, n_eval


def _corner_remainders(domain, recs_all, best, cache):
    """The third-order remainder at the 2^11 corners of the box, for each row's worst case.

    Returns REMAINDER_FACTOR times the largest mismatch of the quadratic model (9,), the
    largest exact |Delta| at the corners (9,) and the plant steps made.
    """
    n = 9
    rem, cmax, n_eval = np.zeros(n), np.zeros(n), 0
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=11)))
    done = {}
    for j in range(n):
        si, c, rho, center, a, x_rs, u_rs, A_s, B_s = best[j]
        key = (si, rho, c)
        if key not in done:
            Zc = center + signs * a
            exact = _disturbance(
                Zc, x_rs, u_rs, A_s, B_s, rho, np.repeat(recs_all[c : c + 1], len(Zc)),
                domain.Ts, domain.n_sub,
            )  # fmt: skip
            n_eval += 2 * len(Zc)
            g0, J, H = cache[key]
            dz = signs * a
            model = g0 + dz @ J.T + 0.5 * np.einsum("li,jik,lk->lj", dz, H, dz)
            done[key] = (np.max(np.abs(exact - model), axis=0), np.max(np.abs(exact), axis=0))
        mis, ex = done[key]
        rem = np.maximum(rem, REMAINDER_FACTOR * mis)
        cmax = np.maximum(cmax, ex)
    return rem, cmax, n_eval


def bound_disturbance(domain: CertificateDomain, vehicle, tp, trim_map, progress=None):
    """Bound max |Delta_j| over the whole domain (module docstring), deterministic.

    For every scheduling point, parameter corner (all 2^P) and rho_f of the domain,
    Delta is expanded about the centre c of the (state, input) box B = c + [-a, a]
    (11 dimensions) with central differences of step a/2 (243 plant steps), and
    bounded over the box by |g0| + |J| a + 1/2 a' |H| a (elementwise absolute values:
    an interval bound of the quadratic model). The third-order remainder is measured
    as the largest mismatch between the exact Delta and the quadratic model at all
    2^11 corners of the box, for the parameter corner and rho_f that give the largest
    quadratic bound of each row, and added times `fahv.bounds.plant_step.REMAINDER_FACTOR`.

    Parameters
    ----------
    domain : CertificateDomain
    vehicle : fahv.model.vehicle.Vehicle
        Nominal vehicle (parameters perturbed here).
    tp : fahv.model.tp_model.TPModel
        The continuous TP model (discretised at `domain.Ts`), CM (9 states).
    trim_map : fahv.model.trim.TrimMap
        Scheduling trims (x_rs, u_rs).
    progress : callable, optional
        Iterable wrapper (tqdm).

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
    quad, best, cache, n_quad = _quadratic_bounds(domain, disc, tp, trim_map, recs_all,
                                                  progress)  # fmt: skip
    rem, cmax, n_rem = _corner_remainders(domain, recs_all, best, cache)
    worst = [
        {
            "schedule": domain.schedules[b[0]].tolist(),
            "corner": dict(zip(domain.uncertainty, corners[b[1]].tolist(), strict=True)),
            "rho_f": b[2],
        }
        for b in best
    ]
    return DisturbanceBound(quad + rem, quad, rem, cmax, worst, n_quad + n_rem)


def disturbance_at(domain: CertificateDomain, vehicle, tp, trim_map, schedule, Z, signs, rho):
    """Delta (L, 9) at explicit points: an independent evaluation for tests.

    Parameters
    ----------
    domain : CertificateDomain
    vehicle, tp, trim_map
        As `bound_disturbance`.
    schedule : (2,) array_like
        Scheduling point (h, V).
    Z : (L, 11) ndarray
        Deviations (x - x_rs, u - u_rs).
    signs : (L, P) ndarray
        Parameter values as fractions in [-1, 1] of the box, one row per point.
    rho : float
        Elevator effectiveness.

    Returns
    -------
    (L, 9) ndarray
    """
    disc = tp.discretize(domain.Ts)
    x_rs, u_rs = trim_map(*schedule)
    A_s, B_s = _scheduled(disc, tp, *schedule)
    recs = perturbed_records(vehicle.params, domain.uncertainty, signs)
    return _disturbance(
        np.asarray(Z, float), np.asarray(x_rs[:9], float), u_rs, A_s, B_s, rho, recs,
        domain.Ts, domain.n_sub,
    )  # fmt: skip


def product_bound(
    nv: NominalVertices, F_8, N_8, H: float, joint=None
) -> tuple[np.ndarray, np.ndarray]:
    """Parameter and interpolation parts (9,), (9,) of the disturbance over the product set.

    The parameter part is, per row, the largest support over {|e_h| <= H} x Z_8 of each
    vehicle's residual (the part of its Jacobian deviation the vertices do not carry)
    applied to [e; P F e], P = diag(1, rho_f), at every box corner, for rho_f at both
    ends of [rho_min, 1] (exact for the product set: |r_h| H plus the ellipsoid's
    support). The interpolation part is the elementwise remainder bound times the
    product set's supports in e and F e. With `joint` the set of (e_8, u - v) is the
    ellipsoid of that shape in place of {(e_8, F_8 e_8) : e_8 in Z_8}. Without it and
    with `nv.tau` < 1 (the adjustable law, eq. 48), u - v = tau' F_8 e_8 for any
    tau' in [tau, 1]: the parameter part is the larger of its values at the two ends
    (each support is convex in tau'), and F_8 Z_8 holds every tau' F_8 Z_8.

    Parameters
    ----------
    nv : NominalVertices
        Vertex data over the scheduling box (`fahv.bounds.vertices.nominal_vertices`).
    F_8 : (2, 8) array_like
    N_8 : (8, 8) array_like
    H : float
        Altitude error bound [ft].
    joint : (10, 10) array_like, optional
        A loop's joint shape of (e_8, u - v) (`fahv.bounds.domain.joint_shape`).

    Returns
    -------
    parameters, interpolation : (9,) ndarray
        In state units per period, rows h ... eta_2_dot.

    Raises
    ------
    ValueError
        On a malformed `joint` or tube set, or a `joint` with `nv.tau` < 1.
    """
    C = joint_of(F_8, N_8, joint)
    if joint is not None and nv.tau < 1.0:
        raise ValueError(
            f"product_bound: a loop's joint shape covers its own gain, not the adjustable "
            f"law's tau' in [{nv.tau:g}, 1]"
        )
    # the adjustable law's gains tau' F, tau' in [nv.tau, 1]: each support is the square
    # root of a convex quadratic in tau', so its largest value is at an end of the segment
    shapes = [C] if nv.tau == 1.0 else [C, joint_of(nv.tau * F_8, N_8, None)]
    par = np.zeros(9)
    R = nv.residual  # (64, C, 9, 11) on (e_h, e_8, u - v)
    for rho, Cg in itertools.product((nv.rho_min, 1.0), shapes):
        S = np.r_[np.ones(9), rho]  # (e_8, u - v) -> (e_8, P (u - v)), P = diag(1, rho_f)
        sup = np.abs(R[..., 0]) * H + np.sqrt(
            np.einsum("scij,jk,scik->sci", R[..., 1:], S[:, None] * Cg * S[None, :], R[..., 1:])
        )
        par = np.maximum(par, sup.max(axis=(0, 1)))
    s_lo, s_oth = product_supports(F_8, N_8, H, C)  # (h, V, alpha, theta, F Z), (q, flexible)
    interp = nv.interp @ np.concatenate([s_lo[:4], s_oth, s_lo[4:]])
    return par, interp


@dataclass(frozen=True)
class AltitudeBound:
    """H of (1) and the disturbance bound of the eight rows it implies.

    Attributes
    ----------
    H : float
        [ft], the fixed point of H = moves (step + w_h(H)).
    step : float
        [ft] largest support over Z_8 of a_h,8 e_8 + b_h F_8 e_8 over the vertices.
    w_h : float
        [ft] the h row's disturbance at H.
    bound : (8,) ndarray
        Disturbance bound of rows V ... eta_2_dot over the product set, e_h's coupling
        max |A_8h| H included.
    """

    H: float
    step: float
    w_h: float
    bound: np.ndarray


def altitude_bound(nv: NominalVertices, A, B, F_8, N_8, moves: int, joint=None) -> AltitudeBound:
    """Solve (1) for H and bound the eight rows' disturbance over the product set.

    Parameters
    ----------
    nv : NominalVertices
    A : (R, 9, 9) array_like
    B : (R, 9, 2) array_like
        The vertices (`fahv.bounds.vertices.NominalVertices.vertices`).
    F_8 : (2, 8) array_like
    N_8 : (8, 8) array_like
    moves : int
        Fast steps between the nominal's altitude resets.
    joint : (10, 10) array_like, optional
        Joint shape of (e_8, u - v) in place of the tube set's
        (`fahv.bounds.domain.joint_shape`): the step of (1) is then the support of
        a_h,8 e_8 + b_h (u - v) over it.

    Returns
    -------
    AltitudeBound

    Raises
    ------
    DesignError
        If the iteration for H does not converge (the h row's own disturbance grows with
        H as fast as the reset allows).
    ValueError
        On a malformed `joint` or tube set.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    C = joint_of(F_8, N_8, joint)
    c = np.concatenate([A[:, 0, 1:], B[:, 0]], axis=1)  # (R, 10) on (e_8, u - v)
    step = float(np.sqrt(np.einsum("ri,ij,rj->r", c, C, c)).max())
    H = moves * step
    for _ in range(100):
        par, interp = product_bound(nv, F_8, N_8, H, joint)  # joint None: the gains of nv.tau
        H_new = moves * (step + par[0] + interp[0])
        if abs(H_new - H) <= 1e-12 * H_new:
            break
        H = H_new
    else:
        raise DesignError(f"eight-state tube: the altitude bound H does not converge ({H:.4g} ft)")
    bound = par[1:] + interp[1:] + np.abs(A[:, 1:, 0]).max(axis=0) * H_new
    return AltitudeBound(float(H_new), step, float(par[0] + interp[0]), bound)
