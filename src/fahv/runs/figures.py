"""Every figure of recorded runs, overlaid: what `fahv plot` writes and `fahv report` shows.

The paper-style groups (`fahv.runs.plots.GROUPS`: trajectory, attitude, flexible), the
engineering figures over time (`fahv.runs.plots_time`: errors, inputs, input rates, tube
level, state estimate), each with every run's fault onset marked, and the spectra
(`fahv.runs.plots_frequency`).
"""

from __future__ import annotations

from fahv.runs.plots import group_figure
from fahv.runs.plots_frequency import spectra_figure
from fahv.runs.plots_time import (
    error_figure,
    estimate_figure,
    input_figure,
    input_rate_figure,
    mark_onsets,
    tube_figure,
)

#: Paper-style groups drawn for recorded runs (the engineering input and tube figures
#: replace the groups of those names).
PLOT_GROUPS = ("trajectory", "attitude", "flexible")

#: The engineering figures over time: file name -> function of the runs.
PLOT_FIGURES = {
    "errors": error_figure,
    "inputs": input_figure,
    "input_rates": input_rate_figure,
    "tube": tube_figure,
    "estimate": estimate_figure,
}


def run_figures(runs: list, whole_run: bool = True) -> list[tuple[str, object]]:
    """Every figure of the runs, in the order `fahv plot` writes them.

    Parameters
    ----------
    runs : list of PlottedRun
        The runs, in drawing order (at least one; `fahv.runs.plots_context.plotted_run`).
    whole_run : bool
        The runs are whole (no time window chosen): each run's spectrum is then taken
        from the settling of its step (`spectra_figure`).

    Returns
    -------
    list of (str, matplotlib.figure.Figure)
        File stem and figure; the caller saves or embeds and closes each.

    Raises
    ------
    ValueError
        If there is no run.
    """
    out = []
    for group in PLOT_GROUPS:
        fig = group_figure(group, [(r.label, r.run) for r in runs])
        mark_onsets(fig, runs)
        out.append((group, fig))
    for name, make in PLOT_FIGURES.items():
        fig = make(runs)
        mark_onsets(fig, runs)
        out.append((name, fig))
    out.append(("spectra", spectra_figure(runs, whole_run)))
    return out
