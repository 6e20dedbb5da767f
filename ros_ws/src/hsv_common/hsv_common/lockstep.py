"""The lockstep state machine shared by every loop node (no model or control maths).

A `LockstepNode` declares the typed parameters of its node
(`hsv_common.parameters`), builds the library object it adapts
(`LockstepNode.make_core`), and then only moves messages:

- Inputs are buffered per step index k; the node calls `LockstepNode.on_step`
  once it holds every input of its current step, publishes the outputs of that step
  and moves to k + 1. A message of an already processed step (stale) is counted and
  logged, never used; a second message of a buffered step (duplicate) means a second
  sender of the same steps and stops the node (exit status 5).
- Reliable, keep-last QoS on every loop topic (`fahv.loop.graph.LOOP_QOS`).
- Start-up, readiness, missing peers and foreign graphs: `GraphStatus`, the
  one readiness logic (the plant waits for every peer before step 0).
- A core that ends the run with a verdict (`fahv.verdict.RunEnded`) stops the
  node with exit status 6; its last status carries the verdict, and every peer stops
  with it (`hsv_common.graph_status.GraphStatus.check_failed_peer`).
- A wall-clock watchdog (parameter `watchdog_s`) turns a silent input into an error
  naming the missing peer (never started, lost, exited) or, when every peer is alive,
  the topic and the node that should have sent it (exit status 3).

The process around the node (exit codes, signals, executor) is `hsv_common.runtime`,
the conversion between typed messages and their CDR bytes the library's codec
(`fahv.sil.wire`).
"""

from __future__ import annotations

import time

from rclpy.node import Node

from fahv.loop.graph import GRAPH, PREVIOUS, loop_nodes, n_steps_of, producer_of
from fahv.loop.params import specs, validate
from fahv.sil.wire import decode_message, encode, step_of
from fahv.verdict import RunEnded
from hsv_common.graph_status import GraphStatus
from hsv_common.parameters import declare_graph, declare_parameters
from hsv_common.runtime import (
    LOOP_QOS,
    ForeignGraphError,
    WatchdogError,
    all_acked,
    node_options,
    quiet_publisher,
    quiet_subscription,
)
from hsv_common.topics import msg_type_of


class LockstepNode(Node):
    """Base of every loop node: parameters, buffering by step, readiness, watchdog.

    Subclasses set `ROLE` (a key of `fahv.loop.graph.GRAPH`) and implement
    `make_core` and `on_step`. `WAIT_FOR_PEERS` (the plant) makes the
    node ready only once every other node of the graph is.
    """

    ROLE = ""
    WAIT_FOR_PEERS = False

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name or self.ROLE, **node_options())
        self.graph_nodes, run_id = declare_graph(self)
        raw = declare_parameters(self, specs()[self.spec_name()])
        self.p = validate(self.spec_name(), raw)
        self.Ts = self.p["Ts"]
        self.Ts_ns = int(round(self.Ts * 1e9))
        self.n_steps = n_steps_of(self.p)
        self.watchdog_s = self.p["watchdog_s"]
        wait_for = self.graph_nodes if self.WAIT_FOR_PEERS else ()
        # announced before the core is built: peers know this node is alive meanwhile
        self.status = GraphStatus(self, self.graph_nodes, run_id, self.watchdog_s, wait_for)
        self.inputs, self.outputs = GRAPH[self.ROLE]
        self.previous = PREVIOUS.get(self.ROLE, ())
        self.make_core(self.p)
        self.k = 0
        self.buf = {t: {} for t in self.inputs}
        self.stale = 0
        self.pubs = {
            t: self.create_publisher(msg_type_of(t), t, LOOP_QOS, event_callbacks=quiet_publisher())
            for t in self.outputs
        }
        self.subs = {  # raw: the CDR bytes, decoded once the step's inputs are all in
            t: self.create_subscription(
                msg_type_of(t),
                t,
                lambda data, t=t: self._receive(t, data),
                LOOP_QOS,
                event_callbacks=quiet_subscription(),
                raw=True,
            )  # fmt: skip
            for t in self.inputs
        }
        self.status.attach(self.subs, self.pubs)
        self.status.waiting = []
        loop = set(loop_nodes())
        self.publish_order = sorted(  # stable: the table's order within each group
            self.outputs, key=lambda t: not loop & set(self.status.consumers(t))
        )
        self.done = False
        self.ended: RunEnded | None = None  # the verdict of the node's core, raised by poll
        self.last_progress = time.monotonic()
        self.t_ready = time.monotonic()

    # -- to implement -------------------------------------------------------------
    def spec_name(self) -> str:
        """Parameter specification used (defaults to the node name)."""
        return self.get_name()

    def make_core(self, p: dict) -> None:
        """Build the library object(s) from the validated parameters `p`."""
        raise NotImplementedError

    def on_step(self, k: int, inputs: dict) -> list[tuple[str, object]]:
        """Outputs (topic, message) of step k given {topic: message} of its inputs.

        Messages are `fahv.msg` messages of one run (the Clock as its fields).
        """
        raise NotImplementedError

    def after_publish(self, k: int) -> None:
        """Work of step k that no output of step k waits for (default: none).

        Called once the outputs of step k are published, before the inputs of step
        k + 1 are taken: what a node does here is off the step's critical path.
        """

    def on_ready(self) -> None:
        """Called once when the node is ready (the plant publishes step 0 here)."""

    def close(self, status: int, reason: str = "") -> None:
        """Called once when the node stops, with its exit status and the error message."""
        self.status.close(status, reason)

    # -- machinery ------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """True once the node announced itself ready."""
        return self.status.ready

    def _receive(self, topic: str, data: bytes) -> None:
        k = step_of(topic, data, self.Ts_ns)
        k = k + 1 if topic in self.previous else k  # the step that uses it
        if k in self.buf[topic]:
            raise ForeignGraphError(
                f"{self.get_name()}: a second {topic} of step {k} arrived: another publisher "
                f"of the same steps runs in ROS domain {self.status.domain} "
                f"(ROS_DOMAIN_ID={self.status.domain}); give each graph its own domain "
                "(fahv sil takes a free one from domain_coordinator)"
            )
        if k < self.k:
            # a later graph in the domain (its steps are behind ours) or a stray sender
            self.stale += 1
            if self.stale == 1 or self.stale % 1000 == 0:
                self.get_logger().warning(
                    f"stale {topic} of step {k} at step {self.k}: ignored ({self.stale} so far)"
                )
            self.status.check_foreign()
            return
        self.buf[topic][k] = data
        self._advance()

    def _advance(self) -> None:
        while (
            not self.done
            and self.ended is None
            and all(
                self.k in b or (self.k == 0 and t in self.previous) for t, b in self.buf.items()
            )
        ):
            inputs = {
                t: decode_message(t, self.buf[t].pop(self.k)) if self.k in self.buf[t] else None
                for t in self.inputs
            }
            try:
                outputs = self.on_step(self.k, inputs)
            except RunEnded as exc:  # the core ended the run: raised by poll, out of the
                self.status.announce(exc.verdict)  # callback; the peers stop at once
                self.ended = exc
                return
            self.publish(outputs)
            self.after_publish(self.k)
            if self.k == 0:
                self.status.set_state("running")
            self.k += 1
            self.status.k = self.k
            self.last_progress = time.monotonic()
            if self.k >= self.n_steps:
                self.finish()

    def publish(self, outputs) -> None:
        """Publish (topic, message) pairs, those a loop node waits for first.

        A step's critical path runs through the loop topics; what only the recorder
        reads (/clock, the tube and fault statuses) is converted and sent after them.
        """
        out = dict(outputs)
        for topic in self.publish_order:
            if topic in out:
                self.pubs[topic].publish(encode(topic, out[topic]))

    def finish(self) -> None:
        """Mark the run as complete for this node."""
        self.done = True
        self.status.set_state("done", self.k)
        wall = time.monotonic() - self.t_ready
        self.get_logger().info(
            f"done: {self.k} steps in {wall:.2f} s wall ({1e3 * wall / max(self.k, 1):.2f} ms per "
            f"step), {self.stale} stale messages"
        )

    def delivered(self) -> bool:
        """True when the node's last messages need no more waiting (then it may exit).

        Every consumer of its outputs finished all steps (the recorder announces that
        once it holds every step of every topic), or every subscriber acknowledged them.
        """
        return self.status.consumers_finished(self.outputs, self.n_steps) or all_acked(self)

    def poll(self) -> None:
        """Called between spins: readiness (then `on_ready`), checks, the watchdog.

        Raises
        ------
        WatchdogError
            If the graph does not start, a peer failed, or an input stays silent.
        ForeignGraphError
            If another graph that joined first runs in the domain.
        RunEnded
            If the node's core ended the run with a verdict (`fahv.verdict`).
        """
        if self.ended is not None:
            raise self.ended
        if not self.status.ready:
            if self.status.poll_ready():
                self.last_progress = self.t_ready = time.monotonic()
                try:
                    self.on_ready()
                except RunEnded as exc:  # e.g. the plant's initial state outside the envelope
                    self.status.announce(exc.verdict)
                    raise
            return
        self.check_watchdog()

    def buf_any(self) -> bool:
        """True if any input of any step arrived."""
        return any(self.buf.values())

    def producer_of(self, topic: str) -> str:
        """Name of the graph node that publishes a topic."""
        return producer_of(topic, self.graph_nodes)

    def check_watchdog(self) -> None:
        """Peer and isolation checks, and the step watchdog.

        Raises
        ------
        WatchdogError
            If a peer failed, or no step was completed for `watchdog_s` seconds of
            wall time: naming the missing peers, else the silent input and its producer.
        ForeignGraphError
            If another graph that joined first runs in the domain.
        """
        if self.done:
            return
        self.status.check_failed_peer()
        self.status.check_foreign(force=False)
        now = time.monotonic()
        if self.k == 0 and not self.buf_any():  # waiting for the graph's step 0
            stalled = self.status.stalled(self.t_ready)
            if stalled is None:
                return
            idle = now - max(self.t_ready, self.status.t_progress)
            cause = f"{stalled}; " if stalled else ""  # the cause first, as below
            raise WatchdogError(
                f"{self.get_name()}: {cause}no step 0 within {idle:.0f} s of the graph's "
                f"last progress{'' if stalled else ' (every peer ready)'}"
            )
        if now - self.last_progress <= self.watchdog_s:
            return
        silent = [
            t
            for t in self.inputs
            if self.k not in self.buf[t] and not (self.k == 0 and t in self.previous)
        ] or list(self.inputs)
        inputs = ", ".join(f"{t} from {self.producer_of(t)}" for t in silent)
        missing = self.status.missing_text()
        if missing:
            raise WatchdogError(
                f"{self.get_name()}: missing {missing}; no {', '.join(silent)} for step "
                f"{self.k} within {self.watchdog_s:g} s"
            )
        raise WatchdogError(
            f"{self.get_name()}: no {inputs} for step {self.k} within {self.watchdog_s:g} s "
            "(every peer alive: a message lost or a peer stuck)"
        )
