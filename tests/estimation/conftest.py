"""Checks shared by the estimation bounds' tests: the exact re-check of a covariance bound
at every vertex pair, and the sample variance of its system under random switching."""

import numpy as np
import pytest
import scipy.linalg


def pair_min_eig(es, S: np.ndarray, R_v: np.ndarray) -> float:
    """min over every pair (i, j) of the smallest eigenvalue of S - M_ij S M_ij' - N_j R_v N_j'
    (scipy's eigvalsh, unscaled)."""
    R = es.n_vertices
    return min(
        scipy.linalg.eigvalsh(S - es.M[i, j] @ S @ es.M[i, j].T - es.N[j] @ R_v @ es.N[j].T)[0]
        for i in range(R) for j in range(R)
    )  # fmt: skip


def switched_variance(es, S: np.ndarray, R_v: np.ndarray, runs: int, steps: int,
                      seed: int) -> np.ndarray:  # fmt: skip
    """Sample variance of every state after `steps` steps of `runs` runs of the linear
    system, each from the bound's own covariance, a random pair (i, j) per run and step,
    Gaussian noise of covariance R_v (diagonal)."""
    rng = np.random.default_rng(seed)
    R, n = es.n_vertices, S.shape[0]
    v_std = np.sqrt(np.diag(R_v))
    e = rng.normal(size=(runs, n)) @ np.linalg.cholesky(S).T
    for _ in range(steps):
        i, j = rng.integers(0, R, runs), rng.integers(0, R, runs)
        v = rng.normal(size=(runs, len(v_std))) * v_std
        e = np.einsum("bij,bj->bi", es.M[i, j], e) + np.einsum("bij,bj->bi", es.N[j], v)
    return e.var(axis=0)


@pytest.fixture
def bound_checks():
    """The two checks: (pair_min_eig, switched_variance)."""
    return pair_min_eig, switched_variance
