"""Compiled TP weights of a batch of scheduling points (numba), eq. (11).

The loop evaluates the LPV model's weights twice a step per run (the Kalman filter's
gains and its error's standard deviation); in numpy that is one `np.interp` per
weighting function and axis, an outer product and a reshape, a dozen calls whose
per-call cost outweighs their arithmetic. Here one compiled loop does it for every
point. numba's `np.interp` is numpy's algorithm (the same slope and the same clipping at
the grid's ends, NaN for a NaN point) and the product is one multiplication, so the
weights are numpy's bit for bit (tests/model/test_lpv_kernel.py compares them on points
inside, outside and on the grid). Compiled once per machine (`cache=True`).
"""

from __future__ import annotations

import functools

import numpy as np


@functools.cache
def weights_kernel():
    """`tp_weights_into` compiled by numba (cached on disk), built at its first use.

    Compiled eagerly for its one signature (C-contiguous float64 arrays), so that the
    model that first asks for it (`fahv.model.lpv.PolytopicLPV`, at its construction: a
    node's start-up) pays the compile or the cache load, not a run's first step. A process
    that never builds an LPV model does not import numba.

    Returns
    -------
    numba dispatcher
        `tp_weights_into`, compiled.
    """
    import numba

    vec, mat = numba.float64[::1], numba.float64[:, ::1]
    return numba.njit(mat(vec, vec, vec, mat, vec, mat, mat), cache=True)(tp_weights_into)


def tp_weights_into(h, V, h_grid, W_h_columns, V_grid, W_V_columns, out):  # pragma: no cover
    """TP weights of B points into out (B, r_h r_V): out[b, a r_V + c] = w_h,a(h_b) w_V,c(V_b).

    Parameters
    ----------
    h, V : (B,) float64 ndarrays
        Scheduling points [ft, ft/s], clipped to the grids as `np.interp` clips.
    h_grid : (n_h,) ndarray
    W_h_columns : (r_h, n_h) C-contiguous ndarray
        The weighting functions of h sampled on `h_grid`, one row per function.
    V_grid : (n_V,) ndarray
    W_V_columns : (r_V, n_V) C-contiguous ndarray
    out : (B, r_h r_V) ndarray
        Written in place.

    Returns
    -------
    (B, r_h r_V) ndarray
        `out`, each row summing to one where the sampled weighting functions do.
    """
    r_V = W_V_columns.shape[0]
    w_V = np.empty(r_V)
    for b in range(h.size):
        for c in range(r_V):
            w_V[c] = np.interp(V[b], V_grid, W_V_columns[c])
        for a in range(W_h_columns.shape[0]):
            w_a = np.interp(h[b], h_grid, W_h_columns[a])
            for c in range(r_V):
                out[b, a * r_V + c] = w_a * w_V[c]
    return out
