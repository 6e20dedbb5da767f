"""Frequency view of runs: spectra of q, the filtered q' and eta_1_dot, what the notch does.

Power spectral densities by Welch's method (`scipy.signal.welch`, Hann window, mean
removed) of the pitch rate q, the notch filter's output q' (eq. 38; the
`/hsv/q_filtered` topic, `RunResult.q_f`; q' = q without a notch) and the rate of
the first flexible coordinate eta_1_dot, over frequency omega [rad/s] up to the
Nyquist frequency pi / Ts. The notch frequency omega_z and the flexible-mode
frequencies omega_flex of the design are marked: with the notch, q' is q with its
mode-1 component removed; overlaying a run without the notch (variant
`tube_mpc_no_notch`) shows how much of the first mode then enters the feedback and
the vehicle.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import welch

from fahv.model.vehicle import ETA1_DOT, IQ
from fahv.runs.metrics import settling_times
from fahv.runs.plots import line_style, plt

#: Samples per Welch segment (at most; fewer when the window is shorter).
NPERSEG = 1024

#: Spectrum panels: (label, function of a RunResult -> (N,) signal, unit of the PSD).
SPECTRUM_PANELS = (
    ("q", lambda r: np.degrees(r.x[:, IQ]), "(deg/s)^2 / (rad/s)"),
    ("q' (notch output)", lambda r: np.degrees(r.q_f), "(deg/s)^2 / (rad/s)"),
    ("eta_1_dot", lambda r: r.x[:, ETA1_DOT], "(1/s)^2 / (rad/s)"),
)


def psd(y, Ts: float, nperseg: int = NPERSEG) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of a sampled signal over omega (Welch).

    Parameters
    ----------
    y : (N,) array_like
        Samples at the period Ts, N >= 2.
    Ts : float
        Sampling period [s].
    nperseg : int
        Samples per segment (at most N); the frequency step is 2 pi / (nperseg Ts).

    Returns
    -------
    omega : (M,) ndarray
        Frequencies 0 ... pi / Ts [rad/s].
    S : (M,) ndarray
        Density per rad/s [unit of y squared per rad/s]: the integral of S over omega
        is the variance of y.

    Raises
    ------
    ValueError
        If Ts <= 0 or y has fewer than 2 samples.

    Examples
    --------
    >>> t = np.arange(4096) * 0.02
    >>> omega, S = psd(np.sin(19.05 * t), 0.02)
    >>> abs(omega[np.argmax(S)] - 19.05) < omega[1]
    True
    """
    y = np.asarray(y, float)
    if Ts <= 0 or y.size < 2:
        raise ValueError(f"a spectrum needs Ts > 0 and 2 samples or more (Ts {Ts}, {y.size})")
    f, S = welch(y, fs=1.0 / Ts, nperseg=min(int(nperseg), y.size), detrend="constant")
    return 2.0 * math.pi * f, S / (2.0 * math.pi)


def spectrum_window(run, after_transient: bool = True) -> tuple[float, float]:
    """Time window [s] of a run's spectrum.

    Parameters
    ----------
    run : RunResult
        N >= 1 steps.
    after_transient : bool
        From the settling of the step (the later of the settling times of h and V,
        `fahv.runs.metrics.settling_times`; the run's second half if it never
        settles) to its end; False: the whole run (a window already chosen).

    Returns
    -------
    (float, float)
        (t0, t1) [s].
    """
    t0, t1 = float(run.t[0]), float(run.t[-1])
    if not after_transient:
        return t0, t1
    ts = max(settling_times(run))
    return (ts if math.isfinite(ts) and ts < t1 else 0.5 * (t0 + t1)), t1


def _mark_frequencies(ax, runs: list) -> None:
    """Vertical lines at the notch frequency (wide) and the flexible modes (dotted, on top)."""
    notch = sorted({r.omega_z for r in runs if r.omega_z is not None})
    modes = sorted({float(w) for r in runs if r.omega_flex is not None for w in r.omega_flex})
    for k, w in enumerate(notch):
        text = "notch omega_z = " + ", ".join(f"{v:.2f}" for v in notch) + " rad/s"
        ax.axvline(w, color="m", lw=4.0, alpha=0.3, label=None if k else text)
    for k, w in enumerate(modes):
        text = "flexible modes omega_flex = " + ", ".join(f"{v:.2f}" for v in modes) + " rad/s"
        ax.axvline(w, color="k", ls=":", lw=1.0, label=None if k else text)


def _run_spectra(run, after_transient: bool) -> tuple[tuple[float, float], float, list]:
    """((t0, t1), Ts, [(omega, S) per panel of `SPECTRUM_PANELS`]) of one run."""
    t0, t1 = spectrum_window(run, after_transient)
    keep = (run.t >= t0) & (run.t <= t1)
    Ts = float(np.median(np.diff(run.t))) if run.t.size > 1 else 0.0
    return (t0, t1), Ts, [psd(fn(run)[keep], Ts) for _, fn, _ in SPECTRUM_PANELS]


def spectra_figure(runs: list, after_transient: bool = True):
    """PSD of q, q' and eta_1_dot of each run and the ratio q'/q; notch and modes marked.

    Parameters
    ----------
    runs : list of PlottedRun
        Runs in drawing order (at least one, each of 2 steps or more).
    after_transient : bool
        Each run's spectrum over `spectrum_window` (from the step's settling);
        False: over the whole (already windowed) run.

    Returns
    -------
    matplotlib.figure.Figure
        Four panels over omega [rad/s] (logarithmic, from the first Welch bin to the
        Nyquist frequency): the densities of q, q', eta_1_dot, and PSD(q') / PSD(q)
        [dB], the notch's |H(j omega)|^2 as the run saw it (0 dB without a notch). The
        legend gives each run's window.

    Raises
    ------
    ValueError
        If there is no run, or a run's window holds fewer than 2 samples.
    """
    if not runs:
        raise ValueError("no run to plot")
    fig, axes = plt.subplots(len(SPECTRUM_PANELS) + 1, 1, figsize=(8, 10), sharex=True)
    lo, hi = math.inf, 0.0
    for i, r in enumerate(runs):
        (t0, t1), Ts, spectra = _run_spectra(r.run, after_transient)
        label = f"{r.label} ({t0:.0f}-{t1:.0f} s)"
        for ax, (omega, S) in zip(axes, spectra, strict=False):
            ax.loglog(omega[1:], S[1:], label=label, **line_style(i))
        ratio = spectra[1][1][1:] / np.maximum(spectra[0][1][1:], np.finfo(float).tiny)
        axes[-1].semilogx(spectra[0][0][1:], 10.0 * np.log10(ratio), label=label, **line_style(i))
        lo, hi = min(lo, float(spectra[0][0][1])), max(hi, math.pi / Ts)
    names = [f"PSD of {n}\n[{u}]" for n, _, u in SPECTRUM_PANELS] + ["PSD(q') / PSD(q)\n[dB]"]
    for ax, name in zip(axes, names, strict=True):
        _mark_frequencies(ax, runs)
        ax.set_ylabel(name, fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    axes[-1].set_ylim(bottom=max(axes[-1].get_ylim()[0], -60.0))
    axes[0].set_xlim(lo, hi)
    axes[0].legend(loc="lower left", fontsize=7)
    axes[-1].set_xlabel("omega [rad/s]")
    fig.suptitle("Spectra (Welch) of q, the notch output q' and eta_1_dot")
    fig.tight_layout()
    return fig
