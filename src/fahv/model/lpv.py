"""Discrete polytopic LPV model, eq. (12): vertex systems and TP weights, evaluated online."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from fahv.model.lpv_kernel import weights_kernel


@dataclass(frozen=True)
class PolytopicLPV:
    """Discrete polytopic LPV model, eq. (12), with its TP weighting functions.

    Attributes
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Discrete vertices A_i, B_i (unscaled, deviation coordinates).
    h_grid, V_grid : ndarray
    W_h, W_V : ndarray
        Sampled weighting functions (see `fahv.model.tp_model.tp_weights`).

    Examples
    --------
    Two vertices along h, one along V:

    >>> lpv = PolytopicLPV(
    ...     A=np.array([[[1.0]], [[3.0]]]), B=np.array([[[0.0]], [[2.0]]]),
    ...     h_grid=np.array([85000.0, 86500.0]), V_grid=np.array([7700.0, 8300.0]),
    ...     W_h=np.eye(2), W_V=np.ones((2, 1)))
    >>> A, B = lpv.system(85375.0, 8000.0)  # a quarter of the way up in h
    >>> float(A[0, 0]), float(B[0, 0])
    (1.5, 0.5)
    """

    A: np.ndarray
    B: np.ndarray
    h_grid: np.ndarray
    V_grid: np.ndarray
    W_h: np.ndarray
    W_V: np.ndarray

    def __post_init__(self) -> None:
        R, n, _ = self.A.shape
        if self.A.shape != (R, n, n) or self.B.shape[:2] != (R, n):
            raise ValueError(f"LPV vertex shapes do not match: A {self.A.shape}, B {self.B.shape}")
        if self.W_h.shape[1] * self.W_V.shape[1] != R:
            raise ValueError(
                f"LPV weighting functions give {self.W_h.shape[1]} x {self.W_V.shape[1]} "
                f"vertices, but there are {R} vertex systems"
            )
        weights_kernel()  # compiled (or loaded) now, at start-up, not in a run's step

    def systems(self, h, V) -> tuple[np.ndarray, np.ndarray]:
        """(A(p) (B, n, n), B(p) (B, n, m)) = sum_i tau_i(p) [A_i, B_i] at B points p.

        Parameters
        ----------
        h, V : (B,) array_like
            Scheduling variables [ft, ft/s], clipped to the weight grids.

        Returns
        -------
        A : (B, n, n) ndarray
        B : (B, n, m) ndarray
            The scheduled discrete matrices at each point.

        Notes
        -----
        The weights are those of `fahv.model.tp_model.tp_weights` (eq. 11); each
        point's sum is one (1, R) @ (R, n n) product, so a point's matrices do not
        depend on the other points.
        """
        R, n, _ = self.A.shape
        m = self.B.shape[2]
        w = self.weights(h, V)
        A = np.matmul(w[:, None, :], self.A.reshape(R, -1))[:, 0, :].reshape(len(w), n, n)
        B = np.matmul(w[:, None, :], self.B.reshape(R, -1))[:, 0, :].reshape(len(w), n, m)
        return A, B

    def weights(self, h, V) -> np.ndarray:
        """TP weights tau_i(p) (B, R) of B points p = (h, V), eq. (11); each row sums to one.

        Parameters
        ----------
        h, V : (B,) array_like
            Scheduling variables [ft, ft/s], clipped to the weight grids.

        Returns
        -------
        (B, R) ndarray
            The weights of the R vertices, in the order of `A` and `B` (compiled:
            `fahv.model.lpv_kernel`, numpy's `np.interp` bit for bit).

        Raises
        ------
        ValueError
            If h and V are not two 1-d arrays of the same length.
        """
        h = np.ascontiguousarray(np.atleast_1d(np.asarray(h, dtype=float)))
        V = np.ascontiguousarray(np.atleast_1d(np.asarray(V, dtype=float)))
        if h.shape != V.shape or h.ndim != 1:
            raise ValueError(f"LPV weights: h {h.shape} and V {V.shape} must be (B,) alike")
        h_grid, W_h, V_grid, W_V = self._weight_tables
        out = np.empty((h.size, self.A.shape[0]))
        return weights_kernel()(h, V, h_grid, W_h, V_grid, W_V, out)

    @functools.cached_property
    def _weight_tables(self) -> tuple[np.ndarray, ...]:
        """(h_grid, W_h's columns as rows, V_grid, W_V's columns as rows), contiguous float64."""
        def rows(W):
            return np.ascontiguousarray(np.asarray(W, dtype=float).T)

        def grid(g):
            return np.ascontiguousarray(g, dtype=float)

        return grid(self.h_grid), rows(self.W_h), grid(self.V_grid), rows(self.W_V)

    def system(self, h: float, V: float) -> tuple[np.ndarray, np.ndarray]:
        """(A(p) (n, n), B(p) (n, m)) at one point p = (h, V): `systems` of one point.

        Parameters
        ----------
        h : float
            Altitude [ft], clipped to the weight grid.
        V : float
            Speed [ft/s], clipped to the weight grid.

        Returns
        -------
        A : (n, n) ndarray
        B : (n, m) ndarray
            The scheduled discrete matrices.
        """
        A, B = self.systems([h], [V])
        return A[0], B[0]
