"""Nominal gain K, LMI (32)-(35), and its certificate checks."""

import dataclasses

import numpy as np
import pytest

from fahv.errors import DesignError
from fahv.tube.nominal import design_nominal, verify_nominal

A = np.array([[[1.05, 0.1], [0.0, 0.98]], [[1.02, 0.12], [0.02, 0.95]]])
B = np.array([[[0.0], [0.1]], [[0.0], [0.12]]])
ONE2, ONE1 = np.ones(2), np.ones(1)
PSI, SIGMA = np.ones(2), np.ones(1)


@pytest.fixture(scope="module")
def nd():
    return design_nominal(A, B, np.array([1.0, -0.5]), np.array([2.0]), PSI, SIGMA, ONE2, ONE1)


def test_certificate_holds(nd):
    cert = verify_nominal(A, B, nd, PSI, SIGMA, ONE2, ONE1)
    assert cert["containment"] <= 1.0
    assert cert["lmi34_min_eig"] > 0.0
    assert cert["input_ratio"] <= 1.0
    assert cert["spectral_radius"] < 1.0


def test_nominal_trajectory_respects_bounds_and_cost(nd):
    """Simulate x+ = A_i x + B_i K x with random vertex switching: |u| <= u_max and the
    realised cost stays below gamma_n * x0' Q^-1 x0 (Kothare's bound)."""
    rng = np.random.default_rng(0)
    x = nd.x0.copy()
    cost = 0.0
    for _ in range(400):
        u = nd.K @ x
        assert abs(u[0]) <= 2.0 + 1e-9
        cost += x @ x + u @ u
        i = rng.integers(2)
        x = A[i] @ x + B[i] @ u
    assert np.linalg.norm(x) < 1e-3
    assert cost <= nd.gamma * (nd.x0 @ np.linalg.solve(nd.Q, nd.x0)) * (1 + 1e-6)


def test_tampered_gain_rejected(nd):
    with pytest.raises(DesignError, match="certificate failed"):
        verify_nominal(A, B, dataclasses.replace(nd, K=np.zeros_like(nd.K)), PSI, SIGMA, ONE2, ONE1)
    with pytest.raises(DesignError, match=r"\(33\)"):
        verify_nominal(A, B, dataclasses.replace(nd, x0=nd.x0 * 3), PSI, SIGMA, ONE2, ONE1)
    with pytest.raises(DesignError, match=r"\(35\)"):
        verify_nominal(A, B, dataclasses.replace(nd, u_max=nd.u_max / 3), PSI, SIGMA, ONE2, ONE1)


def test_empty_nominal_input_set_rejected():
    with pytest.raises(DesignError, match="U minus F Z empty"):
        design_nominal(A, B, np.ones(2), np.array([-0.1]), PSI, SIGMA, ONE2, ONE1)


def test_infeasible_initial_state_rejected():
    with pytest.raises(DesignError, match="infeasible|certificate failed"):
        design_nominal(A, B, np.array([1e4, 0.0]), np.array([0.01]), PSI, SIGMA, ONE2, ONE1)
