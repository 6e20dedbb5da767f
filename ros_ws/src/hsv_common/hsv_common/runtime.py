"""Process runtime of every node: QoS profiles, exit codes, executor, signals, `main`.

Exit status of a node (`main`), also in docs/guide/sil.md:

==  =====================================================================
0   done: every step, and every subscriber acknowledged the last messages
1   any other error (the traceback follows the message)
2   bad parameter (`fahv.errors.ParameterError`)
3   watchdog: the graph did not start, or a peer went missing or silent
4   stopped by SIGINT / SIGTERM before the end
5   another graph in the ROS domain that joined first (or cannot be told apart)
6   the run ended with a verdict (`fahv.verdict`), found by this node's core
    or learnt from a peer's status
==  =====================================================================
"""

from __future__ import annotations

import faulthandler
import gc
import os
import signal
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from fahv.errors import ParameterError
from fahv.loop import graph
from fahv.loop.graph import COMPOSED, TEARDOWN_MARK
from fahv.verdict import RunEnded

EXIT_OK, EXIT_ERROR, EXIT_PARAM, EXIT_WATCHDOG, EXIT_SIGNAL, EXIT_FOREIGN = 0, 1, 2, 3, 4, 5
EXIT_VERDICT = 6
#: Longest DDS teardown (node and participant destruction) after the node closed [s].
#: Fast DDS 2.14 can deadlock destroying a participant while its peers leave (seen in
#: CI: the main thread spinning in DomainParticipant::set_listener while a discovery
#: thread waits for a lock it holds, with the GIL held). A C-level timer
#: (faulthandler) then dumps every thread's traceback and ends the process with status
#: 1 after the line `TEARDOWN_MARK`; the runner reads that as a hung teardown, not a
#: failure, when the node had closed with status 0. A teardown takes 12 ms (median,
#: 36 ms at most, 18 node teardowns under a load of 7 on 2 cores, measured); the
#: runner waits for the stalled one, so the deadline is short.
TEARDOWN_S = 2.0
#: Longest a node's main thread may stay away from its spin loop, beyond its watchdog [s].
#: Every callback returns within `watchdog_s` in a working graph (the peers' watchdogs
#: fail the run otherwise); a main thread stuck in a C call is ended by the same C-level
#: timer as the teardown: faulthandler dumps every thread's traceback and exits with 1.
#: (A plant that never exited with every peer done had its DDS entities destroyed after
#: this guard, when the EventsExecutor was freed: `teardown` now runs under it.)
HANG_S = 10.0
#: Longest wait of one spin of a node's main loop [s]: signals, the peers' statuses and
#: the watchdog are looked at least this often (and a spin is never unbounded, see
#: `make_executor`).
SPIN_S = 0.05
#: Longest wait of one spin while a node waits for its last messages to be delivered [s].
LINGER_SPIN_S = 0.01


class HangGuard:
    """A C-level deadline on the main thread (faulthandler), re-armed from the spin loop.

    `arm(timeout)` sets the deadline `timeout` seconds ahead; `beat` re-arms
    the last timeout at most once per second (re-arming restarts faulthandler's
    watchdog thread). When the deadline passes, every thread's traceback goes to stderr
    and the process exits with status 1: a hung node ends, and says where it hung.
    """

    def __init__(self) -> None:
        self.timeout = None
        self.t_armed = -1e9

    def arm(self, timeout: float) -> None:
        """Deadline `timeout` seconds from now (replaces any earlier one)."""
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


def node_options() -> dict:
    """Keyword arguments of every node's `Node.__init__`: no services unless asked.

    The six parameter services and rclpy's type description service serve `ros2 param`
    and `ros2 topic info` on a full ROS install; the SingleThreadedExecutor (the
    recorder's) puts every service into its wait set at every spin. `HSV_PARAM_SERVICES=1`
    starts them all.
    """
    return {
        "start_parameter_services": START_PARAMETER_SERVICES,
        "parameter_overrides": [
            Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=START_PARAMETER_SERVICES)
        ],
    }


def qos_profile(q: graph.QoS) -> QoSProfile:
    """The rclpy profile of a `fahv.loop.graph.QoS` (the library owns the numbers)."""
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
    """Event callbacks of a subscription without the default handlers (`quiet_publisher`)."""
    return SubscriptionEventCallbacks(use_default_callbacks=False)


#: Loop topics (`fahv.loop.graph.LOOP_QOS`).
LOOP_QOS = qos_profile(graph.LOOP_QOS)
#: Node status topic (`fahv.loop.graph.STATUS_QOS`).
STATUS_QOS = qos_profile(graph.STATUS_QOS)


class WatchdogError(RuntimeError):
    """The graph did not start, or a peer went missing or silent (exit status 3)."""


class ForeignGraphError(RuntimeError):
    """Another graph publishes loop topics in this node's ROS domain (exit status 5)."""


def end_reason(done: bool, status: int) -> str:
    """Run status for a recorded run: complete, interrupted, or with the exit status.

    `interrupted` when the run stopped early on a signal (or with status 0), else
    `interrupted (exit status N)` (N: the node's exit status, e.g. 3 watchdog).
    """
    if done:
        return "complete"
    if status in (EXIT_OK, EXIT_SIGNAL):
        return "interrupted"
    return f"interrupted (exit status {status})"


def make_executor(message_info: bool = False):
    """Executor of a node: rclpy's EventsExecutor unless `HSV_EXECUTOR=single`.

    The EventsExecutor (a C++ event queue fed by the middleware's callbacks) runs the
    lockstep graph about 1.5x faster than the SingleThreadedExecutor, which rebuilds a
    wait set for every callback it hands out. Two properties of the Jazzy wheel (rclpy
    7.1.6, built for manylinux_2_28) decide how `main` uses it:

    - **Only bounded spins.** `spin()`, `spin_once()` without a timeout and
      `spin_until_future_complete(f)` wait for `steady_clock::time_point::max()`.
      The wheel's libstdc++ has no `pthread_cond_clockwait`, converts that deadline to
      the system clock, overflows to a negative `abstime` (`tv_sec = -7.4e9`,
      measured in gdb), so every wait returns at once and the queue's predicate loop
      spins: 100 % CPU in C++ with the GIL released. A Python signal handler only sets a
      flag for the main thread, which never comes back to the interpreter, so SIGTERM
      and SIGINT are ignored. `main` therefore only calls `spin_once` with a
      timeout (`SPIN_S`), and wakes up at least that often.
    - **Tear down the executor first.** It keeps every subscription and service of its
      nodes in use, so `node.destroy_node()` only marks the DDS entities for
      destruction; they went away when the executor object was freed, after the hang
      guard was cancelled, with the GIL held, where a Fast DDS teardown stall (see
      `TEARDOWN_S`) left a process that never exited and ignored SIGTERM.
      `main` calls `ex.shutdown()` (it releases the entities) before
      `destroy_node`, both under the teardown deadline.

    `message_info=True` (the recorder: it keeps the DDS source timestamps) always takes
    the SingleThreadedExecutor: the Jazzy EventsExecutor calls a callback that takes the
    message info with one argument (SystemError, measured).

    Raises
    ------
    ParameterError
        If `HSV_EXECUTOR` is neither `events` nor `single`.
    """
    kind = os.environ.get("HSV_EXECUTOR", "events")
    if kind not in ("single", "events"):
        raise ParameterError(f"HSV_EXECUTOR = {kind!r}: 'events' (default) or 'single'")
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


def delivered(node: Node) -> bool:
    """True when the node's messages need no more waiting.

    `node.delivered()` if the node has one, else `all_acked`.
    """
    check = getattr(node, "delivered", None)
    return check() if check is not None else all_acked(node)


def teardown(ex, node: Node | None) -> None:
    """Release the executor's hold on the node's entities, then destroy the node.

    `ex.shutdown()` first: the EventsExecutor keeps every subscription and service in
    use until then, and `destroy_node` would only mark them (`make_executor`).
    """
    if ex is not None:
        ex.shutdown(timeout_sec=TEARDOWN_S)
    if node is not None:
        node.destroy_node()


def failure(name: str, exc: Exception) -> tuple[int, str]:
    """Exit status and reason of the exception that stopped node `name`; prints them.

    Call it from the `except` clause: an unexpected error prints its traceback too.
    """
    kinds = (
        (RunEnded, EXIT_VERDICT, "run ended"),
        (ParameterError, EXIT_PARAM, "parameter error"),
        (WatchdogError, EXIT_WATCHDOG, "watchdog"),
        (ForeignGraphError, EXIT_FOREIGN, "error"),
    )
    for cls, status, what in kinds:
        if isinstance(exc, cls):
            print(f"[{name}] {what}: {exc}", file=sys.stderr)
            return status, str(exc)
    import traceback

    reason = f"{type(exc).__name__}: {exc}"
    print(f"[{name}] error: {reason}", file=sys.stderr)
    traceback.print_exc()
    return EXIT_ERROR, reason


def linger(node: Node, ex, stop, guard: HangGuard, linger_s: float) -> None:
    """Spin until the node's messages are delivered (`delivered`), a signal, or `linger_s`.

    Parameters
    ----------
    node : rclpy.node.Node
    ex : rclpy executor
        The node's executor.
    stop : callable
        The signal handler of `main` (its `signal` is set by a signal).
    guard : HangGuard
        Re-armed for the linger and the close after it.
    linger_s : float
        Longest wait [s wall time].
    """
    guard.arm(linger_s + 2 * HANG_S)  # the linger, then close (the recorder's file)
    t_end = time.monotonic() + linger_s
    while time.monotonic() < t_end and stop.signal is None and not delivered(node):
        ex.spin_once(timeout_sec=LINGER_SPIN_S)


def main(node_cls, args=None, linger_s: float = 10.0) -> int:
    """Run one node until its last step, a signal, or an error; returns the exit status.

    The node class provides `done` (bool), `k` (step), `poll()` (called between
    spins; raises to stop), `close(status, reason)` (called once at the end, with
    the exit status and the error message, "" when none) and optionally
    `delivered()` (`delivered`).

    After the last step the node stays until its messages are delivered (every
    consumer finished its steps, or every subscriber acknowledged them: the recorder
    may lag behind the loop), at most `linger_s` seconds: a reliable writer that goes
    away earlier loses what is still unacknowledged. SIGINT and SIGTERM stop the spin
    loop cleanly (the node's `close` runs, so the recorder finishes its file). Every
    spin is bounded (`SPIN_S`), and the executor is shut down before the node is
    destroyed, under the teardown deadline (`make_executor`).
    """
    stop = _Stop()
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    node = ex = None
    status = EXIT_OK
    reason = ""
    name = node_cls.ROLE
    guard = HangGuard()
    try:
        node = node_cls()
        name = node.get_name()
        ex = make_executor(getattr(node, "MESSAGE_INFO", False))
        ex.add_node(node)
        # the objects of the start (modules, the core, the entities) live as long as the
        # node: out of the collector's way, a full collection scans only what the run made
        gc.collect()
        gc.freeze()
        guard.arm(max(getattr(node, "watchdog_s", HANG_S), HANG_S) + HANG_S)
        while not node.done and stop.signal is None:
            guard.beat()
            ex.spin_once(timeout_sec=SPIN_S)
            if stop.signal is None:  # a signal first: peers stopping by it are no failure
                node.poll()
        if stop.signal is not None and not node.done:
            reason = f"stopped by signal {signal.Signals(stop.signal).name} at step {node.k}"
            print(f"[{name}] {reason}", file=sys.stderr)
            status = EXIT_SIGNAL
        else:  # let reliable QoS deliver the last messages before the writers go away
            linger(node, ex, stop, guard, linger_s)
    except RunEnded as exc:  # the run's end: what the node published still reaches the recorder
        status, reason = failure(name, exc)
        linger(node, ex, stop, guard, linger_s)
    except Exception as exc:  # report any failure with the node's name
        status, reason = failure(name, exc)
    finally:
        try:
            if node is not None:
                node.close(status, reason)
        finally:
            if node is not None:
                print(f"[{name}] {TEARDOWN_MARK} {status}; DDS teardown", file=sys.stderr,
                      flush=True)  # fmt: skip
            guard.arm(TEARDOWN_S)
            teardown(ex, node)
            ex = None
            if rclpy.ok():
                rclpy.shutdown()
            guard.cancel()
    return status


class _Composition:
    """The nodes of one process (`main_composed`) and how each one ended."""

    def __init__(self) -> None:
        self.nodes: list = []
        self.ended: dict = {}  # node (None: the process) -> (status, reason), in order
        self.closing: dict = {}  # node that ended with a verdict -> its linger deadline
        self.closed: set = set()

    def running(self) -> bool:
        """True while a node is neither done nor ended, or a verdict is still going out."""
        return bool(self.closing) or not all(n.done or n in self.ended for n in self.nodes)

    def close(self, node, status: int, reason: str) -> None:
        """Close `node` once (its last status goes out to its peers)."""
        if node not in self.closed:
            self.closed.add(node)
            node.close(status, reason)

    def poll(self, linger_s: float) -> None:
        """`poll` every running node; close those that stopped (`main_composed`)."""
        for node in self.nodes:
            if node.done or node in self.ended:
                continue
            try:
                node.poll()
            except Exception as exc:  # this node's end: its peers learn it from its status
                self.ended[node] = failure(node.get_name(), exc)
                if isinstance(exc, RunEnded):  # its messages go out first, as in `main`
                    self.closing[node] = time.monotonic() + linger_s
                else:
                    self.close(node, *self.ended[node])
        for node, t_end in list(self.closing.items()):
            if delivered(node) or time.monotonic() > t_end:
                del self.closing[node]
                self.close(node, *self.ended[node])

    def finish(self, stop: _Stop) -> int:
        """Close every node not closed yet; the process's exit status (`main_composed`)."""
        first = next(iter(self.ended.values()), None)
        for node in self.nodes:
            if node in self.ended:
                status, reason = self.ended[node]
            elif node.done:
                status, reason = EXIT_OK, ""
            elif stop.signal is not None:
                status = EXIT_SIGNAL
                reason = f"stopped by signal {signal.Signals(stop.signal).name} at step {node.k}"
            else:  # the process's own failure
                status, reason = first
            self.close(node, status, reason)
        if first is not None:
            status = first[0]
        else:
            status = EXIT_SIGNAL if stop.signal is not None else EXIT_OK
        print(f"[{COMPOSED}] {TEARDOWN_MARK} {status}; DDS teardown", file=sys.stderr, flush=True)
        return status


def main_composed(node_classes: list, args=None, linger_s: float = 10.0) -> int:
    """Run several nodes in one process on one executor; returns the exit status.

    ROS 2's composition: each node keeps its name, parameters, topics and status, and
    the middleware delivers between nodes of one process without the network stack
    (Fast DDS's intra-process delivery), which shortens each hop of a lockstep step.
    The nodes behave as in `main`, each on its own: a node that fails closes
    with its exit status (one that ended the run with a verdict once its messages are
    delivered), and its peers in and out of the process see it in its last status and
    stop by their own checks. The process exits with the status of the first node that
    stopped (the cause; its peers follow with 3 or 6), 4 after a signal, 0 when every
    node finished and its messages were delivered.

    Parameters
    ----------
    node_classes : list of type
        `LockstepNode` subclasses, built in this order.
    args : list of str, optional
        Command line with the ROS arguments (`--ros-args --params-file FILE`), as for
        `rclpy.init`.
    linger_s : float
        Longest wait for the last messages' delivery [s wall time].
    """
    stop = _Stop()
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    c = _Composition()
    ex = make_executor()
    guard = HangGuard()
    try:
        for cls in node_classes:
            c.nodes.append(cls())
            ex.add_node(c.nodes[-1])
        gc.collect()
        gc.freeze()
        guard.arm(max(max(n.watchdog_s for n in c.nodes), HANG_S) + HANG_S)
        while stop.signal is None and c.running():
            guard.beat()
            ex.spin_once(timeout_sec=SPIN_S)
            if stop.signal is None:
                c.poll(linger_s)
        guard.arm(linger_s + 2 * HANG_S)  # the last messages of the finished nodes
        t_end = time.monotonic() + linger_s
        done = [n for n in c.nodes if n.done]
        while stop.signal is None and time.monotonic() < t_end and not all(map(delivered, done)):
            ex.spin_once(timeout_sec=LINGER_SPIN_S)
    except Exception as exc:  # a node not built, or a callback's error: the process's
        built = len(c.nodes) == len(node_classes)
        c.ended[None] = failure(COMPOSED if built else node_classes[len(c.nodes)].ROLE, exc)
    finally:
        status = c.finish(stop)
        guard.arm(TEARDOWN_S)
        teardown(ex, None)  # the executor first, then every node (`make_executor`)
        for node in c.nodes:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
        guard.cancel()
    return status
