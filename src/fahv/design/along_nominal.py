"""The tube certificate along the nominal: vertices over a scheduling box, W of what is left.

With the nominal state moving by the nominal vehicle's nonlinear CM (``mpc.nominal_model:
cm``), z+ = f_0(z, v) + d, and the plant x+ = f_p(x, P u) under u = v + F e (P =
diag(1, rho_f), eq. 15), the tube error e = x - z obeys, once the estimate d holds the
constant part c(z, v) = f_p(z, P v) - f_0(z, v) at the nominal point::

    e+ = f_p(z + e, P (v + F e)) - f_p(z, P v)
       = J_p(z, P v) [e; P F e] + w2(e)                                    (1)

with J_p the one-period Jacobian [A, B] of the perturbed vehicle at the nominal point
and w2 second order in e. Unlike the error around the scheduling trim
(:mod:`fahv.design.certificate`), nothing in (1) grows with the distance of the nominal
from the trim: the nominal's manoeuvre enters only through *where* J_p is taken.

This module covers J_p by a vertex set and bounds the rest by W:

* **Scheduling box** (:class:`SchedulingBox`): the nominal points the certificate covers,
  s = (h, V, alpha - alpha_r, theta - theta_r, Phi - Phi_r, delta_e - delta_e,r) with the
  trim (x_r, u_r) at (h, V) and the applied input; q and the flexible states of the
  nominal within stated half-widths.
* **Vertices** (:func:`nominal_vertices`): the nominal vehicle's J_0 at the 64 corners
  of the box, each shifted along k principal directions of the parameter box's Jacobian
  deviation (the corners of their coefficient range), with B and B P for rho_f in
  {rho_min, 1}: (64 2^k 2) vertices. Between corners J_0 is the multilinear
  interpolation of its corner values (a convex combination of them) plus a remainder
  bounded by sum_i a_i^2 / 8 max |d^2 J_0 / ds_i^2| (tensor-product linear interpolation),
  the second derivatives taken as REMAINDER_FACTOR times the largest second difference
  along each edge of the box.
* **W** (:func:`bound_along_nominal`), per row, three parts, each first or second order
  in the size of Z: the part of each vehicle's Jacobian deviation the directions do not
  carry (every corner of the sec. 5.1 box and interior vehicles, at every corner of the
  scheduling box), the interpolation remainder and the linear effect of the nominal's q
  and flexible deviations (elementwise bounds times the supports of e and F e over Z),
  and w2 over Z (the exact extreme of the quadratic term over the ellipsoid from the
  Hessian at every corner point and vehicle, times REMAINDER_FACTOR for the variation
  between corners and the third-order rest).

**The integral form** (``bound_along_nominal(..., nominal=...)``). By the mean-value
theorem in integral form, (1) holds exactly with the Jacobian averaged along the segment,

    e+ = [int_0^1 J_p(z + s e, P (v + s F e)) ds] [e; P F e],                (2)

no second-order term. If the segment lies in the scheduling box, that average lies in
the convex hull of J_p over the box, hence of the vertices up to the same remainders
(interpolation, parameter residual). The segment lies in the box when the box holds the
nominal's own ranges grown by the supports of Z and F Z: then W has only parts of first
order in the size of Z, so a pair that closes at one size closes at any size whose Z
still fits the box's margin, and W can hold what does not shrink with Z (the estimate's
error). :func:`bound_along_nominal` checks the containment and refuses a box that does
not hold it.

What it assumes (stated by :class:`AlongNominalBound`): the estimate has converged to the
constant part at the nominal point (the onset of a fault and the estimate's lag are not
in W), the nominal stays in the scheduling box (the QP's attitude rows bound alpha and
theta; its input rows and q, the flexible states are assumed), vehicles inside the box
are covered as sampled (the worst case of each parameter's monotone effect at the
corners, interior vehicles checked).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from fahv.design.certificate import REMAINDER_FACTOR, _one_step, _stencil, _taylor, jacobians
from fahv.design.feasibility import gain_vertices
from fahv.errors import DesignError
from fahv.plant.rk4 import params_records, perturbed_records

#: Widening of the parameter coefficients' range (fraction of its width, each side).
COEF_MARGIN = 0.01

#: Coordinates of the scheduling box (units: ft, ft/s, rad, rad, -, rad).
BOX_COORDINATES = ("h", "V", "alpha", "theta", "Phi", "delta_e")


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
        """How far this box reaches beyond ``inner``, in the coordinates' units.

        Returns the lo side (6,), the hi side (6,) and other_half - inner.other_half (5,);
        negative where ``inner`` is not inside.
        """
        return (
            np.asarray(inner.lo, float) - np.asarray(self.lo, float),
            np.asarray(self.hi, float) - np.asarray(inner.hi, float),
            np.asarray(self.other_half, float) - np.asarray(inner.other_half, float),
        )

    def corners(self) -> np.ndarray:
        """The 64 corners (64, 6), in :func:`itertools.product` order (lo first)."""
        return np.array(list(itertools.product(*zip(self.lo, self.hi, strict=True))))

    def points(self, trim_map, s) -> tuple[np.ndarray, np.ndarray]:
        """Nominal states (L, 9) and applied inputs (L, 2) of box points s (L, 6)."""
        s = np.atleast_2d(np.asarray(s, float))
        x_r, u_r = trim_map.at(s[:, 0], s[:, 1])
        X = np.array(x_r, float)[:, :9].copy()
        X[:, 2] += s[:, 2]
        X[:, 3] += s[:, 3]
        return X, np.array(u_r, float) + s[:, 4:6]


@dataclass(frozen=True)
class NominalVertices:
    """The vertex set of a certificate along the nominal and what it leaves to W.

    Attributes
    ----------
    box : SchedulingBox
    J0 : (64, 9, 11) ndarray
        Nominal vehicle's Jacobians at the box corners.
    dirs : (k, 9, 11) ndarray
        Parameter directions (unscaled).
    c_lo, c_hi : (k,) ndarray
        Coefficient range over every vehicle and corner, widened by ``coef_margin`` of
        :func:`nominal_vertices`.
    residual : (64, C, 9, 11) ndarray
        Each vehicle's Jacobian deviation minus its carried part, per corner.
    interp : (9, 11) ndarray
        Elementwise bound of the interpolation remainder of J_0 plus the linear effect
        of the nominal's q and flexible deviations.
    hessians : (64, C, 9, 11, 11) ndarray
        Hessians of one period in (x, u) at every corner point and vehicle.
    rho_min : float
    n_vehicles : tuple of int
        Corners of the parameter box and interior vehicles in ``residual``.
    tau : float
        Smallest factor of the ancillary gain tau' F the vertices cover, tau' in [tau, 1]
        (1: the baseline law, eq. 36; below 1: the adjustable law, eq. 48). Set it with
        :func:`dataclasses.replace`.
    """

    box: SchedulingBox
    J0: np.ndarray
    dirs: np.ndarray
    c_lo: np.ndarray
    c_hi: np.ndarray
    residual: np.ndarray
    interp: np.ndarray
    hessians: np.ndarray
    rho_min: float
    n_vehicles: tuple
    tau: float = 1.0

    @property
    def n_vertices(self) -> int:
        """R, the number of vertices :meth:`vertices` returns (without building them)."""
        return self.J0.shape[0] * 2 ** len(self.c_lo) * 2 * (2 if self.tau < 1.0 else 1)

    def vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) vertex arrays (R, 9, 9), (R, 9, 2) of the tube LMI (24).

        R = 64 2^k 2 (box corners, parameter directions, rho_f at both ends of
        [rho_min, 1]); with ``tau`` < 1 twice that, [A_i, B_i] and [A_i, tau B_i]
        (:func:`fahv.design.feasibility.gain_vertices`, eq. 48): every closed loop
        A_i + tau' B_i F with tau' in [tau, 1] is a convex combination of them.
        """
        As, Bs = [], []
        for rho in (self.rho_min, 1.0):
            for c in itertools.product(*zip(self.c_lo, self.c_hi, strict=True)):
                Jv = self.J0 + np.tensordot(np.asarray(c, float), self.dirs, 1)[None]
                As.append(Jv[:, :, :9])
                Bs.append(Jv[:, :, 9:] * np.array([1.0, rho]))
        return gain_vertices(np.concatenate(As), np.concatenate(Bs), self.tau)


def nominal_vertices(
    box: SchedulingBox,
    vehicle,
    trim_map,
    uncertainty: dict,
    rho_min: float,
    Ts: float,
    n_sub: int,
    scale,
    k: int,
    row_scale,
    col_scale,
    interior: int = 256,
    seed: int = 0,
    hessians: bool = True,
    coef_margin: float = COEF_MARGIN,
) -> NominalVertices:
    """Build the vertex set of module docstring (1) and the data W is bounded from.

    Parameters
    ----------
    box : SchedulingBox
    vehicle : fahv.model.vehicle.Vehicle
        The nominal vehicle.
    trim_map : fahv.model.trim.TrimMap
    uncertainty : dict[str, float]
        Relative half-widths of the parameter box (all 2^P corners are evaluated).
    rho_min : float
        Smallest elevator effectiveness (eq. 15).
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps of the plant per period.
    scale : (11,) array_like
        Design scaling (Dx, Du) of the finite differences.
    k : int
        Parameter directions carried by the vertices.
    row_scale, col_scale : (9,), (11,) array_like
        Row divisor (a W) and column factor (supports of e and F e over a Z) of the
        Jacobian deviations before the SVD: the directions that matter most for that
        pair.
    interior : int
        Vehicles drawn uniformly inside the box (seeded) besides the corners.
    seed : int
    hessians : bool
        Compute the Hessians (243 plant steps per point and vehicle; needed by
        :func:`bound_along_nominal`).
    coef_margin : float
        The coefficient range over the corners, widened by this fraction of its width
        on each side, so that it holds the coefficients of points inside the box too
        (measured by the tests: they exceed the corners' range by less than 1e-4 of it).

    Returns
    -------
    NominalVertices

    Raises
    ------
    DesignError
        If a plant step is not finite (the box leaves the model's validity).
    """
    scale = np.asarray(scale, float)
    names = list(uncertainty)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=len(names))))
    inner = np.random.default_rng(seed).uniform(-1.0, 1.0, (interior, len(names)))
    fractions = np.vstack([corners, inner])
    recs = perturbed_records(vehicle.params, uncertainty, fractions)
    r0 = params_records([vehicle.params])
    S = box.corners()
    X, U = box.points(trim_map, S)
    J0 = jacobians(X, U, np.repeat(r0, len(S)), Ts, n_sub, scale)
    C = len(recs)
    Jp = jacobians(np.repeat(X, C, 0), np.repeat(U, C, 0), np.tile(recs, len(S)), Ts, n_sub,
                   scale).reshape(len(S), C, 9, 11)  # fmt: skip
    if not (np.all(np.isfinite(J0)) and np.all(np.isfinite(Jp))):
        raise DesignError("scheduling box: a plant step is not finite; the box leaves the model")
    rs, cs = np.asarray(row_scale, float), np.asarray(col_scale, float)
    dev = (Jp - J0[:, None]) / rs[None, None, :, None] * cs
    flat = dev.reshape(-1, 99)
    _, _, Vt = np.linalg.svd(flat, full_matrices=False)
    G = Vt[:k]
    coef = flat @ G.T
    unscale = rs[:, None] / cs[None, :]
    residual = (flat - coef @ G).reshape(Jp.shape) * unscale
    interp = _interpolation_remainder(box, trim_map, r0, Ts, n_sub, scale)
    H = np.zeros((len(S), C, 9, 11, 11), dtype=np.float32)
    if hessians:
        H = _hessians(X, U, recs, Ts, n_sub, scale)
    c_lo, c_hi = coef.min(axis=0), coef.max(axis=0)
    pad = coef_margin * (c_hi - c_lo)
    return NominalVertices(
        box, J0, G.reshape(k, 9, 11) * unscale[None], c_lo - pad, c_hi + pad,
        residual, interp, H, float(rho_min), (len(corners), interior),
    )  # fmt: skip


def _interpolation_remainder(box, trim_map, r0, Ts, n_sub, scale) -> np.ndarray:
    """Elementwise bound (9, 11) of J_0 minus its multilinear interpolation, plus q/flex.

    Along each coordinate i and each of the 32 edges of the box in that direction,
    the second difference J(mid) - (J(lo) + J(hi)) / 2 = a_i^2 / 8 J'' (exact for a
    quadratic); REMAINDER_FACTOR times the largest over the edges, summed over the six
    coordinates. The nominal's q and flexible deviations enter J_0 about linearly:
    their effect |J(x + half_j e_j) - J(x)| at the box centre, times REMAINDER_FACTOR.
    """
    lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
    pts = []
    for i in range(6):
        rest = [j for j in range(6) if j != i]
        for sel in itertools.product((0, 1), repeat=5):
            base = np.where(np.array(sel) == 0, lo[rest], hi[rest])
            for t in (lo[i], 0.5 * (lo[i] + hi[i]), hi[i]):
                pts.append(np.insert(base, i, t))
    X, U = box.points(trim_map, np.array(pts))
    J = jacobians(X, U, np.repeat(r0, len(X)), Ts, n_sub, scale).reshape(6, 32, 3, 9, 11)
    second = np.abs(J[:, :, 1] - 0.5 * (J[:, :, 0] + J[:, :, 2]))  # (6, 32, 9, 11)
    E = REMAINDER_FACTOR * second.max(axis=1).sum(axis=0)
    Xc, Uc = box.points(trim_map, 0.5 * (lo + hi))
    Xo = np.repeat(Xc, 6, 0)
    for j, idx in enumerate((4, 5, 6, 7, 8)):
        Xo[j + 1, idx] += box.other_half[j]
    Jo = jacobians(Xo, np.repeat(Uc, 6, 0), np.repeat(r0, 6), Ts, n_sub, scale)
    return E + REMAINDER_FACTOR * np.abs(Jo[1:] - Jo[0]).sum(axis=0)


def _hessians(X, U, recs, Ts, n_sub, scale) -> np.ndarray:
    """Hessians (S, C, 9, 11, 11) of one period in (x, u) at S points for C vehicles.

    Central differences with steps of 1e-2 of the scaling (the stencil of
    :func:`fahv.design.certificate._stencil`), kept in float32 (their use is a bound
    with a factor REMAINDER_FACTOR; the rounding is 1e-7 relative).
    """
    S, C = len(X), len(recs)
    St, hstep = _stencil(1e-2 * np.asarray(scale, float))
    K = len(St)
    out = np.empty((S, C, 9, 11, 11), dtype=np.float32)  # 1.1 kB per point and vehicle
    for si in range(S):
        Z = np.concatenate([X[si], U[si]])[None, :] + St  # (K, 11)
        Zr = np.tile(Z, (C, 1))
        G = _one_step(Zr[:, :9], Zr[:, 9:], np.repeat(recs, K), Ts, n_sub).reshape(C, K, 9)
        for c in range(C):
            out[si, c] = _taylor(G[c], hstep, 11)[2]
    return out


@dataclass(frozen=True)
class AlongNominalBound:
    """Per-row bound of W along the nominal for one tube (module docstring).

    Attributes
    ----------
    parameters, interpolation, second_order, total : (9,) ndarray
        The three parts and their sum, state units (``second_order`` zero in the
        integral form).
    assumptions : tuple of str
    margin : (17,) ndarray or None
        Integral form: the scheduling box's reach beyond the nominal's ranges grown by
        the supports of Z and F Z, as a fraction of those supports (lo side of h, V,
        alpha, theta, Phi, delta_e; hi side; q and the flexible states); >= 0 where it
        holds them. None: the second-order form.
    """

    parameters: np.ndarray
    interpolation: np.ndarray
    second_order: np.ndarray
    total: np.ndarray
    assumptions: tuple
    margin: np.ndarray | None = None

    def ratio(self, W) -> np.ndarray:
        """The bound relative to W: total / W per row (9,)."""
        return self.total / np.asarray(W, float)


ASSUMPTIONS = (
    "the estimate holds the constant part f_p(z, P v) - f_0(z, v) at the nominal point "
    "(onset of a fault and the estimate's lag not in W)",
    "the nominal state and applied input stay in the scheduling box; q and the flexible "
    "states within the stated half-widths",
    "vehicles inside the parameter box: corners and the sampled interior vehicles",
)

INTEGRAL_ASSUMPTIONS = (
    ASSUMPTIONS[0],
    "the nominal state and applied input stay in the nominal box given (the scheduling box "
    "holds it grown by the supports of Z and F Z: checked); q and the flexible states of "
    "the nominal within its half-widths",
    ASSUMPTIONS[2],
)


def segment_supports(F, N) -> tuple[np.ndarray, np.ndarray]:
    """How far e in Z reaches in the box's coordinates.

    Returns (6,) for (h, V, alpha, theta, Phi, delta_e): sqrt(N_jj), and the support of
    F e for the inputs (P F e is smaller for rho_f <= 1); and (5,) for q and the flexible
    states. F (2, 9), N (9, 9), state and input units.
    """
    sZ, sF = _supports(F, N)
    return np.concatenate([sZ[:4], sF]), sZ[4:9]


def _supports(F, N) -> tuple[np.ndarray, np.ndarray]:
    """Supports over Z = {e' N^-1 e <= 1} of e (9,), sqrt(N_jj), and of F e (2,)."""
    F, N = np.asarray(F, float), np.asarray(N, float)
    return np.sqrt(np.diag(N)), np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))


def check_segment_box(box: SchedulingBox, nominal: SchedulingBox, F, N) -> np.ndarray:
    """Margin (17,) of the scheduling box over nominal + Z, per support (integral form).

    Returns the box's reach beyond the nominal's ranges minus the supports of Z and F Z,
    divided by those supports (:class:`AlongNominalBound` ``margin``).

    Raises
    ------
    DesignError
        If the box does not hold nominal + Z in some coordinate: names it, with the
        reach needed and the reach the box has.
    """
    s6, s5 = segment_supports(F, N)
    lo, hi, oth = box.margin_to(nominal)
    need = np.concatenate([s6, s6, s5])
    have = np.concatenate([lo, hi, oth])
    margin = (have - need) / np.maximum(need, 1e-300)
    names = ([f"{c} (lo)" for c in BOX_COORDINATES] + [f"{c} (hi)" for c in BOX_COORDINATES]
             + ["q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot"])  # fmt: skip
    bad = np.flatnonzero(have < need)
    if bad.size:
        i = int(bad[np.argmin(margin[bad])])
        raise DesignError(
            f"integral form: the scheduling box does not hold the nominal's range grown by "
            f"the tube in {names[i]}: needs {need[i]:.4g} beyond it, has {have[i]:.4g} "
            f"({bad.size} coordinates short)"
        )
    return margin


def bound_along_nominal(
    nv: NominalVertices, F, N, nominal: SchedulingBox | None = None
) -> AlongNominalBound:
    """Bound (9,) of what the vertices leave of e+ over Z, for the tube (F (2, 9), N (9, 9)).

    With ``nominal`` (the ranges the nominal itself keeps, a :class:`SchedulingBox`), the
    integral form (2) of the module docstring: the scheduling box must hold ``nominal``
    grown by the supports of Z and F Z (:func:`check_segment_box`, DesignError if not),
    and there is no second-order part. Without it, form (1): the nominal anywhere in the
    box, the second-order part below.

    Parameters part: max over corners, vehicles and rho_f of the exact support over Z of
    each row of residual [I; P F] (sqrt(r N r')). Interpolation part: interp times the
    supports of (e, P F e) over Z (rho_f = 1 is the larger). Second order:
    REMAINDER_FACTOR times max over corners, vehicles and rho_f of the largest
    |eigenvalue| of (1/2) L' M_P' H_j M_P L (N = L L', M_P = [I; P F]), the exact extreme
    of the quadratic term over the ellipsoid.
    """
    F, N = np.asarray(F, float), np.asarray(N, float)
    integral = nominal is not None
    margin = check_segment_box(nv.box, nominal, F, N) if integral else None
    L = np.linalg.cholesky(N)
    sZ, sF = _supports(F, N)
    par = np.zeros(9)
    sec = np.zeros(9)
    for rho in (nv.rho_min, 1.0):
        MP = np.vstack([np.eye(9), np.array([1.0, rho])[:, None] * F])
        R = nv.residual @ MP
        par = np.maximum(par, np.sqrt(np.einsum("scij,jk,scik->sci", R, N, R)).max(axis=(0, 1)))
        ML = MP @ L
        for Hs in () if integral else nv.hessians:  # one corner point at a time (memory)
            Q = 0.5 * np.einsum("ki,cjkl,lm->cjim", ML, Hs.astype(float), ML)
            sec = np.maximum(sec, np.abs(np.linalg.eigvalsh(Q)).max(axis=(0, 2)))
    interp = nv.interp @ np.concatenate([sZ, sF])
    if integral:
        return AlongNominalBound(par, interp, sec, par + interp, INTEGRAL_ASSUMPTIONS, margin)
    sec = REMAINDER_FACTOR * sec
    return AlongNominalBound(par, interp, sec, par + interp + sec, ASSUMPTIONS)


@dataclass(frozen=True)
class OnsetPulse:
    """The onset of an elevator loss as pulse generators of the tube (docs/control_design.md).

    At the step a loss of 1 - rho_f starts, the plant moves by f_p(z, P v) while the
    nominal (with the estimate of the step before) expects f_p(z, v): the tube error
    receives the jump J = f_p(z, P v) - f_p(z, v) once, and after it the estimate's lag
    (1 - gamma)^k J' of the same kind, whatever the filter gain gamma. J lies close to
    one direction (the elevator column of the one-period map, scaled by delta_e), so
    the set of jumps over the nominal box and the parameter box is covered by a few
    generators, J = G' p + r with |p_l| <= 1 and |r| <= ``remainder``: the tube is then
    made RPI for W + remainder plus {G' p} (:func:`fahv.synthesis.feedback.design_tube`,
    ``pulse``), which keeps e in Z through the onset and the estimate's lag.

    Attributes
    ----------
    G : (g, 9) ndarray
        Generators (state units per step).
    remainder : (9,) ndarray
        Elementwise bound of what the generators leave of the sampled jumps.
    jumps : (S, 9) ndarray
        The sampled jumps (every parameter-box corner at the nominal box's corners,
        then interior points and vehicles).
    rho_f : float
        The loss's effectiveness.
    metric : (9, 9) ndarray
        The metric the generators were chosen in.
    """

    G: np.ndarray
    remainder: np.ndarray
    jumps: np.ndarray
    rho_f: float
    metric: np.ndarray

    def decompose(self, J) -> tuple[np.ndarray, np.ndarray]:
        """Coefficients p (S, g) and rest r (S, 9) of jumps J (S, 9) = p G + r.

        p is the projection of J on the generators in ``metric``; J is covered when
        |p| <= 1 and |r| <= ``remainder`` elementwise.
        """
        L = np.linalg.cholesky(self.metric)
        Gm = np.linalg.solve(L, self.G.T)
        Jm = np.linalg.solve(L, np.atleast_2d(np.asarray(J, float)).T)
        p = np.linalg.lstsq(Gm, Jm, rcond=None)[0].T
        return p, np.atleast_2d(J) - p @ self.G


def onset_jumps(box: SchedulingBox, vehicle, trim_map, uncertainty: dict, rho_f: float,
                Ts: float, n_sub: int, interior: int = 4096,
                seed: int = 0) -> tuple[np.ndarray, int]:  # fmt: skip
    """Jumps of the one-step residual at the onset of an elevator loss over a box.

    J = f_p(x, (Phi, rho_f delta_e)) - f_p(x, (Phi, delta_e)): what a loss of 1 - rho_f
    adds to the plant's step at the state x and applied input u of a box point, for the
    dispersed vehicle p. Sampled at the box's 64 corners (q and the flexible states at
    the trim's) with every one of the 2^P corners of the parameter box, then at
    ``interior`` points inside with q and the flexible states anywhere in their ranges
    and, with probability 1/2 each, a corner or an interior vehicle (seeded).

    Parameters
    ----------
    box : SchedulingBox
        States and applied inputs where a loss may start.
    vehicle, trim_map
        The nominal vehicle and its trim map.
    uncertainty : dict[str, float]
        Relative half-widths of the parameter box.
    rho_f : float
        Elevator effectiveness after the loss, in (0, 1].
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period.
    interior, seed : int
        Interior samples and their seed.

    Returns
    -------
    J : (64 2^P + interior, 9) ndarray
        The jumps, corner samples first (state units per period).
    n_corner : int
        How many of them are corner samples (64 2^P).

    Raises
    ------
    ValueError
        If rho_f is not in (0, 1].
    DesignError
        If a plant step is not finite.
    """
    if not 0.0 < rho_f <= 1.0:
        raise ValueError(f"onset_jumps: rho_f must be in (0, 1], got {rho_f}")
    names = list(uncertainty)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=len(names))))
    rng = np.random.default_rng(seed)
    S = box.corners()
    s_in = rng.uniform(box.lo, box.hi, (interior, 6))
    f_in = np.where(rng.random((interior, 1)) < 0.5, corners[rng.integers(len(corners),
                    size=interior)], rng.uniform(-1.0, 1.0, (interior, len(names))))  # fmt: skip
    s_all = np.vstack([np.repeat(S, len(corners), 0), s_in])
    f_all = np.vstack([np.tile(corners, (len(S), 1)), f_in])
    X, U = box.points(trim_map, s_all)
    other = rng.uniform(-1.0, 1.0, (len(s_all), 5)) * np.asarray(box.other_half, float)
    other[: len(S) * len(corners)] = 0.0  # the corner points at the trim's q, eta
    X[:, 4:9] += other
    recs = perturbed_records(vehicle.params, uncertainty, f_all)
    Uf = U.copy()
    Uf[:, 1] *= rho_f
    J = _one_step(X, Uf, recs, Ts, n_sub) - _one_step(X, U, recs, Ts, n_sub)
    if not np.all(np.isfinite(J)):
        raise DesignError("onset_jumps: a plant step is not finite; the box leaves the model")
    return J, len(S) * len(corners)


def onset_pulse(nominal: SchedulingBox, vehicle, trim_map, uncertainty: dict, rho_f: float,
                Ts: float, n_sub: int, metric, g: int = 2, interior: int = 4096,
                seed: int = 0) -> OnsetPulse:  # fmt: skip
    """Jumps of the one-step residual at the onset of a loss, and generators covering them.

    J = f_p(z, (Phi, rho_f delta_e)) - f_p(z, (Phi, delta_e)) at nominal points z, v of
    the box ``nominal`` (its 64 corners with all 2^P corners of the parameter box, then
    ``interior`` points inside with random corner or interior vehicles, seeded). The
    generators are the g leading principal directions of the jumps in the metric
    ``metric`` (9, 9) (e.g. the tube's N, so the directions that matter for Z come
    first), each scaled to the largest coefficient of a sample; what they leave is bounded
    per row by ``remainder``. Jumps are linear in 1 - rho_f to first order, the
    monotone effect of each parameter puts their extremes at the box corners (sampled
    besides).

    Parameters
    ----------
    nominal, vehicle, trim_map, uncertainty, rho_f, Ts, n_sub, interior, seed
        As ``box`` ... ``seed`` of :func:`onset_jumps` (``nominal``: where a loss may start).
    metric : (9, 9) ndarray
        Positive definite metric of the principal directions.
    g : int
        Generators.

    Returns
    -------
    OnsetPulse

    Raises
    ------
    ValueError
        If rho_f is not in (0, 1] or g is not in 1..9.
    DesignError
        If a plant step is not finite.
    """
    if not 1 <= g <= 9:
        raise ValueError(f"onset_pulse: g must be in 1..9, got {g}")
    J, _ = onset_jumps(nominal, vehicle, trim_map, uncertainty, rho_f, Ts, n_sub, interior, seed)
    L = np.linalg.cholesky(np.asarray(metric, float))
    Jm = np.linalg.solve(L, J.T).T
    _, _, Vt = np.linalg.svd(Jm, full_matrices=False)
    coef = Jm @ Vt[:g].T
    G = (np.abs(coef).max(axis=0)[:, None] * Vt[:g]) @ L.T
    rest = J - (coef @ Vt[:g]) @ L.T
    return OnsetPulse(G, np.abs(rest).max(axis=0), J, float(rho_f), np.asarray(metric, float))
