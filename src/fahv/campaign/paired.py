"""Paired comparison of two variants of a campaign on common random numbers.

Every run index draws the same dispersed values whatever its variant
(`fahv.campaign.draws`), so run i of variant A and run i of variant B face the
same plant, fault and command: their difference is a paired sample. For each metric
below, over the indices where both runs completed, this gives the mean of the
differences B - A with a 95 % confidence interval (paired t, `scipy.stats.ttest_rel`,
and a percentile bootstrap of the mean, `scipy.stats.bootstrap`, 10 000 resamples,
seed 0), the median difference, and the fraction of runs in which B is larger.
Settling is censored (a run that never settles has no time): it is compared as the
fraction settled in each variant, and the time difference over the runs settled in
both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Paired metrics: (key, label, function of a result row -> value).
PAIRED_METRICS = (
    ("settling_s", "settling after the command [s] (runs settled in both)",
     lambda r: _get(r, "settling_after_command_s")),
    ("attitude_deg", "max attitude error max(|alpha - alpha_r|, |theta - theta_r|) [deg]",
     lambda r: max(_get(r, "alpha_err_max_deg"), _get(r, "theta_err_max_deg"))),
    ("eta1dot_rms", "RMS eta_1_dot after the fault [1/s]",
     lambda r: _get(r, "eta_1_dot_rms_after_fault")),
    ("eta2dot_rms", "RMS eta_2_dot after the fault [1/s]",
     lambda r: _get(r, "eta_2_dot_rms_after_fault")),
    ("eta1_peak", "peak |eta_1 - eta_1,r|", lambda r: _get(r, "eta_1_dev_peak")),
    ("Phi_range", "Phi range used (max - min)", lambda r: _get(r, "Phi_max") - _get(r, "Phi_min")),
    ("delta_e_range_deg", "delta_e range used (max - min) [deg]",
     lambda r: _get(r, "delta_e_max_deg") - _get(r, "delta_e_min_deg")),
    ("h_final_ft", "|h - h_c| at the end [ft]", lambda r: abs(_get(r, "h_err_final_ft"))),
    ("V_final_fps", "|V - V_c| at the end [ft/s]", lambda r: abs(_get(r, "V_err_final_fps"))),
)  # fmt: skip


def _get(row: dict, key: str) -> float:
    v = row.get(key)
    return math.nan if v is None else float(v)


@dataclass(frozen=True)
class PairedStat:
    """Paired differences B - A of one metric.

    Attributes
    ----------
    key, label : str
    n : int
        Pairs used (both runs completed and the metric finite in both).
    mean_a, mean_b : float
        Means of A and B over those pairs.
    mean_diff : float
        Mean of B - A.
    t_ci : (float, float)
        95 % confidence interval of the mean difference, paired t.
    boot_ci : (float, float)
        95 % percentile bootstrap interval of the mean difference.
    median_diff : float
    frac_b_larger : float
        Fraction of pairs with B > A.
    """

    key: str
    label: str
    n: int
    mean_a: float
    mean_b: float
    mean_diff: float
    t_ci: tuple
    boot_ci: tuple
    median_diff: float
    frac_b_larger: float


def _has_metrics(r: dict) -> bool:
    return r.get("alpha_err_max_deg") is not None


def pairs(rows: list[dict], a: str, b: str, completed: bool = True) -> list[tuple[dict, dict]]:
    """(row of A, row of B) of every run index present in both variants.

    `completed`: only indices whose runs both completed (status `ok`); otherwise
    every index where both runs have metrics (a run that left the flight envelope
    keeps its metrics, `fahv.campaign.engine`).
    """
    keep = (lambda r: r["status"] == "ok") if completed else _has_metrics
    ra = {r["index"]: r for r in rows if r["variant"] == a and keep(r)}
    rb = {r["index"]: r for r in rows if r["variant"] == b and keep(r)}
    return [(ra[i], rb[i]) for i in sorted(ra.keys() & rb.keys())]


def mcnemar_p(only_a: int, only_b: int) -> float:
    """Exact McNemar test of equal probabilities from the discordant pairs' counts.

    The two-sided binomial test (`scipy.stats.binomtest`) of only_a successes in
    only_a + only_b trials at 1/2; 1 without discordant pairs (McNemar 1947).

    Examples
    --------
    >>> round(mcnemar_p(2, 7), 4), mcnemar_p(0, 0)
    (0.1797, 1.0)
    """
    from scipy.stats import binomtest

    disc = only_a + only_b
    return float(binomtest(only_a, disc, 0.5).pvalue) if disc else 1.0


def completion(rows: list[dict], a: str, b: str) -> dict:
    """Paired completion counts over the indices run in both variants.

    Returns
    -------
    dict
        `both`, `only_a`, `only_b`, `neither` (counts of indices by which
        variant completed), `n`, and `p_mcnemar`: exact McNemar test (two-sided
        binomial test on the discordant pairs) of equal completion probabilities.
    """
    ra = {r["index"]: r["status"] == "ok" for r in rows if r["variant"] == a}
    rb = {r["index"]: r["status"] == "ok" for r in rows if r["variant"] == b}
    idx = sorted(ra.keys() & rb.keys())
    both = sum(ra[i] and rb[i] for i in idx)
    only_a = sum(ra[i] and not rb[i] for i in idx)
    only_b = sum(rb[i] and not ra[i] for i in idx)
    return {"n": len(idx), "both": both, "only_a": only_a, "only_b": only_b,
            "neither": len(idx) - both - only_a - only_b,
            "p_mcnemar": mcnemar_p(only_a, only_b)}  # fmt: skip


def paired_stats(
    rows: list[dict], a: str, b: str, confidence: float = 0.95, completed: bool = True
) -> dict:
    """Paired statistics of variant b against variant a (module notes).

    Parameters
    ----------
    rows : list of dict
        Result rows of a campaign (`fahv.campaign.store.read_rows`).
    a, b : str
        Variants; differences are b - a.
    confidence : float
        Level of the intervals.
    completed : bool
        Pairs of completed runs only (default), or every pair with metrics
        (`pairs`).

    Returns
    -------
    dict
        `n_pairs`, `completed` (the flag), `completion` (`completion`),
        `settled` ((fraction of A, fraction of B) over the pairs), `stats` {key:
        PairedStat}, `values` {key: (x_a (n,), x_b (n,))}.
    """
    from scipy import stats

    pr = pairs(rows, a, b, completed)
    out: dict = {"n_pairs": len(pr), "completed": completed,
                 "completion": completion(rows, a, b), "stats": {}, "values": {}}  # fmt: skip
    sa = np.array([_get(x, "settling_after_command_s") for x, _ in pr])
    sb = np.array([_get(y, "settling_after_command_s") for _, y in pr])
    out["settled"] = (
        float(np.mean(np.isfinite(sa))) if pr else math.nan,
        float(np.mean(np.isfinite(sb))) if pr else math.nan,
    )
    for key, label, fn in PAIRED_METRICS:
        xa = np.array([fn(x) for x, _ in pr], float)
        xb = np.array([fn(y) for _, y in pr], float)
        ok = np.isfinite(xa) & np.isfinite(xb)
        xa, xb = xa[ok], xb[ok]
        out["values"][key] = (xa, xb)
        n = int(xa.size)
        if n < 2:
            out["stats"][key] = PairedStat(key, label, n, math.nan, math.nan, math.nan,
                                           (math.nan,) * 2, (math.nan,) * 2, math.nan,
                                           math.nan)  # fmt: skip
            continue
        diff = xb - xa
        if np.all(diff == diff[0]):  # no spread: the interval is the value itself
            t_ci = boot_ci = (float(diff[0]), float(diff[0]))
        else:
            ci = stats.ttest_rel(xb, xa).confidence_interval(confidence)
            t_ci = (float(ci.low), float(ci.high))
            bs = stats.bootstrap((diff,), np.mean, confidence_level=confidence,
                                 n_resamples=10_000, method="percentile",
                                 rng=np.random.default_rng(0))  # fmt: skip
            boot_ci = (float(bs.confidence_interval.low), float(bs.confidence_interval.high))
        out["stats"][key] = PairedStat(
            key, label, n, float(xa.mean()), float(xb.mean()), float(diff.mean()), t_ci,
            boot_ci, float(np.median(diff)), float(np.mean(diff > 0.0)),
        )  # fmt: skip
    return out


def _g(v: float) -> str:
    return "nan" if not np.isfinite(v) else f"{v:.4g}"


def table_cell(text: str) -> str:
    r"""`text` as a Markdown table cell: its bars escaped (|h - h_c|, |alpha - alpha_r|).

    Parameters
    ----------
    text : str

    Returns
    -------
    str
        `text` with every `|` as `\|`, so that a table does not split at it.
    """
    return text.replace("|", "\\|")


def paired_text(res: dict, a: str, b: str) -> list[str]:
    """Markdown lines of a paired comparison (`paired_stats`)."""
    sa, sb = res["settled"]
    c = res["completion"]
    which = (
        "completed in both variants"
        if res["completed"]
        else "with metrics in both variants (runs that left the flight envelope included)"
    )
    lines = [
        f"## Paired comparison: {b} - {a} (same draws per run index; {which})",
        "",
        f"Completion over the {c['n']} indices run in both: both {c['both']}, only {a} "
        f"{c['only_a']}, only {b} {c['only_b']}, neither {c['neither']} (exact McNemar "
        f"p = {c['p_mcnemar']:.3g}).",
        "",
        f"{res['n_pairs']} run indices {which}. Settled within the tolerances (10 ft, "
        f"2 ft/s) and held to the end: {a} {100 * sa:.1f} %, {b} {100 * sb:.1f} %.",
        "",
        f"| metric | n | mean {a} | mean {b} | mean diff ({b} - {a}) | 95 % CI paired t | "
        f"95 % CI bootstrap | median diff | runs with {b} larger |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in res["stats"].values():
        lines.append(
            f"| {table_cell(s.label)} | {s.n} | {_g(s.mean_a)} | {_g(s.mean_b)} | "
            f"{_g(s.mean_diff)} | [{_g(s.t_ci[0])}, {_g(s.t_ci[1])}] | "
            f"[{_g(s.boot_ci[0])}, {_g(s.boot_ci[1])}] | "
            f"{_g(s.median_diff)} | {100 * s.frac_b_larger:.1f} % |"
        )
    return lines + [""]


def paired_figures(res: dict, a: str, b: str, folder, plt) -> list:
    """PNG figures: B against A per metric (diagonal = no difference), and the differences."""
    from pathlib import Path

    keys = [k for k, *_ in PAIRED_METRICS]
    labels = {k: lab for k, lab, _ in PAIRED_METRICS}
    nc = 3
    nr = math.ceil(len(keys) / nc)
    fig, axes = plt.subplots(nr, nc, figsize=(4.0 * nc, 3.4 * nr), squeeze=False)
    for ax, k in zip(axes.ravel(), keys, strict=False):
        xa, xb = res["values"][k]
        if xa.size:
            ax.plot(xa, xb, ".", ms=3, alpha=0.6)
            lo, hi = float(min(xa.min(), xb.min())), float(max(xa.max(), xb.max()))
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set_xlabel(f"{a}", fontsize=8)
        ax.set_ylabel(f"{b}", fontsize=8)
        ax.set_title(labels[k], fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(keys) :]:
        ax.axis("off")
    fig.suptitle(f"{b} against {a}, run by run (same draws); dashed: equal", fontsize=9)
    fig.tight_layout()
    p1 = Path(folder) / f"paired_{a}_vs_{b}.png"
    fig.savefig(p1, dpi=100)
    plt.close(fig)
    fig, axes = plt.subplots(nr, nc, figsize=(4.0 * nc, 3.0 * nr), squeeze=False)
    for ax, k in zip(axes.ravel(), keys, strict=False):
        xa, xb = res["values"][k]
        if xa.size:
            ax.hist(xb - xa, bins=40)
            ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(f"{b} - {a}: {labels[k]}", fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(keys) :]:
        ax.axis("off")
    fig.tight_layout()
    p2 = Path(folder) / f"paired_diff_{a}_vs_{b}.png"
    fig.savefig(p2, dpi=100)
    plt.close(fig)
    return [p1, p2]
