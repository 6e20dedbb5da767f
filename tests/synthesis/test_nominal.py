"""Nominal gain K, LMI (33)-(35'), its certificate checks and the reference governor."""

import dataclasses

import numpy as np
import pytest

from fahv.control.reference import Command, NominalTrajectory
from fahv.errors import DesignError
from fahv.model.lpv import PolytopicLPV
from fahv.synthesis.nominal import contraction, design_nominal, verify_nominal

A = np.array([[[1.05, 0.1], [0.0, 0.98]], [[1.02, 0.12], [0.02, 0.95]]])
B = np.array([[[0.0], [0.1]], [[0.0], [0.12]]])
ONE2, ONE1 = np.ones(2), np.ones(1)
D = np.array([1.0, -0.5])


@pytest.fixture(scope="module")
def nd():
    return design_nominal(A, B, D, np.array([0.5]), ONE2, ONE1, lam=0.99)


def test_certificate_holds(nd):
    cert = verify_nominal(A, B, nd, ONE2, ONE1)
    assert cert["containment"] <= 1.0
    assert cert["contraction"] <= np.sqrt(0.99) + 1e-6
    assert cert["input_ratio"] <= 1.0
    assert cert["spectral_radius"] < 1.0
    assert 0.0 < nd.s <= 1.0
    np.testing.assert_allclose(nd.x0, nd.s * D)


def test_nominal_trajectory_respects_bounds(nd):
    """x+ = A_i x + B_i K x with random vertex switching from the boundary of E(Q):
    |u| <= u_max at every step and x' Q^-1 x decreases by lam at least."""
    rng = np.random.default_rng(0)
    L = np.linalg.cholesky(nd.Q)
    x = L @ np.array([0.6, 0.8])  # on the boundary of E(Q)
    for _ in range(300):
        u = nd.K @ x
        assert abs(u[0]) <= 0.5 * (1 + 1e-9)
        lvl = nd.level(x)
        i = rng.integers(2)
        x = A[i] @ x + B[i] @ u
        assert nd.level(x) <= 0.99 * lvl * (1 + 1e-7) + 1e-15
    assert np.linalg.norm(x) < 0.2


def test_tampered_gain_rejected(nd):
    with pytest.raises(DesignError, match="not invariant"):
        verify_nominal(A, B, dataclasses.replace(nd, K=np.zeros_like(nd.K)), ONE2, ONE1)
    with pytest.raises(DesignError, match=r"\(33\)"):
        verify_nominal(A, B, dataclasses.replace(nd, x0=nd.x0 * 3), ONE2, ONE1)
    with pytest.raises(DesignError, match=r"\(35\)"):
        verify_nominal(A, B, dataclasses.replace(nd, u_max=nd.u_max / 3), ONE2, ONE1)
    assert contraction(A, B, np.zeros_like(nd.K), nd.Q) > 1.0


def test_empty_nominal_input_set_rejected():
    with pytest.raises(DesignError, match="U minus F Z empty"):
        design_nominal(A, B, D, np.array([-0.1]), ONE2, ONE1)


def test_uncontrollable_unstable_vertex_rejected():
    """An unstable mode that the input cannot reach: no invariant ellipsoid exists."""
    A_bad = A.copy()
    A_bad[:, 0, 0] = 1.2
    A_bad[:, 0, 1] = 0.0
    with pytest.raises(DesignError, match="infeasible|unsolvable|certificate failed|no invariant"):
        design_nominal(A_bad, B, D, np.array([0.5]), ONE2, ONE1, lam=0.99)


def test_governor_keeps_nominal_state_in_ellipsoid(nd):
    """Reference governor on a toy trim map x_r(h) = [h, 0]: the command moves far
    beyond E(Q), the nominal state never leaves it and the reference reaches the
    command."""
    lpv = PolytopicLPV(
        A,
        B,
        np.array([0.0, 10.0]),
        np.array([0.0, 1.0]),
        np.array([[1.0, 0.0], [0.0, 1.0]]),
        np.array([[1.0], [1.0]]),
    )

    def trim_map(h, V):
        return np.array([h, 0.0]), np.zeros(1)

    cmd = Command(0.0, 0.0, 5.0, 0.0, 0.0, "step")
    nom = NominalTrajectory(lpv, trim_map, nd.K, nd.Q, cmd, 0.1, level_max=0.999)
    nom.reset(np.zeros(2))
    levels, u = [], []
    for _ in range(3000):
        out = nom.step()
        levels.append(out.level)
        u.append(out.u_n[0])
    assert max(levels) <= 0.999 + 1e-12
    assert np.max(np.abs(u)) <= 0.5
    assert abs(out.h_g - 5.0) < 1e-9
    assert np.linalg.norm(out.x_n) < 1e-3
