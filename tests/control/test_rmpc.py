"""The off-line RMPC baseline (Wan & Kothare 2003 on Kothare's LMIs 32-35): its designed
sequence is re-certified independently, tampered sequences are rejected, and the online
law interpolates in closed form (the ellipsoid boundaries give the stored gains)."""

from types import SimpleNamespace

import numpy as np
import pytest

from fahv.control.rmpc import OfflineRMPC, RMPCLaw
from fahv.errors import DesignError
from fahv.lanes import Lanes
from fahv.loop.params import node_parameters, validate
from fahv.synthesis.lmi import scale_vertices
from fahv.synthesis.offline_rmpc import EllipsoidSequence, design_sequence, verify_sequence


def _seq(a) -> EllipsoidSequence:
    return EllipsoidSequence(
        a["rmpc_Q"], a["rmpc_P"], a["rmpc_K"], a["rmpc_gamma"], a["rmpc_z"], a["rmpc_Ds"],
        a["u_room"],
    )  # fmt: skip


@pytest.fixture(scope="module")
def design(paper_scenario_design):
    """The shipped design of Case 1 with the RMPC baseline (cm_paper)."""
    return paper_scenario_design


@pytest.fixture(scope="module")
def seq(design):
    return _seq(design.arrays)


def test_the_sequence_is_certified_independently(design, seq):
    a = design.arrays
    psi, sigma = np.asarray(design.case["rmpc"]["psi"]), np.full(2, design.case["rmpc"]["sigma"])
    cert = verify_sequence(a["rmpc_A"], a["rmpc_B"], seq, psi, sigma)
    N = design.case["rmpc"]["ellipsoids"]
    assert seq.Q.shape == (N, 9, 9) and cert["contraction"].size == N
    assert np.all(cert["contraction"] < 1.0) and np.all(cert["input_ratio"] <= 1.0)
    assert np.all(cert["nesting"] < 1.0) and np.all(cert["interp_contraction"] < 1.0)
    # by hand: E_1 contracted at every vertex, inputs within the room on E_1
    As, Bs = scale_vertices(a["rmpc_A"], a["rmpc_B"], seq.Ds, seq.u_max)
    L = np.linalg.cholesky(seq.Q[0])
    norms = [np.linalg.norm(np.linalg.solve(L, (As[r] + Bs[r] @ seq.K[0]) @ L), 2)
             for r in range(As.shape[0])]  # fmt: skip
    assert max(norms) < 1.0
    assert np.all(np.sqrt(np.einsum("ij,jk,ik->i", seq.K[0], seq.Q[0], seq.K[0])) <= 1.0)
    # the Case 1 step lies inside E_1 with the design margin, and levels grow inward
    z = a["rmpc_d"] / seq.Ds
    lv = np.einsum("i,nij,j->n", z, seq.P, z)
    assert lv[0] <= 1.0 / design.case["rmpc"]["margin"] ** 2 * (1 + 1e-3)
    assert np.all(np.diff(lv) > 0.0)


@pytest.mark.parametrize(
    "tamper, match",
    [
        (lambda s: s.K.__setitem__(0, 3.0 * s.K[0]), "ellipsoid 1"),
        (lambda s: s.Q.__setitem__(slice(None), s.Q[::-1].copy()), "not inside|ellipsoid"),
        (lambda s: s.Q.__setitem__(0, 1.5 * s.Q[0]), "ellipsoid 1"),
    ],
)
def test_tampered_sequences_are_rejected(design, seq, tamper, match):
    a = design.arrays
    bad = EllipsoidSequence(*(np.array(getattr(seq, f), copy=True) for f in
                              ("Q", "P", "K", "gamma", "z", "Ds", "u_max")))  # fmt: skip
    tamper(bad)
    bad = EllipsoidSequence(bad.Q, np.linalg.inv(bad.Q), bad.K, bad.gamma, bad.z, bad.Ds,
                            bad.u_max)  # fmt: skip
    with pytest.raises(DesignError, match=match):
        verify_sequence(a["rmpc_A"], a["rmpc_B"], bad, np.ones(9), np.ones(2))


def test_the_law_interpolates_between_the_stored_gains(seq):
    law = OfflineRMPC(seq.P, seq.K, seq.Ds, seq.u_max)
    rng = np.random.default_rng(3)
    w = rng.normal(size=9)
    N = seq.P.shape[0]
    for i in range(N):  # on the boundary of E_i the gain is K_i
        z = w / np.sqrt(w @ seq.P[i] @ w)
        du, c, a = law.control((z * seq.Ds)[None])
        assert c[0] in (i + 1, i) and a[0] == pytest.approx(1.0 if c[0] == i + 1 else 0.0, abs=1e-9)
        np.testing.assert_allclose(du[0], seq.u_max * (seq.K[i] @ z), rtol=1e-9, atol=1e-12)
    # between E_2 and E_3: z' (a P_2 + (1 - a) P_3) z = 1 and the gain is the mixture
    z = 0.5 * (w / np.sqrt(w @ seq.P[1] @ w) + w / np.sqrt(w @ seq.P[2] @ w))
    du, c, a = law.control((z * seq.Ds)[None])
    assert c[0] == 2 and 0.0 < a[0] < 1.0
    assert z @ (a[0] * seq.P[1] + (1 - a[0]) * seq.P[2]) @ z == pytest.approx(1.0, rel=1e-12)
    Ka = a[0] * seq.K[1] + (1 - a[0]) * seq.K[2]
    np.testing.assert_allclose(du[0], seq.u_max * (Ka @ z), rtol=1e-12, atol=1e-15)
    # outside E_1: K_1 (counted by the law); inside E_N: K_N
    big, small = 2.0 * w / np.sqrt(w @ seq.P[0] @ w), 0.5 * w / np.sqrt(w @ seq.P[-1] @ w)
    du, c, _ = law.control(np.stack([big, small]) * seq.Ds)
    assert c.tolist() == [0, N]
    np.testing.assert_allclose(du[0], seq.u_max * (seq.K[0] @ big), rtol=1e-12)
    np.testing.assert_allclose(du[1], seq.u_max * (seq.K[-1] @ small), rtol=1e-12)


def test_the_law_counts_steps_outside_the_largest_ellipsoid(design, seq):
    p = validate("rmpc", node_parameters(design, "rmpc")["rmpc"])
    law = RMPCLaw(p, 2)
    w = np.ones(9)
    big = 3.0 * w / np.sqrt(w @ seq.P[0] @ w) * seq.Ds
    x_r = np.zeros((2, 9))
    ref = SimpleNamespace(x_r=x_r, u_r=np.full((2, 2), 0.1))
    lanes = Lanes(2, strict=False)
    for k in range(3):
        out = law.step(k, np.stack([big, 0.0 * big]), ref, lanes)
    assert out.lmi_failed.tolist() == [3, 0] and np.all(np.isnan(out.level))
    np.testing.assert_array_equal(out.u[1], ref.u_r[1])  # at the trim: the trim input


def test_design_sequence_on_a_small_polytope():
    """Two-vertex double integrator: certified, nested; bad fractions and too large a
    state (no invariant ellipsoid within the input bound) are refused."""
    Ts = 0.1
    A = np.stack([np.array([[1.0, Ts], [0.0, 1.0]]), np.array([[1.0, Ts], [0.0, 1.02]])])
    B = np.stack([np.array([[0.0], [Ts]]), np.array([[0.0], [1.2 * Ts]])])
    d, u_max, Ds = np.array([1.0, 0.0]), np.array([1.0]), np.ones(2)
    seq, cert = design_sequence(A, B, d, u_max, np.ones(2), np.ones(1), Ds, [1.0, 0.5, 0.25])
    assert np.all(cert["contraction"] < 1) and np.all(cert["nesting"] < 1)
    assert np.all(np.diff(seq.gamma) < 0)  # smaller states cost less
    with pytest.raises(DesignError, match="strictly decreasing"):
        design_sequence(A, B, d, u_max, np.ones(2), np.ones(1), Ds, [1.0, 1.0])
    with pytest.raises(DesignError, match="ellipsoid 1"):
        design_sequence(A, B, np.array([1e4, 0.0]), np.array([1e-3]), np.ones(2),
                        np.ones(1), Ds, [1.0])  # fmt: skip
