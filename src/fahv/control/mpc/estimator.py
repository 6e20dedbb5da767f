"""State-disturbance estimate of the nominal model and the steady-state shift it implies.

The nominal model is z+ = A z + B u + d with d a constant additive state disturbance
estimated from the measured steps (`DisturbanceEstimator`, a first-order filter
per run with gains of `estimator_gains`, faster along the elevator column of B,
`elevator_share`). d collects the constant part of the parameter uncertainty
(sec. 5.1 of Yang et al. 2022), the trim part (rho_f - 1) delta_e,r of a loss of
elevator effectiveness (eq. 15-16) and the mean modelling error, so that the tracking is
offset-free and the tube only holds what is left. The steady state of the set point
moves by (x_d, u_d) = (H_x d, H_u d), the solution of (A - I) x_d + B u_d + d = 0 with
h_d = V_d = 0 (`steady_state_shift`), as for the offset-free tracking MPC with an
artificial steady state of Limon et al. (2010).
"""

from __future__ import annotations

import numpy as np

from fahv.control.reference import mv


def estimator_gains(
    Ts: float, est_tau: float, est_tau_elevator: float = 0.0
) -> tuple[float, float | None]:
    """Gains per step of the disturbance estimate (`DisturbanceEstimator`).

    Parameters
    ----------
    Ts : float
        Control period [s].
    est_tau : float
        Time constant of the estimate [s] (`mpc.est_tau`; 0: no estimate).
    est_tau_elevator : float
        Time constant along the elevator column [s] (`mpc.est_tau_elevator`; 0: none).

    Returns
    -------
    gamma : float
        min(1, Ts / est_tau) (first-order filter, docs/theory/certificate.md); 1 without an
        estimate.
    gamma_e : float or None
        min(1, Ts / est_tau_elevator); None without it or without an estimate.
    """
    if est_tau <= 0.0:
        return 1.0, None
    return min(1.0, Ts / est_tau), (min(1.0, Ts / est_tau_elevator)
                                    if est_tau_elevator > 0.0 else None)  # fmt: skip


def elevator_share(v, b, scale) -> np.ndarray:
    """Coefficient c of the share of v along b in the metric diag(scale)^-2: c b is it.

    c = (b' S v) / (b' S b), S = diag(scale)^-2: the part of a residual (or of a jump of
    it) that lies along the elevator column b of the model's B, the direction a loss of
    effectiveness or a bias acts in (eq. 15-16).

    Parameters
    ----------
    v, b : (..., p) array_like
        Vectors and directions (broadcast against each other), state units.
    scale : (p,) array_like
        Positive state scale of the metric (the design scaling Dx).

    Returns
    -------
    (...,) ndarray
        c per vector (the projection is `c[..., None] * b`).
    """
    bs, vs = b / scale, v / scale
    return np.einsum("...i,...i->...", bs, vs) / np.einsum("...i,...i->...", bs, bs)


#: How the estimate starts (node parameter `mpc.est_start`): `first`, the first residual
#: initialises it (a loop on the exact state); `mean`, the mean of the residuals so far
#: until the filter's gain takes over (a loop on a noisy state estimate); `zero`, from
#: d = 0 with the filter's own gains from the first residual on (no single residual
#: moves the steady input by more than gamma of itself).
EST_STARTS = ("first", "mean", "zero")


class DisturbanceEstimator:
    """Constant additive state disturbance d (B, p) of the scheduled model, for B runs.

    Each step, the one-step residual of each run's scheduled model,
    r = dx_k - A dx_{k-1} - B du_{k-1} (deviations from the trim at the scheduling
    point), is filtered: d <- d + gamma (r - d) with gamma = Ts / tau_est (first
    order, time constant tau_est). d collects what the nominal model misses at the
    current operating point and that varies slowly: the constant part of the parameter
    uncertainty (sec. 5.1), the trim part (rho_f - 1) delta_e,r of a loss of
    effectiveness (eq. 16), the mean of the modelling error. The nominal model then
    predicts with d, so the tube only has to hold what is left (docs/theory/certificate.md).

    With a gain `gamma_e` along the elevator column b of the scheduled model's B, the
    share of r - d along b (the projection in the metric of `scale`,
    b (b' S r) / (b' S b), S = diag(scale)^-2) is filtered with gamma_e instead: a loss of
    effectiveness or an elevator bias acts along b (eq. 15-16), so with gamma_e = 1 the
    estimate knows it one step after the onset while the other directions keep the slow
    filter (gamma = 1 in every direction made the loop unstable, docs/theory/certificate.md).

    Parameters
    ----------
    n_runs : int
        Runs B.
    p : int
        Measured states (9 for a CM design, 11 for the ECM).
    gamma : float
        Filter gain in (0, 1].
    gamma_e : float, optional
        Filter gain in (0, 1] along the elevator column (None: gamma in every direction).
    scale : (p,) array_like, optional
        State scale of the projection's metric (needed with `gamma_e`).
    start : str
        How d starts (`EST_STARTS`). `first`: the first residual initialises d.
        `mean`: the mean of the residuals so far, the gains max(gamma, 1/k) and
        max(gamma_e, 1/k) at the k-th residual, so the first initialises d, as with
        `first`, and the filter's own gains take over after 1/gamma residuals (the
        growing-memory start of a fading-memory filter: the least-squares estimate of a
        constant from k noisy residuals). `zero`: d = 0 and the filter's own gains from
        the first residual on. `mean` and `zero` are for a loop on a state estimate,
        whose every residual carries the estimator's correction noise.

    Raises
    ------
    ValueError
        If a gain is not in (0, 1], `gamma_e` comes without a positive `scale` of
        length p, or `start` is not one of `EST_STARTS`.
    """

    def __init__(self, n_runs: int, p: int, gamma: float, gamma_e: float | None = None,
                 scale=None, start: str = EST_STARTS[0]) -> None:  # fmt: skip
        if start not in EST_STARTS:
            raise ValueError(f"estimator start must be one of {EST_STARTS}, got {start!r}")
        if not 0.0 < gamma <= 1.0:
            raise ValueError(f"estimator gain gamma must be in (0, 1], got {gamma}")
        if gamma_e is not None:
            if not 0.0 < gamma_e <= 1.0:
                raise ValueError(f"estimator gain gamma_e must be in (0, 1], got {gamma_e}")
            scale = np.asarray(scale, float) if scale is not None else np.zeros(0)
            if scale.shape != (p,) or not np.all(scale > 0.0):
                raise ValueError(f"estimator scale must be ({p},) and positive, got {scale}")
        self.gamma = float(gamma)
        self.gamma_e = None if gamma_e is None else float(gamma_e)
        self.scale = scale
        self.d = np.zeros((n_runs, p))
        #: False until the first residual initialises d (`first`, `mean`); `zero` starts
        #: the filter at d = 0.
        self.started = start == "zero"
        self.mean_start = start == "mean"
        #: residuals filtered so far
        self.n_seen = 0

    def update(self, A, B, dx_prev, du_prev, dx) -> np.ndarray:
        """Estimates d (B, p) [state units per step Ts] after one measured step.

        Parameters
        ----------
        A : (B, p, p) ndarray
        B : (B, p, m) ndarray
            Each run's scheduled model at the fast rate.
        dx_prev, dx : (B, p) ndarray
            Measured states of steps k - 1 and k minus each run's scheduling trim.
        du_prev : (B, m) ndarray
            Commands of step k - 1 minus the scheduling trim input.
        """
        r = (dx - mv(A, np.ascontiguousarray(dx_prev))) - mv(B, np.ascontiguousarray(du_prev))
        return self.update_residual(r, np.asarray(B)[:, :, 1])

    def update_residual(self, r: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
        """Estimates d (B, p) after one step whose residual r (B, p) is given.

        `b` (B, p) is each run's elevator column of the scheduled model, the direction
        filtered with `gamma_e` (ignored without it; required with it).

        r is what the nominal model missed in the measured step (for the nonlinear
        nominal, x_k - f_0(x_{k-1}, u_{k-1}) with f_0 one period of the nominal CM).
        The first residual initialises the filter, d = r: the vehicle was flying
        before the run's first step, so its constant model error is known from the
        first measured step; starting from d = 0 instead made every run begin with a
        start-up transient of the estimate (its error 20-48x the tube's W,
        docs/theory/nominal_mpc.md) during which the nominal input of the first move
        drifted with it beyond the bounds its QP had enforced.
        """
        self.n_seen += 1
        if self.started:
            floor = 1.0 / self.n_seen if self.mean_start else 0.0
            gamma = max(self.gamma, floor)
            e = r - self.d
            self.d = self.d + gamma * e
            if self.gamma_e is not None:
                if b is None:
                    raise ValueError("estimator: gamma_e needs the elevator column b")
                coef = elevator_share(e, b, self.scale)
                self.d = self.d + (max(self.gamma_e, floor) - gamma) * coef[:, None] * b
        else:
            self.d = np.array(r, float, copy=True)
            self.started = True
        return self.d


def steady_state_shift(A, B, Dx, Du) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state shift (x_d, u_d) = (H_x d, H_u d) of a constant state disturbance d.

    Solves (A - I) x_d + B u_d + d = 0 with h_d = V_d = 0 (n equations for the n
    unknowns x_d[2:], u_d) in the scaled coordinates of Dx, Du, for every d at once.

    Parameters
    ----------
    A : (n, n) ndarray
    B : (n, m) ndarray
        Scheduled model at the fast rate (n = m + 2 + the states after h, V).
    Dx : (n,) ndarray
    Du : (m,) ndarray
        Scaling of states and inputs.

    Returns
    -------
    Hx : (n, n) ndarray
        x_d per d (rows h, V zero).
    Hu : (m, n) ndarray
        u_d per d.

    Raises
    ------
    numpy.linalg.LinAlgError
        If the steady-state equations are singular (no steady state holds h, V
        against a constant disturbance).
    """
    n = A.shape[0]
    Dv = np.concatenate([Dx[2:], Du])
    M_ss = np.hstack([(A - np.eye(n))[:, 2:], B]) * Dv[None, :] / Dx[:, None]
    H_ss = -np.linalg.solve(M_ss, np.diag(1.0 / Dx)) * Dv[:, None]
    Hx = np.zeros((n, n))
    Hx[2:] = H_ss[: n - 2]
    return Hx, H_ss[n - 2 :]
