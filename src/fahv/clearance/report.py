"""A clearance folder's report: its table, its Markdown, its convergence figures.

Read from the folder alone (`campaign.json` and the rows of `results/`), so that
`fahv clearance report DIR` writes it again, optionally beside a finished Monte Carlo
campaign of the same campaign file (`--against CAMPAIGN_DIR`): each requirement's worst
margin over that campaign's runs, computed with the same margins
(`fahv.campaign.robustness`), is the yardstick of the search.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.campaign.robustness import robustness
from fahv.clearance.search import Search
from fahv.errors import CampaignError


def _margin(w: dict | None, unit: str) -> str:
    if w is None or w.get("margin") is None:
        return "-"
    m = w["margin"]
    return "ended early" if m == -math.inf else f"{m:.4g} {unit}"


def summary_lines(manifest: dict) -> list[str]:
    """The console table of a clearance folder's manifest: worst margin per requirement."""

    def cell(w: dict | None, unit: str) -> str:
        return "-" if w is None else f"{_margin(w, unit)} ({w['simulations']} runs)"

    against = any(e.get("campaign") for e in manifest.get("requirements", []))
    lines = [f"clearance of {manifest['name']} (budget {manifest['budget']} runs, "
             f"design {manifest['design_hash']})",
             "requirement     worst margin, search            worst margin, Monte Carlo"
             + ("            worst margin, campaign" if against else "")]  # fmt: skip
    for e in manifest.get("requirements", []):
        s = cell(e["search"], e["unit"])
        row = f"{e['requirement']:<15} {s:<31} {cell(e['monte_carlo'], e['unit']):<31}"
        if against:
            c = e.get("campaign")
            row += " -" if c is None else f" {_margin(c, e['unit'])} ({c['runs']} runs)"
        lines.append(row.rstrip())
    lines.append("margin: limit - value (negative: the requirement fails there)")
    for e in manifest.get("requirements", []):
        c = e.get("certificate")
        if c is None:
            continue
        if c["failures"]:
            lines.append(f"CERTIFICATE FAILURE: {e['requirement']} missed in {len(c['failures'])} "
                         f"certified run(s), the worst run {e['search']['index']} (fahv campaign "
                         "rerun DIR INDEX flies it)")  # fmt: skip
        else:
            lines.append(f"certificate: {e['requirement']} held in all {c['certified_runs']} "
                         "certified runs searched")  # fmt: skip
    return lines


def summary_markdown(manifest: dict) -> str:
    """The clearance's result as Markdown, the file `clearance.md`.

    Per requirement the worst margin found, its run and the values that make it, the
    simulations spent, the Monte Carlo's worst margin and, with a campaign beside it, that
    campaign's.
    """
    reqs = manifest.get("requirements", [])
    against = next((e["campaign"] for e in reqs if e.get("campaign")), None)
    extra = f" worst margin, the campaign's {against['runs']} runs |" if against else ""
    lines = [f"Clearance of campaign `{manifest['name']}` (design {manifest['design_hash']}, "
             f"{manifest.get('optimizer', 'cma')}, budget {manifest['budget']} runs of "
             f"{manifest['duration']:g} s per requirement; margin = limit - value)", "",
             "| requirement | worst margin, search | its run | simulations | failing runs "
             "(the first at simulation) | worst margin, Monte Carlo (same budget) |" + extra,
             "|---|---|---|---|---|---|" + ("---|" if against else "")]  # fmt: skip
    for e in reqs:
        w, mc = e["search"], e["monte_carlo"]
        f = e.get("failing")
        failing = "-" if f is None else (f"{f['runs']} ({f['first']})" if f["runs"] else "0")
        row = (f"| {e['requirement']} | {_margin(w, e['unit'])} | {w.get('index', '-')} "
               f"| {w['simulations']} | {failing} | {_margin(mc, e['unit'])} |")  # fmt: skip
        if against:
            c = e.get("campaign")
            row += f" {_margin(c, e['unit'])} (run {c['index']}) |" if c else " - |"
        lines.append(row)
    for e in reqs:
        c = e.get("certificate")
        if c is not None:
            lines += ["", f"Certificate check of {e['requirement']}: " + (
                f"FAILED in {len(c['failures'])} certified run(s), the worst run "
                f"{e['search']['index']}." if c["failures"] else
                f"held in all {c['certified_runs']} certified runs searched.")]
    for e in reqs:
        v = e["search"].get("values") or {}
        if v:
            shown = ", ".join(f"{k} {val:.4g}" if isinstance(val, float) else f"{k} {val}"
                              for k, val in v.items())  # fmt: skip
            lines += ["", f"Worst case of {e['requirement']} (run {e['search']['index']}, "
                      f"`{e['search'].get('scenario', '')}`): {shown}."]  # fmt: skip
    return "\n".join(lines) + "\n"


def write_convergence(out_dir: Path, entry: dict, rows: list[dict]) -> Path:
    """`convergence_<requirement>.png`: the smallest margin against simulations spent.

    The search's and the Monte Carlo's (rows of the folder, in run order), and the worst
    margin of a campaign beside it (`entry["campaign"]`) as a line.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    req, unit = entry["requirement"], entry["unit"]
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for kind, label in (("search", "search"), ("monte_carlo", "Monte Carlo (same budget)")):
        mine = [r for r in rows if r.get("requirement") == req
                and (r.get("search") == "monte_carlo") == (kind == "monte_carlo")]  # fmt: skip
        if mine:
            ordered = sorted(mine, key=lambda r: r["index"])
            best = Search(margins=[np.nan if r["margin"] is None else r["margin"]
                                   for r in ordered]).best_so_far()  # fmt: skip
            ax.step(np.arange(1, best.size + 1), np.where(np.isfinite(best), best, np.nan),
                    where="post", label=label)  # fmt: skip
    c = entry.get("campaign")
    if c:
        ax.axhline(c["margin"], color="C3", lw=1.0, ls="-.",
                   label=f"worst of the campaign's {c['runs']} runs")  # fmt: skip
    ax.axhline(0.0, color="0.3", lw=0.8, ls="--", label="requirement's limit (margin 0)")
    ax.set_xlabel("simulations")
    ax.set_ylabel(f"smallest margin so far [{unit}]")
    ax.set_title(f"Worst case of '{req}' against the simulations spent")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    path = Path(out_dir) / f"convergence_{req}.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _failing(rows: list[dict], requirement: str) -> dict:
    """How many of the search's runs of `requirement` fail (margin < 0), and the first's place.

    `runs` the count, `first` the simulation (1, 2, ...) of the first failing run (None).
    """
    m = [r["margin"] for r in sorted(rows, key=lambda r: r["index"])
         if r.get("requirement") == requirement and r.get("search") != "monte_carlo"]  # fmt: skip
    bad = [i for i, v in enumerate(m) if v is not None and v < 0.0]
    return {"runs": len(bad), "first": bad[0] + 1 if bad else None}


def against_rows(campaign_dir: Path, manifest: dict) -> list[dict]:
    """The rows of a finished campaign of the same campaign file as `manifest`'s folder.

    The runs of the folder's variant (its campaign's first), read once; the yardstick
    of a clearance (`report --against`) and of a sweep
    (`fahv.clearance.sweep_report`).

    Raises
    ------
    CampaignError
        If the folder is not a campaign (a clearance or a sweep folder has a `kind`) of
        the same campaign file (by name), or holds no run of its variant.
    """
    cm = store.read_manifest(Path(campaign_dir))
    if cm is None or cm.get("kind") is not None or cm["name"] != manifest["name"]:
        raise CampaignError(f"--against {campaign_dir}: not a campaign of {manifest['name']}")
    variant = manifest["campaign"]["variants"][0]
    rows = [r for r in store.read_rows(Path(campaign_dir)) if r["variant"] == variant]
    if not rows:
        raise CampaignError(f"--against {campaign_dir}: no run of variant {variant}")
    return rows


def campaign_worst(rows: list[dict], manifest: dict, requirement: str,
                   rate_limit_degps: float = math.nan) -> dict:  # fmt: skip
    """The worst margin of `requirement` over a finished campaign's rows (`against_rows`).

    Returns
    -------
    dict
        `margin` (the requirement's unit; None where it applies to no run), `runs`,
        `index` (the worst run's).
    """
    limits = manifest["campaign"]["requirements"]
    m = np.array([robustness(r, requirement, limits, rate_limit_degps) for r in rows], float)
    if np.all(np.isnan(m)):
        return {"margin": None, "runs": len(rows), "index": None}
    i = int(np.nanargmin(m))
    return {"margin": float(m[i]), "runs": len(rows), "index": int(rows[i]["index"])}


def report(out_dir: str | Path, against: str | Path | None = None,
           rate_limit_degps: float = math.nan) -> dict:  # fmt: skip
    """Write a clearance folder's `clearance.md` and figures again; its manifest.

    Parameters
    ----------
    out_dir : path
        The clearance folder.
    against : path, optional
        A finished campaign folder of the same campaign file: its worst margins are
        added (manifest entry `campaign`, a column, a line in each figure).
    rate_limit_degps : float
        The elevator servo's rate limit [deg/s] for `input_rates` (NaN: the one the
        clearance recorded in its manifest, else none: ideal actuators).

    Raises
    ------
    CampaignError
        If `out_dir` is not a clearance folder, or `against` not a campaign of it.
    """
    out = Path(out_dir)
    man = store.read_manifest(out)
    if man is None or man.get("kind") != "clearance":
        raise CampaignError(f"{out} is not a clearance folder")
    if math.isnan(rate_limit_degps) and man.get("rate_limit_degps") is not None:
        rate_limit_degps = float(man["rate_limit_degps"])
    if against is not None:
        campaign_rows = against_rows(Path(against), man)
        for e in man["requirements"]:
            e["campaign"] = campaign_worst(campaign_rows, man, e["requirement"],
                                           rate_limit_degps)  # fmt: skip
    rows = store.read_rows(out)
    for e in man["requirements"]:
        e["failing"] = _failing(rows, e["requirement"])
        write_convergence(out, e, rows)
    store.write_manifest(out, man)
    (out / "clearance.md").write_text(summary_markdown(man))
    return man
