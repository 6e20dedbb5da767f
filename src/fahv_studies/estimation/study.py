"""The bounds of a design's Kalman filter on a scenario's sensors, and the tube's room for them.

`estimate_study` gathers what `fahv-studies estimation` prints
(`fahv.stochastic.error_bound` for the bounds): the noise-driven error's
covariance bound over every vertex pair and the radius within which a whole run stays
with probability p; the exact frozen-vertex worst cases of the noise and of the model
error taken as bounded sequences; and what the noise-driven error adds to the tube's
one-step level when the tube law feeds back the estimate (u = v + F (x_hat - x_bar), so
e+ = A_cl e + w - B F e_x with e_x the estimation error: eq. (36) with the estimate in
place of the state).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.stats

from fahv.estimation.kalman import (
    D_INTENSITY,
    W_SIGMAS,
    measurement_covariance,
)
from fahv.sensors.data import SensorData
from fahv.sensors.measure import noise_bound
from fahv.stochastic.error_bound import (
    CovarianceBound,
    ErrorSystem,
    covariance_bound,
    error_system,
    peak_to_peak,
)

#: Noise parameters a bound of white noise does not cover: a channel with any of them
#: non-zero is refused by `white_noise_only`.
NOT_WHITE = ("mean", "bias_mean", "bias_stddev", "dynamic_bias_stddev", "precision", "lag",
             "drift_rate", "bias", "delay")  # fmt: skip


def white_noise_only(data: SensorData, measured: Sequence[str]) -> None:
    """Refuse channels whose model is more than white noise sampled every step.

    Parameters
    ----------
    data : SensorData
        The sensors' noise models.
    measured : sequence of str
        The channels the filter reads.

    Raises
    ------
    ValueError
        Naming the channel and its parameters that are not zero (or `period` > 1).
    """
    for c in measured:
        noise = data.channels[c]
        extra = [k for k in NOT_WHITE if getattr(noise, k)] + (["period"] if noise.period != 1
                                                               else [])  # fmt: skip
        if extra:
            raise ValueError(f"estimation bounds: channel {c!r} has {', '.join(extra)} besides "
                             "white noise, which the bounds do not cover")  # fmt: skip


@dataclass(frozen=True)
class EstimateStudy:
    """The bounds of a filter on one scenario (`estimate_study`).

    Attributes
    ----------
    system : ErrorSystem
    covariance : CovarianceBound
        The noise-driven error's covariance bound.
    p : float
        Probability the run-long statements hold with.
    steps : int
        Steps of the run.
    r_state : float
        Radius in standard deviations within which every state's noise-driven error
        stays for the whole run with probability >= p (union bound over steps and the
        11 states): |e_s| <= r_state sqrt(S_ss).
    r_joint : float
        The same for the whole vector: e' S^-1 e <= r_joint^2 at every step (chi-square
        with 11 degrees of freedom, union bound over the steps).
    v_max : (n_y,) ndarray
        Noise bound per channel that the whole run stays within with probability >= p.
    noise_worst : (11,) ndarray
        Worst |e_s| over the frozen vertices of the noise as a sequence within v_max.
    model_worst : (11,) ndarray
        Worst |e_s| over the frozen vertices of the model error g = [w; w_d] as a
        sequence within W and W_SIGMAS times the input disturbance's step deviation.
    tube_room : float
        1 - sqrt(level) of the tube's certified one-step level (its norm's room).
    tube_share : float
        r_joint max_i ||N^-1/2 B_i F S_x^1/2||: the most the noise-driven estimation
        error adds to the one-step norm of the tube error through the feedback.
    """

    system: ErrorSystem
    covariance: CovarianceBound
    p: float
    steps: int
    r_state: float
    r_joint: float
    v_max: np.ndarray
    noise_worst: np.ndarray
    model_worst: np.ndarray
    tube_room: float
    tube_share: float

    @property
    def tube_certified(self) -> bool:
        """Whether the tube's room holds the noise-driven error's share (with probability p)."""
        return self.tube_share <= self.tube_room

    @property
    def run_bound(self) -> np.ndarray:
        """r_state sqrt(diag S) (11,): the run-long bound of the noise-driven error."""
        return self.r_state * self.covariance.std


def tube_share(B: np.ndarray, F: np.ndarray, N: np.ndarray, S_x: np.ndarray,
               r: float) -> float:  # fmt: skip
    """The most an estimation error in {e' S_x^-1 e <= r^2} moves B_i F e in Z's norm.

    Parameters
    ----------
    B : (R, n, m) ndarray
        Input matrices of the vertices.
    F : (m, n) ndarray
        Tube gain.
    N : (n, n) ndarray
        Shape of Z = {e' N^-1 e <= 1}.
    S_x : (n, n) ndarray
        Shape of the estimation error's set.
    r : float
        Its radius.

    Returns
    -------
    float
        r max_i ||N^-1/2 B_i F S_x^1/2||_2.

    Examples
    --------
    >>> round(tube_share(np.ones((1, 1, 1)), np.full((1, 1), 0.5), np.eye(1) * 4.0,
    ...                  np.eye(1), 2.0), 9)
    0.5
    """
    Li = np.linalg.inv(np.linalg.cholesky(N))
    Sh = np.linalg.cholesky(S_x)
    return float(r * max(np.linalg.norm(Li @ Bi @ F @ Sh, 2) for Bi in B))


def estimate_study(flt, arrays, data: SensorData, measured: Sequence[str], Ts: float,
                   steps: int, level: float, p: float = 0.99) -> EstimateStudy:  # fmt: skip
    """The bounds of a design's filter (`fahv.estimation.kalman.design_filter`).

    Parameters
    ----------
    flt : GainScheduledKalman
    arrays : mapping
        The design's arrays: `B`, `F`, `N`, `w_max`.
    data : SensorData
    measured : sequence of str
        The filter's channels.
    Ts : float
        Step [s].
    steps : int
        Steps of the run.
    level : float
        The tube's certified worst one-step level (<= 1).
    p : float
        Probability of the run-long statements.

    Returns
    -------
    EstimateStudy

    Raises
    ------
    ValueError
        If a channel's noise is more than white (`white_noise_only`), or a frozen
        error system is unstable.
    DesignError
        If the covariance bound's LMI fails or its re-check does.
    """
    white_noise_only(data, measured)
    es = error_system(flt)
    cov = covariance_bound(es, measurement_covariance(measured, data))
    n = len(es.sigma)
    v_max = np.array([noise_bound(data.channels[c].stddev, steps * len(measured), p)
                      for c in measured])  # fmt: skip
    w_d = W_SIGMAS * D_INTENSITY * np.sqrt(Ts)
    zeros = np.zeros(n + len(measured))
    noise = zeros.copy()
    noise[n:] = v_max
    model = zeros.copy()
    model[:11] = np.concatenate([np.asarray(arrays["w_max"], float), w_d])  # servos: exact
    if flt.disturbance is not None:  # d_s's random walk, as d's
        model[n - 1] = W_SIGMAS * flt.disturbance.intensity * np.sqrt(Ts)
    r_joint = float(np.sqrt(scipy.stats.chi2.isf((1.0 - p) / steps, n)))
    share = tube_share(np.asarray(arrays["B"], float), np.asarray(arrays["F"], float),
                       np.asarray(arrays["N"], float), cov.S[:9, :9], r_joint)  # fmt: skip
    return EstimateStudy(es, cov, p, steps, noise_bound(1.0, steps * n, p), r_joint, v_max,
                         peak_to_peak(es, noise).max(axis=0),
                         peak_to_peak(es, model).max(axis=0), 1.0 - np.sqrt(level), share)
