"""The claims of the loop on the estimate: a probabilistic reachable set turned into rows.

The covariance bound of `fahv.stochastic.closed_loop` gives standard deviation bounds
of the deviation from the nominal and of the tube's command step; `claims_at` turns
them into an estimate design's two claims per run (`fahv.design.estimate`): the
nominal's attitude rows and its elevator rate rows that leave room for the noise with
a stated probability (union bounds over the claims, the run's steps and the signals).
"""

from __future__ import annotations

from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.estimation.kalman import design_filter, measurement_covariance
from fahv.sensors.data import DEFAULT_MEASURED, load_sensors
from fahv.spec.estimator import ESTIMATE_CLAIMS
from fahv.stochastic.closed_loop import ProbabilisticTube, loop_tube
from fahv.stochastic.error_bound import error_system

#: The probabilistic claims an estimate design can make (`estimate.claims`).
CLAIMS = ESTIMATE_CLAIMS
#: What every claim assumes, printed with it by the design and by `fahv verify`.
ASSUMPTIONS = ("white Gaussian sensor noise at the vehicle file's sigmas (turn-on biases not "
               "in it), the model error inside W reaching the deviation through Z_8, the "
               "servos' limits inactive")


@dataclass(frozen=True)
class EstimateClaims:
    """The claims of the loop on the estimate at one adjustable factor tau.

    Attributes
    ----------
    tau : float
        The adjustable factor of the tube law (eq. 53-54).
    claimed : tuple of str
        The claims the design makes (`estimate.claims`, names of `CLAIMS`).
    p_claim : float
        Each claim's probability per run (p split over the claimed ones).
    r_attitude, r_rate : float
        Radii [standard deviations] a whole run stays within with p_claim (union bound
        over the steps, and the two attitude signals).
    std_attitude : (2,) ndarray
        Standard deviation bound of alpha and theta's noise part [rad].
    std_step : float
        That of the tube's delta_e step [rad per step].
    rows : (2,) ndarray
        The nominal's attitude rows: those the claim allows, at most the design's, when
        the attitude is claimed; the design's otherwise [rad].
    rows_room : (2,) ndarray
        0.5 deg - support of Z_8 - r std: the rows the claim allows before the cap [rad].
    rate_tube, rate_limit : float
        The tube's worst-case part of the delta_e step, and the servo's rate limit times
        Ts [rad per step] (inf: ideal actuators).
    du_plan : float
        The nominal's delta_e rate rows: what the servo leaves after the tube's and the
        noise's parts, at most the design's, when the rate is claimed (<= 0: none, the
        claim fails); the design's otherwise [rad per step].
    rate_room : float
        What the servo leaves after the tube's and the noise's parts [rad per step].
    """

    tau: float
    claimed: tuple
    p_claim: float
    r_attitude: float
    r_rate: float
    std_attitude: np.ndarray
    std_step: float
    rows: np.ndarray
    rows_room: np.ndarray
    rate_tube: float
    rate_limit: float
    du_plan: float
    rate_room: float

    @property
    def attitude_holds(self) -> bool:
        """The attitude claim holds: rows are left for the nominal."""
        return bool(np.all(self.rows_room > 0.0))

    @property
    def rate_holds(self) -> bool:
        """The elevator-rate claim holds: rate rows are left for the nominal."""
        return bool(self.rate_room > 0.0)

    def said(self, claim: str) -> tuple[bool, str]:
        """Whether a claim passes its check, and what its line says of it.

        Parameters
        ----------
        claim : str
            A name of `CLAIMS`.

        Returns
        -------
        (bool, str)
            A claim the design makes passes when it holds ("certified" or "CLAIMED AND
            NOT HELD"); one it does not make always passes, reported with what its
            numbers say ("not claimed (it would hold)" or "(it does not hold)").
        """
        holds = self.attitude_holds if claim == "attitude" else self.rate_holds
        if claim in self.claimed:
            return holds, "certified" if holds else "CLAIMED AND NOT HELD"
        return True, "not claimed (it would hold)" if holds else "not claimed (it does not hold)"

    @property
    def holds(self) -> bool:
        """Every claimed claim holds."""
        return all({"attitude": self.attitude_holds, "elevator_rate": self.rate_holds}[c]
                   for c in self.claimed)  # fmt: skip


def run_radius(p: float, samples: int) -> float:
    """The radius r with P(|n_k| <= r for all `samples` standard normals) >= p (union bound).

    Parameters
    ----------
    p : float
        Probability, 0 < p < 1.
    samples : int
        Number of (possibly dependent) standard normal samples, >= 1.

    Returns
    -------
    float
        r = Phi^-1(1 - (1 - p) / (2 samples)) [standard deviations].

    Examples
    --------
    >>> round(run_radius(0.995, 2 * 15000), 3)
    5.108
    """
    return -NormalDist().inv_cdf((1.0 - p) / (2.0 * samples))


def estimate_filter(case: dict, vehicle, arrays):
    """The filter of an estimate design and its sensors' noise covariance.

    Parameters
    ----------
    case : dict
        The design data with its `estimate` section.
    vehicle : fahv.model.vehicle.Vehicle
        Its sensors (vehicle file) and servos (`estimate.actuators`).
    arrays : mapping
        The design's arrays (`design_filter`'s).

    Returns
    -------
    (GainScheduledKalman, (4, 4) ndarray)
        The filter on h, V, theta, q and R_v.

    Raises
    ------
    fahv.errors.DesignError
        If the vehicle file has no servos of the model the section names.
    """
    from fahv.errors import DesignError

    est = case["estimate"]
    servos = None
    if est["actuators"] != "ideal":
        if est["actuators"] not in vehicle.actuators:
            raise DesignError(f"estimate.actuators = {est['actuators']!r}: the vehicle file "
                              f"{vehicle.source_file} has no such servos")  # fmt: skip
        servos = vehicle.actuators[est["actuators"]]
    data = load_sensors(None if vehicle.packaged else vehicle.source_file)
    measured = list(DEFAULT_MEASURED)
    x0 = np.asarray(arrays["trim_x"], float)[0, 0][None]
    flt = design_filter(arrays, vehicle, data, measured, case["Ts"], case["plant_substeps"],
                        x0, servos, est["state_disturbance"])  # fmt: skip
    return flt, measurement_covariance(measured, data)


def claims_at(pt: ProbabilisticTube, tau: float, case: dict, support: np.ndarray,
              rate_tube: float, rate_limit: float) -> EstimateClaims:  # fmt: skip
    """The claims of a probabilistic tube (module docstring).

    Parameters
    ----------
    pt : ProbabilisticTube
        The loop's bound at tau (`fahv.stochastic.closed_loop.loop_tube`).
    tau : float
        Its adjustable factor.
    case : dict
        The design data: `estimate.probability`, `estimate.duration`, `Ts`,
        `mpc.att_max` [deg], `mpc.du_max` [-, deg].
    support : (2,) ndarray
        Support of Z_8 in alpha and theta [rad].
    rate_tube, rate_limit : float
        [rad per step], as `EstimateClaims`.

    Returns
    -------
    EstimateClaims
    """
    est, mpc = case["estimate"], case["mpc"]
    claimed = tuple(est.get("claims", CLAIMS))
    steps = max(1, round(float(est["duration"]) / float(case["Ts"])))
    p_claim = 1.0 - (1.0 - float(est["probability"])) / max(1, len(claimed))
    r_att, r_rate = run_radius(p_claim, 2 * steps), run_radius(p_claim, steps)
    std_att = np.asarray(pt.std_t[1:3], float)
    room = np.radians(ATTITUDE_BOUND_DEG) - np.asarray(support, float) - r_att * std_att
    design_rows = np.full(2, np.radians(float(mpc["att_max"])))
    rows = np.minimum(room, design_rows) if "attitude" in claimed else design_rows
    std_step = float(pt.std_step[1])
    du_design = np.radians(float(mpc["du_max"][1]))
    rate_room = rate_limit - rate_tube - r_rate * std_step
    du_plan = min(du_design, rate_room) if "elevator_rate" in claimed else du_design
    return EstimateClaims(tau, claimed, p_claim, r_att, r_rate, std_att, std_step, rows,
                          room, rate_tube, rate_limit, du_plan, rate_room)  # fmt: skip


def estimate_bound(case: dict, vehicle, arrays, tau: float, start=None):
    """The probabilistic tube of the design's law tau F on its filter's estimate.

    Parameters
    ----------
    case, vehicle, arrays
        As `estimate_filter`; the arrays also give `F`, `w_max`.
    tau : float
        The adjustable factor.
    start : sequence of (int, int), optional
        The covariance LMI's first pairs (a stored design's `estimate_pairs`).

    Returns
    -------
    (JointSystem, ProbabilisticTube)

    Raises
    ------
    fahv.errors.DesignError, ValueError
        As `fahv.stochastic.closed_loop.loop_tube`.
    """
    flt, R_v = estimate_filter(case, vehicle, arrays)
    return loop_tube(error_system(flt), flt, arrays, tau, R_v, start)
