"""The bounds of the Kalman filter's estimation error (fahv.stochastic.error_bound, study):
the covariance bound holds at every pair of model and gain vertex and above every frozen
vertex's own covariance, random switching stays below it, the frozen worst case is
reached by its sequence, and the nonlinear loop's error stays within the bounds; the
figures of docs/theory/estimation.md."""

import numpy as np
import pytest
import scipy.linalg

from fahv.certificate.verified import load_or_design
from fahv.estimation.kalman import design_filter, measurement_covariance
from fahv.loop.simulate import simulate
from fahv.model.vehicle import ALPHA, THETA, H, V
from fahv.sensors.data import DEFAULT_MEASURED, load_sensors, replace_channel
from fahv.stochastic.error_bound import peak_to_peak, worst_sequence
from fahv_studies.estimation.study import estimate_study, white_noise_only

MEASURED = list(DEFAULT_MEASURED)
STEPS = 15000  # a 300 s run


@pytest.fixture(scope="module")
def certified():
    return load_or_design("offline_design/scenarios/case1.yaml", log=lambda *_: None,
                          variants=["tube_mpc"])  # fmt: skip


@pytest.fixture(scope="module")
def study(certified):
    _, design, vehicle = certified
    a, data = design.arrays, load_sensors()
    flt = design_filter(a, vehicle, data, MEASURED, 0.02, 5, a["x0"][None])
    return estimate_study(flt, a, data, MEASURED, 0.02, STEPS,
                          design.summary["certificate"]["level"])  # fmt: skip


def test_the_covariance_bound_holds_at_every_pair_and_above_every_frozen_vertex(study,
                                                                              bound_checks):
    """S - M_ij S M_ij' - N_j R_v N_j' >= 0 at all 400 pairs (re-checked here with scipy's
    eigvalsh, unscaled, to 1e-12 of S's largest entry), and S is above each matched
    vertex's own stationary covariance (Lyapunov's equation) in every state. The figures:
    1 sigma of alpha and theta 0.0140 deg, h 0.39 ft (2 %)."""
    es, S = study.system, study.covariance.S
    Rv = measurement_covariance(MEASURED, load_sensors())
    R = es.n_vertices
    assert bound_checks[0](es, S, Rv) >= -1e-12 * np.abs(S).max()
    for i in range(R):
        X = scipy.linalg.solve_discrete_lyapunov(es.M[i, i], es.N[i] @ Rv @ es.N[i].T)
        assert np.all(np.diag(X) <= np.diag(S) * (1 + 1e-9)), i
    std = study.covariance.std
    assert np.degrees(std[ALPHA]) == pytest.approx(0.0140, rel=0.02)
    assert np.degrees(std[THETA]) == pytest.approx(0.0140, rel=0.02)
    assert std[H] == pytest.approx(0.39, rel=0.02)


def test_random_switching_stays_below_the_covariance_bound(study, bound_checks):
    """4000 runs of the linear error system, 400 steps each from the bound's own
    covariance, a random pair of model and gain vertex per run and step, Gaussian noise
    of the sensors' stddev: the sample variance of every state stays below S_ss (with 10 %
    for the sampling error of 4000 samples, 2.2 % one sigma)."""
    es, S = study.system, study.covariance.S
    Rv = measurement_covariance(MEASURED, load_sensors())
    ratio = bound_checks[1](es, S, Rv, 4000, 400, seed=11) / np.diag(S)
    print("sample variance / S_ss:", np.round(ratio, 3))
    assert ratio.max() < 1.1, ratio
    assert ratio.max() > 0.5  # the bound is not loose everywhere (measured 0.97)


def test_the_frozen_worst_case_is_reached_by_its_sequence(study):
    """The sign sequence of the impulse response drives alpha's error of the worst frozen
    vertex to the peak-to-peak bound (0.678 deg for the noise within its run-long bound)
    within 1e-9 of it after 6000 steps."""
    es = study.system
    xi = np.concatenate([np.zeros(11), study.v_max])
    pk = peak_to_peak(es, xi)
    i = int(np.argmax(pk[:, ALPHA]))
    e = np.zeros(11)
    D = np.concatenate([es.G[i], es.N[i]], axis=1)
    for x in worst_sequence(es, xi, i, ALPHA, 6000):
        e = es.M[i, i] @ e + D @ x
    assert e[ALPHA] == pytest.approx(pk[i, ALPHA], rel=1e-9)
    assert np.degrees(study.noise_worst[ALPHA]) == pytest.approx(0.678, abs=0.002)


def test_the_nonlinear_loop_stays_within_the_bounds(certified, study):
    """Case 1 on the Kalman estimate, 60 s, a 10 % elevator loss at 20 s: the error of h, V,
    alpha and theta stays within the noise's run-long bound plus the model error's frozen
    worst case (measured: 1.6 ft, 0.60 ft/s, 0.046 deg, 0.046 deg against 19.5 ft, 6.1
    ft/s, 0.23 deg, 0.11 deg); the bounds are those of the linear error system, this is
    the check on the plant."""
    _, design, _ = certified
    m = ",".join(MEASURED)
    ov = {"plant": {"measured": m}, "state_estimator": {"estimator": "kalman", "measured": m},
          "fault_injector": {"t_onset": 20.0}}  # fmt: skip
    run = simulate(design, "tube_mpc", duration=60.0, overrides=ov)
    err = np.abs(run.x_hat - run.x).max(axis=0)
    bound = study.run_bound + study.model_worst
    for s in (H, V, ALPHA, THETA):
        assert err[s] <= bound[s], (s, err[s], bound[s])
    assert np.degrees(err[ALPHA]) > 0.01  # the estimate is not the state


def test_the_tube_has_no_room_for_the_estimate(study):
    """The noise-driven error moves the tube error by 0.84 of Z per step through B F,
    against the room 3.4e-4 of the certified level: the state-feedback tube on the
    estimate is not certified (docs/theory/estimation.md)."""
    assert study.tube_share == pytest.approx(0.843, abs=0.01)
    assert study.tube_room == pytest.approx(3.45e-4, rel=0.01)
    assert not study.tube_certified


def test_noise_beyond_white_is_refused():
    data = replace_channel(load_sensors(), "q", bias=0.001)
    with pytest.raises(ValueError, match="channel 'q' has bias besides white noise"):
        white_noise_only(data, MEASURED)
    white_noise_only(load_sensors(), MEASURED)  # the packaged sensors: white only


def test_the_filters_correction_bounds_are_reached(certified, study):
    """The row bounds of the estimate's correction (fahv_studies.estimation.output_feedback) are
    exact: the sign vector of a gain row at its noise bounds reaches the sensor part, and
    the ellipsoid's support point at the worst pair of vertices reaches the error part;
    random points of the ellipsoid and of the noise box stay within them."""
    from fahv.estimation.kalman import augmented
    from fahv_studies.estimation.output_feedback import error_part, sensor_part

    _, design, vehicle = certified
    a, data = design.arrays, load_sensors()
    flt = design_filter(a, vehicle, data, MEASURED, 0.02, 5, a["x0"][None])
    L, v_max, r, S = flt.L, study.v_max, study.r_joint, study.covariance.S
    Az = augmented(np.asarray(flt.lpv.A), np.asarray(flt.lpv.B))
    Cz = np.hstack([flt.C, np.zeros((len(flt.C), 2))])
    sens, err = sensor_part(L, v_max), error_part(L, Cz, Az, S, r)
    s = ALPHA
    j = int(np.argmax(np.abs(L[:, s, :]) @ v_max))
    assert L[j, s] @ (np.sign(L[j, s]) * v_max) == pytest.approx(sens[s], rel=1e-12)
    rows = np.einsum("jy,iyk->ijk", L[:, s, :], Cz @ Az)  # (R, R, 11): the rows of state s
    i, jj = np.unravel_index(np.argmax(np.einsum("ijk,kl,ijl->ij", rows, S, rows)), rows.shape[:2])
    ell = rows[i, jj]
    e = r * S @ ell / np.sqrt(ell @ S @ ell)  # on the ellipsoid's boundary
    assert e @ np.linalg.solve(S, e) == pytest.approx(r**2, rel=1e-9)
    assert ell @ e == pytest.approx(err[s], rel=1e-9)
    rng = np.random.default_rng(0)
    Sh = np.linalg.cholesky(S)
    u = rng.normal(size=(2000, 11))
    pts = r * (u / np.linalg.norm(u, axis=1)[:, None]) @ Sh.T
    assert np.abs(np.einsum("ijk,pk->ijp", rows, pts)).max() <= err[s] * (1 + 1e-12)
    v = rng.uniform(-1, 1, (2000, len(v_max))) * v_max
    assert np.abs(np.einsum("jsy,py->jsp", L, v)).max(axis=(0, 2)).max() <= sens.max()
    assert np.all(np.abs(np.einsum("jsy,py->jsp", L, v)).max(axis=(0, 2)) <= sens + 1e-15)


def test_a_bound_started_from_its_own_pairs_is_the_same_bound(study):
    """`start`: the pairs the last solve held make the same S in one solve (so a study can
    ship them as a warm start); pairs that are not vertex pairs are refused, named."""
    from fahv.stochastic.error_bound import covariance_bound

    cov = study.covariance
    Rv = measurement_covariance(MEASURED, load_sensors())
    again = covariance_bound(study.system, Rv, start=cov.pairs)
    assert again.pairs == cov.pairs and again.pairs_held == cov.pairs_held
    np.testing.assert_allclose(again.S, cov.S, rtol=1e-9, atol=0)
    assert again.min_eig >= 0.0
    with pytest.raises(ValueError, match=r"start pairs \[\(20, 0\)\] are not vertex pairs"):
        covariance_bound(study.system, Rv, start=[(0, 0), (20, 0)])
