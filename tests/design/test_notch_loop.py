"""The tube loop with the notch filter on q (fahv.tube.notch_loop)."""

import numpy as np
import pytest

from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid
from fahv.synthesis.rpi_level import vertex_levels
from fahv.tube.notch_loop import notch_certificate, notch_closed_loop, notch_loop, notch_tube

NOTCH = NotchFilter(19.05, 0.02, 19.05, 0.5)
TS = 0.02


def _vertex(seed: int):
    """A stable pitch-like vertex (n = 3: alpha, q, eta) and a gain."""
    rng = np.random.default_rng(seed)
    A = np.eye(3) + TS * np.array([[-1.0, 1.0, 0.0], [-4.0, -0.5, 2.0], [0.0, 0.0, -3.0]])
    A = A + 1e-3 * rng.standard_normal((3, 3))
    B = TS * np.array([[0.0], [-6.0], [1.0]])
    F = np.array([[1.5, 0.8, 0.1]])
    return A, B, F


def test_the_loop_matrix_is_the_filter_running_in_the_loop():
    """[e; chi] propagated by the loop matrix equals e with DiscreteNotch's q' fed back."""
    A, B, F = _vertex(0)
    iq, steps = 1, 60
    loop = notch_loop(A[None], B[None], F, NOTCH, TS, iq)
    # rebuild the matrix the way the docstring states it
    dn = DiscreteNotch(NOTCH, TS)
    S = np.eye(3)
    S[iq, iq] = dn.C_q @ dn.B_d + dn.D_q
    Acl = np.block([
        [A + B @ F @ S, B @ F[:, [iq]] * dn.C_q[None, :]],
        [np.outer(dn.A_d @ dn.B_d + dn.B_d, np.eye(3)[iq]), dn.A_d],
    ])  # fmt: skip
    assert loop.rho == pytest.approx(np.abs(np.linalg.eigvals(Acl)).max(), abs=1e-12)
    # time domain: the filter object in the loop, from rest (chi(0) = 0)
    e = np.array([0.01, -0.02, 0.005])
    z = np.r_[e, 0.0, 0.0]
    filt = DiscreteNotch(NOTCH, TS)
    for _ in range(steps):
        qf = filt.step(e[iq : iq + 1])[0]
        ef = e.copy()
        ef[iq] = qf
        e = A @ e + B @ (F @ ef)
        z = Acl @ z
        np.testing.assert_allclose(z[:3], e, rtol=0, atol=1e-14)


def test_an_all_pass_notch_leaves_the_loop_as_certified():
    """eps_z = eps_p: the filter is 1, so the loop's radius is that on the measured q
    (or the filter's own, whichever is larger)."""
    A, B, F = _vertex(1)
    flat = NotchFilter(19.05, 0.5, 19.05, 0.5)
    loop = notch_loop(np.stack([A, 1.01 * A]), np.stack([B, B]), F, flat, TS, 1, "v")
    rho_filter = np.abs(np.linalg.eigvals(DiscreteNotch(flat, TS).A_d)).max()
    assert loop.rho == pytest.approx(max(loop.rho_q, rho_filter), abs=1e-9)
    assert loop.stable and "stable at every vertex" in loop.line()
    assert loop.summary()["certified"] is False


def test_a_lagging_notch_can_destabilise_a_stable_vertex():
    """A high-gain q loop stable on the measured q loses stability through the notch's lag
    (the measured case of the attitude-bounded tube set: 0.995 on q, 1.005 with eps_p 0.2)."""
    A = np.eye(2) + TS * np.array([[0.0, 1.0], [0.0, 0.0]])
    B = TS * np.array([[0.0], [1.0]])
    F = np.array([[-400.0, -60.0]])  # |eig(A + B F)| < 1, a fast q loop
    wide = NotchFilter(19.05, 0.02, 19.05, 2.0)
    loop = notch_loop(A[None], B[None], F, wide, TS, 1, "fast")
    assert loop.rho_q < 1.0
    assert loop.rho > 1.0 and not loop.stable
    assert "UNSTABLE at vertex 0" in loop.line()


def test_shapes_are_checked():
    A, B, F = _vertex(2)
    with pytest.raises(ValueError, match="shapes"):
        notch_loop(A[None], B[None], F[:, :2], NOTCH, TS, 1)
    with pytest.raises(ValueError, match="iq 3"):
        notch_loop(A[None], B[None], F, NOTCH, TS, 3)


# -- the loop with the filter certified in its own states (notch_tube) -------------------
def _two_vertices():
    A0, B0, F = _vertex(3)
    A1, B1, _ = _vertex(4)
    return np.stack([A0, A1]), np.stack([B0, 0.9 * B1]), F


def _lyapunov_shape(A, B, F, scale):
    """A common quadratic shape of the loops on the measured q (the notch-free tube)."""
    from scipy.linalg import solve_discrete_lyapunov

    P = sum(solve_discrete_lyapunov(A[i] + B[i] @ F, np.eye(3)) for i in range(len(A)))
    return scale * P


def test_invariant_ellipsoid_of_the_notch_loop_holds_by_brute_force():
    """The ellipsoid found for the loop with the filter's states is invariant: points of its
    boundary, mapped by every vertex with every corner of W, stay inside (exact level and
    20 000 sampled points); its projection and input support are what it reports."""
    A, B, F = _two_vertices()
    w = np.array([1e-4, 2e-4, 1e-4])
    N = _lyapunov_shape(A, B, F, 4e-4)
    Acl, K = notch_closed_loop(A, B, F, NOTCH, TS, 1)
    w_xi = np.r_[w, 0.0, 0.0]
    signs = np.array(np.meshgrid(*[[-1.0, 1.0]] * 3)).reshape(3, -1).T

    t = np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
    D = np.r_[np.sqrt(np.diag(N)), 1e-3, 1e-3]
    ell = invariant_ellipsoid(Acl, w, D, N, K, 10 * t, lambda P: vertex_levels(Acl, P, w_xi), 0.99,
                              active=1)  # fmt: skip
    assert ell.found
    assert vertex_levels(Acl, ell.P, w_xi).max() <= 1.0
    rng = np.random.default_rng(0)
    L = np.linalg.cholesky(ell.P)
    u = rng.standard_normal((20_000, 5))
    xi = (u / np.linalg.norm(u, axis=1, keepdims=True)) @ L.T  # the boundary of E
    Pinv = np.linalg.inv(ell.P)
    for i in range(len(Acl)):
        for c in signs:
            nxt = xi @ Acl[i].T + np.r_[c * w, 0.0, 0.0]
            assert np.einsum("ij,jk,ik->i", nxt, Pinv, nxt).max() <= 1.0 + 1e-9
    proj = np.einsum("ij,jk,ik->i", xi[:, :3], np.linalg.inv(N), xi[:, :3])
    assert proj.max() <= ell.s**2 * (1 + 1e-9)
    assert proj.max() >= 0.99 * ell.s**2  # the bound is attained (within sampling)
    np.testing.assert_allclose(np.abs(xi @ K.T).max(axis=0), ell.supports, rtol=2e-2)


def test_notch_tube_certifies_only_inside_z_and_the_tightening():
    """A generous Z: certified (level <= 1, s <= 1, supports within F Z's); a Z too small
    for the W: the smallest invariant ellipsoid does not fit, NOT certified."""
    A, B, F = _two_vertices()
    w = np.array([1e-4, 2e-4, 1e-4])
    big = notch_tube(A, B, F, _lyapunov_shape(A, B, F, 4e-4), w, NOTCH, TS, 1, 0.99, "v")
    assert big.certified and big.level <= 1.0 and big.s <= 1.0
    assert all(a <= b * (1 + 1e-9) for a, b in zip(big.supports, big.tightening, strict=True))
    assert "certified with the notch  OK" in big.line()
    assert big.summary()["certified"] is True
    small = notch_tube(A, B, F, _lyapunov_shape(A, B, F, 1e-9), w, NOTCH, TS, 1, 0.99, "v")
    assert not small.certified
    assert "NOT certified with the notch" in small.line()


def test_notch_certificate_rechecks_a_given_ellipsoid():
    """The exact re-check of a given P: a P grown by 10 % stays certified (E RPI implies
    c E RPI for c >= 1 in a linear loop) with s and supports 10 % larger; a wrong shape
    is refused."""
    A, B, F = _two_vertices()
    w = np.array([1e-4, 2e-4, 1e-4])
    N = _lyapunov_shape(A, B, F, 4e-4)
    Acl, K = notch_closed_loop(A, B, F, NOTCH, TS, 1)
    t = np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
    ell = invariant_ellipsoid(Acl, w, np.r_[np.sqrt(np.diag(N)), 1e-3, 1e-3], N, K, t,
                              lambda P: vertex_levels(Acl, P, np.r_[w, 0, 0]), 0.99)  # fmt: skip
    same = notch_certificate(A, B, F, N, w, NOTCH, TS, 1, ell.P, "v")
    grown = notch_certificate(A, B, F, N, w, NOTCH, TS, 1, 1.21 * ell.P, "v")
    assert same.s == pytest.approx(ell.s, rel=1e-9) and same.level <= 1.0
    assert grown.level <= same.level + 1e-12
    assert grown.s == pytest.approx(1.1 * same.s, rel=1e-9)
    np.testing.assert_allclose(grown.supports, 1.1 * np.asarray(same.supports), rtol=1e-9)
    with pytest.raises(ValueError, match="P has shape"):
        notch_certificate(A, B, F, N, w, NOTCH, TS, 1, np.eye(3))
