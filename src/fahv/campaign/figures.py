"""The figures of a campaign report (PNG, matplotlib).

A histogram of each worst-run metric with its requirement, a grid of it against the
dispersed values, and the worst runs' histories; `fahv.campaign.report` writes them
beside its tables (`make_report`).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

#: Metrics of the worst-run tables and histograms: (column, label, how it is made
#: "worse = larger", requirement key of the histogram line).
WORST_METRICS = (
    ("alpha_err_max_deg", "max |alpha - alpha_r| [deg]", abs, "attitude_deg"),
    ("theta_err_max_deg", "max |theta - theta_r| [deg]", abs, "attitude_deg"),
    ("h_err_final_ft", "|h - h_c| at the end [ft]", abs, "h_final_ft"),
    ("V_err_final_fps", "|V - V_c| at the end [ft/s]", abs, "V_final_fps"),
    ("settling_after_command_s", "settling after the command [s]", abs, "settling_s"),
    ("tube_level_max", "max tube level e' N^-1 e", abs, None),
    ("tube_error_h_max_ft", "max |e_h| of the tube error [ft]", abs, None),
    ("eta_1_dot_rms_after_fault", "RMS eta_1_dot after the fault [1/s]", abs, None),
    ("delta_e_max_deg", "max delta_e [deg]", abs, None),
)


#: Axis words of the dispersed columns: column -> (label with its unit, factor).
_AXES = {
    "fault.t_onset": ("fault onset [s]", 1.0), "fault.loss": ("loss 1 - rho_f [%]", 100.0),
    "fault.bias_deg": ("elevator bias [deg]", 1.0),
    "command.dh": ("commanded climb dh [ft]", 1.0), "command.dV": ("commanded dV [ft/s]", 1.0),
    "initial.h0": ("initial h0 [ft]", 1.0), "initial.V0": ("initial V0 [ft/s]", 1.0),
    "actuators.omega_n": ("servo omega_n factor [-]", 1.0),
    "actuators.zeta": ("servo zeta factor [-]", 1.0),
    "actuators.rate_limit": ("servo rate limit factor [-]", 1.0),
    "sensors.stddev": ("sensor noise factor [-]", 1.0),
    "sensors.bias_stddev": ("sensor bias stddev factor [-]", 1.0),
    "sensors.bias_mean": ("sensor bias mean [stddevs]", 1.0),
}  # fmt: skip


def axis_of(column: str, data: dict) -> tuple[str, float]:
    """The scatter axis of a dispersed column: (label with its unit, factor on the value).

    An uncertain parameter's draw s_p becomes the parameter's change from its nominal
    value in percent, s_p x scale x rel_p x 100 (sec. 5.1: p = p_nominal (1 + s_p scale
    rel_p)); the other columns keep their value in their own unit.

    Examples
    --------
    >>> axis_of("s.m", {"dispersions": {"uncertainty": {"scale": 1.0}}})
    ('m from its nominal [%]', 10.0)
    """
    if column.startswith("s."):
        p = column[2:]
        scale = data["dispersions"]["uncertainty"]["scale"]
        return f"{p} from its nominal [%]", 100.0 * scale * PAPER_UNCERTAINTY.get(p, 1.0)
    return _AXES.get(column, (column, 1.0))


def metric(row: dict, key: str) -> float:
    """A run's metric `key` from its result row, as a float (NaN where absent)."""
    v = row.get(key)
    return math.nan if v is None else float(v)


def draw_figures(out: Path, data: dict, per_variant: dict, cols: list[str]) -> list[Path]:
    """PNG figures of a campaign: histograms, metric vs parameter, worst trajectories."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    req = data["requirements"]
    rep = out / "report"
    rep.mkdir(exist_ok=True)
    paths = []
    for key, label, worse, req_key in WORST_METRICS:
        fig, ax = plt.subplots(figsize=(6, 3.6))
        for v, rs in per_variant.items():
            x = np.array([worse(metric(r, key)) for r in rs if r.get(key) is not None])
            x = x[np.isfinite(x)]
            if x.size:
                ax.hist(x, bins=30, alpha=0.6, label=f"{v} (n = {x.size})")
        if req_key is not None:
            unit = re.search(r"\[([^\]]+)\]$", label)
            words = f"requirement {req[req_key]:g}" + (f" {unit.group(1)}" if unit else "")
            ax.axvline(req[req_key], color="r", ls="--", label=words)
        ax.set_xlabel(label)
        ax.set_ylabel("runs")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        if not ax.patches:  # e.g. no run settled, or no variant has a tube
            ax.text(0.5, 0.5, "no run has a finite value", transform=ax.transAxes,
                    ha="center", va="center")  # fmt: skip
        _margins(fig, top=0.15)
        p = rep / f"hist_{key}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
        if not cols:
            continue
        nc = min(4, len(cols))
        nr = math.ceil(len(cols) / nc)
        fig, axes = plt.subplots(nr, nc, figsize=(3.2 * nc, 2.6 * nr), squeeze=False)
        for ax, c in zip(axes.ravel(), cols, strict=False):
            name, factor = axis_of(c, data)
            for v, rs in per_variant.items():
                pts = [(factor * metric(r, c), worse(metric(r, key))) for r in rs
                       if r.get(key) is not None]  # fmt: skip
                if pts:
                    a = np.array(pts)
                    ax.plot(a[:, 0], a[:, 1], ".", ms=3, label=v)
            if req_key is not None:
                ax.axhline(req[req_key], color="r", ls="--", lw=0.8)
            ax.set_xlabel(name, fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in axes.ravel()[len(cols) :]:
            ax.axis("off")
        axes[0, 0].set_ylabel(label, fontsize=8)
        handles, names = axes[0, 0].get_legend_handles_labels()
        if handles:  # one legend for the panels: the variants' colours
            fig.legend(handles, names, loc="upper right", fontsize=7, markerscale=3)
        fig.suptitle(f"{label} against the dispersed values", fontsize=9)
        _margins(fig, hspace=0.45, wspace=0.3)
        p = rep / f"scatter_{key}.png"
        fig.savefig(p, dpi=100)
        plt.close(fig)
        paths.append(p)
    p = _worst_trajectories(out, data, per_variant, plt)
    if p is not None:
        paths.append(p)
    return paths


def _margins(fig, top: float = 0.45, hspace: float = 0.2, wspace: float = 0.2) -> None:
    """Fixed margins, `top` [in] (tight layout drew figures twice: 15.5 s to 9 s of CPU)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=0.75 / w, right=1.0 - 0.15 / w, bottom=0.55 / h, top=1.0 - top / h,
                        hspace=hspace, wspace=wspace)  # fmt: skip


def worst_indices(per_variant: dict, n: int = 5) -> list[tuple[int, str]]:
    """(index, variant) of up to `n` worst runs: the worst of each metric in turn."""
    ranked = []
    for key, _, worse, _ in WORST_METRICS[:5]:
        for v, rs in per_variant.items():
            rs = [r for r in rs if r.get(key) is not None]

            def score(r, key=key, worse=worse):
                x = metric(r, key)
                return math.inf if math.isnan(x) else worse(x)

            ranked.append([(r["index"], v) for r in sorted(rs, key=score, reverse=True)])
    out: list = []
    for depth in range(max((len(r) for r in ranked), default=0)):
        for r in ranked:
            if depth < len(r) and r[depth] not in out:
                out.append(r[depth])
            if len(out) >= n:
                return out
    return out


def _worst_trajectories(out: Path, data: dict, per_variant: dict, plt) -> Path | None:
    """Overlay of the worst runs' decimated histories (from `trajectories/`)."""
    keys = worst_indices(per_variant)
    trajs = {(r["index"], r["variant"]): r for r in store.read_rows(out, store.TRAJECTORIES)}
    keys = [k for k in keys if k in trajs]
    if not keys:
        return None
    panels = (
        ("h_err", "h - h_c [ft]"),
        ("V_err", "V - V_c [ft/s]"),
        ("alpha_err_deg", "alpha - alpha_r [deg]"),
        ("theta_err_deg", "theta - theta_r [deg]"),
        ("delta_e_deg", "delta_e [deg]"),
        ("tube_level", "tube level"),
    )
    fig, axes = plt.subplots(3, 2, figsize=(10, 7.5), sharex=True)
    for (col, label), ax in zip(panels, axes.ravel(), strict=True):
        for idx, v in keys:
            tr = trajs[(idx, v)]
            ax.plot(tr["t"], tr[col], lw=0.8, label=f"run {idx} ({v})")
        ax.set_ylabel(label, fontsize=8)
        if col.endswith("_err_deg"):
            att = data["requirements"]["attitude_deg"]
            for s in (-att, att):
                ax.axhline(s, color="r", ls="--", lw=0.7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("worst runs (the worst of each metric in turn)", fontsize=10)
    _margins(fig, hspace=0.15, wspace=0.25)
    p = out / "report" / "worst_trajectories.png"
    fig.savefig(p, dpi=100)
    plt.close(fig)
    return p
