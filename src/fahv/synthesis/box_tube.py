"""The paper's box-shaped tube Z = {|e| <= z} (eq. 25-28), for a given gain F.

For a box W, Z is robust positively invariant under e+ = A_cl,i e + w at every vertex
iff |A_cl,i| z + w_max <= z elementwise (Farkas' lemma turns the robust constraint (27)
into this linear one), which needs the spectral radius of |A_cl,i| below 1: a property
of the coordinates, not of stability. On this vehicle it fails, which is why the tube
used is the ellipsoid of `fahv.synthesis.feedback`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from fahv.errors import DesignError
from fahv.synthesis.lmi import scale_vertices


@dataclass(frozen=True)
class BoxTubeResult:
    """Outcome of the paper's box-shaped tube (eq. 25-28) for a given F.

    Attributes
    ----------
    feasible : bool
    z : (n,) ndarray or None
        Half-widths of the minimal box RPI set (unscaled) when feasible.
    spectral_radius_abs : (R,) ndarray
        rho(|A_i + B_i F|) in scaled coordinates; a box exists only if all < 1.
    """

    feasible: bool
    z: np.ndarray | None
    spectral_radius_abs: np.ndarray


def box_tube(A, B, F, w_max, Dx, Du) -> BoxTubeResult:
    """Smallest box Z = {|e| <= z} with |A_cl,i| z + w_max <= z for all i (eq. 25-28).

    Solved as the LP min sum z (eq. 28: Farkas' lemma turns the robust constraint (27)
    into this linear one for a box) with cvxpy/HiGHS in scaled coordinates. The result
    is re-checked elementwise.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices (unscaled).
    F : (m, n) ndarray
        Feedback gain (unscaled), A_cl,i = A_i + B_i F.
    w_max : (n,) array_like
        Half-widths of W (state units).
    Dx : (n,) ndarray
    Du : (m,) ndarray
        State and input scaling of the LP.

    Returns
    -------
    BoxTubeResult
        Feasibility, the half-widths z (state units) and rho(|A_cl,i|) per vertex.

    Raises
    ------
    DesignError
        If the LP's solution fails the elementwise re-check.

    Examples
    --------
    One state, A_cl = 0.9 - 0.4 = 0.5, |w| <= 0.1: the smallest box is z = w / (1 - 0.5):

    >>> D = np.ones(1)
    >>> box = box_tube(np.array([[[0.9]]]), np.array([[[1.0]]]), np.array([[-0.4]]), [0.1], D, D)
    >>> box.feasible, [round(float(z), 9) for z in box.z]
    (True, [0.2])
    """
    As, Bs = scale_vertices(np.asarray(A), np.asarray(B), Dx, Du)
    Fs = F * Dx[None, :] / Du[:, None]
    ws = np.asarray(w_max, float) / Dx
    absA = [np.abs(As[i] + Bs[i] @ Fs) for i in range(As.shape[0])]
    rho = np.array([max(abs(np.linalg.eigvals(a))) for a in absA])
    z = cp.Variable(ws.size)
    prob = cp.Problem(cp.Minimize(cp.sum(z)), [a @ z + ws <= z for a in absA] + [z >= 0])
    prob.solve(solver="HIGHS")
    if prob.status != "optimal":
        return BoxTubeResult(False, None, rho)
    zs = z.value
    if any(np.any(a @ zs + ws > zs * (1 + 1e-9) + 1e-12) for a in absA):
        raise DesignError("certificate failed: box tube LP solution is not invariant")
    return BoxTubeResult(True, zs * Dx, rho)
