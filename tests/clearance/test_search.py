"""The worst-case search (fahv.clearance.search) on functions whose worst case is known."""

import math

import numpy as np
import pytest

from fahv.clearance.search import (
    OPTIMIZERS,
    cma_search,
    differential_evolution_search,
    population_size,
)

#: A box of six variables; a convex margin 1 + g'x + 0.1 |x - c|^2 whose one minimum is
#: the corner -sign(g) (the quadratic too weak to pull any variable inside).
BOX = [(-1.0, 1.0)] * 6
G = np.array([0.8, -0.6, 0.5, 0.7, -0.9, 0.4])
C = np.array([0.3, -0.2, 0.1, 0.05, 0.45, -0.35])
CORNER = -np.sign(G)
WORST = 1.0 + float(CORNER @ G) + 0.1 * float(np.sum((CORNER - C) ** 2))  # -2.2832


def convex(X):
    """Margins of the points X (P, 6) and a row each."""
    m = 1.0 + X @ G + 0.1 * np.sum((X - C) ** 2, axis=1)
    return m.tolist(), [{"x": x.tolist()} for x in X]


def bowl(X):
    """1 - |x - c|^2: every one of the 64 corners a local worst case, the farthest one the
    worst (a margin with many local worst cases, as a clearance's often is)."""
    return (1.0 - np.sum((X - C) ** 2, axis=1)).tolist(), [{} for _ in X]


def test_cma_es_finds_the_worst_corner_within_its_budget():
    """400 simulations: CMA-ES's worst margin is within 0.1 % of the true worst (-2.283),
    at the corner to 0.01 in every variable (measured: 0.9990-0.9999 of it, within 0.002,
    seeds 0-4); it spends its budget, one call of `evaluate` per generation of 10."""
    calls = []

    def counted(X):
        calls.append(len(X))
        return convex(X)

    found = cma_search(counted, BOX, budget=400, seed=3)
    assert sum(calls) == len(found.margins) == 400 and set(calls) == {10}
    i = found.worst
    assert found.margins[i] == pytest.approx(WORST, rel=1e-3)
    np.testing.assert_allclose(found.points[i], CORNER, atol=0.01)
    best = found.best_so_far()
    assert np.all(np.diff(best) <= 0) and best[-1] == found.margins[i]


def test_the_optimisers_compared():
    """The comparison the search's notes state, seeds 0-4, 400 simulations each: on the
    convex margin CMA-ES reaches at least 99.5 % of the worst corner's margin every time,
    differential evolution at most 90 % (measured 77-84 %: it resamples a step that leaves
    the box instead of stopping at the bound); on the bowl of 64 local worst cases CMA-ES
    reaches 93 % or more on average (measured 96 %), differential evolution less (74 %)."""
    def reached(f, problem, worst):
        return np.array([min(f(problem, BOX, budget=400, seed=k).margins) / worst
                         for k in range(5)])  # fmt: skip

    far = np.where(C > 0, -1.0, 1.0)
    bowl_worst = 1.0 - float(np.sum((far - C) ** 2))
    assert reached(cma_search, convex, WORST).min() >= 0.995
    assert reached(differential_evolution_search, convex, WORST).max() <= 0.90
    cma_bowl = reached(cma_search, bowl, bowl_worst).mean()
    de_bowl = reached(differential_evolution_search, bowl, bowl_worst).mean()
    assert cma_bowl >= 0.93 and de_bowl < cma_bowl


@pytest.mark.parametrize("optimizer", sorted(OPTIMIZERS))
def test_the_search_finds_a_narrow_valley(optimizer):
    """A failure only within 0.03 of x_0 = 0.71 (a fault onset a Monte Carlo rarely hits):
    each optimiser finds a margin below -0.4 (the valley's floor -0.5) within 300
    simulations, where its first generation does not."""

    def valley(X):
        m = 0.5 - np.exp(-(((X[:, 0] - 0.71) / 0.03) ** 2)) + 0.01 * np.sum(X[:, 1:] ** 2, 1)
        return m.tolist(), [{} for _ in X]

    found = OPTIMIZERS[optimizer](valley, [(0.0, 1.0)] * 3, budget=300, seed=1)
    first = min(m for m, g in zip(found.margins, found.generations, strict=True) if g == 0)
    assert found.margins[found.worst] < -0.4 < first


@pytest.mark.parametrize("optimizer", sorted(OPTIMIZERS))
def test_margins_that_do_not_apply_are_never_the_worst_and_ended_runs_always_are(optimizer):
    """NaN (the requirement does not apply) is never chosen as worst; a run that ended
    early (-inf) is."""

    def odd(X):
        m = np.where(X[:, 0] > 0.5, np.nan, X[:, 1])
        m[X[:, 0] < -0.6] = -math.inf
        return m.tolist(), [{} for _ in X]

    found = OPTIMIZERS[optimizer](odd, [(-1.0, 1.0)] * 2, budget=100, seed=0)
    assert 0 < len(found.margins) <= 100  # DE stops once every point ended early
    assert found.margins[found.worst] == -math.inf
    assert not np.isnan(found.margins[found.worst])


def test_a_budget_below_one_generation_and_an_empty_box_are_refused():
    with pytest.raises(ValueError, match="below one generation"):
        differential_evolution_search(convex, BOX, budget=4)
    with pytest.raises(ValueError, match="below one generation"):
        cma_search(convex, BOX, budget=9)
    with pytest.raises(ValueError, match="non-empty box"):
        differential_evolution_search(convex, [(0.0, 0.0)], budget=10)
    assert population_size(5, 6) == 5 and population_size(10_000, 6) == 60
