"""How fast the tube's part of the command can move: its share of the servos' rate limits.

The ancillary law applies u = v + F e (eq. 36), and along the tube e+ = A_cl,i e + w
with A_cl,i = A_i + B_i F, e in Z and w in W. The tube's part of the command therefore
changes in one step by

    F e+ - F e = F (A_cl,i - I) e + F w,

whose largest value per input is the support of Z in the direction
c_i = (A_cl,i - I)' F_j' plus that of the box W in the direction F_j:

    max |F_j (e+ - e)| = max_i sqrt(c_i' N c_i) + sum_k |F_jk| w_k

(an ellipsoid's support and a box's; the two sets are independent, so their sum is the
support of their Minkowski sum, and the support is convex in A_cl, so the largest over
the polytope of systems is taken at a vertex). The nominal input's own change and its
disturbance estimate's are not part of it (`fahv.control.mpc.settings`, `du_max`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TubeRate:
    """The largest one-step change of the tube's part F e of the command.

    Attributes
    ----------
    over_z : (m,) ndarray
        max over the vertices of the support of Z in the direction (A_cl,i - I)' F_j'
        [input units per step].
    over_w : (m,) ndarray
        Support of W in the direction F_j [input units per step].
    vertex : (m,) ndarray of int
        The vertex of each input's largest `over_z`.
    """

    over_z: np.ndarray
    over_w: np.ndarray
    vertex: np.ndarray

    @property
    def per_step(self) -> np.ndarray:
        """(m,) bound of |F_j (e+ - e)| per step: `over_z` + `over_w`."""
        return self.over_z + self.over_w


def tube_rate(A, B, F, N, W) -> TubeRate:
    """Largest one-step change of F e along the tube, at every vertex (module docstring).

    Parameters
    ----------
    A : (R, n, n) array_like
        Vertex state matrices of the tube's states.
    B : (R, n, m) array_like
        Vertex input matrices.
    F : (m, n) array_like
        Ancillary gain.
    N : (n, n) array_like
        Shape of the tube set Z = {e' N^-1 e <= 1}, positive definite.
    W : (n,) array_like
        Half-widths of the disturbance box W (unscaled, the states' units).

    Returns
    -------
    TubeRate

    Raises
    ------
    ValueError
        On inconsistent shapes or a W that is negative or not finite.

    Examples
    --------
    One state, e+ = 0.5 e + w, F = -1, Z = [-1, 1], |w| <= 0.25: F e moves by at most
    |0.5 - 1| 1 + 0.25 = 0.75 per step.

    >>> r = tube_rate([[[1.0]]], [[[0.5]]], [[-1.0]], [[1.0]], [0.25])
    >>> r.per_step.tolist(), r.vertex.tolist()
    ([0.75], [0])
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    F, N, W = np.atleast_2d(np.asarray(F, float)), np.asarray(N, float), np.asarray(W, float)
    R, n = A.shape[0], A.shape[1]
    m = F.shape[0]
    if A.shape != (R, n, n) or B.shape != (R, n, m) or F.shape != (m, n) \
            or N.shape != (n, n) or W.shape != (n,):  # fmt: skip
        raise ValueError(
            f"tube_rate: shapes A {A.shape}, B {B.shape}, F {F.shape}, N {N.shape}, "
            f"W {W.shape}"
        )
    if not np.all(np.isfinite(W)) or np.any(W < 0.0):
        raise ValueError("tube_rate: W must be finite and non-negative")
    C = F[None] @ (A + B @ F[None] - np.eye(n))  # (R, m, n): F (A_cl,i - I)
    ell = np.sqrt(np.maximum(np.einsum("rjk,kl,rjl->rj", C, N, C), 0.0))
    return TubeRate(ell.max(axis=0), np.abs(F) @ W, ell.argmax(axis=0))


def law_rate(A, B, F, N, W, tau: float = 1.0) -> TubeRate:
    """The one-step change of the command part tau F e the adjustable law applies.

    The law u = v + tau F e (eq. 53-54) closes the loop A_i + tau B_i F, which is the
    vertex [A_i, tau B_i] with the gain F, and its command moves by tau times F's move:
    `tube_rate` over those vertices, times tau. At tau = 1 this is `tube_rate`.

    Parameters
    ----------
    A, B : (R, n, n), (R, n, m) array_like
        The tube's vertices; for tau < 1 the eight-state tube's own (eq. 48), [A_i, B_i]
        and then [A_i, tau B_i] (`fahv.bounds.vertices.gain_vertices`, R even).
    F, N, W : array_like
        As `tube_rate`.
    tau : float
        The adjustable factor, 0 < tau <= 1.

    Returns
    -------
    TubeRate
        Of the law's command [input units per step].

    Raises
    ------
    ValueError
        As `tube_rate`, or if tau is not in (0, 1] or R is odd for tau < 1.

    Examples
    --------
    >>> r = law_rate([[[1.0]], [[1.0]]], [[[0.5]], [[0.25]]], [[-1.0]], [[1.0]], [0.25], 0.5)
    >>> r.per_step.tolist()  # 0.5 (|0.75 - 1| 1 + 0.25)
    [0.25]
    """
    if not 0.0 < tau <= 1.0:
        raise ValueError(f"law_rate: tau = {tau} must lie in (0, 1]")
    A, B = np.asarray(A, float), np.asarray(B, float)
    if tau < 1.0:
        if A.shape[0] % 2:
            raise ValueError("law_rate: tau < 1 needs the tube's 2R gain vertices")
        A, B = A[A.shape[0] // 2:], B[B.shape[0] // 2:]
    r = tube_rate(A, B, F, N, W)
    return TubeRate(tau * r.over_z, tau * r.over_w, r.vertex)
