"""Solves started from where an earlier design's ended (fahv.synthesis: ``start``).

A re-made design starts each constraint generation from the vertices an earlier solve
held, and each RMPC ellipsoid from the coordinates of its certified pass: the first
solve is then the earlier design's last, so the answer is the same in one solve.
"""

import numpy as np
import pytest

import fahv.synthesis.invariant_ellipsoid as ie
import fahv.synthesis.offline_rmpc as rmpc
from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid
from fahv.synthesis.offline_rmpc import design_sequence
from fahv.synthesis.rpi_level import vertex_levels


def _vertices(R: int, seed: int = 0):
    """R stable 3-state closed-loop vertices around a lightly damped oscillator."""
    rng = np.random.default_rng(seed)
    base = np.array([[0.85, 0.10, 0.0], [-0.10, 0.84, 0.02], [0.0, 0.01, 0.80]])
    return base[None] + 0.05 * rng.uniform(-1.0, 1.0, (R, 3, 3))


def _solve(Acl, w, counter, **kw):
    """invariant_ellipsoid on Acl for the box w, counting its LMI solves in ``counter``."""
    return invariant_ellipsoid(Acl, w, np.ones(3), np.eye(2), np.zeros((1, 3)), [1.0],
                               lambda P: vertex_levels(Acl, P, np.r_[w, 0.0]), 0.98, active=1,
                               add=2,
                               **kw)  # fmt: skip


@pytest.fixture
def solves(monkeypatch):
    """The number of LMI solves of invariant_ellipsoid (a list, appended per solve)."""
    calls = []
    real = ie.solve_lmi

    def counted(prob):
        calls.append(len(prob.constraints))
        return real(prob)

    monkeypatch.setattr(ie, "solve_lmi", counted)
    return calls


def test_an_ellipsoid_started_from_its_active_set_is_the_same_in_one_solve(solves):
    Acl = _vertices(200)
    w = np.array([1e-3, 2e-3])
    cold = _solve(Acl, w, solves)
    n_cold = len(solves)
    assert cold.found and n_cold >= 2  # the generation took passes from scratch
    assert vertex_levels(Acl, cold.P, np.r_[w, 0.0]).max() <= 1.0
    warm = _solve(Acl, w, solves, start=cold.active)
    assert len(solves) == n_cold + 1  # one solve
    np.testing.assert_array_equal(warm.active, cold.active)
    np.testing.assert_allclose(warm.P, cold.P, rtol=1e-12, atol=0.0)


def test_an_infeasible_answer_is_found_again_in_one_solve(solves):
    Acl = _vertices(200)
    Acl[17] = 1.02 * np.eye(3)  # one unstable vertex: no ellipsoid is RPI at it
    w = np.array([1e-3, 2e-3])
    cold = _solve(Acl, w, solves)
    assert not cold.found and cold.P is None and cold.s == np.inf
    n_cold = len(solves)
    warm = _solve(Acl, w, solves, start=cold.active)
    assert not warm.found and len(solves) == n_cold + 1
    with pytest.raises(ValueError, match="outside 0..199"):
        _solve(Acl, w, solves, start=[0, 200])


def test_rmpc_ellipsoids_from_their_certified_coordinates_are_the_same(monkeypatch):
    rng = np.random.default_rng(1)
    A = np.array([[1.0, 0.02], [0.0, 1.0]])[None] + 0.002 * rng.uniform(-1, 1, (4, 2, 2))
    B = np.array([[0.0], [0.02]])[None] * (1.0 + 0.1 * rng.uniform(-1, 1, (4, 1, 1)))
    args = (A, B, np.array([1.0, 0.5]), np.array([2.0]), np.ones(2), np.ones(1), np.ones(2),
            [1.05, 0.5, 0.2])  # fmt: skip
    cold, _ = design_sequence(*args)
    assert cold.guess_Q.shape == (3, 2, 2) and cold.guess_gamma.shape == (3,)
    passes = []
    real = rmpc._scaled_pass

    def counted(*a):
        passes.append(1)
        return real(*a)

    monkeypatch.setattr(rmpc, "_scaled_pass", counted)
    warm, _ = design_sequence(*args, start=(cold.guess_Q, cold.guess_gamma))
    assert len(passes) == 3  # one pass per ellipsoid
    np.testing.assert_allclose(warm.Q, cold.Q, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(warm.K, cold.K, rtol=1e-12, atol=0.0)
