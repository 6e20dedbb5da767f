"""The vertex tube checked against its own assumptions (fahv.tube.vertex_tube)."""

import numpy as np
import pytest

from fahv.bounds.vertices import fault_vertices
from fahv.synthesis.rpi_level import worst_level
from fahv.tube.vertex_tube import onset_levels


def test_onset_levels_follow_the_certificate_recursion():
    """Without a pulse and with the budget sum mu w^2 = 1 - lam the level stays at 1; a
    pulse raises it by exactly the recursion's terms."""
    lam, mu, w = 0.99, np.array([2.0, 3.0]), np.array([0.04, 0.03])
    budget = float(mu @ w**2)
    w_full = w * np.sqrt((1 - lam) / budget)
    L = onset_levels(lam, mu, w_full, np.zeros(2), 0.04, 500)
    assert np.allclose(L, 1.0, atol=1e-12)
    L = onset_levels(lam, mu, w, np.array([0.1, 0.0]), 0.5, 3, level0=0.0)
    assert L[1] == pytest.approx(mu @ (w + [0.1, 0]) ** 2, rel=1e-14)
    assert L[2] == pytest.approx(lam * L[1] + mu @ (w + [0.05, 0]) ** 2, rel=1e-14)


def test_design_tube_is_rpi_for_its_W_exactly(design):
    """The exact worst one-step level of the design's tube over its 40 vertices, the
    corners of W and all of Z is at most 1 (printed with its margin)."""
    a = design.arrays
    Af, Bf = fault_vertices(a["A"], a["B"], design.case["tube"]["rho_min"])
    level, _ = worst_level(Af, Bf, a["F"], a["N"], a["w_max"])
    print(f"worst one-step level {level:.6f}, margin {1 - level:.2e}")
    assert level <= 1.0
