"""Process runtime of every node: QoS profiles, exit codes, executor, signals, ``main``.

Exit status of a node (:func:`main`), also in docs/architecture.md:

==  =====================================================================
0   done: every step, and every subscriber acknowledged the last messages
1   any other error (the traceback follows the message)
2   bad parameter (:class:`fahv.errors.ParameterError`)
3   watchdog: the graph did not start, or a peer went missing or silent
4   stopped by SIGINT / SIGTERM before the end
5   another graph in the ROS domain that joined first (or cannot be told apart)
==  =====================================================================
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from fahv.errors import ParameterError
from fahv.loop import graph
from fahv.loop.graph import TEARDOWN_MARK

EXIT_OK, EXIT_ERROR, EXIT_PARAM, EXIT_WATCHDOG, EXIT_SIGNAL, EXIT_FOREIGN = 0, 1, 2, 3, 4, 5
#: Longest DDS teardown (node and participant destruction) after the node closed [s].
#: Fast DDS 2.14 can deadlock destroying a participant while its peers leave (seen in
#: CI: the main thread spinning in DomainParticipant::set_listener while a discovery
#: thread waits for a lock it holds, with the GIL held). A C-level timer
#: (faulthandler) then dumps every thread's traceback and ends the process with status
#: 1 after the line ``TEARDOWN_MARK``; the runner reads that as a hung teardown, not a
#: failure, when the node had closed with status 0.
TEARDOWN_S = 10.0
#: Longest a node's main thread may stay away from its spin loop, beyond its watchdog [s].
#: Every callback returns within ``watchdog_s`` in a working graph (the peers' watchdogs
#: fail the run otherwise); a main thread stuck in a C call (seen once in CI, cause not
#: found: the plant never exited, with every peer done) is ended by the same C-level
#: timer as the teardown: faulthandler dumps every thread's traceback and exits with 1.
HANG_S = 10.0


class HangGuard:
    """A C-level deadline on the main thread (faulthandler), re-armed from the spin loop.

    ``arm(timeout)`` sets the deadline ``timeout`` seconds ahead; :meth:`beat` re-arms
    the last timeout at most once per second (re-arming restarts faulthandler's
    watchdog thread). When the deadline passes, every thread's traceback goes to stderr
    and the process exits with status 1: a hung node ends, and says where it hung.
    """

    def __init__(self) -> None:
        self.timeout = None
        self.t_armed = -1e9

    def arm(self, timeout: float) -> None:
        """Deadline ``timeout`` seconds from now (replaces any earlier one)."""
        self.timeout = float(timeout)
        self.t_armed = time.monotonic()
        faulthandler.dump_traceback_later(self.timeout, exit=True, file=sys.stderr)

    def beat(self) -> None:
        """Move the deadline ahead (at most once per second)."""
        if self.timeout is not None and time.monotonic() - self.t_armed >= 1.0:
            self.arm(self.timeout)

    @staticmethod
    def cancel() -> None:
        """No deadline."""
        faulthandler.cancel_dump_traceback_later()


#: Parameter services cost every spin of every node (more entities in the wait set).
START_PARAMETER_SERVICES = os.environ.get("HSV_PARAM_SERVICES", "0") == "1"


def qos_profile(q: graph.QoS) -> QoSProfile:
    """The rclpy profile of a :class:`fahv.loop.graph.QoS` (the library owns the numbers)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=q.depth,
        reliability=ReliabilityPolicy.RELIABLE if q.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if q.transient_local else DurabilityPolicy.VOLATILE
        ),
    )


def quiet_publisher() -> PublisherEventCallbacks:
    """Event callbacks of a publisher without rclpy's default QoS-event handlers.

    rclpy adds two handlers (incompatible QoS, incompatible type) to every publisher and
    subscription, and the SingleThreadedExecutor polls each at every spin. The graph
    checks its matches itself (GraphStatus), so the loop topics go without them.
    """
    return PublisherEventCallbacks(use_default_callbacks=False)


def quiet_subscription() -> SubscriptionEventCallbacks:
    """Event callbacks of a subscription without the default handlers (:func:`quiet_publisher`)."""
    return SubscriptionEventCallbacks(use_default_callbacks=False)


#: Loop topics (:data:`fahv.loop.graph.LOOP_QOS`).
LOOP_QOS = qos_profile(graph.LOOP_QOS)
#: Node status topic (:data:`fahv.loop.graph.STATUS_QOS`).
STATUS_QOS = qos_profile(graph.STATUS_QOS)


class WatchdogError(RuntimeError):
    """The graph did not start, or a peer went missing or silent (exit status 3)."""


class ForeignGraphError(RuntimeError):
    """Another graph publishes loop topics in this node's ROS domain (exit status 5)."""


def end_reason(done: bool, status: int) -> str:
    """Run status for a recorded run: complete, interrupted, or with the exit status.

    ``interrupted`` when the run stopped early on a signal (or with status 0), else
    ``interrupted (exit status N)`` (N: the node's exit status, e.g. 3 watchdog).
    """
    if done:
        return "complete"
    if status in (EXIT_OK, EXIT_SIGNAL):
        return "interrupted"
    return f"interrupted (exit status {status})"


def make_executor(message_info: bool = False):
    """Executor of every node: rclpy's SingleThreadedExecutor unless ``HSV_EXECUTOR=events``.

    ``HSV_EXECUTOR=events`` selects rclpy's experimental EventsExecutor (a C++ event
    queue) for the nodes that take no message info; it ran the Case 1 graph about 1.4x
    faster on this 2-core machine (docs/sil.md), but it hung in a ring test
    (docs/environment.md) and a plant on it once never exited in CI with every peer
    done, so it is no longer the default. ``message_info=True`` (the recorder: it keeps
    the DDS source timestamps) always takes the SingleThreadedExecutor: the Jazzy
    EventsExecutor cannot call a subscription callback with its message info
    (SystemError, measured).

    Raises
    ------
    ParameterError
        If ``HSV_EXECUTOR`` is neither ``single`` nor ``events``.
    """
    kind = os.environ.get("HSV_EXECUTOR", "single")
    if kind not in ("single", "events"):
        raise ParameterError(f"HSV_EXECUTOR = {kind!r}: 'single' (default) or 'events'")
    if message_info or kind == "single":
        return SingleThreadedExecutor()
    from rclpy.experimental.events_executor import EventsExecutor

    return EventsExecutor()


class _Stop:
    def __init__(self) -> None:
        self.signal = None

    def __call__(self, signum, frame) -> None:
        self.signal = signum


def all_acked(node: Node) -> bool:
    """True when every subscriber acknowledged every message of the node's publishers."""
    return all(p.wait_for_all_acked(Duration(seconds=0)) for p in node.publishers)


def main(node_cls, args=None, linger_s: float = 10.0) -> int:
    """Run one node until its last step, a signal, or an error; returns the exit status.

    The node class provides ``done`` (bool), ``k`` (step), ``poll()`` (called between
    spins; raises to stop) and ``close(status, reason)`` (called once at the end, with
    the exit status and the error message, "" when none).

    After the last step the node stays until every subscriber (the recorder too, which
    may lag behind the loop) acknowledged its messages, at most ``linger_s`` seconds:
    a reliable writer that goes away earlier loses what is still unacknowledged.
    SIGINT and SIGTERM stop the spin loop cleanly (the node's ``close`` runs, so
    the recorder finishes its file).
    """
    stop = _Stop()
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    node = None
    status = EXIT_OK
    reason = ""
    name = node_cls.ROLE
    guard = HangGuard()
    try:
        node = node_cls()
        name = node.get_name()
        ex = make_executor(getattr(node, "MESSAGE_INFO", False))
        ex.add_node(node)
        guard.arm(max(getattr(node, "watchdog_s", HANG_S), HANG_S) + HANG_S)
        while not node.done and stop.signal is None:
            guard.beat()
            ex.spin_once(timeout_sec=0.05)
            if stop.signal is None:  # a signal first: peers stopping by it are no failure
                node.poll()
        if stop.signal is not None and not node.done:
            reason = f"stopped by signal {signal.Signals(stop.signal).name} at step {node.k}"
            print(f"[{name}] {reason}", file=sys.stderr)
            status = EXIT_SIGNAL
        else:  # let reliable QoS deliver the last messages before the writers go away
            guard.arm(linger_s + 2 * HANG_S)  # the linger, then close (the recorder's file)
            t_end = time.monotonic() + linger_s
            while time.monotonic() < t_end and stop.signal is None and not all_acked(node):
                ex.spin_once(timeout_sec=0.01)
    except ParameterError as exc:
        reason = str(exc)
        print(f"[{name}] parameter error: {exc}", file=sys.stderr)
        status = EXIT_PARAM
    except WatchdogError as exc:
        reason = str(exc)
        print(f"[{name}] watchdog: {exc}", file=sys.stderr)
        status = EXIT_WATCHDOG
    except ForeignGraphError as exc:
        reason = str(exc)
        print(f"[{name}] error: {exc}", file=sys.stderr)
        status = EXIT_FOREIGN
    except Exception as exc:  # report any failure with the node's name, then the traceback
        import traceback

        reason = f"{type(exc).__name__}: {exc}"
        print(f"[{name}] error: {reason}", file=sys.stderr)
        traceback.print_exc()
        status = EXIT_ERROR
    finally:
        if node is not None:
            try:
                node.close(status, reason)
            finally:
                print(f"[{name}] {TEARDOWN_MARK} {status}; DDS teardown", file=sys.stderr,
                      flush=True)  # fmt: skip
                guard.arm(TEARDOWN_S)
                node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
        guard.cancel()
    return status
