"""The tube feedback through a notch filter on q, certified in the loop's own states.

The RPI certificate (LMI 24, the exact level) is for e+ = (A_i + B_i F) e + w: the gain
acts on the measured q. A variant with the notch (eq. 38) on the q feedback runs u = F e'
with q' = notch(q) in e', which adds the filter's two states to the loop
(`notch_closed_loop`). `notch_loop` checks its stability at every vertex (a
necessary condition); `notch_tube` seeks an ellipsoid of the loop RPI for W whose
projection lies in Z and whose input support lies within the tightening, and
`notch_certificate` re-checks a given one exactly. A gain designed for the loop is
`fahv.tube.notch_gain.notch_gain`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fahv.model.notch import DiscreteNotch
from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid
from fahv.synthesis.rpi_level import vertex_levels
from fahv.tube.lines import notch_loop_line


@dataclass(frozen=True)
class NotchLoop:
    """The tube feedback through a variant's notch filter on q, at the design's vertices.

    The RPI certificate (LMI 24, the exact level) is for e+ = (A_i + B_i F) e + w: the
    gain acts on the measured q. A variant with the notch (eq. 38) on the q feedback
    runs u = F e' with q' = notch(q) in e', which adds the filter's two states to the
    loop. Always: the loop's stability at every vertex with the filter in it, a
    *necessary* condition for any tube to hold (`notch_loop`). With
    `notch_tube` (or `notch_certificate`): an RPI certificate of that loop in
    its own states, `s`, `level` and `supports` below.

    Attributes
    ----------
    variant : str
    omega, eps_p : float
        Notch centre [rad/s] and pole damping [-].
    rho : float
        Largest spectral radius over the vertices of the loop with the filter.
    rho_q : float
        The same on the measured q (the loop the certificate is for).
    vertex : int
        Vertex of `rho`.
    s : float or None
        With an RPI certificate of the loop with the filter (`notch_tube`): the
        projection of its invariant ellipsoid on e lies in s Z (None: not sought; inf:
        no ellipsoid found).
    level : float or None
        That ellipsoid's exact worst one-step level over the vertices and the corners
        of W (`fahv.synthesis.rpi_level.worst_level`).
    supports : tuple of float or None
        The input deviation's support over it, per input [-, rad] (through q').
    tightening : tuple of float or None
        The tightening the design applies, F Z's support per input [-, rad].
    designed : bool
        True if the loop runs a gain designed for it
        (`fahv.tube.notch_gain.notch_gain`), not the tube's.
    w_ratio : tuple of float or None
        With a designed gain: the closure of the loop on W's assumptions, every entry
        <= 1 (`fahv.design.tube_set_design.designed_notch_loop`: the loop's altitude
        bound over the tube set's H, then the one-step disturbance bound over the loop's own
        set of (e, u - v) per row of W as a fraction of W); None: not bounded, the tube's
        own closure applies.
    active : tuple of int
        The vertices the last LMI solve of `notch_tube` held (constraint
        generation; empty if none was solved): where a later design starts.
    """

    variant: str
    omega: float
    eps_p: float
    rho: float
    rho_q: float
    vertex: int
    s: float | None = None
    level: float | None = None
    supports: tuple[float, ...] | None = None
    tightening: tuple[float, ...] | None = None
    designed: bool = False
    w_ratio: tuple[float, ...] | None = None
    active: tuple[int, ...] = ()

    @property
    def stable(self) -> bool:
        """True if the loop with the filter is stable at every vertex."""
        return self.rho < 1.0

    @property
    def certified(self) -> bool:
        """True if the loop with the filter is certified (`notch_tube`).

        An ellipsoid of the loop with the filter is RPI for W (exact level <= 1),
        projects into Z (s <= 1) and keeps the input deviation within the tightening:
        every assumption the tube's W was bounded under then holds with the filter.
        """
        return (
            self.s is not None
            and self.level is not None
            and self.s <= 1.0
            and self.level <= 1.0
            and all(a <= b * (1.0 + 1e-9) for a, b in zip(self.supports, self.tightening,
                                                          strict=True))
            and (self.w_ratio is None or max(self.w_ratio) <= 1.0)
        )  # fmt: skip

    def line(self) -> str:
        """The design log's line of the loop (`fahv.tube.lines.notch_loop_line`)."""
        return notch_loop_line(self)

    def summary(self) -> dict:
        """JSON-ready record: the attributes, `stable`, `certified` and `ellipsoid`.

        `ellipsoid` says whether one was sought and found ("not sought", "infeasible",
        "found"); `s` is None unless one was found (strict JSON has no inf).
        """
        found = self.s is not None and np.isfinite(self.s)
        state = "found" if found else ("not sought" if self.s is None else "infeasible")
        record = {k: v for k, v in self.__dict__.items() if k != "active"}
        return {**record, "s": self.s if found else None, "ellipsoid": state,
                "stable": self.stable, "certified": self.certified}  # fmt: skip


def notch_closed_loop(A, B, F, notch, Ts: float, iq: int) -> tuple[np.ndarray, np.ndarray]:
    """The tube loop with the notch filter on q, in the states xi = [e; chi] (`notch_loop`).

    The filter is eq. (38) in the state-space form of eq. (39), discretised as the
    notch_filter node runs it (`fahv.model.notch.DiscreteNotch`), in the
    coordinates chi(k) = x_q(k) - B_d q(k) (a standard state space of the same recursion):
    chi+ = A_d chi + (A_d B_d + B_d) q, q' = C_q chi + (C_q B_d + D_q) q. With u = F e'
    (e' is e with q' for e_q):

        xi+ = A_xi,i xi + [I; 0] w,   A_xi,i = [[A_i + B_i F S, B_i F_q C_q], [b E_q, A_d]],
        u = K xi,                     K = [F S, F_q C_q],

    with S the identity but (C_q B_d + D_q) at (iq, iq). The notch's effect on the
    nominal's own q is an exogenous signal and enters neither.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube's error dynamics.
    F : (m, n) ndarray
        Tube gain on e.
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.

    Returns
    -------
    A_xi : (R, n + 2, n + 2) ndarray
    K : (m, n + 2) ndarray
        The input deviation the loop applies, u - v = K xi.

    Raises
    ------
    ValueError
        If the shapes disagree or `iq` is out of range.
    """
    A, B, F = (np.asarray(v, float) for v in (A, B, F))
    R, n, _ = A.shape
    if B.shape[:2] != (R, n) or F.shape != (B.shape[2], n) or not 0 <= iq < n:
        raise ValueError(f"notch_loop: shapes A {A.shape}, B {B.shape}, F {F.shape}, iq {iq}")
    dn = DiscreteNotch(notch, Ts)
    b = dn.A_d @ dn.B_d + dn.B_d
    S = np.eye(n)
    S[iq, iq] = dn.C_q @ dn.B_d + dn.D_q
    K = np.hstack([F @ S, F[:, iq : iq + 1] * dn.C_q[None, :]])
    Acl = np.zeros((R, n + 2, n + 2))
    Acl[:, :n, :] = np.concatenate([A, np.zeros((R, n, 2))], axis=2) + B @ K
    Acl[:, n:, iq] = b
    Acl[:, n:, n:] = dn.A_d
    return Acl, K


def notch_loop(A, B, F, notch, Ts: float, iq: int, variant: str = "") -> NotchLoop:
    """Stability of the tube loop with the notch filter on q at every vertex (`NotchLoop`).

    The spectral radius of each vertex of `notch_closed_loop`, next to the loop's
    on the measured q (A_i + B_i F).

    Parameters
    ----------
    A, B, F, notch, Ts, iq
        As `notch_closed_loop`.
    variant : str
        Name for the report.

    Returns
    -------
    NotchLoop

    Raises
    ------
    ValueError
        If the shapes disagree or `iq` is out of range.
    """
    return _notch_loop(A, B, F, notch, Ts, iq, variant)[0]


def _notch_loop(A, B, F, notch, Ts, iq, variant):
    """`notch_loop` with the loop's A_xi and K of `notch_closed_loop`."""
    Acl, K = notch_closed_loop(A, B, F, notch, Ts, iq)
    A, B, F = (np.asarray(v, float) for v in (A, B, F))
    rho = np.abs(np.linalg.eigvals(Acl)).max(axis=1)
    rho_q = np.abs(np.linalg.eigvals(A + B @ F)).max(axis=1)
    k = int(np.argmax(rho))
    loop = NotchLoop(variant, float(notch.omega_z), float(notch.eps_p), float(rho[k]),
                     float(rho_q.max()), k)  # fmt: skip
    return loop, Acl, K


def notch_loop_scale(N, notch, Ts: float, iq: int) -> np.ndarray:
    """Scaling (n + 2,) of the loop's states xi = [e; chi] for its LMIs (`notch_tube`).

    e by Z's supports sqrt(diag N); the filter's two states chi at their steady size for a
    constant q of Z's q support, |(I - A_d)^-1 (A_d B_d + B_d)| (plus 1e-3, so that
    neither is zero), in the coordinates of `notch_closed_loop`.

    Parameters
    ----------
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.

    Returns
    -------
    (n + 2,) ndarray
        Positive scale, units of e then of the filter's states.
    """
    dn = DiscreteNotch(notch, Ts)
    z = np.sqrt(np.diag(np.asarray(N, float)))
    gain = np.abs(np.linalg.solve(np.eye(2) - dn.A_d, dn.A_d @ dn.B_d + dn.B_d))
    return np.r_[z, (gain + 1e-3) * z[iq]]


#: Vertices `notch_tube` adds per pass of its constraint generation: its loop has
#: ten states (55 unknowns in P), and its last solves hold 100-140 blocks; 24 per pass
#: took 0.66 of the time of 12 per pass from scratch on cm_certified's notch loop.
NOTCH_ADD = 24

#: The projection `notch_tube` asks of the loop's ellipsoid first, s <= NOTCH_S_MAX
#: (Z scaled by it): a certificate with a 2 % margin, not the smallest ellipsoid, which
#: touches the invariance condition at many more vertices (cm_certified's loop on mode 1:
#: 64 blocks and 14 s for s <= 0.98, 154 blocks and 81 s for the smallest s, 0.776; on
#: mode 2: 160 blocks and 62 s, 184 and 123 s for 0.951). If none exists the smallest is
#: sought, which tells how far from 1 the loop is.
NOTCH_S_MAX = 0.98


def notch_tube(A, B, F, N, w_max, notch, Ts: float, iq: int, lam: float = 0.995,
               variant: str = "", active: int = 40, start=None) -> NotchLoop:  # fmt: skip
    """The tube loop with the notch filter on q, certified RPI in its own states.

    The loop of `notch_closed_loop`, xi = [e; chi] with the filter's two states,
    under u = F e' (q' = notch(q) in e'), is checked as it runs: an ellipsoid
    E = {xi' P^-1 xi <= 1} RPI for the box W on e at every vertex is sought with the
    S-procedure (`fahv.synthesis.invariant_ellipsoid.invariant_ellipsoid`), its
    projection on e bounded by s Z and its input deviation K xi by F Z's support (the
    tightening of eq. 30) per input: first one with s <= `NOTCH_S_MAX` (a margin, not
    the smallest s), and only if there is none the smallest s. The solver's answer is
    then re-checked exactly: the worst one-step level of E over every vertex and every
    corner of W
    (`fahv.synthesis.rpi_level.vertex_levels`).
    If the level is at most 1, s at most 1 and the supports within the tightening, every
    assumption W was bounded under (e in Z, the applied input within the tightening)
    holds with the filter in the loop (`NotchLoop.certified`).

    This is the loop the law runs because its error's q is formed with the same filter
    on the nominal's q as well, q' - notch(q_r + q_n) = notch(q - q_r - q_n)
    (`fahv.control.tube_mpc.TubeMPCLaw`); with the measured q filtered alone the
    error would also carry (notch - 1)(q_r + q_n), which this certificate does not cover.

    Parameters
    ----------
    A : (R, n, n) ndarray
    B : (R, n, m) ndarray
        Vertices of the tube's error dynamics (unscaled).
    F : (m, n) ndarray
        Tube gain.
    N : (n, n) ndarray
        Tube shape, Z = {e' N^-1 e <= 1}.
    w_max : (n,) array_like
        Half-widths of W.
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    iq : int
        Index of q in e.
    lam : float
        Contraction factor of the S-procedure certificate.
    variant : str
    active : int
        Vertex blocks of the first solve of the constraint generation.
    start : (a,) array_like of int, optional
        The vertices an earlier design's solve held (its loop's `active`): the first
        solve's blocks in place of `active` chosen by spectral radius.

    Returns
    -------
    NotchLoop
        With `s`, `level`, `supports`, `tightening` and `active` set when an
        ellipsoid was found (`s` None if the loop is unstable, inf if the LMI is
        infeasible).

    Raises
    ------
    ValueError
        On inconsistent shapes.
    DesignError
        If the solver's ellipsoid fails the re-check of its LMI blocks.
    """
    loop, Acl, K = _notch_loop(A, B, F, notch, Ts, iq, variant)
    F, N = np.asarray(F, float), np.asarray(N, float)
    tightening = tuple(np.sqrt(np.einsum("ij,jk,ik->i", F, N, F)).tolist())
    if not loop.stable:
        return replace(loop, tightening=tightening)
    D = notch_loop_scale(N, notch, Ts, iq)
    w_xi = np.r_[np.asarray(w_max, float), 0.0, 0.0]
    def seek(s_max, first):
        return invariant_ellipsoid(Acl, w_max, D, N, K, np.asarray(tightening),
                                   lambda P: vertex_levels(Acl, P, w_xi), lam, active,
                                   add=NOTCH_ADD, start=first, s_max=s_max)  # fmt: skip

    ell = seek(NOTCH_S_MAX, start)
    if not ell.found:
        ell = seek(None, ell.active)
    if not ell.found:
        return replace(loop, s=float("inf"), tightening=tightening,
                       active=tuple(int(i) for i in ell.active))  # fmt: skip
    checked = _recheck(loop, Acl, K, F, N, w_max, ell.P)
    return replace(checked, active=tuple(int(i) for i in ell.active))


def notch_certificate(A, B, F, N, w_max, notch, Ts: float, iq: int, P,
                      variant: str = "", tightening=None) -> NotchLoop:  # fmt: skip
    """Re-check a given ellipsoid of the tube loop with the notch (`notch_tube`).

    Exact, whatever found P: the worst one-step level of E = {xi' P^-1 xi <= 1} over
    every vertex of the loop in [e; chi] and every corner of W
    (`fahv.synthesis.rpi_level.vertex_levels`), the factor s of its projection on e
    into Z, and its input support through q' against F Z's (the tightening). Arguments
    as `notch_tube`; `P` is (n + 2, n + 2) in the coordinates of
    `notch_closed_loop`. `tightening` (m,), if given, is the tightening the
    supports are compared with in place of F Z's: for a gain designed for the loop
    (`fahv.tube.notch_gain.notch_gain`) it is the tube set's, which the nominal QP
    applies.

    Returns
    -------
    NotchLoop
        `certified` if level <= 1, s <= 1 and every support within the tightening.

    Raises
    ------
    ValueError
        On inconsistent shapes (P included).
    """
    loop, Acl, K = _notch_loop(A, B, F, notch, Ts, iq, variant)
    return _recheck(loop, Acl, K, F, N, w_max, P, tightening)


def _recheck(loop, Acl, K, F, N, w_max, P, tightening=None) -> NotchLoop:
    """The exact re-check of `notch_certificate` on a built loop (A_xi, K)."""
    F, N, P = (np.asarray(v, float) for v in (F, N, P))
    n = N.shape[0]
    if P.shape != (n + 2, n + 2):
        raise ValueError(f"notch_certificate: P has shape {P.shape}, expected {(n + 2, n + 2)}")
    level = float(vertex_levels(Acl, P, np.r_[np.asarray(w_max, float), 0.0, 0.0]).max())
    Li = np.linalg.inv(np.linalg.cholesky(N))
    s = float(np.sqrt(np.linalg.eigvalsh(Li @ P[:n, :n] @ Li.T).max()))
    supports = np.sqrt(np.einsum("ij,jk,ik->i", K, P, K))
    if tightening is None:
        tightening = np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
    tightening = np.asarray(tightening, float)
    if tightening.shape != supports.shape:
        raise ValueError(
            f"notch_certificate: tightening has shape {tightening.shape}, expected {supports.shape}"
        )
    return replace(loop, s=s, level=level, supports=tuple(supports.tolist()),
                   tightening=tuple(tightening.tolist()))  # fmt: skip
