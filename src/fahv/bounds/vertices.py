"""Vertex sets of the tube LMI (24): faults, adjustable gains, the error along the nominal.

* `fault_vertices`: every vertex with the elevator at full and at reduced
  effectiveness, eq. (15);
* `gain_vertices`: every vertex with the gain tau' F at both ends of [tau, 1],
  eq. (48);
* `nominal_vertices`: the vertices of the tube error along the nominal, and what
  they leave to W.

**The error along the nominal.** With the nominal state moving by the nominal vehicle's
nonlinear CM, z+ = f_0(z, v) + d, and the plant x+ = f_p(x, P u) under u = v + F e
(P = diag(1, rho_f), eq. 15), the tube error e = x - z obeys, once the estimate d holds
the constant part at the nominal point, by the mean-value theorem in integral form:

    e+ = f_p(z + e, P (v + F e)) - f_p(z, P v)
       = [int_0^1 J_p(z + s e, P (v + s F e)) ds] [e; P F e]                 (1)

with J_p the one-period Jacobian [A, B] of the perturbed vehicle. If the segment lies in
the scheduling box (`fahv.bounds.domain.SchedulingBox`), the averaged Jacobian
lies in the convex hull of J_p over the box. The vertices cover it:

* the nominal vehicle's J_0 at the 64 corners of the box, each shifted along k
  principal directions of the parameter box's Jacobian deviation (the corners of their
  coefficient range), with B and B P for rho_f in {rho_min, 1}: (64 2^k 2) vertices;
* between corners J_0 is the multilinear interpolation of its corner values (a convex
  combination of them) plus a remainder bounded by sum_i a_i^2 / 8 max |d^2 J_0 / ds_i^2|
  (tensor-product linear interpolation), the second derivatives taken as
  REMAINDER_FACTOR times the largest second difference along each edge of the box;
* what the directions do not carry of each vehicle's deviation (every corner of the
  sec. 5.1 box and interior vehicles, at every corner of the scheduling box) is the
  parameter residual.

The residual and the interpolation remainder are what W bounds
(`fahv.bounds.one_step_bound`); both are first order in the size of the tube.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from fahv.bounds.domain import SchedulingBox
from fahv.bounds.plant_step import REMAINDER_FACTOR, jacobians
from fahv.errors import DesignError
from fahv.model.vehicle import DELTA_E
from fahv.plant.rk4 import params_records, perturbed_records

#: Widening of the parameter coefficients' range (fraction of its width, each side).
COEF_MARGIN = 0.01


def fault_vertices(A: np.ndarray, B: np.ndarray, rho_f: float):
    """Vertices [A_i, B_i] and [A_i, B_i P] with P = diag(1, rho_f), eq. (15).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
    rho_f : float
        Elevator effectiveness of the fault.

    Returns
    -------
    (2R, n, n), (2R, n, m) ndarray
    """
    Bf = B.copy()
    Bf[:, :, DELTA_E] *= rho_f
    return np.concatenate([A, A]), np.concatenate([B, Bf])


def gain_vertices(A: np.ndarray, B: np.ndarray, tau: float):
    """Vertices [A_i, B_i] and [A_i, tau B_i] of the adjustable gain tau F, eq. (48).

    A tube LMI (24) solved over both sets makes Z RPI for W under u = tau' F e for every
    tau' in [tau, 1]: A_i + tau' B_i F is affine in tau', so the LMI, affine in the
    closed loop, holds on the segment once it holds at its ends. `tau` = 1 returns
    (A, B) unchanged.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
    tau : float
        Adjustable factor, 0 < tau <= 1.

    Returns
    -------
    (2R, n, n), (2R, n, m) ndarray
        Or (A, B) themselves for tau = 1.

    Raises
    ------
    ValueError
        If tau is not in (0, 1].
    """
    if not 0.0 < tau <= 1.0:
        raise ValueError(f"tube.tau = {tau}: the adjustable factor must lie in (0, 1]")
    if tau == 1.0:
        return A, B
    return np.concatenate([A, A]), np.concatenate([B, tau * B])


@dataclass(frozen=True)
class NominalVertices:
    """The vertex set of the error along the nominal and what it leaves to W.

    Attributes
    ----------
    box : SchedulingBox
    J0 : (64, 9, 11) ndarray
        Nominal vehicle's Jacobians at the box corners.
    dirs : (k, 9, 11) ndarray
        Parameter directions (unscaled).
    c_lo, c_hi : (k,) ndarray
        Coefficient range over every vehicle and corner, widened by `coef_margin` of
        `nominal_vertices`.
    residual : (64, C, 9, 11) ndarray
        Each vehicle's Jacobian deviation minus its carried part, per corner.
    interp : (9, 11) ndarray
        Elementwise bound of the interpolation remainder of J_0 plus the linear effect
        of the nominal's q and flexible deviations.
    rho_min : float
    n_vehicles : tuple of int
        Corners of the parameter box and interior vehicles in `residual`.
    tau : float
        Smallest factor of the ancillary gain tau' F the vertices cover, tau' in [tau, 1]
        (1: the baseline law, eq. 36; below 1: the adjustable law, eq. 48). Set it with
        `dataclasses.replace`.
    """

    box: SchedulingBox
    J0: np.ndarray
    dirs: np.ndarray
    c_lo: np.ndarray
    c_hi: np.ndarray
    residual: np.ndarray
    interp: np.ndarray
    rho_min: float
    n_vehicles: tuple
    tau: float = 1.0

    @property
    def n_vertices(self) -> int:
        """R, the number of vertices `vertices` returns (without building them)."""
        return self.J0.shape[0] * 2 ** len(self.c_lo) * 2 * (2 if self.tau < 1.0 else 1)

    def vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) vertex arrays (R, 9, 9), (R, 9, 2) of the tube LMI (24).

        R = 64 2^k 2 (box corners, parameter directions, rho_f at both ends of
        [rho_min, 1]); with `tau` < 1 twice that, [A_i, B_i] and [A_i, tau B_i]
        (`gain_vertices`, eq. 48): every closed loop A_i + tau' B_i F with tau' in
        [tau, 1] is a convex combination of them.
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
    coef_margin: float = COEF_MARGIN,
) -> NominalVertices:
    """Build the vertex set of the error along the nominal and the data W is bounded from.

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
        tube set.
    interior : int
        Vehicles drawn uniformly inside the box (seeded) besides the corners.
    seed : int
    coef_margin : float
        The coefficient range over the corners, widened by this fraction of its width
        on each side, so that it holds the coefficients of points inside the box too
        (the tests measure them beyond the corners' range by less than 1e-4 of it).

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
    c_lo, c_hi = coef.min(axis=0), coef.max(axis=0)
    pad = coef_margin * (c_hi - c_lo)
    return NominalVertices(
        box, J0, G.reshape(k, 9, 11) * unscale[None], c_lo - pad, c_hi + pad,
        residual, interp, float(rho_min), (len(corners), interior),
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
