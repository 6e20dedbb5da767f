"""Paper-style figures of closed-loop runs (Yang et al. 2022, Fig. 9-17).

Each function takes runs as `[(label, RunResult), ...]` (from `fahv simulate`,
`fahv sil` or a recorded file, `fahv.runs.bag.run_result_of`; the labels of
recorded runs from `fahv.runs.plots_context.run_labels`), overlays them with a
legend and writes one figure (PNG or PDF by the suffix). Drawing is matplotlib (Agg).
Time in s, angles in deg. The engineering figures of `fahv plot` (errors with the
requirement bands, inputs with their limits, spectra) are in
`fahv.runs.plots_time` and `fahv.runs.plots_frequency`.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fahv.model.vehicle import ALPHA, ETA1, ETA1_DOT, ETA2, ETA2_DOT, IQ, THETA, H, V  # noqa: E402

#: Figure groups: name -> (title, [(ylabel, function of a run -> values)]).
GROUPS = {
    "trajectory": (
        "Altitude and velocity",
        [("h [ft]", lambda r: r.x[:, H]), ("V [ft/s]", lambda r: r.x[:, V])],
    ),
    "attitude": (
        "Angle of attack, pitch angle, pitch rate",
        [
            ("alpha [deg]", lambda r: np.degrees(r.x[:, ALPHA])),
            ("theta [deg]", lambda r: np.degrees(r.x[:, THETA])),
            ("q [deg/s]", lambda r: np.degrees(r.x[:, IQ])),
        ],
    ),
    "flexible": (
        "Generalised flexible coordinates",
        [
            ("eta_1", lambda r: r.x[:, ETA1]),
            ("eta_1_dot [1/s]", lambda r: r.x[:, ETA1_DOT]),
            ("eta_2", lambda r: r.x[:, ETA2]),
            ("eta_2_dot [1/s]", lambda r: r.x[:, ETA2_DOT]),
        ],
    ),
    "flexible_rates": (
        "Derivatives of the flexible coordinates",
        [
            ("eta_1_dot [1/s]", lambda r: r.x[:, ETA1_DOT]),
            ("eta_2_dot [1/s]", lambda r: r.x[:, ETA2_DOT]),
        ],
    ),
    "inputs": (
        "Control inputs (controller command)",
        [("Phi [-]", lambda r: r.u[:, 0]), ("delta_e [deg]", lambda r: np.degrees(r.u[:, 1]))],
    ),
    "tube": (
        "Tube error against Z: e' N^-1 e (<= 1 inside)",
        [("tube level", lambda r: r.tube_level)],
    ),
}


def group_figure(group: str, runs: list, title: str | None = None):
    """The figure of one group (`GROUPS`) with several runs overlaid.

    Parameters
    ----------
    group : str
        Key of `GROUPS`.
    runs : list of (str, RunResult)
        Legend label and run, in drawing order.
    title : str, optional
        Figure title (default: the group's).

    Returns
    -------
    matplotlib.figure.Figure
        One panel per quantity of the group; the caller saves and closes it.

    Raises
    ------
    KeyError
        On an unknown group.
    ValueError
        If there is no run.
    """
    if not runs:
        raise ValueError("no run to plot")
    default_title, panels = GROUPS[group]
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.3 * len(panels) + 0.8), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, (ylabel, fn) in zip(axes, panels, strict=True):
        for i, (label, run) in enumerate(runs):  # dashes keep overlapping runs visible
            ax.plot(run.t, fn(run), label=label, **line_style(i))
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    if group == "trajectory":  # each run's own command, thin dash-dots in its colour
        drawn: list = []  # (run index, run) of each distinct command
        for i, (_, run) in enumerate(runs):
            if not any(np.array_equal(run.h_c, r.h_c) and np.array_equal(run.V_c, r.V_c)
                       for _, r in drawn):  # fmt: skip
                drawn.append((i, run))
        for i, run in drawn:
            name = "command" if len(drawn) == 1 else f"{runs[i][0]}: command"
            style = {"color": line_style(i)["color"], "ls": "-.", "lw": 0.9, "zorder": 3}
            axes[0].plot(run.t, run.h_c, label=name, **style)
            axes[1].plot(run.t, run.V_c, **style)
    if group == "tube":
        _tube_axis(axes[0], runs)
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(title or default_title)
    fig.tight_layout()
    return fig


def plot_group(group: str, runs: list, path: str | Path, title: str | None = None) -> Path:
    """Write one figure group (`GROUPS`) of several runs overlaid.

    Parameters
    ----------
    group : str
        Key of `GROUPS`.
    runs : list of (str, RunResult)
    path : path
        Output file (.png or .pdf).
    title : str, optional
        Figure title (default: the group's).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    KeyError
        On an unknown group.
    ValueError
        If there is no run.
    """
    return save_figure(group_figure(group, runs, title), path)


def save_figure(fig, path: str | Path) -> Path:
    """Write a figure (PNG or PDF by the suffix, 110 dpi) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : path
        Output file; its folder is created.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _tube_axis(ax, runs) -> None:
    """Tube levels scaled to the data; the boundary of Z (level 1) drawn or annotated.

    Levels are often a few hundredths: on a 0-1 axis they would look flat at zero, so
    the axis follows the data, and when 1 is far above it a note names the boundary.
    """
    levels = np.concatenate([np.asarray(r.tube_level, float) for _, r in runs])
    finite = levels[np.isfinite(levels)]
    top = float(finite.max()) if finite.size else 1.0
    if top >= 0.5:
        ax.axhline(1.0, color="k", ls="--", lw=0.8, label="boundary of Z (level 1)")
        ax.set_ylim(0.0, max(1.05, 1.05 * top))
    else:
        ax.set_ylim(0.0, 1.15 * top if top > 0 else 1.0)
        ax.text(0.99, 0.95, f"boundary of Z at level 1 (off the axis; max {top:.3g})",
                transform=ax.transAxes, ha="right", va="top", fontsize=8)  # fmt: skip


#: The paper's simulation figures: number -> (case, group, variants, title). A variant
#: written `other_case/variant` is that case's run (the paper's law runs on the vertex
#: tube of `case1_paper`, Case 1's certified design has no such variant).
PAPER_FIGURES = {
    9: (
        "case1",
        "trajectory",
        ("tube_mpc", "tube_mpc_no_notch", "case1_paper/tube_mpc_paper", "rmpc"),
        "Fig. 9: trajectory, Case 1",
    ),
    10: (
        "case1",
        "attitude",
        ("tube_mpc", "tube_mpc_no_notch", "case1_paper/tube_mpc_paper", "rmpc"),
        "Fig. 10: states, Case 1",
    ),
    11: (
        "case1",
        "flexible",
        ("tube_mpc", "tube_mpc_no_notch", "rmpc"),
        "Fig. 11: flexible coordinates, Case 1",
    ),
    12: (
        "case1",
        "inputs",
        ("tube_mpc", "tube_mpc_no_notch", "case1_paper/tube_mpc_paper", "rmpc"),
        "Fig. 12: inputs, Case 1",
    ),
    13: (
        "case1",
        "flexible_rates",
        ("tube_mpc_notch2", "tube_mpc_no_notch", "tube_mpc"),
        "Fig. 13: flexible rates with the notch on mode 2, Case 1",
    ),
    14: ("case2", "trajectory", ("tube_mpc",), "Fig. 14: trajectory, Case 2 (adjustable, tau 0.8)"),
    15: ("case2", "attitude", ("tube_mpc",), "Fig. 15: states, Case 2"),
    16: ("case2", "flexible", ("tube_mpc",), "Fig. 16: flexible coordinates, Case 2"),
    17: ("case2", "inputs", ("tube_mpc",), "Fig. 17: inputs, Case 2"),
}

#: Legend labels of the variants.
LABELS = {
    "tube_mpc": "Tube-MPC + notch",
    "tube_mpc_no_notch": "Tube-MPC, no notch",
    "tube_mpc_notch2": "Tube-MPC + notch on mode 2",
    "tube_mpc_paper": "paper's law (eq. 36, offline K, governor)",
    "rmpc": "RMPC (Kothare)",
}


#: Line style of the i-th run of a figure.
LINESTYLES = ("-", (0, (5, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2)))


def line_style(i: int) -> dict:
    """Line style of the i-th run: colour, dashes, and its place in the drawing order.

    Colours from the cycle, dashes to tell overlaps; the earlier run is drawn over the
    later, so the first run given (the reference) is never hidden under a noisier one.
    """
    return {"lw": 1.0, "ls": LINESTYLES[i % len(LINESTYLES)], "color": f"C{i % 10}",
            "zorder": 2.5 - 0.01 * i}



def paper_figures(runs: dict, out_dir: str | Path) -> list[Path]:
    """Write Fig. 9-17 from `{(case, variant): RunResult}`; skips a figure with no run.

    A run missing from `runs` is left out of its figure; a run of another case than
    the figure's is labelled with that case.
    """
    out = []
    for num, (case, group, variants, title) in PAPER_FIGURES.items():
        keys = [tuple(v.split("/")) if "/" in v else (case, v) for v in variants]
        sel = [
            (LABELS.get(v, v) + ("" if c == case else f" ({c})"), runs[(c, v)])
            for c, v in keys
            if (c, v) in runs
        ]
        if sel:
            out.append(
                plot_group(group, sel, Path(out_dir) / f"fig{num:02d}_{case}_{group}.png", title)
            )
    return out
