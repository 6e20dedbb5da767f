"""Discrete polytopic LPV model, eq. (12): vertex systems and TP weights, evaluated online."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.model.tp_model import tp_weights


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
        Sampled weighting functions (see :func:`fahv.model.tp_model.tp_weights`).
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

    def system(self, h: float, V: float) -> tuple[np.ndarray, np.ndarray]:
        """(A(p) (n, n), B(p) (n, m)) = sum_i tau_i(p) [A_i, B_i] at p = (h, V)."""
        w = tp_weights(h, V, self.h_grid, self.V_grid, self.W_h, self.W_V)
        return np.tensordot(w, self.A, axes=1), np.tensordot(w, self.B, axes=1)
