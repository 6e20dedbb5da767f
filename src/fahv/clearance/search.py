"""The worst-case search: an evolution strategy over a search space, within a budget.

Two maintained optimisers minimise the requirement's margin (`fahv.campaign.robustness`)
over the box of the search space (`fahv.clearance.space`), each generation's population
evaluated together, one batch of simulations:

- `cma` (default): CMA-ES (Hansen's `cma` package; Hansen and Ostermeier 2001) on the box
  mapped to [0, 1]^d, its bounds handled by the package's transformation, from the box's
  middle with a step of 0.3;
- `de`: scipy's `differential_evolution` (Storn and Price 1997), `vectorized` with its
  update deferred to the end of a generation, its first generation a Latin hypercube.
  Its local polish (L-BFGS-B on finite differences) is not used: a simulated margin is
  not smooth in the fault's onset or the noise seed, and the polish would spend single,
  unbatched simulations.

On the test problems of tests/clearance/test_search.py, 400 simulations of six variables
over five seeds: on a convex margin whose worst case is a corner of the box, CMA-ES came
within 0.1 % of its margin every time, differential evolution reached 77-84 % of it (it
resamples a step that leaves the box instead of stopping at the bound); on a margin with a
local worst case at each of the 64 corners, 96 % against 74 % on average. Both found a
failure confined to a valley 0.06 wide in 300 simulations.

The budget counts simulations: a population of P points over G generations spends P G.
Everything evaluated is kept (`Search`), so the worst case is the worst point of any
generation, not only of the last.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import differential_evolution
from scipy.stats import qmc

#: Objective value of a margin that does not apply (NaN) and of a run that ended early
#: (-inf): finite stand-ins, the first never chosen as worst, the second always.
NOT_APPLICABLE, ENDED_EARLY = 1e9, -1e9
#: What an optimiser calls: points X (P, d) -> (margins (P,), rows (P,)).
Evaluate = Callable[[np.ndarray], tuple[list[float], list[dict]]]


@dataclass
class Search:
    """The points a search evaluated, in order, and their margins.

    Attributes
    ----------
    points : list of ndarray
        Each point (d,) in the search space's variables.
    margins : list of float
        Each point's margin (NaN: not applicable, -inf: the run ended early).
    rows : list of dict
        What each evaluation returned (a campaign row: values, status, metrics).
    generations : list of int
        The generation each point belongs to (0: the first, a Latin hypercube).
    """

    points: list = field(default_factory=list)
    margins: list = field(default_factory=list)
    rows: list = field(default_factory=list)
    generations: list = field(default_factory=list)

    @property
    def worst(self) -> int | None:
        """Index of the evaluation of smallest margin (None if no margin applies)."""
        m = np.array(self.margins, float)
        ok = ~np.isnan(m)
        return int(np.flatnonzero(ok)[np.argmin(m[ok])]) if ok.any() else None

    def best_so_far(self) -> np.ndarray:
        """The smallest margin after each evaluation (E,) (+inf before one applies)."""
        m = np.nan_to_num(np.array(self.margins, float), nan=np.inf)
        return np.minimum.accumulate(m) if m.size else m


class _Recorder:
    """The objective the optimisers call: evaluates a generation, keeps every point."""

    def __init__(self, evaluate, population: int) -> None:
        self.evaluate, self.P, self.found = evaluate, population, Search()

    def __call__(self, pts: np.ndarray) -> np.ndarray:
        """Objective values (P,) of the points pts (P, d), finite stand-ins for NaN, -inf."""
        margins, rows = self.evaluate(pts)
        gen = len(self.found.points) // self.P
        for x, m, r in zip(pts, margins, rows, strict=True):
            self.found.points.append(np.array(x, float))
            self.found.margins.append(float(m))
            self.found.rows.append(r)
            self.found.generations.append(gen)
        m = np.array(margins, float)
        return np.where(np.isnan(m), NOT_APPLICABLE, np.maximum(m, ENDED_EARLY))


def _box(bounds) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.array(bounds, float).reshape(-1, 2).T
    if lo.size == 0 or np.any(~(hi > lo)):
        raise ValueError(f"a search needs a non-empty box, got {bounds}")
    return lo, hi


def cma_search(
    evaluate: Evaluate, bounds: list[tuple[float, float]], budget: int, seed: int = 0,
    population: int | None = None,
) -> Search:
    """Minimise a margin over a box with CMA-ES, one batch per generation.

    Parameters and result as `differential_evolution_search`; the population defaults to
    a 40th of the budget, 10 to 40 points, i.e. 40 generations where the budget allows
    (CMA-ES's own default population for 12 variables is 11).

    Raises
    ------
    ValueError
        If the budget is below one generation, or a bound is empty.
    """
    import cma

    lo, hi = _box(bounds)
    P = int(population or min(max(10, budget // 40), 40))
    if budget < P:
        raise ValueError(f"a budget of {budget} simulations is below one generation of {P}")
    rec = _Recorder(evaluate, P)
    es = cma.CMAEvolutionStrategy(np.full(lo.size, 0.5), 0.3, {
        "bounds": [0.0, 1.0], "popsize": P, "seed": int(seed) + 1, "verbose": -9,
        "tolfun": 0.0, "tolx": 0.0, "tolfunhist": 0.0, "tolflatfitness": 10**9,
        "tolstagnation": 10**9})  # fmt: skip
    for _ in range(budget // P):
        U = np.array(es.ask())
        es.tell(list(U), rec(lo + U * (hi - lo)).tolist())
    return rec.found


def population_size(budget: int, n_variables: int) -> int:
    """Points per generation for a budget: about a tenth of it, at least 5, at most 10 d.

    Raises
    ------
    ValueError
        If the budget is below one generation of 5 points.
    """
    if budget < 5:
        raise ValueError(f"a budget of {budget} simulations is below one generation (5)")
    return int(min(max(5, budget // 10), 10 * n_variables, budget))


def differential_evolution_search(
    evaluate: Evaluate, bounds: list[tuple[float, float]], budget: int, seed: int = 0,
    population: int | None = None,
) -> Search:
    """Minimise a margin over a box with differential evolution, one batch per generation.

    Parameters
    ----------
    evaluate : callable
        `evaluate(X)` with X (P, d) returns (margins (P,), rows (P,)) for P points.
    bounds : list of (lo, hi)
        The box (d variables).
    budget : int
        Simulations to spend at most (the population times the generations).
    seed : int
        Seed of the first generation and of the evolution.
    population : int, optional
        Points per generation (default `population_size`).

    Returns
    -------
    Search
        Every point evaluated, its margin and row, in order.

    Raises
    ------
    ValueError
        If the budget is below one generation, or a bound is empty.
    """
    lo, hi = _box(bounds)
    d = lo.size
    P = population_size(budget, d) if population is None else int(population)
    if P > budget or P < 5:
        raise ValueError(f"a budget of {budget} simulations is below one generation of {P}")
    generations = budget // P  # the first included
    init = qmc.scale(qmc.LatinHypercube(d, rng=np.random.default_rng(seed)).random(P), lo, hi)
    rec = _Recorder(evaluate, P)
    if generations == 1:
        rec(init)
        return rec.found
    differential_evolution(lambda X: rec(np.atleast_2d(X.T)), list(zip(lo, hi, strict=True)),
                           init=init, maxiter=generations - 1, tol=0.0, atol=0.0,
                           polish=False, vectorized=True, updating="deferred",
                           rng=seed)  # fmt: skip
    return rec.found


#: The optimisers `fahv clearance --optimizer` offers.
OPTIMIZERS = {"cma": cma_search, "de": differential_evolution_search}
