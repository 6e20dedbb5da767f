"""Paper-style figures of the modelling layer (Yang et al. 2022, Fig. 2-5 and 8).

Frequency responses come from python-control; drawing from matplotlib (Agg).
Every function writes one PNG and returns its path.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

import control

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fahv.model.linearize import classify_modes, linearize  # noqa: E402
from fahv.model.notch import NotchFilter  # noqa: E402
from fahv.model.vehicle import ALPHA, DELTA_E, IQ, PHI, Vehicle  # noqa: E402
from fahv.model.vehicle import V as IV  # noqa: E402

_W = np.logspace(-2, 2.5, 1500)


def _freq(A, B, out: int, inp: int, w=_W):
    """Complex frequency response of x[out] to u[inp] of x_dot = A x + B u."""
    C = np.zeros((1, A.shape[0]))
    C[0, out] = 1.0
    sys = control.ss(A, B[:, [inp]], C, 0.0)
    return np.asarray(control.frequency_response(sys, w).complex).ravel()


def _bode_axes(title: str):
    fig, (am, ph) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
    fig.suptitle(title)
    am.set_ylabel("magnitude [dB]")
    ph.set_ylabel("phase [deg]")
    ph.set_xlabel("frequency [rad/s]")
    for ax in (am, ph):
        ax.grid(True, which="both", alpha=0.3)
    return fig, am, ph


def _bode_line(am, ph, w, resp, **kw):
    am.semilogx(w, 20 * np.log10(np.abs(resp)), **kw)
    ph.semilogx(w, np.degrees(np.unwrap(np.angle(resp))), **kw)


def pole_map(vehicle: Vehicle, h: float, V: float, path: Path) -> Path:
    """Open-loop poles of the linearised CM at (h, V) with named modes (Fig. 4).

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle linearised.
    h : float
        Altitude of the operating point [ft], inside the envelope.
    V : float
        Speed of the operating point [ft/s], inside the envelope.
    path : Path
        PNG file to write.

    Returns
    -------
    Path
        `path`, the PNG written.
    """
    lm = linearize(vehicle, h, V, "cm")
    modes = classify_modes(lm.A, vehicle.params.omega_1, vehicle.params.omega_2)
    fig, (ax, axz) = plt.subplots(1, 2, figsize=(11, 5), gridspec_kw={"width_ratios": [1.4, 1]})
    colors = {
        "flexible 1": "tab:red",
        "flexible 2": "tab:purple",
        "short period": "tab:blue",
        "phugoid": "tab:green",
        "altitude": "tab:orange",
        "other": "k",
    }
    for mo in modes:
        ev = np.array(mo.eigenvalues)
        label = f"{mo.name}: |s| = {mo.wn:.3g} rad/s, zeta = {mo.zeta:.3g}"
        for a in (ax, axz):
            a.plot(
                ev.real,
                ev.imag,
                "x",
                ms=9,
                mew=2,
                color=colors.get(mo.name, "k"),
                label=label if a is ax else None,
            )
    for a in (ax, axz):
        a.axvline(0, color="0.5", lw=0.8)
        a.axhline(0, color="0.5", lw=0.8)
        a.grid(alpha=0.3)
        a.set_xlabel("real [1/s]")
    ax.set_ylabel("imaginary [rad/s]")
    ax.set_title(f"CM open-loop poles, h = {h:.0f} ft, V = {V:.0f} ft/s")
    axz.set_xlim(-2.5, 2.5)
    axz.set_ylim(-0.1, 0.1)
    axz.set_title("zoom: rigid-body modes")
    ax.legend(fontsize=8, loc="center left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def bode_model_vs_lpv(
    vehicle: Vehicle, tp, h: float, V: float, path: Path, notch: NotchFilter | None = None
) -> Path:
    """Bode of the Jacobian linearisation vs the polytopic LPV model at an off-grid p.

    Paper Fig. 2 (`tp.kind == "dm"`) and Fig. 8 (`tp.kind == "ecm"`, codesigned
    model; `notch` required). Channels q (or q') / delta_e, alpha / delta_e, V / Phi.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle linearised.
    tp : fahv.model.tp_model.TPModel
        The polytopic LPV model compared, of the kind linearised.
    h : float
        Altitude of the operating point [ft], inside the envelope (off the TP grid).
    V : float
        Speed of the operating point [ft/s], inside the envelope (off the TP grid).
    path : Path
        PNG file to write.
    notch : NotchFilter, optional
        The notch of the ECM; required when `tp.kind == "ecm"`.

    Returns
    -------
    Path
        `path`, the PNG written.
    """
    kind = tp.kind
    lm = linearize(vehicle, h, V, kind, notch)
    A_tp, B_tp = tp.system(h, V)
    name_m = kind.upper()
    q_name = "q' / delta_e" if kind == "ecm" else "q / delta_e"
    fig, am, ph = _bode_axes(
        f"{name_m} (solid) vs {tp.n_vertices}-vertex polytopic LPV (dashed), "
        f"h = {h:.0f} ft, V = {V:.0f} ft/s"
    )
    for out, inp, name, c in (
        (IQ, DELTA_E, q_name, "tab:red"),
        (ALPHA, DELTA_E, "alpha / delta_e", "tab:blue"),
        (IV, PHI, "V / Phi", "tab:green"),
    ):
        _bode_line(am, ph, _W, _freq(lm.A, lm.B, out, inp), color=c, lw=2, label=f"{name_m} {name}")
        _bode_line(
            am, ph, _W, _freq(A_tp, B_tp, out, inp), color="k", ls="--", lw=1, label=f"LPV {name}"
        )
    am.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _with_notch(A, B, notch: NotchFilter, w=_W):
    """Q / delta_e of the CM followed by the notch (series connection, python-control)."""
    C = np.zeros((1, A.shape[0]))
    C[0, IQ] = 1.0
    plant = control.ss(A, B[:, [DELTA_E]], C, 0.0)
    return np.asarray(
        control.frequency_response(control.series(plant, notch.tf()), w).complex
    ).ravel()


def notch_effect(
    vehicle: Vehicle, h: float, V: float, omega_f: float, eps_z: float, path: Path
) -> Path:
    """Open-loop q / delta_e of the CM with and without notch (Fig. 3).

    (a) omega_p varied with eps_p = 0.5; (b) eps_p varied with omega_p = omega_f.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle linearised.
    h : float
        Altitude of the operating point [ft], inside the envelope.
    V : float
        Speed of the operating point [ft/s], inside the envelope.
    omega_f : float
        Notch frequency omega_z [rad/s] (a flexible mode's frequency).
    eps_z : float
        Numerator damping ratio of every notch drawn [-].
    path : Path
        PNG file to write.

    Returns
    -------
    Path
        `path`, the PNG written.
    """
    lm = linearize(vehicle, h, V, "cm")
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    base = _freq(lm.A, lm.B, IQ, DELTA_E)
    panels = (
        (
            "(a) omega_p varied, eps_p = 0.5",
            [
                (f"omega_p = {wp:g}", NotchFilter(omega_f, eps_z, wp, 0.5))
                for wp in (0.75 * omega_f, omega_f, 1.5 * omega_f)
            ],
        ),
        (
            "(b) eps_p varied, omega_p = omega_z",
            [
                (f"eps_p = {ep:g}", NotchFilter(omega_f, eps_z, omega_f, ep))
                for ep in (0.2, 0.5, 0.9)
            ],
        ),
    )
    for col, (title, filters) in enumerate(panels):
        am, ph = axes[0, col], axes[1, col]
        _bode_line(am, ph, _W, base, color="k", lw=2, label="CM, no notch")
        for label, nf in filters:
            _bode_line(am, ph, _W, _with_notch(lm.A, lm.B, nf), lw=1.2, label=label)
        am.set_title(f"{title}; omega_z = {omega_f:.2f} rad/s, eps_z = {eps_z:g}", fontsize=9)
        am.set_ylabel("|q / delta_e| [dB]")
        ph.set_ylabel("phase [deg]")
        ph.set_xlabel("frequency [rad/s]")
        am.legend(fontsize=8)
        for ax in (am, ph):
            ax.grid(True, which="both", alpha=0.3)
            ax.set_xlim(1, 200)
    fig.suptitle(f"Notch filter on q: CM at h = {h:.0f} ft, V = {V:.0f} ft/s (paper Fig. 3)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def notch_modes(
    vehicle: Vehicle, h: float, V: float, notches: dict[str, NotchFilter], path: Path
) -> Path:
    """Q / delta_e of the CM with a notch on each flexible mode (Fig. 5).

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle linearised.
    h : float
        Altitude of the operating point [ft], inside the envelope.
    V : float
        Speed of the operating point [ft/s], inside the envelope.
    notches : dict of str to NotchFilter
        The notches drawn, by legend label.
    path : Path
        PNG file to write.

    Returns
    -------
    Path
        `path`, the PNG written.
    """
    lm = linearize(vehicle, h, V, "cm")
    fig, am, ph = _bode_axes(
        f"Notch filter on the flexible modes, CM at h = {h:.0f} ft, V = {V:.0f} ft/s (paper Fig. 5)"
    )
    _bode_line(am, ph, _W, _freq(lm.A, lm.B, IQ, DELTA_E), color="k", lw=2, label="CM, no notch")
    for label, nf in notches.items():
        _bode_line(am, ph, _W, _with_notch(lm.A, lm.B, nf), lw=1.3, label=label)
    am.set_xlim(1, 200)
    am.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
