"""Jacobians (complex step) against central finite differences, and the pole map."""

import numpy as np
import pytest

from fahv.model.dynamics import make_model
from fahv.model.jacobian import jacobian_central_difference, jacobians
from fahv.model.linearize import classify_modes, linearize
from fahv.model.notch import NotchFilter


@pytest.mark.parametrize("kind", ["dm", "cm", "ecm"])
def test_jacobian_matches_central_differences(vehicle, kind):
    notch = NotchFilter(19.05, 0.02, 19.05, 0.5)
    lm = linearize(vehicle, 85730.0, 8013.0, kind, notch)
    model = make_model(kind, vehicle, notch)
    dx = model.state_scale(vehicle, notch)
    du = vehicle.input_scale
    # central differences in scaled coordinates with step 1e-4 scale units:
    # truncation O(1e-8), rounding O(1e-12 / 1e-4): both below the 1e-6 target
    Afd = jacobian_central_difference(lambda x: model.f(x, lm.u_r), lm.x_r, 1e-4 * dx)
    Bfd = jacobian_central_difference(lambda u: model.f(lm.x_r, u), lm.u_r, 1e-4 * du)
    S = np.hstack([lm.A * dx / dx[:, None], lm.B * du / dx[:, None]])
    Sfd = np.hstack([Afd * dx / dx[:, None], Bfd * du / dx[:, None]])
    rel = np.max(np.abs(S - Sfd)) / np.max(np.abs(S))
    assert rel < 1e-6


def test_linearization_predicts_small_step(vehicle):
    """f(x_r + dx, u_r + du) ~ A dx + B du to second order."""
    lm = linearize(vehicle, 85500.0, 7900.0, "cm")
    model = make_model("cm", vehicle)
    dx = 1e-3 * vehicle.state_scale
    du = 1e-3 * vehicle.input_scale
    f = model.f(lm.x_r + dx, lm.u_r + du)
    lin = lm.A @ dx + lm.B @ du
    assert np.max(np.abs((f - lin) / vehicle.state_scale)) < 1e-5


def test_jacobians_of_linear_map_exact():
    A0 = np.array([[1.0, 2.0], [3.0, 4.0]])
    B0 = np.array([[5.0], [6.0]])
    A, B = jacobians(lambda x, u: A0 @ x + B0 @ u, np.array([0.3, -0.2]), np.array([1.0]))
    np.testing.assert_allclose(A, A0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(B, B0, rtol=0, atol=1e-14)


def test_pole_map_modes(vehicle):
    """Fig. 4: unstable short period, phugoid pair, two lightly damped flexible pairs."""
    lm = linearize(vehicle, 85500.0, 7900.0, "cm")
    p = vehicle.params
    modes = {m.name: m for m in classify_modes(lm.A, p.omega_1, p.omega_2)}
    for name, om in (("flexible 1", p.omega_1), ("flexible 2", p.omega_2)):
        m = modes[name]
        assert len(m.eigenvalues) == 2 and abs(m.eigenvalues[0].imag) > 0
        assert abs(m.wn - om) / om < 0.10  # within 10 % of the data file's omega_i
        assert 0.0 < m.zeta < 0.05  # lightly damped
    sp = modes["short period"]
    assert max(e.real for e in sp.eigenvalues) > 0.5  # unstable short-period pole
    assert min(e.real for e in sp.eigenvalues) < -0.5
    ph = modes["phugoid"]
    assert ph.wn < 0.2 and abs(ph.eigenvalues[0].imag) > 0


def test_dm_flexible_poles_are_structural(vehicle):
    """In the DM the flexible modes are exactly -zeta w +- j w sqrt(1 - zeta^2)."""
    lm = linearize(vehicle, 85500.0, 7900.0, "dm")
    p = vehicle.params
    modes = {m.name: m for m in classify_modes(lm.A, p.omega_1, p.omega_2)}
    assert modes["flexible 1"].wn == pytest.approx(p.omega_1, rel=1e-9)
    assert modes["flexible 2"].zeta == pytest.approx(p.zeta_2, rel=1e-9)
