"""Checks shared by the estimation bounds' tests: the exact re-check of a covariance bound
at every vertex pair, the sample variance of its system under random switching, and the
nonlinear loop's deviation from its nominal against a probabilistic tube."""

from typing import NamedTuple

import numpy as np
import pytest
import scipy.linalg


def pair_min_eig(es, S: np.ndarray, R_v: np.ndarray) -> float:
    """min over every pair (i, j) of the smallest eigenvalue of S - M_ij S M_ij' - N_j R_v N_j'
    (scipy's eigvalsh, unscaled)."""
    R = es.n_vertices
    return min(
        scipy.linalg.eigvalsh(S - es.M[i, j] @ S @ es.M[i, j].T - es.N[j] @ R_v @ es.N[j].T)[0]
        for i in range(R) for j in range(R)
    )  # fmt: skip


def switched_variance(es, S: np.ndarray, R_v: np.ndarray, runs: int, steps: int,
                      seed: int) -> np.ndarray:  # fmt: skip
    """Sample variance of every state after `steps` steps of `runs` runs of the linear
    system, each from the bound's own covariance, a random pair (i, j) per run and step,
    Gaussian noise of covariance R_v (diagonal)."""
    rng = np.random.default_rng(seed)
    R, n = es.n_vertices, S.shape[0]
    v_std = np.sqrt(np.diag(R_v))
    e = rng.normal(size=(runs, n)) @ np.linalg.cholesky(S).T
    for _ in range(steps):
        i, j = rng.integers(0, R, runs), rng.integers(0, R, runs)
        v = rng.normal(size=(runs, len(v_std))) * v_std
        e = np.einsum("bij,bj->bi", es.M[i, j], e) + np.einsum("bij,bj->bi", es.N[j], v)
    return e.var(axis=0)


class Deviation(NamedTuple):
    """The nonlinear loop's deviation from its nominal against a probabilistic tube
    (`loop_deviation`): standard deviations as fractions of the bound's, attitude parts of
    t in rad, (2,) arrays for alpha and theta."""

    ratio: np.ndarray  # (4,) std of t in V, alpha, theta, q over the bound's
    step: float  # std of the elevator command's step over the bound's
    largest: np.ndarray  # largest |t|
    mean: np.ndarray  # mean of t: the model error's part
    about: np.ndarray  # largest |t - mean|: the noise's part
    reach: np.ndarray  # the bound's whole-run radius at p = 0.99


def loop_deviation(design, pt, duration: float = 100.0, t_from: float = 40.0,
                   overrides=None) -> Deviation:  # fmt: skip
    """The nonlinear loop (`tube_mpc` of the design's scenario, `duration` s, node
    parameter `overrides` as `simulate`'s) against the probabilistic tube `pt`, over
    t >= t_from, t = x - x_r - x_n (`Deviation`)."""
    from fahv.loop.simulate import simulate
    from fahv.model.vehicle import ALPHA, IQ, THETA, V
    from fahv.stochastic.closed_loop import radii

    run = simulate(design, "tube_mpc", duration=duration, overrides=overrides)
    k = run.t >= t_from
    t = (run.x - run.x_r - run.x_n[:, :9])[k]
    att = t[:, [ALPHA, THETA]]
    _, r_run = radii(0.99, len(run.t))
    mean = att.mean(axis=0)
    dev = Deviation(t[:, [V, ALPHA, THETA, IQ]].std(axis=0) / pt.std_t[:4],
                    float(np.diff(run.u[k, 1]).std() / pt.std_step[1]),
                    np.abs(att).max(axis=0), mean, np.abs(att - mean).max(axis=0),
                    r_run * pt.std_t[1:3])  # fmt: skip
    att_deg = (np.round(np.degrees(a), 3) for a in (dev.largest, mean, dev.about, dev.reach))
    print("measured / bound:", np.round(dev.ratio, 3), round(dev.step, 3),
          "largest, mean, largest about it, radius [deg]:", *att_deg)  # fmt: skip
    return dev


def joint_figures(js, pt, std_att_deg, std_u_deg: float, std_step_deg: float) -> None:
    """Assert a joint bound: exact at every pair (scipy's eigvalsh, unscaled, to 1e-12 of
    Sigma's largest entry), and its standard deviations of alpha and theta, of the tube's
    elevator and of its step [deg, deg per step] within 1 %."""
    from fahv.estimation.kalman import measurement_covariance
    from fahv.sensors.data import DEFAULT_MEASURED, load_sensors

    Rv = measurement_covariance(list(DEFAULT_MEASURED), load_sensors())
    assert pair_min_eig(js.system, pt.Sigma, Rv) >= -1e-12 * np.abs(pt.Sigma).max()
    assert np.degrees(pt.std_t[1:3]) == pytest.approx(std_att_deg, rel=0.01)
    assert np.degrees(pt.std_u[1]) == pytest.approx(std_u_deg, rel=0.01)
    assert np.degrees(pt.std_step[1]) == pytest.approx(std_step_deg, rel=0.01)


@pytest.fixture
def bound_checks():
    """The checks: (pair_min_eig, switched_variance, joint_figures)."""
    return pair_min_eig, switched_variance, joint_figures


@pytest.fixture
def deviation_check():
    """`loop_deviation`: the nonlinear loop against a probabilistic tube."""
    return loop_deviation
