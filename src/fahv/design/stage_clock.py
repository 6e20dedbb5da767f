"""Progress of a design while it runs: its stage, the time in it, and the time left.

A design spends minutes in a single LMI or bisection with no loop to put a progress bar
on. `StageClock` prints a line at least every `PERIOD_S` seconds from a
timer thread, whatever the stage is doing, and estimates the time left from the stage
times of the last design of the same file (stored in its summary, `stage_times_s`,
outside the design hash). Without such a record it says so rather than guess.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

#: Largest interval between two progress lines [s wall time].
PERIOD_S = 10.0


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.0f} s"


class StageClock:
    """Stage times of one design and a progress line every `period_s` seconds.

    Call `stage` at the start of each stage and `close` at the end (or use
    the clock as a context manager); `times` holds the stage times [s] so far.

    Parameters
    ----------
    previous : dict of str -> float, optional
        Stage times [s] of the last design of the same file, in stage order (the
        estimate's source); None or empty: no estimate.
    emit : callable
        Receives each progress line (default: stderr).
    period_s : float
        Interval between progress lines [s].
    """

    def __init__(
        self,
        previous: dict[str, float] | None = None,
        emit: Callable[[str], None] = _stderr,
        period_s: float = PERIOD_S,
    ) -> None:
        self.previous = dict(previous or {})
        self.emit, self.period_s = emit, period_s
        self.times: dict[str, float] = {}
        self.current: str | None = None
        self.t0 = self.t_stage = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, name="design-progress", daemon=True)
        self._thread.start()

    def stage(self, name: str) -> None:
        """End the current stage (its time recorded) and start stage `name`."""
        now = time.monotonic()
        if self.current is not None:
            spent = self.times.get(self.current, 0.0) + now - self.t_stage
            self.times[self.current] = round(spent, 1)
        self.current, self.t_stage = name, now

    def close(self) -> dict[str, float]:
        """End the last stage and stop the progress lines; the stage times [s]."""
        self.stage("")
        self.current = None
        self._stop.set()
        self._thread.join(timeout=1.0)
        return dict(self.times)

    def __enter__(self) -> StageClock:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def left(self) -> float | None:
        """Estimated time left [s] from `previous`; None if it has no such estimate."""
        if not self.previous or self.current not in self.previous:
            return None
        names = list(self.previous)
        in_stage = time.monotonic() - self.t_stage
        later = names[names.index(self.current) + 1 :]
        return max(self.previous[self.current] - in_stage, 0.0) + sum(
            self.previous[n] for n in later
        )

    def line(self) -> str:
        """The progress line: stage, time in it, time so far, estimate left."""
        now = time.monotonic()
        left = self.left()
        estimate = (
            f"about {_minutes(left)} left (the last design's stage times)"
            if left is not None
            else "no estimate (no earlier design of this file was timed)"
        )
        return (
            f"design: {self.current}, {_minutes(now - self.t_stage)} in it, "
            f"{_minutes(now - self.t0)} so far; {estimate}"
        )

    def _tick(self) -> None:
        while not self._stop.wait(self.period_s):
            if self.current:
                self.emit(self.line())
