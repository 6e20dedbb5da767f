"""Helpers shared by the LMI designs: scaling and numerical certificate checks."""

from __future__ import annotations

import numpy as np

from fahv.errors import DesignError

#: Solver used for every LMI (interior point, handles SDP cones); see docs/environment.md.
SDP_SOLVER = "CLARABEL"


def scale_vertices(A: np.ndarray, B: np.ndarray, Dx: np.ndarray, Du: np.ndarray):
    """Scaled vertices A_s = D_x^-1 A D_x (R, n, n), B_s = D_x^-1 B D_u (R, n, m)."""
    return A * Dx[None, None, :] / Dx[None, :, None], B * Du[None, None, :] / Dx[None, :, None]


def min_eig(M: np.ndarray) -> float:
    """Smallest eigenvalue of the symmetric part of M."""
    return float(np.linalg.eigvalsh(0.5 * (M + M.T)).min())


def psd_tolerance(M: np.ndarray, rtol: float = 1e-9) -> float:
    """Tolerance of :func:`require_psd`: rtol max(1, max |M_ij|) (>= 0)."""
    return float(rtol * max(1.0, float(np.abs(M).max())))


def require_psd(M: np.ndarray, what: str, rtol: float = 1e-9) -> float:
    """Check M >= -rtol ||M|| I; return the smallest eigenvalue.

    ``||M||`` is max(1, max |M_ij|) (:func:`psd_tolerance`): an eigenvalue that is
    negative by less than that tolerance is rounding of the solver and accepted.

    Raises
    ------
    DesignError
        Naming ``what``, the eigenvalue found and the tolerance, if the check fails.
    """
    e = min_eig(M)
    tol = psd_tolerance(M, rtol)
    if not np.isfinite(e) or e < -tol:
        raise DesignError(
            f"certificate failed: {what} has eigenvalue {e:.3e} < -{tol:.2e} (tolerance)"
        )
    return e
