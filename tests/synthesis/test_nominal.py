"""Nominal gain K, LMI (33)-(35'), its certificate checks and the reference governor."""

import dataclasses

import numpy as np
import pytest

from fahv.control.reference import ReferenceGovernor
from fahv.errors import DesignError
from fahv.lanes import Lanes
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
    # the governor's nominal part with two inputs (the second one unused) on a toy
    # trim map x_r(h) = [h, 0] (bicubic spline of linear data: exact)
    hg, vg = np.linspace(0.0, 10.0, 5), np.linspace(0.0, 1.0, 4)
    trim_x = np.zeros((5, 4, 2))
    trim_x[:, :, 0] = hg[:, None]
    p = {
        "A": A, "B": np.concatenate([B, np.zeros_like(B)], axis=2),
        "h_grid": np.array([0.0, 10.0]), "V_grid": np.array([0.0, 1.0]),
        "W_h": np.array([[1.0, 0.0], [0.0, 1.0]]), "W_V": np.array([[1.0], [1.0]]),
        "K": np.vstack([nd.K, np.zeros((1, 2))]), "Q": nd.Q, "level_max": 0.999, "Ts": 0.1,
        "trim_h": hg, "trim_V": vg, "trim_x": trim_x, "trim_u": np.zeros((5, 4, 2)),
    }  # fmt: skip
    run = {"command.h0": 0.0, "command.V0": 0.0, "command.h_c": 5.0, "command.V_c": 0.0,
           "command.t_start": 0.0, "command.kind": "step", "command.t_ramp": 0.0,
           "x0": np.zeros(2)}  # fmt: skip
    nom = ReferenceGovernor(p, [run], Lanes(1))
    levels, u = [], []
    for k in range(3000):
        out = nom.step(k, k * 0.1, np.zeros((1, 9)), None)
        levels.append(out.level[0])
        u.append(out.u_n[0, 0])
    assert max(levels) <= 0.999 + 1e-12
    assert np.max(np.abs(u)) <= 0.5
    assert abs(out.h_g[0] - 5.0) < 1e-9
    assert np.linalg.norm(out.x_n) < 1e-3
