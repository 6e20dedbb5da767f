"""One-at-a-time sweeps: each dispersed value over its range, the others at the box's centre.

The check of a campaign's attribution (`fahv.campaign.attribution`) by direct simulation:
PAWN ranks the dispersed values by how much each moves a requirement's margin over the
campaign's random runs; a one-at-a-time (OAT) sweep moves one value at a time across its
whole range, every other value at the centre of its range (the search box of
`fahv.clearance.space`, the sensor noise held at the campaign's run 0's), and measures
the margin's spread (largest minus smallest margin over the sweep). An input that drives
the margin in the campaign moves it in its sweep; an input within PAWN's noise level
leaves it flat, unless its effect exists only together with another input's (an
interaction, which an OAT sweep cannot show and PAWN, over the whole sample, can).
Saltelli et al., *Global Sensitivity Analysis: The Primer* (Wiley, 2008), ch. 1, on what
OAT designs can and cannot tell.

The folder it writes:

- `campaign.json` (kind `sweep`): the campaign, the centre, and per input its values and
  each requirement's margins; `sweep.md`: per requirement, the inputs by their spread, beside
  the PAWN index of a finished campaign (`--against`);
- `results/`: every run as a campaign row with its `input` and `margin_<requirement>`;
- `sweep_<requirement>.png`: the margin against each input, in physical units.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.campaign.spec import Campaign
from fahv.certificate.verified import load_or_design
from fahv.clearance.evaluate import CampaignEvaluator
from fahv.clearance.run import check_requirements, elevator_rate_limit_degps
from fahv.clearance.space import SearchSpace
from fahv.cluster import dask_client
from fahv.errors import CampaignError
from fahv.spec.requirements import limits_of
from fahv.version import __version__

#: Marks a sweep folder's manifest (`campaign.json`).
KIND = "sweep"
#: Fewest points of a sweep (its two ends and the centre).
FEWEST_POINTS = 3


@dataclass(frozen=True)
class Sweep:
    """One input swept over its range (`sweep`'s result).

    Attributes
    ----------
    name : str
        The input (`fahv.clearance.space.Variable.name`: `s.m`, `fault.loss`, ...).
    values : (P,) ndarray
        Its values along the sweep [its unit; a choice's index for a choice].
    margins : dict
        Requirement -> (P,) ndarray of the margin at each value (NaN: no margin).
    """

    name: str
    values: np.ndarray
    margins: dict

    def spread(self, requirement: str) -> float:
        """Largest minus smallest finite margin of `requirement` over the sweep (NaN: none)."""
        m = self.margins[requirement]
        m = m[np.isfinite(m)]
        return float(m.max() - m.min()) if m.size else math.nan


def sweep_points(space: SearchSpace, names: list[str], points: int) -> tuple[np.ndarray, list]:
    """The points of the sweeps of `names`: (centre (d,), [(name, its values (P,), X (P, d))]).

    The centre is every variable's mid-range; a choice's sweep takes each of its choices
    once (at the middle of its unit interval), a real value `points` values from its
    lower to its upper bound.

    Raises
    ------
    CampaignError
        If a name is not one of the space's variables (naming them), or `points` is
        below `FEWEST_POINTS`.
    """
    if points < FEWEST_POINTS:
        raise CampaignError(f"--points {points}: a sweep needs at least {FEWEST_POINTS}")
    unknown = [n for n in names if n not in space.names]
    if unknown:
        raise CampaignError(f"--input {', '.join(unknown)}: not a dispersed value of the "
                            f"campaign ({', '.join(space.names)})")  # fmt: skip
    lo, hi = np.array(space.bounds).T
    centre = 0.5 * (lo + hi)
    out = []
    for name in names:
        j = space.names.index(name)
        v = space.variables[j]
        values = (np.arange(len(v.choices)) + 0.5 if v.choices
                  else np.linspace(v.lo, v.hi, points))  # fmt: skip
        X = np.repeat(centre[None], len(values), axis=0)
        X[:, j] = values
        out.append((name, values, X))
    return centre, out


def sweep(campaign: Campaign, requirements: list[str], out_dir: str | Path,
          inputs: list[str] | None = None, points: int = 9, scheduler: str | None = None,
          workers: int | None = None, log=print) -> list[Sweep]:  # fmt: skip
    """Sweep each input of the campaign one at a time; write the folder (module notes).

    Parameters
    ----------
    campaign : Campaign
        Its scenario, dispersions, first variant and requirement limits are used.
    requirements : list of str
        Requirements whose margins are measured (`fahv.campaign.robustness.SEARCHABLE`).
    out_dir : path
        Folder written; must not hold results already.
    inputs : list of str, optional
        The inputs swept (default: every dispersed value but the noise).
    points : int
        Values of each real input's sweep.
    scheduler, workers
        The Dask cluster (`fahv.cluster.dask_client`).
    log : callable
        Progress lines.

    Returns
    -------
    list of Sweep
        In the order of `inputs`.

    Raises
    ------
    CampaignError
        On a requirement that cannot be measured, an unknown input, too few points, or
        a folder that holds results.
    """
    check_requirements(requirements)
    out = Path(out_dir)
    if store.read_rows(out):
        raise CampaignError(f"{out} already holds results: use another --out")
    space = SearchSpace.of(campaign.data, campaign.run_spec.data)
    names = list(inputs) if inputs else space.names
    centre, plan = sweep_points(space, names, points)
    _, design, _ = load_or_design(campaign.run_spec.path, log=lambda *_: None,
                                  allow_uncertified=True)  # fmt: skip
    client, cluster = dask_client(scheduler, workers)
    try:
        tasks = len(client.scheduler_info()["workers"]) or 1
        ev = CampaignEvaluator(space, design, campaign["variants"][0], campaign.duration,
                               client, limits_of(campaign.data),
                               elevator_rate_limit_degps(campaign), tasks)  # fmt: skip
        t0 = time.perf_counter()
        rows = ev.rows(np.vstack([X for _, _, X in plan]))
        log(f"{len(rows)} runs of {campaign.duration:g} s in {time.perf_counter() - t0:.0f} s")
        margins = {}
        for r in requirements:
            ev.requirement = r
            margins[r] = np.array(ev.margins(rows), float)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    found, k = [], 0
    for name, values, _ in plan:
        n = len(values)
        found.append(Sweep(name, values, {r: m[k : k + n] for r, m in margins.items()}))
        for i in range(k, k + n):
            rows[i]["input"] = name
            rows[i].update({f"margin_{r}": float(margins[r][i]) for r in requirements})
        k += n
    out.mkdir(parents=True, exist_ok=True)
    store.write_part(out, store.RESULTS, "part-sweep", rows)
    store.write_manifest(out, {
        "kind": KIND, "name": campaign.name, "campaign": campaign.data,
        "campaign_file": str(campaign.path), "duration": campaign.duration,
        "design_hash": design.summary["design_hash"], "code_version": __version__,
        "started": time.strftime("%Y-%m-%d %H:%M:%S"), "requirements": requirements,
        "centre": dict(zip(space.names, map(float, centre), strict=True)),
        "fixed": space.fixed,
        "inputs": [{"name": s.name, "values": s.values.tolist(),
                    "margins": {r: m.tolist() for r, m in s.margins.items()}}
                   for s in found],
    })  # fmt: skip
    return found
