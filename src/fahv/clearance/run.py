"""`fahv clearance`: search a campaign's dispersion space for each requirement's worst case.

For each requirement asked, a search (`fahv.clearance.search`: CMA-ES or differential
evolution) of
the campaign's dispersions (`fahv.clearance.space`), every generation one batch of runs
on Dask (`fahv.clearance.evaluate`); optionally beside it a Monte Carlo of the same
budget, the campaign's own first draws. The folder it writes:

- `campaign.json`: the campaign, design, budget and, per requirement, the worst case
  found (its margin, run index, values, status), the simulations spent, the Monte Carlo's
  worst; `clearance.md`, the same as a Markdown table (`fahv.clearance.report`);
- `results/`: every run as a campaign row (Parquet) with its `requirement`, `search`
  (`cma`, `de` or `monte_carlo`), `generation` and `margin`;
- `convergence_<requirement>.png`: the smallest margin against the simulations spent;
- `worst_<requirement>.yaml`: the worst case as a scenario extending the campaign's
  (`fahv.clearance.worst`), for `fahv simulate` and `fahv sil`;
- `design/` and `campaign.json`: the design and the campaign, so that
  `fahv campaign rerun DIR INDEX` flies any run of it again (in process or `--sil`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.campaign.draws import row_values
from fahv.campaign.robustness import SEARCHABLE
from fahv.campaign.spec import Campaign
from fahv.certificate.verified import load_or_design
from fahv.clearance.evaluate import CampaignEvaluator
from fahv.clearance.report import report
from fahv.clearance.search import OPTIMIZERS, Search
from fahv.clearance.space import SearchSpace
from fahv.clearance.worst import write_worst_scenario
from fahv.cluster import dask_client
from fahv.errors import CampaignError
from fahv.spec.artefacts import save_design
from fahv.spec.coverage import certified_onset_loss
from fahv.spec.requirements import limits_of
from fahv.spec.schema import plant_choices
from fahv.version import __version__

#: Marks a clearance folder's manifest (`campaign.json`), beside the campaign's data.
KIND = "clearance"


@dataclass
class Found:
    """What the search found for one requirement (`clear`'s result).

    Attributes: `requirement`, `unit`, `search` (the differential evolution's
    `Search`), `monte_carlo` (the campaign's own draws of the same budget, or None).
    """

    requirement: str
    unit: str
    search: Search
    monte_carlo: Search | None = None


def elevator_rate_limit_degps(campaign: Campaign) -> float:
    """The elevator servo's rate limit [deg/s] of the campaign's plant (NaN: ideal)."""
    if plant_choices(campaign.run_spec.data)["actuators"] == "ideal":
        return math.nan
    lim = campaign.vehicle.limits
    return math.degrees(min(lim.rate_incr[1], lim.rate_decr[1]))


def check_requirements(requirements: list[str]) -> None:
    """Refuse a requirement whose margin a clearance cannot measure.

    Raises
    ------
    CampaignError
        Naming the requirement and those that can be searched.
    """
    for r in requirements:
        if r not in SEARCHABLE:
            raise CampaignError(f"--requirement {r}: not a requirement a clearance searches "
                                f"({', '.join(SEARCHABLE)})")  # fmt: skip


def check_request(requirements: list[str], budget: int) -> None:
    """Refuse a requirement a clearance cannot search, or a budget below one generation.

    Raises
    ------
    CampaignError
        Naming the requirement (and those that can be searched) or the budget.
    """
    check_requirements(requirements)
    if budget < 10:
        raise CampaignError(f"--budget {budget}: below one generation of 10 simulations")


def clear(campaign: Campaign, requirements: list[str], budget: int, out_dir: str | Path,
          scheduler: str | None = None, workers: int | None = None, seed: int = 0,
          noise_seeds: int = 0, with_monte_carlo: bool = False, optimizer: str = "cma",
          population: int | None = None, certificate: bool = False,
          log=print) -> list[Found]:  # fmt: skip
    """Search the campaign's dispersions for each requirement's worst case; write the folder.

    Parameters
    ----------
    campaign : Campaign
        Its scenario, dispersions, first variant and requirement limits are used.
    requirements : list of str
        Requirements to search (`fahv.campaign.robustness.SEARCHABLE`).
    budget : int
        Simulations per requirement (and per Monte Carlo).
    out_dir : path
        Folder written (see the module notes); must not hold a clearance already.
    scheduler, workers
        The Dask cluster (`fahv.cluster.dask_client`).
    seed : int
        Seed of the search.
    noise_seeds : int
        Search the sensor noise among the campaign's first runs' seeds (0: fixed).
    with_monte_carlo : bool
        Also run the campaign's first `budget` draws and report their worst.
    optimizer : str
        `cma` or `de` (`fahv.clearance.search.OPTIMIZERS`).
    population : int, optional
        Points per generation (the optimiser's default by the budget).
    certificate : bool
        Check the design's certificate: search only what it certifies (losses up to its
        certified onset loss, runs whose coverage is `certified`); a negative margin there
        is a certificate failure (`certificate_failures`).
    log : callable
        Progress lines.

    Returns
    -------
    list of Found

    Raises
    ------
    CampaignError
        On a requirement that cannot be searched, a budget below one generation, a
        campaign with nothing to search, or a folder that holds results.
    """
    check_request(requirements, budget)
    out = Path(out_dir)
    if store.read_rows(out):
        raise CampaignError(f"{out} already holds results: use another --out")
    space = SearchSpace.of(campaign.data, campaign.run_spec.data, noise_seeds)
    _, design, _ = load_or_design(campaign.run_spec.path, log=lambda *_: None,
                                  allow_uncertified=True)  # fmt: skip
    variant = campaign["variants"][0]
    limits = limits_of(campaign.data)
    if certificate:
        if "fault.loss" in space.names:
            space = space.within("fault.loss", certified_onset_loss(design))
        log(f"certificate check of {design.case['name']}: the certified runs alone, losses up "
            f"to {certified_onset_loss(design):.4g}")  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    save_design(design, out / "design")
    store.write_manifest(out, {
        "kind": KIND, "name": campaign.name, "hash": campaign.content_hash(),
        "campaign": campaign.data, "campaign_file": str(campaign.path),
        "case": campaign.run_spec.data, "duration": campaign.duration,
        "design_hash": design.summary["design_hash"], "code_version": __version__,
        "started": time.strftime("%Y-%m-%d %H:%M:%S"), "budget": budget, "seed": seed,
        "optimizer": optimizer, "population": population, "certificate": certificate,
        "rate_limit_degps": _json_float(elevator_rate_limit_degps(campaign)),
        "variables": [vars(v) | {"choices": list(v.choices)} for v in space.variables],
        "fixed": space.fixed,
    })  # fmt: skip
    client, cluster = dask_client(scheduler, workers)
    found: list[Found] = []
    try:
        tasks = len(client.scheduler_info()["workers"]) or 1
        ev = CampaignEvaluator(space, design, variant, campaign.duration, client, limits,
                               elevator_rate_limit_degps(campaign), tasks,
                               certified_only=certificate)  # fmt: skip
        for r in requirements:
            ev.requirement = r
            t0 = time.perf_counter()
            s = OPTIMIZERS[optimizer](ev, space.bounds, budget, seed, population)
            _write_rows(out, r, optimizer, s)
            log(f"{r}: {len(s.margins)} simulations in {time.perf_counter() - t0:.0f} s")
            mc = None
            if with_monte_carlo:
                rows = ev.draws(range(min(budget, campaign["runs"])))
                mc = Search([np.array([float(x["index"])]) for x in rows], ev.margins(rows),
                            rows, [0] * len(rows))  # fmt: skip
                _write_rows(out, r, "monte_carlo", mc)
            found.append(Found(r, SEARCHABLE[r], s, mc))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    summary = [_summary(f, certificate) for f in found]
    for f, entry in zip(found, summary, strict=True):
        i = f.search.worst
        if i is not None:
            path = write_worst_scenario(campaign, f.search.rows[i], variant, f.requirement, out)
            entry["search"]["scenario"] = path.name
    man = {**(store.read_manifest(out) or {}), "requirements": summary}
    store.write_manifest(out, man)
    report(out)
    return found


def _json_float(v: float) -> float | None:
    """A float for the manifest: None for NaN (JSON has no NaN)."""
    return None if math.isnan(v) else float(v)


def _write_rows(out: Path, requirement: str, search: str, s: Search) -> None:
    rows = [{**row, "requirement": requirement, "search": search, "generation": g,
             "margin": m} for row, m, g in zip(s.rows, s.margins, s.generations, strict=True)]
    store.write_part(out, store.RESULTS, f"part-{requirement}-{search}", rows)


def certificate_failures(s: Search) -> list[int]:
    """Indices (run indices) of the certified runs whose margin is negative."""
    return [int(r["index"]) for r, m in zip(s.rows, s.margins, strict=True) if m < 0.0]


def _summary(f: Found, certificate: bool) -> dict:
    """The manifest's entry of one requirement: worst cases and what they cost."""

    def worst(s: Search | None) -> dict | None:
        if s is None:
            return None
        i = s.worst
        if i is None:
            return {"margin": None, "simulations": len(s.margins), "index": None}
        row = s.rows[i]
        return {"margin": s.margins[i], "simulations": len(s.margins), "index": row["index"],
                "status": row["status"], "reason": row.get("reason", ""),
                "generation": s.generations[i],
                "values": row_values(row)}

    out = {"requirement": f.requirement, "unit": f.unit, "search": worst(f.search),
           "monte_carlo": worst(f.monte_carlo)}
    if certificate:
        certified = int(np.sum(~np.isnan(np.array(f.search.margins, float))))
        out["certificate"] = {"certified_runs": certified,
                              "failures": certificate_failures(f.search)}  # fmt: skip
    return out
