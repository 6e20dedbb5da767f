"""Bode and Nichols figures of the tube loop at the design point, margins marked.

One Bode figure per loop break (|L| and phase of every notch setting at the design
point) and one Nichols figure of both breaks, drawn with matplotlib (Agg) from
python-control's frequency responses. Marked: the flexible-mode frequencies omega_1,
omega_2 and the notch frequency omega_z, each loop's gain crossover of its phase margin
and its phase crossover of its nearer gain margin, and on the Nichols charts the
critical points (-180 deg + k 360 deg, 0 dB) and the 6 dB / 45 deg box about them.
For a scenario whose law acts on the Kalman estimate, a Nichols figure of that loop too
(`estimate_nichols_figure`).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

import control

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fahv.analysis.margin_report import REQUIREMENT  # noqa: E402
from fahv.analysis.margin_study import MarginStudy, design_point_plant  # noqa: E402
from fahv.analysis.margins import BREAKS, frequency_grid, loop_systems  # noqa: E402


def _responses(study: MarginStudy, design, break_at: str):
    """(setting, omega, complex response, LoopMargins) of every setting at the design point."""
    plants, w = design_point_plant(design), frequency_grid(study.Ts, study.omega_flex)
    out = []
    for s in study.settings:
        L = loop_systems(plants, s.F, s.notch, study.Ts, break_at)[0]
        resp = np.ravel(control.frequency_response(L, w).complex)
        row = next(r for r in study.design_point if (r.break_at, r.notch) == (break_at, s.label))
        out.append((s, w, resp, row))
    return out


def _mark_modes(ax, study: MarginStudy) -> None:
    """Vertical lines at omega_1, omega_2 and the notch centres omega_z."""
    for i, f in enumerate(study.omega_flex):
        ax.axvline(f, color="0.4", ls=":", lw=1.0)
        ax.text(f, 1.0, f" omega_{i + 1}", transform=ax.get_xaxis_transform(), va="top",
                fontsize=7, color="0.3")  # fmt: skip
    for s in study.settings:
        if s.notch is not None:
            ax.axvline(s.notch.omega_z, color="tab:red", ls="--", lw=0.6, alpha=0.5)


def _critical_phases(lo: float, hi: float) -> list[float]:
    """The phases -180 deg + k 360 deg within [lo, hi] [deg]."""
    k0, k1 = int(np.ceil((lo + 180.0) / 360.0)), int(np.floor((hi + 180.0) / 360.0))
    return [-180.0 + 360.0 * k for k in range(k0, k1 + 1)]


def bode_figure(study: MarginStudy, design, break_at: str, path: Path) -> Path:
    """Bode plot of the loop broken at `break_at`, every notch setting, at the design point.

    Parameters
    ----------
    study : fahv.analysis.margin_study.MarginStudy
    design : fahv.spec.artefacts.Design
        The design the study was made of.
    break_at : {"delta_e", "q"}
    path : Path
        File to write (its suffix gives the format, png or pdf).

    Returns
    -------
    Path
        `path`.
    """
    fig, (am, ph) = plt.subplots(2, 1, figsize=(8.0, 6.5), sharex=True)
    fig.suptitle(f"{study.design_name}: loop broken at {break_at}, design point")
    for s, w, resp, r in _responses(study, design, break_at):
        label = f"notch {s.label}: PM {r.pm_deg:.1f} deg, GM+ {r.gm_up_db:.1f} dB"
        (line,) = am.semilogx(w, 20 * np.log10(np.abs(resp)), lw=1.2, label=label)
        phase = np.degrees(np.unwrap(np.angle(resp)))
        ph.semilogx(w, phase, lw=1.2, color=line.get_color())
        if np.isfinite(r.w_c):
            am.plot(r.w_c, 0.0, "o", color=line.get_color(), ms=5)
            ph.plot(r.w_c, np.interp(r.w_c, w, phase), "o", color=line.get_color(), ms=5)
        if np.isfinite(r.w_gm):
            am.plot(r.w_gm, 20 * np.log10(np.interp(r.w_gm, w, np.abs(resp))), "s",
                    color=line.get_color(), ms=5)  # fmt: skip
    am.axhline(0.0, color="k", lw=0.6)
    for ax in (am, ph):
        _mark_modes(ax, study)
        ax.grid(True, which="both", alpha=0.3)
    lo, hi = ph.get_ylim()
    for c in _critical_phases(lo, hi):
        ph.axhline(c, color="k", lw=0.6)
    am.set_ylabel("|L| [dB]")
    ph.set_ylabel("phase of L [deg]")
    ph.set_xlabel("frequency [rad/s] (o: gain crossover of PM; s: phase crossover of GM)")
    am.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def nichols_figure(study: MarginStudy, design, path: Path) -> Path:
    """Nichols charts of both breaks, every notch setting, at the design point.

    Parameters
    ----------
    study : fahv.analysis.margin_study.MarginStudy
    design : fahv.spec.artefacts.Design
    path : Path
        File to write (png or pdf).

    Returns
    -------
    Path
        `path`.
    """
    fig, axes = plt.subplots(1, len(BREAKS), figsize=(11.0, 5.0))
    for ax, break_at in zip(axes, BREAKS, strict=True):
        curves = [(f"notch {s.label}", w, resp)
                  for s, w, resp, _ in _responses(study, design, break_at)]  # fmt: skip
        _nichols_axes(ax, curves, study.omega_flex[0], f"broken at {break_at}")
    fig.suptitle(f"{study.design_name}: Nichols charts at the design point")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def _nichols_axes(ax, curves, omega_1: float, title: str) -> None:
    """Nichols curves (label, omega (F,) [rad/s], L (F,) complex) on `ax`, the box marked.

    Each curve's point at omega_1 (^), the critical points (+) and the 6 dB / 45 deg box
    about each (`fahv.analysis.margin_report.REQUIREMENT`).
    """
    g, p = REQUIREMENT["gain_db"], REQUIREMENT["phase_deg"]
    for label, w, resp in curves:
        phase = np.degrees(np.unwrap(np.angle(resp)))
        mag = 20 * np.log10(np.abs(resp))
        (line,) = ax.plot(phase, mag, lw=1.1, label=label)
        i = int(np.argmin(np.abs(w - omega_1)))
        ax.plot(phase[i], mag[i], "^", color=line.get_color(), ms=6)
    for c in _critical_phases(*ax.get_xlim()):
        ax.plot(c, 0.0, "k+", ms=10)
        ax.add_patch(plt.Rectangle((c - p, -g), 2 * p, 2 * g, fill=False, ls="--",
                                   color="tab:red", lw=0.8))  # fmt: skip
    ax.set_ylim(max(ax.get_ylim()[0], -60.0), min(ax.get_ylim()[1], 60.0))
    ax.set_title(f"{title} (^: omega_1; box: +-{g:g} dB, +-{p:g} deg)", fontsize=9)
    ax.set_xlabel("phase of L [deg]")
    ax.set_ylabel("|L| [dB]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)


def estimate_nichols_figure(study: MarginStudy, loops, rows, title: str, path: Path) -> Path:
    """Nichols chart of the loop on the estimate at the design point, every notch setting.

    Parameters
    ----------
    study : fahv.analysis.margin_study.MarginStudy
        The design's study (its period and flexible-mode frequencies).
    loops : list of (NotchSetting, control.StateSpace)
        `fahv.analysis.estimated_loop.design_point_loops`.
    rows : list of fahv.analysis.margins.LoopMargins
        `fahv.analysis.estimated_loop.estimated_margins` of the same settings: each
        curve's label gives its design-point margins.
    title : str
        What the loop is (the filter and the scenario).
    path : Path
        File to write (png or pdf).

    Returns
    -------
    Path
        `path`.
    """
    w = frequency_grid(study.Ts, study.omega_flex)
    curves = []
    for s, sys in loops:
        r = next(r for r in rows if r.notch == s.label and r.point == "design point")
        label = f"notch {s.label}: PM {r.pm_deg:.1f} deg, GM+ {r.gm_up_db:.1f} dB"
        curves.append((label, w, np.ravel(control.frequency_response(sys, w).complex)))
    fig, ax = plt.subplots(figsize=(7.0, 5.5))
    _nichols_axes(ax, curves, study.omega_flex[0], "broken at delta_e, law on x_hat")
    fig.suptitle(f"{study.design_name}: {title}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def margin_figures(study: MarginStudy, design, out: Path, fmt: str = "png") -> list[Path]:
    """Write the Bode figure of each break and the Nichols figure into `out`.

    Parameters
    ----------
    study : fahv.analysis.margin_study.MarginStudy
    design : fahv.spec.artefacts.Design
    out : Path
        Folder (made if missing).
    fmt : {"png", "pdf"}

    Returns
    -------
    list of Path
        `margins_<design>_bode_<break>.<fmt>` per break, then
        `margins_<design>_nichols.<fmt>` (`<design>` the study's design name).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"margins_{study.design_name}_" if study.design_name else "margins_"
    paths = [bode_figure(study, design, b, out / f"{stem}bode_{b}.{fmt}") for b in BREAKS]
    return paths + [nichols_figure(study, design, out / f"{stem}nichols.{fmt}")]
