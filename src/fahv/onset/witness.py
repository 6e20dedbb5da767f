"""A lower bound of the onset transient: the worst onset a tube set's assumptions allow.

The onset bound (`fahv.onset.bound.onset_bound`) is an upper bound of the error's
Z_8 norm after the onset of an elevator loss. `onset_witness` is the matching lower
bound on the same model: an explicit scenario, re-simulated step by step, that every
certificate on those assumptions must cover. If its level exceeds 1 at a loss, no
analysis on the tube set's assumptions certifies that loss.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from fahv.control.mpc.estimator import elevator_share
from fahv.errors import DesignError


@dataclass(frozen=True)
class OnsetWitness:
    """An onset scenario inside a tube set's own assumptions that leaves Z_8 (or comes closest).

    A lower bound of what any analysis of the onset on the tube set's assumptions can
    certify (`onset_witness`): one closed-loop vertex held throughout, a
    disturbance sequence inside the bound's box, one nonlinear jump sample and the
    estimate's most favourable elevator direction. `level` is the Z_8 norm of the
    error that sequence reaches, re-simulated step by step.

    Attributes
    ----------
    level : float
        The Z_8 norm the scenario reaches with the estimate's most favourable column,
        re-simulated.
    vertex, sample, direction : int
        Indices of the vertex, the jump sample and the estimate's direction (-1: none).
    step : int
        Steps after the onset at which the level is reached (0: the onset's own step).
    pre_steps : int
        Steps of the disturbance sequence before that.
    pulse : float
        The Z_8 norm the onset's part alone reaches at that step (the rest is the
        disturbance sequence's).
    level_any_column : float
        The level a scenario of the search reaches whichever column the estimate projects
        on (the smallest over the columns of z' e at each column's peak, <= `level`):
        > 1 shows that no certificate on these assumptions keeps e in Z_8.
    """

    level: float
    vertex: int
    sample: int
    direction: int
    step: int
    pre_steps: int
    pulse: float
    level_any_column: float


def _z_norm(X, Ninv):
    """Z_8 norms sqrt(x' N_8^-1 x) of the rows of X (..., 8)."""
    return np.sqrt(np.sum((X @ Ninv) * X, axis=-1))  # (a 3-operand einsum was 10x slower)


def _pulse_run(Acl_8, Ninv, J_s, c, b, gamma, g_e, steps):
    """e_p over `steps` steps at every vertex, for S jumps and D estimate directions.

    The onset's part of the error at the vertex A, from the jump J_s of sample s with
    the share c_s,d b_d along the estimate's direction b_d, is linear in the jump
    (`onset_witness`): e_k = u_k + c_s,d v_k, with u_0 = J_s,
    u_k = A u_k-1 + (1 - gamma)^k J_s, and v_0 = 0, v_k = A v_k-1 + ((1 - g_e)^k -
    (1 - gamma)^k) b_d. One recursion per sample and one per direction, combined, in
    place of one per pair; in the coordinates z = C' e (N_8^-1 = C C'), where the Z_8
    norm is the Euclidean one. One compiled loop over the vertices, spread over the
    cores (`_pulse_kernel`).

    Parameters
    ----------
    Acl_8 : (R, 8, 8) ndarray
    Ninv : (8, 8) ndarray
        N_8^-1.
    J_s : (S, 8) ndarray
        The jumps.
    c : (S, D) ndarray
        Their shares along the directions (zero without an elevator estimate).
    b : (D, 8) ndarray
        The directions.
    gamma, g_e : float
        The estimate's gains per step (g_e along b).
    steps : int

    Returns
    -------
    best : (S, D, R) ndarray
        The largest Z_8 norm of e_k over the steps.
    k_best : (S, D, R) ndarray of int
        Its step.
    e_best : (S, D, R, 8) ndarray
        The error there.
    """
    C = np.linalg.cholesky(Ninv)
    Aw = np.ascontiguousarray(np.einsum("ji,rjk->rik", C, Acl_8) @ np.linalg.inv(C.T))
    k = np.arange(steps)
    a = (1.0 - gamma) ** k
    g = (1.0 - g_e) ** k - a
    best, k_best, z_best = _pulse_kernel()(
        Aw, np.ascontiguousarray(J_s @ C), np.ascontiguousarray(c, dtype=float),
        np.ascontiguousarray(b @ C), a, g,
    )  # fmt: skip
    return best, k_best, np.linalg.solve(C.T, z_best[..., None])[..., 0]


@functools.cache
def _pulse_kernel():
    """The loop of `_pulse_run` compiled by numba, parallel over the vertices."""
    import numba

    def loop(Aw, U0, c, B, a, g):  # pragma: no cover - compiled
        """Returns best (S, D, R), k_best (S, D, R) and z_best (S, D, R, n)."""
        R, n = Aw.shape[0], Aw.shape[1]
        S, D, steps = U0.shape[0], B.shape[0], a.shape[0]
        best = np.empty((S, D, R))
        k_best = np.zeros((S, D, R), np.int64)
        z_best = np.empty((S, D, R, n))
        for r in numba.prange(R):
            u = np.empty((S, n))
            v = np.zeros((D, n))
            f = np.empty(n)
            u[:, :] = U0
            for s in range(S):
                top = 0.0
                for i in range(n):
                    top += U0[s, i] * U0[s, i]
                for d in range(D):
                    best[s, d, r] = top
                    z_best[s, d, r, :] = U0[s]
            for k in range(1, steps):
                for s in range(S):
                    for i in range(n):
                        acc = a[k] * U0[s, i]
                        for j in range(n):
                            acc += Aw[r, i, j] * u[s, j]
                        f[i] = acc
                    u[s, :] = f
                for d in range(D):
                    for i in range(n):
                        acc = g[k] * B[d, i]
                        for j in range(n):
                            acc += Aw[r, i, j] * v[d, j]
                        f[i] = acc
                    v[d, :] = f
                for s in range(S):
                    for d in range(D):
                        q = 0.0
                        for i in range(n):
                            x = u[s, i] + c[s, d] * v[d, i]
                            q += x * x
                        if q > best[s, d, r]:
                            best[s, d, r], k_best[s, d, r] = q, k
                            for i in range(n):
                                z_best[s, d, r, i] = u[s, i] + c[s, d] * v[d, i]
        return np.sqrt(best), k_best, z_best

    return numba.njit(cache=True, parallel=True, error_model="numpy")(loop)


def _search(Acl_8, Ninv, bound, J8, c, b, gamma, g_e, top, steps, pre_steps, candidates):
    """The scenario of largest level over the jump samples (`onset_witness`).

    For each of the `top` samples the estimate's most favourable direction is taken;
    returns (level, sample, direction, vertex, step, error there) of the largest of
    those levels.
    """
    AT = np.transpose(Acl_8, (0, 2, 1))
    found = None
    tops = np.argsort(-_z_norm(J8, Ninv))[:top]
    runs = _pulse_run(Acl_8, Ninv, J8[tops], c[tops], b, gamma, g_e, steps)
    for i, s in enumerate(tops):
        best, k_best, e_best = (x[i] for x in runs)
        D = len(best)
        # the sequence's share for the best candidates of every direction, all at once
        cand = np.argsort(-best, axis=1)[:, :candidates]  # (D, C)
        rows = np.arange(D)[:, None]
        z = (e_best[rows, cand] @ Ninv) / best[rows, cand][..., None]  # (D, C, 8)
        v, reach = z.reshape(-1, 8), np.zeros(z.shape[0] * z.shape[1])
        At = AT[cand.ravel()]
        for _ in range(pre_steps):
            reach += np.abs(v) @ bound
            v = np.matmul(At, v[:, :, None])[:, :, 0]
        total = best[rows, cand] + reach.reshape(cand.shape)
        levels = []
        for d in range(D):
            j = int(np.argmax(total[d]))
            levels.append((float(total[d, j]), int(cand[d, j])))
        d = int(np.argmin([lv for lv, _ in levels]))  # the estimate's most favourable b
        if found is None or levels[d][0] > found[0]:
            r = levels[d][1]
            found = (levels[d][0], int(s), d, r, int(k_best[d, r]), e_best[d, r].copy())
    return found


def _resimulate(A, bound, J_s, Jb, z, k, pre_steps, gamma, g_e):
    """The scenario step by step from e = 0 at the vertex A, the error it reaches.

    w = sign(z' A^t) bound at t steps before the target, the jump J_s at `k` steps
    before it and the estimate's remaining error after.
    """
    signs, v = [], z.copy()
    for _ in range(pre_steps):
        signs.append(np.sign(v))
        v = A.T @ v
    e = np.zeros(8)
    for t in range(pre_steps - 1, -1, -1):  # steps pre_steps - 1 ... 0 before the target
        e = A @ e + signs[t] * bound
        m = k - t  # this step's index after the onset (0: the onset's own step)
        if m == 0:
            e = e + J_s
        elif m > 0:
            e = e + (1.0 - g_e) ** m * Jb + (1.0 - gamma) ** m * (J_s - Jb)
    return e


def _elevator_shares(J, gamma_e, directions, projection_scale):
    """The jumps' shares c (S, D) along the elevator directions b (D, 8), and the gain."""
    if gamma_e is None:  # no elevator part: p_k = (1 - gamma)^k J
        return np.zeros((len(J), 1)), np.zeros((1, 8)), 1.0
    directions = np.atleast_2d(np.asarray(directions, float))
    scale = np.asarray(projection_scale, float)
    if not 0.0 < gamma_e <= 1.0 or directions.shape[1:] != (9,) or scale.shape != (9,):
        raise ValueError(f"onset_witness: gamma_e {gamma_e}, directions "
                         f"{directions.shape}, projection_scale {scale.shape}")  # fmt: skip
    c = np.stack([elevator_share(J, b, scale) for b in directions], axis=1)
    return c, directions[:, 1:], float(gamma_e)


def onset_witness(Acl_8, N_8, bound, J, gamma: float, *, gamma_e: float | None = None,
                  directions=None, projection_scale=None, top: int = 6, steps: int = 60,
                  pre_steps: int = 3000, candidates: int = 50) -> OnsetWitness:  # fmt: skip
    """The worst onset of a loss the tube set's own assumptions allow, found explicitly.

    The model is the onset bound's own: e = e_w + e_p along any vertex sequence, e_w
    driven by w in the box `bound`, e_p from 0 by the jump J at the onset's step and
    then by what the estimate has not yet removed, p_k = (1 - gamma_e)^k J_b +
    (1 - gamma)^k J_r (J_b = the share of J along the estimate's elevator direction b,
    J_r the rest; p_k = (1 - gamma)^k J without gamma_e). Held at one vertex A, e_p is
    computed exactly for each of the `top` jumps of largest Z_8 norm and every
    direction b, for `steps` steps; at its largest Z_8 norm, at step k with direction
    z = N_8^-1 e_p / ||e_p||, the disturbance w_(k-1-t) = sign(z' A^t) * bound for
    t < `pre_steps` (the last `pre_steps` steps up to k) adds sum_t |z' A^t| . bound
    to z' e. The direction b is taken as the most favourable (the smallest such level
    over the vertices searched): that level, `level_any_column`, is reached whichever
    elevator column the estimate projects on. The winning scenario is re-simulated step
    by step from e = 0 (its norm `level` is at least z' e). Every ingredient (vertex,
    jump sample, w inside the box, the estimate's model) is one the certificate must
    cover, so `level_any_column` above 1 shows that no analysis on these assumptions
    keeps e in Z_8 at this loss.

    Parameters
    ----------
    Acl_8 : (R, 8, 8) ndarray
        The tube set's closed-loop vertices A_8 + B_8 F_8, each a candidate to hold.
    N_8 : (8, 8) ndarray
        Z_8's shape: the level reported is the Z_8 norm sqrt(e' N_8^-1 e).
    bound : (8,) array_like
        Half-widths of the disturbance box (state units per period).
    J : (S, 9) ndarray
        Jump samples J / rho_f, h first (state units per period), e.g. from
        `fahv.onset.bound.onset_jumps`; the estimate's share is taken of all nine
        rows, as it computes it, and the error of the last eight.
    gamma : float
        The estimate's gain per step, in (0, 1].
    gamma_e, directions, projection_scale
        As `fahv.onset.bound.onset_bound` (directions (D, 9), scale (9,)).
    top : int
        Jump samples tried (largest Z_8 norm first).
    steps : int
        Steps after the onset searched for the peak.
    pre_steps : int
        Length of the disturbance sequence.
    candidates : int
        Vertices (largest onset part first) given the disturbance sequence.

    Returns
    -------
    OnsetWitness

    Raises
    ------
    ValueError
        On inconsistent shapes or gains out of range.
    DesignError
        If the re-simulated level falls short of the constructed one (a defect).
    """
    Acl_8, N_8, J = (np.asarray(v, float) for v in (Acl_8, N_8, J))
    bound = np.asarray(bound, float)
    if Acl_8.shape[1:] != (8, 8) or N_8.shape != (8, 8) or bound.shape != (8,) \
            or J.ndim != 2 or J.shape[1] != 9 or not 0.0 < gamma <= 1.0:  # fmt: skip
        raise ValueError(f"onset_witness: shapes Acl_8 {Acl_8.shape}, N_8 {N_8.shape}, bound "
                         f"{bound.shape}, J {J.shape}; gamma {gamma}")  # fmt: skip
    J8 = J[:, 1:]
    c, b, g_e = _elevator_shares(J, gamma_e, directions, projection_scale)
    Ninv = np.linalg.inv(N_8)
    level, s, d, r, k, e_peak = _search(Acl_8, Ninv, bound, J8, c, b, gamma, g_e, top, steps,
                                        pre_steps, candidates)  # fmt: skip
    Jb = c[s, d] * b[d]
    z = Ninv @ e_peak / _z_norm(e_peak, Ninv)
    e = _resimulate(Acl_8[r], bound, J8[s], Jb, z, k, pre_steps, gamma, g_e)
    simulated = float(_z_norm(e, Ninv))
    if simulated < level * (1.0 - 1e-9) or not np.isfinite(simulated):
        raise DesignError(f"onset_witness: the re-simulated level {simulated:.6f} falls short "
                          f"of the constructed {level:.6f}")  # fmt: skip
    return OnsetWitness(simulated, r, s, d if gamma_e is not None else -1, k, pre_steps,
                        float(_z_norm(e_peak, Ninv)), level)  # fmt: skip
