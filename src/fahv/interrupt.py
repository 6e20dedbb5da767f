"""A stop (Ctrl-C, SIGTERM) that waits for the end of a write.

`fahv`'s commands turn the first SIGINT or SIGTERM into a `KeyboardInterrupt` in
the main thread (`fahv.cli.common.stop_signals`), so that a long solve or a run
stops at once. Raised between two writes of one MCAP record, the same exception would
leave a half record in the file: the writer's `close` then writes its summary after
it, and the run reads as truncated (measured: 3 of 16 runs interrupted at random
times, before this module). Code that must not be cut in the middle runs inside
`deferred`; a stop requested there (`request`) is raised when the
outermost such section ends.

Signal handlers run in the main thread only, so the state is the main thread's:
sections entered by other threads do not defer anything (a stop never interrupts
them).
"""

from __future__ import annotations

import contextlib
import threading

_depth = 0
_pending = False


def request() -> None:
    """Stop now (raise `KeyboardInterrupt`), or when the current deferred section ends.

    Called by a signal handler (in the main thread).

    Raises
    ------
    KeyboardInterrupt
        Unless the main thread is inside `deferred`, where the stop is kept
        pending until the outermost section ends.
    """
    global _pending
    if _depth:
        _pending = True
        return
    raise KeyboardInterrupt


@contextlib.contextmanager
def deferred():
    """Section of code that a stop (`request`) must not cut in the middle.

    A stop requested inside is raised as `KeyboardInterrupt` when the outermost
    section ends normally; when the section raises, its own exception propagates and
    the stop stays pending for the next section's end. Nests; costs about a
    microsecond. Outside the main thread it does nothing.

    Raises
    ------
    KeyboardInterrupt
        At the end of the outermost section, if a stop was requested inside it.
    """
    global _depth, _pending
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    if not _depth and _pending:
        _pending = False
        raise KeyboardInterrupt


def clear() -> None:
    """Forget a pending stop (the command that was asked to stop has ended)."""
    global _pending
    _pending = False
