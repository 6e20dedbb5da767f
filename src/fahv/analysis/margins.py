"""Classical loop margins of the tube loop u = v + F e, with and without the notch on q.

With the constraints inactive the nominal part (x_r + x_n, u_r + u_n) is an internal
model driven by the reference: the only path from the plant back to its input is the
ancillary law F e, through the notch filter (eq. 38) on q when the variant runs one
(`fahv.control.tube_mpc.TubeMPCLaw` forms its error's q as
notch(q) - notch(q_r + q_n) = notch(q - q_r - q_n), so the filter sits inside the loop).
Linearised at a point of the plant model, x+ = A x + B u (discrete, period Ts), the loop is
that of `fahv.tube.notch_loop.notch_closed_loop`, xi = [x; chi] with the filter's
two states chi. It is broken at one of two places (`BREAKS`):

* `delta_e`: at the elevator input, the Phi loop closed;
  L(z) = -(delta_e the law commands) / (delta_e injected);
* `q`: at the pitch-rate sensor, every other state fed back;
  L(z) = -(q measured) / (q the law receives).

The sign makes L a negative-feedback loop transfer function, the convention of
python-control's `stability_margins` and `disk_margins`, which compute every margin
(`loop_margins`); the delay margin is the phase margin over its crossover frequency.

The plant points (`Plants`): the design point (the LPV model of eq. 12 at the
design step's (h0, V0), `design_point_plant`), the design's LPV vertices A_i, B_i
(`vertex_plants`) and the corners of the sec. 5.1 parameter box
(`corner_plants`: each corner vehicle's one-period Jacobian at the nominal trim of
the design point, as the design forms its vertices along the nominal).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

import control
from fahv.model.notch import DiscreteNotch, NotchFilter
from fahv.model.vehicle import DELTA_E, IQ, PHI

#: Where the loop is broken: the elevator input and the pitch-rate sensor.
BREAKS = ("delta_e", "q")

#: The notch pole damping eps_p of the paper (Yang et al. 2022, sec. 5.1).
PAPER_EPS_P = 0.5


@dataclass(frozen=True)
class Plants:
    """Discrete plant models x+ = A x + B u at P points (deviation coordinates).

    Attributes
    ----------
    names : tuple of str
        P point names ("design point", "vertex 3", "corner 17").
    A : (P, n, n) ndarray
    B : (P, n, m) ndarray
        State [h ft, V ft/s, alpha rad, theta rad, q rad/s, eta_1, eta_1_dot, eta_2,
        eta_2_dot] and input [Phi -, delta_e rad] matrices, one control period.
    """

    names: tuple
    A: np.ndarray
    B: np.ndarray


def notch_parts(notch: NotchFilter | None, Ts: float):
    """(A_d (k, k), b (k,), C_q (k,), d) of the filter q -> q' in chi coordinates; k = 0 if off.

    Raises ValueError if the notch cannot be sampled at Ts.

    As `fahv.tube.notch_loop.notch_closed_loop`: chi+ = A_d chi + b q,
    q' = C_q chi + d q, with b = A_d B_d + B_d and d = C_q B_d + D_q.
    """
    if notch is None:
        return np.zeros((0, 0)), np.zeros(0), np.zeros(0), 1.0
    dn = DiscreteNotch(notch, Ts)
    return dn.A_d, dn.A_d @ dn.B_d + dn.B_d, dn.C_q, float(dn.C_q @ dn.B_d + dn.D_q)


def law_gain(F, notch, Ts, n, iq):
    """The law's gain K (m, n + k) on xi = [x; chi] and the filter's rows (k, n + k).

    F (m, n) is the ancillary gain, `notch` the filter on q (None: none, k = 0), Ts
    the period [s], iq the index of q among the n states: u = F x with x's q replaced by
    the filter's output q' = C_q chi + d q (eq. 38).
    """
    A_d, b, C_q, d = notch_parts(notch, Ts)
    k = len(b)
    S = np.eye(n)
    S[iq, iq] = d
    K = np.hstack([F @ S, F[:, iq : iq + 1] * C_q[None, :]])
    rows = np.zeros((k, n + k))
    rows[:, iq] = b
    rows[:, n:] = A_d
    return K, rows


def closed_loop(A, B, F, notch: NotchFilter | None, Ts: float, iq: int = IQ) -> np.ndarray:
    """The closed tube loop xi+ = A_cl xi at every point, xi = [x; chi].

    Parameters
    ----------
    A : (P, n, n) ndarray
    B : (P, n, m) ndarray
        Plant points.
    F : (m, n) ndarray
        Ancillary gain (tau F for the adjustable law).
    notch : fahv.model.notch.NotchFilter or None
        Filter on the q feedback (None: q fed back as measured).
    Ts : float
        Control period [s].
    iq : int
        Index of q in x.

    Returns
    -------
    (P, n + k, n + k) ndarray
        k = 2 with the notch, 0 without; the filter's states last.

    Raises
    ------
    ValueError
        If the notch cannot be sampled at Ts.
    """
    A, B, F = (np.asarray(v, float) for v in (A, B, F))
    P, n, _ = A.shape
    K, rows = law_gain(F, notch, Ts, n, iq)
    k = rows.shape[0]
    top = np.concatenate([A, np.zeros((P, n, k))], axis=2) + B @ K
    return np.concatenate([top, np.broadcast_to(rows, (P, k, n + k))], axis=1)


def open_loop(A, B, F, notch: NotchFilter | None, Ts: float, break_at: str,
              iq: int = IQ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The loop broken at `break_at`: L(z) = C_L (zI - A_L)^-1 B_L at every point.

    Parameters
    ----------
    A, B, F, notch, Ts, iq
        As `closed_loop`.
    break_at : {"delta_e", "q"}
        The elevator input (Phi's loop closed) or the pitch-rate sensor (every other
        state fed back).

    Returns
    -------
    A_L : (P, n + k, n + k) ndarray
    B_L : (P, n + k, 1) ndarray
    C_L : (P, 1, n + k) ndarray
        Negative-feedback convention: w = -y closes the loop into `closed_loop`.

    Raises
    ------
    ValueError
        If `break_at` is not one of `BREAKS`.
    """
    A, B, F = (np.asarray(v, float) for v in (A, B, F))
    P, n, _ = A.shape
    K, rows = law_gain(F, notch, Ts, n, iq)
    k = rows.shape[0]
    plant = np.concatenate([np.concatenate([A, np.zeros((P, n, k))], axis=2),
                            np.broadcast_to(rows, (P, k, n + k))], axis=1)  # fmt: skip
    Bxi = np.concatenate([B, np.zeros((P, k, B.shape[2]))], axis=1)
    if break_at == "delta_e":
        A_L = plant + Bxi[:, :, PHI : PHI + 1] @ K[None, PHI : PHI + 1]
        B_L = Bxi[:, :, DELTA_E : DELTA_E + 1]
        C_L = np.broadcast_to(-K[DELTA_E : DELTA_E + 1], (P, 1, n + k))
    elif break_at == "q":
        K_q = K.copy()
        K_q[:, iq] = 0.0  # the law's q column: the injected signal instead of x_q
        _, b, _, d = notch_parts(notch, Ts)
        A_L = plant + Bxi @ K_q
        A_L[:, n:, iq] = 0.0
        B_L = np.concatenate([B @ (F[:, iq] * d), np.broadcast_to(b, (P, k))], axis=1)[..., None]
        C_L = np.zeros((P, 1, n + k))
        C_L[:, 0, iq] = -1.0
    else:
        raise ValueError(f"loop break must be one of {BREAKS}, got {break_at!r}")
    return A_L, B_L, np.ascontiguousarray(C_L)


def spectral_radius(A_cl) -> np.ndarray:
    """Largest |eigenvalue| of each closed loop (P,) [-]: below 1 if stable.

    Parameters
    ----------
    A_cl : (P, k, k) array_like

    Returns
    -------
    (P,) ndarray
    """
    return np.abs(np.linalg.eigvals(np.asarray(A_cl, float))).max(axis=1)


@dataclass(frozen=True)
class LoopMargins:
    """The classical margins of one broken loop at one point (python-control's).

    Attributes
    ----------
    break_at : str
        `BREAKS`.
    notch : str
        The notch setting's label (`NotchSetting`).
    point : str
        The plant point, or "worst of N ..." for a worst case (`worst_case`).
    rho : float
        Closed-loop spectral radius [-] (stable below 1; no margins otherwise).
    open_unstable : int
        Open-loop poles of L on or outside the unit circle.
    gm_up_db, gm_down_db : float
        Gain margins [dB]: the gain increase (inf if none) and the gain decrease (a
        negative number; -inf if none) that make the loop unstable.
    w_gm : float
        Phase crossover of the nearer of the two [rad/s] (nan if neither).
    pm_deg : float
        Phase margin [deg]: the smallest phase change (either sign) at a gain crossover.
    w_c : float
        Its gain crossover [rad/s] (nan if none).
    delay_ms : float
        Delay margin [ms]: the smallest (phase lag to -180 deg) / crossover over the
        gain crossovers (inf if none).
    dm_gain_db, dm_phase_deg : float
        Disk margin, skew 0: the gain [dB] and phase [deg] variations it guarantees.
    gain_w1_db : float
        |L| at the first flexible mode omega_1 [dB].
    """

    break_at: str
    notch: str
    point: str
    rho: float
    open_unstable: int = 0
    gm_up_db: float = math.nan
    gm_down_db: float = math.nan
    w_gm: float = math.nan
    pm_deg: float = math.nan
    w_c: float = math.nan
    delay_ms: float = math.nan
    dm_gain_db: float = math.nan
    dm_phase_deg: float = math.nan
    gain_w1_db: float = math.nan

    @property
    def stable(self) -> bool:
        """True if the closed loop is stable (spectral radius below 1)."""
        return self.rho < 1.0


def frequency_grid(Ts: float, omega_flex=(), points: int = 300) -> np.ndarray:
    """Frequencies [rad/s] of the disk margins and figures: 0.01 rad/s to below Nyquist.

    Log-spaced, plus 41 points within 15 % of each flexible mode, where the loops change
    fastest. With 300 log-spaced points cm_certified's gain and phase margins at the
    design point are within 0.005 dB and 0.001 deg of those on 3000, its disk margins
    (a least value over the grid, so from above) within 0.03 dB and 0.2 deg.

    Parameters
    ----------
    Ts : float
        Control period [s].
    omega_flex : (j,) array_like
        Flexible-mode frequencies [rad/s].
    points : int
        Log-spaced points.

    Returns
    -------
    (N,) ndarray
        Ascending, below pi / Ts.
    """
    top = 0.999 * math.pi / Ts
    w = [np.logspace(-2.0, math.log10(top), points)]
    w += [np.linspace(0.85 * f, min(1.15 * f, top), 41) for f in np.atleast_1d(omega_flex)]
    return np.unique(np.concatenate(w))


def loop_margins(L: control.StateSpace, rho: float, omega, omega_1: float,
                 labels: tuple[str, str, str]) -> LoopMargins:  # fmt: skip
    """Margins of a discrete loop L (negative feedback) whose closed loop has radius rho.

    python-control computes every margin: `control.stability_margins` (every
    crossover) on L's frequency response over `omega` (its `frd` method: the
    polynomial method finds crossovers that are not there on these loops, whose poles
    lie near z = 1), and `control.disk_margins` (skew 0) over `omega`. The delay
    margin at each gain crossover is the phase lag it takes to reach -180 deg (the phase
    margin modulo 360 deg) over the crossover frequency; the smallest is reported.

    Parameters
    ----------
    L : control.StateSpace
        SISO loop, dt = Ts.
    rho : float
        Closed-loop spectral radius [-]; at 1 or above no margin is computed.
    omega : (N,) array_like
        Frequencies [rad/s], ascending, below pi / Ts (`frequency_grid`): margins
        between them are found, none outside them.
    omega_1 : float
        First flexible mode [rad/s].
    labels : (str, str, str)
        break_at, notch, point.

    Returns
    -------
    LoopMargins
    """
    Ts, omega = float(L.dt), np.asarray(omega, float)
    unstable = int(np.sum(np.abs(L.poles()) >= 1.0))
    base = dict(zip(("break_at", "notch", "point"), labels, strict=True))
    gain_w1 = 20.0 * math.log10(abs(complex(np.squeeze(L(np.exp(1j * omega_1 * Ts))))))
    if not rho < 1.0:
        return LoopMargins(**base, rho=float(rho), open_unstable=unstable, gain_w1_db=gain_w1)
    resp = control.frequency_response(L, omega)
    data = (np.ravel(resp.magnitude), np.degrees(np.ravel(resp.phase)), omega)
    gm, pm, _, wpc, wgc, _ = (np.atleast_1d(np.asarray(v, float)) for v in
                              control.stability_margins(data, returnall=True))  # fmt: skip
    up, down = gm > 1.0, gm < 1.0
    near = int(np.argmin(np.abs(np.log(gm)))) if len(gm) else None
    i = int(np.argmin(np.abs(pm))) if len(pm) else None
    delay = float((np.radians(np.mod(pm, 360.0)) / wgc).min()) if len(pm) else math.inf
    _, dgm, dpm = control.disk_margins(L, omega, skew=0.0)
    return LoopMargins(
        **base, rho=float(rho), open_unstable=unstable,
        gm_up_db=20.0 * math.log10(gm[up].min()) if up.any() else math.inf,
        gm_down_db=20.0 * math.log10(gm[down].max()) if down.any() else -math.inf,
        w_gm=float(wpc[near]) if near is not None else math.nan,
        pm_deg=float(pm[i]) if i is not None else math.inf,
        w_c=float(wgc[i]) if i is not None else math.nan, delay_ms=1e3 * delay,
        dm_gain_db=float(dgm), dm_phase_deg=float(dpm), gain_w1_db=gain_w1,
    )  # fmt: skip


def loop_systems(plants: Plants, F, notch, Ts: float, break_at: str) -> list:
    """python-control state-space loops L (dt = Ts) of every plant point.

    Parameters
    ----------
    plants : Plants
    F : (m, n) ndarray
        Ancillary gain.
    notch : fahv.model.notch.NotchFilter or None
    Ts : float
        Control period [s].
    break_at : {"delta_e", "q"}

    Returns
    -------
    list of control.StateSpace
        One SISO loop per point, in the order of `plants.names`.

    Raises
    ------
    ValueError
        If `break_at` is not one of `BREAKS`.
    """
    A_L, B_L, C_L = open_loop(plants.A, plants.B, F, notch, Ts, break_at)
    return [control.ss(a, b, c, 0.0, dt=Ts) for a, b, c in zip(A_L, B_L, C_L, strict=True)]


def worst_case(rows: list[LoopMargins], point: str) -> LoopMargins:
    """Each margin's worst value over `rows` (one break and notch), named `point`.

    The worst of each column may come from a different row; an unstable row makes the
    result unstable (largest rho) with no margins.

    Parameters
    ----------
    rows : list of LoopMargins
        Non-empty, one break and one notch setting.
    point : str
        Name of the worst case, e.g. "worst of 20 vertices".

    Returns
    -------
    LoopMargins

    Raises
    ------
    ValueError
        If `rows` is empty.
    """
    if not rows:
        raise ValueError("worst_case: no rows")
    first = rows[0]
    rho = max(r.rho for r in rows)
    base = dict(break_at=first.break_at, notch=first.notch, point=point, rho=rho,
                open_unstable=max(r.open_unstable for r in rows),
                gain_w1_db=max(r.gain_w1_db for r in rows))  # fmt: skip
    if not rho < 1.0:
        return LoopMargins(**base)
    low = {k: min(getattr(r, k) for r in rows)
           for k in ("gm_up_db", "delay_ms", "dm_gain_db", "dm_phase_deg")}  # fmt: skip
    pm = min(rows, key=lambda r: abs(r.pm_deg))
    return LoopMargins(**base, **low, gm_down_db=max(r.gm_down_db for r in rows),
                       pm_deg=pm.pm_deg, w_c=pm.w_c)  # fmt: skip


def corner_signs(count: int) -> np.ndarray:
    """Every corner of a box of `count` parameters, (2^count, count) of -1 and +1.

    Parameters
    ----------
    count : int

    Returns
    -------
    (2^count, count) ndarray
    """
    return np.array(list(itertools.product((-1.0, 1.0), repeat=count))).reshape(-1, count)
