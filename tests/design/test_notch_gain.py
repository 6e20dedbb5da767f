"""A gain designed for the loop through the notch on q (fahv.tube.notch_gain)."""

import numpy as np
import pytest

from fahv.model.notch import NotchFilter
from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid, output_feedback_step
from fahv.synthesis.rpi_level import vertex_levels
from fahv.tube.notch_gain import notch_gain
from fahv.tube.notch_loop import notch_closed_loop, notch_loop_scale, notch_tube

TS = 0.02


def _lagging_loop():
    """A pitch-rate loop whose tube gain F is certified through a shallow notch only.

    Double integrator (x, q), two vertices (control effectiveness 1 and 0.8, the second
    with some damping); F = [-100, -30] and Z from its own Lyapunov shape: through the
    notch of eps_p 0.5 no ellipsoid of F's loop fits Z and the tightening.
    """
    from scipy.linalg import solve_discrete_lyapunov

    A1 = np.eye(2) + TS * np.array([[0.0, 1.0], [0.0, 0.0]])
    A = np.stack([A1, A1 + TS * np.array([[0.0, 0.0], [-2.0, -0.5]])])
    B = np.stack([TS * np.array([[0.0], [1.0]]), 0.8 * TS * np.array([[0.0], [1.0]])])
    F = np.array([[-100.0, -30.0]])
    N = 1e-4 * sum(solve_discrete_lyapunov(A[i] + B[i] @ F, np.eye(2)) for i in range(2))
    return A, B, F, N, np.array([1e-4, 2e-3])


def test_notch_gain_certifies_a_loop_the_tube_gain_does_not():
    """Through eps_p 0.5, F's loop has no certificate; the designed gain's has one, which an
    independent check confirms: the exact level at every vertex and corner of W (<= 1),
    20 000 boundary points mapped by every vertex and corner staying inside, the
    projection inside Z (s <= 1) and the input support within F Z's (the tightening)."""
    A, B, F, N, w = _lagging_loop()
    deep = NotchFilter(19.05, 0.02, 19.05, 0.5)
    assert not notch_tube(A, B, F, N, w, deep, TS, 1, 0.99, "v").certified
    lines = []
    got = notch_gain(A, B, F, N, w, deep, TS, 1, 0.99, (0.1, 0.2), variant="v", log=lines.append)
    assert got is not None and got.loop.certified and got.loop.designed
    assert "with the gain designed for the loop" in got.loop.line()
    # one step at eps_p 0.2 (gamma 0.967), four at 0.5 (1.156 ... 0.989)
    assert [e for e, _ in got.steps] == [0.2, 0.5, 0.5, 0.5, 0.5]
    gam = [g for e, g in got.steps if e == 0.5]
    assert all(b < a for a, b in zip(gam, gam[1:], strict=False)) and gam[-1] <= 1.0
    assert len(lines) == len(got.steps)
    Acl, K = notch_closed_loop(A, B, got.F, deep, TS, 1)
    w_xi = np.r_[w, 0.0, 0.0]
    assert vertex_levels(Acl, got.P, w_xi).max() == pytest.approx(got.loop.level, abs=1e-12)
    assert got.loop.level <= 1.0
    rng = np.random.default_rng(1)
    u = rng.standard_normal((20_000, 4))
    xi = (u / np.linalg.norm(u, axis=1, keepdims=True)) @ np.linalg.cholesky(got.P).T
    Pinv = np.linalg.inv(got.P)
    for i in range(2):
        for c in ([-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]):
            nxt = xi @ Acl[i].T + np.r_[np.asarray(c) * w, 0.0, 0.0]
            assert np.einsum("ij,jk,ik->i", nxt, Pinv, nxt).max() <= 1.0 + 1e-9
    proj = np.einsum("ij,jk,ik->i", xi[:, :2], np.linalg.inv(N), xi[:, :2])
    assert proj.max() <= 1.0
    tight = np.sqrt(F @ N @ F.T).ravel()
    assert np.abs(xi @ K.T).max() <= tight[0]
    np.testing.assert_allclose(got.loop.tightening, tight, rtol=1e-12)  # F Z's, not the new F's
    # the joint shape of (e, u - v) over the ellipsoid: e's block is P's, u's is K P K'
    C = got.joint(deep, TS, 1)
    np.testing.assert_allclose(C[:2, :2], got.P[:2, :2], rtol=1e-12)
    np.testing.assert_allclose(C[2, 2], (K @ got.P @ K.T)[0, 0], rtol=1e-12)


def test_output_feedback_step_starts_from_the_last_certificate():
    """The step's start (F0, P0) is feasible in its whitened coordinates: gamma is at most
    the start's own max(s, support / t), and the returned P is RPI at every vertex."""
    A, B, F, N, w = _lagging_loop()
    nf = NotchFilter(19.05, 0.02, 19.05, 0.2)
    Acl, K = notch_closed_loop(A, B, F, nf, TS, 1)
    w_xi = np.r_[w, 0.0, 0.0]
    tight = np.sqrt(F @ N @ F.T).ravel()
    ell = invariant_ellipsoid(Acl, w, notch_loop_scale(N, nf, TS, 1), N, K, 100 * tight,
                              lambda P: vertex_levels(Acl, P, w_xi), 0.99)  # fmt: skip
    start = max(ell.s, float(ell.supports[0] / tight[0]))
    A0, _ = notch_closed_loop(A, B, np.zeros_like(F), nf, TS, 1)
    B0 = np.concatenate([B, np.zeros((2, 2, 1))], axis=1)
    _, T = notch_closed_loop(A[:1], np.zeros((1, 2, 2)), np.eye(2), nf, TS, 1)

    def levels(Fk, Pk):
        return vertex_levels(notch_closed_loop(A, B, Fk, nf, TS, 1)[0], Pk, w_xi)

    got = output_feedback_step(A0, B0, T, w, F, ell.P, N, tight, levels, 0.99)
    assert got is not None
    assert got.gamma <= start * (1 + 1e-4)
    assert start > 1.0 > got.gamma  # measured: 1.09 -> 0.967
    assert levels(got.F, got.P).max() <= 1.0
    with pytest.raises(ValueError, match="output_feedback_step: shapes"):
        output_feedback_step(A0, B0, T, w, F, ell.P[:3, :3], N, tight, levels, 0.99)


def test_notch_gain_refuses_a_continuation_that_does_not_increase():
    A, B, F, N, w = _lagging_loop()
    deep = NotchFilter(19.05, 0.02, 19.05, 0.5)
    for bad in ((0.2, 0.1), (0.1, 0.5), (0.0,)):
        with pytest.raises(ValueError, match="continuation"):
            notch_gain(A, B, F, N, w, deep, TS, 1, 0.99, bad)
