"""The paper's vertex tube (``tube.form: vertices``) checked against its own assumptions.

The tube Z = {e : e' N^-1 e <= 1} of LMI (24) is RPI for e+ = (A_i + B_i F) e + w, w in
the sampled box W, at every TP vertex i. That statement is only as true as W: W must
bound the one-step disturbance of the perturbed, faulty nonlinear plant over every state
and input the closed loop can reach. :func:`certify_tube` states that domain
(:class:`fahv.bounds.domain.CertificateDomain`), bounds the disturbance over it
(:func:`fahv.bounds.one_step_bound.bound_disturbance`), computes the exact RPI level and
its margin (:mod:`fahv.synthesis.rpi_level`), and bounds the onset of a loss by the level
recursion of the S-procedure certificate (:func:`onset_levels`). It reports; it does not
refuse a design.
"""

from __future__ import annotations

import numpy as np

from fahv.bounds.domain import CertificateDomain, nominal_half_widths, schedule_points
from fahv.bounds.one_step_bound import bound_disturbance
from fahv.bounds.plant_step import plant_step
from fahv.bounds.vertices import gain_vertices
from fahv.certificate.report import (
    adjustable_tube_line,
    closed_line,
    domain_bound_line,
    domain_line,
    rpi_check_line,
    vertex_onset_line,
)
from fahv.control.mpc.estimator import estimator_gains
from fahv.control.mpc.settings import MPC_SECTION_FIELDS
from fahv.model.vehicle import DELTA_E
from fahv.plant.rk4 import params_records
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.rpi_level import rpi_margin, worst_level


def onset_levels(lam, mu, w_base, pulse, gamma, n_steps, level0=1.0) -> np.ndarray:
    """Tube levels after a pulse in the estimate's error, from the S-procedure certificate.

    The certificate of LMI (24) gives, at every vertex and for every e and w,
    (A_cl e + w)' N^-1 (A_cl e + w) <= lam e' N^-1 e + sum_j mu_j w_j^2. With the
    disturbance estimate d <- d + gamma (r - d), the error of the estimate obeys
    eps_k = (1 - gamma) eps_k-1 + (r_k - r_k-1): a jump J of the residual (a fault
    onset, the constant part at the first step) decays as (1 - gamma)^k J on top of
    the steady bound w_base. Hence the level bound

        L_k+1 = lam L_k + sum_j mu_j (w_base,j + (1 - gamma)^k J_j)^2.

    Parameters
    ----------
    lam : float
    mu : (n,) ndarray
        Certificate of the tube (scaled coordinates).
    w_base, pulse : (n,) ndarray
        Steady bound and jump, scaled like ``mu``.
    gamma : float
        Estimator gain Ts / est_tau (1: no estimate memory).
    n_steps : int
    level0 : float
        Level at the jump (1: the error on the boundary of Z).

    Returns
    -------
    (n_steps + 1,) ndarray
        Level bounds L_0 .. L_n.
    """
    L = np.empty(n_steps + 1)
    L[0] = level0
    decay = 1.0
    for k in range(n_steps):
        w = np.asarray(w_base) + decay * np.asarray(pulse)
        L[k + 1] = lam * L[k] + float(np.asarray(mu) @ w**2)
        decay *= 1.0 - gamma
    return L


def fault_jump(vehicle, trim_map, u_hi_abs: float, rho: float, Ts, n_sub) -> np.ndarray:
    """Jump of the one-step residual at the onset of a loss, per state (9,).

    The worst over the trim grid of |Phi(x_r, (Phi_r, rho d)) - Phi(x_r, (Phi_r, d))|
    at d = u_hi_abs (the largest elevator the domain allows), nominal parameters.
    """
    hs, Vs = trim_map.h_grid, trim_map.V_grid
    X, U = [], []
    for h in hs:
        for V in Vs:
            x, u = trim_map(h, V)
            X.append(np.asarray(x[:9], float))
            U.append(np.array([u[0], u_hi_abs]))
    X, U = np.array(X), np.array(U)
    Uf = U.copy()
    Uf[:, DELTA_E] *= rho
    recs = params_records([vehicle.params] * len(X))
    return np.max(np.abs(plant_step(X, Uf, recs, Ts, n_sub) - plant_step(X, U, recs, Ts, n_sub)),
                  axis=0)  # fmt: skip


def _rpi_check(A, B, tube, tau, log) -> dict:
    """The exact RPI level for W over every gain tau' F, and for tau < 1 that of tau Z."""
    w = tube.w_max
    At, Bt = gain_vertices(A, B, tau)  # every gain tau' F, tau' in [tau, 1] (eq. 48)
    level, _ = worst_level(At, Bt, tube.F, tube.N, w)
    growth = rpi_margin(At, Bt, tube.F, tube.N, w)
    log(rpi_check_line(level, At.shape[0], 2**w.size, growth, tau))
    out = {"rpi_level": level, "rpi_growth": growth, "certified": False}
    if tau < 1:  # eq. (53)'s smaller tube tau Z: RPI for the incomplete set W' only
        level_t = worst_level(A, B, tube.F, tube.N, w, tau)[0]
        w_prime = rpi_margin(A, B, tube.F, tube.N, w, tau)
        log(adjustable_tube_line(tau, level_t, w_prime))
        out.update(rpi_level_tau=level_t, w_prime=w_prime)
    return out


def _domain(case, mpc, vehicle, tube, tau, u_lo, u_hi, rho_min, x_default) -> CertificateDomain:
    """The domain of the certificate: the QP's nominal ranges plus Z, the inputs plus F Z."""
    nominal, notes = nominal_half_widths(mpc, x_default)
    z_box = tube.z_box  # under the whole W the error stays in Z, also for tau < 1
    t = tau * tube.tightening  # the input deviation tau F e, e in Z
    unc = {k: v * case["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    return CertificateDomain(
        schedule_points(vehicle.envelope, case["certificate"]["schedules"]), nominal + z_box,
        nominal, u_lo - t, u_hi + t, unc, tuple(sorted({rho_min, 1.0})), case["Ts"],
        case["plant_substeps"], notes,
    )  # fmt: skip


def certify_tube(case: dict, vehicle, tp, trim_map, A, B, tube, tau, u_lo, u_hi, rho_min,
                 Dx, x_default, log, progress=None) -> dict:  # fmt: skip
    """Check the tube certificate against its own assumptions and report (no exception).

    Prints, with margins (:mod:`fahv.certificate.report`): the exact worst one-step level
    over the vertices and the corners of W and the factor by which W may grow; the
    stated domain; the bound of the one-step disturbance over it per row, as a multiple
    of W; whether the certificate is closed (the bound inside W); the onset of a loss of
    1 - rho_min at the largest elevator of the domain (:func:`onset_levels`).

    Parameters
    ----------
    case : dict
        Validated case data (``mpc``, ``certificate``, ``uncertainty``, ``Ts``,
        ``plant_substeps``).
    vehicle, tp, trim_map
        As :func:`fahv.bounds.one_step_bound.bound_disturbance`.
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube certificate (fault vertices included).
    tube : fahv.synthesis.feedback.TubeDesign
    tau : float
        Adjustable factor (eq. 48). The RPI check covers every gain tau' F, tau' in
        [tau, 1] (:func:`fahv.bounds.vertices.gain_vertices`); for tau < 1 it also
        reports the factor g for which eq. (53)'s tau Z is RPI (W' = g W, eq. 47).
    u_lo, u_hi : (2,) ndarray
        Tightened nominal input limits (absolute).
    rho_min : float
    Dx : (n,) ndarray
        State scaling of the tube certificate (mu is in these units).
    x_default : (n,) ndarray
        Assumed nominal deviations of the states no QP row bounds.
    log : callable
    progress : callable, optional
        Iterable wrapper (tqdm) of the bound's loop.

    Returns
    -------
    dict
        Summary (JSON-able): ``certified`` (bool), per-row ``w_ratio`` and ``slack``,
        ``rpi_level``, ``rpi_growth``, ``onset_level_max``, the domain; for tau < 1
        ``rpi_level_tau`` (tau Z for W) and ``w_prime`` (g).
    """
    out = _rpi_check(A, B, tube, tau, log)
    n_s = case["certificate"]["schedules"]
    if n_s == 0 or A.shape[1] != 9:
        why = (
            "skipped (certificate.schedules: 0)"
            if n_s == 0
            else (f"not evaluated for the {A.shape[1]}-state design model (9-state CM/DM only)")
        )
        log(f"certificate domain: {why}; the tube certificate is NOT checked over its domain")
        out["domain"] = why
        return out
    mpc = case.get("mpc") or {f.name: f.default for f in MPC_SECTION_FIELDS}
    dom = _domain(case, mpc, vehicle, tube, tau, u_lo, u_hi, rho_min, x_default)
    log(domain_line(dom, n_s))
    w = tube.w_max
    bnd = bound_disturbance(dom, vehicle, tp, trim_map, progress)
    ratio = bnd.w_bound / w
    log(domain_bound_line(bnd.n_evaluations, ratio, (w - bnd.w_bound) / w))
    closed = bool(np.all(bnd.w_bound <= w))
    log(closed_line(closed, ratio, out["rpi_growth"]))
    # onset of the design loss at the largest elevator of the domain, estimate's pulse
    gamma, _ = estimator_gains(case["Ts"], mpc.get("est_tau", 0.0))
    J = fault_jump(vehicle, trim_map, float(dom.u_hi[1]), rho_min, case["Ts"],
                   case["plant_substeps"])  # fmt: skip
    Ls = onset_levels(tube.lam, tube.mu, np.minimum(bnd.w_bound, w) / Dx, J / Dx, gamma, 2000)
    log(vertex_onset_line(rho_min, dom.u_hi[1], mpc.get("est_tau"), float(Ls.max())))
    out.update(
        certified=closed and Ls.max() <= 1.0 and out["rpi_level"] <= 1.0,
        w_bound=bnd.w_bound.tolist(), w_ratio=ratio.tolist(),
        slack=((w - bnd.w_bound) / w).tolist(), corner_max=bnd.corner_max.tolist(),
        worst=bnd.worst, onset_level_max=float(Ls.max()), domain=dom.summary(),
    )  # fmt: skip
    return out
