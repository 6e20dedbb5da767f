"""Lockstep plumbing shared by every node of the SIL graph (no model or control maths).

A :class:`LockstepNode` declares the typed parameters of its node from
:data:`fahv.loop.params.specs` (with descriptions and ranges), validates them, builds the
library object it adapts, and then only moves messages:

- Inputs are buffered per step index k; the node calls :meth:`LockstepNode.on_step`
  once it holds every input of its current step, publishes the outputs of that step
  and moves to k + 1. A message of an already processed step (stale) or a second
  message of a buffered step (duplicate) is counted and logged, never used.
- Reliable, keep-last QoS on every loop topic (:data:`fahv.loop.graph.QOS_DEPTH`).
- Start-up: a node announces itself on ``/hsv/ready`` (transient local) once all its
  subscriptions see their publishers and all its publishers see every expected
  subscriber (:data:`GRAPH`); the plant starts step 0 only when every node of the
  graph has announced itself.
- A wall-clock watchdog (parameter ``watchdog_s``) turns a silent or dead peer into
  an error naming the topic and the node that should have sent it (exit status 3).
- Isolation check: a loop topic with more publishers than the graph has producers of
  it means another graph runs in the same ROS domain; the node stops with an error
  naming the domain and the topic (exit status 5) instead of mixing the two runs.
  Checked before step 0, once a second, and at once on any stale or duplicate
  message (discovery may complete only after step 0 has started).

Exit status of :func:`main`: 0 done, 2 bad parameter, 3 watchdog, 4 stopped by a
signal before the end, 5 foreign graph in the domain, 1 any other error.
"""

from __future__ import annotations

import array
import json
import os
import signal
import sys
import time

import numpy as np
import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from fahv.config import Field
from fahv.config.spec import validate_flat
from fahv.errors import ParameterError
from fahv.loop.graph import (
    DEFAULT_GRAPH,
    GRAPH,
    PREVIOUS,
    QOS_DEPTH,
    TOPICS,
    n_steps_of,
    producer_of,
)
from fahv.loop.params import specs, validate
from fahv.msg import MESSAGES, LoopMessage

LOOP_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=QOS_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
READY_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=20,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: Parameter services cost every spin of every node (more entities in the wait set).
START_PARAMETER_SERVICES = os.environ.get("HSV_PARAM_SERVICES", "0") == "1"
EXIT_OK, EXIT_ERROR, EXIT_PARAM, EXIT_WATCHDOG, EXIT_SIGNAL, EXIT_FOREIGN = 0, 1, 2, 3, 4, 5
#: Wall time between two isolation checks of a running node [s].
FOREIGN_CHECK_S = 1.0


class WatchdogError(RuntimeError):
    """A peer went silent for longer than the watchdog time."""


class ForeignGraphError(RuntimeError):
    """Another graph publishes loop topics in this node's ROS domain."""


def foreign_publishers(node: Node, graph_nodes, topics) -> str | None:
    """Check that no loop topic has more publishers than the running graph has.

    Parameters
    ----------
    node : rclpy.node.Node
        The node that checks (its context gives the domain).
    graph_nodes : sequence of str
        Nodes of the running graph (parameter ``graph_nodes``).
    topics : iterable of str
        Loop topics to check (the node's inputs).

    Returns
    -------
    str or None
        A message naming the topic, both counts, the expected publishers and the
        ROS domain, or None when every count is within the graph's.
    """
    for topic in topics:
        producers = [n for n in graph_nodes if n in GRAPH and topic in GRAPH[n][1]]
        found = node.count_publishers(topic)
        if found > len(producers):
            domain = node.context.get_domain_id()
            return (
                f"{node.get_name()}: {found} publishers on {topic}, but its graph has "
                f"{len(producers)} ({', '.join(producers) or 'none'}): another graph is "
                f"running in ROS domain {domain} (ROS_DOMAIN_ID={domain}); give each graph "
                "its own domain (fahv sil takes a free one from domain_coordinator)"
            )
    return None


def msg_type(topic: str):
    """ROS message class of a loop topic."""
    pkg, _, name = TOPICS[topic].split("/")
    module = __import__(f"{pkg}.msg", fromlist=[name])
    return getattr(module, name)


def to_dict(msg) -> dict:
    """Message -> dict of its fields; float64[] as float64 ndarrays, nested as dicts."""
    out = {}
    for name in msg.get_fields_and_field_types():
        v = getattr(msg, name)
        if isinstance(v, array.array | np.ndarray | list):
            v = np.asarray(v, dtype=float)
        elif hasattr(v, "get_fields_and_field_types"):
            v = to_dict(v)
        out[name] = v
    return out


def to_msg(topic: str, message):
    """Loop message of one run (:mod:`fahv.msg`, or the Clock's fields) -> ROS message."""
    msg = msg_type_of(topic)()
    _fill(msg, message.lane(0) if isinstance(message, LoopMessage) else message)
    return msg


def from_msg(topic: str, msg):
    """ROS message of a loop topic -> :mod:`fahv.msg` message of one run (B = 1)."""
    return MESSAGES[TOPICS[topic]].from_lanes([to_dict(msg)])


def _fill(msg, fields: dict) -> None:
    for name in msg.get_fields_and_field_types():
        v = fields[name]
        if isinstance(v, dict):
            _fill(getattr(msg, name), v)
        elif isinstance(v, np.ndarray | list | tuple):
            arr = array.array("d")
            arr.frombytes(np.ascontiguousarray(v, dtype=np.float64).tobytes())
            setattr(msg, name, arr)
        elif isinstance(v, np.floating):
            setattr(msg, name, float(v))
        else:
            setattr(msg, name, v)


_ROS_TYPE = {
    "float": Parameter.Type.DOUBLE,
    "int": Parameter.Type.INTEGER,
    "str": Parameter.Type.STRING,
    "bool": Parameter.Type.BOOL,
    "floats": Parameter.Type.DOUBLE_ARRAY,
    "ints": Parameter.Type.INTEGER_ARRAY,
    "strs": Parameter.Type.STRING_ARRAY,
    "matrix": Parameter.Type.DOUBLE_ARRAY,
}


def descriptor(f: Field) -> ParameterDescriptor:
    """ROS parameter descriptor of a config field.

    Description with unit, range and equation; the numeric range when both ends are
    finite.
    """
    desc = ParameterDescriptor(description=f.doc())
    if f.lo is not None and f.hi is not None:
        if f.type == "float":
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(f.lo), to_value=float(f.hi))
            ]
        elif f.type == "int":
            desc.integer_range = [IntegerRange(from_value=int(f.lo), to_value=int(f.hi))]
    return desc


def declare_parameters(node: Node, fields) -> dict:
    """Declare typed parameters from config fields; return their raw values.

    Matrices are declared as a double array plus ``<name>_shape``. A parameter the
    parameter file does not set is None (absent: its default or "missing" is decided
    by :func:`fahv.config.spec.validate_flat`, the one validation).

    Raises
    ------
    ParameterError
        Naming the key, for a value of the wrong type in the file or outside the
        declared range.
    """
    values = {}
    for f in fields:
        decls = [(f.name, _ROS_TYPE[f.type], descriptor(f))]
        if f.type == "matrix":
            shape = ParameterDescriptor(description=f"shape of {f.name}")
            decls.append((f"{f.name}_shape", Parameter.Type.INTEGER_ARRAY, shape))
        for name, typ, desc in decls:
            try:
                node.declare_parameter(name, typ, desc)
                values[name] = node.get_parameter(name).value
            except rclpy.exceptions.ParameterUninitializedException:
                values[name] = None
            except (
                rclpy.exceptions.InvalidParameterTypeException,
                rclpy.exceptions.InvalidParameterValueException,
            ) as exc:
                raise ParameterError(
                    f"{node.get_name()}: parameter '{name}' is invalid: {exc}"
                ) from None
    for key, v in values.items():
        if isinstance(v, array.array | list):
            v = [x for x in v if x != ""] if _is_str_list(v) else list(v)
            values[key] = v if v or key.endswith("_shape") else None
    return values


def _is_str_list(v) -> bool:
    return isinstance(v, list) and bool(v) and isinstance(v[0], str)


def declare_validated(node: Node, fields) -> dict:
    """Declare config fields as parameters and validate them (the one validation).

    String arrays drop empty strings (``[""]`` stands for an empty list, since a YAML
    ``[]`` has no parameter type).

    Raises
    ------
    ParameterError
        Naming the node and the key.
    """
    return validate_flat(fields, declare_parameters(node, fields), node.get_name(), ParameterError)


def run_metadata_param(node_name: str, text: str) -> dict:
    """Parameter ``metadata_json`` as a dict, with ``code_version`` filled in.

    Raises
    ------
    ParameterError
        If it is not a JSON object.
    """
    from fahv.version import code_version

    try:
        meta = json.loads(text)
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        raise ParameterError(f"{node_name}: parameter 'metadata_json' is not a JSON object")
    meta.setdefault("code_version", code_version())
    return meta


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


class LockstepNode(Node):
    """Base of every loop node: parameters, buffering by step, readiness, watchdog.

    Subclasses set ``ROLE`` (a key of :data:`GRAPH`) and implement :meth:`make_core`
    and :meth:`on_step`.
    """

    ROLE = ""

    def __init__(self, name: str | None = None) -> None:
        super().__init__(
            name or self.ROLE,
            start_parameter_services=START_PARAMETER_SERVICES,
        )
        self.declare_parameter(
            "graph_nodes",
            DEFAULT_GRAPH,
            ParameterDescriptor(description="nodes of the running graph (readiness check)"),
        )
        self.graph_nodes = list(self.get_parameter("graph_nodes").value)
        raw = declare_parameters(self, specs()[self.spec_name()])
        self.p = validate(self.spec_name(), raw)
        self.Ts = self.p["Ts"]
        self.n_steps = n_steps_of(self.p)
        self.watchdog_s = self.p["watchdog_s"]
        self.inputs, self.outputs = GRAPH[self.ROLE]
        self.previous = PREVIOUS.get(self.ROLE, ())
        self.make_core(self.p)
        self.k = 0
        self.buf = {t: {} for t in self.inputs}
        self.stale = 0
        self.duplicate = 0
        self.pubs = {t: self.create_publisher(msg_type_of(t), t, LOOP_QOS) for t in self.outputs}
        self.subs = [
            self.create_subscription(
                msg_type_of(t), t, lambda m, t=t: self._receive(t, m), LOOP_QOS
            )
            for t in self.inputs
        ]
        self.ready_pub = self.create_publisher(String, "/hsv/ready", READY_QOS)
        self.ready = False
        self.done = False
        self.last_progress = time.monotonic()
        self.t_ready = time.monotonic()
        self.next_foreign_check = 0.0

    # -- to implement -------------------------------------------------------------
    def spec_name(self) -> str:
        """Parameter specification used (defaults to the node name)."""
        return self.get_name()

    def make_core(self, p: dict) -> None:
        """Build the library object(s) from the validated parameters ``p``."""
        raise NotImplementedError

    def on_step(self, k: int, inputs: dict) -> list[tuple[str, object]]:
        """Outputs (topic, message) of step k given {topic: message} of its inputs.

        Messages are :mod:`fahv.msg` messages of one run (the Clock as its fields).
        """
        raise NotImplementedError

    def close(self, status: int) -> None:
        """Called once when the node stops, with its exit status."""

    # -- machinery ------------------------------------------------------------------
    def _receive(self, topic: str, msg) -> None:
        k = msg.k + 1 if topic in self.previous else msg.k  # the step that uses it
        if k < self.k or k in self.buf[topic]:
            # a second sender of this step: first of all another graph in the domain
            # (it has surely been discovered by now, whatever the timing at start-up)
            self.check_foreign()
            if k < self.k:
                self.stale += 1
                self.get_logger().warning(f"stale {topic} of step {k} at step {self.k}: ignored")
            else:
                self.duplicate += 1
                self.get_logger().warning(f"duplicate {topic} of step {k}: ignored")
            return
        self.buf[topic][k] = msg
        self._advance()

    def _advance(self) -> None:
        while not self.done and all(
            self.k in b or (self.k == 0 and t in self.previous) for t, b in self.buf.items()
        ):
            inputs = {
                t: from_msg(t, self.buf[t].pop(self.k)) if self.k in self.buf[t] else None
                for t in self.inputs
            }
            for topic, message in self.on_step(self.k, inputs):
                self.pubs[topic].publish(to_msg(topic, message))
            self.k += 1
            self.last_progress = time.monotonic()
            if self.k >= self.n_steps:
                self.finish()

    def finish(self) -> None:
        """Mark the run as complete for this node."""
        self.done = True
        wall = time.monotonic() - self.t_ready
        self.get_logger().info(
            f"done: {self.k} steps in {wall:.2f} s wall ({1e3 * wall / max(self.k, 1):.2f} ms per "
            f"step), {self.stale} stale and {self.duplicate} duplicate messages"
        )

    def expected_subscribers(self, topic: str) -> int:
        """Nodes of the running graph that consume a topic."""
        return sum(
            1 for n in self.graph_nodes if n in GRAPH and topic in GRAPH[n][0] and n != self.ROLE
        )

    def matched(self) -> list[str]:
        """Topics whose peers are not matched yet (empty when ready)."""
        missing = [
            t for t, s in zip(self.inputs, self.subs, strict=True) if s.get_publisher_count() < 1
        ]
        missing += [
            t
            for t, pub in self.pubs.items()
            if pub.get_subscription_count() < self.expected_subscribers(t)
        ]
        return missing

    def check_foreign(self, now: float | None = None) -> None:
        """Isolation check, at most every :data:`FOREIGN_CHECK_S` seconds.

        Parameters
        ----------
        now : float, optional
            ``time.monotonic()`` of the caller; None checks at once.

        Raises
        ------
        ForeignGraphError
            If an input topic has more publishers than the graph has producers of it.
        """
        if now is not None:
            if now < self.next_foreign_check:
                return
            self.next_foreign_check = now + FOREIGN_CHECK_S
        problem = foreign_publishers(self, self.graph_nodes, self.inputs)
        if problem:
            raise ForeignGraphError(problem)

    def poll(self) -> None:
        """Called between spins: readiness announcement and the watchdog."""
        if not self.ready:
            if not self.matched():
                self.check_foreign()
                self.ready = True
                self.ready_pub.publish(String(data=self.get_name()))
                self.get_logger().info("all peers matched: ready")
                self.last_progress = self.t_ready = time.monotonic()
            return
        self.check_watchdog()

    def producer_of(self, topic: str) -> str:
        """Name of the graph node that publishes a topic."""
        return producer_of(topic, self.graph_nodes)

    def check_watchdog(self) -> None:
        """Raise :class:`WatchdogError` naming the silent peer.

        Raises
        ------
        WatchdogError
            If no step was completed for ``watchdog_s`` seconds of wall time.
        """
        now = time.monotonic()
        self.check_foreign(now)
        if self.done or now - self.last_progress <= self.watchdog_s:
            return
        missing = [
            t for t in self.inputs if self.k not in self.buf[t] and not (
                self.k == 0 and t in self.previous)
        ] or list(self.inputs)
        peers = ", ".join(f"{t} from {self.producer_of(t)}" for t in missing)
        raise WatchdogError(
            f"{self.get_name()}: no {peers} for step {self.k} within {self.watchdog_s:g} s "
            "(peer dead or silent)"
        )


def msg_type_of(topic: str):
    """Message class of a topic (the Clock of rosgraph_msgs for /clock)."""
    if topic == "/clock":
        from rosgraph_msgs.msg import Clock

        return Clock
    return msg_type(topic)


def make_executor(message_info: bool = False):
    """Executor of every node: rclpy's EventsExecutor unless ``HSV_EXECUTOR=single``.

    ``message_info=True`` (the recorder: it keeps the DDS source timestamps) selects
    the SingleThreadedExecutor, since the EventsExecutor of Jazzy cannot call a
    subscription callback with its message info (SystemError, measured).

    The events executor (rclpy.experimental, C++ event queue) runs the Case 1 graph
    about 1.4x faster than the SingleThreadedExecutor on this 2-core machine
    (6.5 vs 9.3 ms per step, measured); docs/environment.md saw it hang in another test,
    so the SIL integration tests (lockstep, kill, SIGINT, watchdog) run with it, and
    ``HSV_EXECUTOR=single`` selects the classic executor.
    """
    if message_info or os.environ.get("HSV_EXECUTOR", "events") == "single":
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

    After the last step the node stays until every subscriber (the recorder too, which
    may lag behind the loop) acknowledged its messages, at most ``linger_s`` seconds:
    a reliable writer that goes away earlier loses what is still unacknowledged.
    SIGINT and SIGTERM stop the spin loop cleanly (the node's :meth:`close` runs, so
    the recorder finishes its file).
    """
    stop = _Stop()
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    node = None
    status = EXIT_OK
    name = node_cls.ROLE
    try:
        node = node_cls()
        name = node.get_name()
        ex = make_executor(getattr(node, "MESSAGE_INFO", False))
        ex.add_node(node)
        while not node.done and stop.signal is None:
            ex.spin_once(timeout_sec=0.05)
            node.poll()
        if stop.signal is not None and not node.done:
            print(f"[{name}] stopped by signal {stop.signal} at step {node.k}", file=sys.stderr)
            status = EXIT_SIGNAL
        else:  # let reliable QoS deliver the last messages before the writers go away
            t_end = time.monotonic() + linger_s
            while time.monotonic() < t_end and stop.signal is None and not all_acked(node):
                ex.spin_once(timeout_sec=0.01)
    except ParameterError as exc:
        print(f"[{name}] parameter error: {exc}", file=sys.stderr)
        status = EXIT_PARAM
    except WatchdogError as exc:
        print(f"[{name}] watchdog: {exc}", file=sys.stderr)
        status = EXIT_WATCHDOG
    except ForeignGraphError as exc:
        print(f"[{name}] error: {exc}", file=sys.stderr)
        status = EXIT_FOREIGN
    except Exception as exc:  # report any failure with the node's name, then the traceback
        import traceback

        print(f"[{name}] error: {type(exc).__name__}: {exc}", file=sys.stderr)
        traceback.print_exc()
        status = EXIT_ERROR
    finally:
        if node is not None:
            try:
                node.close(status)
            finally:
                node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return status
