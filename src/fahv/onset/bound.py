"""The onset of an elevator loss as a transient of a closed eight-state tube set.

At the step a loss of 1 - rho_f starts, the plant moves by J = f_p(x, P u) - f_p(x, u)
more than the nominal (with the estimate of the step before) expects
(`onset_jumps`); as the controller's command grows to delta_e / rho_f the residual
grows on to J / rho_f. The estimate removes what it has seen at its gain per step, so
its error is a sum of such jumps, each decaying geometrically. The error dynamics are
linear along any sequence of the vertices, so the error splits into the part the
disturbance drives (in a steady set) and the part the jumps drive (bounded by a norm
recursion, `pulse_peak`): `onset_bound` bounds their sum, and the loss it
certifies. Its lower bound is `fahv.onset.witness.onset_witness`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fahv.bounds.domain import SchedulingBox
from fahv.bounds.one_step_bound import product_bound
from fahv.bounds.plant_step import plant_step
from fahv.bounds.vertices import NominalVertices
from fahv.control.mpc.estimator import elevator_share
from fahv.errors import DesignError
from fahv.onset.witness import OnsetWitness, onset_witness
from fahv.plant.rk4 import perturbed_records
from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid
from fahv.synthesis.rpi_level import vertex_levels

if TYPE_CHECKING:
    from fahv.tube.tube_set import TubeSet

#: Contraction factors tried for the onset bound's steady set (`steady_set`): the
#: smallest ellipsoid RPI for the bound at one factor may not exist at another (on
#: case1.yaml's tube set of 16384 vertices: none at 0.995, 0.419 Z_8 at one of the others).
STEADY_LAMS = (0.995, 0.993, 0.998)


def onset_jumps(box: SchedulingBox, vehicle, trim_map, uncertainty: dict, rho_f: float,
                Ts: float, n_sub: int, interior: int = 4096,
                seed: int = 0) -> tuple[np.ndarray, int]:  # fmt: skip
    """Jumps of the one-step residual at the onset of an elevator loss over a box.

    J = f_p(x, (Phi, rho_f delta_e)) - f_p(x, (Phi, delta_e)): what a loss of 1 - rho_f
    adds to the plant's step at the state x and applied input u of a box point, for the
    dispersed vehicle p. Sampled at the box's 64 corners (q and the flexible states at
    the trim's) with every one of the 2^P corners of the parameter box, then at
    `interior` points inside with q and the flexible states anywhere in their ranges
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
    return OnsetPoints(box, vehicle, trim_map, uncertainty, Ts, n_sub, interior, seed).jumps(rho_f)


class OnsetPoints:
    """The box points, applied inputs and vehicles of `onset_jumps`, stepped once.

    The healthy step f_p(x, u) of every point does not depend on the loss: it is taken
    once here, so that the jumps at another loss (a bisection over the loss) cost one
    plant step per point instead of two. Arguments as `onset_jumps`.
    """

    def __init__(self, box: SchedulingBox, vehicle, trim_map, uncertainty: dict, Ts: float,
                 n_sub: int, interior: int = 4096, seed: int = 0) -> None:  # fmt: skip
        got = _onset_points(box, vehicle, trim_map, uncertainty, interior, seed)
        self.X, self.U, self.recs, self.n_corner = got
        self.Ts, self.n_sub = Ts, n_sub
        self.healthy = plant_step(self.X, self.U, self.recs, Ts, n_sub)

    def jumps(self, rho_f: float) -> tuple[np.ndarray, int]:
        """The jumps (S, 9) at effectiveness rho_f in (0, 1] and the corner count.

        Raises
        ------
        DesignError
            If a plant step is not finite.
        """
        Uf = self.U.copy()
        Uf[:, 1] *= rho_f
        J = plant_step(self.X, Uf, self.recs, self.Ts, self.n_sub) - self.healthy
        if not np.all(np.isfinite(J)):
            raise DesignError("onset_jumps: a plant step is not finite; the box leaves the model")
        return J, self.n_corner


def _onset_points(box, vehicle, trim_map, uncertainty, interior, seed):
    """States X (S, 9), inputs U (S, 2), vehicle records and corner count of the samples."""
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
    return X, U, recs, len(S) * len(corners)


def pulse_peak(a: float, j0: float, parts, steps: int = 100_000) -> float:
    """Peak of d_k+1 = a d_k + p_k, d_0 = 0: the error's largest norm after a jump.

    p_0 = j0 is the jump's first step; after it p_k = sum_i j_i (1 - gamma_i)^k, the parts
    of the jump each removed by the estimate at its own gain per step. d bounds the norm
    of the part of the error the jump drives when every vertex's closed loop contracts
    the norm by at most a. The sequence rises to its peak and then falls (p_k falls).
    The norm recursion of `onset_bound`. For one part (j, gamma) with j0 = j, the
    peak per unit jump is max_k (a^k - b^k) / (a - b), b = 1 - gamma.

    Parameters
    ----------
    a : float
        Contraction of the closed loop in the norm, in [0, 1).
    j0 : float
        Norm of the first step's jump (>= 0).
    parts : sequence of (float, float)
        (j_i, gamma_i): norm of a part of the jump (>= 0) and its estimator gain per
        step, in (0, 1].
    steps : int
        Steps searched for the peak.

    Returns
    -------
    float
        The peak (>= j0).

    Raises
    ------
    ValueError
        If a, a norm or a gain is out of range.
    """
    parts = [(float(j), float(g)) for j, g in parts]
    if not 0.0 <= a < 1.0 or j0 < 0.0 or any(j < 0.0 or not 0.0 < g <= 1.0 for j, g in parts):
        raise ValueError(f"pulse_peak: need 0 <= a < 1, norms >= 0, gains in (0, 1]: got "
                         f"{a}, {j0}, {parts}")  # fmt: skip
    d, peak = float(j0), float(j0)
    decay = [1.0 - g for _, g in parts]
    for k in range(1, steps):
        d = a * d + sum(j * dk**k for (j, _), dk in zip(parts, decay, strict=True))
        if d < peak:
            break
        peak = d
    return peak


@dataclass(frozen=True)
class OnsetBound:
    """The onset of an elevator loss as a transient of a closed tube set (`onset_bound`).

    Attributes
    ----------
    loss : float
        The design's loss 1 - rho_min.
    gamma : float
        The case's estimator gain per step (Ts / est_tau).
    gamma_e : float
        Its gain along the elevator column (Ts / est_tau_elevator; 0: none, gamma in every
        direction).
    contraction : float
        a: largest factor by which a vertex's closed loop A_8 + B_8 F_8 maps Z_8's norm.
    steady : float
        c: the level the error holds at with the disturbance inside the bound (the largest
        bound / W_8, at the altitude bound grown by the onset): c Z_8 is RPI for c W_8.
    steady_shaped : float
        c_w: the same for an ellipsoid shaped for the bound itself (`steady_set`):
        the Z_8 radius of the smallest ellipsoid RPI for the bound's own box at every
        vertex, exactly re-checked (inf if none is found). The level the bound starts
        from is min(c, c_w) (`level0`).
    jump : float
        j: the largest Z_8 norm of J_8 / rho_f at the design loss over the scheduling box
        and every corner of the parameter box.
    jump_elevator, jump_rest : float
        With gamma_e: the largest Z_8 norms of the jump's share along the estimate's
        elevator direction and of the rest, over the samples and the directions (0
        without gamma_e).
    interior_ratio : float
        The interior samples' largest norm over the corners' (<= 1: the corners hold it).
    peak : float
        min(c, c_w) + the jump's pulse peak (`pulse_peak`): the level bound at the
        design loss with the case's estimate (certified when <= 1).
    certified_loss, certified_loss_one_step : float
        The largest loss whose level bound is <= 1 with the case's estimate, and with an
        estimate that knows the whole loss one step after it acts (min(c, c_w) + j <= 1:
        the ceiling of any analysis that keeps e in Z_8 from that steady set).
    jump_h : float
        [ft] largest |J_h| / rho_f at the design loss (e_h's share, added to H).
    jump_share : tuple of 8 floats
        The jump of largest Z_8 norm, state by state (V, alpha, theta, q, eta_1,
        eta_1_dot, eta_2, eta_2_dot) as a signed multiple of Z_8's support in that state:
        which states make the norm.
    jump_rigid : float
        The largest Z_8 norm of the jumps with q and the bending modes left out: what the
        requirement states V, alpha and theta receive.
    jump_rigid_q : float
        The same with only the bending modes left out (V, alpha, theta and q).
    witness : OnsetWitness or None
        The lower bound at the design's loss (`fahv.onset.witness.onset_witness`;
        None: not computed).
    ceiling : float
        With `witness`: the smallest loss found whose lower bound exceeds 1, bisected
        between `certified_loss` and the design's loss (an upper bound of what any
        analysis on the tube set's assumptions can certify); the design's loss when its
        own lower bound is at most 1; nan without `witness`.
    steady_active : tuple of int
        The vertices the steady set's last LMI held at the first contraction factor
        (`steady_set`; empty when `steady_shaped` was given): `steady_start` of a later
        bound on the same tube set.
        Not in `summary`.
    """

    loss: float
    gamma: float
    gamma_e: float
    contraction: float
    steady: float
    steady_shaped: float
    jump: float
    jump_elevator: float
    jump_rest: float
    interior_ratio: float
    peak: float
    certified_loss: float
    certified_loss_one_step: float
    jump_h: float
    jump_share: tuple[float, ...]
    jump_rigid: float
    jump_rigid_q: float
    witness: OnsetWitness | None = None
    ceiling: float = float("nan")
    steady_active: tuple[int, ...] = ()

    @property
    def level0(self) -> float:
        """The steady level the bound starts from, min(c, c_w)."""
        return min(self.steady, self.steady_shaped)

    def summary(self) -> dict:
        """JSON-ready record (the attributes; `jump_share` as a list)."""
        skip = ("witness", "steady_active")
        out = {k: [float(x) for x in v] if isinstance(v, tuple) else float(v)
               for k, v in self.__dict__.items() if k not in skip}  # fmt: skip
        if self.witness is not None:
            out["witness"] = {k: float(v) if isinstance(v, float) else int(v)
                              for k, v in self.witness.__dict__.items()}  # fmt: skip
        return out


def steady_set(Acl_8, N_8, F_8, bound, lam: float,
               start=None) -> tuple[float, np.ndarray | None, np.ndarray]:  # fmt: skip
    """The error's steady set shaped for the disturbance bound itself (the onset bound's c_w).

    Before an onset the error is driven by a disturbance inside the tube set's bound (per
    row, `bound` <= W_8) from e = 0. c Z_8 (c = the largest bound / W_8) is RPI for it,
    but the bound's rows are far from uniform (V 0.85-0.88 of W_8, the others 0.28-0.55),
    so a smaller set is: the smallest ellipsoid E(P) RPI for the box `bound` at every
    closed-loop vertex with its projection in s Z_8, s minimised
    (`fahv.synthesis.invariant_ellipsoid.invariant_ellipsoid`, the analysis form of LMI (24),
    constraint generation over the vertices). Accepted only on the exact re-check, the
    worst one-step level over every vertex and every corner of the box at most 1
    (`fahv.synthesis.rpi_level.vertex_levels`); s is then the largest eigenvalue of
    N_8^-1/2 P N_8^-1/2, square-rooted.

    Parameters
    ----------
    Acl_8 : (R, 8, 8) ndarray
        Closed-loop vertices A_8 + B_8 F_8.
    N_8 : (8, 8) ndarray
        Z_8's shape.
    F_8 : (2, 8) ndarray
        The tube gain (its supports over E(P) are kept within F_8 Z_8's).
    bound : (8,) array_like
        The disturbance bound per row (state units per period).
    lam : float
        Contraction factor of the S-procedure, in (0, 1).
    start : (a,) array_like of int, optional
        The vertices an earlier solve of this set held (its `active`): where the
        constraint generation starts.

    Returns
    -------
    c_w : float
        s (inf if no ellipsoid is found or the exact re-check fails).
    P : (8, 8) ndarray or None
        The ellipsoid's shape.
    active : (a,) ndarray of int
        The vertices the last LMI solve held (infeasible or not).
    """
    Acl_8, N_8, F_8 = (np.asarray(v, float) for v in (Acl_8, N_8, F_8))
    bound = np.asarray(bound, float)
    tightening = np.sqrt(np.einsum("ij,jk,ik->i", F_8, N_8, F_8))
    ell = invariant_ellipsoid(Acl_8, bound, np.sqrt(np.diag(N_8)), N_8, F_8, tightening,
                              lambda P: vertex_levels(Acl_8, P, bound), lam,
                              start=start)  # fmt: skip
    if not ell.found:
        return float("inf"), None, ell.active
    if float(vertex_levels(Acl_8, ell.P, bound).max()) > 1.0:
        return float("inf"), None, ell.active
    L = np.linalg.cholesky(N_8)
    s = np.sqrt(np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, ell.P).T)).max())
    return float(s), ell.P, ell.active


def steady_disturbance(nv: NominalVertices, tube_set: TubeSet, jump_h: float,
                       gamma: float) -> np.ndarray:  # fmt: skip
    """The disturbance bound before an onset, at the altitude bound the onset grows.

    W_8's bound over the product set (`fahv.bounds.one_step_bound.product_bound`)
    with |e_h| <= H + jump_h / gamma: the altitude error takes up to jump_h per step
    until the estimate removes it, at most 1 / gamma of it between resets
    (`onset_bound`).

    Parameters
    ----------
    nv : NominalVertices
    tube_set : TubeSet
    jump_h : float
        [ft] largest |J_h| / rho_f at the design loss (`onset_jumps`).
    gamma : float
        The estimator's gain per step, in (0, 1].

    Returns
    -------
    (8,) ndarray
        The bound per row of e_8 (state units per period).
    """
    H = tube_set.H + jump_h / gamma
    par, interp = product_bound(nv, tube_set.F_8, tube_set.N_8, H)
    A = nv.vertices()[0]
    return par[1:] + interp[1:] + np.abs(A[:, 1:, 0]).max(axis=0) * H


class _OnsetModel:
    """The closed loop and the jumps of one onset bound (`onset_bound`).

    Holds the tube set's closed-loop vertices, their contraction a in Z_8's norm, and
    computes the jumps at any loss with their Z_8 norms and shares.
    """

    def __init__(self, nv, tube_set, vehicle, trim_map, uncertainty, gamma, Ts, n_sub,
                 interior, gamma_e, directions, scale):  # fmt: skip
        self.nv, self.vehicle, self.trim_map, self.uncertainty = nv, vehicle, trim_map, uncertainty
        self.gamma, self.Ts, self.n_sub, self.interior = gamma, Ts, n_sub, interior
        self.gamma_e, self.directions, self.scale = gamma_e, directions, scale
        self.A, B = nv.vertices()
        A_8, B_8 = self.A[:, 1:, 1:], B[:, 1:, :]
        self.L = np.linalg.cholesky(tube_set.N_8)
        self.L_inv = np.linalg.inv(self.L)  # one inverse for the norms of many jumps
        self.Acl_8 = A_8 + B_8 @ tube_set.F_8
        self.points = OnsetPoints(nv.box, vehicle, trim_map, uncertainty, Ts, n_sub, interior)
        self.a = float(np.linalg.norm(np.linalg.solve(self.L, self.Acl_8) @ self.L, 2,
                                      axis=(1, 2)).max())  # fmt: skip

    def z_norm(self, V):
        """Z_8 norms (S,) of the e_8 parts of rows V (S, 9)."""
        return np.sqrt(((V[:, 1:] @ self.L_inv.T) ** 2).sum(axis=1))

    def jumps(self, loss: float):
        """The jumps J / rho_f (S, 9) at `loss` and what the bound takes of them.

        Returns J, its Z_8 norms (S,), the corner count, the largest |J_h| / rho_f and the
        largest norms of the shares along and off the elevator column (0 without gamma_e).
        """
        if not 0.0 < loss < 1.0:
            raise ValueError(f"onset_bound: a loss must be in (0, 1), got {loss}")
        J, n_c = self.points.jumps(1.0 - loss)
        J = J / (1.0 - loss)
        norm, jb, jr = self.z_norm(J), 0.0, 0.0
        if self.gamma_e is not None:
            for b in self.directions:  # the share along b, as the estimate takes it
                PJ = elevator_share(J, b, self.scale)[:, None] * b
                jb = max(jb, float(self.z_norm(PJ).max()))
                jr = max(jr, float(self.z_norm(J - PJ).max()))
        return J, norm, n_c, float(np.abs(J[:, 0]).max()), jb, jr

    def peak(self, j, jb, jr, one_step=False):
        """The pulse part's peak (`pulse_peak`); j alone for a one-step estimate."""
        if one_step:
            return j
        parts = [(j, self.gamma)] if self.gamma_e is None else [(jb, self.gamma_e),
                                                                (jr, self.gamma)]  # fmt: skip
        return pulse_peak(self.a, j, parts)


def _certified_loss(model: _OnsetModel, c0, loss, j, jb, jr, one_step, iterations) -> float:
    """The largest loss with c0 + pulse peak <= 1, bisected with the jumps recomputed."""
    if c0 >= 1.0:
        return 0.0
    p = model.peak(j, jb, jr, one_step)
    if c0 + p <= 1.0:
        return loss
    lo, hi = 0.0, loss
    guess = 2.0 * loss * (1.0 - c0) / p  # twice the first-order loss: bracket

    def ok(x):
        _, n, _, _, xb, xr = model.jumps(x)
        return c0 + model.peak(float(n.max()), xb, xr, one_step) <= 1.0

    if guess < loss:
        lo, hi = (guess, loss) if ok(guess) else (0.0, guess)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def _refuted_loss(witness, model: _OnsetModel, J, loss, certified, iterations):
    """The lower bound at `loss` and the smallest loss it refutes (bisected), or nan."""
    found = witness(J) if iterations > 0 else None
    ceiling = float("nan") if found is None else loss
    if found is not None and found.level_any_column > 1.0:  # the smallest loss refuted
        lo, ceiling = certified, loss
        for _ in range(iterations):
            mid = 0.5 * (lo + ceiling)
            lo, ceiling = (lo, mid) if witness(model.jumps(mid)[0]).level_any_column > 1.0 \
                else (mid, ceiling)  # fmt: skip
    return found, ceiling


def _check_gains(gamma, gamma_e, directions, projection_scale):
    """Validate the estimate's gains; return the directions (D, 9) and scale (9,)."""
    if not 0.0 < gamma <= 1.0:
        raise ValueError(f"onset_bound: gamma must be in (0, 1], got {gamma}")
    if gamma_e is None:
        return directions, projection_scale
    directions = np.atleast_2d(np.asarray(directions, float))
    scale = np.asarray(projection_scale, float)
    if not 0.0 < gamma_e <= 1.0 or directions.shape[1:] != (9,) or scale.shape != (9,) \
            or not np.all(scale > 0.0):  # fmt: skip
        raise ValueError(
            f"onset_bound: gamma_e in (0, 1] needs directions (D, 9) and a positive scale "
            f"(9,); got {gamma_e}, {directions.shape}, {scale.shape}"
        )
    return directions, scale


def onset_bound(nv: NominalVertices, tube_set: TubeSet, vehicle, trim_map,
                uncertainty: dict, gamma: float, Ts: float, n_sub: int, *,
                gamma_e: float | None = None, directions=None, projection_scale=None,
                interior: int = 1024, iterations: int = 6,
                steady_shaped: float | None = None, steady_lams=None,
                witness_iterations: int = 4, steady_start=None) -> OnsetBound:  # fmt: skip
    """Bound the onset of an elevator loss as a transient of the tube set.

    The jumps (module docstring) are taken over the scheduling box at every corner of the
    parameter box (`onset_jumps`). The error dynamics are linear along any sequence
    of the vertices (rho_f at both ends of [rho_min, 1] among them), so e = e_w + e_p:
    e_w, driven by the disturbance inside the bound from the error at the onset, stays in
    c Z_8 if it starts there (c Z_8 is RPI for c W_8); e_p, driven by the estimate's error
    from 0, has the Z_8 norm at most pulse_peak(a, j, [(j, gamma)]),
    j = max ||J_8 / rho_f||_Z_8 (the jumps arriving later only delay part of it). With a
    gain gamma_e along the elevator column b (`fahv.control.mpc.estimator.
    DisturbanceEstimator`), the jump's share along b, P_b J, decays at gamma_e and the
    rest at gamma: pulse_peak(a, j, [(j_b, gamma_e), (j_r, gamma)]) with j_b, j_r the
    largest norms of P_b J and J - P_b J over the samples and the estimate's possible
    directions b. e stays in Z_8 if c + that peak <= 1. The altitude error takes
    |J_h| / rho_f per step on top of H, at most 1 / gamma of it between resets; the
    bound of c is taken at that H. e_w also stays in the ellipsoid RPI for that bound
    itself, which lies in c_w Z_8 (`steady_set`); the bound starts from
    min(c, c_w).

    The bound is an upper one. Its matching lower bound
    (`fahv.onset.witness.onset_witness`) builds the worst onset the same
    model allows at one vertex held throughout, re-simulated: if its level exceeds 1 at
    the design's loss, no analysis on the tube set's assumptions certifies that loss, and
    the smallest loss it so refutes is bisected (`ceiling`): the loss certifiable on
    this tube set lies between `certified_loss` and it.

    Parameters
    ----------
    nv : NominalVertices
        The tube set's vertex data over its scheduling box.
    tube_set : TubeSet
        The closed tube set (its loss is nv.rho_min).
    vehicle, trim_map
        The nominal vehicle and its trim map.
    uncertainty : dict[str, float]
        Relative half-widths of the parameter box.
    gamma : float
        The case's estimator gain per step, in (0, 1].
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period.
    gamma_e : float, optional
        The estimate's gain along the elevator column, in (0, 1].
    directions : (D, 9) array_like, optional
        With gamma_e: the elevator columns the estimate may project on (the scheduled
        model's, e.g. its LPV vertices' B_i[:, 1]).
    projection_scale : (9,) array_like, optional
        With gamma_e: the state scale of the estimate's projection metric (its `scale`).
    interior : int
        Interior samples of the jumps besides the corners.
    iterations : int
        Bisection steps for each certified loss.
    steady_shaped : float, optional
        c_w when already computed for this tube set and bound (`steady_set`, a
        minute or two over 4096 vertices); computed here by default.
    steady_lams : sequence of float, optional
        Contraction factors tried for that ellipsoid (the smallest c_w is kept; a minute
        or two each); default: the tube set's lam alone.
    witness_iterations : int
        Bisection steps for the smallest loss the lower bound refutes (the lower bound at
        the design's loss, then between the certified loss and it; half a minute each
        over 16384 vertices); 0: no lower bound.
    steady_start : (a,) array_like of int, optional
        Where the steady set's constraint generation starts at the first contraction
        factor (an earlier bound's `steady_active` on the same tube set: the same set in
        one solve); it changes how fast the generation ends, not what is accepted.

    Returns
    -------
    OnsetBound

    Raises
    ------
    ValueError
        If a gain is not in (0, 1], or gamma_e comes without directions (D, 9) and a
        positive projection_scale (9,).
    DesignError
        If a plant step is not finite.
    """
    directions, scale = _check_gains(gamma, gamma_e, directions, projection_scale)
    m = _OnsetModel(nv, tube_set, vehicle, trim_map, uncertainty, gamma, Ts, n_sub, interior,
                    gamma_e, directions, scale)  # fmt: skip
    loss = 1.0 - nv.rho_min
    J, norm, n_c, jump_h, jb, jr = m.jumps(loss)
    j = float(norm.max())
    share = tuple(float(v) for v in J[int(norm.argmax()), 1:] / np.sqrt(np.diag(tube_set.N_8)))
    J_rigid = J.copy()
    J_rigid[:, 5:] = 0.0  # the bending modes (J's columns 5-8; column 0 is h)
    rigid_q = float(m.z_norm(J_rigid).max())
    J_rigid[:, 4] = 0.0  # and q
    rigid = float(m.z_norm(J_rigid).max())
    bound = steady_disturbance(nv, tube_set, jump_h, gamma)
    c = float((bound / tube_set.W_8).max())
    active: tuple[int, ...] = ()
    if steady_shaped is None:
        sets = [steady_set(m.Acl_8, tube_set.N_8, tube_set.F_8, bound, lam,
                           steady_start if i == 0 else None)
                for i, lam in enumerate(steady_lams or (tube_set.lam,))]  # fmt: skip
        steady_shaped = min(r[0] for r in sets)
        active = tuple(int(i) for i in sets[0][2])  # where `steady_start` applies
    c_s = float(steady_shaped)
    c0 = min(c, c_s)  # the steady level the bound starts from
    cert = _certified_loss(m, c0, loss, j, jb, jr, False, iterations)
    cert_one_step = _certified_loss(m, c0, loss, j, jb, jr, True, iterations)
    est = {} if gamma_e is None else {"gamma_e": gamma_e, "directions": directions,
                                       "projection_scale": scale}  # fmt: skip

    def witness(J_x):
        return onset_witness(m.Acl_8, tube_set.N_8, bound, J_x, gamma, **est)

    found, ceiling = _refuted_loss(witness, m, J, loss, cert, witness_iterations)
    return OnsetBound(
        loss, gamma, 0.0 if gamma_e is None else float(gamma_e), m.a, c, c_s, j, jb, jr,
        float(norm[n_c:].max() / norm[:n_c].max()) if len(norm) > n_c else 0.0,
        c0 + m.peak(j, jb, jr), cert, cert_one_step, jump_h, share, rigid, rigid_q, found,
        ceiling, active,
    )  # fmt: skip
