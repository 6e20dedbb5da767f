"""The report of a one-at-a-time sweep (`fahv.clearance.sweep`): tables and figures.

Per requirement, the inputs by the spread of the margin over their sweep, each with the
range swept, the margin's smallest and largest value and where it is negative; with a
finished campaign of the same campaign file (`against`), each input's PAWN index over the
campaign's runs and whether it exceeds the noise level (`fahv.campaign.attribution`), and
how far the two rankings agree (the leading inputs both put first, Spearman's rho).
Values in physical units (`fahv.campaign.figures.axis_of`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.campaign.attribution import Attribution, attribute
from fahv.campaign.figures import axis_of
from fahv.campaign.robustness import SEARCHABLE
from fahv.clearance.report import against_rows
from fahv.clearance.sweep import KIND, Sweep
from fahv.errors import CampaignError


def read_sweep(out_dir: Path) -> tuple[dict, list[Sweep]]:
    """A sweep folder's manifest and its sweeps.

    Raises
    ------
    CampaignError
        If the folder holds no sweep.
    """
    man = store.read_manifest(Path(out_dir))
    if man is None or man.get("kind") != KIND:
        raise CampaignError(f"{out_dir} is not a sweep folder (its campaign.json is not a sweep's)")
    sweeps = [Sweep(e["name"], np.array(e["values"], float),
                    {r: np.array(m, float) for r, m in e["margins"].items()})
              for e in man["inputs"]]  # fmt: skip
    return man, sweeps


def campaign_attribution(campaign_dir: Path, man: dict) -> dict[str, Attribution]:
    """The PAWN attribution of each requirement of the sweep over a finished campaign.

    Raises
    ------
    CampaignError
        As `fahv.clearance.report.against_rows`.
    """
    rows = against_rows(Path(campaign_dir), man)
    found = {r: attribute(rows, man["campaign"], r) for r in man["requirements"]}
    return {r: a for r, a in found.items() if a is not None}


def sweep_lines(man: dict, sweeps: list[Sweep], pawn: dict[str, Attribution]) -> list[str]:
    """`sweep.md`: per requirement, the inputs by spread, with PAWN's index where given."""
    data = man["campaign"]
    lines = [f"# One-at-a-time sweeps of {man['name']}", "",
             f"Each input over its range, the others at the centre of theirs; runs of "
             f"{man['duration']:g} s, the sensor noise held fixed. Margin = limit - value "
             "(negative: the requirement fails). Spread = largest - smallest margin over "
             "the sweep."]  # fmt: skip
    for r in man["requirements"]:
        unit, a = SEARCHABLE[r], pawn.get(r)
        by_col = {d.column: d for d in a.drivers} if a else {}
        lines += ["", f"## {r} [{unit}]", ""]
        head = "| input | swept | margin min | margin max | spread | negative at |"
        rule = "|---|---|---|---|---|---|"
        if a:
            lines += [f"PAWN over the campaign's {a.runs} runs ({a.failed} failing), noise "
                      f"level {a.dummy:.3f}.", ""]  # fmt: skip
            head, rule = head + " PAWN | above the noise |", rule + "---|---|"
        lines += [head, rule]
        for s in sorted(sweeps, key=lambda s: -np.nan_to_num(s.spread(r), nan=-1.0)):
            lines.append(_row(s, r, data, by_col.get(s.name), a))
        if a:
            lines += ["", _agreement(sweeps, r, a)]
    return lines


def _row(s: Sweep, r: str, data: dict, driver, a) -> str:
    """One input's row of a requirement's table."""
    label, factor = axis_of(s.name, data)
    m = s.margins[r]
    finite = m[np.isfinite(m)]
    lo_m, hi_m = (f"{finite.min():.4g}", f"{finite.max():.4g}") if finite.size else ("-", "-")
    neg = s.values[np.isfinite(m) & (m < 0)] * factor
    where = "-" if not neg.size else f"{neg.min():.4g} to {neg.max():.4g}"
    swept = f"{s.values[0] * factor:.4g} to {s.values[-1] * factor:.4g}"
    spread = s.spread(r)
    cells = [label, swept, lo_m, hi_m, "-" if math.isnan(spread) else f"{spread:.4g}", where]
    if a is not None:
        cells += (["-", "-"] if driver is None else
                  [f"{driver.pawn:.3f}", "yes" if driver.pawn > a.dummy else "no"])  # fmt: skip
    return "| " + " | ".join(cells) + " |"


def _agreement(sweeps: list[Sweep], r: str, a: Attribution) -> str:
    """How far PAWN's ranking and the sweep's agree: the common leading inputs, Spearman's rho.

    PAWN's index of an input with little influence is its sampling noise (the dummy
    inputs' level), so only the leading inputs' order is compared: the largest k such
    that PAWN's k largest are the sweep's k largest spreads.
    """
    from scipy.stats import spearmanr

    pawn = {d.column: d.pawn for d in a.drivers}
    both = [s for s in sweeps if s.name in pawn and np.isfinite(s.spread(r))]
    if len(both) < 2:
        return "Too few inputs both swept and attributed to compare the rankings."
    by_pawn = sorted((s.name for s in both), key=lambda n: -pawn[n])
    by_sweep = [s.name for s in sorted(both, key=lambda s: -s.spread(r))]
    k = next((j - 1 for j in range(1, len(both) + 1)
              if set(by_pawn[:j]) != set(by_sweep[:j])), len(both))  # fmt: skip
    rho = spearmanr([pawn[s.name] for s in both], [s.spread(r) for s in both]).statistic
    lead = ", ".join(by_sweep[:k]) if k else "none"
    return (f"Largest by PAWN: {', '.join(by_pawn[:4])}; largest spreads of the sweep: "
            f"{', '.join(by_sweep[:4])}. The leading {k} agree ({lead}); Spearman's rank "
            f"correlation over all {len(both)} inputs {rho:.2f}.")


def sweep_figure(man: dict, sweeps: list[Sweep], r: str, path: Path, plt) -> Path:
    """`sweep_<r>.png`: the margin of `r` against each input (one panel each)."""
    n = len(sweeps)
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False,
                             sharey=True)  # fmt: skip
    for ax, s in zip(axes.flat, sweeps, strict=False):
        label, factor = axis_of(s.name, man["campaign"])
        ax.plot(s.values * factor, s.margins[r], "o-", ms=3)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(label, fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel(f"{r} margin [{SEARCHABLE[r]}]", fontsize=8)
    fig.suptitle(f"{man['name']}: {r} margin, one input at a time", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def report(out_dir: str | Path, against: str | Path | None = None) -> list[str]:
    """Write a sweep folder's `sweep.md` and figures (again); its Markdown lines.

    Raises
    ------
    CampaignError
        If `out_dir` holds no sweep, or `against` is not a campaign of it.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    man, sweeps = read_sweep(out)
    pawn = campaign_attribution(Path(against), man) if against is not None else {}
    lines = sweep_lines(man, sweeps, pawn)
    for r in man["requirements"]:
        sweep_figure(man, sweeps, r, out / f"sweep_{r}.png", plt)
    (out / "sweep.md").write_text("\n".join(lines) + "\n")
    return lines
