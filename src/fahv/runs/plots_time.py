"""Engineering figures of runs over time: tracking errors, inputs, input rates, tube level.

Each figure overlays runs given as `fahv.runs.plots_context.PlottedRun` (already
cut to the time window, `fahv.runs.plots_context.clip_runs`) and returns a
matplotlib figure the caller saves and closes. What they draw:

- tracking errors h - h_c [ft], V - V_c [ft/s] against the case command, alpha -
  alpha_r and theta - theta_r [deg] against the trim of the governed reference x_r (as
  `fahv.runs.metrics.metrics` computes them), with the requirement bands shaded:
  +/- `SETTLE_TOL` (settling of h and V) and +/- `ATTITUDE_BOUND_DEG` (sec. 5.1);
  the right column zooms on the bands;
- the controller command u = (Phi, delta_e) with the actuator limits (sec. 5.1) and
  the tightened limits u_lo, u_hi of eq. (30);
- the rates of the applied input (after the fault injector), finite differences over
  the step Ts;
- the tube level e' N^-1 e (<= 1: the tube error e inside Z = {e' N^-1 e <= 1}) on a
  logarithmic axis with the boundary at 1;
- the error of the state estimate the controller read, x_hat - x, of h, V, alpha, theta
  and q (zero for the exact-state loop).

`mark_onsets` draws the fault onset on every panel of any of them.
"""

from __future__ import annotations

import numpy as np

from fahv.model.vehicle import ALPHA, IQ, THETA, H, V
from fahv.runs.metrics import ATTITUDE_BOUND_DEG, SETTLE_TOL, has_servos
from fahv.runs.plots import line_style, plt

#: Tracking-error panels: (quantity, unit, function of a RunResult -> (N,) values,
#: requirement bound in that unit). The bounds are the metrics' requirements.
ERROR_PANELS = (
    ("h - h_c", "ft", lambda r: r.x[:, H] - r.h_c, SETTLE_TOL["h"]),
    ("V - V_c", "ft/s", lambda r: r.x[:, V] - r.V_c, SETTLE_TOL["V"]),
    ("alpha - alpha_r", "deg", lambda r: np.degrees(r.x[:, ALPHA] - r.x_r[:, ALPHA]),
     ATTITUDE_BOUND_DEG),
    ("theta - theta_r", "deg", lambda r: np.degrees(r.x[:, THETA] - r.x_r[:, THETA]),
     ATTITUDE_BOUND_DEG),
)  # fmt: skip

#: Estimate-error panels: (quantity, unit, state index, factor to the drawn unit).
ESTIMATE_PANELS = (
    ("h", "ft", H, 1.0), ("V", "ft/s", V, 1.0), ("alpha", "deg", ALPHA, float(np.degrees(1.0))),
    ("theta", "deg", THETA, float(np.degrees(1.0))), ("q", "deg/s", IQ, float(np.degrees(1.0))),
)  # fmt: skip

#: Input panels: (label, column of u, factor from the stored unit to the drawn one).
INPUT_PANELS = (("Phi [-]", 0, 1.0), ("delta_e [deg]", 1, float(np.degrees(1.0))))

#: Colour of the requirement bands and of the fault onset line.
BAND_COLOUR = "tab:green"


def _band(ax, bound: float, label: str | None) -> None:
    """Shade |y| <= bound with its edges drawn."""
    ax.axhspan(-bound, bound, color=BAND_COLOUR, alpha=0.15, lw=0, label=label)
    for s in (-bound, bound):
        ax.axhline(s, color=BAND_COLOUR, lw=0.8, ls="--")


def mark_onsets(fig, runs: list) -> list[float]:
    """Draw each run's fault onset as a vertical line in its colour on every panel of `fig`.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        A figure over time (x axis: t [s]).
    runs : list of PlottedRun
        The runs drawn, in drawing order (their colours are `line_style`'s); each run's
        `t_onset` within the time span of the runs is drawn, labelled with the run on the
        first panel (`fault onset of <run>, t = 100 s`).

    Returns
    -------
    list of float
        The distinct onset times drawn [s] (empty: no fault in the window).
    """
    t_lo = min(float(r.run.t[0]) for r in runs)
    t_hi = max(float(r.run.t[-1]) for r in runs)
    marked = [(i, r) for i, r in enumerate(runs)
              if r.t_onset is not None and t_lo <= r.t_onset <= t_hi]  # fmt: skip
    for ax in fig.axes:
        for i, r in marked:
            ax.axvline(r.t_onset, color=line_style(i)["color"], lw=1.0, ls=":", zorder=0.5)
    if marked and fig.axes:  # named in the legend of the first panel
        first = fig.axes[0]
        for (_, r), line in zip(marked, first.lines[-len(marked):], strict=True):
            line.set_label(f"fault onset of {r.label}, t = {r.t_onset:g} s")
        first.legend(loc="best", fontsize=7)
    return sorted({r.t_onset for _, r in marked})


def _panels(runs: list, rows: int, cols: int, figsize: tuple):
    """(figure, axes) of rows x cols panels over a shared time axis, for `runs`.

    Raises
    ------
    ValueError
        If there is no run.
    """
    if not runs:
        raise ValueError("no run to plot")
    return plt.subplots(rows, cols, figsize=figsize, sharex=True)


def _finish(fig, axes, title: str) -> None:
    """Label t [s] under the bottom row, set the title, lay the figure out tightly."""
    for ax in np.atleast_2d(axes)[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title)
    fig.tight_layout()


def error_figure(runs: list):
    """Tracking errors with the requirement bands shaded; right column zoomed on them.

    Parameters
    ----------
    runs : list of PlottedRun
        Runs in drawing order (at least one).

    Returns
    -------
    matplotlib.figure.Figure
        4 x 2 panels: h - h_c [ft], V - V_c [ft/s], alpha - alpha_r, theta - theta_r
        [deg]; left the whole range, right +/- 3 bounds around zero.

    Raises
    ------
    ValueError
        If there is no run.
    """
    fig, axes = _panels(runs, len(ERROR_PANELS), 2, (11, 9))
    for row, (label, unit, fn, bound) in zip(axes, ERROR_PANELS, strict=True):
        for col, ax in enumerate(row):
            _band(ax, bound, f"requirement +/- {bound:g} {unit}" if col == 1 else None)
            for i, r in enumerate(runs):
                ax.plot(r.run.t, fn(r.run), label=r.label, **line_style(i))
            ax.grid(True, alpha=0.3)
        row[0].set_ylabel(f"{label} [{unit}]")
        row[1].set_ylim(-3.0 * bound, 3.0 * bound)
        handles = row[1].get_legend_handles_labels()[0][:1]  # the band only
        row[1].legend(loc="upper right", fontsize=7, handles=handles)
    axes[0, 0].set_title("whole range", fontsize=9)
    axes[0, 1].set_title("zoom: +/- 3 x the requirement", fontsize=9)
    axes[0, 0].legend(loc="best", fontsize=7)
    _finish(fig, axes, "Tracking errors (h, V against the command; alpha, theta against x_r)")
    return fig


def _limit_lines(ax, runs: list, j: int, scale: float) -> list[float]:
    """Actuator and tightened limits of input j (drawn once per distinct value)."""
    drawn, values = set(), []
    for r in runs:
        for lim, style, name in (
            ((r.limits.u_min[j], r.limits.u_max[j]) if r.limits else None, "k--",
             "actuator limit (sec. 5.1)"),
            ((r.u_lo[j], r.u_hi[j]) if r.u_lo is not None else None, "m-.",
             "tightened limit u_lo, u_hi (eq. 30)"),
        ):  # fmt: skip
            if lim is None or (style, *lim) in drawn:
                continue
            label = name if not any(s == style for s, *_ in drawn) else None
            drawn.add((style, *lim))
            for k, v in enumerate(lim):
                ax.axhline(scale * v, color=style[0], ls=style[1:], lw=0.9,
                           label=label if k == 0 else None)  # fmt: skip
                values.append(scale * v)
    return values


def input_figure(runs: list):
    """Controller command u with the actuator limits and the tightened limits.

    Parameters
    ----------
    runs : list of PlottedRun
        Runs in drawing order (at least one).

    Returns
    -------
    matplotlib.figure.Figure
        2 x 2 panels: Phi [-] and delta_e [deg]; left with every limit in view, right
        zoomed on the command.

    Raises
    ------
    ValueError
        If there is no run.
    """
    fig, axes = _panels(runs, len(INPUT_PANELS), 2, (11, 6))
    for row, (label, j, scale) in zip(axes, INPUT_PANELS, strict=True):
        for ax in row:
            for i, r in enumerate(runs):
                ax.plot(r.run.t, scale * r.run.u[:, j], label=r.label, **line_style(i))
            ax.grid(True, alpha=0.3)
        lo = min(float(scale * r.run.u[:, j].min()) for r in runs)
        hi = max(float(scale * r.run.u[:, j].max()) for r in runs)
        pad = 0.1 * (hi - lo) or 0.05 * max(abs(hi), 1e-3)
        row[1].set_ylim(lo - pad, hi + pad)
        values = _limit_lines(row[0], runs, j, scale)
        if values:
            span = max(values) - min(values)
            row[0].set_ylim(min(values) - 0.05 * span, max(values) + 0.05 * span)
        row[0].set_ylabel(label)
    axes[0, 0].set_title("with the limits", fontsize=9)
    axes[0, 1].set_title("zoom on the command", fontsize=9)
    axes[0, 0].legend(loc="center right", fontsize=7)
    _finish(fig, axes, "Control inputs (controller command u)")
    return fig


def input_rate_figure(runs: list):
    """Input rates: the controller's command and, with servos, the servo's position.

    Finite differences (u_k - u_(k-1)) / Ts of the command the controller sends (before
    the fault injector: what it asks of the servo) as solid lines, and of the actuator's
    position where the run has servos (`fahv.runs.metrics.has_servos`) as thin lines of
    the same colour, and the envelope +/- of the servo's peak |rate| within the steps of
    each second (its rate state, which the rate limit bounds;
    `RunResult.u_actuator_rate_peak`) as a thick line; the servos' rate
    limits of each run (the vehicle file's times the run's `servo_rate_limit_factor`,
    `PlottedRun.limits`) as dashed lines. A run on
    ideal actuators has no rate limit: it is named in a note.

    Parameters
    ----------
    runs : list of PlottedRun
        Runs in drawing order (at least one).

    Returns
    -------
    matplotlib.figure.Figure
        Two panels: dPhi/dt [1/s] and d delta_e/dt [deg/s], at the later step of each
        difference.

    Raises
    ------
    ValueError
        If there is no run.
    """
    fig, axes = _panels(runs, len(INPUT_PANELS), 1, (8, 5.4))
    units = ("dPhi/dt [1/s]", "d delta_e/dt [deg/s]")
    ideal = []
    for ax, (_, j, scale), unit in zip(axes, INPUT_PANELS, units, strict=True):
        drawn = set()
        for i, r in enumerate(runs):
            t, style = r.run.t, line_style(i)
            if t.size < 2:
                continue
            ax.plot(t[1:], scale * np.diff(r.run.u[:, j]) / np.diff(t),
                    label=f"{r.label}: command", **style)  # fmt: skip
            servos = has_servos(r.run)
            if servos:
                pos = r.run.u_actuator[:, j]
                ax.plot(t[1:], scale * np.diff(pos) / np.diff(t), color=style["color"], lw=0.6,
                        alpha=0.7, label=f"{r.label}: servo position")  # fmt: skip
                envelope = _peak_envelope(t, r.run.u_actuator_rate_peak, j)
                if envelope is not None:
                    tw, v = envelope
                    for sign, label in ((1.0, f"{r.label}: servo's peak |rate| per second"),
                                        (-1.0, None)):  # fmt: skip
                        ax.plot(tw, sign * scale * v, color=style["color"], lw=1.4,
                                drawstyle="steps-post", zorder=3, label=label)  # fmt: skip
            elif j == 0:
                ideal.append(r.label)
            lim = None if r.limits is None or not servos else (
                r.limits.rate_incr[j], r.limits.rate_decr[j])
            if lim is not None and np.all(np.isfinite(lim)) and lim not in drawn:
                drawn.add(lim)
                ax.axhline(scale * lim[0], color=style["color"], ls="--", lw=0.9,
                           label=f"{r.label}: rate limit {scale * lim[0]:g}")  # fmt: skip
                ax.axhline(-scale * lim[1], color=style["color"], ls="--", lw=0.9)
        ax.set_ylabel(unit)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=7)
    if ideal:
        axes[-1].text(0.01, 0.06, "ideal actuators (no rate limit): " + ", ".join(ideal),
                      transform=axes[-1].transAxes, ha="left", va="bottom", fontsize=7,
                      color="0.4")  # fmt: skip
    _finish(fig, axes[:, None],
            "Input rates: command (before the fault injector), servo position and peak rate")
    return fig


def _peak_envelope(t: np.ndarray, peak: np.ndarray | None, j: int):
    """The largest servo |rate| of input j in each second of a run.

    From `RunResult.u_actuator_rate_peak` (N, 2) and the times t (N,) [s]: the start
    times (M,) [s] of the seconds and their largest peak |rate| (M,); None without a
    finite value (ideal actuators).
    """
    if peak is None or not np.isfinite(peak[:, j]).any():
        return None
    per = max(1, int(round(1.0 / float(t[1] - t[0]))))
    starts = np.arange(0, len(t), per)
    v = np.array([np.nanmax(c) if np.isfinite(c).any() else np.nan
                  for c in np.split(peak[:, j], starts[1:])])  # fmt: skip
    return t[starts], v


def tube_figure(runs: list):
    """Tube level e' N^-1 e on a logarithmic axis with the boundary of Z at 1.

    Parameters
    ----------
    runs : list of PlottedRun
        Runs in drawing order (at least one); a run without a tube (NaN levels, the
        RMPC) is named in a note instead of drawn.

    Returns
    -------
    matplotlib.figure.Figure
        One panel; levels above 1 mean the tube error left Z.

    Raises
    ------
    ValueError
        If there is no run.
    """
    fig, ax = _panels(runs, 1, 1, (8, 3.6))
    ax.axhline(1.0, color="k", ls="--", lw=0.9, label="boundary of Z (level 1)")
    no_tube, peak = [], 1e-3
    for i, r in enumerate(runs):
        lvl = np.asarray(r.run.tube_level, float)
        ok = np.isfinite(lvl) & (lvl > 0)
        if not ok.any():
            no_tube.append(r.label)
            continue
        peak = max(peak, float(lvl[ok].max()))
        ax.plot(r.run.t, np.where(ok, lvl, np.nan), label=r.label, **line_style(i))
    ax.set_yscale("log")
    ax.set_ylim(10.0 ** (np.floor(np.log10(peak)) - 4.0), max(2.0, 2.0 * peak))
    ax.set_ylabel("e' N^-1 e")
    ax.grid(True, which="both", alpha=0.3)
    if no_tube:
        ax.text(0.01, 0.02, "no tube: " + ", ".join(no_tube), transform=ax.transAxes,
                fontsize=7, va="bottom")  # fmt: skip
    ax.legend(loc="lower right", fontsize=7)
    _finish(fig, np.array([[ax]]), "Tube level e' N^-1 e (the tube error e is inside Z at <= 1)")
    return fig


def estimate_figure(runs: list):
    """Errors of the state estimate the controller read against the true state.

    Parameters
    ----------
    runs : list of PlottedRun
        Runs in drawing order (at least one); a run without an estimate (recorded before
        the estimator existed) read the exact state: its error is drawn as zero.

    Returns
    -------
    matplotlib.figure.Figure
        5 panels: x_hat - x of h [ft], V [ft/s], alpha, theta [deg] and q [deg/s], with
        each filter's own +/- 3 sigma (its covariance's, `RunResult.x_hat_sigma`) shaded in
        the run's colour where it states one.

    Raises
    ------
    ValueError
        If there is no run.
    """
    fig, axes = _panels(runs, len(ESTIMATE_PANELS), 1, (9, 9))
    for ax, (name, unit, j, scale) in zip(axes, ESTIMATE_PANELS, strict=True):
        for i, r in enumerate(runs):
            x_hat = r.run.x if r.run.x_hat is None else r.run.x_hat
            ax.plot(r.run.t, scale * (x_hat[:, j] - r.run.x[:, j]), label=r.label,
                    **line_style(i))  # fmt: skip
            sigma = getattr(r.run, "x_hat_sigma", None)
            if sigma is not None and np.isfinite(sigma[:, j]).any():
                band = 3.0 * scale * sigma[:, j]
                ax.fill_between(r.run.t, -band, band, color=line_style(i)["color"], alpha=0.15,
                                lw=0, label=f"{r.label}: the filter's +/- 3 sigma")  # fmt: skip
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"{name}_hat - {name}\n[{unit}]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=7)
    _finish(fig, axes[:, None], "State estimate error (what the controller read, less the truth)")
    return fig
