"""Which dispersed values drive each requirement's margin and its failures (given data).

A campaign's runs are a random sample of its dispersion space, so the attribution uses
them as they are, no extra simulation:

- **PAWN** (Pianosi and Wagener, Environmental Modelling & Software 67 (2015) 1-11; SALib's
  `pawn.analyze`): for each dispersed value, the median over 10 slices of its range of
  the Kolmogorov-Smirnov distance between the margin's distribution in the slice and over
  all runs. Moment-independent (a value that moves the tail of the margin counts, not
  only one that moves its mean) and computed from the given runs. Its sampling noise is
  measured by `DUMMIES` dummy inputs drawn beside the others (uniform, seeded, no
  influence by construction): a value whose index does not exceed the largest dummy's is
  not told apart from no influence. A value of no influence is exchangeable with the
  dummies, so it exceeds their largest with probability 1 / (DUMMIES + 1): 1 % per value
  with 99 (with five, one in six, and a campaign of a dozen null values flagged two on
  average; a one-at-a-time sweep, `fahv clearance sweep`, showed them to be noise).
- **Regional sensitivity** (Spear and Hornberger 1980): where runs fail (margin < 0), the
  Kolmogorov-Smirnov distance between the failing and the passing runs' distributions of
  each value (scipy's `ks_2samp`, with its p-value), and the range of the value over the
  failing runs: where in the dispersion space the failures sit (with at least
  `FEWEST_FAILING` failing runs; the range alone with fewer).

The margin is `fahv.campaign.robustness`' (limit minus value, continued past a failure); a
run that ended early takes the smallest finite margin less one, the worst rank. Values in
physical units as the report's scatter plots (`fahv.campaign.figures.axis_of`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fahv.campaign.draws import scatter_columns
from fahv.campaign.figures import axis_of
from fahv.campaign.robustness import robustness
from fahv.spec.requirements import on_estimate

#: Requirements attributed, in report order (`input_rates` needs the servo's rate limit,
#: which a campaign row does not hold).
ATTRIBUTED = ("attitude", "settling", "settling_fault", "final_h", "final_V", "tube")
#: Slices of each value's range of the PAWN index (SALib's default S).
SLICES = 10
#: Fewest runs with an applicable margin a PAWN index is computed from.
FEWEST = 20
#: Fewest failing (and passing) runs the regional sensitivity's KS distance is taken over.
FEWEST_FAILING = 5
#: Dummy inputs whose largest PAWN index is the noise level (a value of no influence
#: exceeds it with probability 1 / (DUMMIES + 1)).
DUMMIES = 99


@dataclass(frozen=True)
class Driver:
    """One dispersed value's share in one requirement.

    Attributes
    ----------
    column : str
        The row's column (`s.m`, `fault.loss`, ...; `fault.kind` as its index).
    label : str
        Its name and unit in the report (`axis_of`).
    pawn : float
        PAWN index (median KS distance over the slices), in [0, 1].
    ks : float
        KS distance between failing and passing runs (NaN without enough of both).
    p_value : float
        Its p-value.
    fail_range : tuple of float
        (lo, hi) of the value over the failing runs [label's unit] (NaN: none).
    """

    column: str
    label: str
    pawn: float
    ks: float
    p_value: float
    fail_range: tuple[float, float]


@dataclass(frozen=True)
class Attribution:
    """The drivers of one requirement's margin over a campaign's runs (`attribute`).

    Attributes: `requirement`, `runs` (with an applicable margin), `failed`, `dummy` (the
    largest of the dummy inputs' PAWN indices: the noise level), `drivers` (by PAWN
    index, largest first).
    """

    requirement: str
    runs: int
    failed: int
    dummy: float
    drivers: tuple[Driver, ...]

    def influential(self) -> list[Driver]:
        """The drivers whose PAWN index exceeds the dummy's."""
        return [d for d in self.drivers if d.pawn > self.dummy]


def _inputs(rows: list[dict], data: dict) -> tuple[list[str], np.ndarray]:
    """The dispersed columns that vary over the rows and their values (N, D)."""
    cols = list(scatter_columns(data))
    kinds = sorted({r["fault.kind"] for r in rows}) if "fault.kind" in rows[0] else []
    if len(kinds) > 1:
        cols.append("fault.kind")
    X = np.array([[kinds.index(r[c]) if c == "fault.kind" else float(r[c]) for c in cols]
                  for r in rows], float)  # fmt: skip
    varies = np.ptp(X, axis=0) > 0 if len(X) else np.zeros(len(cols), bool)
    return [c for c, v in zip(cols, varies, strict=True) if v], X[:, varies]


def attribute(rows: list[dict], data: dict, requirement: str, seed: int = 0
              ) -> Attribution | None:  # fmt: skip
    """The drivers of `requirement`'s margin over the campaign rows of one variant.

    Parameters
    ----------
    rows : list of dict
        Campaign rows (dispersed values, status, metrics) of one variant.
    data : dict
        The validated campaign (its requirement limits, its dispersions).
    requirement : str
        One of `ATTRIBUTED`.
    seed : int
        Seed of the dummy input.

    Returns
    -------
    Attribution or None
        None where fewer than `FEWEST` runs have an applicable margin or nothing varies.
    """
    from SALib.analyze import pawn
    from scipy.stats import ks_2samp

    if not rows:
        return None
    limits = data.get("requirements", {})
    m = np.array([robustness(r, requirement, limits) for r in rows], float)
    ok = ~np.isnan(m)
    if ok.sum() < FEWEST:
        return None
    cols, X = _inputs([r for r, k in zip(rows, ok, strict=True) if k], data)
    if not cols:
        return None
    y = m[ok]
    finite = y[np.isfinite(y)]
    y = np.where(np.isfinite(y), y, (finite.min() if finite.size else 0.0) - 1.0)
    rng = np.random.default_rng(seed)
    Xd = np.column_stack([X, rng.random((len(y), DUMMIES))])
    names = [*cols, *(f"dummy_{k}" for k in range(DUMMIES))]
    problem = {"num_vars": len(names), "names": names,
               "bounds": [[float(a.min()), float(a.max()) + 1e-12] for a in Xd.T]}  # fmt: skip
    index = pawn.analyze(problem, Xd, y, S=SLICES, seed=seed)["median"]
    fail = y < 0.0
    enough = FEWEST_FAILING <= fail.sum() and FEWEST_FAILING <= (~fail).sum()
    out = []
    for j, c in enumerate(cols):
        label, factor = axis_of(c, data)
        ks = ks_2samp(X[fail, j], X[~fail, j]) if enough else None
        lo_hi = ((float(X[fail, j].min() * factor), float(X[fail, j].max() * factor))
                 if fail.any() else (math.nan, math.nan))  # fmt: skip
        out.append(Driver(c, label, float(index[j]), ks.statistic if ks else math.nan,
                          ks.pvalue if ks else math.nan, lo_hi))  # fmt: skip
    out.sort(key=lambda d: -d.pawn)
    return Attribution(requirement, int(ok.sum()), int(fail.sum()),
                       float(np.max(index[len(cols):])), tuple(out))  # fmt: skip


def attribute_all(rows: list[dict], data: dict) -> list[Attribution]:
    """The attributions of every requirement of `ATTRIBUTED` that applies to the rows.

    The tube is left out where the loop reads a state estimate (its verdict is not judged
    there, `fahv.spec.requirements.on_estimate`).
    """
    skip = {"tube"} if rows and on_estimate(rows[0]) else set()
    found = (attribute(rows, data, r) for r in ATTRIBUTED if r not in skip)
    return [a for a in found if a is not None]


def attribution_lines(variant: str, found: list[Attribution]) -> list[str]:
    """The report's section of one variant: a table per requirement, largest driver first."""
    lines = ["", f"## What drives each requirement ({variant})", "",
             "PAWN index of each dispersed value (median KS distance over 10 slices of its "
             f"range; the largest of {DUMMIES} dummy inputs' indices is the noise level), and "
             "where runs fail: the "
             "KS distance between failing and passing runs and the failing runs' "
             "range."]  # fmt: skip
    for a in found:
        lines += ["", f"### {a.requirement}: {a.runs} runs, {a.failed} failing; noise level "
                  f"{a.dummy:.3f}", "",
                  "| value | PAWN | above the noise | KS fail/pass (p) | failing runs' range |",
                  "|---|---|---|---|---|"]  # fmt: skip
        for d in a.drivers:
            ks = "-" if math.isnan(d.ks) else f"{d.ks:.3f} ({d.p_value:.1e})"
            rng = "-" if math.isnan(d.fail_range[0]) else (
                f"{d.fail_range[0]:.4g} to {d.fail_range[1]:.4g}")
            lines.append(f"| {d.label} | {d.pawn:.3f} | {'yes' if d.pawn > a.dummy else 'no'} "
                         f"| {ks} | {rng} |")  # fmt: skip
    return lines


def attribution_figure(variant: str, found: list[Attribution], path, plt):
    """PAWN indices per requirement as bars, the dummy's level dashed; written to `path`."""
    n = len(found)
    height = 0.32 * max(len(a.drivers) for a in found) + 1.6
    fig, axes = plt.subplots(1, n, sharex=True, figsize=(3.6 * n, height), squeeze=False)
    for ax, a in zip(axes[0], found, strict=True):
        labels = [d.label for d in a.drivers][::-1]
        ax.barh(labels, [d.pawn for d in a.drivers][::-1], color="C0")
        ax.axvline(a.dummy, color="0.3", ls="--", lw=0.9,
                   label=f"noise level (dummies) {a.dummy:.3f}")
        ax.set_title(f"{a.requirement} ({a.failed} of {a.runs} fail)", fontsize=9)
        ax.set_xlabel("PAWN index (median KS) [-]")
        ax.tick_params(axis="y", labelsize=7)
        ax.legend(fontsize=7, loc="lower right")
        ax.grid(True, axis="x", alpha=0.3)
    fig.suptitle(f"What drives each requirement's margin ({variant})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
