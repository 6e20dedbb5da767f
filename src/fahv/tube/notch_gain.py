"""A tube gain designed for the loop through the notch on q, with its certificate.

`fahv.tube.notch_loop.notch_tube` certifies the loop u = F e' for the tube's own
F. `notch_gain` designs the gain on e' (q' = notch(q) for q) together with the
loop's ellipsoid, by convex steps in continuation over the notch's pole damping.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid, output_feedback_step
from fahv.synthesis.rpi_level import vertex_levels
from fahv.tube.notch_loop import (
    NotchLoop,
    notch_certificate,
    notch_closed_loop,
    notch_loop_scale,
)


@dataclass(frozen=True)
class NotchGain:
    """A tube gain designed for the loop through the notch and its check (`notch_gain`).

    Attributes
    ----------
    F : (m, n) ndarray
        Gain on e' (e with q' = notch(q) for q) [(-, rad) per state unit].
    P : (n + 2, n + 2) ndarray
        Its ellipsoid in xi = [e; chi] (coordinates of
        `fahv.tube.notch_loop.notch_closed_loop`).
    loop : NotchLoop
        The exact re-check at the case's notch
        (`fahv.tube.notch_loop.notch_certificate` against the tightening the
        design applies), `designed` set.
    steps : tuple of (float, float)
        (eps_p, gamma) of every convex step taken, in order.
    """

    F: np.ndarray
    P: np.ndarray
    loop: NotchLoop
    steps: tuple[tuple[float, float], ...]

    def joint(self, notch, Ts: float, iq: int) -> np.ndarray:
        """Shape (n + m, n + m) of (e, u - v) over E(P): [[I, 0], K] P [[I, 0], K]'.

        `notch`, `Ts`, `iq` as `fahv.tube.notch_loop.notch_closed_loop` (the
        case's notch).
        """
        m, n = self.F.shape
        _, K = notch_closed_loop(np.zeros((1, n, n)), np.zeros((1, n, m)), self.F, notch, Ts, iq)
        J = np.vstack([np.hstack([np.eye(n), np.zeros((n, 2))]), K])
        return J @ self.P @ J.T


def notch_gain(A, B, F, N, w_max, notch, Ts: float, iq: int, lam: float = 0.995,
               continuation=(), max_steps: int = 8, variant: str = "", tightening=None,
               log=print) -> NotchGain | None:  # fmt: skip
    """Design the tube gain of the loop through the notch on q together with its certificate.

    `fahv.tube.notch_loop.notch_tube` certifies the loop u = F e' for the tube's own
    F; a gain that
    tolerates the filter's lag less well than the loop needs (the eight-state tube set with
    its attitude supports bounded: spectral radius above 1 through deep notches) has no
    such certificate. Every assumption the tube was bounded under holds for any gain
    whose loop has an ellipsoid RPI for W with its projection in Z and its input
    support within the tightening the nominal QP applies: the gain on e' is free. It is
    a static output feedback of the loop in xi = [e; chi], u - v = F T xi, designed by
    convex steps in (F, P) (`fahv.synthesis.invariant_ellipsoid.output_feedback_step`: the
    dilated RPI condition, the output structure on the slack, whitened by the last
    ellipsoid), in continuation over the notch's pole damping: from `F`'s own ellipsoid
    at the first eps_p of `continuation` (one is sought with a 100 x looser input
    support bound), each certified gain starts the next, the case's `notch.eps_p`
    last. Each eps_p is stepped until the exact re-check
    (`fahv.tube.notch_loop.notch_certificate`: level over every vertex and corner
    of W, s, the supports against the tightening) certifies it, or gamma gains less than
    1e-3 (stalled), or `max_steps` steps; each eps_p before the case's must end
    certified. A start certified as it is is kept
    (steps that only shrink the ellipsoid were measured not to carry a gain further).

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube's error dynamics (unscaled).
    F : (m, n) ndarray
        The gain the continuation starts from (the tube's).
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W.
    notch : fahv.model.notch.NotchFilter
        The case's notch (its eps_p is the last of the continuation).
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.
    lam : float
        Contraction factor of the S-procedure.
    continuation : sequence of float
        Pole dampings eps_p before the case's, increasing, each below it.
    max_steps : int
        Most convex steps per eps_p.
    variant : str
    tightening : (m,) array_like, optional
        The tightening the nominal QP applies, which the loop's input supports must keep
        within; default F Z's support (the tube's, when `F` is the tube's gain).
    log : callable
        One line per step.

    Returns
    -------
    NotchGain or None
        The last gain reached at the case's eps_p with its re-check (`loop.certified`
        says whether it is certified); None if an earlier eps_p of the continuation was
        not certified or no start ellipsoid exists.

    Raises
    ------
    ValueError
        On inconsistent shapes, or a continuation that is not increasing below the
        case's eps_p.
    DesignError
        If a solve's slack is singular
        (`fahv.synthesis.invariant_ellipsoid.output_feedback_step`).
    """
    A, B, F, N = (np.asarray(v, float) for v in (A, B, F, N))
    path = [float(v) for v in continuation] + [float(notch.eps_p)]
    if any(b <= a for a, b in zip(path, path[1:], strict=False)) or path[0] <= 0.0:
        raise ValueError(f"notch_gain: continuation {list(continuation)} must increase "
                         f"from above 0 to below the case's eps_p {notch.eps_p}")  # fmt: skip
    w = np.asarray(w_max, float)
    tight = (
        np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
        if tightening is None
        else np.asarray(tightening, float)
    )
    steps: list[tuple[float, float]] = []
    loop = None
    for eps_p in path:
        nf = replace(notch, eps_p=eps_p)
        P = _start(A, B, F, N, w, nf, Ts, iq, tight, lam)
        if P is None:
            log(f"variant {variant}: notch gain at eps_p {eps_p:g}: no ellipsoid for the start "
                "gain: NOT designed")  # fmt: skip
            return None
        F, P, loop, taken = _step(A, B, F, P, N, w, nf, Ts, iq, tight, lam, max_steps, variant,
                                  log)  # fmt: skip
        steps += taken
        if not loop.certified and eps_p != path[-1]:
            log(f"variant {variant}: notch gain at eps_p {eps_p:g} NOT certified: the "
                "continuation stops")  # fmt: skip
            return None
    return NotchGain(F, P, loop, tuple(steps))


def _start(A, B, F, N, w, nf, Ts, iq, tight, lam):
    """F's own ellipsoid of the loop through the notch `nf`, or None if there is none.

    Its input support is bounded 100 x looser than `tight`.
    """
    w_xi = np.r_[w, 0.0, 0.0]
    Acl, K = notch_closed_loop(A, B, F, nf, Ts, iq)
    ell = invariant_ellipsoid(Acl, w, notch_loop_scale(N, nf, Ts, iq), N, K, 100.0 * tight,
                              lambda P: vertex_levels(Acl, P, w_xi), lam)  # fmt: skip
    return ell.P


def _step(A, B, F, P, N, w, nf, Ts, iq, tight, lam, max_steps, variant, log):
    """Convex steps from (F, P) at the notch `nf` until certified, stalled or `max_steps`.

    Returns the last (F, P), its re-check and the (eps_p, gamma) of the steps taken.
    """
    R, n, m = B.shape
    w_xi = np.r_[w, 0.0, 0.0]
    B0 = np.concatenate([B, np.zeros((R, 2, m))], axis=1)
    _, T = notch_closed_loop(A[:1], np.zeros((1, n, n)), np.eye(n), nf, Ts, iq)
    A0, _ = notch_closed_loop(A, B, np.zeros_like(F), nf, Ts, iq)
    loop = replace(notch_certificate(A, B, F, N, w, nf, Ts, iq, P, variant, tight),
                   designed=True)  # fmt: skip
    steps, best = [], np.inf
    for _ in range(max_steps):
        if loop.certified:
            break
        got = output_feedback_step(
            A0, B0, T, w, F, P, N, tight,
            lambda Fk, Pk: vertex_levels(notch_closed_loop(A, B, Fk, nf, Ts, iq)[0], Pk, w_xi),
            lam,
        )  # fmt: skip
        if got is None:
            log(f"variant {variant}: notch gain at eps_p {nf.eps_p:g}: the step's LMI failed")
            break
        F, P = got.F, got.P
        steps.append((nf.eps_p, got.gamma))
        loop = replace(notch_certificate(A, B, F, N, w, nf, Ts, iq, P, variant, tight),
                       designed=True)  # fmt: skip
        log(f"variant {variant}: notch gain at eps_p {nf.eps_p:g}: step gamma {got.gamma:.4f} "
            f"({got.n_blocks} vertices held): s {loop.s:.4f}, level {loop.level:.6f}, "
            f"supports " + " / ".join(f"{v:.4f}" for v in loop.supports)
            + (" certified" if loop.certified else ""))  # fmt: skip
        if got.gamma > best - 1e-3:
            break  # stalled
        best = got.gamma
    return F, P, loop, steps
