"""Notch filter, eq. (37)-(39)."""

import numpy as np
import pytest

from fahv.model.notch import DiscreteNotch, NotchFilter


def test_notch_depth_and_passband():
    nf = NotchFilter(20.0, 0.02, 20.0, 0.5)
    mag = nf.magnitude([0.1, 20.0, 500.0])
    assert mag[1] == pytest.approx(0.02 / 0.5, rel=1e-9)  # depth eps_z / eps_p at omega_z
    assert mag[0] == pytest.approx(1.0, abs=1e-3)  # unity far below
    assert mag[2] == pytest.approx(1.0, abs=1e-2)  # and far above the notch


def test_state_space_matches_tf():
    nf = NotchFilter(19.0, 0.03, 22.0, 0.6)
    A, B, C, D = nf.ss()
    for w in (1.0, 19.0, 40.0):
        s = 1j * w
        H_ss = C @ np.linalg.solve(s * np.eye(2) - A, B) + D
        H_tf = (s**2 / 19**2 + 2 * 0.03 * s / 19 + 1) / (s**2 / 22**2 + 2 * 0.6 * s / 22 + 1)
        assert H_ss == pytest.approx(H_tf, rel=1e-10)


@pytest.mark.parametrize(
    "params",
    [(19.05, 0.02, 19.05, 0.1), (30.0, 0.0, 30.0, 0.7), (25.3, 0.05, 31.7, 0.61),
     (4.1, 0.2, 55.0, 0.05)],
)  # fmt: skip
def test_state_space_is_python_controls_realisation_bit_for_bit(params):
    """The written-out canonical form equals control.tf2ss exactly (the ECM's x_q are
    these coordinates, and the shipped designs were made with them)."""
    import control

    nf = NotchFilter(*params)
    ref = control.tf2ss(nf.tf())
    A, B, C, D = nf.ss()
    assert np.array_equal(A, np.asarray(ref.A))
    assert np.array_equal(B, np.asarray(ref.B).ravel())
    assert np.array_equal(C, np.asarray(ref.C).ravel())
    assert D == float(np.asarray(ref.D).item())


def test_building_a_filter_does_not_import_python_control():
    import subprocess
    import sys

    code = (
        "import sys\nfrom fahv.model.notch import DiscreteNotch, NotchFilter\n"
        "DiscreteNotch(NotchFilter(19.05, 0.02, 19.05, 0.1), 0.02).step([0.01])\n"
        "print('control' in sys.modules)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.stdout.strip() == "False", r.stderr


def test_discrete_notch_kills_sinusoid_at_centre():
    Ts, w = 0.02, 19.05
    nf = DiscreteNotch(NotchFilter(w, 0.0, w, 0.5), Ts)
    t = np.arange(0, 20, Ts)
    y = np.array([nf.step(np.sin(w * tk)) for tk in t])
    # tustin with prewarp places the zero exactly at w: residual from the transient only
    assert np.max(np.abs(y[t > 10])) < 1e-3
    nf2 = DiscreteNotch(NotchFilter(w, 0.0, w, 0.5), Ts)
    y2 = np.array([nf2.step(np.sin(2.0 * tk)) for tk in t])
    assert np.max(np.abs(y2[t > 10])) == pytest.approx(1.0, abs=0.02)  # 2 rad/s passes


def test_bad_parameters():
    with pytest.raises(ValueError, match="omega_z"):
        NotchFilter(-1.0, 0.02, 20.0, 0.5)
    with pytest.raises(ValueError, match="Nyquist"):
        NotchFilter(200.0, 0.02, 200.0, 0.5).discretize(0.02)
    with pytest.raises(ValueError, match="must be finite"):
        DiscreteNotch(NotchFilter(20.0, 0.02, 20.0, 0.5), 0.02).step(float("nan"))


def test_discrete_notch_matches_python_control_tustin():
    """The trapezoidal form has the transfer function of control.c2d(tustin, prewarp)."""
    import control

    nf = NotchFilter(19.05, 0.02, 19.05, 0.5)
    Ts = 0.02
    ref = nf.discretize(Ts)
    f = DiscreteNotch(nf, Ts)
    # impulse response of both, 200 samples
    y = [f.step(1.0 if k == 0 else 0.0)[0] for k in range(200)]
    _, y_ref = control.impulse_response(ref, T=np.arange(200) * Ts)
    # python-control scales a discrete impulse response by 1/Ts (unit-area impulse)
    np.testing.assert_allclose(y, np.ravel(y_ref) * Ts, atol=1e-9)


def test_a_batch_of_filters_gives_each_run_the_bits_of_a_single_filter():
    nf = NotchFilter(19.05, 0.02, 19.05, 0.5)
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 3))
    batch = DiscreteNotch(nf, 0.02, [0.0, 0.01, -0.02])
    singles = [DiscreteNotch(nf, 0.02, q0) for q0 in (0.0, 0.01, -0.02)]
    for row in q:
        yb = batch.step(row)
        ys = [f.step(v)[0] for f, v in zip(singles, row, strict=True)]
        np.testing.assert_array_equal(yb, ys)
    np.testing.assert_array_equal(batch.x_q[1], singles[1].x_q[0])
