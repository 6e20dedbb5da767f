"""The compiled kernels of the exact RPI level (`fahv.synthesis.rpi_level`).

Module-level numba functions, cached on disk (`cache=True`): compiled once per
machine, loaded in every later process (a design's Dask workers included). Imported
only where a level is computed, so that the loop and the nodes never load numba.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def dual_at(s, b, cc, r, lam):  # pragma: no cover - compiled
    """The dual function of row r at lam > s[-1]: an upper bound of its maximum.

    cc[r] + lam + sum_j b[r, j]^2 / (lam - s[j]) (weak duality, `dual_bound`).
    """
    total = cc[r] + lam
    for j in range(s.shape[0]):
        if b[r, j] != 0.0:
            total += b[r, j] * b[r, j] / (lam - s[j])
    return total


@numba.njit(cache=True, error_model="numpy")
def row_bound(s, b, cc, r, steps):  # pragma: no cover - compiled
    """The dual bound of row r of `dual_bound` and the lam it was evaluated at."""
    n = s.shape[0]
    smax = s[n - 1]
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
    where = hi
    for at in (hi, lam):
        if at > smax:  # >= 0 gaps; 0 only along the top eigenvector, where b_j = 0
            total = dual_at(s, b, cc, r, at)
            if total < best:
                best = total
                where = at
    return best, where


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
    n_rows = b.shape[0]
    out = np.empty(n_rows)
    for r in range(n_rows):
        out[r] = row_bound(s, b, cc, r, steps)[0]
    return out


@numba.njit(cache=True, error_model="numpy")
def worst_bound(s, b, cc, steps):  # pragma: no cover - compiled
    """The largest `dual_bound` over the rows, and its row, pruned by weak duality.

    The row largest at one lam is bounded first (`row_bound`); every other row is first
    bounded at that row's lam (`dual_at`: any lam above s[-1] bounds every row), and
    only a row whose bound there exceeds the largest so far is bounded in full. A row
    passed over has a bound no larger than the returned one, so the result bounds every
    row's maximum, as `dual_bound`'s largest does (the same value up to rounding).
    """
    n_rows = b.shape[0]
    ref = s[s.shape[0] - 1] + 1.0
    first = 0
    top = -np.inf
    for r in range(n_rows):
        v = dual_at(s, b, cc, r, ref)
        if v > top:
            top = v
            first = r
    best, lam = row_bound(s, b, cc, first, steps)  # inf: so is the maximum, all rows pass
    where = first
    for r in range(n_rows):
        if r == first or dual_at(s, b, cc, r, lam) <= best:
            continue
        v = row_bound(s, b, cc, r, steps)[0]
        if v > best:
            best = v
            where = r
    return best, where


@numba.njit(cache=True, parallel=True, error_model="numpy")
def vertex_bounds(s, CM, C, cc, steps):  # pragma: no cover - compiled
    """Worst dual bound (R,) and its corner (R,) of every vertex.

    The loop of `fahv.synthesis.rpi_level.vertex_levels`, parallel over the vertices,
    each vertex's worst corner by `worst_bound`.
    """
    R = s.shape[0]
    lev = np.empty(R)
    corner = np.empty(R, np.int64)
    for i in numba.prange(R):
        lev[i], corner[i] = worst_bound(s[i], C @ CM[i], cc, steps)
    return lev, corner
