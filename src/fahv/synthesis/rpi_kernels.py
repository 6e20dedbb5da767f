"""The compiled kernels of the exact RPI level (`fahv.synthesis.rpi_level`).

Module-level numba functions, cached on disk (`cache=True`): compiled once per
machine, loaded in every later process (a design's Dask workers included). Imported
only where a level is computed, so that the loop and the nodes never load numba.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def dual_bound(s, b, cc, steps):  # pragma: no cover - compiled
    """The dual bound of `fahv.synthesis.rpi_level.max_on_ball` per row.

    In the eigenbasis of M'M:
    s (n,) ascending eigenvalues, b (L, n) the rows' M'c in that basis, cc (L,) |c_l|^2,
    `steps` iterations at most; returns (L,) upper bounds of the maxima. The minimiser
    lam* > sigma_max^2 of the dual function is where psi(lam) = 1 / |x(lam)| - 1 = 0,
    x(lam) = (lam I - G)^-1 b; psi is nearly linear in lam, so Newton's method on it
    (Moré and Sorensen 1983) reaches lam* in a few steps. Each step is kept inside a
    bracket [lo, hi] of lam* (|x| > 1 at lo, <= 1 at hi) and bisects it where Newton
    would leave it; the iteration stops when the bracket or the step falls below the
    float spacing. The dual function is evaluated at the last hi and the last iterate
    (both above sigma_max^2, so both bound the maximum: weak duality) and the smaller
    is returned; its error is of second order in the distance to lam*.
    """
    n_rows, n = b.shape
    smax = s[n - 1]
    out = np.empty(n_rows)
    for r in range(n_rows):
        bb = 0.0
        for j in range(n):
            bb += b[r, j] * b[r, j]
        lo = smax
        hi = smax + np.sqrt(bb) + 1.0  # |x(hi)| <= |b| / (hi - smax) < 1
        lam = hi
        for _ in range(steps):
            norm2 = 0.0  # |x(lam)|^2, the secular function, and its slope
            slope = 0.0
            for j in range(n):
                d = lam - s[j]
                t = b[r, j] * b[r, j] / (d * d)
                norm2 += t
                slope -= 2.0 * t / d
            if norm2 > 1.0:
                lo = lam
            else:
                hi = lam
            nxt = 0.5 * (lo + hi)
            if norm2 > 0.0 and slope < 0.0:  # Newton on psi = |x|^-1 - 1
                nrm = np.sqrt(norm2)
                step = (1.0 / nrm - 1.0) / (-0.5 * slope / (norm2 * nrm))
                if abs(step) <= 1e-15 * lam:  # converged to the float spacing
                    break
                if lo < lam - step < hi:
                    nxt = lam - step
            if nxt <= lo or nxt >= hi or hi - lo <= 1e-15 * hi:
                break
            lam = nxt
        best = np.inf
        for at in (hi, lam):
            if at > smax:  # >= 0 gaps; 0 only along the top eigenvector, where b_j = 0
                total = cc[r] + at
                for j in range(n):
                    if b[r, j] != 0.0:
                        total += b[r, j] * b[r, j] / (at - s[j])
                best = min(best, total)
        out[r] = best
    return out


@numba.njit(cache=True, parallel=True, error_model="numpy")
def vertex_bounds(s, CM, C, cc, steps):  # pragma: no cover - compiled
    """Worst dual bound (R,) and its corner (R,) of every vertex.

    The loop of `fahv.synthesis.rpi_level.vertex_levels`, parallel over the vertices.
    """
    R = s.shape[0]
    lev = np.empty(R)
    corner = np.empty(R, np.int64)
    for i in numba.prange(R):
        li = dual_bound(s[i], C @ CM[i], cc, steps)
        k = np.argmax(li)
        corner[i] = k
        lev[i] = li[k]
    return lev, corner
