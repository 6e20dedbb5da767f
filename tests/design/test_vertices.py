"""Vertex sets of the tube LMI (fahv.bounds.vertices): faults and adjustable gains."""

import numpy as np
import pytest

from fahv.bounds.vertices import fault_vertices, gain_vertices
from fahv.synthesis.feedback import design_tube, verify_tube
from fahv.synthesis.rpi_level import rpi_margin, worst_level


def test_fault_vertices_scale_the_elevator_column_only():
    """[A_i, B_i] and [A_i, B_i P], P = diag(1, rho_f) (eq. 15)."""
    A, B = np.ones((2, 3, 3)), np.ones((2, 3, 2))
    Af, Bf = fault_vertices(A, B, 0.7)
    assert Af.shape == (4, 3, 3) and Bf.shape == (4, 3, 2)
    np.testing.assert_array_equal(Bf[:2], B)
    np.testing.assert_array_equal(Bf[2:, :, 0], B[:, :, 0])
    np.testing.assert_allclose(Bf[2:, :, 1], 0.7 * B[:, :, 1], rtol=0)


def test_gain_vertices_certify_every_adjustable_gain_and_the_incomplete_set():
    """Eq. (47)-(48) on e+ = a e + b tau' F e + w, Z = [-z, z]: the tube LMI over
    ``gain_vertices`` (tau = 0.5) makes Z RPI for W under every gain tau' F, tau' in
    [0.5, 1] (checked by brute force on a grid of tau', with the exact scalar condition
    |a + b tau' F| z + w <= z), and tau Z RPI for g W with g >= tau, where the exact factor
    is g = tau z (1 - |a + b tau F|) / w."""
    a, b, w, tau = 1.05, 1.0, 0.01, 0.5
    A, B = np.array([[[a]]]), np.array([[[b]]])
    At, Bt = gain_vertices(A, B, tau)
    assert At.shape == (2, 1, 1) and Bt[1, 0, 0] == tau * b
    one = np.ones(1)
    tube = design_tube(At, Bt, np.array([w]), one, one, np.array([1.0]))
    verify_tube(At, Bt, tube, one, one)
    F, z = tube.F[0, 0], float(np.sqrt(tube.N[0, 0]))
    for t in np.linspace(tau, 1.0, 51):
        assert abs(a + b * t * F) * z + w <= z * (1 + 1e-9), t
    level = worst_level(At, Bt, tube.F, tube.N, np.array([w]))[0]
    assert level <= 1.0
    g = rpi_margin(A, B, tube.F, tube.N, np.array([w]), tau)
    g_exact = tau * z * (1.0 - abs(a + b * tau * F)) / w
    assert g == pytest.approx(g_exact, abs=4.0 * 2.0**-30 + 1e-9)
    assert g >= tau * (1 - 1e-9)
    assert gain_vertices(A, B, 1.0)[0] is A
    with pytest.raises(ValueError, match="tube.tau = 0"):
        gain_vertices(A, B, 0.0)
