"""The one readiness logic of every node: its status on the graph, its view of the peers.

`GraphStatus` publishes the node's status on `fahv.loop.graph.STATUS_TOPIC`
(at start, on every change, and as a heartbeat from a thread of its own, so a node busy
building its core or solving still counts as alive), keeps the peers' statuses in a
`fahv.sil.peers.Peers` table, and decides:

- **ready**: every subscription sees its publisher, every publisher sees each subscriber
  the node table expects among `graph_nodes`, every peer listed in `wait_for` (the
  plant: all of them) announced itself ready, and no foreign publisher is on an input;
- **start-up watchdog**: a node that is not ready, or waits for its first step, and
  sees no progress in the graph's start (a peer appearing or changing state, a topic
  matched) stops with `WatchdogError`: after `watchdog_s` when a peer is
  missing (never started, lost, exited), naming it before the topics it waits for;
  after `STARTUP_MAX_S` when every peer is alive but some are still starting;
- **a failed peer**: a peer of the graph that exited with a non-zero status stops the
  node at once, with that peer's name and reason;
- **the run's verdict**: a peer that ended the run with a verdict (`fahv.verdict`)
  stops the node with the same verdict, which its last status carries on;
- **foreign graphs**: another graph in the ROS domain (statuses of another run id, or
  more publishers on an input than the graph has producers of it) stops the graph that
  joined second; the first one goes on and ignores the other's messages (which are of
  earlier steps), unless the two cannot be told apart.
"""

from __future__ import annotations

import os
import threading
import time

from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import String

from fahv.loop.graph import GRAPH, STATUS_PERIOD_S, STATUS_TOPIC, producer_of
from fahv.sil.peers import Peers, parse_status, status
from fahv.verdict import RunEnded
from hsv_common.runtime import (
    STATUS_QOS,
    ForeignGraphError,
    WatchdogError,
    quiet_publisher,
    quiet_subscription,
)

#: Wall time between two foreign-graph checks of a node [s].
FOREIGN_CHECK_S = 1.0
#: Wall time an unexplained extra publisher may take before its node announces itself [s].
FOREIGN_GRACE_S = 2.0 * STATUS_PERIOD_S
#: Longest start of a graph whose peers are all alive but not all ready [s wall time].
STARTUP_MAX_S = 60.0
#: Wall time between two "waiting for ..." lines of a node that is not ready [s].
WAITING_LOG_S = 2.0
#: Longest wait for the peers' acknowledgement of an error exit's status [s].
EXIT_ACK_S = 0.5


class GraphStatus:
    """Status of one node on the graph and its view of the peers.

    Parameters
    ----------
    node : rclpy.node.Node
        The node (its name, context, graph queries).
    graph_nodes : sequence of str
        Nodes of the running graph.
    run_id : str
        Run id shared by the graph's nodes.
    watchdog_s : float
        Start-up watchdog: wall time without progress of the start [s].
    wait_for : sequence of str
        Peers that must be ready before this node is (the plant: every peer).
    """

    def __init__(self, node: Node, graph_nodes, run_id: str, watchdog_s: float, wait_for=()):
        self.node = node
        self.name = node.get_name()
        self.graph_nodes = list(graph_nodes)
        self.watchdog_s = float(watchdog_s)
        self.wait_for = [n for n in wait_for if n != self.name]
        self.domain = node.context.get_domain_id()
        self.peers = Peers(self.name, os.getpid(), run_id, time.time(), self.graph_nodes)
        self.state, self.k, self.waiting = "starting", 0, ["its core"]
        self.inputs: dict = {}  # topic -> subscription
        self.outputs: dict = {}  # topic -> publisher
        self.ready = False
        now = time.monotonic()
        self.t_progress = self.t_log = now
        self.next_foreign = 0.0
        self.extra_since: dict[str, float] = {}  # topic -> first time it had extra publishers
        self.said_stay = False
        self._held: str | None = None
        #: The verdict that ended the run (fahv.verdict.Verdict), announced at once and
        #: in every status after it.
        self.verdict = None
        self._key: list = []
        self._lock = threading.Lock()
        self._pub = node.create_publisher(
            String, STATUS_TOPIC, STATUS_QOS, event_callbacks=quiet_publisher()
        )
        node.create_subscription(
            String, STATUS_TOPIC, self._on_status, STATUS_QOS,
            event_callbacks=quiet_subscription(),
        )  # fmt: skip
        self.publish()
        self._stop = threading.Event()
        self._beat = threading.Thread(target=self._heartbeat, name="status", daemon=True)
        self._beat.start()

    # -- own status ---------------------------------------------------------------------
    def publish(self, exit_status: int | None = None, reason: str = "") -> None:
        """Publish the node's current status."""
        verdict = None if self.verdict is None else self.verdict.as_dict()
        text = status(
            self.name, self.peers.pid, self.peers.run, self.peers.start, self.state, self.k,
            self.waiting, exit_status, reason, verdict=verdict,
        )  # fmt: skip
        with self._lock:
            self._pub.publish(String(data=text))

    def _heartbeat(self) -> None:
        while not self._stop.wait(STATUS_PERIOD_S):
            try:
                self.publish()
            except Exception:  # the context is shutting down: the node is leaving anyway
                return

    def announce(self, verdict) -> None:
        """Hold the run's verdict (`fahv.verdict.Verdict`) and publish it at once.

        Every status after carries it, and the peers stop with it (`check_failed_peer`).
        """
        self.verdict = verdict
        self.publish()

    def set_state(self, state: str, k: int | None = None) -> None:
        """Change the announced state (and step) and publish it at once."""
        self.state = state
        if k is not None:
            self.k = k
        self.publish()

    def close(self, exit_status: int, reason: str) -> None:
        """Stop the heartbeat; announce the exit with its status and reason.

        An error exit waits (at most `EXIT_ACK_S`) until the peers acknowledged it:
        they stop naming this node's reason. A clean exit does not wait: the peers
        already know the node is done.
        """
        self._stop.set()
        self._beat.join(timeout=2.0)
        self.state = "exited"
        try:
            self.publish(exit_status, reason)
            if exit_status:
                self._pub.wait_for_all_acked(Duration(seconds=EXIT_ACK_S))
        except Exception:  # the context may be gone already
            pass

    # -- peers ----------------------------------------------------------------------------
    def _on_status(self, msg: String) -> None:
        if self.peers.update(parse_status(msg.data)):
            self.t_progress = time.monotonic()

    def attach(self, inputs: dict, outputs: dict) -> None:
        """The node's loop subscriptions and publishers ({topic: entity}) to match."""
        self.inputs, self.outputs = dict(inputs), dict(outputs)

    def consumers(self, topic: str) -> list[str]:
        """Nodes of the graph other than this one that consume a topic."""
        return [
            n for n in self.graph_nodes if n in GRAPH and topic in GRAPH[n][0] and n != self.name
        ]

    def finished(self, name: str, n_steps: int) -> bool:
        """True if peer `name` of this run finished its `n_steps` steps.

        It announced them done (or exited cleanly after them): it took every message of
        every step it consumes.
        """
        s = self.peers.own(name)
        return (
            s is not None
            and s["k"] >= n_steps
            and (s["state"] == "done" or (s["state"] == "exited" and not s.get("exit")))
        )

    def consumers_finished(self, topics, n_steps: int) -> bool:
        """True if every consumer of `topics` in the graph finished its `n_steps` steps.

        Then every message of these topics reached its readers, whether or not the DDS
        writer has seen their acknowledgements yet (which may take a heartbeat period of
        the middleware, about 3 s with Fast DDS, measured).
        """
        return all(self.finished(n, n_steps) for t in topics for n in self.consumers(t))

    def unmatched(self) -> list[str]:
        """What the node's topics still wait for, e.g. `/hsv/state (from plant)`."""
        out = []
        for t, sub in self.inputs.items():
            producer = producer_of(t, self.graph_nodes)
            if producer != "?" and sub.get_publisher_count() < 1:
                out.append(f"{t} (from {producer})")
        for t, pub in self.outputs.items():
            want = self.consumers(t)
            if pub.get_subscription_count() < len(want):
                out.append(f"{t} (to {', '.join(want)})")
        return out

    def _peer_text(self, name: str) -> str:
        """A waited-for peer, described: missing, starting (and what it waits for)."""
        gone = self.peers.describe(name)
        if gone is not None:
            return gone
        starting = [d for d in self.peers.not_ready() if d.startswith(f"{name} (")]
        return starting[0] if starting else f"{name} (not ready)"

    def missing_text(self) -> str:
        """The missing peers, described, or ""."""
        return "; ".join(self.peers.missing())

    def check_failed_peer(self) -> None:
        """Stop if a peer ended the run with a verdict, or exited with an error.

        Raises
        ------
        RunEnded
            If a peer announced the run's verdict (`fahv.verdict`): this node
            ends with the same verdict (and announces it at once, as its peer did).
        WatchdogError
            If a peer exited with an error; the message is
            `fahv.sil.peers.Peers.failed_verdict`: the root cause (a peer that
            never started or was lost) first.
        """
        ended = self.peers.run_verdict()
        if ended is not None:
            self.announce(ended)
            raise RunEnded.of(ended)
        verdict = self.peers.failed_verdict()
        if verdict is not None:
            raise WatchdogError(f"{self.name}: {verdict}")

    # -- readiness ------------------------------------------------------------------------
    def poll_ready(self) -> bool:
        """One readiness check; True once the node is ready (then it announces itself).

        Raises
        ------
        WatchdogError
            If the graph's start made no progress for `watchdog_s`, or a peer failed.
        ForeignGraphError
            If another graph that joined first runs in the domain.
        """
        if self.ready:
            return True
        now = time.monotonic()
        self.check_failed_peer()
        unmatched = self.unmatched()
        peers = [n for n in self.wait_for if not self.peers.ready(n)]
        foreign = self.check_foreign(force=False)
        key = unmatched + peers + ([foreign.split(":")[0]] if foreign else [])
        if key != self._key:  # progress of the start: something changed
            self._key = key
            self.t_progress = now
        waiting = unmatched + [self._peer_text(n) for n in peers] + ([foreign] if foreign else [])
        if [w.split(" (")[0] for w in waiting] != [w.split(" (")[0] for w in self.waiting]:
            self.waiting = waiting
            self.publish()
        self.waiting = waiting
        if not waiting:
            self.ready = True
            self.set_state("ready")
            self.node.get_logger().info("all peers matched: ready")
            return True
        if now - self.t_log >= WAITING_LOG_S:
            self.t_log = now
            self.node.get_logger().info(f"waiting for {'; '.join(waiting)}")
        stalled = self.stalled(self.t_progress)
        if stalled is not None:
            raise WatchdogError(
                f"{self.name}: graph not ready, no progress for {now - self.t_progress:.0f} s: "
                f"{stalled + '; ' if stalled else ''}waiting for {'; '.join(waiting)}"
            )
        return False

    def stalled(self, since: float) -> str | None:
        """Whether the graph's start has stalled (before the first step of this node).

        A start makes progress while peers appear or change state. With a peer missing
        (never started, lost, exited) it has stalled after `watchdog_s` without
        progress; with every peer alive but some still starting (building their core,
        waiting for others) only after `STARTUP_MAX_S`.

        Parameters
        ----------
        since : float
            `time.monotonic()` from which this node waits.

        Returns
        -------
        str or None
            None while the start goes on; else the missing (or not ready) peers,
            described ("" when every peer is ready).
        """
        idle = time.monotonic() - max(since, self.t_progress)
        missing = self.peers.missing()
        if missing:
            return f"missing {'; '.join(missing)}" if idle > self.watchdog_s else None
        not_ready = self.peers.not_ready()
        if not_ready:
            limit = max(self.watchdog_s, STARTUP_MAX_S)
            return f"not ready: {'; '.join(not_ready)}" if idle > limit else None
        return "" if idle > self.watchdog_s else None

    # -- foreign graphs -------------------------------------------------------------------
    def check_foreign(self, force: bool = True) -> str | None:
        """Foreign-graph check (at most every `FOREIGN_CHECK_S` unless `force`).

        Returns
        -------
        str or None
            What holds the node back while another graph's extra publishers are still
            on its inputs (they joined later and stop by themselves), else None.

        Raises
        ------
        ForeignGraphError
            If this graph joined second, the two cannot be told apart, or an input has
            extra publishers that no node status explains for `FOREIGN_GRACE_S`
            (or that a later graph still holds after `watchdog_s`).
        """
        now = time.monotonic()
        if not force and now < self.next_foreign:
            return self._held
        self.next_foreign = now + FOREIGN_CHECK_S
        verdict = self.peers.foreign_verdict(self.domain)
        if verdict is not None:
            action, text = verdict
            if action == "stop":
                raise ForeignGraphError(text)
            if not self.said_stay:
                self.said_stay = True
                self.node.get_logger().warning(text)
        self._held = None
        for topic in self.inputs:
            producers = [n for n in self.graph_nodes if n in GRAPH and topic in GRAPH[n][1]]
            found = self.node.count_publishers(topic)
            if found <= len(producers):
                self.extra_since.pop(topic, None)
                continue
            since = self.extra_since.setdefault(topic, now)
            later = any(self.peers.explains(p) for p in producers)
            limit = self.watchdog_s if later else FOREIGN_GRACE_S
            if now - since > limit:
                raise ForeignGraphError(
                    f"{self.name}: {found} publishers on {topic}, but its graph has "
                    f"{len(producers)} ({', '.join(producers) or 'none'}): another graph is "
                    f"running in ROS domain {self.domain} (ROS_DOMAIN_ID={self.domain}); give "
                    "each graph its own domain (fahv sil takes a free one from "
                    "domain_coordinator)"
                )
            self._held = f"{topic}: {found - len(producers)} extra publisher(s) to go"
        return self._held
