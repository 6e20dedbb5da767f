"""Tensor-product (TP) model transformation to a polytopic LPV model, eq. (10)-(12).

Follows Baranyi 2004 (Yang et al. 2022, ref. [33]):

1. Sample S(p) = [A(p) B(p)] of the Jacobian linearisation on a dense grid over
   p = [h, V] (in scaled coordinates, see below).
2. Higher-order SVD per scheduling dimension: unfold the sampled tensor along h
   (resp. V), keep r_h (resp. r_V) weighting functions.
3. Convex hull manipulation: the weighting functions are made sum-normalised (SN)
   and non-negative (NN) by enclosing the sampled points in a simplex of minimum
   volume (an approximation of close-to-normal, CNO: every vertex weight gets as
   close to 1 as the data allow).
4. Vertex systems S_i = core tensor, weights tau_i(p) = w^h_a(h) w^V_b(V) with
   i = a r_V + b (R_l = r_h r_V vertices, eq. 11).

SN by construction: in each dimension, the r weighting functions span the constant
function and the r-1 dominant singular vectors of the centred unfolding (the
unfolding minus its mean over the samples). The singular values of that centred
unfolding are reported; the constant is always kept, so "r weighting functions"
means the affine part plus r-1 singular values.

Scaling: A_s = D_x^-1 A D_x, B_s = D_x^-1 B D_u with the vehicle file's scales, so
that the SVD weighs every entry by its effect in typical units.

Between samples the weighting functions are interpolated linearly, which keeps them
non-negative and summing to 1 everywhere in the envelope.

scipy.signal and scipy.optimize are imported by the design-time functions that use
them, not with this module, which every node of the SIL graph imports (the online
LPV weights need neither; start-up time of the graph, docs/guide/sil.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fahv.errors import DesignError
from fahv.model.blas import one_blas_thread


def tp_weights(h, V, h_grid, V_grid, W_h, W_V) -> np.ndarray:
    """Vertex weights tau_i(p) (R,) = w_h,a(h) w_V,b(V), i = a r_V + b, eq. (11).

    Parameters
    ----------
    h, V : float
        Scheduling variables [ft, ft/s], clipped to the grids.
    h_grid : (N_h,) ndarray
    V_grid : (N_V,) ndarray
    W_h : (N_h, r_h) ndarray
    W_V : (N_V, r_V) ndarray
        Sampled weighting functions, linearly interpolated.

    Returns
    -------
    (R,) ndarray
        The weights, R = r_h r_V: non-negative and summing to 1 where the sampled
        weighting functions are.

    Examples
    --------
    >>> w = tp_weights(0.25, 1.5, np.array([0.0, 1.0]), np.array([0.0, 1.0, 2.0]),
    ...                np.eye(2), np.array([[1.0, 0.0], [0.5, 0.5], [0.0, 1.0]]))
    >>> w.tolist(), float(w.sum())  # (0.75, 0.25) x (0.25, 0.75): non-negative, sum 1
    ([0.1875, 0.5625, 0.0625, 0.1875], 1.0)
    """
    wh = np.array([np.interp(h, h_grid, W_h[:, a]) for a in range(W_h.shape[1])])
    wv = np.array([np.interp(V, V_grid, W_V[:, b]) for b in range(W_V.shape[1])])
    return np.outer(wh, wv).ravel()


@dataclass(frozen=True)
class DiscretePolytope:
    """Discrete polytopic LPV model x(k+1) = sum_i tau_i(p) (A_i x + B_i u), eq. (12).

    Attributes
    ----------
    A : (R, n, n) ndarray
        Vertex state matrices A_i (ZOH of the continuous vertices).
    B : (R, n, m) ndarray
        Vertex input matrices B_i.
    Ts : float
        Sampling period [s].
    """

    A: np.ndarray
    B: np.ndarray
    Ts: float

    @property
    def n_vertices(self) -> int:
        """Number of vertices R_l."""
        return self.A.shape[0]


@dataclass(frozen=True)
class TPModel:
    """Polytopic LPV model from the TP transformation, eq. (11).

    Attributes
    ----------
    kind : str
        Linearised model ("dm", "cm" or "ecm").
    h_grid : (N_h,) ndarray
        Sampling grid in h [ft].
    V_grid : (N_V,) ndarray
        Sampling grid in V [ft/s].
    W_h : (N_h, r_h) ndarray
        Sampled weighting functions of h (non-negative, rows sum to 1).
    W_V : (N_V, r_V) ndarray
        Sampled weighting functions of V.
    A_vertices : (R, n, n) ndarray
        Continuous vertex matrices A_i (unscaled units), R = r_h r_V.
    B_vertices : (R, n, m) ndarray
        Continuous vertex matrices B_i.
    state_scale : (n,) ndarray
    input_scale : (m,) ndarray
    sv_h, sv_V : ndarray
        Singular values of the centred unfoldings (all of them, descending).
    meta : dict
        Free-form notes on how the model was made (empty by default).
    """

    kind: str
    h_grid: np.ndarray
    V_grid: np.ndarray
    W_h: np.ndarray
    W_V: np.ndarray
    A_vertices: np.ndarray
    B_vertices: np.ndarray
    state_scale: np.ndarray
    input_scale: np.ndarray
    sv_h: np.ndarray
    sv_V: np.ndarray
    meta: dict = field(default_factory=dict)

    @property
    def n_vertices(self) -> int:
        """Number of vertex systems R_l = r_h r_V."""
        return self.A_vertices.shape[0]

    @property
    def shape(self) -> tuple[int, int]:
        """(r_h, r_V)."""
        return self.W_h.shape[1], self.W_V.shape[1]

    def weights(self, h: float, V: float) -> np.ndarray:
        """Vertex weights tau_i(p), shape (R,), non-negative, summing to 1.

        Parameters
        ----------
        h, V : float
            Scheduling variables [ft, ft/s]; clipped to the sampling grid (the
            envelope), so a plant that leaves the envelope transiently gets the
            weights of the nearest boundary point.

        Returns
        -------
        (R,) ndarray
            tau_i(p), i = a r_V + b (`tp_weights`).

        Examples
        --------
        >>> from fahv.model.vehicle import load_vehicle
        >>> tp = build_tp_model(load_vehicle(), "dm", 2, 2, n_h=3, n_V=3)
        >>> w = tp.weights(85500.0, 7900.0)
        >>> w.shape, bool(w.min() >= 0.0), round(float(w.sum()), 12)
        ((4,), True, 1.0)
        >>> w_out = tp.weights(90000.0, 7900.0)  # outside: the nearest boundary point's
        >>> bool(np.array_equal(w_out, tp.weights(86500.0, 7900.0)))
        True
        """
        return tp_weights(h, V, self.h_grid, self.V_grid, self.W_h, self.W_V)

    def system(self, h: float, V: float) -> tuple[np.ndarray, np.ndarray]:
        """Continuous A(p) (n, n), B(p) (n, m) = sum_i tau_i(p) [A_i, B_i], eq. (11).

        Parameters
        ----------
        h : float
            Altitude [ft], clipped to the sampling grid.
        V : float
            Speed [ft/s], clipped to the sampling grid.

        Returns
        -------
        A : (n, n) ndarray
        B : (n, m) ndarray
            The scheduled continuous matrices (unscaled units).
        """
        w = self.weights(h, V)
        return (np.tensordot(w, self.A_vertices, axes=1), np.tensordot(w, self.B_vertices, axes=1))

    @one_blas_thread
    def discretize(self, Ts: float) -> DiscretePolytope:
        """ZOH discretisation of every vertex with period Ts [s], eq. (12).

        Uses `scipy.signal.cont2discrete`.

        Parameters
        ----------
        Ts : float
            Sampling period [s], > 0.

        Returns
        -------
        DiscretePolytope
            The discrete vertices A_i (R, n, n), B_i (R, n, m).

        Raises
        ------
        ValueError
            If Ts <= 0 or is not finite.

        Examples
        --------
        >>> from fahv.model.vehicle import load_vehicle
        >>> tp = build_tp_model(load_vehicle(), "dm", 2, 2, n_h=3, n_V=3)
        >>> dp = tp.discretize(0.02)
        >>> dp.n_vertices, dp.A.shape, dp.B.shape, dp.Ts
        (4, (4, 9, 9), (4, 9, 2), 0.02)
        """
        from scipy.signal import cont2discrete  # design time only (node start-up)

        if not (np.isfinite(Ts) and Ts > 0.0):
            raise ValueError(f"sampling period Ts must be > 0, got {Ts}")
        n, m = self.B_vertices.shape[1:]
        Ad, Bd = [], []
        for A, B in zip(self.A_vertices, self.B_vertices, strict=True):
            a, b, *_ = cont2discrete((A, B, np.eye(n), np.zeros((n, m))), Ts, method="zoh")
            Ad.append(a)
            Bd.append(b)
        return DiscretePolytope(np.array(Ad), np.array(Bd), Ts)


def _min_volume_simplex(Y: np.ndarray) -> np.ndarray:
    """Barycentric weights (N, d+1) of points Y (N, d) in a minimum-volume simplex.

    Non-convex (MVES-type): maximise log|det G| over G (d+1, d+1) subject to
    G [Y^T; 1] >= 0 and 1^T G = e_{d+1}^T, so that W^T = G [Y^T; 1] are barycentric
    coordinates; the simplex volume is proportional to 1/|det G|. Solved locally by
    SLSQP from an enclosing corner simplex. For d = 1 the exact answer is the
    interval [min, max].
    """
    N, d = Y.shape
    if d == 1:
        lo, hi = Y[:, 0].min(), Y[:, 0].max()
        w1 = (Y[:, 0] - lo) / (hi - lo)
        return np.column_stack([1.0 - w1, w1])
    # normalise the cloud for conditioning
    mu, sd = Y.mean(axis=0), Y.std(axis=0)
    sd[sd == 0.0] = 1.0
    Yn = (Y - mu) / sd
    lo = Yn.min(axis=0)
    s = (Yn - lo).sum(axis=1).max()
    verts = np.vstack([lo] + [lo + s * np.eye(d)[j] for j in range(d)]) * 1.05 - 0.05 * Yn.mean(0)
    r = d + 1
    Ya = np.vstack([Yn.T, np.ones(N)])  # (r, N)

    def to_G(z):
        return z.reshape(r, r)

    def obj(z):
        sign, logdet = np.linalg.slogdet(to_G(z))
        return -logdet if sign != 0 else 1e6

    M0 = np.vstack([verts.T, np.ones(r)])
    G0 = np.linalg.inv(M0)
    cons = [
        {
            "type": "ineq",
            "fun": lambda z: (to_G(z) @ Ya).ravel(),
            "jac": lambda z: np.kron(np.eye(r), Ya.T),
        },
        {
            "type": "eq",
            "fun": lambda z: np.ones(r) @ to_G(z) - np.eye(r)[-1],
            "jac": lambda z: np.kron(np.ones((1, r)), np.eye(r)),
        },
    ]

    def grad(z):
        G = to_G(z)
        return -np.linalg.inv(G).T.ravel()

    from scipy import optimize  # design time only (node start-up)

    res = optimize.minimize(
        obj,
        G0.ravel(),
        jac=grad,
        constraints=cons,
        method="SLSQP",
        options={"maxiter": 500, "ftol": 1e-12},
    )
    G = to_G(res.x) if np.all(np.isfinite(res.x)) else G0
    W = (G @ Ya).T
    if W.min() < -1e-9:  # solver left the feasible set: fall back to the enclosing simplex
        W = (G0 @ Ya).T
    W = np.clip(W, 0.0, None)
    return W / W.sum(axis=1, keepdims=True)


def _mode_weights(D: np.ndarray, axis: int, r: int) -> tuple[np.ndarray, np.ndarray]:
    """SN/NN weighting functions (N_axis, r) of tensor D along `axis`; singular values."""
    unf = np.moveaxis(D, axis, 0).reshape(D.shape[axis], -1)
    cen = unf - unf.mean(axis=0, keepdims=True)
    U, sv, _ = np.linalg.svd(cen, full_matrices=False)
    if r < 2 or r - 1 > U.shape[1]:
        raise DesignError(
            f"cannot keep r = {r} weighting functions along axis {axis} "
            f"with {D.shape[axis]} samples (need 2 <= r <= samples)"
        )
    return _min_volume_simplex(U[:, : r - 1]), sv


def tp_transform(
    sample,
    h_grid,
    V_grid,
    r_h: int,
    r_V: int,
    state_scale,
    input_scale,
    kind: str = "dm",
    progress=None,
) -> TPModel:
    """TP model transformation of a sampled LPV model, eq. (11).

    Parameters
    ----------
    sample : callable
        sample(h, V) -> (A (n, n), B (n, m)) continuous Jacobian linearisation at p.
    h_grid : (N_h,) array_like
        Sampling grid in h [ft], increasing.
    V_grid : (N_V,) array_like
        Sampling grid in V [ft/s], increasing.
    r_h, r_V : int
        Number of weighting functions kept per dimension (R_l = r_h r_V vertices).
    state_scale : (n,) array_like
    input_scale : (m,) array_like
        Scaling D_x, D_u applied before the SVD.
    kind : str
        Label of the linearised model.
    progress : callable, optional
        Wrapper for an iterable (e.g. `tqdm.tqdm`) to show sampling progress.

    Returns
    -------
    TPModel

    Raises
    ------
    DesignError
        If the grid is too coarse for the requested r, or the weights are not
        SN/NN to 1e-9.

    Examples
    --------
    A model affine in each scheduling variable is reproduced exactly by 2 x 2 vertices,
    off the grid too:

    >>> def sample(h, V):
    ...     return np.array([[h + 2.0 * V]]), np.array([[1.0 + h * V]])
    >>> tp = tp_transform(sample, [0.0, 1.0, 2.0], [0.0, 1.0, 2.0], 2, 2, [1.0], [1.0])
    >>> tp.n_vertices, tp.shape
    (4, (2, 2))
    >>> A, B = tp.system(0.5, 1.5)
    >>> round(float(A[0, 0]), 12), round(float(B[0, 0]), 12)  # 0.5 + 3.0, 1 + 0.75
    (3.5, 1.75)
    """
    h_grid = np.asarray(h_grid, float)
    V_grid = np.asarray(V_grid, float)
    Dx = np.asarray(state_scale, float)
    Du = np.asarray(input_scale, float)
    pts = [(i, j) for i in range(h_grid.size) for j in range(V_grid.size)]
    it = progress(pts) if progress is not None else pts
    tensor = None
    for i, j in it:
        A, B = sample(h_grid[i], V_grid[j])
        S = np.hstack([A * Dx[None, :] / Dx[:, None], B * Du[None, :] / Dx[:, None]])
        if tensor is None:
            tensor = np.empty((h_grid.size, V_grid.size) + S.shape)
        tensor[i, j] = S
    W_h, sv_h = _mode_weights(tensor, 0, r_h)
    W_V, sv_V = _mode_weights(tensor, 1, r_V)
    for name, W in (("h", W_h), ("V", W_V)):
        if W.min() < -1e-9 or np.max(np.abs(W.sum(axis=1) - 1.0)) > 1e-9:
            raise DesignError(f"TP weights along {name} are not SN/NN")
    core = np.einsum("ia,jb,ijkl->abkl", np.linalg.pinv(W_h).T, np.linalg.pinv(W_V).T, tensor)
    n = Dx.size
    core_A = core[..., :n] * Dx[:, None] / Dx[None, :]
    core_B = core[..., n:] * Dx[:, None] / Du[None, :]
    R = r_h * r_V
    return TPModel(
        kind=kind,
        h_grid=h_grid,
        V_grid=V_grid,
        W_h=W_h,
        W_V=W_V,
        A_vertices=core_A.reshape(R, n, n),
        B_vertices=core_B.reshape(R, n, Du.size),
        state_scale=Dx,
        input_scale=Du,
        sv_h=sv_h,
        sv_V=sv_V,
    )


def approximation_error(tp: TPModel, sample, test_points) -> dict[str, float]:
    """Error between the polytopic model and the Jacobian linearisation.

    Parameters
    ----------
    tp : TPModel
    sample : callable
        sample(h, V) -> (A, B) as in `tp_transform`.
    test_points : iterable of (h, V)
        Off-grid points [ft, ft/s].

    Returns
    -------
    dict
        `max_rel`/`mean_rel`: ||S_tp - S||_F / ||S||_F in scaled coordinates;
        `max_abs_scaled`: largest entry error of S_tp - S in scaled coordinates.

    Examples
    --------
    >>> def sample(h, V):
    ...     return np.array([[h + 2.0 * V]]), np.array([[1.0 + h * V]])
    >>> tp = tp_transform(sample, [0.0, 1.0, 2.0], [0.0, 1.0, 2.0], 2, 2, [1.0], [1.0])
    >>> err = approximation_error(tp, sample, [(0.5, 1.5), (1.2, 0.3)])
    >>> err["n_points"], bool(err["max_rel"] < 1e-12)
    (2, True)
    """
    Dx, Du = tp.state_scale, tp.input_scale
    rel, absmax = [], 0.0

    def scaled(A, B):
        return np.hstack([A * Dx[None, :] / Dx[:, None], B * Du[None, :] / Dx[:, None]])

    for h, V in test_points:
        S = scaled(*sample(h, V))
        St = scaled(*tp.system(h, V))
        rel.append(np.linalg.norm(St - S) / np.linalg.norm(S))
        absmax = max(absmax, float(np.max(np.abs(St - S))))
    return {
        "max_rel": float(np.max(rel)),
        "mean_rel": float(np.mean(rel)),
        "max_abs_scaled": absmax,
        "n_points": len(rel),
    }


@one_blas_thread
def build_tp_model(
    vehicle, kind: str, r_h: int, r_V: int, n_h: int = 21, n_V: int = 21, notch=None, progress=None
) -> TPModel:
    """Sample the Jacobian linearisation of `kind` over the envelope and TP-transform it.

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    kind : {"dm", "cm", "ecm"}
    r_h, r_V : int
        Weighting functions per dimension (Case 1: 4 x 5 = 20; Case 2: 2 x 3 = 6).
    n_h, n_V : int
        Sampling grid size over the envelope (uniform, corners included).
    notch : NotchFilter, optional
        Required for "ecm".
    progress : callable, optional
        Iterable wrapper (tqdm) for progress display.

    Returns
    -------
    TPModel

    Raises
    ------
    EnvelopeError, TrimError, DesignError

    Examples
    --------
    A coarse model (the designs use 21 x 21 samples and 4 x 5 or 2 x 3 vertices):

    >>> from fahv.model.vehicle import load_vehicle
    >>> tp = build_tp_model(load_vehicle(), "dm", 2, 2, n_h=3, n_V=3)
    >>> tp.kind, tp.shape, tp.A_vertices.shape, tp.B_vertices.shape
    ('dm', (2, 2), (4, 9, 9), (4, 9, 2))
    """
    from fahv.model.dynamics import make_model
    from fahv.model.linearize import linearize

    env = vehicle.envelope
    h_grid = np.linspace(env.h_min, env.h_max, n_h)
    V_grid = np.linspace(env.V_min, env.V_max, n_V)
    model = make_model(kind, vehicle, notch)

    def sample(h, V):
        lm = linearize(vehicle, h, V, kind, notch)
        return lm.A, lm.B

    tp = tp_transform(
        sample,
        h_grid,
        V_grid,
        r_h,
        r_V,
        model.state_scale(vehicle, notch),
        vehicle.input_scale,
        kind,
        progress,
    )
    return tp


def offgrid_points(tp: TPModel, n_random: int = 50, seed: int = 0) -> list[tuple[float, float]]:
    """Test points off the sampling grid: all cell centres plus `n_random` uniform points.

    The random points are drawn with `numpy.random.default_rng(seed)`.

    Parameters
    ----------
    tp : TPModel
        The model whose sampling grid the points avoid.
    n_random : int
        Uniform random points added to the cell centres.
    seed : int
        Seed of the random points.

    Returns
    -------
    list of (float, float)
        (h [ft], V [ft/s]): the (N_h - 1)(N_V - 1) cell centres, then the random points.

    Examples
    --------
    >>> def sample(h, V):
    ...     return np.array([[h + V]]), np.array([[1.0]])
    >>> tp = tp_transform(sample, [0.0, 1.0, 2.0], [0.0, 1.0, 2.0], 2, 2, [1.0], [1.0])
    >>> points = offgrid_points(tp, n_random=3)
    >>> len(points), points[0]  # 2 x 2 cell centres, then the random points
    (7, (0.5, 0.5))
    """
    hc = 0.5 * (tp.h_grid[1:] + tp.h_grid[:-1])
    vc = 0.5 * (tp.V_grid[1:] + tp.V_grid[:-1])
    pts = [(float(h), float(v)) for h in hc for v in vc]
    rng = np.random.default_rng(seed)
    pts += list(
        zip(
            rng.uniform(tp.h_grid[0], tp.h_grid[-1], n_random).tolist(),
            rng.uniform(tp.V_grid[0], tp.V_grid[-1], n_random).tolist(),
            strict=True,
        )
    )
    return pts
