"""The tube's share of the elevator servo's rate limit (fahv.bounds.input_rate), on the
certified design's own tube set and vertices (16384, rebuilt in tests/design/conftest.py),
and the `input rate` line of `fahv verify`."""

from pathlib import Path

import numpy as np
import pytest

from fahv.bounds.input_rate import tube_rate
from fahv.config.yamlio import load_yaml

ROOT = Path(__file__).resolve().parents[2]


def test_the_tube_part_of_the_elevator_command_leaves_room_in_the_servo_rate(tube_set_case1):
    """F e of cm_certified moves by at most 1.65 deg per step (0.02 s) over the 16384
    vertices, Z_8 and W_8; with the nominal's rate rows (0.2 deg per move start) 1.85 deg,
    inside the elevator servo's 100 deg/s (2 deg per step). Sampled: e on Z_8's boundary
    and w at W_8's corners never exceed the bound, and the maximiser of the worst vertex
    reaches it."""
    d, veh, *_, nv = tube_set_case1
    A, B = nv.vertices()
    A8, B8 = A[:, 1:, 1:], B[:, 1:, :]
    F, N, W = d["F"], d["N"], d["W"]
    r = tube_rate(A8, B8, F, N, W)
    de = np.degrees(r.per_step[1])
    assert de == pytest.approx(1.649, abs=0.005)
    design = load_yaml((ROOT / "offline_design/designs/cm_certified.yaml").read_text())
    ts, du_max = float(design["Ts"]), float(design["mpc"]["du_max"][1])
    servo = np.degrees(veh.actuators["second_order"]["delta_e"].rate_limit_incr) * ts
    assert servo == pytest.approx(2.0, rel=1e-12) and du_max == 0.2
    print(f"tube part {de:.3f} + nominal rows {du_max} = {de + du_max:.3f} <= {servo:.2f} deg "
          f"per step, margin {1 - (de + du_max) / servo:.1%}")  # fmt: skip
    assert de + du_max <= servo
    # sampled: random vertices, e on the boundary of Z_8, w at the corners of W_8
    rng = np.random.default_rng(5)
    L = np.linalg.cholesky(N)
    i = rng.integers(0, len(A8), 20000)
    u = rng.normal(size=(20000, 8))
    e = (u / np.linalg.norm(u, axis=1, keepdims=True)) @ L.T
    w = rng.choice([-1.0, 1.0], (20000, 8)) * W
    Acl = A8[i] + B8[i] @ F
    step = np.einsum("jk,rk->rj", F, np.einsum("rkl,rl->rk", Acl, e) - e + w)
    assert np.all(np.abs(step) <= r.per_step * (1 + 1e-12))
    # the worst vertex's maximiser reaches the Z part exactly
    v = r.vertex[1]
    c = (F[1] @ (A8[v] + B8[v] @ F - np.eye(8)))
    e_star = N @ c / np.sqrt(c @ N @ c)
    assert float(c @ e_star) == pytest.approx(r.over_z[1], rel=1e-12)
    assert np.abs(step[:, 1]).max() >= 0.5 * r.per_step[1]  # the samples reach into it


def test_tube_rate_refuses_bad_shapes_and_a_negative_w():
    with pytest.raises(ValueError, match="shapes"):
        tube_rate(np.zeros((2, 3, 3)), np.zeros((2, 3, 1)), np.zeros((1, 2)), np.eye(3),
                  np.ones(3))  # fmt: skip
    with pytest.raises(ValueError, match="non-negative"):
        tube_rate(np.zeros((1, 1, 1)), np.zeros((1, 1, 1)), [[1.0]], [[1.0]], [-1.0])


def test_the_verify_line_compares_with_the_vehicle_files_servo():
    """`check_input_rate`: the one-state loop of `tube_rate`'s example (F e moves by 0.75
    rad per step = 42.97 deg) with plan rows of 1 deg against servos of 2500 and 2000 deg/s
    at Ts = 0.02 s (50 and 40 deg per step): holds, then fails, margin 1 - 43.97 / limit; no
    line for a vehicle file without a finite rate limit."""
    from types import SimpleNamespace

    from fahv.certificate.verify import check_input_rate
    from fahv.model.actuators import Servo

    args = ([[[1.0]]], [[[0.0, 0.5]]], [[0.0], [-1.0]], [[1.0]], [0.25])
    case = {"Ts": 0.02, "mpc": {"du_max": [0.0, 1.0]}}
    for rate, ok in ((2500.0, True), (2000.0, False)):
        servo = Servo(zeta=0.7, omega_n=150.0, rate_limit_incr=np.radians(rate),
                      rate_limit_decr=np.radians(rate))  # fmt: skip
        veh = SimpleNamespace(actuators={"second_order": {"delta_e": servo}})
        (res,) = check_input_rate(*map(np.asarray, args), case, veh)
        limit = rate * 0.02
        assert res.ok is ok and res.margin == pytest.approx(1 - (np.degrees(0.75) + 1) / limit)
        assert f"{np.degrees(0.75) + 1:.3f} <= {limit:.3f} deg per step" in res.line
    assert check_input_rate(*map(np.asarray, args), case, SimpleNamespace(actuators={})) == []


def test_the_design_prints_the_line_and_refuses_a_tube_set_that_fails_it():
    """The design that closes a tube set prints the same `input rate` line (the
    one-state loop above, plan rows of 1 deg) and stops with a DesignError naming it when
    the servo is too slow; nothing is printed for a vehicle file without a rate limit."""
    from types import SimpleNamespace

    from fahv.design.tube_set_design import log_input_rate
    from fahv.errors import DesignError
    from fahv.model.actuators import Servo

    A, B = np.array([[[1.0, 0.0], [0.0, 1.0]]]), np.array([[[0.0, 0.0], [0.0, 0.5]]])
    nv = SimpleNamespace(vertices=lambda: (A, B))  # h first, then the one tube state
    ts = SimpleNamespace(F_8=np.array([[0.0], [-1.0]]), N_8=np.eye(1), W_8=np.array([0.25]))
    case = {"Ts": 0.02, "mpc": {"du_max": [0.0, 1.0]}}
    for rate, ok in ((2500.0, True), (2000.0, False)):
        servo = Servo(zeta=0.7, omega_n=150.0, rate_limit_incr=np.radians(rate),
                      rate_limit_decr=np.radians(rate))  # fmt: skip
        veh = SimpleNamespace(actuators={"second_order": {"delta_e": servo}})
        lines = []
        if ok:
            log_input_rate(nv, ts, case, veh, lines.append)
        else:
            with pytest.raises(DesignError, match="43.972 <= 40.000 deg per step"):
                log_input_rate(nv, ts, case, veh, lines.append)
        (line,) = lines
        assert line.startswith("input rate: the tube's part of the delta_e command moves at most "
                               "42.972 deg per step over 1 vertices")  # fmt: skip
        assert line.endswith("  OK" if ok else "  FAILED")
    lines = []
    log_input_rate(nv, ts, case, SimpleNamespace(actuators={}), lines.append)
    assert lines == []


def test_the_tube_part_of_a_case1_run_stays_within_the_bound():
    """Case 1 on the exact state (tube_mpc_no_notch, the step and 30 s past the 10 % loss
    at 100 s): the tube's part F e of the elevator command, e = x - x_r - x_n from the
    run's histories, moves by at most 1.649 deg per step, the bound over Z_8 and W_8
    (measured: 0.32 deg, at the loss's onset, which W_8 leaves out; the whole command's
    step, with the disturbance estimate's part, 1.53 deg)."""
    from fahv.certificate.verified import load_or_design
    from fahv.loop.simulate import simulate

    _, design, _ = load_or_design("offline_design/scenarios/case1.yaml", log=lambda *_: None,
                                  variants=["tube_mpc_no_notch"])  # fmt: skip
    run = simulate(design, "tube_mpc_no_notch", duration=130.0)
    e = run.x - run.x_r - run.x_n[:, :9]
    step = np.degrees(np.abs(np.diff(e @ np.asarray(design.arrays["F"], float)[1]))).max()
    assert 0.1 < step <= 1.649, step


def test_the_adjustable_law_moves_its_command_by_tau_times_its_own_loops_move(tube_set_case1):
    """The law tau F (eq. 53-54) closes A_i + tau B_i F, the vertex [A_i, tau B_i] of the
    eight-state tube's gain vertices (eq. 48), and its command moves by tau times F's move
    there: at tau = 0.8 on cm_certified's Z_8 1.200 deg per step against F's 1.649; the
    vertices [A_i, B_i] alone (tau = 1) give F's."""
    from dataclasses import replace

    from fahv.bounds.input_rate import law_rate

    d, *_, nv = tube_set_case1
    A, B = replace(nv, tau=0.8).vertices()
    args = (A[:, 1:, 1:], B[:, 1:, :], d["F"], d["N"], d["W"])
    assert np.degrees(law_rate(*args, 0.8).per_step[1]) == pytest.approx(1.200, abs=0.002)
    half = A.shape[0] // 2
    full = tube_rate(A[:half, 1:, 1:], B[:half, 1:, :], d["F"], d["N"], d["W"])
    one = law_rate(A[:half, 1:, 1:], B[:half, 1:, :], d["F"], d["N"], d["W"], 1.0)
    np.testing.assert_array_equal(one.per_step, full.per_step)
    with pytest.raises(ValueError, match="2R gain vertices"):
        law_rate(A[:3, 1:, 1:], B[:3, 1:, :], d["F"], d["N"], d["W"], 0.8)
