"""Two campaigns of the same draws compared run by run (`fahv campaign compare`).

A campaign's dispersed values are a function of its seed and the run index
(`fahv.campaign.draws`), so two campaign folders made from the same campaign file around
two scenarios (`fahv campaign FILE --scenario S --out DIR`) fly the same vehicles,
faults, commands and sensor seeds at every index: a change of the loop is judged on the
pairs. For each requirement (`fahv.campaign.report.verdicts`) this gives the runs passing
in each, the discordant pairs and the exact McNemar test of equal pass probabilities
(two-sided binomial test on the discordant pairs), with two-sided Clopper-Pearson
intervals of each pass rate; the metrics' paired differences are those of
`fahv.campaign.paired`. Judging a change on the runs that failed before it instead finds
improvements by chance wherever runs sit near a threshold (docs/results/campaigns.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from fahv.campaign import store
from fahv.campaign.paired import mcnemar_p, paired_stats, paired_text, table_cell
from fahv.campaign.report import REQUIREMENTS, verdicts
from fahv.errors import CampaignError

#: The requirements compared: the report's, and every one of them but the tube (a loop on
#: a state estimate is not in the state-feedback tube by construction).
COMPARED = (*((k, label) for k, label in REQUIREMENTS if k != "nominal_range"),
            ("all_but_tube", "every requirement but the tube, at once"))  # fmt: skip


#: The campaign-file keys that must agree for the draws to be the same.
SAME_DRAWS = ("seed", "dispersions", "requirements")


@dataclass(frozen=True)
class RequirementPair:
    """One requirement over the run indices of both campaigns.

    Attributes
    ----------
    key, label : str
    n : int
        Run indices in both.
    pass_a, pass_b : int or None
        Runs passing in each (None: applicable to no run on that side).
    only_a, only_b : int or None
        Discordant pairs: indices passing in one campaign only (None with a side n/a).
    p_mcnemar : float
        Exact McNemar test of equal pass probabilities (1 without discordant pairs; NaN
        with a side n/a).
    ci_a, ci_b : (float, float)
        Two-sided 95 % Clopper-Pearson intervals of each pass rate (NaN where n/a).
    """

    key: str
    label: str
    n: int
    pass_a: int
    pass_b: int
    only_a: int
    only_b: int
    p_mcnemar: float
    ci_a: tuple
    ci_b: tuple


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided Clopper-Pearson interval of a pass rate, k passes in n runs.

    `scipy.stats.binomtest(k, n).proportion_ci(method="exact")`; (nan, nan) for n = 0.

    Examples
    --------
    >>> [round(v, 4) for v in clopper_pearson(893, 1000)]
    [0.8722, 0.9115]
    """
    from scipy.stats import binomtest

    if n == 0:
        return (math.nan, math.nan)
    ci = binomtest(k, n).proportion_ci(confidence_level=confidence, method="exact")
    return float(ci.low), float(ci.high)


def _passes(row: dict, req: dict) -> dict[str, bool]:
    v = verdicts(row, req)
    out = {k: bool(v[k]) for k, _ in COMPARED if k in v and v[k] is not None}
    others = (val for k, val in v.items() if k not in ("all", "tube", "nominal_range"))
    out["all_but_tube"] = all(bool(val) for val in others if val is not None)
    return out


def requirement_pairs(rows_a: list[dict], rows_b: list[dict], req: dict) -> list[RequirementPair]:
    """Each requirement's paired counts over the run indices in both row lists.

    Parameters
    ----------
    rows_a, rows_b : list of dict
        Result rows of one variant in each campaign (`fahv.campaign.store.read_rows`).
    req : dict
        The campaigns' requirements (campaign-file section `requirements`).

    Returns
    -------
    list of RequirementPair
        In the order of `COMPARED`; a requirement not applicable to a run of a list that
        has it in other runs counts as not passing there, one applicable to no run of
        either list is left out, and one applicable to no run of one list (the servos'
        rate on ideal actuators against servos, the tube of a law without one, a metric
        an earlier dataset lacks) is n/a on that side: pass counts None, no McNemar test.
    """
    va = {r["index"]: _passes(r, req) for r in rows_a}
    vb = {r["index"]: _passes(r, req) for r in rows_b}
    idx = sorted(va.keys() & vb.keys())
    out = []
    for key, label in COMPARED:
        if not any(key in va[i] or key in vb[i] for i in idx):
            continue
        if not all(any(key in v[i] for i in idx) for v in (va, vb)):
            counts = [sum(v[i].get(key, False) for i in idx)
                      if any(key in v[i] for i in idx) else None for v in (va, vb)]  # fmt: skip
            cis = [(math.nan, math.nan) if c is None else clopper_pearson(c, len(idx))
                   for c in counts]  # fmt: skip
            out.append(RequirementPair(key, label.format(**req), len(idx), *counts, None, None,
                                       math.nan, *cis))  # fmt: skip
            continue
        a = [va[i].get(key, False) for i in idx]
        b = [vb[i].get(key, False) for i in idx]
        only_a = sum(x and not y for x, y in zip(a, b, strict=True))
        only_b = sum(y and not x for x, y in zip(a, b, strict=True))
        out.append(RequirementPair(key, label.format(**req), len(idx), sum(a), sum(b), only_a,
                                   only_b, mcnemar_p(only_a, only_b),
                                   clopper_pearson(sum(a), len(idx)),
                                   clopper_pearson(sum(b), len(idx))))  # fmt: skip
    return out


def _manifest(folder: Path) -> dict:
    man = store.read_manifest(folder)
    if man is None:
        raise CampaignError(f"{folder} is not a campaign folder (no {store.MANIFEST})")
    return man


def compare_campaigns(dir_a, dir_b, variant: str | None = None,
                      variant_b: str | None = None) -> tuple[list[str], list]:  # fmt: skip
    """The run-by-run comparison of two campaign folders of the same draws.

    Parameters
    ----------
    dir_a, dir_b : path
        Campaign folders; differences are B - A.
    variant : str, optional
        The variant of A compared (default: the first variant of A that B also ran).
    variant_b : str, optional
        The variant of B compared, when another (default: `variant`): a law against
        another over the same draws, each from its own campaign.

    Returns
    -------
    (list of str, list of RequirementPair)
        Markdown lines (the requirements' table, then the metrics' paired differences)
        and the requirements' counts.

    Raises
    ------
    CampaignError
        If a folder is not a campaign folder, the two differ in seed, dispersions or
        requirements (their draws or verdicts are not the same), they share no variant
        (without `variant_b`) or no run index, or a variant is not in its campaign.
    """
    a, b = Path(dir_a), Path(dir_b)
    ma, mb = _manifest(a), _manifest(b)
    for key in SAME_DRAWS:
        if ma["campaign"].get(key) != mb["campaign"].get(key):
            raise CampaignError(f"{a} and {b} differ in the campaign key {key!r}: their runs "
                                "are not the same draws, so they do not pair")  # fmt: skip
    va_all, vb_all = ma["campaign"]["variants"], mb["campaign"]["variants"]
    common = [v for v in va_all if v in vb_all]
    if variant is None and variant_b is None and not common:
        raise CampaignError(f"{a} and {b} share no variant: name them (--variant, --variant-b)")
    v = variant or (common[0] if common and variant_b is None else va_all[0])
    w = variant_b or v
    for name, folder, have in ((v, a, va_all), (w, b, vb_all)):
        if name not in have:
            raise CampaignError(f"variant {name!r} is not in {folder} (its variants: {have})")
    la, lb = f"A ({a.name}, {v})", f"B ({b.name}, {w})"
    rows_a = [dict(r, variant=la) for r in store.read_rows(a) if r["variant"] == v]
    rows_b = [dict(r, variant=lb) for r in store.read_rows(b) if r["variant"] == w]
    req = ma["campaign"]["requirements"]
    pairs = requirement_pairs(rows_a, rows_b, req)
    if not pairs or pairs[0].n == 0:
        raise CampaignError(f"{a} ({v}) and {b} ({w}) have no run index in common")
    lines = [f"# B ({b}, {w}, scenario {mb['case'].get('name', '?')}) against A ({a}, {v}, "
             f"scenario {ma['case'].get('name', '?')}), run by run", "",
             f"{pairs[0].n} run indices in both; passing runs with two-sided 95 % "
             "Clopper-Pearson intervals; discordant pairs and the exact McNemar test.", "",
             "| requirement | A | B | only A | only B | McNemar p |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    def cell(k, ci) -> str:
        return "n/a" if k is None else f"{k} [{ci[0]:.4f}, {ci[1]:.4f}]"

    for r in pairs:  # no discordant pairs where one side's plant lacks the requirement
        test = ("- | - | -" if r.only_a is None else
                f"{r.only_a} | {r.only_b} | {r.p_mcnemar:.3g}")  # fmt: skip
        lines.append(f"| {table_cell(r.label)} | {cell(r.pass_a, r.ci_a)} | "
                     f"{cell(r.pass_b, r.ci_b)} | {test} |")  # fmt: skip
    res = paired_stats(rows_a + rows_b, la, lb, req["confidence"])
    return lines + [""] + paired_text(res, la, lb), pairs
