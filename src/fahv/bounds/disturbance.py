"""Lumped disturbance set W, eq. (13)-(19).

Delta(k) = x(k+1) - A(p(k)) x(k) - B(p(k)) u(k) collects, in one step of the
discrete polytopic model (deviation coordinates around the commanded trim):

* f, modelling error (eq. 13): nominal nonlinear CM vs the polytopic LPV prediction;
* f, parameter uncertainty (eq. 13): perturbed vs nominal nonlinear CM, parameters at
  corners of the parameter box of sec. 5.1;
* w, elevator loss of effectiveness (eq. 14-17): delta_e,applied = rho_f delta_e on the
  whole deflection (trim included), vs the healthy vehicle.

W is the box of the largest |Delta_j| over a seeded random sample of flight
conditions, deviations, inputs, parameter corners and fault states, times a stated
margin. Each source is also bounded alone, to show which dominates.

Constant part. For a law that estimates a constant state disturbance online
(`fahv.control.mpc.estimator.DisturbanceEstimator`, law `tube_mpc`), the part of
the parameter error that does not depend on the deviation -- its value at the sample's
trim point, Delta_0 = f_p(x_r, u_r) - f(x_r, u_r) over one step -- is taken out of the
nominal model's error by the estimate, so W (`constant="estimated"`) bounds
Delta - Delta_0: the deviation part, the modelling error and the mean-free rest. The
paper's W (`constant="bounded"`) keeps it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.model.dynamics import make_model
from fahv.model.trim import trim
from fahv.model.vehicle import DELTA_E
from fahv.plant.integrator import rk4_step
from fahv.plant.uncertainty import perturb

#: Half-widths of the state deviations sampled for W (h ft, V ft/s, alpha rad, theta rad,
#: q rad/s, eta_1, eta_1_dot, eta_2, eta_2_dot): the Case 1 step (600 ft, 250 ft/s) and a
#: few scale units of the attitude and flexible states (docs/theory/certificate.md).
STATE_DEVIATIONS = np.array(
    [600.0, 250.0, np.radians(1.0), np.radians(1.0), np.radians(2.0), 0.5, 5.0, 0.05, 1.0]
)
#: Half-widths of the input deviations sampled for W (Phi, delta_e rad).
INPUT_DEVIATIONS = np.array([0.1, np.radians(3.0)])


def state_deviations(notch=None, q_scale: float = 1.0) -> np.ndarray:
    """Half-widths of the state deviations `sample_disturbance` draws for a model.

    `STATE_DEVIATIONS` for the CM and DM (9 states). For the ECM (`notch` given) the
    notch filter's two states follow, at twice their steady size for a q of `q_scale`
    (`fahv.model.notch.NotchFilter.state_scale`).

    Parameters
    ----------
    notch : fahv.model.notch.NotchFilter or None
        The filter the ECM carries, or None for the CM / DM.
    q_scale : float
        Scale of q [rad/s] the filter's states are sized for (the TP model's state scale
        of q).

    Returns
    -------
    (9,) or (11,) ndarray
        Deviation half-widths, units of x (h ft, V ft/s, angles rad, ...).

    Raises
    ------
    ValueError
        If `q_scale` is not a positive finite number.
    """
    if notch is None:
        return STATE_DEVIATIONS.copy()
    if not (np.isfinite(q_scale) and q_scale > 0.0):
        raise ValueError(f"state_deviations: q_scale must be positive and finite, got {q_scale}")
    return np.concatenate([STATE_DEVIATIONS, 2.0 * np.asarray(notch.state_scale(q_scale), float)])


@dataclass(frozen=True)
class DisturbanceSet:
    """Box W = {|Delta_j| <= w_max_j}, eq. (19), and its parts.

    Attributes
    ----------
    w_max : (n,) ndarray
        Half-widths of W (with margin), deviation units of x.
    parts : dict[str, (n,) ndarray]
        Largest |Delta_j| of each source alone (no margin): "model", "parameters",
        "fault", and "total" (all at once).
    margin : float
    n_samples : int
    """

    w_max: np.ndarray
    parts: dict
    margin: float
    n_samples: int

    def dominant(self) -> list[str]:
        """Name of the largest single source ("model", "parameters", "fault") per state."""
        names = ["model", "parameters", "fault"]
        return [
            names[int(np.argmax([self.parts[k][j] for k in names]))] for j in range(self.w_max.size)
        ]


def sample_disturbance(
    vehicle,
    tp,
    Ts: float,
    uncertainty: dict[str, float],
    rho_f: float,
    dx_half: np.ndarray,
    du_half: np.ndarray,
    n_samples: int,
    seed: int,
    margin: float,
    n_sub: int = 10,
    progress=None,
    notch=None,
    constant: str = "bounded",
) -> DisturbanceSet:
    """Bound W by sampling, eq. (13)-(19).

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    tp : fahv.model.tp_model.TPModel
        Continuous polytopic model; discretised here with Ts.
    Ts : float
        Sampling period [s].
    uncertainty : dict
        Relative parameter bounds (e.g. `fahv.plant.PAPER_UNCERTAINTY`).
    rho_f : float
        Elevator effectiveness after the fault.
    dx_half : (n,) ndarray
        Half-widths of the state deviations x = x_s - x_r sampled (unscaled); n = 9
        for a CM/DM model, 11 for the ECM (notch states last).
    du_half : (2,) ndarray
        Half-widths of the input deviations u = u_s - u_r sampled.
    n_samples : int
    seed : int
        Seed of `numpy.random.default_rng`.
    margin : float
        Factor >= 1 applied to the sampled maximum.
    n_sub : int
        RK4 steps per Ts for the nonlinear one-step prediction.
    progress : callable, optional
        Iterable wrapper (tqdm).
    notch : fahv.model.notch.NotchFilter, optional
        Required when `tp.kind == "ecm"`: the one-step predictions then use the
        ECM (eq. 40) and the trim x_r' of eq. (41).
    constant : {"bounded", "estimated"}
        Whether W keeps the constant part Delta_0 of the parameter error (module
        docstring) or leaves it to an online estimate.

    Returns
    -------
    DisturbanceSet
        `parts` also holds "constant": the largest |Delta_0_j| (no margin).

    Raises
    ------
    ValueError
        If margin < 1, dx_half has the wrong length or is not finite, or `constant`
        is unknown.
    """
    if margin < 1.0:
        raise ValueError(f"disturbance margin must be >= 1, got {margin}")
    if constant not in ("bounded", "estimated"):
        raise ValueError(f"disturbance constant must be 'bounded' or 'estimated', got {constant!r}")
    kind = "ecm" if tp.kind == "ecm" else "cm"
    n = tp.A_vertices.shape[1]
    dx_half = np.asarray(dx_half, float)
    if dx_half.shape != (n,) or not np.all(np.isfinite(dx_half)):
        raise ValueError(f"disturbance dx_half must have {n} finite entries, got {dx_half!r}")
    rng = np.random.default_rng(seed)
    env = vehicle.envelope
    disc = tp.discretize(Ts)
    vp = vehicle.params
    names = list(uncertainty)
    parts = {k: np.zeros(n) for k in ("model", "parameters", "fault", "total", "constant")}
    rng_iter = range(n_samples) if progress is None else progress(range(n_samples))

    nom = make_model(kind, vp, notch).f

    for _ in rng_iter:
        hc = rng.uniform(env.h_min, env.h_max)
        Vc = rng.uniform(env.V_min, env.V_max)
        tr = trim(vehicle, hc, Vc)
        x_r = tr.x_r_ecm if kind == "ecm" else tr.x_r
        x = rng.uniform(-1, 1, n) * dx_half
        xs = x_r + x
        # keep the scheduling point inside the envelope
        xs[0] = np.clip(xs[0], env.h_min, env.h_max)
        xs[1] = np.clip(xs[1], env.V_min, env.V_max)
        x = xs - x_r
        u = rng.uniform(-1, 1, 2) * du_half
        us = tr.u_r + u
        w = tp.weights(xs[0], xs[1])
        x_lpv = np.tensordot(w, disc.A, 1) @ x + np.tensordot(w, disc.B, 1) @ u
        vpp = perturb(
            vp, uncertainty, dict(zip(names, rng.choice([-1.0, 1.0], len(names)), strict=True))
        )
        uf = us.copy()
        uf[DELTA_E] *= rho_f

        per = make_model(kind, vpp, notch).f
        x_nom = rk4_step(nom, xs, us, Ts, n_sub) - x_r
        x_par = rk4_step(per, xs, us, Ts, n_sub) - x_r
        x_flt = rk4_step(nom, xs, uf, Ts, n_sub) - x_r
        x_all = rk4_step(per, xs, uf, Ts, n_sub) - x_r
        # constant part: the parameter error of one step from the trim point itself
        c0 = rk4_step(per, x_r, tr.u_r, Ts, n_sub) - rk4_step(nom, x_r, tr.u_r, Ts, n_sub)
        parts["constant"] = np.maximum(parts["constant"], np.abs(c0))
        if constant == "estimated":
            x_par = x_par - c0
            x_all = x_all - c0
        for key, val in (
            ("model", x_nom - x_lpv),
            ("parameters", x_par - x_nom),
            ("fault", x_flt - x_nom),
            ("total", x_all - x_lpv),
        ):
            parts[key] = np.maximum(parts[key], np.abs(val))
    return DisturbanceSet(
        w_max=margin * parts["total"], parts=parts, margin=margin, n_samples=n_samples
    )
