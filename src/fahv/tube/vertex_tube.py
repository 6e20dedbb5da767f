"""The paper's vertex tube (`tube.form: vertices`) checked against its own assumptions.

The tube Z = {e : e' N^-1 e <= 1} of LMI (24) is RPI for e+ = (A_i + B_i F) e + w, w in
the sampled box W, at every TP vertex i. That statement is only as true as W: W must
bound the one-step disturbance of the perturbed, faulty nonlinear plant over every state
and input the closed loop can reach. `certify_tube` states that domain
(`fahv.bounds.domain.CertificateDomain`), bounds the disturbance over it
(`fahv.bounds.one_step_bound.bound_disturbance`), computes the exact RPI level and
its margin (`fahv.synthesis.rpi_level`), and bounds the onset of a loss by the level
recursion of the S-procedure certificate (`onset_levels`). It reports
(`VertexCertificate`, its lines in `fahv.certificate.report`); it does not
refuse a design.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.bounds.domain import CertificateDomain, nominal_half_widths, schedule_points
from fahv.bounds.one_step_bound import DisturbanceBound, bound_disturbance
from fahv.bounds.plant_step import plant_step
from fahv.bounds.vertices import gain_vertices
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
        Steady bound and jump, scaled like `mu`.
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


@dataclass(frozen=True)
class RPICheck:
    """The exact RPI level of the vertex tube for W over every gain tau' F (`rpi_check`).

    Attributes
    ----------
    level : float
        Worst one-step level over the vertices (the gains tau' F included) and the
        corners of W (`fahv.synthesis.rpi_level.worst_level`).
    n_vertices, n_corners : int
        Vertices and corners of W checked.
    growth : float
        The factor W may grow by (`fahv.synthesis.rpi_level.rpi_margin`).
    tau : float
        Adjustable factor (eq. 48).
    level_tau, w_prime : float or None
        For tau < 1: the level of eq. (53)'s tau Z for W and the factor g for which it is
        RPI (W' = g W, eq. 47).
    """

    level: float
    n_vertices: int
    n_corners: int
    growth: float
    tau: float
    level_tau: float | None = None
    w_prime: float | None = None


def rpi_check(A, B, tube, tau) -> RPICheck:
    """The exact RPI level for W over every gain tau' F, and for tau < 1 that of tau Z."""
    w = tube.w_max
    At, Bt = gain_vertices(A, B, tau)  # every gain tau' F, tau' in [tau, 1] (eq. 48)
    level, _ = worst_level(At, Bt, tube.F, tube.N, w)
    growth = rpi_margin(At, Bt, tube.F, tube.N, w)
    if tau >= 1:
        return RPICheck(level, At.shape[0], 2**w.size, growth, tau)
    # eq. (53)'s smaller tube tau Z: RPI for the incomplete set W' only
    level_t = worst_level(A, B, tube.F, tube.N, w, tau)[0]
    w_prime = rpi_margin(A, B, tube.F, tube.N, w, tau)
    return RPICheck(level, At.shape[0], 2**w.size, growth, tau, level_t, w_prime)


@dataclass(frozen=True)
class VertexCertificate:
    """The vertex tube checked against its own assumptions (`certify_tube`).

    Attributes
    ----------
    rpi : RPICheck
    skipped : str or None
        Why the check over the domain was not made (None: it was).
    n_schedules : int
        Scheduling points of the domain (`certificate.schedules`).
    domain : CertificateDomain or None
    bound : fahv.bounds.one_step_bound.DisturbanceBound or None
        The one-step bound over the domain.
    w_max : (n,) ndarray
        Half-widths of W.
    rho_min : float
        Smallest elevator effectiveness of the fault range.
    est_tau : float or None
        The disturbance estimate's time constant [s] (`mpc.est_tau`).
    onset_level_max : float or None
        Largest level bound after the onset of the loss 1 - rho_min (`onset_levels`).
    """

    rpi: RPICheck
    skipped: str | None
    n_schedules: int
    domain: CertificateDomain | None = None
    bound: DisturbanceBound | None = None
    w_max: np.ndarray | None = None
    rho_min: float = 1.0
    est_tau: float | None = None
    onset_level_max: float | None = None

    @property
    def ratio(self) -> np.ndarray:
        """Bound / W per row (the domain check made)."""
        return self.bound.w_bound / self.w_max

    @property
    def slack(self) -> np.ndarray:
        """(W - bound) / W per row (the domain check made)."""
        return (self.w_max - self.bound.w_bound) / self.w_max

    @property
    def closed(self) -> bool:
        """True if the bound over the domain lies inside W (the domain check made)."""
        return bool(np.all(self.bound.w_bound <= self.w_max))

    def summary(self) -> dict:
        """JSON-able record (the design summary's `certificate`).

        `certified` (bool), `rpi_level`, `rpi_growth`; for tau < 1 `rpi_level_tau`
        and `w_prime`; then either `domain` (why it was skipped) or the bound per row
        (`w_bound`, `w_ratio`, `slack`, `corner_max`, `worst`),
        `onset_level_max` and the `domain`.
        """
        r = self.rpi
        out = {"rpi_level": r.level, "rpi_growth": r.growth, "certified": False}
        if r.tau < 1:
            out.update(rpi_level_tau=r.level_tau, w_prime=r.w_prime)
        if self.skipped is not None:
            out["domain"] = self.skipped
            return out
        bnd, level_max = self.bound, self.onset_level_max
        out.update(
            certified=self.closed and level_max <= 1.0 and r.level <= 1.0,
            w_bound=bnd.w_bound.tolist(), w_ratio=self.ratio.tolist(),
            slack=self.slack.tolist(), corner_max=bnd.corner_max.tolist(),
            worst=bnd.worst, onset_level_max=level_max, domain=self.domain.summary(),
        )  # fmt: skip
        return out


def _domain(spec, mpc, vehicle, tube, tau, u_lo, u_hi, rho_min, x_default) -> CertificateDomain:
    """The domain of the certificate: the QP's nominal ranges plus Z, the inputs plus F Z."""
    nominal, notes = nominal_half_widths(mpc, x_default)
    z_box = tube.z_box  # under the whole W the error stays in Z, also for tau < 1
    t = tau * tube.tightening  # the input deviation tau F e, e in Z
    unc = {k: v * spec["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    return CertificateDomain(
        schedule_points(vehicle.envelope, spec["certificate"]["schedules"]), nominal + z_box,
        nominal, u_lo - t, u_hi + t, unc, tuple(sorted({rho_min, 1.0})), spec["Ts"],
        spec["plant_substeps"], notes,
    )  # fmt: skip


def certify_tube(spec: dict, vehicle, tp, trim_map, A, B, tube, tau, u_lo, u_hi, rho_min,
                 Dx, x_default, progress=None) -> VertexCertificate:  # fmt: skip
    """Check the tube certificate against its own assumptions (no exception).

    Computes: the exact worst one-step level over the vertices and the corners of W and
    the factor by which W may grow (`rpi_check`); the stated domain; the bound of
    the one-step disturbance over it per row, as a multiple of W; whether the
    certificate is closed (the bound inside W); the onset of a loss of 1 - rho_min at the
    largest elevator of the domain (`onset_levels`). Its lines, with margins, are
    `fahv.certificate.report.vertex_certificate_lines`.

    Parameters
    ----------
    spec : dict
        Validated design data (`mpc`, `certificate`, `uncertainty`, `Ts`,
        `plant_substeps`).
    vehicle, tp, trim_map
        As `fahv.bounds.one_step_bound.bound_disturbance`.
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube certificate (fault vertices included).
    tube : fahv.synthesis.feedback.TubeDesign
    tau : float
        Adjustable factor (eq. 48). The RPI check covers every gain tau' F, tau' in
        [tau, 1] (`fahv.bounds.vertices.gain_vertices`); for tau < 1 it also
        reports the factor g for which eq. (53)'s tau Z is RPI (W' = g W, eq. 47).
    u_lo, u_hi : (2,) ndarray
        Tightened nominal input limits (absolute).
    rho_min : float
    Dx : (n,) ndarray
        State scaling of the tube certificate (mu is in these units).
    x_default : (n,) ndarray
        Assumed nominal deviations of the states no QP row bounds.
    progress : callable, optional
        Iterable wrapper (tqdm) of the bound's loop.

    Returns
    -------
    VertexCertificate
        Its `VertexCertificate.summary` is the design summary's `certificate`.
    """
    rpi = rpi_check(A, B, tube, tau)
    n_s = spec["certificate"]["schedules"]
    if n_s == 0 or A.shape[1] != 9:
        why = (
            "skipped (certificate.schedules: 0)"
            if n_s == 0
            else (f"not evaluated for the {A.shape[1]}-state design model (9-state CM/DM only)")
        )
        return VertexCertificate(rpi, why, n_s)
    mpc = spec.get("mpc") or {f.name: f.default for f in MPC_SECTION_FIELDS}
    dom = _domain(spec, mpc, vehicle, tube, tau, u_lo, u_hi, rho_min, x_default)
    w = tube.w_max
    bnd = bound_disturbance(dom, vehicle, tp, trim_map, progress)
    # onset of the design loss at the largest elevator of the domain, estimate's pulse
    gamma, _ = estimator_gains(spec["Ts"], mpc.get("est_tau", 0.0))
    J = fault_jump(vehicle, trim_map, float(dom.u_hi[1]), rho_min, spec["Ts"],
                   spec["plant_substeps"])  # fmt: skip
    Ls = onset_levels(tube.lam, tube.mu, np.minimum(bnd.w_bound, w) / Dx, J / Dx, gamma, 2000)
    return VertexCertificate(rpi, None, n_s, dom, bnd, w, rho_min, mpc.get("est_tau"),
                             float(Ls.max()))  # fmt: skip
