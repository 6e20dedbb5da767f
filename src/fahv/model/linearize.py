"""Jacobian linearisation of the longitudinal models at trim, eq. (6)-(9) and (42).

Derivatives are exact to machine precision by complex-step differentiation
(Squire & Trapp 1998; Martins, Sturdza & Alonso 2003): for a real-analytic f,
df/dx_i = Im f(x + i h e_i) / h with no subtractive cancellation, so h = 1e-30 can
be used. The model functions in `fahv.model.vehicle` are written to be analytic.
They are checked against central finite differences in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.model.jacobian import jacobians


@dataclass(frozen=True)
class LinearModel:
    """Continuous LTI model x_dot = A x + B u about a trim point, eq. (9)/(42).

    Attributes
    ----------
    A : (n, n) ndarray
    B : (n, 2) ndarray
    x_r : (n,) ndarray
        Trim state (eq. 5 / 41).
    u_r : (2,) ndarray
        Trim input.
    h, V : float
        Scheduling variables p = `[h, V]` in ft, ft/s.
    kind : str
        "dm", "cm" or "ecm".
    """

    A: np.ndarray
    B: np.ndarray
    x_r: np.ndarray
    u_r: np.ndarray
    h: float
    V: float
    kind: str


def linearize(vehicle, h: float, V: float, kind: str = "dm", notch=None) -> LinearModel:
    """Trim at p = (h, V) and linearise the model `kind` there, eq. (6)-(9).

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    h, V : float
        Flight condition [ft, ft/s], inside the envelope.
    kind : {"dm", "cm", "ecm"}
    notch : fahv.model.notch.NotchFilter, optional
        Required for "ecm".

    Returns
    -------
    LinearModel

    Raises
    ------
    EnvelopeError, TrimError
        As `fahv.model.trim.trim`.

    Examples
    --------
    >>> from fahv.model.vehicle import load_vehicle
    >>> lm = linearize(load_vehicle(), 85500.0, 7900.0, "cm")
    >>> lm.A.shape, lm.B.shape
    ((9, 9), (9, 2))
    >>> round(float(np.linalg.eigvals(lm.A).real.max()), 3)  # the unstable short period
    1.725
    """
    from fahv.model.dynamics import make_model
    from fahv.model.trim import trim

    tp = trim(vehicle, h, V, kind, notch=notch)
    model = make_model(kind, vehicle, notch)
    x_r = tp.x_r_ecm if kind == "ecm" else tp.x_r
    A, B = jacobians(model.f, x_r, tp.u_r)
    return LinearModel(A, B, x_r, tp.u_r, float(h), float(V), kind)


@dataclass(frozen=True)
class Mode:
    """One open-loop motion mode (paper Fig. 4).

    Attributes
    ----------
    name : str
        "short period", "phugoid", "altitude", "flexible 1", "flexible 2",
        "notch" (ECM filter poles) or "other".
    eigenvalues : tuple of complex
        The pole(s) of the mode [rad/s].
    wn : float
        Natural frequency |lambda| [rad/s] (largest |lambda| for real pairs).
    zeta : float
        Damping ratio -Re(lambda)/|lambda| of the first pole (1 or -1 for real poles).
    """

    name: str
    eigenvalues: tuple
    wn: float
    zeta: float


def classify_modes(
    A: np.ndarray, omega_1: float, omega_2: float, notch_poles: np.ndarray | None = None
) -> list[Mode]:
    """Name the open-loop modes of a linearised CM/DM/ECM, as in the paper's Fig. 4.

    Parameters
    ----------
    A : (n, n) ndarray
        Continuous state matrix.
    omega_1, omega_2 : float
        Structural frequencies of the vehicle file [rad/s]; the complex pair whose
        |lambda| is nearest to each is the flexible mode.
    notch_poles : ndarray, optional
        Poles of the notch filter (ECM) to label "notch".

    Returns
    -------
    list of Mode
        Flexible 1, flexible 2, short period (the real pair of largest |lambda|
        below the flexible modes, one of them unstable for this vehicle), phugoid
        (the remaining complex pair), altitude (the pole nearest 0), others.

    Examples
    --------
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> modes = classify_modes(linearize(v, 85500.0, 7900.0, "cm").A, v.params.omega_1,
    ...                        v.params.omega_2)
    >>> [mode.name for mode in modes]
    ['flexible 1', 'flexible 2', 'altitude', 'short period', 'phugoid']
    >>> [round(float(mode.wn), 2) for mode in modes]  # [rad/s]
    [19.05, 49.12, 0.0, 1.8, 0.04]
    """
    ev = list(np.linalg.eigvals(A))
    modes: list[Mode] = []

    def take(pred_idx):
        lam = ev.pop(pred_idx)
        if abs(lam.imag) > 1e-12:
            j = int(np.argmin([abs(e - np.conj(lam)) for e in ev]))
            return (lam, ev.pop(j))
        return (lam,)

    if notch_poles is not None:
        for p in notch_poles:
            if p.imag >= 0:
                i = int(np.argmin([abs(e - p) for e in ev]))
                pair = take(i)
                modes.append(Mode("notch", pair, abs(pair[0]), -pair[0].real / abs(pair[0])))
    for name, om in (("flexible 1", omega_1), ("flexible 2", omega_2)):
        cands = [i for i, e in enumerate(ev) if abs(e.imag) > 1e-9]
        i = min(cands, key=lambda k: abs(abs(ev[k]) - om))
        pair = take(i)
        modes.append(Mode(name, pair, abs(pair[0]), -pair[0].real / abs(pair[0])))
    # altitude mode: pole nearest the origin
    i = int(np.argmin(np.abs(ev)))
    lam = ev.pop(i)
    modes.append(Mode("altitude", (lam,), abs(lam), 1.0 if lam.real <= 1e-9 else -1.0))
    reals = sorted([i for i, e in enumerate(ev) if abs(e.imag) <= 1e-9], key=lambda k: -abs(ev[k]))
    if len(reals) >= 2:
        sp = (ev[reals[0]], ev[reals[1]])
        for k in sorted(reals[:2], reverse=True):
            ev.pop(k)
        modes.append(
            Mode(
                "short period",
                sp,
                max(abs(s) for s in sp),
                -1.0 if max(s.real for s in sp) > 0 else 1.0,
            )
        )
    cands = [i for i, e in enumerate(ev) if abs(e.imag) > 1e-9]
    if cands:
        pair = take(min(cands, key=lambda k: abs(ev[k])))
        modes.append(Mode("phugoid", pair, abs(pair[0]), -pair[0].real / abs(pair[0])))
    for e in ev:
        modes.append(Mode("other", (e,), abs(e), -e.real / abs(e) if abs(e) > 0 else 1.0))
    return modes
