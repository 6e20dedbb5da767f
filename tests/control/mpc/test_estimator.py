"""The state-disturbance estimate and its steady-state shift (fahv.control.mpc.estimator)."""

import numpy as np
import pytest

from fahv.control.mpc.estimator import (
    DisturbanceEstimator,
    estimator_gains,
    steady_state_shift,
)


def test_estimate_converges_to_the_elevator_loss(design, make_mpc):
    """Known 30 % loss on the linear model: -u_d -> (rho_f - 1) delta_e within 1 % in 15 s."""
    mpc = make_mpc()
    mpc.schedule(85500.0, 7900.0)
    A, B = mpc.A[:9, :9], mpc.B[:9]
    Ts = design.case["Ts"]
    est = DisturbanceEstimator(1, 9, Ts / 2.0)
    rho, de = 0.7, np.radians(12.4)
    x, u = np.zeros(9), np.array([0.0, de])  # deviations; the loss acts on the whole de
    for _ in range(int(15.0 / Ts)):
        x_next = A @ x + B @ np.array([0.0, rho * de])
        est.update(A[None], B[None], x[None], u[None], x_next[None])
        x = x_next
    # the state disturbance lies along the elevator column of B; its steady input
    # correction is the loss: -u_d = (0, (rho_f - 1) delta_e) within 1 %
    d_u = -mpc.Hu[:, :9] @ est.d[0]
    np.testing.assert_allclose(d_u[1], (rho - 1.0) * de, rtol=1e-2)
    assert abs(d_u[0]) < 1e-3  # Phi (fuel-to-air ratio): no throttle correction
    # no steady state shift beyond 0.01 scale units (0.01 deg in alpha, theta)
    np.testing.assert_allclose(mpc.Hx[:, :9] @ est.d[0] / design.arrays["Dx"], 0.0, atol=1e-2)


def test_estimate_starts_from_the_first_residual():
    """The first residual initialises d exactly; later ones are filtered with gain gamma."""
    est = DisturbanceEstimator(2, 3, 0.04)
    r1 = np.array([[1.0, -2.0, 0.5], [0.0, 3.0, -1.0]])
    np.testing.assert_array_equal(est.update_residual(r1), r1)
    r2 = r1 + 1.0
    np.testing.assert_allclose(est.update_residual(r2), r1 + 0.04, rtol=0, atol=1e-15)


def test_the_mean_start_averages_until_the_filter_gain_takes_over():
    """With mean_start the k-th residual has the gain max(gamma, 1/k): d is the mean of
    the residuals so far while 1/k > gamma (here 25 of them at gamma 0.04), the same
    first step as without it, then the fading filter; along the elevator column the
    same with gamma_e."""
    rng = np.random.default_rng(3)
    r = rng.normal(size=(60, 1, 3))
    est = DisturbanceEstimator(1, 3, 0.04, start="mean")
    for k in range(25):
        d = est.update_residual(r[k])
        np.testing.assert_allclose(d, r[: k + 1].mean(axis=0), rtol=0, atol=1e-14)
    d25 = d.copy()
    np.testing.assert_allclose(est.update_residual(r[25]), d25 + 0.04 * (r[25] - d25),
                               rtol=0, atol=1e-15)  # fmt: skip
    b, scale = np.array([[0.0, 1.0, 0.0]]), np.ones(3)
    fast = DisturbanceEstimator(1, 3, 0.04, 0.5, scale, start="mean")
    fast.update_residual(np.zeros((1, 3)), b)
    for _ in range(2):  # gains 1/2, then 1/3 < 0.5: along b at gamma_e, elsewhere 1/k
        fast.update_residual(np.ones((1, 3)), b)
    np.testing.assert_allclose(fast.d, [[1 - (1 / 2) * (2 / 3), 0.75, 1 - (1 / 2) * (2 / 3)]],
                               rtol=0, atol=1e-15)  # fmt: skip


def test_the_zero_start_filters_the_first_residual_at_the_filter_gain():
    """With start "zero" d starts at 0 and every residual, the first included, has the
    filter's gain gamma (gamma_e along the elevator column): one residual moves d by
    gamma of itself, where "first" takes it whole; an unknown start is refused."""
    b, scale = np.array([[0.0, 1.0, 0.0]]), np.ones(3)
    est = DisturbanceEstimator(1, 3, 0.04, 0.5, scale, start="zero")
    np.testing.assert_array_equal(est.d, np.zeros((1, 3)))
    d = est.update_residual(np.ones((1, 3)), b)
    np.testing.assert_allclose(d, [[0.04, 0.5, 0.04]], rtol=0, atol=1e-15)
    d = est.update_residual(np.ones((1, 3)), b)
    np.testing.assert_allclose(d, [[0.04 + 0.04 * 0.96, 0.75, 0.04 + 0.04 * 0.96]],
                               rtol=0, atol=1e-15)  # fmt: skip
    first = DisturbanceEstimator(1, 3, 0.04, 0.5, scale)
    np.testing.assert_array_equal(first.update_residual(np.ones((1, 3)), b), np.ones((1, 3)))
    with pytest.raises(ValueError, match="start must be one of"):
        DisturbanceEstimator(1, 3, 0.04, start="last")


def test_estimate_takes_the_elevator_share_at_its_own_gain(design, make_mpc):
    """With gamma_e = 1 along B's elevator column, a 24 % loss on the linear model is
    known at once: two steps after its onset -u_d = (0, (rho_f - 1) delta_e) within 1 %,
    when the isotropic filter (gamma 0.2) has 36 % of it; a residual orthogonal to b in
    the metric is filtered at gamma alone; gamma_e without its scale or b is refused."""
    mpc = make_mpc()
    mpc.schedule(85500.0, 7900.0)
    A, B = mpc.A[:9, :9], mpc.B[:9]
    Dx = design.arrays["Dx"][:9]
    rho, de = 0.76, np.radians(14.0)
    x, u = np.zeros(9), np.array([0.0, de])
    fast = DisturbanceEstimator(1, 9, 0.2, 1.0, Dx)
    slow = DisturbanceEstimator(1, 9, 0.2)
    for est in (fast, slow):  # the first residual (no loss yet) initialises both at 0
        est.update(A[None], B[None], x[None], u[None], (A @ x + B @ u)[None])
    for _ in range(2):
        x_next = A @ x + B @ np.array([0.0, rho * de])
        for est in (fast, slow):
            est.update(A[None], B[None], x[None], u[None], x_next[None])
        x = x_next
    loss_u = (rho - 1.0) * de
    np.testing.assert_allclose((-mpc.Hu[:, :9] @ fast.d[0])[1], loss_u, rtol=1e-2)
    assert (-mpc.Hu[:, :9] @ slow.d[0])[1] / loss_u == pytest.approx(1 - 0.8**2, abs=0.01)
    b = B[:, 1]
    o = np.zeros(9)
    o[1] = 1.0  # V, then made orthogonal to b in the metric diag(Dx)^-2
    o -= b * ((b / Dx**2) @ o) / ((b / Dx**2) @ b)
    est = DisturbanceEstimator(1, 9, 0.2, 1.0, Dx)
    est.update_residual(np.zeros((1, 9)), b[None])
    np.testing.assert_allclose(est.update_residual(o[None], b[None])[0], 0.2 * o, atol=1e-12)
    with pytest.raises(ValueError, match="gamma_e needs the elevator column"):
        est.update_residual(o[None])
    with pytest.raises(ValueError, match="scale"):
        DisturbanceEstimator(1, 9, 0.2, 1.0)
    with pytest.raises(ValueError, match="gamma_e"):
        DisturbanceEstimator(1, 9, 0.2, 1.5, Dx)


def test_steady_state_shift_solves_the_steady_state_equations():
    """(A - I) x_d + B u_d + d = 0 with h_d = V_d = 0, for any d; singular equations raise."""
    rng = np.random.default_rng(0)
    n, m = 9, 2
    A = np.eye(n) + 0.01 * rng.normal(size=(n, n))
    B = rng.normal(size=(n, m))
    Dx, Du = np.linspace(1.0, 2.0, n), np.array([0.1, 0.2])
    Hx, Hu = steady_state_shift(A, B, Dx, Du)
    assert Hx.shape == (n, n) and Hu.shape == (m, n)
    d = rng.normal(size=n)
    np.testing.assert_allclose((A - np.eye(n)) @ Hx @ d + B @ Hu @ d + d, 0.0, atol=1e-9)
    assert np.all(Hx[:2] == 0.0)
    with pytest.raises(np.linalg.LinAlgError):
        steady_state_shift(np.eye(n), np.zeros((n, m)), Dx, Du)


def test_estimator_gains_are_first_order_filters():
    assert estimator_gains(0.02, 0.0) == (1.0, None)  # no estimate
    gamma, gamma_e = estimator_gains(0.02, 0.1)
    assert gamma == pytest.approx(0.2) and gamma_e is None
    gamma, gamma_e = estimator_gains(0.02, 0.1, 0.01)
    assert gamma == pytest.approx(0.2) and gamma_e == 1.0  # capped at 1
