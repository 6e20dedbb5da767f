"""What can be certified about the Kalman filter's estimation error, and what cannot.

The filter of `fahv.estimation.kalman` corrects with y_k = C x_k + v_k and predicts with
the model; on the LPV model (eq. 11-12) its a-posteriori error e = z - z_hat of the
augmented state z = [x; d] (11,) obeys, for a model vertex i and a gain vertex j,

    e_k+1 = M_ij e_k + G_j g_k + N_j v_k+1,
    M_ij = (I - L_j C_z) A_z,i,   G_j = I - L_j C_z,   N_j = -L_j,

with A_z,i = [[A_i, B_i], [0, I]] (`fahv.estimation.kalman.augmented`), C_z = [C 0],
g_k = [w_k; w_d,k] the one-step model error (inside the design's W, eq. 13-19) and the
input disturbance's step, v the sensors' white noise. A filter with the servos' states
has z = [x; d; s] (15,) and A_z,i of `fahv.estimation.servo_model.with_servos`
(`GainScheduledKalman.model_vertices`); the servos' model is exact, so g's last four
entries are zero. The gains are scheduled on the
estimate and the model on the true state, so every pair (i, j) is a vertex of the
error system. The error splits, by linearity, into a part driven by the noise and a
part driven by g:

- **the noise as a random sequence** (`covariance_bound`): a common bound S on the
  error's covariance, S >= M_ij S M_ij' + N_j R_v N_j' at every pair (an LMI in S,
  Lyapunov's inequality of Kothare-style LPV analysis), so that whatever the vertices
  visit the covariance stays below S; with the union bound over the steps and
  states of a run, |e_s| <= r sqrt(S_ss) for the whole run with probability p;
- **the noise or g as a bounded sequence** (`peak_to_peak`): the exact worst case of
  each state's error at the frozen vertices (M_ii held), the l1 norm of the impulse
  response times the bounds. A certificate that bounds the error for every sequence
  within the bounds must also bound these frozen cases, so they are lower bounds on
  any worst-case (set-based) certificate, and they are reached by the sequence of
  signs of the impulse response (`worst_sequence`).

The error system is linear in the LPV model; the nonlinear plant, the filter's nonlinear
predictor and the scheduling of the gains on the estimate are not in it: the sampled
check (tests/estimation) compares the bound with the error of the nonlinear loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.errors import DesignError
from fahv.estimation.kalman import GainScheduledKalman
from fahv.model.blas import one_blas_thread

#: Strict margin of the covariance LMI (in the coordinates scaled by the filter's own
#: standard deviations, where S is of order 1): the exact re-check then needs none.
COVARIANCE_MARGIN = 1e-6


@dataclass(frozen=True)
class ErrorSystem:
    """The a-posteriori error system of a gain-scheduled filter at its vertex pairs.

    Attributes
    ----------
    M : (R, R, n_z, n_z) ndarray
        M_ij = (I - L_j C_z) A_z,i: model vertex i, gain vertex j; n_z = 11 (z = [x; d]),
        or 15 with the servos' states.
    G : (R, n_z, n_z) ndarray
        G_j = I - L_j C_z, the map of the model error g = [w; w_d] (zero on the servos).
    N : (R, n_z, n_y) ndarray
        N_j = -L_j, the map of the noise v.
    sigma : (n_z,) ndarray
        The largest steady-state standard deviation of each error state over the
        vertices (the filter's own, `GainScheduledKalman.P`): the scale of the analysis.
    """

    M: np.ndarray
    G: np.ndarray
    N: np.ndarray
    sigma: np.ndarray

    @property
    def n_vertices(self) -> int:
        """R, the vertices of the model (and of the gains)."""
        return int(self.M.shape[0])


def error_system(flt: GainScheduledKalman) -> ErrorSystem:
    """The error system of a filter (`fahv.estimation.kalman.design_filter`).

    Parameters
    ----------
    flt : GainScheduledKalman
        A filter with its vertex covariances `P`.

    Returns
    -------
    ErrorSystem

    Raises
    ------
    ValueError
        If the filter has no covariances (`P` None).
    """
    if flt.P is None:
        raise ValueError("error_system: the filter has no steady-state covariances (P)")
    Az = flt.model_vertices()
    n = Az.shape[1]
    Cz = np.hstack([flt.C, np.zeros((len(flt.C), n - flt.C.shape[1]))])
    G = np.eye(n)[None] - np.einsum("jik,kl->jil", flt.L, Cz)
    M = np.einsum("jab,ibc->ijac", G, Az)
    sigma = np.sqrt(np.einsum("rii->ri", flt.P).max(axis=0))
    return ErrorSystem(M, G, -flt.L, sigma)


@dataclass(frozen=True)
class CovarianceBound:
    """A common bound S on the error's covariance at every vertex pair (`covariance_bound`).

    Attributes
    ----------
    S : (n_z, n_z) ndarray
        The bound [units of z squared].
    min_eig : float
        Smallest eigenvalue of S - M_ij S M_ij' - N_j R_v N_j' over all pairs, in the
        scaled coordinates (the exact re-check: >= 0).
    pairs_held : int
        Vertex pairs the last LMI solve held (constraint generation).
    pairs : tuple of (int, int)
        Those pairs (model vertex, gain vertex), in the solve's order: given back as
        `start`, the same bound takes one solve.
    """

    S: np.ndarray
    min_eig: float
    pairs_held: int
    pairs: tuple = ()

    @property
    def std(self) -> np.ndarray:
        """sqrt(diag S) (n_z,): the bound on each state's error standard deviation."""
        return np.sqrt(np.diag(self.S))


def _pair_margins(Ss: np.ndarray, Qs: np.ndarray, Ms: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of S - M_ij S M_ij' - Q_j (R, R), scaled coordinates."""
    lhs = Ss[None, None] - np.einsum("ijab,bc,ijdc->ijad", Ms, Ss, Ms) - Qs[None]
    return np.linalg.eigvalsh(0.5 * (lhs + np.swapaxes(lhs, -1, -2)))[..., 0]


def exact_margin(es: ErrorSystem, S: np.ndarray, R_v: np.ndarray) -> float:
    """The exact re-check of a covariance bound: min over the pairs of the smallest eigenvalue.

    Parameters
    ----------
    es : ErrorSystem
    S : (n, n) ndarray
        A covariance bound in the states' units (`CovarianceBound.S`).
    R_v : (n_y, n_y) ndarray
        The sensors' white-noise covariance.

    Returns
    -------
    float
        min over every pair (i, j) of the smallest eigenvalue of S - M_ij S M_ij' - N_j
        R_v N_j' in the coordinates e / sigma (>= 0: S bounds the covariance).
    """
    D = es.sigma
    Ms = es.M / D[None, None, :, None] * D[None, None, None, :]
    Ns = es.N / D[None, :, None]
    Qs = np.einsum("jab,bc,jdc->jad", Ns, np.asarray(R_v, float), Ns)
    return float(_pair_margins(np.asarray(S, float) / np.outer(D, D), Qs, Ms).min())


def covariance_bound(es: ErrorSystem, R_v: np.ndarray, add: int = 10,
                     start=None) -> CovarianceBound:  # fmt: skip
    """The smallest (in trace, scaled) common covariance bound of the noise-driven error.

    Solves min trace(S) s.t. S - M_ij S M_ij' - N_j R_v N_j' >= COVARIANCE_MARGIN I in the
    coordinates e / sigma, on the matched pairs (i, i) first, then adding per pass the
    `add` pairs of the R^2 whose exact smallest eigenvalue is most negative, until none
    is (constraint generation; a pair off the solution's dual support is released, each
    at most once, `fahv.synthesis.lmi.dual_support`): every pair is then re-checked
    exactly, without a tolerance. If S bounds the covariance of e_k it bounds that of
    e_k+1 whatever pair the step takes, so the bound holds from a start inside it (the
    filter's start at the trim: its own steady covariance) for any sequence of vertices.

    Parameters
    ----------
    es : ErrorSystem
    R_v : (n_y, n_y) ndarray
        Covariance of the sensors' white noise (`fahv.estimation.kalman.measurement_covariance`).
    add : int
        Pairs added per pass.
    start : sequence of (int, int), optional
        The pairs the first solve holds (default the matched pairs (i, i)): a bound's own
        `pairs` make it again in one solve. The re-check over every pair is the same
        whatever the start, so a start changes the work, never what is certified.

    Returns
    -------
    CovarianceBound

    Raises
    ------
    DesignError
        If the LMI is infeasible or the solver fails, or the re-check fails at a pair
        the solve held (naming it and the eigenvalue).
    ValueError
        If a pair of `start` is not a vertex pair of the system.

    Examples
    --------
    One state, e+ = 0.5 e - 0.5 v, var v = 1: S >= 0.25 S + 0.25, so S = 1/3:

    >>> es = ErrorSystem(np.full((1, 1, 1, 1), 0.5), np.ones((1, 1, 1)),
    ...                  np.full((1, 1, 1), -0.5), np.ones(1))
    >>> round(float(covariance_bound(es, np.eye(1)).S[0, 0]), 5)
    0.33333
    """
    import cvxpy as cp  # the solver where it is used: `fahv verify` re-checks without it

    from fahv.synthesis.lmi import dual_support, solve_lmi

    D = es.sigma
    Ms = es.M / D[None, None, :, None] * D[None, None, None, :]
    Ns = es.N / D[None, :, None]
    Qs = np.einsum("jab,bc,jdc->jad", Ns, np.asarray(R_v, float), Ns)
    R, n = es.n_vertices, len(D)
    held = [(i, i) for i in range(R)] if start is None else [(int(i), int(j)) for i, j in start]
    outside = [p for p in held if not (0 <= p[0] < R and 0 <= p[1] < R)]
    if outside or not held:
        raise ValueError(f"covariance_bound: start pairs {outside or held} are not vertex "
                         f"pairs of the {R}-vertex system")  # fmt: skip
    released: set = set()
    while True:
        S = cp.Variable((n, n), symmetric=True)
        cons = [S - Ms[i, j] @ S @ Ms[i, j].T - Qs[j] >> COVARIANCE_MARGIN * np.eye(n)
                for i, j in held]  # fmt: skip
        if not solve_lmi(cp.Problem(cp.Minimize(cp.trace(S)), cons)):
            rho = max(np.abs(np.linalg.eigvals(es.M[i, j])).max() for i, j in held)
            why = ("a pair is not stable" if rho >= 1.0 else "each pair is stable: the LMI "
                   "is infeasible or the solver failed numerically")  # fmt: skip
            raise DesignError(f"covariance bound: the solver found no bound on {len(held)} "
                              f"vertex pairs (largest spectral radius {rho:.6f}; {why})")
        Sv = 0.5 * (S.value + S.value.T)
        margins = _pair_margins(Sv, Qs, Ms)
        bad = [(int(i), int(j)) for i, j in np.argwhere(margins < 0.0) if (i, j) not in held]
        if not bad:
            break
        bad.sort(key=lambda p: margins[p])
        # pairs off the dual support are released, each once (then the passes end)
        support = {held[k] for k in dual_support(cons)}
        drop = {p for p in held if p not in support and p not in released}
        released |= drop
        held = [p for p in held if p not in drop] + bad[:add]
    worst = float(margins.min())
    if worst < 0.0:
        i, j = np.unravel_index(np.argmin(margins), margins.shape)
        raise DesignError(f"covariance bound: re-check failed at model vertex {i}, gain vertex "
                          f"{j}: smallest eigenvalue {worst:.3e} < 0")  # fmt: skip
    return CovarianceBound(Sv * np.outer(D, D), worst, len(held), tuple(held))


def _frozen(es: ErrorSystem) -> tuple[np.ndarray, np.ndarray]:
    """The matched vertices' M_ii (R, n_z, n_z) and their inputs [G_i, N_i] (R, n_z, p)."""
    R = es.n_vertices
    M = es.M[np.arange(R), np.arange(R)]
    return M, np.concatenate([es.G, es.N], axis=2)


def _horizon(M: np.ndarray, tail: float = 1e-12) -> int:
    """Steps after which rho(M_ii)^t < tail at every vertex; ValueError if rho >= 1."""
    rho = float(np.abs(np.linalg.eigvals(M)).max())
    if not rho < 1.0:
        raise ValueError(f"peak_to_peak: a frozen error system is not stable (rho = {rho:.6f})")
    return int(np.ceil(np.log(tail) / np.log(rho))) + 100


#: Steps of the impulse response `peak_to_peak` takes per product: the powers M^k X,
#: k < PEAK_BLOCK, side by side, so that a block of the series is one matrix product.
PEAK_BLOCK = 128


@one_blas_thread
def peak_to_peak(es: ErrorSystem, xi_max: np.ndarray, states=None) -> np.ndarray:
    """The exact worst case of each error state at every frozen vertex (M_ii, G_i, N_i).

    For e_k+1 = M e_k + [G N] xi_k+1 with |xi_c| <= xi_max_c, the largest |e_s| any
    sequence reaches is sum_t sum_c |(M^t [G N])_sc| xi_max_c (the l1 norm of the
    impulse response, reached by `worst_sequence`), summed until the tail is below 1e-12
    of the first term (rho(M_ii)^t). The terms are summed `PEAK_BLOCK` steps at a time,
    the rows of M^(b PEAK_BLOCK) times the block's M^k [G N] xi_max (the inputs that are
    off left out): the same series, rounded otherwise (one BLAS thread).

    Parameters
    ----------
    es : ErrorSystem
    xi_max : (n_z + n_y,) array_like
        Bounds of [w (9); w_d (2); v (n_y)] (zero: that input off).
    states : sequence of int, optional
        The error states to bound (default all of them, in order).

    Returns
    -------
    (R, n_z) ndarray
        Worst |e_s| at each frozen vertex [units of z]; (R, len(states)) with `states`.

    Raises
    ------
    ValueError
        If a frozen vertex's error system is not stable, or xi_max has the wrong length.

    Examples
    --------
    e+ = 0.5 e + v, |v| <= 1: the worst |e| is 1 + 0.5 + 0.25 + ... = 2:

    >>> es = ErrorSystem(np.full((1, 1, 1, 1), 0.5), np.zeros((1, 1, 1)),
    ...                  np.ones((1, 1, 1)), np.ones(1))
    >>> round(float(peak_to_peak(es, [0.0, 1.0])[0, 0]), 9)
    2.0
    """
    M, D = _frozen(es)
    xi = np.asarray(xi_max, float)
    if xi.shape != (D.shape[2],):
        raise ValueError(f"peak_to_peak: xi_max has shape {xi.shape}, expected {(D.shape[2],)}")
    R, n = M.shape[:2]
    on = xi != 0.0
    X = D[:, :, on] * xi[on]  # (R, n, c): the inputs that are on
    rows = np.eye(n)[slice(None) if states is None else np.asarray(states, int)]
    steps = _horizon(M)
    K = min(steps, PEAK_BLOCK)
    Q = np.empty((R, n, K, X.shape[2]))  # M^k X, k < K
    for k in range(K):
        Q[:, :, k] = X
        X = M @ X
    Q = Q.reshape(R, n, -1)
    MK = np.linalg.matrix_power(M, K)
    W = np.repeat(rows[None], R, axis=0)  # the rows of M^t0 of the states asked
    acc = np.zeros(W.shape[:2])
    for t0 in range(0, steps, K):
        terms = np.abs(W @ Q).reshape(R, len(rows), K, -1)
        acc += terms[:, :, : steps - t0].sum(axis=(2, 3))
        W = W @ MK
    return acc


def worst_sequence(es: ErrorSystem, xi_max, vertex: int, state: int,
                   steps: int) -> np.ndarray:  # fmt: skip
    """The input sequence that drives an error state of a frozen vertex to its worst case.

    At the last of `steps` steps: xi_t = sign((M^(T-t) [G N])_s,:) xi_max.

    Parameters
    ----------
    es : ErrorSystem
    xi_max : (n_z + n_y,) array_like
    vertex, state : int
    steps : int
        T.

    Returns
    -------
    (T, n_z + n_y) ndarray
        xi_1 .. xi_T; from e_0 = 0, e_T,s is the sum of the first T terms of
        `peak_to_peak`'s series.
    """
    M, D = _frozen(es)
    row = np.eye(M.shape[1])[state]
    out = np.empty((steps, D.shape[2]))
    for t in range(steps - 1, -1, -1):  # xi_T first: the impulse response's first term
        out[t] = np.sign(row @ D[vertex]) * np.asarray(xi_max, float)
        row = row @ M[vertex]
    return out
