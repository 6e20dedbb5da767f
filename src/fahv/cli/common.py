"""Helpers shared by the command groups: vehicle option, argument types, JSON, run reading."""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import threading
import warnings

import numpy as np
from tqdm import tqdm

from fahv import interrupt
from fahv.model.vehicle import load_vehicle
from fahv.runs.bag import read_run


def vehicle_of(args):
    """The vehicle of `--vehicle FILE` (the packaged one when not given)."""
    return load_vehicle(args.vehicle)


def add_vehicle_option(p: argparse.ArgumentParser) -> None:
    """Add `--vehicle FILE` to a command."""
    p.add_argument(
        "--vehicle",
        metavar="FILE",
        default=None,
        help="vehicle data file (YAML); default: the packaged Parker 2007 curve fit "
        "with representative flexible data",
    )


def shape_arg(s: str) -> tuple[int, int]:
    """Argument type `AxB` -> (A, B)."""
    try:
        a, b = (int(v) for v in s.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected AxB (e.g. 4x5), got {s!r}") from None
    return a, b


def read_run_warned(path):
    """read_run, its warnings (truncated file) printed to stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = read_run(path)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    return rec


def to_json(obj) -> str:
    """Strict JSON (NaN and infinities as null)."""

    def clean(v):
        if isinstance(v, dict):
            return {str(k): clean(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [clean(x) for x in v]
        if isinstance(v, float) and not np.isfinite(v):
            return None
        if isinstance(v, np.generic):
            return clean(v.item())
        return v

    return json.dumps(clean(obj), indent=2)


@contextlib.contextmanager
def stop_signals():
    """SIGINT and SIGTERM as one clean stop while a command runs.

    The first SIGINT or SIGTERM raises `KeyboardInterrupt` in the main thread (at
    once, or at the end of a `fahv.interrupt.deferred` section, such as a record
    being written to a run file), so a command finalises its run (the run writer
    closes with status `interrupted`, `fahv sil` forwards the stop to its graph);
    every further one only prints a note,
    so that a second Ctrl-C cannot cut the finalisation short. After a stop the
    signals stay ignored (the command is ending; a late Ctrl-C must not turn exit
    status 130 into a death by signal); otherwise the previous handlers are restored.
    Outside the main thread (where handlers cannot be set) it does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seen = []

    def handler(signum, frame):
        seen.append(signum)
        if len(seen) == 1:
            interrupt.request()  # at once, or after the write it arrived in
        print("fahv: already stopping; finishing the run, please wait", file=sys.stderr)

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        interrupt.clear()  # a stop left pending by a failing section ends here
        for s, h in old.items():  # after a stop, the process is ending: ignore the rest
            signal.signal(s, signal.SIG_IGN if seen else h)


def progress(iterable=None, **kwargs) -> tqdm:
    """A tqdm progress bar on stderr that also shows in logs (count, rate, ETA).

    On a terminal it updates in place (every 0.5 s at most); when stderr is not a
    terminal (CI, `> log`) it writes a line every 10 s instead of staying silent.
    `kwargs` go to `tqdm` (`desc`, `total`, `unit`, `leave` ...).
    """
    kwargs.setdefault("mininterval", 0.5 if sys.stderr.isatty() else 10.0)
    return tqdm(iterable, **kwargs)
