"""A clearance's simulations: each generation of points one batch on the campaign engine.

The points of a generation become the dispersed values of runs
(`fahv.clearance.space.SearchSpace.values`), split into tasks of at most the campaign's
`batch_size` runs over the Dask workers (`fahv.campaign.engine.run_batch`: the same
overrides, batched simulator and metrics as a campaign's runs), and come back as campaign
rows in order. A run that raises or diverges is a row with status `failed`, as in a
campaign; it never stops the search.
"""

from __future__ import annotations

import math

import numpy as np

from fahv.campaign.engine import run_batch
from fahv.campaign.robustness import robustness
from fahv.clearance.space import SearchSpace
from fahv.spec.coverage import is_certified


class CampaignEvaluator:
    """Runs points of a search space on a Dask client; margins of one requirement.

    Parameters
    ----------
    space : SearchSpace
    design : fahv.spec.artefacts.Design
        The campaign's design (scattered to the workers once).
    variant : str
    duration : float
        Simulated time of each run [s].
    client : distributed.Client
    limits : dict
        Requirement limits (`fahv.spec.requirements.limits_of`).
    rate_limit_degps : float
        The elevator servo's rate limit [deg/s] (NaN: ideal actuators).
    tasks : int
        Tasks a generation is split into at least (the workers; more when a generation
        is larger than the campaign's `batch_size`).
    certified_only : bool
        A run the design does not certify (its `coverage`, `fahv.spec.coverage`) has no
        margin (NaN): the certificate check searches the certified runs alone.
    """

    def __init__(self, space: SearchSpace, design, variant: str, duration: float, client,
                 limits: dict, rate_limit_degps: float = math.nan,
                 tasks: int = 1, certified_only: bool = False) -> None:  # fmt: skip
        self.space, self.variant, self.duration = space, variant, float(duration)
        self.client, self.limits, self.rate = client, limits, float(rate_limit_degps)
        self.tasks, self.certified_only = max(1, int(tasks)), bool(certified_only)
        self.design = client.scatter(design, broadcast=True)
        # the next run's index: after the campaign's own draws, which a Monte Carlo runs
        self.count = int(space.data["runs"])
        self.requirement = ""

    def rows(self, points: np.ndarray) -> list[dict]:
        """The campaign rows of the runs at `points` (P, d), in order."""
        values = [self.space.values(x) for x in np.atleast_2d(points)]
        ids = list(range(self.count, self.count + len(values)))
        self.count += len(values)
        return self._run(ids, values)

    def draws(self, indices) -> list[dict]:
        """The campaign rows of the campaign's own draws `indices` (a Monte Carlo), in order."""
        return self._run([int(i) for i in indices], None)

    def _run(self, ids: list[int], values: list[dict] | None) -> list[dict]:
        n = len(ids)
        size = min(int(self.space.data["batch_size"]), math.ceil(n / self.tasks))
        futures = [
            self.client.submit(run_batch, self.design, self.space.data, self.variant,
                               ids[j : j + size], self.duration,
                               None if values is None else values[j : j + size],
                               pure=False, retries=2)  # fmt: skip
            for j in range(0, n, size)
        ]
        return [row for f in futures for row in f.result()["rows"]]

    def margins(self, rows: list[dict]) -> list[float]:
        """The margin of the current `requirement` on each row.

        NaN for a run the design does not certify, when only certified runs count.
        """
        return [math.nan if self.certified_only and not is_certified(r.get("coverage"))
                else robustness(r, self.requirement, self.limits, self.rate)
                for r in rows]  # fmt: skip

    def __call__(self, points: np.ndarray) -> tuple[list[float], list[dict]]:
        """(margins, rows) of the runs at `points` (P, d): `search`'s `evaluate`."""
        rows = self.rows(points)
        return self.margins(rows), rows
