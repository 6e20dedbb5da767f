"""One run's tracking QP: solution checks, rows, recovery (fahv.control.mpc.tracking)."""

import numpy as np
import pytest

from fahv.control.mpc.settings import X_BOX_STATES, input_box, range_box, state_box
from fahv.errors import DesignError
from fahv.synthesis.nominal import verify_terminal
from fahv.synthesis.qp import check_kkt


def test_qp_solution_meets_tightened_limits_and_kkt(design, make_mpc):
    """First QP of the Case 1 step: inputs of the plan inside the tightened limits."""
    mpc = make_mpc()
    c = design.case["command"]
    mpc.schedule(c["h0"], c["V0"])
    u_base = mpc.u_r_s
    y, why = mpc.solve(np.zeros(mpc.n), u_base, np.array([c["h_c"], c["V_c"]]))
    assert why == "ok"
    N, m = mpc.s.N_p, mpc.m
    u = (mpc.U_y @ y + np.tile(u_base, N)).reshape(N, m)
    tol = 1e-6 * np.abs(mpc.u_hi)
    assert np.all(u >= mpc.u_lo - tol) and np.all(u <= mpc.u_hi + tol)
    # the set point moves toward the command: h to the trust-region bound (+300 ft), V
    # part of the way (the offset cost against the tracking cost; 102 ft/s measured)
    dth = y[mpc.layout.delta] * mpc.theta_scale
    assert dth[0] == pytest.approx(300.0, abs=1e-3)
    assert 50.0 < dth[1] <= 150.0 + 1e-3
    # the climb uses the asymmetric room: Phi above the symmetric bound u_r + 0.069
    assert u[:, 0].max() > u_base[0] + 0.1


def test_the_kkt_check_is_compiled_when_the_mpc_is_built(design, make_mpc):
    """A node builds its MPC before it reports ready: the numba compile of the KKT check
    happens there, and the QPs of the run need no other specialisation."""
    from fahv.synthesis.qp import _kkt_kernel

    mpc = make_mpc()
    assert len(_kkt_kernel().signatures) == 1
    c = design.case["command"]
    mpc.schedule(c["h0"], c["V0"])
    assert mpc.solve(np.zeros(mpc.n), mpc.u_r_s, np.array([c["h_c"], c["V_c"]]))[1] == "ok"
    assert len(_kkt_kernel().signatures) == 1


def test_kkt_check_rejects_a_perturbed_solution():
    H, f = np.eye(2), np.array([-2.0, 0.0])
    A = np.array([[1.0, 1.0]])
    bl, bu = np.array([-1e30, -1e30, -1e30]), np.array([1e30, 1e30, 1.0])
    # min 0.5 |y|^2 - 2 y_1 s.t. y_1 + y_2 <= 1: y = (1.5, -0.5), multiplier 0.5
    y, lam = np.array([1.5, -0.5]), np.array([0.0, 0.0, 0.5])
    assert check_kkt(H, f, A, bl, bu, y, lam) == ""
    assert "stationarity" in check_kkt(H, f, A, bl, bu, np.array([1.4, -0.4]), lam)
    assert "primal" in check_kkt(H, f, A, bl, bu, np.array([1.6, -0.5]), lam)


def test_terminal_set_not_invariant_is_rejected(design):
    a = design.arrays
    path = a["trim_u"][0, :2]
    cert = verify_terminal(a["A"], a["B"], a["K"], a["Q"], a["u_lo"], a["u_hi"], path)
    assert cert["invariance"] < 1.0
    with pytest.raises(DesignError, match="not invariant under K at vertex"):
        verify_terminal(a["A"], a["B"], 5 * a["K"], a["Q"], a["u_lo"], a["u_hi"], path)
    with pytest.raises(DesignError, match="outside the tightened"):
        verify_terminal(a["A"], a["B"], a["K"], a["Q"], a["u_lo"], a["u_lo"] + 1e-3, path)


def test_input_rows_hold_at_every_fast_step_of_the_applied_moves(design, make_mpc):
    """The QP bounds the nominal input u = u_base + Gu delta + K zeta +
    Du c_j at every fast step of the first two moves (the pre-stabilised input moves with
    zeta between move starts), not only at the move starts: a plan of the Case 1 climb,
    propagated fast step by fast step on the scheduled model, stays within the tightened
    limits, and the throttle row is active."""
    mpc = make_mpc()
    c = design.case["command"]
    mpc.schedule(c["h0"], c["V0"])
    s, ly, n, m = mpc.s, mpc.layout, mpc.n, mpc.m
    assert mpc.Uf_y.shape == (s.fine_moves * (s.M - 1) * m, ly.ny)
    y, why = mpc.solve(np.zeros(n), mpc.u_r_s, np.array([c["h_c"], c["V_c"]]))
    assert why == "ok"
    u = _inputs_of_plan(mpc, y, np.zeros(n), mpc.u_r_s)[:2].reshape(-1, m)
    tol = 1e-6 * mpc.Du
    assert np.all(u <= mpc.u_hi + tol) and np.all(u >= mpc.u_lo - tol), (u.max(0), mpc.u_hi)
    assert u[:, 0].max() > mpc.u_hi[0] - 1e-3  # the climb uses the throttle to its limit


def test_attitude_rows_hold_at_every_fast_step_of_the_applied_moves(design, make_mpc):
    """The plan's nominal alpha, theta deviation, propagated fast step by
    fast step on the scheduled model under u = u_s + K (z - x_s) + c_j, stays within the
    attitude bound through the first two moves (the one applied before the next re-plan and
    the one a shifted plan applies), not only at the move starts."""
    a_max = np.radians(0.3)
    mpc = make_mpc(att_max=np.full(2, a_max))
    c = design.case["command"]
    mpc.schedule(c["h0"], c["V0"])
    s, ly, n = mpc.s, mpc.layout, mpc.n
    assert mpc.Att_y.shape[0] == 2 * (s.fine_moves * (s.M - 1) + s.N_p)
    y, why = mpc.solve(np.zeros(n), mpc.u_r_s, np.array([c["h_c"], c["V_c"]]))
    assert why == "ok"
    delta = y[ly.delta]
    AK = mpc.A + mpc.B @ mpc.K
    E = (mpc.A - np.eye(n)) @ mpc.Gx + mpc.B @ mpc.Gu
    zeta = -mpc.Gx @ delta  # zeta_0 = z0 - Gx delta with z0 = 0
    att = []
    for j in range(s.N_p):
        cj = y[ly.move(j)] * mpc.Du
        for _ in range(s.M):
            zeta = AK @ zeta + mpc.B @ cj + E @ delta
            att.append(zeta[2:4].copy())
    att = np.array(att).reshape(s.N_p, s.M, 2)
    # every fast step of moves 0 and 1, and every move start, within the bound
    assert np.abs(att[:2]).max() <= a_max * (1 + 1e-6)
    assert np.abs(att[:, -1]).max() <= a_max * (1 + 1e-6)
    # the rows are active: the climb uses the attitude budget
    assert np.abs(att[:2]).max() > 0.9 * a_max


def test_infeasible_replan_recovers_by_moving_the_set_point(design, make_mpc):
    """A steady elevator 0.01 deg beyond the tightened limit at the set
    point (a loss estimate) makes the QP infeasible when the trust region (here 1 ft,
    0.5 ft/s) cannot move the set point far enough; the recovery QP, the same rows without
    the trust region, moves it to where the steady input fits."""
    mpc = make_mpc(dtheta_max=np.array([1.0, 0.5]))
    mpc.schedule(85500.0, 8000.0)
    u_base = mpc.u_r_s.copy()
    u_base[1] = mpc.u_hi[1] + np.radians(0.01)
    cmd = np.array([85500.0, 8000.0])
    y, why = mpc.solve(np.zeros(mpc.n), u_base, cmd)
    assert y is None and "exit flag" in why
    y, why = mpc.solve(np.zeros(mpc.n), u_base, cmd, recover=True)
    assert why == "ok"
    dth = y[mpc.layout.delta] * mpc.theta_scale
    assert abs(dth[0]) > 10.0  # beyond the 1 ft trust region (measured: -38 ft)
    u_s = u_base + mpc.Gu @ y[mpc.layout.delta]
    assert u_s[1] <= mpc.u_hi[1] + 1e-9


def test_a_steady_input_outside_the_tightened_set_recovers_without_its_rows(design, make_mpc):
    """An estimate shift asking a steady throttle below the tightened limit anywhere on the
    trim map (measured on light vehicles in the climb) leaves the QP and the set-point
    recovery infeasible; the last recovery drops only the steady-input rows (no
    certificate of the tube needs them) and plans with every move's input within the
    tightened limits."""
    mpc = make_mpc()
    mpc.schedule(85500.0, 8000.0)
    u_base = mpc.u_r_s.copy()
    u_base[0] = mpc.u_lo[0] - 0.2  # the steady throttle 0.2 below the tightened limit
    cmd = np.array([85500.0, 8000.0])
    z0 = np.zeros(mpc.n)
    for recover in (False, True):
        y, why = mpc.solve(z0, u_base, cmd, recover=recover)
        assert y is None and "exit flag" in why, why
    y, why = mpc.solve(z0, u_base, cmd, recover=True, relax_steady=True)
    assert why == "ok"
    u = _inputs_of_plan(mpc, y, z0, u_base)
    tol = 1e-6 * mpc.Du
    assert np.all(u[:, 0] >= mpc.u_lo - tol) and np.all(u[:, 0] <= mpc.u_hi + tol)
    assert np.all(u[:2] >= mpc.u_lo - tol) and np.all(u[:2] <= mpc.u_hi + tol)


def _inputs_of_plan(mpc, y, z0, u_base):
    """The plan's nominal input at every fast step (N_p, M, m), propagated step by step on
    the scheduled model under u = u_base + Gu delta + K zeta + Du c_j."""
    s, ly, n = mpc.s, mpc.layout, mpc.n
    delta = y[ly.delta]
    AK = mpc.A + mpc.B @ mpc.K
    E = (mpc.A - np.eye(n)) @ mpc.Gx + mpc.B @ mpc.Gu
    zeta = z0 - mpc.Gx @ delta
    u = np.empty((s.N_p, s.M, mpc.m))
    for j in range(s.N_p):
        cj = y[ly.move(j)] * mpc.Du
        for i in range(s.M):
            u[j, i] = u_base + mpc.Gu @ delta + mpc.K @ zeta + cj
            zeta = AK @ zeta + mpc.B @ cj + E @ delta
    return u


def _free_climb_plan(design, make_mpc):
    """The first plan of the Case 1 climb without rate or box rows: (command section, (h_c,
    V_c), the MPC, z0 = 0, its solution y, the plan's inputs (N_p, M, m))."""
    c = design.case["command"]
    cmd = np.array([c["h_c"], c["V_c"]])
    free = make_mpc()
    free.schedule(c["h0"], c["V0"])
    z0 = np.zeros(free.n)
    y0, why = free.solve(z0, free.u_r_s, cmd)
    assert why == "ok"
    return c, cmd, free, z0, y0, _inputs_of_plan(free, y0, z0, free.u_r_s)


def test_rate_rows_bound_the_jumps_of_the_nominal_input(design, make_mpc):
    """mpc.du_max: the nominal input, propagated fast step by fast step, jumps at each move
    start by at most du_max (from the last fast step of the move before), and the first
    input of a re-plan lies within du_max of the input applied before it; the rows bind
    (without them the same QP jumps by more than 3x du_max)."""
    c, cmd, free, z0, y0, u_free = _free_climb_plan(design, make_mpc)
    du = np.array([0.02, np.radians(0.2)])
    jumps_free = np.abs(np.diff(u_free.reshape(-1, 2), axis=0)).max(axis=0)
    assert np.all(jumps_free > 3.0 * du)
    mpc = make_mpc(du_max=du)
    mpc.schedule(c["h0"], c["V0"])
    u_prev = mpc.u_r_s + np.array([0.01, np.radians(-0.1)])  # the input applied before
    y, why = mpc.solve(z0, mpc.u_r_s, cmd, u_prev=u_prev)
    assert why == "ok"
    assert mpc.A_c.shape[0] == free.A_c.shape[0] + 2 * (mpc.s.N_p - 1)
    u = _inputs_of_plan(mpc, y, z0, mpc.u_r_s)
    tol = 1e-6 * mpc.Du  # the KKT check's primal tolerance (scaled rows)
    assert np.all(np.abs(u[0, 0] - u_prev) <= du + tol)
    starts = np.abs(u[1:, 0] - u[:-1, -1])  # jump at each move start j = 1..N_p-1
    assert np.all(starts <= du + tol)
    assert np.all(starts.max(axis=0) > 0.99 * du)  # the rows bind
    # the constraint rows' own evaluation equals the propagated jumps
    rows = (mpc.Rate_y @ y + mpc.Rate_z @ z0).reshape(-1, 2) * mpc.Du
    np.testing.assert_allclose(rows, u[1:, 0] - u[:-1, -1], atol=1e-9)


def test_input_box_rows_bound_the_manoeuvre_part_of_the_input(design, make_mpc):
    """mpc.u_box (the eight-state tube's nominal box less the corners' trim offsets): the
    manoeuvre part of the nominal input, K zeta + Du c_j (the input minus the set point's
    steady input, trim plus the estimate's shift u_d), stays inside the rows at every move
    start and at every fast step of the first two moves; +0.05 in Phi binds in the Case 1
    climb (without it the same QP asks for more than 0.1 above the trim)."""
    c, cmd, free, z0, y0, u_free = _free_climb_plan(design, make_mpc)
    trim_free = free.u_r_s + free.Gu @ y0[free.layout.delta]
    assert (u_free[:, 0, 0] - trim_free[0]).max() > 0.1
    box = input_box([-0.12, 0.05, -1.0, 7.0])
    mpc = make_mpc(u_box=box)
    mpc.schedule(c["h0"], c["V0"])
    u_d = np.array([-0.02, np.radians(2.0)])  # an estimate's steady shift: not in the rows
    y, why = mpc.solve(z0, mpc.u_r_s + u_d, cmd)
    assert why == "ok"
    n_fine = mpc.Uf_y.shape[0]
    assert mpc.A_c.shape[0] == free.A_c.shape[0] + mpc.s.N_p * mpc.m + n_fine
    u = _inputs_of_plan(mpc, y, z0, mpc.u_r_s + u_d)
    off = u - (mpc.u_r_s + u_d + mpc.Gu @ y[mpc.layout.delta])  # the manoeuvre part
    tol = 1e-6 * mpc.Du
    checked = np.concatenate([off[:2].reshape(-1, 2), off[2:, 0]])  # fine moves, then starts
    assert np.all(checked <= box[1] + tol) and np.all(checked >= box[0] - tol)
    assert checked[:, 0].max() > 0.05 - 1e-4  # the Phi row binds
    with pytest.raises(ValueError, match="mpc.u_box"):
        input_box([0.1, 0.2, -1.0, 7.0])  # the trim itself outside
    assert input_box([0.0, 0.0, 0.0, 0.0]) is None


def _plan_states(mpc, y, z0):
    """The plan's absolute nominal state at every fast step after each move's start
    (N_p, M, n), propagated step by step on the scheduled model: x_r_s + Gx delta + zeta
    (without the estimate's shift)."""
    s, ly, n = mpc.s, mpc.layout, mpc.n
    delta = y[ly.delta]
    AK = mpc.A + mpc.B @ mpc.K
    E = (mpc.A - np.eye(n)) @ mpc.Gx + mpc.B @ mpc.Gu
    zeta = z0 - mpc.Gx @ delta
    x = np.empty((s.N_p, s.M, n))
    for j in range(s.N_p):
        cj = y[ly.move(j)] * mpc.Du
        for i in range(s.M):
            zeta = AK @ zeta + mpc.B @ cj + E @ delta
            x[j, i] = mpc.x_r_s + mpc.Gx @ delta + zeta
    return x


def _states_of_plan(mpc, y, z0):
    """The plan's absolute nominal h [ft], V [ft/s] at every fast step (N_p, M, 2)."""
    return _plan_states(mpc, y, z0)[..., :2]


def test_range_rows_keep_the_set_point_and_the_prediction_in_the_nominal_range(design, make_mpc):
    """mpc.hv_box (the eight-state tube's nominal h, V range): with a command beyond the
    range the artificial set point stops at its edge (normal and recovery QP), and the
    predicted h, V stay inside at every fast step of the first two moves and at every move
    start; without the rows the same QP plans beyond it."""
    c, cmd, free, z0, y0, _ = _free_climb_plan(design, make_mpc)
    hv_free = _states_of_plan(free, y0, z0)
    top = c["h0"] + 100.0  # the range ends 100 ft above the start, 500 ft below the command
    assert hv_free[:, :, 0].max() > top + 50.0  # the free plan climbs through it
    box = range_box([84000.0, top, 7700.0, c["V0"] + 60.0])
    mpc = make_mpc(hv_box=box)
    mpc.schedule(c["h0"], c["V0"])
    for recover in (False, True):
        y, why = mpc.solve(z0, mpc.u_r_s, cmd, recover=recover)
        assert why == "ok"
        h_s, V_s = mpc.theta_s + y[mpc.layout.delta] * mpc.theta_scale
        assert h_s <= top + 1e-3 and V_s <= c["V0"] + 60.0 + 1e-3
        hv = _states_of_plan(mpc, y, z0)
        checked = np.concatenate([hv[:2].reshape(-1, 2), hv[2:, -1]])  # the rows' steps
        tol = np.array([1e-3, 1e-3])
        assert np.all(checked <= box[1] + tol) and np.all(checked >= box[0] - tol)
        assert checked[:, 0].max() > top - 5.0  # it climbs to the edge
    assert mpc.A_c.shape[0] == free.A_c.shape[0] + free.Att_y.shape[0]  # one row per attitude row
    with pytest.raises(ValueError, match="mpc.hv_box"):
        range_box([86000.0, 85000.0, 7700.0, 8300.0])
    assert range_box([0.0, 0.0, 0.0, 0.0]) is None


def _own_trim_states_of_plan(mpc, y, z0, x_d):
    """The plan's alpha .. eta_2_dot at every fast step (N_p, M, 7) as deviations from the
    nominal vehicle's trim at the plan's own (h, V), from the (nonlinear) trim map, with
    the estimate's shift x_d: X = x_r_s + x_d + Gx delta + zeta."""
    X = _plan_states(mpc, y, z0) + x_d
    flat = X.reshape(-1, X.shape[-1])
    x_t, _ = mpc.trim_map.at(flat[:, 0], flat[:, 1])
    return (flat[:, 2:9] - np.asarray(x_t)[:, 2:9]).reshape(*X.shape[:2], 7)


def test_state_range_rows_keep_the_prediction_in_the_certified_range(design, make_mpc):
    """mpc.x_box (the range the eight-state certificate covers, from the trim at the
    nominal's own (h, V)): with |q| <= 0.3 deg/s and alpha within -0.2 .. +0.25 deg, the
    Case 1 climb's plan keeps q and alpha inside at every fast step of the first two moves
    and at every move start, with an estimate's shift x_d in it; the linearised trim (its
    slope at the scheduling point) agrees with the trim map to 2e-3 deg over the plan.
    Without the rows the same QP plans 0.63 deg/s and -0.30 deg (measured)."""
    c, cmd, free, z0, y0, _ = _free_climb_plan(design, make_mpc)
    own_free = _own_trim_states_of_plan(free, y0, z0, np.zeros(free.n))
    assert np.degrees(np.abs(own_free[..., 2]).max()) > 0.45
    assert np.degrees(own_free[..., 0].min()) < -0.25
    lo = [-0.2, -1.0, -0.3, -5.0, -50.0, -5.0, -50.0]
    hi = [0.25, 1.0, 0.3, 5.0, 50.0, 5.0, 50.0]
    box = state_box(lo + hi)
    mpc = make_mpc(x_box=box)
    mpc.schedule(c["h0"], c["V0"])
    x_d = np.zeros(mpc.n)
    x_d[2:4] = np.radians(-0.05)  # an estimate's shift: the vehicle's own trim 0.05 deg lower
    y, why = mpc.solve(z0, mpc.u_r_s, cmd, x_off=x_d)
    assert why == "ok"
    assert mpc.A_c.shape[0] == free.A_c.shape[0] + 7 * free.Att_y.shape[0] // 2
    own = _own_trim_states_of_plan(mpc, y, z0, x_d)
    checked = np.concatenate([own[:2].reshape(-1, 7), own[2:, -1]])  # the rows' steps
    tol = np.array([np.radians(2e-3), np.radians(2e-3), 1e-9, 1e-9, 1e-9, 1e-9, 1e-9])
    assert np.all(checked <= box[1] + tol) and np.all(checked >= box[0] - tol)
    assert np.degrees(np.abs(checked[:, 2]).max()) > 0.3 - 1e-3  # the q row binds
    with pytest.raises(ValueError, match="mpc.x_box"):
        state_box([0.1] + lo[1:] + hi)  # the trim itself outside
    assert state_box([0.0] * 14) is None
    # units: alpha, theta, q from deg (deg/s) to rad (rad/s), the bending modes as given
    assert X_BOX_STATES[2] == "q"
    np.testing.assert_allclose(box[:, 2], np.radians([-0.3, 0.3]), rtol=1e-15)
    np.testing.assert_allclose(box[:, 4], [-50.0, 50.0], rtol=1e-15)
