"""Runs of a batch: which are alive, and where a failed run's error goes.

Every numeric kernel of the loop works on B runs (lanes) at once; a run can fail on
its own (non-finite state, an infeasible first solve, a bad parameter of its own)
without stopping the others. A kernel reports such a failure to `Lanes`; with
`strict=True` (one run: `fahv simulate`, a node of the graph) the error is raised
at once, as a single-run computation would raise it.
"""

from __future__ import annotations

import numpy as np


class Lanes:
    """Alive flags and errors of B runs.

    Parameters
    ----------
    n : int
        Number of runs B (>= 1).
    strict : bool
        Raise a run's error at once (True) or record it and mark the run dead.

    Attributes
    ----------
    alive : (B,) bool ndarray
    errors : list of Exception or None
        Per run, the error that ended it.
    step : int
        The loop step under way (set by the loop; -1 before the first).
    failed_step : list of int or None
        Per run, the step at which it failed (its steps before are valid).
    """

    def __init__(self, n: int, strict: bool = True) -> None:
        if n < 1:
            raise ValueError(f"a batch needs at least one run, got {n}")
        self.n, self.strict = int(n), bool(strict)
        self.alive = np.ones(self.n, dtype=bool)
        self.errors: list[Exception | None] = [None] * self.n
        self.step = -1
        self.failed_step: list[int | None] = [None] * self.n

    def fail(self, b: int, exc: Exception) -> None:
        """Run `b` failed with `exc`: raise it (strict) or record it.

        Raises
        ------
        Exception
            `exc` itself when strict.
        """
        if self.strict:
            raise exc
        if self.alive[b]:
            self.errors[b] = exc
            self.failed_step[b] = self.step
            self.alive[b] = False

    def fail_mask(self, mask: np.ndarray, make_error) -> None:
        """Every alive run b with `mask[b]` fails with `make_error(b)`."""
        for b in np.flatnonzero(np.asarray(mask) & self.alive):
            self.fail(int(b), make_error(int(b)))
