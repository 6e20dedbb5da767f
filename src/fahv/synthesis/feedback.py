"""Robust feedback gain F (LMI 24) and the robust positively invariant tube Z (eq. 25-28).

Z shape. The paper's box Z = {|e| <= z} (eq. 25) is RPI for e+ = A_cl,i e + w,
w in W, iff |A_cl,i| z + w_max <= z for every vertex i (eq. 26-28 by Farkas' lemma),
which needs the spectral radius of |A_cl,i| below 1 -- a property of the
coordinates, not of stability. On this vehicle it fails (see
`fahv.synthesis.box_tube.box_tube`), so the tube used is an ellipsoid
Z = {e : e' N^-1 e <= 1} designed jointly with F:

    [[lam N, 0,        (A_i N + B_i M)'],
     [0,     diag(mu), I               ],      >= 0  for every vertex i,
     [A_i N + B_i M, I, N              ]]
    sum_j mu_j w_j^2 <= 1 - lam,   F = M N^-1.

By the S-procedure this gives (A_cl e + w)' N^-1 (A_cl e + w) <= lam e'N^-1 e +
sum mu_j w_j^2 <= 1 for every e in Z and |w_j| <= w_j: Z is RPI for the whole box W
and all vertices. Deleting the middle row and column leaves
[[lam N, (A_i N + B_i M)'], [A_i N + B_i M, N]] >= 0, i.e. LMI (24) with a decay
rate lam < 1, so F stabilises every vertex.

Pulse generators. A disturbance that is not a box, w + G' p with |p_l| <= 1 (G (g, n):
the onset of an elevator loss, whose one-step jump of the residual lies along a few
directions, docs/theory/certificate.md), enters the same way: the middle block becomes
diag(mu, mu_p), its off-diagonal block [I, G'], and the budget
sum_j mu_j w_j^2 + sum_l mu_p,l <= 1 - lam.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from fahv.errors import DesignError
from fahv.synthesis.lmi import (
    LMI_MARGIN,
    dual_support,
    invariance_blocks,
    require_psd,
    scale_vertices,
    solve_lmi,
)


@dataclass(frozen=True)
class TubeDesign:
    """Robust feedback gain and invariant tube (unscaled units).

    Attributes
    ----------
    F : (m, n) ndarray
        Auxiliary feedback gain of eq. (21)/(36).
    N : (n, n) ndarray
        Shape matrix of Z = {e : e' N^-1 e <= 1}.
    lam : float
        Contraction factor of the S-procedure certificate.
    mu : (n,) ndarray
        S-procedure multipliers (scaled coordinates).
    w_max : (n,) ndarray
        Half-widths of the box W the tube was designed for.
    tightening : (m,) ndarray
        max over Z of |(F e)_j| = sqrt(F_j N F_j'), eq. (30).
    z_box : (n,) ndarray
        Half-widths of the smallest box containing Z: sqrt(diag N).
    min_eigs : (R,) ndarray
        Smallest eigenvalue of each vertex LMI after the solve (scaled).
    n_blocks : int
        Vertex blocks the last LMI solve held (R, or fewer with constraint generation:
        the rest held at its solution).
    pulse : (g, n) ndarray or None
        Pulse generators G (unscaled): Z is RPI for w + G' p, |w| <= w_max, |p| <= 1.
    mu_pulse : (g,) ndarray or None
        Their S-procedure multipliers (scaled coordinates).
    active_set : ActiveSet or None
        The vertices and points that support the solution (constraint generation), the
        start of a later design of the same vertex set (`warm` of `design_tube`).
    """

    F: np.ndarray
    N: np.ndarray
    lam: float
    mu: np.ndarray
    w_max: np.ndarray
    tightening: np.ndarray
    z_box: np.ndarray
    min_eigs: np.ndarray
    n_blocks: int = 0
    pulse: np.ndarray | None = None
    mu_pulse: np.ndarray | None = None
    active_set: ActiveSet | None = None

    def contains(self, e: np.ndarray, scale: float = 1.0) -> bool:
        """True if the error e (n,) lies in scale * Z.

        Parameters
        ----------
        e : (n,) ndarray
            Tube error (state units).
        scale : float
            Factor of the tube (1: Z itself).

        Returns
        -------
        bool
            e' N^-1 e <= scale^2 (to a relative 1e-9).

        Examples
        --------
        >>> tube = design_tube(np.array([[[0.9]]]), np.array([[[1.0]]]), [0.1], np.ones(1),
        ...                    np.ones(1), u_room=[1.0])
        >>> tube.contains(np.zeros(1)), tube.contains(np.ones(1)), tube.contains(np.ones(1), 2.0)
        (True, False, True)
        """
        return float(e @ np.linalg.solve(self.N, e)) <= scale**2 * (1.0 + 1e-9)


def _rpi_blocks(AN, lam, mu, N, G=None) -> np.ndarray:
    """Vertex blocks (R, 3n + g, 3n + g) of the RPI LMI (24) at a solution (scaled units).

    [[lam N, 0, (A_cl,i N)'], [0, diag(mu), E'], [A_cl,i N, E, N]] for each stacked
    AN[i] = A_cl,i N = A_i N + B_i M (M = F N), E = [I, G'] (n, n + g), mu (n + g,).
    The certificate holds at vertex i iff the block is positive semidefinite
    (S-procedure form of (A_cl e + w + G' p)' N^-1 (A_cl e + w + G' p) <= lam e' N^-1 e
    + sum_j mu_j w_j^2 + sum_l mu_p,l p_l^2, with the budget at most 1 - lam).
    """
    return invariance_blocks(AN, lam, mu, N, _generators(AN.shape[1], G))


def _generators(n: int, G) -> np.ndarray:
    """Disturbance matrix E = [I_n, G'] (n, n + g) of the box W and the pulse generators."""
    if G is None or len(G) == 0:
        return np.eye(n)
    return np.hstack([np.eye(n), np.asarray(G, float).T])


def verify_tube(A, B, tube: TubeDesign, Dx, Du) -> np.ndarray:
    """Re-check the RPI certificate of `tube` numerically for every vertex.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices (unscaled).
    tube : TubeDesign
    Dx : (n,) ndarray
    Du : (m,) ndarray
        Scaling used for the design.

    Returns
    -------
    (R,) ndarray
        Smallest eigenvalue of each vertex certificate (scaled).

    Raises
    ------
    DesignError
        If lam is not in (0, 1), the budget sum mu_j w_j^2 (+ sum mu_p,l) > 1 - lam, N is
        not positive definite, or a vertex certificate matrix has a negative eigenvalue.

    Examples
    --------
    >>> import dataclasses
    >>> A, B, D = np.array([[[0.9]]]), np.array([[[1.0]]]), np.ones(1)
    >>> tube = design_tube(A, B, [0.1], D, D, u_room=[1.0])
    >>> verify_tube(A, B, tube, D, D).shape
    (1,)
    >>> verify_tube(A, B, dataclasses.replace(tube, lam=1.0), D, D)
    Traceback (most recent call last):
        ...
    fahv.errors.DesignError: certificate failed: contraction lam = 1.0 not in (0, 1)
    """
    As, Bs = scale_vertices(A, B, Dx, Du)
    Ns = tube.N / np.outer(Dx, Dx)
    Fs = tube.F * Dx[None, :] / Du[:, None]
    ws = tube.w_max / Dx
    Gs, mu = None, np.asarray(tube.mu, float)
    if tube.pulse is not None and len(tube.pulse):
        Gs = np.asarray(tube.pulse, float) / Dx[None, :]
        mu = np.concatenate([mu, np.asarray(tube.mu_pulse, float)])
    if not 0.0 < tube.lam < 1.0:
        raise DesignError(f"certificate failed: contraction lam = {tube.lam} not in (0, 1)")
    budget = float(tube.mu @ ws**2) + float(np.sum(mu[ws.size :]))
    if budget > (1.0 - tube.lam) * (1 + 1e-9):
        raise DesignError(f"certificate failed: sum mu w^2 (+ pulses) = {budget:.6g} > 1 - lam")
    if np.any(mu < -1e-12):
        raise DesignError("certificate failed: negative S-procedure multiplier")
    require_psd(Ns, "tube shape matrix N")
    blocks = _rpi_blocks((As + Bs @ Fs) @ Ns, tube.lam, mu, Ns, Gs)
    return np.array(
        [require_psd(blk, f"RPI LMI at vertex {i}", rtol=1e-12) for i, blk in enumerate(blocks)]
    )


def _levels(P: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Squared levels p' N^-1 p (S,) of the rows of P (S, n) in Z = {e' N^-1 e <= 1}."""
    return np.einsum("si,si->s", P, np.linalg.solve(N, P.T).T)


@dataclass(frozen=True)
class ActiveSet:
    """The vertex blocks and points a tube LMI's last solve held (constraint generation).

    Started from again (`warm` of `design_tube`), the first solve is the last one
    of the design that stored it: on the same data and machine, the same solution.

    Attributes
    ----------
    vertices : (a,) ndarray of int
        Indices of the vertices whose blocks the last solve held.
    points : (b,) ndarray of int
        Indices of the `contain` points it held.
    """

    vertices: np.ndarray
    points: np.ndarray

    @staticmethod
    def empty() -> ActiveSet:
        """No vertex and no point.

        Returns
        -------
        ActiveSet
            Empty index arrays: the constraint generation starts from its own choice.

        Examples
        --------
        >>> empty = ActiveSet.empty()
        >>> empty.vertices.size, empty.points.size
        (0, 0)
        """
        return ActiveSet(np.zeros(0, int), np.zeros(0, int))


#: Vertex blocks and points of the first solve (each, the largest first) and added per
#: pass of constraint generation (the most violated first), the `active` of
#: `design_tube`: an LMI of d unknowns has a subset of at most d constraints with
#: the same optimum, and Clarabel's time grows with the blocks held, so few are held and
#: few added (docs: results/speed).
GENERATION_ADD = 12


def _rpi_problem(As, Bs, ws, room, sw, lam, zs_max, E, Ps):
    """The tube LMI on the given vertices and points (scaled): problem, variables, blocks.

    The S-procedure block of `_rpi_blocks` with its middle diag(mu) eliminated by
    a Schur complement: with nu = 1 / mu (mu > 0 wherever w_j != 0),
    [[lam N, (A N + B M)'], [A N + B M, N - E diag(nu) E']] >= 0, linear in (N, M, nu),
    and the budget sum_j w_j^2 / nu_j (+ sum_l 1 / nu_p,l) <= 1 - lam, convex in nu:
    the same condition on blocks of 2n instead of 3n + g rows (an interior-point
    step's cost grows with the cube of a block's size).

    Returns (prob, (N, M, nu), vertex_constraints, point_constraints).
    """
    R, n, m = Bs.shape
    k = E.shape[1]
    N = cp.Variable((n, n), symmetric=True)
    M = cp.Variable((m, n))
    # nu = weights r / (1 - lam), weights = (w_j^2, 1 per pulse): r of order the count
    r = cp.Variable(k, pos=True)
    weights = np.r_[ws**2, np.ones(k - n)]
    nu = cp.multiply(weights / (1.0 - lam), r)
    t = cp.Variable(m)
    cons = [N >> LMI_MARGIN * np.eye(n), cp.sum(cp.inv_pos(r)) <= 1.0 - 1e-6]
    cons += [N[j, j] <= (1.0 - 1e-6) * zs_max[j] ** 2 for j in range(n) if np.isfinite(zs_max[j])]
    inner = N - E @ cp.diag(nu) @ E.T
    vertex_cons = []
    for i in range(R):
        AN = As[i] @ N + Bs[i] @ M
        blk = cp.bmat([[lam * N, AN.T], [AN, inner]])
        vertex_cons.append(0.5 * (blk + blk.T) >> LMI_MARGIN * np.eye(2 * n))
    point_cons = []
    for p in Ps:  # p' N^-1 p <= 1 - 1e-5: room for the solver's accuracy
        blk = cp.bmat([[np.full((1, 1), 1.0 - 1e-5), p[None, :]], [p[:, None], N]])
        point_cons.append(0.5 * (blk + blk.T) >> 0)
    for j in range(m):
        blk = cp.bmat(
            [[cp.reshape(t[j], (1, 1), order="F"), M[j : j + 1, :]], [M[j : j + 1, :].T, N]]
        )
        cons.append(0.5 * (blk + blk.T) >> 0)
    obj = cp.Minimize(cp.sum(cp.multiply(t, 1.0 / room**2)) + sw @ cp.diag(N))
    return cp.Problem(obj, cons + vertex_cons + point_cons), (N, M, nu), vertex_cons, point_cons


def _reduced_min_eigs(As, Bs, N, M, nu, lam, E) -> np.ndarray:
    """Smallest eigenvalue (R,) of each vertex's reduced block (`_rpi_problem`)."""
    n = N.shape[0]
    AN = As @ N + Bs @ M
    blk = np.empty((As.shape[0], 2 * n, 2 * n))
    blk[:, :n, :n] = lam * N
    blk[:, n:, :n] = AN
    blk[:, :n, n:] = AN.transpose(0, 2, 1)
    blk[:, n:, n:] = N - (E * nu[None, :]) @ E.T
    return np.linalg.eigvalsh(blk)[:, 0]


def _most(values, candidates, count) -> np.ndarray:
    """The `count` candidates of largest `values` (sorted indices)."""
    return np.sort(candidates[np.argsort(-values[candidates], kind="stable")[:count]])


def _solve_rpi_lmi(As, Bs, ws, room, sw, lam, state_max, Dx, active, Gs=None, Ps=None,
                   warm=None):  # fmt: skip
    """Solve the tube LMI for one lam (scaled data); (value, lam, N, M, mu, blocks, set) or None.

    With `active` (an int: the blocks and points added per pass) the vertex blocks and
    the points are generated: the LMI is solved on the `warm` set (an
    `ActiveSet`, e.g. the one a stored design ended with) or else on the
    `active` vertices of largest open-loop norm and points of largest norm; every block
    and point is then evaluated at the solution; the `active` most violated of each are
    added, and the held ones outside the solution's support (a zero dual,
    `fahv.synthesis.lmi.dual_support`) are released, each at most once, until every
    block holds with half the strict margin and every point lies in Z (constraint
    generation). The blocks solved hold with the full margin `LMI_MARGIN`, the ones
    left out with at least half of it, so the result is the full LMI's optimum up to that
    margin (not exactly); `verify_tube` re-checks every one of the R blocks either
    way. `Gs` (g, n): pulse generators (scaled), the last g multipliers of the
    returned mu. `Ps` (S, n): points Z must contain (scaled), p' N^-1 p <= 1, entered
    as [[1 - 1e-5, p'], [p, N]] >= 0 (a margin for the solver's accuracy, as the
    budget's).
    """
    R, n, m = Bs.shape
    E = _generators(n, Gs)
    Ps = np.zeros((0, n)) if Ps is None else np.asarray(Ps, float)
    zs_max = np.full(n, np.inf) if state_max is None else np.asarray(state_max, float) / Dx
    warm = warm or ActiveSet.empty()
    warm_v, warm_p = warm.vertices[warm.vertices < R], warm.points[warm.points < len(Ps)]
    if active is None or active >= R + len(Ps):
        chosen, held = np.arange(R), np.arange(len(Ps))
    elif warm_v.size:  # exactly the set an earlier solve ended on: the same solution again
        chosen, held = np.unique(warm_v), np.unique(warm_p).astype(int)
    else:
        norms = np.linalg.norm(As.reshape(R, -1), axis=1)
        norms = norms + np.linalg.norm(Bs.reshape(R, -1), axis=1)
        chosen = _most(norms, np.arange(R), active)
        held = _most(np.linalg.norm(Ps, axis=1), np.arange(len(Ps)), active)
    released_v, released_p = np.zeros(0, int), np.zeros(0, int)
    while True:
        prob, (N, M, nu), vcons, pcons = _rpi_problem(As[chosen], Bs[chosen], ws, room, sw, lam,
                                                      zs_max, E, Ps[held])  # fmt: skip
        if not solve_lmi(prob):
            return None
        Nv = 0.5 * (N.value + N.value.T)
        level = _levels(Ps, Nv) if len(Ps) else np.zeros(0)
        outside = np.setdiff1d(np.flatnonzero(level > 1.0 + 1e-7), held)
        mu = 1.0 / nu.value
        if len(chosen) < R:
            eig = _reduced_min_eigs(As, Bs, Nv, M.value, nu.value, lam, E)
            bad = np.setdiff1d(np.flatnonzero(eig < 0.5 * LMI_MARGIN), chosen)
        else:
            eig, bad = np.zeros(R), np.zeros(0, int)
        if bad.size == 0 and outside.size == 0:
            return prob.value, lam, N.value, M.value, mu, len(chosen), ActiveSet(chosen, held)
        # release the held constraints outside the support (once each), add the worst
        drop_v = np.setdiff1d(np.setdiff1d(chosen, chosen[dual_support(vcons)]), released_v)
        drop_p = np.setdiff1d(np.setdiff1d(held, held[dual_support(pcons)]), released_p)
        released_v, released_p = np.union1d(released_v, drop_v), np.union1d(released_p, drop_p)
        chosen = np.union1d(np.setdiff1d(chosen, drop_v), _most(-eig, bad, active))
        held = np.union1d(np.setdiff1d(held, drop_p), _most(level, outside, active)).astype(int)


def design_tube(
    A,
    B,
    w_max,
    Dx,
    Du,
    u_room,
    lam_grid=(0.9, 0.95, 0.97, 0.98, 0.99, 0.995),
    state_weight=None,
    state_max=None,
    w_ref=None,
    active=None,
    pulse=None,
    contain=None,
    warm=None,
) -> TubeDesign:
    """Design F and the ellipsoidal RPI tube Z for the box W = {|w| <= w_max}.

    One concept, kept whole: the constraint-generation loop and the re-check of every
    vertex after it are one algorithm.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete polytope vertices (unscaled), eq. (12).
    w_max : (n,) array_like
        Half-widths of W (unscaled), eq. (19).
    Dx : (n,) ndarray
    Du : (m,) ndarray
        State and input scaling.
    u_room : (m,) array_like
        Room of each input row (unscaled): the distance from the trim input to the
        binding side of the asymmetric input set (`fahv.tube.feasibility.input_room`).
        The objective is sum_j (max_Z |F_j e| / u_room_j)^2: the tightening of eq. (30),
        row by row, relative to the room that row has.
    lam_grid : sequence of float
        Contraction factors tried (the LMI is linear for fixed lam).
    state_weight : (n,) array_like, optional
        Weight of diag(N) (scaled) in the objective: smaller attitude tubes.
    state_max : (n,) array_like, optional
        Largest support of Z along each state axis, max_Z |e_j| = sqrt(N_jj) <= state_max_j
        (unscaled; inf: no bound), entered as N_jj <= state_max_j^2 (linear in N). Used
        for the attitude rows: the support of Z in alpha and theta is what the
        nominal MPC's attitude rows are tightened by.
    w_ref : (n,) array_like, optional
        Reference size of W. The RPI condition is homogeneous (Z is RPI for W iff s Z
        is for s W), so the LMI is solved for W / s with s = max_j w_j / w_ref,j (w_j plus
        the pulses' |G_lj| with `pulse`) and Z scaled back by s: a W far smaller or
        larger than w_ref would otherwise meet the fixed strictness margins of the LMI at
        another scale (measured: a W of 1/100 of the design's gave the tube of W / 10).
        With `state_max` the bound is scaled with W (s Z has s times Z's supports).
    active : int, optional
        Vertex blocks and points added per pass of constraint generation, for large
        vertex sets: the LMI is solved on a subset of the vertices and points, grown by
        the most violated and cleared of those outside the solution's support, until
        every block holds at the solution (`_solve_rpi_lmi`); None: all blocks at
        once.
    pulse : (g, n) array_like, optional
        Pulse generators G (unscaled): Z is made RPI for w + G' p, |w| <= w_max,
        |p_l| <= 1 (module docstring), e.g. the one-step jumps of the residual at the
        onset of a loss.
    contain : (S, n) array_like, optional
        Points Z must contain (unscaled), e' N^-1 e <= 1 for each row, entered as
        [[1, e'], [e, N]] >= 0 (linear in N) and generated like the vertex blocks; e.g.
        the one-step jumps of a loss's onset over the level they may use, so that the
        error stays in Z through the onset (`fahv.tube.closure.close_tube_set`).
        Re-checked exactly.
    warm : ActiveSet, optional
        Vertices and points to start the constraint generation from (e.g. the
        `active_set` of an earlier design of the same vertex set); indices beyond the
        vertex or point count are ignored. It changes how fast the solve gets there, not
        what is certified.

    Returns
    -------
    TubeDesign
        Certified by `verify_tube`.

    Raises
    ------
    DesignError
        If no lam gives a feasible LMI or the certificate check fails.

    Examples
    --------
    One state, x+ = 0.9 x + u + w, |w| <= 0.1. For a closed loop a = 0.9 + F and lam the
    S-procedure's smallest tube is N = lam w^2 / ((lam - a^2)(1 - lam)); the design sits
    on it, and the exact level certifies it:

    >>> from fahv.synthesis.rpi_level import worst_level
    >>> A, B, D = np.array([[[0.9]]]), np.array([[[1.0]]]), np.ones(1)
    >>> tube = design_tube(A, B, [0.1], D, D, u_room=[1.0])
    >>> tube.lam, tube.F.shape, tube.N.shape
    (0.9, (1, 1), (1, 1))
    >>> a = 0.9 + float(tube.F[0, 0])
    >>> round(float(tube.N[0, 0]) / (0.9 * 0.1**2 / ((0.9 - a**2) * (1.0 - 0.9))), 2)
    1.0
    >>> bool(worst_level(A, B, tube.F, tube.N, [0.1])[0] <= 1.0)
    True
    """
    if w_ref is not None:
        reach = np.asarray(w_max, float)
        if pulse is not None:  # the pulse is scaled with W: size the two together
            reach = reach + np.abs(np.atleast_2d(np.asarray(pulse, float))).sum(axis=0)
        s = float(np.max(reach / np.asarray(w_ref, float)))
        sm = None if state_max is None else np.asarray(state_max, float) / s
        t = design_tube(A, B, np.asarray(w_max, float) / s, Dx, Du, u_room, lam_grid,
                        state_weight, state_max=sm, active=active,
                        pulse=None if pulse is None else np.asarray(pulse, float) / s,
                        contain=None if contain is None else np.asarray(contain, float) / s,
                        warm=warm)  # fmt: skip
        tube = dataclasses.replace(
            t, N=t.N * s**2, mu=t.mu / s**2, w_max=np.asarray(w_max, float),
            tightening=t.tightening * s, z_box=t.z_box * s,
            pulse=None if pulse is None else np.asarray(pulse, float),
        )  # fmt: skip
        return dataclasses.replace(tube, min_eigs=verify_tube(A, B, tube, Dx, Du))
    As, Bs = scale_vertices(np.asarray(A), np.asarray(B), Dx, Du)
    R, n, m = Bs.shape
    ws = np.asarray(w_max, float) / Dx
    room = np.asarray(u_room, float) / Du
    sw = np.ones(n) * 1e-3 if state_weight is None else np.asarray(state_weight, float)
    Gs = None if pulse is None else np.atleast_2d(np.asarray(pulse, float)) / Dx[None, :]
    Ps = None if contain is None else np.atleast_2d(np.asarray(contain, float)) / Dx[None, :]
    best = None
    for lam in lam_grid:
        sol = _solve_rpi_lmi(As, Bs, ws, room, sw, lam, state_max, Dx, active, Gs, Ps, warm)
        if sol is not None and (best is None or sol[0] < best[0]):
            best = sol
    if best is None:
        bound = ""
        if state_max is not None:
            sm = np.array2string(np.asarray(state_max, float), precision=4)
            bound = f" with the state supports <= {sm}"
        raise DesignError(
            "tube LMI (24) with RPI condition is infeasible for every lam in "
            f"{list(lam_grid)}{bound}: W is too large for any common ellipsoidal tube"
        )
    _, lam, Ns, Ms, mus, n_blocks, active_set = best
    Ns = 0.5 * (Ns + Ns.T)
    Fs = Ms @ np.linalg.inv(Ns)
    F = Fs * Du[:, None] / Dx[None, :]
    N = Ns * np.outer(Dx, Dx)
    mus = np.maximum(mus, 0.0)
    tube = TubeDesign(
        F=F,
        N=N,
        lam=float(lam),
        mu=mus[:n],
        w_max=np.asarray(w_max, float),
        tightening=np.sqrt(np.einsum("ij,jk,ik->i", F, N, F)),
        z_box=np.sqrt(np.diag(N)),
        min_eigs=np.zeros(R),
        n_blocks=int(n_blocks),
        pulse=None if Gs is None else Gs * Dx[None, :],
        mu_pulse=None if Gs is None else mus[n:],
        active_set=active_set,
    )
    eigs = verify_tube(A, B, tube, Dx, Du)
    if Ps is not None:
        inside = _levels(Ps, Ns)  # exact: the LMI held them at 1 - 1e-5
        if inside.max() > 1.0:
            raise DesignError(
                f"certificate failed: point {int(inside.argmax())} of `contain` lies at level "
                f"{np.sqrt(inside.max()):.9f} > 1 of Z"
            )
    if state_max is not None:
        over = tube.z_box > np.asarray(state_max, float)
        if over.any():
            j = int(np.flatnonzero(over)[0])
            raise DesignError(
                f"certificate failed: support of Z along state {j} is {tube.z_box[j]:.6g} > "
                f"the bound {state_max[j]:.6g}"
            )
    return dataclasses.replace(tube, min_eigs=eigs)
