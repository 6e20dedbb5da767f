"""The exact RPI level (fahv.synthesis.rpi_level) against brute force and closed forms."""

import itertools

import numpy as np
import pytest

from fahv.synthesis.rpi_level import max_on_ball, rpi_margin, worst_level


def test_worst_level_is_exact_on_a_small_system():
    """The trust-region maximum equals a dense brute force (from below, to 1e-3)."""
    rng = np.random.default_rng(3)
    n, m, R = 3, 1, 2
    A = rng.normal(0, 0.4, (R, n, n))
    B = rng.normal(0, 1, (R, n, m))
    F = rng.normal(0, 0.2, (m, n))
    G = rng.normal(0, 1, (n, n))
    N = G @ G.T + np.eye(n)
    w = np.array([0.1, 0.3, 0.2])
    level, _ = worst_level(A, B, F, N, w)
    L = np.linalg.cholesky(N)
    u = rng.normal(size=(200_000, n))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    E = u @ L.T  # boundary of Z
    brute = 0.0
    Ninv = np.linalg.inv(N)
    for i, s in itertools.product(range(R), itertools.product((-1, 1), repeat=n)):
        Y = E @ (A[i] + B[i] @ F).T + np.array(s) * w
        brute = max(brute, np.max(np.einsum("ki,ij,kj->k", Y, Ninv, Y)))
    assert brute <= level * (1 + 1e-12)
    assert level <= brute * (1 + 1e-3)


def test_max_on_ball_bounds_the_nearly_hard_case_tightly():
    """The trust-region maximum when M'c is almost orthogonal to the top eigenvector (the
    case where a primal point filled up along that eigenvector overstates by 4e-3): an
    upper bound of the brute-force maximum over 2 000 001 points of the circle, within
    1e-9 of it."""
    M = np.diag([0.9974, 0.9961])
    c = np.array([[2.5e-11, 0.0139], [0.0, 0.0139], [0.3, 0.2]])
    t = np.linspace(0.0, 2.0 * np.pi, 2_000_001)
    U = np.stack([np.cos(t), np.sin(t)], axis=1)
    brute = np.array([np.max(np.sum((U @ M.T + cl) ** 2, axis=1)) for cl in c])
    got = max_on_ball(M, c)
    assert np.all(got >= brute - 1e-12), (got, brute)
    np.testing.assert_allclose(got, brute, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "a, w, factor",
    [(0.5, 0.25, 2.0), (0.9, 1.0, 0.1), (0.999, 1.0, 0.001), (1.2, 0.1, 0.0)],
)
def test_rpi_margin_is_the_exact_factor_below_half_too(a, w, factor):
    """e+ = a e + g w on Z = [-1, 1]: RPI iff |a| + g w <= 1, so g = (1 - a) / w; a loop
    that expands Z without a disturbance gives 0 (the bisection searches from 0, so a
    factor below one half is found too)."""
    A, B, F, N = np.array([[[a]]]), np.zeros((1, 1, 1)), np.zeros((1, 1)), np.eye(1)
    g = rpi_margin(A, B, F, N, np.array([w]))
    assert g == pytest.approx(factor, abs=4.0 * 2.0**-30 + 1e-9)


def test_pruned_worst_corner_equals_the_full_maximum():
    """The all-vertex kernel bounds only the corners weak duality cannot pass over
    (`worst_bound`): on 400 random vertices of eight states and their 256 corners of W,
    its level and corner equal the largest of every corner's bound (`dual_bound`), to
    1e-13 relative, at the tight (level ~1) and the loose (level ~0.3) end."""
    from fahv.synthesis.rpi_kernels import dual_bound, worst_bound

    rng = np.random.default_rng(11)
    n = 8
    C = np.array(list(itertools.product((-1.0, 1.0), repeat=n))) * rng.uniform(0.02, 0.2, n)
    cc = np.einsum("li,li->l", C, C)
    for scale in (0.95, 0.5):
        for _ in range(200):
            M = rng.normal(0, scale / np.sqrt(n), (n, n))
            s, V = np.linalg.eigh(M.T @ M)
            b = C @ (M @ V)
            full = dual_bound(s, b, cc, 200)
            best, row = worst_bound(s, b, cc, 200)
            assert best == pytest.approx(full.max(), rel=1e-13)
            assert full[row] == pytest.approx(full.max(), rel=1e-13)
